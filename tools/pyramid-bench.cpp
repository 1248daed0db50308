// pyramid-bench: times the streamed pyramid build (filter fit, D cascade, U prediction, closed-loop
// residuals with the uniform quantiser; no entropy coding) on a heightmap file.
#include <sys/resource.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <iostream>

#include "cli.h"
#include "json_writer.h"
#include "pyramid/pyramid.h"

namespace {

// Counts bytes only: the benchmark measures the pyramid, not a container.
class CountingSink final : public terrain::PyramidSink {
 public:
  void band(int, int64_t, int64_t, std::vector<uint8_t>&& bytes) override { total += bytes.size(); }
  void mask_band(int64_t, int64_t, std::vector<uint8_t>&& bytes) override { total += bytes.size(); }
  uint64_t total = 0;
};

int run(int argc, char** argv) {
  std::string input;
  cli::CommonFlags common;
  terrain::ReadOptions read_options;
  terrain::BuildOptions o;
  o.temp_dir = "/tmp";
  o.level_ordered_output = false;  // the counting sink takes bands in any order: no temp files
  int64_t step = 4, band_rows = 64;
  cli::ArgParser parser(
      "pyramid-bench", "INPUT [--step S] [--levels N] [--threads T] [--temp-dir DIR] [options]",
      "Builds the residual pyramid of INPUT streamed (one pass over the input, no level spilled\n"
      "to disk), with the uniform quantiser as residual coder and a sink that only counts bytes,\n"
      "and reports throughput (finest samples per second of wall time), times, peak RSS, rows\n"
      "held per level and level statistics. Nothing is written.");
  parser.positional("INPUT", "heightmap to read (any format terrain-info reads; raw needs its .json)",
                    &input);
  parser.option("--step", "S", "quantiser step in level units (default 4)",
                [&](const std::string& v) { step = cli::parse_int("--step", v, 1, 1 << 20); });
  parser.option("--levels", "N", "number of levels (default: coarsest about 128 samples)",
                [&](const std::string& v) { o.level_count = int(cli::parse_int("--levels", v, 1, 40)); });
  parser.option("--threads", "T", "worker threads (default 2; results identical for any T)",
                [&](const std::string& v) { o.threads = int(cli::parse_int("--threads", v, 1, 256)); });
  parser.option("--band-rows", "R", "coder band height (default 64)",
                [&](const std::string& v) { band_rows = cli::parse_int("--band-rows", v, 1, 1 << 20); });
  parser.option("--temp-dir", "DIR", "temp directory (unused with the counting sink; default /tmp)",
                &o.temp_dir);
  cli::add_read_options(parser, read_options);
  parser.add_common(common, true);
  if (auto status = parser.parse(argc, argv)) return *status;

  const auto t0 = std::chrono::steady_clock::now();
  auto reader = terrain::open_band_reader(input, read_options);
  const terrain::GridInfo info = reader->info();
  if (!info.integer_valued()) o.value_scale = 100;  // float input: centimetre levels
  terrain::UniformQuantizerCoder coder(int32_t(step), band_rows);
  CountingSink sink;
  o.temp_name = "pyramid-bench." + std::to_string(::getpid());
  terrain::BuildResult r = terrain::build_pyramid(*reader, o, coder, sink);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  const double samples = double(info.width) * double(info.height);
  const double msps = samples / 1e6 / seconds;
  const double rss_mib = double(ru.ru_maxrss) / 1024.0;

  if (common.json) {
    cli::JsonWriter j(std::cout);
    j.begin_object();
    j.field("input", input).field("width", info.width).field("height", info.height).field("step", step);
    j.field("threads", o.threads).field("seconds", seconds).field("msamples_per_s", msps);
    j.field("seconds_fit", r.seconds_pass_input).field("seconds_build", r.seconds_pass_residual);
    j.field("seconds_replay", r.seconds_pass_filter).field("peak_rss_mib", rss_mib);
    j.field("bytes", int64_t(sink.total)).field("voids", r.void_count);
    j.field("filter", r.filter_report.summary());
    j.key("levels").begin_array();
    for (auto& l : r.levels) {
      j.begin_object();
      j.field("width", l.size.width).field("height", l.size.height).field("residual_rms", l.residual_rms);
      j.field("residual_max", l.residual_max_abs)
          .field("error_rms", l.error_rms)
          .field("error_max", l.error_max_abs);
      j.field("bytes", int64_t(l.bytes));
      j.end_object();
    }
    j.end_array();
    j.end_object();
    j.finish();
  } else {
    std::cout << "pyramid-bench " << input << ": " << info.width << "x" << info.height << ", step " << step
              << ", threads " << o.threads << "\n";
    for (auto& line : r.log) std::cout << "  " << line << "\n";
    std::cout << "  time " << seconds << " s (fitting D " << r.seconds_pass_input << " s, streaming build "
              << r.seconds_pass_residual << " s, level-order replay " << r.seconds_pass_filter << " s)\n";
    std::cout << "  throughput " << msps << " Msamples/s, peak RSS " << rss_mib << " MiB, coded "
              << double(sink.total) / (1 << 20) << " MiB\n";
    std::cout << "  level  size          residual rms   max     error rms  max   MiB\n";
    for (size_t l = 0; l < r.levels.size(); ++l) {
      const auto& s = r.levels[l];
      char line[160];
      std::snprintf(line, sizeof line, "  %-5zu  %6lldx%-6lld  %12.3f  %6lld  %9.3f  %4lld  %8.2f\n", l,
                    (long long)s.size.width, (long long)s.size.height, s.residual_rms,
                    (long long)s.residual_max_abs, s.error_rms, (long long)s.error_max_abs,
                    double(s.bytes) / (1 << 20));
      std::cout << line;
    }
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return cli::run_tool("pyramid-bench", [&] { return run(argc, argv); });
}
