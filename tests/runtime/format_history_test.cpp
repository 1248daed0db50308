// Files of earlier format versions that readers must keep decoding: .pyr 3.3 pyramids, whose phase
// streams are libcodec format 7 (one rANS state per tile), written by an earlier release
// (tests/data/pyr-3.3/README.md), against this writer's 3.4 files (format 8, two states).
#include <catch2/catch.hpp>
#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include "build/pyramid_build.h"
#include "codec/codec.h"
#include "container/pyramid_file.h"
#include "edit/pyramid_edit.h"
#include "io/io_test_util.h"
#include "level_decode_util.h"
#include "readers/terrain_generator.h"
#include "runtime/region_decoder.h"

using namespace terrain;
using namespace terrain::container;

namespace {

const std::string kDir = std::string(TERRAIN_SOURCE_DIR) + "/tests/data/pyr-3.3/";

Heightmap source() {  // what the 3.3 files were built from
  SynthOptions so;
  so.width = 160;
  so.height = 144;
  so.seed = 21;
  return synthesize_terrain(so);
}

using pyrtest::decode_all;

// The libcodec format versions of a file's band streams, how many of each (index = version).
std::vector<int> stream_versions(const std::string& path) {
  const auto f = PyramidFile::open(path);
  std::vector<int> count(codec::kFormatVersion + 1, 0);
  for (int l = 0; l < f->level_count(); ++l)
    for (const BandView& v : f->bands(l)) {
      if (v.empty()) continue;
      codec::HeaderInfo h;
      REQUIRE(codec::read_header(v.data, v.size, &h) == codec::Status::Ok);
      ++count[h.version];
    }
  return count;
}

}  // namespace

TEST_CASE("format history: .pyr 3.3 files (format-7 phase streams) decode to what this writer's 3.4 files do",
          "[runtime][format]") {
  iotest::TempDir dir;
  const Heightmap map = source();
  write_raw(dir.file("t.raw"), map);
  struct Case {
    const char* file;
    ErrorMode mode;
    double target;
    build::DownsampleChoice downsample;
  };
  for (const Case& c : {Case{"lossless.pyr", ErrorMode::Lossless, 0, build::DownsampleChoice::Auto},
                        Case{"max2.pyr", ErrorMode::MaxError, 2, build::DownsampleChoice::Auto},
                        Case{"step3.pyr", ErrorMode::Step, 3, build::DownsampleChoice::Point}}) {
    INFO(c.file);
    const std::string old_file = kDir + c.file;
    {
      const auto f = PyramidFile::open(old_file);
      f->verify();
      CHECK(f->container().minor_version() == 3);
    }
    const std::vector<int> old_versions = stream_versions(old_file);
    CHECK(old_versions[7] > 0);
    CHECK(old_versions[8] == 0);

    build::BuildFileOptions bo;
    bo.levels = 3;
    bo.threads = 1;
    bo.mode = c.mode;
    bo.target_metres = c.target;
    bo.downsample = c.downsample;
    const std::string fresh = dir.file("fresh.pyr");
    build::build_pyramid_file(dir.file("t.raw"), ReadOptions{}, fresh, bo);
    CHECK(PyramidFile::open(fresh)->container().minor_version() == kFormatMinor);
    const std::vector<int> new_versions = stream_versions(fresh);
    CHECK(new_versions[8] == old_versions[7]);  // the same bands, now format 8
    CHECK(new_versions[7] == 0);

    // The entropy code changed, the quantised levels did not: the same samples at every level.
    const auto old_levels = decode_all(old_file), new_levels = decode_all(fresh);
    REQUIRE(old_levels.size() == new_levels.size());
    for (size_t l = 0; l < old_levels.size(); ++l) CHECK(old_levels[l] == new_levels[l]);
    // And the bound holds against the source (the finest level is the input's grid).
    double worst = 0;
    for (size_t i = 0; i < map.values.size(); ++i)
      worst = std::max(worst, std::abs(double(old_levels.back()[i]) - double(map.values[i])));
    if (c.mode == ErrorMode::Lossless) CHECK(worst == 0);
    if (c.mode == ErrorMode::MaxError) CHECK(worst <= 2);
  }
}

TEST_CASE("format history: an edit of a 3.3 file splices format-7 tiles into its format-7 streams",
          "[runtime][format][edit]") {
  iotest::TempDir dir;
  const std::string pyr = dir.file("max2.pyr");
  std::filesystem::copy_file(kDir + "max2.pyr", pyr);
  write_raw(dir.file("t.raw"), source());
  const auto before = decode_all(pyr);
  auto editor = edit::PyramidEditor::open(pyr);
  editor->set_source(dir.file("t.raw"));
  editor->apply(edit::Brush{80.5, 70.25, 12, 25.0, edit::BrushShape::Smooth});
  const edit::EditStats st = editor->commit();
  REQUIRE(st.changed);
  const auto f = PyramidFile::open(pyr);
  f->verify();
  CHECK(f->container().minor_version() == kFormatMinor);  // an edit commits this writer's superblock
  // Re-coded tiles went into the bands' format-7 streams (splice_tiles needs one format).
  const std::vector<int> versions = stream_versions(pyr);
  CHECK(versions[7] > 0);
  CHECK(versions[8] == 0);
  const auto after = decode_all(pyr);
  CHECK(after.back() != before.back());
}
