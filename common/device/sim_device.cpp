#include "common/device/sim_device.hpp"

#include <exception>
#include <stdexcept>
#include <utility>

namespace teleop::device {

SimDeviceConfig SimDeviceConfig::paddle_master(sim::HumanParams human) {
  SimDeviceConfig c;
  c.plant.device = DeviceParams{0.040, 0.41};
  c.human = std::move(human);
  return c;
}

SimDeviceConfig SimDeviceConfig::paddle_slave(sim::Environment environment) {
  SimDeviceConfig c;
  c.plant.device = DeviceParams{0.036, 0.49};
  c.plant.environment = environment;
  return c;
}

SimDevice::SimDevice(SimDeviceConfig config) : config_(std::move(config)) {}

Status SimDevice::configure() {
  stage_ = Stage::kUnconfigured;
  try {
    if (config_.period <= std::chrono::nanoseconds{0}) {
      throw std::invalid_argument("period must be positive");
    }
    sim::PlantParams plant = config_.plant;
    human_.reset();
    malicious_index_.reset();
    if (config_.human) {
      human_.emplace(*config_.human);
      plant.human = human_->impedance_at(0.0);
      malicious_index_ = human_->malicious_index_at(0.0);
    }
    current_human_ = plant.human;
    plant_.emplace(plant, config_.period);
    plant_->reset({config_.initial_position_m, 0.0});
    encoder_.emplace(config_.encoder);
    load_cell_.emplace(config_.load_cell, config_.seed);
    amplifier_.emplace(config_.amplifier);
  } catch (const std::exception& e) {
    error_ = std::string("sim device: ") + e.what();
    return {StatusCode::kInvalidArgument, error_.c_str()};
  }
  time_ = std::chrono::nanoseconds{0};
  scene_origin_.reset();
  command_ = {};
  command_rejected_ = false;
  applied_force_N_ = 0.0;
  last_push_N_ = 0.0;
  cooperating_ = false;
  held_push_N_ = 0.0;
  rejoining_ = false;
  rejoin_start_s_ = 0.0;
  rejoin_offset_N_ = 0.0;
  sample_ = {};
  stage_ = Stage::kInactive;
  take_sample(0);
  return Status::Ok();
}

Status SimDevice::activate() {
  if (stage_ == Stage::kUnconfigured) return {StatusCode::kNotConfigured, "not configured"};
  stage_ = Stage::kActive;
  command_ = {};
  take_sample(estop_ ? SampleFlags::kFault : 0U);
  return Status::Ok();
}

Status SimDevice::deactivate() {
  if (stage_ == Stage::kUnconfigured) return {StatusCode::kNotConfigured, "not configured"};
  stage_ = Stage::kInactive;
  command_ = {};
  return Status::Ok();
}

Status SimDevice::read(Sample& sample) noexcept {
  if (stage_ != Stage::kActive) return {StatusCode::kNotActive, "device not active"};
  sample = sample_;
  return Status::Ok();
}

Status SimDevice::write(const Command& command) noexcept {
  if (stage_ != Stage::kActive) return {StatusCode::kNotActive, "device not active"};
  command_ = amplifier_->apply(command.force_N);
  if (command_.rejected) {
    command_rejected_ = true;
    return {StatusCode::kInvalidArgument, "non-finite force command refused"};
  }
  return Status::Ok();
}

Status SimDevice::advance(std::chrono::nanoseconds period) noexcept {
  if (stage_ == Stage::kUnconfigured) return {StatusCode::kNotConfigured, "not configured"};
  if (period <= std::chrono::nanoseconds{0}) {
    return {StatusCode::kInvalidArgument, "period must be positive"};
  }
  const double period_s = std::chrono::duration<double>(period).count();
  // Scene time: device time, or since engagement when the scene waits for it (no push before).
  const bool scene_running = !config_.hold_scene_until_engaged || scene_origin_.has_value();
  const double t0_s =
      std::chrono::duration<double>(
          scene_running ? time_ - scene_origin_.value_or(std::chrono::nanoseconds{0})
                        : std::chrono::nanoseconds{0})
          .count();
  try {
    if (period_s != plant_->period_s()) plant_->set_period(period);
    if (human_ && human_->malicious()) {
      const std::optional<std::size_t> index = human_->malicious_index_at(t0_s);
      if (index != malicious_index_) {
        malicious_index_ = index;
        current_human_ = human_->impedance_at(t0_s);
        plant_->set_human_impedance(current_human_);
      }
    }
  } catch (...) {
    // Unreachable with a validated configuration; never let it escape the RT path.
    return {StatusCode::kFault, "sim device: propagator rebuild failed"};
  }
  sim::PeriodForce exogenous =
      human_ && scene_running ? human_->exogenous(t0_s, period_s) : sim::PeriodForce{};
  if (human_ && cooperating_) {
    exogenous = sim::PeriodForce{held_push_N_, 0.0};
  } else if (human_ && rejoining_) {
    const double rejoin_s = config_.operator_rejoin_s;
    const double w = rejoin_s > 0.0 ? 1.0 - (t0_s - rejoin_start_s_) / rejoin_s : 0.0;
    if (w > 0.0) {
      exogenous.force_N += w * rejoin_offset_N_;
      exogenous.slope_N_per_s -= rejoin_offset_N_ / rejoin_s;
    } else {
      rejoining_ = false;
    }
  }
  last_push_N_ = exogenous.force_N;
  // The scheduled e-stop press (scene time), on top of the button set_estop() holds.
  const bool scheduled_estop = scene_running && config_.estop_press_at_s &&
                               t0_s >= *config_.estop_press_at_s &&
                               (!config_.estop_release_at_s || t0_s < *config_.estop_release_at_s);
  const bool estop = estop_ || scheduled_estop;
  const bool driving = stage_ == Stage::kActive && !estop;
  applied_force_N_ = driving ? command_.force_N : 0.0;
  plant_->step(applied_force_N_, exogenous.force_N, exogenous.slope_N_per_s);
  // The cooperating operator yields to the force they felt over this period.
  if (cooperating_) held_push_N_ += period_s * config_.operator_yield_per_s * applied_force_N_;
  time_ += period;
  std::uint32_t flags = 0;
  if (driving && command_.saturated) flags |= SampleFlags::kAmplifierSaturated;
  if (command_rejected_) flags |= SampleFlags::kCommandRejected;
  if (estop) flags |= SampleFlags::kFault;
  command_rejected_ = false;
  take_sample(flags);
  return Status::Ok();
}

void SimDevice::take_sample(std::uint32_t flags) noexcept {
  const sim::PlantOutput& out = plant_->output();
  const double true_force_N = human_ ? out.human_force_N : out.environment_force_N;
  const sim::LoadCellReading force = load_cell_->measure(true_force_N);
  if (force.clipped) flags |= SampleFlags::kLoadCellClipped;
  sample_.sequence += 1;
  sample_.time_s = std::chrono::duration<double>(time_).count();
  const double x = plant_->state().position_m;
  sample_.position_m = config_.quantize_position ? encoder_->read_m(x) : x;
  sample_.force_N = force.force_N;
  sample_.flags = flags;
}

SimTruth SimDevice::truth() const noexcept {
  SimTruth t;
  t.time_s = std::chrono::duration<double>(time_).count();
  if (plant_) {
    t.state = plant_->state();
    t.output = plant_->output();
  }
  t.applied_force_N = applied_force_N_;
  t.human = current_human_;
  t.malicious_index = malicious_index_;
  t.human_push_N = last_push_N_;
  t.operator_cooperating = cooperating_;
  return t;
}

double SimDevice::scene_time_s() const noexcept {
  const bool scene_running = !config_.hold_scene_until_engaged || scene_origin_.has_value();
  if (!scene_running) return 0.0;
  return std::chrono::duration<double>(time_ - scene_origin_.value_or(std::chrono::nanoseconds{0}))
      .count();
}

void SimDevice::on_engaged() noexcept {
  if (!scene_origin_) scene_origin_ = time_;
  if (!cooperating_) return;
  // Engaged again: from the push they hold back to the scene's, linearly over rejoin_s.
  cooperating_ = false;
  rejoining_ = human_.has_value();
  rejoin_start_s_ = scene_time_s();
  const double period_s = std::chrono::duration<double>(config_.period).count();
  const double scene_N = human_ ? human_->exogenous(rejoin_start_s_, period_s).force_N : 0.0;
  rejoin_offset_N_ = held_push_N_ - scene_N;
}

void SimDevice::on_disengaged() noexcept {
  if (!human_ || cooperating_) return;
  // The push felt last period is held from now on, and yields to the guidance.
  cooperating_ = true;
  rejoining_ = false;
  held_push_N_ = last_push_N_;
}

}  // namespace teleop::device
