#include "common/control/master_law.hpp"

#include <algorithm>
#include <cmath>

namespace teleop::control {
namespace {

[[nodiscard]] const LawParams& validated(const LawParams& params) {
  validate(params);
  return params;
}

}  // namespace

MasterLaw::MasterLaw(const LawParams& params)
    : params_(validated(params)),
      estimator_(params.period_s, params.velocity_cutoff_hz),
      fixture_(params.master_fixture),
      limiter_(params.master_actuator, params.period_s) {
  const double beta = params_.scaling.force;
  const Gains& g = params_.gains;
  use_kpm_ = beta != 0.0 && g.kpm != 0.0;
  use_kdm_ = beta != 0.0 && g.kdm != 0.0;
  use_kfm_ = beta != 0.0 && g.kfm != 0.0;
  use_kvm_ = g.kvm != 0.0;
  fade_step_ =
      params_.clutch_fade_s > 0.0 ? std::min(1.0, params_.period_s / params_.clutch_fade_s) : 1.0;
}

void MasterLaw::retune(const Gains& gains, const FixtureParams& master_fixture) noexcept {
  params_.gains = gains;
  params_.master_fixture = master_fixture;
  fixture_ = UnilateralFixture(master_fixture);
  const double beta = params_.scaling.force;
  use_kpm_ = beta != 0.0 && gains.kpm != 0.0;
  use_kdm_ = beta != 0.0 && gains.kdm != 0.0;
  use_kfm_ = beta != 0.0 && gains.kfm != 0.0;
  use_kvm_ = gains.kvm != 0.0;
}

Command MasterLaw::step(double position_m, const PeerState& slave) noexcept {
  if (faulted_) return latch_fault();
  const bool bad_own = !std::isfinite(position_m);
  const bool bad_peer =
      slave.valid && !(std::isfinite(slave.position_m) && std::isfinite(slave.velocity_m_per_s) &&
                       std::isfinite(slave.force_N));
  if (bad_own || bad_peer) return latch_fault();

  const double v_m = estimator_.step(position_m);
  stepped_ = true;
  if (slave.valid) {
    have_peer_ = true;
    peer_position_m_ = slave.position_m;
    peer_velocity_m_per_s_ = slave.velocity_m_per_s;
    peer_force_N_ = slave.force_N;
  }

  const double alpha = params_.scaling.position;
  const bool clutched = clutch_requested_;
  if (clutched && !was_clutched_) {
    // Engage: hold what the slave last received unclutched, so both sides hold the same.
    if (published_unclutched_) {
      hold_m_ = published_position_m_;
      hold_anchored_ = true;
    } else {
      hold_m_ = position_m - offset_m_;
      hold_anchored_ = false;
    }
  }
  if (clutched && !hold_anchored_ && have_peer_) {
    // Nothing published yet: align to where the slave is instead.
    hold_m_ = peer_position_m_ / alpha;
    hold_anchored_ = true;
  }
  if (!clutched && was_clutched_) offset_m_ = position_m - hold_m_;
  was_clutched_ = clutched;

  published_clutched_ = clutched;
  if (clutched) {
    published_position_m_ = hold_m_;
    published_velocity_m_per_s_ = 0.0;
  } else {
    published_position_m_ = position_m - offset_m_;
    published_velocity_m_per_s_ = v_m;
    published_unclutched_ = true;
  }

  const bool coupled = !clutched && slave.valid;
  if (coupled) velocity_source_m_per_s_ = v_m;
  weight_ = coupled ? std::min(1.0, weight_ + fade_step_) : std::max(0.0, weight_ - fade_step_);

  const Gains& g = params_.gains;
  double force_N = 0.0;
  if (weight_ > 0.0 && have_peer_) {
    double coupling_N = 0.0;
    if (use_kpm_) coupling_N += g.kpm * (published_position_m_ - peer_position_m_ / alpha);
    if (use_kdm_) {
      coupling_N += g.kdm * (weight_ * velocity_source_m_per_s_ - peer_velocity_m_per_s_ / alpha);
    }
    if (use_kfm_) coupling_N += g.kfm * peer_force_N_;
    force_N += weight_ * params_.scaling.force * coupling_N;
  }
  if (use_kvm_) force_N += g.kvm * v_m;
  const FixtureOutput fixture = fixture_.evaluate(position_m);
  force_N += fixture.force_N;
  if (!std::isfinite(force_N)) return latch_fault();

  const ActuatorLimiter::Result limited = limiter_.apply(force_N);
  Command out;
  out.force_N = limited.force_N;
  out.fixture_force_N = fixture.force_N;
  out.penetration_m = fixture.penetration_m;
  out.flags.saturated = limited.saturated;
  out.flags.rate_limited = limited.rate_limited;
  return out;
}

PeerState MasterLaw::peer_state() const noexcept {
  PeerState out;
  out.position_m = published_position_m_;
  out.velocity_m_per_s = published_velocity_m_per_s_;
  out.force_N = 0.0;
  out.clutched = published_clutched_;
  out.valid = stepped_ && !faulted_;
  return out;
}

Command MasterLaw::latch_fault() noexcept {
  faulted_ = true;
  limiter_.set_last_output(0.0);
  Command out;
  out.flags.input_fault = true;
  return out;
}

void MasterLaw::clear_state() noexcept {
  limiter_.set_last_output(0.0);
  was_clutched_ = false;
  hold_anchored_ = false;
  hold_m_ = 0.0;
  offset_m_ = 0.0;
  weight_ = 0.0;
  velocity_source_m_per_s_ = 0.0;
  have_peer_ = false;
  peer_position_m_ = 0.0;
  peer_velocity_m_per_s_ = 0.0;
  peer_force_N_ = 0.0;
  stepped_ = false;
  published_unclutched_ = false;
  published_position_m_ = 0.0;
  published_velocity_m_per_s_ = 0.0;
  published_clutched_ = false;
  faulted_ = false;
}

void MasterLaw::reset() noexcept {
  clear_state();
  estimator_.reset();
}

void MasterLaw::reset(double position_m) noexcept {
  clear_state();
  if (std::isfinite(position_m)) {
    estimator_.reset(position_m);
  } else {
    estimator_.reset();
  }
}

}  // namespace teleop::control
