// region-bench: times the runtime's whole-level decode of a pyramid file (RegionDecoder::decode_units
// over the whole of one level, cache emptied before each repetition: the path terrain-bench times as
// "pyramid decode") on one thread, and prints a checksum of the decoded samples so that two builds
// can be compared for identical output as well as for speed.
#include <time.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <iostream>
#include <vector>

#include "cli.h"
#include "codec/crc32c.h"
#include "json_writer.h"
#include "runtime/region_decoder.h"

namespace {

double thread_cpu_seconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

int run(int argc, char** argv) {
  std::string input;
  cli::CommonFlags common;
  int64_t repeat = 9, level = -1, cache_mib = 256;
  cli::ArgParser parser(
      "region-bench", "FILE.pyr [--repeat N] [--level L] [--cache-mib M]",
      "Decodes one level of FILE.pyr whole through the runtime's RegionDecoder (one thread, the\n"
      "decoded-tile cache emptied before each repetition) and reports the best and median speed in\n"
      "million samples per second of thread CPU time, and the CRC32C of the decoded samples.");
  parser.positional("FILE.pyr", "pyramid file", &input);
  parser.option("--repeat", "N", "repetitions (default 9)",
                [&](const std::string& v) { repeat = cli::parse_int("--repeat", v, 1, 100000); });
  parser.option("--level", "L", "level to decode (default: the finest)",
                [&](const std::string& v) { level = cli::parse_int("--level", v, 0, 63); });
  parser.option("--cache-mib", "M", "decoded-tile cache bound in MiB (default 256; 0: no cache)",
                [&](const std::string& v) { cache_mib = cli::parse_int("--cache-mib", v, 0, 1 << 20); });
  parser.add_common(common, true);
  if (auto status = parser.parse(argc, argv)) return *status;

  auto file = terrain::container::PyramidFile::open(input);
  if (level < 0) level = file->level_count() - 1;
  if (level >= file->level_count())
    throw terrain::Error(terrain::ErrorCode::InvalidOption, input + ": no level " + std::to_string(level) +
                                                                " (" + std::to_string(file->level_count()) +
                                                                " levels)");
  terrain::runtime::RegionDecoder decoder(file, size_t(cache_mib) << 20);
  const terrain::GridSize size = file->level_size(int(level));
  const terrain::Rect whole{0, 0, size.width, size.height};
  std::vector<int32_t> out(size_t(size.width * size.height));
  std::vector<double> cpu, wall;
  for (int64_t r = 0; r < repeat; ++r) {
    decoder.clear_cache();
    const double c0 = thread_cpu_seconds();
    const auto t0 = std::chrono::steady_clock::now();
    decoder.decode_units(int(level), whole, out.data(), size.width);
    wall.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    cpu.push_back(thread_cpu_seconds() - c0);
  }
  const uint32_t crc = codec::crc32c(out.data(), out.size() * sizeof(int32_t));
  std::sort(cpu.begin(), cpu.end());
  std::sort(wall.begin(), wall.end());
  const double n = double(size.width) * double(size.height) / 1e6;
  const double best = n / cpu.front(), median = n / cpu[cpu.size() / 2];
  if (common.json) {
    cli::JsonWriter j(std::cout);
    j.begin_object();
    j.field("input", input).field("level", level).field("width", size.width).field("height", size.height);
    j.field("repeat", repeat).field("best_msamples_per_s", best).field("median_msamples_per_s", median);
    j.field("best_wall_seconds", wall.front()).field("crc32c", int64_t(crc));
    j.end_object();
    j.finish();
  } else {
    char line[256];
    std::snprintf(line, sizeof line,
                  "%s level %lld (%lldx%lld): best %.1f, median %.1f Msamples/s (thread CPU, %lld reps), "
                  "crc32c %08x\n",
                  input.c_str(), (long long)level, (long long)size.width, (long long)size.height, best,
                  median, (long long)repeat, crc);
    std::cout << line;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return cli::run_tool("region-bench", [&] { return run(argc, argv); });
}
