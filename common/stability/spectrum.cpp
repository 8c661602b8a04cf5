#include "common/stability/spectrum.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

namespace teleop::stability {

namespace {

constexpr double kEps = std::numeric_limits<double>::epsilon();
constexpr int kSmall = 12;
using SmallMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kSmall, kSmall>;

// Parlett-Reinsch balancing with powers of two (exact): states in metres, newtons and
// metres-per-sample live side by side, and balancing keeps the eigenvalues well conditioned.
Eigen::MatrixXd balance(Eigen::MatrixXd a) {
  const Eigen::Index n = a.rows();
  bool converged = false;
  for (int sweep = 0; sweep < 50 && !converged; ++sweep) {
    converged = true;
    for (Eigen::Index i = 0; i < n; ++i) {
      const double c = a.col(i).cwiseAbs().sum() - std::abs(a(i, i));
      const double r = a.row(i).cwiseAbs().sum() - std::abs(a(i, i));
      if (c == 0.0 || r == 0.0) continue;
      double f = 1.0;
      double cc = c;
      double rr = r;
      while (cc < rr / 2.0) {
        cc *= 2.0;
        rr /= 2.0;
        f *= 2.0;
      }
      while (cc >= rr * 2.0) {
        cc /= 2.0;
        rr *= 2.0;
        f /= 2.0;
      }
      if ((cc + rr) < 0.95 * (c + r)) {
        converged = false;
        a.col(i) *= f;
        a.row(i) /= f;
      }
    }
  }
  return a;
}

Mode make_mode(std::complex<double> z, double period_s) {
  Mode m;
  m.z = z;
  m.abs_z = std::abs(z);
  if (!(m.abs_z > 1e-300)) {
    m.s = {-std::numeric_limits<double>::infinity(), 0.0};
    m.damping_ratio = 1.0;
    return m;
  }
  m.s = std::log(z) / period_s;
  m.damping_ratio = damping_ratio(z);
  return m;
}

// Stable only when every mode is inside the circle by more than its error: written so that a
// NaN anywhere fails the test (`!(x < y)`), never passes it.
Verdict verdict_of(const std::vector<Mode>& modes) {
  bool uncertain = false;
  bool unstable = false;
  for (const Mode& m : modes) {
    if (m.structural) continue;
    if (!std::isfinite(m.abs_z) || !std::isfinite(m.error) || std::isnan(m.damping_ratio)) {
      return Verdict::kInvalid;
    }
    const double margin = 1.0 - m.abs_z;
    if (margin < -m.error) unstable = true;
    if (!(margin > m.error)) uncertain = true;
  }
  if (unstable) return Verdict::kUnstable;
  return uncertain ? Verdict::kUncertain : Verdict::kStable;
}

// A spectrum that says nothing: NaN radius and damping ratio, verdict invalid.
Spectrum invalid_spectrum(std::string reason) {
  Spectrum sp;
  sp.spectral_radius = std::numeric_limits<double>::quiet_NaN();
  sp.min_damping_ratio = std::numeric_limits<double>::quiet_NaN();
  sp.verdict = Verdict::kInvalid;
  sp.invalid_reason = std::move(reason);
  return sp;
}

void summarise(Spectrum& sp) {
  std::stable_sort(sp.modes.begin(), sp.modes.end(), [](const Mode& x, const Mode& y) {
    if (x.structural != y.structural) return !x.structural;
    return x.abs_z > y.abs_z;
  });
  sp.spectral_radius = 0.0;
  sp.min_damping_ratio = 1.0;
  for (const Mode& m : sp.modes) {
    if (m.structural) continue;
    sp.spectral_radius = std::max(sp.spectral_radius, m.abs_z);
    sp.min_damping_ratio = std::min(sp.min_damping_ratio, m.damping_ratio);
  }
  sp.verdict = verdict_of(sp.modes);
  if (sp.verdict == Verdict::kInvalid) {
    // std::max/min drop NaNs: never print a radius or a damping ratio that was not computed.
    sp.spectral_radius = std::numeric_limits<double>::quiet_NaN();
    sp.min_damping_ratio = std::numeric_limits<double>::quiet_NaN();
    if (sp.invalid_reason.empty()) {
      sp.invalid_reason =
          "an eigenvalue of the closed loop or its damping ratio is not finite (a parameter "
          "overflows the model)";
    }
  }
}

}  // namespace

double damping_ratio(std::complex<double> z) {
  const double mag = std::abs(z);
  if (!(mag > 1e-300)) return 1.0;  // z = 0: s = -inf, no oscillation
  // ln z = ln|z| + i arg z; log1p keeps the digits of ln|z| for |z| near 1.
  const double re =
      mag < 0.5 ? std::log(mag)
                : 0.5 * std::log1p((z.real() - 1.0) * (z.real() + 1.0) + z.imag() * z.imag());
  const double im = std::arg(z);
  const double norm = std::hypot(re, im);
  if (norm == 0.0) return 0.0;  // z == 1: a marginal rigid-body mode
  return -re / norm;
}

Spectrum compute_spectrum(const Eigen::MatrixXd& a_in, double period_s, int structural_zeros,
                          bool estimate_error) {
  if (!a_in.allFinite()) {
    return invalid_spectrum(
        "the closed-loop matrix has a non-finite entry (a parameter overflows the model)");
  }
  if (!(std::isfinite(period_s) && period_s > 0.0)) {
    return invalid_spectrum("the sample period is not a positive finite number");
  }
  Spectrum sp;
  const Eigen::Index n = a_in.rows();
  if (n > 0) {
    const Eigen::MatrixXd a = balance(a_in);
    const double unit_error = 8.0 * static_cast<double>(n) * kEps * a.norm();
    // Reused between calls so a band sweep does not allocate the solver's workspace each time;
    // the eigenvalue-only path of a sweep runs on stack-sized matrices.
    thread_local Eigen::EigenSolver<Eigen::MatrixXd> es;
    Eigen::VectorXcd lambda;
    if (!estimate_error && n <= kSmall) {
      thread_local Eigen::EigenSolver<SmallMatrix> small;
      small.compute(SmallMatrix(a), false);
      lambda = small.eigenvalues();
    } else {
      es.compute(a, estimate_error);
      lambda = es.eigenvalues();
    }
    bool near_circle = false;
    for (Eigen::Index i = 0; i < n; ++i) {
      near_circle = near_circle || std::abs(1.0 - std::abs(lambda(i))) <= kFastPathMargin;
    }
    std::vector<double> errors(static_cast<std::size_t>(n), kFastPathMargin);
    if (estimate_error || near_circle) {
      // |dz_i| <= kappa_i * |dA| with kappa_i = |y_i| |x_i| / |y_i^H x_i|; the rows of V^-1 are
      // the left eigenvectors scaled so that y_i^H x_i = 1.
      if (!estimate_error) {
        es.compute(a, true);
        lambda = es.eigenvalues();
      }
      const Eigen::MatrixXcd v = es.eigenvectors();
      Eigen::FullPivLU<Eigen::MatrixXcd> lu(v);
      const double kappa_cap = 1.0 / kEps;
      const bool invertible = lu.isInvertible();
      const Eigen::MatrixXcd vinv = invertible ? Eigen::MatrixXcd(lu.inverse()) : v;
      for (Eigen::Index i = 0; i < n; ++i) {
        // A numerically singular eigenvector matrix means a (nearly) defective eigenvalue
        // somewhere: bound every mode by the sqrt(|dA|) splitting of a Jordan pair.
        double kappa = 1.0 / std::sqrt(unit_error);
        if (invertible) kappa = std::min(kappa_cap, vinv.row(i).norm() * v.col(i).norm());
        // A defective (Jordan) pair splits by sqrt(|dA|): never claim less than that.
        errors[static_cast<std::size_t>(i)] =
            std::max(kappa * unit_error, kappa > 1e6 ? std::sqrt(unit_error) : 0.0);
      }
    }
    for (Eigen::Index i = 0; i < n; ++i) {
      Mode m = make_mode(lambda(i), period_s);
      m.error = errors[static_cast<std::size_t>(i)];
      sp.modes.push_back(m);
    }
  }
  for (int i = 0; i < structural_zeros; ++i) {
    Mode m;
    m.structural = true;
    sp.modes.push_back(m);
  }
  summarise(sp);
  return sp;
}

Spectrum merge(const std::vector<Spectrum>& parts) {
  for (const Spectrum& p : parts) {
    if (p.verdict == Verdict::kInvalid) return invalid_spectrum(p.invalid_reason);
  }
  Spectrum sp;
  for (const Spectrum& p : parts) sp.modes.insert(sp.modes.end(), p.modes.begin(), p.modes.end());
  summarise(sp);
  return sp;
}

}  // namespace teleop::stability
