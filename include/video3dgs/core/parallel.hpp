#pragma once
/// @file
/// A small thread pool and deterministic parallel loops.
///
/// Determinism rule used across the library: work is split into chunks whose boundaries depend only
/// on the problem size and a grain (never on the thread count); a chunk writes only its own outputs
/// or its own partial buffer; partial buffers are reduced in chunk order. The result is then
/// bit-identical for any number of threads. `parallel_for_chunks` gives you the chunk index for that.
///
/// Every function takes a `ThreadPool*`; `nullptr` runs serially on the calling thread. A pool called
/// from inside one of its own tasks runs the nested loop serially (no deadlock, same result).

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <exception>
#include <functional>
#include <mutex>
#include <thread>
#include <utility>
#include <vector>

namespace video3dgs {

class ThreadPool {
 public:
  /// @param threads total threads working on a loop, the calling thread included (0 = all cores).
  explicit ThreadPool(unsigned threads = 0) {
    if (threads == 0) threads = std::max(1u, std::thread::hardware_concurrency());
    size_ = threads;
    workers_.reserve(threads - 1);
    for (unsigned i = 0; i + 1 < threads; ++i) workers_.emplace_back([this] { worker_loop(); });
  }
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;
  ~ThreadPool() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stop_ = true;
    }
    wake_.notify_all();
    for (auto& w : workers_) w.join();
  }

  /// Threads working on a loop, the caller included.
  [[nodiscard]] unsigned size() const noexcept { return size_; }

  /// Runs f(task) for every task in [0, tasks) and returns when all have finished. Tasks are taken
  /// dynamically, so f must not depend on which thread runs it. The first exception thrown by a task
  /// is rethrown here (the remaining tasks are skipped).
  template <class F>
  void run(std::size_t tasks, F&& f) {
    if (tasks == 0) return;
    if (size_ == 1 || tasks == 1 || inside_task()) {
      for (std::size_t i = 0; i < tasks; ++i) f(i);
      return;
    }
    std::lock_guard<std::mutex> one_loop_at_a_time(run_mutex_);
    std::function<void(std::size_t)> fn = std::ref(f);
    {
      std::lock_guard<std::mutex> lock(mutex_);
      job_ = &fn;
      tasks_ = tasks;
      next_.store(0);
      pending_ = tasks;
      error_ = nullptr;
      ++generation_;
    }
    wake_.notify_all();
    work_on_job();
    std::unique_lock<std::mutex> lock(mutex_);
    done_.wait(lock, [&] { return pending_ == 0 && busy_ == 0; });
    job_ = nullptr;
    if (error_) std::rethrow_exception(std::exchange(error_, nullptr));
  }

 private:
  static bool& inside_task() {
    thread_local bool inside = false;
    return inside;
  }

  void work_on_job() {
    const bool was_inside = inside_task();
    inside_task() = true;
    for (;;) {
      const std::size_t i = next_.fetch_add(1);
      if (i >= tasks_) break;
      bool skip;
      {
        std::lock_guard<std::mutex> lock(mutex_);
        skip = error_ != nullptr;
      }
      if (!skip) {
        try {
          (*job_)(i);
        } catch (...) {
          std::lock_guard<std::mutex> lock(mutex_);
          if (!error_) error_ = std::current_exception();
        }
      }
      std::lock_guard<std::mutex> lock(mutex_);
      if (--pending_ == 0) done_.notify_all();
    }
    inside_task() = was_inside;
  }

  void worker_loop() {
    std::size_t seen = 0;
    for (;;) {
      {
        std::unique_lock<std::mutex> lock(mutex_);
        wake_.wait(lock, [&] { return stop_ || (generation_ != seen && job_ != nullptr); });
        if (stop_) return;
        seen = generation_;
        ++busy_;
      }
      work_on_job();
      std::lock_guard<std::mutex> lock(mutex_);
      if (--busy_ == 0 && pending_ == 0) done_.notify_all();
    }
  }

  unsigned size_ = 1;
  std::vector<std::thread> workers_;
  std::mutex run_mutex_;
  std::mutex mutex_;
  std::condition_variable wake_, done_;
  std::function<void(std::size_t)>* job_ = nullptr;
  std::size_t tasks_ = 0;
  std::atomic<std::size_t> next_{0};
  std::size_t pending_ = 0;
  unsigned busy_ = 0;
  std::size_t generation_ = 0;
  std::exception_ptr error_;
  bool stop_ = false;
};

/// Number of chunks `parallel_for_chunks` makes for n items of the given grain.
[[nodiscard]] constexpr std::size_t chunk_count(std::size_t n, std::size_t grain) noexcept {
  return grain == 0 ? (n == 0 ? 0 : 1) : (n + grain - 1) / grain;
}

/// Calls f(chunk, begin, end) for the chunks [k*grain, min(n, (k+1)*grain)). The chunking depends on
/// n and grain only, so per-chunk partial results reduced in chunk order are thread-count independent.
template <class F>
void parallel_for_chunks(ThreadPool* pool, std::size_t n, std::size_t grain, F&& f) {
  if (grain == 0) grain = std::max<std::size_t>(n, 1);
  const std::size_t chunks = chunk_count(n, grain);
  auto body = [&](std::size_t k) {
    const std::size_t begin = k * grain;
    f(k, begin, std::min(n, begin + grain));
  };
  if (pool == nullptr) {
    for (std::size_t k = 0; k < chunks; ++k) body(k);
  } else {
    pool->run(chunks, body);
  }
}

/// Calls f(i) for every i in [0, n). Use only when iteration i writes outputs of its own.
template <class F>
void parallel_for(ThreadPool* pool, std::size_t n, F&& f, std::size_t grain = 256) {
  parallel_for_chunks(pool, n, grain, [&](std::size_t, std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) f(i);
  });
}

}  // namespace video3dgs
