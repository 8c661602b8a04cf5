#include "common/config/config_loader.hpp"

#include <google/protobuf/descriptor.h>
#include <google/protobuf/message.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <sstream>
#include <system_error>

#include "common/config/config_internal.hpp"
#include "common/config/parameter_space.hpp"
#include "common/config/text_format.hpp"
#include "common/core/defaults.hpp"

namespace teleop::config {
namespace {

namespace pb = google::protobuf;
using text_format::format_float;
using text_format::Problems;

constexpr int kMaxDelaySamples = 1000;
constexpr int kMaxPointsPerAxis = 100;
constexpr int kMaxForceLevels = 100;
// The humans a band holds (force levels x points_per_axis^3), each analysed at start, on every
// guarded change and by `analyze`: about 30 us each for one axis (docs/benchmarks.md), so the
// converged fine grid of docs/benchmarks.md (19 x 12^3 = 32 832) fits, in about a second, and
// 100 levels x 100^3 (days of analysis) does not.
constexpr long kMaxBandHumans = 40'000;

// How many times validate() ran (validation_count()).
std::atomic<std::uint64_t> validations{0};

// ---------------------------------------------------------------------------------------------
// Validation

// The elements of one repeated field named one by one up to kElementsNamed; the rest counted in
// one line (a million NaN in a list, or a thousand planes with a NaN each, is a short error).
constexpr int kElementsNamed = 3;

// "a.plane[12].normal[1]" -> "a.plane[].normal[]": the elements alike.
std::string without_indices(std::string_view path) {
  std::string out;
  bool in_index = false;
  for (const char c : path) {
    if (c == ']') in_index = false;
    if (!in_index) out += c;
    if (c == '[') in_index = true;
  }
  return out;
}

// Every numeric value anywhere in the configuration, by the one parameter space
// (parameter_space.hpp): finite, and the sign and range config.proto documents for the field.
void check_fields(const pb::Message& message, Problems& problems) {
  struct Alike {
    std::string key;
    std::string first_counted;  // the first element not named (where the count points)
    int count{0};
  };
  std::vector<Alike> alike;
  for (const FieldProblem& p : teleop::config::check_fields(message)) {
    const std::string key = without_indices(p.path);
    auto it =
        std::find_if(alike.begin(), alike.end(), [&](const Alike& a) { return a.key == key; });
    if (it == alike.end()) it = alike.insert(alike.end(), {key, "", 0});
    if (++it->count <= kElementsNamed || key == p.path) {
      problems.add(p.path, p.message);
    } else if (it->first_counted.empty()) {
      it->first_counted = p.path;
    }
  }
  for (const Alike& a : alike) {
    if (a.first_counted.empty()) continue;
    problems.add(a.first_counted, "and " + std::to_string(a.count - kElementsNamed) +
                                      " more elements like these (" + a.key + ")");
  }
}

// Endpoints: each well formed (tcp ports 1-65535), and every bound one distinct from the others.
void check_endpoints(const teleop::v1::SystemConfig& c, Problems& problems) {
  const std::vector<BoundEndpoint> bound = bound_endpoints(c);
  for (const BoundEndpoint& e : bound) {
    if (e.defaulted) continue;
    if (const std::string why = check_endpoint(e.endpoint); !why.empty()) {
      problems.add(e.path, why);
    }
  }
  for (const char* side : {"master", "slave"}) {
    const teleop::v1::Node& node =
        std::string_view(side) == "master" ? c.master().node() : c.slave().node();
    if (node.peer_state_endpoint().empty()) continue;
    if (const std::string why = check_endpoint(node.peer_state_endpoint()); !why.empty()) {
      problems.add(std::string(side) + ".node.peer_state_endpoint", why);
    }
  }
  for (std::size_t i = 0; i < bound.size(); ++i) {
    for (std::size_t j = 0; j < i; ++j) {
      if (!endpoints_clash(bound[i].endpoint, bound[j].endpoint)) continue;
      // Name the one written by the user (a default clashing with a written one).
      const BoundEndpoint& named = bound[i].defaulted && !bound[j].defaulted ? bound[j] : bound[i];
      const BoundEndpoint& other = &named == &bound[i] ? bound[j] : bound[i];
      problems.add(named.path, "\"" + named.endpoint + "\" is also " + other.path +
                                   (other.defaulted ? " (its default)" : "") +
                                   ": every bound endpoint must be distinct");
    }
  }
}

// Signs and ranges of single fields are check_fields' (the parameter space); what follows are
// the rules that involve presence or more than one field.
void require_present(Problems& problems, std::string_view path, bool present,
                     std::string_view why) {
  if (!present) problems.add(path, "missing (" + std::string(why) + ")");
}

void check_device(Problems& problems, const std::string& side, const teleop::v1::Side& config) {
  if (config.has_device()) {
    const std::string prefix = side + ".device.";
    require_present(problems, prefix + "mass_kg",
                    config.device().has_mass_kg() || !config.device().mass_matrix_kg().empty(),
                    "a device needs its mass (or mass_matrix_kg)");
  }
}

// `prefix`: "human.band." or "human.band_per_axis[i]." (several axes: each band alike).
void check_band(Problems& problems, const teleop::v1::HumanBand& band, const std::string& prefix) {
  if (band.force_levels_n_size() == 0) {
    problems.add(prefix + "force_levels_N", "missing (a band needs at least one force level)");
  }
  // Each level is points_per_axis^3 humans to analyse: a bounded band, as points_per_axis is.
  if (band.force_levels_n_size() > kMaxForceLevels) {
    problems.add(prefix + "force_levels_N", "at most " + std::to_string(kMaxForceLevels) +
                                                " force levels, got " +
                                                std::to_string(band.force_levels_n_size()));
  }
  if (band.has_points_per_axis() &&
      (band.points_per_axis() < 2 || band.points_per_axis() > kMaxPointsPerAxis)) {
    problems.add(prefix + "points_per_axis", "must be in [2, " + std::to_string(kMaxPointsPerAxis) +
                                                 "], got " +
                                                 std::to_string(band.points_per_axis()));
  } else if (band.force_levels_n_size() <= kMaxForceLevels) {
    // Both within their own ranges: now their product (at most 100 x 100^3, no overflow).
    const long points =
        band.has_points_per_axis() ? band.points_per_axis() : defaults::kBandPointsPerAxis;
    const long humans = band.force_levels_n_size() * points * points * points;
    if (humans > kMaxBandHumans) {
      problems.add(prefix.substr(0, prefix.size() - 1),
                   std::to_string(humans) + " humans to analyse (" +
                       std::to_string(band.force_levels_n_size()) + " force levels x " +
                       std::to_string(points) + "^3 points), at most " +
                       std::to_string(kMaxBandHumans) + ": fewer force levels or points_per_axis");
    }
  }

  struct Axis {
    const char* name;
    bool present;
    const teleop::v1::ParameterBand& bounds;
    bool lower_must_be_positive;
  };
  const std::array<Axis, 3> axes{{
      {"mass_kg", band.has_mass_kg(), band.mass_kg(), true},
      {"damping_Ns_per_m", band.has_damping_ns_per_m(), band.damping_ns_per_m(), false},
      {"stiffness_N_per_m", band.has_stiffness_n_per_m(), band.stiffness_n_per_m(), false},
  }};
  for (const Axis& axis : axes) {
    const std::string path = prefix + axis.name;
    if (!axis.present) {
      problems.add(path, "missing (a band needs lower and upper lines of every parameter)");
      continue;
    }
    require_present(problems, path + ".lower", axis.bounds.has_lower(), "the lower bounding line");
    require_present(problems, path + ".upper", axis.bounds.has_upper(), "the upper bounding line");
    if (!axis.bounds.has_lower() || !axis.bounds.has_upper()) continue;
    const LinearBound lower{axis.bounds.lower().intercept(), axis.bounds.lower().slope_per_n()};
    const LinearBound upper{axis.bounds.upper().intercept(), axis.bounds.upper().slope_per_n()};
    // The values the lines give obey the fixed human's rule of the same axis (one parameter
    // space): its ceiling.
    const FieldRule* rule =
        rule_for(teleop::v1::HumanImpedance::descriptor()->FindFieldByName(axis.name));
    const double ceiling = rule != nullptr ? rule->max : std::numeric_limits<double>::max();
    // One report per axis: the first force level where each rule fails.
    bool lower_reported = false;
    bool order_reported = false;
    bool ceiling_reported = false;
    for (const double force_N : band.force_levels_n()) {
      const double low = lower.at(force_N);
      const double high = upper.at(force_N);
      if (!std::isfinite(force_N) || !std::isfinite(low) || !std::isfinite(high)) continue;
      const std::string at = " at force level " + format_float(force_N) + " N";
      const bool lower_bad = axis.lower_must_be_positive ? !(low > 0.0) : low < 0.0;
      if (lower_bad && !lower_reported) {
        problems.add(path + ".lower", std::string("must be ") +
                                          (axis.lower_must_be_positive ? "> 0" : ">= 0") + at +
                                          ", got " + format_float(low));
        lower_reported = true;
      }
      if (!(high <= ceiling) && !ceiling_reported) {
        problems.add(path + ".upper",
                     "must be <= " + format_float(ceiling) + at + ", got " + format_float(high));
        ceiling_reported = true;
      }
      if (low > high && !order_reported) {
        problems.add(path, "lower bound " + format_float(low) + " exceeds upper bound " +
                               format_float(high) + at);
        order_reported = true;
      }
    }
  }
}

void check_ranges(const teleop::v1::SystemConfig& c, Problems& problems) {
  if (c.has_master()) check_device(problems, "master", c.master());
  if (c.has_slave()) check_device(problems, "slave", c.slave());
  if (c.has_scaling() && c.scaling().has_position() && c.scaling().position() == 0.0) {
    problems.add("scaling.position", "must not be 0 (the slave would not follow the master)");
  }
  if (c.has_round_trip_delay_samples() &&
      (c.round_trip_delay_samples() < 0 || c.round_trip_delay_samples() > kMaxDelaySamples)) {
    problems.add("round_trip_delay_samples", "must be in [0, " + std::to_string(kMaxDelaySamples) +
                                                 "], got " +
                                                 std::to_string(c.round_trip_delay_samples()));
  }
  if (c.has_human()) {
    const teleop::v1::Human& human = c.human();
    switch (human.kind_case()) {
      case teleop::v1::Human::kFixed:
        break;
      case teleop::v1::Human::kBand:
        check_band(problems, human.band(), "human.band.");
        break;
      case teleop::v1::Human::kNone:
        break;
      case teleop::v1::Human::KIND_NOT_SET:
        if (!human.band_per_axis().empty()) break;  // several axes: axes_config.cpp's rules
        problems.add("human",
                     "give one of fixed, band or none (or leave out the section for the "
                     "default band)");
        break;
    }
    for (int i = 0; i < human.band_per_axis_size(); ++i) {
      check_band(problems, human.band_per_axis(i),
                 "human.band_per_axis[" + std::to_string(i) + "].");
    }
  }
  if (c.has_force_loop()) {
    const teleop::v1::ForceLoop& loop = c.force_loop();
    require_present(problems, "force_loop.mass_kg", loop.has_mass_kg(), "the device's mass");
    require_present(problems, "force_loop.sample_rate_hz", loop.has_sample_rate_hz(),
                    "the loop's rate");
    if (loop.has_sensor_average_samples() && loop.sensor_average_samples() < 1) {
      problems.add("force_loop.sensor_average_samples",
                   "must be >= 1, got " + std::to_string(loop.sensor_average_samples()));
    }
  }
  if (c.has_analysis()) {
    const double ratio = c.analysis().required_damping_ratio();
    if (std::isfinite(ratio) && (ratio < 0.0 || ratio >= 1.0)) {
      problems.add("analysis.required_damping_ratio",
                   "must be in [0, 1), got " + format_float(ratio));
    }
  }
}

LinearBound to_bound(const teleop::v1::LinearBound& bound) {
  return {bound.intercept(), bound.slope_per_n()};
}

ParameterBand to_band(const teleop::v1::ParameterBand& band) {
  return {to_bound(band.lower()), to_bound(band.upper())};
}

DeviceParams to_device(const teleop::v1::Device& device) {
  return {device.mass_kg(), device.damping_ns_per_m()};
}

FixtureParams to_fixture(const teleop::v1::Side& side) {
  if (!side.has_fixture()) return {};
  return {side.fixture().stiffness_n_per_m(), side.fixture().position_m()};
}

void require_section(const LoadedConfig& config, std::vector<std::string>& missing, bool present,
                     std::string_view name, std::string_view purpose) {
  if (!present) {
    missing.push_back(config.source_name + ": missing section '" + std::string(name) +
                      "' (needed to " + std::string(purpose) + ")");
  }
}

}  // namespace

// ---------------------------------------------------------------------------------------------

LoadedConfig parse_config_text(std::string_view text, std::string source_name,
                               const std::vector<std::string>& overrides) {
  LoadedConfig loaded = text_format::parse(text, std::move(source_name));
  text_format::check_repeated_overrides(overrides);
  for (const std::string& assignment : overrides) apply_override(loaded, assignment);
  return loaded;
}

LoadedConfig parse_config_file(const std::filesystem::path& path,
                               const std::vector<std::string>& overrides) {
  const std::string name = path.string();
  std::error_code status_error;
  if (std::filesystem::is_directory(path, status_error)) {
    throw ConfigError(name + ": is a directory, not a configuration file");
  }
  std::ifstream file(path, std::ios::binary);
  if (!file) {
    throw ConfigError(name + ": cannot open: " + std::strerror(errno));
  }
  std::ostringstream contents;
  contents << file.rdbuf();
  if (file.bad()) throw ConfigError(name + ": cannot read: " + std::strerror(errno));
  return parse_config_text(contents.str(), name, overrides);
}

LoadedConfig load_config_text(std::string_view text, std::string source_name,
                              const std::vector<std::string>& overrides) {
  LoadedConfig loaded = parse_config_text(text, std::move(source_name), overrides);
  validate(loaded);
  return loaded;
}

LoadedConfig load_config_file(const std::filesystem::path& path,
                              const std::vector<std::string>& overrides) {
  LoadedConfig loaded = parse_config_file(path, overrides);
  validate(loaded);
  return loaded;
}

std::uint64_t validation_count() noexcept { return validations.load(std::memory_order_relaxed); }

void validate(const LoadedConfig& config) {
  validations.fetch_add(1, std::memory_order_relaxed);
  Problems problems(config);
  check_fields(config.config, problems);
  check_ranges(config.config, problems);
  check_axes(config, problems);
  check_endpoints(config.config, problems);
  problems.throw_if_any();
}

TeleopParams to_teleop_params(const LoadedConfig& config) {
  validate(config);
  return teleop_params_of_validated(config);
}

TeleopParams teleop_params_of_validated(const LoadedConfig& config) {
  require_one_axis(config);  // axes_config.cpp: n > 1 (or an n-axis field) refused, named
  return one_axis_params_of_validated(config);
}

HumanBand to_band(const teleop::v1::HumanBand& band) {
  HumanBand out;
  out.force_levels_N.assign(band.force_levels_n().begin(), band.force_levels_n().end());
  out.points_per_axis =
      band.has_points_per_axis() ? band.points_per_axis() : defaults::kBandPointsPerAxis;
  out.mass_kg = to_band(band.mass_kg());
  out.damping_Ns_per_m = to_band(band.damping_ns_per_m());
  out.stiffness_N_per_m = to_band(band.stiffness_n_per_m());
  return out;
}

TeleopParams one_axis_params_of_validated(const LoadedConfig& config) {
  const teleop::v1::SystemConfig& c = config.config;
  constexpr std::string_view kPurpose = "analyse the teleoperator";
  std::vector<std::string> missing;
  require_section(config, missing, c.has_sample_rate_hz(), "sample_rate_hz", kPurpose);
  require_section(config, missing, c.has_master() && c.master().has_device(), "master.device",
                  kPurpose);
  require_section(config, missing, c.has_slave() && c.slave().has_device(), "slave.device",
                  kPurpose);
  require_section(config, missing, c.has_gains(), "gains", kPurpose);
  text_format::throw_if_any(missing);

  TeleopParams params;
  params.sample_rate_hz = c.sample_rate_hz();
  params.master_device = to_device(c.master().device());
  params.slave_device = to_device(c.slave().device());
  params.master_fixture = to_fixture(c.master());
  params.slave_fixture = to_fixture(c.slave());
  const teleop::v1::Gains& gains = c.gains();
  params.gains = {gains.kpm(), gains.kps(), gains.kdm(), gains.kds(),
                  gains.kvm(), gains.kvs(), gains.kfm()};
  if (c.has_scaling()) {
    if (c.scaling().has_position()) params.scaling.position = c.scaling().position();
    if (c.scaling().has_force()) params.scaling.force = c.scaling().force();
  }
  params.velocity_cutoff_hz = c.velocity_filter().cutoff_hz();
  params.round_trip_delay_samples = c.round_trip_delay_samples();

  if (!c.has_human()) {
    params.human.kind = HumanKind::kBand;
    params.human.band = default_human_band();
  } else if (c.human().has_fixed()) {
    const teleop::v1::HumanImpedance& fixed = c.human().fixed();
    params.human.kind = HumanKind::kFixed;
    params.human.fixed = {fixed.mass_kg(), fixed.damping_ns_per_m(), fixed.stiffness_n_per_m()};
  } else if (c.human().has_band()) {
    params.human.kind = HumanKind::kBand;
    params.human.band = to_band(c.human().band());
  } else if (!c.human().band_per_axis().empty()) {
    params.human.kind = HumanKind::kBand;  // several axes: axes_config.cpp reads the bands
  } else {
    params.human.kind = HumanKind::kNone;
  }

  params.analysis.required_damping_ratio = c.analysis().required_damping_ratio();
  if (c.analysis().has_stiffness_tolerance_n_per_m()) {
    params.analysis.stiffness_tolerance_N_per_m = c.analysis().stiffness_tolerance_n_per_m();
  }
  return params;
}

ForceLoopParams to_force_loop_params(const LoadedConfig& config) {
  validate(config);
  return force_loop_params_of_validated(config);
}

ForceLoopParams force_loop_params_of_validated(const LoadedConfig& config) {
  std::vector<std::string> missing;
  require_section(config, missing, config.config.has_force_loop(), "force_loop",
                  "analyse the force loop");
  text_format::throw_if_any(missing);
  const teleop::v1::ForceLoop& loop = config.config.force_loop();
  ForceLoopParams params;
  params.mass_kg = loop.mass_kg();
  params.damping_Ns_per_m = loop.damping_ns_per_m();
  params.kp = loop.kp();
  params.ki = loop.ki();
  params.sample_rate_hz = loop.sample_rate_hz();
  params.environment_stiffness_N_per_m = loop.environment_stiffness_n_per_m();
  params.environment_damping_Ns_per_m = loop.environment_damping_ns_per_m();
  params.sensor_average_samples = loop.has_sensor_average_samples()
                                      ? loop.sensor_average_samples()
                                      : defaults::kSensorAverageSamples;
  return params;
}

}  // namespace teleop::config
