// Experiment (not built by CMake): what does RLGR's per-value adaptation buy in bits over a simpler
// block-adaptive Golomb-Rice code, the kind a decoder could run with one fixed parameter per block
// (no adaptation or mode decision between values, so several values per decision)? Counts code
// lengths only (no bitstream): each captured LP/HP band group of a real DEM is costed by
//   * RLGR as libcodec codes it (rlgr_encode, default start state), and
//   * block-adaptive Rice: blocks of G values share one parameter k = min{k : N 2^k >= A} from the
//     running sum A of the zig-zag mapped values and their count N seen so far (LOCO-I style, halved
//     at N = 64), escapes as in RLGR (20 ones + 31 bits); variant "flag": when the running mean is
//     below 0.75 a block first spends one bit on "all zero" and, if not, codes its values with k = 0.
// Input: the band groups libcodec decodes (captured through CODEC_BAND_CAPTURE, see tile_coder.cpp).
// Result in docs/codec.md ("Decoder implementation").
//   g++ -O2 -std=c++20 -DCODEC_BAND_CAPTURE -Ilibcodec/src -Ilibcodec/include tools/experiments/block_rice_bits.cpp libcodec/src/*.cpp -o /tmp/block-rice-bits
//   /tmp/block-rice-bits ../shared/data/srtm3_N46W122_rainier_adams_cascades.hgt 6 256   (DEM, step, tile)
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <vector>

#include "codec/codec.h"
#include "rlgr.h"

using namespace codec::detail;
namespace codec::detail {
extern std::vector<std::vector<int32_t>>* g_band_capture;
}

static uint32_t zigzag(int32_t x) { return x >= 0 ? 2u * uint32_t(x) : 2u * uint32_t(-int64_t(x)) - 1; }
static long rice_bits(uint32_t u, int k) {
  const long q = long(u >> k);
  return q < rlgr::kUnaryCap ? q + 1 + k : rlgr::kUnaryCap + rlgr::kEscapeBits;
}

static long block_rice_bits(const std::vector<int32_t>& v, size_t block, bool zero_flag) {
  long bits = 0, sum = 4, n = 1;
  for (size_t b = 0; b < v.size(); b += block) {
    const size_t e = std::min(v.size(), b + block);
    int k = 0;
    while ((n << k) < sum && k < 24) ++k;
    if (zero_flag && sum * 4 < n * 3) {
      bits += 1;
      if (std::any_of(v.begin() + long(b), v.begin() + long(e), [](int32_t x) { return x != 0; }))
        for (size_t i = b; i < e; ++i) bits += rice_bits(zigzag(v[i]), 0);
    } else {
      for (size_t i = b; i < e; ++i) bits += rice_bits(zigzag(v[i]), k);
    }
    for (size_t i = b; i < e; ++i) sum += zigzag(v[i]), ++n;
    if (n >= 64) sum = (sum + 1) / 2, n = (n + 1) / 2;
  }
  return bits;
}

int main(int argc, char** argv) {
  if (argc < 4) {
    std::fprintf(stderr, "usage: %s DEM.hgt STEP TILE\n", argv[0]);
    return 1;
  }
  std::ifstream in(argv[1], std::ios::binary);
  const std::vector<unsigned char> hgt((std::istreambuf_iterator<char>(in)), {});
  const int w = 1201, h = 1201;
  if (hgt.size() != size_t(2 * w * h)) {
    std::fprintf(stderr, "%s: not a 1201x1201 .hgt\n", argv[1]);
    return 1;
  }
  std::vector<int32_t> src(size_t(w) * h);
  for (size_t i = 0; i < src.size(); ++i) {
    const int16_t x = int16_t((hgt[2 * i] << 8) | hgt[2 * i + 1]);
    src[i] = x == -32768 ? 0 : x;
  }
  codec::EncodeOptions opt;
  opt.step = std::atof(argv[2]);
  opt.tile_size = uint32_t(std::atoi(argv[3]));
  std::vector<uint8_t> stream(codec::encode_bound(w, h, opt));
  size_t written = 0;
  codec::Scratch scratch;
  if (codec::encode(src.data(), w, w, h, opt, stream.data(), stream.size(), &written, scratch) != codec::Status::Ok)
    return 1;
  std::vector<std::vector<int32_t>> groups;
  g_band_capture = &groups;
  std::vector<int32_t> decoded(src.size());
  codec::decode(stream.data(), written, decoded.data(), w, scratch);
  g_band_capture = nullptr;

  long rlgr_bits = 0;
  for (const auto& v : groups) {
    std::vector<uint8_t> buf(v.size() * 8 + 64);
    BitWriter out(buf.data(), buf.size());
    RlgrState state;
    rlgr_encode(out, v.data(), v.size(), state);
    rlgr_bits += long(out.bit_count());
  }
  std::printf("%s step %s tile %s: stream %.3f b/s, LP+HP with RLGR %.3f b/s; block Rice, bits vs RLGR:\n", argv[1],
              argv[2], argv[3], written * 8.0 / src.size(), rlgr_bits / double(src.size()));
  for (const bool flag : {false, true}) {
    std::printf("  %-9s", flag ? "flag" : "plain");
    for (const size_t block : {4, 8, 16, 32}) {
      long bits = 0;
      for (const auto& v : groups) bits += block_rice_bits(v, block, flag);
      std::printf("  G=%zu %+.1f%%", block, 100.0 * double(bits - rlgr_bits) / double(rlgr_bits));
    }
    std::printf("\n");
  }
}
