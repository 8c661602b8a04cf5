#include "common/control/slave_law.hpp"

#include <algorithm>
#include <cmath>

namespace teleop::control {
SlaveLaw::SlaveLaw(const LawParams& params) : LawBase(params, LawCore::Side::kSlave) {
  set_terms(core_.params().gains);
  const SlaveLimits& l = core_.params().slave_limits;
  check_position_ = std::isfinite(l.min_position_m) || std::isfinite(l.max_position_m);
  check_velocity_ = std::isfinite(l.max_velocity_m_per_s);
}

void SlaveLaw::set_terms(const Gains& g) noexcept {
  use_kps_ = g.kps != 0.0;
  use_kds_ = g.kds != 0.0;
  use_kvs_ = g.kvs != 0.0;
  follows_master_ = use_kps_ || use_kds_;
}

void SlaveLaw::retune(const Gains& gains, const FixtureParams& slave_fixture) noexcept {
  core_.retune(gains, slave_fixture);
  set_terms(gains);
}

Command SlaveLaw::step(double position_m, double measured_force_N,
                       const PeerState& master) noexcept {
  if (core_.faulted()) return latch_fault();
  const bool bad_own = !std::isfinite(position_m) || !std::isfinite(measured_force_N);
  if (bad_own || LawCore::bad_peer(master)) return latch_fault();

  const double v_s = core_.estimator().step(position_m);
  state_.stepped = true;
  state_.position_m = position_m;
  state_.measured_force_N = measured_force_N;

  const double alpha = core_.params().scaling.position;
  const bool following = master.valid && !master.clutched;
  state_.holding = !following;
  if (!state_.has_reference) {
    state_.reference_m = position_m;  // nothing to follow yet: hold where the slave is
    state_.has_reference = true;
  }
  if (following) {
    const double live_m = alpha * master.position_m;
    state_.reference_velocity_m_per_s = alpha * master.velocity_m_per_s;
    // Leaving a hold: whatever separates the held reference from the live one fades out
    // (about 0 after a clutch, since the master absorbed its offset).
    if (!state_.was_following) {
      state_.mismatch_m = state_.reference_m - live_m;
      state_.mismatch_weight = 1.0;
    }
    state_.weight = core_.faded(state_.weight, true);
    state_.mismatch_weight = core_.faded(state_.mismatch_weight, false);
    state_.reference_m =
        state_.mismatch_weight > 0.0 ? live_m + state_.mismatch_weight * state_.mismatch_m : live_m;
  } else {
    state_.weight = core_.faded(state_.weight, false);
  }
  state_.was_following = following;

  const Gains& g = core_.params().gains;
  const SlaveLimits& limits = core_.params().slave_limits;
  Command out;
  const FixtureOutput fixture = core_.fixture().evaluate(position_m);
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
      double reference_m = state_.reference_m;
      double reference_velocity = state_.weight * state_.reference_velocity_m_per_s;
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
  const ActuatorLimiter::Result limited = core_.limiter().apply(clamped_N);
  out.force_N = limited.force_N;
  out.flags.saturated = limited.saturated || clamped_N != force_N;
  out.flags.rate_limited = limited.rate_limited;
  return out;
}

PeerState SlaveLaw::peer_state() const noexcept {
  PeerState out;
  out.position_m = state_.position_m;
  out.velocity_m_per_s = core_.estimator().velocity_m_per_s();
  out.force_N = state_.measured_force_N;
  out.clutched = false;
  out.valid = state_.stepped && !core_.faulted();
  return out;
}

void SlaveLaw::reset() noexcept {
  state_ = {};
  core_.reset();
}

void SlaveLaw::reset(double position_m) noexcept {
  state_ = {};
  core_.reset(position_m);
}

}  // namespace teleop::control
