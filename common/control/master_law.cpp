#include "common/control/master_law.hpp"

#include <algorithm>
#include <cmath>

namespace teleop::control {
MasterLaw::MasterLaw(const LawParams& params) : LawBase(params, LawCore::Side::kMaster) {
  set_terms(core_.params().gains);
}

void MasterLaw::set_terms(const Gains& g) noexcept {
  const double beta = core_.params().scaling.force;
  use_kpm_ = beta != 0.0 && g.kpm != 0.0;
  use_kdm_ = beta != 0.0 && g.kdm != 0.0;
  use_kfm_ = beta != 0.0 && g.kfm != 0.0;
  use_kvm_ = g.kvm != 0.0;
}

void MasterLaw::retune(const Gains& gains, const FixtureParams& master_fixture) noexcept {
  core_.retune(gains, master_fixture);
  set_terms(gains);
}

Command MasterLaw::step(double position_m, const PeerState& slave) noexcept {
  if (core_.faulted()) return latch_fault();
  const bool bad_own = !std::isfinite(position_m);
  if (bad_own || LawCore::bad_peer(slave)) return latch_fault();

  const double v_m = core_.estimator().step(position_m);
  state_.stepped = true;
  if (slave.valid) {
    state_.have_peer = true;
    state_.peer_position_m = slave.position_m;
    state_.peer_velocity_m_per_s = slave.velocity_m_per_s;
    state_.peer_force_N = slave.force_N;
  }

  const double alpha = core_.params().scaling.position;
  const bool clutched = clutch_requested_;
  if (clutched && !state_.was_clutched) {
    // Engage: hold what the slave last received unclutched, so both sides hold the same.
    if (state_.published_unclutched) {
      state_.hold_m = state_.published_position_m;
      state_.hold_anchored = true;
    } else {
      state_.hold_m = position_m - state_.offset_m;
      state_.hold_anchored = false;
    }
  }
  if (clutched && !state_.hold_anchored && state_.have_peer) {
    // Nothing published yet: align to where the slave is instead.
    state_.hold_m = state_.peer_position_m / alpha;
    state_.hold_anchored = true;
  }
  if (!clutched && state_.was_clutched) state_.offset_m = position_m - state_.hold_m;
  state_.was_clutched = clutched;

  state_.published_clutched = clutched;
  if (clutched) {
    state_.published_position_m = state_.hold_m;
    state_.published_velocity_m_per_s = 0.0;
  } else {
    state_.published_position_m = position_m - state_.offset_m;
    state_.published_velocity_m_per_s = v_m;
    state_.published_unclutched = true;
  }

  const bool coupled = !clutched && slave.valid;
  if (coupled) state_.velocity_source_m_per_s = v_m;
  state_.weight = core_.faded(state_.weight, coupled);

  const Gains& g = core_.params().gains;
  double force_N = 0.0;
  if (state_.weight > 0.0 && state_.have_peer) {
    double coupling_N = 0.0;
    if (use_kpm_)
      coupling_N += g.kpm * (state_.published_position_m - state_.peer_position_m / alpha);
    if (use_kdm_) {
      coupling_N += g.kdm * (state_.weight * state_.velocity_source_m_per_s -
                             state_.peer_velocity_m_per_s / alpha);
    }
    if (use_kfm_) coupling_N += g.kfm * state_.peer_force_N;
    force_N += state_.weight * core_.params().scaling.force * coupling_N;
  }
  if (use_kvm_) force_N += g.kvm * v_m;
  const FixtureOutput fixture = core_.fixture().evaluate(position_m);
  force_N += fixture.force_N;
  if (!std::isfinite(force_N)) return latch_fault();

  const ActuatorLimiter::Result limited = core_.limiter().apply(force_N);
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
  out.position_m = state_.published_position_m;
  out.velocity_m_per_s = state_.published_velocity_m_per_s;
  out.force_N = 0.0;
  out.clutched = state_.published_clutched;
  out.valid = state_.stepped && !core_.faulted();
  return out;
}

void MasterLaw::reset() noexcept {
  state_ = {};
  core_.reset();
}

void MasterLaw::reset(double position_m) noexcept {
  state_ = {};
  core_.reset(position_m);
}

}  // namespace teleop::control
