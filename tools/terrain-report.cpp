// terrain-report: how far a compressed pyramid is from its source: per-level and overall error in
// metres, bits per finest sample, compression factor, build and decode speed, and an error heat-map.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>

#include "cli.h"
#include "json_writer.h"
#include "plot.h"
#include "pyramid/error_stats.h"
#include "pyramid/reference.h"
#include "raster.h"
#include "report_file.h"
#include "runtime/region_decoder.h"

namespace {

using namespace terrain;
using namespace terrain::runtime;
using namespace terrain::container;

// Linear ramp black -> blue -> magenta -> orange -> yellow, for e in [0, 1].
void heat_colour(double e, uint8_t* rgb) {
  static const double stops[5][3] = {
      {0, 0, 0}, {20, 40, 160}, {170, 40, 150}, {250, 130, 30}, {255, 250, 150}};
  e = std::clamp(e, 0.0, 1.0) * 4;
  const int i = std::min(3, int(e));
  const double f = e - i;
  for (int c = 0; c < 3; ++c) rgb[c] = uint8_t(stops[i][c] + f * (stops[i + 1][c] - stops[i][c]) + 0.5);
}

// Writes a picture (write_image8 goes through a temporary, renamed when whole).
void write_picture(const cli::Canvas& canvas, const std::string& path, const char* what) {
  try {
    canvas.write_png(path);
  } catch (const Error& e) {
    throw Error(ErrorCode::WriteFailed, std::string("cannot write the ") + what + ": " + e.what());
  }
}

// The heat map of |error| with a colour scale bar below it (0 .. scale_max metres, labelled).
void write_heatmap(const std::string& path, const std::vector<float>& abs_err, int64_t w, int64_t h,
                   double scale_max) {
  // Max-pool to at most 2048 pixels on the longer side so isolated large errors stay visible.
  const int64_t f = std::max<int64_t>(1, (std::max(w, h) + 2047) / 2048);
  const int64_t ow = (w + f - 1) / f, oh = (h + f - 1) / f;
  // The scale panel: at least 320 pixels wide, 3x text on maps wider than 1200 pixels.
  const int scale = ow > 1200 ? 3 : ow > 600 ? 2 : 1, panel_h = 26 * scale + 12;
  cli::Canvas canvas(int(std::max<int64_t>(ow, 320)), int(oh) + panel_h, {255, 255, 255, 255});
  uint8_t rgb[3];
  for (int64_t oy = 0; oy < oh; ++oy)
    for (int64_t ox = 0; ox < ow; ++ox) {
      float m = 0;
      bool any = false;
      for (int64_t y = oy * f; y < std::min(h, (oy + 1) * f); ++y)
        for (int64_t x = ox * f; x < std::min(w, (ox + 1) * f); ++x) {
          const float e = abs_err[size_t(y * w + x)];
          if (!std::isnan(e)) m = std::max(m, e), any = true;
        }
      if (!any)
        rgb[0] = rgb[1] = rgb[2] = 128;  // void
      else
        heat_colour(scale_max > 0 ? m / scale_max : 0, rgb);
      canvas.set(int(ox), int(oy), {rgb[0], rgb[1], rgb[2], 255});
    }
  // Scale bar: the ramp from 0 to the finest level's max |error|, five labelled ticks, units.
  const cli::Rgba ink{0, 0, 0, 255};
  const std::string units = "|error|, metres (grey: void)";
  const int bar_x = 8 * scale, bar_w = canvas.width() - 16 * scale, bar_y = int(oh) + 4 * scale,
            bar_h = 8 * scale;
  for (int x = 0; x < bar_w; ++x) {
    heat_colour(double(x) / std::max(1, bar_w - 1), rgb);
    canvas.fill_rect(bar_x + x, bar_y, 1, bar_h, {rgb[0], rgb[1], rgb[2], 255});
  }
  for (int t = 0; t <= 4; ++t) {
    const int x = bar_x + int(std::lround(double(t) * (bar_w - 1) / 4));
    canvas.fill_rect(x, bar_y + bar_h, std::max(1, scale / 2), 2 * scale, ink);
    const std::string label = cli::tick_label(scale_max * t / 4);
    const int tw = cli::Canvas::text_width(label, scale);
    canvas.text(std::clamp(x - tw / 2, 0, canvas.width() - tw), bar_y + bar_h + 3 * scale, label, ink, scale);
  }
  canvas.text(canvas.width() - cli::Canvas::text_width(units, scale) - 8 * scale, bar_y + bar_h + 12 * scale,
              units, ink, scale);
  write_picture(canvas, path, "heat-map");
}

// Per-level error plot: rms, 99.9th percentile and max |error| (metres, log axis) against the level.
void write_plot(const std::string& path, const std::vector<ErrorStats>& per_level, const std::string& title) {
  cli::PlotAxes axes;
  axes.title = title;
  axes.x_label = "pyramid level (0 = coarsest)";
  axes.y_label = "|error|, metres";
  axes.log_y = true;
  for (size_t l = 0; l < per_level.size(); ++l) axes.x_ticks.emplace_back(double(l), std::to_string(l));
  const struct {
    const char* name;
    cli::Rgba colour;
    double ErrorStats::*field;
  } fields[3] = {{"max", {200, 40, 40, 255}, &ErrorStats::max_abs},
                 {"p99.9", {230, 140, 20, 255}, &ErrorStats::p999_abs},
                 {"rms", {30, 80, 200, 255}, &ErrorStats::rms}};
  std::vector<cli::PlotSeries> series;
  for (const auto& f : fields) {
    cli::PlotSeries s{f.name, f.colour, {}, {}};
    // max is drawn first and wider: where it equals the 99.9th percentile (coarse levels coded more
    // finely than the finest, a bounded target) the orange line lies inside the red one.
    if (f.field == &ErrorStats::max_abs) s.thickness = 6;
    for (size_t l = 0; l < per_level.size(); ++l)
      s.x.push_back(double(l)), s.y.push_back(per_level[l].*f.field);
    series.push_back(std::move(s));
  }
  write_picture(cli::line_plot(series, axes), path, "plot");
}

int run(int argc, char** argv) {
  std::string input, pyr_path, json_path, heatmap, plot;
  cli::CommonFlags common;
  ReadOptions read_options;
  cli::ArgParser parser(
      "terrain-report",
      "INPUT PYRAMID.pyr [--json FILE] [--heatmap FILE.png] [--plot FILE.png] [read options]",
      "Compares a pyramid file with the input it was built from. Per level and overall: rms,\n"
      "max |error|, 99.9th percentile of |error| (metres) and PSNR = 20 log10((zmax-zmin)/rms) dB,\n"
      "where level l of the source is the builder's own filtered level (same D filter, same void\n"
      "fill) and zmin/zmax are the finest source level's. Also bits per finest sample,\n"
      "compression factor against the source samples, build time (from the file) and decode time.\n"
      "Holds the input in memory (8 bytes per sample).");
  parser.positional("INPUT", "the heightmap the pyramid was built from", &input);
  parser.positional("PYRAMID", "the .pyr file", &pyr_path);
  parser.option("--json", "FILE", "write the report as JSON to FILE ('-' for stdout)", &json_path);
  parser.option("--heatmap", "FILE",
                "write a PNG of |error| at the finest level (grey = void) with a colour scale in metres",
                &heatmap);
  parser.option("--plot", "FILE",
                "write a PNG plot of rms, 99.9th percentile and max |error| per level (metres, log axis)",
                &plot);
  cli::add_read_options(parser, read_options);
  parser.add_common(common, false);
  if (auto status = parser.parse(argc, argv)) return *status;

  auto file = PyramidFile::open(pyr_path);
  const ContainerInfo& info = file->info();
  const Heightmap map = read_heightmap(input, read_options);
  if (uint64_t(map.width()) != info.width || uint64_t(map.height()) != info.height)
    throw Error(ErrorCode::DimensionMismatch,
                input + ": " + std::to_string(map.width()) + "x" + std::to_string(map.height()) +
                    " does not match the pyramid's " + std::to_string(info.width) + "x" +
                    std::to_string(info.height));
  // The reference below is built without the builder's centring offset, so its units map to metres
  // with the input's own offset.
  const double mpu = info.vertical_scale, off = map.info.vertical_offset;

  // The source levels exactly as the builder formed them, with the stored filter.
  BuildOptions bo;
  bo.level_count = file->level_count();
  bo.value_scale = map.info.vertical_scale / mpu;
  bo.use_fixed_filter = true;
  bo.fixed_filter = file->downsample_filter();
  const ReferenceLevels source = reference_levels(map, bo);

  double zmin = INFINITY, zmax = -INFINITY;
  for (int64_t i = 0; i < map.width() * map.height(); ++i)
    if (map.valid.empty() || map.valid[size_t(i)]) {
      const double z = map.values[size_t(i)] * map.info.vertical_scale + map.info.vertical_offset;
      zmin = std::min(zmin, z), zmax = std::max(zmax, z);
    }
  const double range = zmax > zmin ? zmax - zmin : 1.0;

  RegionDecoder decoder(file, 0);
  const int levels = file->level_count();
  std::vector<ErrorStats> per_level(static_cast<size_t>(levels));
  std::vector<double> all_err;
  std::vector<float> finest_err;
  double decode_seconds = 0;
  int64_t voids_mismatch = 0;  // input voids the pyramid decodes as data
  int64_t voids_added = 0;     // input data the pyramid decodes as void (a pyramid of another input)
  for (int l = 0; l < levels; ++l) {
    const GridSize s = file->level_size(l);
    std::vector<float> dec(size_t(s.width * s.height));
    const auto t0 = std::chrono::steady_clock::now();
    decoder.decode_metres(l, terrain::Rect{0, 0, s.width, s.height}, dec.data(), s.width);
    if (l == levels - 1)
      decode_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const std::vector<int32_t>& ref = source.levels[size_t(l)];
    std::vector<double> err;
    err.reserve(dec.size());
    if (l == levels - 1) finest_err.assign(dec.size(), NAN);
    for (size_t i = 0; i < dec.size(); ++i) {
      const bool valid = l < levels - 1 || map.valid.empty() || map.valid[i];
      if (!valid) {
        if (!std::isnan(dec[i])) ++voids_mismatch;
        continue;
      }
      if (std::isnan(dec[i])) {  // no error to measure there: counted, left out of the figures
        ++voids_added;
        continue;
      }
      // float output holds metres to about 1e-7 relative; the error is measured on that output.
      const double e = std::abs(double(dec[i]) - (double(ref[i]) * mpu + off));
      err.push_back(e);
      if (l == levels - 1) finest_err[i] = float(e);
    }
    all_err.insert(all_err.end(), err.begin(), err.end());
    per_level[size_t(l)] = error_stats(err, range);
  }
  const ErrorStats overall = error_stats(all_err, range);
  const ErrorStats& finest = per_level.back();

  const uint64_t bytes = std::filesystem::file_size(pyr_path);
  const int64_t samples = map.width() * map.height();
  const double bits = 8.0 * double(bytes) / double(samples);
  const int source_bits =
      map.info.sample_type == SampleType::Int16 || map.info.sample_type == SampleType::UInt16 ? 16
      : map.info.sample_type == SampleType::TerrainRGB                                        ? 24
                                                                                              : 32;

  if (!heatmap.empty()) write_heatmap(heatmap, finest_err, map.width(), map.height(), finest.max_abs);
  if (!plot.empty())
    write_plot(plot, per_level, "error per level: " + std::filesystem::path(pyr_path).filename().string());

  if (!common.quiet) {
    std::printf("%s vs %s: %dx%d, %d levels, %s\n", pyr_path.c_str(), input.c_str(), int(map.width()),
                int(map.height()), levels,
                voids_mismatch ? "VOIDS NOT RESTORED"
                : voids_added  ? "VOIDS DIFFER (the pyramid has voids where the input has data)"
                               : "voids restored");
    if (voids_added)
      std::printf(
          "%lld samples are void in the pyramid but not in the input: left out of the figures below\n",
          (long long)voids_added);
    std::printf("%-6s %11s %10s %10s %10s %8s\n", "level", "size", "rms m", "max m", "p99.9 m", "PSNR dB");
    for (int l = 0; l < levels; ++l) {
      const GridSize s = file->level_size(l);
      const ErrorStats& e = per_level[size_t(l)];
      std::printf("%-6d %5lldx%-5lld %10.4f %10.4f %10.4f %8.2f\n", l, (long long)s.width,
                  (long long)s.height, e.rms, e.max_abs, e.p999_abs, e.psnr_db);
    }
    std::printf("%-6s %11s %10.4f %10.4f %10.4f %8.2f\n", "all", "", overall.rms, overall.max_abs,
                overall.p999_abs, overall.psnr_db);
    std::printf(
        "size %llu bytes, %.4f bits per finest sample, compression factor %.2f (vs %d-bit source samples)\n",
        (unsigned long long)bytes, bits, double(source_bits) / bits, source_bits);
    std::printf("finest-level decode %.3f s (%.1f Msamples/s, one thread, cold cache)\n", decode_seconds,
                samples / 1e6 / std::max(1e-9, decode_seconds));
  }
  if (!json_path.empty()) {
    cli::ReportFile report(json_path);
    std::ostream& os = report.stream();
    cli::JsonWriter j(os);
    auto put = [&](const ErrorStats& e) {
      j.field("samples", e.count)
          .field("rms_m", e.rms)
          .field("max_m", e.max_abs)
          .field("p999_m", e.p999_abs)
          .field("psnr_db", e.psnr_db);
    };
    j.begin_object();
    j.field("input", input)
        .field("pyramid", pyr_path)
        .field("width", map.width())
        .field("height", map.height());
    j.field("bytes", int64_t(bytes))
        .field("bits_per_sample", bits)
        .field("compression_factor", double(source_bits) / bits);
    j.field("zmin_m", zmin).field("zmax_m", zmax).field("voids_restored", voids_mismatch == 0);
    j.field("voids_added", voids_added);
    j.field("decode_seconds", decode_seconds);
    j.field("decode_msamples_per_s", samples / 1e6 / std::max(1e-9, decode_seconds));
    j.key("overall").begin_object();
    put(overall);
    j.end_object();
    j.key("levels").begin_array();
    for (int l = 0; l < levels; ++l) {
      j.begin_object();
      j.field("level", l)
          .field("width", file->level_size(l).width)
          .field("height", file->level_size(l).height);
      put(per_level[size_t(l)]);
      j.end_object();
    }
    j.end_array();
    j.end_object();
    j.finish();
    report.finish();
  }
  return voids_mismatch || voids_added ? 10 : 0;
}

}  // namespace

int main(int argc, char** argv) {
  return cli::run_tool("terrain-report", [&] { return run(argc, argv); });
}
