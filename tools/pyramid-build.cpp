// pyramid-build: heightmap file -> compressed, error-controlled multiresolution pyramid (.pyr).
#include <malloc.h>

#include <cctype>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <sstream>
#include <thread>

#include "build/pyramid_build.h"
#include "core/cores.h"
#ifdef TERRAIN_HAVE_MPI
#include "build/mpi_group.h"
#endif
#include "cli.h"
#include "json_writer.h"
#include "progress.h"
#include "report_file.h"

namespace {

using terrain::container::ErrorMode;

// "512M", "1G", "1.5GiB", "65536" (bytes; K, M, G, T are powers of 1024).
int64_t parse_size(const std::string& name, const std::string& v) {
  size_t end = 0;
  double n = 0;
  try {
    n = std::stod(v, &end);
  } catch (const std::exception&) {
    throw cli::UsageError(name + " wants a size such as 512M or 1G, not '" + v + "'");
  }
  std::string unit = v.substr(end);
  for (char& c : unit) c = char(std::toupper(static_cast<unsigned char>(c)));
  if (unit.size() > 1 && (unit.substr(1) == "B" || unit.substr(1) == "IB")) unit = unit.substr(0, 1);
  const std::string units = "KMGT";
  double scale = 1;
  if (unit == "B" || unit.empty())
    scale = 1;
  else if (unit.size() == 1 && units.find(unit[0]) != std::string::npos)
    scale = std::ldexp(1.0, 10 * int(units.find(unit[0]) + 1));
  else
    throw cli::UsageError(name + " wants a size such as 512M or 1G, not '" + v + "'");
  const double bytes = n * scale;
  if (!(bytes >= 0) || bytes > 9e18) throw cli::UsageError(name + " is out of range: '" + v + "'");
  return int64_t(bytes);
}

int run(int argc, char** argv) {
#ifdef TERRAIN_HAVE_MPI
  // Under mpirun every rank runs this tool with the same arguments; MPI only when launched so.
  std::unique_ptr<terrain::build::ProcessGroup> group;
  if (terrain::build::launched_by_mpi()) group = terrain::build::mpi_world(&argc, &argv);
#endif
  std::string input, output, json_path;
  cli::CommonFlags common;
  terrain::ReadOptions read_options;
  terrain::build::BuildFileOptions o;
  int targets = 0;
  auto set_target = [&](ErrorMode mode, const std::string& name, const std::string& v) {
    o.mode = mode;
    o.target_metres = cli::parse_double(name, v);
    if (!(o.target_metres > 0) || !std::isfinite(o.target_metres) || o.target_metres > 1e6)
      throw cli::UsageError(name + " must be a positive number of metres (at most 1e6)");
    ++targets;
  };
  cli::ArgParser parser(
      "pyramid-build", "INPUT -o OUT.pyr [--rms M | --max-error M | --step S | --lossless] [options]",
      "Streams a heightmap (any format of terrain-info) once, builds the filtered pyramid (downsampling\n"
      "filter: the dual of the four-point upsampler), and codes the closed-loop residuals of every level\n"
      "with one absolute quantisation step (libcodec). Memory stays bounded for any input height.\n"
      "Error targets, in metres at the finest level: --rms M (the step is calibrated on bands spread over\n"
      "the whole input), --max-error M (guaranteed at every sample), --step S, or --lossless (default; "
      "integer "
      "input).\n"
      "The output is written to OUT.pyr.tmp.XXXXXX (a new random name) and renamed when complete.\n"
      "Striped build (--resume, --stripes, or mpirun -np N pyramid-build ...): the rows are cut into\n"
      "stripes coded into part files in OUT.pyr.build/, shared out among the MPI ranks; rank 0 writes\n"
      "OUT.pyr from them, byte-identical to the one-process build. A killed striped build run again\n"
      "with the same input and options resumes from its completed stripes (docs/scale.md).");
  parser.positional("INPUT", "heightmap to read", &input);
  parser.option("-o,--output", "OUT", "pyramid file to write (required)", &output);
  parser.option("--rms", "M",
                "target rms error in metres at the finest level: the largest step whose rms on the "
                "calibration sample is at most M (within 2 % below it; the whole file lands within 10 %); "
                "a target that only step 1 meets gives the lossless pyramid",
                [&](const std::string& v) { set_target(ErrorMode::Rms, "--rms", v); });
  parser.option("--max-error", "M", "guaranteed max |error| in metres",
                [&](const std::string& v) { set_target(ErrorMode::MaxError, "--max-error", v); });
  parser.option("--step", "S", "quantiser step in metres",
                [&](const std::string& v) { set_target(ErrorMode::Step, "--step", v); });
  bool lossless = false;
  parser.flag("--lossless", "exact reconstruction (integer input, or float at --quantum)", &lossless);
  parser.option("--quantum", "Q", "level unit in metres for float input (default 0.01)",
                [&](const std::string& v) {
                  o.quantum_metres = cli::parse_double("--quantum", v);
                  if (!(o.quantum_metres > 0) || !std::isfinite(o.quantum_metres))
                    throw cli::UsageError("--quantum must be positive");
                });
  parser.option("--levels", "N", "number of levels (default: until the coarsest is about 128 samples)",
                [&](const std::string& v) { o.levels = int(cli::parse_int("--levels", v, 1, 40)); });
  parser.option("--tile", "T", "codec tile side, multiple of 16 in [16, 1024] (default 32)",
                [&](const std::string& v) {
                  o.tile_size = uint32_t(cli::parse_int("--tile", v, 16, 1024));
                  if (o.tile_size % 16) throw cli::UsageError("--tile must be a multiple of 16");
                });
  parser.option("--threads", "N",
                "worker threads (default: the cores this process may run on, its CPU affinity as taskset, a "
                "cpuset or mpirun's binding leave it; under mpirun at most the host's cores divided by its "
                "ranks; output is identical for any N)",
                [&](const std::string& v) { o.threads = int(cli::parse_int("--threads", v, 1, 256)); });
  o.memory_bytes = int64_t(1) << 30;
  parser.option("--memory", "SIZE",
                "memory budget of the build, e.g. 512M, 2G (default 1G; 0: none): fewer bands are coded at "
                "once when it is tight (the same output, slower); below what the input's width needs, the "
                "build fails at the start naming the minimum",
                [&](const std::string& v) { o.memory_bytes = parse_size("--memory", v); });
  parser.option("--level-error", "absolute|screen",
                "error schedule over the levels: one absolute step at every level (default, as in the "
                "paper), or screen: level l's step and max error 2^(m-l) times the finest level's, the same "
                "error in screen space at every level (usually smaller files: -5 to -7 % on SRTM tiles at "
                "--rms 1, though not on every terrain; the target is the finest level's)",
                [&](const std::string& v) {
                  if (v != "absolute" && v != "screen")
                    throw cli::UsageError("--level-error must be absolute or screen");
                  o.screen_level_error = v == "screen";
                });
  parser.option(
      "--coarse-step-ratio", "R|auto",
      "--step and --rms: level l's step is the finest level's times R^min(m-l, 2), R in (0, 1] (coarse "
      "levels at least as accurate as the finest; they predict it better on smooth terrain). "
      "Default auto: 1 for --step (the paper's one absolute step), and for --rms the first of 1, "
      "0.7, 0.5, 0.35 after which a smaller R no longer makes the calibration sample smaller",
      [&](const std::string& v) {
        o.coarse_step_ratio = v == "auto" ? 0.0 : cli::parse_double("--coarse-step-ratio", v, 1e-6, 1);
      });
  parser.option("--downsample", "auto|wavelet|optimal|point",
                "downsampling filter D of the coarse levels: auto (default) is point for --max-error and "
                "--lossless, wavelet for --step, and for --rms whichever of the two the calibration finds "
                "smaller at the target; wavelet, the (4,4) lifting wavelet's low pass, the dual of the "
                "four-point upsampler (smooth or flat terrain, low rates; nothing to fit); optimal, the "
                "paper's per-terrain least-squares 11x11 D fitted on the top rows; point, plain "
                "subsampling (every level's samples are input samples; the residuals are coded by phase "
                "tiles, which skip their even phase)",
                [&](const std::string& v) {
                  const auto choice = terrain::build::downsample_choice_from_name(v);
                  if (!choice) throw cli::UsageError("--downsample must be auto, wavelet, optimal or point");
                  o.downsample = *choice;
                });
  parser.flag("--resume",
              "striped, journalled build: a killed build run again continues from its completed stripes",
              &o.journal);
  parser.option("--stripes", "N", "stripes of a striped build (default: one per MPI rank, 4 for one process)",
                [&](const std::string& v) { o.stripes = int(cli::parse_int("--stripes", v, 1, 100000)); });
  parser.option("--json", "FILE", "write a JSON build report to FILE ('-' for stdout)", &json_path);
  cli::add_read_options(parser, read_options);
  parser.add_common(common, false);
  if (auto status = parser.parse(argc, argv)) return *status;
  if (output.empty()) throw cli::UsageError("missing -o OUT.pyr");
  if (lossless) ++targets;
  if (targets > 1) throw cli::UsageError("give at most one of --rms, --max-error, --step, --lossless");
  int rank = 0, ranks = 1;
#ifdef TERRAIN_HAVE_MPI
  if (group) {
    rank = group->rank(), ranks = group->size();
    o.group = group.get();
    // The host's cores shared among its ranks (each rank's builder has its own threads), and no
    // more than the cores the launcher bound this rank to: Open MPI binds each rank to one core at
    // -np 2 and below, where a share of the host put all of it on that core.
    if (o.threads == 0)
      o.threads = std::max(
          1, std::min(terrain::usable_cores(), int(std::max(1u, std::thread::hardware_concurrency())) /
                                                   terrain::build::local_process_count()));
    if (rank != 0) common.quiet = true, json_path.clear();  // rank 0 reports
  }
#else
  // Without MPI every rank would build the whole pyramid on its own, all into the same output.
  if (const char* n = std::getenv("OMPI_COMM_WORLD_SIZE"); n && std::atoi(n) > 1)
    throw cli::UsageError("this pyramid-build was built without MPI (TERRAIN_MPI): run it without mpirun");
#endif
  (void)rank;

  std::ostringstream opts;
  opts << "{\"target\":\"" << terrain::container::error_mode_name(o.mode)
       << "\",\"metres\":" << o.target_metres << ",\"levels\":" << o.levels << ",\"tile\":" << o.tile_size
       << ",\"level_error\":\"" << (o.screen_level_error ? "screen" : "absolute")
       << "\",\"coarse_step_ratio\":" << o.coarse_step_ratio << ",\"downsample\":\""
       << terrain::build::downsample_choice_name(o.downsample) << "\"}";

  std::unique_ptr<cli::Progress> bar;
  std::string phase;
  auto progress = [&](const std::string& p, double f) {
    if (common.quiet) return;
    if (p != phase) {
      if (bar) bar->finish();
      bar = std::make_unique<cli::Progress>("pyramid-build: " + p, 1000, true);
      phase = p;
    }
    bar->update(int64_t(f * 1000));
  };
  terrain::build::BuildFileResult r;
  try {
    r = terrain::build::build_pyramid_file(input, read_options, output, o, opts.str(), progress);
  } catch (const std::invalid_argument& e) {
    throw cli::UsageError(e.what());
  }
  if (bar) bar->finish();

  const double mpu = r.metres_per_unit;
  const auto& lv = r.build.levels;
  const double bits = 8.0 * double(r.file_bytes) / double(std::max<int64_t>(1, r.finest_samples));
  if (!common.quiet) {
    if (common.verbose)
      for (const auto& line : r.calibration_log) std::cerr << "pyramid-build: calibration: " << line << "\n";
    for (const auto& line : r.build.log) std::cerr << "pyramid-build: " << line << "\n";
    if (r.stripes)
      std::fprintf(stderr, "pyramid-build: striped build: %d stripes, %d process%s, %d stripes resumed\n",
                   r.stripes, ranks, ranks == 1 ? "" : "es", r.stripes_resumed);
    std::fprintf(stderr,
                 "pyramid-build: %s: %zu levels, step %.4g m%s, %llu bytes = %.4f bits/sample, finest rms "
                 "%.4g m, max %.4g m, %.1f Msamples/s\n",
                 output.c_str(), lv.size(), r.step_units * mpu,
                 r.coarse_step_ratio < 1
                     ? (" (coarse levels x" + cli::shortest(r.coarse_step_ratio) + " per level)").c_str()
                     : "",
                 (unsigned long long)r.file_bytes, bits, lv.back().error_rms * mpu,
                 double(lv.back().error_max_abs) * mpu,
                 double(r.finest_samples) / 1e6 / std::max(1e-9, r.seconds_build));
  }
  if (!json_path.empty()) {
    cli::ReportFile report(json_path);
    std::ostream& os = report.stream();
    cli::JsonWriter j(os);
    j.begin_object();
    j.field("input", input).field("output", output).field("bytes", int64_t(r.file_bytes));
    j.field("finest_samples", r.finest_samples).field("bits_per_sample", bits);
    j.field("metres_per_unit", mpu).field("step_metres", r.step_units * mpu);
    j.field("level_error", o.screen_level_error ? "screen" : "absolute");
    j.field("coarse_step_ratio", r.coarse_step_ratio);
    j.field("max_error_bound_metres", o.mode == ErrorMode::MaxError ? double(r.max_error_units) * mpu : -1.0);
    j.field("filter", r.build.filter_report.summary())
        .field("filter_fallback", r.build.filter_report.fallback);
    j.field("seconds_calibrate", r.seconds_calibrate).field("seconds_build", r.seconds_build);
    j.field("build_msamples_per_s", double(r.finest_samples) / 1e6 / std::max(1e-9, r.seconds_build));
    j.field("voids", r.build.void_count);
    j.field("memory_budget_bytes", o.memory_bytes)
        .field("memory_estimate_bytes", r.memory.estimated_bytes + r.memory_outside_builder)
        .field("memory_minimum_bytes", r.memory.minimum_bytes + r.memory_outside_builder)
        .field("bands_in_flight", int64_t(r.memory.bands_in_flight))
        .field("threads", int64_t(r.threads));
    j.field("stripes", int64_t(r.stripes)).field("processes", int64_t(ranks));
    j.field("stripes_resumed", int64_t(r.stripes_resumed));
    j.key("levels").begin_array();
    for (size_t l = 0; l < lv.size(); ++l) {
      j.begin_object();
      j.field("level", int64_t(l)).field("width", lv[l].size.width).field("height", lv[l].size.height);
      j.field("bytes", int64_t(lv[l].bytes)).field("residual_rms_m", lv[l].residual_rms * mpu);
      j.field("step_m", r.level_step_units[l] * mpu);
      j.field("error_rms_m", lv[l].error_rms * mpu).field("error_max_m", double(lv[l].error_max_abs) * mpu);
      j.end_object();
    }
    j.end_array();
    j.end_object();
    j.finish();
    report.finish();
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  // The memory budget counts what the builder holds plus a small slack per thread; glibc keeps up to
  // 8 arenas per core, and freed blocks in each. On the 16-core host a 32768^2 --step 2 build at 64
  // threads peaked at 1098 MiB under the 1 GiB default; on this VM with 128 arenas allowed 1042 MiB,
  // with 16 / 8 / 4 arenas 953 / 949 / 919 MiB at the same speed (docs/scale.md "The budget").
  mallopt(M_ARENA_MAX, 8);
  return cli::run_tool("pyramid-build", [&] { return run(argc, argv); });
}
