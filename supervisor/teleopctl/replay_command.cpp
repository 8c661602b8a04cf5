#include "supervisor/teleopctl/replay_command.hpp"

#include <fmt/format.h>
#include <google/protobuf/text_format.h>
#include <google/protobuf/util/json_util.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <ostream>
#include <stdexcept>
#include <utility>
#include <vector>

#include "common/config/axes_config.hpp"
#include "common/config/config_loader.hpp"
#include "common/config/resimulation_loader.hpp"
#include "common/record/mcap_reader.hpp"
#include "common/scene/resimulate.hpp"
#include "common/session/session_reader.hpp"
#include "common/telemetry/cycle_codec.hpp"
#include "supervisor/teleopctl/cli_args.hpp"
#include "supervisor/teleopctl/progress_line.hpp"
#include "supervisor/teleopctl/replay_live.hpp"
#include "supervisor/teleopctl/replay_resimulation.hpp"
#include "supervisor/teleopctl/replay_summary.hpp"
#include "supervisor/teleopctl/replay_supervision.hpp"
#include "supervisor/teleopctl/svg_plot.hpp"
#include "teleop/v1/telemetry.pb.h"

namespace teleop::ctl {

namespace {

using nlohmann::json;
namespace pb = google::protobuf;
namespace topic = record::topic;

// --- arguments -----------------------------------------------------------------------------

enum class Action { kSummary, kPrint, kCsv, kRecover, kLive, kResimulate, kPlot };

// The file, --speed, the live replay's endpoints, --paused, --hold and --set as the live replay
// takes them (the other actions read the file and --set from there too), and the rest.
struct ReplayArgs : LiveReplayOptions {
  Action action{Action::kSummary};
  bool json{false};
  std::string channel{};                  // --print
  std::optional<std::string> out_path{};  // --csv --out
  std::string recover_path{};             // --recover
  std::string plot_path{};                // --plot
};

void set_action(ReplayArgs& a, Action action, bool& chosen, const std::string& flag) {
  if (chosen && a.action != action) {
    throw UsageError(
        fmt::format("{} cannot be combined with another of --print, --csv, "
                    "--recover, --speed, --resimulate, --plot",
                    flag));
  }
  chosen = true;
  a.action = action;
}

[[nodiscard]] ReplayArgs parse_replay_args(const std::vector<std::string>& args) {
  ReplayArgs a;
  bool chosen = false;
  bool live_only = false;
  ArgCursor c(args);
  while (c.next()) {
    const std::string& arg = c.arg();
    if (arg == "--json") {
      a.json = true;
    } else if (arg == "--print") {
      set_action(a, Action::kPrint, chosen, arg);
      a.channel = c.value("--print");
    } else if (arg == "--csv") {
      set_action(a, Action::kCsv, chosen, arg);
    } else if (arg == "--out") {
      a.out_path = c.value("--out");
    } else if (arg == "--recover") {
      set_action(a, Action::kRecover, chosen, arg);
      a.recover_path = c.value("--recover");
    } else if (arg == "--speed") {
      set_action(a, Action::kLive, chosen, arg);
      const std::string& v = c.value("--speed");
      a.speed = parse_number(v, "--speed");
      if (!(a.speed > 0.0)) throw UsageError(fmt::format("--speed: '{}' is not positive", v));
    } else if (arg == "--resimulate") {
      set_action(a, Action::kResimulate, chosen, arg);
    } else if (arg == "--plot") {
      set_action(a, Action::kPlot, chosen, arg);
      a.plot_path = svg_plot_path(c.value("--plot"));
    } else if (arg == "--set") {
      a.overrides.push_back(c.value("--set"));
    } else if (arg == "--control") {
      a.control = c.value("--control");
      live_only = true;
    } else if (arg == "--master-telemetry") {
      a.master_endpoint = c.value("--master-telemetry");
      live_only = true;
    } else if (arg == "--slave-telemetry") {
      a.slave_endpoint = c.value("--slave-telemetry");
      live_only = true;
    } else if (arg == "--report") {
      a.report_endpoint = c.value("--report");
      live_only = true;
    } else if (arg == "--paused") {
      a.start_paused = true;
      live_only = true;
    } else if (arg == "--hold") {
      a.hold = true;
      live_only = true;
    } else {
      take_only_positional(arg, a.file, "-");
    }
  }
  if (a.file.empty()) throw UsageError("missing FILE");
  if (a.out_path && a.action != Action::kCsv) throw UsageError("--out goes with --csv");
  if (live_only && a.action != Action::kLive) {
    throw UsageError(
        "--control, --master-telemetry, --slave-telemetry, --report, --paused and "
        "--hold go with --speed");
  }
  if (!a.overrides.empty() && a.action != Action::kLive && a.action != Action::kResimulate) {
    throw UsageError("--set goes with --speed or --resimulate");
  }
  if (a.json &&
      (a.action == Action::kCsv || a.action == Action::kLive || a.action == Action::kPlot)) {
    throw UsageError("--json goes with the summary, --print, --recover or --resimulate");
  }
  return a;
}

[[nodiscard]] double seconds_since(std::uint64_t t, std::uint64_t t0) {
  return t >= t0 ? static_cast<double>(t - t0) * 1e-9 : -static_cast<double>(t0 - t) * 1e-9;
}

// --- --print -------------------------------------------------------------------------------

// Every message of the channel, decoded through the schema the file embeds (so files of other
// versions print too).
int print_channel(const record::SessionReader& session, const ReplayArgs& a, std::ostream& out) {
  if (!session.has_topic(a.channel)) {
    throw std::runtime_error(fmt::format("{}: no channel '{}' (channels: {})", a.file, a.channel,
                                         session.channel_list()));
  }
  std::map<std::uint16_t, std::unique_ptr<record::EmbeddedSchemaDecoder>> decoders;
  pb::TextFormat::Printer printer;
  printer.SetSingleLineMode(true);
  pb::util::JsonPrintOptions options;
  options.preserve_proto_field_names = true;
  session.mcap().for_each_message(record::Order::kLogTime, [&](const record::MessageView& m) {
    if (m.channel->topic != a.channel) return;
    if (m.schema == nullptr) {
      throw std::runtime_error(fmt::format("{}: channel {} has no schema", a.file, a.channel));
    }
    auto& d = decoders[m.schema->id];
    if (!d) d = std::make_unique<record::EmbeddedSchemaDecoder>(*m.schema);
    const std::unique_ptr<pb::Message> msg = d->decode(m.data);
    if (!msg) {
      throw std::runtime_error(fmt::format("{}: {} message at log time {} ns does not decode as {}",
                                           a.file, a.channel, m.log_time_ns, m.schema->name));
    }
    if (a.json) {
      std::string body;
      if (!pb::util::MessageToJsonString(*msg, &body, options).ok()) {
        throw std::runtime_error(fmt::format("{}: {} message at log time {} ns: no JSON form",
                                             a.file, a.channel, m.log_time_ns));
      }
      out << "{\"log_time_ns\":" << m.log_time_ns << ",\"message\":" << body << "}\n";
    } else {
      std::string text;
      printer.PrintToString(*msg, &text);
      while (!text.empty() && text.back() == ' ') text.pop_back();
      out << fmt::format("{}.{:09} {{ {} }}\n", m.log_time_ns / 1'000'000'000,
                         m.log_time_ns % 1'000'000'000, text);
    }
  });
  return kExitOk;
}

// --- --csv ---------------------------------------------------------------------------------

// The sample time of the master's first cycle (the slave's when there is no master).
[[nodiscard]] std::optional<std::int64_t> first_cycle_time(
    const record::SessionReader& session, const std::vector<record::MessageView>& master,
    const std::vector<record::MessageView>& slave) {
  for (const std::vector<record::MessageView>* side : {&master, &slave}) {
    for (const record::MessageView& m : *side) {
      const v1::Telemetry t = session.decode<v1::Telemetry>(m);
      if (t.cycles_size() > 0) return t.cycles(0).sample_time_ns();
    }
  }
  return std::nullopt;
}

// The most task-space axes of any cycle of either node (1 for one-axis sessions).
[[nodiscard]] int session_axes(const record::SessionReader& session,
                               const std::vector<record::MessageView>& master,
                               const std::vector<record::MessageView>& slave) {
  int axes = 1;
  for (const std::vector<record::MessageView>* side : {&master, &slave}) {
    for (const record::MessageView& m : *side) {
      const v1::Telemetry t = session.decode<v1::Telemetry>(m);
      for (const v1::CycleRecord& c : t.cycles()) {
        axes = std::max(axes, telemetry::axes_of(c));
      }
    }
  }
  return axes;
}

// Several axes (issue 18): per axis position_m_i, velocity_m_per_s_i, force_N_i, command_N_i
// and peer_position_m_i (empty for axes a cycle does not have), then the per-cycle fields. A
// record the codec refuses is an error naming the file, topic and sequence.
void write_axes_rows(const record::SessionReader& session,
                     const std::vector<record::MessageView>& master,
                     const std::vector<record::MessageView>& slave, int axes,
                     std::int64_t origin_ns, std::ostream& os) {
  os << "node,time_s,sequence,mode,axes";
  for (const char* field :
       {"position_m", "velocity_m_per_s", "force_N", "command_N", "peer_position_m"}) {
    for (int i = 0; i < axes; ++i) os << "," << field << "_" << i;
  }
  os << ",peer_sequence,peer_age_ns,coupling_weight,flags,wakeup_latency_ns,round_trip_ns,"
        "master_sequence,fixture_penetration_m\n";
  std::string line;
  for (const std::vector<record::MessageView>* side : {&master, &slave}) {
    const char* node = side == &master ? "master" : "slave";
    for (const record::MessageView& m : *side) {
      const v1::Telemetry t = session.decode<v1::Telemetry>(m);
      for (const v1::CycleRecord& c : t.cycles()) {
        const std::optional<node::CycleRecordAxes> r = telemetry::axes_from_proto(c);
        if (!r) {
          throw std::runtime_error(
              fmt::format("{}: {} cycle {} (log time {} ns): a record of {} axes the codec refuses",
                          session.path(), m.channel->topic, c.sequence(), m.log_time_ns, c.axes()));
        }
        line.clear();
        fmt::format_to(std::back_inserter(line), "{},{},{},{},{}", node,
                       static_cast<double>(r->sample_time_ns - origin_ns) * 1e-9, r->sequence,
                       v1::NodeMode_Name(c.mode()), r->axes);
        for (const auto* field : {&r->position_m, &r->velocity_m_per_s, &r->force_N, &r->command_N,
                                  &r->peer_position_m}) {
          for (int i = 0; i < axes; ++i) {
            if (i < r->axes) {
              fmt::format_to(std::back_inserter(line), ",{}",
                             (*field)[static_cast<std::size_t>(i)]);
            } else {
              line += ",";
            }
          }
        }
        fmt::format_to(std::back_inserter(line), ",{},{},{},{},{},{},{},{}\n", r->peer_sequence,
                       r->peer_age_ns, r->coupling_weight, r->flags, r->wakeup_latency_ns,
                       r->round_trip_ns, r->master_sequence, r->fixture_penetration_m);
        os << line;
      }
    }
  }
}

int write_cycles_csv(const record::SessionReader& session, const ReplayArgs& a, std::ostream& out) {
  if (!session.has_topic(topic::kMasterTelemetry) && !session.has_topic(topic::kSlaveTelemetry)) {
    throw std::runtime_error(fmt::format("{}: no {} or {} channel (channels: {})", a.file,
                                         topic::kMasterTelemetry, topic::kSlaveTelemetry,
                                         session.channel_list()));
  }
  std::ofstream file;
  std::ostream* os = &out;
  if (a.out_path) {
    file.open(*a.out_path);
    if (!file) throw std::runtime_error(fmt::format("cannot write '{}'", *a.out_path));
    os = &file;
  }
  const std::vector<record::MessageView> master = session.messages_on(topic::kMasterTelemetry);
  const std::vector<record::MessageView> slave = session.messages_on(topic::kSlaveTelemetry);
  // Time from the master's first cycle (the slave's when there is no master).
  const std::optional<std::int64_t> origin = first_cycle_time(session, master, slave);
  if (const int axes = session_axes(session, master, slave); axes > 1) {
    write_axes_rows(session, master, slave, axes, origin.value_or(0), *os);
    os->flush();
    if (!*os) {
      throw std::runtime_error(
          fmt::format("cannot write '{}'", a.out_path ? *a.out_path : std::string("stdout")));
    }
    return kExitOk;
  }
  *os << "node,time_s,sequence,mode,position_m,velocity_m_per_s,force_N,command_N,"
         "peer_sequence,peer_position_m,peer_age_ns,coupling_weight,flags,wakeup_latency_ns,"
         "round_trip_ns,master_sequence,parameter_change_id\n";
  std::string line;
  for (const std::vector<record::MessageView>* side : {&master, &slave}) {
    const char* node = side == &master ? "master" : "slave";
    for (const record::MessageView& m : *side) {
      const v1::Telemetry t = session.decode<v1::Telemetry>(m);
      for (const v1::CycleRecord& c : t.cycles()) {
        line.clear();
        // Shortest round-trip representation of each double.
        fmt::format_to(
            std::back_inserter(line), "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n", node,
            static_cast<double>(c.sample_time_ns() - origin.value_or(0)) * 1e-9, c.sequence(),
            v1::NodeMode_Name(c.mode()), c.position_m(), c.velocity_m_per_s(), c.force_n(),
            c.command_n(), c.peer_sequence(), c.peer_position_m(), c.peer_age_ns(),
            c.coupling_weight(), c.flags(), c.wakeup_latency_ns(), c.round_trip_ns(),
            c.master_sequence(), c.parameter_change_id());
        *os << line;
      }
    }
  }
  os->flush();
  if (!*os) {
    throw std::runtime_error(
        fmt::format("cannot write '{}'", a.out_path ? *a.out_path : std::string("stdout")));
  }
  return kExitOk;
}

// --- --plot --------------------------------------------------------------------------------

// One node's positions (mm) and load-cell forces (N) from `origin_ns`, a line broken wherever
// cycles are missing (a sequence gap or a restart), about kMaxPlotPoints points.
void add_node_traces(Chart& chart, const std::vector<record::RecordedCycle>& cycles,
                     std::int64_t origin_ns, const char* node, std::size_t colour) {
  Series position{fmt::format("{} position", node), {}, line_colour(colour), true};
  Series force{fmt::format("{} force (load cell)", node), {}, line_colour(colour), true};
  const std::size_t stride = plot_stride(cycles.size());
  const double nan = std::nan("");
  for (std::size_t i = 0; i < cycles.size(); ++i) {
    const node::CycleRecord& c = cycles[i].cycle;
    const bool gap = i > 0 && (cycles[i].session_id != cycles[i - 1].session_id ||
                               c.sequence != cycles[i - 1].cycle.sequence + 1);
    const double t = static_cast<double>(c.sample_time_ns - origin_ns) * 1e-9;
    if (gap) {
      position.points.emplace_back(t, nan);
      force.points.emplace_back(t, nan);
    }
    if (gap || i % stride == 0 || i + 1 == cycles.size()) {
      position.points.emplace_back(t, 1e3 * c.position_m);
      force.points.emplace_back(t, c.force_N);
    }
  }
  chart.panels[0].series.push_back(std::move(position));
  chart.panels[1].series.push_back(std::move(force));
}

// Several axes (issue 18): per axis, each node's position (mm) and load-cell force (N), one
// colour per axis, the master solid and the slave dashed, lines broken where cycles are missing.
void add_node_axes_traces(Chart& chart, const std::vector<record::RecordedCycleAxes>& cycles,
                          std::int64_t origin_ns, const char* node, bool dashed, int axes) {
  const std::size_t stride = plot_stride(cycles.size());
  const double nan = std::nan("");
  for (int k = 0; k < axes; ++k) {
    const auto i = static_cast<std::size_t>(k);
    Series position{fmt::format("{} axis {}", node, k), {}, line_colour(i), true};
    Series force{fmt::format("{} axis {}", node, k), {}, line_colour(i), true};
    position.dashed = force.dashed = dashed;
    for (std::size_t j = 0; j < cycles.size(); ++j) {
      const node::CycleRecordAxes& c = cycles[j].cycle;
      const bool gap = j > 0 && (cycles[j].session_id != cycles[j - 1].session_id ||
                                 c.sequence != cycles[j - 1].cycle.sequence + 1);
      const double t = static_cast<double>(c.sample_time_ns - origin_ns) * 1e-9;
      if (gap || k >= c.axes) {
        position.points.emplace_back(t, nan);
        force.points.emplace_back(t, nan);
        if (k >= c.axes) continue;
      }
      if (gap || j % stride == 0 || j + 1 == cycles.size()) {
        position.points.emplace_back(t, 1e3 * c.position_m[i]);
        force.points.emplace_back(t, c.force_N[i]);
      }
    }
    chart.panels[0].series.push_back(std::move(position));
    chart.panels[1].series.push_back(std::move(force));
  }
}

int write_session_axes_plot(const record::SessionReader& session, const ReplayArgs& a, int axes,
                            std::ostream& out) {
  const auto read = [&](bool m) {
    return session.has_topic(topic::telemetry(m)) ? session.cycles_axes(m)
                                                  : std::vector<record::RecordedCycleAxes>{};
  };
  const std::vector<record::RecordedCycleAxes> master = read(true);
  const std::vector<record::RecordedCycleAxes> slave = read(false);
  if (master.empty() && slave.empty()) {
    throw std::runtime_error(fmt::format("{}: no cycles of either node to plot", a.file));
  }
  const std::int64_t origin = (master.empty() ? slave : master).front().cycle.sample_time_ns;
  const std::int64_t last = std::max(master.empty() ? origin : master.back().cycle.sample_time_ns,
                                     slave.empty() ? origin : slave.back().cycle.sample_time_ns);
  Chart chart = position_force_chart(
      fmt::format("Recorded session: positions and forces of {} axes", axes),
      fmt::format("{}: {} master and {} slave cycles over {:.3f} s", a.file, master.size(),
                  slave.size(), static_cast<double>(last - origin) * 1e-9));
  if (!master.empty()) add_node_axes_traces(chart, master, origin, "master", false, axes);
  if (!slave.empty()) add_node_axes_traces(chart, slave, origin, "slave", true, axes);
  chart.notes.push_back(
      "one colour per axis: master solid, slave dashed; the slave's load cell reads its push on "
      "the environment");
  write_svg(a.plot_path, chart);
  out << "wrote " << a.plot_path << "\n";
  return kExitOk;
}

int write_session_plot(const record::SessionReader& session, const ReplayArgs& a,
                       std::ostream& out) {
  if (session.has_topic(topic::kMasterTelemetry) || session.has_topic(topic::kSlaveTelemetry)) {
    const int axes = session_axes(session, session.messages_on(topic::kMasterTelemetry),
                                  session.messages_on(topic::kSlaveTelemetry));
    if (axes > 1) return write_session_axes_plot(session, a, axes, out);
  }
  const std::vector<record::RecordedCycle> master = session.cycles(true);
  const std::vector<record::RecordedCycle> slave = session.cycles(false);
  if (master.empty() && slave.empty()) {
    throw std::runtime_error(fmt::format("{}: no cycles of either node to plot (channels: {})",
                                         a.file, session.channel_list()));
  }
  // Time from the master's first cycle (the slave's when there is no master), as --csv.
  const std::int64_t origin = (master.empty() ? slave : master).front().cycle.sample_time_ns;
  const std::int64_t last = std::max(master.empty() ? origin : master.back().cycle.sample_time_ns,
                                     slave.empty() ? origin : slave.back().cycle.sample_time_ns);
  Chart chart = position_force_chart(
      "Recorded session: positions and forces of both nodes",
      fmt::format("{}: {} master and {} slave cycles over {:.3f} s", a.file, master.size(),
                  slave.size(), static_cast<double>(last - origin) * 1e-9));
  if (!master.empty()) add_node_traces(chart, master, origin, "master", 0);
  if (!slave.empty()) add_node_traces(chart, slave, origin, "slave", 1);
  // The fixtures of the recorded configuration, where the positions meet them.
  if (const std::optional<config::LoadedConfig> cfg = record::recorded_config(session)) {
    if (cfg->config.has_gains()) {
      const TeleopParams p = config::to_teleop_params(*cfg);
      const double t_end = static_cast<double>(last - origin) * 1e-9;
      const std::pair<const char*, const FixtureParams*> fixtures[] = {
          {"master", &p.master_fixture}, {"slave", &p.slave_fixture}};
      for (std::size_t i = 0; i < 2; ++i) {
        const FixtureParams& f = *fixtures[i].second;
        if (!(f.stiffness_N_per_m > 0.0)) continue;
        add_level(chart, 0,
                  fmt::format("{} fixture ({:g} N/m)", fixtures[i].first, f.stiffness_N_per_m),
                  1e3 * f.position_m, 0.0, t_end, line_colour(i));
      }
    }
  }
  chart.notes.push_back(
      "the slave's load cell reads its push on the environment; lines break where cycles are "
      "missing");
  write_svg(a.plot_path, chart);
  out << "wrote " << a.plot_path << "\n";
  return kExitOk;
}

// --- --recover -----------------------------------------------------------------------------

// The three passes of --recover in the time they take (measured on a 94 MB session cut short):
// the scan of the damaged file 0.16 s, the copy of what it keeps 0.30 s, the count of the
// written file 0.14 s.
constexpr double kRecoverScan = 0.16;
constexpr double kRecoverCopy = 0.30;
constexpr double kRecoverCount = 0.14;

int recover(const ReplayArgs& a, std::ostream& out, std::ostream& err) {
  if (!std::filesystem::exists(a.file)) {
    throw std::runtime_error(fmt::format("{}: no such file", a.file));
  }
  if (std::filesystem::exists(a.recover_path) &&
      std::filesystem::equivalent(a.file, a.recover_path)) {
    throw std::runtime_error(
        fmt::format("--recover {}: the output must not be the damaged file itself", a.file));
  }
  std::map<std::string, std::uint64_t> per_topic;
  std::optional<record::McapReader> reopened;
  record::RecoveryReport r;
  {
    // Erased (leaving scope) before anything is printed.
    ProgressLine progress(err, "replay --recover", !a.json && stderr_is_terminal());
    ProgressParts parts(progress, kRecoverScan + kRecoverCopy + kRecoverCount);
    const auto scanned = parts.bytes(kRecoverScan);
    const auto copied = parts.bytes(kRecoverCopy);
    r = record::recover_file(a.file, a.recover_path, scanned, copied);
    reopened.emplace(record::McapReader::open(a.recover_path));
    for (const auto& [id, ch] : reopened->channels()) per_topic[ch.topic] = 0;
    const auto counted = parts.bytes(kRecoverCount);
    const std::uint64_t size = reopened->file_size();
    reopened->for_each_message(record::Order::kFile, [&](const record::MessageView& m) {
      ++per_topic[m.channel->topic];
      if (counted) counted(m.record_offset, size);
    });
  }
  const record::McapReader& written = *reopened;
  std::optional<std::pair<std::uint64_t, std::uint64_t>> span;  // log times kept
  if (written.statistics() && written.statistics()->message_count > 0) {
    span.emplace(written.statistics()->message_start_time, written.statistics()->message_end_time);
  }
  if (a.json) {
    json j = {{"file", a.file},
              {"out", a.recover_path},
              {"file_size", r.file_size},
              {"chunks", r.chunks},
              {"messages", r.messages},
              {"data_end", r.data_end},
              {"bytes_dropped", r.file_size - r.data_end},
              {"complete", r.complete},
              {"stopped", r.stopped},
              {"first_log_time_ns", span ? json(span->first) : json(nullptr)},
              {"last_log_time_ns", span ? json(span->second) : json(nullptr)},
              {"topics", per_topic}};
    out << j.dump(2) << "\n";
    return kExitOk;
  }
  out << fmt::format(
      "{}: kept {} complete chunks, {} messages; the data is whole up to byte {} "
      "of {} ({} bytes dropped)\n",
      a.file, r.chunks, r.messages, r.data_end, r.file_size, r.file_size - r.data_end);
  out << (r.complete ? std::string("  the data section was complete (only the summary was "
                                   "rebuilt)\n")
                     : fmt::format("  stopped: {}\n", r.stopped));
  if (span) {
    out << fmt::format("  the messages kept span {:.3f} s (log times {} to {} ns)\n",
                       seconds_since(span->second, span->first), span->first, span->second);
  }
  for (const auto& [topic, n] : per_topic) out << fmt::format("  {:<32} {:>8}\n", topic, n);
  out << fmt::format("wrote {}\n", a.recover_path);
  return kExitOk;
}

// --- --resimulate --------------------------------------------------------------------------

[[nodiscard]] json oscillation_json(const scene::Oscillation& o) {
  return {{"detected", o.detected},
          {"amplitude_m", o.amplitude_m},
          {"frequency_hz", o.frequency_hz},
          {"previous_amplitude_m", o.previous_amplitude_m}};
}

[[nodiscard]] json outcome_json(const scene::SlaveOutcome& o) {
  return {{"cycles", o.cycles},
          {"tracking_error_rms_m", o.tracking_rms_m},
          {"max_penetration_slave_m", o.max_penetration_m},
          {"oscillation", oscillation_json(o.oscillation)},
          {"fault", o.fault}};
}

[[nodiscard]] bool coupled(node::Mode mode) {
  return mode == node::Mode::kEngaged || mode == node::Mode::kClutched;
}

// What happened: the recorded slave, measured as the resimulation will be.
[[nodiscard]] scene::SlaveOutcome recorded_outcome(const std::vector<record::RecordedCycle>& slave,
                                                   const TeleopParams& params,
                                                   const device::SimDeviceConfig& slave_device) {
  scene::SlaveOutcomeMeter before{params.scaling.position, params.slave_fixture};
  for (const record::RecordedCycle& r : slave) {
    const node::CycleRecord& c = r.cycle;
    before.add(c.position_m,
               coupled(c.mode) ? std::optional<double>(c.peer_position_m) : std::nullopt);
  }
  return before.finish(1.0 / params.sample_rate_hz, scene::oscillation_threshold_m(slave_device));
}

// The recorded master motion as the resimulation replays it.
[[nodiscard]] std::vector<scene::MasterCycle> master_motion(
    const std::vector<record::RecordedCycle>& master) {
  std::vector<scene::MasterCycle> motion;
  motion.reserve(master.size());
  for (const record::RecordedCycle& r : master) {
    motion.push_back(
        {r.cycle.position_m, coupled(r.cycle.mode), r.cycle.mode == node::Mode::kClutched});
  }
  return motion;
}

void print_resimulation(const json& j, const ReplayArgs& a, const scene::SlaveOutcome& recorded,
                        const scene::SlaveOutcome& resimulated, std::ostream& out) {
  out << fmt::format(
      "{}: the recorded master motion ({} cycles, {:.3f} s) through the slave "
      "side of the law{}\n",
      a.file, j["master_cycles"].get<std::size_t>(), j["duration_s"].get<double>(),
      a.overrides.empty() ? " as recorded" : " with:");
  for (const std::string& o : a.overrides) out << "  --set " << o << "\n";
  const json& ra = j["recorded"]["analysis"];
  const json& na = j["resimulated"]["analysis"];
  auto num = [](const json& v, const char* f) {
    return v.is_null() ? std::string("-") : fmt::format(fmt::runtime(f), v.get<double>());
  };
  auto osc = [](const scene::SlaveOutcome& o) {
    return o.oscillation.detected
               ? fmt::format("sustained, {:.3g} mm at {:.3g} Hz", o.oscillation.amplitude_m * 1e3,
                             o.oscillation.frequency_hz)
               : fmt::format("none ({:.3g} mm)", o.oscillation.amplitude_m * 1e3);
  };
  out << fmt::format("  {:<34} {:<28} {}\n", "", "recorded", "resimulated");
  auto row = [&](const std::string& name, const std::string& x, const std::string& y) {
    out << fmt::format("  {:<34} {:<28} {}\n", name, x, y);
  };
  row("analyser verdict", ra["verdict"].get<std::string>(), na["verdict"].get<std::string>());
  row("min damping ratio", num(ra["min_damping_ratio"], "{:.4f}"),
      num(na["min_damping_ratio"], "{:.4f}"));
  row("slave fixture (N/m)", num(ra["slave_fixture_stiffness_N_per_m"], "{:.0f}"),
      num(na["slave_fixture_stiffness_N_per_m"], "{:.0f}"));
  row("max stable slave fixture (N/m)", num(ra["max_stable_slave_stiffness_N_per_m"], "{:.0f}"),
      num(na["max_stable_slave_stiffness_N_per_m"], "{:.0f}"));
  row("max stable master fixture (N/m)", num(ra["max_stable_master_stiffness_N_per_m"], "{:.0f}"),
      num(na["max_stable_master_stiffness_N_per_m"], "{:.0f}"));
  row("slave tracking error rms (mm)", fmt::format("{:.4g}", recorded.tracking_rms_m * 1e3),
      fmt::format("{:.4g}", resimulated.tracking_rms_m * 1e3));
  row("max slave fixture penetration (mm)", fmt::format("{:.4g}", recorded.max_penetration_m * 1e3),
      fmt::format("{:.4g}", resimulated.max_penetration_m * 1e3));
  row("slave oscillation", osc(recorded), osc(resimulated));
  if (resimulated.fault) out << "  the resimulated slave law latched a fault\n";
}

int resimulate(const record::SessionReader& session, const ReplayArgs& a, std::ostream& out,
               std::ostream& err) {
  // Erased before anything is printed (the output below comes after the analyses).
  std::optional<ProgressLine> progress;
  progress.emplace(err, "replay --resimulate", !a.json && stderr_is_terminal());
  const bool overrides = !a.overrides.empty();
  ProgressParts parts(*progress,
                      (overrides ? 2.0 : 1.0) * kConfigPass + 2.0 * kCyclesPass + kResimulation);
  const ResimulationRequest request{a.file, a.overrides, a.json};
  const ResimulationConfigs configs = resimulation_configs(session, request, parts);
  // Several task-space axes (issue 18): the n-axis laws and plant.
  if (config::configured_axes(configs.recorded.config) > 1) {
    return resimulate_axes(session, request, configs, parts, progress, out);
  }
  const config::LoadedConfig& cfg = configs.config;
  const std::vector<record::RecordedCycle> master = session.cycles(true, parts.bytes(kCyclesPass));
  const std::vector<record::RecordedCycle> slave = session.cycles(false, parts.bytes(kCyclesPass));
  if (master.empty()) {
    throw std::runtime_error(fmt::format("{}: no master cycles to replay ({} is empty or missing)",
                                         a.file, topic::kMasterTelemetry));
  }
  const TeleopParams params_before = config::to_teleop_params(configs.recorded);
  const TeleopParams params = config::to_teleop_params(cfg);
  // The law and the slave device as the lockstep simulator (with a scene) or a node builds them.
  const std::optional<config::Resimulation> setup =
      config::to_resimulation(cfg, configs.recorded, master.front().cycle.position_m,
                              slave.empty() ? 0.0 : slave.front().cycle.position_m);
  if (!setup) {
    throw std::runtime_error(
        fmt::format("{}: a force device scene has no slave to resimulate", a.file));
  }
  const scene::SlaveOutcome before = recorded_outcome(slave, params_before, setup->recorded_slave);
  // What would have happened: the recorded master motion through the slave side of the law.
  const scene::SlaveOutcome after =
      scene::resimulate(setup->setup, master_motion(master), parts.fraction(kResimulation));

  const double period_s = 1.0 / params.sample_rate_hz;
  json j = {{"file", a.file},
            {"overrides", a.overrides},
            {"master_cycles", master.size()},
            {"duration_s", static_cast<double>(master.size()) * period_s},
            {"round_trip_samples", setup->setup.round_trip_delay_samples},
            {"recorded",
             {{"analysis", guard_analysis_json(params_before)}, {"outcome", outcome_json(before)}}},
            {"resimulated",
             {{"analysis", guard_analysis_json(params)}, {"outcome", outcome_json(after)}}}};
  progress.reset();
  if (a.json) {
    out << j.dump(2) << "\n";
  } else {
    print_resimulation(j, a, before, after, out);
  }
  return resimulation_exit_code(after.fault, after.oscillation.detected,
                                j["resimulated"]["analysis"]["verdict"].get<std::string>());
}

int run(const ReplayArgs& a, std::ostream& out, std::ostream& err) {
  if (a.action == Action::kRecover) return recover(a, out, err);
  const record::SessionReader session = record::SessionReader::open(a.file);
  switch (a.action) {
    case Action::kSummary: {
      const json j = summary_json(session);
      if (a.json) {
        out << j.dump(2) << "\n";
      } else {
        print_summary(j, out);
      }
      return kExitOk;
    }
    case Action::kPrint:
      return print_channel(session, a, out);
    case Action::kCsv:
      return write_cycles_csv(session, a, out);
    case Action::kLive:
      return replay_live(session, a, out, err);
    case Action::kResimulate:
      return resimulate(session, a, out, err);
    case Action::kPlot:
      return write_session_plot(session, a, out);
    case Action::kRecover:
      break;
  }
  return kExitOk;
}

}  // namespace

std::string replay_usage() {
  return "usage: teleopctl replay FILE.mcap [--json]\n"
         "       teleopctl replay FILE.mcap --print CHANNEL [--json]\n"
         "       teleopctl replay FILE.mcap --csv [--out FILE.csv]\n"
         "       teleopctl replay FILE.mcap --recover OUT.mcap [--json]\n"
         "       teleopctl replay FILE.mcap --speed X [--control ENDPOINT] [--paused] [--hold]\n"
         "                        [--master-telemetry EP] [--slave-telemetry EP] [--report EP]\n"
         "                        [--set PATH=VALUE]...\n"
         "       teleopctl replay FILE.mcap --resimulate [--set PATH=VALUE]... [--json]\n"
         "       teleopctl replay FILE.mcap --plot FILE.svg\n\n"
         "A recorded session (teleop-supervisor's, or 'teleopctl simulate --out FILE.mcap').\n"
         "  (default)      summary: duration, channels with message counts and schemas, recorder\n"
         "                 drops when known, node cycles and cycles missing (sequence gaps), "
         "alarms,\n"
         "                 parameter changes and the stability margin over time\n"
         "  --print CH     every message of channel CH, one per line with its log time: protobuf\n"
         "                 text, or with --json {\"log_time_ns\":N,\"message\":{...}}\n"
         "  --csv          every cycle of both nodes as CSV (node, time_s from the master's first\n"
         "                 cycle, sequence, mode, position_m, velocity_m_per_s, force_N, "
         "command_N,\n"
         "                 peer_sequence, peer_position_m, ..., round_trip_ns), master rows first\n"
         "  --recover OUT  writes a valid file from a damaged or cut-short one: every complete\n"
         "                 chunk whose CRC checks, and says where the good data ended\n"
         "  --speed X      re-publishes the session as if live at X times real time: telemetry on\n"
         "                 the master's and slave's telemetry endpoints, stability reports and\n"
         "                 alarms on the supervisor's report endpoint (multipart "
         "'report'|'alarm',\n"
         "                 message), from the recorded /config unless --set or the endpoint flags\n"
         "                 say otherwise. Control (REQ/REP, plain text) on --control (default\n"
         "                 tcp://127.0.0.1:5568): pause, resume, toggle, seek SECONDS (+S, -S:\n"
         "                 from here), speed X (xF: times the speed in force), status, stop;\n"
         "                 each reply gives the position. --paused starts paused; --hold\n"
         "                 keeps the control endpoint up at the end until 'stop'. Ten times a\n"
         "                 second, playing, paused or held, the report endpoint also carries the\n"
         "                 supervisor's summary stream ('status'|teleop.v1.SupervisorStatus, "
         "source\n"
         "                 \"replay\", the nodes as recorded at the position, the replay's "
         "state),\n"
         "                 so 'teleopctl console' shows a replay as it shows a live session\n"
         "  --resimulate   the recorded master motion through the slave side of the law and the\n"
         "                 simulated slave, with the recorded /config plus --set overrides: the\n"
         "                 analyser's verdict and limits, slave tracking error, fixture\n"
         "                 penetration and oscillation, next to what the recording shows;\n"
         "                 several axes: both n-axis laws, and per axis how far the resimulated\n"
         "                 slave's position and command are from the recorded ones\n"
         "  --plot F.svg   both nodes' positions (mm) and load-cell forces (N) against time, two\n"
         "                 panels (render a PNG with 'rsvg-convert -o F.png F.svg')\n"
         "Exit: 0 ok, 1 bad file (not MCAP, damaged: try --recover) or unknown channel, 2 usage;\n"
         "--resimulate: 3 the resimulated slave oscillates or the analyser calls the resimulated\n"
         "loop unstable, 4 the analysis is uncertain, 5 its law latched a fault, 1 the\n"
         "resimulated model is not finite (invalid).\n";
}

int run_replay(const std::vector<std::string>& args, std::ostream& out, std::ostream& err) {
  return run_parsed("replay", args, replay_usage, out, err, parse_replay_args,
                    [&](const ReplayArgs& a) { return run(a, out, err); });
}

}  // namespace teleop::ctl
