// SlaveLawAxes (law_axes.hpp): SlaveLaw (slave_law.cpp) per axis, in the same order of
// operations, so that n = 1 gives the same bits.
#include <algorithm>
#include <cmath>

#include "common/control/law_axes.hpp"

namespace teleop::control {

SlaveLawAxes::SlaveLawAxes(const LawAxesParams& params)
    : LawAxesSide(params, LawAxesCore::Side::kSlave) {
  set_terms();
}

void SlaveLawAxes::set_terms() noexcept {
  const LawGainsAxes& g = core_.params().gains;
  use_kps_ = any_nonzero(g.kps);
  use_kds_ = any_nonzero(g.kds);
  use_kvs_ = any_nonzero(g.kvs);
  follows_master_ = use_kps_ || use_kds_;
  kds_plus_kvs_ = g.kds + g.kvs;
}

void SlaveLawAxes::retune(const LawGainsAxes& gains, const PlaneSet& slave_planes) noexcept {
  core_.retune(gains, slave_planes);
  set_terms();
}

void SlaveLawAxes::update_reference(const AxisVector& position_m,
                                    const PeerStateAxes& master) noexcept {
  const double alpha = core_.params().scaling.position;
  const bool following = master.valid && !master.clutched;
  state_.holding = !following;
  if (!state_.has_reference) {
    state_.reference_m = position_m;  // nothing to follow yet: hold where the slave is
    state_.has_reference = true;
  }
  if (following) {
    AxisVector live_m = AxisVector::Zero(position_m.size());
    for (Eigen::Index i = 0; i < position_m.size(); ++i) {
      live_m(i) = alpha * master.position_m(i);
      state_.reference_velocity_m_per_s(i) = alpha * master.velocity_m_per_s(i);
    }
    // Leaving a hold: the held reference's distance from the live one fades out.
    if (!state_.was_following) {
      state_.mismatch_m = state_.reference_m - live_m;
      state_.mismatch_weight = 1.0;
    }
    state_.weight = core_.faded(state_.weight, true);
    state_.mismatch_weight = core_.faded(state_.mismatch_weight, false);
    if (state_.mismatch_weight > 0.0) {
      for (Eigen::Index i = 0; i < position_m.size(); ++i) {
        state_.reference_m(i) = live_m(i) + state_.mismatch_weight * state_.mismatch_m(i);
      }
    } else {
      state_.reference_m = live_m;
    }
  } else {
    state_.weight = core_.faded(state_.weight, false);
  }
  state_.was_following = following;
}

// The law (or the safe command) before the fixture and the limits.
void SlaveLawAxes::law_force(const AxisVector& position_m, const AxisVector& v_s,
                             AxisVector& force_N, CommandAxes& out) const noexcept {
  const Eigen::Index n = position_m.size();
  const LawGainsAxes& g = core_.params().gains;
  const SlaveLimitsAxes& limits = core_.params().slave_limits;
  bool violation = false;
  for (Eigen::Index i = 0; i < n; ++i) {
    violation = violation || position_m(i) < limits.min_position_m(i) ||
                position_m(i) > limits.max_position_m(i) ||
                std::abs(v_s(i)) > limits.max_velocity_m_per_s(i);
  }
  if (violation) {
    out.flags.limit_violation = true;
    if (use_kps_) {
      AxisVector back_m = AxisVector::Zero(n);
      for (Eigen::Index i = 0; i < n; ++i) {
        const double bound_m =
            std::clamp(position_m(i), limits.min_position_m(i), limits.max_position_m(i));
        back_m(i) = bound_m - position_m(i);
      }
      add_product(g.kps, back_m, force_N);
    }
    subtract_product(kds_plus_kvs_, v_s, force_N);
    return;
  }
  if (follows_master_) {
    AxisVector reference_m = state_.reference_m;
    AxisVector reference_velocity = AxisVector::Zero(n);
    for (Eigen::Index i = 0; i < n; ++i) {
      reference_velocity(i) = state_.weight * state_.reference_velocity_m_per_s(i);
      if (reference_m(i) < limits.min_position_m(i) || reference_m(i) > limits.max_position_m(i)) {
        out.flags.reference_limited = true;
        reference_m(i) =
            std::clamp(reference_m(i), limits.min_position_m(i), limits.max_position_m(i));
        reference_velocity(i) = 0.0;
      }
    }
    if (use_kps_) add_product(g.kps, reference_m - position_m, force_N);
    if (use_kds_) add_product(g.kds, reference_velocity - v_s, force_N);
  }
  if (use_kvs_) subtract_product(g.kvs, v_s, force_N);
}

CommandAxes SlaveLawAxes::step(const AxisVector& position_m, const AxisVector& measured_force_N,
                               const PeerStateAxes& master) noexcept {
  if (core_.faulted()) return core_.latch_fault();
  const int n = core_.axes();
  const bool bad_own = position_m.size() != n || measured_force_N.size() != n ||
                       !all_finite(position_m) || !all_finite(measured_force_N);
  if (bad_own || core_.bad_peer(master)) return core_.latch_fault();

  const AxisVector v_s = core_.velocity(position_m);
  state_.stepped = true;
  state_.position_m = position_m;
  state_.measured_force_N = measured_force_N;
  update_reference(position_m, master);

  CommandAxes out;
  core_.fixture(position_m, out);

  AxisVector force_N = AxisVector::Zero(n);
  law_force(position_m, v_s, force_N, out);
  force_N -= out.fixture_force_N;
  if (!all_finite(force_N)) return core_.latch_fault();

  const AxisVector& max_force_N = core_.params().slave_limits.max_force_N;
  AxisVector clamped_N = AxisVector::Zero(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    clamped_N(i) = std::clamp(force_N(i), -max_force_N(i), max_force_N(i));
    if (clamped_N(i) != force_N(i)) out.saturated_axes |= 1U << static_cast<unsigned>(i);
  }
  core_.limit(clamped_N, out);
  return out;
}

PeerStateAxes SlaveLawAxes::peer_state() const noexcept {
  PeerStateAxes out;
  out.position_m = state_.position_m;
  out.velocity_m_per_s = core_.filtered_velocity();
  out.force_N = state_.measured_force_N;
  out.clutched = false;
  out.valid = state_.stepped && !core_.faulted();
  return out;
}

}  // namespace teleop::control
