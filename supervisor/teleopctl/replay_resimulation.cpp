#include "supervisor/teleopctl/replay_resimulation.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <nlohmann/json.hpp>
#include <ostream>
#include <stdexcept>
#include <string_view>

#include "common/config/axes_config.hpp"
#include "common/config/resimulation_loader.hpp"
#include "common/record/session.hpp"
#include "common/scene/lockstep_axes.hpp"
#include "common/stability/analysis_axes.hpp"

namespace teleop::ctl {

namespace {

using nlohmann::json;
namespace topic = record::topic;

[[nodiscard]] bool coupled(node::Mode mode) {
  return mode == node::Mode::kEngaged || mode == node::Mode::kClutched;
}

// A node's cycles, each of `axes` axes; otherwise an error naming the file, topic and sequence.
void check_axes(const record::SessionReader& session, bool master,
                const std::vector<record::RecordedCycleAxes>& cycles, int axes) {
  for (const record::RecordedCycleAxes& r : cycles) {
    if (r.cycle.axes != axes) {
      throw std::runtime_error(fmt::format(
          "{}: {} cycle {}: {} task-space axes, the recorded configuration {}", session.path(),
          topic::telemetry(master), r.cycle.sequence, r.cycle.axes, axes));
    }
  }
}

[[nodiscard]] Eigen::VectorXd position_of(const node::CycleRecordAxes& c) {
  Eigen::VectorXd x(c.axes);
  for (int i = 0; i < c.axes; ++i) x(i) = c.position_m[static_cast<std::size_t>(i)];
  return x;
}

[[nodiscard]] Eigen::VectorXd peer_position_of(const node::CycleRecordAxes& c) {
  Eigen::VectorXd x(c.axes);
  for (int i = 0; i < c.axes; ++i) x(i) = c.peer_position_m[static_cast<std::size_t>(i)];
  return x;
}

// What happened: the recorded slave, measured as the resimulation is.
[[nodiscard]] scene::AxesSlaveOutcome recorded_outcome(
    const std::vector<record::RecordedCycleAxes>& slave, const TeleopAxesParams& p) {
  scene::AxesSlaveOutcomeMeter meter(p.axes, p.scaling.position, p.slave_planes);
  for (const record::RecordedCycleAxes& r : slave) {
    meter.add(position_of(r.cycle), coupled(r.cycle.mode)
                                        ? std::optional<Eigen::VectorXd>(peer_position_of(r.cycle))
                                        : std::nullopt);
  }
  return meter.finish(1.0 / p.sample_rate_hz);
}

[[nodiscard]] json outcome_json(const scene::AxesSlaveOutcome& o) {
  return {{"cycles", o.cycles},
          {"tracking_error_rms_m", o.tracking_rms_m},
          {"max_penetration_slave_m", o.max_penetration_m},
          {"oscillation",
           {{"detected", o.oscillation.detected},
            {"amplitude_m", o.oscillation.amplitude_m},
            {"frequency_hz", o.oscillation.frequency_hz},
            {"previous_amplitude_m", o.oscillation.previous_amplitude_m},
            {"axis", o.oscillation_axis}}},
          {"fault", o.fault}};
}

[[nodiscard]] json analysis_json(const TeleopAxesParams& p) {
  const stability::AxesAnalysis a = stability::analyze_axes(p);
  return {{"verdict", stability::to_string(a.verdict)},
          {"min_damping_ratio", a.min_damping_ratio},
          {"spectral_radius", a.spectral_radius}};
}

// Per axis, the resimulated slave's position and command less the recorded ones, cycle by cycle
// (cycle k of the resimulation against the slave's k-th recorded cycle): the largest |difference|
// and the sequence of the recorded cycle where the position's is, and the rms.
[[nodiscard]] json deviation_json(const scene::AxesResimulation& r,
                                  const std::vector<record::RecordedCycleAxes>& slave) {
  const auto n = static_cast<std::size_t>(r.axes);
  const std::size_t compared = std::min(slave.size(), r.slave_position_m.size() / n);
  json axes = json::array();
  double worst = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    double max_x = 0.0;
    double max_u = 0.0;
    double sum_sq = 0.0;
    std::uint64_t at = compared > 0 ? slave.front().cycle.sequence : 0;
    for (std::size_t k = 0; k < compared; ++k) {
      const node::CycleRecordAxes& c = slave[k].cycle;
      const double dx = std::abs(r.slave_position_m[k * n + i] - c.position_m[i]);
      const double du = std::abs(r.slave_command_N[k * n + i] - c.command_N[i]);
      // NaN never reads as "no deviation".
      if (dx > max_x || std::isnan(dx)) {
        max_x = std::isnan(dx) ? std::numeric_limits<double>::infinity() : dx;
        at = c.sequence;
      }
      max_u = std::isnan(du) ? std::numeric_limits<double>::infinity() : std::max(max_u, du);
      sum_sq += dx * dx;
    }
    worst = std::max(worst, max_x);
    axes.push_back(
        {{"axis", i},
         {"max_abs_position_m", max_x},
         {"rms_position_m", compared > 0 ? std::sqrt(sum_sq / static_cast<double>(compared)) : 0.0},
         {"at_sequence", at},
         {"max_abs_command_N", max_u}});
  }
  return {{"cycles_compared", compared}, {"max_abs_position_m", worst}, {"per_axis", axes}};
}

void print_resimulation_axes(const json& j, const ResimulationRequest& a, std::ostream& out) {
  out << fmt::format(
      "{}: the recorded master motion ({} cycles, {:.3f} s, {} axes) through both laws and the "
      "simulated slave{}\n",
      a.file, j["master_cycles"].get<std::size_t>(), j["duration_s"].get<double>(),
      j["axes"].get<int>(), a.overrides.empty() ? " as recorded" : " with:");
  for (const std::string& o : a.overrides) out << "  --set " << o << "\n";
  const json& rec = j["recorded"];
  const json& sim = j["resimulated"];
  auto row = [&](const std::string& name, const std::string& x, const std::string& y) {
    out << fmt::format("  {:<34} {:<28} {}\n", name, x, y);
  };
  out << fmt::format("  {:<34} {:<28} {}\n", "", "recorded", "resimulated");
  row("analyser verdict", rec["analysis"]["verdict"].get<std::string>(),
      sim["analysis"]["verdict"].get<std::string>());
  auto num = [](const json& v, const char* f) {
    return v.is_null() ? std::string("-") : fmt::format(fmt::runtime(f), v.get<double>());
  };
  row("min damping ratio", num(rec["analysis"]["min_damping_ratio"], "{:.4f}"),
      num(sim["analysis"]["min_damping_ratio"], "{:.4f}"));
  auto mm = [](const json& o, const char* f) {
    return fmt::format("{:.4g}", 1e3 * o[f].get<double>());
  };
  row("slave tracking error rms (mm)", mm(rec["outcome"], "tracking_error_rms_m"),
      mm(sim["outcome"], "tracking_error_rms_m"));
  row("max slave plane penetration (mm)", mm(rec["outcome"], "max_penetration_slave_m"),
      mm(sim["outcome"], "max_penetration_slave_m"));
  auto osc = [](const json& o) {
    const json& s = o["oscillation"];
    return fmt::format("{}, axis {}, {:.3g} mm", s["detected"].get<bool>() ? "sustained" : "none",
                       s["axis"].get<int>(), 1e3 * s["amplitude_m"].get<double>());
  };
  row("slave oscillation (worst axis)", osc(rec["outcome"]), osc(sim["outcome"]));
  if (sim["outcome"]["fault"].get<bool>()) out << "  the resimulated slave law latched a fault\n";
  const json& d = j["deviation"];
  out << fmt::format("  the resimulated slave less the recorded one, {} cycles compared:\n",
                     d["cycles_compared"].get<std::size_t>());
  for (const json& x : d["per_axis"]) {
    out << fmt::format(
        "    axis {}: position up to {:.6g} mm (rms {:.6g} mm, at cycle {}), "
        "command up to {:.6g} N\n",
        x["axis"].get<int>(), 1e3 * x["max_abs_position_m"].get<double>(),
        1e3 * x["rms_position_m"].get<double>(), x["at_sequence"].get<std::uint64_t>(),
        x["max_abs_command_N"].get<double>());
  }
}

}  // namespace

ResimulationConfigs resimulation_configs(const record::SessionReader& session,
                                         const ResimulationRequest& a, ProgressParts& parts) {
  std::optional<config::LoadedConfig> recorded =
      record::recorded_config(session, {}, parts.bytes(kConfigPass));
  if (!recorded) {
    throw std::runtime_error(
        fmt::format("{}: no /config channel: --resimulate needs the "
                    "recorded configuration (channels: {})",
                    a.file, session.channel_list()));
  }
  ResimulationConfigs c;
  c.config = a.overrides.empty()
                 ? *recorded
                 : *record::recorded_config(session, a.overrides, parts.bytes(kConfigPass));
  c.recorded = std::move(*recorded);
  return c;
}

int resimulation_exit_code(bool fault, bool oscillation, const std::string& verdict) {
  if (fault) return 5;
  if (verdict == "invalid") return 1;
  if (oscillation || verdict == "unstable") return 3;
  return verdict == "uncertain" ? 4 : 0;
}

int resimulate_axes(const record::SessionReader& session, const ResimulationRequest& a,
                    const ResimulationConfigs& c, ProgressParts& parts,
                    std::optional<ProgressLine>& progress, std::ostream& out) {
  const int n = config::configured_axes(c.recorded.config);
  if (const int now = config::configured_axes(c.config.config); now != n) {
    throw std::runtime_error(fmt::format(
        "{}: --set axes: the session recorded {} axes; a resimulation keeps them, not {}", a.file,
        n, now));
  }
  const std::vector<record::RecordedCycleAxes> master =
      session.cycles_axes(true, parts.bytes(kCyclesPass));
  const std::vector<record::RecordedCycleAxes> slave =
      session.cycles_axes(false, parts.bytes(kCyclesPass));
  check_axes(session, true, master, n);
  check_axes(session, false, slave, n);
  if (master.empty()) {
    throw std::runtime_error(fmt::format("{}: no master cycles to replay ({} is empty or missing)",
                                         a.file, topic::kMasterTelemetry));
  }
  const TeleopAxesParams before = config::to_axes_params(c.recorded);
  const TeleopAxesParams params = config::to_axes_params(c.config);
  const scene::AxesResimulationSetup setup = config::to_axes_resimulation(
      c.config, position_of(master.front().cycle),
      slave.empty() ? Eigen::VectorXd::Zero(n) : position_of(slave.front().cycle));
  std::vector<scene::AxesMasterCycle> motion;
  motion.reserve(master.size());
  for (const record::RecordedCycleAxes& r : master) {
    motion.push_back(
        {position_of(r.cycle), coupled(r.cycle.mode), r.cycle.mode == node::Mode::kClutched});
  }
  const scene::AxesResimulation after =
      scene::resimulate_axes(setup, motion, parts.fraction(kResimulation));
  const json j = {{"file", a.file},
                  {"overrides", a.overrides},
                  {"axes", n},
                  {"master_cycles", master.size()},
                  {"duration_s", static_cast<double>(master.size()) / params.sample_rate_hz},
                  {"round_trip_samples", setup.round_trip_delay_samples},
                  {"recorded",
                   {{"analysis", analysis_json(before)},
                    {"outcome", outcome_json(recorded_outcome(slave, before))}}},
                  {"resimulated",
                   {{"analysis", analysis_json(params)}, {"outcome", outcome_json(after.outcome)}}},
                  {"deviation", deviation_json(after, slave)}};
  progress.reset();
  if (a.json) {
    out << j.dump(2) << "\n";
  } else {
    print_resimulation_axes(j, a, out);
  }
  return resimulation_exit_code(after.outcome.fault, after.outcome.oscillation.detected,
                                j["resimulated"]["analysis"]["verdict"].get<std::string>());
}

}  // namespace teleop::ctl
