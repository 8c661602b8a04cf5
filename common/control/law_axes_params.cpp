#include "common/control/law_axes_params.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

namespace teleop::control {
namespace {

const std::string kPrefix = "LawAxesParams.";

[[noreturn]] void fail(const std::string& field, const std::string& what) {
  throw std::invalid_argument(kPrefix + field + ": " + what);
}

void require(bool ok, const std::string& field, const std::string& what) {
  if (!ok) fail(field, what);
}

std::string indexed(const std::string& field, Eigen::Index i) {
  return field + "[" + std::to_string(i) + "]";
}

std::string indexed(const std::string& field, Eigen::Index i, Eigen::Index j) {
  return indexed(field, i) + "[" + std::to_string(j) + "]";
}

std::string axes_text(int n) { return std::to_string(n) + " (axes)"; }

void require_size(const AxisVector& v, int n, const std::string& field) {
  require(v.size() == n, field,
          "must have " + axes_text(n) + " entries, has " + std::to_string(v.size()));
}

void require_gain(const AxisMatrix& m, int n, const std::string& field) {
  require(m.rows() == n && m.cols() == n, field,
          "must be " + std::to_string(n) + " x " + std::to_string(n) + " (axes), is " +
              std::to_string(m.rows()) + " x " + std::to_string(m.cols()));
  for (Eigen::Index i = 0; i < n; ++i) {
    for (Eigen::Index j = 0; j < n; ++j) {
      require(std::isfinite(m(i, j)), indexed(field, i, j), "must be finite");
    }
  }
}

void require_planes(const PlaneSet& planes, int n, const std::string& field) {
  for (int k = 0; k < planes.size(); ++k) {
    const Plane& p = planes.plane(k);
    const std::string name = indexed(field, k);
    require_size(p.normal, n, name + ".normal");
    require(p.normal.allFinite(), name + ".normal", "must be finite");
    const double length = p.normal.norm();
    require(std::abs(length - 1.0) <= 1e-9, name + ".normal",
            "must have unit length, has " + std::to_string(length));
    require(std::isfinite(p.offset_m), name + ".offset_m", "must be finite");
    require(std::isfinite(p.stiffness_N_per_m) && p.stiffness_N_per_m >= 0.0,
            name + ".stiffness_N_per_m", "must be finite and >= 0");
  }
}

// A limit is a positive number or +infinity (no limit); NaN is never a limit.
void require_limits(const AxisVector& v, int n, const std::string& field) {
  require_size(v, n, field);
  for (Eigen::Index i = 0; i < n; ++i) {
    require(v(i) > 0.0, indexed(field, i), "must be > 0 (infinity for no limit)");
  }
}

void require_slave_limits(const SlaveLimitsAxes& l, int n) {
  require_size(l.min_position_m, n, "slave_limits.min_position_m");
  require_size(l.max_position_m, n, "slave_limits.max_position_m");
  for (Eigen::Index i = 0; i < n; ++i) {
    require(!std::isnan(l.min_position_m(i)), indexed("slave_limits.min_position_m", i),
            "must not be NaN");
    require(!std::isnan(l.max_position_m(i)), indexed("slave_limits.max_position_m", i),
            "must not be NaN");
    require(l.min_position_m(i) < l.max_position_m(i), indexed("slave_limits.max_position_m", i),
            "must be greater than " + indexed("slave_limits.min_position_m", i));
  }
  require_limits(l.max_velocity_m_per_s, n, "slave_limits.max_velocity_m_per_s");
  require_limits(l.max_force_N, n, "slave_limits.max_force_N");
}

AxisMatrix gain(const Eigen::MatrixXd& m, int n, const std::string& field) {
  require(m.rows() == n && m.cols() == n, field,
          "must be " + std::to_string(n) + " x " + std::to_string(n) + " (axes)");
  return m;
}

PlaneSet planes(const std::vector<PlaneFixtureParams>& in, int n, const std::string& field) {
  require(in.size() <= static_cast<std::size_t>(kMaxPlanes), field,
          "at most " + std::to_string(kMaxPlanes) + " planes, has " + std::to_string(in.size()));
  PlaneSet out;
  for (std::size_t k = 0; k < in.size(); ++k) {
    require(in[k].normal.size() == n, indexed(field, static_cast<Eigen::Index>(k)) + ".normal",
            "must have " + axes_text(n) + " entries");
    out.add({in[k].normal, in[k].offset_m, in[k].stiffness_N_per_m});
  }
  return out;
}

AxisVector filled(int axes, double value) { return AxisVector::Constant(axes, value); }

}  // namespace

ActuatorLimitsAxes no_actuator_limits(int axes) {
  return {filled(axes, kNoLimit), filled(axes, kNoLimit)};
}

SlaveLimitsAxes no_slave_limits(int axes) {
  return {filled(axes, -kNoLimit), filled(axes, kNoLimit), filled(axes, kNoLimit),
          filled(axes, kNoLimit)};
}

LawAxesParams from_teleop_axes_params(const TeleopAxesParams& params) {
  const int n = params.axes;
  require(n >= 1 && n <= kMaxAxes, "axes", "must be 1 to " + std::to_string(kMaxAxes));
  LawAxesParams out;
  out.axes = n;
  out.period_s = params.period_s();
  const GainsAxes& g = params.gains;
  out.gains = {gain(g.kpm, n, "gains.kpm"), gain(g.kps, n, "gains.kps"),
               gain(g.kdm, n, "gains.kdm"), gain(g.kds, n, "gains.kds"),
               gain(g.kvm, n, "gains.kvm"), gain(g.kvs, n, "gains.kvs"),
               gain(g.kfm, n, "gains.kfm")};
  out.scaling = params.scaling;
  out.master_planes = planes(params.master_planes, n, "master_planes");
  out.slave_planes = planes(params.slave_planes, n, "slave_planes");
  out.velocity_cutoff_hz = params.velocity_cutoff_hz;
  out.master_actuator = no_actuator_limits(n);
  out.slave_actuator = no_actuator_limits(n);
  out.slave_limits = no_slave_limits(n);
  return out;
}

LawAxesParams to_law_axes(const LawParams& p) {
  const auto scalar = [](double v) { return AxisMatrix::Constant(1, 1, v); };
  const auto one = [](double v) { return AxisVector::Constant(1, v); };
  LawAxesParams out;
  out.axes = 1;
  out.period_s = p.period_s;
  const Gains& g = p.gains;
  out.gains = {scalar(g.kpm), scalar(g.kps), scalar(g.kdm), scalar(g.kds),
               scalar(g.kvm), scalar(g.kvs), scalar(g.kfm)};
  out.scaling = p.scaling;
  out.master_planes.add(
      {one(1.0), p.master_fixture.position_m, p.master_fixture.stiffness_N_per_m});
  out.slave_planes.add({one(1.0), p.slave_fixture.position_m, p.slave_fixture.stiffness_N_per_m});
  out.velocity_cutoff_hz = p.velocity_cutoff_hz;
  out.master_actuator = {one(p.master_actuator.max_force_N),
                         one(p.master_actuator.max_rate_N_per_s)};
  out.slave_actuator = {one(p.slave_actuator.max_force_N), one(p.slave_actuator.max_rate_N_per_s)};
  const SlaveLimits& l = p.slave_limits;
  out.slave_limits = {one(l.min_position_m), one(l.max_position_m), one(l.max_velocity_m_per_s),
                      one(l.max_force_N)};
  out.clutch_fade_s = p.clutch_fade_s;
  return out;
}

void validate(const LawAxesParams& p) {
  const int n = p.axes;
  require(n >= 1 && n <= kMaxAxes, "axes", "must be 1 to " + std::to_string(kMaxAxes));
  require(std::isfinite(p.period_s) && p.period_s > 0.0, "period_s", "must be finite and > 0");
  const LawGainsAxes& g = p.gains;
  require_gain(g.kpm, n, "gains.kpm");
  require_gain(g.kps, n, "gains.kps");
  require_gain(g.kdm, n, "gains.kdm");
  require_gain(g.kds, n, "gains.kds");
  require_gain(g.kvm, n, "gains.kvm");
  require_gain(g.kvs, n, "gains.kvs");
  require_gain(g.kfm, n, "gains.kfm");
  require(std::isfinite(p.scaling.position) && p.scaling.position != 0.0, "scaling.position",
          "must be finite and non-zero");
  require(std::isfinite(p.scaling.force), "scaling.force", "must be finite");
  require_planes(p.master_planes, n, "master_planes");
  require_planes(p.slave_planes, n, "slave_planes");
  require(std::isfinite(p.velocity_cutoff_hz) && p.velocity_cutoff_hz >= 0.0, "velocity_cutoff_hz",
          "must be finite and >= 0");
  require_limits(p.master_actuator.max_force_N, n, "master_actuator.max_force_N");
  require_limits(p.master_actuator.max_rate_N_per_s, n, "master_actuator.max_rate_N_per_s");
  require_limits(p.slave_actuator.max_force_N, n, "slave_actuator.max_force_N");
  require_limits(p.slave_actuator.max_rate_N_per_s, n, "slave_actuator.max_rate_N_per_s");
  require_slave_limits(p.slave_limits, n);
  require(std::isfinite(p.clutch_fade_s) && p.clutch_fade_s >= 0.0, "clutch_fade_s",
          "must be finite and >= 0");
}

}  // namespace teleop::control
