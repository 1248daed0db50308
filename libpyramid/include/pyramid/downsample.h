// The 11x11 downsampling filter D and its application (L&H 2004 §7). Pure functions; any thread.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>

#include "pyramid/levels.h"

namespace terrain {

// D: 11x11 linear downsampling filter, centred on fine sample (2i, 2j) of coarse sample (i, j).
// Beyond the edges the fine level is extended by mirror reflection without repeating the edge
// sample (f[-k] = f[k], f[n-1+k] = f[n-1-k]; folded repeatedly for levels narrower than 6).

struct DownsampleFilter {
  static constexpr int kRadius = 5;
  static constexpr int kSize = 2 * kRadius + 1;
  enum class Kind { Optimal, Default, Impulse, Box2x2, Custom, Wavelet };
  Kind kind = Kind::Default;
  // taps[(dy + 5) * 11 + (dx + 5)] weighs fine sample (2i + dx, 2j + dy). Sums to 1.
  std::array<double, kSize * kSize> taps{};

  double tap(int dx, int dy) const { return taps[size_t((dy + kRadius) * kSize + (dx + kRadius))]; }
  // True when symmetric in x, in y and about the diagonal (enables the folded fast path).
  bool symmetric8() const;
  double sum() const;

  // The default used when the least-squares fit is degenerate: the separable tent
  // (1/4, 1/2, 1/4) x (1/4, 1/2, 1/4).
  static DownsampleFilter default_filter();
  // The dual of U: the analysis low pass of the (4,4) interpolating lifting wavelet whose predict
  // step is U's four-point filter (predict (-1, 9, 9, -1) / 16, update (-1, 9, 9, -1) / 32), i.e.
  // (-1, 0, 18, -16, -63, 144, 348, 144, -63, -16, 18, 0, -1) / 512 with its +-6 taps (-1/512) dropped
  // to fit 11 taps and the rest renormalised by 514; separable (h x h). With it the low band of the
  // residual's lifting transform is (nearly) the coarse level's own coding error, so the closed loop
  // re-codes less: 1.0-3.3 % fewer bits than the fitted optimal D at equal finest-level rms, max error
  // and lossless on the shared DEMs (docs/pyramid.md "D: the wavelet filter"), and no fit to run.
  static DownsampleFilter wavelet();
  // True when the taps are exactly wavelet()'s, whatever `kind` says (the D engine's separable path,
  // the file's provenance and the build log all decide by this).
  bool is_wavelet() const;
  // Plain subsampling: coarse (i, j) = fine (2i, 2j). The point-sampled pyramid of --max-error and
  // --lossless builds: every level's samples are input samples, so a residual's even phase is the
  // coarse level's own error and libcodec's phase tiles skip it (docs/pyramid.md "D: point sampling").
  static DownsampleFilter impulse();
  // True when the taps are exactly impulse()'s.
  bool is_point() const;
  // The 2x2 box of fine (2i..2i+1, 2j..2j+1) (a half-sample shift: the mipmap baseline).
  static DownsampleFilter box2x2();
  // An 8-fold symmetric filter from its 21 orbit weights (see symmetric_orbits()).
  static DownsampleFilter from_orbit_weights(const std::array<double, 21>& w, Kind kind);
};

// The 21 orbits of offsets under the 8-fold symmetry: orbit k holds all (dx, dy) with
// (max(|dx|,|dy|), min(|dx|,|dy|)) == orbit_key(k). Returns, for each k, {a, b, member count}.
struct FilterOrbit {
  int a, b, count;
};
const std::array<FilterOrbit, 21>& symmetric_orbits();

// coarse = round(D(fine)) (half away from zero, saturated to int32); coarse is
// coarse_extent(w) x coarse_extent(h). Same row engine as the streaming builder.
void downsample(const DownsampleFilter& filter, const int32_t* fine, GridSize fine_level, int32_t* coarse,
                int threads = 1);

}  // namespace terrain
