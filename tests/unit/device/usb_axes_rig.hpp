// The n-axis USB host against the emulator through the in-memory link (shared by
// test_usb_device_axes.cpp and test_usb_device_axes_rt.cpp): the test is the RT loop and the
// emulator's clock; the host's I/O thread is real, so the tests wait on conditions with a
// generous deadline, never for time to pass.
#pragma once

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <numbers>
#include <thread>

#include "common/device/usb_device_axes.hpp"
#include "common/device/usb_emulator.hpp"

namespace teleop::device::test_axes {

namespace usb = teleop::device::usb;
using std::chrono::milliseconds;

template <typename Predicate>
bool eventually(Predicate done) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds{20};
  while (!done()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(std::chrono::microseconds{50});
  }
  return true;
}

// The paddle's encoder (500 counts per motor turn, 10:1): one count is 2 pi / 5000 rad of
// joint, 0.115 m of arc per radian on a Cartesian axis.
inline constexpr double kCount_rad = 2.0 * std::numbers::pi / 5000.0;
inline constexpr double kCount_m = kCount_rad * 0.115;
// The emulator's DAC step (its default scaling: 16.5 N at full scale).
inline constexpr double kDacStep_N = 16.5 / 32767.0;

// The seed's planar five-bar (as test_sim_device_axes): base 0.1 m, proximal links 0.1 m, distal
// 0.15 m; home at q = (120, 60) degrees, the symmetric pose with the end point above the base.
inline kinematics::FiveBarGeometry five_bar_geometry() {
  kinematics::FiveBarGeometry g;
  g.base_separation_m = 0.1;
  g.proximal_m[0] = g.proximal_m[1] = 0.1;
  g.distal_m[0] = g.distal_m[1] = 0.15;
  return g;
}
inline const Eigen::Vector2d kHome_rad{2.0 * std::numbers::pi / 3.0, std::numbers::pi / 3.0};

// Actuators: K_T K_amp = 0.05 N m/A * 1e-4 A/count = 5e-6 N m per count on the two joints,
// 2 N/A * 2.5e-4 A/count = 5e-4 N per count on the Cartesian axis 2.
inline constexpr double kJointStep_Nm = 0.05 * 1e-4;
inline constexpr double kAxisStep_N = 2.0 * 2.5e-4;

inline UsbDeviceAxesConfig five_bar_config() {
  UsbDeviceAxesConfig c;
  // A slow test machine must not read as a lost link; the link-loss tests set their own.
  c.link.report_timeout = milliseconds{60'000};
  c.axes = 3;
  c.kinematics = DeviceKinematics::kFiveBar;
  c.five_bar = five_bar_geometry();
  c.five_bar_home_joint_rad = kHome_rad;
  c.actuators = {{0.05, 1e-4}, {0.05, 1e-4}, {2.0, 2.5e-4}};
  return c;
}

inline usb::EmulatorConfig emulator_config(std::size_t channels) {
  usb::EmulatorConfig e;
  e.protocol_version = usb::kProtocolVersion2;
  e.channels = channels;
  return e;
}

struct AxesRig {
  explicit AxesRig(const usb::EmulatorConfig& emulator = emulator_config(3),
                   const UsbDeviceAxesConfig& device = five_bar_config())
      : emu(emulator, link.open_device()),
        dev(device, [this](const UsbDeviceConfig&) { return link.open_host(); }) {}

  // activate(), then the emulator takes the re-arming command and reports; the first sample
  // is the one acknowledging it.
  SampleAxes bring_up() {
    const Status configured = dev.configure();
    EXPECT_TRUE(configured.ok()) << configured.message;
    EXPECT_TRUE(dev.activate().ok());
    take_command();
    EXPECT_FALSE(emu.watchdog_tripped());
    emu.step(milliseconds{1});
    return next_sample(0);
  }

  void take_command() {
    const std::uint64_t before = emu.stats().commands_accepted;
    EXPECT_TRUE(eventually([&] {
      emu.process_commands();
      return emu.stats().commands_accepted > before;
    }));
  }

  SampleAxes next_sample(std::uint64_t after) {
    SampleAxes s;
    EXPECT_TRUE(eventually([&] { return dev.read(s).ok() && s.sequence > after; }))
        << "no sample after " << after;
    return s;
  }

  // One control period: write, the device takes the command, a tick, read.
  SampleAxes cycle(const AxisVector& force_N, std::uint64_t after) {
    CommandAxes c;
    c.force_N = force_N;
    EXPECT_TRUE(dev.write(c).ok());
    take_command();
    emu.step(milliseconds{1});
    return next_sample(after);
  }

  // Channel c's encoder count now (the emulator rounds its plant's position to counts).
  [[nodiscard]] long counts(std::size_t channel) const {
    return std::lround(emu.plant(channel).state().position_m / kCount_m);
  }

  usb::MemoryLink link;
  usb::Emulator emu;
  UsbDeviceAxes dev;
};

}  // namespace teleop::device::test_axes
