// libcodec tests: lossless round trips, quantiser error predictions, max-error guarantee, region
// decoding, and rejection of corrupted / truncated streams.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "codec/codec.h"
#include "core/bytes.h"
#include "readers/heightmap.h"
#include "shared_data.h"
// Internal headers, for the SIMD == scalar checks of the inverse transform.
#include "codec/internal/lapped_kernels.h"
#include "codec/internal/lapped_transform.h"
#include "codec/internal/rlgr.h"

namespace {

struct Image {
  int64_t width = 0, height = 0;
  std::vector<int32_t> samples;
  int32_t at(int64_t x, int64_t y) const { return samples[size_t(y * width + x)]; }
};

std::vector<uint8_t> encode_image(const Image& img, const codec::EncodeOptions& options,
                                  std::vector<int32_t>* recon = nullptr) {
  codec::Scratch scratch;
  std::vector<uint8_t> out(codec::encode_bound(img.width, img.height, options));
  REQUIRE(!out.empty());
  size_t written = 0;
  if (recon) recon->assign(img.samples.size(), 0);
  const codec::Status s =
      codec::encode(img.samples.data(), img.width, img.width, img.height, options, out.data(), out.size(),
                    &written, scratch, recon ? recon->data() : nullptr, img.width);
  REQUIRE(codec::status_name(s) == std::string("ok"));
  out.resize(written);
  return out;
}

std::vector<int32_t> decode_image(const std::vector<uint8_t>& stream, const Image& like) {
  codec::Scratch scratch;
  std::vector<int32_t> out(like.samples.size(), 0);
  const codec::Status s = codec::decode(stream.data(), stream.size(), out.data(), like.width, scratch);
  REQUIRE(codec::status_name(s) == std::string("ok"));
  return out;
}

// Index of the first differing sample, or -1 (Catch would print whole vectors on failure).
int64_t first_difference(const std::vector<int32_t>& a, const std::vector<int32_t>& b) {
  if (a.size() != b.size()) return int64_t(std::min(a.size(), b.size()));
  for (size_t i = 0; i < a.size(); ++i)
    if (a[i] != b[i]) return int64_t(i);
  return -1;
}

// Integer grid of a shared DEM: native values when they are integers, else tenths (Terrain-RGB).
Image load_dem(const std::string& path) {
  terrain::ReadOptions options;
  if (path.find("terrainrgb") != std::string::npos) options.terrain_rgb = true;
  const terrain::Heightmap map = terrain::read_heightmap(path, options);
  Image img{map.width(), map.height(), std::vector<int32_t>(map.values.size())};
  bool integral = true;
  for (double v : map.values) integral = integral && v == std::floor(v);
  for (size_t i = 0; i < map.values.size(); ++i)
    img.samples[i] = int32_t(std::lround(integral ? map.values[i] : map.values[i] * 10.0));
  return img;
}

Image crop(const Image& src, int64_t x0, int64_t y0, int64_t w, int64_t h) {
  Image out{w, h, std::vector<int32_t>(size_t(w * h))};
  for (int64_t y = 0; y < h; ++y)
    for (int64_t x = 0; x < w; ++x) out.samples[size_t(y * w + x)] = src.at(x0 + x, y0 + y);
  return out;
}

// Residual-like image: Laplacian noise (scale b) with rare outliers up to +-2^20.
Image residual_like(int64_t w, int64_t h, double b, uint32_t seed) {
  std::mt19937 rng(seed);
  std::exponential_distribution<double> expo(1.0 / b);
  std::uniform_int_distribution<int> coin(0, 1), rare(0, 999);
  std::uniform_int_distribution<int32_t> big(-codec::kMaxAbsSample, codec::kMaxAbsSample);
  Image img{w, h, std::vector<int32_t>(size_t(w * h))};
  for (auto& v : img.samples) {
    v = int32_t(std::lround(expo(rng))) * (coin(rng) ? 1 : -1);
    if (rare(rng) == 0) v = big(rng);
  }
  return img;
}

Image uniform_noise(int64_t w, int64_t h, int32_t amplitude, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int32_t> dist(-amplitude, amplitude);
  Image img{w, h, std::vector<int32_t>(size_t(w * h))};
  for (auto& v : img.samples) v = dist(rng);
  return img;
}

struct ErrorStats {
  double rms = 0;
  int64_t max_abs = 0;
};

ErrorStats error_stats(const Image& img, const std::vector<int32_t>& decoded) {
  double sum = 0;
  int64_t worst = 0;
  for (size_t i = 0; i < decoded.size(); ++i) {
    const int64_t e = int64_t(decoded[i]) - img.samples[i];
    sum += double(e) * double(e);
    worst = std::max<int64_t>(worst, e < 0 ? -e : e);
  }
  return {std::sqrt(sum / double(decoded.size())), worst};
}

// A max-error stream's options: tiles of tile_size, quantiser step `step`, every sample within
// max_error.
codec::EncodeOptions max_error_options(uint32_t tile_size, double step, uint32_t max_error) {
  codec::EncodeOptions options;
  options.tile_size = tile_size;
  options.step = step;
  options.bound_max_error = true;
  options.max_error = max_error;
  return options;
}

}  // namespace

TEST_CASE("lossless round trip at step 1 on every shared DEM", "[codec][data]") {
  const auto dems = testdata::all_dems();
  for (const auto& path : dems) {
    INFO(path);
    const Image img = load_dem(path);
    REQUIRE(img.width > 0);
    codec::EncodeOptions options;  // step 1
    std::vector<int32_t> recon;
    const auto stream = encode_image(img, options, &recon);
    CHECK(first_difference(decode_image(stream, img), img.samples) == -1);
    CHECK(first_difference(recon, img.samples) == -1);
    // Every DEM in the set must compress well below its 16-bit source (the 0.1 m Puget Sound PNG is
    // the hardest, near 9.6 bits/sample).
    CHECK(double(stream.size()) * 8.0 / double(img.samples.size()) < 11.0);
  }
}

TEST_CASE("lossless round trip on residual-like and extreme synthetic data", "[codec]") {
  for (uint32_t tile : {16u, 64u, 128u}) {
    codec::EncodeOptions options;
    options.tile_size = tile;
    const Image residual = residual_like(300, 211, 3.0, 7 + tile);
    CHECK(first_difference(decode_image(encode_image(residual, options), residual), residual.samples) == -1);
  }
  {
    // 512-sample tiles: four tile shapes, two of them above the decoder's cached-layout size (the
    // decoder keeps one layout for those and rebuilds it when the shape changes).
    codec::EncodeOptions options;
    options.tile_size = 512;
    const Image residual = residual_like(700, 600, 3.0, 11);
    CHECK(first_difference(decode_image(encode_image(residual, options), residual), residual.samples) == -1);
    options.step = 5;
    std::vector<int32_t> recon;
    const auto stream = encode_image(residual, options, &recon);
    CHECK(first_difference(decode_image(stream, residual), recon) == -1);
  }
  const Image noise = uniform_noise(97, 131, codec::kMaxAbsSample, 3);
  CHECK(first_difference(decode_image(encode_image(noise, {}), noise), noise.samples) == -1);
  // Largest possible steps between neighbours: +-2^20 checkerboard and stripes.
  Image checker{70, 50, std::vector<int32_t>(70 * 50)};
  for (int64_t y = 0; y < 50; ++y)
    for (int64_t x = 0; x < 70; ++x)
      checker.samples[size_t(y * 70 + x)] = ((x + y) & 1) ? codec::kMaxAbsSample : -codec::kMaxAbsSample;
  CHECK(first_difference(decode_image(encode_image(checker, {}), checker), checker.samples) == -1);
  Image stripes = checker;
  for (int64_t y = 0; y < 50; ++y)
    for (int64_t x = 0; x < 70; ++x)
      stripes.samples[size_t(y * 70 + x)] =
          ((x / 2 + y / 3) & 1) ? codec::kMaxAbsSample : -codec::kMaxAbsSample;
  CHECK(first_difference(decode_image(encode_image(stripes, {}), stripes), stripes.samples) == -1);
  // Lossy at a large step on extreme data stays consistent with the encoder's reconstruction.
  codec::EncodeOptions lossy;
  lossy.step = 4096;
  std::vector<int32_t> recon;
  const auto stream = encode_image(checker, lossy, &recon);
  CHECK(first_difference(decode_image(stream, checker), recon) == -1);
}

TEST_CASE("lossy coding of extreme data at both sample precisions stays close", "[codec]") {
  // Samples at the edges of the two fraction-bit ranges (+-2^18: 4 bits, +-2^20: 2 bits) in the
  // patterns with the largest transform intermediates: if any lifting step overflowed, the decoded
  // error would be of the order of the samples rather than of the step.
  for (int32_t range : {int32_t(1) << 18, codec::kMaxAbsSample}) {
    Image checker{70, 50, std::vector<int32_t>(70 * 50)};
    for (int64_t y = 0; y < 50; ++y)
      for (int64_t x = 0; x < 70; ++x) checker.samples[size_t(y * 70 + x)] = ((x + y) & 1) ? range : -range;
    Image stripes = checker;
    for (int64_t y = 0; y < 50; ++y)
      for (int64_t x = 0; x < 70; ++x)
        stripes.samples[size_t(y * 70 + x)] = ((x / 2 + y / 3) & 1) ? range : -range;
    Image noise = uniform_noise(70, 50, range, 11);
    for (const Image* img : {&checker, &stripes, &noise})
      for (double step : {1.5, 3.0, 64.0}) {
        codec::EncodeOptions lossy;
        lossy.step = step;
        std::vector<int32_t> recon;
        const auto stream = encode_image(*img, lossy, &recon);
        const auto decoded = decode_image(stream, *img);
        CHECK(first_difference(decoded, recon) == -1);
        const ErrorStats e = error_stats(*img, decoded);
        INFO("range " << range << " step " << step);
        CHECK(e.max_abs <= 16 * step + 4);
      }
  }
}

TEST_CASE("odd sizes round trip losslessly and lossily", "[codec]") {
  std::vector<std::pair<int64_t, int64_t>> sizes;
  for (int64_t h = 1; h <= 7; ++h)
    for (int64_t w = 1; w <= 7; ++w) sizes.push_back({w, h});
  sizes.push_back({1, 1000});
  sizes.push_back({1000, 1});
  sizes.push_back({65, 129});
  for (auto [w, h] : sizes) {
    INFO(w << "x" << h);
    const Image img = residual_like(w, h, 20.0, uint32_t(w * 1000 + h));
    CHECK(first_difference(decode_image(encode_image(img, {}), img), img.samples) == -1);
    codec::EncodeOptions lossy;
    lossy.step = 5;
    std::vector<int32_t> recon;
    const auto stream = encode_image(img, lossy, &recon);
    CHECK(first_difference(decode_image(stream, img), recon) == -1);
    codec::HeaderInfo header;
    REQUIRE(codec::read_header(stream.data(), stream.size(), &header) == codec::Status::Ok);
    CHECK(header.width == w);
    CHECK(header.height == h);
    CHECK(header.step == 5.0);
  }
}

// Prediction (codec.h): rms = S * sqrt(1/12 + 1/64) = 0.315 S when coefficients spread over many
// steps (uniform noise with amplitude >> S): checked within 15 % (plus 0.3 for integer rounding in the
// lifting steps). Smooth DEMs put many coefficients in the dead zone, so there the prediction is an
// upper bound (checked with 10 % slack). Max error has no hard bound outside max-error mode; errors
// are near Gaussian, so over these sizes the maximum stays below 3 S + 2 (about 9.5 sigma).
TEST_CASE("rms and max error at steps 2..64 follow the quantiser prediction", "[codec]") {
  const Image noise = uniform_noise(256, 256, 1 << 16, 11);
  for (double step : {2.0, 3.0, 5.0, 8.0, 16.0, 32.0, 64.0}) {
    INFO("step " << step);
    codec::EncodeOptions options;
    options.step = step;
    const ErrorStats e = error_stats(noise, decode_image(encode_image(noise, options), noise));
    CHECK(std::abs(e.rms - codec::predicted_rms(step)) <= 0.15 * codec::predicted_rms(step) + 0.3);
    CHECK(double(e.max_abs) <= 3.0 * step + 2.0);
    CHECK(codec::step_for_target_rms(codec::predicted_rms(step)) == Approx(step));
  }
  const auto dems = testdata::all_dems();
  for (size_t d = 0; d < dems.size(); d += 4) {
    const Image dem = crop(load_dem(dems[d]), 100, 100, 384, 320);
    size_t previous_size = SIZE_MAX;
    for (double step : {1.0, 2.0, 4.0, 16.0, 64.0}) {
      INFO(dems[d] << " step " << step);
      codec::EncodeOptions options;
      options.step = step;
      const auto stream = encode_image(dem, options);
      const ErrorStats e = error_stats(dem, decode_image(stream, dem));
      CHECK(e.rms <= 1.1 * codec::predicted_rms(step) + 0.3);
      CHECK(double(e.max_abs) <= 3.0 * step + 2.0);
      // A coarser step never costs more bits (past the header, whose step varint may grow a byte).
      codec::HeaderInfo header;
      REQUIRE(codec::read_header(stream.data(), stream.size(), &header) == codec::Status::Ok);
      CHECK(stream.size() - header.data_offset <= previous_size);
      previous_size = stream.size() - header.data_offset;
    }
  }
}

TEST_CASE("max-error mode never exceeds E", "[codec]") {
  std::vector<Image> images;
  const auto dems = testdata::all_dems();
  for (size_t d = 0; d < dems.size(); d += 5) images.push_back(crop(load_dem(dems[d]), 400, 300, 300, 260));
  images.push_back(uniform_noise(150, 90, 5000, 5));
  images.push_back(residual_like(211, 77, 4.0, 9));
  for (const Image& img : images) {
    for (uint32_t e : {0u, 1u, 2u, 5u, 17u, 100u}) {
      for (double step : {0.0, 8.0}) {
        INFO("E " << e << " step " << step << " size " << img.width << "x" << img.height);
        codec::EncodeOptions options;
        options.bound_max_error = true;
        options.max_error = e;
        options.step = step;  // 0 = automatic (2E)
        std::vector<int32_t> recon;
        const auto stream = encode_image(img, options, &recon);
        const auto decoded = decode_image(stream, img);
        CHECK(first_difference(decoded, recon) == -1);
        CHECK(error_stats(img, decoded).max_abs <= int64_t(e));
        codec::HeaderInfo header;
        REQUIRE(codec::read_header(stream.data(), stream.size(), &header) == codec::Status::Ok);
        CHECK(header.step == (step > 0 ? step : std::max(1.0, 2.0 * e)));  // 0 = automatic 2E
      }
    }
  }
}

// A uniformly random non-empty rectangle inside img.
codec::Rect random_rect(std::mt19937& rng, const Image& img) {
  codec::Rect r;
  r.width = std::uniform_int_distribution<int64_t>(1, img.width)(rng);
  r.height = std::uniform_int_distribution<int64_t>(1, img.height)(rng);
  r.x0 = std::uniform_int_distribution<int64_t>(0, img.width - r.width)(rng);
  r.y0 = std::uniform_int_distribution<int64_t>(0, img.height - r.height)(rng);
  return r;
}

TEST_CASE("decode_region equals the same window of a full decode", "[codec]") {
  const Image img = residual_like(333, 257, 6.0, 21);
  std::mt19937 rng(5);
  for (int variant = 0; variant < 3; ++variant) {
    codec::EncodeOptions options;
    options.tile_size = variant == 0 ? 64 : variant == 1 ? 16 : 128;
    options.step = variant == 1 ? 1.0 : 6.0;
    options.bound_max_error = variant == 2;
    options.max_error = 3;
    const auto stream = encode_image(img, options);
    const auto full = decode_image(stream, img);
    codec::Decoder decoder;
    REQUIRE(decoder.open(stream.data(), stream.size()) == codec::Status::Ok);
    codec::Scratch scratch;
    for (int trial = 0; trial < 40; ++trial) {
      const codec::Rect r = random_rect(rng, img);
      const ptrdiff_t stride = r.width + 3;
      std::vector<int32_t> window(size_t(stride * r.height), 12345);
      REQUIRE(decoder.decode_region(r, window.data(), stride, scratch) == codec::Status::Ok);
      bool same = true;
      for (int64_t y = 0; y < r.height; ++y)
        for (int64_t x = 0; x < r.width; ++x)
          same = same && window[size_t(y * stride + x)] == full[size_t((r.y0 + y) * img.width + r.x0 + x)];
      for (int64_t y = 0; y < r.height; ++y)  // padding past the row width is untouched
        for (int64_t x = r.width; x < stride; ++x) same = same && window[size_t(y * stride + x)] == 12345;
      CHECK(same);
    }
    std::vector<int32_t> one(1);
    CHECK(decoder.decode_region({img.width, 0, 1, 1}, one.data(), 1, scratch) ==
          codec::Status::InvalidArgument);
    CHECK(decoder.decode_region({0, 0, 0, 1}, one.data(), 1, scratch) == codec::Status::InvalidArgument);
  }
}

TEST_CASE("decode_region_add adds (saturating) what decode_region writes, and a damaged tile adds nothing",
          "[codec]") {
  const Image img = residual_like(333, 257, 6.0, 22);
  std::mt19937 rng(6);
  std::uniform_int_distribution<int32_t> any(INT32_MIN, INT32_MAX), small(-100000, 100000);
  for (int variant = 0; variant < 4; ++variant) {
    codec::EncodeOptions options;
    options.tile_size = variant == 1 ? 16 : 64;
    options.step = variant == 1 ? 1.0 : variant == 3 ? 2.5 : 6.0;  // 2.5: fraction bits
    options.bound_max_error = variant == 2;                        // spatial and corrected tiles
    options.max_error = 3;
    const auto stream = encode_image(img, options);
    codec::Decoder decoder;
    REQUIRE(decoder.open(stream.data(), stream.size()) == codec::Status::Ok);
    codec::Scratch scratch;
    for (int trial = 0; trial < 12; ++trial) {
      const codec::Rect r = random_rect(rng, img);
      const ptrdiff_t stride = r.width + 3;
      std::vector<int32_t> base(size_t(stride * r.height)), decoded(base.size());
      // Near the int32 bounds half the time, so that the sums saturate.
      for (auto& v : base) v = trial % 2 ? any(rng) : small(rng);
      std::vector<int32_t> sum = base;
      REQUIRE(decoder.decode_region(r, decoded.data(), stride, scratch) == codec::Status::Ok);
      REQUIRE(decoder.decode_region_add(r, sum.data(), stride, scratch) == codec::Status::Ok);
      bool same = true;
      for (int64_t y = 0; y < r.height; ++y)
        for (int64_t x = 0; x < stride; ++x) {
          const size_t i = size_t(y * stride + x);
          const int64_t want = x < r.width
                                   ? std::clamp<int64_t>(int64_t(base[i]) + decoded[i], INT32_MIN, INT32_MAX)
                                   : base[i];
          same = same && sum[i] == want;
        }
      CHECK(same);
    }
  }
  // A damaged payload byte (the tile row's CRC fails): a one-tile call leaves dst as it was. The last
  // tile (13 x 1) gets samples far beyond the step, so that it is coded (small ones may be left empty
  // by the encoder's rate-distortion test).
  Image marked = img;
  for (int64_t x = (img.width - 1) / 64 * 64; x < img.width; ++x)
    marked.samples[size_t((img.height - 1) * img.width + x)] = 1000 + int32_t(x);
  codec::EncodeOptions options;
  options.tile_size = 64;
  options.step = 6.0;
  auto stream = encode_image(marked, options);
  codec::Decoder intact;
  REQUIRE(intact.open(stream.data(), stream.size()) == codec::Status::Ok);
  const codec::TileEntry& last = intact.index().back();
  REQUIRE(last.size > 0);
  stream[size_t(last.offset + last.size / 2)] ^= 0x10;
  codec::Decoder damaged;
  REQUIRE(damaged.open(stream.data(), stream.size()) == codec::Status::Ok);
  codec::Scratch scratch;
  const codec::Rect tile{(img.width - 1) / 64 * 64, (img.height - 1) / 64 * 64, 1, 1};
  std::vector<int32_t> dst(1, 777);
  CHECK(damaged.decode_region_add(tile, dst.data(), 1, scratch) != codec::Status::Ok);
  CHECK(dst[0] == 777);
}

TEST_CASE("decode_region reads only the tiles it intersects", "[codec]") {
  const Image img = residual_like(256, 192, 4.0, 31);
  codec::EncodeOptions options;
  options.tile_size = 64;
  auto stream = encode_image(img, options);
  codec::HeaderInfo header;
  REQUIRE(codec::read_header(stream.data(), stream.size(), &header) == codec::Status::Ok);
  std::vector<codec::TileEntry> index;
  std::vector<codec::RowChecksum> rows;
  REQUIRE(codec::read_tile_index(stream.data(), stream.size(), header, &index, &rows) == codec::Status::Ok);
  REQUIRE(index.size() == size_t(header.tile_count()));  // noise: no empty tiles
  // Damage the payload of tile (3, 2) only; the CRC of tile row 2 no longer matches.
  const auto& damaged = index[size_t(2 * header.tiles_x + 3)];
  stream[size_t(damaged.offset + damaged.size / 2)] ^= 0x10;
  codec::Scratch scratch;
  std::vector<int32_t> window(100 * 100);
  CHECK(codec::decode_region(stream.data(), stream.size(), {10, 20, 100, 100}, window.data(), 100, scratch) ==
        codec::Status::Ok);
  bool same = true;
  for (int64_t y = 0; y < 100; ++y)
    for (int64_t x = 0; x < 100; ++x) same = same && window[size_t(y * 100 + x)] == img.at(10 + x, 20 + y);
  CHECK(same);
  CHECK(codec::decode_region(stream.data(), stream.size(), {190, 130, 10, 10}, window.data(), 10, scratch) ==
        codec::Status::ChecksumMismatch);
}

TEST_CASE("header and tile index are readable without decoding", "[codec]") {
  const Image img = residual_like(130, 70, 2.0, 4);
  const auto stream = encode_image(img, max_error_options(32, 2.5, 4));
  codec::HeaderInfo header;
  REQUIRE(codec::read_header(stream.data(), stream.size(), &header) == codec::Status::Ok);
  CHECK(header.version == codec::kOldestFormatVersion);  // lapped streams keep version 4
  CHECK(header.tiles_x == 5);
  CHECK(header.tiles_y == 3);
  CHECK(header.step == 2.5);
  CHECK(header.bound_max_error);
  CHECK(header.max_error == 4);
  std::vector<codec::TileEntry> index;
  std::vector<codec::RowChecksum> rows;
  REQUIRE(codec::read_tile_index(stream.data(), stream.size(), header, &index, &rows) == codec::Status::Ok);
  uint64_t expected = header.data_offset;
  int64_t tiles = 0;
  for (const auto& e : index) {  // tiles are stored back to back in raster order
    CHECK(e.first_tile == tiles);
    CHECK(e.offset == expected);
    expected += e.size;
    tiles += e.count;
  }
  CHECK(tiles == header.tile_count());
  CHECK(expected == header.index_offset);  // the index follows the payloads
  CHECK(header.index_offset < stream.size());
  REQUIRE(rows.size() == 3);  // one checksum per tile row with payload
  for (size_t r = 0; r < rows.size(); ++r) CHECK(rows[r].tile_row == int64_t(r));
  CHECK(rows[0].offset == header.data_offset);
  CHECK(rows[2].offset + rows[2].size == header.index_offset);
}

TEST_CASE("truncated and corrupted streams are rejected", "[codec]") {
  const Image img = residual_like(40, 35, 3.0, 8);
  const auto stream = encode_image(img, max_error_options(16, 2, 2));
  codec::Scratch scratch;
  std::vector<int32_t> out(img.samples.size());
  for (size_t len = 0; len < stream.size(); ++len) {
    INFO("length " << len);
    CHECK(codec::decode(stream.data(), len, out.data(), img.width, scratch) != codec::Status::Ok);
  }
  std::mt19937 rng(99);
  int rejected = 0, flips = 0;
  for (size_t byte = 0; byte < stream.size(); ++byte) {
    for (int trial = 0; trial < 2; ++trial) {
      auto bad = stream;
      bad[byte] ^= uint8_t(1u << std::uniform_int_distribution<int>(0, 7)(rng));
      ++flips;
      rejected += codec::decode(bad.data(), bad.size(), out.data(), img.width, scratch) != codec::Status::Ok;
    }
  }
  CHECK(rejected == flips);
  // Multi-byte garbage anywhere in the stream.
  for (int trial = 0; trial < 300; ++trial) {
    auto bad = stream;
    const size_t at = std::uniform_int_distribution<size_t>(0, stream.size() - 1)(rng);
    const size_t n = std::min<size_t>(bad.size() - at, 1 + trial % 40);
    for (size_t i = 0; i < n; ++i) bad[at + i] = uint8_t(rng());
    if (bad == stream) continue;
    CHECK(codec::decode(bad.data(), bad.size(), out.data(), img.width, scratch) != codec::Status::Ok);
  }
  for (uint8_t version : {3, 9}) {  // version 3 (the previous format) and unknown ones
    auto wrong_version = stream;
    wrong_version[4] = version;
    CHECK(codec::decode(wrong_version.data(), wrong_version.size(), out.data(), img.width, scratch) ==
          codec::Status::UnsupportedVersion);
  }
  auto wrong_magic = stream;
  wrong_magic[0] = 'X';
  CHECK(codec::decode(wrong_magic.data(), wrong_magic.size(), out.data(), img.width, scratch) ==
        codec::Status::Corrupt);
}

// Zero except for a few blocks of residual-like noise: whole empty tiles, runs of them across tile
// rows, empty tile rows and near-zero tiles (|value| <= 1) beside non-empty ones.
Image mostly_zero(int64_t w, int64_t h, uint32_t seed) {
  Image img = residual_like(w, h, 5.0, seed);
  for (int64_t y = 0; y < h; ++y)
    for (int64_t x = 0; x < w; ++x) {
      const bool island = (x >= 20 && x < 45 && y >= 5 && y < 30) || (x >= 70 && y >= 60 && y < 70);
      const bool ripple = y >= 90 && y < 100;  // within +-1: empty at E >= 1 and at lossy steps
      int32_t& v = img.samples[size_t(y * w + x)];
      v = island ? v : ripple ? int32_t((x + y) % 3) - 1 : 0;
    }
  return img;
}

TEST_CASE("empty tiles: no payload, exact zeros, region decode equals full decode", "[codec]") {
  const Image img = mostly_zero(150, 120, 41);
  const Image noise = residual_like(150, 120, 5.0, 41);
  std::mt19937 rng(8);
  for (int variant = 0; variant < 3; ++variant) {
    INFO("variant " << variant);
    codec::EncodeOptions options;
    options.tile_size = 16;
    options.step = variant == 1 ? 4.0 : 1.0;
    options.bound_max_error = variant == 2;
    options.max_error = 1;
    std::vector<int32_t> recon;
    const auto stream = encode_image(img, options, &recon);
    const auto full = decode_image(stream, img);
    CHECK(first_difference(full, recon) == -1);
    if (variant == 0) CHECK(first_difference(full, img.samples) == -1);
    if (variant == 2) CHECK(error_stats(img, full).max_abs <= 1);
    // Samples outside the islands (and, except losslessly, the ripple) decode to exact zeros.
    bool zeros = true;
    for (int64_t y = 0; y < img.height; ++y)
      for (int64_t x = 0; x < img.width; ++x) {
        const bool tile_with_data = (x >= 16 && x < 48 && y < 32) || (x >= 64 && y >= 48 && y < 80) ||
                                    (variant == 0 && y >= 80 && y < 112);
        if (!tile_with_data) zeros = zeros && full[size_t(y * img.width + x)] == 0;
      }
    CHECK(zeros);
    codec::HeaderInfo header;
    REQUIRE(codec::read_header(stream.data(), stream.size(), &header) == codec::Status::Ok);
    std::vector<codec::TileEntry> index;
    std::vector<codec::RowChecksum> rows;
    REQUIRE(codec::read_tile_index(stream.data(), stream.size(), header, &index, &rows) == codec::Status::Ok);
    int64_t empty = 0;
    for (const auto& e : index) empty += e.size == 0 ? e.count : 0;
    // 80 tiles: the islands touch 16, the ripple rows 20 more (empty unless lossless).
    CHECK(index.size() < size_t(header.tile_count()));  // runs of empty tiles are single records
    CHECK(empty == (variant == 0 ? 44 : 64));
    CHECK(stream.size() * 4 < encode_image(noise, options).size());
    codec::Decoder decoder;
    REQUIRE(decoder.open(stream.data(), stream.size()) == codec::Status::Ok);
    codec::Scratch scratch;
    for (int trial = 0; trial < 60; ++trial) {
      const codec::Rect r = random_rect(rng, img);
      std::vector<int32_t> window(size_t(r.width * r.height), 777);
      REQUIRE(decoder.decode_region(r, window.data(), r.width, scratch) == codec::Status::Ok);
      bool same = true;
      for (int64_t y = 0; y < r.height; ++y)
        for (int64_t x = 0; x < r.width; ++x)
          same = same && window[size_t(y * r.width + x)] == full[size_t((r.y0 + y) * img.width + r.x0 + x)];
      CHECK(same);
    }
  }
}

TEST_CASE("an all-zero or near-zero image is a stream of a few bytes", "[codec]") {
  Image zero{1000, 700, std::vector<int32_t>(700000, 0)};
  Image small = zero;
  for (size_t i = 0; i < small.samples.size(); ++i) small.samples[i] = int32_t(i % 5) - 2;  // within +-2
  for (uint32_t tile : {16u, 64u}) {
    codec::EncodeOptions lossless;
    lossless.tile_size = tile;
    codec::EncodeOptions bounded = lossless;
    bounded.bound_max_error = true;
    bounded.max_error = 2;
    for (const auto& [img, options] : {std::pair{&zero, lossless}, std::pair{&small, bounded}}) {
      std::vector<int32_t> recon;
      const auto stream = encode_image(*img, options, &recon);
      CHECK(stream.size() <= 24);
      codec::HeaderInfo header;
      REQUIRE(codec::read_header(stream.data(), stream.size(), &header) == codec::Status::Ok);
      CHECK(header.empty());
      const auto decoded = decode_image(stream, *img);
      CHECK(first_difference(decoded, recon) == -1);
      CHECK(first_difference(decoded, zero.samples) == -1);
    }
  }
}

TEST_CASE("every corrupted byte of a stream with empty tiles is rejected", "[codec]") {
  const Image img = mostly_zero(100, 100, 77);  // 16-sample tiles: runs, empty rows, row checksums
  for (bool bounded : {false, true}) {
    codec::EncodeOptions options;
    options.tile_size = 16;
    options.bound_max_error = bounded;
    options.max_error = 1;
    const auto stream = encode_image(img, options);
    INFO("bounded " << bounded << ", " << stream.size() << " bytes");
    codec::Scratch scratch;
    std::vector<int32_t> out(img.samples.size());
    for (size_t len = 0; len < stream.size(); ++len)
      CHECK(codec::decode(stream.data(), len, out.data(), img.width, scratch) != codec::Status::Ok);
    int accepted = 0;
    for (size_t byte = 0; byte < stream.size(); ++byte)
      for (int bit = 0; bit < 8; ++bit) {
        auto bad = stream;
        bad[byte] ^= uint8_t(1u << bit);
        accepted +=
            codec::decode(bad.data(), bad.size(), out.data(), img.width, scratch) == codec::Status::Ok;
      }
    CHECK(accepted == 0);
    auto longer = stream;  // the CRC is the stream's last 4 bytes: trailing bytes are not a stream
    longer.push_back(0);
    CHECK(codec::decode(longer.data(), longer.size(), out.data(), img.width, scratch) != codec::Status::Ok);
  }
}

TEST_CASE("a forged stream of 2^50 empty tiles opens without a per-tile index", "[codec]") {
  // Hand-made version-4 stream (docs/codec.md): 2^40 x 2^20 samples in 32-sample tiles, lossless, no
  // payload, one record for a run of every tile, then the CRC of header and index.
  std::vector<uint8_t> s = {'T', 'P', 'T', 'C', uint8_t(codec::kOldestFormatVersion), 0};
  const int64_t tiles = (int64_t(1) << 35) * (int64_t(1) << 15);
  for (uint64_t v :
       {uint64_t(1) << 40, uint64_t(1) << 20, uint64_t(2), uint64_t(0), uint64_t(256), uint64_t(0)})
    terrain::bytes::put_varint(s, v);
  const size_t header_size = s.size();
  terrain::bytes::put_varint(s, (uint64_t(tiles - 1) << 1) | 1);
  const uint32_t crc =
      codec::crc32c(s.data() + header_size, s.size() - header_size, codec::crc32c(s.data(), header_size));
  for (int i = 0; i < 4; ++i) s.push_back(uint8_t(crc >> (8 * i)));
  codec::Decoder decoder;
  REQUIRE(decoder.open(s.data(), s.size()) == codec::Status::Ok);
  CHECK(decoder.header().tile_count() == tiles);
  CHECK(decoder.header().empty());
  CHECK(decoder.index().size() == 1);
  codec::Scratch scratch;
  std::vector<int32_t> window(40 * 40, 5);
  const codec::Rect far{(int64_t(1) << 40) - 40, (int64_t(1) << 20) - 40, 40, 40};
  REQUIRE(decoder.decode_region(far, window.data(), 40, scratch) == codec::Status::Ok);
  CHECK(std::all_of(window.begin(), window.end(), [](int32_t v) { return v == 0; }));
  // The same header with a run one tile short of the image: the index does not cover it.
  std::vector<uint8_t> short_run(s.begin(), s.begin() + long(header_size));
  terrain::bytes::put_varint(short_run, (uint64_t(tiles - 2) << 1) | 1);
  const uint32_t crc2 = codec::crc32c(short_run.data() + header_size, short_run.size() - header_size,
                                      codec::crc32c(short_run.data(), header_size));
  for (int i = 0; i < 4; ++i) short_run.push_back(uint8_t(crc2 >> (8 * i)));
  CHECK(decoder.open(short_run.data(), short_run.size()) != codec::Status::Ok);
}

TEST_CASE("bad arguments return a status", "[codec]") {
  Image img = residual_like(20, 20, 2.0, 1);
  codec::Scratch scratch;
  std::vector<uint8_t> out(codec::encode_bound(20, 20, {}));
  size_t written = 0;
  const auto run = [&](const codec::EncodeOptions& o, size_t capacity) {
    return codec::encode(img.samples.data(), 20, 20, 20, o, out.data(), capacity, &written, scratch);
  };
  codec::EncodeOptions o;
  CHECK(run(o, out.size()) == codec::Status::Ok);
  const size_t needed = written;
  CHECK(run(o, 100) == codec::Status::BufferTooSmall);
  CHECK(written == 0);
  CHECK(run(o, needed - 1) == codec::Status::BufferTooSmall);
  CHECK(run(o, needed) == codec::Status::Ok);
  o.step = 0.5;
  CHECK(run(o, out.size()) == codec::Status::InvalidArgument);
  o = {};
  o.tile_size = 24;
  CHECK(run(o, out.size()) == codec::Status::InvalidArgument);
  CHECK(codec::encode_bound(20, 20, o) == 0);
  o = {};
  o.bound_max_error = true;  // the largest E is accepted and its automatic step stays in range
  o.max_error = uint32_t(codec::kMaxAbsSample);
  CHECK(run(o, out.size()) == codec::Status::Ok);
  o.max_error = uint32_t(codec::kMaxAbsSample) + 1;
  CHECK(run(o, out.size()) == codec::Status::InvalidArgument);
  o = {};
  img.samples[37] = codec::kMaxAbsSample + 1;
  CHECK(run(o, out.size()) == codec::Status::ValueOutOfRange);
  img.samples[37] = -codec::kMaxAbsSample - 1;
  CHECK(run(o, out.size()) == codec::Status::ValueOutOfRange);
}

TEST_CASE("encoding is deterministic and the encoder's reconstruction is the decoder's output", "[codec]") {
  const Image img = residual_like(200, 150, 10.0, 77);
  codec::EncodeOptions options;
  options.step = 7.3;
  std::vector<int32_t> recon1, recon2;
  const auto a = encode_image(img, options, &recon1);
  const auto b = encode_image(img, options, &recon2);
  CHECK((a == b));
  CHECK(first_difference(recon1, recon2) == -1);
  CHECK(first_difference(decode_image(a, img), recon1) == -1);
}

namespace {

// Coefficient tiles that the vector inverse must treat exactly like the scalar one.
std::vector<int32_t> coefficient_tile(int kind, int w, int h, bool lossy, std::mt19937& rng) {
  std::vector<int32_t> tile(size_t(w) * h);
  switch (kind) {
    case 0: {  // any int32: wrapping arithmetic everywhere
      std::uniform_int_distribution<int32_t> any(INT32_MIN, INT32_MAX);
      for (auto& v : tile) v = any(rng);
      break;
    }
    case 1: {  // extremes and the limits valid streams stay within
      constexpr int32_t kValues[] = {INT32_MIN,  INT32_MAX, 0,          1,   -1,  1 << 25,
                                     -(1 << 25), 1 << 29,   -(1 << 29), 255, -256};
      std::uniform_int_distribution<size_t> pick(0, std::size(kValues) - 1);
      for (auto& v : tile) v = kValues[pick(rng)];
      break;
    }
    case 2: {  // sparse small coefficients, as a decoder sees them
      std::uniform_int_distribution<int32_t> value(-4096, 4096), sparse(0, 3);
      for (auto& v : tile) v = sparse(rng) == 0 ? value(rng) : 0;
      break;
    }
    default: {  // transformed samples (+-2^22) with quantisation-like noise
      std::uniform_int_distribution<int32_t> sample(-(1 << 22), 1 << 22), noise(-40, 40);
      for (auto& v : tile) v = sample(rng);
      codec::detail::forward_lapped(tile.data(), w, h, lossy);
      for (auto& v : tile) v += noise(rng);
      break;
    }
  }
  return tile;
}

}  // namespace

TEST_CASE("vector inverse transforms equal the scalar reference on random and extreme tiles", "[codec]") {
  using namespace codec::detail;
  std::mt19937 rng(1234);
  bool vector_ran = false;
  const bool avx2 = cpu_has_avx2(), avx512 = cpu_has_avx512();
  // 272x272: above inverse_stage2_lanes' compact grid, so the scalar stage 2 there.
  const int sizes[][2] = {{16, 16}, {32, 32}, {48, 16}, {16, 80}, {64, 64}, {96, 48}, {272, 32}, {272, 272}};
  for (const auto& size : sizes)
    for (const bool lossy : {false, true})
      for (int kind = 0; kind < 4; ++kind)
        for (int trial = 0; trial < 3; ++trial) {
          const int w = size[0], h = size[1];
          const std::vector<int32_t> input = coefficient_tile(kind, w, h, lossy, rng);
          std::vector<int32_t> reference = input, vector = input, wide = input, wider = input,
                               dispatched = input;
          inverse_lapped_scalar(reference.data(), w, h, lossy);
          inverse_lapped(dispatched.data(), w, h, lossy);
          INFO("size " << w << "x" << h << " lossy " << lossy << " kind " << kind);
          CHECK(first_difference(dispatched, reference) == -1);
          if (inverse_lapped_vector(vector.data(), w, h, lossy)) {
            vector_ran = true;
            CHECK(first_difference(vector, reference) == -1);
          }
          if (avx2 && inverse_lapped_avx2(wide.data(), w, h, lossy))
            CHECK(first_difference(wide, reference) == -1);
          if (avx512 && inverse_lapped_avx512(wider.data(), w, h, lossy))
            CHECK(first_difference(wider, reference) == -1);
        }
#if defined(__x86_64__) && defined(CODEC_VECTOR_TRANSFORM)
  CHECK(vector_ran);
#endif
}

#ifdef CODEC_VECTOR_TRANSFORM
TEST_CASE("vector shrink (division-free) equals the scalar integer division", "[codec]") {
  using namespace codec::detail;
  // A sweep over all of int32 and a dense window around 0 (the full range was checked exhaustively
  // once, by the same comparison, when the vector form was written).
  const auto check = [](int64_t first, int64_t last, int64_t stride) {
    int64_t bad = 0;
    for (int64_t y = first; y + 3 * stride <= last; y += 4 * stride) {
      const V4 v = {int32_t(y), int32_t(y + stride), int32_t(y + 2 * stride), int32_t(y + 3 * stride)};
      const V4 inner = shrink<kExpandInner>(v), outer = shrink<kExpandOuter>(v);
      for (int j = 0; j < 4; ++j) {
        bad += inner[j] != shrink<kExpandInner>(v[j]);
        bad += outer[j] != shrink<kExpandOuter>(v[j]);
      }
    }
    return bad;
  };
  CHECK(check(INT32_MIN, INT32_MAX, 4099) == 0);
  CHECK(check(-(1 << 18), 1 << 18, 1) == 0);
  CHECK(check(INT32_MAX - 4096, INT32_MAX, 1) == 0);
  CHECK(check(INT32_MIN, INT32_MIN + 4096, 1) == 0);
}
#endif

TEST_CASE("RLGR escapes: the largest magnitudes round trip in both modes, larger ones are rejected",
          "[codec]") {
  using namespace codec::detail;
  const int32_t big = kRlgrMaxMagnitude - 1;
  const std::vector<int32_t> values = {big, -big, 0, 0, 0, 0, 5, -big, 0, big, 1, 0};
  for (const RlgrState start : {RlgrState{0, 8}, RlgrState{8, 8}, RlgrState{40, 80}}) {
    std::vector<uint8_t> buf(1024);
    BitWriter w(buf.data(), buf.size());
    RlgrState s = start;
    rlgr_encode(w, values.data(), values.size(), s);
    const size_t n = w.finish();
    REQUIRE_FALSE(w.overflow());
    BitReader r(buf.data(), n);
    std::vector<int32_t> out(values.size());
    s = start;
    INFO("start kp " << start.kp << " krp " << start.krp);
    CHECK(rlgr_decode(r, out.data(), out.size(), s));
    CHECK_FALSE(r.overrun());
    CHECK(out == values);
  }
  // Forged escapes one beyond the range: Golomb-Rice mode's mapped value 2^31 - 1 (|v| = 2^30) and
  // run mode's magnitude - 1 = 2^30 - 1; one below each decodes.
  const auto forged = [](bool run_mode, uint32_t escaped, int32_t* decoded) {
    std::vector<uint8_t> buf(64);
    BitWriter w(buf.data(), buf.size());
    if (run_mode) w.put(0b100, 3);  // k = 1: a run ended by a value, run length 0, positive
    w.put_ones(rlgr::kUnaryCap);
    w.put(escaped, rlgr::kEscapeBits);
    const size_t n = w.finish();
    BitReader r(buf.data(), n);
    RlgrState s = run_mode ? RlgrState{8, 8} : RlgrState{0, 8};
    return rlgr_decode(r, decoded, 1, s);
  };
  int32_t v = 0;
  CHECK_FALSE(forged(false, 0x7FFFFFFFu, &v));
  CHECK(forged(false, 0x7FFFFFFEu, &v));
  CHECK(v == big);
  CHECK_FALSE(forged(true, uint32_t(kRlgrMaxMagnitude) - 1, &v));
  CHECK(forged(true, uint32_t(kRlgrMaxMagnitude) - 2, &v));
  CHECK(v == big);
}

TEST_CASE("rms streams leave a tile empty when coding it removes less error than its bits are worth",
          "[codec]") {
  // 128 x 64: a left tile of noise within +-3 (at step 8 the coder turns a few coefficients into 9
  // bytes that remove almost none of its error; before this rule that tile was coded) and a right
  // tile of a ramp far beyond the step (always coded).
  Image img;
  img.width = 128;
  img.height = 64;
  img.samples.assign(size_t(img.width * img.height), 0);
  for (int64_t y = 0; y < 64; ++y)
    for (int64_t x = 0; x < 128; ++x)
      img.samples[size_t(y * 128 + x)] =
          x < 64 ? int32_t((uint32_t(x * 2654435761u ^ y * 40503u ^ 1067u) >> 7) % 7u) - 3
                 : int32_t(40 * (x - 64) + 20 * y);
  codec::EncodeOptions options;
  options.tile_size = 64;
  options.step = 8.0;
  std::vector<int32_t> recon;
  const auto stream = encode_image(img, options, &recon);
  codec::Decoder decoder;
  REQUIRE(decoder.open(stream.data(), stream.size()) == codec::Status::Ok);
  // The index: a run of one empty tile, then the coded one.
  REQUIRE(decoder.index().size() == 2);
  CHECK(decoder.index()[0].size == 0);
  CHECK(decoder.index()[1].size > 0);
  // What the encoder hands back for the closed loop is what a decoder makes.
  CHECK(first_difference(decode_image(stream, img), recon) == -1);
  for (int64_t y = 0; y < 64; ++y)
    for (int64_t x = 0; x < 64; ++x) REQUIRE(recon[size_t(y * 128 + x)] == 0);
  // Lossless streams never drop a tile that carries information.
  options.step = 1;
  CHECK(first_difference(decode_image(encode_image(img, options), img), img.samples) == -1);
}
