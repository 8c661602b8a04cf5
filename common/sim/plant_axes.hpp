// One simulated device with n task-space axes (issue 18, "Simulation"; docs/plant-axes.md): the
// vector form of plant.hpp's Plant, stepped exactly over each control period with the actuator
// force held (ZOH).
//
//   (M + M_h) x'' + (B + B_h) x' + K_h x + C sgn(x') = u + F_h*(t) + F_env(x, x')
//
// M is the n x n mass matrix (symmetric positive definite), B and C diagonal (viscous and Coulomb
// per task axis), the human the equilibrium-point model F_h = F_h* - M_h x'' - B_h x' - K_h x
// with symmetric matrices (as Plant's one axis, its mass, damping and spring move to the left).
// F_h* is supplied per period as a value and a slope (piecewise linear).
//
// Environment: up to four planes, each a tissue-like unilateral spring-damper on a half-space.
// Plane j with unit normal n_j and offset p_j is entered where d_j = n_j^T x - p_j > 0 and
// pushes F = -f_j n_j with f_j = max(0, k_j d_j + b_j n_j^T x'): it never pulls (a device leaving
// faster than the plane relaxes separates before d_j returns to 0). In contact it adds
// k_j n_j n_j^T to the stiffness and b_j n_j n_j^T to the damping, a rank-one term.
//
// Coulomb friction with sticking per axis, as Plant: an axis at rest (x'_i = 0) stays at rest
// while the net force on it without friction, P_i, satisfies |P_i| <= C_i, and slides in the
// direction of P_i otherwise. This is exact only when the total mass M + M_h is diagonal: then
// a stuck axis's constraint force does not accelerate the other axes and P_i does not depend
// on which other axes stick. With a coupled mass the friction forces of the stuck axes solve
// a complementarity problem over all axes at once, which this plant does not do, so a coupled
// total mass with any C_i > 0 is refused.
//
// A mode is the set of planes in contact and the set of stuck axes. Within a mode the dynamics
// are linear with a piecewise-linear input; their exact solution is the matrix exponential of
// the 2n-state system (augmented for the held and ramped forces), precomputed in long double
// per mode for the periods T / 2^k, k = 0..36. Mode switches (a plane entered or left, a
// sliding axis stopping, a stuck axis breaking free) are located inside the period by
// bisection on that dyadic grid, as Plant's kEventLocation: the first chunk whose end leaves
// the mode, or whose end values and slopes say an event function may dip through zero inside,
// is halved down to one tick (T / 2^36); the step continues from its far side in the new mode.
// With every axis stuck the state is constant and the instant the first axis breaks free is
// found in closed form (P is linear in time then). At most 64 events per step (Zeno guard).
//
// Propagators are cached per mode in a fixed-capacity pool (64 modes). Construction fills it
// with every mode when they fit (always without friction: 2^planes <= 16 modes); otherwise the
// modes without stuck axes are filled and the others are computed on first use inside step()
// into the least recently used slot, without allocation (fixed-size long-double matrices; a few
// tens of microseconds at n = 6).
#pragma once

#include <Eigen/Core>
#include <array>
#include <chrono>
#include <cstdint>
#include <vector>

#include "common/core/fixed_axes.hpp"
#include "common/core/rt_safe.hpp"
#include "common/core/teleop_axes.hpp"
#include "common/sim/plant.hpp"

namespace teleop::sim {

// Fixed-capacity n-vectors and n x n matrices (no allocation for any n <= kMaxAxes).
using AxesVector = FixedAxisVector;
using AxesMatrix = FixedAxisMatrix;

inline constexpr int kMaxContactPlanes = 4;

// A tissue-like half-space: pushes f n back with f = max(0, k d + b n^T v) where
// d = n^T x - offset_m > 0.
struct ContactPlane {
  Eigen::VectorXd normal{};  // n, unit length
  double offset_m{0.0};
  double stiffness_N_per_m{0.0};
  double damping_Ns_per_m{0.0};
};

struct PlantAxesParams {
  DeviceAxesParams device{};           // M (n x n SPD), B and C diagonals (n)
  HumanImpedanceAxes human{};          // empty matrices: no human; else n x n symmetric, >= 0
  std::vector<ContactPlane> planes{};  // at most kMaxContactPlanes

  [[nodiscard]] int axes() const noexcept { return static_cast<int>(device.mass_kg.rows()); }
};

// The one-axis Plant's parameters as n = 1 (a tissue becomes the plane normal (+1) at its
// position). Throws std::invalid_argument naming the field for what PlantAxes does not model:
// a rigid wall (environment.kind) and sub-stepping (method).
[[nodiscard]] PlantAxesParams to_axes(const PlantParams& one_axis);

struct PlantAxesState {
  AxesVector position_m{};
  AxesVector velocity_m_per_s{};
};

// The physics at the end of the last step (the left limit at the sample instant).
struct PlantAxesOutput {
  AxesVector acceleration_m_per_s2{};
  AxesVector environment_force_N{};                       // on the device: -sum_j f_j n_j
  AxesVector human_force_N{};                             // F_h on the device
  std::array<double, kMaxContactPlanes> plane_force_N{};  // f_j >= 0, on plane j
  unsigned contact_mask{0};                               // bit j: plane j in contact
  unsigned stuck_mask{0};                                 // bit i: axis i held by friction
  int events{0};                                          // mode switches located in the last step
  double first_event_s{-1.0};  // time of the first of them within the step; -1: none
  bool event_limit_hit{false};
};

class PlantAxes {
 public:
  // Throws std::invalid_argument naming the field when a parameter is out of range.
  PlantAxes(const PlantAxesParams& params, std::chrono::nanoseconds period);

  // Sizes must be n (checked by assertion only: RT-safe).
  void reset(const PlantAxesState& state) noexcept;

  // One control period: actuator force u held, exogenous force (the human's F_h*)
  // exogenous_N + slope_N_per_s * tau for tau in [0, T). Each vector has n entries. RT-safe.
  TELEOP_RT const PlantAxesOutput& step(const AxesVector& actuator_N, const AxesVector& exogenous_N,
                                        const AxesVector& slope_N_per_s) noexcept;
  TELEOP_RT const PlantAxesOutput& step(const AxesVector& actuator_N) noexcept;

  [[nodiscard]] int axes() const noexcept { return n_; }
  [[nodiscard]] const PlantAxesState& state() const noexcept { return state_; }
  [[nodiscard]] const PlantAxesOutput& output() const noexcept { return output_; }
  [[nodiscard]] const PlantAxesParams& params() const noexcept { return params_; }
  [[nodiscard]] double period_s() const noexcept { return period_s_; }
  [[nodiscard]] std::uint64_t total_events() const noexcept { return total_events_; }
  // Modes whose propagators were computed inside step() (cache misses).
  [[nodiscard]] std::uint64_t late_modes() const noexcept { return late_modes_; }

  static constexpr int kTickBits = 36;
  static constexpr int kMaxEventsPerStep = 64;
  static constexpr int kMaxWorkPerStep = 1 << 14;
  static constexpr int kModeSlots = 64;

 private:
  struct Mode {
    unsigned contact{0};
    unsigned stuck{0};
    std::array<int, kMaxAxes> sign{};  // sliding friction direction; 0 when stuck or C_i = 0
  };
  struct Input {
    const AxesVector* actuator;
    const AxesVector* exogenous;
    const AxesVector* slope;
  };
  // Per contact set: the stiffness, damping and damping-scaled inverse mass of that mode.
  struct ContactModel {
    AxesMatrix stiffness{};
    AxesMatrix damping{};
    int guard_level{0};  // chunks no longer than T / 2^guard_level
  };
  struct Slot {
    int key{-1};
    std::uint64_t used{0};
    std::size_t offset{0};  // into table_: (kTickBits + 1) levels of 2n x 3n, column-major
  };

  void validate() const;
  void build_models();
  TELEOP_RT void fill(int slot, int key) noexcept;
  TELEOP_RT [[nodiscard]] const double* propagators(unsigned contact, unsigned stuck) noexcept;
  TELEOP_RT [[nodiscard]] double depth(int plane, const AxesVector& x) const noexcept;
  TELEOP_RT [[nodiscard]] double normal_dot(int plane, const AxesVector& v) const noexcept;
  TELEOP_RT [[nodiscard]] bool plane_contact(int plane, const AxesVector& x,
                                             const AxesVector& v) const noexcept;
  TELEOP_RT [[nodiscard]] unsigned contacts(const AxesVector& x,
                                            const AxesVector& v) const noexcept;
  // u + F_h* - K_h x - sum_contact k_j d_j n_j: everything but damping and friction.
  TELEOP_RT void net_force(const AxesVector& x, double tau, unsigned contact, const Input& in,
                           AxesVector& out) const noexcept;
  // net_force - C sgn, what the propagators take.
  TELEOP_RT void net_drive(const Mode& mode, const AxesVector& x, double tau, const Input& in,
                           AxesVector& out) const noexcept;
  // The net force without friction on each axis, damping included (P of a stuck axis).
  TELEOP_RT void applied_force(unsigned contact, const AxesVector& x, const AxesVector& v,
                               double tau, const Input& in, AxesVector& out) const noexcept;
  TELEOP_RT void acceleration(const Mode& mode, const AxesVector& x, const AxesVector& v,
                              double tau, const Input& in, AxesVector& out) const noexcept;
  TELEOP_RT [[nodiscard]] Mode classify(double tau, const Input& in) noexcept;
  TELEOP_RT [[nodiscard]] bool valid(const Mode& mode, const AxesVector& x, const AxesVector& v,
                                     double tau, const Input& in) const noexcept;
  TELEOP_RT [[nodiscard]] bool may_hide_event(const Mode& mode, double tau0,
                                              const PlantAxesState& s0, double tau1,
                                              const PlantAxesState& s1,
                                              const Input& in) const noexcept;
  TELEOP_RT void propagate(const double* table, std::size_t level, const Mode& mode, double tau,
                           const Input& in, PlantAxesState& out) const noexcept;
  TELEOP_RT [[nodiscard]] double rest_wait_s(const Mode& mode, double tau,
                                             const Input& in) const noexcept;
  TELEOP_RT void step_events(const Input& in) noexcept;
  TELEOP_RT void finish(const Input& in) noexcept;

  PlantAxesParams params_{};
  int n_{0};
  int planes_{0};
  double period_s_{0.0};
  bool mass_diagonal_{false};
  unsigned friction_axes_{0};  // bit i: C_i > 0
  AxesMatrix mass_kg_{};       // M + M_h
  AxesMatrix mass_inverse_{};
  AxesVector coulomb_N_{};
  AxesMatrix human_stiffness_{};
  AxesMatrix human_damping_{};
  AxesMatrix human_mass_{};
  std::array<AxesVector, kMaxContactPlanes> normal_{};
  std::array<double, kMaxContactPlanes> offset_m_{};
  std::array<double, kMaxContactPlanes> stiffness_{};
  std::array<double, kMaxContactPlanes> damping_{};
  std::array<ContactModel, 1 << kMaxContactPlanes> model_{};
  std::vector<double> table_{};     // the slots' propagators, allocated at construction
  std::vector<int> slot_of_key_{};  // key = contact | stuck << kMaxContactPlanes; -1: none
  std::array<Slot, kModeSlots> slots_{};
  int slot_count_{0};
  std::uint64_t clock_{0};
  PlantAxesState state_{};
  PlantAxesOutput output_{};
  std::uint64_t total_events_{0};
  std::uint64_t late_modes_{0};
};

}  // namespace teleop::sim
