#include "common/config/parameter_space.hpp"

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <limits>
#include <numbers>
#include <optional>
#include <string>
#include <unordered_map>

#include "common/config/axes_config.hpp"
#include "common/core/defaults.hpp"
#include "common/core/teleop_axes.hpp"

namespace teleop::config {
namespace {

namespace pb = google::protobuf;

constexpr double kInf = std::numeric_limits<double>::infinity();

// Ceilings, one per kind of quantity (config.proto repeats them next to each field). Each is far
// above what any haptic device needs and far below what overflows the discretised model
// (1e308 does; products of these ceilings over the smallest mass and period stay < 1e30).
//
// Stiffness, N/m: the stiffest rendered haptic walls are ~1e4-1e5 N/m (impedance devices at
// 1-10 kHz); an industrial servo stage reaches ~1e7. Position gains are stiffnesses too.
constexpr double kMaxStiffness = 1e7;
// Damping, Ns/m: 1e5 Ns/m stops a 1 t stage in 10 ms; haptic devices use < 100.
constexpr double kMaxDamping = 1e5;
// Masses, kg: 0.1 g (a MEMS micro-manipulator stage) to 1 t (a heavy slave arm).
constexpr double kMinDeviceMass = 1e-4;
constexpr double kMaxMass = 1e3;
// A human's arm, hand or finger as felt at the handle: at most 100 kg (the whole body).
constexpr double kMaxHumanMass = 1e2;
// Loop rates, Hz: 1 Hz to 100 kHz (a node's period is whole nanoseconds; haptic loops run at
// 1-20 kHz).
constexpr double kMinRate = 1.0;
constexpr double kMaxRate = 1e5;
// Force-feedback gain and scaling: micro-surgery scales forces by up to ~1e3; 1e4 leaves room.
constexpr double kMaxForceGain = 1e4;
// Position scaling |alpha| in [1e-4, 1e4]: 1:10000 micro-manipulation either way.
constexpr double kMinPositionScale = 1e-4;
constexpr double kMaxScale = 1e4;
// Forces, N: a haptic device gives a few N, a heavy slave arm ~1 kN; 1e5 N leaves room.
constexpr double kMaxForce = 1e5;
// Times, ms: ramps and timeouts of at most a minute (a node holds them in integer ns).
constexpr double kMaxMs = 60000.0;
// Positions, m: a workspace is < 1 m; 10 m covers any linear stage.
constexpr double kMaxPosition = 10.0;

struct NamedRule {
  const char* field;  // full protobuf name
  FieldRule rule;
};

constexpr FieldRule non_negative(double max, std::string_view unit, std::string_view why) {
  return {0.0, max, false, unit, why};
}
constexpr FieldRule positive(double max, std::string_view unit, std::string_view why) {
  return {0.0, max, true, unit, why};
}
constexpr FieldRule at_least(double min, double max, std::string_view unit, std::string_view why) {
  return {min, max, false, unit, why};
}
constexpr FieldRule symmetric(double max, std::string_view unit, std::string_view why) {
  return {-max, max, false, unit, why};
}

constexpr std::string_view kStiffnessWhy = "the stiffest haptic walls are ~1e5 N/m";
constexpr std::string_view kDampingWhy = "haptic devices use < 100 Ns/m";
constexpr std::string_view kDeviceMassWhy = "0.1 g to 1 t";
constexpr std::string_view kHumanMassWhy = "a human limb as felt at the handle";
constexpr std::string_view kRateWhy = "a node's loop runs at 1 Hz to 100 kHz";
constexpr std::string_view kForceGainWhy = "force scaling of micro-surgery is ~1e3";
constexpr std::string_view kForceWhy = "a heavy slave arm gives ~1 kN";
constexpr std::string_view kMsWhy = "at most a minute";
constexpr std::string_view kPositionWhy = "a workspace is < 1 m";
// A five-bar's links, m: 1 mm (a micro-manipulator's) to 10 m.
constexpr double kMinLink = 1e-3;
constexpr std::string_view kLinkWhy = "a link of 1 mm to 10 m";

const std::array kRules{
    NamedRule{"teleop.v1.SystemConfig.sample_rate_hz",
              at_least(kMinRate, kMaxRate, "Hz", kRateWhy)},
    // Gains: all >= 0 (a negative gain is positive feedback: Abbott-Okamura eqs. 8-9 with the
    // signs of config.proto's Gains comment).
    NamedRule{"teleop.v1.Gains.kpm", non_negative(kMaxStiffness, "N/m", kStiffnessWhy)},
    NamedRule{"teleop.v1.Gains.kps", non_negative(kMaxStiffness, "N/m", kStiffnessWhy)},
    NamedRule{"teleop.v1.Gains.kdm", non_negative(kMaxDamping, "Ns/m", kDampingWhy)},
    NamedRule{"teleop.v1.Gains.kds", non_negative(kMaxDamping, "Ns/m", kDampingWhy)},
    NamedRule{"teleop.v1.Gains.kvm", non_negative(kMaxDamping, "Ns/m", kDampingWhy)},
    NamedRule{"teleop.v1.Gains.kvs", non_negative(kMaxDamping, "Ns/m", kDampingWhy)},
    NamedRule{"teleop.v1.Gains.kfm", non_negative(kMaxForceGain, "", kForceGainWhy)},
    // Scaling: either sign (a mirrored axis); |alpha| >= 1e-4 (the law divides by it).
    NamedRule{"teleop.v1.Scaling.position", symmetric(kMaxScale, "", "1:10000 scaling")},
    NamedRule{"teleop.v1.Scaling.force", symmetric(kMaxScale, "", kForceGainWhy)},
    NamedRule{"teleop.v1.VelocityFilter.cutoff_hz",
              non_negative(10.0 * kMaxRate, "Hz", "ten times the fastest loop")},
    // Devices.
    NamedRule{"teleop.v1.Device.mass_kg", {kMinDeviceMass, kMaxMass, false, "kg", kDeviceMassWhy}},
    NamedRule{"teleop.v1.Device.damping_Ns_per_m", non_negative(kMaxDamping, "Ns/m", kDampingWhy)},
    NamedRule{"teleop.v1.Device.coulomb_friction_N", non_negative(kMaxForce, "N", kForceWhy)},
    NamedRule{"teleop.v1.Encoder.transmission_ratio",
              positive(1e4, "", "gearboxes stop at ~1:1000")},
    NamedRule{"teleop.v1.Encoder.metres_per_radian", positive(kMaxPosition, "m/rad", kPositionWhy)},
    NamedRule{"teleop.v1.LoadCell.noise_std_N", non_negative(kMaxForce, "N", kForceWhy)},
    NamedRule{"teleop.v1.LoadCell.range_N", positive(kMaxForce, "N", kForceWhy)},
    NamedRule{"teleop.v1.LoadCell.bias_N", symmetric(kMaxForce, "N", kForceWhy)},
    NamedRule{"teleop.v1.Actuator.max_force_N", positive(kMaxForce, "N", kForceWhy)},
    NamedRule{"teleop.v1.Actuator.max_rate_N_per_s",
              positive(kMaxForce* kMaxRate, "N/s", "full force within one fastest period")},
    NamedRule{"teleop.v1.Fixture.stiffness_N_per_m",
              non_negative(kMaxStiffness, "N/m", kStiffnessWhy)},
    NamedRule{"teleop.v1.Fixture.position_m", symmetric(kMaxPosition, "m", kPositionWhy)},
    NamedRule{"teleop.v1.Limits.min_position_m", symmetric(kMaxPosition, "m", kPositionWhy)},
    NamedRule{"teleop.v1.Limits.max_position_m", symmetric(kMaxPosition, "m", kPositionWhy)},
    NamedRule{"teleop.v1.Limits.max_velocity_m_per_s",
              positive(1e3, "m/s", "no haptic slave moves at 1 km/s")},
    NamedRule{"teleop.v1.Limits.max_force_N", positive(kMaxForce, "N", kForceWhy)},
    // The human.
    NamedRule{"teleop.v1.HumanImpedance.mass_kg", non_negative(kMaxHumanMass, "kg", kHumanMassWhy)},
    NamedRule{"teleop.v1.HumanImpedance.damping_Ns_per_m",
              non_negative(kMaxDamping, "Ns/m", kDampingWhy)},
    NamedRule{"teleop.v1.HumanImpedance.stiffness_N_per_m",
              non_negative(kMaxStiffness, "N/m", kStiffnessWhy)},
    NamedRule{"teleop.v1.HumanBand.force_levels_N",
              non_negative(1e3, "N", "no finger grips with 1 kN")},
    // Band lines: the values they give at each force level are checked against the axis's rule
    // by check_band; the coefficients only must not overflow there.
    NamedRule{"teleop.v1.LinearBound.intercept", symmetric(1e9, "", "a band coefficient")},
    NamedRule{"teleop.v1.LinearBound.slope_per_N", symmetric(1e9, "", "a band coefficient")},
    // The force-controlled device.
    NamedRule{"teleop.v1.ForceLoop.mass_kg",
              {kMinDeviceMass, kMaxMass, false, "kg", kDeviceMassWhy}},
    NamedRule{"teleop.v1.ForceLoop.damping_Ns_per_m",
              non_negative(kMaxDamping, "Ns/m", kDampingWhy)},
    NamedRule{"teleop.v1.ForceLoop.kp", symmetric(kMaxForceGain, "", kForceGainWhy)},
    NamedRule{"teleop.v1.ForceLoop.ki", symmetric(1e6, "1/s", "a force integrator")},
    NamedRule{"teleop.v1.ForceLoop.sample_rate_hz", at_least(kMinRate, kMaxRate, "Hz", kRateWhy)},
    NamedRule{"teleop.v1.ForceLoop.environment_stiffness_N_per_m",
              non_negative(kMaxStiffness, "N/m", kStiffnessWhy)},
    NamedRule{"teleop.v1.ForceLoop.environment_damping_Ns_per_m",
              non_negative(kMaxDamping, "Ns/m", kDampingWhy)},
    NamedRule{"teleop.v1.ForceLoop.sensor_average_samples",
              {-kInf, 1e5, false, "samples", "the paper averages 50"}},
    NamedRule{"teleop.v1.Analysis.stiffness_tolerance_N_per_m",
              positive(1e6, "N/m", "a tenth of the stiffness ceiling")},
    // The link.
    NamedRule{"teleop.v1.Link.peer_timeout_ms", positive(kMaxMs, "ms", kMsWhy)},
    NamedRule{"teleop.v1.Link.safe_ramp_ms",
              non_negative(1000.0, "ms", "longer leaves force on a dead link")},
    NamedRule{"teleop.v1.Link.engage_ramp_ms", non_negative(kMaxMs, "ms", kMsWhy)},
    NamedRule{"teleop.v1.Link.alignment_tolerance_m", positive(1.0, "m", kPositionWhy)},
    NamedRule{"teleop.v1.Link.centring_stiffness_N_per_m",
              non_negative(kMaxStiffness, "N/m", kStiffnessWhy)},
    NamedRule{"teleop.v1.Link.centring_damping_Ns_per_m",
              non_negative(kMaxDamping, "Ns/m", kDampingWhy)},
    NamedRule{"teleop.v1.Link.centring_max_force_N", non_negative(kMaxForce, "N", kForceWhy)},
    NamedRule{"teleop.v1.Node.telemetry_rate_hz",
              positive(1000.0, "Hz", "one message per cycle at 1 kHz")},
    NamedRule{"teleop.v1.Usb.watchdog_ms", at_least(1.0, 1000.0, "ms", "the device's own range")},
    // The supervisor.
    NamedRule{"teleop.v1.Supervisor.oscillation_threshold_m", positive(1.0, "m", kPositionWhy)},
    NamedRule{"teleop.v1.Supervisor.passivity_threshold_J",
              positive(1e3, "J", "a kJ is no longer a haptic energy")},
    NamedRule{"teleop.v1.Supervisor.escalation_ms", positive(kMaxMs, "ms", kMsWhy)},
    NamedRule{"teleop.v1.Supervisor.change_ramp_ms", non_negative(kMaxMs, "ms", kMsWhy)},
    NamedRule{"teleop.v1.Supervisor.passivity_power_threshold_W",
              positive(1e3, "W", "a kW is no longer a haptic power")},
    NamedRule{"teleop.v1.Supervisor.max_sessions_MB", non_negative(1e9, "MB", "a petabyte")},
    // Scenes: ceilings only (their signs are the scene loader's, with its own messages).
    NamedRule{"teleop.v1.Scene.duration_s", {-kInf, 86400.0, false, "s", "a day of simulation"}},
    NamedRule{"teleop.v1.Scene.output_rate_hz", {-kInf, 1e6, false, "Hz", "a row per us"}},
    NamedRule{"teleop.v1.MaliciousUser.dwell_s", {-kInf, 86400.0, false, "s", "a day"}},
    // A live parameter change: the same rules as the configuration's fields.
    NamedRule{"teleop.v1.ParameterUpdate.master_fixture_stiffness_N_per_m",
              non_negative(kMaxStiffness, "N/m", kStiffnessWhy)},
    NamedRule{"teleop.v1.ParameterUpdate.slave_fixture_stiffness_N_per_m",
              non_negative(kMaxStiffness, "N/m", kStiffnessWhy)},
    NamedRule{"teleop.v1.ParameterUpdate.master_fixture_position_m",
              symmetric(kMaxPosition, "m", kPositionWhy)},
    NamedRule{"teleop.v1.ParameterUpdate.slave_fixture_position_m",
              symmetric(kMaxPosition, "m", kPositionWhy)},
    NamedRule{"teleop.v1.ParameterUpdate.ramp_ms", non_negative(kMaxMs, "ms", kMsWhy)},
    NamedRule{"teleop.v1.ParameterUpdate.master_plane_stiffness_N_per_m",
              non_negative(kMaxStiffness, "N/m", kStiffnessWhy)},
    NamedRule{"teleop.v1.ParameterUpdate.slave_plane_stiffness_N_per_m",
              non_negative(kMaxStiffness, "N/m", kStiffnessWhy)},
    // Several axes (issue 18): element by element here; sizes, symmetry, definiteness, unit
    // normals and the five-bar's home pose are axes_config.cpp's.
    NamedRule{"teleop.v1.SystemConfig.axes", at_least(1.0, 6.0, "", "1 to 6 task-space axes")},
    NamedRule{"teleop.v1.Device.mass_matrix_kg", symmetric(kMaxMass, "kg", kDeviceMassWhy)},
    NamedRule{"teleop.v1.Device.damping_Ns_per_m_per_axis",
              non_negative(kMaxDamping, "Ns/m", kDampingWhy)},
    NamedRule{"teleop.v1.Device.coulomb_N_per_axis", non_negative(kMaxForce, "N", kForceWhy)},
    NamedRule{"teleop.v1.Device.torque_constant_N_m_per_A",
              positive(1e3, "N m/A", "a kN m per amp is no haptic motor")},
    NamedRule{"teleop.v1.Device.force_constant_N_per_A",
              positive(1e4, "N/A", "10 kN per amp is no haptic drive")},
    NamedRule{"teleop.v1.Device.amplifier_A_per_count",
              positive(10.0, "A/count", "10 A per DAC count is no haptic amplifier")},
    NamedRule{"teleop.v1.FiveBar.base_separation_m", non_negative(kMaxPosition, "m", kPositionWhy)},
    // A link of 1 mm at least: a vanishing link makes the linkage singular (its joint moves the
    // end point by nothing) whatever its transmission angles say.
    NamedRule{"teleop.v1.FiveBar.proximal_m", at_least(kMinLink, kMaxPosition, "m", kLinkWhy)},
    NamedRule{"teleop.v1.FiveBar.distal_m", at_least(kMinLink, kMaxPosition, "m", kLinkWhy)},
    NamedRule{"teleop.v1.FiveBar.home_joint_rad",
              symmetric(2.0 * std::numbers::pi, "rad", "one turn either way")},
    NamedRule{"teleop.v1.FiveBar.min_singularity_distance",
              positive(1.0, "", "|sin| of a transmission angle")},
    NamedRule{"teleop.v1.Plane.normal", symmetric(1e6, "", "a direction, normalised on load")},
    NamedRule{"teleop.v1.Scene.human_force_direction",
              symmetric(1e6, "", "a direction, normalised on load")},
    NamedRule{"teleop.v1.Plane.offset_m", symmetric(kMaxPosition, "m", kPositionWhy)},
    NamedRule{"teleop.v1.Plane.stiffness_N_per_m",
              non_negative(kMaxStiffness, "N/m", kStiffnessWhy)},
    NamedRule{"teleop.v1.Gains.kpm_per_axis", non_negative(kMaxStiffness, "N/m", kStiffnessWhy)},
    NamedRule{"teleop.v1.Gains.kps_per_axis", non_negative(kMaxStiffness, "N/m", kStiffnessWhy)},
    NamedRule{"teleop.v1.Gains.kdm_per_axis", non_negative(kMaxDamping, "Ns/m", kDampingWhy)},
    NamedRule{"teleop.v1.Gains.kds_per_axis", non_negative(kMaxDamping, "Ns/m", kDampingWhy)},
    NamedRule{"teleop.v1.Gains.kvm_per_axis", non_negative(kMaxDamping, "Ns/m", kDampingWhy)},
    NamedRule{"teleop.v1.Gains.kvs_per_axis", non_negative(kMaxDamping, "Ns/m", kDampingWhy)},
    NamedRule{"teleop.v1.Gains.kfm_per_axis", non_negative(kMaxForceGain, "", kForceGainWhy)},
    NamedRule{"teleop.v1.Gains.kpm_matrix", symmetric(kMaxStiffness, "N/m", kStiffnessWhy)},
    NamedRule{"teleop.v1.Gains.kps_matrix", symmetric(kMaxStiffness, "N/m", kStiffnessWhy)},
    NamedRule{"teleop.v1.Gains.kdm_matrix", symmetric(kMaxDamping, "Ns/m", kDampingWhy)},
    NamedRule{"teleop.v1.Gains.kds_matrix", symmetric(kMaxDamping, "Ns/m", kDampingWhy)},
    NamedRule{"teleop.v1.Gains.kvm_matrix", symmetric(kMaxDamping, "Ns/m", kDampingWhy)},
    NamedRule{"teleop.v1.Gains.kvs_matrix", symmetric(kMaxDamping, "Ns/m", kDampingWhy)},
    NamedRule{"teleop.v1.Gains.kfm_matrix", symmetric(kMaxForceGain, "", kForceGainWhy)},
};

const std::unordered_map<std::string, const FieldRule*>& rule_index() {
  static const auto* index = [] {
    auto* map = new std::unordered_map<std::string, const FieldRule*>();
    for (const NamedRule& r : kRules) map->emplace(r.field, &r.rule);
    return map;
  }();
  return *index;
}

std::string number(double value) {
  std::array<char, 64> buffer{};
  const auto result = std::to_chars(buffer.data(), buffer.data() + buffer.size(), value);
  return std::string(buffer.data(), result.ptr);
}

double numeric_value(const pb::Message& m, const pb::FieldDescriptor* f, int index) {
  const pb::Reflection* r = m.GetReflection();
  const bool rep = index >= 0;
  switch (f->cpp_type()) {
    case pb::FieldDescriptor::CPPTYPE_DOUBLE:
      return rep ? r->GetRepeatedDouble(m, f, index) : r->GetDouble(m, f);
    case pb::FieldDescriptor::CPPTYPE_FLOAT:
      return rep ? r->GetRepeatedFloat(m, f, index) : r->GetFloat(m, f);
    case pb::FieldDescriptor::CPPTYPE_INT32:
      return rep ? r->GetRepeatedInt32(m, f, index) : r->GetInt32(m, f);
    case pb::FieldDescriptor::CPPTYPE_INT64:
      return static_cast<double>(rep ? r->GetRepeatedInt64(m, f, index) : r->GetInt64(m, f));
    case pb::FieldDescriptor::CPPTYPE_UINT32:
      return rep ? r->GetRepeatedUInt32(m, f, index) : r->GetUInt32(m, f);
    case pb::FieldDescriptor::CPPTYPE_UINT64:
      return static_cast<double>(rep ? r->GetRepeatedUInt64(m, f, index) : r->GetUInt64(m, f));
    default:
      return 0.0;
  }
}

bool is_numeric(const pb::FieldDescriptor* f) {
  switch (f->cpp_type()) {
    case pb::FieldDescriptor::CPPTYPE_DOUBLE:
    case pb::FieldDescriptor::CPPTYPE_FLOAT:
    case pb::FieldDescriptor::CPPTYPE_INT32:
    case pb::FieldDescriptor::CPPTYPE_INT64:
    case pb::FieldDescriptor::CPPTYPE_UINT32:
    case pb::FieldDescriptor::CPPTYPE_UINT64:
      return true;
    default:
      return false;
  }
}

void walk(const pb::Message& message, const std::string& prefix, std::vector<FieldProblem>& out) {
  const pb::Descriptor* type = message.GetDescriptor();
  const pb::Reflection* r = message.GetReflection();
  for (int i = 0; i < type->field_count(); ++i) {
    const pb::FieldDescriptor* field = type->field(i);
    const std::string name = prefix.empty() ? field->name() : prefix + "." + field->name();
    const bool is_message = field->cpp_type() == pb::FieldDescriptor::CPPTYPE_MESSAGE;
    if (!is_message && !is_numeric(field)) continue;
    const auto visit = [&](int index, const std::string& path) {
      if (is_message) {
        walk(index < 0 ? r->GetMessage(message, field)
                       : r->GetRepeatedMessage(message, field, index),
             path, out);
        return;
      }
      const double value = numeric_value(message, field, index);
      // A plain proto3 scalar at 0 is its default ("unset"): only its finiteness matters.
      if (index < 0 && !field->has_presence() && value == 0.0) return;
      std::string why = check_value(field, value);
      if (!why.empty()) out.push_back({path, std::move(why)});
    };
    if (field->is_repeated()) {
      for (int k = 0; k < r->FieldSize(message, field); ++k) {
        visit(k, name + "[" + std::to_string(k) + "]");
      }
    } else if (!field->has_presence() || r->HasField(message, field)) {
      visit(-1, name);
    }
  }
}

// "tcp://HOST:PORT" -> (HOST, PORT text); empty host for other forms.
struct TcpParts {
  std::string host{};
  std::string port{};
};
std::optional<TcpParts> split_tcp(std::string_view endpoint) {
  constexpr std::string_view kTcp = "tcp://";
  if (!endpoint.starts_with(kTcp)) return std::nullopt;
  const std::string_view rest = endpoint.substr(kTcp.size());
  const auto colon = rest.rfind(':');
  if (colon == std::string_view::npos) return TcpParts{std::string(rest), ""};
  return TcpParts{std::string(rest.substr(0, colon)), std::string(rest.substr(colon + 1))};
}

std::string normal_host(std::string host) {
  if (host == "localhost") return "127.0.0.1";
  if (host == "[::1]") return "::1";
  return host;
}

bool wildcard_host(const std::string& host) {
  return host == "*" || host == "0.0.0.0" || host == "[::]" || host == "::";
}

}  // namespace

std::vector<std::string_view> ruled_fields() {
  std::vector<std::string_view> names;
  for (const NamedRule& r : kRules) names.emplace_back(r.field);
  return names;
}

const FieldRule* rule_for(const pb::FieldDescriptor* field) {
  if (field == nullptr) return nullptr;
  const auto& index = rule_index();
  const auto it = index.find(field->full_name());
  return it == index.end() ? nullptr : it->second;
}

std::string check_value(const pb::FieldDescriptor* field, double value) {
  if (!std::isfinite(value)) return "must be finite, got " + number(value);
  const FieldRule* rule = rule_for(field);
  if (rule == nullptr) return {};
  const std::string unit = rule->unit.empty() ? "" : " " + std::string(rule->unit);
  // The sign rule first, in the words config.proto uses.
  if (rule->min == 0.0 && rule->min_exclusive && !(value > 0.0)) {
    return "must be > 0, got " + number(value);
  }
  if (rule->min >= 0.0 && value < 0.0) {
    return std::string("must be ") + (rule->min > 0.0 ? "> 0" : ">= 0") + ", got " + number(value);
  }
  if (rule->min > 0.0 && value == 0.0) return "must be > 0, got 0";
  if (field->full_name() == "teleop.v1.Scaling.position" && value != 0.0 &&
      std::abs(value) < kMinPositionScale) {
    return "|value| must be >= " + number(kMinPositionScale) + " (1:10000 scaling), got " +
           number(value);
  }
  const bool below = rule->min_exclusive ? !(value > rule->min) : !(value >= rule->min);
  if (!std::isfinite(rule->min) && !(value <= rule->max)) {
    return "must be <= " + number(rule->max) + unit + " (" + std::string(rule->why) + "), got " +
           number(value);
  }
  if (below || !(value <= rule->max)) {
    const std::string low = number(rule->min);
    return "must be in " + std::string(rule->min_exclusive ? "(" : "[") + low + ", " +
           number(rule->max) + "]" + unit + " (" + std::string(rule->why) + "), got " +
           number(value);
  }
  return {};
}

std::vector<FieldProblem> check_fields(const pb::Message& message) {
  std::vector<FieldProblem> out;
  walk(message, "", out);
  return out;
}

std::vector<std::string> n_axis_gain_fields(const teleop::v1::Gains& gains) {
  std::vector<std::string> out;
  const pb::Descriptor* d = teleop::v1::Gains::descriptor();
  const pb::Reflection* r = gains.GetReflection();
  for (int i = 0; i < d->field_count(); ++i) {
    const pb::FieldDescriptor* f = d->field(i);
    if (f->is_repeated() && r->FieldSize(gains, f) > 0) out.push_back("gains." + f->name());
  }
  return out;
}

std::string check_one_axis_gains(const teleop::v1::Gains& gains) {
  std::string text;
  for (const std::string& name : n_axis_gain_fields(gains)) {
    if (!text.empty()) text += "; ";
    text += name + ": an n-axis field; a live change is one axis (the gains' scalars)";
  }
  return text;
}

std::string check_parameter_update(const teleop::v1::ParameterUpdate& update) {
  // A live change is one axis (the nodes run one): its gains are the scalars. A per-axis list or
  // a matrix would be dropped by the node without a word; refused, one line a field.
  std::string text = check_one_axis_gains(update.gains());
  const auto n_axis_field = [&text](bool given, const std::string& line) {
    if (!given) return;
    if (!text.empty()) text += "; ";
    text += line + ": an n-axis field; this is a one-axis change";
  };
  n_axis_field(update.axes() != 0, "axes (" + std::to_string(update.axes()) + ")");
  n_axis_field(!update.master_plane_stiffness_n_per_m().empty(), "master_plane_stiffness_N_per_m");
  n_axis_field(!update.slave_plane_stiffness_n_per_m().empty(), "slave_plane_stiffness_N_per_m");
  const std::vector<std::string> n_axis = n_axis_gain_fields(update.gains());
  for (const FieldProblem& p : check_fields(update)) {
    bool in_n_axis = false;
    for (const std::string& name : n_axis) in_n_axis = in_n_axis || p.path.starts_with(name + "[");
    if (in_n_axis) continue;
    // Name the fields as the configuration does (gains.kps, not update.gains.kps).
    if (!text.empty()) text += "; ";
    text += p.path + ": " + p.message;
  }
  return text;
}

namespace {

// "" when `given` values are one per plane of a side with `planes` planes.
std::string plane_count(const google::protobuf::RepeatedField<double>& given, int planes,
                        const char* field) {
  if (given.size() == planes) return {};
  return std::string(field) + ": one stiffness per plane of the side (" + std::to_string(planes) +
         " in the configuration), got " + std::to_string(given.size());
}

}  // namespace

std::string check_parameter_update_axes(const teleop::v1::ParameterUpdate& update, int axes,
                                        int master_planes, int slave_planes) {
  std::vector<std::string> lines;
  if (update.axes() != static_cast<std::uint32_t>(axes)) {
    lines.push_back("axes: an update for " + std::to_string(update.axes()) +
                    " axes, this one has " + std::to_string(axes));
  }
  // The one-axis fixture fields have no meaning here (the planes carry the stiffnesses).
  if (update.master_fixture_stiffness_n_per_m() != 0.0 ||
      update.slave_fixture_stiffness_n_per_m() != 0.0 ||
      update.master_fixture_position_m() != 0.0 || update.slave_fixture_position_m() != 0.0) {
    lines.emplace_back(
        "master_fixture_* / slave_fixture_*: one-axis fields; an n-axis update gives "
        "master_plane_stiffness_N_per_m and slave_plane_stiffness_N_per_m");
  }
  for (const std::string& line : {plane_count(update.master_plane_stiffness_n_per_m(),
                                              master_planes, "master_plane_stiffness_N_per_m"),
                                  plane_count(update.slave_plane_stiffness_n_per_m(), slave_planes,
                                              "slave_plane_stiffness_N_per_m")}) {
    if (!line.empty()) lines.push_back(line);
  }
  // One line a field (a hostile list of thousands of NaNs is one line, not thousands).
  std::vector<std::string> named;
  for (const FieldProblem& p : check_fields(update)) {
    const std::string field = p.path.substr(0, p.path.find('['));
    if (std::find(named.begin(), named.end(), field) != named.end()) continue;
    named.push_back(field);
    lines.push_back(p.path + ": " + p.message);
  }
  if (lines.empty() && axes >= 1 && axes <= kMaxAxes) {
    std::string why;
    (void)gains_axes_of(update.gains(), axes, why);
    if (!why.empty()) lines.push_back(why);
  }
  std::string text;
  for (const std::string& line : lines) text += (text.empty() ? "" : "; ") + line;
  return text;
}

std::string check_endpoint(std::string_view endpoint) {
  if (endpoint.starts_with("ipc://")) {
    return endpoint.size() > 6 ? "" : "ipc:// needs a path";
  }
  if (endpoint.starts_with("inproc://")) {
    return endpoint.size() > 9 ? "" : "inproc:// needs a name";
  }
  const auto tcp = split_tcp(endpoint);
  if (!tcp) {
    return "must be tcp://HOST:PORT (or ipc://PATH), got \"" + std::string(endpoint) + "\"";
  }
  if (tcp->host.empty())
    return "needs a host: tcp://HOST:PORT, got \"" + std::string(endpoint) + "\"";
  if (tcp->port.empty())
    return "needs a port: tcp://HOST:PORT, got \"" + std::string(endpoint) + "\"";
  int port = 0;
  const auto result = std::from_chars(tcp->port.data(), tcp->port.data() + tcp->port.size(), port);
  if (result.ec != std::errc{} || result.ptr != tcp->port.data() + tcp->port.size() || port < 1 ||
      port > 65535) {
    return "port must be a number in 1-65535 (peers connect to it), got \"" + tcp->port + "\"";
  }
  return {};
}

std::vector<BoundEndpoint> bound_endpoints(const teleop::v1::SystemConfig& c) {
  std::vector<BoundEndpoint> out;
  auto add = [&](std::string path, const std::string& value, std::string_view fallback) {
    const bool defaulted = value.empty();
    out.push_back({std::move(path), defaulted ? std::string(fallback) : value, defaulted});
  };
  const teleop::v1::Node& m = c.master().node();
  const teleop::v1::Node& s = c.slave().node();
  add("master.node.state_endpoint", m.state_endpoint(), defaults::kMasterStateEndpoint);
  add("master.node.command_endpoint", m.command_endpoint(), defaults::kMasterCommandEndpoint);
  add("master.node.telemetry_endpoint", m.telemetry_endpoint(), defaults::kMasterTelemetryEndpoint);
  add("slave.node.state_endpoint", s.state_endpoint(), defaults::kSlaveStateEndpoint);
  add("slave.node.command_endpoint", s.command_endpoint(), defaults::kSlaveCommandEndpoint);
  add("slave.node.telemetry_endpoint", s.telemetry_endpoint(), defaults::kSlaveTelemetryEndpoint);
  add("supervisor.report_endpoint", c.supervisor().report_endpoint(),
      defaults::kSupervisorReportEndpoint);
  add("supervisor.request_endpoint", c.supervisor().request_endpoint(),
      defaults::kSupervisorRequestEndpoint);
  return out;
}

bool endpoints_clash(std::string_view a, std::string_view b) {
  const auto ta = split_tcp(a);
  const auto tb = split_tcp(b);
  if (!ta || !tb) return a == b;
  if (ta->port != tb->port) return false;
  const std::string ha = normal_host(ta->host);
  const std::string hb = normal_host(tb->host);
  return ha == hb || wildcard_host(ha) || wildcard_host(hb);
}

}  // namespace teleop::config
