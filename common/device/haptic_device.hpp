// The one interface every haptic device implements (docs/architecture.md §4.4), simulated or real;
// chosen by configuration through make_device, never by scattered `if (sim)`.
//
// Lifecycle: configure() (setup: validate, allocate) -> activate() (start producing samples) ->
// read()/write() at the loop rate -> deactivate(). read() and write() are RT-safe: no
// allocation, no lock, no exception. Setup calls may allocate.
//
// Signs (docs/architecture.md §2.1): positions along the device's arc, positive into the
// fixture/environment. Command::force_N is the actuator's force on the device along +x. The
// master's law computes F_am with F_h - F_am = (m s^2 + b s) X_m, so the master node writes
// force_N = -F_am; the slave writes force_N = F_as. Sample::force_N is the load cell, compression
// positive: on the master the human's force on the handle (F_h), on the slave the device's force
// on its environment (F_e).
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>

#include "common/core/rt_safe.hpp"

namespace teleop::device {

enum class StatusCode : std::uint8_t {
  kOk,
  kInvalidArgument,
  kNotConfigured,
  kNotActive,
  kUnavailable,
  kFault,
};

// message points at a string literal or at storage owned by the device that returned it (valid
// until that device's next setup call): copying a Status never allocates.
struct [[nodiscard]] Status {
  StatusCode code{StatusCode::kOk};
  const char* message{""};

  [[nodiscard]] bool ok() const noexcept { return code == StatusCode::kOk; }
  [[nodiscard]] static Status Ok() noexcept { return {}; }
};

[[nodiscard]] const char* to_string(StatusCode code) noexcept;

// Bits of Sample::flags.
struct SampleFlags {
  static constexpr std::uint32_t kLoadCellClipped = 1U << 0;     // force outside the cell's range
  static constexpr std::uint32_t kAmplifierSaturated = 1U << 1;  // command clipped this period
  static constexpr std::uint32_t kFault = 1U << 2;  // e-stop engaged or device fault: no force
  static constexpr std::uint32_t kCommandRejected = 1U << 3;  // a non-finite command was refused
};

struct Sample {
  std::uint64_t sequence{0};  // increments with every new sample
  double time_s{0.0};         // device time of the sample
  double position_m{0.0};     // as sensed (quantised by the encoder)
  double force_N{0.0};        // load cell, compression positive
  std::uint32_t flags{0};
};

struct Command {
  double force_N{0.0};  // actuator force on the device along +x
};

class HapticDevice {
 public:
  virtual ~HapticDevice() = default;
  HapticDevice() = default;
  HapticDevice(const HapticDevice&) = delete;
  HapticDevice& operator=(const HapticDevice&) = delete;

  virtual Status configure() = 0;
  virtual Status activate() = 0;
  virtual Status deactivate() = 0;
  // The latest sample. RT-safe.
  TELEOP_RT virtual Status read(Sample& sample) noexcept = 0;
  // Held until the next write. RT-safe.
  TELEOP_RT virtual Status write(const Command& command) noexcept = 0;
  // End of the node's cycle, after write(): a simulated device steps its physics one period
  // here (the lockstep order: read, law, write, step); a real device has nothing to do.
  // RT-safe.
  TELEOP_RT virtual Status tick(std::chrono::nanoseconds /*period*/) noexcept {
    return Status::Ok();
  }
  // The node became engaged (from aligning: the first time, or again after a safe or a
  // disengage): a simulated device starts its scene (the human's push, a malicious user's
  // schedule) the first time, and its operator takes the scene's push up again later ones; a
  // real device ignores it. RT-safe.
  TELEOP_RT virtual void on_engaged() noexcept {}
  // The coupling ended (engaged or clutched -> aligning, armed, safe, fault): a simulated
  // operator stops following the scene and cooperates with the guidance (sim_device.hpp); a
  // real device ignores it. RT-safe.
  TELEOP_RT virtual void on_disengaged() noexcept {}
};

enum class DeviceKind { kSim, kUsb };

struct SimDeviceConfig;  // common/device/sim_device.hpp
struct UsbDeviceConfig;  // common/device/usb_host_link.hpp (included by usb_device.hpp)

struct MakeDeviceResult {
  std::unique_ptr<HapticDevice> device{};
  Status status{};
};

// The device the configuration names, unconfigured (call configure()). kSim: a SimDevice from
// sim. kUsb: a UsbDevice over libusb from usb; its configure() opens the device and, with none
// attached, returns kUnavailable "no USB haptic device attached: expected vendor 0x1209 product
// 0x7E1E (check the cable and udev permissions)".
[[nodiscard]] MakeDeviceResult make_device(DeviceKind kind, const SimDeviceConfig& sim,
                                           const UsbDeviceConfig& usb);
// As above with the default UsbDeviceConfig.
[[nodiscard]] MakeDeviceResult make_device(DeviceKind kind, const SimDeviceConfig& sim);
// As above with the default SimDeviceConfig (a haptic-paddle slave in free space).
[[nodiscard]] MakeDeviceResult make_device(DeviceKind kind);

}  // namespace teleop::device
