#pragma once
/// @file
/// `ScopedTimer`: adds the wall-clock seconds of a scope to a `double` (stage timers of the trainer
/// and of the clip graph). A null sink times nothing.

#include <chrono>

namespace video3dgs {

class ScopedTimer {
 public:
  using clock = std::chrono::steady_clock;
  explicit ScopedTimer(double* sink) noexcept : sink_(sink), start_(sink ? clock::now() : clock::time_point{}) {}
  explicit ScopedTimer(double& sink) noexcept : ScopedTimer(&sink) {}
  ScopedTimer(const ScopedTimer&) = delete;
  ScopedTimer& operator=(const ScopedTimer&) = delete;
  ~ScopedTimer() {
    if (sink_) *sink_ += std::chrono::duration<double>(clock::now() - start_).count();
  }

 private:
  double* sink_;
  clock::time_point start_;
};

}  // namespace video3dgs
