// clipmap-view: plays a camera flight over a compressed pyramid through the geometry clipmap and
// the headless OpenGL renderer; writes PNG frames and per-frame statistics (CSV and JSON).
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <optional>
#include <sstream>

#include "cli.h"
#include "codec/codec.h"
#include "container/container.h"
#include "json_writer.h"
#include "pyramid/pyramid.h"
#include "render/renderer.h"
#include "runtime/clipmap.h"
#include "runtime/region_decoder.h"
#include "runtime/synthesis.h"

using namespace terrain;
using namespace terrain::runtime;

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// One keyframe: position in metres (x east along columns, y along rows), height above the ground,
// heading and pitch in degrees.
struct Key {
  double frame, x, y, above, yaw_deg, pitch_deg;
};

std::vector<Key> read_path(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw Error(ErrorCode::NotFound, "cannot open camera path " + path);
  std::vector<Key> keys;
  std::string line;
  int number = 0;
  while (std::getline(in, line)) {
    ++number;
    const auto hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    std::istringstream s(line);
    Key k{};
    if (!(s >> k.frame)) continue;  // blank or comment line
    if (!(s >> k.x >> k.y >> k.above >> k.yaw_deg >> k.pitch_deg) ||
        !std::isfinite(k.x + k.y + k.above + k.yaw_deg + k.pitch_deg))
      throw Error(ErrorCode::MissingField, path + ":" + std::to_string(number) +
                                               ": expected 'frame x_m y_m above_m yaw_deg pitch_deg'");
    if (!keys.empty() && k.frame <= keys.back().frame)
      throw Error(ErrorCode::MissingField,
                  path + ":" + std::to_string(number) + ": frame numbers must increase");
    keys.push_back(k);
  }
  if (keys.empty()) throw Error(ErrorCode::MissingField, path + ": no keyframes");
  return keys;
}

// The built-in flight: towards the highest point of the coarsest level (so the default shows relief
// rather than sea), past it, then a climbing turn. Distances scale with the terrain's extent.
std::vector<Key> default_path(HeightSource& source, double spacing, int frames) {
  const GridSize c = source.level_size(0);
  std::vector<float> coarse(size_t(c.width * c.height));
  source.fill(0, Rect{0, 0, c.width, c.height}, coarse.data(), c.width);
  const size_t peak = size_t(std::max_element(coarse.begin(), coarse.end()) - coarse.begin());
  const double cs = std::ldexp(spacing, source.level_count() - 1);  // metres per coarsest sample
  // Kept in the middle of the terrain: beyond its edges the clipmap shows the repeated edge samples.
  const double wm = double(c.width) * cs, hm = double(c.height) * cs;
  const double px = std::clamp(double(int64_t(peak) % c.width) * cs, 0.45 * wm, 0.7 * wm);
  const double py = std::clamp(double(int64_t(peak) / c.width) * cs, 0.4 * hm, 0.55 * hm);
  const double ext = std::max(wm, hm), f = std::max(frames - 1, 1);
  return {{0, px - 0.25 * ext, py - 0.10 * ext, 0.008 * ext, 20, -14},
          {0.6 * f, px - 0.06 * ext, py - 0.03 * ext, 0.008 * ext, 25, -16},
          {0.8 * f, px + 0.01 * ext, py + 0.02 * ext, 0.015 * ext, 90, -22},
          {f, px, py + 0.08 * ext, 0.04 * ext, 180, -35}};
}

Key interpolate(const std::vector<Key>& keys, double frame) {
  if (frame <= keys.front().frame) return keys.front();
  if (frame >= keys.back().frame) return keys.back();
  size_t i = 1;
  while (keys[i].frame < frame) ++i;
  const Key &a = keys[i - 1], &b = keys[i];
  const double t = (frame - a.frame) / (b.frame - a.frame);
  auto mix = [t](double u, double v) { return u + (v - u) * t; };
  return Key{frame,
             mix(a.x, b.x),
             mix(a.y, b.y),
             mix(a.above, b.above),
             mix(a.yaw_deg, b.yaw_deg),
             mix(a.pitch_deg, b.pitch_deg)};
}

// CPU seconds of the whole process (all threads, llvmpipe's included): on a shared machine a steadier
// measure of the work per frame than wall time.
double cpu_seconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
         1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const double k = std::clamp(std::ceil(p * double(v.size())) - 1, 0.0, double(v.size() - 1));
  return v[size_t(k)];
}

// --bench: full refills of every clipmap level, one core, a fresh decoder (empty tile cache) for
// every repetition, at positions spread over the terrain. Each level's refill is split as the
// clipmap reports it: U of the coarser clipmap level, the residual (entropy decode and addition),
// the rest of the fill (units to metres, edge replication, toroidal copies; for the coarsest level,
// whose coarser level is not in the clipmap, the whole recursive region decode), zc, normals and z
// bounds. Then the two halves of the region decode of one n x n window of the finest level measured
// apart, straight from libcodec: U of the coarser level and the entropy decode of the residual.
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

  // The finest level's window, split: U (coarse window decoded beforehand, untimed) and residual.
  const int fl = file->level_count() - 1;
  if (fl > 0) {
    const int64_t w = std::min<int64_t>(copt.n, fs.width), h = std::min<int64_t>(copt.n, fs.height);
    const Rect win{(fs.width - w) / 2, (fs.height - h) / 2, w, h};
    RegionDecoder dec(file);
    const Rect need = upsample_required_window(win, fs);
    std::vector<int32_t> coarse(size_t(need.width * need.height)), out(size_t(w * h)),
        residual(size_t(w * h));
    dec.decode_units(fl - 1, need, coarse.data(), need.width);
    const CoarseWindow cw{coarse.data(), need.width, need, file->level_size(fl - 1)};
    UpsampleScratch us;
    codec::Scratch cs;
    std::vector<double> tu, tr;
    for (int r = 0; r < std::max(reps, 5); ++r) {
      auto t0 = Clock::now();
      upsample_region(cw, fs, win, out.data(), w, us);
      tu.push_back(since(t0) * 1e3);
      t0 = Clock::now();
      const auto& bands = file->bands(fl);
      for (size_t b = file->band_of_row(fl, win.y0); b < bands.size() && bands[b].y0 < win.y0 + h; ++b) {
        const int64_t y0 = std::max(win.y0, bands[b].y0),
                      y1 = std::min(win.y0 + h, bands[b].y0 + bands[b].rows);
        codec::Decoder d;
        if (d.open(bands[b].data, bands[b].size) != codec::Status::Ok ||
            d.decode_region(codec::Rect{win.x0, y0 - bands[b].y0, w, y1 - y0}, residual.data(), w, cs) !=
                codec::Status::Ok)
          throw Error(ErrorCode::CorruptData,
                      file->path() + ": residual band " + std::to_string(b) + " does not decode");
      }
      tr.push_back(since(t0) * 1e3);
    }
    std::printf(
        "finest level %lldx%lld window, median: U (upsample_region) %.3f ms, residual entropy decode %.3f "
        "ms\n",
        (long long)w, (long long)h, percentile(tu, 0.5), percentile(tr, 0.5));
  }
  if (!quiet) std::fflush(stdout);
  return 0;
}

int run(int argc, char** argv) {
  std::string pyramid, out_dir = "clipmap-frames", path_file, reference, original;
  std::optional<double> original_vscale;
  int bench = 0, synth_levels = 0;
  double synth_detail = 1.0;
  int width = 640, height = 480, n = 255, levels = 0, frames = 300, png_every = 1;
  int64_t budget = 0;
  double fov = 60;
  std::optional<double> max_screen_error;
  bool n_given = false;
  bool no_transitions = false, no_culling = false;
  cli::CommonFlags common;
  cli::ArgParser p(
      "clipmap-view", "PYRAMID [options]",
      "Flies a camera over a compressed pyramid (.pyr) with the geometry clipmap, renders each frame\n"
      "off-screen with OpenGL 4.5 core through EGL (Mesa llvmpipe when there is no GPU), and writes\n"
      "PNG frames, stats.csv (one row per frame) and stats.json (summary) into --out.");
  p.positional("PYRAMID", "compressed pyramid file written by pyramid-build", &pyramid);
  p.option("--out", "DIR", "output directory (default clipmap-frames)",
           [&](const std::string& v) { out_dir = v; });
  p.option("--path", "FILE",
           "camera keyframes, one per line: frame x_m y_m above_ground_m yaw_deg pitch_deg (# comments);\n"
           "linear in between. Default: a built-in pass over the terrain",
           [&](const std::string& v) { path_file = v; });
  p.option("--width", "PX", "frame width (default 640)",
           [&](const std::string& v) { width = int(cli::parse_int("--width", v, 16, 8192)); });
  p.option("--height", "PX", "frame height (default 480)",
           [&](const std::string& v) { height = int(cli::parse_int("--height", v, 16, 8192)); });
  p.option("--n", "N", "clipmap level size, 2^k-1 in 15..1023 (default 255)", [&](const std::string& v) {
    n = int(cli::parse_int("--n", v, 15, 1023));
    n_given = true;
    if (((n + 1) & n) != 0) throw cli::UsageError("--n must be 2^k - 1, got " + v);
  });
  p.option("--max-screen-error", "PX",
           "choose n instead of --n: the smallest 2^k-1 (15..1023) whose 99.9th-percentile screen-space\n"
           "geometric error (L&H 2004 Table 2, at this --width/--height/--fov) is at most PX pixels on\n"
           "the worst rendered level, from the pyramid's own finest level plus that level's compression\n"
           "error as the file records it (a bound; files of format 1.0 lack the record and get an estimate\n"
           "without it; --original reports the true figures). Rugged 90 m DEMs need n = 511 for 1 px",
           [&](const std::string& v) {
             max_screen_error = cli::parse_double("--max-screen-error", v);
             if (!(*max_screen_error > 0 && *max_screen_error <= 1000))
               throw cli::UsageError("--max-screen-error must be in (0, 1000] pixels");
           });
  p.option("--levels", "L", "clipmap levels (default: all pyramid levels)",
           [&](const std::string& v) { levels = int(cli::parse_int("--levels", v, 1, 30)); });
  p.option("--budget", "SAMPLES", "samples refilled per frame (default n*n)",
           [&](const std::string& v) { budget = cli::parse_int("--budget", v, 1, int64_t(1) << 40); });
  p.option("--fov", "DEG", "vertical field of view (default 60)", [&](const std::string& v) {
    fov = cli::parse_double("--fov", v);
    if (!(fov > 1 && fov < 179)) throw cli::UsageError("--fov must be in (1, 179) degrees");
  });
  p.option("--frames", "N", "frames to play (default 300)",
           [&](const std::string& v) { frames = int(cli::parse_int("--frames", v, 1, 1000000)); });
  p.option("--png-every", "K", "write every K-th frame as PNG, 0 = none (default 1)",
           [&](const std::string& v) { png_every = int(cli::parse_int("--png-every", v, 0, 1000000)); });
  p.option("--reference", "PYR",
           "also render the flight from this pyramid (e.g. a --lossless build of the original input) and\n"
           "report per-frame image PSNR of PYRAMID's frames against it",
           [&](const std::string& v) { reference = v; });
  p.option("--original", "FILE",
           "the original, uncompressed input (any format pyramid-build reads): render the flight from its\n"
           "lossless pyramid too and report per-frame image PSNR against it, and the screen-space geometric\n"
           "error per level (L&H 2004 Table 2: rms, 99.9th percentile, max pixels) of PYRAMID's levels\n"
           "against the original's finest level",
           [&](const std::string& v) { original = v; });
  p.option("--original-vscale", "S",
           "metres per stored unit of --original (default: the pyramid's for integer inputs)",
           [&](const std::string& v) { original_vscale = cli::parse_double("--original-vscale", v); });
  p.option("--bench", "K",
           "benchmark instead of a flight: K full n x n refills of each clipmap level on one core (fresh\n"
           "decoder cache each time), timing U, residual decode, the rest of the fill, zc, normal map and\n"
           "z bounds; then U and the residual entropy decode of one n x n window straight from libcodec",
           [&](const std::string& v) { bench = int(cli::parse_int("--bench", v, 1, 1000)); });
  p.option("--synth-levels", "K",
           "synthesise K levels finer than the pyramid's finest (U + Gaussian noise whose variance is\n"
           "extrapolated from the stored residual statistics; docs/synthesis.md)",
           [&](const std::string& v) {
             synth_levels = int(cli::parse_int("--synth-levels", v, 1, SynthesisOptions::kMaxLevels));
           });
  p.option("--synth-detail", "F", "scale of the synthesised noise (default 1; 0 = zero detail, U alone)",
           [&](const std::string& v) {
             synth_detail = cli::parse_double("--synth-detail", v);
             if (!(synth_detail >= 0 && synth_detail <= 100))
               throw cli::UsageError("--synth-detail must be in [0, 100]");
           });
  p.flag("--no-transitions", "disable the transition morph (to see popping)", &no_transitions);
  p.flag("--no-culling", "disable view-frustum culling", &no_culling);
  p.add_common(common, false);
  p.epilog(
      "Times in stats: update = decode (the height source's fill, of which upsample = U of the coarser\n"
      "clipmap level and residual = residual decode + addition) + zc + normals + z bounds; upload = texture\n"
      "uploads; render = draw + glFinish. The summary line gives the median and\n"
      "99th percentile of update + upload + render per frame.");
  if (auto status = p.parse(argc, argv)) return *status;

  if (!reference.empty() && !original.empty())
    throw cli::UsageError("give --reference or --original, not both");
  std::shared_ptr<const PyramidFile> file, ref_file;
  try {
    file = PyramidFile::open(pyramid);
    if (!reference.empty()) ref_file = PyramidFile::open(reference);
  } catch (const Error& e) {
    std::cerr << "clipmap-view: error: " << e.what() << "\n";
    return cli::exit_status(e.code());
  }
  const ContainerInfo& info = file->info();
  // Arc-second grids: about 30.87 m per arc-second (the terrain is rendered flat, as in the paper).
  const double spacing = info.horizontal_units == "arc-second" ? info.spacing_x * 30.87 : info.spacing_x;
  auto decoder = std::make_shared<const RegionDecoder>(file);
  RegionDecoderSource source(decoder, spacing);
  std::unique_ptr<SynthesisSource> synth;
  if (synth_levels > 0) {
    if (!reference.empty() || !original.empty() || bench > 0)
      throw cli::UsageError("--synth-levels cannot be combined with --reference, --original or --bench");
    ResidualFit fit;
    synth = std::make_unique<SynthesisSource>(
        source, synthesis_options_for(*file, synth_levels, 1, synth_detail, &fit));
    if (!common.quiet) {
      std::cerr << "clipmap-view: synthesis: " << fit.note << ", log2 variance slope " << fit.slope
                << " per level (fitted " << fit.slope_fitted << "); noise std";
      for (int l = source.level_count(); l < synth->level_count(); ++l)
        std::cerr << ' ' << synth->noise_std_m(l);
      std::cerr << " m\n";
    }
  }
  HeightSource& heights = synth ? static_cast<HeightSource&>(*synth) : source;
  if (levels > heights.level_count())
    throw cli::UsageError("--levels " + std::to_string(levels) + " exceeds the source's " +
                          std::to_string(heights.level_count()));
  ClipmapOptions copt;
  copt.levels = levels;
  copt.budget = budget;
  if (max_screen_error) {
    if (n_given) throw cli::UsageError("give --n or --max-screen-error, not both");
    if (synth) throw cli::UsageError("--max-screen-error cannot be combined with --synth-levels");
    const int first_level = source.level_count() - clipmap_level_count(copt, source.level_count());
    const double s_ref = triangle_size_px(width, height, fov, 255);
    const auto t0 = Clock::now();
    std::vector<LevelScreenError> errors = estimate_screen_space_error(source, first_level, s_ref);
    // The estimate takes the file's finest level for the truth; the finest level's own error against
    // the input, which version 1.1 files record, turns it into a bound.
    const std::optional<LevelError> finest_error = level_error_metres(info, info.levels.size() - 1);
    if (finest_error) add_finest_error_bound(errors, finest_error->rms, finest_error->max_abs, s_ref);
    const ClipmapSizeChoice choice =
        clipmap_size_for_screen_error(errors, s_ref, width, height, fov, *max_screen_error);
    n = choice.n;
    if (!common.quiet) {
      std::fprintf(
          stderr,
          "clipmap-view: --max-screen-error %g px: n = %d, p99.9 %s %.3f px on the worst level (%.2f s)%s\n",
          *max_screen_error, n, finest_error ? "bound" : "estimate", choice.p999_px, since(t0),
          choice.met ? "" : "; n = 1023 is the largest, so the tolerance is not met");
      if (finest_error)
        std::fprintf(stderr,
                     "clipmap-view: the bound includes the finest level's compression error (max %.3f m)\n",
                     finest_error->max_abs);
      else
        std::fprintf(stderr,
                     "clipmap-view: warning: %s (format 1.0) does not record its compression error; the "
                     "estimate leaves it out\n",
                     pyramid.c_str());
    }
  }
  copt.n = n;
  if (bench > 0) return run_bench(file, spacing, copt, bench, common.quiet);
  Clipmap clipmap(heights, copt);
  const int finest_level = source.level_count() - 1;

  // The reference flight: same clipmap options over another pyramid or the original input.
  std::unique_ptr<HeightSource> ref_source;
  const GridHeightSource* original_grid = nullptr;
  if (ref_file) {
    if (ref_file->level_count() != file->level_count() ||
        !(ref_file->level_size(finest_level) == file->level_size(finest_level))) {
      std::cerr << "clipmap-view: error: " << reference << ": levels or size differ from " << pyramid << "\n";
      return 5;
    }
    ref_source =
        std::make_unique<RegionDecoderSource>(std::make_shared<const RegionDecoder>(ref_file), spacing);
  } else if (!original.empty()) {
    ReadOptions ro;
    const GridInfo gi = probe(original);
    // An integer input is stored in its own unit: the pyramid's scale is the input's (e.g. 0.1 m for
    // the Puget Sound PNG, which the file itself does not say).
    if (original_vscale)
      ro.vertical_scale = *original_vscale;
    else if (gi.integer_valued())
      ro.vertical_scale = info.vertical_scale, ro.vertical_offset = info.vertical_offset;
    const auto t0 = Clock::now();
    try {
      auto grid = std::make_unique<GridHeightSource>(original_source(
          original, ro, file->level_size(finest_level), file->level_count(), info.filter, spacing));
      original_grid = grid.get();
      ref_source = std::move(grid);
    } catch (const std::invalid_argument& e) {
      std::cerr << "clipmap-view: error: " << e.what() << "\n";
      return 5;
    }
    if (!common.quiet)
      std::cerr << "clipmap-view: lossless pyramid of " << original << " in " << since(t0) << " s\n";
  }
  std::unique_ptr<Clipmap> ref_clipmap;
  if (ref_source) ref_clipmap = std::make_unique<Clipmap>(*ref_source, copt);

  std::vector<Key> keys;
  keys = path_file.empty() ? default_path(source, spacing, frames) : read_path(path_file);

  std::error_code ec;
  std::filesystem::create_directories(out_dir, ec);
  const std::string csv_path = out_dir + "/stats.csv", json_path = out_dir + "/stats.json";
  std::ofstream csv(csv_path + ".tmp");
  if (!csv) throw Error(ErrorCode::WriteFailed, "cannot write " + csv_path);
  csv << "frame,x_m,y_m,z_m,update_ms,decode_ms,upsample_ms,residual_ms,zc_ms,normals_ms,bounds_ms,upload_ms,"
         "render_ms,frame_ms,"
         "triangles,blocks_drawn,blocks_culled,draw_calls,active_levels,levels_behind,samples_decoded,"
         "samples_reconstructed,residual_samples_decoded,samples_uploaded,psnr_db\n";

  // Screen-space geometric error of the levels this clipmap renders (L&H 2004 Table 2).
  const double s_px = triangle_size_px(width, height, fov, n);
  std::vector<LevelScreenError> sse;
  if (original_grid) {
    RegionDecoderSource table_source(std::make_shared<const RegionDecoder>(file), spacing);
    sse = screen_space_error(table_source, *original_grid, clipmap.source_level(0), s_px);
    std::printf("screen-space geometric error, %dx%d, vertical fov %g deg, n=%d: s = %.2f px per grid cell\n",
                width, height, fov, n, s_px);
    std::printf("%6s %12s %10s %10s %10s %12s %10s\n", "level", "spacing_m", "rms_m", "max_m", "rms_px",
                "p99.9_px", "max_px");
    for (const LevelScreenError& e : sse)
      std::printf("%6d %12.1f %10.3f %10.3f %10.4f %12.4f %10.4f\n", e.level, e.spacing_m, e.rms_m, e.max_m,
                  e.rms_px, e.p999_px, e.max_px);
    std::fflush(stdout);
  }

  // Every GL call runs under a GlLeakCheckPause: Mesa's process-lifetime allocations would otherwise
  // fail an ASan build at exit.
  std::optional<GlLeakCheckPause> gl_setup_pause(std::in_place);
  HeadlessGL gl;
  ClipmapRenderer renderer(n, clipmap.level_count(), width, height);
  std::unique_ptr<ClipmapRenderer> ref_renderer;
  if (ref_clipmap) ref_renderer = std::make_unique<ClipmapRenderer>(n, clipmap.level_count(), width, height);
  gl_setup_pause.reset();
  std::vector<uint8_t> ref_pixels;
  std::vector<double> psnr;
  if (!common.quiet)
    std::cerr << "clipmap-view: " << gl.renderer_name() << " (EGL " << gl.platform() << "), n=" << n << ", "
              << clipmap.level_count() << " levels, " << width << "x" << height << ", spacing " << spacing
              << " m\n";
  RenderOptions ropt;
  ropt.transitions = !no_transitions;
  ropt.culling = !no_culling;
  std::vector<uint8_t> pixels;
  std::vector<double> frame_ms, update_ms, render_ms, upload_ms;
  // The update's parts per frame, ms: decode (all of the fill), U, residual, zc, normals, bounds.
  const char* const part_names[] = {"decode", "upsample", "residual", "zc", "normals", "bounds"};
  std::array<std::vector<double>, 6> part_ms;
  int64_t triangles_total = 0;
  float ground_scratch = 0;
  std::vector<std::string> written;
  const double cpu0 = cpu_seconds();
  for (int f = 0; f < frames; ++f) {
    const Key k = interpolate(keys, double(f));
    // Ground under the camera from the finest level (one sample, decoded through the tile cache).
    const GridSize fs = source.level_size(finest_level);
    const int64_t gx = std::clamp<int64_t>(int64_t(std::llround(k.x / spacing)), 0, fs.width - 1);
    const int64_t gy = std::clamp<int64_t>(int64_t(std::llround(k.y / spacing)), 0, fs.height - 1);
    source.fill(finest_level, Rect{gx, gy, 1, 1}, &ground_scratch, 1);
    Camera cam;
    cam.position[0] = k.x;
    cam.position[1] = k.y;
    cam.position[2] = double(ground_scratch) + k.above;
    cam.yaw = k.yaw_deg * M_PI / 180.0;
    cam.pitch = k.pitch_deg * M_PI / 180.0;
    cam.fov_y_deg = fov;
    const RegionStats before = decoder->stats();
    const auto t0 = Clock::now();
    const ClipmapUpdateStats us = clipmap.update(cam.position[0], cam.position[1], cam.position[2]);
    const double upd = since(t0);
    RenderStats rs;
    {
      const GlLeakCheckPause gl_pause;
      renderer.upload(clipmap);
      rs = renderer.render(clipmap, cam, ropt);
    }
    const double total = since(t0);
    const RegionStats after = decoder->stats();
    double frame_psnr = std::nan("");
    if (ref_clipmap) {
      ref_clipmap->update(cam.position[0], cam.position[1], cam.position[2]);
      {
        const GlLeakCheckPause gl_pause;
        ref_renderer->upload(*ref_clipmap);
        ref_renderer->render(*ref_clipmap, cam, ropt);
        ref_renderer->read_rgba(ref_pixels);
        renderer.read_rgba(pixels);
      }
      double sq = 0;
      for (size_t i = 0; i < pixels.size(); ++i)
        if (i % 4 != 3)
          sq += double((int(pixels[i]) - int(ref_pixels[i])) * (int(pixels[i]) - int(ref_pixels[i])));
      const double mse = sq / double(pixels.size() / 4 * 3);
      frame_psnr = mse > 0 ? 10.0 * std::log10(255.0 * 255.0 / mse) : 99.0;  // 99 dB: identical frames
      psnr.push_back(frame_psnr);
    }
    if (png_every > 0 && f % png_every == 0) {
      {
        const GlLeakCheckPause gl_pause;
        renderer.read_rgba(pixels);
      }
      char name[64];
      std::snprintf(name, sizeof name, "/frame_%05d.png", f);
      write_png_rgba(out_dir + name, width, height, pixels);
      written.push_back(out_dir + name);
      if (ref_renderer) {
        std::snprintf(name, sizeof name, "/reference_%05d.png", f);
        write_png_rgba(out_dir + name, width, height, ref_pixels);
      }
    }
    frame_ms.push_back(total * 1e3);
    update_ms.push_back(upd * 1e3);
    const double parts[6] = {us.seconds_fill,   us.seconds_upsample, us.seconds_residual,
                             us.seconds_coarse, us.seconds_normals,  us.seconds_bounds};
    for (size_t part = 0; part < part_ms.size(); ++part) part_ms[part].push_back(parts[part] * 1e3);
    render_ms.push_back(rs.seconds_render * 1e3);
    upload_ms.push_back(rs.seconds_upload * 1e3);
    triangles_total += rs.triangles;
    csv << f << ',' << cam.position[0] << ',' << cam.position[1] << ',' << cam.position[2] << ',' << upd * 1e3
        << ',' << us.seconds_fill * 1e3 << ',' << us.seconds_upsample * 1e3 << ','
        << us.seconds_residual * 1e3 << ',' << us.seconds_coarse * 1e3 << ',' << us.seconds_normals * 1e3
        << ',' << us.seconds_bounds * 1e3 << ',' << rs.seconds_upload * 1e3 << ',' << rs.seconds_render * 1e3
        << ',' << total * 1e3 << ',' << rs.triangles << ',' << rs.blocks_drawn << ',' << rs.blocks_culled
        << ',' << rs.draw_calls << ',' << us.active_levels << ',' << us.levels_behind << ','
        << us.samples_filled << ',' << after.samples_reconstructed - before.samples_reconstructed << ','
        << after.residual_samples_decoded - before.residual_samples_decoded << ',' << rs.samples_uploaded
        << ',';
    if (std::isnan(frame_psnr))
      csv << '\n';
    else
      csv << frame_psnr << '\n';
  }
  // CPU per frame covers everything in the loop (reference renders and PNG writing included).
  const double cpu_ms_per_frame = (cpu_seconds() - cpu0) * 1e3 / frames;
  csv.close();
  if (!csv) throw Error(ErrorCode::WriteFailed, "cannot write " + csv_path);
  std::filesystem::rename(csv_path + ".tmp", csv_path);

  const double med = percentile(frame_ms, 0.5), p99 = percentile(frame_ms, 0.99);
  {
    std::ofstream js(json_path + ".tmp");
    cli::JsonWriter j(js);
    j.begin_object();
    j.field("pyramid", pyramid)
        .field("renderer", gl.renderer_name())
        .field("n", n)
        .field("levels", clipmap.level_count());
    if (max_screen_error) j.field("max_screen_error_px", *max_screen_error);
    j.field("width", width).field("height", height).field("fov_y_deg", fov).field("frames", frames);
    j.field("budget", clipmap.budget()).field("transitions", !no_transitions).field("culling", !no_culling);
    j.field("frame_ms_median", med).field("frame_ms_p99", p99);
    j.field("fps_median", med > 0 ? 1e3 / med : 0.0).field("cpu_ms_per_frame", cpu_ms_per_frame);
    j.field("update_ms_median", percentile(update_ms, 0.5))
        .field("update_ms_p99", percentile(update_ms, 0.99));
    for (size_t k = 0; k < part_ms.size(); ++k) {
      j.field(std::string(part_names[k]) + "_ms_median", percentile(part_ms[k], 0.5));
      j.field(std::string(part_names[k]) + "_ms_p99", percentile(part_ms[k], 0.99));
    }
    j.field("upload_ms_median", percentile(upload_ms, 0.5))
        .field("upload_ms_p99", percentile(upload_ms, 0.99));
    j.field("render_ms_median", percentile(render_ms, 0.5))
        .field("render_ms_p99", percentile(render_ms, 0.99));
    j.field("triangles_mean", double(triangles_total) / frames);
    if (!psnr.empty()) {
      double sum = 0;
      for (double v : psnr) sum += v;
      j.field("reference", ref_file ? reference : original).field("psnr_db_mean", sum / double(psnr.size()));
      j.field("psnr_db_min", *std::min_element(psnr.begin(), psnr.end()));
      j.field("psnr_db_median", percentile(psnr, 0.5));
    }
    if (!sse.empty()) {
      j.field("triangle_size_px", s_px);
      j.key("screen_space_error").begin_array();
      for (const LevelScreenError& e : sse) {
        j.begin_object();
        j.field("level", e.level)
            .field("spacing_m", e.spacing_m)
            .field("rms_m", e.rms_m)
            .field("max_m", e.max_m);
        j.field("rms_px", e.rms_px).field("p999_px", e.p999_px).field("max_px", e.max_px);
        j.end_object();
      }
      j.end_array();
    }
    j.end_object();
    j.finish();
    js.close();
    if (!js) throw Error(ErrorCode::WriteFailed, "cannot write " + json_path);
  }
  std::filesystem::rename(json_path + ".tmp", json_path);
  std::printf(
      "frames %d at %dx%d: frame time median %.2f ms (%.1f fps), p99 %.2f ms; update median %.3f ms, p99 "
      "%.3f ms; "
      "upload median %.3f ms; render median %.2f ms; %.0f triangles/frame; process CPU %.1f ms/frame; stats "
      "in %s\n",
      frames, width, height, med, med > 0 ? 1e3 / med : 0.0, p99, percentile(update_ms, 0.5),
      percentile(update_ms, 0.99), percentile(upload_ms, 0.5), percentile(render_ms, 0.5),
      double(triangles_total) / frames, cpu_ms_per_frame, out_dir.c_str());
  std::printf(
      "update parts, median ms: decode %.3f (U %.3f, residual %.3f), zc %.3f, normals %.3f, bounds %.3f\n",
      percentile(part_ms[0], 0.5), percentile(part_ms[1], 0.5), percentile(part_ms[2], 0.5),
      percentile(part_ms[3], 0.5), percentile(part_ms[4], 0.5), percentile(part_ms[5], 0.5));
  if (!psnr.empty())
    std::printf("image PSNR against %s: median %.2f dB, min %.2f dB (99 = identical)\n",
                (ref_file ? reference : original).c_str(), percentile(psnr, 0.5),
                *std::min_element(psnr.begin(), psnr.end()));
  if (!written.empty() && !common.quiet)
    std::cerr << "clipmap-view: " << written.size() << " PNG frames in " << out_dir << "\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return cli::run_tool("clipmap-view", [&] { return run(argc, argv); });
}
