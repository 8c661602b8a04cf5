// The firmware emulator as the protocol specifies it (docs/usb-protocol.md §5-7), driven by the
// test as the host through the in-memory link with explicit time steps: the watchdog is counted
// in emulator periods, never waited for.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <vector>

#include "common/device/usb_emulator.hpp"
#include "common/device/usb_protocol.hpp"

namespace {

namespace usb = teleop::device::usb;
using std::chrono::milliseconds;
using usb::PacketError;
using usb::ReportFlags;

constexpr double kDacStep_N = 16.5 / 32767.0;  // default actuator full scale over the DAC

struct Bench {
  explicit Bench(const usb::EmulatorConfig& config = {}) : emu(config, link.open_device()) {}

  void send_bytes(std::span<const std::uint8_t> bytes) {
    ASSERT_TRUE(host->send(bytes, milliseconds{0}).ok());
  }
  void send(std::uint32_t sequence, bool enable, std::int16_t dac, std::uint16_t watchdog_ms = 20) {
    send_flags(sequence, enable ? usb::CommandFlags::kEnable : std::uint8_t{0}, dac, watchdog_ms);
  }
  void send_flags(std::uint32_t sequence, std::uint8_t flags, std::int16_t dac,
                  std::uint16_t watchdog_ms = 20) {
    usb::CommandPacket p;
    p.sequence = sequence;
    p.watchdog_ms = watchdog_ms;
    p.flags = flags;
    p.actuator_dac = dac;
    usb::CommandBytes bytes{};
    ASSERT_EQ(usb::encode(p, bytes), PacketError::kNone);
    send_bytes(bytes);
  }
  // Steps one period and returns the report it sent.
  usb::ReportPacket step(milliseconds period = milliseconds{1}) {
    emu.step(period);
    std::array<std::uint8_t, usb::kMaxPacketSize> buffer{};
    std::size_t n = 0;
    EXPECT_TRUE(host->receive(buffer, n, milliseconds{0}).ok());
    usb::ReportPacket r;
    EXPECT_EQ(usb::decode(std::span<const std::uint8_t>(buffer.data(), n), r), PacketError::kNone);
    return r;
  }

  usb::MemoryLink link;
  std::unique_ptr<usb::Transport> host{link.open_host()};
  usb::Emulator emu;
};

TEST(UsbEmulator, PowersUpTrippedAndArmsOnlyThroughADisabledCommand) {
  Bench b;
  EXPECT_TRUE(b.emu.watchdog_tripped());
  b.send(1, true, 1000);
  usb::ReportPacket r = b.step();
  EXPECT_EQ(r.sequence, 1U);
  EXPECT_EQ(r.device_time_us, 1000U);
  EXPECT_EQ(r.last_command_sequence, 1U);  // accepted, but it cannot drive
  EXPECT_NE(r.flags & ReportFlags::kWatchdogTripped, 0);
  EXPECT_EQ(r.actuator_dac, 0);
  EXPECT_EQ(b.emu.output_force_N(), 0.0);

  b.send(2, false, 0);
  r = b.step();
  EXPECT_EQ(r.flags & ReportFlags::kWatchdogTripped, 0);
  EXPECT_EQ(r.actuator_dac, 0);

  b.send(3, true, 1000);
  r = b.step();
  EXPECT_EQ(r.flags, 0);
  EXPECT_EQ(r.actuator_dac, 1000);
  EXPECT_DOUBLE_EQ(b.emu.output_force_N(), 1000.0 * kDacStep_N);
  EXPECT_EQ(b.emu.stats().commands_accepted, 3U);
}

// The last command arrives at t = 0; the device drives over [0, W) and is at 0 N from W on:
// exactly W one-millisecond periods with output, the W from the command's header.
class UsbEmulatorWatchdog : public testing::TestWithParam<int> {};

TEST_P(UsbEmulatorWatchdog, ZeroesOutputWhenCommandsStopForWatchdogMs) {
  const int watchdog_ms = GetParam();
  Bench b;
  b.send(1, false, 0, static_cast<std::uint16_t>(watchdog_ms));
  b.send(2, true, -500, static_cast<std::uint16_t>(watchdog_ms));
  int driven_periods = 0;
  for (int k = 0; k < watchdog_ms + 10; ++k) {
    const usb::ReportPacket r = b.step();
    const bool tripped = (r.flags & ReportFlags::kWatchdogTripped) != 0;
    // The report after the period starting at k ms.
    EXPECT_EQ(tripped, k >= watchdog_ms) << "period starting at " << k << " ms";
    EXPECT_EQ(r.actuator_dac, tripped ? 0 : -500) << "period starting at " << k << " ms";
    if (r.actuator_dac != 0) ++driven_periods;
  }
  EXPECT_EQ(driven_periods, watchdog_ms);
  EXPECT_TRUE(b.emu.watchdog_tripped());
  EXPECT_EQ(b.emu.output_force_N(), 0.0);
}

INSTANTIATE_TEST_SUITE_P(HeaderValues, UsbEmulatorWatchdog, testing::Values(1, 5, 20));

TEST(UsbEmulator, WatchdogIsFedByEachNewValidCommand) {
  Bench b;
  b.send(1, false, 0, 5);
  std::uint32_t seq = 2;
  // A command every 4 ms keeps a 5 ms watchdog from tripping.
  for (int k = 0; k < 40; ++k) {
    if (k % 4 == 0) b.send(seq++, true, 100, 5);
    const usb::ReportPacket r = b.step();
    EXPECT_EQ(r.flags & ReportFlags::kWatchdogTripped, 0) << k;
    EXPECT_EQ(r.actuator_dac, 100);
  }
  // Repeating the newest command is a duplicate: it does not feed the watchdog.
  const std::uint32_t newest = seq - 1;
  bool tripped = false;
  for (int k = 0; k < 10 && !tripped; ++k) {
    b.send(newest, true, 100, 5);
    tripped = (b.step().flags & ReportFlags::kWatchdogTripped) != 0;
  }
  EXPECT_TRUE(tripped);
  EXPECT_GE(b.emu.stats().rejected[PacketError::kDuplicate], 1U);
}

TEST(UsbEmulator, ResumesAfterATripOnlyThroughADisabledCommand) {
  Bench b;
  b.send(100, false, 0);
  b.send(101, true, 700);
  for (int k = 0; k < 25; ++k) (void)b.step();
  ASSERT_TRUE(b.emu.watchdog_tripped());

  // The host resumes mid-stream with kEnable: accepted, but the trip is latched.
  b.send(102, true, 700);
  usb::ReportPacket r = b.step();
  EXPECT_EQ(r.last_command_sequence, 102U);
  EXPECT_NE(r.flags & ReportFlags::kWatchdogTripped, 0);
  EXPECT_EQ(r.actuator_dac, 0);

  // A corrupted disabled command re-arms nothing.
  usb::CommandPacket p;
  p.sequence = 103;
  usb::CommandBytes bytes{};
  ASSERT_EQ(usb::encode(p, bytes), PacketError::kNone);
  bytes[12] ^= 0xFFU;
  b.send_bytes(bytes);
  r = b.step();
  EXPECT_NE(r.flags & ReportFlags::kWatchdogTripped, 0);
  EXPECT_EQ(b.emu.stats().rejected[PacketError::kBadCrc], 1U);

  b.send(103, false, 0);
  r = b.step();
  EXPECT_EQ(r.flags & ReportFlags::kWatchdogTripped, 0);
  EXPECT_EQ(r.actuator_dac, 0);
  b.send(104, true, 700);
  r = b.step();
  EXPECT_EQ(r.actuator_dac, 700);
  EXPECT_DOUBLE_EQ(b.emu.output_force_N(), 700.0 * kDacStep_N);
}

TEST(UsbEmulator, ResyncStartsANewHostSessionDisabled) {
  Bench b;
  b.send(5000, false, 0);
  b.send(5001, true, 700);
  EXPECT_EQ(b.step().actuator_dac, 700);
  // A restarted host counting from 1 is old news to the device...
  b.send(1, false, 0);
  usb::ReportPacket r = b.step();
  EXPECT_EQ(b.emu.stats().rejected[PacketError::kOutOfOrder], 1U);
  EXPECT_EQ(r.actuator_dac, 700);
  // ...until its first command says so: taken as is, and at 0 N.
  b.send_flags(1, usb::CommandFlags::kResync, 0);
  r = b.step();
  EXPECT_EQ(r.last_command_sequence, 1U);
  EXPECT_EQ(r.actuator_dac, 0);
  b.send(2, true, 700);
  EXPECT_EQ(b.step().actuator_dac, 700);
  // Resync is only valid disabled: a session never starts with force.
  usb::CommandPacket p;
  p.sequence = 1;
  p.flags = usb::CommandFlags::kResync;
  p.actuator_dac = 1000;
  usb::CommandBytes bytes{};
  ASSERT_EQ(usb::encode(p, bytes), PacketError::kNone);  // the encoder refuses kEnable with it
  std::vector<std::uint8_t> v(bytes.begin(), bytes.end() - 4);
  v[10] |= usb::CommandFlags::kEnable;
  const std::uint32_t crc = usb::crc32(v);
  for (unsigned i = 0; i < 4; ++i) v.push_back(static_cast<std::uint8_t>(crc >> (8U * i)));
  b.send_bytes(v);
  r = b.step();
  EXPECT_EQ(b.emu.stats().rejected[PacketError::kBadField], 1U);
  EXPECT_EQ(r.actuator_dac, 700);
  EXPECT_EQ(r.last_command_sequence, 2U);
}

TEST(UsbEmulator, RefusedCommandsAreCountedByReasonAndChangeNothing) {
  Bench b;
  b.send(10, false, 0);
  b.send(11, true, 300);
  EXPECT_EQ(b.step().actuator_dac, 300);

  usb::CommandPacket p;
  p.sequence = 12;
  p.flags = usb::CommandFlags::kEnable;
  p.actuator_dac = -9000;
  usb::CommandBytes good{};
  ASSERT_EQ(usb::encode(p, good), PacketError::kNone);
  const auto with_crc = [](std::vector<std::uint8_t> v) {
    v.resize(v.size() - 4);
    const std::uint32_t crc = usb::crc32(v);
    for (unsigned i = 0; i < 4; ++i) v.push_back(static_cast<std::uint8_t>(crc >> (8U * i)));
    return v;
  };
  std::vector<std::uint8_t> v(good.begin(), good.end());
  std::vector<std::vector<std::uint8_t>> bad;
  bad.push_back(v);
  bad.back()[5] ^= 0x10U;  // CRC
  bad.push_back(v);
  bad.back()[1] = 0x00;  // magic
  bad.push_back(v);
  bad.back()[2] = 0x02;  // version
  bad.push_back(v);
  bad.back()[3] = 0x02;                      // type: a report
  bad.emplace_back(v.begin(), v.end() - 1);  // truncated
  bad.push_back(v);
  bad.back().push_back(0);  // oversized
  bad.push_back(v);
  bad.back()[8] = 0;  // watchdog 0 ms
  bad.back() = with_crc(bad.back());
  for (const auto& bytes : bad) b.send_bytes(bytes);
  b.send(11, true, -9000);  // duplicate
  b.send(9, true, -9000);   // out of order
  const usb::ReportPacket r = b.step();
  EXPECT_EQ(r.actuator_dac, 300);  // still the last accepted command
  EXPECT_EQ(r.last_command_sequence, 11U);
  EXPECT_EQ(r.commands_rejected, 9U);
  const usb::PacketCounters& c = b.emu.stats().rejected;
  for (const PacketError e :
       {PacketError::kBadCrc, PacketError::kBadMagic, PacketError::kBadVersion,
        PacketError::kBadType, PacketError::kTruncated, PacketError::kOversized,
        PacketError::kBadField, PacketError::kDuplicate, PacketError::kOutOfOrder}) {
    EXPECT_EQ(c[e], 1U) << usb::to_string(e);
  }
  EXPECT_EQ(c.total_rejected(), 9U);

  // Refused commands do not feed the watchdog: a stream of them lets it trip at 20 ms.
  int driven = 2;  // the periods starting at 0 and 1 ms above
  for (int k = 1; k < 30; ++k) {
    b.send_bytes(bad[0]);
    if (b.step().actuator_dac != 0) ++driven;
  }
  EXPECT_EQ(driven, 20);
}

TEST(UsbEmulator, SequenceGapsAreCountedAsLost) {
  Bench b;
  b.send(1, false, 0);
  b.send(2, true, 1);
  b.send(6, true, 2);
  b.send(7, true, 3);
  EXPECT_EQ(b.step().actuator_dac, 3);
  EXPECT_EQ(b.emu.stats().commands_accepted, 4U);
  EXPECT_EQ(b.emu.stats().commands_lost, 3U);
}

TEST(UsbEmulator, DeadmanEstopAndFaultZeroTheOutputWhileActive) {
  Bench b;
  b.send(1, false, 0);
  std::uint32_t seq = 2;
  const auto cycle = [&] {
    b.send(seq++, true, 4000);
    return b.step();
  };
  EXPECT_EQ(cycle().actuator_dac, 4000);
  b.emu.set_deadman_pressed(false);
  usb::ReportPacket r = cycle();
  EXPECT_EQ(r.flags, ReportFlags::kDeadmanReleased);
  EXPECT_EQ(r.actuator_dac, 0);
  EXPECT_EQ(b.emu.output_force_N(), 0.0);
  b.emu.set_deadman_pressed(true);
  EXPECT_EQ(cycle().actuator_dac, 4000);
  b.emu.set_estop_pressed(true);
  r = cycle();
  EXPECT_EQ(r.flags, ReportFlags::kEstopPressed);
  EXPECT_EQ(r.actuator_dac, 0);
  b.emu.set_estop_pressed(false);
  b.emu.set_fault(true);
  r = cycle();
  EXPECT_EQ(r.flags, ReportFlags::kFault);
  EXPECT_EQ(r.actuator_dac, 0);
  b.emu.set_fault(false);
  r = cycle();
  EXPECT_EQ(r.flags, 0);
  EXPECT_EQ(r.actuator_dac, 4000);
}

TEST(UsbEmulator, SaturationAtTheDacRailAndTheAmplifierLimit) {
  usb::EmulatorConfig config;
  config.amplifier_limit_N = 5.0;
  Bench b(config);
  b.send(1, false, 0);
  b.send(2, true, 32767);
  usb::ReportPacket r = b.step();
  EXPECT_EQ(r.flags, ReportFlags::kAmplifierSaturated);
  EXPECT_DOUBLE_EQ(b.emu.output_force_N(), 5.0);
  // 8 N asks 15887 counts; the amplifier gives 5 N.
  b.send(3, true, 15887);
  r = b.step();
  EXPECT_EQ(r.flags, ReportFlags::kAmplifierSaturated);
  EXPECT_EQ(r.actuator_dac, 15887);
  EXPECT_DOUBLE_EQ(b.emu.output_force_N(), 5.0);
  b.send(4, true, -4000);  // -2.01 N: within the limit
  r = b.step();
  EXPECT_EQ(r.flags, 0);
  EXPECT_DOUBLE_EQ(b.emu.output_force_N(), -4000.0 * kDacStep_N);
}

TEST(UsbEmulator, EncoderCountsAndLoadCellAreThePlantQuantised) {
  usb::EmulatorConfig config;
  config.initial_position_m = 0.004;
  // Tissue at 0 with 500 N/m: F_e = 500 x + 5 x' on the load cell.
  config.plant.environment = teleop::sim::Environment::tissue(500.0, 5.0, 0.0);
  Bench b(config);
  // The paddle: 500 counts per motor turn, 10:1, 0.115 m of arc per paddle radian.
  const double q_m = 2.0 * std::numbers::pi * 0.115 / (500.0 * 10.0);
  const double cell_N_per_count = 10.0 / 32767.0;
  b.send(1, false, 0);
  std::uint32_t seq = 2;
  for (int k = 0; k < 15; ++k) {
    b.send(seq++, true, 2000);
    const usb::ReportPacket r = b.step();
    const double x = b.emu.plant().state().position_m;
    const double f = b.emu.plant().output().environment_force_N;
    EXPECT_EQ(r.encoder_counts, std::llround(x / q_m)) << k;
    EXPECT_EQ(r.load_cell_adc, std::llround(f / cell_N_per_count)) << k;
    EXPECT_GT(r.load_cell_adc, 0);
    EXPECT_EQ(r.flags, 0);
  }
  // Pushed 30 mm into 500 N/m: 15 N, beyond the 10 N cell.
  config.initial_position_m = 0.03;
  Bench deep(config);
  deep.send(1, false, 0);
  const usb::ReportPacket r = deep.step();
  EXPECT_EQ(r.load_cell_adc, 32767);
  EXPECT_EQ(r.flags, ReportFlags::kLoadCellClipped);
}

TEST(UsbEmulator, RejectsABadConfigurationNamingTheField) {
  usb::MemoryLink link;
  usb::EmulatorConfig config;
  config.scaling.transmission_ratio = 0.0;
  try {
    usb::Emulator emu(config, link.open_device());
    FAIL() << "accepted transmission_ratio 0";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("scaling.transmission_ratio"), std::string::npos);
  }
  EXPECT_THROW(usb::Emulator(usb::EmulatorConfig{}, nullptr), std::invalid_argument);
}

}  // namespace
