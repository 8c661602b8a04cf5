#include "common/stability/zoh.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace teleop::stability {

namespace {

// 2x2 long double matrices as plain arrays: this runs once per human of a band.
struct M2 {
  long double a{0.0L}, b{0.0L}, c{0.0L}, d{0.0L};  // [[a, b], [c, d]]
};
M2 mul(const M2& x, const M2& y) {
  return {x.a * y.a + x.b * y.c, x.a * y.b + x.b * y.d, x.c * y.a + x.d * y.c,
          x.c * y.b + x.d * y.d};
}

}  // namespace

// E = exp(X) and F = phi1(X) = sum X^n/(n+1)! for X = A T, by Taylor series on X / 2^s with
// ||X / 2^s|| <= 1/4, then s doublings: exp(2Y) = E^2, phi1(2Y) = phi1(Y) (E + I) / 2.
// Phi = E and Gamma = T F B: the augmented exponential exp([[A, B], [0, 0]] T) without the
// zero row, and no division by the difference of the poles anywhere.
ZohPlant discretize_plant(double mass_kg, double damping_Ns_per_m, double stiffness_N_per_m,
                          double period_s) {
  const long double t = period_s;
  const long double m = mass_kg;
  const M2 x{0.0L, t, -static_cast<long double>(stiffness_N_per_m) / m * t,
             -static_cast<long double>(damping_Ns_per_m) / m * t};
  const long double norm =
      std::max(std::fabs(x.a) + std::fabs(x.b), std::fabs(x.c) + std::fabs(x.d));
  int squarings = 0;
  if (!std::isfinite(norm)) {
    // An overflowing plant (e.g. a mass of 1e-4000): NaN matrices, which the spectrum reports
    // as an invalid model, never a number of squarings out of an infinite norm.
    ZohPlant plant;
    plant.phi.setConstant(std::numeric_limits<double>::quiet_NaN());
    plant.gamma.setConstant(std::numeric_limits<double>::quiet_NaN());
    return plant;
  }
  if (norm > 0.25L) squarings = static_cast<int>(std::ceil(std::log2(norm / 0.25L)));
  const long double scale = std::ldexp(1.0L, -squarings);
  const M2 y{x.a * scale, x.b * scale, x.c * scale, x.d * scale};
  M2 e{1.0L, 0.0L, 0.0L, 1.0L};  // exp(Y)
  M2 f{1.0L, 0.0L, 0.0L, 1.0L};  // phi1(Y)
  M2 term{1.0L, 0.0L, 0.0L, 1.0L};
  for (int n = 1; n < 30; ++n) {
    term = mul(term, y);
    const long double inv_n = 1.0L / static_cast<long double>(n);
    term = {term.a * inv_n, term.b * inv_n, term.c * inv_n, term.d * inv_n};  // Y^n / n!
    const long double to_phi = 1.0L / static_cast<long double>(n + 1);
    e = {e.a + term.a, e.b + term.b, e.c + term.c, e.d + term.d};
    f = {f.a + term.a * to_phi, f.b + term.b * to_phi, f.c + term.c * to_phi,
         f.d + term.d * to_phi};
    const long double size = std::max(std::max(std::fabs(term.a), std::fabs(term.b)),
                                      std::max(std::fabs(term.c), std::fabs(term.d)));
    if (size <= 1e-24L) break;
  }
  for (int i = 0; i < squarings; ++i) {
    const M2 e_plus_i{e.a + 1.0L, e.b, e.c, e.d + 1.0L};
    f = mul(f, e_plus_i);
    f = {f.a * 0.5L, f.b * 0.5L, f.c * 0.5L, f.d * 0.5L};
    e = mul(e, e);
  }
  ZohPlant plant;
  plant.phi << static_cast<double>(e.a), static_cast<double>(e.b), static_cast<double>(e.c),
      static_cast<double>(e.d);
  // Gamma = T phi1(A T) [0, 1/m]^T.
  plant.gamma << static_cast<double>(t * f.b / m), static_cast<double>(t * f.d / m);
  return plant;
}

ZohTransferFunction transfer_function(const ZohPlant& p) {
  // C adj(zI - phi) gamma with C = [1 0]; denominator det(zI - phi).
  ZohTransferFunction tf;
  tf.a1 = -p.phi.trace();
  tf.a2 = p.phi(0, 0) * p.phi(1, 1) - p.phi(0, 1) * p.phi(1, 0);
  tf.b1 = p.gamma(0);
  tf.b2 = p.phi(0, 1) * p.gamma(1) - p.phi(1, 1) * p.gamma(0);
  return tf;
}

}  // namespace teleop::stability
