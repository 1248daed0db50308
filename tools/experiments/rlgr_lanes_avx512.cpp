// Experiment (not built by CMake): would a format with 8 interleaved RLGR streams ("lanes") decode
// fast enough to justify its bits? Value j goes to lane (j / B) % 8; each lane is coded as its own
// RLGR stream (fresh state), the lanes concatenated at bit granularity. The decoder runs the 8 lanes
// in lock-step, one 64-bit AVX-512 element each, without branches (window from a gather at each
// lane's bit position, both RLGR modes computed, results selected by masks, non-zero values
// scattered). Escapes are not handled (the larger-value cases stop with a mismatch). Results in
// docs/codec.md ("Decoder implementation").
//   g++ -O2 -std=c++20 -Ilibcodec/src tools/experiments/rlgr_lanes_avx512.cpp libcodec/src/rlgr.cpp -o /tmp/rlgr-lanes
//   /tmp/rlgr-lanes [laplacian scale] [share of zeros] [B]
#include "rlgr.h"
#include <immintrin.h>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <random>
#include <vector>
using namespace codec::detail;
using namespace codec::detail::rlgr;

static size_t B = 1;
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
    if (_mm512_mask_cmpge_epi64_mask(rice & active, q, _mm512_set1_epi64(kUnaryCap))) return false;  // escape: not in prototype
    __m512i len_gr = _mm512_add_epi64(_mm512_add_epi64(ones, one), kr);
    __m512i len_r = _mm512_mask_blend_epi64(flag, one, _mm512_add_epi64(_mm512_add_epi64(k, _mm512_set1_epi64(3)), _mm512_add_epi64(ones_r, kr)));
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
    _mm512_mask_i64scatter_epi32(out, store, gidx, _mm512_cvtepi64_epi32(signed_v), 4);
    i = _mm512_mask_add_epi64(i, active, i, adv);
    active = _mm512_cmplt_epu64_mask(i, cnt);
  }
  (void)n;
  return true;
}

int main(int argc, char** argv) {
  B = argc > 3 ? atoi(argv[3]) : 1; const double scale = argc > 1 ? atof(argv[1]) : 1.0, pzero = argc > 2 ? atof(argv[2]) : 0.6;
  const size_t n = 4096 * 16;
  std::mt19937 rng(1); std::vector<int32_t> a(n);
  std::uniform_real_distribution<double> u(0, 1); std::exponential_distribution<double> e(1.0 / scale);
  for (size_t i = 0; i < n; ++i) { const double pz = ((i / 256) % 4 == 0) ? 0.95 : pzero; a[i] = u(rng) < pz ? 0 : int32_t(1 + e(rng)) * (u(rng) < 0.5 ? -1 : 1); }
  std::vector<uint8_t> b(n * 8); BitWriter w(b.data(), b.size()); RlgrState s0; rlgr_encode(w, a.data(), n, s0); const size_t bits1 = w.bit_count(); const size_t len1 = w.finish();
  Lanes L = encode_lanes(a);
  printf("bits/value single %.4f, 8 lanes %.4f\n", double(bits1) / n, 8.0 * double(L.bytes.size() - 16) / n);
  std::vector<int32_t> o(n);
  double t1 = 1e9, t8 = 1e9;
  for (int rep = 0; rep < 100; ++rep) {
    std::fill(o.begin(), o.end(), 0);
    auto t0 = std::chrono::steady_clock::now();
    { BitReader r(b.data(), len1); RlgrState s; rlgr_decode_nonzero(r, n, s, [&](size_t i, uint32_t m, bool ng) { o[i] = ng ? -int32_t(m) : int32_t(m); return true; }); }
    auto tA = std::chrono::steady_clock::now();
    if (rep == 0 && o != a) { printf("scalar mismatch\n"); return 1; }
    std::fill(o.begin(), o.end(), 0);
    auto tB = std::chrono::steady_clock::now();
    bool ok = decode_avx512(L, o.data(), n);
    auto tC = std::chrono::steady_clock::now();
    if (rep == 0 && (!ok || o != a)) { printf("lanes mismatch ok=%d\n", ok); size_t bad=0; for (size_t i=0;i<n;++i) if (o[i]!=a[i]) {if (bad<5) printf(" at %zu: %d vs %d\n", i, o[i], a[i]); ++bad;} printf(" %zu bad\n", bad); return 1; }
    t1 = std::min(t1, std::chrono::duration<double>(tA - t0).count());
    t8 = std::min(t8, std::chrono::duration<double>(tC - tB).count());
  }
  printf("ns/value: scalar %.3f, 8 lanes avx512 %.3f (x%.2f)\n", t1 * 1e9 / n, t8 * 1e9 / n, t1 / t8);
}
