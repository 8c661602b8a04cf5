#include "common/device/libusb_transport.hpp"

#include <fmt/format.h>
#include <libusb.h>

#include <algorithm>
#include <array>
#include <limits>
#include <stdexcept>
#include <string>

namespace teleop::device::usb {

namespace {

std::string expected_ids(const LibusbTransportConfig& c) {
  return fmt::format("vendor 0x{:04X} product 0x{:04X}", c.vendor_id, c.product_id);
}

[[noreturn]] void fail_not_attached(const LibusbTransportConfig& c, const std::string& detail) {
  throw std::runtime_error("no USB haptic device attached: expected " + expected_ids(c) + " (" +
                           detail + "check the cable and udev permissions)");
}

std::string libusb_error(int code) {
  return fmt::format("{} ({})", libusb_error_name(code), libusb_strerror(code));
}

// libusb takes 0 as "wait forever": the shortest finite wait is 1 ms.
unsigned int timeout_ms(std::chrono::milliseconds timeout) {
  const auto ms = timeout.count();
  if (ms <= 0) return 1U;
  if (ms > std::numeric_limits<int>::max()) return std::numeric_limits<int>::max();
  return static_cast<unsigned int>(ms);
}

// One interrupt or bulk transfer (as the endpoint's descriptor says), in either direction
// (the endpoint address carries it); libusb's return code.
int transfer(libusb_device_handle* handle, bool interrupt, unsigned char endpoint,
             unsigned char* data, int length, int& transferred, std::chrono::milliseconds timeout) {
  return interrupt ? libusb_interrupt_transfer(handle, endpoint, data, length, &transferred,
                                               timeout_ms(timeout))
                   : libusb_bulk_transfer(handle, endpoint, data, length, &transferred,
                                          timeout_ms(timeout));
}

TransportStatus status_of(int rc) {
  switch (rc) {
    case LIBUSB_SUCCESS:
      return {TransportCode::kOk, ""};
    case LIBUSB_ERROR_TIMEOUT:
      return {TransportCode::kTimeout, "usb transfer timed out"};
    case LIBUSB_ERROR_OVERFLOW:
      return {TransportCode::kOverflow, "usb packet longer than the receive buffer"};
    case LIBUSB_ERROR_NO_DEVICE:
      return {TransportCode::kDisconnected, "usb device disconnected"};
    case LIBUSB_ERROR_PIPE:
      return {TransportCode::kError, "usb endpoint stalled"};
    default:
      return {TransportCode::kError, "usb transfer failed"};
  }
}

struct DeviceList {
  libusb_device** devices{nullptr};
  ~DeviceList() {
    if (devices != nullptr) libusb_free_device_list(devices, 1);
  }
};

struct ConfigDescriptor {
  libusb_config_descriptor* descriptor{nullptr};
  ~ConfigDescriptor() {
    if (descriptor != nullptr) libusb_free_config_descriptor(descriptor);
  }
};

}  // namespace

std::unique_ptr<LibusbTransport> LibusbTransport::open(const LibusbTransportConfig& config) {
  // The destructor releases whatever was acquired when a later step throws.
  std::unique_ptr<LibusbTransport> t{new LibusbTransport()};
  t->config_ = config;

  // Without a USB bus (no usbfs) libusb itself cannot start: still "no device attached".
  if (const int rc = libusb_init(&t->context_); rc != LIBUSB_SUCCESS) {
    t->context_ = nullptr;
    fail_not_attached(config, "libusb could not start: " + libusb_error(rc) + "; ");
  }

  DeviceList list;
  const ssize_t count = libusb_get_device_list(t->context_, &list.devices);
  if (count < 0) {
    fail_not_attached(config,
                      "cannot list USB devices: " + libusb_error(static_cast<int>(count)) + "; ");
  }
  libusb_device* match = nullptr;
  for (ssize_t i = 0; i < count && match == nullptr; ++i) {
    libusb_device_descriptor d{};
    if (libusb_get_device_descriptor(list.devices[i], &d) != LIBUSB_SUCCESS) continue;
    if (d.idVendor == config.vendor_id && d.idProduct == config.product_id) {
      match = list.devices[i];
    }
  }
  if (match == nullptr) fail_not_attached(config, "");

  if (const int rc = libusb_open(match, &t->handle_); rc != LIBUSB_SUCCESS) {
    t->handle_ = nullptr;
    throw std::runtime_error("USB haptic device " + expected_ids(config) +
                             " found but cannot be opened: " + libusb_error(rc) +
                             " (check the udev permissions)");
  }

  // The endpoints must be on the interface, and their type decides the transfer call.
  ConfigDescriptor cfg;
  if (const int rc = libusb_get_active_config_descriptor(match, &cfg.descriptor);
      rc != LIBUSB_SUCCESS) {
    throw std::runtime_error("USB haptic device " + expected_ids(config) +
                             ": cannot read its configuration: " + libusb_error(rc));
  }
  bool found_in = false;
  bool found_out = false;
  for (int i = 0; i < cfg.descriptor->bNumInterfaces; ++i) {
    const libusb_interface& itf = cfg.descriptor->interface[i];
    for (int a = 0; a < itf.num_altsetting; ++a) {
      const libusb_interface_descriptor& alt = itf.altsetting[a];
      if (alt.bInterfaceNumber != config.interface_number || alt.bAlternateSetting != 0) continue;
      for (int e = 0; e < alt.bNumEndpoints; ++e) {
        const libusb_endpoint_descriptor& ep = alt.endpoint[e];
        const int type = ep.bmAttributes & LIBUSB_TRANSFER_TYPE_MASK;
        const bool interrupt = type == LIBUSB_TRANSFER_TYPE_INTERRUPT;
        if (!interrupt && type != LIBUSB_TRANSFER_TYPE_BULK) continue;
        if (ep.bEndpointAddress == config.endpoint_in) {
          found_in = true;
          t->in_is_interrupt_ = interrupt;
        } else if (ep.bEndpointAddress == config.endpoint_out) {
          found_out = true;
          t->out_is_interrupt_ = interrupt;
        }
      }
    }
  }
  if (!found_in || !found_out) {
    std::string missing;
    if (!found_in) missing += fmt::format(" IN 0x{:02X}", config.endpoint_in);
    if (!found_out) missing += fmt::format(" OUT 0x{:02X}", config.endpoint_out);
    throw std::runtime_error(
        fmt::format("USB haptic device {}: interface {} lacks the interrupt or bulk endpoint(s){}",
                    expected_ids(config), config.interface_number, missing));
  }

  if (const int rc = libusb_set_auto_detach_kernel_driver(t->handle_, 1);
      rc != LIBUSB_SUCCESS && rc != LIBUSB_ERROR_NOT_SUPPORTED) {
    throw std::runtime_error("USB haptic device " + expected_ids(config) +
                             ": cannot detach the kernel driver: " + libusb_error(rc));
  }
  if (const int rc = libusb_claim_interface(t->handle_, config.interface_number);
      rc != LIBUSB_SUCCESS) {
    throw std::runtime_error(fmt::format(
        "USB haptic device {}: cannot claim interface {}: {} (another program holds it?)",
        expected_ids(config), config.interface_number, libusb_error(rc)));
  }
  t->claimed_ = true;
  return t;
}

LibusbTransport::~LibusbTransport() {
  if (claimed_) libusb_release_interface(handle_, config_.interface_number);
  if (handle_ != nullptr) libusb_close(handle_);
  if (context_ != nullptr) libusb_exit(context_);
}

TransportStatus LibusbTransport::send(std::span<const std::uint8_t> packet,
                                      std::chrono::milliseconds timeout) {
  if (packet.size() > kMaxPacketSize) return {TransportCode::kError, "usb packet too long"};
  // libusb takes a non-const buffer for both directions; an OUT transfer only reads it.
  std::array<unsigned char, kMaxPacketSize> buffer{};
  std::copy(packet.begin(), packet.end(), buffer.begin());
  int transferred = 0;
  const int length = static_cast<int>(packet.size());
  const int rc = transfer(handle_, out_is_interrupt_, config_.endpoint_out, buffer.data(), length,
                          transferred, timeout);
  if (rc != LIBUSB_SUCCESS) return status_of(rc);
  if (transferred != length) return {TransportCode::kError, "usb packet sent in part"};
  return {};
}

TransportStatus LibusbTransport::receive(std::span<std::uint8_t> buffer, std::size_t& received,
                                         std::chrono::milliseconds timeout) {
  received = 0;
  int transferred = 0;
  const int length =
      static_cast<int>(std::min<std::size_t>(buffer.size(), std::numeric_limits<int>::max()));
  const int rc = transfer(handle_, in_is_interrupt_, config_.endpoint_in, buffer.data(), length,
                          transferred, timeout);
  if (rc != LIBUSB_SUCCESS) return status_of(rc);
  received = static_cast<std::size_t>(transferred);
  return {};
}

}  // namespace teleop::device::usb
