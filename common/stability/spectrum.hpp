// Eigenvalues of a discrete closed loop, their s-plane images and damping ratios (eqs. 30-31),
// and a verdict that says "uncertain" when the numerical error could change it.
#pragma once

#include <Eigen/Core>
#include <complex>
#include <string>
#include <vector>

#include "common/stability/verdict.hpp"

namespace teleop::stability {

struct Mode {
  std::complex<double> z{};
  double abs_z{0.0};
  bool structural{false};     // identically zero by the model's structure; s and zeta undefined
  std::complex<double> s{};   // ln(z)/T
  double damping_ratio{1.0};  // -Re(s)/|s|
  double error{0.0};          // bound on |error of z| used for the verdict
};

struct Spectrum {
  std::vector<Mode> modes{};  // non-structural modes first, by decreasing |z|
  double spectral_radius{0.0};
  double min_damping_ratio{1.0};
  Verdict verdict{Verdict::kStable};
  // Why the verdict is kInvalid (empty otherwise).
  std::string invalid_reason{};
};

// Modes farther than this from the unit circle are decided without an error estimate.
inline constexpr double kFastPathMargin = 1e-6;

// `estimate_error`: compute each eigenvalue's condition number from the eigenvectors (slower);
// otherwise modes within kFastPathMargin of the unit circle trigger the estimate anyway.
[[nodiscard]] Spectrum compute_spectrum(const Eigen::MatrixXd& a, double period_s,
                                        int structural_zeros, bool estimate_error);

// The damping ratio of one z-plane eigenvalue (eq. 31 through z = e^{sT}).
[[nodiscard]] double damping_ratio(std::complex<double> z);

// Union of block spectra (a block-triangular loop's spectrum is the union of its blocks').
[[nodiscard]] Spectrum merge(const std::vector<Spectrum>& parts);

}  // namespace teleop::stability
