// clipmap-view: plays a camera flight over a compressed pyramid through the geometry clipmap and
// the headless OpenGL renderer; writes PNG frames and per-frame statistics (CSV and JSON). This file:
// the options, the choice of n and the dispatch to the flight (flight.cpp, verify.cpp) or --bench
// (bench.cpp).
#include <cstdio>
#include <iostream>

#include "cli.h"
#include "clipmap_view.h"
#include "container/container.h"
#include "runtime/mirrored_source.h"
#include "runtime/synthesis.h"

using namespace terrain;
using namespace terrain::runtime;
using namespace terrain::container;
using namespace clipmap_view;

namespace clipmap_view {
std::vector<LevelScreenError> screen_error_bound(const ViewOptions& o, const ContainerInfo& info,
                                                 RegionDecoderSource& source, int first_level, double s_px,
                                                 std::optional<LevelError>& finest_error) {
  std::vector<LevelScreenError> errors = estimate_screen_space_error(source, first_level, s_px);
  // The estimate takes the file's finest level for the truth; the finest level's own error against
  // the input, which version 1.1 files record, turns it into a bound.
  finest_error = level_error_metres(info, info.levels.size() - 1);
  if (finest_error)
    add_finest_error_bound(errors, finest_error->rms, finest_error->max_abs, s_px);
  else if (!o.quiet)
    std::fprintf(stderr,
                 "clipmap-view: warning: %s (format 1.0) does not record its compression error; the "
                 "estimate leaves it out\n",
                 o.pyramid.c_str());
  return errors;
}
}  // namespace clipmap_view

namespace {

// --max-screen-error: the smallest n whose estimated (or, with the file's recorded finest-level
// error, bounded) p99.9 screen-space error meets the tolerance on the worst rendered level.
int clipmap_size_for(const ViewOptions& o, const ContainerInfo& info, RegionDecoderSource& source,
                     const ClipmapOptions& copt) {
  const int first_level = source.level_count() - clipmap_level_count(copt, source.level_count());
  const double s_ref = triangle_size_px(o.width, o.height, o.fov, 255);
  const auto t0 = Clock::now();
  std::optional<LevelError> finest_error;
  const std::vector<LevelScreenError> errors =
      screen_error_bound(o, info, source, first_level, s_ref, finest_error);
  const ClipmapSizeChoice choice =
      clipmap_size_for_screen_error(errors, s_ref, o.width, o.height, o.fov, *o.max_screen_error);
  if (!o.quiet) {
    std::fprintf(
        stderr,
        "clipmap-view: --max-screen-error %g px: n = %d, p99.9 %s %.3f px on the worst level (%.2f s)%s\n",
        *o.max_screen_error, choice.n, finest_error ? "bound" : "estimate", choice.p999_px, since(t0),
        choice.met ? "" : "; n = 1023 is the largest, so the tolerance is not met");
    if (finest_error)
      std::fprintf(stderr,
                   "clipmap-view: the bound includes the finest level's compression error (max %.3f m)\n",
                   finest_error->max_abs);
  }
  return choice.n;
}

int run(int argc, char** argv) {
  ViewOptions o;
  int bench = 0, bench_render = 0, synth_levels = 0;
  double synth_detail = 1.0;
  int n = 255, levels = 0;
  int64_t budget = 0;
  double budget_ms = 0;
  bool n_given = false;
  cli::CommonFlags common;
  cli::ArgParser p(
      "clipmap-view", "PYRAMID [options]",
      "Flies a camera over a compressed pyramid (.pyr) with the geometry clipmap, renders each frame\n"
      "off-screen with OpenGL 4.5 core through EGL (Mesa llvmpipe when there is no GPU), and writes\n"
      "PNG frames, stats.csv (one row per frame) and stats.json (summary) into --out.");
  p.positional("PYRAMID", "compressed pyramid file written by pyramid-build", &o.pyramid);
  p.option("--out", "DIR", "output directory (default clipmap-frames)", &o.out_dir);
  p.option("--path", "FILE",
           "camera keyframes, one per line: frame x_m y_m above_ground_m yaw_deg pitch_deg (# comments);\n"
           "linear in between. Default: a built-in pass over the terrain",
           &o.path_file);
  p.option("--width", "PX", "frame width (default 640)",
           [&](const std::string& v) { o.width = int(cli::parse_int("--width", v, 16, 8192)); });
  p.option("--height", "PX", "frame height (default 480)",
           [&](const std::string& v) { o.height = int(cli::parse_int("--height", v, 16, 8192)); });
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
             o.max_screen_error = cli::parse_double("--max-screen-error", v);
             if (!(*o.max_screen_error > 0 && *o.max_screen_error <= 1000))
               throw cli::UsageError("--max-screen-error must be in (0, 1000] pixels");
           });
  p.option("--levels", "L", "clipmap levels (default: all pyramid levels)",
           [&](const std::string& v) { levels = int(cli::parse_int("--levels", v, 1, 30)); });
  p.option("--budget", "SAMPLES", "samples refilled per frame (default n*n)",
           [&](const std::string& v) { budget = cli::parse_int("--budget", v, 1, int64_t(1) << 40); });
  p.option(
      "--budget-ms", "MS",
      "milliseconds of clipmap refill per frame (the paper's steady frame rate): the update refills in\n"
      "strips and stops before one that would pass MS; levels left behind are cropped as with --budget.\n"
      "Not deterministic (what fits depends on the machine); --budget is the deterministic limit",
      [&](const std::string& v) {
        budget_ms = cli::parse_double("--budget-ms", v);
        if (!(budget_ms > 0 && budget_ms <= 1e5)) throw cli::UsageError("--budget-ms must be in (0, 1e5]");
      });
  p.option("--plot-times", "FILE.png", "write a plot of update and render time per frame (headless flight)",
           &o.plot_times);
  p.option(
      "--edit-script", "FILE",
      "timed terrain edits during the flight: lines 'SECONDS brush X Y RADIUS HEIGHT [cone|smooth|flat]',\n"
      "'SECONDS channel X0 Y0 X1 Y1 RADIUS DEPTH' (finest-level samples, metres; frame = 30 SECONDS),\n"
      "applied in memory over the pyramid's heights; the clipmap refills what each reaches",
      &o.edit_script);
  p.flag("--edit-pyramid",
         "--edit-script writes each edit into PYRAMID itself (libedit: re-coded tiles, atomic copy-on-write\n"
         "commit) and the flight shows the file's new version; without it the edits stay in memory",
         &o.edit_pyramid);
  p.option("--edit-source", "HEIGHTMAP",
           "--edit-pyramid: the heightmap PYRAMID was built from; the edited file then decodes like a\n"
           "rebuild from the edited heightmap (within the file's step)",
           &o.edit_source);
  p.option("--mirror", "SIZE",
           "fly over a virtual SIZE x SIZE terrain (up to 2^30) repeating the pyramid by mirror reflection,\n"
           "not materialised (coarser levels than the file's computed by its D); default path: straight, low",
           [&](const std::string& v) { o.mirror = cli::parse_int("--mirror", v, 1, int64_t(1) << 30); });
  p.option("--fov", "DEG", "vertical field of view (default 60)", [&](const std::string& v) {
    o.fov = cli::parse_double("--fov", v);
    if (!(o.fov > 1 && o.fov < 179)) throw cli::UsageError("--fov must be in (1, 179) degrees");
  });
  p.option("--frames", "N", "frames to play (default 300)", [&](const std::string& v) {
    o.frames = int(cli::parse_int("--frames", v, 1, 1000000));
    o.frames_given = true;
  });
  p.option("--png-every", "K", "write every K-th frame as PNG, 0 = none (default 1)",
           [&](const std::string& v) { o.png_every = int(cli::parse_int("--png-every", v, 0, 1000000)); });
  p.option("--reference", "PYR",
           "also render the flight from this pyramid (e.g. a --lossless build of the original input) and\n"
           "report per-frame image PSNR of PYRAMID's frames against it",
           &o.reference);
  p.option("--original", "FILE",
           "the original, uncompressed input (any format pyramid-build reads): render the flight from its\n"
           "lossless pyramid too and report per-frame image PSNR against it, and the screen-space geometric\n"
           "error per level (L&H 2004 Table 2: rms, 99.9th percentile, max pixels) of PYRAMID's levels\n"
           "against the original's finest level",
           &o.original);
  p.option("--original-vscale", "S",
           "metres per stored unit of --original (default: the pyramid's for integer inputs)",
           [&](const std::string& v) { o.original_vscale = cli::parse_double("--original-vscale", v); });
  p.option("--bench", "K",
           "benchmark instead of a flight: K full n x n refills of each clipmap level on one core (fresh\n"
           "decoder cache each time), timing U, residual decode, the rest of the fill, zc, normal map and\n"
           "z bounds; then U and the residual decode of one n x n window through the region decoder",
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
  p.option("--shading", "MODE",
           "hypsometric (default: height tints, water at or below 0 m blue, hillshade, sky and haze) or\n"
           "flat (the earlier look: a ramp over the frame's height range on a plain background)",
           [&](const std::string& v) {
             if (v == "hypsometric")
               o.shading = terrain::render::Shading::Hypsometric;
             else if (v == "flat")
               o.shading = terrain::render::Shading::Flat;
             else
               throw cli::UsageError("--shading must be flat or hypsometric, got " + v);
           });
  p.option("--mesh", "MESH",
           "footprints (default: A&H 2005's constant vertex/index buffers) or tessellation (Song et al.\n"
           "2016: only patch corners go to the GPU, GL 4.5 tessellation shaders make the grid)",
           [&](const std::string& v) {
             if (v == "footprints")
               o.mesh = terrain::render::Mesh::Footprints;
             else if (v == "tessellation")
               o.mesh = terrain::render::Mesh::Tessellation;
             else
               throw cli::UsageError("--mesh must be footprints or tessellation, got " + v);
           });
  p.option("--bench-render", "FRAMES",
           "benchmark instead of a flight: the first FRAMES frames of the flight drawn with both meshes at\n"
           "640x480 and 1280x720 (same clipmap, same renderer); prints CPU (submission), render and GPU ms,\n"
           "fps and triangles per mesh and the image PSNR between them; the middle frames go to --out\n"
           "(none with --png-every 0)",
           [&](const std::string& v) { bench_render = int(cli::parse_int("--bench-render", v, 3, 100000)); });
  p.option("--drape", "IMAGE",
           "an 8-bit RGB(A) image (e.g. an orthophoto) draped over the terrain with --shading hypsometric:\n"
           "it covers the pyramid's whole extent (same georeferencing; transparent pixels keep the tints)",
           &o.drape);
  p.flag("--window",
         "fly interactively in a desktop window (GLFW) instead of the headless flight:\n"
         "WASD move, E/Q up/down, mouse look (left-button drag), +/- speed, T transitions,\n"
         "C culling, L level colours, F wireframe, Esc quits. Exit 12 when this build has\n"
         "no GLFW or no display can be opened",
         &o.window);
  p.option("--script", "FILE",
           "--window driven by timed events instead of the user: lines 'SECONDS key NAME down|up',\n"
           "'SECONDS mouse DX DY', 'SECONDS quit' (# comments); time advances 1/30 s per frame",
           &o.script);
  p.option("--screenshot", "FILE.png", "--window: write the last frame (without the overlay) on exit",
           &o.screenshot);
  p.option("--screenshot-window", "FILE.png", "--window: write the window as last shown, overlay included",
           &o.screenshot_window);
  p.option("--record-path", "FILE",
           "--window: write the camera of every frame as --path keyframes (replay it headless)",
           &o.record_path);
  p.flag("--no-transitions", "disable the transition morph (to see popping)", &o.no_transitions);
  p.flag("--no-culling", "disable view-frustum culling", &o.no_culling);
  p.add_common(common, false);
  p.epilog(
      "Times in stats: update = decode (the height source's fill, of which upsample = U of the coarser\n"
      "clipmap level and residual = residual decode + addition) + zc + normals + z bounds; upload = texture\n"
      "uploads; render = draw + glFinish. The summary line gives the median and\n"
      "99th percentile of update + upload + render per frame.");
  if (auto status = p.parse(argc, argv)) return *status;
  o.quiet = common.quiet;

  if (!o.reference.empty() && !o.original.empty())
    throw cli::UsageError("give --reference or --original, not both");
  if (!o.window &&
      (!o.script.empty() || !o.screenshot.empty() || !o.screenshot_window.empty() || !o.record_path.empty()))
    throw cli::UsageError("--script, --screenshot, --screenshot-window and --record-path need --window");
  if (o.window && (!o.reference.empty() || !o.original.empty() || bench > 0))
    throw cli::UsageError("--window cannot be combined with --reference, --original or --bench");
  std::shared_ptr<const PyramidFile> file, ref_file;
  try {
    file = PyramidFile::open(o.pyramid);
    if (!o.reference.empty()) ref_file = PyramidFile::open(o.reference);
  } catch (const Error& e) {
    std::cerr << "clipmap-view: error: " << e.what() << "\n";
    return cli::exit_status(e.code());
  }
  const ContainerInfo& info = file->info();
  // Arc-second grids: about 30.87 m per arc-second (the terrain is rendered flat, as in the paper).
  const double spacing = info.horizontal_units == "arc-second" ? info.spacing_x * 30.87 : info.spacing_x;
  // A damaged tile must not end the flight: its region shows the coarser level, and it is reported.
  auto decoder = std::make_shared<const RegionDecoder>(file, size_t(256) << 20, DamagePolicy::Degrade);
  RegionDecoderSource source(decoder, spacing);
  std::unique_ptr<SynthesisSource> synth;
  if (synth_levels > 0) {
    if (!o.reference.empty() || !o.original.empty() || bench > 0)
      throw cli::UsageError("--synth-levels cannot be combined with --reference, --original or --bench");
    ResidualFit fit;
    synth = std::make_unique<SynthesisSource>(
        source, synthesis_options_for(*file, synth_levels, 1, synth_detail, &fit));
    if (!o.quiet) {
      std::cerr << "clipmap-view: synthesis: " << fit.note << ", log2 variance slope " << fit.slope
                << " per level (fitted " << fit.slope_fitted << "); noise std";
      for (int l = source.level_count(); l < synth->level_count(); ++l)
        std::cerr << ' ' << synth->noise_std_m(l);
      std::cerr << " m\n";
    }
  }
  HeightSource& stored = synth ? static_cast<HeightSource&>(*synth) : source;
  std::unique_ptr<MirroredSource> mirror;
  if (o.mirror > 0) {
    if (o.window || !o.reference.empty() || !o.original.empty() || bench > 0)
      throw cli::UsageError("--mirror cannot be combined with --window, --reference, --original or --bench");
    const GridSize fs = stored.level_size(stored.level_count() - 1);
    if (o.mirror < std::max(fs.width, fs.height))
      throw cli::UsageError("--mirror must be at least the pyramid's finest side (" +
                            std::to_string(std::max(fs.width, fs.height)) + ")");
    mirror =
        std::make_unique<MirroredSource>(stored, GridSize{o.mirror, o.mirror}, file->downsample_filter());
    if (!o.quiet)
      std::cerr << "clipmap-view: --mirror " << o.mirror << ": " << mirror->level_count() << " levels ("
                << mirror->level_count() - mirror->base_level(mirror->level_count() - 1) - 1
                << " beyond the file's own), " << mirror->memory_bytes() / 1024 << " KiB held\n";
  }
  HeightSource& heights = mirror ? static_cast<HeightSource&>(*mirror) : stored;
  if (levels > heights.level_count())
    throw cli::UsageError("--levels " + std::to_string(levels) + " exceeds the source's " +
                          std::to_string(heights.level_count()));
  ClipmapOptions copt;
  copt.levels = levels;
  copt.budget = budget;
  copt.budget_ms = budget_ms;
  if (o.window && (budget_ms > 0 || !o.plot_times.empty() || !o.edit_script.empty()))
    throw cli::UsageError("--budget-ms, --plot-times and --edit-script are for the headless flight");
  if ((o.edit_pyramid || !o.edit_source.empty()) && o.edit_script.empty())
    throw cli::UsageError("--edit-pyramid and --edit-source need --edit-script");
  if (!o.edit_source.empty() && !o.edit_pyramid) throw cli::UsageError("--edit-source needs --edit-pyramid");
  if (o.edit_pyramid && (synth || mirror || !o.reference.empty() || !o.original.empty()))
    throw cli::UsageError(
        "--edit-pyramid cannot be combined with --synth-levels, --mirror, --reference or --original");
  if (o.max_screen_error) {
    if (n_given) throw cli::UsageError("give --n or --max-screen-error, not both");
    if (synth) throw cli::UsageError("--max-screen-error cannot be combined with --synth-levels");
    n = clipmap_size_for(o, info, source, copt);
  }
  copt.n = n;
  if (bench > 0) return run_bench(file, spacing, copt, bench, o.quiet);
  if (bench_render > 0) {
    if (o.window || bench > 0 || !o.reference.empty() || !o.original.empty())
      throw cli::UsageError(
          "--bench-render cannot be combined with --window, --bench, --reference or --original");
    return run_bench_render(Flight{o, file, ref_file, decoder, source, heights, copt, spacing, mirror.get()},
                            bench_render);
  }
  if (o.window)
    return run_window(Flight{o, file, ref_file, decoder, source, heights, copt, spacing, nullptr});
  return run_flight(Flight{o, file, ref_file, decoder, source, heights, copt, spacing, mirror.get()});
}

}  // namespace

int main(int argc, char** argv) {
  return cli::run_tool("clipmap-view", [&] { return run(argc, argv); });
}
