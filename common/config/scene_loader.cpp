#include "common/config/scene_loader.hpp"

#include <cmath>
#include <limits>
#include <numbers>
#include <string>
#include <vector>

namespace teleop::config {

namespace {

namespace v1 = teleop::v1;

constexpr double kUnlimited = std::numeric_limits<double>::infinity();
// The paper's paddle hardware (Abbott-Okamura §4.1): 16-bit D/A at +-10 V, 1.65 N/V.
constexpr double kPaddleMaxForceN = 16.5;
constexpr double kPaddleLoadCellRangeN = 10.0;

class Checks {
 public:
  explicit Checks(const LoadedConfig& c) : config_(c) {}
  void positive(const std::string& path, double v) {
    if (!(v > 0.0)) add(path, "must be > 0, got " + std::to_string(v));
  }
  void non_negative(const std::string& path, double v) {
    if (!(v >= 0.0)) add(path, "must be >= 0, got " + std::to_string(v));
  }
  void add(const std::string& path, const std::string& message) {
    lines_.push_back(field_origin(config_, path) + ": " + path + ": " + message);
  }
  void throw_if_any() const {
    if (lines_.empty()) return;
    std::string text;
    for (const std::string& l : lines_) text += (text.empty() ? "" : "\n") + l;
    throw ConfigError(text);
  }

 private:
  const LoadedConfig& config_;
  std::vector<std::string> lines_;
};

sim::ForceProfile to_profile(const v1::ForceProfile& p, Checks& checks, const std::string& path) {
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

// Sensors and actuator of one simulated side; the analyser's assumptions when ideal.
void fill_hardware(const v1::Device& d, const std::string& path, bool ideal, std::uint64_t seed,
                   device::SimDeviceConfig& cfg, control::ActuatorLimits& limits, Checks& checks) {
  if (d.kind() == v1::USB) {
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
                                                        : kPaddleLoadCellRangeN;
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
  const double max_force = a.has_max_force_n() ? a.max_force_n() : kPaddleMaxForceN;
  cfg.amplifier.max_force_N = ideal ? 1e12 : max_force;
  limits.max_force_N = ideal ? kUnlimited : max_force;
  limits.max_rate_N_per_s =
      (ideal || !a.has_max_rate_n_per_s()) ? kUnlimited : a.max_rate_n_per_s();
}

sim::Environment to_environment(const v1::Scene& s, Checks& checks) {
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

scene::ForceDeviceSetup to_force_device(const LoadedConfig& config, bool ideal, std::uint64_t seed,
                                        Checks& checks) {
  const ForceLoopParams fl = to_force_loop_params(config);
  const v1::Scene& s = config.config.scene();
  const v1::ForceDeviceScene& f = s.force_device();
  scene::ForceDeviceSetup out;
  const double k_grip = f.has_grip_stiffness_n_per_m() ? f.grip_stiffness_n_per_m() : 2000.0;
  const double b_grip = f.has_grip_damping_ns_per_m() ? f.grip_damping_ns_per_m() : 20.0;
  checks.positive("scene.force_device.grip_stiffness_N_per_m", k_grip);
  checks.non_negative("scene.force_device.grip_damping_Ns_per_m", b_grip);
  // The hand moves the handle through a spring-damper grip: in the equilibrium-point model
  // the exogenous force is k x_hand + b x_hand' and the impedance is the grip's.
  sim::ForceProfile hand;
  sim::ForceProfile push;
  if (f.has_trace()) {
    const auto& t = f.trace();
    if (t.time_s_size() < 2 || t.time_s_size() != t.position_m_size()) {
      checks.add("scene.force_device.trace", "needs at least two (time_s, position_m) points");
    } else {
      std::vector<double> times(t.time_s().begin(), t.time_s().end());
      std::vector<double> pos(t.position_m().begin(), t.position_m().end());
      std::vector<double> ft;
      std::vector<double> fv;
      // Velocity is constant on each segment: the k x + b v profile steps at the knots (by a
      // microsecond-wide ramp, the trace being piecewise linear).
      constexpr double kStep = 1e-6;
      for (std::size_t i = 0; i + 1 < times.size(); ++i) {
        const double dt = times[i + 1] - times[i];
        if (!(dt > 2 * kStep)) {
          checks.add("scene.force_device.trace.time_s", "must increase by more than 2 us");
          break;
        }
        const double v = (pos[i + 1] - pos[i]) / dt;
        ft.push_back(times[i] + (i == 0 ? 0.0 : kStep));
        fv.push_back(k_grip * pos[i] + b_grip * v);
        ft.push_back(times[i + 1] - kStep);
        fv.push_back(k_grip * (pos[i + 1] - v * kStep) + b_grip * v);
      }
      ft.push_back(times.back() + kStep);
      fv.push_back(k_grip * pos.back());
      hand = sim::ForceProfile::trace(times, pos);
      push = sim::ForceProfile::trace(ft, fv);
    }
  } else {
    const v1::PositionSinusoid& p = f.sinusoid();
    const double w = 2.0 * std::numbers::pi * p.frequency_hz();
    hand =
        sim::ForceProfile::sinusoid(p.offset_m(), p.amplitude_m(), p.frequency_hz(), p.phase_rad());
    // k (o + A sin(wt + f)) + b A w cos(wt + f) = k o + A sqrt(k^2 + (b w)^2)
    // sin(wt + f + atan2(b w, k)).
    push = sim::ForceProfile::sinusoid(
        k_grip * p.offset_m(), p.amplitude_m() * std::hypot(k_grip, b_grip * w), p.frequency_hz(),
        p.phase_rad() + std::atan2(b_grip * w, k_grip));
  }
  out.hand_position_m = hand;
  out.device.plant.device = {fl.mass_kg, fl.damping_Ns_per_m};
  sim::HumanParams grip;
  grip.profile = push;
  grip.impedance = {0.0, b_grip, k_grip};
  grip.sampling = sim::ProfileSampling::kFirstOrderHold;
  out.device.human = grip;
  out.controller = control::from_force_loop_params(fl);
  out.environment = {fl.environment_stiffness_N_per_m, fl.environment_damping_Ns_per_m,
                     f.has_tissue_position_m() ? f.tissue_position_m() : 0.03};
  fill_hardware(f.device(), "scene.force_device.device", ideal, seed, out.device,
                out.controller.limits, checks);
  return out;
}

}  // namespace

scene::SceneSetup to_scene_setup(const LoadedConfig& config) {
  validate(config);
  const v1::SystemConfig& c = config.config;
  if (!c.has_scene() || !c.scene().has_duration_s()) {
    throw ConfigError(config.source_name +
                      ": missing section 'scene.duration_s' (needed to simulate a scene)");
  }
  const v1::Scene& s = c.scene();
  Checks checks(config);
  checks.positive("scene.duration_s", s.duration_s());
  scene::SceneSetup out;
  out.duration_s = s.duration_s();
  out.seed = s.seed();
  out.ideal = s.ideal();
  if (s.has_output_rate_hz()) {
    checks.positive("scene.output_rate_hz", s.output_rate_hz());
    out.output_rate_hz = s.output_rate_hz();
  }
  if (s.has_force_device()) {
    out.force_device = to_force_device(config, out.ideal, out.seed, checks);
    checks.throw_if_any();
    return out;
  }

  out.teleop = to_teleop_params(config);
  out.law = control::from_teleop_params(out.teleop);
  out.master.plant.device = out.teleop.master_device;
  out.slave.plant.device = out.teleop.slave_device;
  fill_hardware(c.master().device(), "master.device", out.ideal, out.seed, out.master,
                out.law.master_actuator, checks);
  fill_hardware(c.slave().device(), "slave.device", out.ideal, out.seed + 1, out.slave,
                out.law.slave_actuator, checks);
  out.slave.plant.environment = to_environment(s, checks);
  // The analyser's assumptions have no limits either.
  if (c.slave().has_limits() && !out.ideal) {
    const v1::Limits& l = c.slave().limits();
    if (l.has_min_position_m()) out.law.slave_limits.min_position_m = l.min_position_m();
    if (l.has_max_position_m()) out.law.slave_limits.max_position_m = l.max_position_m();
    if (l.has_max_velocity_m_per_s()) {
      checks.positive("slave.limits.max_velocity_m_per_s", l.max_velocity_m_per_s());
      out.law.slave_limits.max_velocity_m_per_s = l.max_velocity_m_per_s();
    }
    if (l.has_max_force_n()) {
      checks.positive("slave.limits.max_force_N", l.max_force_n());
      out.law.slave_limits.max_force_N = l.max_force_n();
    }
  }

  sim::HumanParams human;
  human.profile = s.has_human_force() ? to_profile(s.human_force(), checks, "scene.human_force")
                                      : sim::ForceProfile::constant(0.0);
  switch (out.teleop.human.kind) {
    case HumanKind::kFixed:
      human.impedance = out.teleop.human.fixed;
      break;
    case HumanKind::kNone:
      break;
    case HumanKind::kBand:
      if (!s.has_malicious_user()) {
        checks.add("human",
                   "a band of humans needs scene.malicious_user to simulate (or give "
                   "human.fixed)");
      } else {
        const double dwell = s.malicious_user().has_dwell_s() ? s.malicious_user().dwell_s() : 1.0;
        checks.positive("scene.malicious_user.dwell_s", dwell);
        checks.non_negative("scene.malicious_user.force_level_N",
                            s.malicious_user().force_level_n());
        human.malicious = sim::MaliciousUserParams{out.teleop.human.band,
                                                   s.malicious_user().force_level_n(), dwell};
      }
      break;
  }
  out.master.human = human;

  if (s.has_equilibrium_perturbation_m()) {
    if (!s.human_force().has_constant()) {
      checks.add("scene.equilibrium_perturbation_m",
                 "an equilibrium start needs a constant scene.human_force");
    }
    // The equilibrium is solved for the loop alone: free space, a fixed (or no) human.
    if (s.has_environment() && !s.environment().has_free()) {
      checks.add("scene.equilibrium_perturbation_m",
                 "an equilibrium start needs the slave in free space (scene.environment)");
    }
    if (out.teleop.human.kind == HumanKind::kBand) {
      checks.add("scene.equilibrium_perturbation_m",
                 "an equilibrium start needs human.fixed (or human.none)");
    }
    out.equilibrium_perturbation_m = s.equilibrium_perturbation_m();
    out.equilibrium_push_N = s.human_force().constant().force_n();
  }
  checks.throw_if_any();
  return out;
}

}  // namespace teleop::config
