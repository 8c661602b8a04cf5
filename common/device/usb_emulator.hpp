// The device side of the USB protocol without the hardware: an in-memory link standing in for
// the bus, and an emulator of the firmware (docs/usb-protocol.md §5-7) driving a simulated
// plant. Tests run the host's UsbDevice against it; the emulator's time is its own, advanced
// only by step(period), so its watchdog is measured in emulator time, never by sleeping.
#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include "common/device/usb_protocol.hpp"
#include "common/device/usb_transport.hpp"
#include "common/sim/plant.hpp"
#include "common/sim/sensors.hpp"

namespace teleop::device::usb {

// Two bounded packet queues, one per direction. open_host() and open_device() hand out ends
// (any number, sharing the queues: reopening after a close finds the same link). A send to a
// full queue waits up to its timeout, as a NAKed transfer does; send and receive are
// thread-safe, so the host's I/O thread and a test thread can sit on the two ends.
class MemoryLink {
 public:
  explicit MemoryLink(std::size_t capacity_packets = 256);
  ~MemoryLink();
  MemoryLink(const MemoryLink&) = delete;
  MemoryLink& operator=(const MemoryLink&) = delete;

  [[nodiscard]] std::unique_ptr<Transport> open_host();
  [[nodiscard]] std::unique_ptr<Transport> open_device();

  struct Queue;

 private:
  std::shared_ptr<Queue> to_device_;
  std::shared_ptr<Queue> to_host_;
};

struct EmulatorConfig {
  // The plant's own period (its propagators); step() with another period rebuilds them.
  std::chrono::nanoseconds period{std::chrono::milliseconds{1}};
  // The haptic-paddle slave of Abbott-Okamura §4.1 in free space, as SimDeviceConfig's default.
  sim::PlantParams plant{DeviceParams{0.036, 0.49}};
  Scaling scaling{};
  // The amplifier's current limit as a force; absent: the DAC's full scale.
  std::optional<double> amplifier_limit_N{};
  double load_cell_noise_std_N{0.0};
  std::uint64_t seed{1};
  // false: the load cell reads the environment force F_e (slave); true: the human's F_h (master).
  bool load_cell_measures_human{false};
  double initial_position_m{0.0};
  // The newest protocol version the firmware speaks: 1 (a version-1-only device: any other
  // version is refused as bad_version) or 2 (docs/usb-protocol.md "Version 2: n channels": it
  // takes commands of both and answers each host in the version of its newest accepted command;
  // before any, v1 when channels = 1, else v2).
  std::uint8_t protocol_version{kProtocolVersion};
  // n in [1, 6] (more than 1 needs protocol_version 2): independent channels, each a copy of
  // `plant` with its own load cell (seed + channel). Channel 0 is version 1's device; a v1 host
  // drives channel 0 only (the others output 0 N).
  std::size_t channels{1};
};

class Emulator {
 public:
  // Throws std::invalid_argument naming the field.
  Emulator(const EmulatorConfig& config, std::unique_ptr<Transport> transport);

  // Takes every command waiting on the link at the current emulator time (commands that arrive
  // between two steps are handled at the later step's start, as the firmware's USB interrupt
  // would). Time does not advance.
  void process_commands();
  // One firmware tick: process_commands(), the watchdog check at the current time, the output
  // (0 N when gated) held over period through the plant, time += period, then the sensors are
  // sampled and a report is sent.
  void step(std::chrono::nanoseconds period);

  // The handle's buttons and the fault line.
  void set_deadman_pressed(bool pressed) noexcept { deadman_pressed_ = pressed; }
  void set_estop_pressed(bool pressed) noexcept { estop_pressed_ = pressed; }
  void set_fault(bool fault) noexcept { fault_ = fault; }
  // Exogenous force on the handle along +x (a human's push), held over the following steps.
  void set_external_force_N(double force_N) noexcept { external_force_N_ = force_N; }
  // The same on one channel (channel 0 is the one above); channel < channels().
  void set_external_force_N(std::size_t channel, double force_N) noexcept;

  struct Stats {
    std::uint64_t commands_accepted{0};
    std::uint64_t commands_lost{0};  // sequence gaps
    PacketCounters rejected{};       // by reason, duplicates and out-of-order included
    std::uint64_t reports_sent{0};
    std::uint64_t report_send_failures{0};
  };
  [[nodiscard]] const Stats& stats() const noexcept { return stats_; }
  [[nodiscard]] std::chrono::nanoseconds time() const noexcept { return time_; }
  [[nodiscard]] bool watchdog_tripped() const noexcept { return watchdog_tripped_; }
  // The newest accepted command (meaningful once one was accepted).
  [[nodiscard]] const std::optional<CommandPacket>& command() const noexcept { return command_; }
  // The actuator's force over the last step, after gating and the amplifier's limit.
  [[nodiscard]] double output_force_N() const noexcept { return output_force_N_; }
  [[nodiscard]] const ReportPacket& last_report() const noexcept { return report_; }
  [[nodiscard]] const sim::Plant& plant() const noexcept { return plant_; }

  // Version 2. channel < channels() (channel 0: the accessors above).
  [[nodiscard]] std::size_t channels() const noexcept { return config_.channels; }
  [[nodiscard]] const sim::Plant& plant(std::size_t channel) const noexcept;
  [[nodiscard]] double output_force_N(std::size_t channel) const noexcept {
    return output_forces_N_[channel];
  }
  // The version the emulator reports in (that of the newest accepted command).
  [[nodiscard]] std::uint8_t report_version() const noexcept { return report_version_; }
  [[nodiscard]] const ReportPacketV2& last_report_v2() const noexcept { return report_v2_; }
  // The DAC value on `channel` of the newest accepted version-2 command (0 before any, and after
  // a version-1 command), as the host wrote it: before gating and the amplifier's limit.
  [[nodiscard]] std::int16_t commanded_dac(std::size_t channel) const noexcept {
    return channel_dac_[channel];
  }

 private:
  void handle(std::span<const std::uint8_t> bytes);
  // Samples the sensors into report_ (sequence, time, flags as given).
  void fill_report(std::uint16_t flags);
  // Channels 1..n-1 over one period: drive, plant, sensors into report_v2_; returns the flags
  // (saturated, clipped) they add.
  std::uint16_t step_extra_channels(bool drive, std::chrono::nanoseconds period);
  void send_report();

  EmulatorConfig config_;
  std::unique_ptr<Transport> transport_;
  sim::Plant plant_;
  sim::LoadCell load_cell_;
  double amplifier_limit_N_{0.0};
  std::chrono::nanoseconds time_{0};
  // Power-up is the tripped state: no output until a command with kEnable clear re-arms it.
  // Sequence tracking restarts only on kResync (docs/usb-protocol.md §6).
  bool watchdog_tripped_{true};
  std::optional<std::chrono::nanoseconds> last_command_time_{};
  std::chrono::milliseconds watchdog_{kDefaultWatchdogMs};
  SequenceTracker sequence_{};
  std::optional<CommandPacket> command_{};
  std::uint16_t commands_rejected_wire_{0};
  bool deadman_pressed_{true};
  bool estop_pressed_{false};
  bool fault_{false};
  double external_force_N_{0.0};
  double output_force_N_{0.0};
  std::uint32_t report_sequence_{0};
  ReportPacket report_{};
  Stats stats_{};
  // Version 2: channels 1..n-1 (index i - 1), their commands and outputs.
  std::vector<sim::Plant> extra_plants_{};
  std::vector<sim::LoadCell> extra_load_cells_{};
  std::array<std::int16_t, kMaxChannels> channel_dac_{};
  std::array<double, kMaxChannels> external_forces_N_{};  // [0] unused: external_force_N_
  std::array<double, kMaxChannels> output_forces_N_{};
  std::uint8_t report_version_{kProtocolVersion};
  ReportPacketV2 report_v2_{};
};

}  // namespace teleop::device::usb
