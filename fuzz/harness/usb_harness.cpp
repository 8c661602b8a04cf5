// The USB device's packet codec (common/device/usb_protocol.hpp) on whatever arrives on the bus:
// reports as the host decodes them, commands as the firmware (the emulator) decodes them.
//
// Input: the whole input is first decoded as one packet of each type; then it is read as a
// stream of packets, each [u8 length][length bytes] (at most 64 packets; lengths up to 255, so
// oversized packets reach the receive buffer's overflow path). Checked:
// - a packet that decodes re-encodes to exactly its bytes, and has its type's size;
// - reports: the sequence rule counts every accepted packet once and moves only forwards, and
//   the SI conversions of an accepted report are finite;
// - commands, through an in-memory bus into the device emulator, one 1 ms step each: every
//   packet is counted once (accepted or refused by reason), the output force is finite, within
//   the actuator's full scale and zero while the watchdog is tripped, and every report the
//   emulator sends decodes on the host, in sequence.
// - version 2 (n channels): every input and packet also through decode_v2 (both types) and
//   decode_any: a packet that decodes has the size its n gives and re-encodes to its bytes; and
//   through a second emulator speaking v2 with 3 channels, checked as the first (every channel's
//   output finite and within full scale, every report it sends decodes in its version).
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <deque>
#include <memory>
#include <span>
#include <vector>

#include "common/device/usb_emulator.hpp"
#include "common/device/usb_protocol.hpp"
#include "fuzz/harness/fuzz_check.hpp"

namespace teleop::fuzz {
namespace {

namespace usb = device::usb;
using usb::PacketError;

constexpr std::size_t kMaxPackets = 64;

// The bus for the emulator, without waiting: the emulator's own MemoryLink blocks on condition
// variables even for a zero timeout (a futex wait per poll), which slowed fuzzing 5x.
struct Bus {
  std::deque<std::vector<std::uint8_t>> to_device{};
  std::deque<std::vector<std::uint8_t>> to_host{};
};

class BusEnd final : public usb::Transport {
 public:
  BusEnd(std::deque<std::vector<std::uint8_t>>& out, std::deque<std::vector<std::uint8_t>>& in)
      : out_(out), in_(in) {}
  usb::TransportStatus send(std::span<const std::uint8_t> packet,
                            std::chrono::milliseconds) override {
    out_.emplace_back(packet.begin(), packet.end());
    return {};
  }
  usb::TransportStatus receive(std::span<std::uint8_t> buffer, std::size_t& received,
                               std::chrono::milliseconds) override {
    received = 0;
    if (in_.empty()) return {usb::TransportCode::kTimeout, "nothing received"};
    const std::vector<std::uint8_t> packet = std::move(in_.front());
    in_.pop_front();
    // As a USB transfer into a buffer too small for the packet (libusb's LIBUSB_ERROR_OVERFLOW).
    if (packet.size() > buffer.size()) return {usb::TransportCode::kOverflow, "overflow"};
    std::copy(packet.begin(), packet.end(), buffer.begin());
    received = packet.size();
    return {};
  }

 private:
  std::deque<std::vector<std::uint8_t>>& out_;
  std::deque<std::vector<std::uint8_t>>& in_;
};

void check_command(std::span<const std::uint8_t> bytes) {
  usb::CommandPacket c;
  if (usb::decode(bytes, c) != PacketError::kNone) return;
  TELEOP_FUZZ_CHECK(bytes.size() == usb::kCommandSize, "a command of the wrong size decoded");
  usb::CommandBytes again{};
  TELEOP_FUZZ_CHECK(usb::encode(c, again) == PacketError::kNone, "a decoded command re-encodes");
  TELEOP_FUZZ_CHECK(std::equal(again.begin(), again.end(), bytes.begin()),
                    "decode/encode changed a command's bytes");
}

bool check_report(std::span<const std::uint8_t> bytes, usb::ReportPacket& r) {
  if (usb::decode(bytes, r) != PacketError::kNone) return false;
  TELEOP_FUZZ_CHECK(bytes.size() == usb::kReportSize, "a report of the wrong size decoded");
  usb::ReportBytes again{};
  TELEOP_FUZZ_CHECK(usb::encode(r, again) == PacketError::kNone, "a decoded report re-encodes");
  TELEOP_FUZZ_CHECK(std::equal(again.begin(), again.end(), bytes.begin()),
                    "decode/encode changed a report's bytes");
  const usb::Scaling scaling{};
  TELEOP_FUZZ_CHECK(std::isfinite(usb::counts_to_position_m(r.encoder_counts, scaling)) &&
                        std::isfinite(usb::adc_to_force_N(r.load_cell_adc, scaling)) &&
                        std::isfinite(usb::dac_to_force_N(r.actuator_dac, scaling)),
                    "non-finite SI value from an accepted report");
  TELEOP_FUZZ_CHECK(
      std::abs(usb::adc_to_force_N(r.load_cell_adc, scaling)) <= scaling.load_cell_full_scale_N,
      "load cell beyond full scale");
  return true;
}

void check_v2(std::span<const std::uint8_t> bytes) {
  usb::PacketBuffer again{};
  std::size_t size = 0;
  usb::CommandPacketV2 c;
  if (usb::decode_v2(bytes, c) == PacketError::kNone) {
    TELEOP_FUZZ_CHECK(c.channels >= 1 && c.channels <= usb::kMaxChannels, "v2 command n");
    TELEOP_FUZZ_CHECK(bytes.size() == usb::command_size_v2(c.channels), "v2 command size");
    TELEOP_FUZZ_CHECK(usb::encode(c, again, size) == PacketError::kNone, "v2 command re-encodes");
    TELEOP_FUZZ_CHECK(size == bytes.size() && std::equal(bytes.begin(), bytes.end(), again.begin()),
                      "decode/encode changed a v2 command's bytes");
  }
  usb::ReportPacketV2 r;
  if (usb::decode_v2(bytes, r) == PacketError::kNone) {
    TELEOP_FUZZ_CHECK(bytes.size() == usb::report_size_v2(r.channels), "v2 report size");
    TELEOP_FUZZ_CHECK(usb::encode(r, again, size) == PacketError::kNone, "v2 report re-encodes");
    TELEOP_FUZZ_CHECK(size == bytes.size() && std::equal(bytes.begin(), bytes.end(), again.begin()),
                      "decode/encode changed a v2 report's bytes");
    const usb::Scaling scaling{};
    for (std::size_t i = 0; i < r.channels; ++i) {
      TELEOP_FUZZ_CHECK(std::abs(usb::adc_to_force_N(r.load_cell_adc[i], scaling)) <=
                                scaling.load_cell_full_scale_N &&
                            std::isfinite(usb::counts_to_position_m(r.encoder_counts[i], scaling)),
                        "v2 report channel out of range");
    }
  }
  std::uint8_t version = 0;
  if (usb::decode_any(bytes, c, version) == PacketError::kNone) {
    TELEOP_FUZZ_CHECK(version == bytes[2], "decode_any's version is not byte 2");
    TELEOP_FUZZ_CHECK(version == usb::kProtocolVersion2 || c.channels == 1, "v1 as n = 1");
  }
}

// The v2 emulator's step checks, and every report it sent decodes in its version, in sequence.
void check_v2_emulator(usb::Emulator& emulator, BusEnd& host_end, usb::SequenceTracker& reports,
                       const usb::EmulatorConfig& config) {
  for (std::size_t i = 0; i < emulator.channels(); ++i) {
    const double out = emulator.output_force_N(i);
    TELEOP_FUZZ_CHECK(std::isfinite(out) && std::abs(out) <= config.scaling.actuator_full_scale_N,
                      "v2: output force beyond the actuator's full scale");
    TELEOP_FUZZ_CHECK(!emulator.watchdog_tripped() || out == 0.0, "v2: output while tripped");
  }
  usb::PacketBuffer buffer{};
  std::size_t received = 0;
  while (host_end.receive(buffer, received, std::chrono::milliseconds{0}).ok()) {
    const std::span<const std::uint8_t> bytes(buffer.data(), received);
    std::uint32_t sequence = 0;
    if (received >= 3 && buffer[2] == usb::kProtocolVersion2) {
      usb::ReportPacketV2 report;
      TELEOP_FUZZ_CHECK(usb::decode_v2(bytes, report) == PacketError::kNone,
                        "the v2 emulator sent a v2 report the host refuses");
      TELEOP_FUZZ_CHECK(report.channels == emulator.channels(), "v2 report of another n");
      sequence = report.sequence;
    } else {
      usb::ReportPacket report;
      TELEOP_FUZZ_CHECK(usb::decode(bytes, report) == PacketError::kNone,
                        "the v2 emulator sent a v1 report the host refuses");
      sequence = report.sequence;
    }
    const auto result = reports.accept(sequence);
    TELEOP_FUZZ_CHECK(result.error == PacketError::kNone && result.lost == 0,
                      "the v2 emulator's reports out of sequence");
  }
}

}  // namespace

int usb(const std::uint8_t* data, std::size_t size) {
  const std::span<const std::uint8_t> whole(data, size);
  check_command(whole);
  usb::ReportPacket ignored;
  (void)check_report(whole, ignored);
  check_v2(whole);

  const usb::EmulatorConfig config{};
  Bus bus;
  BusEnd host(bus.to_device, bus.to_host);
  usb::Emulator emulator(config, std::make_unique<BusEnd>(bus.to_host, bus.to_device));
  usb::SequenceTracker fuzzed_reports;  // the input's packets read as reports
  usb::SequenceTracker device_reports;  // what the emulator sends
  usb::EmulatorConfig config_v2{};
  config_v2.protocol_version = usb::kProtocolVersion2;
  config_v2.channels = 3;
  Bus bus_v2;
  BusEnd host_v2(bus_v2.to_device, bus_v2.to_host);
  usb::Emulator emulator_v2(config_v2, std::make_unique<BusEnd>(bus_v2.to_host, bus_v2.to_device));
  usb::SequenceTracker device_reports_v2;
  std::uint64_t delivered_v2 = 0;
  std::uint64_t delivered = 0;
  std::size_t pos = 0;
  for (std::size_t n = 0; n < kMaxPackets && pos < size; ++n) {
    const std::size_t length = std::min<std::size_t>(data[pos], size - pos - 1);
    const std::span<const std::uint8_t> packet(data + pos + 1, length);
    pos += 1 + length;

    check_command(packet);
    check_v2(packet);
    usb::ReportPacket r;
    if (check_report(packet, r)) {
      const std::uint32_t newest = fuzzed_reports.newest();
      const bool started = fuzzed_reports.started();
      const usb::SequenceTracker::Result result = fuzzed_reports.accept(r.sequence);
      if (result.error == PacketError::kNone) {
        TELEOP_FUZZ_CHECK(fuzzed_reports.newest() == r.sequence, "accepted but not the newest");
        TELEOP_FUZZ_CHECK(!started || result.lost == r.sequence - newest - 1U, "lost miscounted");
      } else {
        TELEOP_FUZZ_CHECK(fuzzed_reports.newest() == newest, "a refused sequence moved the newest");
        TELEOP_FUZZ_CHECK(result.error == (r.sequence == newest ? PacketError::kDuplicate
                                                                : PacketError::kOutOfOrder),
                          "wrong refusal");
      }
    }

    if (host.send(packet, std::chrono::milliseconds{0}).ok()) ++delivered;
    emulator.step(std::chrono::milliseconds{1});
    const usb::Emulator::Stats& s = emulator.stats();
    TELEOP_FUZZ_CHECK(s.commands_accepted + s.rejected.total_rejected() == delivered,
                      "a command not counted exactly once");
    const double out = emulator.output_force_N();
    TELEOP_FUZZ_CHECK(std::isfinite(out) && std::abs(out) <= config.scaling.actuator_full_scale_N,
                      "output force beyond the actuator's full scale");
    TELEOP_FUZZ_CHECK(!emulator.watchdog_tripped() || out == 0.0, "output while tripped");

    std::array<std::uint8_t, usb::kMaxPacketSize> buffer{};
    std::size_t received = 0;
    while (host.receive(buffer, received, std::chrono::milliseconds{0}).ok()) {
      usb::ReportPacket report;
      TELEOP_FUZZ_CHECK(usb::decode(std::span<const std::uint8_t>(buffer.data(), received),
                                    report) == PacketError::kNone,
                        "the emulator sent a report the host refuses");
      const auto result = device_reports.accept(report.sequence);
      TELEOP_FUZZ_CHECK(result.error == PacketError::kNone && result.lost == 0,
                        "the emulator's reports out of sequence");
    }

    if (host_v2.send(packet, std::chrono::milliseconds{0}).ok()) ++delivered_v2;
    emulator_v2.step(std::chrono::milliseconds{1});
    const usb::Emulator::Stats& s2 = emulator_v2.stats();
    TELEOP_FUZZ_CHECK(s2.commands_accepted + s2.rejected.total_rejected() == delivered_v2,
                      "v2: a command not counted exactly once");
    check_v2_emulator(emulator_v2, host_v2, device_reports_v2, config_v2);
  }
  return 0;
}

}  // namespace teleop::fuzz
