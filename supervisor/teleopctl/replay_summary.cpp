#include "supervisor/teleopctl/replay_summary.hpp"

#include <fmt/format.h>

#include <cmath>
#include <cstdint>
#include <map>
#include <optional>
#include <ostream>
#include <string>

#include "common/session/session_stats.hpp"

namespace teleop::ctl {
namespace {

using nlohmann::json;

[[nodiscard]] double seconds_since(std::uint64_t t, std::uint64_t t0) {
  return t >= t0 ? static_cast<double>(t - t0) * 1e-9 : -static_cast<double>(t0 - t) * 1e-9;
}

[[nodiscard]] json optional_number(bool has, double v) { return has ? json(v) : json(nullptr); }

// --- JSON ----------------------------------------------------------------------------------

[[nodiscard]] json wakeup_json(const record::NodeTelemetryStats& s) {
  const std::optional<record::WakeupLatencySummary> w = s.wakeup_latency();
  if (!w) return nullptr;
  json bins = json::array();
  for (const record::WakeupLatencySummary::Bin& b : w->histogram) {
    bins.push_back({{"from_us", b.from_us},
                    {"to_us", b.to_us ? json(*b.to_us) : json(nullptr)},
                    {"cycles", b.cycles}});
  }
  return {{"p50_us", w->p50_us}, {"p99_us", w->p99_us}, {"p999_us", w->p999_us},
          {"max_us", w->max_us}, {"histogram", bins},   {"negative", w->negative}};
}

[[nodiscard]] json overruns_json(const record::NodeTelemetryStats& s) {
  const record::OverrunSummary o = s.overruns();
  json bins = json::array();
  for (const record::OverrunSummary::Bin& b : o.seconds_histogram) {
    bins.push_back(
        {{"from", b.from}, {"to", b.to ? json(*b.to) : json(nullptr)}, {"seconds", b.seconds}});
  }
  return {{"total", o.total},
          {"seconds", o.seconds},
          {"worst_second", o.worst_second},
          {"seconds_histogram", bins}};
}

// Each task-space axis's position range and largest |force| and |command| (issue 18).
[[nodiscard]] json per_axis_json(const record::NodeTelemetryStats& s) {
  json axes = json::array();
  for (const record::AxisSummary& a : s.per_axis) {
    axes.push_back({{"min_position_m", a.min_position_m},
                    {"max_position_m", a.max_position_m},
                    {"max_abs_force_N", a.max_abs_force_N},
                    {"max_abs_command_N", a.max_abs_command_N}});
  }
  return axes;
}

[[nodiscard]] json node_json(const record::NodeTelemetryStats& s) {
  return {
      {"telemetry_messages", s.messages},
      {"cycles", s.cycles},
      {"cycles_missing", s.missing},
      {"cycles_out_of_order", s.out_of_order},
      {"restarts", s.restarts},
      {"cycles_dropped_by_node", s.cycles_dropped},
      {"flight_records", s.flight_records},
      {"first_sequence", s.any ? json(s.first_sequence) : json(nullptr)},
      {"last_sequence", s.any ? json(s.last_sequence) : json(nullptr)},
      {"modes", s.modes},
      {"wakeup_latency", wakeup_json(s)},
      {"overruns", overruns_json(s)},
      {"axes", s.axes},
      {"axes_changes", s.axes_changes},
      {"refused_records", s.refused},
      {"first_refused_sequence", s.refused > 0 ? json(s.first_refused_sequence) : json(nullptr)},
      {"per_axis", per_axis_json(s)}};
}

[[nodiscard]] json alarm_json(double t, const v1::Alarm& a) {
  json evidence = json::array();
  for (const v1::Evidence& e : a.evidence()) {
    evidence.push_back({{"name", e.name()}, {"value", e.value()}, {"unit", e.unit()}});
  }
  return {{"time_s", t},
          {"severity", v1::Alarm::Severity_Name(a.severity())},
          {"kind", a.kind()},
          {"side", a.side()},
          {"message", a.message()},
          {"action", a.action()},
          {"master_sequence", a.master_sequence()},
          {"evidence", evidence}};
}

[[nodiscard]] json change_json(double t, const v1::ParameterChangeRecord& r) {
  const v1::ParameterChangeRequest& q = r.request();
  json requested = json::object();
  if (q.has_master_fixture_stiffness_n_per_m()) {
    requested["master_fixture_stiffness_N_per_m"] = q.master_fixture_stiffness_n_per_m();
  }
  if (q.has_slave_fixture_stiffness_n_per_m()) {
    requested["slave_fixture_stiffness_N_per_m"] = q.slave_fixture_stiffness_n_per_m();
  }
  if (q.has_gains()) {
    const v1::Gains& g = q.gains();
    requested["gains"] = {{"kpm", g.kpm()}, {"kps", g.kps()}, {"kdm", g.kdm()}, {"kds", g.kds()},
                          {"kvm", g.kvm()}, {"kvs", g.kvs()}, {"kfm", g.kfm()}};
  }
  return {{"time_s", t},
          {"requested_by", q.requested_by()},
          {"dry_run", q.dry_run()},
          {"requested", requested},
          {"accepted", r.reply().accepted()},
          {"change_id", r.reply().change_id()},
          {"apply_at_master_sequence", r.reply().apply_at_master_sequence()},
          {"reason", r.reply().reason()}};
}

[[nodiscard]] json stability_json(double t, const v1::StabilityReport& s) {
  return {{"time_s", t},
          {"verdict", s.verdict()},
          {"min_damping_ratio", s.min_damping_ratio()},
          {"required_damping_ratio", s.required_damping_ratio()},
          {"round_trip_samples", s.round_trip_samples()},
          {"sample_rate_hz", s.sample_rate_hz()},
          {"slave_fixture_stiffness_N_per_m", s.slave_fixture_stiffness_n_per_m()},
          {"master_fixture_stiffness_N_per_m", s.master_fixture_stiffness_n_per_m()},
          {"max_stable_slave_stiffness_N_per_m",
           optional_number(s.has_max_stable_slave_stiffness_n_per_m(),
                           s.max_stable_slave_stiffness_n_per_m())},
          {"max_stable_master_stiffness_N_per_m",
           optional_number(s.has_max_stable_master_stiffness_n_per_m(),
                           s.max_stable_master_stiffness_n_per_m())},
          {"slave_margin", optional_number(s.has_slave_margin(), s.slave_margin())},
          {"master_margin", optional_number(s.has_master_margin(), s.master_margin())},
          {"reason", s.reason()}};
}

// What one pass over the session gathers.
struct Gathered {
  std::map<std::uint16_t, std::uint64_t> counts{};
  std::uint64_t total{0};
  record::NodeTelemetryStats master{};
  record::NodeTelemetryStats slave{};
  json alarms = json::array();
  std::map<std::string, std::uint64_t> by_severity{};
  json changes = json::array();
  json stability = json::array();
  std::optional<std::uint64_t> drops{};
  std::string drops_source{};
};

[[nodiscard]] Gathered gather(const record::SessionReader& session, std::uint64_t t0) {
  Gathered g;
  record::SessionVisitor v;
  v.message = [&](const record::MessageView& m) {
    ++g.counts[m.channel->id];
    ++g.total;
    // The recorder's drops, from the newest supervisor message that carries them.
    if (m.channel->topic.rfind(record::topic::kSupervisorPrefix, 0) == 0) {
      if (const std::optional<std::uint64_t> d = record::recording_drops(m)) {
        g.drops = d;
        g.drops_source = m.channel->topic;
      }
    }
  };
  v.telemetry = [&](std::uint64_t, bool master, const v1::Telemetry& t) {
    (master ? g.master : g.slave).add(t);
  };
  v.alarm = [&](std::uint64_t log_time_ns, const v1::Alarm& a) {
    ++g.by_severity[v1::Alarm::Severity_Name(a.severity())];
    g.alarms.push_back(alarm_json(seconds_since(log_time_ns, t0), a));
  };
  v.parameter_change = [&](std::uint64_t log_time_ns, const v1::ParameterChangeRecord& r) {
    g.changes.push_back(change_json(seconds_since(log_time_ns, t0), r));
  };
  v.report = [&](std::uint64_t log_time_ns, const v1::StabilityReport& s) {
    g.stability.push_back(stability_json(seconds_since(log_time_ns, t0), s));
  };
  session.visit(v);
  return g;
}

// --- text ----------------------------------------------------------------------------------

[[nodiscard]] std::string margin_text(const json& v) {
  return v.is_null() ? "-" : fmt::format("{:.3f}", v.get<double>());
}

void print_header_and_channels(const json& j, std::ostream& out) {
  out << fmt::format("{}: {} messages over {:.3f} s ({} bytes, {}, written by {})\n",
                     j["file"].get<std::string>(), j["messages"].get<std::uint64_t>(),
                     j["duration_s"].get<double>(), j["file_size"].get<std::uint64_t>(),
                     j["indexed"].get<bool>() ? "indexed" : "scanned (no summary)",
                     j["library"].get<std::string>());
  out << "channels:\n";
  for (const json& c : j["channels"]) {
    out << fmt::format("  {:<32} {:>8}  {}\n", c["topic"].get<std::string>(),
                       c["messages"].get<std::uint64_t>(),
                       c["schema"].is_null() ? "(no schema)" : c["schema"].get<std::string>());
  }
  if (j["recorder_drops"].is_null()) {
    out << "recorder drops: unknown (no supervisor message in the file carries them)\n";
  } else {
    out << fmt::format("recorder drops: {} (from {})\n", j["recorder_drops"].get<std::uint64_t>(),
                       j["recorder_drops_source"].get<std::string>());
  }
}

// Nodes of several axes: each axis's position range, largest |F| and |u|; refused records.
void print_node_axes(const json& n, std::ostream& out) {
  if (n.contains("refused_records") && n["refused_records"].get<std::uint64_t>() > 0) {
    out << fmt::format(
        "         {} cycle records the codec refuses (first: sequence {}), left out of the "
        "per-axis figures\n",
        n["refused_records"].get<std::uint64_t>(),
        n["first_refused_sequence"].get<std::uint64_t>());
  }
  if (!n.contains("axes") || n["axes"].get<int>() < 2) return;
  out << fmt::format("         {} task-space axes{}:\n", n["axes"].get<int>(),
                     n["axes_changes"].get<std::uint64_t>() > 0
                         ? fmt::format(" ({} changes of the number of axes)",
                                       n["axes_changes"].get<std::uint64_t>())
                         : std::string());
  int k = 0;
  for (const json& a : n["per_axis"]) {
    out << fmt::format(
        "           axis {}: position {:.3f} .. {:.3f} mm, |force| up to {:.3f} N, |command| up "
        "to {:.3f} N\n",
        k++, a["min_position_m"].get<double>() * 1e3, a["max_position_m"].get<double>() * 1e3,
        a["max_abs_force_N"].get<double>(), a["max_abs_command_N"].get<double>());
  }
}

void print_node_cycles(const json& j, std::ostream& out) {
  out << "node cycles:\n";
  for (const char* side : {"master", "slave"}) {
    const json& n = j["nodes"][side];
    if (n["cycles"].get<std::uint64_t>() == 0) {
      out << fmt::format("  {:<6} none recorded\n", side);
      continue;
    }
    std::string modes;
    for (const auto& [mode, count] : n["modes"].items()) {
      modes += fmt::format("{}{} {}", modes.empty() ? "" : ", ", mode, count.get<std::uint64_t>());
    }
    out << fmt::format(
        "  {:<6} {} cycles (sequences {}..{}), {} missing, {} restarts, {} dropped by the node; "
        "{} telemetry messages; {}\n",
        side, n["cycles"].get<std::uint64_t>(), n["first_sequence"].get<std::uint64_t>(),
        n["last_sequence"].get<std::uint64_t>(), n["cycles_missing"].get<std::uint64_t>(),
        n["restarts"].get<std::uint64_t>(), n["cycles_dropped_by_node"].get<std::uint64_t>(),
        n["telemetry_messages"].get<std::uint64_t>(), modes);
    print_node_axes(n, out);
  }
}

void print_node_timing(const json& j, std::ostream& out) {
  for (const char* side : {"master", "slave"}) {
    const json& w = j["nodes"][side]["wakeup_latency"];
    if (w.is_null()) continue;
    std::string bins;
    for (const json& b : w["histogram"]) {
      bins +=
          fmt::format("{}{}{} {}", bins.empty() ? "" : ", ", b["to_us"].is_null() ? ">=" : "",
                      b["to_us"].is_null() ? std::to_string(b["from_us"].get<std::int64_t>())
                                           : fmt::format("{}-{}", b["from_us"].get<std::int64_t>(),
                                                         b["to_us"].get<std::int64_t>()),
                      b["cycles"].get<std::uint64_t>());
    }
    out << fmt::format(
        "  {:<6} wake-up latency p50 {:.0f} us, p99 {:.0f} us, p99.9 {:.0f} us, max {:.0f} us; "
        "cycles by us: {}\n",
        side, w["p50_us"].get<double>(), w["p99_us"].get<double>(), w["p999_us"].get<double>(),
        w["max_us"].get<double>(), bins);
    const json& o = j["nodes"][side]["overruns"];
    std::string seconds;
    for (const json& b : o["seconds_histogram"]) {
      const std::uint64_t from = b["from"].get<std::uint64_t>();
      seconds += fmt::format("{}{} {}", seconds.empty() ? "" : ", ",
                             b["to"].is_null() ? fmt::format(">={}", from)
                             : b["to"].get<std::uint64_t>() == from
                                 ? std::to_string(from)
                                 : fmt::format("{}-{}", from, b["to"].get<std::uint64_t>()),
                             b["seconds"].get<std::uint64_t>());
    }
    out << fmt::format("  {:<6} overruns {} in {} s (worst second {}); seconds by overruns: {}\n",
                       side, o["total"].get<std::uint64_t>(), o["seconds"].get<std::size_t>(),
                       o["worst_second"].get<std::uint64_t>(), seconds);
  }
}

void print_alarms_and_changes(const json& j, std::ostream& out) {
  const json& alarms = j["alarms"];
  std::string severities;
  for (const auto& [s, count] : alarms["by_severity"].items()) {
    severities +=
        fmt::format("{}{} {}", severities.empty() ? "" : ", ", s, count.get<std::uint64_t>());
  }
  out << fmt::format("alarms: {}{}\n", alarms["count"].get<std::size_t>(),
                     severities.empty() ? "" : " (" + severities + ")");
  for (const json& a : alarms["list"]) {
    const std::string action = a["action"].get<std::string>();
    out << fmt::format("  {:>9.3f} s  {:<8} {:<12} {:<6} {}{}\n", a["time_s"].get<double>(),
                       a["severity"].get<std::string>(), a["kind"].get<std::string>(),
                       a["side"].get<std::string>(), a["message"].get<std::string>(),
                       action.empty() ? "" : " -> " + action);
  }
  out << fmt::format("parameter changes: {}\n", j["parameter_changes"].size());
  for (const json& c : j["parameter_changes"]) {
    out << fmt::format("  {:>9.3f} s  by {}: {}{} ({}) {}\n", c["time_s"].get<double>(),
                       c["requested_by"].get<std::string>(),
                       c["accepted"].get<bool>() ? "accepted" : "refused",
                       c["dry_run"].get<bool>() ? " (dry run)" : "", c["requested"].dump(),
                       c["reason"].get<std::string>());
  }
}

// Whether two stability reports make one row: the same verdict and round trip, the damping
// ratio and margins within 0.001.
[[nodiscard]] bool same_row(const json& a, const json& b) {
  auto close = [](const json& x, const json& y) {
    if (x.is_null() || y.is_null()) return x.is_null() == y.is_null();
    return std::abs(x.get<double>() - y.get<double>()) < 1e-3;
  };
  return a["verdict"] == b["verdict"] && a["round_trip_samples"] == b["round_trip_samples"] &&
         close(a["min_damping_ratio"], b["min_damping_ratio"]) &&
         close(a["slave_margin"], b["slave_margin"]) &&
         close(a["master_margin"], b["master_margin"]);
}

void print_stability(const json& j, std::ostream& out) {
  const json& st = j["stability"];
  out << fmt::format("stability: {} report{}\n", st.size(), st.size() == 1 ? "" : "s");
  if (st.empty()) return;
  out << "  time (s)  verdict    min zeta  round trip  slave margin  master margin  reports\n";
  // Compact: a row per change of verdict, round trip or (by 0.001) damping ratio or margins.
  std::size_t i = 0;
  while (i < st.size()) {
    std::size_t k = i + 1;
    while (k < st.size() && same_row(st[i], st[k])) ++k;
    const json& r = st[i];
    out << fmt::format("  {:>8.3f}  {:<9}  {:>8.4f}  {:>10}  {:>12}  {:>13}  {}\n",
                       r["time_s"].get<double>(), r["verdict"].get<std::string>(),
                       r["min_damping_ratio"].get<double>(), r["round_trip_samples"].get<int>(),
                       margin_text(r["slave_margin"]), margin_text(r["master_margin"]), k - i);
    i = k;
  }
}

}  // namespace

json summary_json(const record::SessionReader& session) {
  const record::McapReader& reader = session.mcap();
  const std::uint64_t t0 = session.first_log_time_ns();
  const std::uint64_t t1 = session.last_log_time_ns();
  Gathered g = gather(session, t0);
  json channels = json::array();
  for (const auto& [id, ch] : reader.channels()) {
    const auto s = reader.schemas().find(ch.schema_id);
    channels.push_back(
        {{"topic", ch.topic},
         {"schema", s == reader.schemas().end() ? json(nullptr) : json(s->second.name)},
         {"message_encoding", ch.message_encoding},
         {"messages", g.counts[id]}});
  }
  return {
      {"file", reader.path().string()},
      {"file_size", reader.file_size()},
      {"library", reader.header().library},
      {"indexed", reader.indexed()},
      {"messages", g.total},
      {"start_log_time_ns", t0},
      {"end_log_time_ns", t1},
      {"duration_s", g.total > 0 ? seconds_since(t1, t0) : 0.0},
      {"channels", channels},
      {"recorder_drops", g.drops ? json(*g.drops) : json(nullptr)},
      {"recorder_drops_source", g.drops ? json(g.drops_source) : json(nullptr)},
      {"nodes", {{"master", node_json(g.master)}, {"slave", node_json(g.slave)}}},
      {"alarms", {{"count", g.alarms.size()}, {"by_severity", g.by_severity}, {"list", g.alarms}}},
      {"parameter_changes", g.changes},
      {"stability", g.stability}};
}

void print_summary(const json& j, std::ostream& out) {
  print_header_and_channels(j, out);
  print_node_cycles(j, out);
  print_node_timing(j, out);
  print_alarms_and_changes(j, out);
  print_stability(j, out);
}

}  // namespace teleop::ctl
