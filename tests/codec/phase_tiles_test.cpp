// libcodec format 6 (phase tiles of max-error streams, docs/codec.md "Phase tiles (format 6)"): the
// bound at every sample (lossless included), the encoder's reconstruction, region decoding, the
// version rules and damaged streams, on the residuals of a point-sampled pyramid.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <random>
#include <vector>

#include "codec/codec.h"
#include "codec/crc32c.h"
#include "codec/internal/phase_coder.h"
#include "stream_test_util.h"

namespace {

using codec_test::encode;
using codec_test::Image;

// What a point-sampled pyramid's residual looks like: even-even samples within +-e (the coarse
// level's error), the other phases Laplacian of scale b (the four-point interpolation's error).
Image point_residual(int64_t w, int64_t h, double b, int e, uint32_t seed) {
  std::mt19937 rng(seed);
  std::exponential_distribution<double> lap(1.0 / b);
  std::uniform_int_distribution<int> small(-e, e);
  Image img{w, h, std::vector<int32_t>(size_t(w * h))};
  for (int64_t y = 0; y < h; ++y)
    for (int64_t x = 0; x < w; ++x)
      img.samples[size_t(y * w + x)] =
          (x % 2 == 0 && y % 2 == 0) ? small(rng) : int32_t(std::lround((rng() & 1 ? 1 : -1) * lap(rng)));
  return img;
}

codec::EncodeOptions options(uint32_t e, bool phase, uint32_t tile = 32) {
  codec::EncodeOptions o;
  o.bound_max_error = true;
  o.max_error = e;
  o.tile_size = tile;
  o.transform = codec::Transform::Residual;
  o.phase_tiles = phase;
  return o;
}

codec::Status decode(const std::vector<uint8_t>& s, const Image& like, std::vector<int32_t>* out) {
  return codec_test::decode_into(s, like, out);
}

int64_t max_abs_error(const Image& img, const std::vector<int32_t>& out) {
  int64_t m = 0;
  for (size_t i = 0; i < out.size(); ++i)
    m = std::max<int64_t>(m, std::llabs(int64_t(out[i]) - img.samples[i]));
  return m;
}

}  // namespace

TEST_CASE("phase tiles: the bound holds at every sample, lossless is exact, decode == encoder", "[codec]") {
  for (uint32_t e : {0u, 1u, 2u, 5u})
    for (int64_t w : {1, 2, 17, 64, 101})
      for (int64_t h : {1, 3, 32, 75}) {
        const Image img = point_residual(w, h, 3.0 + 4.0 * e, int(e), uint32_t(w * 131 + h * 7 + e));
        std::vector<int32_t> recon, out;
        const auto s = encode(img, options(e, true, 16), &recon);
        REQUIRE(decode(s, img, &out) == codec::Status::Ok);
        CHECK(out == recon);
        CHECK(max_abs_error(img, out) <= int64_t(e));
      }
}

TEST_CASE("phase tiles: smaller than the other modes on a point-sampled residual, never larger", "[codec]") {
  for (uint32_t e : {0u, 2u, 5u}) {
    const Image img = point_residual(256, 192, 2.0 + 3.0 * e, int(e), 40 + e);
    std::vector<int32_t> recon;
    const auto with = encode(img, options(e, true), &recon);
    const auto without = encode(img, options(e, false), &recon);
    INFO("E " << e << ": " << with.size() << " bytes with phase tiles, " << without.size() << " without");
    CHECK(double(with.size()) < 0.9 * double(without.size()));
    // Data the phase mode does not suit (a smooth ramp, its even phase far outside the bound) keeps
    // the other modes: at most the stream's version costs nothing and every tile picks the smallest.
    Image ramp{256, 64, std::vector<int32_t>(256 * 64)};
    for (int64_t y = 0; y < 64; ++y)
      for (int64_t x = 0; x < 256; ++x) ramp.samples[size_t(y * 256 + x)] = int32_t(3 * x + 5 * y);
    const auto ramp_with = encode(ramp, options(e, true), &recon);
    const auto ramp_without = encode(ramp, options(e, false), &recon);
    CHECK(ramp_with.size() <= ramp_without.size());
  }
}

TEST_CASE("phase tiles: region decodes equal the full decode", "[codec]") {
  const Image img = point_residual(203, 157, 6.0, 2, 11);
  std::vector<int32_t> recon;
  const auto s = encode(img, options(2, true), &recon);
  codec_test::check_regions(s, img, recon);
}

TEST_CASE("format versions: 6 exactly with the phase flag, only in max-error streams", "[codec]") {
  // One tile row, so codec_test::reseal works. Header: magic, u16 version, varints width (64), height (16),
  // tile / 16 (2), flags.
  const Image img = point_residual(64, 16, 4.0, 1, 5);
  constexpr size_t kFlags = 9;
  std::vector<int32_t> recon;
  const auto phase = encode(img, options(1, true), &recon);
  const auto plain = encode(img, options(1, false), &recon);
  codec::HeaderInfo h;
  REQUIRE(codec::read_header(phase.data(), phase.size(), &h) == codec::Status::Ok);
  CHECK(h.version == 6);
  CHECK(h.phase_tiles);
  REQUIRE(codec::read_header(plain.data(), plain.size(), &h) == codec::Status::Ok);
  CHECK(h.version == 5);
  CHECK(!h.phase_tiles);
  REQUIRE(phase[kFlags] == (1 | 4 | 8));  // max error, residual transform, phase tiles

  std::vector<uint8_t> v6_without_flag = phase;
  v6_without_flag[kFlags] = 1 | 4;
  codec_test::reseal(v6_without_flag);
  CHECK(codec::read_header(v6_without_flag.data(), v6_without_flag.size(), &h) == codec::Status::Corrupt);
  std::vector<uint8_t> v5_with_flag = plain;
  v5_with_flag[kFlags] = 1 | 4 | 8;
  codec_test::reseal(v5_with_flag);
  CHECK(codec::read_header(v5_with_flag.data(), v5_with_flag.size(), &h) == codec::Status::Corrupt);
  // A phase tile in a stream that does not allow them (the flag cleared, version 5) is rejected.
  std::vector<uint8_t> downgraded = phase;
  downgraded[4] = 5;
  downgraded[kFlags] = 1 | 4;
  codec_test::reseal(downgraded);
  std::vector<int32_t> out;
  CHECK(decode(downgraded, img, &out) != codec::Status::Ok);
}

TEST_CASE("phase tiles: every damaged byte is rejected, never a crash", "[codec]") {
  const Image img = point_residual(70, 40, 6.0, 2, 9);
  std::vector<int32_t> recon, out;
  const auto s = encode(img, options(2, true, 16), &recon);
  for (size_t i = 0; i < s.size(); ++i)
    for (uint8_t flip : {uint8_t(1), uint8_t(0x80)}) {
      std::vector<uint8_t> bad = s;
      bad[i] ^= flip;
      CHECK(decode(bad, img, &out) != codec::Status::Ok);
    }
  for (size_t n = 1; n < s.size(); n += 3) {
    std::vector<uint8_t> cut(s.begin(), s.begin() + std::ptrdiff_t(n));
    CHECK(decode(cut, img, &out) != codec::Status::Ok);
  }
  // The phase decoder itself on random payloads (what a forged stream with resealed CRCs reaches):
  // it returns or rejects, stays in its buffers (ASan), and keeps accepted samples within +-2^30. (An
  // arithmetic code accepts most byte strings: the stream's CRCs, checked above, catch damage.)
  std::mt19937 rng(1);
  std::vector<int32_t> recon_out(32 * 32), levels(codec::detail::phase_levels_size(32, 32));
  for (int k = 0; k < 2000; ++k) {
    std::vector<uint8_t> payload(size_t(rng() % 64));
    for (uint8_t& b : payload) b = uint8_t(rng());
    if (codec::detail::decode_phase(payload.data(), payload.size(), 32, 32, rng() % 4, recon_out.data(),
                                    levels.data())) {
      for (int32_t v : recon_out) REQUIRE(std::abs(int64_t(v)) <= (int64_t(1) << 30));
    }
  }
}
