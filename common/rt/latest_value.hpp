// The newest value from one writer to one reader (the peer's latest state, the device's latest
// sample): a triple buffer, so neither side ever waits or sees a torn value.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <type_traits>

#include "common/core/rt_safe.hpp"

namespace teleop::rt {

template <typename T>
class LatestValue {
  static_assert(std::is_trivially_copyable_v<T>, "values cross threads by copy");

 public:
  // Writer side. RT-safe.
  TELEOP_RT void write(const T& value) noexcept {
    buffers_[write_index_] = value;
    // Publish the written buffer, take the one the reader is not holding.
    const std::uint8_t previous = middle_.exchange(static_cast<std::uint8_t>(write_index_ | kFresh),
                                                   std::memory_order_acq_rel);
    write_index_ = previous & kIndexMask;
  }

  // Reader side: true and the newest value when one arrived since the last read. RT-safe.
  TELEOP_RT [[nodiscard]] bool read(T& out) noexcept {
    if ((middle_.load(std::memory_order_relaxed) & kFresh) == 0) return false;
    const std::uint8_t previous = middle_.exchange(read_index_, std::memory_order_acq_rel);
    read_index_ = previous & kIndexMask;
    out = buffers_[read_index_];
    return true;
  }

 private:
  static constexpr std::uint8_t kFresh = 0x4;
  static constexpr std::uint8_t kIndexMask = 0x3;
  std::array<T, 3> buffers_{};
  std::uint8_t write_index_{0};                      // writer's private buffer
  std::uint8_t read_index_{1};                       // reader's private buffer
  alignas(64) std::atomic<std::uint8_t> middle_{2};  // the exchanged one, with a fresh bit
};

}  // namespace teleop::rt
