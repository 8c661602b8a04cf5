#include "common/config/scene_loader.hpp"

#include <cmath>
#include <numbers>
#include <string>
#include <utility>
#include <vector>

#include "common/config/config_internal.hpp"
#include "common/config/simulated_sides.hpp"
#include "common/core/defaults.hpp"

namespace teleop::config {

namespace {

namespace v1 = teleop::v1;

scene::ForceDeviceSetup to_force_device(const LoadedConfig& config, bool ideal, std::uint64_t seed,
                                        SceneChecks& checks) {
  const ForceLoopParams fl = force_loop_params_of_validated(config);
  const v1::Scene& s = config.config.scene();
  const v1::ForceDeviceScene& f = s.force_device();
  scene::ForceDeviceSetup out;
  const double k_grip = f.has_grip_stiffness_n_per_m() ? f.grip_stiffness_n_per_m()
                                                       : defaults::kGripStiffness_N_per_m;
  const double b_grip =
      f.has_grip_damping_ns_per_m() ? f.grip_damping_ns_per_m() : defaults::kGripDamping_Ns_per_m;
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
  out.environment = {
      fl.environment_stiffness_N_per_m, fl.environment_damping_Ns_per_m,
      f.has_tissue_position_m() ? f.tissue_position_m() : defaults::kForceDeviceTissuePosition_m};
  fill_hardware(f.device(), "scene.force_device.device", ideal, seed, true, out.device,
                out.controller.limits, checks);
  return out;
}

}  // namespace

scene::SceneSetup to_scene_setup(const LoadedConfig& config) {
  validate(config);  // the one validation of a scene; what follows only reads
  const v1::SystemConfig& c = config.config;
  if (!c.has_scene() || !c.scene().has_duration_s()) {
    throw ConfigError(config.source_name +
                      ": missing section 'scene.duration_s' (needed to simulate a scene)");
  }
  const v1::Scene& s = c.scene();
  SceneChecks checks(config);
  check_scene_times(s, checks);
  scene::SceneSetup out;
  out.duration_s = s.duration_s();
  out.seed = s.seed();
  out.ideal = s.ideal();
  if (s.has_output_rate_hz()) out.output_rate_hz = s.output_rate_hz();
  if (s.has_force_device()) {
    out.force_device = to_force_device(config, out.ideal, out.seed, checks);
    checks.throw_if_any();
    return out;
  }

  // The paddles: the same sides a live node simulates (simulated_sides.hpp).
  out.teleop = teleop_params_of_validated(config);
  SimulatedSides sides = simulated_sides(config, out.teleop, SidesFor::kScene, checks);
  out.law = sides.law;
  out.master = std::move(sides.master);
  out.slave = std::move(sides.slave);
  if (s.has_equilibrium_perturbation_m()) {
    out.equilibrium_perturbation_m = s.equilibrium_perturbation_m();
    out.equilibrium_push_N = s.human_force().constant().force_n();
  }
  checks.throw_if_any();
  return out;
}

}  // namespace teleop::config
