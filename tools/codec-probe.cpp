// codec-probe: single-threaded speed and rate probe of libcodec on DEM files.
//
// For each file and step: bits/sample, rms and max error, encode and decode Msamples/s (best of
// --repeat runs, one core). Exit statuses as every tool's (codec-probe --help).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <string>
#include <vector>

#include "cli.h"
#include "codec/codec.h"
#include "readers/heightmap.h"

namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<double> steps = {1, 2, 4, 8, 16, 32};
  uint32_t tile = 64;
  int repeat = 3;
  long max_error = -1;
  std::vector<std::string> files;
  cli::CommonFlags common;
  cli::ArgParser p(
      "codec-probe", "[--steps S1,S2,...] [--tile N] [--repeat N] [--max-error E] FILE...",
      "Encodes each DEM (integer samples; Terrain-RGB PNGs in 0.1 m units) with libcodec on one\n"
      "core and prints bits/sample, rms/max error and encode/decode Msamples/s (best of --repeat).");
  p.rest("FILE", "DEM files (a name containing \"terrainrgb\" is read as Terrain-RGB)", &files, 1);
  p.option("--steps", "S1,S2,...",
           "quantiser steps >= 1 (1 = lossless); 0 = automatic (2E) with --max-error (default 1,2,4,8,16,32)",
           [&](const std::string& list) {
             steps.clear();
             std::stringstream ss(list);
             for (std::string item; std::getline(ss, item, ',');) {
               const double s = cli::parse_double("--steps", item, 0, 1e9);
               if (s > 0 && s < 1) throw cli::UsageError("--steps: step " + item + " is neither 0 nor >= 1");
               steps.push_back(s);
             }
             if (steps.empty()) throw cli::UsageError("--steps needs at least one step");
           });
  p.option("--tile", "N", "libcodec tile size (default 64)",
           [&](const std::string& v) { tile = uint32_t(cli::parse_int("--tile", v, 1, 1 << 20)); });
  p.option("--repeat", "N", "runs of each encode and decode; the fastest counts (default 3)",
           [&](const std::string& v) { repeat = int(cli::parse_int("--repeat", v, 1, 1000000)); });
  p.option("--max-error", "E", "bound the max |error| to E sample units (encoder's max-error mode)",
           [&](const std::string& v) { max_error = long(cli::parse_int("--max-error", v, 0, INT32_MAX)); });
  p.add_common(common, false);
  if (auto status = p.parse(argc, argv)) return *status;
  std::printf("%-48s %6s %5s %8s %8s %7s %9s %9s\n", "file", "step", "E", "bits/smp", "rms", "maxerr",
              "enc Ms/s", "dec Ms/s");
  codec::Scratch scratch;
  for (const auto& path : files) {
    terrain::Heightmap map;
    try {
      terrain::ReadOptions ro;
      if (path.find("terrainrgb") != std::string::npos) ro.terrain_rgb = true;
      map = terrain::read_heightmap(path, ro);
    } catch (const terrain::Error& e) {
      std::fprintf(stderr, "codec-probe: %s\n", e.what());
      return cli::exit_status(e.code());
    }
    bool integral = true;
    for (double v : map.values) integral = integral && v == std::floor(v);
    std::vector<int32_t> src(map.values.size());
    for (size_t i = 0; i < src.size(); ++i)
      src[i] = int32_t(std::lround(integral ? map.values[i] : map.values[i] * 10));
    const int64_t w = map.width(), h = map.height();
    const double n = double(src.size());
    std::vector<int32_t> out(src.size());
    const std::string name = path.substr(path.find_last_of('/') + 1);
    if (common.verbose)
      std::fprintf(stderr, "codec-probe: %s: %lldx%lld, %s\n", name.c_str(), (long long)w, (long long)h,
                   integral ? "integer samples" : "coded in 0.1 m units");
    for (double step : steps) {
      codec::EncodeOptions o;
      o.step = step;
      o.tile_size = tile;
      if (max_error >= 0) {
        o.bound_max_error = true;
        o.max_error = uint32_t(max_error);
      }
      std::vector<uint8_t> stream(codec::encode_bound(w, h, o));
      if (stream.empty()) {
        std::fprintf(stderr, "codec-probe: invalid options (tile %u)\n", tile);
        return 1;
      }
      size_t written = 0;
      double enc = 1e30, dec = 1e30;
      for (int r = 0; r < repeat; ++r) {
        const auto t0 = std::chrono::steady_clock::now();
        const codec::Status s =
            codec::encode(src.data(), w, w, h, o, stream.data(), stream.size(), &written, scratch);
        enc = std::min(enc, seconds_since(t0));
        if (s != codec::Status::Ok) {
          std::fprintf(stderr, "codec-probe: %s: encode failed: %s\n", path.c_str(), codec::status_name(s));
          return 10;
        }
      }
      for (int r = 0; r < repeat; ++r) {
        const auto t0 = std::chrono::steady_clock::now();
        const codec::Status s = codec::decode(stream.data(), written, out.data(), w, scratch);
        dec = std::min(dec, seconds_since(t0));
        if (s != codec::Status::Ok) {
          std::fprintf(stderr, "codec-probe: %s: decode failed: %s\n", path.c_str(), codec::status_name(s));
          return 10;
        }
      }
      double sq = 0;
      int64_t worst = 0;
      for (size_t i = 0; i < src.size(); ++i) {
        const int64_t e = int64_t(out[i]) - src[i];
        sq += double(e * e);
        worst = std::max<int64_t>(worst, std::llabs(e));
      }
      std::printf("%-48s %6.2f %5ld %8.3f %8.3f %7lld %9.1f %9.1f\n", name.c_str(), step, max_error,
                  double(written) * 8 / n, std::sqrt(sq / n), (long long)worst, n / enc / 1e6, n / dec / 1e6);
    }
  }
  return 0;
}
