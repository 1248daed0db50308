// clipmap-view's verification: the reference flight (another pyramid, or the original input's own
// levels) rendered beside the pyramid's, its image PSNR, and the screen-space geometric error of the
// rendered levels against the original (L&H 2004 Table 2).
#include <cmath>
#include <cstdio>
#include <iostream>
#include <stdexcept>

#include "clipmap_view.h"

namespace clipmap_view {

using namespace terrain;
using namespace terrain::runtime;
using namespace terrain::container;

std::optional<int> open_reference(const Flight& flight, Reference& out) {
  const ViewOptions& o = flight.options;
  const PyramidFile& file = *flight.file;
  const int finest_level = file.level_count() - 1;
  if (flight.ref_file) {
    if (flight.ref_file->level_count() != file.level_count() ||
        !(flight.ref_file->level_size(finest_level) == file.level_size(finest_level))) {
      std::cerr << "clipmap-view: error: " << o.reference << ": levels or size differ from " << o.pyramid
                << "\n";
      return 5;
    }
    out.source = std::make_unique<RegionDecoderSource>(std::make_shared<const RegionDecoder>(flight.ref_file),
                                                       flight.spacing);
  } else if (!o.original.empty()) {
    const ContainerInfo& info = file.info();
    ReadOptions ro;
    const GridInfo gi = probe(o.original);
    // An integer input is stored in its own unit: the pyramid's scale is the input's (e.g. 0.1 m for
    // the Puget Sound PNG, which the file itself does not say).
    if (o.original_vscale)
      ro.vertical_scale = *o.original_vscale;
    else if (gi.integer_valued())
      ro.vertical_scale = info.vertical_scale, ro.vertical_offset = info.vertical_offset;
    const auto t0 = Clock::now();
    try {
      auto grid = std::make_unique<GridHeightSource>(
          original_source(o.original, ro, file.level_size(finest_level), file.level_count(),
                          file.downsample_filter(), flight.spacing));
      out.original = grid.get();
      out.source = std::move(grid);
    } catch (const std::invalid_argument& e) {
      std::cerr << "clipmap-view: error: " << e.what() << "\n";
      return 5;
    }
    if (!o.quiet)
      std::cerr << "clipmap-view: lossless pyramid of " << o.original << " in " << since(t0) << " s\n";
  }
  return std::nullopt;
}

std::vector<LevelScreenError> report_screen_space_error(const Flight& flight,
                                                        const GridHeightSource& original, int first_level,
                                                        double s_px, DamageLog& damage) {
  const ViewOptions& o = flight.options;
  const auto decoder =
      std::make_shared<const RegionDecoder>(flight.file, size_t(256) << 20, DamagePolicy::Degrade);
  RegionDecoderSource table_source(decoder, flight.spacing);
  std::vector<LevelScreenError> sse = screen_space_error(table_source, original, first_level, s_px);
  damage.poll(*decoder);
  std::printf("screen-space geometric error, %dx%d, vertical fov %g deg, n=%d: s = %.2f px per grid cell\n",
              o.width, o.height, o.fov, flight.clipmap.n, s_px);
  std::printf("%6s %12s %10s %10s %10s %12s %10s\n", "level", "spacing_m", "rms_m", "max_m", "rms_px",
              "p99.9_px", "max_px");
  for (const LevelScreenError& e : sse)
    std::printf("%6d %12.1f %10.3f %10.3f %10.4f %12.4f %10.4f\n", e.level, e.spacing_m, e.rms_m, e.max_m,
                e.rms_px, e.p999_px, e.max_px);
  std::fflush(stdout);
  return sse;
}

double image_psnr(const std::vector<uint8_t>& pixels, const std::vector<uint8_t>& reference) {
  double sq = 0;
  for (size_t i = 0; i < pixels.size(); ++i)
    if (i % 4 != 3) sq += double((int(pixels[i]) - int(reference[i])) * (int(pixels[i]) - int(reference[i])));
  const double mse = sq / double(pixels.size() / 4 * 3);
  return mse > 0 ? 10.0 * std::log10(255.0 * 255.0 / mse) : 99.0;  // 99 dB: identical frames
}

}  // namespace clipmap_view
