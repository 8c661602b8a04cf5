#include "common/config/axes_scene_loader.hpp"

#include <cmath>
#include <string>
#include <vector>

#include "common/config/axes_config.hpp"
#include "common/config/config_internal.hpp"
#include "common/config/simulated_sides.hpp"
#include "common/config/text_format.hpp"
#include "common/sim/plant_axes.hpp"

namespace teleop::config {

namespace {

namespace v1 = teleop::v1;
using Values = google::protobuf::RepeatedField<double>;

// The plane's stiffness and offset bounds of Fixture.plane, for the environment's planes.
constexpr double kMaxPlaneStiffness_N_per_m = 1e7;
constexpr double kMaxPlaneOffset_m = 10.0;

// A direction of n values: finite, not all 0, normalised. Empty (and a problem) otherwise;
// `what`: what needs the direction ("the push", "a plane").
Eigen::VectorXd direction_of(text_format::Problems& problems, const std::string& path,
                             const Values& values, int n, const std::string& what) {
  if (values.size() != n) {
    problems.add(path, "must have " + std::to_string(n) + " values (one per axis, axes: " +
                           std::to_string(n) + "), got " + std::to_string(values.size()));
    return {};
  }
  Eigen::VectorXd v(n);
  for (int i = 0; i < n; ++i) {
    if (!std::isfinite(values[i])) {
      problems.add(path, "element [" + std::to_string(i) + "] is not a finite number");
      return {};
    }
    v(i) = values[i];
  }
  Eigen::VectorXd unit = unit_direction(v);  // exact also for subnormal elements
  if (unit.size() == 0) problems.add(path, "must not be zero (" + what + " needs a direction)");
  return unit;
}

struct SceneAxes {
  Eigen::VectorXd push_direction{};
  std::vector<sim::ContactPlane> environment{};
};

// Every rule on the scene's n-axis fields, and the one-axis scene fields an n-axis scene
// refuses.
SceneAxes read_scene_axes(text_format::Problems& problems, const v1::Scene& s, int n) {
  SceneAxes out;
  if (!s.human_force_direction().empty()) {
    out.push_direction = direction_of(problems, "scene.human_force_direction",
                                      s.human_force_direction(), n, "the push");
  } else if (s.has_human_force()) {
    problems.add("scene.human_force_direction",
                 "required with scene.human_force when axes > 1: the push's direction, " +
                     std::to_string(n) + " values");
  }
  if (s.environment_plane_size() > sim::kMaxContactPlanes) {
    problems.add("scene.environment_plane", "at most " + std::to_string(sim::kMaxContactPlanes) +
                                                " planes, got " +
                                                std::to_string(s.environment_plane_size()));
  }
  for (int i = 0; i < s.environment_plane_size(); ++i) {
    const v1::Plane& p = s.environment_plane(i);
    const std::string path = "scene.environment_plane[" + std::to_string(i) + "].";
    const Eigen::VectorXd normal =
        direction_of(problems, path + "normal", p.normal(), n, "a plane");
    const double k = p.stiffness_n_per_m();
    if (!(k > 0.0 && k <= kMaxPlaneStiffness_N_per_m)) {
      problems.add(path + "stiffness_N_per_m",
                   "must be in (0, 1e7] N/m, got " + text_format::format_float(k));
    }
    if (!(std::abs(p.offset_m()) <= kMaxPlaneOffset_m)) {
      problems.add(path + "offset_m",
                   "must be in [-10, 10] m, got " + text_format::format_float(p.offset_m()));
    }
    if (normal.size() == n) out.environment.push_back({normal, p.offset_m(), k, 0.0});
  }
  const std::string why = " with axes: " + std::to_string(n) + " (the n-axis simulator has ";
  if (s.has_environment()) {
    problems.add("scene.environment", "the one-axis environment; with axes: " + std::to_string(n) +
                                          " give the slave's planes as scene.environment_plane");
  }
  if (s.seed() != 0) {
    problems.add("scene.seed", "no random source" + why + "ideal sensors)");
  }
  if (s.has_malicious_user()) {
    problems.add("scene.malicious_user", "not simulated" + why + "one fixed human)");
  }
  if (s.has_force_device()) {
    problems.add("scene.force_device", "a one-axis device scene; not simulated" + why +
                                           "the bilateral teleoperator only)");
  }
  return out;
}

}  // namespace

void check_scene_axes(const LoadedConfig& config, text_format::Problems& problems) {
  const int n = configured_axes(config.config);
  if (n < 2 || n > kMaxAxes || !config.config.has_scene()) return;
  (void)read_scene_axes(problems, config.config.scene(), n);
}

scene::AxesSceneSetup to_axes_scene_setup(const LoadedConfig& config) {
  const AxesConfig axes = to_axes_config(config);  // validates, once
  const v1::SystemConfig& c = config.config;
  if (!c.has_scene() || !c.scene().has_duration_s()) {
    throw ConfigError(config.source_name +
                      ": missing section 'scene.duration_s' (needed to simulate a scene)");
  }
  const v1::Scene& s = c.scene();
  const int n = axes.teleop.axes;
  text_format::Problems problems(config);
  SceneAxes fields = read_scene_axes(problems, s, n);
  problems.throw_if_any();  // validate() has seen these: none here

  SceneChecks checks(config);
  check_scene_times(s, checks);
  scene::AxesSceneSetup out;
  out.teleop = axes.teleop;
  out.duration_s = s.duration_s();
  if (s.has_output_rate_hz()) out.output_rate_hz = s.output_rate_hz();
  if (out.teleop.human.kind == HumanKind::kBand) {
    checks.add("human",
               "a band of humans cannot be simulated with several axes: give human.fixed (every "
               "axis) or human.none");
  }
  // No push: any direction (the profile is 0).
  out.push_direction =
      fields.push_direction.size() == n ? fields.push_direction : Eigen::VectorXd::Unit(n, 0);
  out.push_profile = s.has_human_force()
                         ? scene_force_profile(s.human_force(), checks, "scene.human_force")
                         : sim::ForceProfile::constant(0.0);
  out.slave_environment = std::move(fields.environment);
  if (s.has_equilibrium_perturbation_m()) {
    if (!s.human_force().has_constant()) {
      checks.add("scene.equilibrium_perturbation_m",
                 "an equilibrium start needs a constant scene.human_force");
    }
    out.equilibrium_perturbation_m = s.equilibrium_perturbation_m() * out.push_direction;
  }
  checks.throw_if_any();
  return out;
}

}  // namespace teleop::config
