#include "common/stability/discrete_model_axes.hpp"

#include <Eigen/Cholesky>
#include <Eigen/QR>
#include <cmath>
#include <numbers>
#include <stdexcept>

namespace teleop::stability {

namespace {

using Mat = Eigen::MatrixXd;

std::string indexed(const std::string& base, std::size_t i) {
  return base + "[" + std::to_string(i) + "]";
}

// Square n x n and finite, else what is wrong with `field`.
std::string check_square(const Mat& m, int n, const std::string& field) {
  if (m.rows() != n || m.cols() != n) {
    return field + " must be " + std::to_string(n) + "x" + std::to_string(n) + ", got " +
           std::to_string(m.rows()) + "x" + std::to_string(m.cols());
  }
  if (!m.allFinite()) return field + " must be finite (has NaN or infinity)";
  return "";
}

std::string check_vector(const Eigen::VectorXd& v, int n, const std::string& field,
                         bool non_negative) {
  if (v.size() != n) return field + " must have " + std::to_string(n) + " entries";
  if (!v.allFinite()) return field + " must be finite (has NaN or infinity)";
  if (non_negative && (v.array() < 0.0).any()) return field + " must not be negative";
  return "";
}

std::string check_device(const DeviceAxesParams& d, int n, const std::string& field) {
  if (auto why = check_square(d.mass_kg, n, field + ".mass_kg"); !why.empty()) return why;
  if (!d.mass_kg.isApprox(d.mass_kg.transpose(), 1e-12)) {
    return field + ".mass_kg must be symmetric";
  }
  if (Eigen::LLT<Mat>(d.mass_kg).info() != Eigen::Success) {
    return field + ".mass_kg must be positive definite";
  }
  if (auto why = check_vector(d.damping_Ns_per_m, n, field + ".damping_Ns_per_m", true);
      !why.empty()) {
    return why;
  }
  if (d.coulomb_N.size() != 0) return check_vector(d.coulomb_N, n, field + ".coulomb_N", true);
  return "";
}

std::string check_planes(const std::vector<PlaneFixtureParams>& planes, int n,
                         const std::string& field) {
  if (planes.size() > static_cast<std::size_t>(kMaxPlanesPerSide)) {
    return field + ": at most " + std::to_string(kMaxPlanesPerSide) + " planes a side, got " +
           std::to_string(planes.size());
  }
  for (std::size_t i = 0; i < planes.size(); ++i) {
    const PlaneFixtureParams& pl = planes[i];
    const std::string f = indexed(field, i);
    if (auto why = check_vector(pl.normal, n, f + ".normal", false); !why.empty()) return why;
    if (std::abs(pl.normal.norm() - 1.0) > 1e-9) return f + ".normal must have unit length";
    if (!std::isfinite(pl.offset_m)) return f + ".offset_m must be finite";
    if (!std::isfinite(pl.stiffness_N_per_m)) return f + ".stiffness_N_per_m must be finite";
    if (pl.stiffness_N_per_m < 0.0) return f + ".stiffness_N_per_m must not be negative";
  }
  return "";
}

std::string check_band(const HumanBand& b, const std::string& f) {
  if (b.force_levels_N.empty()) return f + ".force_levels_N must not be empty";
  for (const double x : b.force_levels_N) {
    if (!std::isfinite(x)) return f + ".force_levels_N must be finite";
  }
  if (b.points_per_axis < 1) return f + ".points_per_axis must be at least 1";
  const std::pair<const ParameterBand*, const char*> parts[] = {
      {&b.mass_kg, ".mass_kg"},
      {&b.damping_Ns_per_m, ".damping_Ns_per_m"},
      {&b.stiffness_N_per_m, ".stiffness_N_per_m"}};
  for (const auto& [band, name] : parts) {
    for (const double x : {band->lower.intercept, band->lower.slope_per_N, band->upper.intercept,
                           band->upper.slope_per_N}) {
      if (!std::isfinite(x)) return f + name + " must be finite";
    }
  }
  return "";
}

std::string check_human(const HumanModelAxes& h, int n) {
  if (h.kind == HumanKind::kFixed) {
    const std::pair<const Mat*, const char*> parts[] = {
        {&h.fixed.mass_kg, "human.fixed.mass_kg"},
        {&h.fixed.damping_Ns_per_m, "human.fixed.damping_Ns_per_m"},
        {&h.fixed.stiffness_N_per_m, "human.fixed.stiffness_N_per_m"}};
    for (const auto& [m, name] : parts) {
      if (auto why = check_square(*m, n, name); !why.empty()) return why;
    }
  }
  if (h.kind == HumanKind::kBand) {
    if (h.band_per_axis.size() != static_cast<std::size_t>(n)) {
      return "human.band_per_axis must have " + std::to_string(n) + " entries";
    }
    for (std::size_t i = 0; i < h.band_per_axis.size(); ++i) {
      if (auto why = check_band(h.band_per_axis[i], indexed("human.band_per_axis", i));
          !why.empty()) {
        return why;
      }
    }
  }
  return "";
}

std::string check_gains(const GainsAxes& g, int n) {
  const std::pair<const Mat*, const char*> parts[] = {
      {&g.kpm, "gains.kpm"}, {&g.kps, "gains.kps"}, {&g.kdm, "gains.kdm"}, {&g.kds, "gains.kds"},
      {&g.kvm, "gains.kvm"}, {&g.kvs, "gains.kvs"}, {&g.kfm, "gains.kfm"}};
  for (const auto& [m, name] : parts) {
    if (auto why = check_square(*m, n, name); !why.empty()) return why;
  }
  return "";
}

bool nonzero(const Mat& m) { return !m.isZero(0.0); }

// The rows of `e` that are not identically zero.
std::vector<int> live_rows(const Mat& e) {
  std::vector<int> rows;
  for (int i = 0; i < e.rows(); ++i) {
    if (!e.row(i).isZero(0.0)) rows.push_back(i);
  }
  return rows;
}

Mat take_rows(const Mat& e, const std::vector<int>& rows) {
  Mat out(static_cast<Eigen::Index>(rows.size()), e.cols());
  for (std::size_t i = 0; i < rows.size(); ++i) {
    out.row(static_cast<Eigen::Index>(i)) = e.row(rows[i]);
  }
  return out;
}

}  // namespace

std::string check_axes_params(const TeleopAxesParams& p) {
  const int n = p.axes;
  if (n < 1 || n > kMaxAxes) return "axes must be 1 to 6, got " + std::to_string(n);
  if (!std::isfinite(p.sample_rate_hz) || !(p.sample_rate_hz > 0.0)) {
    return "sample_rate_hz must be positive and finite";
  }
  if (auto why = check_device(p.master_device, n, "master_device"); !why.empty()) return why;
  if (auto why = check_device(p.slave_device, n, "slave_device"); !why.empty()) return why;
  if (auto why = check_planes(p.master_planes, n, "master_planes"); !why.empty()) return why;
  if (auto why = check_planes(p.slave_planes, n, "slave_planes"); !why.empty()) return why;
  if (auto why = check_gains(p.gains, n); !why.empty()) return why;
  if (!std::isfinite(p.scaling.position) || p.scaling.position == 0.0) {
    return "scaling.position must be finite and non-zero";
  }
  if (!std::isfinite(p.scaling.force)) return "scaling.force must be finite";
  if (!std::isfinite(p.velocity_cutoff_hz) || p.velocity_cutoff_hz < 0.0) {
    return "velocity_cutoff_hz must be finite and not negative";
  }
  if (p.round_trip_delay_samples < 0) return "round_trip_delay_samples must not be negative";
  if (!std::isfinite(p.analysis.required_damping_ratio)) {
    return "analysis.required_damping_ratio must be finite";
  }
  if (auto why = check_human(p.human, n); !why.empty()) return why;
  if (p.human.kind == HumanKind::kFixed) {
    const Mat& hm = p.human.fixed.mass_kg;
    if (!hm.isApprox(hm.transpose(), 1e-12)) return "human.fixed.mass_kg must be symmetric";
    if (Eigen::LLT<Mat>(p.master_device.mass_kg + hm).info() != Eigen::Success) {
      return "master_device.mass_kg + human.fixed.mass_kg must be positive definite";
    }
  }
  return "";
}

Eigen::MatrixXd plane_stiffness_matrix(const std::vector<PlaneFixtureParams>& planes, int axes,
                                       const std::vector<bool>& active) {
  Mat k = Mat::Zero(axes, axes);
  for (std::size_t i = 0; i < planes.size(); ++i) {
    if (!active.empty() && !active[i]) continue;
    const PlaneFixtureParams& pl = planes[i];
    if (pl.stiffness_N_per_m == 0.0) continue;
    k += pl.stiffness_N_per_m * pl.normal * pl.normal.transpose();
  }
  return k;
}

DiscreteModelAxes::DiscreteModelAxes(const TeleopAxesParams& params, bool master_planes_used,
                                     bool slave_planes_used)
    : p_(params), n_(params.axes), period_s_(params.period_s()) {
  if (const std::string why = check_axes_params(p_); !why.empty()) {
    throw std::invalid_argument(why);
  }
  if (p_.velocity_cutoff_hz > 0.0) {
    filter_r_ = std::exp(-2.0 * std::numbers::pi * p_.velocity_cutoff_hz * period_s_);
    filter_a_ = -std::expm1(-2.0 * std::numbers::pi * p_.velocity_cutoff_hz * period_s_);
  }
  slave_plant_ =
      discretize_plant_axes(p_.slave_device.mass_kg, p_.slave_device.damping_Ns_per_m.asDiagonal(),
                            Mat::Zero(n_, n_), period_s_);
  const GainsAxes& g = p_.gains;
  const double beta = p_.scaling.force;
  // The one-axis decisions (discrete_model.cpp) with "non-zero" meaning any entry non-zero.
  const bool master_feels_slave = beta != 0.0 && (nonzero(g.kpm) || nonzero(g.kdm));
  const bool slave_follows_master = nonzero(g.kps) || nonzero(g.kds);
  const bool master_wall = nonzero(plane_stiffness_matrix(p_.master_planes, n_));
  const bool slave_wall = nonzero(plane_stiffness_matrix(p_.slave_planes, n_));
  const bool master_actuated =
      master_feels_slave || nonzero(g.kvm) || master_wall || master_planes_used;
  const bool slave_in_loop =
      slave_follows_master || slave_planes_used || slave_wall || !master_actuated;
  structure_ =
      structure_of(master_feels_slave, slave_follows_master, master_actuated, slave_in_loop);
}

ZohPlantAxes DiscreteModelAxes::master_plant(const HumanImpedanceAxes& h) const {
  const DeviceAxesParams& d = p_.master_device;
  const auto or_zero = [this](const Mat& m) { return m.size() == 0 ? Mat(Mat::Zero(n_, n_)) : m; };
  return discretize_plant_axes(d.mass_kg + or_zero(h.mass_kg),
                               Mat(d.damping_Ns_per_m.asDiagonal()) + or_zero(h.damping_Ns_per_m),
                               or_zero(h.stiffness_N_per_m), period_s_);
}

std::vector<AxesBlock> DiscreteModelAxes::build(const ZohPlantAxes& master_plant, const Mat& kmvf,
                                                const Mat& ksvf) const {
  return blocks_of<AxesBlock>(structure_, [&](bool with_master, bool with_slave) {
    return build_block(with_master, with_slave, master_plant, kmvf, ksvf);
  });
}

AxesBlock DiscreteModelAxes::build_block(bool with_master, bool with_slave,
                                         const ZohPlantAxes& master_plant, const Mat& kmvf,
                                         const Mat& ksvf) const {
  const int n = n_;
  const GainsAxes& g = p_.gains;
  const double t = period_s_;
  const double alpha = p_.scaling.position;
  const double beta = p_.scaling.force;
  const int delay = (with_master && with_slave) ? p_.round_trip_delay_samples : 0;

  // Layout: [x_m, T v_m] (2n), [x_s, T v_s] (2n), x_m(k-1) ... x_m(k-d) (d n), then the
  // velocity memories. Velocities carried as v T (metres) as in the one-axis model.
  int size = 0;
  const int ixm = with_master ? size : -1;
  size += with_master ? 2 * n : 0;
  const int ixs = with_slave ? size : -1;
  size += with_slave ? 2 * n : 0;
  const int id0 = size;
  size += delay * n;
  const int src = with_master ? (delay > 0 ? id0 + (delay - 1) * n : ixm) : -1;
  const int plant_states = size;

  // Velocity signals e = E x (gain-weighted positions) of each controller; the velocity force
  // is (a/T) e + f with one memory f per live row (discrete_model.cpp, per axis).
  Mat em = Mat::Zero(n, plant_states);
  Mat es = Mat::Zero(n, plant_states);
  if (with_master) {
    em.middleCols(ixm, n) += beta * g.kdm + g.kvm;
    if (with_slave) em.middleCols(ixs, n) -= (beta / alpha) * g.kdm;
  }
  if (with_slave) {
    es.middleCols(ixs, n) -= g.kds + g.kvs;
    if (with_master) es.middleCols(src, n) += alpha * g.kds;
  }
  const std::vector<int> rows_m = with_master ? live_rows(em) : std::vector<int>{};
  const std::vector<int> rows_s = with_slave ? live_rows(es) : std::vector<int>{};
  const Mat em_live = take_rows(em, rows_m);
  const Mat es_live = take_rows(es, rows_s);
  // Without a low-pass, a master signal that is a combination of the slave's makes its
  // memory the same combination of the slave's: it shares them (the one-axis shared memory).
  bool shared = false;
  Mat share;  // em_live = share * es_live
  if (!rows_m.empty() && !rows_s.empty() && filter_r_ == 0.0) {
    share = es_live.transpose().completeOrthogonalDecomposition().solve(em_live.transpose());
    share.transposeInPlace();
    shared =
        (em_live - share * es_live).cwiseAbs().maxCoeff() <= 1e-14 * em_live.cwiseAbs().maxCoeff();
  }
  const int ps = static_cast<int>(rows_s.size());
  const int pm = shared ? 0 : static_cast<int>(rows_m.size());
  const int ifs = id0 + delay * n;
  const int ifm = ifs + ps;
  size += ps + pm;

  const double a = filter_a_;
  const double r = filter_r_;
  Mat big_a = Mat::Zero(size, size);
  auto widen = [&](const Mat& e) {
    Mat w = Mat::Zero(e.rows(), size);
    w.leftCols(plant_states) = e;
    return w;
  };
  // Plant rows: [x; T v](k+1) = phi~ [x; T v] + gamma~ u with u = sign * force * state.
  auto plant_rows = [&](int ix, const ZohPlantAxes& pl, const Mat& force, double sign) {
    big_a.block(ix, ix, n, n) = pl.phi.topLeftCorner(n, n);
    big_a.block(ix, ix + n, n, n) = pl.phi.topRightCorner(n, n) / t;
    big_a.block(ix + n, ix, n, n) = t * pl.phi.bottomLeftCorner(n, n);
    big_a.block(ix + n, ix + n, n, n) = pl.phi.bottomRightCorner(n, n);
    big_a.middleRows(ix, n) += (sign * pl.gamma.topRows(n)) * force;
    big_a.middleRows(ix + n, n) += (sign * t * pl.gamma.bottomRows(n)) * force;
  };
  if (with_master) {
    Mat force = Mat::Zero(n, size);
    force.middleCols(ixm, n) = beta * g.kpm + kmvf;
    if (with_slave) force.middleCols(ixs, n) = -(beta / alpha) * g.kpm;
    if (!rows_m.empty()) {
      force += (a / t) * widen(em);
      for (int i = 0; i < static_cast<int>(rows_m.size()); ++i) {
        if (shared) {
          force.block(rows_m[static_cast<std::size_t>(i)], ifs, 1, ps) += share.row(i);
        } else {
          force(rows_m[static_cast<std::size_t>(i)], ifm + i) += 1.0;
        }
      }
    }
    // The master is pushed by -F_am; F_h* is constant about the equilibrium.
    plant_rows(ixm, master_plant, force, -1.0);
    if (pm > 0) {
      big_a.middleRows(ifm, pm) = -(a * a / t) * widen(em_live);
      big_a.block(ifm, ifm, pm, pm).diagonal().array() += r;
    }
  }
  if (with_slave) {
    Mat force = Mat::Zero(n, size);
    force.middleCols(ixs, n) = -(g.kps + ksvf);
    if (with_master) force.middleCols(src, n) += alpha * g.kps;
    if (ps > 0) {
      force += (a / t) * widen(es);
      for (int i = 0; i < ps; ++i) force(rows_s[static_cast<std::size_t>(i)], ifs + i) += 1.0;
    }
    plant_rows(ixs, slave_plant_, force, 1.0);
    if (ps > 0) {
      big_a.middleRows(ifs, ps) = -(a * a / t) * widen(es_live);
      big_a.block(ifs, ifs, ps, ps).diagonal().array() += r;
    }
  }
  for (int j = 0; j < delay; ++j) {
    const int from = j == 0 ? ixm : id0 + (j - 1) * n;
    big_a.block(id0 + j * n, from, n, n).setIdentity();
  }

  AxesBlock block;
  block.a = std::move(big_a);
  block.includes_master = with_master;
  block.master_position = ixm;
  block.slave_position = ixs;
  const int paper_states = (with_master ? 4 * n : 0) + (with_slave ? 4 * n : 0) + delay * n;
  block.structural_zeros = paper_states - size;
  return block;
}

}  // namespace teleop::stability
