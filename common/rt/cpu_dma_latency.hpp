// A low CPU wake-up latency for as long as the node runs (issue 4 "Loop"): the kernel's PM QoS
// interface /dev/cpu_dma_latency keeps deep C-states off while the file stays open with a
// 32-bit target in microseconds written to it.
#pragma once

#include <optional>
#include <string>

namespace teleop::rt {

class CpuDmaLatency {
 public:
  // Requests `target_us` (>= 0); refusal() names why when the kernel or permissions refuse.
  explicit CpuDmaLatency(int target_us);
  ~CpuDmaLatency();
  CpuDmaLatency(const CpuDmaLatency&) = delete;
  CpuDmaLatency& operator=(const CpuDmaLatency&) = delete;

  [[nodiscard]] bool held() const noexcept { return fd_ >= 0; }
  [[nodiscard]] const std::optional<std::string>& refusal() const noexcept { return refusal_; }

 private:
  int fd_{-1};
  std::optional<std::string> refusal_{};
};

}  // namespace teleop::rt
