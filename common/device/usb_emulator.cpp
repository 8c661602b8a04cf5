#include "common/device/usb_emulator.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <limits>
#include <mutex>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace teleop::device::usb {

struct MemoryLink::Queue {
  explicit Queue(std::size_t cap) : capacity(cap) {}

  std::mutex mutex;
  std::condition_variable not_empty;
  std::condition_variable not_full;
  std::deque<std::vector<std::uint8_t>> packets;
  std::size_t capacity;
};

namespace {

class MemoryEnd final : public Transport {
 public:
  MemoryEnd(std::shared_ptr<MemoryLink::Queue> out, std::shared_ptr<MemoryLink::Queue> in)
      : out_(std::move(out)), in_(std::move(in)) {}

  TransportStatus send(std::span<const std::uint8_t> packet,
                       std::chrono::milliseconds timeout) override {
    std::unique_lock lock(out_->mutex);
    if (!out_->not_full.wait_for(lock, timeout,
                                 [&] { return out_->packets.size() < out_->capacity; })) {
      return {TransportCode::kTimeout, "memory link full"};
    }
    out_->packets.emplace_back(packet.begin(), packet.end());
    lock.unlock();
    out_->not_empty.notify_one();
    return {};
  }

  TransportStatus receive(std::span<std::uint8_t> buffer, std::size_t& received,
                          std::chrono::milliseconds timeout) override {
    received = 0;
    std::unique_lock lock(in_->mutex);
    if (!in_->not_empty.wait_for(lock, timeout, [&] { return !in_->packets.empty(); })) {
      return {TransportCode::kTimeout, "nothing received"};
    }
    const std::vector<std::uint8_t> packet = std::move(in_->packets.front());
    in_->packets.pop_front();
    lock.unlock();
    in_->not_full.notify_one();
    if (packet.size() > buffer.size()) {
      return {TransportCode::kOverflow, "packet longer than the receive buffer"};
    }
    std::copy(packet.begin(), packet.end(), buffer.begin());
    received = packet.size();
    return {};
  }

 private:
  std::shared_ptr<MemoryLink::Queue> out_;
  std::shared_ptr<MemoryLink::Queue> in_;
};

void require(bool ok, const char* what) {
  if (!ok) throw std::invalid_argument(std::string("usb emulator: ") + what);
}

sim::Plant make_plant(const EmulatorConfig& c) {
  require(c.period > std::chrono::nanoseconds{0}, "period must be positive");
  const char* bad = c.scaling.invalid_field();
  require(*bad == '\0', bad);
  require(std::isfinite(c.initial_position_m), "initial_position_m must be finite");
  require(c.protocol_version == kProtocolVersion || c.protocol_version == kProtocolVersion2,
          "protocol_version must be 1 or 2");
  require(c.channels >= 1 && c.channels <= kMaxChannels, "channels must be in [1, 6]");
  require(c.channels == 1 || c.protocol_version == kProtocolVersion2,
          "channels above 1 need protocol_version 2");
  require(!c.amplifier_limit_N || (std::isfinite(*c.amplifier_limit_N) && *c.amplifier_limit_N > 0),
          "amplifier_limit_N must be positive and finite");
  sim::Plant plant(c.plant, c.period);
  plant.reset({c.initial_position_m, 0.0});
  return plant;
}

sim::LoadCellParams load_cell_params(const EmulatorConfig& c) {
  sim::LoadCellParams p;
  p.noise_std_N = c.load_cell_noise_std_N;
  // The ADC rails clip, not the cell: let the cell pass everything through.
  p.range_N = std::numeric_limits<double>::max();
  return p;
}

}  // namespace

MemoryLink::MemoryLink(std::size_t capacity_packets)
    : to_device_(std::make_shared<Queue>(std::max<std::size_t>(capacity_packets, 1))),
      to_host_(std::make_shared<Queue>(std::max<std::size_t>(capacity_packets, 1))) {}

MemoryLink::~MemoryLink() = default;

std::unique_ptr<Transport> MemoryLink::open_host() {
  return std::make_unique<MemoryEnd>(to_device_, to_host_);
}

std::unique_ptr<Transport> MemoryLink::open_device() {
  return std::make_unique<MemoryEnd>(to_host_, to_device_);
}

Emulator::Emulator(const EmulatorConfig& config, std::unique_ptr<Transport> transport)
    : config_(config),
      transport_(std::move(transport)),
      plant_(make_plant(config)),
      load_cell_(load_cell_params(config), config.seed),
      amplifier_limit_N_(config.amplifier_limit_N.value_or(config.scaling.actuator_full_scale_N)) {
  require(transport_ != nullptr, "transport must not be null");
  for (std::size_t i = 1; i < config_.channels; ++i) {
    extra_plants_.push_back(plant_);
    extra_load_cells_.emplace_back(load_cell_params(config), config.seed + i);
  }
  if (config_.channels > 1) report_version_ = kProtocolVersion2;
  // What the device would report at power-up; the first report goes out after the first step.
  fill_report(ReportFlags::kWatchdogTripped);
}

void Emulator::process_commands() {
  std::array<std::uint8_t, kMaxPacketSize> buffer{};
  for (;;) {
    std::size_t n = 0;
    const TransportStatus s = transport_->receive(buffer, n, std::chrono::milliseconds{0});
    if (s.code == TransportCode::kTimeout) return;
    if (!s.ok()) {
      // An overflowing packet is an oversized one the endpoint could not even hold.
      stats_.rejected.add(PacketError::kOversized);
      commands_rejected_wire_ = static_cast<std::uint16_t>(commands_rejected_wire_ + 1U);
      continue;
    }
    handle(std::span<const std::uint8_t>(buffer.data(), n));
  }
}

void Emulator::handle(std::span<const std::uint8_t> bytes) {
  CommandPacket c;
  // Version 2 (when spoken): the whole command; channel 0 also in `c`, as version 1's.
  CommandPacketV2 all;
  const bool v2 = config_.protocol_version == kProtocolVersion2 && bytes.size() >= 3 &&
                  bytes[2] == kProtocolVersion2;
  PacketError error = v2 ? decode_v2(bytes, all) : decode(bytes, c);
  if (v2 && error == PacketError::kNone) {
    if (all.channels != config_.channels) error = PacketError::kChannelMismatch;
    c.sequence = all.sequence;
    c.watchdog_ms = all.watchdog_ms;
    c.flags = all.flags;
    c.actuator_dac = all.actuator_dac[0];
  }
  std::uint32_t lost = 0;
  if (error == PacketError::kNone) {
    if ((c.flags & CommandFlags::kResync) != 0) sequence_.reset();
    const SequenceTracker::Result r = sequence_.accept(c.sequence);
    error = r.error;
    lost = r.lost;
  }
  if (error != PacketError::kNone) {
    // Refused commands change nothing: not the output, not the watchdog.
    stats_.rejected.add(error);
    commands_rejected_wire_ = static_cast<std::uint16_t>(commands_rejected_wire_ + 1U);
    return;
  }
  stats_.commands_accepted += 1;
  stats_.commands_lost += lost;
  command_ = c;
  channel_dac_ = v2 ? all.actuator_dac : std::array<std::int16_t, kMaxChannels>{};
  report_version_ = v2 ? kProtocolVersion2 : kProtocolVersion;
  last_command_time_ = time_;
  watchdog_ = std::chrono::milliseconds{c.watchdog_ms};
  // Only a deliberate disabled command re-arms: a host that stalled and resumes mid-stream
  // with kEnable set keeps getting 0 N until it goes through disabled.
  if (watchdog_tripped_ && (c.flags & CommandFlags::kEnable) == 0) watchdog_tripped_ = false;
}

void Emulator::step(std::chrono::nanoseconds period) {
  require(period > std::chrono::nanoseconds{0}, "step period must be positive");
  process_commands();
  if (!watchdog_tripped_ && (!last_command_time_ || time_ - *last_command_time_ >= watchdog_)) {
    watchdog_tripped_ = true;
  }

  std::uint16_t flags = 0;
  if (!deadman_pressed_) flags |= ReportFlags::kDeadmanReleased;
  if (estop_pressed_) flags |= ReportFlags::kEstopPressed;
  if (watchdog_tripped_) flags |= ReportFlags::kWatchdogTripped;
  if (fault_) flags |= ReportFlags::kFault;
  const bool drive = (flags & ReportFlags::kNoOutput) == 0 && command_ &&
                     (command_->flags & CommandFlags::kEnable) != 0;
  const std::int16_t dac = drive ? command_->actuator_dac : std::int16_t{0};
  const double requested_N = dac_to_force_N(dac, config_.scaling);
  output_force_N_ = std::clamp(requested_N, -amplifier_limit_N_, amplifier_limit_N_);
  if (dac == kRawFullScale || dac == -kRawFullScale || output_force_N_ != requested_N) {
    flags |= ReportFlags::kAmplifierSaturated;
  }
  report_.actuator_dac = dac;

  if (std::chrono::duration<double>(period).count() != plant_.period_s()) {
    plant_.set_period(period);
  }
  plant_.step(output_force_N_, external_force_N_);
  output_forces_N_[0] = output_force_N_;
  flags |= step_extra_channels(drive, period);
  time_ += period;
  report_sequence_ += 1;
  fill_report(flags);
  send_report();
}

std::uint16_t Emulator::step_extra_channels(bool drive, std::chrono::nanoseconds period) {
  std::uint16_t flags = 0;
  const Scaling& s = config_.scaling;
  for (std::size_t i = 1; i < config_.channels; ++i) {
    sim::Plant& plant = extra_plants_[i - 1];
    const std::int16_t dac = drive ? channel_dac_[i] : std::int16_t{0};
    const double requested_N = dac_to_force_N(dac, s);
    const double out_N = std::clamp(requested_N, -amplifier_limit_N_, amplifier_limit_N_);
    if (dac == kRawFullScale || dac == -kRawFullScale || out_N != requested_N) {
      flags |= ReportFlags::kAmplifierSaturated;
    }
    output_forces_N_[i] = out_N;
    if (std::chrono::duration<double>(period).count() != plant.period_s()) plant.set_period(period);
    plant.step(out_N, external_forces_N_[i]);
    const sim::PlantOutput& o = plant.output();
    const double true_force_N =
        config_.load_cell_measures_human ? o.human_force_N : o.environment_force_N;
    const double adc = std::round(extra_load_cells_[i - 1].measure(true_force_N).force_N /
                                  s.load_cell_N_per_count());
    constexpr double kRail = kRawFullScale;
    if (adc >= kRail || adc <= -kRail) flags |= ReportFlags::kLoadCellClipped;
    report_v2_.load_cell_adc[i] = static_cast<std::int16_t>(std::clamp(adc, -kRail, kRail));
    report_v2_.encoder_counts[i] = static_cast<std::int32_t>(
        std::llround(plant.state().position_m / s.position_m_per_count()));
  }
  return flags;
}

void Emulator::send_report() {
  if (report_version_ == kProtocolVersion2) {
    // Channel 0 and the common fields are version 1's report; the flags fit one byte (bits 0-5).
    report_v2_.sequence = report_.sequence;
    report_v2_.device_time_us = report_.device_time_us;
    report_v2_.flags = static_cast<std::uint8_t>(report_.flags & ReportFlags::kKnown);
    report_v2_.channels = static_cast<std::uint8_t>(config_.channels);
    report_v2_.last_command_sequence = report_.last_command_sequence;
    report_v2_.commands_rejected = report_.commands_rejected;
    report_v2_.encoder_counts[0] = report_.encoder_counts;
    report_v2_.load_cell_adc[0] = report_.load_cell_adc;
    PacketBuffer buffer{};
    std::size_t size = 0;
    if (encode(report_v2_, buffer, size) != PacketError::kNone) {
      stats_.report_send_failures += 1;  // unreachable: every field is built in range
      return;
    }
    if (transport_
            ->send(std::span<const std::uint8_t>(buffer.data(), size), std::chrono::milliseconds{0})
            .ok()) {
      stats_.reports_sent += 1;
    } else {
      stats_.report_send_failures += 1;
    }
    return;
  }
  ReportBytes bytes{};
  if (encode(report_, bytes) != PacketError::kNone) {
    stats_.report_send_failures += 1;  // unreachable: every field is built in range
    return;
  }
  if (transport_->send(bytes, std::chrono::milliseconds{0}).ok()) {
    stats_.reports_sent += 1;
  } else {
    stats_.report_send_failures += 1;
  }
}

void Emulator::set_external_force_N(std::size_t channel, double force_N) noexcept {
  if (channel == 0) {
    external_force_N_ = force_N;
  } else if (channel < config_.channels) {
    external_forces_N_[channel] = force_N;
  }
}

const sim::Plant& Emulator::plant(std::size_t channel) const noexcept {
  return channel == 0 || channel > extra_plants_.size() ? plant_ : extra_plants_[channel - 1];
}

void Emulator::fill_report(std::uint16_t flags) {
  const Scaling& s = config_.scaling;
  const sim::PlantOutput& out = plant_.output();
  const double true_force_N =
      config_.load_cell_measures_human ? out.human_force_N : out.environment_force_N;
  const double adc =
      std::round(load_cell_.measure(true_force_N).force_N / s.load_cell_N_per_count());
  constexpr double kRail = kRawFullScale;
  if (adc >= kRail || adc <= -kRail) flags |= ReportFlags::kLoadCellClipped;

  report_.sequence = report_sequence_;
  report_.device_time_us = static_cast<std::uint64_t>(
      std::chrono::duration_cast<std::chrono::microseconds>(time_).count());
  // The encoder counts from its index at 0 m, rounding to the nearest count as sim::Encoder.
  report_.encoder_counts =
      static_cast<std::int32_t>(std::llround(plant_.state().position_m / s.position_m_per_count()));
  report_.load_cell_adc = static_cast<std::int16_t>(std::clamp(adc, -kRail, kRail));
  report_.flags = flags;
  report_.last_command_sequence = command_ ? command_->sequence : 0U;
  report_.commands_rejected = commands_rejected_wire_;
}

}  // namespace teleop::device::usb
