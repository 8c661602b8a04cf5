// The master half of the three-channel law (Abbott-Okamura eqs. 7-9, docs/architecture.md §2.3):
//
//   F_am = w beta [K_pm (x_r - x_s/alpha) + K_dm (w v_r - v_s/alpha) + K_fm F_e] + K_vm v_m + F_mVF
//
// x_r = x_m - offset is the published (clutch-corrected) master position (x_hold while
// clutched), v_r the master's own filtered velocity v_m (held while uncoupled), x_s, v_s, F_e
// the newest valid slave state, F_mVF = K_mVF (x_m - p_m) for x_m > p_m. w is the coupling
// weight: 1 in normal operation, when this is exactly the law the stability engine analyses
// (common/stability/discrete_model.cpp). The master plant is pushed by -F_am: F_am is the
// force the master actuator applies against the human.
//
// Clutch (indexing), set_clutch(true):
//  - the master publishes clutched = true and a held position x_hold (its last published
//    unclutched position) with zero velocity, so the slave holds its reference;
//  - the coupling fades out: w falls by T / clutch_fade_s per sample to 0, and the velocity
//    reference decays with it (w v_r, v_r held at its last coupled value), so the force
//    neither steps at engage nor persists while clutched. K_vm v_m and the master's own
//    fixture still act: they are not coupling;
//  - on release the master absorbs the offset: offset = x_m - x_hold, so the published
//    position continues from x_hold and the slave's reference does not jump; the coupling
//    fades back in over clutch_fade_s.
//  If the clutch is engaged before anything was published unclutched (start-up, or after
//  reset()), x_hold is the slave's position / alpha, so releasing aligns the master to the
//  slave instead of dragging the slave to the master.
//
// Link: a peer with valid = false (nothing received, or the slave faulted) is not read; the
// coupling fades out as for the clutch, using the last valid slave state, and fades back in
// when valid states return. The coupling also fades in from 0 after construction and reset().
//
// Faults: a non-finite own position, a non-finite field of a valid peer state, or a
// non-finite computed force gives a 0 N command with flags.input_fault, and latches: every
// later step returns the same until reset(); peer_state() then reports valid = false.
//
// Limits: the actuator force is saturated to +-master_actuator.max_force_N, then limited to
// change by at most max_rate_N_per_s * T per sample (flags.saturated, flags.rate_limited).
#pragma once

#include "common/control/law_core.hpp"
#include "common/core/rt_safe.hpp"

namespace teleop::control {

class MasterLaw : public LawBase {
 public:
  // Throws std::invalid_argument naming the field (validate()).
  explicit MasterLaw(const LawParams& params);

  // One sample: own measured position, newest slave state. RT-safe (no allocation, lock,
  // exception or I/O).
  TELEOP_RT [[nodiscard]] Command step(double position_m, const PeerState& slave) noexcept;

  // Live retuning (the supervisor's guarded parameter changes, ramped by the caller): new gains
  // and master fixture from the next step on, every other state kept. The caller validated
  // them (finite; stiffness >= 0). RT-safe.
  TELEOP_RT void retune(const Gains& gains, const FixtureParams& master_fixture) noexcept;

  // Engage (true) or release (false) the clutch; takes effect at the next step(). RT-safe.
  TELEOP_RT void set_clutch(bool engaged) noexcept { clutch_requested_ = engaged; }
  [[nodiscard]] bool clutch_engaged() const noexcept { return clutch_requested_; }

  // What to send to the slave after step(): published position x_m - offset (x_hold while
  // clutched), own filtered velocity (0 while clutched), force 0, clutched, valid (false
  // before the first step and while faulted). RT-safe.
  TELEOP_RT [[nodiscard]] PeerState peer_state() const noexcept;

  // Clears the fault latch and every state except the clutch request: velocity at rest at
  // the next sample (or at `position_m`), offset 0, coupling fading in from 0. RT-safe.
  TELEOP_RT void reset() noexcept;
  TELEOP_RT void reset(double position_m) noexcept;

  [[nodiscard]] double coupling_weight() const noexcept { return state_.weight; }
  [[nodiscard]] double offset_m() const noexcept { return state_.offset_m; }

 private:
  TELEOP_RT void set_terms(const Gains& g) noexcept;
  // Which terms are non-zero (from the gains and beta).
  bool use_kpm_{false};
  bool use_kdm_{false};
  bool use_kfm_{false};
  bool use_kvm_{false};
  bool clutch_requested_{false};  // kept by reset()

  // Everything reset() clears.
  struct State {
    bool was_clutched{false};
    bool hold_anchored{false};  // x_hold came from a published position or the slave's
    double hold_m{0.0};
    double offset_m{0.0};
    double weight{0.0};
    double velocity_source_m_per_s{0.0};  // v_r: live while coupled, held otherwise
    bool have_peer{false};
    double peer_position_m{0.0};
    double peer_velocity_m_per_s{0.0};
    double peer_force_N{0.0};
    bool stepped{false};
    bool published_unclutched{false};
    double published_position_m{0.0};
    double published_velocity_m_per_s{0.0};
    bool published_clutched{false};
  };
  State state_{};
};

}  // namespace teleop::control
