// The device emulator speaking protocol version 2 (docs/usb-protocol.md "Version 2: n
// channels"): a host built from the codec alone drives it in-process at n = 3 (positions
// against the closed-form response of a mass-damper, values through the raw scaling within one
// LSB), a v1 host still gets v1, n = 1 over v2 is v1's device exactly, and refusals.
#include <gtest/gtest.h>

#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <memory>
#include <numbers>
#include <stdexcept>
#include <string>
#include <vector>

#include "common/device/usb_emulator.hpp"
#include "common/device/usb_protocol.hpp"

namespace {

namespace usb = teleop::device::usb;
using std::chrono::milliseconds;
using usb::PacketError;

constexpr double kMass_kg = 0.036;  // EmulatorConfig's default plant
constexpr double kDamping_Ns_per_m = 0.49;

// A host of either version on one end of a MemoryLink, the emulator on the other.
struct Host {
  explicit Host(const usb::EmulatorConfig& config)
      : emu(config, link.open_device()), end(link.open_host()) {}

  void send_v2(std::uint32_t seq, std::uint8_t flags, std::span<const double> forces_N) {
    usb::CommandPacketV2 c;
    c.sequence = seq;
    c.flags = flags;
    ASSERT_EQ(usb::forces_to_dacs(forces_N, usb::Scaling{}, c).error, PacketError::kNone);
    usb::PacketBuffer buffer{};
    std::size_t size = 0;
    ASSERT_EQ(usb::encode(c, buffer, size), PacketError::kNone);
    ASSERT_TRUE(
        end->send(std::span<const std::uint8_t>(buffer.data(), size), milliseconds{0}).ok());
  }
  void send_v1(std::uint32_t seq, std::uint8_t flags, std::int16_t dac) {
    usb::CommandPacket c;
    c.sequence = seq;
    c.flags = flags;
    c.actuator_dac = dac;
    usb::CommandBytes bytes{};
    ASSERT_EQ(usb::encode(c, bytes), PacketError::kNone);
    ASSERT_TRUE(end->send(bytes, milliseconds{0}).ok());
  }
  // One firmware period; the report it sent, as raw bytes.
  std::vector<std::uint8_t> step() {
    emu.step(milliseconds{1});
    usb::PacketBuffer buffer{};
    std::size_t n = 0;
    if (!end->receive(buffer, n, milliseconds{0}).ok()) return {};
    return {buffer.begin(), buffer.begin() + static_cast<std::ptrdiff_t>(n)};
  }

  usb::MemoryLink link;
  usb::Emulator emu;
  std::unique_ptr<usb::Transport> end;
};

usb::EmulatorConfig config_v2(std::size_t channels) {
  usb::EmulatorConfig c;
  c.protocol_version = usb::kProtocolVersion2;
  c.channels = channels;
  // Tissue from 0 m (k = 300 N/m): a channel pushed to +x loads its load cell, one pulled to -x
  // stays in free space.
  c.plant.environment = teleop::sim::Environment::tissue(300.0, 0.0, 0.0);
  return c;
}

// x(T) of a mass-damper from rest under a constant force F: F/b (T - m/b (1 - exp(-b T / m))).
double free_response_m(double force_N, double t_s) {
  const double tau = kMass_kg / kDamping_Ns_per_m;
  return force_N / kDamping_Ns_per_m * (t_s - tau * (1.0 - std::exp(-t_s / tau)));
}

TEST(UsbEmulatorV2, HostCodecDrivesThreeChannelsInProcess) {
  Host h(config_v2(3));
  const usb::Scaling s{};
  const double dac_lsb_N = 16.5 / 32767.0;
  const double adc_lsb_N = 10.0 / 32767.0;
  const double count_m = 2.0 * std::numbers::pi * 0.115 / (500.0 * 10.0);

  const std::array<double, 3> zero{0.0, 0.0, 0.0};
  h.send_v2(100, usb::CommandFlags::kResync, zero);
  std::vector<std::uint8_t> bytes = h.step();
  usb::ReportPacketV2 r;
  ASSERT_EQ(usb::decode_v2(bytes, r), PacketError::kNone);
  EXPECT_EQ(r.channels, 3);
  EXPECT_EQ(r.last_command_sequence, 100U);

  const std::array<double, 3> forces{2.0, -1.5, 0.7};
  constexpr int kSteps = 150;
  for (int k = 1; k <= kSteps; ++k) {
    h.send_v2(100U + static_cast<std::uint32_t>(k), usb::CommandFlags::kEnable, forces);
    bytes = h.step();
    ASSERT_EQ(bytes.size(), usb::report_size_v2(3));
    ASSERT_EQ(usb::decode_v2(bytes, r), PacketError::kNone) << k;
    EXPECT_EQ(r.last_command_sequence, 100U + static_cast<std::uint32_t>(k));
    EXPECT_EQ(r.flags & usb::ReportFlags::kNoOutput, 0);
    for (std::size_t i = 0; i < 3; ++i) {
      // Commands in: the force each channel outputs is the host's within one DAC step.
      EXPECT_NEAR(h.emu.output_force_N(i), forces[i], dac_lsb_N) << i;
      // Reports out: position and load cell within one count of the plant's.
      EXPECT_NEAR(usb::counts_to_position_m(r.encoder_counts[i], s),
                  h.emu.plant(i).state().position_m, count_m)
          << i;
      EXPECT_NEAR(usb::adc_to_force_N(r.load_cell_adc[i], s),
                  h.emu.plant(i).output().environment_force_N, adc_lsb_N)
          << i;
    }
  }
  // Channel 1 was pulled into free space: the closed form of its quantised force, within a count.
  const double f1 = std::round(-1.5 / dac_lsb_N) * dac_lsb_N;
  EXPECT_NEAR(usb::counts_to_position_m(r.encoder_counts[1], s), free_response_m(f1, kSteps * 1e-3),
              count_m);
  EXPECT_LT(r.encoder_counts[1], -10);
  EXPECT_EQ(r.load_cell_adc[1], 0);
  // Channels 0 and 2 pushed into the tissue: a compression on their load cells, the larger on 0.
  EXPECT_GT(r.encoder_counts[0], 0);
  EXPECT_GT(r.load_cell_adc[0], r.load_cell_adc[2]);
  EXPECT_GT(r.load_cell_adc[2], 0);
  EXPECT_EQ(h.emu.report_version(), 2);
}

TEST(UsbEmulatorV2, AVersion1HostStillGetsVersion1AndDrivesChannelZero) {
  Host h(config_v2(3));
  EXPECT_EQ(h.emu.report_version(), 2);  // n = 3: v2 until a host speaks
  h.send_v1(7, usb::CommandFlags::kResync, 0);
  usb::ReportPacket v1;
  ASSERT_EQ(usb::decode(h.step(), v1), PacketError::kNone);
  EXPECT_EQ(v1.last_command_sequence, 7U);
  h.send_v1(8, usb::CommandFlags::kEnable, 2000);
  ASSERT_EQ(usb::decode(h.step(), v1), PacketError::kNone);
  EXPECT_EQ(v1.actuator_dac, 2000);
  EXPECT_DOUBLE_EQ(h.emu.output_force_N(0), 2000 * 16.5 / 32767.0);
  EXPECT_EQ(h.emu.output_force_N(1), 0.0);
  EXPECT_EQ(h.emu.output_force_N(2), 0.0);
  // The same device switches to v2 for a v2 host.
  const std::array<double, 3> forces{0.1, 0.2, 0.3};
  h.send_v2(9, usb::CommandFlags::kEnable, forces);
  usb::ReportPacketV2 v2;
  ASSERT_EQ(usb::decode_v2(h.step(), v2), PacketError::kNone);
  EXPECT_EQ(v2.last_command_sequence, 9U);
  EXPECT_NEAR(h.emu.output_force_N(2), 0.3, 16.5 / 32767.0);
}

TEST(UsbEmulatorV2, OneChannelOverVersion2IsVersion1sDeviceExactly) {
  usb::EmulatorConfig c1 = config_v2(1);
  c1.load_cell_noise_std_N = 0.01;  // the same noise draws on both
  Host v1_host(c1);
  Host v2_host(c1);
  v1_host.send_v1(1, usb::CommandFlags::kResync, 0);
  const std::array<double, 1> zero{0.0};
  v2_host.send_v2(1, usb::CommandFlags::kResync, zero);
  for (int k = 0; k < 120; ++k) {
    const double f = 3.0 * std::sin(0.05 * k);
    const usb::DacValue dac = usb::force_to_dac(f, usb::Scaling{});
    if (k > 0) {
      v1_host.send_v1(1U + static_cast<std::uint32_t>(k), usb::CommandFlags::kEnable, dac.dac);
      const std::array<double, 1> forces{f};
      v2_host.send_v2(1U + static_cast<std::uint32_t>(k), usb::CommandFlags::kEnable, forces);
    }
    usb::ReportPacket a;
    usb::ReportPacketV2 b;
    ASSERT_EQ(usb::decode(v1_host.step(), a), PacketError::kNone);
    ASSERT_EQ(usb::decode_v2(v2_host.step(), b), PacketError::kNone);
    EXPECT_EQ(a.sequence, b.sequence);
    EXPECT_EQ(a.device_time_us, b.device_time_us);
    EXPECT_EQ(a.encoder_counts, b.encoder_counts[0]);
    EXPECT_EQ(a.load_cell_adc, b.load_cell_adc[0]);
    EXPECT_EQ(a.flags, b.flags);
    EXPECT_EQ(a.last_command_sequence, b.last_command_sequence);
    EXPECT_EQ(v1_host.emu.output_force_N(), v2_host.emu.output_force_N(0));
  }
}

TEST(UsbEmulatorV2, RefusesAChannelCountNotItsOwnAndV1OnlyFirmwareRefusesV2) {
  Host h(config_v2(3));
  const std::array<double, 2> two{0.0, 0.0};
  h.send_v2(1, usb::CommandFlags::kResync, two);
  usb::ReportPacketV2 r;
  ASSERT_EQ(usb::decode_v2(h.step(), r), PacketError::kNone);
  EXPECT_EQ(r.commands_rejected, 1);
  EXPECT_EQ(h.emu.stats().rejected[PacketError::kChannelMismatch], 1U);
  EXPECT_EQ(h.emu.stats().commands_accepted, 0U);

  Host old(usb::EmulatorConfig{});  // version 1 only, as before version 2
  const std::array<double, 1> one{0.0};
  old.send_v2(1, usb::CommandFlags::kResync, one);
  usb::ReportPacket v1;
  ASSERT_EQ(usb::decode(old.step(), v1), PacketError::kNone);
  EXPECT_EQ(v1.commands_rejected, 1);
  EXPECT_EQ(old.emu.stats().rejected[PacketError::kBadVersion], 1U);
}

TEST(UsbEmulatorV2, RejectsABadChannelConfigurationNamingTheField) {
  const auto message = [](const usb::EmulatorConfig& c) {
    usb::MemoryLink link;
    try {
      usb::Emulator e(c, link.open_device());
    } catch (const std::invalid_argument& error) {
      return std::string(error.what());
    }
    return std::string();
  };
  usb::EmulatorConfig c = config_v2(0);
  EXPECT_NE(message(c).find("channels"), std::string::npos);
  c.channels = 7;
  EXPECT_NE(message(c).find("channels"), std::string::npos);
  c.channels = 3;
  c.protocol_version = 1;
  EXPECT_NE(message(c).find("channels"), std::string::npos);
  c.protocol_version = 3;
  EXPECT_NE(message(c).find("protocol_version"), std::string::npos);
  EXPECT_EQ(message(config_v2(6)), "");
}

}  // namespace
