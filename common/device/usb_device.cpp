#include "common/device/usb_device.hpp"

#include <exception>
#include <random>
#include <system_error>
#include <utility>

#include "common/device/libusb_transport.hpp"

namespace teleop::device {

namespace {

std::unique_ptr<usb::Transport> open_libusb(const UsbDeviceConfig& c) {
  usb::LibusbTransportConfig t;
  t.vendor_id = c.vendor_id;
  t.product_id = c.product_id;
  t.interface_number = c.interface_number;
  t.endpoint_in = c.endpoint_in;
  t.endpoint_out = c.endpoint_out;
  return usb::LibusbTransport::open(t);
}

std::uint32_t to_sample_flags(std::uint16_t device_flags) noexcept {
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

}  // namespace

UsbDevice::UsbDevice(UsbDeviceConfig config) : UsbDevice(std::move(config), open_libusb) {}

UsbDevice::UsbDevice(UsbDeviceConfig config, TransportFactory open_transport)
    : config_(std::move(config)), open_transport_(std::move(open_transport)) {}

UsbDevice::~UsbDevice() { stop_thread(); }

void UsbDevice::stop_thread() noexcept {
  if (io_thread_.joinable()) {
    io_thread_.request_stop();
    io_thread_.join();
  }
}

Status UsbDevice::configure() {
  stop_thread();
  stage_ = Stage::kUnconfigured;
  transport_.reset();
  const auto invalid = [this](const std::string& what) -> Status {
    error_ = "usb device: " + what;
    return {StatusCode::kInvalidArgument, error_.c_str()};
  };
  if (const char* bad = config_.scaling.invalid_field(); *bad != '\0') return invalid(bad);
  if (config_.watchdog < std::chrono::milliseconds{usb::kMinWatchdogMs} ||
      config_.watchdog > std::chrono::milliseconds{usb::kMaxWatchdogMs}) {
    return invalid("watchdog must be in [1, 1000] ms");
  }
  if (config_.endpoint_in < 0x81 || config_.endpoint_in > 0x8F) {
    return invalid("endpoint_in must be an IN endpoint address in [0x81, 0x8F]");
  }
  if (config_.endpoint_out < 0x01 || config_.endpoint_out > 0x0F) {
    return invalid("endpoint_out must be an OUT endpoint address in [0x01, 0x0F]");
  }
  if (config_.interface_number < 0 || config_.interface_number > 255) {
    return invalid("interface_number must be in [0, 255]");
  }
  if (config_.poll_timeout <= std::chrono::milliseconds{0}) {
    return invalid("poll_timeout must be positive");
  }
  if (config_.send_timeout <= std::chrono::milliseconds{0}) {
    return invalid("send_timeout must be positive");
  }
  if (config_.report_timeout <= std::chrono::milliseconds{0}) {
    return invalid("report_timeout must be positive");
  }
  if (!open_transport_) return invalid("no transport factory");
  try {
    transport_ = open_transport_(config_);
  } catch (const std::exception& e) {
    error_ = e.what();
    return {StatusCode::kUnavailable, error_.c_str()};
  }
  if (transport_ == nullptr) {
    return {StatusCode::kUnavailable, "usb device: the transport factory opened nothing"};
  }
  stage_ = Stage::kInactive;
  return Status::Ok();
}

Status UsbDevice::activate() {
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
  Sample stale_sample;
  while (samples_.read(stale_sample)) {
  }
  CommandSlot stale_command;
  while (commands_.read(stale_command)) {
  }
  latest_ = {};
  have_sample_ = false;
  command_rejected_ = false;

  stage_ = Stage::kActive;
  try {
    io_thread_ = std::jthread([this](const std::stop_token& stop) { io_loop(stop); });
  } catch (const std::system_error& e) {
    stage_ = Stage::kInactive;
    error_ = std::string("usb device: cannot start the I/O thread: ") + e.what();
    return {StatusCode::kFault, error_.c_str()};
  }
  return Status::Ok();
}

Status UsbDevice::deactivate() {
  if (stage_ == Stage::kUnconfigured) return {StatusCode::kNotConfigured, "not configured"};
  stop_thread();
  stage_ = Stage::kInactive;
  return Status::Ok();
}

Status UsbDevice::read(Sample& sample) noexcept {
  if (stage_ != Stage::kActive) return {StatusCode::kNotActive, "device not active"};
  Sample fresh;
  if (samples_.read(fresh)) {
    latest_ = fresh;
    if (command_rejected_) latest_.flags |= SampleFlags::kCommandRejected;
    command_rejected_ = false;
    have_sample_ = true;
  }
  if (!have_sample_) {
    return {StatusCode::kUnavailable, "usb device: no report acknowledging this activation yet"};
  }
  sample = latest_;
  if (link_lost_.load(std::memory_order_acquire)) {
    sample.flags |= SampleFlags::kFault;
    return {StatusCode::kFault, "usb device: no report within report_timeout (link lost)"};
  }
  return Status::Ok();
}

Status UsbDevice::write(const Command& command) noexcept {
  if (stage_ != Stage::kActive) return {StatusCode::kNotActive, "device not active"};
  const usb::DacValue value = usb::force_to_dac(command.force_N, config_.scaling);
  if (value.error != usb::PacketError::kNone) {
    commands_.write(CommandSlot{0});
    command_rejected_ = true;
    commands_non_finite_.fetch_add(1, std::memory_order_relaxed);
    return {StatusCode::kInvalidArgument, "non-finite force command refused"};
  }
  commands_.write(CommandSlot{value.dac});
  return Status::Ok();
}

UsbDevice::LinkStats UsbDevice::stats() const noexcept {
  constexpr auto relaxed = std::memory_order_relaxed;
  LinkStats s;
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
  s.device_commands_rejected = device_commands_rejected_.load(relaxed);
  return s;
}

bool UsbDevice::send_command(std::uint8_t flags, std::int16_t dac) {
  usb::CommandPacket p;
  // A failed send may still have reached the device: never reuse its number.
  p.sequence = next_command_sequence_++;
  p.watchdog_ms = static_cast<std::uint16_t>(config_.watchdog.count());
  p.flags = flags;
  p.actuator_dac = dac;
  usb::CommandBytes bytes{};
  if (usb::encode(p, bytes) != usb::PacketError::kNone ||
      !transport_->send(bytes, config_.send_timeout).ok()) {
    send_failures_.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  commands_sent_.fetch_add(1, std::memory_order_relaxed);
  return true;
}

void UsbDevice::io_loop(const std::stop_token& stop) {
  using Clock = std::chrono::steady_clock;
  // Resync and re-arm: the session starts disabled, its sequence taken as is.
  constexpr std::uint8_t kStart = usb::CommandFlags::kResync;
  bool started = send_command(kStart, 0);
  Clock::time_point last_report = Clock::now();
  std::array<std::uint8_t, usb::kMaxPacketSize> buffer{};
  while (!stop.stop_requested()) {
    std::size_t received = 0;
    const usb::TransportStatus status = transport_->receive(buffer, received, config_.poll_timeout);
    if (status.ok()) {
      // Clears link_lost_ itself before publishing, so a fresh sample never reads as lost.
      if (handle_report(std::span<const std::uint8_t>(buffer.data(), received))) {
        last_report = Clock::now();
      }
    } else if (status.code == usb::TransportCode::kOverflow) {
      rejected_[static_cast<std::size_t>(usb::PacketError::kOversized)].fetch_add(
          1, std::memory_order_relaxed);
    } else if (status.code != usb::TransportCode::kTimeout) {
      receive_failures_.fetch_add(1, std::memory_order_relaxed);
      // A broken bus fails at once: do not spin on it.
      std::this_thread::sleep_for(config_.poll_timeout);
    }
    if (Clock::now() - last_report > config_.report_timeout) {
      link_lost_.store(true, std::memory_order_release);
    }
    if (!started) started = send_command(kStart, 0);
    CommandSlot command;
    if (started && commands_.read(command)) {
      (void)send_command(usb::CommandFlags::kEnable, command.dac);
    }
  }
  // Leave the device at 0 N now rather than when its watchdog notices.
  (void)send_command(0, 0);
}

bool UsbDevice::handle_report(std::span<const std::uint8_t> bytes) {
  const auto count = [this](usb::PacketError e) {
    rejected_[static_cast<std::size_t>(e)].fetch_add(1, std::memory_order_relaxed);
  };
  usb::ReportPacket r;
  if (const usb::PacketError e = usb::decode(bytes, r); e != usb::PacketError::kNone) {
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
  Sample s;
  s.sequence = ++samples_published_;
  s.time_s = static_cast<double>(r.device_time_us) * 1e-6;
  s.position_m = usb::counts_to_position_m(r.encoder_counts, config_.scaling);
  s.force_N = usb::adc_to_force_N(r.load_cell_adc, config_.scaling);
  s.flags = to_sample_flags(r.flags);
  device_commands_rejected_.store(r.commands_rejected, std::memory_order_relaxed);
  reports_accepted_.fetch_add(1, std::memory_order_relaxed);
  link_lost_.store(false, std::memory_order_release);
  samples_.write(s);
  return true;
}

}  // namespace teleop::device
