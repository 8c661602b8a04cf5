#include "common/config/simulated_sides.hpp"

#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "common/core/defaults.hpp"

namespace teleop::config {

namespace {

namespace v1 = teleop::v1;

constexpr double kUnlimited = std::numeric_limits<double>::infinity();

sim::ForceProfile to_profile(const v1::ForceProfile& p, SceneChecks& checks,
                             const std::string& path) {
  switch (p.kind_case()) {
    case v1::ForceProfile::kConstant:
      return sim::ForceProfile::constant(p.constant().force_n());
    case v1::ForceProfile::kRamp:
      checks.non_negative(path + ".ramp.duration_s", p.ramp().duration_s());
      return sim::ForceProfile::ramp(p.ramp().from_n(), p.ramp().to_n(), p.ramp().start_s(),
                                     p.ramp().duration_s());
    case v1::ForceProfile::kSinusoid:
      checks.non_negative(path + ".sinusoid.frequency_hz", p.sinusoid().frequency_hz());
      return sim::ForceProfile::sinusoid(p.sinusoid().offset_n(), p.sinusoid().amplitude_n(),
                                         p.sinusoid().frequency_hz(), p.sinusoid().phase_rad());
    case v1::ForceProfile::kTrace: {
      const auto& t = p.trace();
      std::vector<double> times(t.time_s().begin(), t.time_s().end());
      std::vector<double> values(t.force_n().begin(), t.force_n().end());
      if (times.empty() || times.size() != values.size()) {
        checks.add(path + ".trace", "needs as many time_s as force_N values, at least one");
        return sim::ForceProfile::constant(0.0);
      }
      for (std::size_t i = 1; i < times.size(); ++i) {
        if (!(times[i] > times[i - 1])) {
          checks.add(path + ".trace.time_s", "must be strictly increasing");
          return sim::ForceProfile::constant(0.0);
        }
      }
      return sim::ForceProfile::trace(std::move(times), std::move(values));
    }
    case v1::ForceProfile::KIND_NOT_SET:
      break;
  }
  return sim::ForceProfile::constant(0.0);
}

sim::Environment to_environment(const v1::Scene& s, SceneChecks& checks) {
  if (!s.has_environment()) return sim::Environment::free_space();
  const v1::Environment& e = s.environment();
  switch (e.kind_case()) {
    case v1::Environment::kTissue:
      checks.positive("scene.environment.tissue.stiffness_N_per_m", e.tissue().stiffness_n_per_m());
      checks.non_negative("scene.environment.tissue.damping_Ns_per_m",
                          e.tissue().damping_ns_per_m());
      return sim::Environment::tissue(e.tissue().stiffness_n_per_m(), e.tissue().damping_ns_per_m(),
                                      e.tissue().position_m());
    case v1::Environment::kWall:
      return sim::Environment::rigid_wall(e.wall().position_m());
    case v1::Environment::kFree:
    case v1::Environment::KIND_NOT_SET:
      break;
  }
  return sim::Environment::free_space();
}

// The slave's workspace limits (slave.limits); the analyser's assumptions have none.
void slave_limits(const v1::SystemConfig& c, bool ideal, control::SlaveLimits& out,
                  SceneChecks& checks) {
  if (!c.slave().has_limits() || ideal) return;
  const v1::Limits& l = c.slave().limits();
  if (l.has_min_position_m()) out.min_position_m = l.min_position_m();
  if (l.has_max_position_m()) out.max_position_m = l.max_position_m();
  if (l.has_max_velocity_m_per_s()) {
    checks.positive("slave.limits.max_velocity_m_per_s", l.max_velocity_m_per_s());
    out.max_velocity_m_per_s = l.max_velocity_m_per_s();
  }
  if (l.has_max_force_n()) {
    checks.positive("slave.limits.max_force_N", l.max_force_n());
    out.max_force_N = l.max_force_n();
  }
}

// The human a node's simulated master holds: a band of humans (without a malicious user to
// walk it) is the band's middle at its lowest force level.
HumanModel node_human(const HumanModel& configured, const v1::Scene& s) {
  if (configured.kind != HumanKind::kBand || s.has_malicious_user()) return configured;
  const HumanBand& band = configured.band;
  const double f = band.force_levels_N.empty() ? 0.0 : band.force_levels_N.front();
  auto mid = [f](const ParameterBand& b) { return 0.5 * (b.lower.at(f) + b.upper.at(f)); };
  HumanModel fixed;
  fixed.kind = HumanKind::kFixed;
  fixed.fixed = {mid(band.mass_kg), mid(band.damping_Ns_per_m), mid(band.stiffness_N_per_m)};
  return fixed;
}

sim::HumanParams to_human(const HumanModel& model, const v1::Scene& s, SceneChecks& checks) {
  sim::HumanParams human;
  human.profile = s.has_human_force() ? to_profile(s.human_force(), checks, "scene.human_force")
                                      : sim::ForceProfile::constant(0.0);
  switch (model.kind) {
    case HumanKind::kFixed:
      human.impedance = model.fixed;
      break;
    case HumanKind::kNone:
      break;
    case HumanKind::kBand:
      if (!s.has_malicious_user()) {
        checks.add("human",
                   "a band of humans needs scene.malicious_user to simulate (or give "
                   "human.fixed)");
      } else {
        const double dwell = s.malicious_user().has_dwell_s() ? s.malicious_user().dwell_s()
                                                              : defaults::kMaliciousDwell_s;
        checks.positive("scene.malicious_user.dwell_s", dwell);
        checks.non_negative("scene.malicious_user.force_level_N",
                            s.malicious_user().force_level_n());
        human.malicious =
            sim::MaliciousUserParams{model.band, s.malicious_user().force_level_n(), dwell};
      }
      break;
  }
  return human;
}

// An equilibrium start (scene.equilibrium_perturbation_m) is solved for the loop alone.
void check_equilibrium(const v1::Scene& s, HumanKind human, SceneChecks& checks) {
  if (!s.has_equilibrium_perturbation_m()) return;
  if (!s.human_force().has_constant()) {
    checks.add("scene.equilibrium_perturbation_m",
               "an equilibrium start needs a constant scene.human_force");
  }
  // Free space, a fixed (or no) human.
  if (s.has_environment() && !s.environment().has_free()) {
    checks.add("scene.equilibrium_perturbation_m",
               "an equilibrium start needs the slave in free space (scene.environment)");
  }
  if (human == HumanKind::kBand) {
    checks.add("scene.equilibrium_perturbation_m",
               "an equilibrium start needs human.fixed (or human.none)");
  }
}

}  // namespace

sim::ForceProfile scene_force_profile(const v1::ForceProfile& profile, SceneChecks& checks,
                                      const std::string& path) {
  return to_profile(profile, checks, path);
}

void SceneChecks::positive(const std::string& path, double v) {
  if (!(v > 0.0)) add(path, "must be > 0, got " + std::to_string(v));
}

void SceneChecks::non_negative(const std::string& path, double v) {
  if (!(v >= 0.0)) add(path, "must be >= 0, got " + std::to_string(v));
}

void SceneChecks::add(const std::string& path, const std::string& message) {
  lines_.push_back(field_origin(config_, path) + ": " + path + ": " + message);
}

void SceneChecks::throw_if_any() const {
  if (lines_.empty()) return;
  std::string text;
  for (const std::string& l : lines_) text += (text.empty() ? "" : "\n") + l;
  throw ConfigError(text);
}

void check_scene_times(const v1::Scene& s, SceneChecks& checks) {
  if (s.has_duration_s()) checks.positive("scene.duration_s", s.duration_s());
  if (s.has_output_rate_hz()) checks.positive("scene.output_rate_hz", s.output_rate_hz());
}

void fill_hardware(const v1::Device& d, const std::string& path, bool ideal, std::uint64_t seed,
                   bool check_kind, device::SimDeviceConfig& cfg, control::ActuatorLimits& limits,
                   SceneChecks& checks) {
  if (check_kind && d.kind() == v1::USB) {
    checks.add(path + ".kind", "a scene runs on simulated devices: use SIM (or leave it out)");
  }
  cfg.seed = seed;
  checks.non_negative(path + ".coulomb_friction_N", d.coulomb_friction_n());
  cfg.plant.coulomb_friction_N = ideal ? 0.0 : d.coulomb_friction_n();
  if (d.has_encoder()) {
    const v1::Encoder& e = d.encoder();
    if (e.has_counts_per_rev()) {
      if (e.counts_per_rev() <= 0) checks.add(path + ".encoder.counts_per_rev", "must be > 0");
      cfg.encoder.counts_per_rev = e.counts_per_rev();
    }
    if (e.has_transmission_ratio()) {
      checks.positive(path + ".encoder.transmission_ratio", e.transmission_ratio());
      cfg.encoder.transmission_ratio = e.transmission_ratio();
    }
    if (e.has_metres_per_radian()) {
      checks.positive(path + ".encoder.metres_per_radian", e.metres_per_radian());
      cfg.encoder.metres_per_radian = e.metres_per_radian();
    }
  }
  cfg.quantize_position = !ideal;
  checks.non_negative(path + ".load_cell.noise_std_N", d.load_cell().noise_std_n());
  cfg.load_cell.noise_std_N = ideal ? 0.0 : d.load_cell().noise_std_n();
  cfg.load_cell.bias_N = ideal ? 0.0 : d.load_cell().bias_n();
  if (d.load_cell().has_range_n())
    checks.positive(path + ".load_cell.range_N", d.load_cell().range_n());
  cfg.load_cell.range_N = ideal                         ? 1e12
                          : d.load_cell().has_range_n() ? d.load_cell().range_n()
                                                        : defaults::kPaddleLoadCellRange_N;
  if (d.has_estop()) {
    const v1::EStopSchedule& e = d.estop();
    if (!e.has_press_at_s()) {
      checks.add(path + ".estop.press_at_s", "is required when estop is given");
    } else {
      checks.non_negative(path + ".estop.press_at_s", e.press_at_s());
      cfg.estop_press_at_s = e.press_at_s();
    }
    if (e.has_release_at_s()) {
      if (!(e.release_at_s() > e.press_at_s())) {
        checks.add(path + ".estop.release_at_s", "must be after press_at_s");
      }
      cfg.estop_release_at_s = e.release_at_s();
    }
  }
  const v1::Actuator& a = d.actuator();
  if (a.has_max_force_n()) checks.positive(path + ".actuator.max_force_N", a.max_force_n());
  if (a.has_max_rate_n_per_s()) {
    checks.positive(path + ".actuator.max_rate_N_per_s", a.max_rate_n_per_s());
  }
  const double max_force = a.has_max_force_n() ? a.max_force_n() : defaults::kPaddleMaxForce_N;
  cfg.amplifier.max_force_N = ideal ? 1e12 : max_force;
  limits.max_force_N = ideal ? kUnlimited : max_force;
  limits.max_rate_N_per_s =
      (ideal || !a.has_max_rate_n_per_s()) ? kUnlimited : a.max_rate_n_per_s();
}

SimulatedSides simulated_sides(const LoadedConfig& config, const TeleopParams& teleop,
                               SidesFor purpose, SceneChecks& checks) {
  const v1::SystemConfig& c = config.config;
  const v1::Scene& s = c.scene();  // the empty scene when absent: no push, free space
  const bool scene = purpose == SidesFor::kScene;
  SimulatedSides out;
  out.law = control::from_teleop_params(teleop);
  out.master.plant.device = teleop.master_device;
  out.slave.plant.device = teleop.slave_device;
  fill_hardware(c.master().device(), "master.device", s.ideal(), s.seed(), scene, out.master,
                out.law.master_actuator, checks);
  fill_hardware(c.slave().device(), "slave.device", s.ideal(), s.seed() + 1, scene, out.slave,
                out.law.slave_actuator, checks);
  out.slave.plant.environment = to_environment(s, checks);
  slave_limits(c, s.ideal(), out.law.slave_limits, checks);
  const HumanModel human = scene ? teleop.human : node_human(teleop.human, s);
  out.master.human = to_human(human, s, checks);
  check_equilibrium(s, human.kind, checks);
  return out;
}

}  // namespace teleop::config
