// ZOH coefficients against the 50-digit reference in every damping regime.
#include <gtest/gtest.h>

#include <cmath>

#include "common/stability/zoh.hpp"
#include "reference.hpp"

namespace teleop::stability {
namespace {

struct Case {
  const char* name;
  double m, b, k, t;
};

// Relative error per coefficient; an entry far below its matrix's scale is compared against
// that scale instead (its own relative error is then meaningless for the model).
void expect_close(double got, const reference::Real& want, double scale, const char* what,
                  const Case& c) {
  const double w = static_cast<double>(want);
  const double denom = std::max(std::abs(w), 1e-6 * scale);
  EXPECT_LE(std::abs(got - w) / denom, 1e-12)
      << c.name << " " << what << " got " << got << " want " << w;
}

TEST(Zoh, MatchesHighPrecisionReferenceInEveryDampingRegime) {
  // zeta = b / (2 sqrt(k m)); critical damping exactly at b = 2 for k = 100, m = 0.01.
  const Case cases[] = {
      {"underdamped paddle+finger", 0.050, 2.41, 300.0, 0.002},
      {"lightly damped stiff", 0.036, 0.49, 1e5, 0.001},
      {"critically damped", 0.01, 2.0, 100.0, 0.002},
      {"critical +1e-9", 0.01, 2.0 * (1.0 + 1e-9), 100.0, 0.002},
      {"critical -1e-9", 0.01, 2.0 * (1.0 - 1e-9), 100.0, 0.002},
      {"overdamped", 0.01, 50.0, 100.0, 0.002},
      {"heavily overdamped", 0.001, 10.0, 10.0, 0.002},
      {"mass-damper (slave)", 0.036, 0.49, 0.0, 0.002},
      {"pure mass", 0.04, 0.0, 0.0, 0.001},
      {"T = 10 us stiff", 0.04, 0.41, 1e5, 1e-5},
      {"T = 10 us critical", 0.01, 2.0, 100.0, 1e-5},
      {"many periods per sample", 0.05, 0.5, 1e5, 0.01},
  };
  for (const Case& c : cases) {
    const ZohPlant got = discretize_plant(c.m, c.b, c.k, c.t);
    const reference::Zoh want = reference::zoh(reference::Real(c.m), reference::Real(c.b),
                                               reference::Real(c.k), reference::Real(c.t));
    for (int i = 0; i < 2; ++i) {
      for (int j = 0; j < 2; ++j) {
        // Rows have different units (m and m/s): scale each row by its own magnitude.
        const double row_scale = std::max(std::abs(got.phi(i, 0)), std::abs(got.phi(i, 1)));
        expect_close(got.phi(i, j), want.phi[i][j], row_scale, "phi", c);
      }
      expect_close(got.gamma(i), want.gamma[i], std::abs(got.gamma(i)), "gamma", c);
    }
  }
}

TEST(Zoh, MassDamperHasTheClosedFormOfFranklinPowell) {
  // 1/(s(ms+b)) with ZOH: poles 1 and E = e^{-bT/m};
  // b1 = (T - (1-E)/p)/b, b2 = ((1-E)/p - T E)/b with p = b/m.
  const double m = 0.036, b = 0.49, t = 0.002;
  const double p = b / m;
  const double e = std::exp(-p * t);
  const ZohTransferFunction tf = transfer_function(discretize_plant(m, b, 0.0, t));
  EXPECT_NEAR(tf.a1, -(1.0 + e), 1e-14);
  EXPECT_NEAR(tf.a2, e, 1e-14);
  EXPECT_NEAR(tf.b1 / ((t + std::expm1(-p * t) / p) / b), 1.0, 1e-9);
  EXPECT_NEAR(tf.b2 / ((-std::expm1(-p * t) / p - t * e) / b), 1.0, 1e-9);
}

TEST(Zoh, UndampedOscillatorIsARotation) {
  // m x'' + k x = 0: phi = [[cos wT, sin wT / w], [-w sin wT, cos wT]] (physics).
  const double m = 0.05, k = 500.0, t = 0.003;
  const double w = std::sqrt(k / m);
  const ZohPlant z = discretize_plant(m, 0.0, k, t);
  EXPECT_NEAR(z.phi(0, 0), std::cos(w * t), 1e-15);
  EXPECT_NEAR(z.phi(0, 1), std::sin(w * t) / w, 1e-17);
  EXPECT_NEAR(z.phi(1, 0), -w * std::sin(w * t), 1e-12);
  EXPECT_NEAR(z.gamma(0), (1.0 - std::cos(w * t)) / k, 1e-17);
}

}  // namespace
}  // namespace teleop::stability
