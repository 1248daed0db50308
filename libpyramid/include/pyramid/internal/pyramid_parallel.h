// Static row partitioning over a few threads. Work is split into fixed contiguous chunks and every
// chunk writes only its own outputs, so results never depend on the thread count.
#pragma once

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <exception>
#include <functional>
#include <mutex>
#include <span>
#include <thread>
#include <vector>

namespace terrain::detail {

// How the pools below and the builder's helper threads end: `stop` set under `lock`, every waiter on
// `wake` notified, `threads` joined. Their owners call it before the members the threads read die.
inline void stop_and_join(std::mutex& lock, std::condition_variable& wake, bool& stop,
                          std::span<std::thread> threads) {
  {
    const std::lock_guard<std::mutex> hold(lock);
    stop = true;
  }
  wake.notify_all();
  for (std::thread& t : threads) t.join();
}

// The threads a pool keeps, and what they wait on. A pool's destructor calls stop_threads().
class PoolThreads {
 protected:
  void stop_threads() {
    stop_and_join(lock_, wake_, stop_, threads_);
    threads_.clear();
  }
  std::vector<std::thread> threads_;
  std::mutex lock_;
  std::condition_variable wake_;
  bool stop_ = false;
};

// Workers kept by one calling thread for its parallel_chunks calls (thread_local: the builder's main
// thread runs D's batches one after another, hundreds per level, and starting fresh threads for
// each was part of its serial time). Grows to the largest worker count asked; joined when the
// calling thread exits. Not reentrant from inside a chunk.
class ChunkPool : PoolThreads {
 public:
  ~ChunkPool() { stop_threads(); }
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

  std::condition_variable done_;
  const std::function<void(int)>* job_ = nullptr;
  uint64_t generation_ = 0;
  int active_ = 0, pending_ = 0;
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

// Workers kept by one calling thread for its parallel_items calls. Where ChunkPool gives each worker
// a fixed chunk and waits for every worker, here the items are claimed one at a time by whoever is
// running (the calling thread included) and a batch ends when its items are done: a worker that
// has not been scheduled by then is not waited for (it finds the batch closed and sleeps again).
// The builder's D cascade runs hundreds of short batches per level beside the busy coding threads;
// with fixed chunks each one waited for its last chunk's thread to be scheduled (docs/scale.md,
// "where the 16-thread build loses"). Not reentrant from inside an item.
class ClaimPool : PoolThreads {
 public:
  ~ClaimPool() { stop_threads(); }
  // Calls item(slot, i) for every i in [0, n), each once, on this thread (slot 0) and on at most
  // workers - 1 pool threads (slots 1 .. workers - 1, each slot used by one thread at a time);
  // returns when every item is done. The first exception is rethrown after that; items not yet
  // claimed when it was thrown are skipped.
  void run(int workers, int64_t n, const std::function<void(int, int64_t)>& item) {
    while (int(threads_.size()) < workers - 1) threads_.emplace_back([this] { serve(); });
    Batch batch;
    batch.item = &item, batch.n = n, batch.slots = workers;
    {
      const std::lock_guard<std::mutex> hold(lock_);
      batch_ = &batch;
      ++generation_;
    }
    wake_.notify_all();
    work(batch, 0);
    std::unique_lock<std::mutex> hold(lock_);
    batch_ = nullptr;  // late workers find nothing to join
    done_.wait(hold, [&] { return batch.users == 0; });
    if (batch.error) std::rethrow_exception(batch.error);
  }

 private:
  struct Batch {
    const std::function<void(int, int64_t)>* item = nullptr;
    int64_t n = 0;
    int slots = 1;
    std::atomic<int64_t> next{0};
    std::atomic<bool> failed{false};
    int users = 0, slots_taken = 1;  // under lock_; slot 0 is the caller's
    std::exception_ptr error;        // under lock_
  };
  void work(Batch& b, int slot) {
    for (int64_t i; !b.failed.load(std::memory_order_relaxed) &&
                    (i = b.next.fetch_add(1, std::memory_order_relaxed)) < b.n;) {
      try {
        (*b.item)(slot, i);
      } catch (...) {
        const std::lock_guard<std::mutex> hold(lock_);
        if (!b.error) b.error = std::current_exception();
        b.failed.store(true, std::memory_order_relaxed);
      }
    }
  }
  void serve() {
    uint64_t seen = 0;
    for (;;) {
      Batch* b = nullptr;
      int slot = 0;
      {
        std::unique_lock<std::mutex> hold(lock_);
        wake_.wait(hold, [&] { return stop_ || (batch_ && generation_ != seen); });
        if (stop_) return;
        seen = generation_;
        if (batch_->slots_taken >= batch_->slots) continue;
        b = batch_;
        slot = b->slots_taken++;
        ++b->users;
      }
      work(*b, slot);
      {
        const std::lock_guard<std::mutex> hold(lock_);
        if (--b->users == 0) done_.notify_one();
      }
    }
  }

  std::condition_variable done_;
  Batch* batch_ = nullptr;
  uint64_t generation_ = 0;
};

// Calls item(slot, i) for i in [0, n), claimed one at a time by the calling thread (slot 0) and up
// to workers - 1 threads of the calling thread's ClaimPool. For many short items beside other busy
// threads; results must not depend on which slot ran an item. Rethrows the first exception.
template <class Item> void parallel_items(int workers, int64_t n, Item&& item) {
  workers = int(std::clamp<int64_t>(workers, 1, std::max<int64_t>(n, 1)));
  if (workers == 1) {
    for (int64_t i = 0; i < n; ++i) item(0, i);
    return;
  }
  const std::function<void(int, int64_t)> run = [&](int slot, int64_t i) { item(slot, i); };
  thread_local ClaimPool pool;
  pool.run(workers, n, run);
}

}  // namespace terrain::detail
