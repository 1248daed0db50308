// codec-probe: single-threaded speed and rate probe of libcodec on DEM files.
//
// For each file and step: bits/sample, rms and max error, encode and decode Msamples/s (best of
// --repeat runs, one core). Usage: codec-probe [--steps 1,2,4,...] [--tile N] [--repeat N]
//   [--max-error E] FILE...
// Exit codes (project-wide): 0 success; 1 usage error; 2 input not found or unreadable;
// 3..8 input format problems (see terrain::ErrorCode); 10 codec error; 70 internal error.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "cli.h"
#include "codec/codec.h"
#include "readers/heightmap.h"

namespace {

void usage(FILE* to) {
  std::fprintf(to,
               "usage: codec-probe [--steps S1,S2,...] [--tile N] [--repeat N] [--max-error E] FILE...\n"
               "  --steps: quantiser steps >= 1 (1 = lossless); 0 = automatic (2E) with --max-error\n"
               "  Encodes each DEM (integer samples; Terrain-RGB PNGs in 0.1 m units) with libcodec on one\n"
               "  core and prints bits/sample, rms/max error and encode/decode Msamples/s.\n"
               "exit codes: 0 ok, 1 usage, 2 input not found/unreadable, 3-8 input format errors,\n"
               "  10 codec error, 70 internal error\n");
}

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
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const bool has_value = i + 1 < argc;
    if (a == "--help" || a == "-h") {
      usage(stdout);
      return 0;
    } else if (a == "--steps" && has_value) {
      steps.clear();
      std::string list = argv[++i];
      size_t p = 0;
      while (p <= list.size()) {
        const size_t q = std::min(list.find(',', p), list.size());
        const double s = std::atof(list.substr(p, q - p).c_str());
        if (!(s >= 1.0 || s == 0.0)) {  // 0 = automatic step in max-error mode
          std::fprintf(stderr, "codec-probe: bad step in --steps %s\n", list.c_str());
          return 1;
        }
        steps.push_back(s);
        p = q + 1;
      }
    } else if (a == "--tile" && has_value) {
      tile = uint32_t(std::atoi(argv[++i]));
    } else if (a == "--repeat" && has_value) {
      repeat = std::max(1, std::atoi(argv[++i]));
    } else if (a == "--max-error" && has_value) {
      max_error = std::atol(argv[++i]);
      if (max_error < 0) {
        std::fprintf(stderr, "codec-probe: --max-error must be >= 0\n");
        return 1;
      }
    } else if (!a.empty() && a[0] == '-') {
      std::fprintf(stderr, "codec-probe: unknown option %s\n", a.c_str());
      usage(stderr);
      return 1;
    } else {
      files.push_back(a);
    }
  }
  if (files.empty()) {
    usage(stderr);
    return 1;
  }
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
