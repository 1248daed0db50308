// Shared plumbing of the file-reader fuzz targets: the readers take paths (the format is detected
// from the name and the sidecar sits beside the file), so each input is written into a private
// scratch directory under $TMPDIR and read back through the public API. Any Error is fine;
// crashes, sanitizer reports, leaks and other exception types are not.
#pragma once

#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "readers/heightmap.h"

namespace fuzz_io {

// A per-process directory, removed at exit. The path lives on the heap and is never freed: the
// exit handler is registered while the path is being built, so it runs after any static string
// would already have been destroyed.
inline const std::string& scratch_dir() {
  static const std::string* dir = [] {
    const char* tmp = std::getenv("TMPDIR");
    auto* d = new std::string(std::string(tmp && *tmp ? tmp : "/tmp") + "/terrain-fuzz-" +
                              std::to_string(getpid()));
    std::filesystem::create_directories(*d);
    std::atexit([] {
      std::error_code ec;
      std::filesystem::remove_all(*dir, ec);
    });
    return d;
  }();
  return *dir;
}

inline std::string write_file(const std::string& name, const uint8_t* data, size_t size) {
  const std::string path = scratch_dir() + "/" + name;
  FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) std::abort();
  if (size && std::fwrite(data, 1, size, f) != size) std::abort();
  std::fclose(f);
  return path;
}

inline void remove_file(const std::string& name) {
  std::error_code ec;
  std::filesystem::remove(scratch_dir() + "/" + name, ec);
}

// Reads the grid both whole and streamed in small bands; both must agree on what they accept.
// Grids over max_samples are only probed (keeps memory per input small).
inline void read_both_ways(const std::string& path, const terrain::ReadOptions& options,
                           int64_t max_samples = 1 << 20) {
  terrain::GridInfo info;
  try {
    info = terrain::probe(path, options);
  } catch (const terrain::Error&) {
    return;
  }
  if (info.width <= 0 || info.height <= 0) std::abort();  // probe must reject empty grids
  if (info.width > max_samples / info.height) return;
  bool whole_ok = true;
  terrain::Heightmap map;
  try {
    map = terrain::read_heightmap(path, options);
  } catch (const terrain::Error&) {
    whole_ok = false;
  }
  if (whole_ok) {
    if (int64_t(map.values.size()) != map.width() * map.height()) std::abort();
    if (!map.valid.empty() && map.valid.size() != map.values.size()) std::abort();
    (void)terrain::compute_stats(map);
  }
  try {
    auto reader = terrain::open_band_reader(path, options);
    (void)terrain::stream_stats(*reader, 3);
  } catch (const terrain::Error&) {
  }
  // Readers that decode integers directly (read_rows_int32) give what the whole read gave, in bands
  // of 5 rows, or fail where it failed.
  try {
    auto reader = terrain::open_band_reader(path, options);
    if (!reader->reads_int32()) return;
    const int64_t w = info.width, band = 5;
    std::vector<int32_t> ints(size_t(w * band));
    std::vector<uint8_t> valid(ints.size());
    int64_t row = 0;
    while (const int64_t n = reader->read_rows_int32(band, ints.data(), valid.data())) {
      if (!whole_ok || n > band || row + n > map.height()) std::abort();
      for (int64_t i = 0; i < n * w; ++i) {
        const int64_t x = i % w, y = row + i / w;
        const bool v = map.is_valid(x, y);
        if ((valid[size_t(i)] != 0) != v || double(ints[size_t(i)]) != (v ? map.at(x, y) : 0.0)) std::abort();
      }
      row += n;
    }
    if (row != info.height) std::abort();
  } catch (const terrain::Error&) {
    if (whole_ok) std::abort();
  }
}

}  // namespace fuzz_io
