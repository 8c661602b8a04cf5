#include "common/device/usb_host_link.hpp"

#include <exception>
#include <random>
#include <system_error>
#include <utility>

#include "common/device/libusb_transport.hpp"

namespace teleop::device {

std::unique_ptr<usb::Transport> open_usb_transport(const UsbDeviceConfig& c) {
  usb::LibusbTransportConfig t;
  t.vendor_id = c.vendor_id;
  t.product_id = c.product_id;
  t.interface_number = c.interface_number;
  t.endpoint_in = c.endpoint_in;
  t.endpoint_out = c.endpoint_out;
  return usb::LibusbTransport::open(t);
}

std::uint32_t usb_sample_flags(std::uint16_t device_flags) noexcept {
  std::uint32_t flags = 0;
  if ((device_flags & usb::ReportFlags::kNoOutput) != 0) flags |= SampleFlags::kFault;
  if ((device_flags & usb::ReportFlags::kAmplifierSaturated) != 0) {
    flags |= SampleFlags::kAmplifierSaturated;
  }
  if ((device_flags & usb::ReportFlags::kLoadCellClipped) != 0) {
    flags |= SampleFlags::kLoadCellClipped;
  }
  return flags;
}

namespace {

// The configuration's rules: "" when valid, else the field and why (a string literal).
const char* invalid_link_field(const UsbDeviceConfig& c) noexcept {
  if (const char* bad = c.scaling.invalid_field(); *bad != '\0') return bad;
  if (c.watchdog < std::chrono::milliseconds{usb::kMinWatchdogMs} ||
      c.watchdog > std::chrono::milliseconds{usb::kMaxWatchdogMs}) {
    return "watchdog must be in [1, 1000] ms";
  }
  if (c.endpoint_in < 0x81 || c.endpoint_in > 0x8F) {
    return "endpoint_in must be an IN endpoint address in [0x81, 0x8F]";
  }
  if (c.endpoint_out < 0x01 || c.endpoint_out > 0x0F) {
    return "endpoint_out must be an OUT endpoint address in [0x01, 0x0F]";
  }
  if (c.interface_number < 0 || c.interface_number > 255) {
    return "interface_number must be in [0, 255]";
  }
  if (c.poll_timeout <= std::chrono::milliseconds{0}) return "poll_timeout must be positive";
  if (c.send_timeout <= std::chrono::milliseconds{0}) return "send_timeout must be positive";
  if (c.report_timeout <= std::chrono::milliseconds{0}) return "report_timeout must be positive";
  return "";
}

}  // namespace

UsbHostLink::UsbHostLink(UsbDeviceConfig config, TransportFactory open_transport,
                         std::uint8_t version, std::size_t channels, const char* who,
                         UsbReportSink& sink)
    : config_(std::move(config)),
      open_transport_(std::move(open_transport)),
      version_(version),
      channels_(channels),
      who_(who),
      sink_(sink) {}

UsbHostLink::~UsbHostLink() { stop_thread(); }

void UsbHostLink::stop_thread() noexcept {
  if (io_thread_.joinable()) {
    io_thread_.request_stop();
    io_thread_.join();
  }
}

Status UsbHostLink::configure() {
  close();
  const auto invalid = [this](const std::string& what) -> Status {
    error_ = std::string(who_) + ": " + what;
    return {StatusCode::kInvalidArgument, error_.c_str()};
  };
  if (const char* bad = invalid_link_field(config_); *bad != '\0') return invalid(bad);
  const bool v1 = version_ == usb::kProtocolVersion && channels_ == 1;
  const bool v2 =
      version_ == usb::kProtocolVersion2 && channels_ >= 1 && channels_ <= usb::kMaxChannels;
  if (!v1 && !v2) return invalid("protocol version and channel count are not a valid pair");
  const std::string wanted = "this host speaks protocol version 2 with " +
                             std::to_string(channels_) + " channel" + (channels_ == 1 ? "" : "s");
  mismatch_messages_[0] = std::string(who_) +
                          ": the device answers in protocol version 1 only (a version-1-only "
                          "firmware, or a device of another channel count); " +
                          wanted;
  for (std::size_t n = 1; n <= usb::kMaxChannels; ++n) {
    mismatch_messages_[n] = std::string(who_) + ": the device has " + std::to_string(n) +
                            " channel" + (n == 1 ? "" : "s") + ", the configuration " +
                            std::to_string(channels_) + " axes; " + wanted;
  }
  if (!open_transport_) return invalid("no transport factory");
  try {
    transport_ = open_transport_(config_);
  } catch (const std::exception& e) {
    error_ = e.what();
    return {StatusCode::kUnavailable, error_.c_str()};
  }
  if (transport_ == nullptr) {
    error_ = std::string(who_) + ": the transport factory opened nothing";
    return {StatusCode::kUnavailable, error_.c_str()};
  }
  stage_ = Stage::kInactive;
  return Status::Ok();
}

void UsbHostLink::close() noexcept {
  stop_thread();
  stage_ = Stage::kUnconfigured;
  transport_.reset();
}

Status UsbHostLink::activate() {
  if (stage_ == Stage::kUnconfigured) return {StatusCode::kNotConfigured, "not configured"};
  if (stage_ == Stage::kActive) return Status::Ok();

  report_sequence_.reset();
  acknowledged_ = false;
  samples_published_ = 0;
  // Somewhere in [1, 2^31): a report echoing a previous run's command cannot pass for an
  // acknowledgement of this one's, and the range does not wrap for 2^31 commands.
  std::random_device entropy;
  first_command_sequence_ = 1U + (entropy() % 0x7FFFFFFEU);
  next_command_sequence_ = first_command_sequence_;
  link_lost_.store(false);
  mismatch_.store(kNoMismatch);
  UsbDacCommand stale_command;
  while (commands_.read(stale_command)) {
  }

  stage_ = Stage::kActive;
  try {
    io_thread_ = std::jthread([this](const std::stop_token& stop) { io_loop(stop); });
  } catch (const std::system_error& e) {
    stage_ = Stage::kInactive;
    error_ = std::string(who_) + ": cannot start the I/O thread: " + e.what();
    return {StatusCode::kFault, error_.c_str()};
  }
  return Status::Ok();
}

Status UsbHostLink::deactivate() {
  if (stage_ == Stage::kUnconfigured) return {StatusCode::kNotConfigured, "not configured"};
  stop_thread();
  stage_ = Stage::kInactive;
  return Status::Ok();
}

void UsbHostLink::submit(const UsbDacCommand& command) noexcept { commands_.write(command); }

void UsbHostLink::refuse(Refusal reason) noexcept {
  commands_.write(UsbDacCommand{});
  auto& counter = reason == Refusal::kNonFinite ? commands_non_finite_ : commands_wrong_axes_;
  counter.fetch_add(1, std::memory_order_relaxed);
}

const char* UsbHostLink::mismatch() const noexcept {
  if (!link_lost()) return nullptr;
  const std::uint8_t m = mismatch_.load(std::memory_order_acquire);
  if (m == kNoMismatch) return nullptr;
  if (m == kVersion1) return mismatch_messages_[0].c_str();
  return mismatch_messages_[m].c_str();
}

UsbLinkStats UsbHostLink::stats() const noexcept {
  constexpr auto relaxed = std::memory_order_relaxed;
  UsbLinkStats s;
  s.reports_accepted = reports_accepted_.load(relaxed);
  s.reports_lost = reports_lost_.load(relaxed);
  s.reports_unacknowledged = reports_unacknowledged_.load(relaxed);
  for (std::size_t i = 0; i < kReasons; ++i) {
    s.rejected.add(static_cast<usb::PacketError>(i), rejected_[i].load(relaxed));
  }
  s.receive_failures = receive_failures_.load(relaxed);
  s.commands_sent = commands_sent_.load(relaxed);
  s.send_failures = send_failures_.load(relaxed);
  s.commands_non_finite = commands_non_finite_.load(relaxed);
  s.commands_wrong_axes = commands_wrong_axes_.load(relaxed);
  s.device_commands_rejected = device_commands_rejected_.load(relaxed);
  return s;
}

void UsbHostLink::count(usb::PacketError error) noexcept {
  rejected_[static_cast<std::size_t>(error)].fetch_add(1, std::memory_order_relaxed);
}

bool UsbHostLink::send_command(std::uint8_t flags, const UsbDacCommand& command) {
  // A failed send may still have reached the device: never reuse its number.
  const std::uint32_t sequence = next_command_sequence_++;
  const auto watchdog_ms = static_cast<std::uint16_t>(config_.watchdog.count());
  bool sent = false;
  if (version_ == usb::kProtocolVersion) {
    usb::CommandPacket p;
    p.sequence = sequence;
    p.watchdog_ms = watchdog_ms;
    p.flags = flags;
    p.actuator_dac = command.dac[0];
    usb::CommandBytes bytes{};
    sent = usb::encode(p, bytes) == usb::PacketError::kNone &&
           transport_->send(bytes, config_.send_timeout).ok();
  } else {
    usb::CommandPacketV2 p;
    p.sequence = sequence;
    p.watchdog_ms = watchdog_ms;
    p.flags = flags;
    p.channels = static_cast<std::uint8_t>(channels_);
    p.actuator_dac = command.dac;
    usb::PacketBuffer bytes{};
    std::size_t size = 0;
    sent = usb::encode(p, bytes, size) == usb::PacketError::kNone &&
           transport_->send(std::span<const std::uint8_t>(bytes.data(), size), config_.send_timeout)
               .ok();
  }
  if (!sent) {
    send_failures_.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  commands_sent_.fetch_add(1, std::memory_order_relaxed);
  return true;
}

void UsbHostLink::io_loop(const std::stop_token& stop) {
  using Clock = std::chrono::steady_clock;
  // Resync and re-arm: the session starts disabled, its sequence taken as is.
  constexpr std::uint8_t kStart = usb::CommandFlags::kResync;
  const UsbDacCommand zero{};
  bool started = send_command(kStart, zero);
  Clock::time_point last_report = Clock::now();
  usb::PacketBuffer buffer{};
  while (!stop.stop_requested()) {
    std::size_t received = 0;
    const usb::TransportStatus status = transport_->receive(buffer, received, config_.poll_timeout);
    if (status.ok()) {
      // Clears link_lost_ itself before publishing, so a fresh sample never reads as lost.
      if (handle_report(std::span<const std::uint8_t>(buffer.data(), received))) {
        last_report = Clock::now();
      }
    } else if (status.code == usb::TransportCode::kOverflow) {
      count(usb::PacketError::kOversized);
    } else if (status.code != usb::TransportCode::kTimeout) {
      receive_failures_.fetch_add(1, std::memory_order_relaxed);
      // A broken bus fails at once: do not spin on it.
      std::this_thread::sleep_for(config_.poll_timeout);
    }
    if (Clock::now() - last_report > config_.report_timeout) {
      link_lost_.store(true, std::memory_order_release);
    }
    if (!started) started = send_command(kStart, zero);
    UsbDacCommand command;
    if (started && commands_.read(command)) {
      (void)send_command(usb::CommandFlags::kEnable, command);
    }
  }
  // Leave the device at 0 output now rather than when its watchdog notices.
  (void)send_command(0, zero);
}

usb::PacketError UsbHostLink::decode_report(std::span<const std::uint8_t> bytes,
                                            usb::ReportPacketV2& out) {
  usb::ReportPacket v1;
  if (version_ == usb::kProtocolVersion) {
    if (const usb::PacketError e = usb::decode(bytes, v1); e != usb::PacketError::kNone) return e;
    out.sequence = v1.sequence;
    out.device_time_us = v1.device_time_us;
    out.flags = static_cast<std::uint8_t>(v1.flags);  // bits 0-5 only (decode checks)
    out.channels = 1;
    out.last_command_sequence = v1.last_command_sequence;
    out.commands_rejected = v1.commands_rejected;
    out.encoder_counts[0] = v1.encoder_counts;
    out.load_cell_adc[0] = v1.load_cell_adc;
    return usb::PacketError::kNone;
  }
  const usb::PacketError e = usb::decode_v2(bytes, out);
  if (e == usb::PacketError::kBadVersion) {
    // A whole, CRC-checked version-1 report: the device speaks version 1 (to us, for now).
    if (usb::decode(bytes, v1) == usb::PacketError::kNone) {
      mismatch_.store(kVersion1, std::memory_order_release);
    }
    return e;
  }
  if (e == usb::PacketError::kNone && out.channels != channels_) {
    mismatch_.store(out.channels, std::memory_order_release);
    return usb::PacketError::kChannelMismatch;
  }
  return e;
}

bool UsbHostLink::handle_report(std::span<const std::uint8_t> bytes) {
  usb::ReportPacketV2 r;
  if (const usb::PacketError e = decode_report(bytes, r); e != usb::PacketError::kNone) {
    count(e);
    return false;
  }
  const usb::SequenceTracker::Result order = report_sequence_.accept(r.sequence);
  if (order.error != usb::PacketError::kNone) {
    count(order.error);
    return false;
  }
  reports_lost_.fetch_add(order.lost, std::memory_order_relaxed);
  if (!acknowledged_) {
    // Serial-number distance into this activation's commands [first, next).
    const std::uint32_t offset = r.last_command_sequence - first_command_sequence_;
    const std::uint32_t sent = next_command_sequence_ - first_command_sequence_;
    if (offset >= sent) {
      reports_unacknowledged_.fetch_add(1, std::memory_order_relaxed);
      return false;
    }
    acknowledged_ = true;
  }
  device_commands_rejected_.store(r.commands_rejected, std::memory_order_relaxed);
  reports_accepted_.fetch_add(1, std::memory_order_relaxed);
  mismatch_.store(kNoMismatch, std::memory_order_release);
  link_lost_.store(false, std::memory_order_release);
  sink_.on_report(++samples_published_, r);
  return true;
}

}  // namespace teleop::device
