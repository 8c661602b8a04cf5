// Exact zero-order-hold discretisation of a mass-spring-damper (Abbott-Okamura eq. 27).
#pragma once

#include <Eigen/Core>

namespace teleop::stability {

// x(k+1) = phi x(k) + gamma u(k) for the state [position_m, velocity_m_per_s] of
// m x'' + b x' + k x = u with u held constant over each period. Exact at the samples.
struct ZohPlant {
  Eigen::Matrix2d phi{Eigen::Matrix2d::Identity()};
  Eigen::Vector2d gamma{Eigen::Vector2d::Zero()};
};

// Computed as exp(A T) and T phi1(A T) B (the augmented exponential exp([[A, B], [0, 0]] T)) by
// a Taylor series with scaling and squaring in long double: no closed form that divides by the
// difference of the poles, so it stays accurate through critical damping and as T -> 0.
[[nodiscard]] ZohPlant discretize_plant(double mass_kg, double damping_Ns_per_m,
                                        double stiffness_N_per_m, double period_s);

// The same map as a transfer function X(z)/U(z) = (b1 z + b2) / (z^2 + a1 z + a2).
struct ZohTransferFunction {
  double a1{0.0};
  double a2{0.0};
  double b1{0.0};
  double b2{0.0};
};
[[nodiscard]] ZohTransferFunction transfer_function(const ZohPlant& plant);

}  // namespace teleop::stability
