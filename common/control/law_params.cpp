#include "common/control/law_params.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

namespace teleop::control {
namespace {

void require(bool ok, const char* field, const char* what) {
  if (!ok) throw std::invalid_argument(std::string("LawParams.") + field + ": " + what);
}

void require_finite(double value, const char* field) {
  require(std::isfinite(value), field, "must be finite");
}

// A limit is a positive number or +infinity (no limit); NaN is never a limit.
void require_limit(double value, const char* field) {
  require(value > 0.0, field, "must be > 0 (infinity for no limit)");
}

}  // namespace

LawParams from_teleop_params(const TeleopParams& params) {
  LawParams out;
  out.period_s = params.period_s();
  out.gains = params.gains;
  out.scaling = params.scaling;
  out.master_fixture = params.master_fixture;
  out.slave_fixture = params.slave_fixture;
  out.velocity_cutoff_hz = params.velocity_cutoff_hz;
  return out;
}

void validate(const LawParams& p) {
  require(std::isfinite(p.period_s) && p.period_s > 0.0, "period_s", "must be finite and > 0");
  const Gains& g = p.gains;
  require_finite(g.kpm, "gains.kpm");
  require_finite(g.kps, "gains.kps");
  require_finite(g.kdm, "gains.kdm");
  require_finite(g.kds, "gains.kds");
  require_finite(g.kvm, "gains.kvm");
  require_finite(g.kvs, "gains.kvs");
  require_finite(g.kfm, "gains.kfm");
  require(std::isfinite(p.scaling.position) && p.scaling.position != 0.0, "scaling.position",
          "must be finite and non-zero");
  require_finite(p.scaling.force, "scaling.force");
  require(std::isfinite(p.master_fixture.stiffness_N_per_m) &&
              p.master_fixture.stiffness_N_per_m >= 0.0,
          "master_fixture.stiffness_N_per_m", "must be finite and >= 0");
  require_finite(p.master_fixture.position_m, "master_fixture.position_m");
  require(
      std::isfinite(p.slave_fixture.stiffness_N_per_m) && p.slave_fixture.stiffness_N_per_m >= 0.0,
      "slave_fixture.stiffness_N_per_m", "must be finite and >= 0");
  require_finite(p.slave_fixture.position_m, "slave_fixture.position_m");
  require(std::isfinite(p.velocity_cutoff_hz) && p.velocity_cutoff_hz >= 0.0, "velocity_cutoff_hz",
          "must be finite and >= 0");
  require_limit(p.master_actuator.max_force_N, "master_actuator.max_force_N");
  require_limit(p.master_actuator.max_rate_N_per_s, "master_actuator.max_rate_N_per_s");
  require_limit(p.slave_actuator.max_force_N, "slave_actuator.max_force_N");
  require_limit(p.slave_actuator.max_rate_N_per_s, "slave_actuator.max_rate_N_per_s");
  const SlaveLimits& l = p.slave_limits;
  require(!std::isnan(l.min_position_m), "slave_limits.min_position_m", "must not be NaN");
  require(!std::isnan(l.max_position_m), "slave_limits.max_position_m", "must not be NaN");
  require(l.min_position_m < l.max_position_m, "slave_limits.max_position_m",
          "must be greater than slave_limits.min_position_m");
  require_limit(l.max_velocity_m_per_s, "slave_limits.max_velocity_m_per_s");
  require_limit(l.max_force_N, "slave_limits.max_force_N");
  require(std::isfinite(p.clutch_fade_s) && p.clutch_fade_s >= 0.0, "clutch_fade_s",
          "must be finite and >= 0");
}

}  // namespace teleop::control
