// Protocol version 2 (n channels, docs/usb-protocol.md "Version 2: n channels"): the codec
// against packets written out byte by byte in this file with a CRC-32 computed bit by bit from
// its definition, lengths from the layout table, round trips at n = 1..6, every truncation and
// every single-bit flip refused with its reason, and version 1 unchanged beside it.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <span>
#include <vector>

#include "common/device/usb_protocol.hpp"

namespace {

namespace usb = teleop::device::usb;
using usb::PacketError;
using Bytes = std::vector<std::uint8_t>;

// CRC-32/ISO-HDLC from its definition: reflected, polynomial 0xEDB88320, init and xorout
// 0xFFFFFFFF, one bit at a time.
std::uint32_t reference_crc32(std::span<const std::uint8_t> bytes) {
  std::uint32_t c = 0xFFFFFFFFU;
  for (const std::uint8_t b : bytes) {
    c ^= b;
    for (int i = 0; i < 8; ++i) c = (c >> 1U) ^ ((c & 1U) != 0 ? 0xEDB88320U : 0U);
  }
  return ~c;
}

void append_crc(Bytes& bytes) {
  const std::uint32_t crc = reference_crc32(bytes);
  for (unsigned i = 0; i < 4; ++i) bytes.push_back(static_cast<std::uint8_t>(crc >> (8U * i)));
}

Bytes bytes_of(const usb::PacketBuffer& buffer, std::size_t size) {
  return Bytes(buffer.begin(), buffer.begin() + static_cast<std::ptrdiff_t>(size));
}

// n = 3: seq 0x01020304, watchdog 20 ms, enable, DACs -2, 1000, -32767.
Bytes hand_command_n3() {
  Bytes b = {
      0x54, 0x48,              // magic "TH"
      0x02,                    // version 2
      0x01,                    // type: command
      0x03,                    // n = 3
      0x01,                    // flags: enable
      0x14, 0x00,              // watchdog_ms 20
      0x04, 0x03, 0x02, 0x01,  // sequence 0x01020304
      0xFE, 0xFF,              // channel 0: DAC -2
      0xE8, 0x03,              // channel 1: DAC 1000
      0x01, 0x80,              // channel 2: DAC -32767
  };
  append_crc(b);
  return b;
}

usb::CommandPacketV2 the_command_n3() {
  usb::CommandPacketV2 p;
  p.sequence = 0x01020304U;
  p.watchdog_ms = 20;
  p.flags = usb::CommandFlags::kEnable;
  p.channels = 3;
  p.actuator_dac = {-2, 1000, -32767, 0, 0, 0};
  return p;
}

Bytes hand_report_n3() {
  Bytes b = {
      0x54, 0x48,                                      // magic
      0x02,                                            // version 2
      0x02,                                            // type: report
      0x03,                                            // n = 3
      0x28,                                            // flags: saturated | clipped
      0x07, 0x00,                                      // commands_rejected 7
      0xD4, 0xC3, 0xB2, 0xA1,                          // sequence 0xA1B2C3D4
      0x44, 0x33, 0x22, 0x11,                          // last_command_sequence 0x11223344
      0x08, 0x07, 0x06, 0x05, 0x04, 0x03, 0x02, 0x01,  // device_time_us 0x0102030405060708
      0x18, 0xFC, 0xFF, 0xFF,                          // channel 0: encoder -1000
      0xD4, 0xFE,                                      //            load cell -300
      0x70, 0x11, 0x01, 0x00,                          // channel 1: encoder 70000
      0xFF, 0x7F,                                      //            load cell 32767
      0x00, 0x00, 0x00, 0x80,                          // channel 2: encoder -2^31
      0x00, 0x00,                                      //            load cell 0
  };
  append_crc(b);
  return b;
}

usb::ReportPacketV2 the_report_n3() {
  usb::ReportPacketV2 p;
  p.sequence = 0xA1B2C3D4U;
  p.device_time_us = 0x0102030405060708ULL;
  p.flags = static_cast<std::uint8_t>(usb::ReportFlags::kAmplifierSaturated |
                                      usb::ReportFlags::kLoadCellClipped);
  p.channels = 3;
  p.last_command_sequence = 0x11223344U;
  p.commands_rejected = 7;
  p.encoder_counts = {-1000, 70000, std::numeric_limits<std::int32_t>::min(), 0, 0, 0};
  p.load_cell_adc = {-300, 32767, 0, 0, 0, 0};
  return p;
}

void expect_same(const usb::CommandPacketV2& a, const usb::CommandPacketV2& b) {
  EXPECT_EQ(a.sequence, b.sequence);
  EXPECT_EQ(a.watchdog_ms, b.watchdog_ms);
  EXPECT_EQ(a.flags, b.flags);
  ASSERT_EQ(a.channels, b.channels);
  for (std::size_t i = 0; i < a.channels; ++i) EXPECT_EQ(a.actuator_dac[i], b.actuator_dac[i]);
}

void expect_same(const usb::ReportPacketV2& a, const usb::ReportPacketV2& b) {
  EXPECT_EQ(a.sequence, b.sequence);
  EXPECT_EQ(a.device_time_us, b.device_time_us);
  EXPECT_EQ(a.flags, b.flags);
  EXPECT_EQ(a.last_command_sequence, b.last_command_sequence);
  EXPECT_EQ(a.commands_rejected, b.commands_rejected);
  ASSERT_EQ(a.channels, b.channels);
  for (std::size_t i = 0; i < a.channels; ++i) {
    EXPECT_EQ(a.encoder_counts[i], b.encoder_counts[i]);
    EXPECT_EQ(a.load_cell_adc[i], b.load_cell_adc[i]);
  }
}

TEST(UsbProtocolV2, LengthsFollowTheLayoutTableAndSixChannelsFit) {
  // Command: 12 header bytes + 2 per channel + 4 CRC; report: 24 + 6 per channel + 4.
  const std::size_t command[] = {18, 20, 22, 24, 26, 28};
  const std::size_t report[] = {34, 40, 46, 52, 58, 64};
  for (std::size_t n = 1; n <= 6; ++n) {
    EXPECT_EQ(usb::command_size_v2(n), command[n - 1]) << n;
    EXPECT_EQ(usb::report_size_v2(n), report[n - 1]) << n;
  }
  EXPECT_EQ(usb::kMaxChannels, 6U);
  EXPECT_EQ(usb::report_size_v2(6), usb::kMaxPacketSize);  // exactly one full-speed packet
}

TEST(UsbProtocolV2, CommandN3ByteByByte) {
  const Bytes hand = hand_command_n3();
  ASSERT_EQ(hand.size(), 22U);
  usb::PacketBuffer buffer{};
  std::size_t size = 0;
  ASSERT_EQ(usb::encode(the_command_n3(), buffer, size), PacketError::kNone);
  EXPECT_EQ(bytes_of(buffer, size), hand);
  usb::CommandPacketV2 decoded;
  ASSERT_EQ(usb::decode_v2(hand, decoded), PacketError::kNone);
  expect_same(decoded, the_command_n3());
}

TEST(UsbProtocolV2, ReportN3ByteByByte) {
  const Bytes hand = hand_report_n3();
  ASSERT_EQ(hand.size(), 46U);
  usb::PacketBuffer buffer{};
  std::size_t size = 0;
  ASSERT_EQ(usb::encode(the_report_n3(), buffer, size), PacketError::kNone);
  EXPECT_EQ(bytes_of(buffer, size), hand);
  usb::ReportPacketV2 decoded;
  ASSERT_EQ(usb::decode_v2(hand, decoded), PacketError::kNone);
  expect_same(decoded, the_report_n3());
}

TEST(UsbProtocolV2, RoundTripsAtEveryChannelCount) {
  for (std::uint8_t n = 1; n <= 6; ++n) {
    usb::CommandPacketV2 c;
    c.sequence = 0xFFFFFFF0U + n;
    c.watchdog_ms = static_cast<std::uint16_t>(n == 6 ? 1000 : n);
    c.flags = n % 2 == 0 ? usb::CommandFlags::kEnable : usb::CommandFlags::kResync;
    c.channels = n;
    for (std::size_t i = 0; i < n; ++i) {
      c.actuator_dac[i] = static_cast<std::int16_t>(i % 2 == 0 ? 32767 - 11 * static_cast<int>(i)
                                                               : -32767 + 7 * static_cast<int>(i));
    }
    usb::PacketBuffer buffer{};
    std::size_t size = 0;
    ASSERT_EQ(usb::encode(c, buffer, size), PacketError::kNone);
    EXPECT_EQ(size, 16U + 2U * n);
    usb::CommandPacketV2 back;
    ASSERT_EQ(usb::decode_v2(std::span<const std::uint8_t>(buffer.data(), size), back),
              PacketError::kNone);
    expect_same(back, c);

    usb::ReportPacketV2 r;
    r.sequence = 1000U * n;
    r.device_time_us = 0xFEDCBA9876543210ULL - n;
    r.flags = static_cast<std::uint8_t>(0x3F >> n);
    r.channels = n;
    r.last_command_sequence = 0x80000000U + n;
    r.commands_rejected = static_cast<std::uint16_t>(65535 - n);
    for (std::size_t i = 0; i < n; ++i) {
      r.encoder_counts[i] = (i % 2 == 0 ? 1 : -1) * static_cast<std::int32_t>(123457 * (i + 1));
      r.load_cell_adc[i] =
          static_cast<std::int16_t>(i % 2 == 0 ? -32767 : 32767 - 3 * static_cast<int>(i));
    }
    ASSERT_EQ(usb::encode(r, buffer, size), PacketError::kNone);
    EXPECT_EQ(size, 28U + 6U * n);
    usb::ReportPacketV2 rback;
    ASSERT_EQ(usb::decode_v2(std::span<const std::uint8_t>(buffer.data(), size), rback),
              PacketError::kNone);
    expect_same(rback, r);
  }
}

template <typename Packet>
void expect_every_truncation_and_flip_refused(const Bytes& good) {
  Packet p;
  ASSERT_EQ(usb::decode_v2(good, p), PacketError::kNone);
  for (std::size_t len = 0; len < good.size(); ++len) {
    EXPECT_EQ(usb::decode_v2(std::span<const std::uint8_t>(good.data(), len), p),
              PacketError::kTruncated)
        << len;
  }
  Bytes longer = good;
  longer.push_back(0);
  EXPECT_EQ(usb::decode_v2(longer, p), PacketError::kOversized);
  for (std::size_t byte = 0; byte < good.size(); ++byte) {
    for (unsigned bit = 0; bit < 8; ++bit) {
      Bytes flipped = good;
      flipped[byte] = static_cast<std::uint8_t>(flipped[byte] ^ (1U << bit));
      const PacketError e = usb::decode_v2(flipped, p);
      if (byte < 2) {
        EXPECT_EQ(e, PacketError::kBadMagic) << byte << ":" << bit;
      } else if (byte == 2) {
        EXPECT_EQ(e, PacketError::kBadVersion) << byte << ":" << bit;
      } else if (byte == 3) {
        EXPECT_EQ(e, PacketError::kBadType) << byte << ":" << bit;
      } else if (byte == 4) {
        // n = 3 flipped: 2 and 1 make the packet too long, 7 and above are out of range.
        EXPECT_TRUE(e == PacketError::kBadChannels || e == PacketError::kOversized ||
                    e == PacketError::kTruncated)
            << byte << ":" << bit << " " << usb::to_string(e);
      } else {
        EXPECT_EQ(e, PacketError::kBadCrc) << byte << ":" << bit;
      }
    }
  }
}

TEST(UsbProtocolV2, EveryTruncationAndEverySingleBitFlipIsRefused) {
  expect_every_truncation_and_flip_refused<usb::CommandPacketV2>(hand_command_n3());
  expect_every_truncation_and_flip_refused<usb::ReportPacketV2>(hand_report_n3());
}

// A command header with channel count n and `payload` bytes after it, then a valid CRC.
Bytes command_with(std::uint8_t n, std::size_t payload) {
  const std::array<std::uint8_t, 12> header = {0x54, 0x48, 0x02, 0x01, n,    0x00,
                                               0x14, 0x00, 0x01, 0x00, 0x00, 0x00};
  Bytes b(header.size() + payload, 0);  // (not resize: GCC 12 -O3 -Warray-bounds false positive)
  for (std::size_t i = 0; i < header.size(); ++i) b[i] = header[i];
  append_crc(b);
  return b;
}

TEST(UsbProtocolV2, BadChannelCountsAndLengthsNotMatchingNAreRefused) {
  usb::CommandPacketV2 c;
  usb::ReportPacketV2 r;
  // n = 0, 7, 255, each with a valid CRC over what a length of 2n would be.
  EXPECT_EQ(usb::decode_v2(command_with(0, 0), c), PacketError::kBadChannels);
  EXPECT_EQ(usb::decode_v2(command_with(7, 14), c), PacketError::kBadChannels);
  EXPECT_EQ(usb::decode_v2(command_with(255, 40), c), PacketError::kBadChannels);
  Bytes report_n0 = {0x54, 0x48, 0x02, 0x02, 0x00};
  report_n0.resize(24, 0);
  append_crc(report_n0);
  EXPECT_EQ(usb::decode_v2(report_n0, r), PacketError::kBadChannels);
  // Exactly 4 frozen bytes: n is missing.
  EXPECT_EQ(usb::decode_v2(Bytes{0x54, 0x48, 0x02, 0x01}, c), PacketError::kTruncated);
  // n = 3 with four channels' bytes (valid CRC) and n = 4 with three.
  EXPECT_EQ(usb::decode_v2(command_with(3, 8), c), PacketError::kOversized);
  EXPECT_EQ(usb::decode_v2(command_with(4, 6), c), PacketError::kTruncated);
  ASSERT_EQ(usb::decode_v2(command_with(3, 6), c), PacketError::kNone);
  EXPECT_EQ(c.channels, 3);

  usb::PacketBuffer buffer{};
  std::size_t size = 0;
  usb::CommandPacketV2 bad = the_command_n3();
  for (const std::uint8_t n : {std::uint8_t{0}, std::uint8_t{7}, std::uint8_t{255}}) {
    bad.channels = n;
    EXPECT_EQ(usb::encode(bad, buffer, size), PacketError::kBadChannels);
    usb::ReportPacketV2 bad_report = the_report_n3();
    bad_report.channels = n;
    EXPECT_EQ(usb::encode(bad_report, buffer, size), PacketError::kBadChannels);
  }
}

TEST(UsbProtocolV2, FieldsOutOfRangeAreRefusedBothWays) {
  usb::PacketBuffer buffer{};
  std::size_t size = 0;
  usb::CommandPacketV2 c = the_command_n3();
  c.actuator_dac[2] = -32768;
  EXPECT_EQ(usb::encode(c, buffer, size), PacketError::kBadField);
  c = the_command_n3();
  c.actuator_dac[3] = -32768;  // beyond n: not on the wire
  EXPECT_EQ(usb::encode(c, buffer, size), PacketError::kNone);
  c = the_command_n3();
  c.flags = usb::CommandFlags::kEnable | usb::CommandFlags::kResync;
  EXPECT_EQ(usb::encode(c, buffer, size), PacketError::kBadField);
  c.flags = 0;
  c.watchdog_ms = 0;
  EXPECT_EQ(usb::encode(c, buffer, size), PacketError::kBadField);
  usb::ReportPacketV2 r = the_report_n3();
  r.flags = 0x40;
  EXPECT_EQ(usb::encode(r, buffer, size), PacketError::kBadField);
  r = the_report_n3();
  r.load_cell_adc[1] = -32768;
  EXPECT_EQ(usb::encode(r, buffer, size), PacketError::kBadField);

  // The same on decode, the CRC recomputed so only the field is wrong.
  usb::CommandPacketV2 out;
  Bytes cmd = hand_command_n3();
  cmd.resize(cmd.size() - 4);
  cmd[16] = 0x00;
  cmd[17] = 0x80;  // channel 2: -32768
  append_crc(cmd);
  EXPECT_EQ(usb::decode_v2(cmd, out), PacketError::kBadField);
  cmd = hand_command_n3();
  cmd.resize(cmd.size() - 4);
  cmd[5] = 0x04;  // undefined flag bit
  append_crc(cmd);
  EXPECT_EQ(usb::decode_v2(cmd, out), PacketError::kBadField);
  usb::ReportPacketV2 rout;
  Bytes rep = hand_report_n3();
  rep.resize(rep.size() - 4);
  rep[5] = 0x80;  // undefined flag bit
  append_crc(rep);
  EXPECT_EQ(usb::decode_v2(rep, rout), PacketError::kBadField);
}

TEST(UsbProtocolV2, UnknownVersionsAndCrossVersionPacketsAreRefused) {
  // Version 3 with a valid CRC: nothing past byte 3 is read.
  Bytes v3 = hand_command_n3();
  v3.resize(v3.size() - 4);
  v3[2] = 0x03;
  append_crc(v3);
  usb::CommandPacketV2 c;
  std::uint8_t version = 0;
  EXPECT_EQ(usb::decode_v2(v3, c), PacketError::kBadVersion);
  EXPECT_EQ(usb::decode_any(v3, c, version), PacketError::kBadVersion);
  // A v1-only reader refuses v2 packets as an unsupported version, never misreads them.
  usb::CommandPacket v1c;
  usb::ReportPacket v1r;
  EXPECT_EQ(usb::decode(hand_command_n3(), v1c), PacketError::kBadVersion);
  EXPECT_EQ(usb::decode(hand_report_n3(), v1r), PacketError::kBadVersion);
  // A v2 packet whose length happens to be v1's: still refused by version.
  const Bytes v2_of_v1_length = command_with(2, 4);  // 20 bytes, as a v1 command
  ASSERT_EQ(v2_of_v1_length.size(), usb::kCommandSize);
  EXPECT_EQ(usb::decode(v2_of_v1_length, v1c), PacketError::kBadVersion);
  // And the v2 decoder refuses v1 packets.
  usb::CommandPacket one;
  one.sequence = 5;
  usb::CommandBytes v1_bytes{};
  ASSERT_EQ(usb::encode(one, v1_bytes), PacketError::kNone);
  EXPECT_EQ(usb::decode_v2(v1_bytes, c), PacketError::kBadVersion);
}

// Version 1's command as written out in docs/usb-protocol.md §3: seq 0x01020304, watchdog 20 ms,
// enable, DAC -2 (the golden bytes of test_usb_protocol.cpp, repeated here).
Bytes hand_command_v1() {
  Bytes b = {0x54, 0x48, 0x01, 0x01, 0x04, 0x03, 0x02, 0x01,
             0x14, 0x00, 0x01, 0x00, 0xFE, 0xFF, 0x00, 0x00};
  append_crc(b);
  return b;
}

TEST(UsbProtocolV2, Version1StillDecodesAsVersion1) {
  const Bytes golden = hand_command_v1();
  usb::CommandPacket v1;
  v1.sequence = 0x01020304U;
  v1.watchdog_ms = 20;
  v1.flags = usb::CommandFlags::kEnable;
  v1.actuator_dac = -2;
  usb::CommandBytes encoded{};
  ASSERT_EQ(usb::encode(v1, encoded), PacketError::kNone);
  EXPECT_EQ(Bytes(encoded.begin(), encoded.end()), golden);
  usb::CommandPacket back;
  ASSERT_EQ(usb::decode(golden, back), PacketError::kNone);
  EXPECT_EQ(back.sequence, v1.sequence);
  EXPECT_EQ(back.actuator_dac, -2);

  // The reader of both versions: v1 bytes come out as n = 1 with v1's values.
  usb::CommandPacketV2 any;
  std::uint8_t version = 0;
  ASSERT_EQ(usb::decode_any(golden, any, version), PacketError::kNone);
  EXPECT_EQ(version, 1);
  EXPECT_EQ(any.channels, 1);
  EXPECT_EQ(any.sequence, 0x01020304U);
  EXPECT_EQ(any.watchdog_ms, 20);
  EXPECT_EQ(any.flags, usb::CommandFlags::kEnable);
  EXPECT_EQ(any.actuator_dac[0], -2);
  // Its v1 refusals are v1's.
  Bytes corrupt = golden;
  corrupt[12] ^= 0x01;
  EXPECT_EQ(usb::decode_any(corrupt, any, version), PacketError::kBadCrc);
  EXPECT_EQ(usb::decode_any(Bytes{0x54, 0x48}, any, version), PacketError::kTruncated);
  // v2 bytes come out as v2.
  ASSERT_EQ(usb::decode_any(hand_command_n3(), any, version), PacketError::kNone);
  EXPECT_EQ(version, 2);
  expect_same(any, the_command_n3());
}

TEST(UsbProtocolV2, ForcesSaturateOrAreRefusedAsInVersion1) {
  const usb::Scaling scaling{};
  const double step = 16.5 / 32767.0;  // the default amplifier's full scale over the DAC's
  usb::CommandPacketV2 c;
  const double forces[] = {0.0, 3.0 * step + 0.4 * step, -100.0, 1e9, -step * 2.6};
  const usb::DacValuesV2 ok = usb::forces_to_dacs(forces, scaling, c);
  ASSERT_EQ(ok.error, PacketError::kNone);
  EXPECT_TRUE(ok.saturated);
  ASSERT_EQ(c.channels, 5);
  EXPECT_EQ(c.actuator_dac[0], 0);
  EXPECT_EQ(c.actuator_dac[1], 3);
  EXPECT_EQ(c.actuator_dac[2], -32767);  // -100 N is beyond -16.5 N: clipped
  EXPECT_EQ(c.actuator_dac[3], 32767);
  EXPECT_EQ(c.actuator_dac[4], -3);
  const double small[] = {1.0, -1.0};
  const usb::DacValuesV2 unsaturated = usb::forces_to_dacs(small, scaling, c);
  EXPECT_FALSE(unsaturated.saturated);
  EXPECT_EQ(c.channels, 2);
  EXPECT_EQ(c.actuator_dac[0], static_cast<std::int16_t>(std::lround(1.0 / step)));

  // A non-finite force anywhere refuses the whole command; the packet is untouched.
  const usb::CommandPacketV2 before = c;
  for (const double bad :
       {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity(),
        -std::numeric_limits<double>::infinity()}) {
    const double with_bad[] = {1.0, 2.0, bad};
    EXPECT_EQ(usb::forces_to_dacs(with_bad, scaling, c).error, PacketError::kNonFinite);
    expect_same(c, before);
  }
  const double seven[7] = {};
  EXPECT_EQ(usb::forces_to_dacs(seven, scaling, c).error, PacketError::kBadChannels);
  EXPECT_EQ(usb::forces_to_dacs(std::span<const double>{}, scaling, c).error,
            PacketError::kBadChannels);
  expect_same(c, before);
}

TEST(UsbProtocolV2, NewReasonsHaveNames) {
  EXPECT_STREQ(usb::to_string(PacketError::kBadChannels), "bad_channels");
  EXPECT_STREQ(usb::to_string(PacketError::kChannelMismatch), "channel_mismatch");
}

}  // namespace
