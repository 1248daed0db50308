// Fixed-point value noise + ridged multifractal. Integers only: floating-point contraction (FMA) or
// library functions could differ between machines, and the output must be bit-identical everywhere.
#include "readers/terrain_generator.h"

#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

namespace terrain {
namespace {

constexpr int64_t kOne = 1 << 16;  // fixed-point 1.0

uint64_t mix64(uint64_t z) {
  // splitmix64 finaliser: a well-distributed integer hash.
  z += 0x9e3779b97f4a7c15ull;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}

// Lattice value in [-32768, 32767] for integer lattice point (ix, iy) of one noise layer.
int64_t lattice(uint64_t layer_key, int64_t ix, int64_t iy) {
  uint64_t h = mix64(layer_key ^ mix64(uint64_t(ix) * 0x632be59bd9b4e019ull ^ mix64(uint64_t(iy))));
  return int64_t(h >> 48) - 32768;
}

int64_t floor_div(int64_t a, int64_t b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

// 3t^2 - 2t^3 for t in [0, kOne], in fixed point.
int64_t smooth(int64_t t) { return ((t * t) >> 16) * (3 * kOne - 2 * t) >> 16; }

int64_t lerp(int64_t a, int64_t b, int64_t s) { return a + (((b - a) * s) >> 16); }

// Smoothly interpolated value noise with lattice spacing `cell` pixels, in [-32768, 32767].
int64_t value_noise(uint64_t layer_key, int64_t x, int64_t y, int64_t cell) {
  int64_t ix = floor_div(x, cell), iy = floor_div(y, cell);
  int64_t sx = smooth((x - ix * cell) * kOne / cell);
  int64_t sy = smooth((y - iy * cell) * kOne / cell);
  int64_t top = lerp(lattice(layer_key, ix, iy), lattice(layer_key, ix + 1, iy), sx);
  int64_t bottom = lerp(lattice(layer_key, ix, iy + 1), lattice(layer_key, ix + 1, iy + 1), sx);
  return lerp(top, bottom, sy);
}

int64_t clamp_unit(int64_t v) { return std::clamp<int64_t>(v, 0, kOne); }

}  // namespace

Heightmap synthesize_terrain(const SynthOptions& options) {
  if (options.width <= 0 || options.height <= 0 || options.width > 65536 || options.height > 65536)
    throw Error(ErrorCode::DimensionMismatch, "synthetic terrain: size " + std::to_string(options.width) +
                                                  "x" + std::to_string(options.height) +
                                                  " must be between 1 and 65536 per side");
  Heightmap map;
  GridInfo& g = map.info;
  g.width = options.width;
  g.height = options.height;
  g.sample_type = SampleType::Int16;
  g.format = FileFormat::Raw;
  g.spacing_x = g.spacing_y = options.spacing_m;
  g.horizontal_units = "m";
  map.values.resize(size_t(g.width * g.height));

  // Continents span about half the larger side, so every output shows several of them.
  int64_t continent_cell = 16;
  while (continent_cell * 2 < std::max(g.width, g.height)) continent_cell *= 2;
  int ridge_octaves = 0;
  for (int64_t c = continent_cell / 2; c >= 2; c /= 2) ++ridge_octaves;
  const uint64_t seed_key = mix64(options.seed);
  auto key = [&](uint64_t layer) { return mix64(seed_key + layer * 0x9e3779b97f4a7c15ull); };
  const uint64_t continent_keys[3] = {key(1), key(2), key(3)};
  uint64_t ridge_keys[32];
  for (int k = 0; k < ridge_octaves && k < 32; ++k) ridge_keys[k] = key(100 + uint64_t(k));
  int64_t ridge_norm = 0;
  for (int k = 0; k < ridge_octaves; ++k) ridge_norm += kOne >> k;

  int64_t h_max = INT64_MIN;
  for (int64_t y = 0; y < g.height; ++y) {
    for (int64_t x = 0; x < g.width; ++x) {
      int64_t c = (4 * value_noise(continent_keys[0], x, y, continent_cell) +
                   2 * value_noise(continent_keys[1], x, y, continent_cell / 2) +
                   value_noise(continent_keys[2], x, y, continent_cell / 4)) /
                  7;
      int64_t base = c + 32768;  // [0, kOne)
      // Mountains rise where the continent is high; lowlands stay gentle.
      int64_t mask = smooth(clamp_unit((base - kOne * 30 / 100) * 100 / 30));
      int64_t ridges = 0, weight = kOne, hills = 0;
      int64_t cell = continent_cell / 2;
      for (int k = 0; k < ridge_octaves; ++k, cell /= 2) {
        int64_t n = value_noise(ridge_keys[k], x, y, cell);
        int64_t r = clamp_unit(kOne - 2 * (n < 0 ? -n : n));
        r = (r * r) >> 16;       // sharpen the crests
        r = (r * weight) >> 16;  // fine ridges grow on coarse crests, not in the valleys
        weight = clamp_unit(r * 3 / 2);
        ridges += r >> k;
        hills += n >> (k + 1);  // plain fBm: rolling relief everywhere
      }
      ridges = ridges * kOne / ridge_norm;
      int64_t h = base * 35 / 100 + ((mask * ridges) >> 16) * 65 / 100 + hills / 6;
      h_max = std::max(h_max, h);
      map.values[size_t(y * g.width + x)] = double(h);  // exact: |h| < 2^17
    }
  }
  // A quarter of the area (the lowest samples) becomes flat sea at 0, like coastal SRTM tiles; the
  // rest is stretched so that the highest sample is 3100 m, whatever relief the seed drew.
  std::vector<double> sorted = map.values;
  auto quartile = sorted.begin() + std::ptrdiff_t(sorted.size() / 4);
  std::nth_element(sorted.begin(), quartile, sorted.end());
  const int64_t sea = int64_t(*quartile);
  const int64_t range = std::max<int64_t>(1, h_max - sea);
  for (double& v : map.values) v = double(std::max<int64_t>(0, (int64_t(v) - sea) * 3100 / range));
  return map;
}

}  // namespace terrain
