// UsbDevice, the host side: over the emulator through the in-memory link (its I/O thread is
// real, so the tests wait on conditions - a counter, a sample - with a generous deadline, never
// for time to pass), against hand-made reports for the receive rules, and over libusb on a
// machine with no USB bus for the "no device attached" error.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "common/device/haptic_device.hpp"
#include "common/device/sim_device.hpp"
#include "common/device/usb_device.hpp"
#include "common/device/usb_emulator.hpp"
#include "common/device/usb_protocol.hpp"

namespace {

namespace usb = teleop::device::usb;
using std::chrono::milliseconds;
using teleop::device::Command;
using teleop::device::DeviceKind;
using teleop::device::make_device;
using teleop::device::MakeDeviceResult;
using teleop::device::Sample;
using teleop::device::SampleFlags;
using teleop::device::SimDeviceConfig;
using teleop::device::Status;
using teleop::device::StatusCode;
using teleop::device::UsbDevice;
using teleop::device::UsbDeviceConfig;

// The paddle's encoder: 500 counts per motor turn, 10:1, 0.115 m of arc per paddle radian.
const double kCount_m = 2.0 * std::numbers::pi * 0.115 / (500.0 * 10.0);
constexpr double kDacStep_N = 16.5 / 32767.0;

template <typename Predicate>
bool eventually(Predicate done) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds{20};
  while (!done()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(std::chrono::microseconds{50});
  }
  return true;
}

UsbDeviceConfig test_config() {
  UsbDeviceConfig c;
  // A slow test machine must not read as a lost link; the link-loss test sets its own.
  c.report_timeout = milliseconds{60'000};
  return c;
}

// UsbDevice <-> in-memory link <-> emulator; the test is the RT loop and the emulator's clock.
struct Rig {
  explicit Rig(const usb::EmulatorConfig& emulator_config = {},
               const UsbDeviceConfig& device_config = test_config())
      : emu(emulator_config, link.open_device()),
        dev(device_config, [this](const UsbDeviceConfig&) { return link.open_host(); }) {}

  // activate(), then the emulator takes the re-arming command and reports; the first sample
  // is the one acknowledging it.
  Sample bring_up() {
    EXPECT_TRUE(dev.configure().ok());
    EXPECT_TRUE(dev.activate().ok());
    const std::uint64_t before = emu.stats().commands_accepted;
    EXPECT_TRUE(eventually([&] {
      emu.process_commands();
      return emu.stats().commands_accepted > before;
    }));
    EXPECT_FALSE(emu.watchdog_tripped());
    emu.step(milliseconds{1});
    return next_sample(0);
  }

  Sample next_sample(std::uint64_t after) {
    Sample s;
    EXPECT_TRUE(eventually([&] { return dev.read(s).ok() && s.sequence > after; }))
        << "no sample after " << after;
    return s;
  }

  // One control period as a node runs it: write, the device takes the command, a tick, read.
  Sample cycle(double force_N, std::uint64_t after) {
    const std::uint64_t before = emu.stats().commands_accepted;
    EXPECT_TRUE(dev.write(Command{force_N}).ok());
    EXPECT_TRUE(eventually([&] {
      emu.process_commands();
      return emu.stats().commands_accepted > before;
    }));
    emu.step(milliseconds{1});
    return next_sample(after);
  }

  usb::MemoryLink link;
  usb::Emulator emu;
  UsbDevice dev;
};

TEST(UsbDevice, NoDeviceAttachedNamesTheExpectedIds) {
  // No USB bus on these machines: libusb finds nothing (or cannot start) either way.
  MakeDeviceResult made = make_device(DeviceKind::kUsb, SimDeviceConfig{}, UsbDeviceConfig{});
  ASSERT_TRUE(made.status.ok());
  ASSERT_NE(made.device, nullptr);
  ASSERT_NE(dynamic_cast<UsbDevice*>(made.device.get()), nullptr);
  const Status s = made.device->configure();
  EXPECT_EQ(s.code, StatusCode::kUnavailable);
  const std::string message = s.message;
  EXPECT_EQ(
      message.rfind("no USB haptic device attached: expected vendor 0x1209 product 0x7E1E (", 0),
      0U)
      << message;
  EXPECT_NE(message.find("check the cable and udev permissions)"), std::string::npos) << message;
  EXPECT_EQ(made.device->activate().code, StatusCode::kNotConfigured);
  Sample sample;
  EXPECT_EQ(made.device->read(sample).code, StatusCode::kNotActive);
  EXPECT_EQ(made.device->write(Command{1.0}).code, StatusCode::kNotActive);

  UsbDeviceConfig other;
  other.vendor_id = 0x1234;
  other.product_id = 0x00AB;
  UsbDevice dev(other);
  const Status t = dev.configure();
  EXPECT_EQ(t.code, StatusCode::kUnavailable);
  EXPECT_EQ(std::string(t.message).rfind(
                "no USB haptic device attached: expected vendor 0x1234 product 0x00AB (", 0),
            0U)
      << t.message;
}

TEST(UsbDevice, MakeDeviceKeepsTheSimOverloads) {
  MakeDeviceResult sim = make_device(DeviceKind::kSim);
  ASSERT_TRUE(sim.status.ok());
  EXPECT_NE(dynamic_cast<teleop::device::SimDevice*>(sim.device.get()), nullptr);
  MakeDeviceResult usb_default = make_device(DeviceKind::kUsb, SimDeviceConfig{});
  ASSERT_TRUE(usb_default.status.ok());
  const auto* dev = dynamic_cast<UsbDevice*>(usb_default.device.get());
  ASSERT_NE(dev, nullptr);
  EXPECT_EQ(dev->config().vendor_id, 0x1209);
  EXPECT_EQ(dev->config().product_id, 0x7E1E);
  EXPECT_EQ(dev->config().watchdog, milliseconds{20});
}

TEST(UsbDevice, ConfigureNamesTheBadField) {
  const auto configure_with = [](UsbDeviceConfig c) {
    UsbDevice dev(c, [](const UsbDeviceConfig&) -> std::unique_ptr<usb::Transport> {
      throw std::logic_error("must not open with a bad configuration");
    });
    const Status s = dev.configure();
    EXPECT_EQ(s.code, StatusCode::kInvalidArgument);
    return std::string(s.message);
  };
  UsbDeviceConfig c;
  c.scaling.counts_per_rev = 0;
  EXPECT_EQ(configure_with(c), "usb device: scaling.counts_per_rev must be positive");
  c = UsbDeviceConfig{};
  c.scaling.load_cell_full_scale_N = -1.0;
  EXPECT_NE(configure_with(c).find("scaling.load_cell_full_scale_N"), std::string::npos);
  c = UsbDeviceConfig{};
  c.watchdog = milliseconds{0};
  EXPECT_EQ(configure_with(c), "usb device: watchdog must be in [1, 1000] ms");
  c.watchdog = milliseconds{1001};
  EXPECT_EQ(configure_with(c), "usb device: watchdog must be in [1, 1000] ms");
  c = UsbDeviceConfig{};
  c.endpoint_in = 0x01;
  EXPECT_NE(configure_with(c).find("endpoint_in"), std::string::npos);

  // A transport that cannot open: its message is the status message.
  UsbDevice failing(UsbDeviceConfig{},
                    [](const UsbDeviceConfig&) -> std::unique_ptr<usb::Transport> {
                      throw std::runtime_error("bus on fire");
                    });
  const Status s = failing.configure();
  EXPECT_EQ(s.code, StatusCode::kUnavailable);
  EXPECT_STREQ(s.message, "bus on fire");
}

TEST(UsbDevice, PositionsReadBackAsThePlantQuantisedToCounts) {
  usb::EmulatorConfig config;
  config.initial_position_m = 0.01234;
  Rig rig(config);
  Sample s = rig.bring_up();
  EXPECT_EQ(s.sequence, 1U);
  EXPECT_DOUBLE_EQ(s.time_s, 1e-3);
  // 0.01234 m is 85.39 counts: 85 counts.
  EXPECT_DOUBLE_EQ(s.position_m, 85.0 * kCount_m);
  EXPECT_EQ(s.flags, 0U);

  for (int k = 0; k < 30; ++k) {
    const double force_N = k < 15 ? 2.0 : -2.0;
    s = rig.cycle(force_N, s.sequence);
    const double x = rig.emu.plant().state().position_m;
    EXPECT_DOUBLE_EQ(s.position_m, static_cast<double>(std::llround(x / kCount_m)) * kCount_m) << k;
    EXPECT_NEAR(s.time_s, 1e-3 * (k + 2), 1e-12);
    EXPECT_EQ(s.sequence, static_cast<std::uint64_t>(k + 2));
    EXPECT_EQ(s.flags, 0U) << k;
  }
  // It moved: 2 N on 0.036 kg for 15 ms, then -2 N for 15 ms, is about 10 mm (70 counts).
  EXPECT_GT(std::abs(s.position_m - 85.0 * kCount_m), 50.0 * kCount_m);
  const UsbDevice::LinkStats stats = rig.dev.stats();
  EXPECT_EQ(stats.reports_accepted, 31U);
  EXPECT_EQ(stats.reports_lost, 0U);
  EXPECT_EQ(stats.rejected.total_rejected(), 0U);
  EXPECT_EQ(stats.commands_sent, 31U);  // the re-arming command and 30 writes
}

TEST(UsbDevice, CommandsArriveAsActuatorForceWithinOneDacStep) {
  Rig rig;
  Sample s = rig.bring_up();
  for (const double force_N : {1.0, -3.3, 0.0001, 7.77, -16.4}) {
    s = rig.cycle(force_N, s.sequence);
    EXPECT_LE(std::abs(rig.emu.output_force_N() - force_N), 0.5 * kDacStep_N) << force_N;
    EXPECT_EQ(s.flags, 0U);
  }
  // Beyond full scale: clipped to the rail, which the device reports as saturation.
  s = rig.cycle(40.0, s.sequence);
  EXPECT_DOUBLE_EQ(rig.emu.output_force_N(), 16.5);
  EXPECT_EQ(s.flags, SampleFlags::kAmplifierSaturated);
  s = rig.cycle(-16.5, s.sequence);
  EXPECT_DOUBLE_EQ(rig.emu.output_force_N(), -16.5);
  EXPECT_EQ(s.flags, SampleFlags::kAmplifierSaturated);
  // The watchdog the device applies is the configured one.
  ASSERT_TRUE(rig.emu.command().has_value());
  EXPECT_EQ(rig.emu.command()->watchdog_ms, 20);
}

TEST(UsbDevice, LoadCellReadsBackInNewtons) {
  usb::EmulatorConfig config;
  config.plant.environment = teleop::sim::Environment::rigid_wall(0.0);
  Rig rig(config);
  Sample s = rig.bring_up();
  // Pushing 3 N into a wall at rest: the cell reads the push, to one ADC count (10 N / 32767).
  for (int k = 0; k < 5; ++k) s = rig.cycle(3.0, s.sequence);
  const double pushed_N = std::round(3.0 / kDacStep_N) * kDacStep_N;
  EXPECT_NEAR(s.force_N, pushed_N, 0.5 * 10.0 / 32767.0);
  EXPECT_EQ(s.flags, 0U);
}

TEST(UsbDevice, DeadmanAndEstopReadAsFault) {
  Rig rig;
  Sample s = rig.bring_up();
  s = rig.cycle(1.0, s.sequence);
  EXPECT_EQ(s.flags & SampleFlags::kFault, 0U);
  rig.emu.set_deadman_pressed(false);
  s = rig.cycle(1.0, s.sequence);
  EXPECT_NE(s.flags & SampleFlags::kFault, 0U);
  EXPECT_EQ(rig.emu.output_force_N(), 0.0);
  Sample again;
  EXPECT_TRUE(rig.dev.read(again).ok());  // a fault is data, the read itself succeeded
  EXPECT_NE(again.flags & SampleFlags::kFault, 0U);
  rig.emu.set_deadman_pressed(true);
  s = rig.cycle(1.0, s.sequence);
  EXPECT_EQ(s.flags & SampleFlags::kFault, 0U);
  rig.emu.set_estop_pressed(true);
  s = rig.cycle(1.0, s.sequence);
  EXPECT_NE(s.flags & SampleFlags::kFault, 0U);
  EXPECT_EQ(rig.emu.output_force_N(), 0.0);
}

TEST(UsbDevice, StalledWritesTripTheDeviceWatchdogUntilReactivated) {
  Rig rig;
  Sample s = rig.bring_up();
  s = rig.cycle(2.0, s.sequence);
  // The RT loop stalls: no writes, so nothing is sent (the I/O thread never repeats a command).
  for (int k = 0; k < 25; ++k) {
    rig.emu.step(milliseconds{1});
    s = rig.next_sample(s.sequence);
  }
  EXPECT_TRUE(rig.emu.watchdog_tripped());
  EXPECT_NE(s.flags & SampleFlags::kFault, 0U);
  // Writing again does not bring the force back: the trip is latched.
  s = rig.cycle(2.0, s.sequence);
  EXPECT_NE(s.flags & SampleFlags::kFault, 0U);
  EXPECT_EQ(rig.emu.output_force_N(), 0.0);
  // deactivate() leaves the device disabled at once; activate() re-arms it.
  EXPECT_TRUE(rig.dev.deactivate().ok());
  rig.emu.process_commands();
  ASSERT_TRUE(rig.emu.command().has_value());
  EXPECT_EQ(rig.emu.command()->flags, 0);
  EXPECT_FALSE(rig.emu.watchdog_tripped());
  s = rig.bring_up();
  EXPECT_EQ(s.sequence, 1U);
  s = rig.cycle(2.0, s.sequence);
  EXPECT_EQ(s.flags & SampleFlags::kFault, 0U);
  EXPECT_LE(std::abs(rig.emu.output_force_N() - 2.0), 0.5 * kDacStep_N);
}

TEST(UsbDevice, NonFiniteWriteIsRefusedAndFlagged) {
  Rig rig;
  Sample s = rig.bring_up();
  s = rig.cycle(1.0, s.sequence);
  const std::uint64_t before = rig.emu.stats().commands_accepted;
  EXPECT_EQ(rig.dev.write(Command{std::numeric_limits<double>::quiet_NaN()}).code,
            StatusCode::kInvalidArgument);
  EXPECT_EQ(rig.dev.write(Command{-std::numeric_limits<double>::infinity()}).code,
            StatusCode::kInvalidArgument);
  ASSERT_TRUE(eventually([&] {
    rig.emu.process_commands();
    return rig.emu.stats().commands_accepted > before;
  }));
  rig.emu.step(milliseconds{1});
  s = rig.next_sample(s.sequence);
  EXPECT_NE(s.flags & SampleFlags::kCommandRejected, 0U);
  EXPECT_EQ(rig.emu.output_force_N(), 0.0);  // 0 N went out in its place
  EXPECT_EQ(rig.dev.stats().commands_non_finite, 2U);
  s = rig.cycle(1.0, s.sequence);
  EXPECT_EQ(s.flags & SampleFlags::kCommandRejected, 0U);
}

// The test is the device: hand-made reports for the host's receive rules.
struct RawRig {
  explicit RawRig(const UsbDeviceConfig& config = test_config())
      : device_end(link.open_device()),
        dev(config, [this](const UsbDeviceConfig&) { return link.open_host(); }) {
    EXPECT_TRUE(dev.configure().ok());
    EXPECT_TRUE(dev.activate().ok());
    // The session start: disabled with kResync, the sequence the reports must acknowledge.
    std::array<std::uint8_t, usb::kMaxPacketSize> buffer{};
    std::size_t n = 0;
    EXPECT_TRUE(eventually([&] { return device_end->receive(buffer, n, milliseconds{1}).ok(); }));
    usb::CommandPacket c;
    EXPECT_EQ(usb::decode(std::span<const std::uint8_t>(buffer.data(), n), c),
              usb::PacketError::kNone);
    EXPECT_EQ(c.flags, usb::CommandFlags::kResync);
    EXPECT_EQ(c.watchdog_ms, 20);
    first_command = c.sequence;
  }

  usb::ReportBytes report(std::uint32_t sequence, std::int32_t counts,
                          std::uint32_t acknowledged) const {
    usb::ReportPacket r;
    r.sequence = sequence;
    r.device_time_us = 1000U * sequence;
    r.encoder_counts = counts;
    r.last_command_sequence = acknowledged;
    usb::ReportBytes bytes{};
    EXPECT_EQ(usb::encode(r, bytes), usb::PacketError::kNone);
    return bytes;
  }
  void send(std::span<const std::uint8_t> bytes) {
    ASSERT_TRUE(device_end->send(bytes, milliseconds{1000}).ok());
  }
  // Everything sent so far has been received and judged.
  void settle(std::uint64_t packets) {
    ASSERT_TRUE(eventually([&] {
      const UsbDevice::LinkStats s = dev.stats();
      return s.reports_accepted + s.reports_unacknowledged + s.rejected.total_rejected() >= packets;
    }));
  }

  usb::MemoryLink link;
  std::unique_ptr<usb::Transport> device_end;
  UsbDevice dev;
  std::uint32_t first_command{0};
};

TEST(UsbDevice, NoSamplesBeforeAReportAcknowledgesThisActivation) {
  RawRig rig;
  Sample s;
  EXPECT_EQ(rig.dev.read(s).code, StatusCode::kUnavailable);
  // Echoing a command this activation never sent (a previous run's).
  rig.send(rig.report(1, 5, rig.first_command - 1));
  rig.send(rig.report(2, 5, rig.first_command + 1));
  rig.settle(2);
  EXPECT_EQ(rig.dev.stats().reports_unacknowledged, 2U);
  EXPECT_EQ(rig.dev.read(s).code, StatusCode::kUnavailable);
  rig.send(rig.report(3, 5, rig.first_command));
  ASSERT_TRUE(eventually([&] { return rig.dev.read(s).ok(); }));
  EXPECT_EQ(s.sequence, 1U);
  EXPECT_DOUBLE_EQ(s.position_m, 5.0 * kCount_m);
  EXPECT_DOUBLE_EQ(s.time_s, 3e-3);
}

TEST(UsbDevice, GapsCountedAsLostDuplicatesAndReorderedDropped) {
  RawRig rig;
  const std::uint32_t ack = rig.first_command;
  rig.send(rig.report(10, 100, ack));
  rig.send(rig.report(11, 110, ack));
  rig.send(rig.report(11, 999, ack));  // duplicate
  rig.send(rig.report(9, 999, ack));   // out of order
  rig.send(rig.report(15, 150, ack));  // 12, 13, 14 lost
  rig.settle(5);
  const UsbDevice::LinkStats stats = rig.dev.stats();
  EXPECT_EQ(stats.reports_accepted, 3U);
  EXPECT_EQ(stats.reports_lost, 3U);
  EXPECT_EQ(stats.rejected[usb::PacketError::kDuplicate], 1U);
  EXPECT_EQ(stats.rejected[usb::PacketError::kOutOfOrder], 1U);
  Sample s;
  ASSERT_TRUE(rig.dev.read(s).ok());
  EXPECT_EQ(s.sequence, 3U);  // one per accepted report
  EXPECT_DOUBLE_EQ(s.position_m, 150.0 * kCount_m);
  EXPECT_DOUBLE_EQ(s.time_s, 15e-3);
}

TEST(UsbDevice, MalformedReportsAreCountedByReason) {
  RawRig rig;
  const usb::ReportBytes good = rig.report(1, 7, rig.first_command);
  std::vector<std::vector<std::uint8_t>> bad(8,
                                             std::vector<std::uint8_t>(good.begin(), good.end()));
  bad[0][17] ^= 0x04U;                  // CRC
  bad[1][0] = 0x00;                     // magic
  bad[2][2] = 0x07;                     // version
  bad[3][3] = 0x01;                     // type: a command
  bad[4].resize(usb::kReportSize - 1);  // truncated
  bad[5].push_back(0x00);               // oversized
  bad[6].resize(200, 0x00);             // larger than any USB packet: overflows the buffer
  bad[7][25] = 0x80;                    // unknown flag bit...
  bad[7].resize(usb::kReportSize - 4);  // ...with a valid CRC
  const std::uint32_t crc = usb::crc32(bad[7]);
  for (unsigned i = 0; i < 4; ++i) bad[7].push_back(static_cast<std::uint8_t>(crc >> (8U * i)));
  for (const auto& b : bad) rig.send(b);
  rig.send(good);
  rig.settle(9);
  const UsbDevice::LinkStats stats = rig.dev.stats();
  EXPECT_EQ(stats.rejected[usb::PacketError::kBadCrc], 1U);
  EXPECT_EQ(stats.rejected[usb::PacketError::kBadMagic], 1U);
  EXPECT_EQ(stats.rejected[usb::PacketError::kBadVersion], 1U);
  EXPECT_EQ(stats.rejected[usb::PacketError::kBadType], 1U);
  EXPECT_EQ(stats.rejected[usb::PacketError::kTruncated], 1U);
  EXPECT_EQ(stats.rejected[usb::PacketError::kOversized], 2U);
  EXPECT_EQ(stats.rejected[usb::PacketError::kBadField], 1U);
  EXPECT_EQ(stats.rejected.total_rejected(), 8U);
  EXPECT_EQ(stats.reports_accepted, 1U);
  Sample s;
  ASSERT_TRUE(rig.dev.read(s).ok());
  EXPECT_EQ(s.sequence, 1U);
  EXPECT_DOUBLE_EQ(s.position_m, 7.0 * kCount_m);
}

TEST(UsbDevice, DeviceFlagsMapToSampleFlags) {
  RawRig rig;
  const std::uint32_t ack = rig.first_command;
  const auto flags_of = [&](std::uint32_t seq, std::uint16_t device_flags) {
    usb::ReportPacket r;
    r.sequence = seq;
    r.flags = device_flags;
    r.last_command_sequence = ack;
    usb::ReportBytes bytes{};
    EXPECT_EQ(usb::encode(r, bytes), usb::PacketError::kNone);
    rig.send(bytes);
    Sample s;
    EXPECT_TRUE(eventually([&] { return rig.dev.read(s).ok() && s.sequence == seq; }));
    return s.flags;
  };
  using F = usb::ReportFlags;
  EXPECT_EQ(flags_of(1, 0), 0U);
  EXPECT_EQ(flags_of(2, F::kDeadmanReleased), SampleFlags::kFault);
  EXPECT_EQ(flags_of(3, F::kEstopPressed), SampleFlags::kFault);
  EXPECT_EQ(flags_of(4, F::kWatchdogTripped), SampleFlags::kFault);
  EXPECT_EQ(flags_of(5, F::kFault), SampleFlags::kFault);
  EXPECT_EQ(flags_of(6, F::kAmplifierSaturated), SampleFlags::kAmplifierSaturated);
  EXPECT_EQ(flags_of(7, F::kLoadCellClipped), SampleFlags::kLoadCellClipped);
  EXPECT_EQ(flags_of(8, F::kKnown),
            SampleFlags::kFault | SampleFlags::kAmplifierSaturated | SampleFlags::kLoadCellClipped);
}

TEST(UsbDevice, SilentDeviceReadsAsLinkLost) {
  UsbDeviceConfig config = test_config();
  config.report_timeout = milliseconds{5};
  Rig rig({}, config);
  Sample s = rig.bring_up();
  // The device stops reporting: read() turns to kFault by itself (the I/O thread's clock).
  Status status;
  ASSERT_TRUE(eventually([&] {
    status = rig.dev.read(s);
    return status.code == StatusCode::kFault;
  }));
  EXPECT_NE(s.flags & SampleFlags::kFault, 0U);
  EXPECT_EQ(s.sequence, 1U);  // still the old sample
  // Reports again: a fresh sample, and the link is back.
  rig.emu.step(milliseconds{1});
  EXPECT_TRUE(eventually([&] { return rig.dev.read(s).ok() && s.sequence == 2; }));
  EXPECT_EQ(s.flags & SampleFlags::kFault, 0U);
}

}  // namespace
