// Exact zero-order-hold discretisation of an n-axis coupled mass-spring-damper (issue 18,
// "Simulation" and "Stability"): M x'' + B x' + K x = u with M symmetric positive definite, the
// vector generalisation of zoh.hpp's one axis (Abbott-Okamura eq. 27).
#pragma once

#include <Eigen/Core>
#include <string>

namespace teleop::stability {

// x(k+1) = phi x(k) + gamma u(k) for the state [positions (m); velocities (m/s)] (2n) and the
// force u (N, n) held over each period. Exact at the samples.
struct ZohPlantAxes {
  Eigen::MatrixXd phi;    // 2n x 2n
  Eigen::MatrixXd gamma;  // 2n x n
};

// What is wrong with (M, B, K) for n axes (empty when nothing is): square, of one size 1-6,
// finite, M symmetric positive definite.
[[nodiscard]] std::string check_plant_axes(const Eigen::MatrixXd& mass_kg,
                                           const Eigen::MatrixXd& damping_Ns_per_m,
                                           const Eigen::MatrixXd& stiffness_N_per_m);

// exp(A T) and T phi1(A T) [0; M^-1] by the same Taylor series with scaling and squaring in long
// double as the one-axis discretize_plant (no eigen-decomposition, so it stays accurate for
// repeated and critically damped modes). Throws std::invalid_argument naming the fault when
// check_plant_axes does.
[[nodiscard]] ZohPlantAxes discretize_plant_axes(const Eigen::MatrixXd& mass_kg,
                                                 const Eigen::MatrixXd& damping_Ns_per_m,
                                                 const Eigen::MatrixXd& stiffness_N_per_m,
                                                 double period_s);

}  // namespace teleop::stability
