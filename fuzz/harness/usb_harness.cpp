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

}  // namespace

int usb(const std::uint8_t* data, std::size_t size) {
  const std::span<const std::uint8_t> whole(data, size);
  check_command(whole);
  usb::ReportPacket ignored;
  (void)check_report(whole, ignored);

  const usb::EmulatorConfig config{};
  Bus bus;
  BusEnd host(bus.to_device, bus.to_host);
  usb::Emulator emulator(config, std::make_unique<BusEnd>(bus.to_host, bus.to_device));
  usb::SequenceTracker fuzzed_reports;  // the input's packets read as reports
  usb::SequenceTracker device_reports;  // what the emulator sends
  std::uint64_t delivered = 0;
  std::size_t pos = 0;
  for (std::size_t n = 0; n < kMaxPackets && pos < size; ++n) {
    const std::size_t length = std::min<std::size_t>(data[pos], size - pos - 1);
    const std::span<const std::uint8_t> packet(data + pos + 1, length);
    pos += 1 + length;

    check_command(packet);
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
  }
  return 0;
}

}  // namespace teleop::fuzz
