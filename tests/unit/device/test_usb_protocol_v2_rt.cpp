// The version 2 codec (encode, decode_v2, decode_any, forces_to_dacs) never allocates, at every
// n = 1..6 and on refused packets too: malloc and friends are interposed and counted
// (tests/support/alloc_counter.hpp). Sanitizer builds replace the allocator and leave it out.
#include <gtest/gtest.h>

#include <array>
#include <cstdint>
#include <span>

#include "common/device/usb_protocol.hpp"
#include "tests/support/alloc_counter.hpp"

namespace {

namespace usb = teleop::device::usb;
using usb::PacketError;

TEST(UsbProtocolV2Rt, EncodeAndDecodeNeverAllocate) {
  const usb::Scaling scaling{};
  usb::PacketBuffer buffer{};
  usb::CommandPacketV2 c;
  usb::CommandPacketV2 c_back;
  usb::ReportPacketV2 r;
  usb::ReportPacketV2 r_back;
  std::array<double, usb::kMaxChannels> forces{};
  long accepted = 0;
  long refused = 0;
  teleop::test::start_counting(true);
  for (int k = 0; k < 500; ++k) {
    const std::size_t n = 1 + static_cast<std::size_t>(k) % usb::kMaxChannels;
    for (std::size_t i = 0; i < n; ++i) forces[i] = 0.01 * k - 2.0 * static_cast<double>(i);
    c.sequence = static_cast<std::uint32_t>(k);
    c.flags = usb::CommandFlags::kEnable;
    std::size_t size = 0;
    std::uint8_t version = 0;
    bool ok = usb::forces_to_dacs(std::span<const double>(forces.data(), n), scaling, c).error ==
              PacketError::kNone;
    ok = ok && usb::encode(c, buffer, size) == PacketError::kNone;
    const std::span<const std::uint8_t> command(buffer.data(), size);
    ok = ok && usb::decode_v2(command, c_back) == PacketError::kNone &&
         usb::decode_any(command, c_back, version) == PacketError::kNone &&
         c_back.actuator_dac[n - 1] == c.actuator_dac[n - 1];
    accepted += ok ? 1 : 0;
    refused += usb::decode_v2(command.first(size - 1), c_back) == PacketError::kTruncated ? 1 : 0;

    r.sequence = static_cast<std::uint32_t>(k);
    r.channels = static_cast<std::uint8_t>(n);
    r.encoder_counts[n - 1] = -k;
    ok = usb::encode(r, buffer, size) == PacketError::kNone;
    const std::span<const std::uint8_t> report(buffer.data(), size);
    ok = ok && usb::decode_v2(report, r_back) == PacketError::kNone &&
         r_back.encoder_counts[n - 1] == -k;
    accepted += ok ? 1 : 0;
    buffer[size - 1] ^= 0x01;
    refused += usb::decode_v2(report, r_back) == PacketError::kBadCrc ? 1 : 0;
  }
  const long calls = teleop::test::stop_counting();
  EXPECT_EQ(calls, 0);
  EXPECT_EQ(accepted, 1000);
  EXPECT_EQ(refused, 1000);
}

}  // namespace
