// The three-channel law in task space (issue 18 "Law"; docs/architecture.md §2.3 "n axes"):
// MasterLaw and SlaveLaw (master_law.hpp, slave_law.hpp) written in n-vectors and n x n gain
// matrices, with plane fixtures (plane_fixtures.hpp):
//
//   F_am = w beta [K_pm (x_r - x_s/alpha) + K_dm (w v_r - v_s/alpha) + K_fm F_e] + K_vm v_m + F_mVF
//   F_as = K_ps (x_r - x_s) + K_ds (u v_r - v_s) - K_vs v_s - F_sVF
//
// F_iVF = sum over the side's planes with n^T x_i > p of K (n^T x_i - p) n, the resistance the
// planes ask for (the device is pushed with -F_iVF). Everything the one-axis laws do happens
// here per axis or, where it is one decision, for the whole vector:
//  - clutch indexing with vectors: x_hold, the offset x_m - x_hold absorbed at release, the
//    slave's held reference and the mismatch that fades out when it follows again;
//  - the coupling weights w (master) and u (slave): one scalar each, faded over clutch_fade_s
//    on clutch, link loss (valid = false), construction and reset();
//  - faults: a non-finite component of the own position, the measured force or a valid peer
//    state, or of a computed force, latches a 0 N command on every axis with
//    flags.input_fault until reset();
//  - the velocity filter per axis (velocity_estimator.hpp);
//  - the slave's workspace box: any axis outside its position bounds or faster than its
//    velocity bound gives the safe command K_ps (clamp(x_s) - x_s) - (K_ds + K_vs) v_s - F_sVF
//    on every axis; a reference outside the box is clamped per axis with that axis's velocity
//    reference set to 0; then the slave force clamp per axis;
//  - the actuator per axis: saturation, then the rate limit (flags say whether any axis was
//    clipped, the masks which).
// With n = 1, every gain a 1 x 1 matrix and one plane of normal (+1), the arithmetic is the
// one-axis laws' in the same order: commands and peer states are bit for bit equal
// (tests/unit/control/test_law_axes_equivalence.cpp). Each sum over a matrix row starts from 0
// and runs over the columns in order.
#pragma once

#include <array>
#include <cmath>

#include "common/control/actuator_limiter.hpp"
#include "common/control/command.hpp"
#include "common/control/law_axes_params.hpp"
#include "common/control/plane_fixtures.hpp"
#include "common/control/velocity_estimator.hpp"
#include "common/core/rt_safe.hpp"

namespace teleop::control {

// PeerState (command.hpp) with n-vectors.
struct PeerStateAxes {
  AxisVector position_m{};        // sender's task coordinates (master: net of its clutch offset)
  AxisVector velocity_m_per_s{};  // the sender's own filtered velocity
  AxisVector force_N{};           // slave -> master: measured environment force F_e
  bool clutched{false};
  bool valid{false};  // false: nothing received yet, or the sender is faulted
};

// Command (command.hpp) with n-vectors. The flags are the OR over the axes; the masks have bit
// i set when axis i was clipped.
struct CommandAxes {
  AxisVector force_N{};          // to the actuators (after limits)
  AxisVector fixture_force_N{};  // this side's F_VF = sum K (n^T x - p) n (n = 1: K (x - p))
  double penetration_m{0.0};     // the deepest plane's n^T x - p, else 0
  int deepest_plane{-1};         // its index, -1 outside every plane
  CommandFlags flags{};
  unsigned saturated_axes{0};
  unsigned rate_limited_axes{0};
};

// Every finite component (RT-safe).
TELEOP_RT [[nodiscard]] inline bool all_finite(const AxisVector& v) noexcept {
  for (Eigen::Index i = 0; i < v.size(); ++i) {
    if (!std::isfinite(v(i))) return false;
  }
  return true;
}

// out[i] += sum_j K(i, j) e[j], the sum from 0 over j in order (RT-safe).
TELEOP_RT inline void add_product(const AxisMatrix& k, const AxisVector& e,
                                  AxisVector& out) noexcept {
  for (Eigen::Index i = 0; i < out.size(); ++i) {
    double sum = 0.0;
    for (Eigen::Index j = 0; j < e.size(); ++j) sum += k(i, j) * e(j);
    out(i) += sum;
  }
}

// out[i] -= sum_j K(i, j) e[j] (RT-safe).
TELEOP_RT inline void subtract_product(const AxisMatrix& k, const AxisVector& e,
                                       AxisVector& out) noexcept {
  for (Eigen::Index i = 0; i < out.size(); ++i) {
    double sum = 0.0;
    for (Eigen::Index j = 0; j < e.size(); ++j) sum += k(i, j) * e(j);
    out(i) -= sum;
  }
}

// A matrix with a non-zero entry (RT-safe).
TELEOP_RT [[nodiscard]] inline bool any_nonzero(const AxisMatrix& k) noexcept {
  for (Eigen::Index i = 0; i < k.rows(); ++i) {
    for (Eigen::Index j = 0; j < k.cols(); ++j) {
      if (k(i, j) != 0.0) return true;
    }
  }
  return false;
}

// What MasterLawAxes and SlaveLawAxes share: parameters, per-axis filters and limiters, the
// side's planes, the fade step and the fault latch. RT-safe but the constructor.
class LawAxesCore {
 public:
  enum class Side { kMaster, kSlave };

  // Throws std::invalid_argument naming the field (validate()).
  LawAxesCore(const LawAxesParams& params, Side side);

  TELEOP_RT void retune(const LawGainsAxes& gains, const PlaneSet& planes) noexcept;

  // A valid peer state with a non-finite component, or of the wrong size: a fault.
  TELEOP_RT [[nodiscard]] bool bad_peer(const PeerStateAxes& p) const noexcept;
  TELEOP_RT [[nodiscard]] CommandAxes latch_fault() noexcept;
  TELEOP_RT void reset() noexcept;
  TELEOP_RT void reset(const AxisVector& position_m) noexcept;

  // v(k) per axis from x(k). RT-safe.
  TELEOP_RT [[nodiscard]] AxisVector velocity(const AxisVector& position_m) noexcept;
  TELEOP_RT [[nodiscard]] AxisVector filtered_velocity() const noexcept;

  // This side's planes at position_m into out: fixture_force_N = F_VF (0 - the planes' force,
  // so +0 outside as K (x - p) is), the penetration and the deepest plane. RT-safe.
  TELEOP_RT void fixture(const AxisVector& position_m, CommandAxes& out) const noexcept;

  // Saturation then rate limit per axis into out.force_N and the flags. RT-safe.
  TELEOP_RT void limit(const AxisVector& force_N, CommandAxes& out) noexcept;

  TELEOP_RT [[nodiscard]] double faded(double weight, bool in) const noexcept {
    return in ? std::min(1.0, weight + fade_step_) : std::max(0.0, weight - fade_step_);
  }

  [[nodiscard]] int axes() const noexcept { return params_.axes; }
  [[nodiscard]] const LawAxesParams& params() const noexcept { return params_; }
  [[nodiscard]] const PlaneSet& planes() const noexcept { return planes_; }
  [[nodiscard]] bool faulted() const noexcept { return faulted_; }

 private:
  LawAxesParams params_{};
  Side side_;
  std::array<VelocityEstimator, kMaxAxes> estimators_;
  std::array<ActuatorLimiter, kMaxAxes> limiters_;
  PlaneSet planes_{};
  double fade_step_{1.0};
  bool faulted_{false};
};

TELEOP_RT inline bool LawAxesCore::bad_peer(const PeerStateAxes& p) const noexcept {
  if (!p.valid) return false;
  const Eigen::Index n = params_.axes;
  if (p.position_m.size() != n || p.velocity_m_per_s.size() != n || p.force_N.size() != n) {
    return true;
  }
  return !(all_finite(p.position_m) && all_finite(p.velocity_m_per_s) && all_finite(p.force_N));
}

TELEOP_RT inline AxisVector LawAxesCore::velocity(const AxisVector& position_m) noexcept {
  AxisVector v = AxisVector::Zero(position_m.size());
  for (Eigen::Index i = 0; i < position_m.size(); ++i) {
    v(i) = estimators_[static_cast<std::size_t>(i)].step(position_m(i));
  }
  return v;
}

TELEOP_RT inline AxisVector LawAxesCore::filtered_velocity() const noexcept {
  AxisVector v = AxisVector::Zero(params_.axes);
  for (Eigen::Index i = 0; i < v.size(); ++i) {
    v(i) = estimators_[static_cast<std::size_t>(i)].velocity_m_per_s();
  }
  return v;
}

TELEOP_RT inline void LawAxesCore::fixture(const AxisVector& position_m,
                                           CommandAxes& out) const noexcept {
  const PlaneSetOutput planes = planes_.evaluate(position_m);
  out.fixture_force_N = AxisVector::Zero(position_m.size());
  for (Eigen::Index i = 0; i < position_m.size(); ++i) {
    out.fixture_force_N(i) = 0.0 - planes.force_N(i);
  }
  out.penetration_m = planes.penetration_m;
  out.deepest_plane = planes.deepest_plane;
}

TELEOP_RT inline void LawAxesCore::limit(const AxisVector& force_N, CommandAxes& out) noexcept {
  out.force_N = AxisVector::Zero(force_N.size());
  for (Eigen::Index i = 0; i < force_N.size(); ++i) {
    const ActuatorLimiter::Result r = limiters_[static_cast<std::size_t>(i)].apply(force_N(i));
    out.force_N(i) = r.force_N;
    if (r.saturated) out.saturated_axes |= 1U << static_cast<unsigned>(i);
    if (r.rate_limited) out.rate_limited_axes |= 1U << static_cast<unsigned>(i);
  }
  out.flags.saturated = out.flags.saturated || out.saturated_axes != 0;
  out.flags.rate_limited = out.rate_limited_axes != 0;
}

// Every vector at n zeros (fixed capacity: no allocation). RT-safe.
template <class... Vectors>
TELEOP_RT void set_zero(int n, Vectors&... v) noexcept {
  (v.setZero(n), ...);
}

// What MasterLawAxes and SlaveLawAxes share around their core (as LawBase for the one-axis
// laws): the accessors and reset(). State is the side's own state, State::initial(n) its value
// at construction and after reset().
template <class State>
class LawAxesSide {
 public:
  // Clears the fault latch and every state but the clutch request (as MasterLaw::reset(),
  // SlaveLaw::reset()); the velocity filter at rest, or at position_m. RT-safe.
  TELEOP_RT void reset() noexcept {
    state_ = State::initial(core_.axes());
    core_.reset();
  }
  TELEOP_RT void reset(const AxisVector& position_m) noexcept {
    state_ = State::initial(core_.axes());
    core_.reset(position_m);
  }

  [[nodiscard]] bool faulted() const noexcept { return core_.faulted(); }
  [[nodiscard]] AxisVector velocity_m_per_s() const noexcept { return core_.filtered_velocity(); }
  [[nodiscard]] const LawAxesParams& params() const noexcept { return core_.params(); }

 protected:
  // Throws std::invalid_argument naming the field (validate()).
  LawAxesSide(const LawAxesParams& params, LawAxesCore::Side side)
      : core_(params, side), state_(State::initial(params.axes)) {}

  LawAxesCore core_;
  State state_{};
};

// MasterLawAxes' state: everything reset() clears (the vectors at n zeros).
struct MasterAxesState {
  bool was_clutched{false};
  bool hold_anchored{false};
  AxisVector hold_m{};
  AxisVector offset_m{};
  double weight{0.0};
  AxisVector velocity_source_m_per_s{};
  bool have_peer{false};
  AxisVector peer_position_m{};
  AxisVector peer_velocity_m_per_s{};
  AxisVector peer_force_N{};
  bool stepped{false};
  bool published_unclutched{false};
  AxisVector published_position_m{};
  AxisVector published_velocity_m_per_s{};
  bool published_clutched{false};

  TELEOP_RT [[nodiscard]] static MasterAxesState initial(int n) noexcept {
    MasterAxesState s;
    set_zero(n, s.hold_m, s.offset_m, s.velocity_source_m_per_s, s.peer_position_m,
             s.peer_velocity_m_per_s, s.peer_force_N, s.published_position_m,
             s.published_velocity_m_per_s);
    return s;
  }
};

// SlaveLawAxes' state: everything reset() clears.
struct SlaveAxesState {
  bool has_reference{false};
  bool was_following{false};
  bool holding{false};
  AxisVector reference_m{};
  AxisVector mismatch_m{};
  double mismatch_weight{0.0};
  AxisVector reference_velocity_m_per_s{};
  double weight{0.0};
  bool stepped{false};
  AxisVector position_m{};
  AxisVector measured_force_N{};

  TELEOP_RT [[nodiscard]] static SlaveAxesState initial(int n) noexcept {
    SlaveAxesState s;
    set_zero(n, s.reference_m, s.mismatch_m, s.reference_velocity_m_per_s, s.position_m,
             s.measured_force_N);
    return s;
  }
};

class MasterLawAxes : public LawAxesSide<MasterAxesState> {
 public:
  // Throws std::invalid_argument naming the field (validate()).
  explicit MasterLawAxes(const LawAxesParams& params);

  // One sample: own measured position (n entries), newest slave state. RT-safe.
  TELEOP_RT [[nodiscard]] CommandAxes step(const AxisVector& position_m,
                                           const PeerStateAxes& slave) noexcept;

  // New gains and master planes from the next step on (validated by the caller). RT-safe.
  TELEOP_RT void retune(const LawGainsAxes& gains, const PlaneSet& master_planes) noexcept;

  TELEOP_RT void set_clutch(bool engaged) noexcept { clutch_requested_ = engaged; }
  [[nodiscard]] bool clutch_engaged() const noexcept { return clutch_requested_; }

  // As MasterLaw::peer_state(), per axis. RT-safe.
  TELEOP_RT [[nodiscard]] PeerStateAxes peer_state() const noexcept;

  [[nodiscard]] double coupling_weight() const noexcept { return state_.weight; }
  [[nodiscard]] const AxisVector& offset_m() const noexcept { return state_.offset_m; }

 private:
  TELEOP_RT void set_terms() noexcept;
  TELEOP_RT void update_clutch(const AxisVector& position_m, bool clutched) noexcept;
  TELEOP_RT void publish(const AxisVector& position_m, const AxisVector& v_m,
                         bool clutched) noexcept;
  TELEOP_RT [[nodiscard]] AxisVector coupling(int n) const noexcept;

  bool use_kpm_{false};
  bool use_kdm_{false};
  bool use_kfm_{false};
  bool use_kvm_{false};
  bool clutch_requested_{false};  // kept by reset()
};

class SlaveLawAxes : public LawAxesSide<SlaveAxesState> {
 public:
  // Throws std::invalid_argument naming the field (validate()).
  explicit SlaveLawAxes(const LawAxesParams& params);

  // One sample: own measured position and environment force (n entries each), newest master
  // state. RT-safe.
  TELEOP_RT [[nodiscard]] CommandAxes step(const AxisVector& position_m,
                                           const AxisVector& measured_force_N,
                                           const PeerStateAxes& master) noexcept;

  TELEOP_RT void retune(const LawGainsAxes& gains, const PlaneSet& slave_planes) noexcept;

  // As SlaveLaw::peer_state(), per axis. RT-safe.
  TELEOP_RT [[nodiscard]] PeerStateAxes peer_state() const noexcept;

  [[nodiscard]] bool holding() const noexcept { return state_.holding; }
  [[nodiscard]] const AxisVector& reference_m() const noexcept { return state_.reference_m; }
  [[nodiscard]] double reference_weight() const noexcept { return state_.weight; }

 private:
  TELEOP_RT void set_terms() noexcept;
  TELEOP_RT void update_reference(const AxisVector& position_m,
                                  const PeerStateAxes& master) noexcept;
  TELEOP_RT void law_force(const AxisVector& position_m, const AxisVector& v_s, AxisVector& force_N,
                           CommandAxes& out) const noexcept;

  AxisMatrix kds_plus_kvs_{};
  bool follows_master_{false};
  bool use_kps_{false};
  bool use_kds_{false};
  bool use_kvs_{false};
};

}  // namespace teleop::control
