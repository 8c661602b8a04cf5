#include "supervisor/teleopctl/json_output.hpp"

#include <google/protobuf/util/json_util.h>

#include <cmath>
#include <stdexcept>
#include <string>

namespace teleop::ctl {

using nlohmann::json;

namespace {

json complex_json(std::complex<double> c) { return json::array({c.real(), c.imag()}); }

json optional_number(const std::optional<double>& v) { return v ? json(*v) : json(nullptr); }

}  // namespace

json proto_json(const google::protobuf::Message& message) {
  google::protobuf::util::JsonPrintOptions o;
  o.always_print_primitive_fields = true;
  o.preserve_proto_field_names = true;
  std::string text;
  if (!google::protobuf::util::MessageToJsonString(message, &text, o).ok()) {
    throw std::runtime_error("a " + message.GetTypeName() + " has no JSON form");
  }
  return json::parse(text);
}

json human_json(const std::optional<stability::HumanSample>& human) {
  if (!human) return nullptr;
  return {{"force_N", human->has_force ? json(human->force_N) : json(nullptr)},
          {"mass_kg", human->impedance.mass_kg},
          {"damping_Ns_per_m", human->impedance.damping_Ns_per_m},
          {"stiffness_N_per_m", human->impedance.stiffness_N_per_m}};
}

json mode_json(const stability::Mode& m) {
  const bool has_s = !m.structural && std::isfinite(m.s.real()) && std::isfinite(m.s.imag());
  return {{"z", complex_json(m.z)},
          {"abs_z", std::abs(m.z)},
          {"s", has_s ? complex_json(m.s) : json(nullptr)},
          {"damping_ratio", m.structural ? json(nullptr) : json(m.damping_ratio)},
          {"structural", m.structural},
          {"error_bound", m.structural ? json(nullptr) : json(m.error)}};
}

json analysis_json(const stability::AnalysisResult& r, const TeleopParams& p) {
  json modes = json::array();
  for (const stability::Mode& m : r.spectrum.modes) modes.push_back(mode_json(m));
  return {{"verdict", stability::to_string(r.verdict)},
          {"invalid_reason", r.invalid_reason.empty() ? json(nullptr) : json(r.invalid_reason)},
          {"stable", r.verdict == stability::Verdict::kStable},
          {"spectral_radius", r.spectral_radius},
          {"min_damping_ratio", r.min_damping_ratio},
          {"required_damping_ratio", p.analysis.required_damping_ratio},
          {"meets_required_damping_ratio",
           r.verdict == stability::Verdict::kStable &&
               r.min_damping_ratio >= p.analysis.required_damping_ratio},
          {"worst_human", human_json(r.worst_human)},
          {"spectral_radius_human", human_json(r.radius_human)},
          {"structure", stability::to_string(r.structure)},
          {"humans_evaluated", r.humans_evaluated},
          {"sample_rate_hz", p.sample_rate_hz},
          {"round_trip_delay_samples", p.round_trip_delay_samples},
          {"master_fixture_N_per_m", p.master_fixture.stiffness_N_per_m},
          {"slave_fixture_N_per_m", p.slave_fixture.stiffness_N_per_m},
          {"eigenvalues", modes}};
}

json limit_json(const stability::StiffnessLimit& l, stability::Side side, double rate_hz) {
  json j = {{"sample_rate_hz", rate_hz},
            {"max_stable_stiffness_N_per_m", optional_number(l.max_stable_stiffness_N_per_m)},
            {"worst_human", human_json(l.worst_human)},
            {"evaluations", l.evaluations}};
  if (!l.reason.empty()) j["reason"] = l.reason;
  if (l.invalid) j["invalid"] = true;
  j["other_fixture_N_per_m"] = l.other_fixture_N_per_m;
  if (side == stability::Side::kMaster) {
    j["passivity_limit_N_per_m"] = optional_number(l.passivity_limit_N_per_m);
    if (!l.passivity_reason.empty()) j["passivity_reason"] = l.passivity_reason;
  }
  return j;
}

json force_loop_json(const stability::ForceLoopResult& r, const ForceLoopParams& p) {
  json roots = json::array();
  for (const auto& root : r.roots) roots.push_back(complex_json(root));
  json j = {
      {"controller", r.proportional_integral ? "PI" : "P"},
      // The paper's B_v limit is eq. 14 for P; PI has no closed form, so its search.
      {"bv_limit_Ns_per_m",
       optional_number(r.proportional_integral ? r.bv_limit_Ns_per_m : r.bv_limit_eq14_Ns_per_m)},
      {"bv_limit_eq14_Ns_per_m", optional_number(r.bv_limit_eq14_Ns_per_m)},
      {"bv_limit_at_configured_kv_Ns_per_m", optional_number(r.bv_limit_Ns_per_m)},
      {"kv_limit_N_per_m", optional_number(r.kv_limit_N_per_m)},
      {"verdict", stability::to_string(r.verdict)},
      {"stable", r.stable},
      {"environment_stiffness_N_per_m", p.environment_stiffness_N_per_m},
      {"environment_damping_Ns_per_m", p.environment_damping_Ns_per_m},
      {"characteristic_polynomial", r.characteristic_polynomial},
      {"roots", roots}};
  if (!r.limit_reason.empty()) j["reason"] = r.limit_reason;
  return j;
}

}  // namespace teleop::ctl
