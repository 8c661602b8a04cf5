// SupervisorCore with several task-space axes (supervisor_core.hpp; docs/architecture.md "The
// supervisor with several axes"): the n-axis report, the monitors per axis and on the vector
// port, the refusal of change requests, and the nodes' fingerprints against each other.
#include <fmt/core.h>
#include <spdlog/spdlog.h>

#include <array>
#include <optional>
#include <span>

#include "common/config/control_fingerprint.hpp"
#include "common/telemetry/cycle_codec.hpp"
#include "supervisor/core/supervisor_core.hpp"

namespace teleop::supervisor {
namespace {

// Why the codec refused a cycle, or why it is not this system's.
std::string refusal(const v1::CycleRecord& c, const std::optional<node::CycleRecordAxes>& r,
                    int axes) {
  if (!r) {
    return fmt::format(
        "cycle {} is malformed (axes {}, {} positions, {} velocities, {} forces: the codec "
        "refuses it)",
        c.sequence(), c.axes(), c.positions_m_size(), c.velocities_m_per_s_size(),
        c.forces_n_size());
  }
  return fmt::format("cycle {} has {} axes, the configuration {}", c.sequence(), r->axes, axes);
}

}  // namespace

void SupervisorCore::publish_axes_report(const std::string& reason) {
  // The file's model with the measured rate and round trip (update_model keeps them in live_).
  TeleopAxesParams p = axes_->params;
  p.sample_rate_hz = live_.sample_rate_hz;
  p.round_trip_delay_samples = live_.round_trip_samples;
  const std::pair<double, int> key{p.sample_rate_hz, p.round_trip_delay_samples};
  auto known = axes_->assessed.find(key);
  if (known == axes_->assessed.end()) {
    known = axes_->assessed.emplace(key, assess_axes(p, p.analysis.required_damping_ratio)).first;
  }
  axes_->assessment = known->second;
  const AxesAssessment& a = axes_->assessment;
  report_ = to_report(
      a, p, ReportContext{now_ns_, master_sequence(), measured_round_trip_ns_, reason, change_id_});
  ports_.report(report_);
  record(record::topic::kStability, report_);
  std::string planes;
  for (const PlaneMargin& m : a.planes) planes += "; " + m.describe();
  spdlog::info("stability ({} axes): {} (min damping ratio {:.4f}, round trip {} samples{}){} [{}]",
               p.axes, report_.verdict(), report_.min_damping_ratio(), report_.round_trip_samples(),
               a.invalid_reason.empty() ? "" : ", " + a.invalid_reason, planes, reason);
}

// Each cycle as n axes (axes_from_proto): positions into the per-axis oscillation monitors,
// f . v into the passivity observer while coupled (the master's port with the measured force,
// the slave's with its opposite, as for one axis). A cycle the codec refuses, or one of another
// number of axes, is skipped and alarmed, never trusted.
void SupervisorCore::feed_axes_monitors(NodeView& n, const v1::Telemetry& t) {
  const int axes = axes_->params.axes;
  const auto count = static_cast<std::size_t>(axes);
  const bool is_master = n.side == Side::kMaster;
  std::uint64_t refused = 0;
  std::string first;
  for (const v1::CycleRecord& c : t.cycles()) {
    const std::optional<node::CycleRecordAxes> r = telemetry::axes_from_proto(c);
    if (!r || r->axes != axes) {
      if (refused++ == 0) first = refusal(c, r, axes);
      continue;
    }
    if (c.mode() != v1::ENGAGED && c.mode() != v1::CLUTCHED) {
      n.oscillation_axes->clear();
      n.passivity_axes->reset();
      continue;
    }
    std::array<double, kMaxAxes> force{};
    for (std::size_t i = 0; i < count; ++i) force[i] = is_master ? r->force_N[i] : -r->force_N[i];
    n.oscillation_axes->add(std::span<const double>(r->position_m.data(), count));
    (void)n.passivity_axes->add(std::span<const double>(force.data(), count),
                                std::span<const double>(r->velocity_m_per_s.data(), count));
  }
  if (refused == 0) return;
  n.refused_cycles += refused;
  alarm(
      v1::Alarm::WARNING, "telemetry", n.name,
      fmt::format("{} of {} cycles refused and not monitored: {}", refused, t.cycles_size(), first),
      {{"refused_cycles", static_cast<double>(refused), ""},
       {"refused_cycles_total", static_cast<double>(n.refused_cycles), ""}});
}

// A sustained oscillation on some axis (the worst named), or else an active vector port.
SupervisorCore::Finding SupervisorCore::axes_finding(NodeView& n) const {
  Finding f;
  if (n.oscillation_axes->full()) {
    const OscillationAxes o = n.oscillation_axes->check();
    if (o.detected()) {
      f.what = fmt::format("{} axis {}: oscillation {:.0f} Hz, {:.2g} mm", n.name, o.worst_axis,
                           o.worst.frequency_hz, o.worst.amplitude_m * 1e3);
      f.kind = "oscillation";
      f.evidence = {{"axis", static_cast<double>(o.worst_axis), ""},
                    {"amplitude", o.worst.amplitude_m * 1e3, "mm"},
                    {"frequency", o.worst.frequency_hz, "Hz"},
                    {"previous_amplitude", o.worst.previous_amplitude_m * 1e3, "mm"}};
      return f;
    }
  }
  const PassivityObserverAxes& p = *n.passivity_axes;
  if (p.energy_J() < -passivity_threshold_J_ &&
      p.recent_power_W() < -passivity_power_threshold_W_) {
    f.what = fmt::format("{}: active port over its {} axes (passivity observer on f . v)", n.name,
                         p.axes());
    f.kind = "passivity";
    f.evidence = {{"energy", p.energy_J(), "J"},
                  {"min_energy", p.min_energy_J(), "J"},
                  {"power_last_second", p.recent_power_W(), "W"}};
  }
  return f;
}

// What a console shows of one node's monitors: the worst axis's oscillation, the port's energy.
MonitorReadings SupervisorCore::axes_readings(const NodeView& n) const {
  MonitorReadings r;
  if (n.oscillation_axes->full()) {
    const OscillationAxes o = n.oscillation_axes->check();
    r.oscillation_amplitude_m = o.worst.amplitude_m;
    r.oscillation_frequency_hz = o.worst.frequency_hz;
    r.oscillating = o.detected();
  }
  r.passivity_energy_J = n.passivity_axes->energy_J();
  return r;
}

// A change request with several axes: refused, nothing sent to a node (a RETUNE carries the
// one-axis gains and fixtures, and n > 1 nodes refuse every RETUNE). Recorded and published as
// every decided change is.
void SupervisorCore::refuse_axes_change(const v1::ParameterChangeRequest& c,
                                        v1::SupervisorReply& reply) {
  v1::ParameterChangeReply& refused = *reply.mutable_change();
  refused.set_accepted(false);
  std::string reason = fmt::format(
      "refused: guarded parameter changes are not supported with {} axes yet (the nodes cannot "
      "apply one for n > 1); nothing was sent to the nodes",
      axes_->params.axes);
  *refused.mutable_prediction() = report_;
  // A fixture stiffness asked for: what the n-axis guard would say, every plane of that side at
  // it (the one-axis request names one stiffness a side). Gains are not assessed here. Not with
  // a human band: the guard's ramp checks over a band take seconds (11 s for cartesian3), which
  // the supervisor's loop cannot spare while it watches the nodes.
  const bool stiffness =
      c.has_master_fixture_stiffness_n_per_m() || c.has_slave_fixture_stiffness_n_per_m();
  if (stiffness && axes_->params.human.kind == HumanKind::kBand) {
    reason +=
        "; the n-axis guard's opinion is not computed in the supervisor's loop with a human band "
        "(`teleopctl analyze FILE --set ...` gives every plane's limit)";
  } else if (stiffness) {
    TeleopAxesParams current = axes_->params;
    current.sample_rate_hz = live_.sample_rate_hz;
    current.round_trip_delay_samples = live_.round_trip_samples;
    TeleopAxesParams proposed = current;
    if (c.has_master_fixture_stiffness_n_per_m()) {
      for (PlaneFixtureParams& p : proposed.master_planes) {
        p.stiffness_N_per_m = c.master_fixture_stiffness_n_per_m();
      }
    }
    if (c.has_slave_fixture_stiffness_n_per_m()) {
      for (PlaneFixtureParams& p : proposed.slave_planes) {
        p.stiffness_N_per_m = c.slave_fixture_stiffness_n_per_m();
      }
    }
    const AxesDecision d = assess_axes_change(current, proposed);
    reason += "; were it applied to every plane of the side, the n-axis guard says: " + d.reason;
    *refused.mutable_prediction() =
        to_report(d.prediction, proposed,
                  ReportContext{now_ns_, master_sequence(), measured_round_trip_ns_,
                                "prediction: requested by " + c.requested_by(), change_id_});
  }
  refused.set_reason(reason);
  v1::ParameterChangeRecord rec;
  *rec.mutable_request() = c;
  *rec.mutable_reply() = refused;
  rec.set_time_ns(now_ns_);
  change_decided(rec);
  spdlog::info("change request ({}): {}", c.requested_by(), refused.reason());
}

// Several axes: the supervisor computes no fingerprint of an n-axis file yet (its own is the
// one-axis view's); the nodes' are compared with each other.
std::string SupervisorCore::axes_configuration_mismatch() const {
  if (!master_.last || !slave_.last) return {};
  const std::uint64_t m = master_.last->config_fingerprint();
  const std::uint64_t s = slave_.last->config_fingerprint();
  if (m == s) return {};
  return fmt::format(
      "configuration fingerprints differ: master {}, slave {} (with {} axes the supervisor "
      "compares the nodes with each other)",
      config::fingerprint_hex(m), config::fingerprint_hex(s), axes_->params.axes);
}

}  // namespace teleop::supervisor
