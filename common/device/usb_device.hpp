// The USB haptic device (docs/usb-protocol.md): the HapticDevice interface over the packet
// protocol. An I/O thread owns the transport: it receives the device's reports into a
// latest-value buffer and sends each newly written command; read() and write() touch only the
// two lock-free buffers, so they are RT-safe.
//
// Startup: activate() sends a disabled command with kResync (re-arming the device's watchdog,
// restarting its sequence tracking) and samples flow once a report acknowledges one of this
// activation's commands; until then read() returns kUnavailable. Each write() is sent once: the
// device's watchdog sees a stalled RT loop as silence, never as a repeated stale command.
#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
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

class UsbDevice final : public HapticDevice {
 public:
  // Opens the link when configure() runs; may throw (its message becomes the status message).
  using TransportFactory =
      std::function<std::unique_ptr<usb::Transport>(const UsbDeviceConfig& config)>;

  // The real device over libusb.
  explicit UsbDevice(UsbDeviceConfig config);
  // Any transport (the tests: the emulator's in-memory link).
  UsbDevice(UsbDeviceConfig config, TransportFactory open_transport);
  ~UsbDevice() override;

  // Validates the configuration (errors name the field) and opens the transport: on this
  // machine kUnavailable, "no USB haptic device attached: expected vendor 0x1209 product 0x7E1E
  // (check the cable and udev permissions)".
  Status configure() override;
  // Starts the I/O thread (see above).
  Status activate() override;
  // Sends a disabled command (0 N at once, not after the watchdog) and stops the I/O thread.
  Status deactivate() override;
  // The newest sample: position from encoder counts, force from the load cell. Device flags
  // map to SampleFlags: deadman released, e-stop, watchdog tripped or fault -> kFault;
  // amplifier saturated -> kAmplifierSaturated; load cell at a rail -> kLoadCellClipped.
  // kUnavailable before the first acknowledged report; kFault with kFault set when the link is
  // lost. RT-safe.
  TELEOP_RT Status read(Sample& sample) noexcept override;
  // Scales to DAC counts (clipped at full scale) for the I/O thread to send. A non-finite
  // force is refused: kInvalidArgument, 0 N sent, kCommandRejected in the next sample. RT-safe.
  TELEOP_RT Status write(const Command& command) noexcept override;

  struct LinkStats {
    std::uint64_t reports_accepted{0};
    std::uint64_t reports_lost{0};            // sequence gaps
    std::uint64_t reports_unacknowledged{0};  // valid reports before the startup handshake
    usb::PacketCounters rejected{};           // refused reports by reason
    std::uint64_t receive_failures{0};        // transport errors other than timeouts
    std::uint64_t commands_sent{0};
    std::uint64_t send_failures{0};
    std::uint64_t commands_non_finite{0};       // write() refusals
    std::uint16_t device_commands_rejected{0};  // the device's own count, from its reports
  };
  // A snapshot; safe from any thread.
  [[nodiscard]] LinkStats stats() const noexcept;
  [[nodiscard]] const UsbDeviceConfig& config() const noexcept { return config_; }

 private:
  enum class Stage { kUnconfigured, kInactive, kActive };
  struct CommandSlot {
    std::int16_t dac{0};
  };
  static constexpr std::size_t kReasons = static_cast<std::size_t>(usb::PacketError::kCount);

  void stop_thread() noexcept;
  void io_loop(const std::stop_token& stop);
  // true: a sample was published.
  bool handle_report(std::span<const std::uint8_t> bytes);
  bool send_command(std::uint8_t flags, std::int16_t dac);

  UsbDeviceConfig config_;
  TransportFactory open_transport_;
  Stage stage_{Stage::kUnconfigured};
  std::unique_ptr<usb::Transport> transport_{};
  std::jthread io_thread_{};
  std::string error_{};

  // I/O thread state (reset by activate() before the thread starts).
  usb::SequenceTracker report_sequence_{};
  std::uint32_t next_command_sequence_{1};
  std::uint32_t first_command_sequence_{1};
  bool acknowledged_{false};
  std::uint64_t samples_published_{0};

  // Between the threads.
  rt::LatestValue<Sample> samples_{};
  rt::LatestValue<CommandSlot> commands_{};
  std::atomic<bool> link_lost_{false};
  std::atomic<std::uint64_t> reports_accepted_{0};
  std::atomic<std::uint64_t> reports_lost_{0};
  std::atomic<std::uint64_t> reports_unacknowledged_{0};
  std::array<std::atomic<std::uint64_t>, kReasons> rejected_{};
  std::atomic<std::uint64_t> receive_failures_{0};
  std::atomic<std::uint64_t> commands_sent_{0};
  std::atomic<std::uint64_t> send_failures_{0};
  std::atomic<std::uint64_t> commands_non_finite_{0};
  std::atomic<std::uint16_t> device_commands_rejected_{0};

  // RT thread state.
  Sample latest_{};
  bool have_sample_{false};
  bool command_rejected_{false};
};

}  // namespace teleop::device
