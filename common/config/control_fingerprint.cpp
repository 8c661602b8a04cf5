#include "common/config/control_fingerprint.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <exception>
#include <string_view>

#include "common/config/node_loader.hpp"
#include "common/config/system_compiler.hpp"
#include "common/stability/analysis_axes.hpp"
#include "common/stability/analyzer.hpp"

namespace teleop::config {
namespace {

// The shortest text that reads back as the same double; -0 as 0 (equal values, one text).
std::string canonical(double v) {
  if (v == 0.0) return "0";
  if (std::isnan(v)) return "nan";
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof(buf), v);
  return std::string(buf, r.ptr);
}

class Fields {
 public:
  void add(std::string path, double v) { out_.push_back({std::move(path), canonical(v)}); }
  void add_int(std::string path, long long v) {
    out_.push_back({std::move(path), std::to_string(v)});
  }
  void add_text(std::string path, std::string v) {
    out_.push_back({std::move(path), std::move(v)});
  }
  void device(const std::string& side, const DeviceParams& d) {
    add(side + ".device.mass_kg", d.mass_kg);
    add(side + ".device.damping_Ns_per_m", d.damping_Ns_per_m);
  }
  void fixture(const std::string& side, const FixtureParams& f) {
    add(side + ".fixture.stiffness_N_per_m", f.stiffness_N_per_m);
    add(side + ".fixture.position_m", f.position_m);
  }
  void actuator(const std::string& side, const control::ActuatorLimits& a) {
    add(side + ".device.actuator.max_force_N", a.max_force_N);
    add(side + ".device.actuator.max_rate_N_per_s", a.max_rate_N_per_s);
  }
  void band(const std::string& path, const ParameterBand& b) {
    add(path + ".lower.intercept", b.lower.intercept);
    add(path + ".lower.slope_per_N", b.lower.slope_per_N);
    add(path + ".upper.intercept", b.upper.intercept);
    add(path + ".upper.slope_per_N", b.upper.slope_per_N);
  }
  std::vector<ControlField> take() { return std::move(out_); }

 private:
  std::vector<ControlField> out_{};
};

}  // namespace

std::vector<ControlField> control_fields(const TeleopParams& p, const node::NodeSettings& s,
                                         bool allow_unstable) {
  Fields f;
  f.add("sample_rate_hz", p.sample_rate_hz);
  f.device("master", p.master_device);
  f.device("slave", p.slave_device);
  f.fixture("master", p.master_fixture);
  f.fixture("slave", p.slave_fixture);
  const Gains& g = p.gains;
  f.add("gains.kpm", g.kpm);
  f.add("gains.kps", g.kps);
  f.add("gains.kdm", g.kdm);
  f.add("gains.kds", g.kds);
  f.add("gains.kvm", g.kvm);
  f.add("gains.kvs", g.kvs);
  f.add("gains.kfm", g.kfm);
  f.add("scaling.position", p.scaling.position);
  f.add("scaling.force", p.scaling.force);
  f.add("velocity_filter.cutoff_hz", p.velocity_cutoff_hz);
  f.add_int("round_trip_delay_samples", p.round_trip_delay_samples);
  switch (p.human.kind) {
    case HumanKind::kNone:
      f.add_text("human.none", "{}");
      break;
    case HumanKind::kFixed:
      f.add("human.fixed.mass_kg", p.human.fixed.mass_kg);
      f.add("human.fixed.damping_Ns_per_m", p.human.fixed.damping_Ns_per_m);
      f.add("human.fixed.stiffness_N_per_m", p.human.fixed.stiffness_N_per_m);
      break;
    case HumanKind::kBand: {
      const HumanBand& b = p.human.band;
      std::string levels;
      for (const double l : b.force_levels_N) levels += (levels.empty() ? "" : ",") + canonical(l);
      f.add_text("human.band.force_levels_N", levels);
      f.add_int("human.band.points_per_axis", b.points_per_axis);
      f.band("human.band.mass_kg", b.mass_kg);
      f.band("human.band.damping_Ns_per_m", b.damping_Ns_per_m);
      f.band("human.band.stiffness_N_per_m", b.stiffness_N_per_m);
      break;
    }
  }
  f.add("analysis.required_damping_ratio", p.analysis.required_damping_ratio);
  f.add("analysis.stiffness_tolerance_N_per_m", p.analysis.stiffness_tolerance_N_per_m);
  // What the running law clamps to (the analysis assumes none; the law does).
  f.actuator("master", s.law.master_actuator);
  f.actuator("slave", s.law.slave_actuator);
  f.add("slave.limits.min_position_m", s.law.slave_limits.min_position_m);
  f.add("slave.limits.max_position_m", s.law.slave_limits.max_position_m);
  f.add("slave.limits.max_velocity_m_per_s", s.law.slave_limits.max_velocity_m_per_s);
  f.add("slave.limits.max_force_N", s.law.slave_limits.max_force_N);
  // Link timing of the coupling, in integer nanoseconds as the node holds it.
  f.add_int("link.peer_timeout_ms", s.machine.peer_timeout.count());
  f.add_int("link.engage_ramp_ms", s.machine.engage_ramp.count());
  f.add_int("link.safe_ramp_ms", s.safe_ramp.count());
  f.add("link.alignment_tolerance_m", s.alignment.tolerance_m);
  f.add("link.centring_stiffness_N_per_m", s.alignment.centring_stiffness_N_per_m);
  f.add("link.centring_damping_Ns_per_m", s.alignment.centring_damping_Ns_per_m);
  f.add("link.centring_max_force_N", s.alignment.centring_max_force_N);
  f.add_text("experiment.allow_unstable", allow_unstable ? "true" : "false");
  return f.take();
}

std::vector<ControlField> control_fields(const LoadedConfig& config) {
  const CompiledSystem system = compile_system(config);
  return control_fields(system.teleop(), system.node(transport::Role::kMaster).settings,
                        system.allow_unstable());
}

std::uint64_t fingerprint(const std::vector<ControlField>& fields) {
  std::uint64_t h = 0xcbf29ce484222325ULL;
  auto mix = [&h](std::string_view s) {
    for (const char c : s) {
      h ^= static_cast<unsigned char>(c);
      h *= 0x100000001b3ULL;
    }
  };
  mix("teleop control fingerprint v1\n");
  for (const ControlField& f : fields) {
    mix(f.path);
    mix("=");
    mix(f.value);
    mix("\n");
  }
  return h == 0 ? 1 : h;
}

std::uint64_t control_fingerprint(const LoadedConfig& config) {
  return fingerprint(control_fields(config));
}

std::string fingerprint_hex(std::uint64_t fingerprint) {
  return fmt::format("{:016x}", fingerprint);
}

namespace {

// The verdict and damping ratio of the own analysis -> coupling permitted or refused, and why.
// NaN compares false: never "meets".
void conclude(ConfigurationCheck& c, double spectral_radius) {
  if (!std::isfinite(c.min_damping_ratio) || !std::isfinite(spectral_radius)) {
    c.verdict = "invalid";
  }
  const bool meets = c.verdict == "stable" && c.min_damping_ratio >= c.required_damping_ratio;
  c.permits_coupling = meets || c.allow_unstable;
  if (!c.permits_coupling) {
    c.refusal = fmt::format(
        "refused: the configuration's own analysis says {} (least damping ratio {:.4f}, "
        "required {:.4f}) at a round trip of {} sample{}; experiment {{ allow_unstable: true }} "
        "to run it anyway",
        c.verdict, c.min_damping_ratio, c.required_damping_ratio, c.round_trip_samples,
        c.round_trip_samples == 1 ? "" : "s");
  }
}

// The own analysis of `params` (one axis or n), at a round trip of at least one sample: two
// free-running loops add one. `analyse` returns the analyser's result (verdict, least damping
// ratio, spectral radius); a throw is an invalid configuration.
template <typename Params, typename Analyse>
ConfigurationCheck check_with(const Params& params, bool allow_unstable, Analyse analyse) {
  ConfigurationCheck c;
  c.allow_unstable = allow_unstable;
  c.required_damping_ratio = params.analysis.required_damping_ratio;
  Params p = params;
  p.round_trip_delay_samples = std::max(1, params.round_trip_delay_samples);
  c.round_trip_samples = p.round_trip_delay_samples;
  double radius = std::nan("");
  try {
    const auto r = analyse(p);
    c.verdict = std::string(stability::to_string(r.verdict));
    c.min_damping_ratio = r.min_damping_ratio;
    radius = r.spectral_radius;
  } catch (const std::exception&) {
    c.verdict = "invalid";
    c.min_damping_ratio = std::nan("");
  }
  conclude(c, radius);
  return c;
}

}  // namespace

ConfigurationCheck check_configuration(const TeleopParams& params, bool allow_unstable) {
  return check_with(params, allow_unstable,
                    [](const TeleopParams& p) { return stability::analyze(p); });
}

// Every plane active (the equilibrium in their corner), no plane limits: the verdict only.
ConfigurationCheck check_configuration_axes(const TeleopAxesParams& params, bool allow_unstable) {
  return check_with(params, allow_unstable,
                    [](const TeleopAxesParams& p) { return stability::analyze_axes(p); });
}

}  // namespace teleop::config
