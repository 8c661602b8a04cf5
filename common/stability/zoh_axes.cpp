#include "common/stability/zoh_axes.hpp"

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <cmath>
#include <stdexcept>

namespace teleop::stability {

namespace {

using MatL = Eigen::Matrix<long double, Eigen::Dynamic, Eigen::Dynamic>;

}  // namespace

std::string check_plant_axes(const Eigen::MatrixXd& m, const Eigen::MatrixXd& b,
                             const Eigen::MatrixXd& k) {
  const Eigen::Index n = m.rows();
  if (n < 1 || n > 6) return "the plant must have 1 to 6 axes, got " + std::to_string(n);
  for (const auto* x : {&m, &b, &k}) {
    if (x->rows() != n || x->cols() != n) {
      return "mass, damping and stiffness must all be " + std::to_string(n) + "x" +
             std::to_string(n);
    }
    if (!x->allFinite()) return "mass, damping and stiffness must be finite";
  }
  if (!m.isApprox(m.transpose(), 1e-12)) return "the mass matrix must be symmetric";
  const Eigen::LLT<Eigen::MatrixXd> llt(m);
  if (llt.info() != Eigen::Success) return "the mass matrix must be positive definite";
  return "";
}

// E = exp(X), F = phi1(X) for X = A T: Taylor series on X / 2^s with ||X / 2^s||_inf <= 1/4,
// then s doublings exp(2Y) = E^2, phi1(2Y) = phi1(Y) (E + I) / 2 (as zoh.cpp for one axis).
ZohPlantAxes discretize_plant_axes(const Eigen::MatrixXd& mass_kg,
                                   const Eigen::MatrixXd& damping_Ns_per_m,
                                   const Eigen::MatrixXd& stiffness_N_per_m, double period_s) {
  if (const std::string why = check_plant_axes(mass_kg, damping_Ns_per_m, stiffness_N_per_m);
      !why.empty()) {
    throw std::invalid_argument(why);
  }
  if (!(period_s > 0.0) || !std::isfinite(period_s)) {
    throw std::invalid_argument("the period must be positive and finite");
  }
  const Eigen::Index n = mass_kg.rows();
  const long double t = period_s;
  const MatL m_inv = mass_kg.cast<long double>().inverse();
  MatL x = MatL::Zero(2 * n, 2 * n);
  x.topRightCorner(n, n) = MatL::Identity(n, n) * t;
  x.bottomLeftCorner(n, n) = -m_inv * stiffness_N_per_m.cast<long double>() * t;
  x.bottomRightCorner(n, n) = -m_inv * damping_Ns_per_m.cast<long double>() * t;
  const long double norm = x.cwiseAbs().rowwise().sum().maxCoeff();
  int squarings = 0;
  if (norm > 0.25L) squarings = static_cast<int>(std::ceil(std::log2(norm / 0.25L)));
  const MatL y = x * std::ldexp(1.0L, -squarings);
  const MatL identity = MatL::Identity(2 * n, 2 * n);
  MatL e = identity;
  MatL f = identity;
  MatL term = identity;
  for (int k = 1; k < 30; ++k) {
    term = (term * y) / static_cast<long double>(k);  // Y^k / k!
    e += term;
    f += term / static_cast<long double>(k + 1);
    if (term.cwiseAbs().maxCoeff() <= 1e-24L) break;
  }
  for (int i = 0; i < squarings; ++i) {
    f = (f * (e + identity)) * 0.5L;
    e = e * e;
  }
  ZohPlantAxes plant;
  plant.phi = e.cast<double>();
  // Gamma = T phi1(A T) [0; M^-1].
  plant.gamma = (t * f.rightCols(n) * m_inv).cast<double>();
  return plant;
}

}  // namespace teleop::stability
