// Routh-Hurwitz and polynomial roots against polynomials built here from chosen roots, so every
// expected verdict and root is known by construction.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <random>
#include <stdexcept>
#include <vector>

#include "common/stability/routh_hurwitz.hpp"

namespace teleop::stability {
namespace {

using Complex = std::complex<double>;
using Poly = std::vector<double>;  // descending powers

[[nodiscard]] Poly multiply(const Poly& a, const Poly& b) {
  Poly out(a.size() + b.size() - 1, 0.0);
  for (std::size_t i = 0; i < a.size(); ++i) {
    for (std::size_t j = 0; j < b.size(); ++j) out[i + j] += a[i] * b[j];
  }
  return out;
}

// Monic polynomial with the given roots; a complex root stands for itself and its conjugate.
[[nodiscard]] Poly from_roots(const std::vector<double>& real_roots,
                              const std::vector<Complex>& pairs) {
  Poly p{1.0};
  for (const double r : real_roots) p = multiply(p, {1.0, -r});
  for (const Complex& z : pairs) p = multiply(p, {1.0, -2.0 * z.real(), std::norm(z)});
  return p;
}

[[nodiscard]] std::vector<Complex> all_roots(const std::vector<double>& real_roots,
                                             const std::vector<Complex>& pairs) {
  std::vector<Complex> roots(real_roots.begin(), real_roots.end());
  for (const Complex& z : pairs) {
    roots.push_back(z);
    roots.push_back(std::conj(z));
  }
  return roots;
}

// Every expected root has a distinct computed root within tol * max(1, |root|).
void expect_roots_match(std::vector<Complex> computed, const std::vector<Complex>& expected,
                        double tol) {
  ASSERT_EQ(computed.size(), expected.size());
  for (const Complex& e : expected) {
    const auto nearest = std::min_element(
        computed.begin(), computed.end(),
        [&](const Complex& a, const Complex& b) { return std::abs(a - e) < std::abs(b - e); });
    EXPECT_LE(std::abs(*nearest - e), tol * std::max(1.0, std::abs(e))) << "root " << e;
    computed.erase(nearest);
  }
}

TEST(RouthHurwitz, StableQuarticWithLightlyDampedPair) {
  // (s+1)(s+2)(s^2+0.1s+9): all roots in the left half plane, one pair with zeta = 0.017.
  EXPECT_EQ(routh_hurwitz(from_roots({-1.0, -2.0}, {{-0.05, std::sqrt(9.0 - 0.0025)}})),
            Verdict::kStable);
  const Poly p = multiply(multiply({1.0, 1.0}, {1.0, 2.0}), {1.0, 0.1, 9.0});
  EXPECT_EQ(routh_hurwitz(p), Verdict::kStable);
}

TEST(RouthHurwitz, OneRootInTheRightHalfPlaneIsUnstable) {
  const Poly stable = multiply(multiply({1.0, 1.0}, {1.0, 2.0}), {1.0, 0.1, 9.0});
  EXPECT_EQ(routh_hurwitz(multiply(stable, {1.0, -0.5})), Verdict::kUnstable);
  // Positive coefficients are necessary, not sufficient: (s+3)(s^2 - 0.2 s + 4) =
  // s^3 + 2.8 s^2 + 3.4 s + 12 has a pair at 0.1 +- 2j.
  const Poly hidden = multiply({1.0, 3.0}, {1.0, -0.2, 4.0});
  ASSERT_TRUE(std::all_of(hidden.begin(), hidden.end(), [](double a) { return a > 0.0; }));
  EXPECT_EQ(routh_hurwitz(hidden), Verdict::kUnstable);
}

TEST(RouthHurwitz, PairOnTheImaginaryAxisIsUncertain) {
  EXPECT_EQ(routh_hurwitz(multiply(multiply({1.0, 1.0}, {1.0, 2.0}), {1.0, 0.0, 9.0})),
            Verdict::kUncertain);
  // Inexact coefficients (0.37^2 is not a double): the zero is only zero to rounding.
  EXPECT_EQ(routh_hurwitz(from_roots({-1.0, -2.5}, {{0.0, 0.37}, {-0.3, 1.1}})),
            Verdict::kUncertain);
  // A root at +0.5 as well: unstable whatever the marginal pair does.
  EXPECT_EQ(routh_hurwitz(from_roots({0.5, -1.0}, {{0.0, 3.0}})), Verdict::kUnstable);
}

TEST(RouthHurwitz, RootAtTheOriginIsUncertain) {
  EXPECT_EQ(routh_hurwitz(from_roots({0.0, -1.0, -2.0}, {})), Verdict::kUncertain);
}

TEST(RouthHurwitz, FirstDegree) {
  EXPECT_EQ(routh_hurwitz(Poly{2.0, 3.0}), Verdict::kStable);
  EXPECT_EQ(routh_hurwitz(Poly{2.0, -3.0}), Verdict::kUnstable);
  EXPECT_EQ(routh_hurwitz(Poly{-2.0, -3.0}), Verdict::kStable);
  EXPECT_EQ(routh_hurwitz(Poly{1.0, 0.0}), Verdict::kUncertain);
}

TEST(RouthHurwitz, ConstantHasNoRoots) {
  EXPECT_EQ(routh_hurwitz(Poly{5.0}), Verdict::kStable);
  EXPECT_TRUE(polynomial_roots(Poly{5.0}).empty());
}

TEST(RouthHurwitz, LeadingSignAndLeadingZerosDoNotMatter) {
  const Poly p = from_roots({-1.0, -2.0, -7.0}, {{-0.5, 4.0}});
  Poly negated = p;
  for (double& a : negated) a = -a;
  EXPECT_EQ(routh_hurwitz(negated), Verdict::kStable);
  Poly padded{0.0, 0.0};
  padded.insert(padded.end(), p.begin(), p.end());
  EXPECT_EQ(routh_hurwitz(padded), Verdict::kStable);
  expect_roots_match(polynomial_roots(padded), all_roots({-1.0, -2.0, -7.0}, {{-0.5, 4.0}}), 1e-12);
}

// Known roots of every degree 1..8: stable as built, unstable with one root mirrored into the
// right half plane, uncertain with one pair moved onto the imaginary axis.
TEST(RouthHurwitz, RandomPolynomialsOfDegreeOneToEight) {
  std::mt19937 rng(20240611);
  std::uniform_real_distribution<double> real_part(-5.0, -0.2);
  std::uniform_real_distribution<double> imag_part(0.2, 6.0);
  std::uniform_int_distribution<int> coin(0, 1);
  for (int degree = 1; degree <= 8; ++degree) {
    for (int trial = 0; trial < 300; ++trial) {
      std::vector<double> reals;
      std::vector<Complex> pairs;
      int remaining = degree;
      while (remaining > 0) {
        if (remaining >= 2 && coin(rng) == 1) {
          const double re = real_part(rng);  // two statements: argument order is unspecified
          pairs.emplace_back(re, imag_part(rng));
          remaining -= 2;
        } else {
          reals.push_back(real_part(rng));
          remaining -= 1;
        }
      }
      ASSERT_EQ(routh_hurwitz(from_roots(reals, pairs)), Verdict::kStable)
          << "degree " << degree << " trial " << trial;
      expect_roots_match(polynomial_roots(from_roots(reals, pairs)), all_roots(reals, pairs), 1e-6);

      std::vector<double> mirrored_reals = reals;
      std::vector<Complex> mirrored_pairs = pairs;
      if (!mirrored_reals.empty()) {
        mirrored_reals.front() = -mirrored_reals.front();
      } else {
        mirrored_pairs.front() = {-mirrored_pairs.front().real(), mirrored_pairs.front().imag()};
      }
      EXPECT_EQ(routh_hurwitz(from_roots(mirrored_reals, mirrored_pairs)), Verdict::kUnstable)
          << "degree " << degree << " trial " << trial;

      if (!pairs.empty()) {
        std::vector<Complex> marginal = pairs;
        marginal.front() = {0.0, marginal.front().imag()};
        EXPECT_EQ(routh_hurwitz(from_roots(reals, marginal)), Verdict::kUncertain)
            << "degree " << degree << " trial " << trial;
      }
    }
  }
}

// A zero in the first column with no other sign information: the array cannot be completed
// without inventing a sign (the epsilon method), so the verdict is uncertain, never a guess.
TEST(RouthHurwitz, SingularArrayIsUncertainNotAGuess) {
  EXPECT_EQ(routh_hurwitz(Poly{1.0, 1.0, 2.0, 2.0, 3.0}), Verdict::kUncertain);
  // A whole row vanishing (roots symmetric about the origin): (s^2 + 1)(s^2 + 4).
  EXPECT_EQ(routh_hurwitz(Poly{1.0, 0.0, 5.0, 0.0, 4.0}), Verdict::kUncertain);
}

TEST(RouthHurwitz, CallerErrorBoundsWidenTheUncertainBand) {
  // s^2 + 1e-10 s + 1: exactly known, the tiny damping is still damping.
  const Poly p{1.0, 1e-10, 1.0};
  EXPECT_EQ(routh_hurwitz(p), Verdict::kStable);
  EXPECT_EQ(routh_hurwitz(p, Poly{0.0, 0.0, 0.0}), Verdict::kStable);
  // Known only to +-1e-9: it may be either side of the axis.
  EXPECT_EQ(routh_hurwitz(p, Poly{0.0, 1e-9, 0.0}), Verdict::kUncertain);
  // A leading coefficient that may be zero leaves a root near infinity of unknown sign.
  EXPECT_EQ(routh_hurwitz(Poly{1e-20, 1.0, 1.0}, Poly{1e-18, 0.0, 0.0}), Verdict::kUncertain);
}

TEST(RouthHurwitz, RejectsMalformedInput) {
  EXPECT_THROW((void)routh_hurwitz(Poly{}), std::invalid_argument);
  EXPECT_THROW((void)routh_hurwitz(Poly{0.0, 0.0}), std::invalid_argument);
  EXPECT_THROW((void)routh_hurwitz(Poly{1.0, std::nan(""), 1.0}), std::invalid_argument);
  EXPECT_THROW((void)routh_hurwitz(Poly{1.0, 1.0}, Poly{0.0}), std::invalid_argument);
  EXPECT_THROW((void)routh_hurwitz(Poly{1.0, 1.0}, Poly{0.0, -1.0}), std::invalid_argument);
  EXPECT_THROW((void)polynomial_roots(Poly{}), std::invalid_argument);
  EXPECT_THROW((void)polynomial_roots(Poly{0.0}), std::invalid_argument);
  EXPECT_THROW((void)polynomial_roots(Poly{1.0, INFINITY}), std::invalid_argument);
}

TEST(PolynomialRoots, ExactZeroRootsAndSortedOutput) {
  const std::vector<Complex> roots = polynomial_roots(Poly{1.0, 3.0, 2.0, 0.0, 0.0});
  ASSERT_EQ(roots.size(), 4U);
  EXPECT_EQ(roots[0], Complex(0.0, 0.0));
  EXPECT_EQ(roots[1], Complex(0.0, 0.0));
  EXPECT_NEAR(roots[2].real(), -1.0, 1e-14);
  EXPECT_NEAR(roots[3].real(), -2.0, 1e-14);
}

// Roots spanning four decades, as in the force loop (the Pade pole at -2/T next to the device's
// slow modes): the balanced companion matrix keeps each to near machine precision.
TEST(PolynomialRoots, WidelySpreadRoots) {
  const std::vector<double> reals{-2000.0, -0.05};
  const std::vector<Complex> pairs{{-9.75, 49.06}, {-300.0, 1200.0}};
  const Poly p = multiply(from_roots(reals, pairs), {2.5e-4});
  expect_roots_match(polynomial_roots(p), all_roots(reals, pairs), 1e-10);
}

}  // namespace
}  // namespace teleop::stability
