// The n-axis USB haptic device (issue 18 "Devices"; docs/usb-protocol.md §12 and "The n-axis
// host"): HapticDeviceAxes over protocol version 2 with one channel per joint. The link
// (transport, I/O thread, handshake, sequences, report timeout, counters) is UsbHostLink, shared
// with the one-axis UsbDevice; this class maps joint encoder counts to task space through the
// device's kinematics and task-space forces to per-channel DAC values.
//
// Channels. Channel i carries joint i's encoder, the actuator of joint i and the load cell of
// task axis i (a handle-mounted cell measuring the task-space force, compression positive).
//
// Kinematics (as SimDeviceAxes):
//  - kCartesian: joint i is task axis i, a capstan: x_i = counts_i *
//  scaling.position_m_per_count().
//  - kFiveBar: channels 0 and 1 are the planar five-bar's actuated joints
//  (kinematics/five_bar.hpp).
//    The encoders count from the home pose: q_j = five_bar_home_joint_rad(j) + counts_j 2 pi /
//    (counts_per_rev transmission_ratio), and (x_0, x_1) = FK(q) - FK(home), so x = 0 at home.
//    Further channels are Cartesian. Angles at which the linkage does not assemble hold the last
//    reading and flag kFault.
//
// Forces. The actuators are driven as Vlachos-Papadopoulos eq. 7b, u = (K_T K_amp)^-1 J^T F,
// with u in DAC counts (K_amp the amplifier's current per count): joint efforts tau = J^T F
// (N m on a five-bar joint, J the linkage's Jacobian at the newest sample read; N on a Cartesian
// axis, J = I), then u_i = round(tau_i / (K_T,i K_amp,i)), clipped to +-32767 (the device then
// reports saturation).
// A command with a non-finite entry or the wrong number of entries is refused as a whole: 0 on
// every channel is sent in its place, kCommandRejected in the next sample (as SimDeviceAxes).
//
// Protocol. The host speaks version 2 with n = axes() channels. A device that answers only in
// version 1, or with another channel count, never gets a sample through: read() returns kFault
// with a message naming which, once report_timeout passed without an accepted report (see
// usb_host_link.hpp for why it waits).
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "common/core/rt_safe.hpp"
#include "common/device/haptic_device_axes.hpp"
#include "common/device/sim_device_axes.hpp"
#include "common/device/usb_host_link.hpp"
#include "common/device/usb_protocol.hpp"
#include "common/kinematics/five_bar.hpp"
#include "common/rt/latest_value.hpp"

namespace teleop::device {

// One channel's actuator: the DAC value is u = tau / (K_T K_amp).
struct UsbActuatorGains {
  // K_T: joint effort per amplifier current (N m/A on a five-bar joint, N/A on a Cartesian one).
  double torque_constant_per_A{0.0};
  // K_amp: amplifier current per DAC count (A per count).
  double amplifier_A_per_count{0.0};
};

struct UsbDeviceAxesConfig {
  // Ids, endpoints, watchdog, timeouts; scaling: every channel's encoder and load cell (and,
  // with no actuators given, its actuator).
  UsbDeviceConfig link{};
  int axes{1};  // n in [1, 6]: the device's channel count
  DeviceKinematics kinematics{DeviceKinematics::kCartesian};
  kinematics::FiveBarGeometry five_bar{};             // kFiveBar only
  Eigen::Vector2d five_bar_home_joint_rad{0.0, 0.0};  // kFiveBar: q at encoder count 0
  // n entries, or empty: K_T K_amp = link.scaling.actuator_N_per_count() on every channel (one
  // DAC step is version 1's force step).
  std::vector<UsbActuatorGains> actuators{};
};

class UsbDeviceAxes final : public HapticDeviceAxes, private UsbReportSink {
 public:
  using TransportFactory = UsbHostLink::TransportFactory;

  // The real device over libusb.
  explicit UsbDeviceAxes(UsbDeviceAxesConfig config);
  // Any transport (the tests: the emulator's in-memory link).
  UsbDeviceAxes(UsbDeviceAxesConfig config, TransportFactory open_transport);
  ~UsbDeviceAxes() override;

  // Validates (errors name the field: "usb device axes: ...") and opens the transport.
  Status configure() override;
  Status activate() override;
  // Sends 0 on every channel at once and stops the I/O thread.
  Status deactivate() override;
  [[nodiscard]] int axes() const noexcept override { return config_.axes; }
  // The newest sample (see above). kUnavailable before the first acknowledged report; kFault
  // with kFault set when the link is lost, or naming the protocol mismatch. RT-safe.
  TELEOP_RT Status read(SampleAxes& sample) noexcept override;
  // u = (K_T K_amp)^-1 J^T F per channel, for the I/O thread to send. RT-safe.
  TELEOP_RT Status write(const CommandAxes& command) noexcept override;

  [[nodiscard]] UsbLinkStats stats() const noexcept { return link_.stats(); }
  [[nodiscard]] const UsbDeviceAxesConfig& config() const noexcept { return config_; }

 private:
  // What crosses from the I/O thread to the RT thread (trivially copyable).
  struct Reading {
    std::uint64_t sequence{0};
    double time_s{0.0};
    std::uint32_t flags{0};
    std::array<double, usb::kMaxChannels> position_m{};
    std::array<double, usb::kMaxChannels> force_N{};
    std::array<double, 4> jacobian{};  // five-bar: dP/dq (m/rad), column-major
  };

  [[nodiscard]] std::string invalid_field() const;
  void on_report(std::uint64_t sample_number, const usb::ReportPacketV2& report) noexcept override;
  TELEOP_RT void fill(SampleAxes& sample) const noexcept;

  UsbDeviceAxesConfig config_;
  UsbHostLink link_;
  std::string error_{};
  bool five_bar_{false};
  Eigen::Vector2d home_end_m_{Eigen::Vector2d::Zero()};
  std::array<double, 4> home_jacobian_{};
  double radians_per_count_{0.0};
  // Per channel: link.scaling with the actuator's step K_T K_amp (force_to_dac rounds and clips).
  std::array<usb::Scaling, usb::kMaxChannels> actuator_scaling_{};

  rt::LatestValue<Reading> samples_{};
  Reading io_reading_{};  // I/O thread: the last published reading (held on a bad pose)

  // RT thread state.
  Reading latest_{};
  bool have_sample_{false};
  bool command_rejected_{false};
};

// The n-axis USB device over libusb, unconfigured (configure() opens it and, with none attached,
// returns kUnavailable naming the vendor and product ids). For the node (issue 18): its
// configuration's axes, kinematics (config::KinematicsConfig: kind, five_bar, home_joint_rad)
// and the device's UsbDeviceConfig fill a UsbDeviceAxesConfig.
[[nodiscard]] std::unique_ptr<HapticDeviceAxes> make_usb_device_axes(
    const UsbDeviceAxesConfig& config);

}  // namespace teleop::device
