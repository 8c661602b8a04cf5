#include "common/rt/loop_timing.hpp"

#include <algorithm>
#include <cmath>

namespace teleop::rt {

std::chrono::nanoseconds LatencyHistogram::bin_upper_edge(int bin) noexcept {
  // Bin i holds (edge(i-1), edge(i)] with edge(i) = 1 us * 2^(i/3).
  const double us = std::exp2(static_cast<double>(bin) / 3.0);
  return std::chrono::nanoseconds(static_cast<std::int64_t>(std::llround(us * 1000.0)));
}

void LatencyHistogram::add(std::chrono::nanoseconds value) noexcept {
  const double us = static_cast<double>(std::max<std::int64_t>(value.count(), 0)) / 1000.0;
  int bin = 0;
  if (us > 1.0) bin = static_cast<int>(std::ceil(3.0 * std::log2(us) - 1e-9));
  bin = std::clamp(bin, 0, kBins - 1);
  ++bins_[static_cast<std::size_t>(bin)];
  ++count_;
  max_ = std::max(max_, value);
}

std::chrono::nanoseconds LatencyHistogram::quantile(double q) const noexcept {
  if (count_ == 0) return std::chrono::nanoseconds{0};
  const auto rank =
      static_cast<std::uint64_t>(std::ceil(std::clamp(q, 0.0, 1.0) * static_cast<double>(count_)));
  std::uint64_t seen = 0;
  for (int i = 0; i < kBins; ++i) {
    seen += bins_[static_cast<std::size_t>(i)];
    if (seen >= std::max<std::uint64_t>(rank, 1)) return bin_upper_edge(i);
  }
  return bin_upper_edge(kBins - 1);
}

LoopTiming::TimePoint LoopTiming::woke(TimePoint now) noexcept {
  const TimePoint deadline = next_;
  last_wakeup_ = now - deadline;
  wakeup_.add(last_wakeup_);
  cycle_start_ = now;
  ++cycles_;
  next_ = deadline + period_;
  if (now >= next_) {
    // Whole periods slept through: count them, and resume on the grid after now.
    const auto missed = (now - deadline) / period_;
    overruns_ += static_cast<std::uint64_t>(missed);
    next_ = deadline + (missed + 1) * period_;
  }
  return deadline;
}

void LoopTiming::finished(TimePoint now) noexcept {
  compute_.add(now - cycle_start_);
  if (now >= next_) {
    // The work itself ran past the next deadline: that cycle is lost too.
    const auto missed = (now - next_) / period_ + 1;
    overruns_ += static_cast<std::uint64_t>(missed);
    next_ += missed * period_;
  }
}

}  // namespace teleop::rt
