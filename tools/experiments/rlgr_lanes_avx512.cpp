// Experiment (not built by CMake): would a format with 8 interleaved RLGR streams ("lanes") decode
// fast enough to justify its bits? Value j goes to lane (j / B) % 8; each lane is coded as its own
// RLGR stream (fresh state), the lanes concatenated at bit granularity. The decoder runs the 8 lanes
// in lock-step, one 64-bit AVX-512 element each, without branches (window from a gather at each
// lane's bit position, both RLGR modes computed, results selected by masks, non-zero values
// scattered; escapes read a second window). Results in docs/codec.md ("Decoder implementation").
// Input: the LP and HP band groups of a real DEM coded by libcodec (captured from a decode: the
// library's sources built with CODEC_BAND_CAPTURE). The decoders include the real decoder's sink:
// each non-zero level's slot (tile offset and band), dequantisation, store; the lane decoder gathers
// slots and band steps and scatters. Prints bits/value (one stream vs 8 lanes) and ns/value.
//   g++ -O2 -std=c++20 -DCODEC_BAND_CAPTURE -Ilibcodec/src -Ilibcodec/include tools/experiments/rlgr_lanes_avx512.cpp libcodec/src/*.cpp -o /tmp/rlgr-lanes
//   /tmp/rlgr-lanes ../shared/data/srtm3_N46W122_rainier_adams_cascades.hgt 6 256   (DEM, step, tile)
#include "codec/codec.h"
#include "rlgr.h"
#include <fstream>
#include <immintrin.h>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <random>
#include <algorithm>
#include <vector>
using namespace codec::detail;
using namespace codec::detail::rlgr;
namespace codec::detail { extern std::vector<std::vector<int32_t>>* g_band_capture; }

static size_t B = 1;
static const uint32_t* g_slots; static const uint32_t* g_q8;
struct Lanes { std::vector<uint8_t> bytes; uint64_t start[8]; size_t count[8]; };

static Lanes encode_lanes(const std::vector<int32_t>& v) {
  Lanes L; std::vector<uint8_t> buf(v.size() * 8 + 64); size_t total_bits = 0;
  std::vector<std::vector<uint8_t>> lane_bytes(8); std::vector<size_t> lane_bits(8);
  for (int l = 0; l < 8; ++l) {
    std::vector<int32_t> s; for (size_t j = 0; j < v.size(); ++j) if ((j / B) % 8 == size_t(l)) s.push_back(v[j]);
    std::vector<uint8_t> b(s.size() * 8 + 16); BitWriter w(b.data(), b.size()); RlgrState st; rlgr_encode(w, s.data(), s.size(), st);
    lane_bits[l] = w.bit_count(); w.finish(); lane_bytes[l] = b; L.count[l] = s.size();
  }
  // concatenate at bit granularity
  BitWriter w(buf.data(), buf.size());
  for (int l = 0; l < 8; ++l) {
    L.start[l] = total_bits;
    BitReader r(lane_bytes[l].data(), lane_bytes[l].size()); size_t n = lane_bits[l];
    while (n >= 16) { w.put(r.get(16), 16); n -= 16; }
    if (n) w.put(r.get(int(n)), int(n));
    total_bits += lane_bits[l];
  }
  size_t bytes = w.finish(); buf.resize(bytes + 16, 0); L.bytes = buf; return L;
}

// out must be zeroed; writes the value at j.
__attribute__((target("avx512f,avx512cd,avx512bw,avx512vl,avx512dq,bmi2")))
static bool decode_avx512(const Lanes& L, int32_t* out, size_t n) {
  const __m512i one = _mm512_set1_epi64(1), zero = _mm512_setzero_si512();
  const __m512i bswap = _mm512_set_epi8(8,9,10,11,12,13,14,15, 0,1,2,3,4,5,6,7, 8,9,10,11,12,13,14,15, 0,1,2,3,4,5,6,7,
                                        8,9,10,11,12,13,14,15, 0,1,2,3,4,5,6,7, 8,9,10,11,12,13,14,15, 0,1,2,3,4,5,6,7);
  __m512i pos = _mm512_loadu_si512(L.start);
  __m512i cnt = _mm512_loadu_si512(L.count);
  __m512i i = zero, kp = _mm512_set1_epi64(8), krp = _mm512_set1_epi64(8);
  const __m512i lane = _mm512_set_epi64(7,6,5,4,3,2,1,0);
  const uint8_t* base = L.bytes.data();
  __mmask8 active = _mm512_cmplt_epu64_mask(i, cnt);
  while (active) {
    __m512i raw = _mm512_mask_i64gather_epi64(zero, active, _mm512_srli_epi64(pos, 3), base, 1);
    __m512i w = _mm512_sllv_epi64(_mm512_shuffle_epi8(raw, bswap), _mm512_and_si512(pos, _mm512_set1_epi64(7)));
    __m512i k = _mm512_srli_epi64(kp, 3), kr = _mm512_srli_epi64(krp, 3);
    __mmask8 gr = _mm512_cmpeq_epi64_mask(k, zero);
    __m512i c64 = _mm512_set1_epi64(64);
    // GR
    __m512i ones = _mm512_lzcnt_epi64(_mm512_ternarylogic_epi64(w, w, w, 0x55));
    __m512i after = _mm512_sllv_epi64(w, _mm512_add_epi64(ones, one));
    __m512i val = _mm512_or_si512(_mm512_sllv_epi64(ones, kr), _mm512_srlv_epi64(after, _mm512_sub_epi64(c64, kr)));
    // run
    __mmask8 flag = _mm512_cmplt_epi64_mask(w, zero);
    __m512i run = _mm512_srlv_epi64(_mm512_slli_epi64(w, 1), _mm512_sub_epi64(c64, k));
    __m512i neg = _mm512_srli_epi64(_mm512_sllv_epi64(w, _mm512_add_epi64(k, one)), 63);
    __m512i rest = _mm512_sllv_epi64(w, _mm512_add_epi64(k, _mm512_set1_epi64(2)));
    __m512i ones_r = _mm512_lzcnt_epi64(_mm512_ternarylogic_epi64(rest, rest, rest, 0x55));
    __m512i after_r = _mm512_sllv_epi64(rest, _mm512_add_epi64(ones_r, one));
    __m512i m1 = _mm512_or_si512(_mm512_sllv_epi64(ones_r, kr), _mm512_srlv_epi64(after_r, _mm512_sub_epi64(c64, kr)));
    __m512i q = _mm512_mask_blend_epi64(gr, ones_r, ones);
    __mmask8 rice = gr | flag;
    __m512i len_gr = _mm512_add_epi64(_mm512_add_epi64(ones, one), kr);
    __m512i len_r = _mm512_mask_blend_epi64(flag, one, _mm512_add_epi64(_mm512_add_epi64(k, _mm512_set1_epi64(3)), _mm512_add_epi64(ones_r, kr)));
    const __mmask8 esc = _mm512_mask_cmpge_epi64_mask(rice & active, q, _mm512_set1_epi64(kUnaryCap));
    if (esc) [[unlikely]] {  // 20 ones, then a 31-bit value: read from a second window
      const __m512i prefix = _mm512_maskz_add_epi64(~gr, k, _mm512_set1_epi64(2));
      const __m512i at = _mm512_add_epi64(pos, _mm512_add_epi64(prefix, _mm512_set1_epi64(kUnaryCap)));
      __m512i r2 = _mm512_mask_i64gather_epi64(zero, esc, _mm512_srli_epi64(at, 3), base, 1);
      r2 = _mm512_sllv_epi64(_mm512_shuffle_epi8(r2, bswap), _mm512_and_si512(at, _mm512_set1_epi64(7)));
      const __m512i escaped = _mm512_srli_epi64(r2, 64 - kEscapeBits);
      const __m512i elen = _mm512_add_epi64(prefix, _mm512_set1_epi64(kUnaryCap + kEscapeBits));
      val = _mm512_mask_mov_epi64(val, esc & gr, escaped);
      m1 = _mm512_mask_mov_epi64(m1, esc & ~gr, escaped);
      len_gr = _mm512_mask_mov_epi64(len_gr, esc & gr, elen);
      len_r = _mm512_mask_mov_epi64(len_r, esc & ~gr, elen);
      q = _mm512_mask_mov_epi64(q, esc, _mm512_set1_epi64(kUnaryCap));
      if (_mm512_mask_cmpge_epu64_mask(esc & gr, val, _mm512_set1_epi64(2 * int64_t(kRlgrMaxMagnitude))) ||
          _mm512_mask_cmpge_epu64_mask(esc & ~gr, m1, _mm512_set1_epi64(kRlgrMaxMagnitude)))
        return false;
    }
    __m512i len = _mm512_mask_blend_epi64(gr, len_r, len_gr);
    __mmask8 nz = (_mm512_mask_cmpneq_epi64_mask(gr, val, zero)) | (flag & ~gr);
    __m512i mag = _mm512_mask_blend_epi64(gr, _mm512_add_epi64(m1, one), _mm512_srli_epi64(_mm512_add_epi64(val, one), 1));
    __m512i sgn = _mm512_mask_blend_epi64(gr, neg, _mm512_and_si512(val, one));
    __m512i signed_v = _mm512_mask_sub_epi64(mag, _mm512_cmpneq_epi64_mask(sgn, zero), zero, mag);
    __m512i left = _mm512_sub_epi64(cnt, i);
    __m512i full = _mm512_min_epu64(_mm512_sllv_epi64(one, k), left);
    __m512i opos = _mm512_mask_add_epi64(i, flag & ~gr, i, run);
    if (_mm512_mask_cmpge_epu64_mask(flag & ~gr & active, run, left)) return false;
    __m512i adv = _mm512_mask_blend_epi64(gr, _mm512_mask_blend_epi64(flag, full, _mm512_add_epi64(run, one)), one);
    // kp
    __m512i dk_gr = _mm512_mask_blend_epi64(nz, _mm512_set1_epi64(kUpZero), _mm512_set1_epi64(-kDownZero));
    __m512i dk_r = _mm512_mask_blend_epi64(flag, _mm512_set1_epi64(kUpRun), _mm512_set1_epi64(-kDownRun));
    __m512i nkp = _mm512_add_epi64(kp, _mm512_mask_blend_epi64(gr, dk_r, dk_gr));
    nkp = _mm512_min_epi64(_mm512_max_epi64(nkp, zero), _mm512_set1_epi64(kKpMax));
    __m512i dq = _mm512_sub_epi64(q, _mm512_add_epi64(_mm512_maskz_mov_epi64(_mm512_cmpeq_epi64_mask(q, zero), _mm512_set1_epi64(2)),
                                                      _mm512_maskz_mov_epi64(_mm512_cmpeq_epi64_mask(q, one), one)));
    __m512i nkrp = _mm512_min_epi64(_mm512_max_epi64(_mm512_add_epi64(krp, dq), zero), _mm512_set1_epi64(kKpMax));
    kp = _mm512_mask_mov_epi64(kp, active, nkp);
    krp = _mm512_mask_mov_epi64(krp, active & rice, nkrp);
    pos = _mm512_mask_add_epi64(pos, active, pos, len);
    // output: global index = opos * 8 + lane
    __mmask8 store = nz & active;
    __m512i gidx;
    if (B == 1) gidx = _mm512_add_epi64(_mm512_slli_epi64(opos, 3), lane);
    else { const __m512i bb = _mm512_set1_epi64(int64_t(B)); const __m512i blk = _mm512_srli_epi64(opos, __builtin_ctzll(B));
      gidx = _mm512_add_epi64(_mm512_mullo_epi64(_mm512_add_epi64(_mm512_slli_epi64(blk, 3), lane), bb), _mm512_and_si512(opos, _mm512_sub_epi64(bb, one))); }
    const __m256i slot = _mm512_mask_i64gather_epi32(_mm256_setzero_si256(), store, gidx, (const int*)g_slots, 4);
    const __m256i q8 = _mm256_i32gather_epi32((const int*)g_q8, _mm256_srli_epi32(slot, 24), 4);
    // value = ((mag * 16 + 1) * q8 + 2048) >> 12, signed
    __m512i mq = _mm512_mul_epu32(_mm512_add_epi64(_mm512_slli_epi64(mag, 4), one), _mm512_cvtepu32_epi64(q8));
    mq = _mm512_srli_epi64(_mm512_add_epi64(mq, _mm512_set1_epi64(2048)), 12);
    const __m512i dv = _mm512_mask_sub_epi64(mq, _mm512_cmpneq_epi64_mask(sgn, zero), zero, mq);
    _mm512_mask_i32scatter_epi32(out, store, _mm512_castsi256_si512(_mm256_and_si256(slot, _mm256_set1_epi32(0xFFFFFF))), _mm512_castsi256_si512(_mm512_cvtepi64_epi32(dv)), 4);
    i = _mm512_mask_add_epi64(i, active, i, adv);
    active = _mm512_cmplt_epu64_mask(i, cnt);
  }
  (void)n;
  return true;
}


int main(int argc, char** argv) {
  if (argc < 4) { fprintf(stderr, "usage: %s DEM.hgt STEP TILE\n", argv[0]); return 1; }
  std::ifstream in(argv[1], std::ios::binary);
  const std::vector<unsigned char> hgt((std::istreambuf_iterator<char>(in)), {});
  const int w = 1201, h = 1201;
  if (hgt.size() != size_t(2 * w * h)) { fprintf(stderr, "%s: not a 1201x1201 .hgt\n", argv[1]); return 1; }
  std::vector<int32_t> src(w * h);
  for (int i = 0; i < w * h; ++i) { const int16_t v = int16_t((hgt[2 * i] << 8) | hgt[2 * i + 1]); src[i] = v == -32768 ? 0 : v; }
  codec::EncodeOptions opt; opt.step = atof(argv[2]); opt.tile_size = uint32_t(atoi(argv[3]));
  std::vector<uint8_t> stream(codec::encode_bound(w, h, opt)); size_t written = 0; codec::Scratch scratch;
  if (codec::encode(src.data(), w, w, h, opt, stream.data(), stream.size(), &written, scratch) != codec::Status::Ok) return 1;
  std::vector<std::vector<int32_t>> g; g_band_capture = &g;
  std::vector<int32_t> decoded(w * h); codec::decode(stream.data(), written, decoded.data(), w, scratch); g_band_capture = nullptr;
  printf("%s step %s tile %s: %.3f bits/sample, %zu band groups\n", argv[1], argv[2], argv[3], 8.0 * written / (w * h), g.size());
  uint32_t q8[32]; for (int b = 0; b < 32; ++b) q8[b] = 256 * 6 + b * 40;
  g_q8 = q8;
  for (size_t Bv : {size_t(1), size_t(16), size_t(64)}) {
    B = Bv;
    size_t bits1 = 0, bits8 = 0, values = 0; double t1 = 0, t8 = 0; bool ok = true;
    for (auto& v : g) {
      const size_t n = v.size(); values += n;
      std::vector<uint32_t> slots(n); for (size_t j = 0; j < n; ++j) slots[j] = uint32_t(j % 15) << 24 | uint32_t(j);
      g_slots = slots.data();
      std::vector<uint8_t> b(n * 8 + 64); BitWriter w(b.data(), b.size()); RlgrState s0; rlgr_encode(w, v.data(), n, s0);
      bits1 += w.bit_count(); const size_t len1 = w.finish();
      Lanes L = encode_lanes(v); bits8 += (L.bytes.size() - 16) * 8;
      std::vector<int32_t> o1(n), o8(n);
      double best1 = 1e9, best8 = 1e9;
      for (int rep = 0; rep < 15; ++rep) {
        std::fill(o1.begin(), o1.end(), 0); std::fill(o8.begin(), o8.end(), 0);
        auto a = std::chrono::steady_clock::now();
        { BitReader r(b.data(), len1); RlgrState s; rlgr_decode_nonzero(r, n, s, [&](size_t i, uint32_t m, bool ng) {
            const uint32_t slot = slots[i]; const uint64_t val = ((uint64_t(m) * 16 + 1) * q8[slot >> 24] + 2048) >> 12;
            o1[slot & 0xFFFFFF] = int32_t(ng ? 0u - uint32_t(val) : uint32_t(val)); return val <= (1u << 29); }); }
        auto bb = std::chrono::steady_clock::now();
        const bool okk = decode_avx512(L, o8.data(), n);
        auto c = std::chrono::steady_clock::now();
        if (rep == 0 && (!okk || o1 != o8)) ok = false;
        best1 = std::min(best1, std::chrono::duration<double>(bb - a).count());
        best8 = std::min(best8, std::chrono::duration<double>(c - bb).count());
      }
      t1 += best1; t8 += best8;
    }
    printf("B=%3zu: bits single %.4f b/v, 8 lanes %.4f b/v (+%.2f%%); decode ns/value single %.3f, lanes %.3f (x%.2f)%s\n", B,
           double(bits1) / values, double(bits8) / values, 100.0 * (double(bits8) / bits1 - 1), t1 * 1e9 / values, t8 * 1e9 / values, t1 / t8,
           ok ? "" : "  (MISMATCH or escape in some group)");
  }
}
