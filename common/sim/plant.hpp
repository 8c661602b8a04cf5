// The physics of one simulated haptic device and what it is coupled to (docs/architecture.md §1.4,
// §2.2): a mass-damper along the device's arc, the human's impedance on the master side, an
// environment on the slave side and Coulomb friction, stepped over one control period with the
// actuator force held (ZOH).
//
//   (m + m_h) x'' + (b + b_h) x' + k_h x = u + F_h*(t) - F_e(x, x') - F_c sign(x')
//
// x is positive into the fixture/environment. The human term is Abbott-Okamura's
// equilibrium-point model F_h = F_h* - m_h x'' - b_h x' - k_h x, whose mass, damping and stiffness
// move to the left-hand side; F_h* is the exogenous input, supplied per period as a value and a
// slope (piecewise linear; see human.hpp for how profiles are sampled).
//
// Environment (force F_e on the environment, the device feels -F_e):
//  - free space: F_e = 0;
//  - tissue: unilateral spring-damper F_e = max(0, k_e (x - p_e) + b_e x') for x > p_e. The
//    clamp means tissue never pulls: a device leaving faster than the tissue relaxes separates
//    before x returns to p_e;
//  - rigid wall at p_w: an inelastic unilateral constraint (x <= p_w, perfectly plastic impact:
//    the velocity into the wall is lost on contact). No stiffness to tune and no artificial
//    kHz contact mode aliasing into the 1 kHz loop; a compliant stiff wall is a tissue with a
//    large k_e (1e5-1e6 N/m), which the exact per-mode solution handles without stiffness
//    trouble.
//
// Coulomb friction with sticking: at rest (x' = 0) the device stays at rest while the net
// applied force P = u + F_h* - k_h x - k_e (x - p_e)^+ satisfies |P| <= F_c and slides in the
// direction of P otherwise; sliding friction is -F_c sign(x'). Resting against the wall, the
// wall takes any push into it (the load cell reads max(P, 0)) and friction holds a pull away up
// to F_c: the split is statically indeterminate and this is the choice that makes the wall
// reaction the whole push, as a load cell between the tip and the wall would see it.
//
// Within a mode (free/contact, sliding sign or rest) the dynamics are linear with a
// piecewise-linear input, and each method uses the exact solution of that linear system (an
// augmented matrix exponential computed once in long double for the configured period, so a
// free step is exact to rounding). The methods differ in how they switch modes:
//  - kEventLocation: the contact switch, the velocity zero and the wall impact are located by
//    bisection on the analytic solution (on a dyadic grid of T/2^36 with precomputed
//    propagators), the mode switched and the step continued; leaving rest is found in closed
//    form (P is linear in time within a step). Chunks are short against the mode's dynamics
//    (|lambda| tau <= 1/4), and a chunk whose ends are both valid is still refined when an event
//    function could dip through zero inside it (a velocity that slows, nearly stops and speeds
//    up again; a device that turns just short of the wall), by bounds from the end values and
//    slopes. At most 64 events per step (Zeno guard), after which the step finishes
//    frozen-mode. Exact to rounding: it matches a fine RK4 reference to ~1e-12 relative on
//    random scenes with friction, humans, 1e6 N/m tissue and walls.
//  - kSubSteps: N sub-steps of T/N, each with the mode frozen at its start and then corrected
//    at its end (wall penetration projected onto the wall with zero velocity; a velocity that
//    changed sign under sliding friction set to zero). First order in T/N at switches.
// With no contact and no friction both are exact.
#pragma once

#include <array>
#include <chrono>
#include <cstdint>

#include "common/core/rt_safe.hpp"
#include "common/core/teleop_params.hpp"

namespace teleop::sim {

enum class EnvironmentKind { kFree, kTissue, kRigidWall };

// What the device touches on its + side (the slave's environment).
struct Environment {
  EnvironmentKind kind{EnvironmentKind::kFree};
  double stiffness_N_per_m{0.0};  // tissue only
  double damping_Ns_per_m{0.0};   // tissue only
  double position_m{0.0};         // surface: acts for x > position_m

  [[nodiscard]] static Environment free_space() { return {}; }
  [[nodiscard]] static Environment tissue(double stiffness_N_per_m, double damping_Ns_per_m,
                                          double position_m) {
    return {EnvironmentKind::kTissue, stiffness_N_per_m, damping_Ns_per_m, position_m};
  }
  [[nodiscard]] static Environment rigid_wall(double position_m) {
    return {EnvironmentKind::kRigidWall, 0.0, 0.0, position_m};
  }
};

enum class SteppingMethod { kSubSteps, kEventLocation };

[[nodiscard]] const char* to_string(SteppingMethod method) noexcept;

struct PlantParams {
  DeviceParams device{};
  double coulomb_friction_N{0.0};
  HumanImpedance human{};  // all zero: no human attached
  Environment environment{};
  SteppingMethod method{SteppingMethod::kEventLocation};
  int substeps{8};  // kSubSteps only
};

struct PlantState {
  double position_m{0.0};
  double velocity_m_per_s{0.0};
};

// The physics at the end of the last step (the left limit at the sample instant, before the
// next command applies): what sensors measure and what logging wants.
struct PlantOutput {
  double acceleration_m_per_s2{0.0};
  double environment_force_N{0.0};  // F_e, the force on the environment, >= 0
  double human_force_N{0.0};        // F_h, the human's force on the device along +x
  bool in_contact{false};           // touching the tissue or resting against the wall
  bool resting{false};              // stuck by friction or held by the wall
  int events{0};                    // mode switches located in the last step
  bool event_limit_hit{false};      // the Zeno guard ended event location early
};

// One device. Construction and set_* compute the propagators (tens of microseconds, no
// allocation); step() is RT-safe: no allocation, no exception.
class Plant {
 public:
  // Throws std::invalid_argument naming the field when a parameter is out of range.
  Plant(const PlantParams& params, std::chrono::nanoseconds period);

  void reset(const PlantState& state) noexcept;

  // One control period: actuator force u held, exogenous force (the human's F_h*)
  // exogenous_N + exogenous_slope_N_per_s * tau for tau in [0, T). RT-safe.
  TELEOP_RT const PlantOutput& step(double actuator_force_N, double exogenous_force_N = 0.0,
                                    double exogenous_slope_N_per_s = 0.0) noexcept;

  // The malicious user changes impedance at run time: recomputes the propagators.
  void set_human_impedance(const HumanImpedance& human);
  void set_period(std::chrono::nanoseconds period);
  void set_method(SteppingMethod method, int substeps);

  [[nodiscard]] const PlantState& state() const noexcept { return state_; }
  [[nodiscard]] const PlantOutput& output() const noexcept { return output_; }
  [[nodiscard]] const PlantParams& params() const noexcept { return params_; }
  [[nodiscard]] double period_s() const noexcept { return period_s_; }
  [[nodiscard]] std::uint64_t total_events() const noexcept { return total_events_; }

  // Bisection resolution: the period is 2^kTickBits ticks.
  static constexpr int kTickBits = 36;
  static constexpr int kMaxEventsPerStep = 64;
  static constexpr int kMaxWorkPerStep = 1 << 14;  // propagations; a safety net like the above

  // The exact solution after tau of M x'' + B x' + K x = g0 + g1 t, as increments:
  // x += x[0] v + x[1] n + x[2] g1, v = v[0] v + v[1] n + v[2] g1, with n = g0 - K x.
  struct Propagator {
    std::array<double, 3> x{};
    std::array<double, 3> v{};
  };

 private:
  struct ModeCache {
    double mass_kg{0.0};
    double damping_Ns_per_m{0.0};
    double stiffness_N_per_m{0.0};
    Propagator substep{};
    std::array<Propagator, kTickBits + 1> dyadic{};  // tau = T / 2^k
    int guard_level{0};                              // chunks no longer than T / 2^guard_level
  };
  struct Mode {
    bool resting{false};
    bool at_wall{false};
    bool contact{false};
    int sign{0};  // sliding friction direction; 0 without friction
  };
  struct Input {
    double actuator_N{0.0};
    double exogenous_N{0.0};
    double slope_N_per_s{0.0};
  };

  void validate() const;
  void rebuild();
  // `field` = `value` and rebuild() when the parameters stay valid; otherwise `field` is left
  // as it was and validate()'s exception thrown.
  template <typename T>
  void change(T& field, T value);
  TELEOP_RT [[nodiscard]] bool tissue() const noexcept;
  TELEOP_RT [[nodiscard]] bool wall() const noexcept;
  TELEOP_RT [[nodiscard]] bool tissue_contact(double x, double v) const noexcept;
  TELEOP_RT [[nodiscard]] double net_force(double x, double tau, bool contact,
                                           const Input& in) const noexcept;
  TELEOP_RT [[nodiscard]] Mode classify(double tau, const Input& in) noexcept;
  TELEOP_RT [[nodiscard]] bool valid(const Mode& mode, double x, double v) const noexcept;
  // Everything but damping: u + F_h* - k_h x - k_e (x - p_e) [contact] - F_c sign.
  TELEOP_RT [[nodiscard]] double net_drive(const Mode& mode, double x, double tau,
                                           const Input& in) const noexcept;
  TELEOP_RT [[nodiscard]] double acceleration(const Mode& mode, double x, double v, double tau,
                                              const Input& in) const noexcept;
  TELEOP_RT [[nodiscard]] bool may_hide_event(const Mode& mode, double tau0, double x0, double v0,
                                              double tau1, double x1, double v1,
                                              const Input& in) const noexcept;
  TELEOP_RT void correct(const Mode& mode) noexcept;
  TELEOP_RT void step_substeps(const Input& in) noexcept;
  TELEOP_RT void step_events(const Input& in) noexcept;
  TELEOP_RT void finish(const Input& in) noexcept;

  PlantParams params_{};
  double period_s_{0.0};
  PlantState state_{};
  PlantOutput output_{};
  std::array<ModeCache, 2> cache_{};  // [0] free, [1] tissue contact
  std::uint64_t total_events_{0};
};

}  // namespace teleop::sim
