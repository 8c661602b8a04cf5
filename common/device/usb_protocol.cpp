#include "common/device/usb_protocol.hpp"

#include <zlib.h>

#include <cmath>
#include <numbers>

namespace teleop::device::usb {

namespace {

// Little-endian field access, byte by byte, so the layout does not depend on the host's
// endianness or alignment.
void put_u8(std::span<std::uint8_t> out, std::size_t at, std::uint8_t v) noexcept { out[at] = v; }

void put_u16(std::span<std::uint8_t> out, std::size_t at, std::uint16_t v) noexcept {
  out[at] = static_cast<std::uint8_t>(v & 0xFFU);
  out[at + 1] = static_cast<std::uint8_t>(v >> 8U);
}

void put_u32(std::span<std::uint8_t> out, std::size_t at, std::uint32_t v) noexcept {
  for (std::size_t i = 0; i < 4; ++i) {
    out[at + i] = static_cast<std::uint8_t>((v >> (8U * i)) & 0xFFU);
  }
}

void put_u64(std::span<std::uint8_t> out, std::size_t at, std::uint64_t v) noexcept {
  for (std::size_t i = 0; i < 8; ++i) {
    out[at + i] = static_cast<std::uint8_t>((v >> (8U * i)) & 0xFFU);
  }
}

std::uint16_t get_u16(std::span<const std::uint8_t> in, std::size_t at) noexcept {
  return static_cast<std::uint16_t>(in[at] | (in[at + 1] << 8U));
}

std::uint32_t get_u32(std::span<const std::uint8_t> in, std::size_t at) noexcept {
  std::uint32_t v = 0;
  for (std::size_t i = 0; i < 4; ++i) v |= static_cast<std::uint32_t>(in[at + i]) << (8U * i);
  return v;
}

std::uint64_t get_u64(std::span<const std::uint8_t> in, std::size_t at) noexcept {
  std::uint64_t v = 0;
  for (std::size_t i = 0; i < 8; ++i) v |= static_cast<std::uint64_t>(in[at + i]) << (8U * i);
  return v;
}

// Two's complement both ways (well defined in C++20).
std::uint16_t from_i16(std::int16_t v) noexcept { return static_cast<std::uint16_t>(v); }
std::int16_t to_i16(std::uint16_t v) noexcept { return static_cast<std::int16_t>(v); }
std::uint32_t from_i32(std::int32_t v) noexcept { return static_cast<std::uint32_t>(v); }
std::int32_t to_i32(std::uint32_t v) noexcept { return static_cast<std::int32_t>(v); }

constexpr std::int16_t kInvalidRaw = -32768;

void put_header(std::span<std::uint8_t> out, PacketType type, std::uint32_t sequence) noexcept {
  put_u16(out, 0, kMagic);
  put_u8(out, 2, kProtocolVersion);
  put_u8(out, 3, static_cast<std::uint8_t>(type));
  put_u32(out, 4, sequence);
}

void put_crc(std::span<std::uint8_t> out) noexcept {
  const std::size_t body = out.size() - 4;
  put_u32(out, body, crc32(out.first(body)));
}

// The frozen bytes, then the size for the type, then the CRC.
PacketError check_frame(std::span<const std::uint8_t> in, PacketType type,
                        std::size_t size) noexcept {
  if (in.size() < 4) return PacketError::kTruncated;
  if (get_u16(in, 0) != kMagic) return PacketError::kBadMagic;
  if (in[2] != kProtocolVersion) return PacketError::kBadVersion;
  if (in[3] != static_cast<std::uint8_t>(type)) return PacketError::kBadType;
  if (in.size() < size) return PacketError::kTruncated;
  if (in.size() > size) return PacketError::kOversized;
  if (crc32(in.first(size - 4)) != get_u32(in, size - 4)) return PacketError::kBadCrc;
  return PacketError::kNone;
}

bool command_fields_valid(const CommandPacket& p) noexcept {
  return p.watchdog_ms >= kMinWatchdogMs && p.watchdog_ms <= kMaxWatchdogMs &&
         (p.flags & ~CommandFlags::kKnown) == 0 &&
         (p.flags & (CommandFlags::kEnable | CommandFlags::kResync)) !=
             (CommandFlags::kEnable | CommandFlags::kResync) &&
         p.actuator_dac != kInvalidRaw;
}

bool report_fields_valid(const ReportPacket& p) noexcept {
  return (p.flags & ~ReportFlags::kKnown) == 0 && p.load_cell_adc != kInvalidRaw &&
         p.actuator_dac != kInvalidRaw;
}

// ---- version 2 ----

bool channels_valid(std::size_t n) noexcept { return n >= 1 && n <= kMaxChannels; }

void put_header_v2(std::span<std::uint8_t> out, PacketType type, std::uint8_t channels) noexcept {
  put_u16(out, 0, kMagic);
  put_u8(out, 2, kProtocolVersion2);
  put_u8(out, 3, static_cast<std::uint8_t>(type));
  put_u8(out, 4, channels);
}

// The frozen bytes, n, the size n gives, then the CRC; `channels` is n when kNone.
PacketError check_frame_v2(std::span<const std::uint8_t> in, PacketType type,
                           std::size_t& channels) noexcept {
  if (in.size() < 4) return PacketError::kTruncated;
  if (get_u16(in, 0) != kMagic) return PacketError::kBadMagic;
  if (in[2] != kProtocolVersion2) return PacketError::kBadVersion;
  if (in[3] != static_cast<std::uint8_t>(type)) return PacketError::kBadType;
  if (in.size() < 5) return PacketError::kTruncated;
  if (!channels_valid(in[4])) return PacketError::kBadChannels;
  const std::size_t size =
      type == PacketType::kCommand ? command_size_v2(in[4]) : report_size_v2(in[4]);
  if (in.size() < size) return PacketError::kTruncated;
  if (in.size() > size) return PacketError::kOversized;
  if (crc32(in.first(size - 4)) != get_u32(in, size - 4)) return PacketError::kBadCrc;
  channels = in[4];
  return PacketError::kNone;
}

bool command_fields_valid(const CommandPacketV2& p) noexcept {
  if (!(p.watchdog_ms >= kMinWatchdogMs && p.watchdog_ms <= kMaxWatchdogMs &&
        (p.flags & ~CommandFlags::kKnown) == 0 &&
        (p.flags & (CommandFlags::kEnable | CommandFlags::kResync)) !=
            (CommandFlags::kEnable | CommandFlags::kResync))) {
    return false;
  }
  for (std::size_t i = 0; i < p.channels; ++i) {
    if (p.actuator_dac[i] == kInvalidRaw) return false;
  }
  return true;
}

bool report_fields_valid(const ReportPacketV2& p) noexcept {
  if ((p.flags & ~ReportFlags::kKnown) != 0) return false;
  for (std::size_t i = 0; i < p.channels; ++i) {
    if (p.load_cell_adc[i] == kInvalidRaw) return false;
  }
  return true;
}

// Command v2 offsets (docs/usb-protocol.md "Version 2: n channels").
constexpr std::size_t kCmdFlags = 5;
constexpr std::size_t kCmdWatchdog = 6;
constexpr std::size_t kCmdSequence = 8;
constexpr std::size_t kCmdDac = 12;  // + 2 i
// Report v2 offsets.
constexpr std::size_t kRepFlags = 5;
constexpr std::size_t kRepRejected = 6;
constexpr std::size_t kRepSequence = 8;
constexpr std::size_t kRepLastCommand = 12;
constexpr std::size_t kRepTime = 16;
constexpr std::size_t kRepChannel = 24;  // + 6 i: encoder i32, then load cell i16
constexpr std::size_t kRepChannelStride = 6;

}  // namespace

const char* to_string(PacketError error) noexcept {
  switch (error) {
    case PacketError::kNone:
      return "none";
    case PacketError::kTruncated:
      return "truncated";
    case PacketError::kOversized:
      return "oversized";
    case PacketError::kBadMagic:
      return "bad_magic";
    case PacketError::kBadVersion:
      return "bad_version";
    case PacketError::kBadType:
      return "bad_type";
    case PacketError::kBadCrc:
      return "bad_crc";
    case PacketError::kBadField:
      return "bad_field";
    case PacketError::kNonFinite:
      return "non_finite";
    case PacketError::kDuplicate:
      return "duplicate";
    case PacketError::kOutOfOrder:
      return "out_of_order";
    case PacketError::kBadChannels:
      return "bad_channels";
    case PacketError::kChannelMismatch:
      return "channel_mismatch";
    case PacketError::kCount:
      break;
  }
  return "unknown";
}

std::uint32_t crc32(std::span<const std::uint8_t> bytes) noexcept {
  return static_cast<std::uint32_t>(::crc32(0L, bytes.data(), static_cast<uInt>(bytes.size())));
}

PacketError encode(const CommandPacket& p, CommandBytes& out) noexcept {
  if (!command_fields_valid(p)) return PacketError::kBadField;
  const std::span<std::uint8_t> s{out};
  put_header(s, PacketType::kCommand, p.sequence);
  put_u16(s, 8, p.watchdog_ms);
  put_u8(s, 10, p.flags);
  put_u8(s, 11, 0);  // reserved
  put_u16(s, 12, from_i16(p.actuator_dac));
  put_u16(s, 14, 0);  // reserved
  put_crc(s);
  return PacketError::kNone;
}

PacketError encode(const ReportPacket& p, ReportBytes& out) noexcept {
  if (!report_fields_valid(p)) return PacketError::kBadField;
  const std::span<std::uint8_t> s{out};
  put_header(s, PacketType::kReport, p.sequence);
  put_u64(s, 8, p.device_time_us);
  put_u32(s, 16, from_i32(p.encoder_counts));
  put_u16(s, 20, from_i16(p.load_cell_adc));
  put_u16(s, 22, from_i16(p.actuator_dac));
  put_u16(s, 24, p.flags);
  put_u32(s, 26, p.last_command_sequence);
  put_u16(s, 30, p.commands_rejected);
  put_crc(s);
  return PacketError::kNone;
}

PacketError decode(std::span<const std::uint8_t> in, CommandPacket& out) noexcept {
  if (const PacketError e = check_frame(in, PacketType::kCommand, kCommandSize);
      e != PacketError::kNone) {
    return e;
  }
  if (in[11] != 0 || get_u16(in, 14) != 0) return PacketError::kBadField;
  CommandPacket p;
  p.sequence = get_u32(in, 4);
  p.watchdog_ms = get_u16(in, 8);
  p.flags = in[10];
  p.actuator_dac = to_i16(get_u16(in, 12));
  if (!command_fields_valid(p)) return PacketError::kBadField;
  out = p;
  return PacketError::kNone;
}

PacketError decode(std::span<const std::uint8_t> in, ReportPacket& out) noexcept {
  if (const PacketError e = check_frame(in, PacketType::kReport, kReportSize);
      e != PacketError::kNone) {
    return e;
  }
  ReportPacket p;
  p.sequence = get_u32(in, 4);
  p.device_time_us = get_u64(in, 8);
  p.encoder_counts = to_i32(get_u32(in, 16));
  p.load_cell_adc = to_i16(get_u16(in, 20));
  p.actuator_dac = to_i16(get_u16(in, 22));
  p.flags = get_u16(in, 24);
  p.last_command_sequence = get_u32(in, 26);
  p.commands_rejected = get_u16(in, 30);
  if (!report_fields_valid(p)) return PacketError::kBadField;
  out = p;
  return PacketError::kNone;
}

PacketError encode(const CommandPacketV2& p, PacketBuffer& out, std::size_t& size) noexcept {
  if (!channels_valid(p.channels)) return PacketError::kBadChannels;
  if (!command_fields_valid(p)) return PacketError::kBadField;
  size = command_size_v2(p.channels);
  const std::span<std::uint8_t> s = std::span<std::uint8_t>{out}.first(size);
  put_header_v2(s, PacketType::kCommand, p.channels);
  put_u8(s, kCmdFlags, p.flags);
  put_u16(s, kCmdWatchdog, p.watchdog_ms);
  put_u32(s, kCmdSequence, p.sequence);
  for (std::size_t i = 0; i < p.channels; ++i) {
    put_u16(s, kCmdDac + 2 * i, from_i16(p.actuator_dac[i]));
  }
  put_crc(s);
  return PacketError::kNone;
}

PacketError encode(const ReportPacketV2& p, PacketBuffer& out, std::size_t& size) noexcept {
  if (!channels_valid(p.channels)) return PacketError::kBadChannels;
  if (!report_fields_valid(p)) return PacketError::kBadField;
  size = report_size_v2(p.channels);
  const std::span<std::uint8_t> s = std::span<std::uint8_t>{out}.first(size);
  put_header_v2(s, PacketType::kReport, p.channels);
  put_u8(s, kRepFlags, p.flags);
  put_u16(s, kRepRejected, p.commands_rejected);
  put_u32(s, kRepSequence, p.sequence);
  put_u32(s, kRepLastCommand, p.last_command_sequence);
  put_u64(s, kRepTime, p.device_time_us);
  for (std::size_t i = 0; i < p.channels; ++i) {
    const std::size_t at = kRepChannel + kRepChannelStride * i;
    put_u32(s, at, from_i32(p.encoder_counts[i]));
    put_u16(s, at + 4, from_i16(p.load_cell_adc[i]));
  }
  put_crc(s);
  return PacketError::kNone;
}

PacketError decode_v2(std::span<const std::uint8_t> in, CommandPacketV2& out) noexcept {
  std::size_t n = 0;
  if (const PacketError e = check_frame_v2(in, PacketType::kCommand, n); e != PacketError::kNone) {
    return e;
  }
  CommandPacketV2 p;
  p.channels = static_cast<std::uint8_t>(n);
  p.flags = in[kCmdFlags];
  p.watchdog_ms = get_u16(in, kCmdWatchdog);
  p.sequence = get_u32(in, kCmdSequence);
  for (std::size_t i = 0; i < n; ++i) p.actuator_dac[i] = to_i16(get_u16(in, kCmdDac + 2 * i));
  if (!command_fields_valid(p)) return PacketError::kBadField;
  out = p;
  return PacketError::kNone;
}

PacketError decode_v2(std::span<const std::uint8_t> in, ReportPacketV2& out) noexcept {
  std::size_t n = 0;
  if (const PacketError e = check_frame_v2(in, PacketType::kReport, n); e != PacketError::kNone) {
    return e;
  }
  ReportPacketV2 p;
  p.channels = static_cast<std::uint8_t>(n);
  p.flags = in[kRepFlags];
  p.commands_rejected = get_u16(in, kRepRejected);
  p.sequence = get_u32(in, kRepSequence);
  p.last_command_sequence = get_u32(in, kRepLastCommand);
  p.device_time_us = get_u64(in, kRepTime);
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t at = kRepChannel + kRepChannelStride * i;
    p.encoder_counts[i] = to_i32(get_u32(in, at));
    p.load_cell_adc[i] = to_i16(get_u16(in, at + 4));
  }
  if (!report_fields_valid(p)) return PacketError::kBadField;
  out = p;
  return PacketError::kNone;
}

PacketError decode_any(std::span<const std::uint8_t> in, CommandPacketV2& out,
                       std::uint8_t& version) noexcept {
  if (in.size() >= 3 && in[2] == kProtocolVersion) {
    CommandPacket v1;
    const PacketError e = decode(in, v1);
    if (e != PacketError::kNone) return e;
    CommandPacketV2 p;
    p.sequence = v1.sequence;
    p.watchdog_ms = v1.watchdog_ms;
    p.flags = v1.flags;
    p.channels = 1;
    p.actuator_dac[0] = v1.actuator_dac;
    out = p;
    version = kProtocolVersion;
    return PacketError::kNone;
  }
  const PacketError e = decode_v2(in, out);
  if (e == PacketError::kNone) version = kProtocolVersion2;
  return e;
}

SequenceTracker::Result SequenceTracker::accept(std::uint32_t sequence) noexcept {
  if (!started_) {
    started_ = true;
    newest_ = sequence;
    return {};
  }
  const std::uint32_t ahead = sequence - newest_;  // modulo 2^32
  if (ahead == 0) return {PacketError::kDuplicate, 0};
  if (ahead >= 0x80000000U) return {PacketError::kOutOfOrder, 0};
  newest_ = sequence;
  return {PacketError::kNone, ahead - 1};
}

std::uint64_t PacketCounters::total_rejected() const noexcept {
  std::uint64_t total = 0;
  for (std::size_t i = 1; i < counts_.size(); ++i) total += counts_[i];
  return total;
}

double Scaling::position_m_per_count() const noexcept {
  return 2.0 * std::numbers::pi * metres_per_radian /
         (static_cast<double>(counts_per_rev) * transmission_ratio);
}

double Scaling::load_cell_N_per_count() const noexcept {
  return load_cell_full_scale_N / static_cast<double>(kRawFullScale);
}

double Scaling::actuator_N_per_count() const noexcept {
  return actuator_full_scale_N / static_cast<double>(kRawFullScale);
}

const char* Scaling::invalid_field() const noexcept {
  const auto positive = [](double v) { return std::isfinite(v) && v > 0.0; };
  if (counts_per_rev <= 0) return "scaling.counts_per_rev must be positive";
  if (!positive(transmission_ratio)) {
    return "scaling.transmission_ratio must be positive and finite";
  }
  if (!positive(metres_per_radian)) return "scaling.metres_per_radian must be positive and finite";
  if (!positive(load_cell_full_scale_N)) {
    return "scaling.load_cell_full_scale_N must be positive and finite";
  }
  if (!positive(actuator_full_scale_N)) {
    return "scaling.actuator_full_scale_N must be positive and finite";
  }
  return "";
}

DacValue force_to_dac(double force_N, const Scaling& scaling) noexcept {
  if (!std::isfinite(force_N)) return {0, false, PacketError::kNonFinite};
  const double counts = std::round(force_N / scaling.actuator_N_per_count());
  constexpr double kRail = kRawFullScale;
  if (counts > kRail) return {kRawFullScale, true, PacketError::kNone};
  if (counts < -kRail) return {static_cast<std::int16_t>(-kRawFullScale), true, PacketError::kNone};
  return {static_cast<std::int16_t>(counts), false, PacketError::kNone};
}

double dac_to_force_N(std::int16_t dac, const Scaling& scaling) noexcept {
  return static_cast<double>(dac) * scaling.actuator_N_per_count();
}

double adc_to_force_N(std::int16_t adc, const Scaling& scaling) noexcept {
  return static_cast<double>(adc) * scaling.load_cell_N_per_count();
}

double counts_to_position_m(std::int32_t counts, const Scaling& scaling) noexcept {
  return static_cast<double>(counts) * scaling.position_m_per_count();
}

DacValuesV2 forces_to_dacs(std::span<const double> forces_N, const Scaling& scaling,
                           CommandPacketV2& out) noexcept {
  if (!channels_valid(forces_N.size())) return {PacketError::kBadChannels, false};
  std::array<std::int16_t, kMaxChannels> dacs{};
  bool saturated = false;
  for (std::size_t i = 0; i < forces_N.size(); ++i) {
    const DacValue v = force_to_dac(forces_N[i], scaling);
    if (v.error != PacketError::kNone) return {v.error, false};
    dacs[i] = v.dac;
    saturated = saturated || v.saturated;
  }
  out.channels = static_cast<std::uint8_t>(forces_N.size());
  out.actuator_dac = dacs;
  return {PacketError::kNone, saturated};
}

}  // namespace teleop::device::usb
