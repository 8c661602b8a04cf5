// The USB haptic device's packet protocol, version 1 (docs/usb-protocol.md is the spec): the
// codec for the two packet types, the sequence rule both sides apply, and the scaling between
// the raw wire integers and SI units. Pure functions on fixed-size buffers: no allocation, no
// exception, so both the host's I/O thread and the device emulator use them as they are.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

#include "common/core/defaults.hpp"

namespace teleop::device::usb {

// Placeholders: the pid.codes open-source vendor id and a product id not allocated to this
// project. A shipped device needs its own allocation (docs/usb-protocol.md §1).
inline constexpr std::uint16_t kVendorId = defaults::kUsbVendorId;
inline constexpr std::uint16_t kProductId = defaults::kUsbProductId;

// "TH" on the wire (0x54 0x48): bytes 0-1, frozen across versions, as are version (byte 2)
// and type (byte 3).
inline constexpr std::uint16_t kMagic = 0x4854;
inline constexpr std::uint8_t kProtocolVersion = 1;

inline constexpr std::size_t kCommandSize = 20;
inline constexpr std::size_t kReportSize = 36;
// A full-speed interrupt/bulk endpoint's largest packet: receive buffers hold this much, so an
// oversized packet up to it is seen (and rejected) rather than overflowing the transfer.
inline constexpr std::size_t kMaxPacketSize = 64;

// Full scale of the signed 16-bit actuator DAC and load-cell ADC: +-32767 (-32768 is invalid,
// keeping the scale symmetric).
inline constexpr std::int16_t kRawFullScale = 32767;

inline constexpr std::uint16_t kMinWatchdogMs = 1;
inline constexpr std::uint16_t kMaxWatchdogMs = 1000;
inline constexpr std::uint16_t kDefaultWatchdogMs =
    static_cast<std::uint16_t>(defaults::kUsbWatchdog.count());

enum class PacketType : std::uint8_t {
  kCommand = 0x01,  // host -> device, OUT endpoint
  kReport = 0x02,   // device -> host, IN endpoint
};

// Bits of CommandPacket::flags; the others must be zero.
struct CommandFlags {
  // Drive the actuator with actuator_dac. Clear: the device outputs 0 N, and an accepted
  // command with this bit clear is what re-arms a tripped watchdog.
  static constexpr std::uint8_t kEnable = 1U << 0;
  // The first command of a host session: the device takes it whatever its sequence and tracks
  // sequences from it. Only valid with kEnable clear, so every session starts at 0 N.
  static constexpr std::uint8_t kResync = 1U << 1;
  static constexpr std::uint8_t kKnown = kEnable | kResync;
};

// Bits of ReportPacket::flags; the others must be zero.
struct ReportFlags {
  static constexpr std::uint16_t kDeadmanReleased = 1U << 0;     // output forced to 0 N
  static constexpr std::uint16_t kEstopPressed = 1U << 1;        // output forced to 0 N
  static constexpr std::uint16_t kWatchdogTripped = 1U << 2;     // latched; output forced to 0 N
  static constexpr std::uint16_t kAmplifierSaturated = 1U << 3;  // DAC at a rail or current-limited
  static constexpr std::uint16_t kFault = 1U << 4;  // device fault (over-temperature, encoder...)
  static constexpr std::uint16_t kLoadCellClipped = 1U << 5;  // ADC at a rail
  static constexpr std::uint16_t kKnown = 0x3F;
  // Any of these means no force reaches the handle.
  static constexpr std::uint16_t kNoOutput =
      kDeadmanReleased | kEstopPressed | kWatchdogTripped | kFault;
};

// Host -> device, 20 bytes.
struct CommandPacket {
  std::uint32_t sequence{0};
  std::uint16_t watchdog_ms{kDefaultWatchdogMs};  // in [1, 1000]
  std::uint8_t flags{0};
  std::int16_t actuator_dac{0};  // in [-32767, 32767]; full scale = Scaling::actuator_full_scale_N
};

// Device -> host, 36 bytes.
struct ReportPacket {
  std::uint32_t sequence{0};
  std::uint64_t device_time_us{0};  // the device's clock at the sample
  std::int32_t encoder_counts{0};
  std::int16_t load_cell_adc{0};  // in [-32767, 32767]; full scale = load_cell_full_scale_N
  std::int16_t actuator_dac{0};   // what the DAC outputs this period (0 when gated)
  std::uint16_t flags{0};
  std::uint32_t last_command_sequence{0};  // the newest accepted command (0: none yet)
  std::uint16_t commands_rejected{0};      // commands the device refused, wrapping
};

using CommandBytes = std::array<std::uint8_t, kCommandSize>;
using ReportBytes = std::array<std::uint8_t, kReportSize>;

// Why a packet (or a command value) was refused. Receivers count each reason.
enum class PacketError : std::uint8_t {
  kNone,
  kTruncated,   // shorter than its type's size (or than the 4 frozen bytes)
  kOversized,   // longer than its type's size
  kBadMagic,    // bytes 0-1 are not "TH"
  kBadVersion,  // another protocol version: its layout is unknown, nothing else is read
  kBadType,     // not the type this side receives
  kBadCrc,      // CRC-32 over the bytes before it does not match
  kBadField,    // a reserved byte or flag bit set, a value out of its range
  kNonFinite,   // a NaN or infinite force the host refused to put on the wire
  kDuplicate,   // sequence equal to the newest accepted one
  kOutOfOrder,  // sequence older than the newest accepted one
  // Version 2 (docs/usb-protocol.md "Version 2: n channels"):
  kBadChannels,      // the channel count n (byte 4) outside [1, kMaxChannels]
  kChannelMismatch,  // a v2 command whose n is not the device's channel count
  kCount,
};

[[nodiscard]] const char* to_string(PacketError error) noexcept;

// CRC-32 (IEEE 802.3, reflected, poly 0xEDB88320, init and xorout 0xFFFFFFFF; zlib's crc32):
// "123456789" -> 0xCBF43926.
[[nodiscard]] std::uint32_t crc32(std::span<const std::uint8_t> bytes) noexcept;

// kBadField when a value is out of its range (nothing written then).
[[nodiscard]] PacketError encode(const CommandPacket& packet, CommandBytes& out) noexcept;
[[nodiscard]] PacketError encode(const ReportPacket& packet, ReportBytes& out) noexcept;
// Checks, in order: truncated (< 4 bytes), magic, version, type, size, CRC, fields. `out` is
// written only when the result is kNone.
[[nodiscard]] PacketError decode(std::span<const std::uint8_t> bytes, CommandPacket& out) noexcept;
[[nodiscard]] PacketError decode(std::span<const std::uint8_t> bytes, ReportPacket& out) noexcept;

// ---- Version 2: n channels (docs/usb-protocol.md "Version 2: n channels") ----
// The same frozen bytes 0-3 (version 2), the channel count n at byte 4, then the v1 fields with
// n values per channel, the CRC-32 over every byte before it. The length follows from n, so a
// length that does not match is refused. Both types fit kMaxPacketSize at n = 6 (the report
// exactly: it carries no per-channel actuator echo and its flags are one byte, see the docs).
inline constexpr std::uint8_t kProtocolVersion2 = 2;
inline constexpr std::size_t kMaxChannels = 6;

[[nodiscard]] constexpr std::size_t command_size_v2(std::size_t channels) noexcept {
  return 16 + 2 * channels;
}
[[nodiscard]] constexpr std::size_t report_size_v2(std::size_t channels) noexcept {
  return 28 + 6 * channels;
}
static_assert(command_size_v2(kMaxChannels) <= kMaxPacketSize);
static_assert(report_size_v2(kMaxChannels) <= kMaxPacketSize);

// Host -> device, 16 + 2n bytes.
struct CommandPacketV2 {
  std::uint32_t sequence{0};
  std::uint16_t watchdog_ms{kDefaultWatchdogMs};          // in [1, 1000]
  std::uint8_t flags{0};                                  // CommandFlags
  std::uint8_t channels{1};                               // n in [1, kMaxChannels]
  std::array<std::int16_t, kMaxChannels> actuator_dac{};  // [0, n) used, each in [-32767, 32767]
};

// Device -> host, 28 + 6n bytes.
struct ReportPacketV2 {
  std::uint32_t sequence{0};
  std::uint64_t device_time_us{0};
  std::uint8_t flags{0};     // ReportFlags bits 0-5 (saturated / clipped: any channel)
  std::uint8_t channels{1};  // n in [1, kMaxChannels]
  std::uint32_t last_command_sequence{0};
  std::uint16_t commands_rejected{0};
  std::array<std::int32_t, kMaxChannels> encoder_counts{};  // [0, n) used
  std::array<std::int16_t, kMaxChannels> load_cell_adc{};   // [0, n) used, in [-32767, 32767]
};

// Any packet of either version fits.
using PacketBuffer = std::array<std::uint8_t, kMaxPacketSize>;

// kBadChannels / kBadField when a value is out of its range (nothing written then); else the
// packet is out[0, size).
[[nodiscard]] PacketError encode(const CommandPacketV2& packet, PacketBuffer& out,
                                 std::size_t& size) noexcept;
[[nodiscard]] PacketError encode(const ReportPacketV2& packet, PacketBuffer& out,
                                 std::size_t& size) noexcept;
// Version 2 only (a v1 packet is kBadVersion). Checks, in order: truncated (< 4 bytes), magic,
// version, type, truncated (< 5 bytes), n in [1, 6] (kBadChannels), the size for n, CRC, fields.
// `out` is written only when the result is kNone.
[[nodiscard]] PacketError decode_v2(std::span<const std::uint8_t> bytes,
                                    CommandPacketV2& out) noexcept;
[[nodiscard]] PacketError decode_v2(std::span<const std::uint8_t> bytes,
                                    ReportPacketV2& out) noexcept;
// A reader of both versions: a v1 packet (byte 2 = 1) goes through the v1 decoder unchanged and
// comes out as n = 1 (its actuator_dac in channel 0), anything else through decode_v2.
// `version` is the packet's version when the result is kNone.
[[nodiscard]] PacketError decode_any(std::span<const std::uint8_t> bytes, CommandPacketV2& out,
                                     std::uint8_t& version) noexcept;

// The receiver's sequence rule (both directions): the first packet after reset() is accepted;
// after that a packet is accepted when it is newer in 32-bit serial-number arithmetic (RFC 1982:
// 0 < s - newest < 2^31), the skipped numbers counted as lost; equal is a duplicate, older is
// out of order, and both are dropped.
class SequenceTracker {
 public:
  struct Result {
    PacketError error{PacketError::kNone};  // kNone, kDuplicate or kOutOfOrder
    std::uint32_t lost{0};                  // packets skipped before this one
  };

  void reset() noexcept { started_ = false; }
  [[nodiscard]] Result accept(std::uint32_t sequence) noexcept;
  [[nodiscard]] bool started() const noexcept { return started_; }
  [[nodiscard]] std::uint32_t newest() const noexcept { return newest_; }

 private:
  bool started_{false};
  std::uint32_t newest_{0};
};

// Counts of refused packets by reason.
class PacketCounters {
 public:
  void add(PacketError error, std::uint64_t count = 1) noexcept {
    counts_[static_cast<std::size_t>(error)] += count;
  }
  [[nodiscard]] std::uint64_t operator[](PacketError error) const noexcept {
    return counts_[static_cast<std::size_t>(error)];
  }
  [[nodiscard]] std::uint64_t total_rejected() const noexcept;  // all but kNone

 private:
  std::array<std::uint64_t, static_cast<std::size_t>(PacketError::kCount)> counts_{};
};

// The hardware's scaling between wire integers and SI units: a property of the device (its
// encoder, drive, load cell and amplifier), configured identically on the host and in the
// firmware. Defaults: the haptic paddle of common/sim/sensors.hpp (500 counts per motor turn,
// 10:1 capstan, 0.115 m of arc per paddle radian), its +-10 N load cell and 16.5 N amplifier.
struct Scaling {
  int counts_per_rev{500};
  double transmission_ratio{10.0};
  double metres_per_radian{0.115};
  double load_cell_full_scale_N{10.0};  // force at ADC +32767
  double actuator_full_scale_N{16.5};   // force at DAC +32767

  // 2 pi metres_per_radian / (counts_per_rev transmission_ratio).
  [[nodiscard]] double position_m_per_count() const noexcept;
  [[nodiscard]] double load_cell_N_per_count() const noexcept;
  [[nodiscard]] double actuator_N_per_count() const noexcept;  // one DAC step
  // Empty when valid, else the name of the first bad field and why (a string literal).
  [[nodiscard]] const char* invalid_field() const noexcept;
};

struct DacValue {
  std::int16_t dac{0};
  bool saturated{false};                  // clipped to +-32767
  PacketError error{PacketError::kNone};  // kNonFinite: dac is 0
};

// round(force / step), clipped to +-32767. A non-finite force gives kNonFinite and 0.
[[nodiscard]] DacValue force_to_dac(double force_N, const Scaling& scaling) noexcept;
[[nodiscard]] double dac_to_force_N(std::int16_t dac, const Scaling& scaling) noexcept;
[[nodiscard]] double adc_to_force_N(std::int16_t adc, const Scaling& scaling) noexcept;
[[nodiscard]] double counts_to_position_m(std::int32_t counts, const Scaling& scaling) noexcept;

// Per-channel force_to_dac of forces_N (1..kMaxChannels entries, else kBadChannels):
// each rounded and clipped to +-32767 (`saturated` tells whether any was); a non-finite force
// anywhere refuses the whole command (kNonFinite, `out` untouched), as v1 refuses one.
struct DacValuesV2 {
  PacketError error{PacketError::kNone};
  bool saturated{false};
};
[[nodiscard]] DacValuesV2 forces_to_dacs(std::span<const double> forces_N, const Scaling& scaling,
                                         CommandPacketV2& out) noexcept;

}  // namespace teleop::device::usb
