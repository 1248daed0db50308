// Experiment (not built by CMake): can RLGR decoding go faster without changing the code itself?
// Times, on synthetic HP-like sequences, (1) the library's per-codeword decoding, branchy, one
// stream after the other; (2) two independent streams decoded in lock-step (instruction-level
// parallelism across streams, as a two-stream format would allow); (3) run mode without branches
// (both outcomes of the run flag computed, one selected). Results are in docs/codec.md.
//   g++ -O2 -std=c++20 -Ilibcodec/src tools/experiments/rlgr_decode_variants.cpp libcodec/src/rlgr.cpp -o /tmp/rlgr-variants
//   /tmp/rlgr-variants [laplacian scale] [share of zeros]
#include "rlgr.h"
#include <chrono>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>
using namespace codec::detail;

// The library's per-codeword decoder, as rlgr_decode_nonzero runs it.
template <class Sink>
__attribute__((always_inline)) inline bool step(BitReader& in, size_t count, RlgrState& s, size_t& i, Sink&& sink) {
  if (!in.refill_fast()) in.refill();
  auto accept = [&](size_t at, uint32_t m, bool neg) {
    sink(at, m, neg);
    return true;
  };
  return rlgr_decode_codeword(in, count, s, i, accept);
}

template <class Sink>
__attribute__((always_inline)) inline bool step_b(BitReader& in, size_t count, RlgrState& s, size_t& i, Sink&& sink) {
  using namespace rlgr;
  if (!in.refill_fast()) in.refill();
  const int k = s.kp >> 3;
  const int kr = s.krp >> 3;
  if (k == 0) {
    const int ones = in.leading_ones();
    if (ones >= kUnaryCap) [[unlikely]] return step(in, count, s, i, sink);
    in.skip(ones + 1);
    adapt_rice(s, ones);
    const uint32_t mapped = (uint32_t(ones) << kr) | in.take(kr);
    if (mapped != 0) sink(i, (mapped + 1) >> 1, (mapped & 1) != 0);
    ++i;
    s.kp = clamp_kp(s.kp + kUpZero - (kUpZero + kDownZero) * int(mapped != 0));
    return true;
  }
  const uint64_t c = in.cache();
  const uint64_t flag = c >> 63;
  const uint64_t rest = c << (k + 2);
  const int ones = __builtin_clzll(~rest | 1);
  if (ones >= kUnaryCap) [[unlikely]] return step(in, count, s, i, sink);
  const size_t run = size_t((c << 1) >> (64 - k));
  const uint32_t neg = uint32_t((c << (k + 1)) >> 63);
  const uint32_t m1 = (uint32_t(ones) << kr) | uint32_t((rest << ones) >> (63 - kr));
  const size_t full = std::min(size_t(1) << k, count - i);
  const size_t fmask = size_t(0) - size_t(flag);   // all ones when a value ends the run
  const size_t at = i + (run & fmask);
  if (at >= count) [[unlikely]] return false;
  sink(at, (m1 + 1) & uint32_t(fmask), neg != 0);
  i = ((at + 1) & fmask) | ((i + full) & ~fmask);
  const int bits = k + 2 + ones + 1 + kr;
  in.skip(flag ? bits : 1);
  s.kp = clamp_kp(s.kp + (flag ? -kDownRun : kUpRun));
  const int d = ones - 2 * int(ones == 0) - int(ones == 1);
  s.krp = clamp_kp(s.krp + (d & int(fmask)));
  return true;
}

int main(int argc, char** argv) {
  const double scale = argc > 1 ? atof(argv[1]) : 1.0;   // Laplacian scale of the non-zero part
  const double pzero = argc > 2 ? atof(argv[2]) : 0.6;   // probability of zero
  const size_t n = 4096 * 16;  // 16 tiles' worth
  std::mt19937 rng(1);
  std::vector<int32_t> a(n), b(n);
  std::uniform_real_distribution<double> u(0, 1);
  std::exponential_distribution<double> e(1.0 / scale);
  for (auto* v : {&a, &b})
    for (size_t i = 0; i < n; ++i) {
      // bursts: smooth regions have more zeros
      const double pz = ((i / 256) % 4 == 0) ? 0.95 : pzero;
      (*v)[i] = u(rng) < pz ? 0 : int32_t(1 + e(rng)) * (u(rng) < 0.5 ? -1 : 1);
    }
  std::vector<uint8_t> ba(n * 8), bb(n * 8);
  BitWriter wa(ba.data(), ba.size()), wb(bb.data(), bb.size());
  RlgrState sa, sb;
  rlgr_encode(wa, a.data(), n, sa);
  rlgr_encode(wb, b.data(), n, sb);
  const size_t la = wa.finish(), lb = wb.finish();
  printf("bits/value %.3f\n", 8.0 * double(la + lb) / double(2 * n));
  std::vector<int32_t> oa(n), ob(n);
  auto sinkA = [&](size_t i, uint32_t m, bool neg) { oa[i] = neg ? -int32_t(m) : int32_t(m); };
  auto zero = [&] {
    std::fill(oa.begin(), oa.end(), 0);
    std::fill(ob.begin(), ob.end(), 0);
  };
  auto sinkB = [&](size_t i, uint32_t m, bool neg) { ob[i] = neg ? -int32_t(m) : int32_t(m); };
  double best1 = 1e9, best2 = 1e9, best3 = 1e9;
  for (int rep = 0; rep < 200; ++rep) {
    auto t0 = std::chrono::steady_clock::now();
    {
      BitReader ra(ba.data(), la); RlgrState s; size_t i = 0;
      while (i < n) step(ra, n, s, i, sinkA);
      BitReader rb(bb.data(), lb); RlgrState s2; size_t j = 0;
      while (j < n) step(rb, n, s2, j, sinkB);
    }
    auto t1 = std::chrono::steady_clock::now();
    {
      BitReader ra(ba.data(), la); RlgrState s; size_t i = 0;
      BitReader rb(bb.data(), lb); RlgrState s2; size_t j = 0;
      while (i < n && j < n) {
        step(ra, n, s, i, sinkA);
        step(rb, n, s2, j, sinkB);
      }
      while (i < n) step(ra, n, s, i, sinkA);
      while (j < n) step(rb, n, s2, j, sinkB);
    }
    auto t2 = std::chrono::steady_clock::now();
    {
      BitReader ra(ba.data(), la); RlgrState s; size_t i = 0;
      BitReader rb(bb.data(), lb); RlgrState s2; size_t j = 0;
      while (i < n) step_b(ra, n, s, i, sinkA);
      while (j < n) step_b(rb, n, s2, j, sinkB);
    }
    auto t3 = std::chrono::steady_clock::now();
    best1 = std::min(best1, std::chrono::duration<double>(t1 - t0).count());
    best2 = std::min(best2, std::chrono::duration<double>(t2 - t1).count());
    best3 = std::min(best3, std::chrono::duration<double>(t3 - t2).count());
  }
  // Each variant writes non-zero values (and, the branch-free one, some zeros) into zeroed arrays.
  bool ok = true;
  for (int variant = 0; variant < 2; ++variant) {
    zero();
    BitReader ra(ba.data(), la), rb(bb.data(), lb);
    RlgrState s, s2;
    size_t i = 0, j = 0;
    while (i < n) variant ? step_b(ra, n, s, i, sinkA) : step(ra, n, s, i, sinkA);
    while (j < n) variant ? step_b(rb, n, s2, j, sinkB) : step(rb, n, s2, j, sinkB);
    ok = ok && oa == a && ob == b;
  }
  printf("ns/value: branchy %.2f, two streams in lock-step %.2f, run mode branch-free %.2f (%s)\n",
         best1 * 1e9 / double(2 * n), best2 * 1e9 / double(2 * n), best3 * 1e9 / double(2 * n),
         ok ? "decoded values check" : "MISMATCH");
  return ok ? 0 : 1;
}
