// The n-axis haptic device interface (issue 18, "Devices"; docs/plant-axes.md "The n-axis
// device"): HapticDevice (haptic_device.hpp) with task-space vectors of n = 1..6 entries in place
// of its scalars. Same lifecycle, same Status, same SampleFlags bits, same signs per axis: the
// master writes force_N = -F_am and reads the human's force F_h, the slave writes F_as and reads
// the force it puts on its environment F_e.
//
// Positions are task-space coordinates of the handle (m): a device with joint encoders reports
// the forward kinematics of its quantised joint angles. Forces are task-space (N) at the handle;
// a device with a linkage turns them into joint torques tau = J^T F itself.
#pragma once

#include <Eigen/Core>
#include <chrono>
#include <cstdint>

#include "common/core/rt_safe.hpp"
#include "common/core/teleop_axes.hpp"
#include "common/device/haptic_device.hpp"

namespace teleop::device {

// A task-space vector with at most kMaxAxes entries (fixed capacity: no allocation). The same
// type as control::AxisVector and sim::AxesVector.
using AxisVector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxAxes, 1>;

struct SampleAxes {
  std::uint64_t sequence{0};  // increments with every new sample
  double time_s{0.0};         // device time of the sample
  int axes{0};                // n: the size of position_m and force_N
  AxisVector position_m{};    // task space, as sensed (through the quantised joint encoders)
  AxisVector force_N{};       // load cell per task axis, compression positive
  std::uint32_t flags{0};     // SampleFlags bits (any axis)
};

struct CommandAxes {
  AxisVector force_N{};  // n entries: the actuator's task-space force on the device
};

class HapticDeviceAxes {
 public:
  virtual ~HapticDeviceAxes() = default;
  HapticDeviceAxes() = default;
  HapticDeviceAxes(const HapticDeviceAxes&) = delete;
  HapticDeviceAxes& operator=(const HapticDeviceAxes&) = delete;

  virtual Status configure() = 0;
  virtual Status activate() = 0;
  virtual Status deactivate() = 0;
  // n, the number of task-space axes (valid after construction).
  [[nodiscard]] virtual int axes() const noexcept = 0;
  // The latest sample. RT-safe.
  TELEOP_RT virtual Status read(SampleAxes& sample) noexcept = 0;
  // Held until the next write; command.force_N must have axes() entries. RT-safe.
  TELEOP_RT virtual Status write(const CommandAxes& command) noexcept = 0;
  // End of the node's cycle, after write() (HapticDevice::tick). RT-safe.
  TELEOP_RT virtual Status tick(std::chrono::nanoseconds /*period*/) noexcept {
    return Status::Ok();
  }
  // The node became engaged (HapticDevice::on_engaged). RT-safe.
  TELEOP_RT virtual void on_engaged() noexcept {}
  // The coupling ended (HapticDevice::on_disengaged). RT-safe.
  TELEOP_RT virtual void on_disengaged() noexcept {}
};

}  // namespace teleop::device
