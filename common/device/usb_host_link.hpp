// The host's end of the USB link (docs/usb-protocol.md), shared by the one-axis UsbDevice
// (protocol version 1) and the n-axis UsbDeviceAxes (version 2, n channels): the transport, the
// I/O thread, the startup handshake, the sequence rule, the report timeout and the counters.
// What differs between the two devices is only what a report means (position, force, flags) and
// how a command becomes DAC values; each device is a UsbReportSink that turns an accepted report
// into its own sample.
//
// The I/O thread owns the transport: it receives the device's reports, hands each accepted one
// to the sink (which publishes a sample through its own lock-free buffer) and sends each newly
// submitted command once. submit() touches only a lock-free buffer, so it is RT-safe.
//
// Startup: activate() sends a disabled command with kResync (re-arming the device's watchdog,
// restarting its sequence tracking) and reports reach the sink once one acknowledges one of this
// activation's commands. Each submit() is sent once: the device's watchdog sees a stalled RT loop
// as silence, never as a repeated stale command. No accepted report for report_timeout: the link
// is lost (link_lost()).
//
// Version 2 only: a device whose CRC-valid reports are of version 1, or of version 2 with another
// channel count, is refused: its reports are counted (bad_version, channel_mismatch) and never
// reach the sink, and once the link is lost for want of an accepted report, mismatch() names why.
// The decision waits for the report timeout because a version-2 device reports in the version of
// the newest command it accepted: a previous version-1 session's reports may still arrive before
// it takes this session's first command.
#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <thread>

#include "common/core/rt_safe.hpp"
#include "common/device/haptic_device.hpp"
#include "common/device/usb_protocol.hpp"
#include "common/device/usb_transport.hpp"
#include "common/rt/latest_value.hpp"

namespace teleop::device {

struct UsbDeviceConfig {
  // Placeholders (the pid.codes vendor id, a product id not allocated to us): docs §1.
  std::uint16_t vendor_id{usb::kVendorId};
  std::uint16_t product_id{usb::kProductId};
  int interface_number{0};
  std::uint8_t endpoint_in{0x81};
  std::uint8_t endpoint_out{0x01};
  // Sent in every command: the device zeroes its output when no valid command arrived for
  // this long. Whole milliseconds in [1, 1000].
  std::chrono::milliseconds watchdog{usb::kDefaultWatchdogMs};
  // Encoder counts per motor turn and drive, load-cell and actuator full scales.
  usb::Scaling scaling{};
  // The I/O thread's receive wait: a written command waits at most this long when the device
  // is silent (reports normally wake it every device period).
  std::chrono::milliseconds poll_timeout{1};
  std::chrono::milliseconds send_timeout{5};
  // No accepted report for this long: read() flags kFault and returns kFault (link lost).
  std::chrono::milliseconds report_timeout{50};
};

// The real device's transport: libusb, opening the vendor and product ids of the configuration.
[[nodiscard]] std::unique_ptr<usb::Transport> open_usb_transport(const UsbDeviceConfig& config);

// The device's report flags as SampleFlags: deadman released, e-stop, watchdog tripped or fault
// -> kFault; amplifier saturated -> kAmplifierSaturated; load cell at a rail -> kLoadCellClipped.
[[nodiscard]] std::uint32_t usb_sample_flags(std::uint16_t device_flags) noexcept;

struct UsbLinkStats {
  std::uint64_t reports_accepted{0};
  std::uint64_t reports_lost{0};            // sequence gaps
  std::uint64_t reports_unacknowledged{0};  // valid reports before the startup handshake
  usb::PacketCounters rejected{};           // refused reports by reason
  std::uint64_t receive_failures{0};        // transport errors other than timeouts
  std::uint64_t commands_sent{0};
  std::uint64_t send_failures{0};
  std::uint64_t commands_non_finite{0};       // write() refusals of a NaN or infinite force
  std::uint64_t commands_wrong_axes{0};       // write() refusals of another number of axes
  std::uint16_t device_commands_rejected{0};  // the device's own count, from its reports
};

// One command's DAC values: channel 0 only in version 1, [0, n) in version 2.
struct UsbDacCommand {
  std::array<std::int16_t, usb::kMaxChannels> dac{};
};

// Receives the accepted, acknowledged reports on the I/O thread. A version-1 report arrives as
// a one-channel ReportPacketV2 (its DAC echo dropped, its flags in the low byte: only bits 0-5
// are defined).
class UsbReportSink {
 public:
  // sample_number: 1 for the first report of an activation, +1 per accepted report.
  virtual void on_report(std::uint64_t sample_number,
                         const usb::ReportPacketV2& report) noexcept = 0;

 protected:
  ~UsbReportSink() = default;
};

class UsbHostLink {
 public:
  using TransportFactory =
      std::function<std::unique_ptr<usb::Transport>(const UsbDeviceConfig& config)>;
  enum class Refusal : std::uint8_t { kNonFinite, kWrongAxes };

  // version 1 (channels 1) or 2 (channels in [1, 6]). `who` prefixes the error messages
  // ("usb device"); a string literal.
  UsbHostLink(UsbDeviceConfig config, TransportFactory open_transport, std::uint8_t version,
              std::size_t channels, const char* who, UsbReportSink& sink);
  ~UsbHostLink();
  UsbHostLink(const UsbHostLink&) = delete;
  UsbHostLink& operator=(const UsbHostLink&) = delete;

  // Stops the thread, validates the configuration (errors name the field) and opens the
  // transport (a factory's exception message becomes the status message).
  Status configure();
  // Stops the thread and closes the transport: unconfigured (an owner's refused configuration).
  void close() noexcept;
  // Starts the I/O thread. The owner resets its own sample state first, while inactive().
  Status activate();
  // Stops the I/O thread, which sends a disabled command (0 output at once) as its last act.
  Status deactivate();
  [[nodiscard]] bool configured() const noexcept { return stage_ != Stage::kUnconfigured; }
  [[nodiscard]] bool active() const noexcept { return stage_ == Stage::kActive; }

  // The next command to send. RT-safe.
  TELEOP_RT void submit(const UsbDacCommand& command) noexcept;
  // A refused write: 0 output on every channel is sent in its place, counted by reason. RT-safe.
  TELEOP_RT void refuse(Refusal reason) noexcept;
  // No accepted report for report_timeout. RT-safe.
  TELEOP_RT [[nodiscard]] bool link_lost() const noexcept {
    return link_lost_.load(std::memory_order_acquire);
  }
  // Version 2: when the link is lost and the device's newest valid reports were of version 1 or
  // of another channel count, the message naming which; else nullptr. RT-safe.
  TELEOP_RT [[nodiscard]] const char* mismatch() const noexcept;

  // A snapshot; safe from any thread.
  [[nodiscard]] UsbLinkStats stats() const noexcept;
  [[nodiscard]] const UsbDeviceConfig& config() const noexcept { return config_; }

 private:
  enum class Stage { kUnconfigured, kInactive, kActive };
  static constexpr std::size_t kReasons = static_cast<std::size_t>(usb::PacketError::kCount);
  // mismatch_: none, the device's channel count 1..6, or a version-1 device.
  static constexpr std::uint8_t kNoMismatch = 0;
  static constexpr std::uint8_t kVersion1 = 0xFF;

  void stop_thread() noexcept;
  void io_loop(const std::stop_token& stop);
  // true: the report was accepted (and handed to the sink).
  bool handle_report(std::span<const std::uint8_t> bytes);
  usb::PacketError decode_report(std::span<const std::uint8_t> bytes, usb::ReportPacketV2& out);
  bool send_command(std::uint8_t flags, const UsbDacCommand& command);
  void count(usb::PacketError error) noexcept;

  UsbDeviceConfig config_;
  TransportFactory open_transport_;
  std::uint8_t version_;
  std::size_t channels_;
  const char* who_;
  UsbReportSink& sink_;
  Stage stage_{Stage::kUnconfigured};
  std::unique_ptr<usb::Transport> transport_{};
  std::jthread io_thread_{};
  std::string error_{};
  // [0]: a version-1 device; [n]: a device of n channels (built by configure()).
  std::array<std::string, usb::kMaxChannels + 1> mismatch_messages_{};

  // I/O thread state (reset by activate() before the thread starts).
  usb::SequenceTracker report_sequence_{};
  std::uint32_t next_command_sequence_{1};
  std::uint32_t first_command_sequence_{1};
  bool acknowledged_{false};
  std::uint64_t samples_published_{0};

  // Between the threads.
  rt::LatestValue<UsbDacCommand> commands_{};
  std::atomic<bool> link_lost_{false};
  std::atomic<std::uint8_t> mismatch_{kNoMismatch};
  std::atomic<std::uint64_t> reports_accepted_{0};
  std::atomic<std::uint64_t> reports_lost_{0};
  std::atomic<std::uint64_t> reports_unacknowledged_{0};
  std::array<std::atomic<std::uint64_t>, kReasons> rejected_{};
  std::atomic<std::uint64_t> receive_failures_{0};
  std::atomic<std::uint64_t> commands_sent_{0};
  std::atomic<std::uint64_t> send_failures_{0};
  std::atomic<std::uint64_t> commands_non_finite_{0};
  std::atomic<std::uint64_t> commands_wrong_axes_{0};
  std::atomic<std::uint16_t> device_commands_rejected_{0};
};

}  // namespace teleop::device
