// Helpers shared by the libcodec stream tests: encode with the encoder's reconstruction, decode,
// reseal a forged one-row stream, and compare region decodes with the reconstruction.
#pragma once

#include <catch2/catch.hpp>
#include <cstdint>
#include <random>
#include <vector>

#include "codec/codec.h"
#include "codec/crc32c.h"

namespace codec_test {

struct Image {
  int64_t width = 0, height = 0;
  std::vector<int32_t> samples;
};

inline std::vector<uint8_t> encode(const Image& img, const codec::EncodeOptions& o,
                                   std::vector<int32_t>* recon) {
  codec::Scratch scratch;
  std::vector<uint8_t> out(codec::encode_bound(img.width, img.height, o));
  size_t n = 0;
  recon->assign(img.samples.size(), 0);
  REQUIRE(codec::encode(img.samples.data(), img.width, img.width, img.height, o, out.data(), out.size(), &n,
                        scratch, recon->data(), img.width) == codec::Status::Ok);
  out.resize(n);
  return out;
}

// Decodes the whole stream into `out` (sized like `like`); returns the status.
inline codec::Status decode_into(const std::vector<uint8_t>& s, const Image& like,
                                 std::vector<int32_t>* out) {
  codec::Scratch scratch;
  out->assign(like.samples.size(), 0);
  return codec::decode(s.data(), s.size(), out->data(), like.width, scratch);
}

// A stream of one tile row: its CRC covers every byte before it, so a forged field can be resealed.
inline void reseal(std::vector<uint8_t>& s) {
  const uint32_t crc = codec::crc32c(s.data(), s.size() - 4);
  for (int i = 0; i < 4; ++i) s[s.size() - 4 + size_t(i)] = uint8_t(crc >> (8 * i));
}

// 40 random regions of the stream decode to the encoder's reconstruction (and, added to a
// destination, add exactly it).
inline void check_regions(const std::vector<uint8_t>& s, const Image& img,
                          const std::vector<int32_t>& recon) {
  codec::Decoder d;
  REQUIRE(d.open(s.data(), s.size()) == codec::Status::Ok);
  codec::Scratch scratch;
  std::mt19937 rng(3);
  for (int k = 0; k < 40; ++k) {
    const int64_t w = 1 + rng() % 90, h = 1 + rng() % 90;
    const int64_t x0 = rng() % (img.width - w + 1), y0 = rng() % (img.height - h + 1);
    std::vector<int32_t> part(size_t(w * h), 7), sum(size_t(w * h), 100);
    REQUIRE(d.decode_region({x0, y0, w, h}, part.data(), w, scratch) == codec::Status::Ok);
    REQUIRE(d.decode_region_add({x0, y0, w, h}, sum.data(), w, scratch) == codec::Status::Ok);
    bool same = true, added = true;
    for (int64_t y = 0; y < h; ++y)
      for (int64_t x = 0; x < w; ++x) {
        const int32_t want = recon[size_t((y0 + y) * img.width + x0 + x)];
        same = same && part[size_t(y * w + x)] == want;
        added = added && sum[size_t(y * w + x)] == 100 + want;
      }
    CHECK(same);
    CHECK(added);
  }
}

}  // namespace codec_test
