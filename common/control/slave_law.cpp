#include "common/control/slave_law.hpp"

#include <algorithm>
#include <cmath>

namespace teleop::control {
namespace {

[[nodiscard]] const LawParams& validated(const LawParams& params) {
  validate(params);
  return params;
}

}  // namespace

SlaveLaw::SlaveLaw(const LawParams& params)
    : params_(validated(params)),
      estimator_(params.period_s, params.velocity_cutoff_hz),
      fixture_(params.slave_fixture),
      limiter_(params.slave_actuator, params.period_s) {
  const Gains& g = params_.gains;
  use_kps_ = g.kps != 0.0;
  use_kds_ = g.kds != 0.0;
  use_kvs_ = g.kvs != 0.0;
  follows_master_ = use_kps_ || use_kds_;
  const SlaveLimits& l = params_.slave_limits;
  check_position_ = std::isfinite(l.min_position_m) || std::isfinite(l.max_position_m);
  check_velocity_ = std::isfinite(l.max_velocity_m_per_s);
  fade_step_ =
      params_.clutch_fade_s > 0.0 ? std::min(1.0, params_.period_s / params_.clutch_fade_s) : 1.0;
}

void SlaveLaw::retune(const Gains& gains, const FixtureParams& slave_fixture) noexcept {
  params_.gains = gains;
  params_.slave_fixture = slave_fixture;
  fixture_ = UnilateralFixture(slave_fixture);
  use_kps_ = gains.kps != 0.0;
  use_kds_ = gains.kds != 0.0;
  use_kvs_ = gains.kvs != 0.0;
  follows_master_ = use_kps_ || use_kds_;
}

Command SlaveLaw::step(double position_m, double measured_force_N,
                       const PeerState& master) noexcept {
  if (faulted_) return latch_fault();
  const bool bad_own = !std::isfinite(position_m) || !std::isfinite(measured_force_N);
  const bool bad_peer =
      master.valid && !(std::isfinite(master.position_m) &&
                        std::isfinite(master.velocity_m_per_s) && std::isfinite(master.force_N));
  if (bad_own || bad_peer) return latch_fault();

  const double v_s = estimator_.step(position_m);
  stepped_ = true;
  position_m_ = position_m;
  measured_force_N_ = measured_force_N;

  const double alpha = params_.scaling.position;
  const bool following = master.valid && !master.clutched;
  holding_ = !following;
  if (!has_reference_) {
    reference_m_ = position_m;  // nothing to follow yet: hold where the slave is
    has_reference_ = true;
  }
  if (following) {
    const double live_m = alpha * master.position_m;
    reference_velocity_m_per_s_ = alpha * master.velocity_m_per_s;
    // Leaving a hold: whatever separates the held reference from the live one fades out
    // (about 0 after a clutch, since the master absorbed its offset).
    if (!was_following_) {
      mismatch_m_ = reference_m_ - live_m;
      mismatch_weight_ = 1.0;
    }
    weight_ = std::min(1.0, weight_ + fade_step_);
    mismatch_weight_ = std::max(0.0, mismatch_weight_ - fade_step_);
    reference_m_ = mismatch_weight_ > 0.0 ? live_m + mismatch_weight_ * mismatch_m_ : live_m;
  } else {
    weight_ = std::max(0.0, weight_ - fade_step_);
  }
  was_following_ = following;

  const Gains& g = params_.gains;
  const SlaveLimits& limits = params_.slave_limits;
  Command out;
  const FixtureOutput fixture = fixture_.evaluate(position_m);
  out.fixture_force_N = fixture.force_N;
  out.penetration_m = fixture.penetration_m;

  const bool outside_position =
      check_position_ && (position_m < limits.min_position_m || position_m > limits.max_position_m);
  const bool too_fast = check_velocity_ && std::abs(v_s) > limits.max_velocity_m_per_s;
  double force_N = 0.0;
  if (outside_position || too_fast) {
    out.flags.limit_violation = true;
    const double bound_m = std::clamp(position_m, limits.min_position_m, limits.max_position_m);
    if (use_kps_) force_N += g.kps * (bound_m - position_m);
    force_N -= (g.kds + g.kvs) * v_s;
  } else {
    if (follows_master_) {
      double reference_m = reference_m_;
      double reference_velocity = weight_ * reference_velocity_m_per_s_;
      if (check_position_ &&
          (reference_m < limits.min_position_m || reference_m > limits.max_position_m)) {
        out.flags.reference_limited = true;
        reference_m = std::clamp(reference_m, limits.min_position_m, limits.max_position_m);
        reference_velocity = 0.0;
      }
      if (use_kps_) force_N += g.kps * (reference_m - position_m);
      if (use_kds_) force_N += g.kds * (reference_velocity - v_s);
    }
    if (use_kvs_) force_N -= g.kvs * v_s;
  }
  force_N -= fixture.force_N;
  if (!std::isfinite(force_N)) return latch_fault();

  const double clamped_N = std::clamp(force_N, -limits.max_force_N, limits.max_force_N);
  const ActuatorLimiter::Result limited = limiter_.apply(clamped_N);
  out.force_N = limited.force_N;
  out.flags.saturated = limited.saturated || clamped_N != force_N;
  out.flags.rate_limited = limited.rate_limited;
  return out;
}

PeerState SlaveLaw::peer_state() const noexcept {
  PeerState out;
  out.position_m = position_m_;
  out.velocity_m_per_s = estimator_.velocity_m_per_s();
  out.force_N = measured_force_N_;
  out.clutched = false;
  out.valid = stepped_ && !faulted_;
  return out;
}

Command SlaveLaw::latch_fault() noexcept {
  faulted_ = true;
  limiter_.set_last_output(0.0);
  Command out;
  out.flags.input_fault = true;
  return out;
}

void SlaveLaw::clear_state() noexcept {
  limiter_.set_last_output(0.0);
  has_reference_ = false;
  was_following_ = false;
  holding_ = false;
  mismatch_m_ = 0.0;
  mismatch_weight_ = 0.0;
  reference_m_ = 0.0;
  reference_velocity_m_per_s_ = 0.0;
  weight_ = 0.0;
  stepped_ = false;
  position_m_ = 0.0;
  measured_force_N_ = 0.0;
  faulted_ = false;
}

void SlaveLaw::reset() noexcept {
  clear_state();
  estimator_.reset();
}

void SlaveLaw::reset(double position_m) noexcept {
  clear_state();
  if (std::isfinite(position_m)) {
    estimator_.reset(position_m);
  } else {
    estimator_.reset();
  }
}

}  // namespace teleop::control
