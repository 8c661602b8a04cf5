// Fixture stiffness as a rank-one term: where the loop's modes cross the admissible boundary
// (docs/stability-limits.md). A fixture stiffness K multiplies one position state, so the
// closed loop of a block is A(K) = A(0) + K u e_p^T and its characteristic polynomial is
// det(zI - A(0)) (1 - K G(z)) with G(z) = e_p^T (zI - A(0))^-1 u. A mode meets the boundary of
// the admissible region at z exactly when K = 1 / G(z) is real and positive there; those K are
// found by following G along the boundary, never from polynomial coefficients.
#pragma once

#include <Eigen/Core>
#include <complex>
#include <vector>

#include "common/stability/discrete_model.hpp"

namespace teleop::stability {

// The admissible region for a required damping ratio zeta: |z| < 1 and every mode's
// -Re(s)/|s| >= zeta (s = ln(z)/T). Its boundary's upper half is the logarithmic spiral
// z(theta) = exp(-theta zeta / sqrt(1 - zeta^2)) e^{i theta}, theta in [0, pi] (the unit
// circle for zeta = 0); the region is {r e^{i theta} : r < |z(|theta|)|}.
class AdmissibleBoundary {
 public:
  explicit AdmissibleBoundary(double required_damping_ratio);
  [[nodiscard]] std::complex<double> at(double theta) const;
  [[nodiscard]] double decay_per_radian() const { return kappa_; }

 private:
  double kappa_{0.0};  // zeta / sqrt(1 - zeta^2)
};

struct Crossing {
  double stiffness_N_per_m{0.0};
  std::complex<double> z{};  // where the mode meets the boundary (upper half plane)
  // The mode only touches the boundary here (or two crossings lie too close to separate):
  // reported, and the verdict there is uncertain.
  bool near_double{false};
};

// One point of the boundary's upper half. With P0 = det M(z) (the characteristic polynomial
// is z^d P0) and P1 = det [[M, u], [e_p^T, 0]], the loop's is
// det(M - K u e_p^T) = P0 + K P1 = P1 (r + K), r = P0 / P1 = -1 / G: a mode is at z for K = -r.
struct BoundaryPoint {
  double theta{0.0};
  std::complex<double> p1_phase{};  // z^d P1 / |z^d P1|
  std::complex<double> r{};
  bool singular{false};  // P1 = 0 here (G = 0): evaluated a hair beside
};

struct CrossingSearch {
  std::vector<Crossing> crossings{};  // K in (0, max], ascending
  long boundary_points{0};            // evaluations of G along the boundary
  // Somewhere the boundary passes within the resolution of a pole or zero of G that the
  // sampling could not separate: a crossing may be missing there.
  bool unresolved{false};
  // The samples (theta ascending over [0, pi]), for counting modes at any K without
  // sampling again (RankOneLoop::modes_outside).
  std::vector<BoundaryPoint> samples{};
  double required_damping_ratio{0.0};
};

// One block of the loop with the stiffness of one fixture as the free parameter. The
// round-trip delay chain, if any, is eliminated: it contributes z^-d to one column, so every
// evaluation costs a solve of the 6x6 (at most) core whatever the delay.
class RankOneLoop {
 public:
  // `at_zero` / `at_one`: the block at K = 0 and K = 1 N/m (the other fixture as configured).
  // Throws std::invalid_argument if they differ elsewhere than in column `position_state`.
  RankOneLoop(const ModelBlock& at_zero, const ModelBlock& at_one, int position_state);

  // Every K in (0, max_stiffness] at which a mode meets the boundary, ascending.
  [[nodiscard]] CrossingSearch crossings(double required_damping_ratio,
                                         double max_stiffness_N_per_m) const;

  // How many modes lie outside the admissible region at K, by the argument principle along
  // the boundary; -1 when a mode lies on it within the resolution.
  [[nodiscard]] int modes_outside(double stiffness_N_per_m, double required_damping_ratio,
                                  long* boundary_points = nullptr) const;

  // The same from the samples of a crossing search (refined only where K makes the phase
  // move faster than they resolve); adds its evaluations to `boundary_points`.
  [[nodiscard]] int modes_outside(const CrossingSearch& search, double stiffness_N_per_m,
                                  long* boundary_points = nullptr) const;

  [[nodiscard]] int order() const { return m_ + delay_; }

  [[nodiscard]] BoundaryPoint evaluate(double theta, const AdmissibleBoundary& boundary) const;

 private:
  Eigen::MatrixXd core_{};          // A(0) without the delay chain
  Eigen::VectorXd u_{};             // dA/dK restricted to the core
  Eigen::VectorXd link_{};          // the column the last delayed state feeds (times z^-d)
  std::vector<double> neg_core_{};  // -A_core, row-major, and u and link as plain arrays
  std::vector<double> u_rm_{};
  std::vector<double> link_rm_{};
  int m_{0};
  int delay_{0};
  int source_{-1};  // core index of the delayed state's source (the master position)
  int position_{-1};
};

}  // namespace teleop::stability
