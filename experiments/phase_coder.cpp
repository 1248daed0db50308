// Prototype (built as experiments/phase_coder, not installed): the issue-17 "polyphase" lever measured
// through the real coder. In the closed loop D(R_l) ~ -e_{l-1}, so the even-even phase of a level's
// residual is largely predictable from its three odd phases. This coder splits each band of R_l into
// its four phases, codes the three odd ones (even row/odd column, odd/even, odd/odd) as quarter-size
// libcodec images, predicts the even-even phase from the decoded odd-phase samples of a 7x7 window
// (least squares per band, coefficients tied by the square's 8 symmetries: 7 numbers, stored as float32),
// and codes the even-even prediction error as the fourth image. Every phase is quantised with the same
// step, so the error bound of each sample is the one of the plain coder.
// It is compared with PtcResidualCoder on the whole pyramid, at equal finest-level rms (the phase
// coder's step is bisected until its rms matches), and per level.
// Build: cmake --build build --target phase_coder
// Run:   [BEST_OF_BOTH=1] build/experiments/phase_coder DEM STEP [TILE [BAND_ROWS]]
//        BEST_OF_BOTH: each band keeps the smaller of the plain and the phase coding (one marker byte).
// The coarsest level (its "residual" is T_0 itself) is always coded plainly.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "build/ptc_coder.h"
#include "pyramid/builder.h"
#include "pyramid/memory_pyramid.h"
#include "readers/heightmap.h"

using namespace terrain;

namespace {

// Offsets of the odd-phase samples in the 7x7 window around an even-even sample, by symmetry class.
struct Tap {
  int dy, dx, cls;
};
std::vector<Tap> make_taps() {
  std::vector<Tap> taps;
  const int classes[4][4] = {{-1, 0, -1, 1}, {0, 2, 3, 4}, {-1, 3, -1, 5}, {1, 4, 5, 6}};
  // classes[|dy|][|dx|]: (0,1)=0 (0,3)=1 (1,1)=2 (1,2)=3 (1,3)=4 (2,3)=5 (3,3)=6; both even: -1
  for (int dy = -3; dy <= 3; ++dy)
    for (int dx = -3; dx <= 3; ++dx) {
      const int c = classes[std::abs(dy)][std::abs(dx)];
      if (c >= 0) taps.push_back({dy, dx, c});
    }
  return taps;
}
constexpr int kClasses = 7;
const std::vector<Tap> kTaps = make_taps();

// Samples of the full band (w x h) at (y, x), edge-clamped, from the decoded odd phases (ee: 0).
int32_t at(const std::vector<int32_t>& full, int64_t w, int64_t h, int64_t y, int64_t x) {
  y = std::clamp<int64_t>(y, 0, h - 1);
  x = std::clamp<int64_t>(x, 0, w - 1);
  if ((y & 1) == 0 && (x & 1) == 0) return 0;  // not known to the predictor
  return full[size_t(y * w + x)];
}

void features(const std::vector<int32_t>& full, int64_t w, int64_t h, int64_t y, int64_t x, double* f) {
  std::fill(f, f + kClasses, 0.0);
  for (const Tap& t : kTaps) {
    int64_t yy = y + t.dy, xx = x + t.dx;
    // Reflect so that the parity of the tap holds at the border (clamping would hit an even sample).
    if (yy < 0) yy = -yy;
    if (xx < 0) xx = -xx;
    if (yy >= h) yy = 2 * (h - 1) - yy;
    if (xx >= w) xx = 2 * (w - 1) - xx;
    if (yy < 0 || xx < 0 || yy >= h || xx >= w) continue;
    f[t.cls] += at(full, w, h, yy, xx);
  }
}

bool solve(std::array<double, kClasses * kClasses> a, std::array<double, kClasses> b, float* out) {
  const int n = kClasses;
  for (int i = 0; i < n; ++i) a[size_t(i * n + i)] += 1e-6 * (1 + a[size_t(i * n + i)]);
  for (int k = 0; k < n; ++k) {
    int p = k;
    for (int i = k + 1; i < n; ++i)
      if (std::fabs(a[size_t(i * n + k)]) > std::fabs(a[size_t(p * n + k)])) p = i;
    if (std::fabs(a[size_t(p * n + k)]) < 1e-12) return false;
    for (int j = 0; j < n; ++j) std::swap(a[size_t(k * n + j)], a[size_t(p * n + j)]);
    std::swap(b[size_t(k)], b[size_t(p)]);
    for (int i = k + 1; i < n; ++i) {
      const double m = a[size_t(i * n + k)] / a[size_t(k * n + k)];
      for (int j = k; j < n; ++j) a[size_t(i * n + j)] -= m * a[size_t(k * n + j)];
      b[size_t(i)] -= m * b[size_t(k)];
    }
  }
  for (int k = n - 1; k >= 0; --k) {
    double s = b[size_t(k)];
    for (int j = k + 1; j < n; ++j) s -= a[size_t(k * n + j)] * double(out[j]);
    out[k] = float(s / a[size_t(k * n + k)]);
  }
  return true;
}

int32_t predict(const float* c, const double* f) {
  double p = 0;
  for (int k = 0; k < kClasses; ++k) p += double(c[k]) * f[k];
  return int32_t(std::lround(p));
}

class PhaseCoder final : public ResidualCoder {
 public:
  // coarsest: levels_above_finest of the coarsest level, whose "residual" is T_0 itself (coded plainly).
  PhaseCoder(const PtcCoderOptions& o, int coarsest) : inner_(o), coarsest_(coarsest) {}
  int64_t band_rows() const override { return inner_.band_rows(); }
  uint64_t coefficient_bytes = 0;
  bool best_of_both = std::getenv("BEST_OF_BOTH") != nullptr;  // per band: the smaller of plain and phase
  int plain_bands = 0, phase_bands = 0;
  struct Stat {
    double ee_raw = 0, ee_err = 0, n_ee = 0, bytes[4] = {0, 0, 0, 0};
  } stat[4];

  std::vector<uint8_t> encode(const int32_t* r, int64_t w, int64_t h, int32_t* recon, int lvl, bool coarsest,
                              int /*threads*/) override {
    std::vector<int32_t> plain_recon;
    std::vector<uint8_t> plain;
    if (best_of_both && lvl != coarsest_) {
      plain_recon.resize(size_t(w * h));
      plain = inner_.encode(r, w, h, plain_recon.data(), lvl, coarsest, 1);
    }
    if (lvl == coarsest_) {
      plain = inner_.encode(r, w, h, recon, lvl, coarsest, 1);
      if (plain.empty()) return plain;
      plain.insert(plain.begin(), 0xFF);
      return plain;
    }
    std::vector<int32_t> full(size_t(w * h), 0);
    std::vector<uint8_t> out(4 * sizeof(uint32_t) + kClasses * sizeof(float), 0);
    std::vector<std::vector<uint8_t>> streams(4);
    // Odd phases: p = 1 (even row, odd col), 2 (odd, even), 3 (odd, odd).
    for (int p = 1; p <= 3; ++p) {
      const int py = p >> 1, px = p & 1;
      const int64_t pw = (w - px + 1) / 2, ph = (h - py + 1) / 2;
      if (pw <= 0 || ph <= 0) continue;
      std::vector<int32_t> in(size_t(pw * ph)), rec(size_t(pw * ph));
      for (int64_t y = 0; y < ph; ++y)
        for (int64_t x = 0; x < pw; ++x) in[size_t(y * pw + x)] = r[(2 * y + py) * w + 2 * x + px];
      streams[size_t(p)] = inner_.encode(in.data(), pw, ph, rec.data(), lvl, coarsest, 1);
      if (streams[size_t(p)].empty()) std::fill(rec.begin(), rec.end(), 0);
      for (int64_t y = 0; y < ph; ++y)
        for (int64_t x = 0; x < pw; ++x)
          full[size_t((2 * y + py) * w + 2 * x + px)] = rec[size_t(y * pw + x)];
    }
    // Even-even phase: least-squares predictor from the decoded odd phases.
    const int64_t ew = (w + 1) / 2, eh = (h + 1) / 2;
    std::array<double, kClasses * kClasses> a{};
    std::array<double, kClasses> b{};
    double f[kClasses];
    for (int64_t y = 0; y < eh; ++y)
      for (int64_t x = 0; x < ew; ++x) {
        features(full, w, h, 2 * y, 2 * x, f);
        const double t = r[(2 * y) * w + 2 * x];
        for (int i = 0; i < kClasses; ++i) {
          b[size_t(i)] += f[i] * t;
          for (int j = 0; j < kClasses; ++j) a[size_t(i * kClasses + j)] += f[i] * f[j];
        }
      }
    float c[kClasses] = {};
    if (!solve(a, b, c)) std::fill(c, c + kClasses, 0.0f);
    std::vector<int32_t> err(size_t(ew * eh)), pred(size_t(ew * eh)), rec(size_t(ew * eh));
    for (int64_t y = 0; y < eh; ++y)
      for (int64_t x = 0; x < ew; ++x) {
        features(full, w, h, 2 * y, 2 * x, f);
        pred[size_t(y * ew + x)] = predict(c, f);
        err[size_t(y * ew + x)] = r[(2 * y) * w + 2 * x] - pred[size_t(y * ew + x)];
      }
    streams[0] = inner_.encode(err.data(), ew, eh, rec.data(), lvl, coarsest, 1);
    if (lvl < 4) {
      double sr = 0, se = 0;
      for (int64_t y = 0; y < eh; ++y)
        for (int64_t x = 0; x < ew; ++x) {
          sr += double(r[(2 * y) * w + 2 * x]) * r[(2 * y) * w + 2 * x];
          se += double(err[size_t(y * ew + x)]) * err[size_t(y * ew + x)];
        }
      stat[lvl].ee_raw += sr, stat[lvl].ee_err += se, stat[lvl].n_ee += double(ew * eh);
      for (int p = 0; p < 4; ++p) stat[lvl].bytes[p] += double(streams[size_t(p)].size());
    }
    if (streams[0].empty()) std::fill(rec.begin(), rec.end(), 0);
    for (int64_t y = 0; y < eh; ++y)
      for (int64_t x = 0; x < ew; ++x)
        full[size_t((2 * y) * w + 2 * x)] = pred[size_t(y * ew + x)] + rec[size_t(y * ew + x)];
    std::memcpy(recon, full.data(), size_t(w * h) * sizeof(int32_t));
    bool all_zero = true;
    for (int32_t v : full) all_zero = all_zero && v == 0;
    if (all_zero) return {};
    for (int p = 0; p < 4; ++p) {
      const uint32_t n = uint32_t(streams[size_t(p)].size());
      std::memcpy(out.data() + 4 * p, &n, 4);
    }
    std::memcpy(out.data() + 16, c, sizeof c);
    coefficient_bytes += sizeof c;
    for (auto& s : streams) out.insert(out.end(), s.begin(), s.end());
    if (best_of_both && plain.size() + 1 <= out.size()) {
      std::memcpy(recon, plain_recon.data(), size_t(w * h) * sizeof(int32_t));
      if (plain.empty()) return plain;
      plain.insert(plain.begin(), 0xFF);
      ++plain_bands;
      return plain;
    }
    ++phase_bands;
    return out;
  }

  bool decode(const uint8_t* data, size_t n, int64_t w, int64_t h, int32_t* out) override {
    std::fill(out, out + w * h, 0);
    if (n == 0) return true;
    if (data[0] == 0xFF) return inner_.decode(data + 1, n - 1, w, h, out);
    if (n < 16 + sizeof(float) * kClasses) return false;
    uint32_t sizes[4];
    std::memcpy(sizes, data, 16);
    float c[kClasses];
    std::memcpy(c, data + 16, sizeof c);
    size_t pos = 16 + sizeof c;
    const uint8_t* s[4];
    for (int p = 0; p < 4; ++p) {
      if (sizes[p] > n - pos) return false;
      s[p] = data + pos;
      pos += sizes[p];
    }
    std::vector<int32_t> full(size_t(w * h), 0);
    for (int p = 1; p <= 3; ++p) {
      const int py = p >> 1, px = p & 1;
      const int64_t pw = (w - px + 1) / 2, ph = (h - py + 1) / 2;
      if (pw <= 0 || ph <= 0 || sizes[p] == 0) continue;
      std::vector<int32_t> rec(size_t(pw * ph));
      if (!inner_.decode(s[p], sizes[p], pw, ph, rec.data())) return false;
      for (int64_t y = 0; y < ph; ++y)
        for (int64_t x = 0; x < pw; ++x)
          full[size_t((2 * y + py) * w + 2 * x + px)] = rec[size_t(y * pw + x)];
    }
    const int64_t ew = (w + 1) / 2, eh = (h + 1) / 2;
    std::vector<int32_t> rec(size_t(ew * eh), 0);
    if (sizes[0] && !inner_.decode(s[0], sizes[0], ew, eh, rec.data())) return false;
    double f[kClasses];
    for (int64_t y = 0; y < eh; ++y)
      for (int64_t x = 0; x < ew; ++x) {
        features(full, w, h, 2 * y, 2 * x, f);
        full[size_t((2 * y) * w + 2 * x)] = predict(c, f) + rec[size_t(y * ew + x)];
      }
    std::memcpy(out, full.data(), size_t(w * h) * sizeof(int32_t));
    return true;
  }

 private:
  PtcResidualCoder inner_;
  int coarsest_;
};

struct Result {
  BuildResult build;
  uint64_t total = 0;
};

Result run(const Heightmap& map, ResidualCoder& coder) {
  BuildOptions b;
  b.threads = 1;
  MemoryPyramid mem;
  mem.keep_reconstruction = false;
  Result r;
  r.build = build_pyramid(map, b, coder, mem);
  r.total = mem.total_bytes();
  return r;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: phase_coder DEM STEP [TILE [BAND_ROWS]]\n");
    return 2;
  }
  const Heightmap map = read_heightmap(argv[1]);
  PtcCoderOptions o;
  o.step = std::atof(argv[2]);
  o.tile_size = argc > 3 ? uint32_t(std::atoi(argv[3])) : 32;
  o.band_rows = argc > 4 ? std::atoi(argv[4]) : 128;
  const double samples = double(map.info.width) * double(map.info.height);

  PtcResidualCoder base(o);
  const Result rb = run(map, base);
  const double target = rb.build.levels.back().error_rms;

  // Bisect the phase coder's step to the baseline's finest rms.
  double lo = o.step * 0.7, hi = o.step * 1.3;
  Result rp;
  PtcCoderOptions po = o;
  for (int it = 0; it < 14; ++it) {
    po.step = it == 0 ? o.step : 0.5 * (lo + hi);
    PhaseCoder phase(po, int(rb.build.levels.size()) - 1);
    rp = run(map, phase);
    for (int l = 0; l < 4; ++l)
      if (phase.stat[l].n_ee > 0)
        std::printf("  lvl+%d: ee rms raw %.3f pred err %.3f; bytes ee %.0f eo %.0f oe %.0f oo %.0f\n", l,
                    std::sqrt(phase.stat[l].ee_raw / phase.stat[l].n_ee),
                    std::sqrt(phase.stat[l].ee_err / phase.stat[l].n_ee), phase.stat[l].bytes[0],
                    phase.stat[l].bytes[1], phase.stat[l].bytes[2], phase.stat[l].bytes[3]);
    if (phase.best_of_both)
      std::printf("  bands: phase %d, plain %d\n", phase.phase_bands, phase.plain_bands);
    const double e = rp.build.levels.back().error_rms;
    if (it == 0)
      std::printf("phase coder at the same step %.4f: finest rms %.4f (base %.4f), %.4f b/s\n", o.step, e,
                  target, 8.0 * double(rp.total) / samples);
    if (std::fabs(e - target) < 0.002 * target && it > 0) break;
    (e > target ? hi : lo) = po.step;
  }
  std::printf("%s step %.3f tile %u band %lld\n", argv[1], o.step, o.tile_size, (long long)o.band_rows);
  std::printf("level        size   base b/s  phase b/s  ratio   base rms  phase rms  base max  phase max\n");
  for (size_t l = 0; l < rb.build.levels.size(); ++l) {
    const auto& a = rb.build.levels[l];
    const auto& p = rp.build.levels[l];
    const double n = double(a.size.width) * double(a.size.height);
    std::printf("%5zu %6lldx%-6lld %9.4f %10.4f %6.3f %10.4f %10.4f %9lld %10lld\n", l,
                (long long)a.size.width, (long long)a.size.height, 8.0 * a.bytes / n, 8.0 * p.bytes / n,
                double(p.bytes) / double(a.bytes), a.error_rms, p.error_rms, (long long)a.error_max_abs,
                (long long)p.error_max_abs);
  }
  std::printf("whole: base %.4f b/s, phase %.4f b/s (step %.4f), ratio %.4f\n", 8.0 * rb.total / samples,
              8.0 * rp.total / samples, po.step, double(rp.total) / double(rb.total));
  return 0;
}
