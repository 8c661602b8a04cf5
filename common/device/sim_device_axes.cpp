#include "common/device/sim_device_axes.hpp"

#include <cmath>
#include <exception>
#include <stdexcept>
#include <string>
#include <utility>

namespace teleop::device {

namespace {

void require(bool ok, const std::string& field, const char* what) {
  if (!ok) throw std::invalid_argument(field + " " + what);
}

// Empty, or n finite entries.
void check_vector(const Eigen::VectorXd& v, int n, const char* field) {
  if (v.size() == 0) return;
  require(v.size() == n, field, "must be empty or have one entry per axis (n)");
  require(v.allFinite(), field, "must be finite");
}

// Empty, or n x n and finite (symmetry and definiteness: PlantAxes).
void check_matrix(const Eigen::MatrixXd& m, int n, const char* field) {
  if (m.size() == 0) return;
  require(m.rows() == n && m.cols() == n, field, "must be empty or n x n");
  require(m.allFinite(), field, "must be finite");
}

AxisVector or_zero(const Eigen::VectorXd& v, int n) {
  if (v.size() == 0) return AxisVector::Zero(n);
  return v;
}

}  // namespace

SimDeviceAxes::SimDeviceAxes(SimDeviceAxesConfig config) : config_(std::move(config)) {}

void SimDeviceAxes::validate() const {
  require(config_.period > std::chrono::nanoseconds{0}, "period", "must be positive");
  const Eigen::MatrixXd& m = config_.plant.device.mass_kg;
  const int n = config_.axes();
  require(n >= 1 && n <= kMaxAxes && m.cols() == n, "plant.device.mass_kg",
          "must be n x n with 1 <= n <= 6");
  check_vector(config_.initial_position_m, n, "initial_position_m");
  check_vector(config_.initial_velocity_m_per_s, n, "initial_velocity_m_per_s");
  const auto encoders = static_cast<int>(config_.encoders.size());
  require(encoders == 0 || encoders == n, "encoders",
          "must be empty or have one entry per axis (n)");
  for (int i = 0; i < encoders; ++i) {
    const sim::EncoderParams& e = config_.encoders[static_cast<std::size_t>(i)];
    const std::string at = "encoders[" + std::to_string(i) + "].";
    require(e.counts_per_rev > 0, at + "counts_per_rev", "must be positive");
    require(std::isfinite(e.transmission_ratio) && e.transmission_ratio > 0.0,
            at + "transmission_ratio", "must be positive and finite");
    require(std::isfinite(e.metres_per_radian) && e.metres_per_radian > 0.0,
            at + "metres_per_radian", "must be positive and finite");
  }
  if (config_.kinematics == DeviceKinematics::kFiveBar) {
    require(n >= 2, "kinematics", "five_bar needs at least 2 axes (axes 0 and 1 are the plane)");
    const std::string problem = kinematics::check(config_.five_bar);
    require(problem.empty(), "five_bar", problem.c_str());
    require(config_.five_bar_home_m.allFinite(), "five_bar_home_m", "must be finite");
    const Eigen::Vector2d start =
        config_.five_bar_home_m + or_zero(config_.initial_position_m, n).head<2>();
    const auto q = kinematics::inverse(config_.five_bar, start);
    require(q.has_value() && kinematics::forward(config_.five_bar, *q).has_value(),
            "initial_position_m", "is out of the five-bar's reach (five_bar_home_m + x)");
  }
  if (config_.human) {
    const SimHumanAxes& h = *config_.human;
    check_matrix(h.impedance.mass_kg, n, "human.impedance.mass_kg");
    check_matrix(h.impedance.damping_Ns_per_m, n, "human.impedance.damping_Ns_per_m");
    check_matrix(h.impedance.stiffness_N_per_m, n, "human.impedance.stiffness_N_per_m");
    check_vector(h.set_point_m, n, "human.set_point_m");
    require(h.direction.size() == n, "human.direction", "must have one entry per axis (n)");
    require(h.direction.allFinite() && std::abs(h.direction.norm() - 1.0) <= 1e-9,
            "human.direction", "must be a finite unit vector");
    require(!h.profile.times_s.empty() || h.profile.kind != sim::ProfileKind::kTrace,
            "human.profile.times_s", "must not be empty for a trace");
  }
}

Status SimDeviceAxes::configure() {
  stage_ = Stage::kUnconfigured;
  try {
    validate();
    n_ = config_.axes();
    sim::PlantAxesParams plant = config_.plant;
    human_.reset();
    direction_ = AxisVector::Zero(n_);
    hold_N_ = AxisVector::Zero(n_);
    if (config_.human) {
      const SimHumanAxes& h = *config_.human;
      plant.human = h.impedance;
      sim::HumanParams push;
      push.profile = h.profile;
      push.sampling = h.sampling;
      human_.emplace(std::move(push));
      direction_ = h.direction;
      if (h.impedance.stiffness_N_per_m.size() > 0 && h.set_point_m.size() > 0) {
        hold_N_ = h.impedance.stiffness_N_per_m * h.set_point_m;
      }
    }
    plant_.emplace(plant, config_.period);
    plant_->reset(
        {or_zero(config_.initial_position_m, n_), or_zero(config_.initial_velocity_m_per_s, n_)});
    encoders_.clear();
    for (int i = 0; i < n_; ++i) {
      sim::EncoderParams e = config_.encoders.empty()
                                 ? sim::EncoderParams{}
                                 : config_.encoders[static_cast<std::size_t>(i)];
      // A five-bar joint is an angle: its "metres" are radians.
      if (config_.kinematics == DeviceKinematics::kFiveBar && i < 2) e.metres_per_radian = 1.0;
      encoders_.emplace_back(e);
    }
    load_cells_.clear();
    for (int i = 0; i < n_; ++i) {
      load_cells_.emplace_back(config_.load_cell, config_.seed + static_cast<std::uint64_t>(i));
    }
    amplifier_.emplace(config_.amplifier);
  } catch (const std::exception& e) {
    error_ = std::string("sim device axes: ") + e.what();
    return {StatusCode::kInvalidArgument, error_.c_str()};
  }
  time_ = std::chrono::nanoseconds{0};
  scene_started_ = false;
  scene_origin_ = std::chrono::nanoseconds{0};
  command_N_ = AxisVector::Zero(n_);
  saturated_ = false;
  command_rejected_ = false;
  applied_N_ = AxisVector::Zero(n_);
  push_N_ = AxisVector::Zero(n_);
  slope_N_per_s_ = AxisVector::Zero(n_);
  joints_rad_ = AxisVector::Zero(n_);
  sample_ = {};
  sample_.axes = n_;
  sample_.position_m = AxisVector::Zero(n_);
  sample_.force_N = AxisVector::Zero(n_);
  stage_ = Stage::kInactive;
  take_sample(0);
  return Status::Ok();
}

Status SimDeviceAxes::activate() {
  if (stage_ == Stage::kUnconfigured) return {StatusCode::kNotConfigured, "not configured"};
  stage_ = Stage::kActive;
  command_N_.setZero(n_);
  saturated_ = false;
  take_sample(estop_ ? SampleFlags::kFault : 0U);
  return Status::Ok();
}

Status SimDeviceAxes::deactivate() {
  if (stage_ == Stage::kUnconfigured) return {StatusCode::kNotConfigured, "not configured"};
  stage_ = Stage::kInactive;
  command_N_.setZero(n_);
  saturated_ = false;
  return Status::Ok();
}

Status SimDeviceAxes::read(SampleAxes& sample) noexcept {
  if (stage_ != Stage::kActive) return {StatusCode::kNotActive, "device not active"};
  sample = sample_;
  return Status::Ok();
}

Status SimDeviceAxes::write(const CommandAxes& command) noexcept {
  if (stage_ != Stage::kActive) return {StatusCode::kNotActive, "device not active"};
  if (command.force_N.size() != n_) {
    command_N_.setZero(n_);
    saturated_ = false;
    command_rejected_ = true;
    return {StatusCode::kInvalidArgument, "force command has the wrong number of axes"};
  }
  bool saturated = false;
  for (int i = 0; i < n_; ++i) {
    const sim::AmplifierOutput out = amplifier_->apply(command.force_N(i));
    if (out.rejected) {
      command_N_.setZero(n_);
      saturated_ = false;
      command_rejected_ = true;
      return {StatusCode::kInvalidArgument, "non-finite force command refused"};
    }
    command_N_(i) = out.force_N;
    saturated = saturated || out.saturated;
  }
  saturated_ = saturated;
  return Status::Ok();
}

Status SimDeviceAxes::tick(std::chrono::nanoseconds period) noexcept {
  if (stage_ == Stage::kUnconfigured) return {StatusCode::kNotConfigured, "not configured"};
  if (period != config_.period) {
    return {StatusCode::kInvalidArgument, "period differs from the configured period"};
  }
  const double period_s = plant_->period_s();
  // Scene time: device time, or since engagement when the scene waits for it (no push before).
  const bool scene_running = !config_.hold_scene_until_engaged || scene_started_;
  const double t0_s = std::chrono::duration<double>(scene_running ? time_ - scene_origin_
                                                                  : std::chrono::nanoseconds{0})
                          .count();
  const sim::PeriodForce push =
      human_ && scene_running ? human_->exogenous(t0_s, period_s) : sim::PeriodForce{};
  for (int i = 0; i < n_; ++i) {
    push_N_(i) = direction_(i) * push.force_N + hold_N_(i);
    slope_N_per_s_(i) = direction_(i) * push.slope_N_per_s;
  }
  const bool driving = stage_ == Stage::kActive && !estop_;
  if (driving) {
    applied_N_ = command_N_;
  } else {
    applied_N_.setZero(n_);
  }
  plant_->step(applied_N_, push_N_, slope_N_per_s_);
  time_ += period;
  std::uint32_t flags = 0;
  if (driving && saturated_) flags |= SampleFlags::kAmplifierSaturated;
  if (command_rejected_) flags |= SampleFlags::kCommandRejected;
  if (estop_) flags |= SampleFlags::kFault;
  command_rejected_ = false;
  take_sample(flags);
  return Status::Ok();
}

bool SimDeviceAxes::sense(const AxisVector& x, AxisVector& sensed) noexcept {
  int first_cartesian = 0;
  if (config_.kinematics == DeviceKinematics::kFiveBar) {
    first_cartesian = 2;
    const Eigen::Vector2d end = config_.five_bar_home_m + Eigen::Vector2d(x(0), x(1));
    const std::optional<Eigen::Vector2d> q = kinematics::inverse(config_.five_bar, end);
    if (!q) return false;
    const Eigen::Vector2d quantised(encoders_[0].read_m((*q)(0)), encoders_[1].read_m((*q)(1)));
    const std::optional<kinematics::FiveBarPose> pose =
        kinematics::forward(config_.five_bar, quantised);
    if (!pose) return false;
    joints_rad_(0) = quantised(0);
    joints_rad_(1) = quantised(1);
    sensed(0) = pose->end_m(0) - config_.five_bar_home_m(0);
    sensed(1) = pose->end_m(1) - config_.five_bar_home_m(1);
  }
  for (int i = first_cartesian; i < n_; ++i) {
    const auto u = static_cast<std::size_t>(i);
    sensed(i) = encoders_[u].read_m(x(i));
    const double r = config_.encoders.empty() ? sim::EncoderParams{}.metres_per_radian
                                              : config_.encoders[u].metres_per_radian;
    joints_rad_(i) = sensed(i) / r;
  }
  return true;
}

void SimDeviceAxes::take_sample(std::uint32_t flags) noexcept {
  const sim::PlantAxesOutput& out = plant_->output();
  const AxisVector& x = plant_->state().position_m;
  for (int i = 0; i < n_; ++i) {
    const double true_force_N = human_ ? out.human_force_N(i) : -out.environment_force_N(i);
    const sim::LoadCellReading force =
        load_cells_[static_cast<std::size_t>(i)].measure(true_force_N);
    if (force.clipped) flags |= SampleFlags::kLoadCellClipped;
    sample_.force_N(i) = force.force_N;
  }
  if (!config_.quantize_position) {
    sample_.position_m = x;
  } else if (!sense(x, sample_.position_m)) {
    // The linkage cannot be where the plant is: the last reading is held and flagged.
    flags |= SampleFlags::kFault;
  }
  sample_.sequence += 1;
  sample_.time_s = std::chrono::duration<double>(time_).count();
  sample_.flags = flags;
}

SimTruthAxes SimDeviceAxes::truth() const noexcept {
  SimTruthAxes t;
  t.time_s = std::chrono::duration<double>(time_).count();
  if (plant_) {
    t.state = plant_->state();
    t.output = plant_->output();
  }
  t.applied_force_N = applied_N_;
  t.human_push_N = push_N_;
  t.joint_angles_rad = joints_rad_;
  return t;
}

void SimDeviceAxes::on_engaged() noexcept {
  if (scene_started_) return;
  scene_started_ = true;
  scene_origin_ = time_;
}

}  // namespace teleop::device
