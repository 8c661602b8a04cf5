#include "supervisor/core/configuration_check.hpp"

#include <fmt/core.h>

#include <cmath>
#include <vector>

#include "common/config/control_fingerprint.hpp"

namespace teleop::supervisor {
namespace {

std::string hex_or_none(std::uint64_t f) {
  return f == 0 ? std::string("none (an older node?)") : config::fingerprint_hex(f);
}

// The value `name` has in ActiveParameters (complete ramps only: mid-ramp values are neither).
struct Value {
  const char* name;
  double approved;
  double (*get)(const v1::ActiveParameters&);
};

std::vector<Value> values(const ApprovedConfiguration& a) {
  const Gains& g = a.gains;
  return {
      {"gains.kpm", g.kpm, [](const v1::ActiveParameters& p) { return p.gains().kpm(); }},
      {"gains.kps", g.kps, [](const v1::ActiveParameters& p) { return p.gains().kps(); }},
      {"gains.kdm", g.kdm, [](const v1::ActiveParameters& p) { return p.gains().kdm(); }},
      {"gains.kds", g.kds, [](const v1::ActiveParameters& p) { return p.gains().kds(); }},
      {"gains.kvm", g.kvm, [](const v1::ActiveParameters& p) { return p.gains().kvm(); }},
      {"gains.kvs", g.kvs, [](const v1::ActiveParameters& p) { return p.gains().kvs(); }},
      {"gains.kfm", g.kfm, [](const v1::ActiveParameters& p) { return p.gains().kfm(); }},
      {"master.fixture.stiffness_N_per_m", a.master_fixture_N_per_m,
       [](const v1::ActiveParameters& p) { return p.master_fixture_stiffness_n_per_m(); }},
      {"slave.fixture.stiffness_N_per_m", a.slave_fixture_N_per_m,
       [](const v1::ActiveParameters& p) { return p.slave_fixture_stiffness_n_per_m(); }},
  };
}

bool settled(const v1::Telemetry* t) {
  return t != nullptr && t->has_active() && t->active().ramp_progress() >= 1.0;
}

}  // namespace

ConfigurationMismatch compare_configurations(std::uint64_t own,
                                             const ApprovedConfiguration& approved,
                                             const v1::Telemetry* master,
                                             const v1::Telemetry* slave) {
  ConfigurationMismatch out;
  const bool master_differs = master != nullptr && master->config_fingerprint() != own;
  const bool slave_differs = slave != nullptr && slave->config_fingerprint() != own;
  if (!master_differs && !slave_differs) return out;
  out.side = master_differs && slave_differs ? "system" : (master_differs ? "master" : "slave");
  out.message = "configuration fingerprints differ: supervisor " + config::fingerprint_hex(own);
  if (master != nullptr) out.message += ", master " + hex_or_none(master->config_fingerprint());
  if (slave != nullptr) out.message += ", slave " + hex_or_none(slave->config_fingerprint());
  // The fields telemetry shows, where a node runs what the supervisor approved (same change,
  // ramp complete): any value that is not the approved one, or not the other node's.
  const v1::Telemetry* m =
      settled(master) && master->active().change_id() == approved.change_id ? master : nullptr;
  const v1::Telemetry* s =
      settled(slave) && slave->active().change_id() == approved.change_id ? slave : nullptr;
  std::string fields;
  for (const Value& v : values(approved)) {
    const bool md = m != nullptr && v.get(m->active()) != v.approved;
    const bool sd = s != nullptr && v.get(s->active()) != v.approved;
    if (!md && !sd) continue;
    fields += fmt::format("{}{} (supervisor {:g}", fields.empty() ? "" : ", ", v.name, v.approved);
    if (m != nullptr) fields += fmt::format(", master {:g}", v.get(m->active()));
    if (s != nullptr) fields += fmt::format(", slave {:g}", v.get(s->active()));
    fields += ")";
  }
  out.message += fields.empty()
                     ? "; the gains and fixture stiffnesses in force agree, so the difference is "
                       "elsewhere (rate, devices, scaling, filter, round trip, human, analysis, "
                       "limits, link timing or the experiment flag)"
                     : "; differing: " + fields;
  return out;
}

std::string experiment_banner(bool own_allow_unstable, const v1::Telemetry* master,
                              const v1::Telemetry* slave) {
  std::string who;
  std::string verdicts;
  for (const auto& [name, t] : {std::pair<const char*, const v1::Telemetry*>{"master", master},
                                std::pair<const char*, const v1::Telemetry*>{"slave", slave}}) {
    if (t == nullptr || !t->configuration_check().allow_unstable()) continue;
    const v1::ConfigurationCheck& c = t->configuration_check();
    who += (who.empty() ? "" : " and ") + std::string(name);
    verdicts += fmt::format("{}{} analysis: {} (least damping ratio {:.4f}, required {:.4f})",
                            verdicts.empty() ? "" : "; ", name, c.verdict(), c.min_damping_ratio(),
                            c.required_damping_ratio());
  }
  if (who.empty() && !own_allow_unstable) return {};
  return "EXPERIMENT: experiment.allow_unstable is set" +
         (who.empty() ? std::string(" in the supervisor's configuration")
                      : " on the " + who + ": configurations predicted unstable may engage") +
         (verdicts.empty() ? std::string() : " [" + verdicts + "]");
}

}  // namespace teleop::supervisor
