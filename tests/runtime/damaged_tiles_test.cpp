// Damaged tiles degrade instead of ending the run: the region decoder's DamagePolicy::Degrade
// reports each damaged tile row, tile or stream once (level, tile, file offset) and shows its region
// from the coarser level, and clipmap-view finishes its flight on a damaged file with exit 11.
#include <catch2/catch.hpp>
#include <cstring>
#include <filesystem>
#include <string>

#include "build/pyramid_build.h"
#include "codec/codec.h"
#include "container/pyramid_file.h"
#include "io/io_test_util.h"
#include "readers/terrain_generator.h"
#include "runtime/pyr_test_util.h"
#include "runtime/region_decoder.h"

using namespace terrain;
using namespace terrain::container;
using namespace terrain::runtime;

namespace {

// A 300 x 400 synthetic pyramid at 1 m rms, 32-sample tiles: the finest level's bands are 4 tile
// rows high, the coarsest level's one.
std::string build_small(const iotest::TempDir& dir) {
  const std::string src = dir.file("s.raw"), pyr = dir.file("s.pyr");
  write_raw(src, synthesize_terrain(SynthOptions{.seed = 5, .width = 300, .height = 400}));
  build::BuildFileOptions o;
  o.mode = ErrorMode::Rms;
  o.target_metres = 1;
  o.threads = 2;
  build::build_pyramid_file(src, {}, pyr, o);
  return pyr;
}

// A non-empty tile in tile row >= 1 of a finest-level band with several tile rows: the first one of
// its row, so that its payload starts the row's payload.
struct Target {
  int level = -1;
  size_t band = 0;
  int64_t tx = 0, ty = 0;
  uint64_t stream_offset = 0, tile_offset = 0, tile_bytes = 0, row_bytes = 0;
  int64_t tile_size = 0, band_y0 = 0;
};

Target find_target(const PyramidFile& f) {
  Target t;
  const int top = f.level_count() - 1;
  const uint64_t blob = f.info().levels[size_t(top)].blob_offset;
  for (size_t b = 0; b < f.bands(top).size(); ++b) {
    const BandView& v = f.bands(top)[b];
    if (v.empty()) continue;
    codec::Decoder d;
    REQUIRE(d.open(v.data, v.size) == codec::Status::Ok);
    const codec::HeaderInfo& h = d.header();
    if (h.tiles_y < 2) continue;
    for (const codec::TileEntry& e : d.index()) {
      if (e.size == 0 || e.first_tile / h.tiles_x < 1) continue;
      if (t.level < 0) {
        t.level = top;
        t.band = b;
        t.tx = e.first_tile % h.tiles_x;
        t.ty = e.first_tile / h.tiles_x;
        t.stream_offset = blob + uint64_t(v.data - f.container().level(uint32_t(top)).data);
        t.tile_offset = t.stream_offset + e.offset;
        t.tile_bytes = e.size;
        t.tile_size = h.tile_size;
        t.band_y0 = v.y0;
      }
      if (e.first_tile / h.tiles_x == t.ty) t.row_bytes += e.size;
    }
    if (t.level >= 0) return t;
  }
  FAIL("no finest-level band with a non-empty tile below its first tile row");
  return t;
}

std::vector<int32_t> decode_level(const RegionDecoder& d, int level) {
  const GridSize g = d.file().level_size(level);
  std::vector<int32_t> out(size_t(g.width * g.height));
  d.decode_units(level, Rect{0, 0, g.width, g.height}, out.data(), g.width);
  return out;
}

// The good file's decode less the residual of `area` (in level coordinates, inside band b): what
// the level shows there when that residual is left out, U of the coarser level.
std::vector<int32_t> without_residual(const std::shared_ptr<const PyramidFile>& good, int level, size_t b,
                                      const Rect& area) {
  std::vector<int32_t> out = decode_level(RegionDecoder(good), level);
  const BandView& v = good->bands(level)[b];
  std::vector<int32_t> r(size_t(area.width * area.height));
  codec::Scratch scratch;
  REQUIRE(codec::decode_region(v.data, v.size, codec::Rect{area.x0, area.y0 - v.y0, area.width, area.height},
                               r.data(), area.width, scratch) == codec::Status::Ok);
  const int64_t w = good->level_size(level).width;
  for (int64_t y = 0; y < area.height; ++y)
    for (int64_t x = 0; x < area.width; ++x)
      out[size_t((area.y0 + y) * w + area.x0 + x)] -= r[size_t(y * area.width + x)];
  return out;
}

}  // namespace

TEST_CASE("region decoder: a tile row failing its CRC is reported once and shown from the coarser level",
          "[runtime][damage]") {
  iotest::TempDir dir;
  const std::string pyr = build_small(dir), bad_path = dir.file("bad.pyr");
  const auto good = PyramidFile::open(pyr);
  const Target t = find_target(*good);
  std::vector<uint8_t> bytes = iotest::read_file(pyr);
  bytes[t.tile_offset + t.tile_bytes / 2] ^= 0x40;  // one payload byte: its tile row's CRC fails
  iotest::write_file(bad_path, bytes);
  const auto bad = PyramidFile::open(bad_path);  // the index and band tables are intact
  const int top = t.level;
  const GridSize g = bad->level_size(top);

  // The default policy throws, naming the file, level, band and tile row.
  try {
    decode_level(RegionDecoder(bad), top);
    FAIL("a damaged tile row decoded under DamagePolicy::Throw");
  } catch (const Error& e) {
    CHECK(e.code() == ErrorCode::ChecksumMismatch);
    CHECK_THAT(e.what(), Catch::Contains(bad_path) && Catch::Contains("level " + std::to_string(top)) &&
                             Catch::Contains("tile row " + std::to_string(t.ty)));
  }

  const Rect area{0, t.band_y0 + t.ty * t.tile_size, g.width,
                  std::min<int64_t>(t.tile_size, good->bands(top)[t.band].y0 + good->bands(top)[t.band].rows -
                                                     (t.band_y0 + t.ty * t.tile_size))};
  const std::vector<int32_t> expected = without_residual(good, top, t.band, area);
  const std::vector<int32_t> intact = decode_level(RegionDecoder(good), top);
  for (const size_t cache : {size_t(64) << 20, size_t(0)}) {
    INFO("cache " << cache);
    const RegionDecoder d(bad, cache, DamagePolicy::Degrade);
    const std::vector<int32_t> shown = decode_level(d, top);
    int64_t differ = 0;
    for (int64_t y = 0; y < g.height; ++y)
      for (int64_t x = 0; x < g.width; ++x) {
        const size_t i = size_t(y * g.width + x);
        const bool in = y >= area.y0 && y < area.y0 + area.height;
        if (shown[i] != (in ? expected[i] : intact[i])) ++differ;
      }
    CHECK(differ == 0);
    const std::vector<DamagedTile> damaged = d.damaged_tiles();
    REQUIRE(damaged.size() == 1);
    const DamagedTile& dt = damaged[0];
    CHECK(dt.level == top);
    CHECK(dt.band == t.band);
    CHECK(dt.tile_x == -1);  // a row CRC covers the whole tile row
    CHECK(dt.tile_y == t.ty);
    CHECK(dt.area == area);
    CHECK(dt.file_offset == t.tile_offset);
    CHECK(dt.bytes == t.row_bytes);
    CHECK(dt.code == ErrorCode::ChecksumMismatch);
    CHECK_THAT(dt.message, Catch::Contains(bad_path) && Catch::Contains(std::to_string(t.tile_offset)));
    // Met again (and the coarser levels, which are intact): no second report.
    (void)decode_level(d, top);
    for (int l = 0; l < top; ++l) CHECK(decode_level(d, l) == decode_level(RegionDecoder(good), l));
    CHECK(d.damaged_count() == 1);
    CHECK(d.damaged_tiles(1).empty());
  }
}

TEST_CASE(
    "region decoder: a tile that does not decode (CRCs recomputed) is one report, and a stream that "
    "does not open is one report for its band",
    "[runtime][damage]") {
  iotest::TempDir dir;
  const std::string pyr = build_small(dir);
  const auto good = PyramidFile::open(pyr);
  const Target t = find_target(*good);
  const int top = t.level;
  {
    std::vector<uint8_t> bytes = iotest::read_file(pyr);
    std::memset(bytes.data() + t.tile_offset, 0xff, t.tile_bytes);  // not a valid tile bitstream
    pyrtest::reseal_all(bytes);  // every CRC matches again: only decoding can tell
    const std::string forged = dir.file("forged.pyr");
    iotest::write_file(forged, bytes);
    const auto f = PyramidFile::open(forged);
    CHECK_NOTHROW(f->container().verify());
    const RegionDecoder d(f, size_t(64) << 20, DamagePolicy::Degrade);
    (void)decode_level(d, top);
    const std::vector<DamagedTile> damaged = d.damaged_tiles();
    REQUIRE(damaged.size() == 1);
    CHECK(damaged[0].tile_x == t.tx);
    CHECK(damaged[0].tile_y == t.ty);
    CHECK(damaged[0].code == ErrorCode::CorruptData);
    CHECK(damaged[0].file_offset == t.tile_offset);
    CHECK(damaged[0].bytes == t.tile_bytes);
    CHECK(damaged[0].area.width ==
          std::min<int64_t>(t.tile_size, good->level_size(top).width - t.tx * t.tile_size));
    // terrain-info --verify decodes every tile: exit 10 naming the level, band record and tile row.
    const auto r = iotest::run_tool(dir, {"terrain-info", {forged, "--verify"}});
    CHECK(r.status == 10);
    CHECK_THAT(r.err,
               Catch::Contains("level " + std::to_string(top) + ", band record " + std::to_string(t.band)) &&
                   Catch::Contains("tile row " + std::to_string(t.ty)));
    CHECK(iotest::run_tool(dir, {"terrain-info", {forged}}).status == 0);  // without --verify: the index only
  }
  {
    std::vector<uint8_t> bytes = iotest::read_file(pyr);
    bytes[t.stream_offset + 5] ^= 0x01;  // the stream's version field: the stream CRC fails on open
    const std::string bad = dir.file("header.pyr");
    iotest::write_file(bad, bytes);
    const RegionDecoder d(PyramidFile::open(bad), 0, DamagePolicy::Degrade);
    (void)decode_level(d, top);
    const std::vector<DamagedTile> damaged = d.damaged_tiles();
    REQUIRE(damaged.size() == 1);
    const BandView& v = good->bands(top)[t.band];
    CHECK(damaged[0].tile_y == -1);
    CHECK(damaged[0].area == Rect{0, v.y0, good->level_size(top).width, v.rows});
    CHECK(damaged[0].file_offset == t.stream_offset);
    CHECK(damaged[0].bytes == v.size);
  }
}

TEST_CASE("clipmap-view finishes a flight over a damaged pyramid with exit 11, each damaged part logged once",
          "[runtime][damage]") {
  iotest::TempDir dir;
  const std::string pyr = build_small(dir), bad = dir.file("bad.pyr"), frames = dir.file("frames");
  const auto good = PyramidFile::open(pyr);
  // A payload byte of the coarsest level's first band (one tile row: the stream CRC covers its
  // payload, so the stream does not open); the first frame's full refill decodes the whole level.
  const BandView& v = good->bands(0)[0];
  REQUIRE(!v.empty());
  const uint64_t at = good->info().levels[0].blob_offset + uint64_t(v.data - good->container().level(0).data);
  std::vector<uint8_t> bytes = iotest::read_file(pyr);
  bytes[at + v.size / 2] ^= 0x08;
  iotest::write_file(bad, bytes);
  const auto r = iotest::run_tool(dir, {"clipmap-view",
                                        {bad, "--frames", "3", "--n", "127", "--width", "160", "--height",
                                         "120", "--out", frames, "-q"}});
  INFO(r.err);
  CHECK(r.status == 11);
  size_t logged = 0;
  for (size_t p = r.err.find("clipmap-view: damaged: "); p != std::string::npos;
       p = r.err.find("clipmap-view: damaged: ", p + 1))
    ++logged;
  CHECK(logged == 1);
  CHECK_THAT(r.err, Catch::Contains("level 0, band 0") && Catch::Contains("finished with 1 damaged"));
  for (const char* f : {"/frame_00000.png", "/frame_00002.png", "/stats.csv", "/stats.json"})
    CHECK(std::filesystem::exists(frames + f));
  // stats.json locates the damaged bytes: the flipped one lies inside the reported range.
  const std::vector<uint8_t> json_bytes = iotest::read_file(frames + "/stats.json");
  const std::string json(json_bytes.begin(), json_bytes.end());
  const size_t off = json.find("\"file_offset\": "), len = json.find("\"bytes\": ");
  REQUIRE(off != std::string::npos);
  REQUIRE(len != std::string::npos);
  const uint64_t first = std::stoull(json.substr(off + 15)), size = std::stoull(json.substr(len + 9));
  CHECK(first <= at + v.size / 2);
  CHECK(at + v.size / 2 < first + size);
  CHECK_THAT(r.err, Catch::Contains("file offset " + std::to_string(first)));
  // The intact file: exit 0, nothing logged; the exit status is documented in --help.
  const auto ok = iotest::run_tool(dir, {"clipmap-view",
                                         {pyr, "--frames", "1", "--n", "127", "--width", "160", "--height",
                                          "120", "--out", frames, "-q"}});
  CHECK(ok.status == 0);
  CHECK(ok.err.find("damaged") == std::string::npos);
  const auto help = iotest::run_tool(dir, {"clipmap-view", {"--help"}});
  CHECK_THAT(help.out, Catch::Contains("11  finished with damaged tiles"));
}
