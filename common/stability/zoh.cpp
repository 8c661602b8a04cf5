#include "common/stability/zoh.hpp"

#include <Eigen/Dense>
#include <cmath>

namespace teleop::stability {

namespace {

using Mat3L = Eigen::Matrix<long double, 3, 3>;

// exp(M) by scaling to ||M|| <= 1/4, a Taylor series to long double round-off, then squaring.
Mat3L expm(const Mat3L& m) {
  const long double norm = m.cwiseAbs().rowwise().sum().maxCoeff();
  int squarings = 0;
  if (norm > 0.25L) {
    squarings = static_cast<int>(std::ceil(std::log2(norm / 0.25L)));
  }
  const Mat3L scaled = m / std::ldexp(1.0L, squarings);
  Mat3L result = Mat3L::Identity();
  Mat3L term = Mat3L::Identity();
  for (int n = 1; n < 40; ++n) {
    term = term * scaled / static_cast<long double>(n);
    result += term;
    if (term.cwiseAbs().maxCoeff() <= 1e-22L * result.cwiseAbs().maxCoeff()) {
      break;
    }
  }
  for (int i = 0; i < squarings; ++i) {
    result = result * result;
  }
  return result;
}

}  // namespace

ZohPlant discretize_plant(double mass_kg, double damping_Ns_per_m, double stiffness_N_per_m,
                          double period_s) {
  const long double m = mass_kg;
  const long double t = period_s;
  Mat3L aug = Mat3L::Zero();
  aug(0, 1) = t;
  aug(1, 0) = -static_cast<long double>(stiffness_N_per_m) / m * t;
  aug(1, 1) = -static_cast<long double>(damping_Ns_per_m) / m * t;
  aug(1, 2) = t / m;
  const Mat3L e = expm(aug);
  ZohPlant plant;
  for (int i = 0; i < 2; ++i) {
    for (int j = 0; j < 2; ++j) {
      plant.phi(i, j) = static_cast<double>(e(i, j));
    }
    plant.gamma(i) = static_cast<double>(e(i, 2));
  }
  return plant;
}

ZohTransferFunction transfer_function(const ZohPlant& p) {
  // C adj(zI - phi) gamma with C = [1 0]; denominator det(zI - phi).
  ZohTransferFunction tf;
  tf.a1 = -p.phi.trace();
  tf.a2 = p.phi.determinant();
  tf.b1 = p.gamma(0);
  tf.b2 = p.phi(0, 1) * p.gamma(1) - p.phi(1, 1) * p.gamma(0);
  return tf;
}

}  // namespace teleop::stability
