// Static row partitioning over a few std::threads. Work is split into fixed contiguous chunks and
// every chunk writes only its own outputs, so results never depend on the thread count.
#pragma once

#include <algorithm>
#include <cstdint>
#include <exception>
#include <thread>
#include <vector>

namespace terrain::detail {

// Calls body(worker, begin, end) for `workers` contiguous chunks of [0, n); worker 0 runs on the
// calling thread. The first exception thrown by any chunk is rethrown after all have finished.
template <class Body> void parallel_chunks(int workers, int64_t n, Body&& body) {
  workers = int(std::clamp<int64_t>(workers, 1, std::max<int64_t>(n, 1)));
  if (workers == 1) {
    body(0, int64_t(0), n);
    return;
  }
  std::vector<std::exception_ptr> errors(static_cast<size_t>(workers));
  std::vector<std::thread> pool;
  pool.reserve(size_t(workers - 1));
  auto run = [&](int w) {
    const int64_t b = n * w / workers, e = n * (w + 1) / workers;
    try {
      body(w, b, e);
    } catch (...) {
      errors[size_t(w)] = std::current_exception();
    }
  };
  for (int w = 1; w < workers; ++w) pool.emplace_back(run, w);
  run(0);
  for (auto& t : pool) t.join();
  for (auto& e : errors)
    if (e) std::rethrow_exception(e);
}

}  // namespace terrain::detail
