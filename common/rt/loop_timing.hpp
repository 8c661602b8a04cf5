// Timing of a periodic RT loop, separate from the sleeping: absolute deadlines on a monotonic
// clock, overruns counted and skipped ahead (never a burst of catch-up cycles), wake-up latency
// and compute time kept as histograms. The scheduler thread calls these with the clock's
// readings; tests call them with a fake clock.
#pragma once

#include <array>
#include <chrono>
#include <cstdint>

#include "common/core/rt_safe.hpp"

namespace teleop::rt {

// Log-spaced latency histogram from 1 us to ~1 s, fixed size (no allocation). RT-safe.
class LatencyHistogram {
 public:
  static constexpr int kBins = 64;  // 2^(i/3) us: 1 us .. 2^21 us

  TELEOP_RT void add(std::chrono::nanoseconds value) noexcept;
  [[nodiscard]] std::uint64_t count() const noexcept { return count_; }
  [[nodiscard]] std::chrono::nanoseconds max() const noexcept { return max_; }
  // Upper edge of the bin holding the q-quantile (q in [0, 1]); 0 when empty.
  [[nodiscard]] std::chrono::nanoseconds quantile(double q) const noexcept;
  [[nodiscard]] static std::chrono::nanoseconds bin_upper_edge(int bin) noexcept;
  [[nodiscard]] const std::array<std::uint64_t, kBins>& bins() const noexcept { return bins_; }

 private:
  std::array<std::uint64_t, kBins> bins_{};
  std::uint64_t count_{0};
  std::chrono::nanoseconds max_{0};
};

class LoopTiming {
 public:
  using TimePoint = std::chrono::nanoseconds;  // since the monotonic clock's epoch

  LoopTiming(std::chrono::nanoseconds period, TimePoint start) noexcept
      : period_(period), next_(start + period) {}

  // The absolute deadline to sleep until.
  [[nodiscard]] TimePoint next_deadline() const noexcept { return next_; }

  // Called on waking at `now`: records the latency, and when one or more whole periods were
  // missed counts them as overruns and moves the deadline past `now` (skip ahead). Returns the
  // deadline this cycle belongs to. RT-safe.
  TELEOP_RT TimePoint woke(TimePoint now) noexcept;

  // Called when the cycle's work is done at `now`. RT-safe.
  TELEOP_RT void finished(TimePoint now) noexcept;

  [[nodiscard]] std::uint64_t cycles() const noexcept { return cycles_; }
  [[nodiscard]] std::uint64_t overruns() const noexcept { return overruns_; }
  [[nodiscard]] const LatencyHistogram& wakeup_latency() const noexcept { return wakeup_; }
  // Of the newest cycle.
  [[nodiscard]] std::chrono::nanoseconds last_wakeup_latency() const noexcept {
    return last_wakeup_;
  }
  [[nodiscard]] const LatencyHistogram& compute_time() const noexcept { return compute_; }
  // The clock read on waking for the newest cycle (its deadline plus the wake-up latency):
  // what ages and stalls are measured against, since after a stall the deadline woke() returns
  // lies in the past.
  [[nodiscard]] TimePoint last_woke() const noexcept { return cycle_start_; }

 private:
  std::chrono::nanoseconds period_;
  TimePoint next_;
  TimePoint cycle_start_{0};
  std::chrono::nanoseconds last_wakeup_{0};
  std::uint64_t cycles_{0};
  std::uint64_t overruns_{0};
  LatencyHistogram wakeup_{};
  LatencyHistogram compute_{};
};

}  // namespace teleop::rt
