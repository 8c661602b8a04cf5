// Routh-Hurwitz test and polynomial roots for real polynomials of any degree. Coefficients are
// given highest power first: {a_n, a_(n-1), ..., a_0}.
#pragma once

#include <complex>
#include <span>
#include <vector>

#include "common/stability/verdict.hpp"

namespace teleop::stability {

// kStable iff every root has Re < 0, decided from the complete Routh array (first column
// strictly positive once the leading coefficient's sign is normalised). Every entry carries a
// first-order bound on its rounding error; an entry within that error of zero (a root on or
// numerically at the imaginary axis, or a singular array) gives kUncertain rather than a guess.
// A clearly negative entry (or coefficient) preceded only by clearly positive ones proves a root
// with Re > 0 (kUnstable). The coefficients are taken to carry one rounding each (eps * |a_i|).
// Leading coefficients that are exactly zero are ignored; a constant has no roots (kStable).
// Throws std::invalid_argument for an empty, all-zero or non-finite polynomial.
[[nodiscard]] Verdict routh_hurwitz(std::span<const double> coefficients);

// As above, with caller-supplied absolute error bounds on each coefficient (same length, >= 0),
// e.g. from the cancellation in forming them.
[[nodiscard]] Verdict routh_hurwitz(std::span<const double> coefficients,
                                    std::span<const double> coefficient_errors);

// Roots from the eigenvalues of the balanced companion matrix, sorted by decreasing real part
// (then increasing imaginary part). Leading zeros are ignored; trailing zeros give exact zero
// roots. Throws std::invalid_argument for an empty, all-zero or non-finite polynomial.
[[nodiscard]] std::vector<std::complex<double>> polynomial_roots(
    std::span<const double> coefficients);

}  // namespace teleop::stability
