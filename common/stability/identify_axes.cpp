#include "common/stability/identify_axes.hpp"

#include <Eigen/Dense>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "common/core/teleop_axes.hpp"
#include "common/stability/identify_detail.hpp"

namespace teleop::stability {
namespace {

using namespace detail;  // the one-axis identify()'s bounds, for the same reasons, and str()

[[nodiscard]] std::string axis_name(Eigen::Index axis) { return std::to_string(axis + 1); }

[[nodiscard]] std::invalid_argument error(const std::string& what) {
  return std::invalid_argument("identify_axes: " + what);
}

[[nodiscard]] std::invalid_argument run_error(std::size_t run, const std::string& what) {
  return error("run " + std::to_string(run + 1) + ": " + what);
}

// One unknown: M_ij (i <= j) or B_ij, zero-based.
struct Parameter {
  bool mass{true};
  Eigen::Index i{0};
  Eigen::Index j{0};
};

[[nodiscard]] std::string parameter_name(const Parameter& p) {
  const std::string axes =
      p.i == p.j ? "axis " + axis_name(p.i) : "axes " + axis_name(p.i) + " and " + axis_name(p.j);
  return std::string(p.mass ? "M(" : "B(") + axis_name(p.i) + "," + axis_name(p.j) + ") (" + axes +
         ")";
}

[[nodiscard]] std::vector<Parameter> parameters(Eigen::Index n, const IdentifyAxesOptions& o) {
  std::vector<Parameter> out;
  for (Eigen::Index i = 0; i < n; ++i) {
    if (o.mass == MassModel::kPerAxis) {
      out.push_back({true, i, i});
      continue;
    }
    for (Eigen::Index j = i; j < n; ++j) out.push_back({true, i, j});
  }
  for (Eigen::Index i = 0; i < n; ++i) {
    if (o.damping == DampingModel::kDiagonal) {
      out.push_back({false, i, i});
      continue;
    }
    for (Eigen::Index j = 0; j < n; ++j) out.push_back({false, i, j});
  }
  return out;
}

void require_finite(std::size_t run, const char* field, const Eigen::MatrixXd& m) {
  for (Eigen::Index k = 0; k < m.rows(); ++k) {
    for (Eigen::Index i = 0; i < m.cols(); ++i) {
      if (!std::isfinite(m(k, i))) {
        throw run_error(run, std::string(field) + "[" + std::to_string(k) + "] axis " +
                                 axis_name(i) + " is not finite (" + str(m(k, i)) + ")");
      }
    }
  }
}

[[nodiscard]] bool column_constant(const Eigen::MatrixXd& m, Eigen::Index col) {
  return (m.col(col).array() == m(0, col)).all();
}

// Sizes, finiteness and the plain excitation of every axis (it moves, it is driven).
void check_run(std::size_t run, const SeriesAxes& s, Eigen::Index n) {
  if (s.position_m.cols() != n) {
    throw run_error(run, "position_m has " + std::to_string(s.position_m.cols()) +
                             " axes but run 1 has " + std::to_string(n));
  }
  if (s.position_m.rows() < 2) throw run_error(run, "position_m needs at least two samples");
  if (s.force_N.rows() != s.position_m.rows() || s.force_N.cols() != n) {
    throw run_error(run, "force_N is " + std::to_string(s.force_N.rows()) + " x " +
                             std::to_string(s.force_N.cols()) + " but position_m is " +
                             std::to_string(s.position_m.rows()) + " x " + std::to_string(n));
  }
  const bool held = s.held_force_N.size() > 0;
  if (held && (s.held_force_N.rows() != s.position_m.rows() || s.held_force_N.cols() != n)) {
    throw run_error(run, "held_force_N is " + std::to_string(s.held_force_N.rows()) + " x " +
                             std::to_string(s.held_force_N.cols()) + " but position_m is " +
                             std::to_string(s.position_m.rows()) + " x " + std::to_string(n));
  }
  require_finite(run, "position_m", s.position_m);
  require_finite(run, "force_N", s.force_N);
  require_finite(run, "held_force_N", s.held_force_N);
  for (Eigen::Index i = 0; i < n; ++i) {
    if (column_constant(s.position_m, i)) {
      throw run_error(run, "axis " + axis_name(i) + " never moves (position_m constant at " +
                               str(s.position_m(0, i)) +
                               " m): nothing about it can be identified; drive every axis");
    }
    const bool force_constant =
        column_constant(s.force_N, i) && (!held || column_constant(s.held_force_N, i));
    if (force_constant) {
      throw run_error(run, "axis " + axis_name(i) +
                               " is never driven (its force is constant): drive every axis with "
                               "its own varying force");
    }
  }
}

// One axis of one run as the one-axis Series.
[[nodiscard]] Series axis_series(const SeriesAxes& s, Eigen::Index axis) {
  Series out;
  out.period_s = s.period_s;
  out.time_s = s.time_s;
  const auto column = [axis](const Eigen::MatrixXd& m) {
    std::vector<double> v(static_cast<std::size_t>(m.rows()));
    for (Eigen::Index k = 0; k < m.rows(); ++k) v[static_cast<std::size_t>(k)] = m(k, axis);
    return v;
  };
  out.position_m = column(s.position_m);
  out.force_N = column(s.force_N);
  if (s.held_force_N.size() > 0) out.held_force_N = column(s.held_force_N);
  return out;
}

// The one-axis filters' rows of a run, re-raising their errors with the run and axis.
[[nodiscard]] RegressionRows axis_rows(std::size_t run, const SeriesAxes& s, Eigen::Index axis,
                                       const IdentifyOptions& o) {
  try {
    return regression_rows(axis_series(s, axis), o);
  } catch (const std::invalid_argument& e) {
    std::string what = e.what();
    const std::string prefix = "identify: run 1: ";
    if (what.rfind(prefix, 0) == 0) what = what.substr(prefix.size());
    throw run_error(run, "axis " + axis_name(axis) + ": " + what);
  }
}

// The period of a run (time_s's mean step, else period_s), after regression_rows validated it.
[[nodiscard]] double period_of(const SeriesAxes& s) {
  if (s.time_s.empty()) return s.period_s;
  return (s.time_s.back() - s.time_s.front()) / static_cast<double>(s.time_s.size() - 1);
}

// The filtered regressors and forces, all runs stacked: rows x n each.
struct Stacked {
  Eigen::MatrixXd acceleration{};
  Eigen::MatrixXd velocity{};
  Eigen::MatrixXd force{};
};

[[nodiscard]] Stacked stack(const std::vector<SeriesAxes>& runs, Eigen::Index n,
                            const IdentifyOptions& o) {
  std::vector<std::vector<RegressionRows>> per_run(runs.size());
  Eigen::Index total = 0;
  for (std::size_t r = 0; r < runs.size(); ++r) {
    for (Eigen::Index i = 0; i < n; ++i) per_run[r].push_back(axis_rows(r, runs[r], i, o));
    total += static_cast<Eigen::Index>(per_run[r].front().force.size());
  }
  Stacked s{Eigen::MatrixXd(total, n), Eigen::MatrixXd(total, n), Eigen::MatrixXd(total, n)};
  Eigen::Index row = 0;
  for (const std::vector<RegressionRows>& axes : per_run) {
    const Eigen::Index len = static_cast<Eigen::Index>(axes.front().force.size());
    for (Eigen::Index i = 0; i < n; ++i) {
      const RegressionRows& rr = axes[static_cast<std::size_t>(i)];
      for (Eigen::Index k = 0; k < len; ++k) {
        const auto src = static_cast<std::size_t>(k);
        s.acceleration(row + k, i) = rr.acceleration[src];
        s.velocity(row + k, i) = rr.velocity[src];
        s.force(row + k, i) = rr.force[src];
      }
    }
    row += len;
  }
  return s;
}

// Motion below rounding of an axis's position scale cannot carry a parameter (as identify()).
void check_motion(const std::vector<SeriesAxes>& runs, const Stacked& s) {
  double period_max = 0.0;
  for (const SeriesAxes& r : runs) period_max = std::max(period_max, period_of(r));
  const double rows = static_cast<double>(s.force.rows());
  for (Eigen::Index i = 0; i < s.force.cols(); ++i) {
    double x_scale = 0.0;
    for (const SeriesAxes& r : runs)
      x_scale = std::max(x_scale, r.position_m.col(i).cwiseAbs().maxCoeff());
    const double v_rms = s.velocity.col(i).norm() / std::sqrt(rows);
    const double a_rms = s.acceleration.col(i).norm() / std::sqrt(rows);
    if (!(v_rms > kNegligibleRelative * x_scale / period_max)) {
      throw error("axis " + axis_name(i) + ": the velocity is negligible after smoothing (rms " +
                  str(v_rms) + " m/s): the axis barely moved; its damping cannot be identified");
    }
    if (!(a_rms > kNegligibleRelative * x_scale / (period_max * period_max))) {
      throw error("axis " + axis_name(i) +
                  ": the acceleration is negligible after smoothing (rms " + str(a_rms) +
                  " m/s^2): the axis moved at constant velocity; its mass cannot be "
                  "identified");
    }
  }
}

// D (eq. 33 for every axis): axis e's equations fill rows e*N .. (e+1)*N - 1.
[[nodiscard]] Eigen::MatrixXd regression(const Stacked& s, const std::vector<Parameter>& ps) {
  const Eigen::Index rows = s.force.rows();
  const Eigen::Index n = s.force.cols();
  Eigen::MatrixXd d = Eigen::MatrixXd::Zero(n * rows, static_cast<Eigen::Index>(ps.size()));
  for (std::size_t c = 0; c < ps.size(); ++c) {
    const Parameter& p = ps[c];
    const auto col = static_cast<Eigen::Index>(c);
    if (!p.mass) {
      d.col(col).segment(p.i * rows, rows) = s.velocity.col(p.j);
      continue;
    }
    // M_ij x_j'' in axis i's equation and, by symmetry, M_ij x_i'' in axis j's.
    d.col(col).segment(p.i * rows, rows) = s.acceleration.col(p.j);
    if (p.i != p.j) d.col(col).segment(p.j * rows, rows) = s.acceleration.col(p.i);
  }
  return d;
}

// The least-squares fit: parameters, the condition number of D with unit-norm columns and the
// parameter that dominates its least-determined direction, the stacked force and residual.
struct Solution {
  Eigen::VectorXd p{};
  double condition{0.0};
  Eigen::Index worst{0};
  Eigen::VectorXd f{};
  Eigen::VectorXd residual{};
};

[[nodiscard]] Eigen::VectorXd stacked_force(const Stacked& s) {
  const Eigen::Index rows = s.force.rows();
  Eigen::VectorXd f(s.force.size());
  for (Eigen::Index i = 0; i < s.force.cols(); ++i) f.segment(i * rows, rows) = s.force.col(i);
  return f;
}

[[nodiscard]] double condition_of(const Eigen::VectorXd& sigma) {
  const Eigen::Index last = sigma.size() - 1;
  return sigma(last) > 0.0 ? sigma(0) / sigma(last) : std::numeric_limits<double>::infinity();
}

// p = D^+ F (eq. 35) on the whole D with unit-norm columns: the one-axis identify()'s very
// operations, so that n = 1 gives its numbers.
[[nodiscard]] Solution solve_direct(const Stacked& s, const std::vector<Parameter>& ps) {
  const Eigen::MatrixXd d = regression(s, ps);
  Solution out;
  out.f = stacked_force(s);
  Eigen::VectorXd scale(d.cols());
  for (Eigen::Index c = 0; c < d.cols(); ++c) scale(c) = 1.0 / d.col(c).norm();
  const Eigen::MatrixXd ds = d * scale.asDiagonal();
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(ds, Eigen::ComputeThinU | Eigen::ComputeThinV);
  out.condition = condition_of(svd.singularValues());
  svd.matrixV().col(d.cols() - 1).cwiseAbs().maxCoeff(&out.worst);
  out.p = scale.asDiagonal() * svd.solve(out.f);
  out.residual = out.f - d * out.p;
  return out;
}

// Row k of axis e's equations of D (unscaled), as regression() fills them.
void regression_row(const Stacked& s, const std::vector<Parameter>& ps, Eigen::Index e,
                    Eigen::Index k, Eigen::Ref<Eigen::RowVectorXd> row) {
  for (std::size_t c = 0; c < ps.size(); ++c) {
    const Parameter& p = ps[c];
    double value = 0.0;
    if (p.mass) {
      if (p.i == e)
        value = s.acceleration(k, p.j);
      else if (p.j == e)
        value = s.acceleration(k, p.i);
    } else if (p.i == e) {
      value = s.velocity(k, p.j);
    }
    row(static_cast<Eigen::Index>(c)) = value;
  }
}

// The same least squares without forming D (n N x P: 160 MB for six axes with a full B over a
// minute at 1 kHz): the R factor of [D_s F] is accumulated over blocks of rows by Householder
// QR (R of [R; next rows] is R of all rows so far), and D_s's singular values and the solution
// come from the SVD of R's P x P corner, R_P p_s = (Q^T F)_P.
[[nodiscard]] Solution solve_blocked(const Stacked& s, const std::vector<Parameter>& ps) {
  const Eigen::Index rows = s.force.rows();
  const Eigen::Index n = s.force.cols();
  const auto cols = static_cast<Eigen::Index>(ps.size());
  Eigen::RowVectorXd row(cols);
  Eigen::VectorXd norm2 = Eigen::VectorXd::Zero(cols);
  for (Eigen::Index e = 0; e < n; ++e) {
    for (Eigen::Index k = 0; k < rows; ++k) {
      regression_row(s, ps, e, k, row);
      norm2 += row.transpose().cwiseAbs2();
    }
  }
  const Eigen::VectorXd scale = norm2.cwiseSqrt().cwiseInverse();
  constexpr Eigen::Index kBlock = 2048;
  Eigen::MatrixXd work = Eigen::MatrixXd::Zero(cols + 1 + kBlock, cols + 1);
  Eigen::MatrixXd r = Eigen::MatrixXd::Zero(cols + 1, cols + 1);
  Eigen::Index filled = 0;
  const auto reduce = [&]() {
    work.topRows(cols + 1) = r;
    const Eigen::HouseholderQR<Eigen::MatrixXd> qr(work.topRows(cols + 1 + filled));
    r = qr.matrixQR().topRows(cols + 1).triangularView<Eigen::Upper>();
    filled = 0;
  };
  for (Eigen::Index e = 0; e < n; ++e) {
    for (Eigen::Index k = 0; k < rows; ++k) {
      regression_row(s, ps, e, k, row);
      work.row(cols + 1 + filled).head(cols) = row.cwiseProduct(scale.transpose());
      work(cols + 1 + filled, cols) = s.force(k, e);
      if (++filled == kBlock) reduce();
    }
  }
  if (filled > 0) reduce();
  const Eigen::MatrixXd rp = r.topLeftCorner(cols, cols);
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(rp, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Solution out;
  out.condition = condition_of(svd.singularValues());
  svd.matrixV().col(cols - 1).cwiseAbs().maxCoeff(&out.worst);
  out.p = scale.asDiagonal() * svd.solve(r.col(cols).head(cols));
  out.f = stacked_force(s);
  out.residual.resize(out.f.size());
  for (Eigen::Index e = 0; e < n; ++e) {
    for (Eigen::Index k = 0; k < rows; ++k) {
      regression_row(s, ps, e, k, row);
      out.residual(e * rows + k) = s.force(k, e) - row.dot(out.p);
    }
  }
  return out;
}

[[nodiscard]] double r_squared(const Eigen::VectorXd& f, const Eigen::VectorXd& residual) {
  const double ss_tot = (f.array() - f.mean()).square().sum();
  return ss_tot > 0.0 ? 1.0 - residual.squaredNorm() / ss_tot
                      : std::numeric_limits<double>::quiet_NaN();
}

void fill_quality(const Eigen::VectorXd& f, const Eigen::VectorXd& residual, Eigen::Index n,
                  IdentifyAxesResult& out) {
  const Eigen::Index rows = f.size() / n;
  out.axis_r_squared.resize(n);
  out.axis_residual_rms_N.resize(n);
  double ss_tot = 0.0;
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::VectorXd fi = f.segment(i * rows, rows);
    const Eigen::VectorXd ri = residual.segment(i * rows, rows);
    out.axis_r_squared(i) = r_squared(fi, ri);
    out.axis_residual_rms_N(i) = ri.norm() / std::sqrt(static_cast<double>(rows));
    ss_tot += (fi.array() - fi.mean()).square().sum();
  }
  if (!(ss_tot > 0.0)) {
    throw error(
        "the force is constant over the fitted rows: r^2 is undefined; drive every axis "
        "with a varying force");
  }
  out.r_squared = 1.0 - residual.squaredNorm() / ss_tot;
  out.residual_rms_N = residual.norm() / std::sqrt(static_cast<double>(f.size()));
}

}  // namespace

IdentifyAxesResult identify_axes(const std::vector<SeriesAxes>& runs,
                                 const IdentifyAxesOptions& o) {
  if (runs.empty()) throw error("no runs given");
  const Eigen::Index n = runs.front().position_m.cols();
  if (n < 1 || n > kMaxAxes) {
    throw run_error(0, "position_m has " + std::to_string(n) + " axes; 1 to " +
                           std::to_string(kMaxAxes) + " are supported");
  }
  if (o.filter.smoothing_passes < 1 || o.filter.smoothing_passes > kMaxSmoothingPasses) {
    throw error("filter.smoothing_passes must be in [1, " + std::to_string(kMaxSmoothingPasses) +
                "], got " + std::to_string(o.filter.smoothing_passes));
  }
  for (std::size_t r = 0; r < runs.size(); ++r) check_run(r, runs[r], n);
  const Stacked s = stack(runs, n, o.filter);
  check_motion(runs, s);

  const std::vector<Parameter> ps = parameters(n, o);
  const Solution fit = n == 1 ? solve_direct(s, ps) : solve_blocked(s, ps);
  if (!(fit.condition <= kMaxConditionNumber)) {
    throw error("the data do not excite every direction (condition number " + str(fit.condition) +
                "): the least-determined combination of parameters is mostly " +
                parameter_name(ps[static_cast<std::size_t>(fit.worst)]) +
                "; drive the axes with independent forces over a band of frequencies");
  }
  const Eigen::VectorXd& p = fit.p;
  if (!p.allFinite()) throw error("the fit is not finite");

  IdentifyAxesResult out;
  out.mass_kg = Eigen::MatrixXd::Zero(n, n);
  out.damping_Ns_per_m = Eigen::MatrixXd::Zero(n, n);
  for (std::size_t c = 0; c < ps.size(); ++c) {
    const Parameter& q = ps[c];
    const double value = p(static_cast<Eigen::Index>(c));
    if (q.mass) {
      out.mass_kg(q.i, q.j) = value;
      out.mass_kg(q.j, q.i) = value;
    } else {
      out.damping_Ns_per_m(q.i, q.j) = value;
    }
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(out.mass_kg, Eigen::EigenvaluesOnly);
  out.mass_positive_definite = eig.eigenvalues().minCoeff() > 0.0;
  fill_quality(fit.f, fit.residual, n, out);
  out.samples = static_cast<std::size_t>(s.force.rows());
  out.parameters = ps.size();
  out.condition_number = fit.condition;
  return out;
}

}  // namespace teleop::stability
