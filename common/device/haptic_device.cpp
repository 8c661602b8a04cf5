#include "common/device/haptic_device.hpp"

#include "common/device/sim_device.hpp"
#include "common/device/usb_device.hpp"

namespace teleop::device {

const char* to_string(StatusCode code) noexcept {
  switch (code) {
    case StatusCode::kOk:
      return "ok";
    case StatusCode::kInvalidArgument:
      return "invalid argument";
    case StatusCode::kNotConfigured:
      return "not configured";
    case StatusCode::kNotActive:
      return "not active";
    case StatusCode::kUnavailable:
      return "unavailable";
    case StatusCode::kFault:
      return "fault";
  }
  return "unknown";
}

MakeDeviceResult make_device(DeviceKind kind, const SimDeviceConfig& sim,
                             const UsbDeviceConfig& usb) {
  switch (kind) {
    case DeviceKind::kSim:
      return {std::make_unique<SimDevice>(sim), Status::Ok()};
    case DeviceKind::kUsb:
      return {std::make_unique<UsbDevice>(usb), Status::Ok()};
  }
  return {nullptr, {StatusCode::kInvalidArgument, "unknown device kind"}};
}

MakeDeviceResult make_device(DeviceKind kind, const SimDeviceConfig& sim) {
  return make_device(kind, sim, UsbDeviceConfig{});
}

MakeDeviceResult make_device(DeviceKind kind) { return make_device(kind, SimDeviceConfig{}); }

}  // namespace teleop::device
