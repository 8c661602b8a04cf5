#include "common/stability/identify.hpp"

#include <Eigen/Dense>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "common/stability/identify_detail.hpp"

namespace teleop::stability {
namespace {

using namespace detail;  // the bounds and str() shared with identify_axes.cpp

// Time steps may differ from the mean by this fraction of it.
constexpr double kTimeStepTolerance = 0.01;
constexpr std::size_t kDifferenceHalfWidth = 2;  // five-point stencil
// More rows than parameters, so that a run's r^2 means something.
constexpr std::size_t kMinRowsPerRun = 3;

[[nodiscard]] std::invalid_argument run_error(std::size_t run, const std::string& what) {
  return std::invalid_argument("identify: run " + std::to_string(run + 1) + ": " + what);
}

// A signal valid on [lo, hi) of a full-length buffer; indices stay those of the run's samples.
struct Signal {
  std::vector<double> v{};
  std::size_t lo{0};
  std::size_t hi{0};
};

// One three-point moving-average pass; the ends lose a sample each.
void smooth_pass(Signal& s, std::vector<double>& scratch) {
  scratch.assign(s.v.size(), 0.0);
  for (std::size_t i = s.lo + 1; i + 1 < s.hi; ++i) {
    scratch[i] = (s.v[i - 1] + s.v[i] + s.v[i + 1]) / 3.0;
  }
  s.v.swap(scratch);
  s.lo += 1;
  s.hi -= 1;
}

void smooth(Signal& s, int passes) {
  std::vector<double> scratch;
  for (int p = 0; p < passes; ++p) smooth_pass(s, scratch);
}

// Five-point central difference, fourth-order accurate and zero phase.
[[nodiscard]] Signal differentiate(const Signal& s, double period_s) {
  Signal d;
  d.v.assign(s.v.size(), 0.0);
  d.lo = s.lo + kDifferenceHalfWidth;
  d.hi = s.hi - kDifferenceHalfWidth;
  const double scale = 1.0 / (12.0 * period_s);
  for (std::size_t i = d.lo; i < d.hi; ++i) {
    d.v[i] = (s.v[i - 2] - 8.0 * s.v[i - 1] + 8.0 * s.v[i + 1] - s.v[i + 2]) * scale;
  }
  return d;
}

void require_finite(std::size_t run, const char* field, const std::vector<double>& v) {
  for (std::size_t i = 0; i < v.size(); ++i) {
    if (!std::isfinite(v[i])) {
      throw run_error(run, std::string(field) + "[" + std::to_string(i) + "] is not finite (" +
                               str(v[i]) + ")");
    }
  }
}

[[nodiscard]] double run_period(std::size_t run, const Series& s) {
  if (s.time_s.empty()) {
    if (!(std::isfinite(s.period_s) && s.period_s > 0.0)) {
      throw run_error(run, "period_s must be positive and finite, got " + str(s.period_s) +
                               " (or give time_s)");
    }
    return s.period_s;
  }
  if (s.time_s.size() != s.position_m.size()) {
    throw run_error(run, "time_s has " + std::to_string(s.time_s.size()) +
                             " samples but position_m has " + std::to_string(s.position_m.size()));
  }
  require_finite(run, "time_s", s.time_s);
  if (s.time_s.size() < 2) throw run_error(run, "time_s needs at least two samples");
  const double mean =
      (s.time_s.back() - s.time_s.front()) / static_cast<double>(s.time_s.size() - 1);
  if (!(mean > 0.0)) throw run_error(run, "time_s is not increasing");
  for (std::size_t i = 1; i < s.time_s.size(); ++i) {
    const double step = s.time_s[i] - s.time_s[i - 1];
    if (!(std::abs(step - mean) <= kTimeStepTolerance * mean)) {
      throw run_error(run, "time_s is not uniformly sampled: the step to sample " +
                               std::to_string(i) + " is " + str(step) + " s, the mean is " +
                               str(mean) + " s (resample, or split the run at the gap)");
    }
  }
  return mean;
}

[[nodiscard]] std::size_t edge_samples(const IdentifyOptions& o) {
  return 2 * static_cast<std::size_t>(o.smoothing_passes) + 2 * kDifferenceHalfWidth +
         o.trim_samples;
}

[[nodiscard]] std::size_t minimum_samples(bool has_held_force, const IdentifyOptions& o) {
  return 2 * edge_samples(o) + kMinRowsPerRun + (has_held_force ? 1 : 0);
}

[[nodiscard]] bool is_constant(const std::vector<double>& v) {
  return std::all_of(v.begin(), v.end(), [&](double x) { return x == v.front(); });
}

[[nodiscard]] RegressionRows run_rows(std::size_t run, const Series& s, const IdentifyOptions& o) {
  const std::size_t n = s.position_m.size();
  if (s.force_N.size() != n) {
    throw run_error(run, "force_N has " + std::to_string(s.force_N.size()) +
                             " samples but position_m has " + std::to_string(n));
  }
  const bool held = !s.held_force_N.empty();
  if (held && s.held_force_N.size() != n) {
    throw run_error(run, "held_force_N has " + std::to_string(s.held_force_N.size()) +
                             " samples but position_m has " + std::to_string(n));
  }
  const double period_s = run_period(run, s);
  require_finite(run, "position_m", s.position_m);
  require_finite(run, "force_N", s.force_N);
  require_finite(run, "held_force_N", s.held_force_N);
  if (usable_rows(n, held, o) == 0) {
    throw run_error(run, "too few samples: " + std::to_string(n) + "; " +
                             std::to_string(o.smoothing_passes) + " smoothing passes and " +
                             std::to_string(o.trim_samples) +
                             " trimmed samples at each end need at least " +
                             std::to_string(minimum_samples(held, o)));
  }
  if (is_constant(s.position_m)) {
    throw run_error(run, "position_m is constant (" + str(s.position_m.front()) +
                             " m): the device did not move, so nothing can be identified");
  }

  const std::size_t len = held ? n - 1 : n;
  Signal x{std::vector<double>(s.position_m.begin(),
                               s.position_m.begin() + static_cast<std::ptrdiff_t>(len)),
           0, len};
  Signal f{
      std::vector<double>(s.force_N.begin(), s.force_N.begin() + static_cast<std::ptrdiff_t>(len)),
      0, len};
  if (held) {
    for (std::size_t i = 0; i < len; ++i) {
      f.v[i] += 0.5 * (s.held_force_N[i] + s.held_force_N[i + 1]);
    }
  }
  if (is_constant(f.v)) {
    throw run_error(run, "the force is constant (" + str(f.v.front()) +
                             " N): drive the device with a varying force");
  }

  smooth(x, o.smoothing_passes);
  Signal v = differentiate(x, period_s);
  smooth(v, o.smoothing_passes);
  const Signal a = differentiate(v, period_s);
  if (o.smooth_force) smooth(f, 2 * o.smoothing_passes);

  const std::size_t lo = a.lo + o.trim_samples;
  const std::size_t hi = a.hi - o.trim_samples;
  RegressionRows rows;
  rows.first_sample = lo;
  rows.acceleration.assign(a.v.begin() + static_cast<std::ptrdiff_t>(lo),
                           a.v.begin() + static_cast<std::ptrdiff_t>(hi));
  rows.velocity.assign(v.v.begin() + static_cast<std::ptrdiff_t>(lo),
                       v.v.begin() + static_cast<std::ptrdiff_t>(hi));
  rows.force.assign(f.v.begin() + static_cast<std::ptrdiff_t>(lo),
                    f.v.begin() + static_cast<std::ptrdiff_t>(hi));
  return rows;
}

[[nodiscard]] double r_squared(const Eigen::VectorXd& f, const Eigen::VectorXd& residual) {
  const double ss_tot = (f.array() - f.mean()).square().sum();
  return ss_tot > 0.0 ? 1.0 - residual.squaredNorm() / ss_tot
                      : std::numeric_limits<double>::quiet_NaN();
}

}  // namespace

RegressionRows regression_rows(const Series& run, const IdentifyOptions& options) {
  return run_rows(0, run, options);
}

std::size_t usable_rows(std::size_t samples, bool has_held_force, const IdentifyOptions& o) {
  if (o.smoothing_passes < 1 || o.smoothing_passes > kMaxSmoothingPasses) return 0;
  const std::size_t len = has_held_force && samples > 0 ? samples - 1 : samples;
  const std::size_t edge = edge_samples(o);
  return len >= 2 * edge + kMinRowsPerRun ? len - 2 * edge : 0;
}

IdentifyResult identify(const std::vector<Series>& runs, const IdentifyOptions& o) {
  if (runs.empty()) throw std::invalid_argument("identify: no runs given");
  if (o.smoothing_passes < 1 || o.smoothing_passes > kMaxSmoothingPasses) {
    throw std::invalid_argument("identify: smoothing_passes must be in [1, " +
                                std::to_string(kMaxSmoothingPasses) + "], got " +
                                std::to_string(o.smoothing_passes));
  }
  std::vector<RegressionRows> per_run;
  per_run.reserve(runs.size());
  std::size_t total = 0;
  for (std::size_t r = 0; r < runs.size(); ++r) {
    per_run.push_back(run_rows(r, runs[r], o));
    total += per_run.back().force.size();
  }

  // Stack the runs (eq. 33).
  Eigen::MatrixXd d(static_cast<Eigen::Index>(total), 2);
  Eigen::VectorXd f(static_cast<Eigen::Index>(total));
  Eigen::Index row = 0;
  for (const RegressionRows& rr : per_run) {
    for (std::size_t i = 0; i < rr.force.size(); ++i, ++row) {
      d(row, 0) = rr.acceleration[i];
      d(row, 1) = rr.velocity[i];
      f(row) = rr.force[i];
    }
  }

  // Motion below rounding of the position scale cannot carry a parameter.
  double x_scale = 0.0;
  double period_max = 0.0;
  for (std::size_t r = 0; r < runs.size(); ++r) {
    for (const double x : runs[r].position_m) x_scale = std::max(x_scale, std::abs(x));
    period_max = std::max(period_max, run_period(r, runs[r]));
  }
  const double rows = static_cast<double>(total);
  const double a_rms = d.col(0).norm() / std::sqrt(rows);
  const double v_rms = d.col(1).norm() / std::sqrt(rows);
  if (!(v_rms > kNegligibleRelative * x_scale / period_max)) {
    throw std::invalid_argument("identify: the velocity is negligible after smoothing (rms " +
                                str(v_rms) +
                                " m/s): the device barely moved; damping cannot be identified");
  }
  if (!(a_rms > kNegligibleRelative * x_scale / (period_max * period_max))) {
    throw std::invalid_argument(
        "identify: the acceleration is negligible after smoothing (rms " + str(a_rms) +
        " m/s^2): the device moved at constant velocity; mass cannot be identified");
  }

  // p = D^+ F (eq. 35) through the SVD. The columns are scaled to unit norm first: the same
  // least-squares solution, but singular values that measure how far x'' and x' are from
  // proportional rather than their units.
  const Eigen::Vector2d scale(1.0 / d.col(0).norm(), 1.0 / d.col(1).norm());
  const Eigen::MatrixXd ds = d * scale.asDiagonal();
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(ds, Eigen::ComputeThinU | Eigen::ComputeThinV);
  const Eigen::Vector2d sigma = svd.singularValues();
  const double condition =
      sigma(1) > 0.0 ? sigma(0) / sigma(1) : std::numeric_limits<double>::infinity();
  if (!(condition <= kMaxConditionNumber)) {
    throw std::invalid_argument(
        "identify: acceleration and velocity are proportional (condition number " + str(condition) +
        "), as in a free decay: m and b cannot be separated; drive the device with a force "
        "that varies over a band of frequencies");
  }
  const Eigen::Vector2d p = scale.asDiagonal() * svd.solve(f);
  if (!p.allFinite()) throw std::invalid_argument("identify: the fit is not finite");

  IdentifyResult result;
  result.mass_kg = p(0);
  result.damping_Ns_per_m = p(1);
  const Eigen::VectorXd residual = f - d * p;
  result.r_squared = r_squared(f, residual);
  if (!std::isfinite(result.r_squared)) {
    throw std::invalid_argument(
        "identify: the force is constant over the fitted rows: r^2 is undefined; drive the "
        "device with a varying force");
  }
  result.residual_rms_N = residual.norm() / std::sqrt(rows);
  result.samples = total;
  result.condition_number = condition;
  row = 0;
  for (const RegressionRows& rr : per_run) {
    const Eigen::Index len = static_cast<Eigen::Index>(rr.force.size());
    RunFit fit;
    fit.samples = rr.force.size();
    fit.r_squared = r_squared(f.segment(row, len), residual.segment(row, len));
    result.runs.push_back(fit);
    row += len;
  }
  return result;
}

}  // namespace teleop::stability
