// libcodec format 5 (the residual transform, docs/codec.md "Residual transform (format 5)"): exact
// round trips, the encoder's reconstruction, region decoding, the per-tile choice, version rules and
// damaged streams, on closed-loop-residual-like data.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <random>
#include <vector>

#include "codec/codec.h"
#include "codec/crc32c.h"
#include "stream_test_util.h"

namespace {

using codec_test::encode;
using codec_test::Image;
using codec_test::reseal;

// A closed-loop-residual-like image: smooth low band (the coarse error, +-s/2) plus Laplacian
// details of scale b, with a few large outliers.
Image residual(int64_t w, int64_t h, double b, double s, uint32_t seed) {
  std::mt19937 rng(seed);
  std::exponential_distribution<double> lap(1.0 / b);
  std::uniform_real_distribution<double> u(-0.5, 0.5);
  Image img{w, h, std::vector<int32_t>(size_t(w * h))};
  for (int64_t y = 0; y < h; ++y)
    for (int64_t x = 0; x < w; ++x) {
      const double detail = (rng() & 1 ? 1 : -1) * lap(rng);
      const double low = s * (0.5 * std::sin(double(x) / 5) * std::cos(double(y) / 7) + 0.5 * u(rng));
      const int32_t outlier = (rng() % 997 == 0) ? int32_t(rng() % 200000) - 100000 : 0;
      img.samples[size_t(y * w + x)] = int32_t(std::lround(detail + low)) + outlier;
    }
  return img;
}

codec::EncodeOptions options(double step, uint32_t tile, codec::Transform t) {
  codec::EncodeOptions o;
  o.step = step;
  o.tile_size = tile;
  o.transform = t;
  return o;
}

std::vector<int32_t> decode(const std::vector<uint8_t>& s, const Image& like,
                            codec::Status* status = nullptr) {
  std::vector<int32_t> out;
  const codec::Status st = codec_test::decode_into(s, like, &out);
  if (status)
    *status = st;
  else
    REQUIRE(st == codec::Status::Ok);
  return out;
}

}  // namespace

TEST_CASE("residual transform: lossless is exact, lossy decodes to the encoder's reconstruction", "[codec]") {
  // Odd and even sizes, tiles one sample wide or high, several tile sizes.
  for (const auto& [w, h] : std::vector<std::pair<int64_t, int64_t>>{
           {1, 1}, {1, 37}, {37, 1}, {2, 3}, {33, 17}, {130, 70}, {97, 161}})
    for (uint32_t tile : {16u, 32u, 64u}) {
      const Image img = residual(w, h, 6.0, 9.0, uint32_t(w * 131 + h + tile));
      std::vector<int32_t> recon;
      const auto lossless = encode(img, options(1, tile, codec::Transform::Residual), &recon);
      CHECK(recon == img.samples);
      CHECK(decode(lossless, img) == img.samples);
      for (double step : {1.5, 3.0, 8.0, 40.0}) {
        const auto lossy = encode(img, options(step, tile, codec::Transform::Residual), &recon);
        CHECK(decode(lossy, img) == recon);
        codec::HeaderInfo h0;
        REQUIRE(codec::read_header(lossy.data(), lossy.size(), &h0) == codec::Status::Ok);
        CHECK(h0.version == 5);
        CHECK(h0.transform == codec::Transform::Residual);
      }
    }
}

TEST_CASE("residual transform: fewer bits than lapped on residuals at equal error, and max-error holds",
          "[codec]") {
  const Image img = residual(256, 192, 5.0, 6.0, 7);
  double err[2] = {0, 0};
  size_t bytes[2] = {0, 0};
  for (int k = 0; k < 2; ++k) {
    std::vector<int32_t> recon;
    const auto s =
        encode(img, options(4.0, 32, k ? codec::Transform::Residual : codec::Transform::Lapped), &recon);
    bytes[k] = s.size();
    for (size_t i = 0; i < recon.size(); ++i)
      err[k] += double(recon[i] - img.samples[i]) * (recon[i] - img.samples[i]);
  }
  // The rate-distortion choice per tile can only lower the cost bits + lambda * error.
  const double lambda = 6.0 / (std::log(2.0) * 16.0);
  CHECK(8.0 * bytes[1] + lambda * err[1] <= 8.0 * bytes[0] + lambda * err[0]);
  CHECK(bytes[1] < bytes[0]);

  codec::EncodeOptions o = options(0, 32, codec::Transform::Residual);
  o.bound_max_error = true;
  for (uint32_t e : {1u, 3u, 10u}) {
    o.max_error = e;
    std::vector<int32_t> recon;
    const auto s = encode(img, o, &recon);
    const auto out = decode(s, img);
    CHECK(out == recon);
    int64_t worst = 0;
    for (size_t i = 0; i < out.size(); ++i)
      worst = std::max<int64_t>(worst, std::abs(int64_t(out[i]) - img.samples[i]));
    CHECK(worst <= int64_t(e));
  }
}

TEST_CASE("residual transform: region decodes equal the full decode", "[codec]") {
  const Image img = residual(203, 157, 8.0, 12.0, 11);
  std::vector<int32_t> recon;
  const auto s = encode(img, options(3.0, 32, codec::Transform::Residual), &recon);
  codec_test::check_regions(s, img, recon);
}

TEST_CASE("format versions: 5 exactly with the residual flag, lapped streams stay version 4", "[codec]") {
  // One tile row (h <= tile): the stream CRC covers every byte before it, so a forged field can be
  // resealed. Header: magic, u16 version, varints width (64), height (16), tile / 16 (2), flags.
  const Image img = residual(64, 16, 4.0, 4.0, 5);
  constexpr size_t kFlags = 9;
  std::vector<int32_t> recon;
  const auto lapped = encode(img, options(2.0, 32, codec::Transform::Lapped), &recon);
  const auto lifted = encode(img, options(2.0, 32, codec::Transform::Residual), &recon);
  codec::HeaderInfo h;
  REQUIRE(codec::read_header(lapped.data(), lapped.size(), &h) == codec::Status::Ok);
  CHECK(h.version == 4);
  CHECK(h.transform == codec::Transform::Lapped);
  REQUIRE(codec::read_header(lifted.data(), lifted.size(), &h) == codec::Status::Ok);
  CHECK(h.version == 5);
  REQUIRE(lifted[kFlags] == 4);  // the residual flag; lossy F = 4, no max error
  REQUIRE(lapped[kFlags] == 0);

  std::vector<uint8_t> v5_without_flag = lifted;
  v5_without_flag[kFlags] = 0;
  reseal(v5_without_flag);
  CHECK(codec::read_header(v5_without_flag.data(), v5_without_flag.size(), &h) == codec::Status::Corrupt);
  std::vector<uint8_t> v4_with_flag = lapped;
  v4_with_flag[kFlags] = 4;
  reseal(v4_with_flag);
  CHECK(codec::read_header(v4_with_flag.data(), v4_with_flag.size(), &h) == codec::Status::Corrupt);
  std::vector<uint8_t> v7 = lifted;  // version 7 needs the phase flag (and a max-error stream)
  v7[4] = 7;
  reseal(v7);
  CHECK(codec::read_header(v7.data(), v7.size(), &h) == codec::Status::Corrupt);
  std::vector<uint8_t> v6 = lifted;  // the retired first phase-tile format
  v6[4] = 6;
  reseal(v6);
  CHECK(codec::read_header(v6.data(), v6.size(), &h) == codec::Status::UnsupportedVersion);
  std::vector<uint8_t> v8 = lifted;  // so does version 8 (two rANS states per phase tile)
  v8[4] = 8;
  reseal(v8);
  CHECK(codec::read_header(v8.data(), v8.size(), &h) == codec::Status::Corrupt);
  std::vector<uint8_t> v9 = lifted;
  v9[4] = 9;
  reseal(v9);
  CHECK(codec::read_header(v9.data(), v9.size(), &h) == codec::Status::UnsupportedVersion);
  std::vector<uint8_t> v3 = lapped;
  v3[4] = 3;
  reseal(v3);
  CHECK(codec::read_header(v3.data(), v3.size(), &h) == codec::Status::UnsupportedVersion);
}

TEST_CASE("residual transform: every damaged byte is rejected, never a crash", "[codec]") {
  const Image img = residual(70, 40, 6.0, 8.0, 9);
  std::vector<int32_t> recon;
  const auto s = encode(img, options(3.0, 16, codec::Transform::Residual), &recon);
  for (size_t i = 0; i < s.size(); ++i)
    for (uint8_t flip : {uint8_t(1), uint8_t(0x80)}) {
      std::vector<uint8_t> bad = s;
      bad[i] ^= flip;
      codec::Status st;
      decode(bad, img, &st);
      CHECK(st != codec::Status::Ok);
    }
  for (size_t n = 0; n < s.size(); n += 7) {
    std::vector<uint8_t> cut(s.begin(), s.begin() + std::ptrdiff_t(n));
    codec::Status st;
    codec::Scratch scratch;
    std::vector<int32_t> out(img.samples.size());
    st = cut.empty() ? codec::Status::Truncated
                     : codec::decode(cut.data(), cut.size(), out.data(), img.width, scratch);
    CHECK(st != codec::Status::Ok);
  }
}
