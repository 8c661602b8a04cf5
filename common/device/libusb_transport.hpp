// The real USB link: libusb-1.0, synchronous transfers on one claimed interface's IN and OUT
// endpoints (interrupt or bulk, as the interface descriptor says). Untested on the development
// machines (no USB bus there): docs/usb-protocol.md §11.
#pragma once

#include <cstdint>
#include <memory>

#include "common/device/usb_protocol.hpp"
#include "common/device/usb_transport.hpp"

struct libusb_context;
struct libusb_device_handle;

namespace teleop::device::usb {

struct LibusbTransportConfig {
  std::uint16_t vendor_id{kVendorId};
  std::uint16_t product_id{kProductId};
  int interface_number{0};
  std::uint8_t endpoint_in{0x81};
  std::uint8_t endpoint_out{0x01};
};

class LibusbTransport final : public Transport {
 public:
  // Opens the first device with the vendor and product id, detaches a kernel driver if one is
  // bound, claims the interface and checks both endpoints exist on it. Throws
  // std::runtime_error; with no matching device the message is "no USB haptic device
  // attached: expected vendor 0x1209 product 0x7E1E (check the cable and udev permissions)".
  [[nodiscard]] static std::unique_ptr<LibusbTransport> open(const LibusbTransportConfig& config);
  ~LibusbTransport() override;  // releases the interface, closes the device

  TransportStatus send(std::span<const std::uint8_t> packet,
                       std::chrono::milliseconds timeout) override;
  TransportStatus receive(std::span<std::uint8_t> buffer, std::size_t& received,
                          std::chrono::milliseconds timeout) override;

 private:
  LibusbTransport() = default;

  libusb_context* context_{nullptr};
  libusb_device_handle* handle_{nullptr};
  LibusbTransportConfig config_{};
  bool claimed_{false};
  bool in_is_interrupt_{true};
  bool out_is_interrupt_{true};
};

}  // namespace teleop::device::usb
