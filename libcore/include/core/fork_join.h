// A fork-join of n parts for an encoder's own parallelism (libcodec's tile rows, EncodeOptions::threads):
// part 0 on the calling thread, the others on threads started and joined within the call.
// Callers split their work so that the result does not depend on n.
#pragma once

#include <cstddef>
#include <exception>
#include <functional>
#include <thread>
#include <vector>

namespace terrain {

// Runs body(c) for c in [0, n) and returns when all have ended; the first exception a part threw
// (lowest c) is then rethrown. n <= 1 runs on the calling thread alone.
template <class Body> void fork_join(size_t n, Body&& body) {
  if (n <= 1) {
    if (n == 1) body(size_t(0));
    return;
  }
  std::vector<std::exception_ptr> errors(n);
  const auto run = [&](size_t c) {
    try {
      body(c);
    } catch (...) {
      errors[c] = std::current_exception();
    }
  };
  std::vector<std::thread> threads;
  threads.reserve(n - 1);
  for (size_t c = 1; c < n; ++c) threads.emplace_back(run, c);
  run(0);
  for (std::thread& t : threads) t.join();
  for (const std::exception_ptr& e : errors)
    if (e) std::rethrow_exception(e);
}

// Experimental: runs the parts of a fork-join on threads the caller already has (the pyramid
// builder's coding workers, so that the parts of all the bands coded at once share them) instead
// of threads started for the call.
class PartRunner {
 public:
  virtual ~PartRunner() = default;
  // Calls part(c) once for every c in [0, n), on any threads and in any order, and returns when all
  // have returned; the first exception a part threw (lowest c) is then rethrown. Called from any
  // thread the runner serves; a part must not call run() itself.
  virtual void run(size_t n, const std::function<void(size_t)>& part) = 0;
};

// fork_join with the parts on `runner`'s threads (null: on threads started here).
template <class Body> void fork_join(size_t n, Body&& body, PartRunner* runner) {
  if (!runner || n <= 1) {
    fork_join(n, body);
    return;
  }
  runner->run(n, std::function<void(size_t)>(std::ref(body)));
}

}  // namespace terrain
