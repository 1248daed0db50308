// Editing a .pyr in place (libedit): error bounds against the edited input at every level, untouched
// bands and tiles byte-identical, crashes at every commit step leave a readable version, compaction.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <limits>

#include "build/pyramid_build.h"
#include "codec/codec.h"
#include "container/pyramid_file.h"
#include "edit/pyramid_edit.h"
#include "io/io_test_util.h"
#include "level_decode_util.h"
#include "readers/terrain_generator.h"
#include "runtime/height_source.h"
#include "runtime/region_decoder.h"
#include "shared_data.h"

using namespace terrain;
using namespace terrain::container;

namespace {

constexpr int64_t kW = 300, kH = 260;
constexpr int kLevels = 4;

// The brush's change in metres at (x, y), restated from the header's contract (smooth profile).
double smooth_brush(const edit::Brush& b, int64_t x, int64_t y) {
  const double r = std::hypot(double(x) - b.x, double(y) - b.y) / b.radius;
  return r <= 1 ? b.height * (1 - r * r) * (1 - r * r) : 0.0;
}

// Synthetic terrain (int16 metres) at <dir>/t.raw and the same with the brush applied (rounded to
// the metre, as the editor rounds to the level unit) at <dir>/edited.raw.
void write_inputs(const iotest::TempDir& dir, const edit::Brush& brush) {
  SynthOptions so;
  so.width = kW;
  so.height = kH;
  so.seed = 21;
  Heightmap map = synthesize_terrain(so);
  write_raw(dir.file("t.raw"), map);
  for (int64_t y = 0; y < kH; ++y)
    for (int64_t x = 0; x < kW; ++x)
      map.values[size_t(y * kW + x)] =
          std::round(map.values[size_t(y * kW + x)] + smooth_brush(brush, x, y) / map.info.vertical_scale);
  write_raw(dir.file("edited.raw"), map);
}

void build_file(const iotest::TempDir& dir, const std::string& out, ErrorMode mode, double target) {
  build::BuildFileOptions bo;
  bo.levels = kLevels;
  bo.threads = 1;
  bo.mode = mode;
  bo.target_metres = target;
  build::build_pyramid_file(dir.file("t.raw"), ReadOptions{}, out, bo);
}

using pyrtest::decode_all;

// Largest |decoded - T_l(edited input)| per level, in level units (the reference uses the file's D).
std::vector<double> max_error_against(const std::string& pyr, const std::string& input) {
  const auto f = PyramidFile::open(pyr);
  const auto decoded = decode_all(pyr);
  const runtime::GridHeightSource ref =
      runtime::original_source(input, ReadOptions{}, f->level_size(f->level_count() - 1), f->level_count(),
                               f->downsample_filter(), 30.0);
  std::vector<double> out;
  const double scale = f->info().vertical_scale, offset = f->info().vertical_offset;
  for (int l = 0; l < f->level_count(); ++l) {
    double worst = 0;
    for (size_t i = 0; i < decoded[size_t(l)].size(); ++i)
      worst =
          std::max(worst, std::abs(decoded[size_t(l)][i] * scale + offset - double(ref.level(l)[i])) / scale);
    out.push_back(worst);
  }
  return out;
}

// File offset and size of every band stream, per level.
std::vector<std::vector<std::pair<uint64_t, size_t>>> stream_places(const std::string& path) {
  const auto f = PyramidFile::open(path);
  std::vector<std::vector<std::pair<uint64_t, size_t>>> out(static_cast<size_t>(f->level_count()));
  for (int l = 0; l < f->level_count(); ++l)
    for (const BandView& v : f->bands(l))
      if (!v.empty()) out[size_t(l)].push_back({f->container().offset_of(v.data), v.size});
  return out;
}

}  // namespace

TEST_CASE("edit: a brush with the source meets the max error against the edited input at every level",
          "[runtime][edit]") {
  iotest::TempDir dir;
  const edit::Brush brush{150.5, 70.25, 18, 35.0, edit::BrushShape::Smooth};
  write_inputs(dir, brush);
  const std::string pyr = dir.file("t.pyr");
  build_file(dir, pyr, ErrorMode::MaxError, 2.0);
  const auto before = decode_all(pyr);
  const auto places_before = stream_places(pyr);
  const uint64_t size_before = std::filesystem::file_size(pyr);
  const double e_units = 2.0 / PyramidFile::open(pyr)->info().vertical_scale;
  std::filesystem::copy_file(pyr, dir.file("unedited.pyr"));

  auto editor = edit::PyramidEditor::open(pyr);
  editor->set_source(dir.file("t.raw"));
  editor->apply(brush);
  const edit::EditStats st = editor->commit();
  REQUIRE(st.changed);
  CHECK(st.generation == 1);
  CHECK(st.bytes_appended > 0);
  CHECK(st.bytes_appended < size_before / 2);
  CHECK(st.dead_bytes > 0);
  PyramidFile::open(pyr)->verify();

  // (a) every level within E = 2 m of the edited input's T_l (what a rebuild codes).
  const std::vector<double> err = max_error_against(pyr, dir.file("edited.raw"));
  for (int l = 0; l < kLevels; ++l) {
    INFO("level " << l << " max error " << err[size_t(l)] << " units");
    CHECK(err[size_t(l)] <= e_units + 1e-9);
  }
  // The unedited file is far off the edited input near the brush: the edit did something.
  CHECK(max_error_against(dir.file("unedited.pyr"), dir.file("edited.raw"))[kLevels - 1] > 10 * e_units);

  // (b) samples away from the brush are unchanged, and so are the streams of bands it does not reach.
  const auto after = decode_all(pyr);
  const auto places_after = stream_places(pyr);
  const auto f = PyramidFile::open(pyr);
  // The reach of the edit, as a radius in each level's samples: D (radius 5 fine samples, so 2.5
  // coarse ones, plus rounding) going coarse-wards, U (a four-point support) going back fine-wards;
  // a re-coded tile changes anywhere in it, so one tile (32) more.
  std::vector<double> reach(kLevels);
  reach[kLevels - 1] = brush.radius + 1;
  for (int l = kLevels - 1; l > 0; --l) reach[size_t(l - 1)] = reach[size_t(l)] / 2 + 3.5;
  for (int l = 1; l < kLevels; ++l)
    reach[size_t(l)] = std::max(reach[size_t(l)], 2 * reach[size_t(l - 1)] + 4);
  int64_t kept_total = 0;
  for (int l = 0; l < kLevels; ++l) {
    const GridSize s = f->level_size(l);
    const int shift = kLevels - 1 - l;
    const double cx = brush.x / (1 << shift), cy = brush.y / (1 << shift), r = reach[size_t(l)] + 32;
    int64_t changed_far = 0;
    for (int64_t y = 0; y < s.height; ++y)
      for (int64_t x = 0; x < s.width; ++x)
        if ((std::abs(double(x) - cx) > r || std::abs(double(y) - cy) > r) &&
            before[size_t(l)][size_t(y * s.width + x)] != after[size_t(l)][size_t(y * s.width + x)])
          ++changed_far;
    INFO("level " << l);
    CHECK(changed_far == 0);
    // The reported box holds every changed sample.
    const Rect& c = st.levels[size_t(l)].changed;
    for (int64_t y = 0; y < s.height; ++y)
      for (int64_t x = 0; x < s.width; ++x)
        if (before[size_t(l)][size_t(y * s.width + x)] != after[size_t(l)][size_t(y * s.width + x)])
          REQUIRE((x >= c.x0 && x < c.x0 + c.width && y >= c.y0 && y < c.y0 + c.height));
    CHECK(c.width > 0);
    for (const auto& p : places_before[size_t(l)])
      kept_total += std::count(places_after[size_t(l)].begin(), places_after[size_t(l)].end(), p);
  }
  CHECK(kept_total > 0);
  CHECK(st.levels[kLevels - 1].tiles_kept > 0);     // clean tiles of re-coded bands were copied
  CHECK(st.levels[kLevels - 1].bands_recoded < 3);  // of the finest level's 3 bands of 128 rows
}

TEST_CASE("edit: without a source the edit is carried down through D, untouched bytes stay",
          "[runtime][edit]") {
  iotest::TempDir dir;
  const edit::Brush brush{40, 200, 12, -20.0, edit::BrushShape::Smooth};
  write_inputs(dir, brush);
  const std::string pyr = dir.file("t.pyr");
  build_file(dir, pyr, ErrorMode::Step, 2.0);
  const auto f0 = PyramidFile::open(pyr);
  const auto before = decode_all(pyr);
  auto editor = edit::PyramidEditor::open(pyr);
  editor->apply(brush);
  const edit::EditStats st = editor->commit();
  REQUIRE(st.changed);
  PyramidFile::open(pyr)->verify();
  const auto after = decode_all(pyr);
  // The finest level near the brush centre moved by about the brush height (-20 m; 1 m units).
  REQUIRE(f0->info().vertical_scale == 1.0);
  const size_t centre = size_t(200 * kW + 40);
  CHECK(after[kLevels - 1][centre] - before[kLevels - 1][centre] < -15);
  CHECK(after[kLevels - 1][centre] - before[kLevels - 1][centre] > -25);
  // Against the edited input the error stays within twice the unedited file's at every level (the
  // target is T^ + Delta: the stored error plus the re-coding's).
  const std::vector<double> err_edit = max_error_against(pyr, dir.file("edited.raw"));
  build_file(dir, dir.file("fresh.pyr"), ErrorMode::Step, 2.0);
  const std::vector<double> err_orig = max_error_against(dir.file("fresh.pyr"), dir.file("t.raw"));
  for (int l = 0; l < kLevels; ++l) {
    INFO("level " << l << ": " << err_edit[size_t(l)] << " vs " << err_orig[size_t(l)]);
    CHECK(err_edit[size_t(l)] <= 2 * err_orig[size_t(l)] + 2);
  }
}

TEST_CASE("edit: a crash at any commit step leaves a readable version, compaction drops dead bytes",
          "[runtime][edit]") {
  iotest::TempDir dir;
  const edit::Brush brush{220, 130, 10, 15.0, edit::BrushShape::Cone};
  write_inputs(dir, brush);
  const std::string base = dir.file("base.pyr");
  build_file(dir, base, ErrorMode::Step, 2.0);
  const auto original = decode_all(base);
  const auto original_bytes = iotest::read_file(base);

  // The clean commit, for comparison.
  const std::string clean = dir.file("clean.pyr");
  std::filesystem::copy_file(base, clean);
  {
    auto e = edit::PyramidEditor::open(clean);
    e->apply(brush);
    REQUIRE(e->commit().changed);
  }
  const auto edited = decode_all(clean);
  REQUIRE(edited != original);

  for (const edit::CrashPoint cp : {edit::CrashPoint::AfterBlobs, edit::CrashPoint::AfterIndex}) {
    const std::string p = dir.file("crash.pyr");
    std::filesystem::remove(p);
    std::filesystem::copy_file(base, p);
    {
      auto e = edit::PyramidEditor::open(p);
      e->apply(brush);
      e->commit(cp);
    }
    INFO("crash point " << int(cp));
    const auto f = PyramidFile::open(p);
    f->verify();
    CHECK(f->container().uncommitted_bytes() > 0);
    CHECK(decode_all(p) == original);
    // The bytes of the previous version are untouched.
    const auto now = iotest::read_file(p);
    REQUIRE(now.size() > original_bytes.size());
    CHECK(std::equal(original_bytes.begin(), original_bytes.end(), now.begin()));
    // The next edit cuts the uncommitted tail off and commits normally.
    auto e = edit::PyramidEditor::open(p);
    e->apply(brush);
    REQUIRE(e->commit().changed);
    CHECK(PyramidFile::open(p)->container().uncommitted_bytes() == 0);
    CHECK(decode_all(p) == edited);
  }
  {
    // A torn superblock write: the reader falls back to the tail copy, the new version.
    const std::string p = dir.file("torn.pyr");
    std::filesystem::copy_file(base, p);
    {
      auto e = edit::PyramidEditor::open(p);
      e->apply(brush);
      e->commit(edit::CrashPoint::TornSuperblock);
    }
    const auto f = PyramidFile::open(p);
    CHECK(f->container().from_tail_superblock());
    f->verify();
    CHECK(decode_all(p) == edited);
  }

  {
    // Two editors of one version: the second commit would overwrite the first's, so it is refused.
    const std::string p = dir.file("two.pyr");
    std::filesystem::copy_file(base, p);
    auto a = edit::PyramidEditor::open(p), b = edit::PyramidEditor::open(p);
    a->apply(brush);
    b->apply(edit::Brush{20, 20, 5, 3.0, edit::BrushShape::Flat});
    REQUIRE(a->commit().changed);
    try {
      b->commit();
      FAIL("the stale editor committed");
    } catch (const Error& e) {
      CHECK(e.code() == ErrorCode::WriteFailed);
      CHECK_THAT(e.what(), Catch::Contains("changed by another writer"));
    }
    CHECK(decode_all(p) == edited);
  }

  // Compaction: no dead bytes, the same decode, a plain (unedited) layout.
  const auto f = PyramidFile::open(clean);
  const uint64_t dead = f->dead_bytes();
  CHECK(dead > 0);
  const edit::CompactStats cs = edit::compact(clean);
  CHECK(cs.bytes_after + dead <= cs.bytes_before);
  const auto g = PyramidFile::open(clean);
  CHECK(!g->container().edited());
  CHECK(g->dead_bytes() == 0);
  g->verify();
  CHECK(decode_all(clean) == edited);
}

TEST_CASE("terrain-edit: options, named errors, --json, --compact", "[runtime][edit]") {
  iotest::TempDir dir;
  const edit::Brush brush{100, 100, 8, 12.0, edit::BrushShape::Flat};
  write_inputs(dir, brush);
  const std::string pyr = dir.file("t.pyr");
  build_file(dir, pyr, ErrorMode::Step, 2.0);
  const auto before = decode_all(pyr);
  const auto bytes_before = iotest::read_file(pyr);
  // Refused, file untouched: outside the grid, NaN, bad shape, nothing to do, not a pyramid.
  const auto outside = iotest::run_tool(dir, {"terrain-edit", {pyr, "--brush", "5000,10,4,1"}});
  CHECK(outside.status == 1);
  CHECK_THAT(outside.err, Catch::Contains("outside the 300x260 grid"));
  CHECK(iotest::run_tool(dir, {"terrain-edit", {pyr, "--brush", "nan,10,4,1"}}).status == 1);
  CHECK(iotest::run_tool(dir, {"terrain-edit", {pyr, "--brush", "10,10,4,1,square"}}).status == 1);
  CHECK(iotest::run_tool(dir, {"terrain-edit", {pyr}}).status == 1);
  CHECK(iotest::run_tool(dir, {"terrain-edit", {dir.file("t.raw"), "--brush", "10,10,4,1"}}).status == 6);
  CHECK(iotest::read_file(pyr) == bytes_before);
  const auto help = iotest::run_tool(dir, {"terrain-edit", {"--help"}});
  CHECK(help.status == 0);
  CHECK_THAT(help.out, Catch::Contains("Exit status"));

  const auto r = iotest::run_tool(dir, {"terrain-edit", {pyr, "--brush", "100,100,8,12,flat", "--json"}});
  REQUIRE(r.status == 0);
  CHECK_THAT(r.out, Catch::Contains("\"generation\": 1"));
  CHECK_THAT(r.out, Catch::Contains("\"tiles_recoded\""));
  const auto info = iotest::run_tool(dir, {"terrain-info", {pyr, "--verify", "--json"}});
  REQUIRE(info.status == 0);
  CHECK_THAT(info.out, Catch::Contains("\"edit_generation\": 1"));
  const auto after = decode_all(pyr);
  // The 12 m of the flat brush, give or take the step-2 quantisation of both decodes.
  CHECK(std::abs(after[kLevels - 1][size_t(100 * kW + 100)] - before[kLevels - 1][size_t(100 * kW + 100)] -
                 12) <= 2);
  REQUIRE(iotest::run_tool(dir, {"terrain-edit", {pyr, "--compact", "-q"}}).status == 0);
  CHECK(decode_all(pyr) == after);
  CHECK_THAT(iotest::run_tool(dir, {"terrain-info", {pyr, "--json"}}).out,
             Catch::Contains("\"dead_bytes\": 0"));
}

// File offset of a byte in the middle of the tile payloads of the finest level's band `band` (a band of
// several tile rows, so the byte is covered by a tile-row CRC as well as the stream's own).
uint64_t payload_byte(const std::string& pyr, size_t band) {
  const auto f = PyramidFile::open(pyr);
  const BandView& v = f->bands(f->level_count() - 1).at(band);
  codec::HeaderInfo h;
  REQUIRE(codec::read_header(v.data, v.size, &h) == codec::Status::Ok);
  REQUIRE(h.tiles_y > 1);
  return f->container().offset_of(v.data) + h.data_offset + (h.index_offset - h.data_offset) / 2;
}

void flip_byte(const std::string& path, uint64_t offset) {
  std::vector<uint8_t> bytes = iotest::read_file(path);
  REQUIRE(offset < bytes.size());
  bytes[size_t(offset)] ^= 0x10;
  iotest::write_file(path, bytes);
}

void require_compaction_refused(const iotest::TempDir& dir, const std::string& pyr,
                                const std::string& expected) {
  const auto bytes = iotest::read_file(pyr);
  try {
    edit::compact(pyr);
    FAIL("a damaged file was compacted");
  } catch (const Error& e) {
    CHECK(e.code() == ErrorCode::ChecksumMismatch);
    CHECK_THAT(e.what(), Catch::Contains(pyr) && Catch::Contains(expected));
  }
  CHECK(iotest::read_file(pyr) == bytes);  // nothing written, no temporary left renamed over it
  const auto r = iotest::run_tool(dir, {"terrain-edit", {pyr, "--compact", "-q"}});
  CHECK(r.status == 10);
  CHECK_THAT(r.err, Catch::Contains(expected));
  CHECK(iotest::read_file(pyr) == bytes);
}

// scripts/hostile: --compact exited 0 on a pyramid with a flipped or zeroed payload byte; the copy
// got fresh level blob CRCs, so only the stream's tile-row CRC still told (terrain-info --verify).
TEST_CASE("edit: compaction refuses damaged streams instead of copying them under fresh CRCs",
          "[runtime][edit]") {
  iotest::TempDir dir;
  const edit::Brush brush{60, 20, 8, 10.0, edit::BrushShape::Smooth};
  write_inputs(dir, brush);
  const std::string base = dir.file("base.pyr");
  build_file(dir, base, ErrorMode::Step, 2.0);

  // An unedited file: the byte lies in the finest level's blob, whose CRC fails.
  const std::string plain = dir.file("plain.pyr");
  std::filesystem::copy_file(base, plain);
  flip_byte(plain, payload_byte(plain, 1));
  require_compaction_refused(dir, plain, "level " + std::to_string(kLevels - 1) + " blob checksum mismatch");

  // An edited file whose finest band 1 kept its stream in the first generation's blob: no blob CRC
  // covers it any more (the level's band map has its own), only the stream's CRCs do.
  const std::string edited = dir.file("edited.pyr");
  std::filesystem::copy_file(base, edited);
  const uint64_t at = payload_byte(edited, 1);
  {
    auto e = edit::PyramidEditor::open(edited);
    e->apply(brush);
    REQUIRE(e->commit().changed);
  }
  REQUIRE(payload_byte(edited, 1) == at);  // band 1 was out of the edit's reach
  flip_byte(edited, at);
  PyramidFile::open(edited)->container().verify();  // the blob CRCs all hold
  require_compaction_refused(dir, edited, "band record 1 (rows 128..255");
}

TEST_CASE("terrain-edit killed at any moment leaves the old or the new version", "[runtime][edit]") {
  iotest::TempDir dir;
  const edit::Brush brush{150, 128, 30, 25.0, edit::BrushShape::Smooth};
  write_inputs(dir, brush);
  const std::string base = dir.file("base.pyr");
  build_file(dir, base, ErrorMode::Step, 2.0);
  const auto old_levels = decode_all(base);
  const std::string done = dir.file("done.pyr");
  std::filesystem::copy_file(base, done);
  REQUIRE(iotest::run_tool(dir, {"terrain-edit", {done, "--brush", "150,128,30,25", "-q"}}).status == 0);
  const auto new_levels = decode_all(done);
  int saw_old = 0, saw_new = 0;
  for (int k = 0; k < 8; ++k) {
    const std::string p = dir.file("k.pyr");
    std::filesystem::remove(p);
    std::filesystem::copy_file(base, p);
    // SIGKILL after k milliseconds (the edit takes a few): no cleanup runs.
    const std::string cmd = iotest::shell_quote(iotest::tool_path("terrain-edit")) + " " +
                            iotest::shell_quote(p) + " --brush 150,128,30,25 -q & pid=$!; sleep 0.00" +
                            std::to_string(k) + "; kill -9 $pid 2>/dev/null; wait $pid 2>/dev/null; true";
    REQUIRE(std::system(cmd.c_str()) == 0);
    const auto f = PyramidFile::open(p);
    f->verify();
    const auto now = decode_all(p);
    INFO("killed after " << k << " ms");
    CHECK((now == old_levels || now == new_levels));
    saw_old += now == old_levels;
    saw_new += now == new_levels;
  }
  CHECK(saw_old + saw_new == 8);
}

TEST_CASE("edit: a patch blended in meets the file's max error against its heights", "[runtime][edit]") {
  iotest::TempDir dir;
  write_inputs(dir, edit::Brush{0, 0, 1, 0.0, edit::BrushShape::Flat});
  const std::string pyr = dir.file("t.pyr");
  build_file(dir, pyr, ErrorMode::MaxError, 2.0);  // 1 m units: E = 2
  const auto before = decode_all(pyr);
  edit::Patch p;
  p.x = 250;  // hangs over the right edge: only its first 50 columns land
  p.y = 40;
  p.width = 80;
  p.height = 30;
  for (int64_t y = 0; y < p.height; ++y)
    for (int64_t x = 0; x < p.width; ++x) p.heights.push_back(float(500 + 3 * x + 2 * y));
  p.heights[5] = std::numeric_limits<float>::quiet_NaN();  // left alone
  auto editor = edit::PyramidEditor::open(pyr);
  editor->apply(p);
  edit::Patch half = p;
  half.blend = 0.5;
  half.x = 10;
  editor->apply(half);
  REQUIRE(editor->commit().changed);
  const auto after = decode_all(pyr);
  const auto& fine = after[kLevels - 1];
  double worst = 0;
  for (int64_t y = p.y; y < p.y + p.height; ++y)
    for (int64_t x = p.x; x < kW; ++x) {
      if (x == p.x + 5 && y == p.y) continue;
      worst =
          std::max(worst, std::abs(fine[size_t(y * kW + x)] - double(500 + 3 * (x - p.x) + 2 * (y - p.y))));
    }
  CHECK(worst <= 2.0);
  // blend 0.5: halfway between the decoded height and the patch, within E.
  const size_t i = size_t(50 * kW + 30);
  const double expect = 0.5 * before[kLevels - 1][i] + 0.5 * (500 + 3 * 20 + 2 * 10);
  CHECK(std::abs(fine[i] - expect) <= 2.5);
  CHECK_THROWS_AS(editor->apply(edit::Patch{5000, 0, 1, 1, {1.0f}, 1.0}), std::invalid_argument);
  CHECK_THROWS_AS(editor->apply(edit::Patch{0, 0, 2, 1, {1.0f}, 1.0}), std::invalid_argument);
  CHECK_THROWS_AS(editor->apply(edit::Patch{0, 0, 1, 1, {1.0f}, 1.5}), std::invalid_argument);
}

namespace {
// Every "max_m" figure of a terrain-report --json document, in order (the levels, coarsest first, and
// the overall one).
std::vector<double> report_max_m(const std::string& json) {
  std::vector<double> out;
  const std::string key = "\"max_m\":";
  for (size_t p = json.find(key); p != std::string::npos; p = json.find(key, p + key.size()))
    out.push_back(std::strtod(json.c_str() + p + key.size(), nullptr));
  return out;
}
}  // namespace

TEST_CASE("terrain-edit on a 1201^2 DEM meets the file's max error against the edited input (terrain-report)",
          "[runtime][edit]") {
  const std::string dem = testdata::require("srtm3_N46W122_rainier_adams_cascades.hgt");
  if (dem.empty()) return;  // skipped with a warning (a failure in CI)
  iotest::TempDir dir;
  const std::string pyr = dir.file("r.pyr"), edited = dir.file("edited.raw");
  REQUIRE(iotest::run_tool(dir, {"pyramid-build", {dem, "-o", pyr, "--max-error", "2", "-q"}}).status == 0);
  const std::string before = dir.file("before.pyr");
  std::filesystem::copy_file(pyr, before);
  // A 120 m smooth mound of radius 40 samples, written through with the original as the source.
  REQUIRE(iotest::run_tool(
              dir, {"terrain-edit",
                    {pyr, "--source", dem, "--source-out", edited, "--brush", "600,600,40,120,smooth", "-q"}})
              .status == 0);
  REQUIRE(iotest::run_tool(dir, {"terrain-info", {pyr, "--verify", "-q"}}).status == 0);
  const auto report = iotest::run_tool(dir, {"terrain-report", {edited, pyr, "--json", "-", "-q"}});
  REQUIRE(report.status == 0);
  const std::vector<double> max_m = report_max_m(report.out);
  REQUIRE(max_m.size() == 5);  // four levels and the overall figure
  for (size_t l = 0; l < max_m.size(); ++l) {
    INFO("figure " << l);
    CHECK(max_m[l] <= 2.0 + 1e-9);
  }
  // The edit is real: the file before it is far from the edited input near the mound.
  const auto old = iotest::run_tool(dir, {"terrain-report", {edited, before, "--json", "-", "-q"}});
  REQUIRE(old.status == 0);
  const std::vector<double> old_max = report_max_m(old.out);
  REQUIRE(old_max.size() == 5);
  CHECK(old_max[3] > 100.0);
}
