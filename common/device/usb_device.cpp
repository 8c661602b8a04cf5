#include "common/device/usb_device.hpp"

#include <utility>

namespace teleop::device {

UsbDevice::UsbDevice(UsbDeviceConfig config) : UsbDevice(std::move(config), open_usb_transport) {}

UsbDevice::UsbDevice(UsbDeviceConfig config, TransportFactory open_transport)
    : link_(std::move(config), std::move(open_transport), usb::kProtocolVersion, 1, "usb device",
            *this) {}

UsbDevice::~UsbDevice() { (void)link_.deactivate(); }

Status UsbDevice::configure() { return link_.configure(); }

Status UsbDevice::activate() {
  if (link_.configured() && !link_.active()) {
    Sample stale_sample;
    while (samples_.read(stale_sample)) {
    }
    latest_ = {};
    have_sample_ = false;
    command_rejected_ = false;
  }
  return link_.activate();
}

Status UsbDevice::deactivate() { return link_.deactivate(); }

Status UsbDevice::read(Sample& sample) noexcept {
  if (!link_.active()) return {StatusCode::kNotActive, "device not active"};
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
  if (link_.link_lost()) {
    sample.flags |= SampleFlags::kFault;
    return {StatusCode::kFault, "usb device: no report within report_timeout (link lost)"};
  }
  return Status::Ok();
}

Status UsbDevice::write(const Command& command) noexcept {
  if (!link_.active()) return {StatusCode::kNotActive, "device not active"};
  const usb::DacValue value = usb::force_to_dac(command.force_N, link_.config().scaling);
  if (value.error != usb::PacketError::kNone) {
    link_.refuse(UsbHostLink::Refusal::kNonFinite);
    command_rejected_ = true;
    return {StatusCode::kInvalidArgument, "non-finite force command refused"};
  }
  UsbDacCommand dacs;
  dacs.dac[0] = value.dac;
  link_.submit(dacs);
  return Status::Ok();
}

void UsbDevice::on_report(std::uint64_t sample_number, const usb::ReportPacketV2& r) noexcept {
  const usb::Scaling& scaling = link_.config().scaling;
  Sample s;
  s.sequence = sample_number;
  s.time_s = static_cast<double>(r.device_time_us) * 1e-6;
  s.position_m = usb::counts_to_position_m(r.encoder_counts[0], scaling);
  s.force_N = usb::adc_to_force_N(r.load_cell_adc[0], scaling);
  s.flags = usb_sample_flags(r.flags);
  samples_.write(s);
}

}  // namespace teleop::device
