// terrain-info --verify checks the structure of a .pyr 2.0, not only its checksums: band tables
// forged to be consistent in themselves and resealed (every CRC recomputed) are exit 10 naming the
// level, the band record and the field, while the plain description (the index alone) accepts them.
#include <algorithm>
#include <catch2/catch.hpp>
#include <functional>
#include <string>
#include <utility>

#include "container/pyramid_file.h"
#include "core/bytes.h"
#include "io/io_test_util.h"
#include "runtime/pyr_test_util.h"

using namespace terrain;
using namespace terrain::container;

namespace {

using Records = std::vector<std::pair<uint64_t, uint64_t>>;  // (rows, code) per band record

// Rewrites the band table of `level` through `edit`; the new table must have the old one's length
// (so nothing else moves). Then reseals every checksum but the streams' (they are unchanged).
void forge_table(std::vector<uint8_t>& b, int level, const std::function<void(Records&)>& edit) {
  const std::vector<pyrtest::LevelAt> levels = pyrtest::locate_levels(b);
  REQUIRE(size_t(level) < levels.size());
  const pyrtest::LevelAt& lv = levels[size_t(level)];
  REQUIRE(lv.has_table);
  Records records;
  const uint8_t *p = b.data() + lv.table, *end = p + lv.table_size;
  while (p < end) {
    uint64_t rows, code;
    REQUIRE(pyrtest::read_varint(p, end, &rows));
    REQUIRE(pyrtest::read_varint(p, end, &code));
    records.push_back({rows, code});
  }
  edit(records);
  std::vector<uint8_t> table;
  for (const auto& [rows, code] : records) {
    bytes::put_varint(table, rows);
    bytes::put_varint(table, code);
  }
  REQUIRE(table.size() == lv.table_size);
  std::copy(table.begin(), table.end(), b.begin() + std::ptrdiff_t(lv.table));
  pyrtest::reseal_all(b, false);
}

}  // namespace

TEST_CASE("terrain-info --verify: forged but resealed band tables and footers fail naming the field",
          "[runtime][verify]") {
  iotest::TempDir dir;
  const std::string src = dir.file("s.raw"), pyr = dir.file("s.pyr"), forged = dir.file("forged.pyr");
  REQUIRE(iotest::run_tool(dir, {"terrain-synth", {"-o", src, "--width", "260", "--height", "400", "-q"}})
              .status == 0);
  REQUIRE(iotest::run_tool(dir, {"pyramid-build", {src, "-o", pyr, "--rms", "1", "-q"}}).status == 0);
  const std::vector<uint8_t> good = iotest::read_file(pyr);
  const auto file = PyramidFile::open(pyr);
  const int top = file->level_count() - 1;
  REQUIRE(file->bands(top).size() >= 3);  // 128-row bands: 128, 128, 128, 16
  REQUIRE(!file->bands(top)[0].empty());
  REQUIRE(!file->bands(top)[1].empty());
  {
    std::vector<uint8_t> b = good;  // resealed without an edit: still verifies
    pyrtest::reseal_all(b);
    CHECK(b == good);
  }
  CHECK(iotest::run_tool(dir, {"terrain-info", {pyr, "--verify"}}).status == 0);

  const std::string level = "level " + std::to_string(top);
  const auto check = [&](const std::vector<uint8_t>& b, const std::string& what, bool opens,
                         const std::vector<std::string>& names) {
    INFO(what);
    iotest::write_file(forged, b);
    CHECK(iotest::run_tool(dir, {"terrain-info", {forged}}).status == 0);  // the index is consistent
    if (opens) CHECK_NOTHROW(PyramidFile::open(forged));
    const auto r = iotest::run_tool(dir, {"terrain-info", {forged, "--verify"}});
    CHECK(r.status == 10);
    CHECK_THAT(r.err, Catch::Contains(forged) && Catch::Contains(level));
    for (const std::string& name : names) CHECK_THAT(r.err, Catch::Contains(name));
  };
  {  // the first and the last band's rows swapped: the rows still add up to the level's height
    std::vector<uint8_t> b = good;
    forge_table(b, top, [](Records& r) { std::swap(r.front().first, r.back().first); });
    const int64_t rows0 = file->bands(top).back().rows;
    check(b, "rows swapped", true,
          {"band record 0", "band table rows " + std::to_string(rows0) + ", but the stream codes 128 rows"});
  }
  {  // one byte moved from the second stream to the first: the streams still fill the blob
    std::vector<uint8_t> b = good;
    forge_table(b, top, [](Records& r) {
      r[0].second += 2;  // code = size << 1
      r[1].second -= 2;
    });
    check(b, "stream sizes shifted", true, {"band record 0", "the stream does not open"});
  }
  {  // a record past the level's rows: rejected by the band table checks (PyramidFile::open)
    std::vector<uint8_t> b = good;
    forge_table(b, top, [](Records& r) { r.back().first += 1; });
    check(b, "rows past the level", false, {"rows do not tile the level"});
  }
  {  // the footer's magic: only --verify parses the band tables
    std::vector<uint8_t> b = good;
    const pyrtest::LevelAt lv = pyrtest::locate_levels(b)[size_t(top)];
    b[lv.blob + lv.blob_size - 8] = 'X';
    pyrtest::reseal_all(b, false);
    check(b, "footer magic", false, {"band table magic missing"});
  }
  {  // a tile row's payload damaged without resealing the streams: its row CRC fails
    std::vector<uint8_t> b = good;
    const pyrtest::LevelAt lv = pyrtest::locate_levels(b)[size_t(top)];
    const pyrtest::StreamAt& s = lv.streams[1];
    b[s.index_begin - 1] ^= 0x01;   // the stream's last payload byte
    pyrtest::reseal_all(b, false);  // the blob CRC matches again: only the stream's own CRCs can tell
    check(b, "payload byte", true, {"band record 1", "checksum mismatch"});
  }
}
