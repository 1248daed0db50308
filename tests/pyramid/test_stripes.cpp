// Stripe builds (build_pyramid_stripe, the parts of a build spread over processes): the stripes of
// any partition of the rows, put together level by level, give the whole build's bands, figures and
// mask, byte for byte.
#include <catch2/catch.hpp>
#include <cmath>
#include <random>

#include "build/ptc_coder.h"
#include "pyramid/pyramid.h"

using namespace terrain;

namespace {

Heightmap rough(int64_t w, int64_t h, uint32_t seed, bool voids) {
  Heightmap m;
  m.info.width = w, m.info.height = h;
  m.info.sample_type = SampleType::Int16;
  m.values.resize(size_t(w * h));
  std::mt19937 rng(seed);
  for (int64_t y = 0; y < h; ++y)
    for (int64_t x = 0; x < w; ++x)
      m.values[size_t(y * w + x)] = std::round(700 * std::sin(x * 0.017 + seed) * std::cos(y * 0.013) +
                                               90 * std::sin(x * 0.11 + y * 0.07) + double(rng() % 9));
  if (voids) {  // a lake and a run of whole void rows (the fill's carry crosses them)
    m.valid.assign(size_t(w * h), 1);
    for (int64_t y = h / 3; y < h / 3 + 70 && y < h; ++y)
      for (int64_t x = 0; x < w; ++x)
        if (y > h / 3 + 20 || (x - w / 2) * (x - w / 2) < 400) m.valid[size_t(y * w + x)] = 0;
  }
  return m;
}

struct Band {
  int level;
  int64_t y0, rows;
  std::vector<uint8_t> bytes, mask;
  BandFigures f;
  bool operator==(const Band& o) const {
    return level == o.level && y0 == o.y0 && rows == o.rows && bytes == o.bytes && mask == o.mask &&
           f.res_sq == o.f.res_sq && f.err_sq == o.f.err_sq && f.res_max == o.f.res_max &&
           f.err_max == o.f.err_max && f.counted == o.f.counted;
  }
};

// Keeps every band with its figures and (finest level) mask rows, per level in arrival order.
class Recorder final : public PyramidSink {
 public:
  void begin(const PyramidHeader& h) override {
    levels.resize(h.levels.size()), width = h.levels.back().width;
  }
  void mask_rows(int64_t, int64_t rows, const uint8_t* valid) override {
    mask.assign(valid, valid + rows * width);
  }
  void band_figures(int, int64_t, const BandFigures& f) override { figures = f; }
  void band(int level, int64_t y0, int64_t rows, std::vector<uint8_t>&& bytes) override {
    const bool finest = size_t(level) + 1 == levels.size();
    levels[size_t(level)].push_back(
        Band{level, y0, rows, bytes, finest ? mask : std::vector<uint8_t>{}, figures});
  }
  std::vector<std::vector<Band>> levels;
  std::vector<uint8_t> mask;
  BandFigures figures;
  int64_t width = 0;
};

// A Recorder that also keeps T^ of one level, whole.
class CoarseRecorder final : public PyramidSink {
 public:
  CoarseRecorder(Recorder& bands, int level, GridSize size) : bands_(bands), level_(level), size_(size) {
    grid.assign(size_t(size.width * size.height), 0);
  }
  void begin(const PyramidHeader& h) override { bands_.begin(h); }
  void mask_rows(int64_t y0, int64_t rows, const uint8_t* valid) override {
    bands_.mask_rows(y0, rows, valid);
  }
  void band_figures(int l, int64_t y0, const BandFigures& f) override { bands_.band_figures(l, y0, f); }
  void band(int l, int64_t y0, int64_t rows, std::vector<uint8_t>&& bytes) override {
    bands_.band(l, y0, rows, std::move(bytes));
  }
  bool wants_reconstruction(int l) const override { return l == level_; }
  void reconstructed_rows(int l, int64_t y0, int64_t rows, int64_t width, const int32_t* data) override {
    REQUIRE(l == level_);
    REQUIRE(width == size_.width);
    REQUIRE(y0 + rows <= size_.height);
    std::copy(data, data + rows * width, grid.begin() + y0 * width);
    rows_seen += rows;
  }
  std::vector<int32_t> grid;
  int64_t rows_seen = 0;

 private:
  Recorder& bands_;
  int level_;
  GridSize size_;
};

// The coder and build options both stripe tests use: many bands, so that stripes cut every level.
PtcCoderOptions small_band_coder(double step) {
  PtcCoderOptions co;
  co.step = step;
  co.tile_size = 16;
  co.band_rows = 32;
  return co;
}
BuildOptions small_build_options(int levels) {
  BuildOptions bo;
  bo.level_count = levels;
  bo.min_coarsest_side = 16;
  bo.threads = 2;
  bo.fit_rows = 96;
  bo.fill_band_rows = 8;  // stripe reads aligned to 8 rows (and 2^m): little slack beyond the D halo
  return bo;
}

// Every level's bands put together from the stripes equal the whole build's, band for band.
void check_bands_equal(const std::vector<std::vector<Band>>& joined,
                       const std::vector<std::vector<Band>>& whole) {
  for (size_t l = 0; l < joined.size(); ++l) {
    INFO("level " << l);
    REQUIRE(joined[l].size() == whole[l].size());
    for (size_t b = 0; b < joined[l].size(); ++b) CHECK(joined[l][b] == whole[l][b]);
  }
}

}  // namespace

TEST_CASE("shared coarse levels: stripes' level rows, coarse levels and fine levels equal the whole build",
          "[pyramid][stripes]") {
  struct Case {
    int64_t w, h;
    bool voids;
    double step;
  };
  const Case cases[] = {{257, 700, false, 1}, {301, 517, true, 3}, {120, 1201, false, 2}};
  for (const Case& c : cases) {
    const Heightmap map = rough(c.w, c.h, uint32_t(c.w) + 5, c.voids);
    PtcResidualCoder coder(small_band_coder(c.step));
    const BuildOptions bo = small_build_options(0);
    Recorder whole;
    const BuildResult ref = build_pyramid(map, bo, coder, whole);
    const int m = int(ref.header.levels.size()) - 1;
    REQUIRE(m >= 3);
    BuildOptions fixed = bo;
    fixed.use_fixed_filter = true;
    fixed.fixed_filter = ref.header.filter;
    for (int k : {0, m / 2, m - 1})
      for (int stripes : {1, 2, 3, 7}) {
        // With the T_{m-1} rows kept by the first pass (D's finest level runs once) or made again.
        const bool keep = stripes != 2;
        INFO(c.w << "x" << c.h << ", level " << k << ", " << stripes << " stripes, keep " << keep);
        const GridSize sk = ref.header.levels[size_t(k)];
        std::vector<int32_t> tk(size_t(sk.width * sk.height), 0);
        int64_t next = 0;
        std::vector<BuildStripe> cut;
        for (int s = 0; s < stripes; ++s) cut.push_back({s * c.h / stripes, (s + 1) * c.h / stripes});
        std::vector<StripeLevelRows> kept(cut.size());
        for (size_t i = 0; i < cut.size(); ++i) {
          const BuildStripe& s = cut[i];
          StripeLevelRows& rows = kept[i];
          auto reader = make_memory_band_reader(map, 37);
          // The first stripe fits D as the whole build does; the others get it fixed.
          const BuildResult r =
              build_stripe_level_rows(*reader, s.y0 == 0 ? bo : fixed, s, k, coder, rows, keep);
          CHECK(rows.fine_rows.empty() == (!keep || k == m - 1));
          CHECK(r.header.filter.taps == ref.header.filter.taps);
          REQUIRE(rows.width == sk.width);
          REQUIRE(rows.first_row == next);  // the shares tile the level
          std::copy(rows.rows.begin(), rows.rows.end(), tk.begin() + rows.first_row * sk.width);
          next += int64_t(rows.rows.size()) / sk.width;
        }
        REQUIRE(next == sk.height);
        Recorder coarse;
        CoarseRecorder that(coarse, k, sk);
        build_pyramid_coarse_levels(map.info, fixed, k, tk, coder, that);
        REQUIRE(that.rows_seen == sk.height);
        std::vector<std::vector<Band>> joined(whole.levels.size());
        for (int l = 0; l <= k; ++l) joined[size_t(l)] = coarse.levels[size_t(l)];
        for (size_t l = size_t(k) + 1; l < coarse.levels.size(); ++l) CHECK(coarse.levels[l].empty());
        for (size_t i = 0; i < cut.size(); ++i) {
          Recorder part;
          auto reader = make_memory_band_reader(map, 37);
          build_pyramid_stripe_fine_levels(*reader, fixed, cut[i], k, that.grid, coder, part, &kept[i]);
          const StripeLevelRows& other = kept[(i + 1) % cut.size()];
          if (!kept[i].fine_rows.empty() && !other.fine_rows.empty() &&
              other.fine_first_row != kept[i].fine_first_row) {  // another stripe's rows are refused
            Recorder unused;
            auto again = make_memory_band_reader(map, 37);
            CHECK_THROWS_AS(
                build_pyramid_stripe_fine_levels(*again, fixed, cut[i], k, that.grid, coder, unused, &other),
                std::invalid_argument);
          }
          for (int l = 0; l <= k; ++l) CHECK(part.levels[size_t(l)].empty());
          for (size_t l = size_t(k) + 1; l < part.levels.size(); ++l)
            joined[l].insert(joined[l].end(), part.levels[l].begin(), part.levels[l].end());
        }
        check_bands_equal(joined, whole.levels);
      }
    // Unusable splits.
    Recorder sink;
    auto reader = make_memory_band_reader(map);
    StripeLevelRows rows;
    CHECK_THROWS_AS(build_stripe_level_rows(*reader, bo, BuildStripe{0, c.h}, m, coder, rows),
                    std::invalid_argument);
    CHECK_THROWS_AS(build_pyramid_coarse_levels(map.info, bo, 0, std::vector<int32_t>(1), coder, sink),
                    std::invalid_argument);
    const GridSize s0 = ref.header.levels[0];
    CHECK_THROWS_AS(build_pyramid_coarse_levels(
                        map.info, bo, 0, std::vector<int32_t>(size_t(s0.width * s0.height)), coder, sink),
                    std::invalid_argument);
  }
}

TEST_CASE("stripe builds put together equal the whole build", "[pyramid][stripes]") {
  struct Case {
    int64_t w, h;
    bool voids;
    double step;
    int levels;
  };
  const Case cases[] = {{257, 700, false, 1, 0}, {301, 517, true, 3, 0}, {120, 1201, false, 2, 5}};
  for (const Case& c : cases) {
    const Heightmap map = rough(c.w, c.h, uint32_t(c.w), c.voids);
    PtcResidualCoder coder(small_band_coder(c.step));
    const BuildOptions bo = small_build_options(c.levels);
    Recorder whole;
    const BuildResult ref = build_pyramid(map, bo, coder, whole);
    for (int stripes : {1, 2, 3, 7}) {
      INFO(c.w << "x" << c.h << ", " << stripes << " stripes");
      std::vector<std::vector<Band>> joined(whole.levels.size());
      for (int k = 0; k < stripes; ++k) {
        // Stripe edges off the band grid too: ownership follows each band's first row.
        const BuildStripe s{k * c.h / stripes, (k + 1) * c.h / stripes};
        Recorder part;
        auto reader = make_memory_band_reader(map, 37);
        const BuildResult r = build_pyramid_stripe(*reader, bo, s, coder, part);
        CHECK(r.header.filter.taps == ref.header.filter.taps);
        for (size_t l = 0; l < part.levels.size(); ++l)
          joined[l].insert(joined[l].end(), part.levels[l].begin(), part.levels[l].end());
      }
      check_bands_equal(joined, whole.levels);
    }
    // An empty stripe codes nothing and fits the same D.
    Recorder none;
    auto reader = make_memory_band_reader(map);
    const BuildResult r = build_pyramid_stripe(*reader, bo, BuildStripe{c.h / 2, c.h / 2}, coder, none);
    CHECK(r.header.filter.taps == ref.header.filter.taps);
    CHECK(r.filter_report.summary() == ref.filter_report.summary());
    for (const auto& level : none.levels) CHECK(level.empty());
  }
  Recorder sink;
  const Heightmap map = rough(40, 40, 1, false);
  PtcResidualCoder coder(PtcCoderOptions{});
  auto reader = make_memory_band_reader(map);
  CHECK_THROWS_AS(build_pyramid_stripe(*reader, BuildOptions{}, BuildStripe{10, 41}, coder, sink),
                  std::invalid_argument);
}
