// The codec against byte layouts written out by hand (docs/usb-protocol.md §3-4) and a CRC-32
// computed bit by bit from its definition, the rejection reasons, the sequence rule and the
// scaling.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <span>
#include <vector>

#include "common/device/usb_protocol.hpp"

namespace {

namespace usb = teleop::device::usb;
using usb::PacketError;

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

void append_crc(std::vector<std::uint8_t>& bytes) {
  const std::uint32_t crc = reference_crc32(bytes);
  for (unsigned i = 0; i < 4; ++i) bytes.push_back(static_cast<std::uint8_t>(crc >> (8U * i)));
}

// seq 0x01020304, watchdog 20 ms, enable, DAC -2.
std::vector<std::uint8_t> hand_command() {
  std::vector<std::uint8_t> b = {
      0x54, 0x48,              // magic "TH"
      0x01,                    // version
      0x01,                    // type: command
      0x04, 0x03, 0x02, 0x01,  // sequence
      0x14, 0x00,              // watchdog_ms 20
      0x01,                    // flags: enable
      0x00,                    // reserved
      0xFE, 0xFF,              // actuator_dac -2
      0x00, 0x00,              // reserved
  };
  append_crc(b);
  return b;
}

usb::CommandPacket the_command() {
  usb::CommandPacket p;
  p.sequence = 0x01020304U;
  p.watchdog_ms = 20;
  p.flags = usb::CommandFlags::kEnable;
  p.actuator_dac = -2;
  return p;
}

std::vector<std::uint8_t> hand_report() {
  std::vector<std::uint8_t> b = {
      0x54, 0x48,                                      // magic
      0x01,                                            // version
      0x02,                                            // type: report
      0xD4, 0xC3, 0xB2, 0xA1,                          // sequence 0xA1B2C3D4
      0x08, 0x07, 0x06, 0x05, 0x04, 0x03, 0x02, 0x01,  // device_time_us 0x0102030405060708
      0x18, 0xFC, 0xFF, 0xFF,                          // encoder_counts -1000
      0xD4, 0xFE,                                      // load_cell_adc -300
      0xD2, 0x04,                                      // actuator_dac 1234
      0x24, 0x00,                                      // flags: watchdog tripped | clipped
      0x44, 0x33, 0x22, 0x11,                          // last_command_sequence
      0x07, 0x00,                                      // commands_rejected 7
  };
  append_crc(b);
  return b;
}

usb::ReportPacket the_report() {
  usb::ReportPacket p;
  p.sequence = 0xA1B2C3D4U;
  p.device_time_us = 0x0102030405060708ULL;
  p.encoder_counts = -1000;
  p.load_cell_adc = -300;
  p.actuator_dac = 1234;
  p.flags = usb::ReportFlags::kWatchdogTripped | usb::ReportFlags::kLoadCellClipped;
  p.last_command_sequence = 0x11223344U;
  p.commands_rejected = 7;
  return p;
}

TEST(UsbProtocol, Crc32CheckValue) {
  const std::vector<std::uint8_t> digits = {'1', '2', '3', '4', '5', '6', '7', '8', '9'};
  EXPECT_EQ(usb::crc32(digits), 0xCBF43926U);
  EXPECT_EQ(reference_crc32(digits), 0xCBF43926U);
  EXPECT_EQ(usb::crc32({}), 0x00000000U);
}

TEST(UsbProtocol, CommandLayoutByteByByte) {
  usb::CommandBytes bytes{};
  ASSERT_EQ(usb::encode(the_command(), bytes), PacketError::kNone);
  const std::vector<std::uint8_t> expected = hand_command();
  ASSERT_EQ(expected.size(), usb::kCommandSize);
  EXPECT_EQ(std::vector<std::uint8_t>(bytes.begin(), bytes.end()), expected);
}

TEST(UsbProtocol, ReportLayoutByteByByte) {
  usb::ReportBytes bytes{};
  ASSERT_EQ(usb::encode(the_report(), bytes), PacketError::kNone);
  const std::vector<std::uint8_t> expected = hand_report();
  ASSERT_EQ(expected.size(), usb::kReportSize);
  EXPECT_EQ(std::vector<std::uint8_t>(bytes.begin(), bytes.end()), expected);
}

TEST(UsbProtocol, CommandRoundTrip) {
  for (const std::int16_t dac : {std::int16_t{-32767}, std::int16_t{-1}, std::int16_t{0},
                                 std::int16_t{1986}, std::int16_t{32767}}) {
    for (const std::uint16_t watchdog_ms : {std::uint16_t{1}, std::uint16_t{1000}}) {
      usb::CommandPacket in;
      in.sequence = 0xFFFFFFFFU - static_cast<std::uint32_t>(watchdog_ms);
      in.watchdog_ms = watchdog_ms;
      in.flags = dac > 0 ? usb::CommandFlags::kEnable : std::uint8_t{0};
      in.actuator_dac = dac;
      usb::CommandBytes bytes{};
      ASSERT_EQ(usb::encode(in, bytes), PacketError::kNone);
      usb::CommandPacket out;
      ASSERT_EQ(usb::decode(bytes, out), PacketError::kNone);
      EXPECT_EQ(out.sequence, in.sequence);
      EXPECT_EQ(out.watchdog_ms, in.watchdog_ms);
      EXPECT_EQ(out.flags, in.flags);
      EXPECT_EQ(out.actuator_dac, in.actuator_dac);
    }
  }
  usb::CommandPacket out;
  ASSERT_EQ(usb::decode(hand_command(), out), PacketError::kNone);
  EXPECT_EQ(out.sequence, 0x01020304U);
  EXPECT_EQ(out.actuator_dac, -2);
}

TEST(UsbProtocol, ReportRoundTrip) {
  usb::ReportPacket in = the_report();
  for (const std::int32_t counts : {std::numeric_limits<std::int32_t>::min(), -1, 0,
                                    std::numeric_limits<std::int32_t>::max()}) {
    in.encoder_counts = counts;
    in.flags = usb::ReportFlags::kKnown;
    in.load_cell_adc = -32767;
    in.actuator_dac = 32767;
    usb::ReportBytes bytes{};
    ASSERT_EQ(usb::encode(in, bytes), PacketError::kNone);
    usb::ReportPacket out;
    ASSERT_EQ(usb::decode(bytes, out), PacketError::kNone);
    EXPECT_EQ(out.sequence, in.sequence);
    EXPECT_EQ(out.device_time_us, in.device_time_us);
    EXPECT_EQ(out.encoder_counts, counts);
    EXPECT_EQ(out.load_cell_adc, -32767);
    EXPECT_EQ(out.actuator_dac, 32767);
    EXPECT_EQ(out.flags, usb::ReportFlags::kKnown);
    EXPECT_EQ(out.last_command_sequence, in.last_command_sequence);
    EXPECT_EQ(out.commands_rejected, in.commands_rejected);
  }
  usb::ReportPacket out;
  ASSERT_EQ(usb::decode(hand_report(), out), PacketError::kNone);
  EXPECT_EQ(out.encoder_counts, -1000);
  EXPECT_EQ(out.load_cell_adc, -300);
}

// Bytes with one byte changed and the CRC recomputed: only the field check can refuse them.
std::vector<std::uint8_t> patched(std::vector<std::uint8_t> bytes, std::size_t at,
                                  std::uint8_t value) {
  bytes.resize(bytes.size() - 4);
  bytes[at] = value;
  append_crc(bytes);
  return bytes;
}

PacketError decode_command(const std::vector<std::uint8_t>& bytes) {
  usb::CommandPacket out;
  out.sequence = 99;
  const PacketError e = usb::decode(bytes, out);
  if (e != PacketError::kNone) {
    EXPECT_EQ(out.sequence, 99U) << "written on " << usb::to_string(e);
  }
  return e;
}

PacketError decode_report(const std::vector<std::uint8_t>& bytes) {
  usb::ReportPacket out;
  return usb::decode(bytes, out);
}

TEST(UsbProtocol, RejectsEachMalformationWithItsReason) {
  const std::vector<std::uint8_t> good = hand_command();
  ASSERT_EQ(decode_command(good), PacketError::kNone);

  std::vector<std::uint8_t> b = good;
  b[13] ^= 0x01U;  // payload bit flip
  EXPECT_EQ(decode_command(b), PacketError::kBadCrc);
  b = good;
  b[19] ^= 0x80U;  // CRC bit flip
  EXPECT_EQ(decode_command(b), PacketError::kBadCrc);

  EXPECT_EQ(decode_command(patched(good, 0, 0x55)), PacketError::kBadMagic);
  EXPECT_EQ(decode_command(patched(good, 2, 0x02)), PacketError::kBadVersion);
  EXPECT_EQ(decode_command(patched(good, 2, 0x00)), PacketError::kBadVersion);
  EXPECT_EQ(decode_command(hand_report()), PacketError::kBadType);
  EXPECT_EQ(decode_report(good), PacketError::kBadType);

  EXPECT_EQ(decode_command({}), PacketError::kTruncated);
  EXPECT_EQ(decode_command({0x54, 0x48, 0x01}), PacketError::kTruncated);
  EXPECT_EQ(decode_command(std::vector<std::uint8_t>(good.begin(), good.end() - 1)),
            PacketError::kTruncated);
  b = good;
  b.push_back(0x00);
  EXPECT_EQ(decode_command(b), PacketError::kOversized);
  std::vector<std::uint8_t> r = hand_report();
  r.resize(usb::kMaxPacketSize, 0x00);
  EXPECT_EQ(decode_report(r), PacketError::kOversized);

  // Fields: watchdog 0 and 1001, an unknown flag, a reserved byte, DAC -32768.
  EXPECT_EQ(decode_command(patched(good, 8, 0x00)), PacketError::kBadField);
  EXPECT_EQ(decode_command(patched(patched(good, 8, 0xE9), 9, 0x03)), PacketError::kBadField);
  EXPECT_EQ(decode_command(patched(patched(good, 8, 0xE8), 9, 0x03)), PacketError::kNone);
  EXPECT_EQ(decode_command(patched(good, 10, 0x04)), PacketError::kBadField);  // unknown flag
  EXPECT_EQ(decode_command(patched(good, 10, 0x02)), PacketError::kNone);      // resync
  EXPECT_EQ(decode_command(patched(good, 10, 0x03)), PacketError::kBadField);  // resync + enable
  EXPECT_EQ(decode_command(patched(good, 11, 0x01)), PacketError::kBadField);
  EXPECT_EQ(decode_command(patched(good, 15, 0x01)), PacketError::kBadField);
  EXPECT_EQ(decode_command(patched(patched(good, 12, 0x00), 13, 0x80)), PacketError::kBadField);
  const std::vector<std::uint8_t> report = hand_report();
  EXPECT_EQ(decode_report(patched(report, 25, 0x01)), PacketError::kBadField);  // flag bit 8
  EXPECT_EQ(decode_report(patched(report, 24, 0x40)), PacketError::kBadField);  // flag bit 6
  EXPECT_EQ(decode_report(patched(patched(report, 20, 0x00), 21, 0x80)), PacketError::kBadField);

  // Encoders refuse what decoders would.
  usb::CommandPacket c = the_command();
  usb::CommandBytes cb{};
  c.watchdog_ms = 0;
  EXPECT_EQ(usb::encode(c, cb), PacketError::kBadField);
  c = the_command();
  c.flags = usb::CommandFlags::kEnable | usb::CommandFlags::kResync;
  EXPECT_EQ(usb::encode(c, cb), PacketError::kBadField);
  c = the_command();
  c.actuator_dac = -32768;
  EXPECT_EQ(usb::encode(c, cb), PacketError::kBadField);
  usb::ReportPacket rp = the_report();
  usb::ReportBytes rb{};
  rp.flags = 0x40;
  EXPECT_EQ(usb::encode(rp, rb), PacketError::kBadField);
}

TEST(UsbProtocol, ReasonsAreCounted) {
  usb::PacketCounters counters;
  counters.add(PacketError::kBadCrc);
  counters.add(PacketError::kBadCrc);
  counters.add(PacketError::kDuplicate, 3);
  EXPECT_EQ(counters[PacketError::kBadCrc], 2U);
  EXPECT_EQ(counters[PacketError::kDuplicate], 3U);
  EXPECT_EQ(counters[PacketError::kBadMagic], 0U);
  EXPECT_EQ(counters.total_rejected(), 5U);
  EXPECT_STREQ(usb::to_string(PacketError::kOutOfOrder), "out_of_order");
}

TEST(UsbProtocol, SequenceGapsDuplicatesAndReordering) {
  usb::SequenceTracker t;
  EXPECT_EQ(t.accept(100).error, PacketError::kNone);  // the first is taken as is
  auto r = t.accept(101);
  EXPECT_EQ(r.error, PacketError::kNone);
  EXPECT_EQ(r.lost, 0U);
  r = t.accept(105);
  EXPECT_EQ(r.error, PacketError::kNone);
  EXPECT_EQ(r.lost, 3U);  // 102, 103, 104
  EXPECT_EQ(t.accept(105).error, PacketError::kDuplicate);
  EXPECT_EQ(t.accept(103).error, PacketError::kOutOfOrder);
  EXPECT_EQ(t.newest(), 105U);
  // Serial-number arithmetic across the wrap.
  t.reset();
  EXPECT_EQ(t.accept(0xFFFFFFFEU).error, PacketError::kNone);
  r = t.accept(0x00000001U);
  EXPECT_EQ(r.error, PacketError::kNone);
  EXPECT_EQ(r.lost, 2U);  // 0xFFFFFFFF, 0
  EXPECT_EQ(t.accept(0xFFFFFFFFU).error, PacketError::kOutOfOrder);
  // Half the space or more behind is old.
  t.reset();
  EXPECT_EQ(t.accept(0).error, PacketError::kNone);
  EXPECT_EQ(t.accept(0x80000000U).error, PacketError::kOutOfOrder);
  EXPECT_EQ(t.accept(0x7FFFFFFFU).error, PacketError::kNone);
}

TEST(UsbProtocol, ScalingOfCountsLoadCellAndDac) {
  const usb::Scaling s;  // 500 counts/rev, 10:1, 0.115 m/rad, 10 N cell, 16.5 N actuator
  // One count: 2 pi 0.115 / 5000 m = 0.1445 mm.
  const double q = 2.0 * std::numbers::pi * 0.115 / 5000.0;
  EXPECT_DOUBLE_EQ(s.position_m_per_count(), q);
  EXPECT_DOUBLE_EQ(usb::counts_to_position_m(-1000, s), -1000.0 * q);
  EXPECT_DOUBLE_EQ(usb::adc_to_force_N(32767, s), 10.0);
  EXPECT_DOUBLE_EQ(usb::adc_to_force_N(-16384, s), -16384.0 * 10.0 / 32767.0);
  EXPECT_STREQ(s.invalid_field(), "");

  // 1 N at 32767 / 16.5 counts per newton = 1985.88 counts -> 1986.
  usb::DacValue v = usb::force_to_dac(1.0, s);
  EXPECT_EQ(v.dac, 1986);
  EXPECT_FALSE(v.saturated);
  EXPECT_EQ(v.error, PacketError::kNone);
  EXPECT_LE(std::abs(usb::dac_to_force_N(v.dac, s) - 1.0), 0.5 * 16.5 / 32767.0);
  EXPECT_EQ(usb::force_to_dac(-1.0, s).dac, -1986);
  EXPECT_EQ(usb::force_to_dac(16.5, s).dac, 32767);
  v = usb::force_to_dac(17.0, s);
  EXPECT_EQ(v.dac, 32767);
  EXPECT_TRUE(v.saturated);
  v = usb::force_to_dac(-1e9, s);
  EXPECT_EQ(v.dac, -32767);
  EXPECT_TRUE(v.saturated);
  for (const double bad :
       {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity(),
        -std::numeric_limits<double>::infinity()}) {
    v = usb::force_to_dac(bad, s);
    EXPECT_EQ(v.error, PacketError::kNonFinite);
    EXPECT_EQ(v.dac, 0);
  }

  usb::Scaling bad = s;
  bad.counts_per_rev = 0;
  EXPECT_STREQ(bad.invalid_field(), "scaling.counts_per_rev must be positive");
  bad = s;
  bad.actuator_full_scale_N = std::numeric_limits<double>::quiet_NaN();
  EXPECT_STREQ(bad.invalid_field(), "scaling.actuator_full_scale_N must be positive and finite");
}

}  // namespace
