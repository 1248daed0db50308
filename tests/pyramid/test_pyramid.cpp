// The closed-loop residual pyramid: coding, decoding, streaming, nodata, tiny grids.
#include <algorithm>
#include <array>
#include <atomic>
#include <catch2/catch.hpp>
#include <cmath>
#include <iostream>
#include <random>

#include "pyramid/pyramid.h"
#include "shared_data.h"

using namespace terrain;

namespace {

BuildOptions options(int levels = 0, int threads = 2) {
  BuildOptions o;
  o.level_count = levels;
  o.threads = threads;
  return o;
}

// Deterministic rough terrain: octaves of value noise, int16 range.
Heightmap synthetic(int64_t w, int64_t h, uint32_t seed) {
  Heightmap m;
  m.info.width = w, m.info.height = h;
  m.info.sample_type = SampleType::Int16;
  m.values.resize(size_t(w * h));
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> phase(0, 6.283);
  double p[8];
  for (double& v : p) v = phase(rng);
  for (int64_t y = 0; y < h; ++y)
    for (int64_t x = 0; x < w; ++x) {
      double v = 0, amp = 900, fx = 0.013, fy = 0.011;
      for (int o = 0; o < 4; ++o, amp *= 0.45, fx *= 2.1, fy *= 1.9)
        v += amp * std::sin(x * fx + p[o]) * std::cos(y * fy + p[o + 4]);
      v += double(int(rng() % 7) - 3);  // sensor noise
      m.values[size_t(y * w + x)] = std::round(v + 1000);
    }
  return m;
}

Heightmap grid_from(const std::vector<int32_t>& g, int64_t w, int64_t h) {
  Heightmap m;
  m.info.width = w, m.info.height = h;
  m.info.sample_type = SampleType::Int32;
  m.values.assign(g.begin(), g.end());
  return m;
}

// Feeds rows in small uneven chunks, as a file reader on a slow pipe might.
class TricklingReader final : public BandReader {
 public:
  TricklingReader(std::unique_ptr<BandReader> inner, uint32_t seed) : inner_(std::move(inner)), rng_(seed) {}
  const GridInfo& info() const override { return inner_->info(); }
  int64_t read_rows(int64_t rows, double* values, uint8_t* valid) override {
    const int64_t n = std::min<int64_t>(rows, 1 + int64_t(rng_() % 7));
    const int64_t got = inner_->read_rows(n, values, valid);
    rows_read_ += got;
    return got;
  }

 private:
  std::unique_ptr<BandReader> inner_;
  std::mt19937 rng_;
};

void require_same_output(const MemoryPyramid& a, const MemoryPyramid& b) {
  REQUIRE(a.header.levels == b.header.levels);
  REQUIRE(a.header.filter.taps == b.header.filter.taps);
  REQUIRE(a.bands.size() == b.bands.size());
  for (size_t l = 0; l < a.bands.size(); ++l) {
    REQUIRE(a.bands[l].size() == b.bands[l].size());
    for (size_t k = 0; k < a.bands[l].size(); ++k) REQUIRE(a.bands[l][k].bytes == b.bands[l][k].bytes);
  }
  REQUIRE(a.mask == b.mask);
  REQUIRE(a.recon == b.recon);
}

}  // namespace

TEST_CASE("uniform quantiser: error within step/2, exact at step 1, rejects bad bytes") {
  std::vector<int32_t> r{0, 1, -1, 2, -2, 3, -3, 1000, -1000, 2147483647, -2147483647 - 1, 5, -6};
  for (int32_t step : {1, 2, 3, 4, 7}) {
    UniformQuantizerCoder coder(step);
    std::vector<int32_t> rec(r.size()), dec(r.size());
    auto bytes = coder.encode(r.data(), int64_t(r.size()), 1, rec.data(), 0, false, 1);
    REQUIRE(coder.decode(bytes.data(), bytes.size(), int64_t(r.size()), 1, dec.data()));
    CHECK(rec == dec);
    for (size_t k = 0; k < r.size(); ++k) {  // the int32 extremes (9, 10) saturate
      if (k == 9 || k == 10) continue;
      REQUIRE(std::abs(int64_t(r[k]) - rec[k]) <= step / 2);
    }
    if (step == 1) CHECK(std::vector<int32_t>(r.begin(), r.end()) == rec);
    CHECK_FALSE(coder.decode(bytes.data(), bytes.size() - 1, int64_t(r.size()), 1, dec.data()));
    auto longer = bytes;
    longer.push_back(0);
    CHECK_FALSE(coder.decode(longer.data(), longer.size(), int64_t(r.size()), 1, dec.data()));
  }
  CHECK_THROWS_AS(UniformQuantizerCoder(0), std::invalid_argument);
}

TEST_CASE("closed loop: decoder output equals the builder's reconstruction, step 1 is lossless") {
  Heightmap map = synthetic(203, 157, 11);
  for (int32_t step : {1, 4}) {
    UniformQuantizerCoder coder(step, 16);
    MemoryPyramid out;
    BuildResult res = build_pyramid(map, options(4), coder, out);
    REQUIRE(res.header.levels.size() == 4);
    for (int l = 0; l < 4; ++l) REQUIRE(decode_pyramid(out, coder, l) == out.recon[size_t(l)]);
    auto finest = decode_pyramid(out, coder, 3);
    int64_t max_err = 0;
    for (size_t k = 0; k < finest.size(); ++k)
      max_err = std::max<int64_t>(max_err, std::llabs(int64_t(map.values[k]) - finest[k]));
    CHECK(max_err <= step / 2);
    CHECK(res.levels.back().error_max_abs == max_err);
  }
}

TEST_CASE("closed loop: int32 extremes saturate, the figures match the decoded levels") {
  // Neighbours at both ends of int32: U overshoots, residuals and reconstructions saturate, so the
  // builder's overflow checks send these rows through its saturating loops.
  // A plateau just below the top with spikes to it: residuals fit, but rounded up by a step of 300
  // the reconstruction passes the top (the figures' loop saturates it).
  Heightmap spikes;
  spikes.info.width = 67, spikes.info.height = 45;
  spikes.info.sample_type = SampleType::Int32;
  Heightmap extremes;
  extremes.info = spikes.info;
  std::mt19937 rng(3);
  const double hi = 2147483647.0 - 3, lo = -2147483648.0 + 3;
  for (int64_t k = 0; k < 67 * 45; ++k) {
    extremes.values.push_back(rng() % 3 == 0 ? hi : rng() % 2 ? lo : 17.0);
    spikes.values.push_back(rng() % 5 == 0 ? 2147483647.0 : 2147483647.0 - 200);
  }
  for (auto [input, step] : {std::pair{&extremes, 1}, {&extremes, 1000}, {&spikes, 300}}) {
    const Heightmap& map = *input;
    INFO("step " << step);
    for (int threads : {1, 3}) {
      UniformQuantizerCoder coder(step, 16);
      MemoryPyramid out;
      BuildResult res = build_pyramid(map, options(3, threads), coder, out);
      for (int l = 0; l < 3; ++l) REQUIRE(decode_pyramid(out, coder, l) == out.recon[size_t(l)]);
      const auto finest = decode_pyramid(out, coder, 2);
      int64_t max_err = 0;
      double sum_sq = 0;
      for (size_t k = 0; k < finest.size(); ++k) {
        const int64_t e = int64_t(map.values[k]) - finest[k];
        max_err = std::max<int64_t>(max_err, std::llabs(e));
        sum_sq += double(e) * double(e);
      }
      CHECK(res.levels.back().error_max_abs == max_err);
      CHECK(res.levels.back().error_rms == Approx(std::sqrt(sum_sq / double(finest.size()))).epsilon(1e-9));
    }
  }
}

TEST_CASE("closed loop: finest-level error does not grow with the number of levels") {
  std::vector<std::pair<std::string, Heightmap>> inputs;
  inputs.emplace_back("synthetic 515x389", synthetic(515, 389, 5));
  const std::string dem = testdata::require("srtm3_N46W122_rainier_adams_cascades.hgt");
  if (!dem.empty()) inputs.emplace_back("N46W122", read_heightmap(dem));
  const int32_t step = 4;
  for (auto& [name, map] : inputs) {
    std::vector<double> rms;
    for (int levels : {2, 4, 6}) {
      UniformQuantizerCoder coder(step);
      MemoryPyramid out;
      out.keep_reconstruction = false;
      BuildResult res = build_pyramid(map, options(levels), coder, out);
      const LevelBuildStats& fin = res.levels.back();
      std::cout << "[closed loop] " << name << " step " << step << ", " << levels
                << " levels: finest error rms " << fin.error_rms << ", max " << fin.error_max_abs
                << ", residual rms " << fin.residual_rms << ", bytes " << out.total_bytes() << "\n";
      CHECK(fin.error_max_abs <= step / 2);
      rms.push_back(fin.error_rms);
    }
    // The quantiser alone sets the error: uniform on {-2..2} gives rms ~1.2 at every depth.
    CHECK(rms[1] <= rms[0] * 1.05 + 0.01);
    CHECK(rms[2] <= rms[0] * 1.05 + 0.01);
  }
}

TEST_CASE("streamed == in-memory, bit-exact, whatever the chunking and thread count") {
  SECTION("synthetic") {
    Heightmap map = synthetic(290, 333, 9);
    map.valid.assign(map.values.size(), 1);
    for (int64_t k = 0; k < 200; ++k) map.valid[size_t((k * 7919) % int64_t(map.values.size()))] = 0;
    UniformQuantizerCoder coder(3, 32);
    BuildOptions o = options(4, 2);
    o.fill_band_rows = 40;
    MemoryPyramid mem, streamed, one_thread;
    build_pyramid(map, o, coder, mem);
    TricklingReader trickle(make_memory_band_reader(map, 5), 42);
    build_pyramid(trickle, o, coder, streamed);
    require_same_output(mem, streamed);
    o.threads = 1;
    build_pyramid(map, o, coder, one_thread);
    require_same_output(mem, one_thread);
  }
  SECTION("bands come as produced: levels interleaved, each level top to bottom") {
    // Taller than fit_rows plus the levels' lag, so that coding starts before the input ends.
    Heightmap map = synthetic(150, 1400, 4);
    UniformQuantizerCoder coder(2, 16);
    // Records the order of the sink calls.
    struct OrderSink final : PyramidSink {
      std::vector<std::array<int64_t, 3>> bands;  // level, y0, rows
      std::vector<int64_t> mask_y0;
      void band(int level, int64_t y0, int64_t rows, std::vector<uint8_t>&&) override {
        bands.push_back({level, y0, rows});
      }
      void mask_rows(int64_t y0, int64_t, const uint8_t*) override { mask_y0.push_back(y0); }
    } order;
    build_pyramid(map, options(5, 2), coder, order);
    std::vector<int64_t> next_row(5, 0);
    std::vector<int64_t> finest_y0;
    bool interleaved = false;
    int previous = 0;
    for (auto [level, y0, rows] : order.bands) {
      REQUIRE(y0 == next_row[size_t(level)]);
      next_row[size_t(level)] = y0 + rows;
      if (level < previous) interleaved = true;  // a coarser level's band after a finer one's
      previous = int(level);
      if (level == 4) finest_y0.push_back(y0);
    }
    CHECK(interleaved);
    CHECK(order.mask_y0 == finest_y0);  // a mask call for every finest band, voids or not
    MemoryPyramid mem;
    build_pyramid(map, options(5, 2), coder, mem);
    CHECK(mem.mask.empty());  // no voids: nothing kept
    // Coarser levels use shorter bands (band_rows >> (m - l), but up to 16 rows while the lag stays
    // within 4 band_rows input rows), so they do not hold back finer ones: 16, 16, 16, 8, 4 rows.
    CHECK(mem.bands[4].front().rows == 16);
    CHECK(mem.bands[2].front().rows == 16);
    CHECK(mem.bands[1].front().rows == 8);
    CHECK(mem.bands[0].front().rows == 4);
    for (int l = 0; l < 5; ++l) CHECK(mem.bands[size_t(l)].front().rows << (4 - l) <= 4 * 16);
  }
  SECTION("shared tiles read through open_band_reader") {
    for (const char* name : {"srtm3_N44E033_crimea_coast_mountains.hgt", "pugetsound_ps_height_1k.png"}) {
      const std::string path = testdata::require(name);
      if (path.empty()) continue;
      INFO(name);
      Heightmap map = read_heightmap(path);
      UniformQuantizerCoder coder(2);
      MemoryPyramid mem, streamed;
      build_pyramid(map, options(), coder, mem);
      auto file_reader = open_band_reader(path);
      TricklingReader trickle(std::move(file_reader), 1);
      BuildOptions o = options();
      o.threads = 1;
      build_pyramid(trickle, o, coder, streamed);
      require_same_output(mem, streamed);
    }
  }
}

TEST_CASE("a coder's parts run on the round's workers: same bytes, errors reach the caller") {
  // Codes a band's rows in up to `parts` pieces on the runner (a uniform quantiser's bytes are one
  // varint per sample, so the pieces' bytes in order are the whole band's).
  struct PartsCoder final : ResidualCoder {
    UniformQuantizerCoder inner{3, 32};
    std::atomic<int> part_calls{0}, runs{0};
    bool fail = false;
    int64_t band_rows() const override { return inner.band_rows(); }
    std::vector<uint8_t> encode(const int32_t* r, int64_t w, int64_t h, int32_t* rec, int above,
                                bool coarsest, int threads) override {
      return inner.encode(r, w, h, rec, above, coarsest, threads);
    }
    std::vector<uint8_t> encode_parts(const int32_t* r, int64_t w, int64_t h, int32_t* rec, int above,
                                      bool coarsest, int parts, PartRunner& runner) override {
      const size_t n = size_t(std::clamp<int64_t>(parts, 1, h));
      std::vector<std::vector<uint8_t>> pieces(n);
      ++runs;
      runner.run(n, [&](size_t c) {
        ++part_calls;
        if (fail && c == n - 1) throw std::runtime_error("part failed on purpose");
        const int64_t y0 = h * int64_t(c) / int64_t(n), y1 = h * int64_t(c + 1) / int64_t(n);
        pieces[c] = inner.encode(r + y0 * w, w, y1 - y0, rec + y0 * w, above, coarsest, 1);
      });
      std::vector<uint8_t> out;
      for (const auto& p : pieces) out.insert(out.end(), p.begin(), p.end());
      return out;
    }
    bool decode(const uint8_t* d, size_t n, int64_t w, int64_t h, int32_t* out) override {
      return inner.decode(d, n, w, h, out);
    }
  };
  // Wide enough that the finest bands (32 rows) are split (the builder asks for a part per 2^16
  // samples).
  Heightmap map = synthetic(4100, 300, 12);
  UniformQuantizerCoder plain(3, 32);
  MemoryPyramid one_thread;
  build_pyramid(map, options(5, 1), plain, one_thread);
  for (int threads : {2, 3, 8}) {
    INFO("threads " << threads);
    PartsCoder coder;
    MemoryPyramid parts;
    build_pyramid(map, options(5, threads), coder, parts);
    require_same_output(one_thread, parts);
    CHECK(coder.runs > 0);
    CHECK(coder.part_calls > coder.runs);  // bands were split into several parts
    PartsCoder failing;
    failing.fail = true;
    MemoryPyramid unused;
    REQUIRE_THROWS_WITH(build_pyramid(map, options(5, threads), failing, unused),
                        Catch::Contains("part failed on purpose"));
  }
}

TEST_CASE("nodata: voids survive a round trip, valid samples stay within step/2") {
  Heightmap map = synthetic(300, 270, 21);
  map.valid.assign(map.values.size(), 1);
  auto void_at = [&](int64_t x, int64_t y) {
    map.valid[size_t(y * 300 + x)] = 0;
    map.values[size_t(y * 300 + x)] = -32768;  // what a reader might leave behind
  };
  for (int64_t y = 100; y < 160; ++y)
    for (int64_t x = 40; x < 120; ++x) void_at(x, y);                         // a lake-sized hole
  for (int64_t x = 0; x < 300; ++x) void_at(x, 7);                            // a whole void row
  for (int64_t k = 0; k < 500; ++k) void_at((k * 97) % 300, (k * 61) % 270);  // scattered
  for (int64_t y = 0; y < 270; ++y) void_at(299, y);                          // the east edge column
  const int32_t step = 4;
  UniformQuantizerCoder coder(step);
  MemoryPyramid out;
  BuildResult res = build_pyramid(map, options(3), coder, out);
  REQUIRE(out.mask.size() == map.valid.size());
  CHECK(res.void_count == std::count(map.valid.begin(), map.valid.end(), uint8_t(0)));
  std::vector<uint8_t> valid;
  auto dec = decode_pyramid(out, coder, 2, &valid);
  CHECK(valid == map.valid);
  for (size_t k = 0; k < dec.size(); ++k)
    if (map.valid[k]) REQUIRE(std::llabs(int64_t(map.values[k]) - dec[k]) <= step / 2);
  // The fill keeps voids from polluting the coarse levels: no sample near -32768 anywhere.
  for (int l = 0; l < 2; ++l)
    for (int32_t v : out.recon[size_t(l)]) REQUIRE(v > -2000);

  // Real voids (852 samples in N44E033).
  const std::string dem = testdata::require("srtm3_N44E033_crimea_coast_mountains.hgt");
  if (!dem.empty()) {
    Heightmap real = read_heightmap(dem);
    MemoryPyramid out2;
    out2.keep_reconstruction = false;
    BuildResult r2 = build_pyramid(real, options(), coder, out2);
    std::vector<uint8_t> v2;
    auto d2 = decode_pyramid(out2, coder, int(out2.header.levels.size()) - 1, &v2);
    std::vector<uint8_t> expect = real.valid.empty() ? std::vector<uint8_t>(d2.size(), 1) : real.valid;
    CHECK(r2.void_count == 852);
    CHECK(v2 == expect);
    int64_t max_err = 0;
    for (size_t k = 0; k < d2.size(); ++k)
      if (expect[k]) max_err = std::max<int64_t>(max_err, std::llabs(int64_t(real.values[k]) - d2[k]));
    CHECK(max_err <= step / 2);
  }
}

TEST_CASE("tiny grids 1x1..7x7 and strips round-trip losslessly at step 1") {
  std::mt19937 rng(99);
  std::vector<GridSize> sizes;
  for (int64_t w = 1; w <= 7; ++w)
    for (int64_t h = 1; h <= 7; ++h) sizes.push_back({w, h});
  for (GridSize s : {GridSize{1, 300}, GridSize{300, 1}, GridSize{2, 515}, GridSize{515, 3}})
    sizes.push_back(s);
  UniformQuantizerCoder coder(1, 4);
  for (GridSize s : sizes)
    for (int levels : {0, 3, 20}) {
      INFO(s.width << "x" << s.height << ", levels " << levels);
      std::vector<int32_t> g(size_t(s.width * s.height));
      for (auto& v : g) v = int32_t(rng() % 5000) - 2500;
      MemoryPyramid out;
      BuildResult res = build_pyramid(grid_from(g, s.width, s.height), options(levels), coder, out);
      const int L = int(res.header.levels.size());
      REQUIRE(res.header.levels.back() == s);
      REQUIRE(decode_pyramid(out, coder, L - 1) == g);
    }
}

TEST_CASE("bad input gives clear errors") {
  UniformQuantizerCoder coder(1);
  MemoryPyramid out;
  Heightmap frac = grid_from({1, 2, 3, 4}, 2, 2);
  frac.info.sample_type = SampleType::Int16;
  frac.values[1] = 2.5;
  CHECK_THROWS_WITH(build_pyramid(frac, options(), coder, out), Catch::Contains("non-integer"));
  Heightmap huge = grid_from({1, 2, 3, 4}, 2, 2);
  huge.info.sample_type = SampleType::Float32;
  huge.values[0] = 1e12;
  CHECK_THROWS_WITH(build_pyramid(huge, options(), coder, out), Catch::Contains("int32"));
  Heightmap empty;
  CHECK_THROWS_AS(build_pyramid(empty, options(), coder, out), std::invalid_argument);
}
