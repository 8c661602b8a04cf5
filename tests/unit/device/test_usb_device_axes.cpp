// UsbDeviceAxes, the n-axis USB host (protocol version 2), against the emulator: positions
// against the test's own forward kinematics of the emulator's joints, commands against a
// Jacobian derived by hand (and by finite differences of the test's kinematics), the one-axis
// host at n = 1, the refusal of a version-1 device and of another channel count, and the one-axis
// host's fault paths (silence, a stalled RT loop, malformed reports).
#include <gtest/gtest.h>

#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "common/device/usb_device.hpp"
#include "common/device/usb_device_axes.hpp"
#include "common/device/usb_emulator.hpp"
#include "common/device/usb_protocol.hpp"
#include "tests/unit/device/usb_axes_rig.hpp"

namespace teleop::device {
namespace {

using namespace test_axes;  // NOLINT(google-build-using-namespace): the rig's helpers

// The end point of the five-bar at joint angles q, written from the geometry alone: the elbows
// B_i = A_i + a (cos q_i, sin q_i) with A = (-+s/2, 0); P on the circles of radius b about both,
// on the left of B1 -> B2: P = B1 + l u + h u_perp, u = (B2 - B1)/d, l = (b1^2 - b2^2 + d^2)/2d
// (d/2 here), h = sqrt(b1^2 - l^2), u_perp = (-u_y, u_x).
Eigen::Vector2d end_point(const Eigen::Vector2d& q) {
  const double s = 0.1;
  const double a = 0.1;
  const double b = 0.15;
  const Eigen::Vector2d b1(-s / 2 + a * std::cos(q(0)), a * std::sin(q(0)));
  const Eigen::Vector2d b2(s / 2 + a * std::cos(q(1)), a * std::sin(q(1)));
  const double d = (b2 - b1).norm();
  const Eigen::Vector2d u = (b2 - b1) / d;
  const double l = d / 2;  // b1 = b2
  const double h = std::sqrt(b * b - l * l);
  return b1 + l * u + h * Eigen::Vector2d(-u(1), u(0));
}

// dP/dq by central differences of end_point.
Eigen::Matrix2d jacobian_fd(const Eigen::Vector2d& q) {
  constexpr double kStep = 1e-6;
  Eigen::Matrix2d j;
  for (int i = 0; i < 2; ++i) {
    const Eigen::Vector2d dq = kStep * Eigen::Vector2d::Unit(i);
    j.col(i) = (end_point(q + dq) - end_point(q - dq)) / (2 * kStep);
  }
  return j;
}

AxisVector vec3(double a, double b, double c) {
  AxisVector v(3);
  v << a, b, c;
  return v;
}

TEST(UsbDeviceAxes, FiveBarPositionsAreTheKinematicsOfTheEmulatorsJoints) {
  AxesRig rig;
  SampleAxes s = rig.bring_up();
  ASSERT_EQ(s.axes, 3);
  // At home every encoder reads 0: the task origin.
  EXPECT_EQ(s.position_m, AxisVector::Zero(3));
  EXPECT_EQ(s.flags, 0U);
  // Push the joints apart (the human on the emulator's handles), commanding nothing.
  rig.emu.set_external_force_N(0, 0.3);
  rig.emu.set_external_force_N(1, -0.2);
  rig.emu.set_external_force_N(2, 0.1);
  const Eigen::Vector2d home_end = end_point(kHome_rad);
  for (int k = 0; k < 40; ++k) {
    s = rig.cycle(AxisVector::Zero(3), s.sequence);
    const Eigen::Vector2d q =
        kHome_rad + kCount_rad * Eigen::Vector2d(static_cast<double>(rig.counts(0)),
                                                 static_cast<double>(rig.counts(1)));
    const Eigen::Vector2d x = end_point(q) - home_end;
    EXPECT_NEAR(s.position_m(0), x(0), 1e-12) << k;
    EXPECT_NEAR(s.position_m(1), x(1), 1e-12) << k;
    EXPECT_NEAR(s.position_m(2), static_cast<double>(rig.counts(2)) * kCount_m, 1e-15) << k;
    EXPECT_EQ(s.flags, 0U) << k;
  }
  // The joints moved many counts (0.3 N on 0.036 kg for 40 ms is about 6 mm, 40 counts).
  EXPECT_GT(rig.counts(0), 20);
  EXPECT_LT(rig.counts(1), -12);
  EXPECT_GT(rig.counts(2), 6);
  EXPECT_GT(std::abs(s.position_m(0)), 1e-3);
}

TEST(UsbDeviceAxes, TaskForceArrivesAsJTransposeFOverTheActuatorGains) {
  AxesRig rig;
  SampleAxes s = rig.bring_up();
  // At home (q = 120, 60 degrees) by hand: P - B1 = (0.1, h), P - B2 = (-0.1, h) with
  // h = sqrt(0.15^2 - 0.1^2); differentiating |P - B_i|^2 = b^2 gives (P - B_i) . dP =
  // (P - B_i) . a (-sin q_i, cos q_i) dq_i = -+e dq_i, e = 0.1 (0.1 sin 60 + h cos 60), so
  // J = [[0.1, h], [-0.1, h]]^-1 diag(-e, e) = [[-5 e, -5 e], [-e / 2h, e / 2h]].
  const double h = std::sqrt(0.15 * 0.15 - 0.1 * 0.1);
  const double e = 0.1 * (0.1 * std::sqrt(3.0) / 2.0 + h * 0.5);
  const double fx = 1.0;
  const double fy = -0.5;
  const double fz = 0.8;
  const double tau0 = -5.0 * e * fx - e / (2.0 * h) * fy;  // -0.0394 N m
  const double tau1 = -5.0 * e * fx + e / (2.0 * h) * fy;  // -0.1031 N m
  s = rig.cycle(vec3(fx, fy, fz), s.sequence);
  // The DAC values arriving: u = tau / (K_T K_amp), rounded (the emulator drives dac * 16.5/32767).
  const std::array<double, 3> u{tau0 / kJointStep_Nm, tau1 / kJointStep_Nm, fz / kAxisStep_N};
  for (std::size_t c = 0; c < 3; ++c) {
    EXPECT_NEAR(rig.emu.output_force_N(c), std::round(u[c]) * kDacStep_N, 1e-12) << c;
  }
  EXPECT_NEAR(rig.emu.output_force_N(2) / kDacStep_N, 1600.0, 1e-9);
  EXPECT_EQ(s.flags, 0U);

  // Away from home: J at the newest sample's joint angles (finite differences).
  rig.emu.set_external_force_N(0, -0.4);
  rig.emu.set_external_force_N(1, -0.3);
  for (int k = 0; k < 30; ++k) s = rig.cycle(AxisVector::Zero(3), s.sequence);
  const Eigen::Vector2d q =
      kHome_rad + kCount_rad * Eigen::Vector2d(static_cast<double>(rig.counts(0)),
                                               static_cast<double>(rig.counts(1)));
  ASSERT_GT(std::abs(q(0) - kHome_rad(0)), 0.02);
  const Eigen::Vector2d tau = jacobian_fd(q).transpose() * Eigen::Vector2d(fx, fy);
  rig.cycle(vec3(fx, fy, fz), s.sequence);
  EXPECT_LE(std::abs(rig.emu.output_force_N(0) / kDacStep_N - tau(0) / kJointStep_Nm), 0.5 + 1e-3);
  EXPECT_LE(std::abs(rig.emu.output_force_N(1) / kDacStep_N - tau(1) / kJointStep_Nm), 0.5 + 1e-3);
  // The pose changed the command (else this part could not fail).
  EXPECT_GT(std::abs(tau(0) / kJointStep_Nm - u[0]), 5.0);
}

TEST(UsbDeviceAxes, SaturatedAndRefusedCommands) {
  AxesRig rig;
  SampleAxes s = rig.bring_up();
  // 20 N on the Cartesian axis is 40000 counts: the rail, reported as saturation.
  s = rig.cycle(vec3(0.0, 0.0, 20.0), s.sequence);
  EXPECT_DOUBLE_EQ(rig.emu.output_force_N(2), 16.5);
  EXPECT_EQ(s.flags, SampleFlags::kAmplifierSaturated);
  // A NaN on one axis, or the wrong number of axes: 0 on every channel, flagged.
  s = rig.cycle(vec3(0.0, 0.0, 1.0), s.sequence);
  ASSERT_NE(rig.emu.output_force_N(2), 0.0);
  CommandAxes bad;
  bad.force_N = vec3(0.1, std::numeric_limits<double>::quiet_NaN(), 1.0);
  EXPECT_EQ(rig.dev.write(bad).code, StatusCode::kInvalidArgument);
  rig.take_command();
  rig.emu.step(milliseconds{1});
  s = rig.next_sample(s.sequence);
  EXPECT_NE(s.flags & SampleFlags::kCommandRejected, 0U);
  for (std::size_t c = 0; c < 3; ++c) EXPECT_EQ(rig.emu.output_force_N(c), 0.0) << c;
  s = rig.cycle(vec3(0.0, 0.0, 1.0), s.sequence);
  EXPECT_EQ(s.flags & SampleFlags::kCommandRejected, 0U);
  bad.force_N = AxisVector::Ones(2);
  EXPECT_EQ(rig.dev.write(bad).code, StatusCode::kInvalidArgument);
  rig.take_command();
  rig.emu.step(milliseconds{1});
  s = rig.next_sample(s.sequence);
  EXPECT_NE(s.flags & SampleFlags::kCommandRejected, 0U);
  EXPECT_EQ(rig.emu.output_force_N(2), 0.0);
  const UsbLinkStats stats = rig.dev.stats();
  EXPECT_EQ(stats.commands_non_finite, 1U);
  EXPECT_EQ(stats.commands_wrong_axes, 1U);
}

TEST(UsbDeviceAxes, LoadCellsReadPerAxisInNewtons) {
  AxesRig rig;
  SampleAxes s = rig.bring_up();
  // The emulator's cells read the environment force (free space: 0) - the slave's convention.
  for (int k = 0; k < 3; ++k) s = rig.cycle(vec3(0.5, 0.5, 0.5), s.sequence);
  EXPECT_EQ(s.force_N, AxisVector::Zero(3));
  usb::EmulatorConfig walls = emulator_config(3);
  walls.plant.environment = teleop::sim::Environment::rigid_wall(0.0);
  AxesRig pushed(walls);
  s = pushed.bring_up();
  // Pushing each channel into its wall: its cell reads its DAC's force, to one ADC count.
  for (int k = 0; k < 5; ++k) s = pushed.cycle(vec3(0.0, 0.0, 3.0), s.sequence);
  EXPECT_NEAR(s.force_N(2), std::round(3.0 / kAxisStep_N) * kDacStep_N, 0.5 * 10.0 / 32767.0);
}

// n = 1, Cartesian, default actuators: the v2 host on a v2 device is the v1 host on a v1 device.
TEST(UsbDeviceAxes, OneAxisIsTheOneAxisHostExactly) {
  usb::EmulatorConfig e1;
  e1.initial_position_m = 0.01234;
  e1.plant.environment = teleop::sim::Environment::rigid_wall(0.015);
  usb::EmulatorConfig e2 = e1;
  e2.protocol_version = usb::kProtocolVersion2;
  UsbDeviceAxesConfig c;
  c.link.report_timeout = milliseconds{60'000};
  AxesRig axes(e2, c);
  usb::MemoryLink link1;
  usb::Emulator emu1(e1, link1.open_device());
  UsbDeviceConfig c1;
  c1.report_timeout = milliseconds{60'000};
  UsbDevice one(c1, [&](const UsbDeviceConfig&) { return link1.open_host(); });
  ASSERT_TRUE(one.configure().ok());
  ASSERT_TRUE(one.activate().ok());
  // The one-axis host's period: the device takes what was written, a tick, a new sample.
  const auto one_tick = [&](std::uint64_t after) {
    const std::uint64_t before = emu1.stats().commands_accepted;
    EXPECT_TRUE(eventually([&] {
      emu1.process_commands();
      return emu1.stats().commands_accepted > before;
    }));
    emu1.step(milliseconds{1});
    Sample s;
    EXPECT_TRUE(eventually([&] { return one.read(s).ok() && s.sequence > after; }));
    return s;
  };
  Sample s1 = one_tick(0);
  SampleAxes s2 = axes.bring_up();
  for (int k = 0; k < 60; ++k) {
    ASSERT_EQ(s2.sequence, s1.sequence);
    EXPECT_EQ(s2.time_s, s1.time_s) << k;
    EXPECT_EQ(s2.position_m(0), s1.position_m) << k;
    EXPECT_EQ(s2.force_N(0), s1.force_N) << k;
    EXPECT_EQ(s2.flags, s1.flags) << k;
    const double force_N = k < 20 ? 3.0 : (k < 40 ? -1.7 : 12.0);
    EXPECT_TRUE(one.write(Command{force_N}).ok());
    s1 = one_tick(s1.sequence);
    s2 = axes.cycle(AxisVector::Constant(1, force_N), s2.sequence);
    EXPECT_EQ(axes.emu.output_force_N(0), emu1.output_force_N()) << k;
  }
  // It touched the wall and saturated: the comparison covered the load cell and the flags.
  EXPECT_GT(s1.force_N, 1.0);
  EXPECT_EQ(axes.emu.report_version(), usb::kProtocolVersion2);
  EXPECT_EQ(emu1.report_version(), usb::kProtocolVersion);
}

// Steps the emulator (it keeps reporting) until read() turns to kFault; the status.
Status fault_while_reporting(AxesRig& rig, SampleAxes& s) {
  Status status;
  EXPECT_TRUE(eventually([&] {
    rig.emu.process_commands();
    rig.emu.step(milliseconds{1});
    status = rig.dev.read(s);
    return status.code == StatusCode::kFault;
  }));
  return status;
}

UsbDeviceAxesConfig cartesian(int n, milliseconds report_timeout) {
  UsbDeviceAxesConfig c;
  c.axes = n;
  c.link.report_timeout = report_timeout;
  return c;
}

TEST(UsbDeviceAxes, VersionOneDeviceIsRefusedNamingTheVersion) {
  usb::EmulatorConfig v1;  // protocol_version 1: the firmware before version 2
  AxesRig rig(v1, cartesian(3, milliseconds{20}));
  ASSERT_TRUE(rig.dev.configure().ok());
  ASSERT_TRUE(rig.dev.activate().ok());
  SampleAxes s;
  const Status status = fault_while_reporting(rig, s);
  EXPECT_NE(std::string(status.message).find("protocol version 1 only"), std::string::npos)
      << status.message;
  EXPECT_NE(std::string(status.message).find("version 2 with 3 channels"), std::string::npos)
      << status.message;
  EXPECT_NE(s.flags & SampleFlags::kFault, 0U);
  EXPECT_EQ(s.axes, 3);
  // The device refused every command (nothing drives it), the host every report.
  EXPECT_EQ(rig.emu.stats().commands_accepted, 0U);
  EXPECT_GT(rig.emu.stats().rejected[usb::PacketError::kBadVersion], 0U);
  EXPECT_EQ(rig.emu.output_force_N(), 0.0);
  EXPECT_GT(rig.dev.stats().rejected[usb::PacketError::kBadVersion], 0U);
  EXPECT_EQ(rig.dev.stats().reports_accepted, 0U);
}

TEST(UsbDeviceAxes, OtherChannelCountIsRefusedNamingIt) {
  AxesRig rig(emulator_config(2), cartesian(3, milliseconds{20}));
  ASSERT_TRUE(rig.dev.configure().ok());
  ASSERT_TRUE(rig.dev.activate().ok());
  SampleAxes s;
  const Status status = fault_while_reporting(rig, s);
  EXPECT_NE(std::string(status.message).find("the device has 2 channels, the configuration 3 axes"),
            std::string::npos)
      << status.message;
  EXPECT_EQ(rig.emu.stats().commands_accepted, 0U);
  EXPECT_GT(rig.emu.stats().rejected[usb::PacketError::kChannelMismatch], 0U);
  EXPECT_GT(rig.dev.stats().rejected[usb::PacketError::kChannelMismatch], 0U);
  EXPECT_EQ(rig.dev.stats().reports_accepted, 0U);
}

TEST(UsbDeviceAxes, SilentDeviceReadsAsLinkLost) {
  UsbDeviceAxesConfig c = five_bar_config();
  c.link.report_timeout = milliseconds{50};  // short, yet longer than a loaded machine's stall
  AxesRig rig(emulator_config(3), c);
  SampleAxes s = rig.bring_up();
  s = rig.cycle(vec3(0.2, 0.1, 0.3), s.sequence);
  ASSERT_NE(rig.emu.output_force_N(2), 0.0);
  // The device stops reporting: read() turns to kFault by itself, naming the lost link.
  Status status;
  ASSERT_TRUE(eventually([&] {
    status = rig.dev.read(s);
    return status.code == StatusCode::kFault;
  }));
  EXPECT_NE(std::string(status.message).find("link lost"), std::string::npos) << status.message;
  EXPECT_NE(s.flags & SampleFlags::kFault, 0U);
  EXPECT_EQ(s.sequence, 2U);
  // The device's side of the same silence: nothing new arrives, its watchdog zeroes every channel.
  for (int k = 0; k < 25; ++k) rig.emu.step(milliseconds{1});
  EXPECT_TRUE(rig.emu.watchdog_tripped());
  for (std::size_t c3 = 0; c3 < 3; ++c3) EXPECT_EQ(rig.emu.output_force_N(c3), 0.0) << c3;
}

TEST(UsbDeviceAxes, StalledWritesTripTheDeviceWatchdogOnEveryChannel) {
  AxesRig rig;
  SampleAxes s = rig.bring_up();
  s = rig.cycle(vec3(0.2, -0.1, 1.0), s.sequence);
  for (std::size_t c = 0; c < 3; ++c) ASSERT_NE(rig.emu.output_force_N(c), 0.0) << c;
  for (int k = 0; k < 25; ++k) {
    rig.emu.step(milliseconds{1});
    s = rig.next_sample(s.sequence);
  }
  EXPECT_TRUE(rig.emu.watchdog_tripped());
  EXPECT_NE(s.flags & SampleFlags::kFault, 0U);
  for (std::size_t c = 0; c < 3; ++c) EXPECT_EQ(rig.emu.output_force_N(c), 0.0) << c;
  // Latched until reactivated; deactivate() sends 0 on every channel at once.
  s = rig.cycle(vec3(0.2, -0.1, 1.0), s.sequence);
  EXPECT_NE(s.flags & SampleFlags::kFault, 0U);
  EXPECT_TRUE(rig.dev.deactivate().ok());
  rig.emu.process_commands();
  EXPECT_FALSE(rig.emu.watchdog_tripped());
  s = rig.bring_up();
  EXPECT_EQ(s.sequence, 1U);
  s = rig.cycle(vec3(0.2, -0.1, 1.0), s.sequence);
  EXPECT_EQ(s.flags & SampleFlags::kFault, 0U);
  EXPECT_NEAR(rig.emu.output_force_N(2), std::round(1.0 / kAxisStep_N) * kDacStep_N, 1e-12);
}

// The test is the device: hand-made version-2 reports.
TEST(UsbDeviceAxes, MalformedReportsAreCountedAndOnlyMalformedReportsLoseTheLink) {
  usb::MemoryLink link;
  std::unique_ptr<usb::Transport> device_end = link.open_device();
  UsbDeviceAxesConfig config = cartesian(3, milliseconds{60'000});
  UsbDeviceAxes dev(config, [&](const UsbDeviceConfig&) { return link.open_host(); });
  ASSERT_TRUE(dev.configure().ok());
  ASSERT_TRUE(dev.activate().ok());
  usb::PacketBuffer buffer{};
  std::size_t size = 0;
  ASSERT_TRUE(eventually([&] { return device_end->receive(buffer, size, milliseconds{1}).ok(); }));
  usb::CommandPacketV2 start;
  ASSERT_EQ(usb::decode_v2(std::span<const std::uint8_t>(buffer.data(), size), start),
            usb::PacketError::kNone);
  EXPECT_EQ(start.flags, usb::CommandFlags::kResync);
  EXPECT_EQ(start.channels, 3);
  const auto report = [&](std::uint32_t sequence, std::uint8_t channels) {
    usb::ReportPacketV2 r;
    r.sequence = sequence;
    r.device_time_us = 1000U * sequence;
    r.channels = channels;
    r.last_command_sequence = start.sequence;
    r.encoder_counts = {7, -8, 9, 0, 0, 0};
    usb::PacketBuffer out{};
    std::size_t n = 0;
    EXPECT_EQ(usb::encode(r, out, n), usb::PacketError::kNone);
    return std::vector<std::uint8_t>(out.begin(), out.begin() + static_cast<std::ptrdiff_t>(n));
  };
  const std::vector<std::uint8_t> good = report(1, 3);
  std::vector<std::vector<std::uint8_t>> bad(5, good);
  bad[0][20] ^= 0x04U;    // CRC
  bad[1][4] = 7;          // channel count out of range
  bad[2].pop_back();      // truncated
  bad[3] = report(2, 2);  // a whole report of 2 channels
  bad[4][2] = 1;          // version 1 (not a valid v1 report: no mismatch)
  for (const auto& b : bad) ASSERT_TRUE(device_end->send(b, milliseconds{1000}).ok());
  ASSERT_TRUE(device_end->send(good, milliseconds{1000}).ok());
  SampleAxes s;
  ASSERT_TRUE(eventually([&] { return dev.read(s).ok(); }));
  EXPECT_EQ(s.sequence, 1U);
  EXPECT_NEAR(s.position_m(1), -8.0 * kCount_m, 1e-15);
  const UsbLinkStats stats = dev.stats();
  EXPECT_EQ(stats.rejected[usb::PacketError::kBadCrc], 1U);
  EXPECT_EQ(stats.rejected[usb::PacketError::kBadChannels], 1U);
  EXPECT_EQ(stats.rejected[usb::PacketError::kTruncated], 1U);
  EXPECT_EQ(stats.rejected[usb::PacketError::kChannelMismatch], 1U);
  EXPECT_EQ(stats.rejected[usb::PacketError::kBadVersion], 1U);
  EXPECT_EQ(stats.reports_accepted, 1U);
}

TEST(UsbDeviceAxes, ACorruptedStreamReadsAsLinkLostNotAsAMismatch) {
  usb::MemoryLink link;
  std::unique_ptr<usb::Transport> device_end = link.open_device();
  UsbDeviceAxes dev(cartesian(2, milliseconds{50}),
                    [&](const UsbDeviceConfig&) { return link.open_host(); });
  ASSERT_TRUE(dev.configure().ok());
  ASSERT_TRUE(dev.activate().ok());
  usb::PacketBuffer buffer{};
  std::size_t size = 0;
  ASSERT_TRUE(eventually([&] { return device_end->receive(buffer, size, milliseconds{1}).ok(); }));
  usb::CommandPacketV2 start;
  ASSERT_EQ(usb::decode_v2(std::span<const std::uint8_t>(buffer.data(), size), start),
            usb::PacketError::kNone);
  usb::ReportPacketV2 r;
  r.channels = 2;
  r.last_command_sequence = start.sequence;
  std::uint32_t sequence = 1;
  const auto send = [&](bool corrupt) {
    r.sequence = sequence++;
    usb::PacketBuffer out{};
    std::size_t n = 0;
    EXPECT_EQ(usb::encode(r, out, n), usb::PacketError::kNone);
    if (corrupt) out[n - 1] ^= 0x01U;
    EXPECT_TRUE(
        device_end->send(std::span<const std::uint8_t>(out.data(), n), milliseconds{100}).ok());
  };
  send(false);
  SampleAxes s;
  ASSERT_TRUE(eventually([&] { return dev.read(s).ok(); }));
  // From now on every report is corrupted: the host drops them and the link is lost.
  Status status;
  ASSERT_TRUE(eventually([&] {
    send(true);
    status = dev.read(s);
    return status.code == StatusCode::kFault;
  }));
  EXPECT_NE(std::string(status.message).find("link lost"), std::string::npos) << status.message;
  EXPECT_NE(s.flags & SampleFlags::kFault, 0U);
  EXPECT_EQ(s.sequence, 1U);
  EXPECT_GT(dev.stats().rejected[usb::PacketError::kBadCrc], 0U);
}

TEST(UsbDeviceAxes, ConfigureNamesTheBadField) {
  const auto configure_with = [](const UsbDeviceAxesConfig& c) {
    UsbDeviceAxes dev(c, [](const UsbDeviceConfig&) -> std::unique_ptr<usb::Transport> {
      throw std::logic_error("must not open with a bad configuration");
    });
    const Status s = dev.configure();
    EXPECT_EQ(s.code, StatusCode::kInvalidArgument);
    return std::string(s.message);
  };
  UsbDeviceAxesConfig c = five_bar_config();
  c.axes = 7;
  EXPECT_EQ(configure_with(c), "usb device axes: axes must be in [1, 6]");
  c = five_bar_config();
  c.actuators.pop_back();
  EXPECT_NE(configure_with(c).find("actuators must be empty or have one entry per axis"),
            std::string::npos);
  c = five_bar_config();
  c.actuators[1].amplifier_A_per_count = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(configure_with(c),
            "usb device axes: actuators[1].amplifier_A_per_count must be positive and finite");
  c = five_bar_config();
  c.axes = 1;
  c.actuators.clear();
  EXPECT_NE(configure_with(c).find("five_bar needs at least 2 axes"), std::string::npos);
  c = five_bar_config();
  c.five_bar_home_joint_rad(1) = std::numeric_limits<double>::infinity();
  EXPECT_EQ(configure_with(c),
            "usb device axes: five_bar_home_joint_rad: the linkage does not assemble there");
  c = five_bar_config();
  c.five_bar.distal_m[0] = -0.15;
  EXPECT_NE(configure_with(c).find("usb device axes: five_bar: "), std::string::npos);
  c = five_bar_config();
  c.link.watchdog = milliseconds{0};
  EXPECT_EQ(configure_with(c), "usb device axes: watchdog must be in [1, 1000] ms");
}

TEST(UsbDeviceAxes, FactoryOpensLibusbAndNamesTheExpectedIds) {
  // No USB bus on these machines: libusb finds nothing (or cannot start) either way.
  UsbDeviceAxesConfig c = five_bar_config();
  std::unique_ptr<HapticDeviceAxes> dev = make_usb_device_axes(c);
  ASSERT_NE(dev, nullptr);
  EXPECT_EQ(dev->axes(), 3);
  const Status s = dev->configure();
  EXPECT_EQ(s.code, StatusCode::kUnavailable);
  EXPECT_EQ(std::string(s.message).rfind(
                "no USB haptic device attached: expected vendor 0x1209 product 0x7E1E (", 0),
            0U)
      << s.message;
  SampleAxes sample;
  EXPECT_EQ(dev->read(sample).code, StatusCode::kNotActive);
  EXPECT_EQ(dev->activate().code, StatusCode::kNotConfigured);
}

}  // namespace
}  // namespace teleop::device
