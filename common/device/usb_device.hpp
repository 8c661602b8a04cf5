// The USB haptic device (docs/usb-protocol.md): the HapticDevice interface over the packet
// protocol, version 1. The link (transport, I/O thread, handshake, sequences, timeouts,
// counters) is UsbHostLink (usb_host_link.hpp), shared with the n-axis UsbDeviceAxes; this class
// turns its reports into Samples and forces into DAC values. An I/O thread owns the transport: it
// receives the device's reports into a latest-value buffer and sends each newly written command;
// read() and write() touch only the two lock-free buffers, so they are RT-safe.
//
// Startup: activate() sends a disabled command with kResync (re-arming the device's watchdog,
// restarting its sequence tracking) and samples flow once a report acknowledges one of this
// activation's commands; until then read() returns kUnavailable. Each write() is sent once: the
// device's watchdog sees a stalled RT loop as silence, never as a repeated stale command.
#pragma once

#include <cstdint>
#include <memory>

#include "common/core/rt_safe.hpp"
#include "common/device/haptic_device.hpp"
#include "common/device/usb_host_link.hpp"
#include "common/device/usb_protocol.hpp"
#include "common/device/usb_transport.hpp"
#include "common/rt/latest_value.hpp"

namespace teleop::device {

class UsbDevice final : public HapticDevice, private UsbReportSink {
 public:
  // Opens the link when configure() runs; may throw (its message becomes the status message).
  using TransportFactory = UsbHostLink::TransportFactory;

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
  // map to SampleFlags (usb_sample_flags). kUnavailable before the first acknowledged report;
  // kFault with kFault set when the link is lost. RT-safe.
  TELEOP_RT Status read(Sample& sample) noexcept override;
  // Scales to DAC counts (clipped at full scale) for the I/O thread to send. A non-finite
  // force is refused: kInvalidArgument, 0 N sent, kCommandRejected in the next sample. RT-safe.
  TELEOP_RT Status write(const Command& command) noexcept override;

  using LinkStats = UsbLinkStats;
  // A snapshot; safe from any thread.
  [[nodiscard]] LinkStats stats() const noexcept { return link_.stats(); }
  [[nodiscard]] const UsbDeviceConfig& config() const noexcept { return link_.config(); }

 private:
  // On the I/O thread: an accepted report becomes a Sample.
  void on_report(std::uint64_t sample_number, const usb::ReportPacketV2& report) noexcept override;

  UsbHostLink link_;
  rt::LatestValue<Sample> samples_{};

  // RT thread state.
  Sample latest_{};
  bool have_sample_{false};
  bool command_rejected_{false};
};

}  // namespace teleop::device
