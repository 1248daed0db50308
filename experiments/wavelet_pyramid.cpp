// Prototype (built as experiments/wavelet_pyramid, not installed): is a critically sampled pyramid
// the lever that closes issue 17's gap? The closed-loop Laplacian pyramid codes N * 4/3 samples and
// re-codes every coarse level's quantisation error in the next finer residual; a lifting wavelet
// whose predict step is the pyramid's four-point U codes N samples, and its synthesis low-pass is
// exactly U (zero details: even = coarse, odd = four-point interpolation), so every pyramid level
// is the wavelet's low band at that scale, decodable coarse to fine as today.
//
// Per level, on rows then columns (inverse: columns then rows):
//   d[i] = x[2i+1] - P(s)[i], P = (-1, 9, 9, -1) / 16 with U's point-reflection edge extension,
//   s[i] = x[2i] + Upd(d)[i], Upd = none | (d[i-1] + d[i]) / 4 | (-d[i-2] + 9 d[i-1] + 9 d[i] - d[i+1]) / 32.
// In double precision (a measurement of rate, not a codec). Every subband is quantised with the
// dead-zone rule of libcodec (rounding offset 3/8, reconstruction |q| + 1/16) at step
// S / (its synthesis norm), the MSE-optimal allocation, and S is bisected until the finest level's
// rms error matches the target. Rates: (a) libcodec's RLGR on each subband in raster order, state
// reset per 32x32 tile (region-decodable); (b) the same, state reset per subband; (c) an adaptive
// context model (what an arithmetic / rANS coder with per-context tables could reach): the
// magnitude class of the causal neighbours and the parent coefficient selects one of 12 adaptive
// tables of min(|q|, 18) (escape: Elias-gamma of the rest), plus one bit of sign.
// Closed loop (CLOSED=r: coarse step r^k S at k levels above the finest) with ROUNDT=1: the coarse
// truths rounded to the input's unit, as the product stores its levels.
// Run: build/experiments/wavelet_pyramid DEM RMS [UPDATE 0|2|4] [LEVELS]
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "codec/codec.h"
#include "codec/internal/bitio.h"
#include "codec/internal/rlgr.h"
#include "pyramid/builder.h"
#include "pyramid/reference.h"
#include "readers/heightmap.h"

using namespace terrain;

namespace {

int g_update = 2;

// Point reflection about the edge sample (pyramid U's rule): index e of a length-n even array.
int g_mirror = 0;  // residual transforms: 1 = whole-sample mirror extension (s[-1] = s[1]), 2 = constant
double ext(const double* s, int64_t n, int64_t e) {
  if (n == 1) return s[0];
  if (g_mirror && (e < 0 || e >= n)) {
    if (g_mirror == 2) return s[e < 0 ? 0 : n - 1];
    while (e < 0 || e >= n) {
      if (e < 0) e = -e;
      if (e >= n) e = 2 * (n - 1) - e;
    }
    return s[e];
  }
  if (e >= 0 && e < n) return s[e];
  if (e == -1) return 2 * s[0] - s[1];
  if (e == n) return 2 * s[n - 1] - s[n - 2];
  if (n >= 3) return 2 * s[n - 1] - s[n - 3];
  return 3 * s[1] - 2 * s[0];
}
double dext(const double* d, int64_t n, int64_t i) {  // even-symmetric extension of the details
  if (n == 0) return 0;
  while (i < 0 || i >= n) {
    if (i < 0) i = -i - 1;
    if (i >= n) i = 2 * n - 1 - i;
  }
  return d[i];
}
double predict(const double* s, int64_t ne, int64_t i) {
  return (-ext(s, ne, i - 1) + 9 * ext(s, ne, i) + 9 * ext(s, ne, i + 1) - ext(s, ne, i + 2)) / 16;
}
double update(const double* d, int64_t no, int64_t i) {
  if (g_update == 0) return 0;
  if (g_update == 2) return (dext(d, no, i - 1) + dext(d, no, i)) / 4;
  return (-dext(d, no, i - 2) + 9 * dext(d, no, i - 1) + 9 * dext(d, no, i) - dext(d, no, i + 1)) / 32;
}

// 1D forward on x[0..n) with stride: evens to the front, odds behind them.
void fwd1(double* x, int64_t n, int64_t stride, std::vector<double>& tmp) {
  if (n < 2) return;
  const int64_t ne = (n + 1) / 2, no = n / 2;
  tmp.assign(size_t(n), 0);
  double* s = tmp.data();
  double* d = tmp.data() + ne;
  for (int64_t i = 0; i < ne; ++i) s[i] = x[2 * i * stride];
  for (int64_t i = 0; i < no; ++i) d[i] = x[(2 * i + 1) * stride] - predict(s, ne, i);
  for (int64_t i = 0; i < ne; ++i) s[i] += update(d, no, i);
  for (int64_t i = 0; i < n; ++i) x[i * stride] = tmp[size_t(i)];
}
void inv1(double* x, int64_t n, int64_t stride, std::vector<double>& tmp) {
  if (n < 2) return;
  const int64_t ne = (n + 1) / 2, no = n / 2;
  tmp.assign(size_t(n), 0);
  for (int64_t i = 0; i < n; ++i) tmp[size_t(i)] = x[i * stride];
  double* s = tmp.data();
  double* d = tmp.data() + ne;
  for (int64_t i = 0; i < ne; ++i) s[i] -= update(d, no, i);
  for (int64_t i = 0; i < ne; ++i) x[2 * i * stride] = s[i];
  for (int64_t i = 0; i < no; ++i) x[(2 * i + 1) * stride] = d[i] + predict(s, ne, i);
}

struct Image {
  int64_t w, h;
  std::vector<double> v;
  double& at(int64_t x, int64_t y) { return v[size_t(y * w + x)]; }
};

// Mallat layout in place: level j's low band occupies the top-left lw x lh.
void forward(Image& im, int levels) {
  std::vector<double> tmp;
  int64_t lw = im.w, lh = im.h;
  for (int l = 0; l < levels; ++l) {
    for (int64_t y = 0; y < lh; ++y) fwd1(&im.at(0, y), lw, 1, tmp);
    for (int64_t x = 0; x < lw; ++x) fwd1(&im.at(x, 0), lh, im.w, tmp);
    lw = (lw + 1) / 2, lh = (lh + 1) / 2;
  }
}
// Inverse down to the level whose low band is `stop` levels below the finest (0 = finest).
void inverse(Image& im, int levels, int stop = 0) {
  std::vector<double> tmp;
  std::vector<int64_t> ws{im.w}, hs{im.h};
  for (int l = 0; l < levels; ++l) ws.push_back((ws.back() + 1) / 2), hs.push_back((hs.back() + 1) / 2);
  for (int l = levels - 1; l >= stop; --l) {
    const int64_t lw = ws[size_t(l)], lh = hs[size_t(l)];
    for (int64_t x = 0; x < lw; ++x) inv1(&im.at(x, 0), lh, im.w, tmp);
    for (int64_t y = 0; y < lh; ++y) inv1(&im.at(0, y), lw, 1, tmp);
  }
}

struct Band {
  int level;   // 0 = finest details
  int orient;  // 0 LL (coarsest only), 1 HL (odd columns), 2 LH, 3 HH
  int64_t x0, y0, w, h;
  double norm2 = 1;
};

std::vector<Band> bands_of(int64_t W, int64_t H, int levels) {
  std::vector<Band> out;
  int64_t lw = W, lh = H;
  for (int l = 0; l < levels; ++l) {
    const int64_t ew = (lw + 1) / 2, eh = (lh + 1) / 2;
    out.push_back({l, 1, ew, 0, lw - ew, eh});
    out.push_back({l, 2, 0, eh, ew, lh - eh});
    out.push_back({l, 3, ew, eh, lw - ew, lh - eh});
    lw = ew, lh = eh;
  }
  out.push_back({levels, 0, 0, 0, lw, lh});
  return out;
}

// Synthesis norm^2 of one interior coefficient of each band (the energy it puts into the finest level).
void measure_norms(std::vector<Band>& bands, int64_t W, int64_t H, int levels) {
  for (Band& b : bands) {
    Image im{W, H, std::vector<double>(size_t(W * H), 0.0)};
    im.at(b.x0 + b.w / 2, b.y0 + b.h / 2) = 1;
    inverse(im, levels);
    double e = 0;
    for (double v : im.v) e += v * v;
    b.norm2 = e;
  }
}

int32_t quantise(double c, double step) {
  const double a = std::fabs(c) / step + 0.375;
  const int32_t q = int32_t(std::floor(a));
  return c < 0 ? -q : q;
}
double dequantise(int32_t q, double step) {
  if (q == 0) return 0;
  const double m = (std::abs(q) + 1.0 / 16) * step;
  return q < 0 ? -m : m;
}

size_t rlgr_bits(const std::vector<int32_t>& vals) {
  std::vector<uint8_t> buf(vals.size() * 16 + 64);
  codec::detail::BitWriter w(buf.data(), buf.size());
  codec::detail::RlgrState st;
  codec::detail::rlgr_encode(w, vals.data(), vals.size(), st);
  return w.bit_count();
}

// Adaptive context model cost in bits (see the header comment).
struct Model {
  static constexpr int kSyms = 19, kCtx = 12;
  std::vector<uint32_t> f = std::vector<uint32_t>(kCtx * kSyms, 1);
  std::vector<uint32_t> tot = std::vector<uint32_t>(kCtx, kSyms);
  double cost(int ctx, int sym) {
    uint32_t* fr = &f[size_t(ctx * kSyms)];
    const double c = -std::log2(double(fr[sym]) / tot[size_t(ctx)]);
    fr[sym] += 24, tot[size_t(ctx)] += 24;
    if (tot[size_t(ctx)] > 1u << 16) {
      tot[size_t(ctx)] = 0;
      for (int s = 0; s < kSyms; ++s) fr[s] = (fr[s] + 1) / 2, tot[size_t(ctx)] += fr[s];
    }
    return c;
  }
};
double gamma_bits(uint32_t v) {  // v >= 1
  int n = 0;
  while ((v >> n) > 1) ++n;
  return 2 * n + 1;
}

struct Quantised {
  std::vector<std::vector<int32_t>> q;  // per band, raster
};

double context_bits(const std::vector<Band>& bands, const Quantised& Q) {
  double bits = 0;
  for (size_t bi = 0; bi < bands.size(); ++bi) {
    const Band& b = bands[bi];
    const std::vector<int32_t>& q = Q.q[bi];
    // Parent: the same orientation one level coarser (none for the coarsest details and LL).
    const std::vector<int32_t>* parent = nullptr;
    int64_t pw = 0, ph = 0;
    if (b.orient != 0 && bi + 3 < bands.size() && bands[bi + 3].orient == b.orient) {
      parent = &Q.q[bi + 3];
      pw = bands[bi + 3].w, ph = bands[bi + 3].h;
    }
    Model m;
    auto mag = [&](int64_t x, int64_t y) -> int {
      if (x < 0 || y < 0 || x >= b.w) return 0;
      return std::abs(q[size_t(y * b.w + x)]);
    };
    for (int64_t y = 0; y < b.h; ++y)
      for (int64_t x = 0; x < b.w; ++x) {
        int32_t v = q[size_t(y * b.w + x)];
        if (b.orient == 0) {  // coarsest low band: code the MED prediction residual
          auto at = [&](int64_t xx, int64_t yy) { return q[size_t(yy * b.w + xx)]; };
          int32_t a = x > 0 ? at(x - 1, y) : (y > 0 ? at(x, y - 1) : 0);
          int32_t c = y > 0 ? at(x, y - 1) : a;
          int32_t d = (x > 0 && y > 0) ? at(x - 1, y - 1) : a;
          int32_t p = d >= std::max(a, c) ? std::min(a, c) : d <= std::min(a, c) ? std::max(a, c) : a + c - d;
          v -= p;
        }
        double s =
            2.0 * mag(x - 1, y) + mag(x, y - 1) + mag(x - 1, y - 1) + mag(x + 1, y - 1) + mag(x - 2, y);
        if (parent && pw > 0 && ph > 0) {
          const int64_t px = std::min(x / 2, pw - 1), py = std::min(y / 2, ph - 1);
          s += 2.0 * std::abs((*parent)[size_t(py * pw + px)]);
        }
        int ctx = s <= 0 ? 0 : std::min(Model::kCtx - 1, 1 + int(std::floor(std::log2(s) * 1.5)));
        if (b.orient == 0) ctx = std::min(Model::kCtx - 1, ctx);
        const uint32_t a = uint32_t(std::abs(v));
        const int sym = int(std::min<uint32_t>(a, Model::kSyms - 1));
        bits += m.cost(ctx, sym);
        if (sym == Model::kSyms - 1) bits += gamma_bits(a - (Model::kSyms - 1) + 1);
        if (a != 0) bits += 1;
      }
  }
  return bits;
}

struct Trial {
  double rms, maxerr;
  std::vector<double> level_rms, level_max;
  Quantised Q;
};

Trial trial(const Image& input, const Image& coeffs, std::vector<Band>& bands, int levels, double S) {
  Trial t;
  Image rec{coeffs.w, coeffs.h, std::vector<double>(coeffs.v.size(), 0.0)};
  for (const Band& b : bands) {
    const double step = S / std::sqrt(b.norm2);
    std::vector<int32_t> q(size_t(b.w * b.h));
    for (int64_t y = 0; y < b.h; ++y)
      for (int64_t x = 0; x < b.w; ++x) {
        const double c = coeffs.v[size_t((b.y0 + y) * coeffs.w + b.x0 + x)];
        const int32_t qi = quantise(c, step);
        q[size_t(y * b.w + x)] = qi;
        rec.at(b.x0 + x, b.y0 + y) = dequantise(qi, step);
      }
    t.Q.q.push_back(std::move(q));
  }
  // Per level: the low band reconstructed to that level against the input's low band at that level.
  for (int stop = levels; stop >= 0; --stop) {
    Image r = rec, ref = coeffs;
    inverse(r, levels, stop);
    inverse(ref, levels, stop);
    int64_t lw = coeffs.w, lh = coeffs.h;
    for (int l = 0; l < stop; ++l) lw = (lw + 1) / 2, lh = (lh + 1) / 2;
    double se = 0, mx = 0;
    for (int64_t y = 0; y < lh; ++y)
      for (int64_t x = 0; x < lw; ++x) {
        const double e = r.at(x, y) - (stop == 0 ? input.v[size_t(y * input.w + x)] : ref.at(x, y));
        se += e * e, mx = std::max(mx, std::fabs(e));
      }
    t.level_rms.push_back(std::sqrt(se / double(lw * lh)));
    t.level_max.push_back(mx);
  }
  t.rms = t.level_rms.back();
  t.maxerr = t.level_max.back();
  return t;
}

// Variant B (CLOSED=r): the closed-loop pyramid of today with the lifting low band as the coarse
// levels and one lifting level as the residual's transform: R_l = T_l - U(T^_{l-1}) is analysed into
// four bands (its low band ~ the coarse level's error), all four quantised at S_l / norm, S_l = S r^(m-l).
struct Closed {
  double rms, bits;
  std::vector<double> level_bits, level_rms;
};
Image upsample(const Image& c, int64_t W, int64_t H) {
  Image f{W, H, std::vector<double>(size_t(W * H), 0.0)};
  for (int64_t y = 0; y < c.h; ++y)
    for (int64_t x = 0; x < c.w; ++x) f.at(x, y) = c.v[size_t(y * c.w + x)];
  inverse(f, 1);
  return f;
}
// TILED=1 (with TILE=t): the low band of independent t x t tiles, with the residual transform's own
// edge extension (MIRROR): D equal to the residual transform's low band tile by tile, so the
// residual's low band is the coarse level's error also at tile edges.
Image low_band_tiled(const Image& im, int64_t t) {
  Image out{(im.w + 1) / 2, (im.h + 1) / 2, std::vector<double>(size_t(((im.w + 1) / 2) * ((im.h + 1) / 2)))};
  g_mirror = std::getenv("MIRROR") ? std::atoi(std::getenv("MIRROR")) : 0;
  for (int64_t ty = 0; ty < im.h; ty += t)
    for (int64_t tx = 0; tx < im.w; tx += t) {
      const int64_t w = std::min(t, im.w - tx), h = std::min(t, im.h - ty);
      Image tile{w, h, std::vector<double>(size_t(w * h))};
      for (int64_t y = 0; y < h; ++y)
        for (int64_t x = 0; x < w; ++x) tile.at(x, y) = im.v[size_t((ty + y) * im.w + tx + x)];
      forward(tile, 1);
      for (int64_t y = 0; y < (h + 1) / 2; ++y)
        for (int64_t x = 0; x < (w + 1) / 2; ++x) out.at(tx / 2 + x, ty / 2 + y) = tile.at(x, y);
    }
  g_mirror = 0;
  return out;
}
Image low_band(const Image& im) {
  if (std::getenv("TILED") && std::getenv("TILE")) return low_band_tiled(im, std::atoi(std::getenv("TILE")));
  Image c = im;
  forward(c, 1);
  Image out{(im.w + 1) / 2, (im.h + 1) / 2, {}};
  for (int64_t y = 0; y < out.h; ++y)
    for (int64_t x = 0; x < out.w; ++x) out.v.push_back(c.at(x, y));
  return out;
}
size_t tile_rlgr(const std::vector<int32_t>& v, int64_t w, int64_t h) {
  size_t bits = 0;
  for (int64_t ty = 0; ty < h; ty += 32)
    for (int64_t tx = 0; tx < w; tx += 32) {
      std::vector<int32_t> t;
      for (int64_t y = ty; y < std::min(h, ty + 32); ++y)
        for (int64_t x = tx; x < std::min(w, tx + 32); ++x) t.push_back(v[size_t(y * w + x)]);
      bits += rlgr_bits(t);
    }
  return bits;
}
Closed closed_loop(const std::vector<Image>& T, double S, double r) {
  Closed out;
  const int m = int(T.size()) - 1;
  // Coarsest: spatial quantisation, horizontal differences.
  Image rec = T[0];
  {
    const double step = S * std::pow(r, m);
    std::vector<int32_t> q(rec.v.size()), dq(rec.v.size());
    for (size_t i = 0; i < q.size(); ++i)
      q[i] = int32_t(std::lround(T[0].v[i] / step)), rec.v[i] = q[i] * step;
    for (int64_t y = 0; y < rec.h; ++y)
      for (int64_t x = 0; x < rec.w; ++x)
        dq[size_t(y * rec.w + x)] = q[size_t(y * rec.w + x)] - (x ? q[size_t(y * rec.w + x - 1)] : 0);
    out.level_bits.push_back(double(tile_rlgr(dq, rec.w, rec.h)));
    double se = 0;
    for (size_t i = 0; i < q.size(); ++i) se += (rec.v[i] - T[0].v[i]) * (rec.v[i] - T[0].v[i]);
    out.level_rms.push_back(std::sqrt(se / double(q.size())));
  }
  for (int l = 1; l <= m; ++l) {
    const Image& t = T[size_t(l)];
    Image up = upsample(rec, t.w, t.h);
    Image R{t.w, t.h, std::vector<double>(t.v.size())};
    for (size_t i = 0; i < t.v.size(); ++i) R.v[i] = t.v[i] - up.v[i];
    const int64_t tile_side = std::getenv("TILE") ? std::atoi(std::getenv("TILE")) : 0;
    const double Sl = S * std::pow(r, m - l);
    Image Rq{t.w, t.h, std::vector<double>(t.v.size(), 0.0)};
    double bits = 0;
    // Whole level (T = 0) or independent tiles of T x T (hard tile edges, as libcodec's tiles).
    const int64_t tw = tile_side ? tile_side : t.w, th = tile_side ? tile_side : t.h;
    static std::vector<double> norms;
    if (norms.empty()) {
      std::vector<Band> nb = bands_of(64, 64, 1);
      measure_norms(nb, 64, 64, 1);
      for (const Band& b : nb) norms.push_back(b.norm2);
    }
    for (int64_t ty = 0; ty < t.h; ty += th)
      for (int64_t tx = 0; tx < t.w; tx += tw) {
        const int64_t w = std::min(tw, t.w - tx), h = std::min(th, t.h - ty);
        Image tile{w, h, std::vector<double>(size_t(w * h))};
        for (int64_t y = 0; y < h; ++y)
          for (int64_t x = 0; x < w; ++x) tile.at(x, y) = R.at(tx + x, ty + y);
        g_mirror = std::getenv("MIRROR") ? std::atoi(std::getenv("MIRROR")) : 0;
        forward(tile, 1);
        std::vector<Band> bands = bands_of(w, h, 1);
        Image tq{w, h, std::vector<double>(size_t(w * h), 0.0)};
        for (size_t bi = 0; bi < bands.size(); ++bi) {
          const Band& b = bands[bi];
          const double step = Sl / std::sqrt(norms[bi]);
          std::vector<int32_t> q(size_t(b.w * b.h));
          for (int64_t y = 0; y < b.h; ++y)
            for (int64_t x = 0; x < b.w; ++x) {
              const int32_t qi = quantise(tile.at(b.x0 + x, b.y0 + y), step);
              q[size_t(y * b.w + x)] = qi;
              tq.at(b.x0 + x, b.y0 + y) = dequantise(qi, step);
            }
          bits += double(tile_side ? rlgr_bits(q) : tile_rlgr(q, b.w, b.h));
        }
        inverse(tq, 1);
        g_mirror = 0;
        for (int64_t y = 0; y < h; ++y)
          for (int64_t x = 0; x < w; ++x) Rq.at(tx + x, ty + y) = tq.at(x, y);
      }
    rec = up;
    double se = 0;
    for (size_t i = 0; i < rec.v.size(); ++i) {
      rec.v[i] += Rq.v[i];
      se += (rec.v[i] - t.v[i]) * (rec.v[i] - t.v[i]);
    }
    out.level_bits.push_back(bits);
    out.level_rms.push_back(std::sqrt(se / double(rec.v.size())));
  }
  out.rms = out.level_rms.back();
  out.bits = 0;
  for (double b : out.level_bits) out.bits += b;
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: wavelet_pyramid DEM RMS [UPDATE 0|2|4] [LEVELS]\n");
    return 2;
  }
  const Heightmap map = read_heightmap(argv[1]);
  const double target = std::atof(argv[2]);
  if (argc > 3) g_update = std::atoi(argv[3]);
  int levels = 3;
  if (argc > 4) levels = std::atoi(argv[4]);
  const int64_t W = map.width(), H = map.height();
  Image input{W, H, std::vector<double>(size_t(W * H))};
  for (int64_t y = 0; y < H; ++y)
    for (int64_t x = 0; x < W; ++x) input.at(x, y) = map.metres(x, y);
  if (const char* cl = std::getenv("CLOSED")) {
    const double r = std::atof(cl);
    std::vector<Image> T{input};
    for (int l = 0; l < levels; ++l) T.insert(T.begin(), low_band(T.front()));
    if (std::getenv("ROUNDT"))  // coarse truths rounded to the input's unit, as the product stores them
      for (size_t l = 0; l + 1 < T.size(); ++l)
        for (double& v : T[l].v) v = std::round(v);
    if (std::getenv("REFD")) {  // the builder's D cascade (per-terrain optimal 11x11 D) instead
      BuildOptions bo;
      bo.level_count = levels + 1;
      if (std::getenv("LIFTD")) {  // D = the (4,4) lifting low-pass, truncated to 11 taps (+-6: -1/512)
        const double h[11] = {18, -16, -63, 144, 348, 144, -63, -16, 18, 0, 0};
        double h11[11], sum = 0;
        for (int i = 0; i < 11; ++i) h11[i] = i < 1 ? 0 : h[i - 1], sum += h11[i];
        bo.use_fixed_filter = true;
        bo.fixed_filter.kind = DownsampleFilter::Kind::Custom;
        for (int y = 0; y < 11; ++y)
          for (int x = 0; x < 11; ++x)
            bo.fixed_filter.taps[size_t(y * 11 + x)] = h11[y] * h11[x] / (sum * sum);
      }
      const ReferenceLevels ref = reference_levels(map, bo);
      for (size_t l = 0; l < T.size(); ++l)
        for (size_t i = 0; i < T[l].v.size(); ++i) T[l].v[i] = double(ref.levels[l][i]);
    }
    double lo = 0.05, hi = 64;
    Closed best;
    for (int it = 0; it < 25; ++it) {
      const double S = std::sqrt(lo * hi);
      Closed c = closed_loop(T, S, r);
      if (c.rms > target)
        hi = S;
      else
        lo = S, best = c;
    }
    const double N = double(W * H);
    std::printf(
        "%s closed loop r %.2f update %d: S %.3f rms %.4f bits/sample %.4f; per level (coarsest first) b/s "
        "and rms:",
        argv[1], r, g_update, lo, best.rms, best.bits / N);
    for (size_t i = 0; i < best.level_bits.size(); ++i)
      std::printf(" %.3f/%.3f", best.level_bits[i] / N, best.level_rms[i]);
    std::printf("\n");
    return 0;
  }
  Image coeffs = input;
  forward(coeffs, levels);
  std::vector<Band> bands = bands_of(W, H, levels);
  measure_norms(bands, W, H, levels);

  double lo = 0.05, hi = 64;
  Trial best;
  double bestS = 0;
  for (int it = 0; it < 30; ++it) {
    const double S = std::sqrt(lo * hi);
    Trial t = trial(input, coeffs, bands, levels, S);
    if (t.rms > target)
      hi = S;
    else
      lo = S, best = std::move(t), bestS = S;
  }
  const double N = double(W * H);
  size_t rlgr_tile = 0, rlgr_band = 0;
  std::vector<double> level_bits(size_t(levels + 1), 0);
  for (size_t bi = 0; bi < bands.size(); ++bi) {
    const Band& b = bands[bi];
    const std::vector<int32_t>& q = best.Q.q[bi];
    std::vector<int32_t> v = q;
    if (b.orient == 0) {  // coarsest band: horizontal differences (what a DPCM would code)
      for (int64_t y = 0; y < b.h; ++y)
        for (int64_t x = b.w - 1; x >= 1; --x) v[size_t(y * b.w + x)] -= q[size_t(y * b.w + x - 1)];
    }
    rlgr_band += rlgr_bits(v);
    for (int64_t ty = 0; ty < b.h; ty += 32)
      for (int64_t tx = 0; tx < b.w; tx += 32) {
        std::vector<int32_t> t;
        for (int64_t y = ty; y < std::min(b.h, ty + 32); ++y)
          for (int64_t x = tx; x < std::min(b.w, tx + 32); ++x) t.push_back(v[size_t(y * b.w + x)]);
        const size_t bits = rlgr_bits(t);
        rlgr_tile += bits;
        level_bits[size_t(b.level)] += double(bits);
      }
  }
  const double ctx = context_bits(bands, best.Q);
  // (d) libcodec on each band's quantised values, losslessly (its reversible transform, RLGR, tiles of 32).
  size_t codec_bytes = 0;
  for (size_t bi = 0; bi < bands.size(); ++bi) {
    const Band& b = bands[bi];
    if (b.w == 0 || b.h == 0) continue;
    codec::EncodeOptions eo;
    eo.tile_size = 32;
    std::vector<uint8_t> out(codec::encode_bound(b.w, b.h, eo));
    size_t n = 0;
    codec::Scratch scratch;
    if (codec::encode(best.Q.q[bi].data(), b.w, b.w, b.h, eo, out.data(), out.size(), &n, scratch) !=
        codec::Status::Ok)
      std::fprintf(stderr, "encode failed\n");
    codec_bytes += n;
  }
  std::printf("  libcodec lossless on the quantised bands: %.4f bits/sample\n", double(codec_bytes) * 8 / N);
  std::printf("%s rms target %.2f update %d levels %d: S %.3f, finest rms %.4f max %.2f m\n", argv[1], target,
              g_update, levels, bestS, best.rms, best.maxerr);
  std::printf("  bits/sample: rlgr per 32^2 tile %.4f, rlgr per band %.4f, context model %.4f\n",
              double(rlgr_tile) / N, double(rlgr_band) / N, ctx / N);
  std::printf("  rlgr-tile bits by level (finest first, per finest sample):");
  for (double b : level_bits) std::printf(" %.3f", b / N);
  std::printf("\n  error per level (coarsest first): rms/max m:");
  for (size_t i = 0; i < best.level_rms.size(); ++i)
    std::printf(" %.3f/%.2f", best.level_rms[i], best.level_max[i]);
  std::printf("\n");
  return 0;
}
