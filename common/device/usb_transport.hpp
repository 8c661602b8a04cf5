// What the USB device's codec sits on: one packet out, one packet in, each with a timeout.
// Implemented by libusb (libusb_transport.hpp) for the real device and by an in-memory link
// (usb_emulator.hpp) for the emulator the tests drive. Calls block up to their timeout: they
// belong on the device's I/O thread, never on the RT thread.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <span>

namespace teleop::device::usb {

enum class TransportCode : std::uint8_t {
  kOk,
  kTimeout,       // nothing arrived / the device did not take the packet in time
  kOverflow,      // the packet was longer than the receive buffer (its bytes are lost)
  kDisconnected,  // the device went away
  kError,         // anything else the bus reported
};

struct [[nodiscard]] TransportStatus {
  TransportCode code{TransportCode::kOk};
  const char* message{""};  // a string literal

  [[nodiscard]] bool ok() const noexcept { return code == TransportCode::kOk; }
};

class Transport {
 public:
  virtual ~Transport() = default;
  Transport() = default;
  Transport(const Transport&) = delete;
  Transport& operator=(const Transport&) = delete;

  // One packet to the device (OUT endpoint). Not RT-safe.
  virtual TransportStatus send(std::span<const std::uint8_t> packet,
                               std::chrono::milliseconds timeout) = 0;
  // One packet from the device (IN endpoint) into buffer; received is its length. Waits up to
  // timeout (0: only what is already there). Not RT-safe.
  virtual TransportStatus receive(std::span<std::uint8_t> buffer, std::size_t& received,
                                  std::chrono::milliseconds timeout) = 0;
};

}  // namespace teleop::device::usb
