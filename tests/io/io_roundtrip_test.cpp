// Every writer/reader pair returns exactly the samples it was given (bit-exact for float32),
// and hand-written ESRI .bil/.flt files decode as their headers say.
#include <catch2/catch.hpp>
#include <cmath>
#include <cstring>
#include <limits>

#include "io_test_util.h"
#include "readers/heightmap.h"

namespace {

using terrain::Heightmap;
using terrain::SampleType;

uint32_t float_bits(double v) {
  float f = float(v);
  uint32_t b;
  std::memcpy(&b, &f, 4);
  return b;
}

// A small grid exercising the type's extremes, a ramp, and (when the type has room) a void.
Heightmap test_grid(SampleType type, int64_t w = 37, int64_t h = 23) {
  Heightmap m;
  m.info.width = w;
  m.info.height = h;
  m.info.sample_type = type;
  m.info.spacing_x = 2.5;
  m.info.spacing_y = 3.25;
  m.info.vertical_scale = 0.25;
  m.info.vertical_offset = -12.5;
  m.info.origin_x = 123.456;
  m.info.origin_y = -45.75;
  m.values.resize(size_t(w * h));
  double lo = 0, hi = 0;
  switch (type) {
    case SampleType::Int16:
      lo = -32767, hi = 32767;
      break;  // -32768 is the nodata value below
    case SampleType::UInt16:
      lo = 0, hi = 65534;
      break;
    case SampleType::Int32:
      lo = -2147483647.0, hi = 2147483647.0;
      break;
    default:
      lo = double(float(-1e30)), hi = double(float(3.4e38));
      break;
  }
  for (int64_t i = 0; i < w * h; ++i) {
    double v;
    if (type == SampleType::Float32)
      v = double(float(std::sin(double(i) * 0.37) * 4321.123 + double(i) * 1e-3));
    else
      v = std::floor(lo + (hi - lo) * double((i * 7919) % (w * h)) / double(w * h - 1));
    m.values[size_t(i)] = v;
  }
  m.values[0] = lo;
  m.values[1] = hi;
  if (type == SampleType::Float32) {
    m.values[2] = double(std::numeric_limits<float>::denorm_min());
    m.values[3] = double(-std::numeric_limits<float>::max());
  }
  // One void, written as the nodata value.
  m.info.nodata = type == SampleType::Int16 ? -32768.0 : type == SampleType::UInt16 ? 65535.0 : -99999.0;
  m.valid.assign(size_t(w * h), 1);
  m.valid[size_t(w + 5)] = 0;
  m.values[size_t(w + 5)] = 0;
  return m;
}

void require_same_samples(const Heightmap& a, const Heightmap& b) {
  REQUIRE(a.width() == b.width());
  REQUIRE(a.height() == b.height());
  // One assertion for the whole grid (per-sample assertions are slow under sanitizers); the first
  // mismatch is reported.
  std::string first_mismatch;
  for (int64_t y = 0; y < a.height() && first_mismatch.empty(); ++y)
    for (int64_t x = 0; x < a.width(); ++x) {
      bool same = a.is_valid(x, y) == b.is_valid(x, y);
      if (same && a.is_valid(x, y))
        same = a.info.sample_type == SampleType::Float32 ? float_bits(a.at(x, y)) == float_bits(b.at(x, y))
                                                         : a.at(x, y) == b.at(x, y);
      if (!same) {
        first_mismatch = "row " + std::to_string(y) + " column " + std::to_string(x) + ": " +
                         std::to_string(a.at(x, y)) + " vs " + std::to_string(b.at(x, y));
        break;
      }
    }
  INFO(first_mismatch);
  REQUIRE(first_mismatch.empty());
}

}  // namespace

TEST_CASE("raw + JSON sidecar round-trips all four types in both byte orders", "[io][raw]") {
  iotest::TempDir dir;
  for (SampleType type : {SampleType::Int16, SampleType::UInt16, SampleType::Int32, SampleType::Float32}) {
    for (bool big : {false, true}) {
      INFO(terrain::sample_type_name(type) << (big ? " big" : " little") << " endian");
      Heightmap m = test_grid(type);
      std::string path =
          dir.file(std::string("grid_") + terrain::sample_type_name(type) + (big ? "_be" : "_le") + ".raw");
      terrain::write_raw(path, m, big);
      Heightmap r = terrain::read_heightmap(path);
      CHECK(r.info.format == terrain::FileFormat::Raw);
      CHECK(r.info.sample_type == type);
      CHECK(r.info.spacing_x == 2.5);
      CHECK(r.info.spacing_y == 3.25);
      CHECK(r.info.vertical_scale == 0.25);
      CHECK(r.info.vertical_offset == -12.5);
      CHECK(*r.info.origin_x == 123.456);
      CHECK(*r.info.origin_y == -45.75);
      CHECK(*r.info.nodata == *m.info.nodata);
      require_same_samples(m, r);
      // The byte order really is the requested one: check the first sample's bytes.
      auto bytes = iotest::read_file(path);
      int n = type == SampleType::Int16 || type == SampleType::UInt16 ? 2 : 4;
      REQUIRE(bytes.size() == size_t(m.width() * m.height() * n));
      uint32_t expect =
          n == 2 ? uint32_t(uint16_t(int32_t(m.values[0])))
                 : (type == SampleType::Float32 ? float_bits(m.values[0]) : uint32_t(int32_t(m.values[0])));
      uint32_t got = 0;
      for (int i = 0; i < n; ++i) got |= uint32_t(bytes[size_t(i)]) << (big ? 8 * (n - 1 - i) : 8 * i);
      CHECK(got == expect);
    }
  }
}

TEST_CASE("16-bit PNG and TIFF round-trip exactly", "[io][image]") {
  iotest::TempDir dir;
  // m written as a 16-bit image at dir/name (format by extension) comes back with its sample type
  // and samples; the read is returned for further checks.
  const auto round_trip = [&](const Heightmap& m, const std::string& name) {
    const std::string path = dir.file(name);
    terrain::write_image16(path, m);
    Heightmap r = terrain::read_heightmap(path);
    CHECK(r.info.sample_type == m.info.sample_type);
    require_same_samples(m, r);
    return r;
  };
  SECTION("PNG uint16") {
    Heightmap m = test_grid(SampleType::UInt16);
    m.valid.clear();  // images carry no nodata value
    m.values[size_t(m.width() + 5)] = 65535;
    CHECK(round_trip(m, "grid.png").info.format == terrain::FileFormat::Image);
  }
  SECTION("TIFF int16 with negative values") {
    Heightmap m = test_grid(SampleType::Int16);
    m.valid.clear();
    m.values[size_t(m.width() + 5)] = -32768;
    round_trip(m, "grid.tif");
  }
  SECTION("TIFF uint16") {
    Heightmap m = test_grid(SampleType::UInt16);
    m.valid.clear();
    round_trip(m, "grid.tiff");
  }
  SECTION("PNG refuses values a 16-bit PNG cannot hold, leaving no file behind") {
    Heightmap m = test_grid(SampleType::Int16);
    m.valid.clear();
    std::string path = dir.file("neg.png");
    REQUIRE_THROWS_AS(terrain::write_image16(path, m), terrain::Error);
    CHECK_FALSE(std::filesystem::exists(path));
    CHECK(std::filesystem::is_empty(std::filesystem::path(path).parent_path()));
  }
}

TEST_CASE("float32 EXR round-trips bit-exactly", "[io][image]") {
  iotest::TempDir dir;
  Heightmap m = test_grid(SampleType::Float32);
  m.valid.clear();
  m.values[size_t(m.width() + 5)] = 0.125;
  std::string path = dir.file("grid.exr");
  terrain::write_exr(path, m);
  Heightmap r = terrain::read_heightmap(path);
  CHECK(r.info.sample_type == SampleType::Float32);
  require_same_samples(m, r);
}

namespace {

// Writes the samples of `m` as an ESRI grid with the given header lines.
void write_esri(const std::string& data_path, const std::string& hdr_path, const Heightmap& m, int bytes,
                bool big, bool is_float, const std::string& header) {
  std::vector<uint8_t> out;
  for (double v : m.values) {
    uint32_t u = is_float ? float_bits(v) : uint32_t(int32_t(v));
    for (int i = 0; i < bytes; ++i) out.push_back(uint8_t(u >> (big ? 8 * (bytes - 1 - i) : 8 * i)));
  }
  iotest::write_file(data_path, out);
  iotest::write_file(hdr_path, header);
}

}  // namespace

TEST_CASE("ESRI .bil and .flt written by hand decode as their headers say", "[io][esri]") {
  iotest::TempDir dir;
  SECTION("16-bit signed BIL, Motorola byte order, UL map georeference") {
    Heightmap m = test_grid(SampleType::Int16, 19, 11);
    m.values[size_t(m.width() + 5)] = -32768;
    write_esri(dir.file("dem.bil"), dir.file("dem.hdr"), m, 2, true, false,
               "BYTEORDER M\nLAYOUT BIL\nNROWS 11\nNCOLS 19\nNBANDS 1\nNBITS 16\nPIXELTYPE SIGNEDINT\n"
               "ULXMAP 500000.5\nULYMAP 4200000\nXDIM 30\nYDIM 25\nNODATA -32768\n");
    Heightmap r = terrain::read_heightmap(dir.file("dem.bil"));
    CHECK(r.info.format == terrain::FileFormat::EsriBil);
    CHECK(r.info.sample_type == SampleType::Int16);
    CHECK(r.info.spacing_x == 30);
    CHECK(r.info.spacing_y == 25);
    CHECK(*r.info.origin_x == 500000.5);
    CHECK(*r.info.origin_y == 4200000);
    require_same_samples(m, r);
  }
  SECTION("float FLT, LSBFIRST, lower-left corner georeference") {
    Heightmap m = test_grid(SampleType::Float32, 13, 9);
    m.values[size_t(m.width() + 5)] = -9999;
    m.info.nodata = -9999;
    write_esri(dir.file("dem.flt"), dir.file("dem.hdr"), m, 4, false, true,
               "ncols 13\nnrows 9\nxllcorner 100\nyllcorner 200\ncellsize 10\nNODATA_value -9999\nbyteorder "
               "LSBFIRST\n");
    Heightmap r = terrain::read_heightmap(dir.file("dem.flt"));
    CHECK(r.info.format == terrain::FileFormat::EsriFlt);
    CHECK(r.info.sample_type == SampleType::Float32);
    CHECK(*r.info.origin_x == 105);             // centre of the first column
    CHECK(*r.info.origin_y == 200 + 8.5 * 10);  // centre of the top row
    require_same_samples(m, r);
  }
  SECTION("32-bit unsigned BIL is rejected as an unknown type") {
    Heightmap m = test_grid(SampleType::Int32, 4, 4);
    m.valid.clear();
    write_esri(dir.file("u32.bil"), dir.file("u32.hdr"), m, 4, false, false,
               "NROWS 4\nNCOLS 4\nNBITS 32\nPIXELTYPE UNSIGNEDINT\n");
    try {
      terrain::read_heightmap(dir.file("u32.bil"));
      FAIL("no error");
    } catch (const terrain::Error& e) {
      CHECK(e.code() == terrain::ErrorCode::UnknownType);
    }
  }
}
