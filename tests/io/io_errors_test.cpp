// Malformed input is rejected with the documented exit status and a message naming the file:
// checked by running the terrain-info executable on files written here, plus library-level checks.
#include <zlib.h>

#include <catch2/catch.hpp>
#include <cmath>
#include <cstring>
#include <limits>

#include "cli.h"
#include "io_test_util.h"
#include "readers/heightmap.h"

namespace {

std::vector<uint8_t> float_le(const std::vector<float>& values) {
  std::vector<uint8_t> out;
  for (float f : values) {
    uint32_t u;
    std::memcpy(&u, &f, 4);
    for (int i = 0; i < 4; ++i) out.push_back(uint8_t(u >> (8 * i)));
  }
  return out;
}

terrain::ErrorCode library_error(const std::string& path, const terrain::ReadOptions& o = {}) {
  try {
    terrain::read_heightmap(path, o);
  } catch (const terrain::Error& e) {
    CHECK(std::string(e.what()).find(path) != std::string::npos);
    return e.code();
  }
  FAIL("no Error for " << path);
  return terrain::ErrorCode::NotFound;
}

const char* kSidecar10x10 = R"({"width": 10, "height": 10, "type": "int16", "byte_order": "little"})";

struct ErrorCase {
  std::string what, file;
  std::vector<std::string> extra_args;
  int status;
  std::string mention;  // text the message must contain besides the file name
};

}  // namespace

TEST_CASE("terrain-info exits with the documented status on malformed input", "[io][errors]") {
  iotest::TempDir dir;
  REQUIRE(std::filesystem::exists(iotest::tool_path("terrain-info")));
  std::vector<ErrorCase> cases;

  cases.push_back({"missing file", dir.file("N00E000_missing.hgt"), {}, 2, "no such file"});

  std::string truncated = dir.file("N10E010.hgt");
  iotest::write_file(truncated, std::vector<uint8_t>(2 * 1201 * 1201 - 2000, 0));
  cases.push_back({"truncated .hgt", truncated, {}, 3, "truncated"});

  std::string oversized = dir.file("N10E011.hgt");
  iotest::write_file(oversized, std::vector<uint8_t>(2 * 1201 * 1201 + 2, 0));
  cases.push_back({"oversized .hgt", oversized, {}, 4, "oversized"});

  std::string short_raw = dir.file("short.raw");
  iotest::write_file(short_raw, std::vector<uint8_t>(150, 0));
  iotest::write_file(short_raw + ".json", std::string(kSidecar10x10));
  cases.push_back({"sidecar dimensions don't match the size", short_raw, {}, 5, "200 bytes"});

  std::string complex_raw = dir.file("complex.raw");
  iotest::write_file(complex_raw, std::vector<uint8_t>(200, 0));
  iotest::write_file(complex_raw + ".json",
                     std::string(R"({"width": 10, "height": 10, "type": "complex64"})"));
  cases.push_back({"unknown sample type in sidecar", complex_raw, {}, 6, "complex64"});

  std::vector<float> v(12 * 5, 1.0f);
  v[2 * 12 + 3] = std::numeric_limits<float>::quiet_NaN();
  std::string nan_raw = dir.file("nan.raw");
  iotest::write_file(nan_raw, float_le(v));
  iotest::write_file(nan_raw + ".json", std::string(R"({"width": 12, "height": 5, "type": "float32"})"));
  cases.push_back({"NaN in float raw", nan_raw, {}, 7, "NaN at row 2, column 3"});

  std::string no_height = dir.file("noheight.raw");
  iotest::write_file(no_height, std::vector<uint8_t>(200, 0));
  iotest::write_file(no_height + ".json", std::string(R"({"width": 10, "type": "int16"})"));
  cases.push_back({"sidecar missing height", no_height, {}, 8, "\"height\""});

  std::string corrupt_gz = dir.file("N10E012.hgt.gz");
  {
    std::vector<uint8_t> tile(2 * 1201 * 1201);
    for (size_t i = 0; i < tile.size(); ++i) tile[i] = uint8_t((i * 131) >> 7);
    gzFile gz = gzopen(corrupt_gz.c_str(), "wb1");
    REQUIRE(gz != nullptr);
    REQUIRE(gzwrite(gz, tile.data(), unsigned(tile.size())) == int(tile.size()));
    REQUIRE(gzclose(gz) == Z_OK);
    auto bytes = iotest::read_file(corrupt_gz);
    bytes[bytes.size() - 6] ^= 0x5a;  // inside the CRC32 of the trailer
    iotest::write_file(corrupt_gz, bytes);
  }
  cases.push_back({"corrupt .hgt.gz", corrupt_gz, {}, 10, "corrupt"});

  std::vector<iotest::Invocation> calls;
  for (const auto& c : cases) {
    iotest::Invocation call{"terrain-info", {c.file}};
    call.args.insert(call.args.end(), c.extra_args.begin(), c.extra_args.end());
    calls.push_back(call);
  }
  auto results = iotest::run_tools(dir, calls);
  for (size_t i = 0; i < cases.size(); ++i) {
    const auto& c = cases[i];
    const auto& r = results[i];
    INFO(c.what << ": terrain-info " << c.file << "\nstderr: " << r.err);
    CHECK(r.status == c.status);
    CHECK(r.err.find(c.file) != std::string::npos);  // the message names the file
    CHECK(r.err.find(c.mention) != std::string::npos);
    CHECK(r.out.empty());
  }
}

TEST_CASE("terrain-info usage, help and success paths", "[io][errors]") {
  iotest::TempDir dir;
  // A NaN nodata value (by bit pattern) is a void, not an error.
  std::vector<float> v(3 * 2, 2.5f);
  v[4] = std::numeric_limits<float>::quiet_NaN();
  std::string f = dir.file("nan_nodata.raw");
  iotest::write_file(f, float_le(v));
  iotest::write_file(f + ".json",
                     std::string(R"({"width": 3, "height": 2, "type": "float32", "nodata": "NaN"})"));
  auto r = iotest::run_tools(dir, {{"terrain-info", {"--no-such-option"}},
                                   {"terrain-info", {}},
                                   {"terrain-info", {"--help"}},
                                   {"terrain-info", {f, "--json", "-q"}}});
  CHECK(r[0].status == 1);
  CHECK(r[0].err.find("--no-such-option") != std::string::npos);
  CHECK(r[1].status == 1);
  CHECK(r[2].status == 0);
  CHECK(r[2].out.find("Exit status") != std::string::npos);
  CHECK(r[2].out.find(" 7  NaN/Inf") != std::string::npos);
  INFO(r[3].err);
  CHECK(r[3].status == 0);
  CHECK(r[3].out.find("\"nodata_count\": 1") != std::string::npos);
  CHECK(r[3].out.find("\"min_m\": 2.5") != std::string::npos);
  CHECK(r[3].out.find("\"width\": 3") != std::string::npos);
}

TEST_CASE("one mapping from error codes to the tools' documented exit statuses", "[io][errors]") {
  using terrain::ErrorCode;
  const std::pair<ErrorCode, int> expected[] = {
      {ErrorCode::InvalidOption, 1},     {ErrorCode::NotFound, 2},
      {ErrorCode::Truncated, 3},         {ErrorCode::Oversized, 4},
      {ErrorCode::DimensionMismatch, 5}, {ErrorCode::UnknownType, 6},
      {ErrorCode::NonFinite, 7},         {ErrorCode::MissingField, 8},
      {ErrorCode::WriteFailed, 9},       {ErrorCode::ChecksumMismatch, 10},
      {ErrorCode::CorruptData, 10},      {ErrorCode::UnsupportedVersion, 10}};
  for (const auto& [code, status] : expected) CHECK(cli::exit_status(code) == status);
  // Every code is documented in --help and has a name.
  const std::string help = cli::exit_codes_help();
  for (int c = 0; c <= int(ErrorCode::InvalidOption); ++c) {
    const int status = cli::exit_status(ErrorCode(c));
    CHECK(help.find((status < 10 ? "  " : " ") + std::to_string(status) + "  ") != std::string::npos);
    CHECK(std::string(terrain::error_code_name(ErrorCode(c))) != "unknown error");
  }
}

TEST_CASE("library error codes match the classes", "[io][errors]") {
  iotest::TempDir dir;
  using terrain::ErrorCode;
  CHECK(library_error(dir.file("absent.raw")) == ErrorCode::NotFound);

  std::string f = dir.file("grid.raw");
  iotest::write_file(f, std::vector<uint8_t>(200, 0));
  iotest::write_file(f + ".json", std::string(kSidecar10x10));
  CHECK_NOTHROW(terrain::read_heightmap(f));
  terrain::ReadOptions wrong;
  wrong.width = 11;  // options override the sidecar, and 11x10 int16 needs 220 bytes
  CHECK(library_error(f, wrong) == ErrorCode::DimensionMismatch);
  iotest::write_file(f + ".json",
                     std::string(R"({"width": 10, "height": 10, "type": "int16", "byte_order": "middle"})"));
  CHECK(library_error(f) == ErrorCode::UnknownType);
  iotest::write_file(f + ".json", std::string(R"({"width": -10, "height": 10, "type": "int16"})"));
  CHECK(library_error(f) == ErrorCode::MissingField);
  iotest::write_file(f + ".json", std::string(R"({"width": "10", "height": 10, "type": "int16"})"));
  CHECK(library_error(f) == ErrorCode::MissingField);
  iotest::write_file(f + ".json", std::string(R"({"width": 10, "height": 10, "type": "int16",})"));
  CHECK(library_error(f) == ErrorCode::MissingField);

  std::string bare = dir.file("bare.raw");  // no sidecar, no options: dimensions cannot be derived
  iotest::write_file(bare, std::vector<uint8_t>(150, 0));
  CHECK(library_error(bare) == ErrorCode::DimensionMismatch);
  terrain::ReadOptions square;
  square.sample_type = terrain::SampleType::Int16;
  iotest::write_file(bare, std::vector<uint8_t>(2 * 9 * 9, 0));
  CHECK(terrain::probe(bare, square).width == 9);  // a square grid is derived from the size

  std::string mystery = dir.file("mystery.xyz");
  iotest::write_file(mystery, std::string("not a heightmap"));
  CHECK(library_error(mystery) == ErrorCode::UnknownType);

  std::vector<float> v(4 * 4, 1.0f);
  v[15] = -std::numeric_limits<float>::infinity();
  std::string inf = dir.file("inf.bin");
  iotest::write_file(inf, float_le(v));
  terrain::ReadOptions as_float;
  as_float.sample_type = terrain::SampleType::Float32;
  as_float.width = 4;
  CHECK(library_error(inf, as_float) == ErrorCode::NonFinite);

  std::string no_hdr = dir.file("nohdr.bil");
  iotest::write_file(no_hdr, std::vector<uint8_t>(200, 0));
  CHECK(library_error(no_hdr) == ErrorCode::MissingField);
  iotest::write_file(dir.file("nohdr.hdr"),
                     std::string("NROWS 10\nNCOLS 10\nNBITS 16\nPIXELTYPE SIGNEDINT\nBYTEORDER X\n"));
  CHECK(library_error(no_hdr) == ErrorCode::UnknownType);
  iotest::write_file(dir.file("nohdr.hdr"), std::string("NROWS 10\nNBITS 16\n"));
  CHECK(library_error(no_hdr) == ErrorCode::MissingField);
  iotest::write_file(dir.file("nohdr.hdr"), std::string("NROWS 10\nNCOLS 11\nNBITS 16\n"));
  CHECK(library_error(no_hdr) == ErrorCode::DimensionMismatch);

  std::string rgb_tif = dir.file("rgb.tif");  // an image that is neither grey nor Terrain-RGB
  terrain::Heightmap m;
  m.info.width = m.info.height = 4;
  m.values.assign(16, 7.0);
  terrain::write_image16(rgb_tif, m);
  terrain::ReadOptions rgb;
  rgb.terrain_rgb = true;
  CHECK(library_error(rgb_tif, rgb) == ErrorCode::UnknownType);
}

TEST_CASE("sidecar parser survives every truncation and corruption of a sidecar", "[io][errors]") {
  iotest::TempDir dir;
  std::string f = dir.file("fuzz.raw");
  iotest::write_file(f, std::vector<uint8_t>(200, 0));
  const std::string good =
      R"({"width": 10, "height": 10, "type": "int16", "byte_order": "big", "nodata": -32768, "note": {"a": [1, 2.5e3, "x\u00e9\""]}})";
  iotest::write_file(f + ".json", good);
  CHECK(terrain::probe(f).width == 10);
  int errors = 0;
  auto attempt = [&](const std::string& text) {
    iotest::write_file(f + ".json", text);
    try {
      terrain::probe(f);
    } catch (const terrain::Error& e) {
      ++errors;
      CHECK(std::string(e.what()).find("fuzz.raw") != std::string::npos);
    }
  };
  for (size_t n = 0; n < good.size(); ++n) attempt(good.substr(0, n));
  for (size_t i = 0; i < good.size(); ++i)
    for (char c : {i % 2 ? '\0' : '"', i % 3 ? '{' : ']', i % 2 ? '\\' : '9'}) {
      std::string bad = good;
      bad[i] = c;
      attempt(bad);
    }
  attempt(std::string(100000, '['));
  attempt("{\"width\": 1e999, \"height\": 10, \"type\": \"int16\"}");
  CHECK(errors >= int(good.size()));  // every proper prefix is malformed
}
