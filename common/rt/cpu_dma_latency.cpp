#include "common/rt/cpu_dma_latency.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <cstring>

namespace teleop::rt {

CpuDmaLatency::CpuDmaLatency(int target_us) {
  const int fd = ::open("/dev/cpu_dma_latency", O_WRONLY | O_CLOEXEC);
  if (fd < 0) {
    const int e = errno;
    refusal_ = std::string("cpu_dma_latency: /dev/cpu_dma_latency: ") + std::strerror(e) +
               (e == EACCES || e == EPERM ? " (needs root or write permission on the device)" : "");
    return;
  }
  const std::int32_t value = target_us;
  if (::write(fd, &value, sizeof(value)) != static_cast<ssize_t>(sizeof(value))) {
    refusal_ = std::string("cpu_dma_latency: write: ") + std::strerror(errno);
    ::close(fd);
    return;
  }
  fd_ = fd;  // the request holds while the file is open
}

CpuDmaLatency::~CpuDmaLatency() {
  if (fd_ >= 0) ::close(fd_);
}

}  // namespace teleop::rt
