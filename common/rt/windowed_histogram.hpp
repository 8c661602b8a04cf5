// Quantiles of a duration over a sliding window, for the real-time loop: fixed storage (no
// allocation), no lock, no I/O, nothing that throws. The nodes use it for the link's round
// trip, which the supervisor's model takes: a cumulative histogram would let an hour of a
// short round trip hide a grown one for tens of seconds (1 % of an hour's samples is 36 s of
// them), and 2^(1/3)-wide bins would report it up to 26 % long.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>

#include "common/core/rt_safe.hpp"

namespace teleop::rt {

class WindowedHistogram {
 public:
  // Bins 2^(1/24) apart (a quantile is its bin's upper edge: at most 2.9 % long) from 1 us
  // (bin 0 holds everything up to it) to 2^20 us = 1.05 s (the last bin holds what is above).
  static constexpr int kBinsPerOctave = 24;
  static constexpr int kBins = 20 * kBinsPerOctave + 1;
  // The window: the last kSlots slots of `slot_ns` each, so between (kSlots - 1) and kSlots
  // slots long.
  static constexpr int kSlots = 10;

  explicit WindowedHistogram(std::int64_t slot_ns = 1'000'000'000) noexcept : slot_ns_(slot_ns) {}

  // Ends the slots older than the window at `now_ns` (a monotonic time); the first call starts
  // the first slot.
  TELEOP_RT void advance(std::int64_t now_ns) noexcept {
    if (slot_start_ns_ == kUnset) {
      slot_start_ns_ = now_ns;
      return;
    }
    if (now_ns - slot_start_ns_ >= static_cast<std::int64_t>(kSlots) * slot_ns_) {
      clear();
      slot_start_ns_ = now_ns;
      return;
    }
    while (now_ns - slot_start_ns_ >= slot_ns_) {
      current_ = (current_ + 1) % kSlots;
      auto& slot = slots_[static_cast<std::size_t>(current_)];
      for (std::size_t i = 0; i < slot.size(); ++i) total_[i] -= slot[i];
      count_ -= slot_counts_[static_cast<std::size_t>(current_)];
      slot.fill(0);
      slot_counts_[static_cast<std::size_t>(current_)] = 0;
      slot_start_ns_ += slot_ns_;
    }
  }

  // One value (ns; negative counts as 0) at `now_ns`.
  TELEOP_RT void add(std::int64_t now_ns, std::int64_t value_ns) noexcept {
    advance(now_ns);
    const std::size_t bin = static_cast<std::size_t>(bin_of(value_ns));
    ++slots_[static_cast<std::size_t>(current_)][bin];
    ++slot_counts_[static_cast<std::size_t>(current_)];
    ++total_[bin];
    ++count_;
  }

  [[nodiscard]] std::uint64_t count() const noexcept { return count_; }

  // The upper edge (ns) of the bin holding the q-quantile (nearest rank) of the window; 0 when
  // it is empty.
  [[nodiscard]] std::int64_t quantile(double q) const noexcept {
    if (count_ == 0) return 0;
    const auto rank = std::max<std::uint64_t>(
        1, static_cast<std::uint64_t>(
               std::ceil(std::clamp(q, 0.0, 1.0) * static_cast<double>(count_))));
    std::uint64_t seen = 0;
    for (int i = 0; i < kBins; ++i) {
      seen += total_[static_cast<std::size_t>(i)];
      if (seen >= rank) return upper_edge_ns(i);
    }
    return upper_edge_ns(kBins - 1);
  }

  // Bin i holds (edge(i - 1), edge(i)] with edge(i) = 1 us * 2^(i / 24).
  [[nodiscard]] static std::int64_t upper_edge_ns(int bin) noexcept {
    return std::llround(1000.0 * std::exp2(static_cast<double>(bin) / kBinsPerOctave));
  }
  TELEOP_RT [[nodiscard]] static int bin_of(std::int64_t value_ns) noexcept {
    const double us = static_cast<double>(std::max<std::int64_t>(value_ns, 0)) / 1000.0;
    if (!(us > 1.0)) return 0;
    int bin = static_cast<int>(std::ceil(kBinsPerOctave * std::log2(us) - 1e-9));
    bin = std::clamp(bin, 0, kBins - 1);
    // Rounding at an edge: keep value <= edge(bin) and value > edge(bin - 1).
    if (bin < kBins - 1 && value_ns > upper_edge_ns(bin)) ++bin;
    if (bin > 0 && value_ns <= upper_edge_ns(bin - 1)) --bin;
    return bin;
  }

 private:
  static constexpr std::int64_t kUnset = std::numeric_limits<std::int64_t>::min();

  void clear() noexcept {
    for (auto& slot : slots_) slot.fill(0);
    slot_counts_.fill(0);
    total_.fill(0);
    count_ = 0;
  }

  std::int64_t slot_ns_;
  std::int64_t slot_start_ns_{kUnset};
  int current_{0};
  std::array<std::array<std::uint32_t, kBins>, kSlots> slots_{};
  std::array<std::uint32_t, kSlots> slot_counts_{};
  std::array<std::uint64_t, kBins> total_{};
  std::uint64_t count_{0};
};

}  // namespace teleop::rt
