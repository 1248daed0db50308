// D's engine alone, as the builder runs its finest level (the wavelet D, rounded, batches of 32
// coarse rows, bands of 128 fine rows pushed, samples known to be int16), on the first ROWS rows of a
// little-endian int16 grid WIDTH samples wide, with THREADS threads; prints the seconds. The rows are
// converted to int32 before the clock starts, and the emitted rows are cast to int32 as the builder's D
// thread does. Usage: d_engine GRID.raw WIDTH ROWS THREADS   (docs/scale.md: pin with taskset, alternate
// builds)
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "pyramid/internal/filter_downsample.h"

int main(int argc, char** argv) {
  if (argc != 5) {
    std::fprintf(stderr, "usage: d_engine GRID.raw WIDTH ROWS THREADS\n");
    return 2;
  }
  const int64_t w = std::atoll(argv[2]), h = std::atoll(argv[3]);
  const int threads = std::atoi(argv[4]);
  if (w < 2 || h < 2 || threads < 1) {
    std::fprintf(stderr, "d_engine: WIDTH and ROWS must be >= 2, THREADS >= 1\n");
    return 2;
  }
  std::FILE* f = std::fopen(argv[1], "rb");
  std::vector<int16_t> raw(size_t(w * h));
  if (!f || std::fread(raw.data(), 2, raw.size(), f) != raw.size()) {
    std::fprintf(stderr, "d_engine: %s: cannot read %lld x %lld int16 samples\n", argv[1], (long long)w,
                 (long long)h);
    return 1;
  }
  std::fclose(f);
  const std::vector<int32_t> rows(raw.begin(), raw.end());
  terrain::detail::DownsampleEngine engine(terrain::DownsampleFilter::wavelet(), terrain::GridSize{w, h},
                                           threads, 32, true, 32768);
  const int64_t cw = engine.coarse().width;
  std::vector<int32_t> chunk;
  int64_t emitted = 0, check = 0;
  const auto emit = [&](int64_t, int64_t n, const double* out) {
    chunk.resize(size_t(n * cw));
    for (int64_t k = 0; k < n * cw; ++k) chunk[size_t(k)] = static_cast<int32_t>(out[k]);
    emitted += n;
    check += chunk[0];
  };
  const auto t0 = std::chrono::steady_clock::now();
  for (int64_t y = 0; y < h; y += 128)
    engine.push_rows(rows.data() + y * w, std::min<int64_t>(128, h - y), emit);
  engine.finish(emit);
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("threads %d: %lld coarse rows in %.3f s (check %lld)\n", threads, (long long)emitted, s,
              (long long)check);
  return 0;
}
