// The slave half of the three-channel law (Abbott-Okamura eqs. 7-9, docs/architecture.md §2.3):
//
//   F_as = K_ps (x_r - x_s) + K_ds (u v_r - v_s) - K_vs v_s - F_sVF
//
// x_r = alpha x_m and v_r = alpha v_m from the newest master state (v_m is the master's own
// filtered velocity, as transmitted), v_s the slave's own filtered velocity,
// F_sVF = K_sVF (x_s - p_s) for x_s > p_s. u is the reference-velocity weight: 1 in normal
// operation, when this is exactly the law the stability engine analyses
// (common/stability/discrete_model.cpp). F_as pushes the slave (F_as - F_e = Z_s X_s).
//
// Hold: while the master state is clutched or not valid (nothing received, master faulted)
// the slave holds its reference: x_r stays where it last was (alpha times the last valid
// unclutched master position; the slave's own position if there never was one), and the
// velocity reference fades out (u falls by T / clutch_fade_s per sample, v_r held), so the
// command does not step. When valid unclutched states return, x_r follows them again and u
// fades back in. Any mismatch between the held and the live reference at that moment (about
// 0 after a clutch, because the master absorbs its offset; the whole start-up offset when
// the link first comes up) fades out over clutch_fade_s:
//   x_r = alpha x_m + m (x_hold - alpha x_m(resume)),  m from 1 down to 0 by T / clutch_fade_s.
// u also fades in from 0 after construction and reset(); with clutch_fade_s = 0 every
// transition is immediate.
//
// Workspace limits (slave coordinates, all evaluated every sample, none latched):
//  - reference: x_r outside [min_position_m, max_position_m] is clamped to the nearer bound
//    and its velocity reference set to 0 (flags.reference_limited): the slave does not chase
//    the master out of its workspace;
//  - violation: x_s outside [min_position_m, max_position_m] or |v_s| > max_velocity_m_per_s
//    replaces the law by the safe command
//      F = K_ps (clamp(x_s, min, max) - x_s) - (K_ds + K_vs) v_s - F_sVF
//    (flags.limit_violation): damping only inside the position limits (a velocity
//    violation), a spring back to the violated bound plus damping outside them; the master is
//    ignored and the fixture still acts. The law resumes when the slave is back inside.
//  - force: the command is clamped to +-max_force_N (flags.saturated).
// Then the actuator: saturation to +-slave_actuator.max_force_N and the per-sample rate limit
// max_rate_N_per_s * T (flags.saturated, flags.rate_limited).
//
// Faults: a non-finite own position or measured force, a non-finite field of a valid master
// state, or a non-finite computed force gives a 0 N command with flags.input_fault, and
// latches until reset(); peer_state() then reports valid = false.
#pragma once

#include "common/control/law_core.hpp"
#include "common/core/rt_safe.hpp"

namespace teleop::control {

class SlaveLaw : public LawBase {
 public:
  // Throws std::invalid_argument naming the field (validate()).
  explicit SlaveLaw(const LawParams& params);

  // One sample: own measured position, own measured environment force F_e (only relayed to
  // the master, for K_fm), newest master state. RT-safe (no allocation, lock, exception or
  // I/O).
  TELEOP_RT [[nodiscard]] Command step(double position_m, double measured_force_N,
                                       const PeerState& master) noexcept;

  // Live retuning (the supervisor's guarded parameter changes, ramped by the caller): new gains
  // and slave fixture from the next step on, every other state kept. The caller validated them.
  // RT-safe.
  TELEOP_RT void retune(const Gains& gains, const FixtureParams& slave_fixture) noexcept;

  // What to send to the master after step(): own position, own filtered velocity, measured
  // force, clutched = false, valid (false before the first step and while faulted). RT-safe.
  TELEOP_RT [[nodiscard]] PeerState peer_state() const noexcept;

  // Clears the fault latch and every state: velocity at rest at the next sample (or at
  // `position_m`), no reference (the next step holds where the slave is unless a valid
  // unclutched master state arrives), velocity reference fading in from 0. RT-safe.
  TELEOP_RT void reset() noexcept;
  TELEOP_RT void reset(double position_m) noexcept;

  [[nodiscard]] bool holding() const noexcept { return state_.holding; }
  // The position reference x_r (slave coordinates) of the last step, before clamping.
  [[nodiscard]] double reference_m() const noexcept { return state_.reference_m; }
  [[nodiscard]] double reference_weight() const noexcept { return state_.weight; }

 private:
  TELEOP_RT void set_terms(const Gains& g) noexcept;
  // Which terms are non-zero (from the gains) and which limits are set.
  bool follows_master_{false};  // K_ps or K_ds non-zero
  bool use_kps_{false};
  bool use_kds_{false};
  bool use_kvs_{false};
  bool check_position_{false};
  bool check_velocity_{false};

  // Everything reset() clears.
  struct State {
    bool has_reference{false};
    bool was_following{false};
    bool holding{false};
    double reference_m{0.0};  // x_r of the last step (held while holding)
    double mismatch_m{0.0};   // held minus live reference when following resumed
    double mismatch_weight{0.0};
    double reference_velocity_m_per_s{0.0};  // v_r: live while following, held otherwise
    double weight{0.0};
    bool stepped{false};
    double position_m{0.0};
    double measured_force_N{0.0};
  };
  State state_{};
};

}  // namespace teleop::control
