// Pyramid container: writer/reader round trips, atomic writing, and rejection of damaged files.
#include "container/container.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <numeric>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "runtime/pyr_test_util.h"

namespace fs = std::filesystem;
using namespace terrain::container;
using namespace pyrtest;
using terrain::Error;
using terrain::ErrorCode;

namespace {

// A fresh directory per test, removed afterwards.
class TempDir {
 public:
  TempDir() {
    static std::atomic<int> counter{0};
    path_ = fs::temp_directory_path() /
            ("terrain_container_test_" + std::to_string(::getpid()) + "_" + std::to_string(counter++));
    fs::remove_all(path_);
    fs::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  std::string file(const std::string& name) const { return (path_ / name).string(); }
  size_t entry_count() const {
    return size_t(std::distance(fs::directory_iterator(path_), fs::directory_iterator()));
  }

 private:
  fs::path path_;
};

std::vector<uint8_t> read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::vector<uint8_t>(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

void write_bytes(const std::string& path, const uint8_t* data, size_t size) {
  // Unlink first: rewriting through truncation makes ext4 flush on close (its protection for
  // truncate-and-rewrite), which would make the thousands of damaged copies below very slow.
  fs::remove(path);
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(data), std::streamsize(size));
}
void write_bytes(const std::string& path, const std::vector<uint8_t>& bytes) {
  write_bytes(path, bytes.data(), bytes.size());
}

struct Sample {
  ContainerInfo info;
  std::vector<std::vector<uint8_t>> blobs;
  std::vector<uint8_t> mask;  // empty: none given to the writer
  std::string json;
};

// A random but consistent pyramid description with random blobs, mask and metadata.
Sample random_sample(std::mt19937_64& rng, uint64_t width, uint64_t height, size_t level_count) {
  Sample s;
  ContainerInfo& info = s.info;
  info.width = width;
  info.height = height;
  info.levels.resize(level_count);
  uint64_t w = width, h = height;
  for (size_t l = level_count; l-- > 0;) {
    info.levels[l].width = w;
    info.levels[l].height = h;
    info.levels[l].stats = {double(rng() % 100) - 50, double(rng() % 1000) / 7, double(rng() % 100) / 3,
                            -double(rng() % 500), double(rng() % 500)};
    if (rng() % 3) info.levels[l].error = LevelError{double(rng() % 1000) / 9, double(rng() % 100)};
    w = (w + 1) / 2;
    h = (h + 1) / 2;
  }
  std::uniform_real_distribution<double> unit(-1, 1);
  info.spacing_x = 1.0 / 3600 + unit(rng) * 1e-5;
  info.spacing_y = 30 + unit(rng);
  info.horizontal_units = (rng() % 2) ? "arc-second" : "m";
  info.vertical_units = "m";
  info.vertical_scale = 0.1 + std::abs(unit(rng));
  info.vertical_offset = unit(rng) * 1000;
  if (rng() % 2) {
    Georeference g;
    g.geotransform = {unit(rng) * 180, 0.001 + std::abs(unit(rng)), 0, unit(rng) * 90, 0, -0.002};
    g.units = "degree";
    g.crs_epsg = (rng() % 2) ? 4326 : 0;
    if (rng() % 2) g.crs_text = std::string(size_t(rng() % 300), 'w');  // any length, not 8-aligned
    info.georeference = std::move(g);
  }
  info.filter_size = (rng() % 4 == 0) ? 0 : 11;
  info.filter.resize(size_t(info.filter_size) * info.filter_size);
  for (double& c : info.filter) c = unit(rng);
  info.filter_provenance = FilterProvenance(rng() % 3);
  info.quantisation = {double(1 + rng() % 8), 0.25 * double(1 + rng() % 8), ErrorMode(rng() % 4),
                       unit(rng) + 2};

  for (size_t l = 0; l < level_count; ++l) {
    // Some empty blobs; otherwise sizes not multiple of 8 to exercise padding.
    const size_t size = (rng() % 5 == 0) ? 0 : size_t(rng() % 700);
    std::vector<uint8_t> blob(size);
    for (auto& b : blob) b = uint8_t(rng());
    s.blobs.push_back(std::move(blob));
  }
  const uint64_t samples = width * height;
  switch (rng() % 4) {
    case 0:
      break;  // no mask given
    case 1:
      s.mask.assign(size_t(samples), 1);
      break;  // mask given, all valid
    case 2:
      s.mask.assign(size_t(samples), 0);
      break;  // all void
    default:
      s.mask.resize(size_t(samples));
      for (size_t i = 0; i < s.mask.size(); ++i) s.mask[i] = (rng() % 7 == 0) ? 0 : uint8_t(1 + rng() % 255);
  }
  const size_t json_size = size_t(rng() % 300);
  for (size_t i = 0; i < json_size; ++i) s.json.push_back(char(32 + rng() % 95));
  return s;
}

// Writes a sample with levels in random order, some streamed in pieces, the mask in pieces.
void write_sample(const std::string& path, const Sample& s, std::mt19937_64& rng, bool checksums = true) {
  ContainerWriter w(path);
  w.set_level_checksums(checksums);
  std::vector<uint32_t> order(s.blobs.size());
  std::iota(order.begin(), order.end(), 0u);
  std::shuffle(order.begin(), order.end(), rng);
  if (rng() % 2) w.set_info(s.info);
  for (uint32_t l : order) {
    const auto& blob = s.blobs[l];
    if (rng() % 2) {
      w.add_level(l, blob.data(), blob.size());
    } else {
      for (size_t pos = 0; pos < blob.size();) {
        const size_t n = std::min<size_t>(blob.size() - pos, 1 + rng() % 100);
        w.append_level(l, blob.data() + pos, n);
        pos += n;
      }
      w.end_level(l);
    }
  }
  for (size_t pos = 0; pos < s.mask.size();) {
    const size_t n = std::min<size_t>(s.mask.size() - pos, 1 + rng() % 50);
    w.append_mask(s.mask.data() + pos, n);
    pos += n;
  }
  w.set_info(s.info);
  w.set_metadata_json(s.json);
  w.finish();
}

void check_matches(const Container& c, const Sample& s, bool checksums) {
  const ContainerInfo& a = c.info();
  const ContainerInfo& e = s.info;
  CHECK(a.width == e.width);
  CHECK(a.height == e.height);
  REQUIRE(a.levels.size() == e.levels.size());
  CHECK(c.level_count() == e.levels.size());
  for (size_t l = 0; l < e.levels.size(); ++l) {
    INFO("level " << l);
    const LevelView v = c.level(uint32_t(l));
    CHECK(v.width == e.levels[l].width);
    CHECK(v.height == e.levels[l].height);
    CHECK(a.levels[l].width == e.levels[l].width);
    CHECK(a.levels[l].height == e.levels[l].height);
    REQUIRE(v.size == s.blobs[l].size());
    CHECK(std::equal(v.data, v.data + v.size, s.blobs[l].begin()));
    CHECK(reinterpret_cast<uintptr_t>(v.data) % 8 == 0);
    CHECK(a.levels[l].stats.mean == e.levels[l].stats.mean);
    CHECK(a.levels[l].stats.variance == e.levels[l].stats.variance);
    CHECK(a.levels[l].stats.rms == e.levels[l].stats.rms);
    CHECK(a.levels[l].stats.min == e.levels[l].stats.min);
    CHECK(a.levels[l].stats.max == e.levels[l].stats.max);
    REQUIRE(a.levels[l].error.has_value() == e.levels[l].error.has_value());
    if (e.levels[l].error) {
      CHECK(a.levels[l].error->rms == e.levels[l].error->rms);
      CHECK(a.levels[l].error->max_abs == e.levels[l].error->max_abs);
    }
    CHECK(a.levels[l].has_blob_crc == checksums);
    CHECK(c.level_checksum_ok(uint32_t(l)));
  }
  CHECK(a.spacing_x == e.spacing_x);
  CHECK(a.spacing_y == e.spacing_y);
  CHECK(a.horizontal_units == e.horizontal_units);
  CHECK(a.vertical_units == e.vertical_units);
  CHECK(a.vertical_scale == e.vertical_scale);
  CHECK(a.vertical_offset == e.vertical_offset);
  REQUIRE(a.georeference.has_value() == e.georeference.has_value());
  if (e.georeference) {
    CHECK(a.georeference->geotransform == e.georeference->geotransform);
    CHECK(a.georeference->crs_epsg == e.georeference->crs_epsg);
    CHECK(a.georeference->crs_text == e.georeference->crs_text);
    CHECK(a.georeference->units == e.georeference->units);
  }
  CHECK(a.filter_size == e.filter_size);
  CHECK(a.filter == e.filter);
  CHECK(a.filter_provenance == e.filter_provenance);
  CHECK(a.quantisation.step_units == e.quantisation.step_units);
  CHECK(a.quantisation.step_metres == e.quantisation.step_metres);
  CHECK(a.quantisation.mode == e.quantisation.mode);
  CHECK(a.quantisation.target == e.quantisation.target);
  CHECK(c.metadata_json() == s.json);

  const uint64_t voids = uint64_t(std::count(s.mask.begin(), s.mask.end(), uint8_t(0)));
  CHECK(a.void_count == voids);
  const std::vector<uint8_t> mask = c.mask();
  if (voids == 0) {
    CHECK(mask.empty());
  } else {
    REQUIRE(mask.size() == s.mask.size());
    for (size_t i = 0; i < mask.size(); ++i) {
      if (mask[i] != (s.mask[i] ? 1 : 0)) FAIL("mask differs at sample " << i);
    }
  }
  // Row bands agree with the whole mask (all data when there are no voids).
  std::vector<uint8_t> band(static_cast<size_t>(a.width * a.height), 7);
  for (uint64_t first : {uint64_t(0), a.height / 2, a.height - 1}) {
    for (uint64_t count : {uint64_t(1), a.height - first}) {
      c.mask_rows(first, count, band.data());
      bool same = true;
      for (uint64_t i = 0; i < count * a.width; ++i) {
        const uint64_t sample = first * a.width + i;
        const uint8_t expected = (voids == 0 || s.mask[size_t(sample)]) ? 1 : 0;
        same = same && band[size_t(i)] == expected;
      }
      CHECK(same);
    }
  }
  CHECK_NOTHROW(c.mask_rows(a.height, 0, band.data()));
  CHECK_THROWS_AS(c.mask_rows(a.height, 1, band.data()), std::out_of_range);
  CHECK_THROWS_AS(c.mask_rows(~uint64_t(0), 2, band.data()), std::out_of_range);
  CHECK_NOTHROW(c.verify());
}

// A small fixed file used by the damage tests: 3 levels, voids, metadata, georeference.
Sample small_sample() {
  std::mt19937_64 rng(99);
  Sample s = random_sample(rng, 13, 6, 3);
  s.info.georeference = Georeference{{7.5, 0.25, 0, 46.25, 0, -0.25}, "degree", 4326, ""};
  s.info.filter_size = 3;
  s.info.filter.assign(9, 0.125);
  s.blobs = {std::vector<uint8_t>(5, 0xA1), std::vector<uint8_t>(0), std::vector<uint8_t>(37, 0xB2)};
  s.mask.assign(13 * 6, 1);
  s.mask[3] = s.mask[40] = s.mask[41] = 0;
  s.json = R"({"tool":"test","version":"0.1"})";
  s.info.levels[2].error = LevelError{0.75, 3.0};
  return s;
}

// write_sample, then the file's bytes.
std::vector<uint8_t> write_sample_bytes(const std::string& path, const Sample& s, std::mt19937_64& rng) {
  write_sample(path, s, rng);
  return read_bytes(path);
}

ErrorCode open_error_code(const std::string& path) {
  try {
    Container::open(path);
  } catch (const Error& e) {
    return e.code();
  }
  FAIL("open succeeded on " << path);
  return ErrorCode::CorruptData;
}

// Writes edited bytes with their checksums made to match again (so only the edit can be noticed),
// then opens them.
ErrorCode resealed_open_error(const std::string& path, std::vector<uint8_t> bytes) {
  reseal(bytes);
  write_bytes(path, bytes);
  return open_error_code(path);
}

}  // namespace

TEST_CASE("container round trip with random pyramids", "[runtime][container]") {
  TempDir dir;
  std::mt19937_64 rng(2024);
  struct Shape {
    uint64_t w, h;
    size_t levels;
  };
  const Shape shapes[] = {{1, 1, 1},   {1, 1, 3},   {2, 1, 2},   {7, 5, 3},    {64, 64, 7},
                          {100, 3, 4}, {33, 65, 6}, {5, 200, 9}, {129, 127, 8}};
  int trial = 0;
  for (const Shape& shape : shapes) {
    for (int repeat = 0; repeat < 3; ++repeat, ++trial) {
      const bool checksums = (trial % 3) != 2;
      INFO("shape " << shape.w << "x" << shape.h << " levels " << shape.levels << " trial " << trial);
      const Sample s = random_sample(rng, shape.w, shape.h, shape.levels);
      const std::string path = dir.file("pyramid" + std::to_string(trial) + ".pyr");
      write_sample(path, s, rng, checksums);
      const Container c = Container::open(path);
      check_matches(c, s, checksums);
      CHECK(c.path() == path);
      CHECK(fs::file_size(path) % 8 == 0);
    }
  }
  CHECK(dir.entry_count() == size_t(trial));  // no temporary files left behind
}

TEST_CASE("container without metadata, mask or filter", "[runtime][container]") {
  TempDir dir;
  const std::string path = dir.file("bare.pyr");
  ContainerInfo info;
  info.width = 1;
  info.height = 1;
  info.levels = {LevelInfo{1, 1, {}, {}}};
  {
    ContainerWriter w(path);
    w.set_info(info);
    w.add_level(0, nullptr, 0);
    w.finish();
  }
  const Container c = Container::open(path);
  CHECK(c.level_count() == 1);
  CHECK(c.level(0).size == 0);
  CHECK(c.metadata_json().empty());
  CHECK(c.mask().empty());
  CHECK(c.info().filter.empty());
  CHECK_FALSE(c.info().georeference.has_value());
  CHECK_THROWS_AS(c.level(1), std::out_of_range);
}

TEST_CASE("container levels reserved and filled by another writer", "[runtime][container]") {
  // The striped build's parallel assembly: a level's first bytes are a hole that another file
  // descriptor (another process) fills; its CRC is combined with the bytes appended after it.
  TempDir dir;
  const std::string path = dir.file("reserved.pyr");
  std::mt19937 rng(99);
  std::vector<uint8_t> a(1000), b(37), tail(13), c(5000);
  for (auto* v : {&a, &b, &tail, &c})
    for (auto& x : *v) x = uint8_t(rng());
  ContainerInfo info;
  info.width = 4;
  info.height = 4;
  info.levels = {LevelInfo{1, 1, {}, {}}, LevelInfo{2, 2, {}, {}}, LevelInfo{4, 4, {}, {}}};
  {
    ContainerWriter w(path);
    w.set_info(info);
    const uint64_t at0 = w.reserve_level(0, a.size() + b.size());
    w.append_level(0, tail.data(), tail.size());
    w.end_level(0);
    CHECK_THROWS_AS(w.reserve_level(2, 10), std::logic_error);  // level 1 comes first
    const uint64_t at1 = w.reserve_level(1, 0);                 // an empty hole: CRC 0
    w.end_level(1);
    CHECK_THROWS_AS(w.reserve_level(1, 4), std::logic_error);  // ended
    const uint64_t at2 = w.reserve_level(2, c.size());
    w.end_level(2);
    CHECK(at1 % 8 == 0);
    const int fd = ::open(w.temp_path().c_str(), O_WRONLY);
    REQUIRE(fd >= 0);
    // Filled out of order, as several writers would.
    CHECK(::pwrite(fd, c.data(), c.size(), off_t(at2)) == ssize_t(c.size()));
    CHECK(::pwrite(fd, b.data(), b.size(), off_t(at0 + a.size())) == ssize_t(b.size()));
    CHECK(::pwrite(fd, a.data(), a.size(), off_t(at0)) == ssize_t(a.size()));
    ::close(fd);
    CHECK_THROWS_AS(w.finish(), std::logic_error);  // the holes' CRCs are missing
  }
  {
    ContainerWriter w(path);
    w.set_info(info);
    const uint64_t at0 = w.reserve_level(0, a.size());
    w.append_level(0, tail.data(), tail.size());
    w.end_level(0);
    w.reserve_level(1, 0);
    w.end_level(1);
    CHECK_THROWS_AS(w.set_reserved_crc(1, 5), std::logic_error);
    w.set_reserved_crc(1, 0);
    const uint64_t at2 = w.reserve_level(2, c.size());
    w.end_level(2);
    const int fd = ::open(w.temp_path().c_str(), O_WRONLY);
    REQUIRE(fd >= 0);
    CHECK(::pwrite(fd, a.data(), a.size(), off_t(at0)) == ssize_t(a.size()));
    CHECK(::pwrite(fd, c.data(), c.size(), off_t(at2)) == ssize_t(c.size()));
    ::close(fd);
    w.set_reserved_crc(0, crc32c(a.data(), a.size()));
    w.set_reserved_crc(2, crc32c(c.data(), c.size()));
    w.finish();
  }
  const Container got = Container::open(path);
  got.verify();
  std::vector<uint8_t> level0(a);
  level0.insert(level0.end(), tail.begin(), tail.end());
  REQUIRE(got.level(0).size == level0.size());
  CHECK(std::equal(level0.begin(), level0.end(), got.level(0).data));
  CHECK(got.level(1).size == 0);
  REQUIRE(got.level(2).size == c.size());
  CHECK(std::equal(c.begin(), c.end(), got.level(2).data));
  // A hole whose bytes differ from the CRC given for it is caught by verify().
  const std::string bad = dir.file("bad.pyr");
  {
    ContainerWriter w(bad);
    w.set_info(info);
    for (uint32_t l = 0; l < 3; ++l) {
      const uint64_t at = w.reserve_level(l, c.size());
      w.end_level(l);
      const int fd = ::open(w.temp_path().c_str(), O_WRONLY);
      REQUIRE(fd >= 0);
      CHECK(::pwrite(fd, c.data(), c.size(), off_t(at)) == ssize_t(c.size()));
      ::close(fd);
      w.set_reserved_crc(l, crc32c(c.data(), c.size() - (l == 1 ? 1 : 0)));
    }
    w.finish();
  }
  const Container damaged = Container::open(bad);
  CHECK(damaged.level_checksum_ok(0));
  CHECK_FALSE(damaged.level_checksum_ok(1));
  CHECK_THROWS_AS(damaged.verify(), Error);
}

TEST_CASE("container is moved and read concurrently", "[runtime][container]") {
  TempDir dir;
  const std::string path = dir.file("shared.pyr");
  std::mt19937_64 rng(5);
  const Sample s = small_sample();
  write_sample(path, s, rng);
  Container opened = Container::open(path);
  const Container c = std::move(opened);
  std::atomic<int> failures{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&] {
      for (int i = 0; i < 50; ++i) {
        try {
          c.verify();
          if (c.mask() != std::vector<uint8_t>(s.mask.begin(), s.mask.end())) ++failures;
          if (c.level(2).size != 37 || c.level(2).data[36] != 0xB2) ++failures;
        } catch (...) {
          ++failures;
        }
      }
    });
  }
  for (auto& t : threads) t.join();
  CHECK(failures == 0);
}

TEST_CASE("container file appears only on finish and temp files never linger", "[runtime][container]") {
  TempDir dir;
  const std::string path = dir.file("atomic.pyr");
  const Sample s = small_sample();
  SECTION("finish renames the complete file into place") {
    ContainerWriter w(path);
    CHECK(w.temp_path().rfind(path + ".tmp.", 0) == 0);
    w.set_info(s.info);
    for (uint32_t l = 0; l < 3; ++l) w.add_level(l, s.blobs[l].data(), s.blobs[l].size());
    w.append_mask(s.mask.data(), s.mask.size());
    w.set_metadata_json(s.json);
    CHECK(fs::exists(w.temp_path()));
    CHECK_FALSE(fs::exists(path));
    w.finish();
    CHECK(fs::exists(path));
    CHECK_FALSE(fs::exists(w.temp_path()));
    CHECK_NOTHROW(Container::open(path));
  }
  SECTION("destroying an unfinished writer removes its temp file") {
    std::string temp;
    {
      ContainerWriter w(path);
      temp = w.temp_path();
      w.set_info(s.info);
      w.add_level(1, s.blobs[1].data(), s.blobs[1].size());
      w.append_level(2, s.blobs[2].data(), 10);
      CHECK(fs::exists(temp));
    }
    CHECK_FALSE(fs::exists(temp));
    CHECK_FALSE(fs::exists(path));
    CHECK(dir.entry_count() == 0);
  }
  SECTION("a failed finish leaves no file at the target and removes the temp file") {
    std::string temp;
    {
      ContainerWriter w(path);
      temp = w.temp_path();
      w.set_info(s.info);
      w.add_level(0, s.blobs[0].data(), s.blobs[0].size());
      w.add_level(2, s.blobs[2].data(), s.blobs[2].size());
      CHECK_THROWS_AS(w.finish(), std::invalid_argument);  // level 1 missing
      CHECK_FALSE(fs::exists(path));
    }
    CHECK_FALSE(fs::exists(temp));
    CHECK(dir.entry_count() == 0);
  }
  SECTION("finish replaces an existing file atomically") {
    write_bytes(path, std::vector<uint8_t>(100, 'x'));
    std::mt19937_64 rng(1);
    write_sample(path, s, rng);
    CHECK_NOTHROW(Container::open(path));
    CHECK(dir.entry_count() == 1);
  }
  SECTION("two writers aimed at one target use distinct temp files") {
    ContainerWriter a(path), b(path);
    CHECK(a.temp_path() != b.temp_path());
  }
}

TEST_CASE("container writer rejects inconsistent input", "[runtime][container]") {
  TempDir dir;
  const std::string path = dir.file("bad.pyr");
  Sample s = small_sample();
  ContainerWriter w(path);
  SECTION("broken dimension chain") {
    s.info.levels[0].width = 3;  // ceil(7/2) = 4
    CHECK_THROWS_AS(w.set_info(s.info), std::invalid_argument);
  }
  SECTION("finest level differs from the grid") {
    s.info.width = 14;
    CHECK_THROWS_AS(w.set_info(s.info), std::invalid_argument);
  }
  SECTION("units string too long") {
    s.info.horizontal_units = std::string(40, 'u');
    CHECK_THROWS_AS(w.set_info(s.info), std::invalid_argument);
  }
  SECTION("filter size and coefficient count disagree") {
    s.info.filter.pop_back();
    CHECK_THROWS_AS(w.set_info(s.info), std::invalid_argument);
  }
  SECTION("non-finite spacing") {
    s.info.spacing_x = std::nan("");
    CHECK_THROWS_AS(w.set_info(s.info), std::invalid_argument);
  }
  SECTION("level written twice") {
    w.add_level(0, s.blobs[0].data(), s.blobs[0].size());
    CHECK_THROWS_AS(w.add_level(0, s.blobs[0].data(), s.blobs[0].size()), std::invalid_argument);
  }
  SECTION("level beyond the described count") {
    w.set_info(s.info);
    for (uint32_t l = 0; l < 4; ++l) w.add_level(l, nullptr, 0);
    CHECK_THROWS_AS(w.finish(), std::invalid_argument);
  }
  SECTION("mask shorter than the grid") {
    w.set_info(s.info);
    for (uint32_t l = 0; l < 3; ++l) w.add_level(l, nullptr, 0);
    w.append_mask(s.mask.data(), s.mask.size() - 1);
    CHECK_THROWS_AS(w.finish(), std::invalid_argument);
  }
  SECTION("finish without info") { CHECK_THROWS_AS(w.finish(), std::invalid_argument); }
  SECTION("unbalanced streaming calls") {
    w.set_info(s.info);
    w.end_level(0);
    CHECK_THROWS_AS(w.append_level(0, nullptr, 0), std::invalid_argument);  // after its end
    CHECK_THROWS_AS(w.end_level(0), std::invalid_argument);
    CHECK_THROWS_AS(w.append_level(kMaxLevels, nullptr, 0), std::invalid_argument);
    w.append_level(2, s.blobs[2].data(), 3);
    w.end_level(1);
    CHECK_THROWS_AS(w.finish(), std::logic_error);  // level 2 still open
  }
  CHECK_FALSE(fs::exists(path));
}

TEST_CASE("container open reports missing and foreign files", "[runtime][container]") {
  TempDir dir;
  CHECK(open_error_code(dir.file("missing.pyr")) == ErrorCode::NotFound);
  fs::create_directories(dir.file("a_directory"));
  CHECK(open_error_code(dir.file("a_directory")) == ErrorCode::NotFound);
  const std::string text = dir.file("text.pyr");
  const std::string hello = "hello, this is not a pyramid container but it is long enough for a header......";
  write_bytes(text, reinterpret_cast<const uint8_t*>(hello.data()), hello.size());
  CHECK(open_error_code(text) == ErrorCode::UnknownType);
  try {
    Container::open(text);
  } catch (const Error& e) {
    CHECK_THAT(e.what(), Catch::Contains(text) && Catch::Contains("magic"));
  }
}

TEST_CASE("container version rules", "[runtime][container]") {
  TempDir dir;
  const std::string path = dir.file("v.pyr");
  std::mt19937_64 rng(3);
  const std::vector<uint8_t> good = write_sample_bytes(path, small_sample(), rng);
  CHECK(get_le(good, kSbMajor, 2) == kFormatMajor);
  CHECK(get_le(good, kSbMinor, 2) == kFormatMinor);

  SECTION("an unknown major version is rejected by name, checksum or not") {
    for (bool sealed : {false, true}) {
      std::vector<uint8_t> b = good;
      put_le(b, kSbMajor, kFormatMajor + 1, 2);
      if (sealed) reseal(b);
      write_bytes(path, b);
      try {
        Container::open(path);
        FAIL("version 3 accepted");
      } catch (const Error& e) {
        CHECK(e.code() == ErrorCode::UnsupportedVersion);
        CHECK_THAT(e.what(),
                   Catch::Contains(path) && Catch::Contains("version " + std::to_string(kFormatMajor + 1) +
                                                            "." + std::to_string(kFormatMinor)));
      }
    }
  }
  SECTION("a 2.0 file (no geotransform or CRS fields) still opens, its geotransform derived") {
    std::vector<uint8_t> b = good;
    const size_t index = size_t(get_le(b, kSbIndexOffset, 8));
    const size_t tail = 3 * 96 + 8 * 9;  // level records and filter of small_sample
    std::vector<uint8_t> v20(b.begin(), b.begin() + std::ptrdiff_t(index + 264));
    v20.insert(v20.end(), b.begin() + std::ptrdiff_t(index + kInfoBlock),
               b.begin() + std::ptrdiff_t(index + kInfoBlock + tail));
    put_le(v20, index + kInfoSize, 264, 4);
    put_le(v20, kSbMajor, 2, 2);
    put_le(v20, kSbMinor, 0, 2);
    put_le(v20, kSbIndexSize, 264 + tail, 8);
    put_le(v20, kSbFileSize, v20.size(), 8);
    reseal(v20);
    write_bytes(path, v20);
    const Container c = Container::open(path);
    CHECK(c.minor_version() == 0);
    REQUIRE(c.info().georeference.has_value());
    const Georeference& g = *c.info().georeference;
    const double per_unit = c.info().horizontal_units == "arc-second" ? 1.0 / 3600.0 : 1.0;
    CHECK(g.geotransform[1] == c.info().spacing_x * per_unit);
    CHECK(g.geotransform[5] == -c.info().spacing_y * per_unit);
    CHECK(g.origin_x() == Approx(7.625).epsilon(1e-12));
    CHECK(g.origin_y() == Approx(46.125).epsilon(1e-12));
    CHECK(g.crs_epsg == 0);
    CHECK(g.crs_text.empty());
  }
  SECTION("bad 2.1 georeference fields are refused, naming the field") {
    const size_t index = size_t(get_le(good, kSbIndexOffset, 8));
    const auto refused = [&](std::vector<uint8_t> b, const std::string& field) {
      reseal(b);
      write_bytes(path, b);
      try {
        Container::open(path);
        FAIL(field << " accepted");
      } catch (const Error& e) {
        CHECK(e.code() == ErrorCode::CorruptData);
        CHECK_THAT(e.what(), Catch::Contains(path) && Catch::Contains(field));
      }
    };
    std::vector<uint8_t> b = good;
    put_f64(b, index + 264, std::nan(""));
    refused(b, "geotransform[0]");
    b = good;
    put_f64(b, index + 264 + 8, 0.0);
    refused(b, "pixel size");
    b = good;
    put_f64(b, index + 264 + 16, 0.5);
    refused(b, "rotation");
    b = good;
    put_le(b, index + 316, 9000, 4);
    refused(b, "crs_text_size");
    b = good;
    put_f64(b, index + 264, 7.0);  // the 2.0 origin field no longer matches
    refused(b, "disagree");
  }
  SECTION(
      "3.2 files of point sampling (libcodec format-6 streams) are refused by name; other 3.2 files open") {
    const size_t provenance_at = size_t(get_le(good, kSbIndexOffset, 8)) + 132;  // info::kFilterProvenance
    for (uint32_t provenance : {0u, 2u, 3u}) {
      std::vector<uint8_t> b = good;
      put_le(b, kSbMinor, 2, 2);
      put_le(b, provenance_at, provenance, 4);
      reseal(b);
      write_bytes(path, b);
      if (provenance != 3) {
        CHECK(Container::open(path).minor_version() == 2);
        continue;
      }
      try {
        Container::open(path);
        FAIL("a 3.2 point-sampled file accepted");
      } catch (const Error& e) {
        CHECK(e.code() == ErrorCode::UnsupportedVersion);
        CHECK_THAT(e.what(), Catch::Contains(path) && Catch::Contains("3.2") && Catch::Contains("format-6") &&
                                 Catch::Contains("rebuild"));
      }
    }
  }
  SECTION("a newer minor version of the same major is read") {
    std::vector<uint8_t> b = good;
    put_le(b, kSbMinor, kFormatMinor + 1, 2);
    reseal(b);
    write_bytes(path, b);
    const Container c = Container::open(path);
    CHECK(c.minor_version() == kFormatMinor + 1);
    CHECK(c.level(2).size == 37);
  }
}

TEST_CASE("container 1.x files are rejected with a message to rebuild them", "[runtime][container]") {
  // Version 1.0 and 1.1 files hold format-1 level blobs (fixed 32-byte band records, libcodec format
  // 3 streams), which this reader cannot decode: rejected by version, whether or not the header's
  // checksum was updated, naming the file, its version and the fix.
  TempDir dir;
  const std::string path = dir.file("v1.pyr");
  std::mt19937_64 rng(5);
  const std::vector<uint8_t> good = write_sample_bytes(path, small_sample(), rng);
  REQUIRE(kFormatMajor == 3);
  for (int minor : {0, 1})
    for (bool sealed : {false, true}) {
      std::vector<uint8_t> b = good;
      put_le(b, kSbMajor, 1, 2);
      put_le(b, kSbMinor, uint64_t(minor), 2);
      if (sealed) reseal(b);
      write_bytes(path, b);
      try {
        Container::open(path);
        FAIL("version 1." << minor << " accepted");
      } catch (const Error& e) {
        CHECK(e.code() == ErrorCode::UnsupportedVersion);
        CHECK_THAT(e.what(), Catch::Contains(path) && Catch::Contains("version 1." + std::to_string(minor)) &&
                                 Catch::Contains("rebuild it with pyramid-build"));
      }
    }
}

TEST_CASE("container level error figures are validated", "[runtime][container]") {
  TempDir dir;
  const std::string path = dir.file("err.pyr");
  std::mt19937_64 rng(6);
  Sample s = small_sample();
  s.info.levels[0].error = LevelError{0.5, 2.0};
  s.info.levels[1].error.reset();
  const std::vector<uint8_t> good = write_sample_bytes(path, s, rng);
  const size_t records = size_t(get_le(good, kSbIndexOffset, 8)) + kInfoBlock;
  constexpr size_t kRecord = 96, kFlags = 36, kErrorRms = 80, kErrorMax = 88;
  const auto damaged = [&](size_t at, uint64_t value, int bytes) {
    std::vector<uint8_t> b = good;
    put_le(b, at, value, bytes);
    return resealed_open_error(path, b);
  };
  CHECK(damaged(records + kErrorMax, std::bit_cast<uint64_t>(std::nan("")), 8) == ErrorCode::CorruptData);
  CHECK(damaged(records + kErrorRms, std::bit_cast<uint64_t>(-1.0), 8) == ErrorCode::CorruptData);
  CHECK(damaged(records + kRecord + kErrorRms, std::bit_cast<uint64_t>(1.0), 8) == ErrorCode::CorruptData);
  CHECK(damaged(records + kRecord + kFlags, 1 | 2 | 4, 4) == ErrorCode::CorruptData);  // unknown flag
  {  // the flag set on zero figures is a valid record: no error at all
    std::vector<uint8_t> b = good;
    put_le(b, records + kRecord + kFlags, 1 | 2, 4);
    reseal(b);
    write_bytes(path, b);
    const Container c = Container::open(path);
    REQUIRE(c.info().levels[1].error.has_value());
    CHECK(c.info().levels[1].error->max_abs == 0.0);
    CHECK(c.info().levels[0].error->max_abs == 2.0);
  }
  ContainerInfo bad = s.info;
  bad.levels[2].error = LevelError{std::nan(""), 1};
  CHECK_THROWS_AS(validate_info(bad), std::invalid_argument);
}

TEST_CASE("container checksum mismatches are reported", "[runtime][container]") {
  TempDir dir;
  const std::string path = dir.file("crc.pyr");
  std::mt19937_64 rng(4);
  const std::vector<uint8_t> good = write_sample_bytes(path, small_sample(), rng);

  SECTION("superblock") {
    std::vector<uint8_t> b = good;
    b[50] ^= 0x01;  // a reserved byte: only the checksum can notice
    write_bytes(path, b);
    CHECK(open_error_code(path) == ErrorCode::ChecksumMismatch);
  }
  SECTION("index") {
    std::vector<uint8_t> b = good;
    b[get_le(good, kSbIndexOffset, 8) + 100] ^= 0x40;
    write_bytes(path, b);
    CHECK(open_error_code(path) == ErrorCode::ChecksumMismatch);
  }
  SECTION("a blob, found by verify() only") {
    const Container original = Container::open(path);
    const uint64_t blob = original.info().levels[2].blob_offset;
    std::vector<uint8_t> b = good;
    b[blob + 20] ^= 0x08;
    const std::string damaged = dir.file("blob.pyr");
    write_bytes(damaged, b);
    const Container c = Container::open(damaged);
    CHECK(c.level_checksum_ok(0));
    CHECK_FALSE(c.level_checksum_ok(2));
    try {
      c.verify();
      FAIL("verify() accepted a damaged blob");
    } catch (const Error& e) {
      CHECK(e.code() == ErrorCode::ChecksumMismatch);
      CHECK_THAT(e.what(), Catch::Contains("level 2"));
    }
  }
}

TEST_CASE("container: a damaged byte anywhere is caught by open() or verify()", "[runtime][container]") {
  TempDir dir;
  const std::string path = dir.file("flip.pyr");
  std::mt19937_64 rng(6);
  write_sample(path, small_sample(), rng);
  const Container original = Container::open(path);
  const std::vector<uint8_t> good = read_bytes(path);
  const auto in_blob = [&](uint64_t at) {
    for (const LevelInfo& l : original.info().levels)
      if (at >= l.blob_offset && at < l.blob_offset + l.blob_size) return true;
    return false;
  };
  const std::string damaged = dir.file("damaged.pyr");
  int blob_bytes = 0;
  for (size_t at = 0; at < good.size(); ++at) {
    std::vector<uint8_t> b = good;
    b[at] ^= uint8_t(1 + rng() % 255);
    write_bytes(damaged, b);
    INFO("byte " << at << " of " << good.size());
    if (in_blob(at)) {
      ++blob_bytes;
      const Container c = Container::open(damaged);
      CHECK_THROWS_AS(c.verify(), Error);
    } else {
      CHECK_THROWS_AS(Container::open(damaged), Error);
    }
  }
  CHECK(blob_bytes == 42);
}

TEST_CASE("container: every truncation is rejected as truncated", "[runtime][container]") {
  TempDir dir;
  const std::string path = dir.file("trunc.pyr");
  std::mt19937_64 rng(7);
  const std::vector<uint8_t> good = write_sample_bytes(path, small_sample(), rng);
  const std::string cut = dir.file("cut.pyr");
  for (size_t length = 0; length < good.size(); ++length) {
    write_bytes(cut, good.data(), length);
    INFO("length " << length << " of " << good.size());
    CHECK(open_error_code(cut) == ErrorCode::Truncated);
  }
  std::vector<uint8_t> longer = good;
  longer.push_back(0);
  write_bytes(cut, longer);
  CHECK(open_error_code(cut) == ErrorCode::CorruptData);
}

TEST_CASE("container: resealed random index edits never crash the reader", "[runtime][container]") {
  // Edits with recomputed checksums reach the structural checks behind the CRCs: each file must
  // either be rejected with Error or be fully readable within its bounds.
  TempDir dir;
  const std::string path = dir.file("fuzz.pyr");
  std::mt19937_64 rng(8);
  const std::vector<uint8_t> good = write_sample_bytes(path, small_sample(), rng);
  const uint64_t index_offset = get_le(good, kSbIndexOffset, 8);
  const std::string edited = dir.file("edited.pyr");
  int accepted = 0;
  const auto interesting = [&](uint64_t v) -> uint64_t {
    switch (rng() % 8) {
      case 0:
        return 0;
      case 1:
        return ~uint64_t(0);
      case 2:
        return ~uint64_t(0) - rng() % 64;
      case 3:
        return uint64_t(1) << (rng() % 64);
      case 4:
        return v + 1 + rng() % 16;
      case 5:
        return v - 1 - rng() % 16;
      case 6:
        return good.size() + rng() % 16 - 8;
      default:
        return rng();
    }
  };
  for (int trial = 0; trial < 3000; ++trial) {
    std::vector<uint8_t> b = good;
    const int edits = 1 + int(rng() % 3);
    for (int e = 0; e < edits; ++e) {
      // Aligned 4- or 8-byte fields in the superblock (before its CRC) or the index.
      const bool superblock = rng() % 4 == 0;
      const int width = (rng() % 2) ? 8 : 4;
      const size_t lo = superblock ? 8 : size_t(index_offset);
      const size_t hi = superblock ? kSbCrc : b.size();
      const size_t at = lo + ((rng() % ((hi - lo) / size_t(width))) * size_t(width));
      put_le(b, at, interesting(get_le(b, at, width)), width);
    }
    reseal(b);
    write_bytes(edited, b);
    try {
      const Container c = Container::open(edited);
      ++accepted;
      uint64_t sum = 0;
      for (uint32_t l = 0; l < c.level_count(); ++l) {
        const LevelView v = c.level(l);
        for (size_t i = 0; i < v.size; ++i) sum += v.data[i];
      }
      const uint64_t samples = c.info().width * c.info().height;
      REQUIRE(samples <= 1000000);  // a larger grid would need its voids' runs to cover it
      const std::vector<uint8_t> mask = c.mask();
      CHECK((mask.empty() || mask.size() == samples));
      std::vector<uint8_t> rows(static_cast<size_t>(samples));
      c.mask_rows(0, c.info().height, rows.data());
      sum += uint64_t(std::count(rows.begin(), rows.end(), uint8_t(1)));
      for (char ch : c.metadata_json()) sum += uint8_t(ch);
      try {
        c.verify();
      } catch (const Error&) {
      }
      CHECK(sum < (uint64_t(1) << 40));
    } catch (const Error&) {
    }
  }
  // Edits of stats, spacing and filter values leave valid files: the loop did reach the accessors.
  CHECK(accepted > 0);
  CHECK(accepted < 3000);
}

TEST_CASE("container: crafted huge offsets are rejected without overflow", "[runtime][container]") {
  TempDir dir;
  const std::string path = dir.file("huge.pyr");
  std::mt19937_64 rng(9);
  const std::vector<uint8_t> good = write_sample_bytes(path, small_sample(), rng);
  const uint64_t index = get_le(good, kSbIndexOffset, 8);
  // Level records start 320 bytes into the index (96 bytes each, blob offset at +16, size at +24).
  const size_t record2 = size_t(index) + kInfoBlock + 2 * 96;
  const uint64_t cases[][2] = {{~uint64_t(0) - 7, 16},
                               {8, ~uint64_t(0) - 7},
                               {uint64_t(1) << 32, 37},
                               {64, uint64_t(1) << 33},
                               {good.size() - 32, 40}};
  for (const auto& c : cases) {
    std::vector<uint8_t> b = good;
    put_le(b, record2 + 16, c[0], 8);
    put_le(b, record2 + 24, c[1], 8);
    INFO("offset " << c[0] << " size " << c[1]);
    CHECK(resealed_open_error(path, b) == ErrorCode::CorruptData);
  }
  std::vector<uint8_t> b = good;
  put_le(b, kSbFileSize, ~uint64_t(0), 8);
  CHECK(resealed_open_error(path, b) == ErrorCode::Truncated);
  b = good;
  put_le(b, kSbIndexOffset, ~uint64_t(0) - 7, 8);
  CHECK(resealed_open_error(path, b) == ErrorCode::CorruptData);
}

// Hidden (run with "[large]"): a level blob beyond 4 GiB, so offsets and sizes need 64 bits.
TEST_CASE("container with a blob larger than 4 GiB", "[.][large][runtime][container]") {
  TempDir dir;
  const std::string path = dir.file("large.pyr");
  ContainerInfo info;
  info.width = 2;
  info.height = 2;
  info.levels = {LevelInfo{1, 1, {}, {}}, LevelInfo{2, 2, {}, {}}};
  const size_t chunk = size_t(1) << 26;
  std::vector<uint8_t> data(chunk);
  for (size_t i = 0; i < chunk; ++i) data[i] = uint8_t(i * 31 + 7);
  const uint64_t total = (uint64_t(1) << 32) + (uint64_t(1) << 26) + 3;
  {
    ContainerWriter w(path);
    w.set_info(info);
    w.add_level(0, data.data(), 5);
    for (uint64_t pos = 0; pos < total;) {
      const size_t n = size_t(std::min<uint64_t>(chunk, total - pos));
      w.append_level(1, data.data(), n);
      pos += n;
    }
    w.end_level(1);
    w.finish();
  }
  const Container c = Container::open(path);
  const LevelView v = c.level(1);
  CHECK(v.size == total);
  CHECK(v.data[total - 1] == data[(total - 1) % chunk]);
  CHECK(c.level(0).size == 5);
  CHECK_NOTHROW(c.verify());
}

TEST_CASE("container bytes follow docs/format.md", "[runtime][container]") {
  TempDir dir;
  const std::string path = dir.file("layout.pyr");
  std::mt19937_64 rng(10);
  const std::vector<uint8_t> b = write_sample_bytes(path, small_sample(), rng);
  const uint8_t magic[8] = {0x89, 'T', 'P', 'Y', 'R', 0x0D, 0x0A, 0x1A};
  CHECK(std::equal(magic, magic + 8, b.begin()));
  CHECK(get_le(b, 12, 4) == 64);
  CHECK(get_le(b, kSbFileSize, 8) == b.size());
  const uint64_t index = get_le(b, kSbIndexOffset, 8), index_size = get_le(b, kSbIndexSize, 8);
  CHECK(index % 8 == 0);
  CHECK(index_size == kInfoBlock + 3 * 96 + 8 * 9);
  CHECK(index + index_size == b.size());
  CHECK(get_le(b, kSbIndexCrc, 4) == crc32c(b.data() + index, size_t(index_size)));
  CHECK(get_le(b, kSbCrc, 4) == crc32c(b.data(), 60));
  CHECK(get_le(b, index + 4, 4) == 3);    // level count
  CHECK(get_le(b, index + 16, 8) == 13);  // width
  CHECK(get_le(b, index + 24, 8) == 6);   // height
  CHECK(get_le(b, index + 204, 4) == 1);  // mask encoding: runs
  CHECK(get_le(b, index + 232, 8) == 3);  // void count
  // Mask runs: data 3, void 1, data 36, void 2, data 36 (13 x 6 = 78 samples).
  const uint64_t mask = get_le(b, index + 216, 8);
  CHECK(get_le(b, index + 224, 8) == 5);
  CHECK(std::vector<uint8_t>(b.begin() + long(mask), b.begin() + long(mask) + 5) ==
        std::vector<uint8_t>{3, 1, 36, 2, 36});
  CHECK(get_le(b, kSbMajor, 2) == 3);
  CHECK(get_le(b, kSbMinor, 2) == 4);
  CHECK(get_le(b, index + 0, 4) == 320);  // info size (2.1)
  CHECK(get_le(b, index + 8, 4) == 96);   // level record size
  const uint64_t level2 = index + kInfoBlock + 2 * 96;
  CHECK(get_le(b, level2, 8) == 13);
  CHECK(get_le(b, level2 + 24, 8) == 37);
  const uint64_t blob = get_le(b, level2 + 16, 8);
  CHECK(blob % 8 == 0);
  CHECK(get_le(b, level2 + 32, 4) == crc32c(b.data() + blob, 37));
  CHECK(get_le(b, level2 + 36, 4) == 3);                            // flags: checksum, error figures
  CHECK(std::bit_cast<double>(get_le(b, level2 + 80, 8)) == 0.75);  // error rms
  CHECK(std::bit_cast<double>(get_le(b, level2 + 88, 8)) == 3.0);   // error max
  const uint64_t filter = index + kInfoBlock + 3 * 96;
  CHECK(std::bit_cast<double>(get_le(b, filter + 8 * 8, 8)) == 0.125);
}
