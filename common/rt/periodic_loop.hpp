// The RT loop's thread: absolute deadlines on CLOCK_MONOTONIC with clock_nanosleep, and the RT
// settings a node asks for (SCHED_FIFO, mlockall, CPU affinity), each refusal named.
#pragma once

#include <atomic>
#include <chrono>
#include <functional>
#include <string>
#include <thread>
#include <vector>

#include "common/rt/loop_timing.hpp"

namespace teleop::rt {

struct RtSettings {
  int fifo_priority{0};  // 0: leave the scheduler alone; 1..99: SCHED_FIFO
  bool lock_memory{false};
  int cpu{-1};           // -1: any CPU
  bool required{false};  // a refusal is fatal (rt { required: true })
};

// Applies the settings to the calling thread; returns one message per refused setting, naming
// it and the kernel's reason. Throws std::runtime_error with all of them when `required`.
std::vector<std::string> apply_rt_settings(const RtSettings& settings);

// Runs `step(deadline)` once per period on its own thread until stop(). `step` is the node's
// RT step: it must not allocate, lock or throw; it receives the cycle's deadline on the
// monotonic clock (ns since its epoch). After a stall that deadline is in the past: the clock
// read on waking is timing().last_woke() (read on the loop's thread, inside step).
class PeriodicLoop {
 public:
  using Step = std::function<void(std::chrono::nanoseconds deadline)>;

  PeriodicLoop(std::chrono::nanoseconds period, RtSettings settings, Step step);
  ~PeriodicLoop();
  PeriodicLoop(const PeriodicLoop&) = delete;
  PeriodicLoop& operator=(const PeriodicLoop&) = delete;

  void start();
  void stop();  // joins
  // Settings the kernel refused (valid after start()).
  [[nodiscard]] const std::vector<std::string>& refused() const { return refused_; }
  // Read after stop(): the loop's own statistics.
  [[nodiscard]] const LoopTiming& timing() const { return timing_; }

  [[nodiscard]] static std::chrono::nanoseconds monotonic_now() noexcept;

 private:
  void run();

  std::chrono::nanoseconds period_;
  RtSettings settings_;
  Step step_;
  LoopTiming timing_;
  std::vector<std::string> refused_{};
  std::atomic<bool> running_{false};
  std::atomic<bool> started_{false};
  std::thread thread_{};
};

}  // namespace teleop::rt
