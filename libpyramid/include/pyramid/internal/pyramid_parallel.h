// Static row partitioning over a few threads. Work is split into fixed contiguous chunks and every
// chunk writes only its own outputs, so results never depend on the thread count.
#pragma once

#include <algorithm>
#include <condition_variable>
#include <cstdint>
#include <exception>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace terrain::detail {

// Workers kept by one calling thread for its parallel_chunks calls (thread_local: the builder's main
// thread runs D's batches one after another, hundreds per level, and starting fresh threads for
// each was part of its serial time). Grows to the largest worker count asked; joined when the
// calling thread exits. Not reentrant from inside a chunk.
class ChunkPool {
 public:
  ~ChunkPool() {
    {
      const std::lock_guard<std::mutex> hold(lock_);
      stop_ = true;
    }
    wake_.notify_all();
    for (std::thread& t : threads_) t.join();
  }
  // Runs job(w) for w = 1 .. workers - 1 on the pool and job(0) here; returns when all are done.
  void run(int workers, const std::function<void(int)>& job) {
    while (int(threads_.size()) < workers - 1) {
      const int index = int(threads_.size()) + 1;
      threads_.emplace_back([this, index] { serve(index); });
    }
    {
      const std::lock_guard<std::mutex> hold(lock_);
      job_ = &job;
      active_ = workers;
      pending_ = workers - 1;
      ++generation_;
    }
    wake_.notify_all();
    job(0);
    std::unique_lock<std::mutex> hold(lock_);
    done_.wait(hold, [this] { return pending_ == 0; });
    job_ = nullptr;
  }

 private:
  void serve(int index) {
    uint64_t seen = 0;
    for (;;) {
      const std::function<void(int)>* job = nullptr;
      {
        std::unique_lock<std::mutex> hold(lock_);
        wake_.wait(hold, [&] { return stop_ || (generation_ != seen && index < active_); });
        if (stop_) return;
        seen = generation_;
        job = job_;
      }
      (*job)(index);
      {
        const std::lock_guard<std::mutex> hold(lock_);
        if (--pending_ == 0) done_.notify_one();
      }
    }
  }

  std::vector<std::thread> threads_;
  std::mutex lock_;
  std::condition_variable wake_, done_;
  const std::function<void(int)>* job_ = nullptr;
  uint64_t generation_ = 0;
  int active_ = 0, pending_ = 0;
  bool stop_ = false;
};

// Calls body(worker, begin, end) for `workers` contiguous chunks of [0, n); worker 0 runs on the
// calling thread, the others on the calling thread's ChunkPool. The first exception thrown by any
// chunk is rethrown after all have finished.
template <class Body> void parallel_chunks(int workers, int64_t n, Body&& body) {
  workers = int(std::clamp<int64_t>(workers, 1, std::max<int64_t>(n, 1)));
  if (workers == 1) {
    body(0, int64_t(0), n);
    return;
  }
  std::vector<std::exception_ptr> errors(static_cast<size_t>(workers));
  const std::function<void(int)> run = [&](int w) {
    const int64_t b = n * w / workers, e = n * (w + 1) / workers;
    try {
      body(w, b, e);
    } catch (...) {
      errors[size_t(w)] = std::current_exception();
    }
  };
  thread_local ChunkPool pool;
  pool.run(workers, run);
  for (auto& e : errors)
    if (e) std::rethrow_exception(e);
}

}  // namespace terrain::detail
