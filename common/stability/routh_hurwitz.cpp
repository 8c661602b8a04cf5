#include "common/stability/routh_hurwitz.hpp"

#include <Eigen/Dense>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#include <stdexcept>
#include <string>

namespace teleop::stability {
namespace {

constexpr double kEps = std::numeric_limits<double>::epsilon();

// The propagated bounds are first order and assume few roundings per input coefficient; the
// margin covers the neglected terms, so only entries far from their error count as signed.
constexpr double kSafety = 64.0;

// A value with an absolute bound on the error it carries.
struct Bounded {
  double value{0.0};
  double error{0.0};
};

[[nodiscard]] bool near_zero(const Bounded& x) { return std::abs(x.value) <= kSafety * x.error; }

void check_finite(std::span<const double> coefficients, const char* what) {
  if (coefficients.empty()) {
    throw std::invalid_argument(std::string(what) + ": polynomial has no coefficients");
  }
  for (std::size_t i = 0; i < coefficients.size(); ++i) {
    if (!std::isfinite(coefficients[i])) {
      throw std::invalid_argument(std::string(what) + ": coefficient " + std::to_string(i) +
                                  " is not finite");
    }
  }
}

// Index of the first nonzero coefficient; an all-zero polynomial vanishes everywhere and has no
// meaningful roots or verdict.
[[nodiscard]] std::size_t first_nonzero(std::span<const double> coefficients, const char* what) {
  const auto it =
      std::find_if(coefficients.begin(), coefficients.end(), [](double a) { return a != 0.0; });
  if (it == coefficients.end()) {
    throw std::invalid_argument(std::string(what) + ": polynomial is identically zero");
  }
  return static_cast<std::size_t>(it - coefficients.begin());
}

// c = a - (p / d) * b with first-order error propagation (d is known to be clearly nonzero).
[[nodiscard]] Bounded eliminate(const Bounded& a, const Bounded& p, const Bounded& d,
                                const Bounded& b) {
  const double q = p.value / d.value;
  const double q_error = (p.error + std::abs(q) * d.error) / std::abs(d.value) + kEps * std::abs(q);
  const double qb = q * b.value;
  const double value = a.value - qb;
  const double error = a.error + std::abs(q) * b.error + std::abs(b.value) * q_error +
                       kEps * (std::abs(a.value) + std::abs(qb));
  return {value, error};
}

[[nodiscard]] Verdict routh_array_verdict(std::vector<Bounded> coefficients) {
  // Normalise the leading sign: the roots do not change and the test reads "all positive".
  if (coefficients.front().value < 0.0) {
    for (Bounded& c : coefficients) c.value = -c.value;
  }
  const std::size_t degree = coefficients.size() - 1;
  if (near_zero(coefficients.front())) {
    // The degree itself is in doubt: a root near infinity of unknown sign.
    return Verdict::kUncertain;
  }
  if (degree == 0) return Verdict::kStable;  // no roots at all

  // Every polynomial with all roots in the closed left half plane has non-negative
  // coefficients, so a clearly negative one proves a root with Re > 0.
  for (const Bounded& c : coefficients) {
    if (c.value < 0.0 && !near_zero(c)) return Verdict::kUnstable;
  }

  const std::size_t width = degree / 2 + 1;
  std::vector<Bounded> previous(width);
  std::vector<Bounded> current(width);
  for (std::size_t i = 0; i <= degree; ++i) {
    (i % 2 == 0 ? previous : current)[i / 2] = coefficients[i];
  }
  // The first-column entries are ratios of successive Hurwitz determinants. Stopping at the
  // first entry that is not clearly positive is exact: if it is clearly negative, some Hurwitz
  // determinant is negative, which no polynomial in the closure of the stable set has.
  for (std::size_t row = 1; row <= degree; ++row) {
    const Bounded& pivot = current.front();
    if (near_zero(pivot)) return Verdict::kUncertain;
    if (pivot.value < 0.0) return Verdict::kUnstable;
    if (row == degree) break;
    std::vector<Bounded> next(width);
    for (std::size_t j = 0; j + 1 < width; ++j) {
      next[j] = eliminate(previous[j + 1], previous.front(), pivot, current[j + 1]);
    }
    previous = std::move(current);
    current = std::move(next);
  }
  return Verdict::kStable;
}

// Scales rows and columns by powers of two (exact) so that their norms match; the eigenvalues
// are unchanged and their rounding error shrinks when coefficients span many decades.
void balance(Eigen::MatrixXd& a) {
  const Eigen::Index n = a.rows();
  constexpr int kMaxSweeps = 100;
  for (int sweep = 0; sweep < kMaxSweeps; ++sweep) {
    bool converged = true;
    for (Eigen::Index i = 0; i < n; ++i) {
      double column = 0.0;
      double row = 0.0;
      for (Eigen::Index j = 0; j < n; ++j) {
        if (j == i) continue;
        column += std::abs(a(j, i));
        row += std::abs(a(i, j));
      }
      if (column == 0.0 || row == 0.0) continue;
      const double total = column + row;
      double f = 1.0;
      while (column < row / 2.0) {
        f *= 2.0;
        column *= 4.0;
      }
      while (column > row * 2.0) {
        f /= 2.0;
        column /= 4.0;
      }
      if ((column + row) / f < 0.95 * total) {
        converged = false;
        a.row(i) /= f;
        a.col(i) *= f;
      }
    }
    if (converged) return;
  }
}

}  // namespace

Verdict routh_hurwitz(std::span<const double> coefficients) {
  check_finite(coefficients, "routh_hurwitz");
  const std::size_t start = first_nonzero(coefficients, "routh_hurwitz");
  std::vector<Bounded> bounded;
  bounded.reserve(coefficients.size() - start);
  for (std::size_t i = start; i < coefficients.size(); ++i) {
    bounded.push_back({coefficients[i], kEps * std::abs(coefficients[i])});
  }
  return routh_array_verdict(std::move(bounded));
}

Verdict routh_hurwitz(std::span<const double> coefficients,
                      std::span<const double> coefficient_errors) {
  check_finite(coefficients, "routh_hurwitz");
  if (coefficient_errors.size() != coefficients.size()) {
    throw std::invalid_argument("routh_hurwitz: " + std::to_string(coefficient_errors.size()) +
                                " error bounds for " + std::to_string(coefficients.size()) +
                                " coefficients");
  }
  for (const double e : coefficient_errors) {
    if (!std::isfinite(e) || e < 0.0) {
      throw std::invalid_argument("routh_hurwitz: error bounds must be finite and >= 0");
    }
  }
  // Only exactly known zeros lower the degree; an uncertain leading zero is judged below.
  std::size_t start = 0;
  while (start < coefficients.size() && coefficients[start] == 0.0 &&
         coefficient_errors[start] == 0.0) {
    ++start;
  }
  if (start == coefficients.size()) {
    throw std::invalid_argument("routh_hurwitz: polynomial is identically zero");
  }
  std::vector<Bounded> bounded;
  bounded.reserve(coefficients.size() - start);
  for (std::size_t i = start; i < coefficients.size(); ++i) {
    bounded.push_back({coefficients[i], coefficient_errors[i]});
  }
  return routh_array_verdict(std::move(bounded));
}

std::vector<std::complex<double>> polynomial_roots(std::span<const double> coefficients) {
  check_finite(coefficients, "polynomial_roots");
  const std::size_t start = first_nonzero(coefficients, "polynomial_roots");
  std::size_t end = coefficients.size();
  std::vector<std::complex<double>> roots;
  // Trailing zeros are factors of s: exact roots at the origin, kept out of the eigenproblem.
  while (coefficients[end - 1] == 0.0) {
    roots.emplace_back(0.0, 0.0);
    --end;
  }
  const auto n = static_cast<Eigen::Index>(end - start - 1);
  if (n > 0) {
    const double leading = coefficients[start];
    Eigen::MatrixXd companion = Eigen::MatrixXd::Zero(n, n);
    for (Eigen::Index j = 0; j < n; ++j) {
      companion(0, j) = -coefficients[start + 1 + static_cast<std::size_t>(j)] / leading;
    }
    for (Eigen::Index i = 1; i < n; ++i) companion(i, i - 1) = 1.0;
    balance(companion);
    const Eigen::EigenSolver<Eigen::MatrixXd> solver(companion, /*computeEigenvectors=*/false);
    if (solver.info() != Eigen::Success) {
      throw std::runtime_error("polynomial_roots: eigenvalue iteration did not converge");
    }
    const Eigen::VectorXcd eigenvalues = solver.eigenvalues();
    for (Eigen::Index i = 0; i < eigenvalues.size(); ++i) roots.push_back(eigenvalues(i));
  }
  std::sort(roots.begin(), roots.end(),
            [](const std::complex<double>& a, const std::complex<double>& b) {
              if (a.real() != b.real()) return a.real() > b.real();
              return a.imag() < b.imag();
            });
  return roots;
}

}  // namespace teleop::stability
