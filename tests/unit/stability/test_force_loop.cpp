// The Vlachos-Papadopoulos force loop. Expected values come from the paper (1105 N/m), from
// its printed closed forms typed in here, or from this file's own expansion of
// 1 + G_m G_v G_c H_s = 0 and its own (scaled companion) root finder — never from the code
// under test.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <complex>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "common/core/teleop_params.hpp"
#include "common/stability/force_loop.hpp"
#include "common/stability/routh_hurwitz.hpp"

namespace teleop::stability {
namespace {

using Poly = std::vector<double>;  // descending powers of s

// The paper's device and loop (section IV): M = 0.25 kg, B = 5 Ns/m, T = 1 ms, K_p = 5,
// B_v = 0.1 Ns/m, rendering its tissue (k = 125 N/m).
[[nodiscard]] ForceLoopParams paper_params() {
  ForceLoopParams p;
  p.mass_kg = 0.25;
  p.damping_Ns_per_m = 5.0;
  p.kp = 5.0;
  p.ki = 0.0;
  p.sample_rate_hz = 1000.0;
  p.environment_stiffness_N_per_m = 125.0;
  p.environment_damping_Ns_per_m = 0.1;
  return p;
}

[[nodiscard]] Poly multiply(const Poly& a, const Poly& b) {
  Poly out(a.size() + b.size() - 1, 0.0);
  for (std::size_t i = 0; i < a.size(); ++i) {
    for (std::size_t j = 0; j < b.size(); ++j) out[i + j] += a[i] * b[j];
  }
  return out;
}

[[nodiscard]] Poly add(Poly a, Poly b) {
  if (a.size() < b.size()) std::swap(a, b);
  const std::size_t shift = a.size() - b.size();
  for (std::size_t i = 0; i < b.size(); ++i) a[shift + i] += b[i];
  return a;
}

// Denominators cleared from 1 + G_m G_v G_c H_s = 0, by multiplying the blocks of Table II.
[[nodiscard]] Poly loop_polynomial(const ForceLoopParams& p) {
  const double t = 1.0 / p.sample_rate_hz;
  const Poly plant{p.mass_kg, p.damping_Ns_per_m, 0.0};  // 1/G_m
  const Poly hold_den{t, 2.0};                           // 2 + T s
  const Poly hold_num{-t, 2.0};                          // 2 - T s
  const Poly environment{p.environment_damping_Ns_per_m, p.environment_stiffness_N_per_m};
  const bool pi = p.ki > 0.0;
  const Poly controller_num = pi ? Poly{p.kp, p.ki} : Poly{p.kp};
  const Poly controller_den = pi ? Poly{1.0, 0.0} : Poly{1.0};
  return add(multiply(multiply(plant, hold_den), controller_den),
             multiply(multiply(controller_num, environment), hold_num));
}

// Roots of s-polynomial via z = s / sigma with sigma the geometric mean root modulus, so the
// companion matrix is O(1) whatever the units; independent of the library's balancing.
[[nodiscard]] std::vector<std::complex<double>> test_roots(const Poly& a) {
  const auto n = static_cast<Eigen::Index>(a.size() - 1);
  const double sigma = a.back() != 0.0
                           ? std::pow(std::abs(a.back() / a.front()), 1.0 / static_cast<double>(n))
                           : 1.0;
  Eigen::MatrixXd companion = Eigen::MatrixXd::Zero(n, n);
  for (Eigen::Index k = 1; k <= n; ++k) {
    // coefficient of z^(n-k) over that of z^n: a_k sigma^(n-k) / (a_0 sigma^n)
    companion(0, k - 1) =
        -a[static_cast<std::size_t>(k)] / a[0] / std::pow(sigma, static_cast<double>(k));
  }
  for (Eigen::Index i = 1; i < n; ++i) companion(i, i - 1) = 1.0;
  const Eigen::EigenSolver<Eigen::MatrixXd> solver(companion, false);
  std::vector<std::complex<double>> roots;
  for (Eigen::Index i = 0; i < n; ++i) roots.push_back(sigma * solver.eigenvalues()(i));
  return roots;
}

enum class RootClass { kStable, kUnstable, kTooClose };

// Each root is polished by Newton's method in long double and its real part counts only when it
// exceeds that root's own error estimate (coefficients exact, evaluation in extended precision):
// the crossing pair and the integrator's slow root are tiny next to the hold's -2/T pole, so a
// margin relative to the largest root would hide exactly the roots that decide.
[[nodiscard]] RootClass classify(const Poly& a) {
  using Ld = long double;
  using ComplexLd = std::complex<Ld>;
  bool too_close = false;
  for (const std::complex<double>& r0 : test_roots(a)) {
    ComplexLd r{r0.real(), r0.imag()};
    Ld slope = 0.0L;
    Ld magnitude = 0.0L;
    for (int iteration = 0; iteration < 6; ++iteration) {
      ComplexLd value{0.0L, 0.0L};
      ComplexLd derivative{0.0L, 0.0L};
      magnitude = 0.0L;
      for (const double ai : a) {
        derivative = derivative * r + value;
        value = value * r + static_cast<Ld>(ai);
        magnitude = magnitude * std::abs(r) + std::abs(static_cast<Ld>(ai));
      }
      slope = std::abs(derivative);
      if (slope == 0.0L || std::abs(value) <= 1e-19L * magnitude) break;
      r -= value / derivative;
    }
    const Ld error = slope > 0.0L ? 1e-16L * magnitude / slope : INFINITY;
    if (r.real() > error + 1e-13L * std::abs(r)) return RootClass::kUnstable;
    if (r.real() >= -(error + 1e-13L * std::abs(r))) too_close = true;
  }
  return too_close ? RootClass::kTooClose : RootClass::kStable;
}

[[nodiscard]] Verdict to_verdict(RootClass c) {
  return c == RootClass::kStable ? Verdict::kStable : Verdict::kUnstable;
}

// The paper's printed closed forms, eqs. 14-15, exactly as printed (expanded).
struct PrintedP {
  double bv_bound{0.0};  // eq. 14
  double nom{0.0};
  double denom{0.0};
};

[[nodiscard]] PrintedP printed_p(double m, double b, double t, double kp, double bv) {
  return {(2.0 * m + b * t) / (kp * t),
          4.0 * b * m + 4.0 * bv * kp * m + 2.0 * b * b * t - 2.0 * bv * bv * kp * kp * t,
          4.0 * kp * m * t + b * kp * t * t - bv * kp * kp * t * t};
}

// Largest B_v with [0, B_v] satisfying eqs. 14-15 at stiffness kv, by bisection on the printed
// inequalities (stable at 0 assumed; eq. 14's bound fails eq. 15 since Nom_p vanishes there).
[[nodiscard]] double printed_bv_limit(double m, double b, double t, double kp, double kv) {
  double lo = 0.0;
  double hi = printed_p(m, b, t, kp, 0.0).bv_bound;
  for (int i = 0; i < 200; ++i) {
    const double mid = 0.5 * (lo + hi);
    const PrintedP c = printed_p(m, b, t, kp, mid);
    (mid < c.bv_bound && kv * c.denom < c.nom ? lo : hi) = mid;
  }
  return lo;
}

[[nodiscard]] double log_uniform(std::mt19937& rng, double lo, double hi) {
  std::uniform_real_distribution<double> u(std::log(lo), std::log(hi));
  return std::exp(u(rng));
}

TEST(ForceLoop, PaperKvLimitIs1105) {
  const ForceLoopResult r = analyze_force_loop(paper_params());
  ASSERT_TRUE(r.kv_limit_N_per_m.has_value()) << r.limit_reason;
  EXPECT_NEAR(*r.kv_limit_N_per_m, 1105.0, 1.0);  // the paper's text
  // Eq. 15 by hand: Nom_p = 5 + 0.5 + 0.05 - 0.0005 = 5.5495,
  // Denom_p = 0.005 + 0.000025 - 0.0000025 = 0.0050225, ratio 1104.9278...
  EXPECT_NEAR(*r.kv_limit_N_per_m, 5.5495 / 0.0050225, 1e-9 * 1105.0);
  EXPECT_FALSE(r.proportional_integral);
  EXPECT_EQ(r.verdict, Verdict::kStable);  // the tissue, 125 N/m, is well inside
  EXPECT_TRUE(r.stable);
  EXPECT_TRUE(r.limit_reason.empty());
}

TEST(ForceLoop, PaperBvLimitAgainstEq14) {
  // Eq. 14 by hand: (2 * 0.25 + 5 * 0.001) / (5 * 0.001) = 0.505 / 0.005 = 101 Ns/m.
  const double eq14 = 101.0;
  ForceLoopParams p = paper_params();
  const ForceLoopResult r = analyze_force_loop(p);
  ASSERT_TRUE(r.bv_limit_Ns_per_m.has_value()) << r.limit_reason;
  // At K_v = 125 N/m eq. 15 binds before eq. 14: solving eq. 15 for B_v gives 100.9387 Ns/m.
  EXPECT_LT(*r.bv_limit_Ns_per_m, eq14);
  EXPECT_NEAR(*r.bv_limit_Ns_per_m, printed_bv_limit(0.25, 5.0, 1e-3, 5.0, 125.0), 1e-9 * eq14);
  EXPECT_NEAR(*r.bv_limit_Ns_per_m, 100.9387, 1e-4);
  // Eq. 14 alone is the bound as K_v -> 0.
  p.environment_stiffness_N_per_m = 1e-6;
  const ForceLoopResult soft = analyze_force_loop(p);
  ASSERT_TRUE(soft.bv_limit_Ns_per_m.has_value()) << soft.limit_reason;
  EXPECT_NEAR(*soft.bv_limit_Ns_per_m, eq14, 1e-6 * eq14);
}

TEST(ForceLoop, PaperLimitsAreWhereRootsCrossTheAxis) {
  const ForceLoopResult r = analyze_force_loop(paper_params());
  ASSERT_TRUE(r.kv_limit_N_per_m && r.bv_limit_Ns_per_m);
  for (const double factor : {1.0 - 1e-6, 1.0 + 1e-6}) {
    ForceLoopParams p = paper_params();
    p.environment_stiffness_N_per_m = *r.kv_limit_N_per_m * factor;
    const RootClass expected = factor < 1.0 ? RootClass::kStable : RootClass::kUnstable;
    EXPECT_EQ(classify(loop_polynomial(p)), expected) << "K_v factor " << factor;
    EXPECT_EQ(analyze_force_loop(p).verdict, to_verdict(expected));
    p = paper_params();
    p.environment_damping_Ns_per_m = *r.bv_limit_Ns_per_m * factor;
    EXPECT_EQ(classify(loop_polynomial(p)), expected) << "B_v factor " << factor;
    EXPECT_EQ(analyze_force_loop(p).verdict, to_verdict(expected));
  }
}

TEST(ForceLoop, CharacteristicPolynomialMatchesIndependentExpansion) {
  ForceLoopParams p = paper_params();
  for (const double ki : {0.0, 40.0}) {
    p.ki = ki;
    const Poly expected = loop_polynomial(p);
    const Poly actual = characteristic_polynomial(p);
    ASSERT_EQ(actual.size(), ki > 0.0 ? 5U : 4U);
    ASSERT_EQ(actual.size(), expected.size());
    for (std::size_t i = 0; i < actual.size(); ++i) {
      EXPECT_NEAR(actual[i], expected[i], 1e-14 * std::abs(expected[i])) << "coefficient " << i;
    }
    const ForceLoopResult r = analyze_force_loop(p);
    EXPECT_EQ(r.proportional_integral, ki > 0.0);
    EXPECT_EQ(r.characteristic_polynomial, actual);
    ASSERT_EQ(r.roots.size(), actual.size() - 1);
    for (const std::complex<double>& root : r.roots) {
      std::complex<double> value{0.0, 0.0};
      for (const double a : expected) value = value * root + a;
      double scale = 0.0;
      for (const double a : expected) scale = scale * std::abs(root) + std::abs(a);
      EXPECT_LE(std::abs(value), 1e-12 * scale) << "root " << root;
    }
  }
}

// P case: the paper's eqs. 14-15 (as printed) decide exactly what the roots decide, over wide
// parameter ranges; and the analysis reproduces both.
TEST(ForceLoop, ClosedFormsAgreeWithRootsOnRandomParameters) {
  std::mt19937 rng(1234567);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  int stable = 0;
  int unstable = 0;
  int skipped = 0;
  constexpr int kDraws = 4000;
  for (int draw = 0; draw < kDraws; ++draw) {
    ForceLoopParams p;
    p.mass_kg = log_uniform(rng, 1e-3, 10.0);
    p.damping_Ns_per_m = log_uniform(rng, 1e-3, 100.0);
    p.sample_rate_hz = log_uniform(rng, 100.0, 1e5);
    p.kp = log_uniform(rng, 1e-2, 100.0);
    const double m = p.mass_kg;
    const double b = p.damping_Ns_per_m;
    const double t = 1.0 / p.sample_rate_hz;
    const double kp = p.kp;
    const double eq14 = printed_p(m, b, t, kp, 0.0).bv_bound;
    const double bv = eq14 * 1.3 * unit(rng);
    const PrintedP printed = printed_p(m, b, t, kp, bv);
    const double eq15 = printed.nom / printed.denom;
    const PrintedP at_zero = printed_p(m, b, t, kp, 0.0);
    const double kv_scale = bv < eq14 ? eq15 : at_zero.nom / at_zero.denom;
    const double kv = kv_scale * (-0.05 + 2.05 * unit(rng));
    p.environment_damping_Ns_per_m = bv;
    p.environment_stiffness_N_per_m = kv;
    SCOPED_TRACE("draw " + std::to_string(draw));

    const bool near_boundary = std::abs(bv - eq14) <= 1e-6 * eq14 ||
                               std::abs(kv) <= 1e-6 * kv_scale ||
                               std::abs(kv - eq15) <= 1e-6 * std::abs(eq15);
    const RootClass roots = classify(loop_polynomial(p));
    if (near_boundary || roots == RootClass::kTooClose) {
      ++skipped;
      continue;
    }
    const bool closed_form_stable = bv < eq14 && kv > 0.0 && kv < eq15;
    ASSERT_EQ(closed_form_stable, roots == RootClass::kStable);
    (closed_form_stable ? stable : unstable) += 1;

    const ForceLoopResult r = analyze_force_loop(p);
    EXPECT_EQ(r.verdict, to_verdict(roots));
    if (bv < eq14) {
      ASSERT_TRUE(r.kv_limit_N_per_m.has_value()) << r.limit_reason;
      EXPECT_NEAR(*r.kv_limit_N_per_m, eq15, 1e-8 * eq15);
    } else {
      EXPECT_FALSE(r.kv_limit_N_per_m.has_value());
      EXPECT_NE(r.limit_reason.find("eq. 14"), std::string::npos) << r.limit_reason;
    }
    if (kv > 0.0 && kv < at_zero.nom / at_zero.denom) {  // B_v = 0 satisfies eq. 15
      ASSERT_TRUE(r.bv_limit_Ns_per_m.has_value()) << r.limit_reason;
      EXPECT_NEAR(*r.bv_limit_Ns_per_m, printed_bv_limit(m, b, t, kp, kv), 1e-7 * eq14);
    } else {
      EXPECT_FALSE(r.bv_limit_Ns_per_m.has_value());
    }
  }
  EXPECT_GT(stable, kDraws / 5);
  EXPECT_GT(unstable, kDraws / 5);
  EXPECT_LT(skipped, kDraws / 100);
}

// PI case: the complete Routh-Hurwitz test (on this file's polynomial, and inside the analysis)
// against the roots; and the reported limits are where the roots cross the axis.
TEST(ForceLoop, PiRouthHurwitzAgreesWithRootsOnRandomParameters) {
  std::mt19937 rng(987654);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  int stable = 0;
  int unstable = 0;
  int skipped = 0;
  int limits_checked = 0;
  constexpr int kDraws = 3000;
  for (int draw = 0; draw < kDraws; ++draw) {
    ForceLoopParams p;
    p.mass_kg = log_uniform(rng, 1e-3, 10.0);
    p.damping_Ns_per_m = log_uniform(rng, 1e-2, 100.0);
    p.sample_rate_hz = log_uniform(rng, 100.0, 1e5);
    p.kp = draw % 10 == 0 ? 0.0 : log_uniform(rng, 1e-2, 100.0);
    p.ki = log_uniform(rng, 1e-3, 1e3) * std::max(p.kp, 0.1);
    const double t = 1.0 / p.sample_rate_hz;
    const PrintedP at_zero = printed_p(p.mass_kg, p.damping_Ns_per_m, t, std::max(p.kp, 0.1), 0.0);
    p.environment_damping_Ns_per_m = at_zero.bv_bound * 1.2 * unit(rng);
    p.environment_stiffness_N_per_m = at_zero.nom / at_zero.denom * 1.5 * unit(rng);
    SCOPED_TRACE("draw " + std::to_string(draw));

    const Poly poly = loop_polynomial(p);
    const RootClass roots = classify(poly);
    if (roots == RootClass::kTooClose) {
      ++skipped;
      continue;
    }
    (roots == RootClass::kStable ? stable : unstable) += 1;
    EXPECT_EQ(routh_hurwitz(poly), to_verdict(roots));
    const ForceLoopResult r = analyze_force_loop(p);
    EXPECT_TRUE(r.proportional_integral);
    EXPECT_EQ(r.verdict, to_verdict(roots));

    if (draw % 25 != 0) continue;
    // Every K_v below the limit is stable; just above it is not. Likewise B_v from 0.
    if (r.kv_limit_N_per_m) {
      ++limits_checked;
      const double limit = *r.kv_limit_N_per_m;
      for (int k = 0; k <= 40; ++k) {
        ForceLoopParams q = p;
        q.environment_stiffness_N_per_m = limit * std::pow(1e-4, k / 40.0) * (1.0 - 1e-5);
        EXPECT_EQ(classify(loop_polynomial(q)), RootClass::kStable) << "K_v " << k;
      }
      ForceLoopParams q = p;
      q.environment_stiffness_N_per_m = limit * (1.0 + 1e-5);
      EXPECT_EQ(classify(loop_polynomial(q)), RootClass::kUnstable) << "K_v above " << limit;
    }
    if (r.bv_limit_Ns_per_m) {
      ++limits_checked;
      const double limit = *r.bv_limit_Ns_per_m;
      for (int k = 0; k <= 40; ++k) {
        ForceLoopParams q = p;
        q.environment_damping_Ns_per_m = limit * (1.0 - 1e-5) * k / 40.0;
        EXPECT_EQ(classify(loop_polynomial(q)), RootClass::kStable) << "B_v " << k;
      }
      ForceLoopParams q = p;
      q.environment_damping_Ns_per_m = limit * (1.0 + 1e-5);
      EXPECT_EQ(classify(loop_polynomial(q)), RootClass::kUnstable) << "B_v above " << limit;
    }
  }
  EXPECT_GT(stable, kDraws / 10);
  EXPECT_GT(unstable, kDraws / 10);
  EXPECT_LT(skipped, kDraws / 100);
  EXPECT_GT(limits_checked, 40);
}

// Why the complete test is needed: on the paper's device with K_i = 1000 1/s every coefficient of
// the quartic is positive (and the printed eq. 16 is satisfied), yet a pair of roots is in the
// right half plane.
TEST(ForceLoop, PiCoefficientPositivityIsNotEnough) {
  ForceLoopParams p = paper_params();
  p.ki = 1000.0;
  const Poly a = loop_polynomial(p);
  ASSERT_EQ(a.size(), 5U);
  for (const double ai : a) EXPECT_GT(ai, 0.0);
  // Hurwitz determinant D3 = a3 a2 a1 - a4 a1^2 - a3^2 a0 (a4 = a[0] ... a0 = a[4]).
  const double d3 = a[1] * a[2] * a[3] - a[0] * a[3] * a[3] - a[1] * a[1] * a[4];
  EXPECT_LT(d3, 0.0);
  EXPECT_EQ(classify(a), RootClass::kUnstable);

  // The printed eq. 16, first clause: B_v < B/(3 K_p), K_v <= -sqrt(A) + B, K_i < C.
  const double b = 5.0;
  const double t = 1e-3;
  const double kp = 5.0;
  const double bv = 0.1;
  const double kv = 125.0;
  const double big_a = (b * b - 2.0 * b * bv * kp - 3.0 * bv * bv * kp * kp) / (kp * kp * t * t);
  const double big_b = (b + bv * kp) / (kp * t);
  const double big_c = (2.0 * b + 2.0 * bv * kp - kp * kv * t) / (bv * t);
  EXPECT_LT(bv, b / (3.0 * kp));
  EXPECT_LE(kv, -std::sqrt(big_a) + big_b);
  EXPECT_LT(p.ki, big_c);

  const ForceLoopResult r = analyze_force_loop(p);
  EXPECT_TRUE(r.proportional_integral);
  EXPECT_EQ(r.verdict, Verdict::kUnstable);
  EXPECT_FALSE(r.stable);
  ASSERT_TRUE(r.kv_limit_N_per_m.has_value()) << r.limit_reason;
  EXPECT_LT(*r.kv_limit_N_per_m, 125.0);
}

// As K_i -> 0 the integrator's pole and zero cancel and the PI limits become the P limits.
TEST(ForceLoop, PiLimitsTendToPLimitsAsKiVanishes) {
  ForceLoopParams p = paper_params();
  p.ki = 1e-6;
  const ForceLoopResult r = analyze_force_loop(p);
  ASSERT_TRUE(r.proportional_integral);
  ASSERT_TRUE(r.kv_limit_N_per_m.has_value()) << r.limit_reason;
  ASSERT_TRUE(r.bv_limit_Ns_per_m.has_value()) << r.limit_reason;
  EXPECT_NEAR(*r.kv_limit_N_per_m, 5.5495 / 0.0050225, 1e-6 * 1105.0);
  EXPECT_NEAR(*r.bv_limit_Ns_per_m, printed_bv_limit(0.25, 5.0, 1e-3, 5.0, 125.0), 1e-6 * 101.0);
}

TEST(ForceLoop, PiWithoutFiniteLimitSaysSo) {
  // A weak loop at 100 kHz: a_2 = 2B - K_p K_v T + ... stays positive up to K_v = 1e9.
  ForceLoopParams p = paper_params();
  p.sample_rate_hz = 1e5;
  p.kp = 1e-4;
  p.ki = 1e-4;
  const ForceLoopResult r = analyze_force_loop(p);
  EXPECT_FALSE(r.kv_limit_N_per_m.has_value());
  EXPECT_NE(r.limit_reason.find("K_v"), std::string::npos) << r.limit_reason;
  EXPECT_NE(r.limit_reason.find("1e+09"), std::string::npos) << r.limit_reason;
  p.environment_stiffness_N_per_m = 1e9;
  EXPECT_EQ(classify(loop_polynomial(p)), RootClass::kStable);
}

TEST(ForceLoop, NoForceFeedbackHasNoLimit) {
  ForceLoopParams p = paper_params();
  p.kp = 0.0;
  const ForceLoopResult r = analyze_force_loop(p);
  EXPECT_FALSE(r.kv_limit_N_per_m.has_value());
  EXPECT_FALSE(r.bv_limit_Ns_per_m.has_value());
  EXPECT_NE(r.limit_reason.find("kp = 0"), std::string::npos) << r.limit_reason;
  // What is left is the open loop: the free device's pole at s = 0 is marginal.
  EXPECT_EQ(r.verdict, Verdict::kUncertain);
  EXPECT_FALSE(r.stable);
  ASSERT_FALSE(r.roots.empty());
  EXPECT_EQ(r.roots.front(), std::complex<double>(0.0, 0.0));
}

TEST(ForceLoop, DampingAboveEq14IsUnstableForEveryStiffness) {
  ForceLoopParams p = paper_params();
  p.environment_damping_Ns_per_m = 150.0;  // eq. 14: 101 Ns/m
  const ForceLoopResult r = analyze_force_loop(p);
  EXPECT_EQ(r.verdict, Verdict::kUnstable);
  EXPECT_EQ(classify(loop_polynomial(p)), RootClass::kUnstable);
  EXPECT_FALSE(r.kv_limit_N_per_m.has_value());
  EXPECT_NE(r.limit_reason.find("eq. 14"), std::string::npos) << r.limit_reason;
  p.environment_stiffness_N_per_m = 1.0;
  EXPECT_EQ(classify(loop_polynomial(p)), RootClass::kUnstable);
}

TEST(ForceLoop, InvalidInputThrowsNamingTheField) {
  const auto expect_throw = [](ForceLoopParams p, const std::string& field) {
    for (int call = 0; call < 2; ++call) {
      try {
        if (call == 0) {
          (void)analyze_force_loop(p);
        } else {
          (void)characteristic_polynomial(p);
        }
        ADD_FAILURE() << "no exception for " << field;
      } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find("force_loop." + field), std::string::npos) << e.what();
      }
    }
  };
  ForceLoopParams p = paper_params();
  p.mass_kg = -1.0;
  expect_throw(p, "mass_kg");
  p.mass_kg = 0.0;
  expect_throw(p, "mass_kg");
  p = paper_params();
  p.sample_rate_hz = 0.0;
  expect_throw(p, "sample_rate_hz");
  p = paper_params();
  p.damping_Ns_per_m = std::nan("");
  expect_throw(p, "damping_Ns_per_m");
  p = paper_params();
  p.kp = -1.0;
  expect_throw(p, "kp");
  p = paper_params();
  p.ki = -0.5;
  expect_throw(p, "ki");
  p = paper_params();
  p.environment_stiffness_N_per_m = INFINITY;
  expect_throw(p, "environment_stiffness_N_per_m");
  p = paper_params();
  p.environment_damping_Ns_per_m = std::nan("");
  expect_throw(p, "environment_damping_Ns_per_m");
  p = paper_params();
  p.sensor_average_samples = 0;
  expect_throw(p, "sensor_average_samples");

  p = paper_params();
  p.mass_kg = -1.0;
  try {
    (void)analyze_force_loop(p);
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "force_loop.mass_kg must be > 0, got -1");
  }
}

}  // namespace
}  // namespace teleop::stability
