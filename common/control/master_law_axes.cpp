// MasterLawAxes (law_axes.hpp): MasterLaw (master_law.cpp) per axis, in the same order of
// operations, so that n = 1 gives the same bits.
#include <algorithm>
#include <cmath>

#include "common/control/law_axes.hpp"

namespace teleop::control {

MasterLawAxes::MasterLawAxes(const LawAxesParams& params)
    : LawAxesSide(params, LawAxesCore::Side::kMaster) {
  set_terms();
}

void MasterLawAxes::set_terms() noexcept {
  const double beta = core_.params().scaling.force;
  const LawGainsAxes& g = core_.params().gains;
  use_kpm_ = beta != 0.0 && any_nonzero(g.kpm);
  use_kdm_ = beta != 0.0 && any_nonzero(g.kdm);
  use_kfm_ = beta != 0.0 && any_nonzero(g.kfm);
  use_kvm_ = any_nonzero(g.kvm);
}

void MasterLawAxes::retune(const LawGainsAxes& gains, const PlaneSet& master_planes) noexcept {
  core_.retune(gains, master_planes);
  set_terms();
}

void MasterLawAxes::update_clutch(const AxisVector& position_m, bool clutched) noexcept {
  const double alpha = core_.params().scaling.position;
  if (clutched && !state_.was_clutched) {
    // Engage: hold what the slave last received unclutched.
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
    for (Eigen::Index i = 0; i < position_m.size(); ++i) {
      state_.hold_m(i) = state_.peer_position_m(i) / alpha;
    }
    state_.hold_anchored = true;
  }
  if (!clutched && state_.was_clutched) state_.offset_m = position_m - state_.hold_m;
  state_.was_clutched = clutched;
}

void MasterLawAxes::publish(const AxisVector& position_m, const AxisVector& v_m,
                            bool clutched) noexcept {
  state_.published_clutched = clutched;
  if (clutched) {
    state_.published_position_m = state_.hold_m;
    state_.published_velocity_m_per_s.setZero();
  } else {
    state_.published_position_m = position_m - state_.offset_m;
    state_.published_velocity_m_per_s = v_m;
    state_.published_unclutched = true;
  }
}

// beta [K_pm (x_r - x_s/alpha) + K_dm (w v_r - v_s/alpha) + K_fm F_e] without the weight.
AxisVector MasterLawAxes::coupling(int n) const noexcept {
  const double alpha = core_.params().scaling.position;
  const LawGainsAxes& g = core_.params().gains;
  AxisVector c = AxisVector::Zero(n);
  if (use_kpm_) {
    AxisVector e = AxisVector::Zero(n);
    for (Eigen::Index i = 0; i < n; ++i) {
      e(i) = state_.published_position_m(i) - state_.peer_position_m(i) / alpha;
    }
    add_product(g.kpm, e, c);
  }
  if (use_kdm_) {
    AxisVector e = AxisVector::Zero(n);
    for (Eigen::Index i = 0; i < n; ++i) {
      e(i) = state_.weight * state_.velocity_source_m_per_s(i) -
             state_.peer_velocity_m_per_s(i) / alpha;
    }
    add_product(g.kdm, e, c);
  }
  if (use_kfm_) add_product(g.kfm, state_.peer_force_N, c);
  return c;
}

CommandAxes MasterLawAxes::step(const AxisVector& position_m, const PeerStateAxes& slave) noexcept {
  if (core_.faulted()) return core_.latch_fault();
  const int n = core_.axes();
  const bool bad_own = position_m.size() != n || !all_finite(position_m);
  if (bad_own || core_.bad_peer(slave)) return core_.latch_fault();

  const AxisVector v_m = core_.velocity(position_m);
  state_.stepped = true;
  if (slave.valid) {
    state_.have_peer = true;
    state_.peer_position_m = slave.position_m;
    state_.peer_velocity_m_per_s = slave.velocity_m_per_s;
    state_.peer_force_N = slave.force_N;
  }

  const bool clutched = clutch_requested_;
  update_clutch(position_m, clutched);
  publish(position_m, v_m, clutched);

  const bool coupled = !clutched && slave.valid;
  if (coupled) state_.velocity_source_m_per_s = v_m;
  state_.weight = core_.faded(state_.weight, coupled);

  AxisVector force_N = AxisVector::Zero(n);
  if (state_.weight > 0.0 && state_.have_peer) {
    const AxisVector c = coupling(n);
    const double w_beta = state_.weight * core_.params().scaling.force;
    for (Eigen::Index i = 0; i < n; ++i) force_N(i) += w_beta * c(i);
  }
  if (use_kvm_) add_product(core_.params().gains.kvm, v_m, force_N);
  CommandAxes out;
  core_.fixture(position_m, out);
  for (Eigen::Index i = 0; i < n; ++i) force_N(i) += out.fixture_force_N(i);
  if (!all_finite(force_N)) return core_.latch_fault();

  core_.limit(force_N, out);
  return out;
}

PeerStateAxes MasterLawAxes::peer_state() const noexcept {
  PeerStateAxes out;
  out.position_m = state_.published_position_m;
  out.velocity_m_per_s = state_.published_velocity_m_per_s;
  out.force_N = AxisVector::Zero(core_.axes());
  out.clutched = state_.published_clutched;
  out.valid = state_.stepped && !core_.faulted();
  return out;
}

}  // namespace teleop::control
