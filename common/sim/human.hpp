// The human on the master (Abbott-Okamura eq. 2, equilibrium-point model):
//   F_h = F_h*(t) - m_h x'' - b_h x' - k_h x,
// an exogenous force profile F_h*(t) pushed through an impedance. The impedance is fixed, or a
// "malicious user" walks it through the corners and grid points of a HumanBand, dwelling on each,
// looking for a limit cycle.
#pragma once

#include <cstddef>
#include <optional>
#include <vector>

#include "common/core/rt_safe.hpp"
#include "common/core/teleop_params.hpp"

namespace teleop::sim {

enum class ProfileKind { kConstant, kRamp, kSinusoid, kTrace };

// F_h*(t) in N, t in s from the start of the run.
struct ForceProfile {
  ProfileKind kind{ProfileKind::kConstant};
  double value_N{0.0};      // constant; ramp: from; sinusoid: offset
  double to_N{0.0};         // ramp: final value, held after the ramp
  double start_s{0.0};      // ramp start
  double duration_s{0.0};   // ramp duration (0: a step at start_s)
  double amplitude_N{0.0};  // sinusoid
  double frequency_hz{0.0};
  double phase_rad{0.0};
  std::vector<double> times_s{};   // trace knots, strictly increasing; linear between, held
  std::vector<double> values_N{};  // outside

  [[nodiscard]] static ForceProfile constant(double value_N);
  [[nodiscard]] static ForceProfile ramp(double from_N, double to_N, double start_s,
                                         double duration_s);
  // offset + amplitude sin(2 pi f t + phase)
  [[nodiscard]] static ForceProfile sinusoid(double offset_N, double amplitude_N,
                                             double frequency_hz, double phase_rad = 0.0);
  [[nodiscard]] static ForceProfile trace(std::vector<double> times_s,
                                          std::vector<double> values_N);

  void validate() const;  // throws std::invalid_argument naming the field
  TELEOP_RT [[nodiscard]] double at(double t_s) const noexcept;  // RT-safe
};

// How F_h* enters the plant within one control period [t, t + T).
//  kZeroOrderHold: F_h*(t) held, as the paper's discrete model (and the analyser) assumes; use it
//    when the simulation must agree with the analyser.
//  kFirstOrderHold: linear from F_h*(t) to F_h*(t + T); the plant integrates the ramp exactly, so
//    constants, ramps and traces with knots on sample times are reproduced exactly and a
//    sinusoid to O(T^2), with no sub-step sampling of the profile.
enum class ProfileSampling { kZeroOrderHold, kFirstOrderHold };

struct PeriodForce {
  double force_N{0.0};
  double slope_N_per_s{0.0};
};

struct MaliciousUserParams {
  HumanBand band{};           // points_per_axis >= 2
  double force_level_N{0.0};  // where the band's bounding lines are evaluated
  double dwell_s{1.0};        // time on each impedance
};

// The schedule: the 8 corners of the band's (m, b, k) box at the force level first (the extremes
// are where the worst case usually sits), then the remaining points of the points_per_axis^3
// grid in lexicographic order; then it starts over.
class MaliciousUser {
 public:
  explicit MaliciousUser(const MaliciousUserParams& params);  // throws std::invalid_argument

  [[nodiscard]] std::size_t size() const noexcept { return schedule_.size(); }
  [[nodiscard]] const HumanImpedance& impedance(std::size_t index) const noexcept {
    return schedule_[index];
  }
  [[nodiscard]] bool is_corner(std::size_t index) const noexcept { return index < 8; }
  TELEOP_RT [[nodiscard]] std::size_t index_at(double t_s) const noexcept;  // RT-safe
  [[nodiscard]] const MaliciousUserParams& params() const noexcept { return params_; }

 private:
  MaliciousUserParams params_{};
  std::vector<HumanImpedance> schedule_{};
};

struct HumanParams {
  ForceProfile profile{};
  HumanImpedance impedance{};  // ignored when malicious is set
  ProfileSampling sampling{ProfileSampling::kZeroOrderHold};
  std::optional<MaliciousUserParams> malicious{};

  // A malicious user pushing with a constant F_h* equal to the band's force level.
  [[nodiscard]] static HumanParams malicious_pushing(const HumanBand& band, double force_level_N,
                                                     double dwell_s);
};

class Human {
 public:
  explicit Human(HumanParams params);  // throws std::invalid_argument naming the field

  // F_h* over [t, t + T) per the sampling mode. RT-safe.
  TELEOP_RT [[nodiscard]] PeriodForce exogenous(double t_s, double period_s) const noexcept;
  TELEOP_RT [[nodiscard]] HumanImpedance impedance_at(double t_s) const noexcept;
  // The malicious user's schedule index at t (for logging); nullopt for a fixed impedance.
  TELEOP_RT [[nodiscard]] std::optional<std::size_t> malicious_index_at(double t_s) const noexcept;
  [[nodiscard]] const HumanParams& params() const noexcept { return params_; }
  [[nodiscard]] const std::optional<MaliciousUser>& malicious() const noexcept {
    return malicious_;
  }

 private:
  HumanParams params_{};
  std::optional<MaliciousUser> malicious_{};
};

}  // namespace teleop::sim
