// clipmap-view --bench: full refills of every clipmap level, one core, a fresh decoder (empty tile
// cache) for every repetition, at positions spread over the terrain. Each level's refill is split as
// the clipmap reports it: U of the coarser clipmap level, the residual (entropy decode and addition),
// the rest of the fill (units to metres, edge replication, toroidal copies; for the coarsest level,
// whose coarser level is not in the clipmap, the whole recursive region decode), zc, normals and z
// bounds. Then the two halves of the region decode of one n x n window of the finest level measured
// apart by the region decoder itself: U of the coarser level and the residual.
#include <algorithm>
#include <array>
#include <cstdio>

#include "clipmap_view.h"

namespace clipmap_view {

using namespace terrain;
using namespace terrain::runtime;
using namespace terrain::container;

namespace {

// The finest level's window, split: U (coarse window decoded beforehand, untimed) and residual.
void bench_finest_window(const std::shared_ptr<const PyramidFile>& file, int n, int reps) {
  const int fl = file->level_count() - 1;
  const GridSize fs = file->level_size(fl);
  const int64_t w = std::min<int64_t>(n, fs.width), h = std::min<int64_t>(n, fs.height);
  const Rect win{(fs.width - w) / 2, (fs.height - h) / 2, w, h};
  // No residual cache: every repetition entropy-decodes the window's tiles.
  const RegionDecoder dec(file, 0);
  const Rect need = upsample_required_window(win, fs);
  std::vector<int32_t> coarse(size_t(need.width * need.height)), out(size_t(w * h));
  dec.decode_units(fl - 1, need, coarse.data(), need.width);
  const CoarseWindow cw{coarse.data(), need.width, need, file->level_size(fl - 1)};
  std::vector<double> tu, tr;
  for (int r = 0; r < std::max(reps, 5); ++r) {
    double seconds_upsample = 0, seconds_residual = 0;
    dec.decode_refined(fl, win, cw, out.data(), w, &seconds_upsample, &seconds_residual);
    tu.push_back(seconds_upsample * 1e3);
    tr.push_back(seconds_residual * 1e3);
  }
  std::printf(
      "finest level %lldx%lld window, median: U (upsample_region) %.3f ms, residual entropy decode %.3f "
      "ms\n",
      (long long)w, (long long)h, percentile(tu, 0.5), percentile(tr, 0.5));
}

}  // namespace

int run_bench(const std::shared_ptr<const PyramidFile>& file, double spacing, ClipmapOptions copt, int reps,
              bool quiet) {
  copt.budget = int64_t(1) << 40;
  copt.deactivate_by_height = false;
  const int levels = clipmap_level_count(copt, file->level_count());
  const GridSize fs = file->level_size(file->level_count() - 1);
  enum Part { kUpsample, kResidual, kFillOther, kZc, kNormals, kBounds, kTotal, kParts };
  std::vector<std::array<std::vector<double>, kParts>> t(static_cast<size_t>(levels));
  for (int r = 0; r < reps; ++r) {
    auto decoder = std::make_shared<const RegionDecoder>(file);
    RegionDecoderSource source(decoder, spacing);
    Clipmap cm(source, copt);
    const double fx = 0.3 + 0.4 * double(r % 5) / 4.0, fy = 0.3 + 0.4 * double((r * 3) % 5) / 4.0;
    const ClipmapUpdateStats s =
        cm.update(fx * double(fs.width) * spacing, fy * double(fs.height) * spacing, 0.0);
    for (int l = 0; l < levels; ++l) {
      const auto& p = s.per_level[size_t(l)];
      const double v[kParts] = {p.seconds_upsample,
                                p.seconds_residual,
                                p.seconds_fill - p.seconds_upsample - p.seconds_residual,
                                p.seconds_coarse,
                                p.seconds_normals,
                                p.seconds_bounds,
                                p.seconds_fill + p.seconds_coarse + p.seconds_normals + p.seconds_bounds};
      for (int k = 0; k < kParts; ++k) t[size_t(l)][size_t(k)].push_back(v[k] * 1e3);
    }
  }
  std::printf(
      "full %dx%d level refill, one core, median of %d (ms): U = upsampling of the coarser clipmap level, "
      "residual = residual decode + addition, fill+ = rest of the fill (level 0: its whole recursive "
      "decode), "
      "zc, normals (2x normal map), z bounds; total = their sum; total_min = the fastest repetition\n",
      copt.n, copt.n, reps);
  std::printf("%6s %7s %8s %9s %8s %7s %8s %7s %8s %10s\n", "level", "source", "U", "residual", "fill+", "zc",
              "normals", "bounds", "total", "total_min");
  const int first = file->level_count() - levels;
  for (int l = 0; l < levels; ++l) {
    auto med = [&](int k) { return percentile(t[size_t(l)][size_t(k)], 0.5); };
    std::printf("%6d %7d %8.3f %9.3f %8.3f %7.3f %8.3f %7.3f %8.3f %10.3f\n", l, first + l, med(kUpsample),
                med(kResidual), med(kFillOther), med(kZc), med(kNormals), med(kBounds), med(kTotal),
                percentile(t[size_t(l)][kTotal], 0.0));
  }
  if (file->level_count() > 1) bench_finest_window(file, copt.n, reps);
  if (!quiet) std::fflush(stdout);
  return 0;
}

}  // namespace clipmap_view
