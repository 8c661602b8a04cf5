#include "supervisor/teleopctl/replay_command.hpp"

#include <fmt/format.h>
#include <google/protobuf/descriptor.h>
#include <google/protobuf/descriptor.pb.h>
#include <google/protobuf/dynamic_message.h>
#include <google/protobuf/text_format.h>
#include <google/protobuf/util/json_util.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <deque>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <numbers>
#include <optional>
#include <ostream>
#include <stdexcept>
#include <vector>
#include <zmq.hpp>

#include "common/config/config_loader.hpp"
#include "common/config/node_loader.hpp"
#include "common/config/scene_loader.hpp"
#include "common/control/master_law.hpp"
#include "common/control/slave_law.hpp"
#include "common/control/velocity_estimator.hpp"
#include "common/device/sim_device.hpp"
#include "common/record/mcap_reader.hpp"
#include "common/scene/lockstep.hpp"
#include "common/scene/oscillation.hpp"
#include "common/transport/zmq_security.hpp"
#include "common/transport/zmq_sockets.hpp"
#include "supervisor/core/monitors.hpp"
#include "supervisor/core/stability_guard.hpp"
#include "supervisor/core/status_builder.hpp"
#include "supervisor/teleopctl/cli_args.hpp"
#include "teleop/v1/config.pb.h"
#include "teleop/v1/supervisor.pb.h"
#include "teleop/v1/telemetry.pb.h"

namespace teleop::ctl {

namespace {

using nlohmann::json;
namespace pb = google::protobuf;

constexpr const char* kConfigTopic = "/config";
constexpr const char* kMasterTopic = "/master/telemetry";
constexpr const char* kSlaveTopic = "/slave/telemetry";
constexpr const char* kStabilityTopic = "/supervisor/stability";
constexpr const char* kAlarmTopic = "/supervisor/alarms";
constexpr const char* kChangeTopic = "/supervisor/parameter_changes";
constexpr const char* kStatusTopic = "/supervisor/status";
constexpr const char* kDefaultControl = "tcp://127.0.0.1:5568";
constexpr const char* kDefaultReport = "tcp://127.0.0.1:5566";

// --- arguments -----------------------------------------------------------------------------

enum class Action { kSummary, kPrint, kCsv, kRecover, kLive, kResimulate };

struct ReplayArgs {
  std::string file{};
  Action action{Action::kSummary};
  bool json{false};
  std::string channel{};                  // --print
  std::optional<std::string> out_path{};  // --csv --out
  std::string recover_path{};             // --recover
  double speed{1.0};                      // --speed
  std::string control{kDefaultControl};
  std::optional<std::string> master_endpoint{};
  std::optional<std::string> slave_endpoint{};
  std::optional<std::string> report_endpoint{};
  bool start_paused{false};
  bool hold{false};
  std::vector<std::string> overrides{};  // --set
};

void set_action(ReplayArgs& a, Action action, bool& chosen, const std::string& flag) {
  if (chosen && a.action != action) {
    throw UsageError(
        fmt::format("{} cannot be combined with another of --print, --csv, "
                    "--recover, --speed, --resimulate",
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
    } else if (arg == "--set") {
      a.overrides.push_back(c.value("--set"));
    } else if (arg.rfind("--set=", 0) == 0) {
      a.overrides.push_back(arg.substr(6));
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
    } else if (!arg.empty() && arg.front() == '-') {
      throw UsageError(fmt::format("unknown option '{}'", arg));
    } else if (a.file.empty()) {
      a.file = arg;
    } else {
      throw UsageError(fmt::format("unexpected argument '{}'", arg));
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
  if (a.json && (a.action == Action::kCsv || a.action == Action::kLive)) {
    throw UsageError("--json goes with the summary, --print, --recover or --resimulate");
  }
  return a;
}

// --- reading -------------------------------------------------------------------------------

[[nodiscard]] record::McapReader open_session(const std::string& path) {
  if (!std::filesystem::exists(path)) {
    throw std::runtime_error(fmt::format("{}: no such file", path));
  }
  try {
    return record::McapReader::open(path);
  } catch (const record::McapError& e) {
    if (!is_mcap_file(path)) throw;
    throw std::runtime_error(fmt::format(
        "{}\n(the file was cut short or damaged: 'teleopctl replay --recover OUT.mcap {}' keeps "
        "every complete chunk)",
        e.what(), path));
  }
}

// Every message of `topic`, in log-time order; empty when there is no such channel.
[[nodiscard]] std::vector<record::MessageView> messages_on(const record::McapReader& reader,
                                                           const std::string& topic) {
  std::vector<record::MessageView> out;
  reader.for_each_message(record::Order::kLogTime, [&](const record::MessageView& m) {
    if (m.channel->topic == topic) out.push_back(m);
  });
  return out;
}

template <typename T>
[[nodiscard]] T decode(const record::McapReader& reader, const record::MessageView& m) {
  const std::string& want = T::descriptor()->full_name();
  if (m.schema == nullptr || m.schema->name != want) {
    throw std::runtime_error(fmt::format("{}: channel {} carries {}, not {}",
                                         reader.path().string(), m.channel->topic,
                                         m.schema ? m.schema->name : "no schema", want));
  }
  T t;
  if (!t.ParseFromArray(m.data.data(), static_cast<int>(m.data.size()))) {
    throw std::runtime_error(fmt::format("{}: {} message at log time {} ns does not decode as {}",
                                         reader.path().string(), m.channel->topic, m.log_time_ns,
                                         want));
  }
  return t;
}

[[nodiscard]] std::string channel_list(const record::McapReader& reader) {
  std::string s;
  for (const auto& [id, ch] : reader.channels()) s += (s.empty() ? "" : ", ") + ch.topic;
  return s.empty() ? "none" : s;
}

[[nodiscard]] bool has_topic(const record::McapReader& reader, const std::string& topic) {
  for (const auto& [id, ch] : reader.channels()) {
    if (ch.topic == topic) return true;
  }
  return false;
}

[[nodiscard]] std::uint64_t first_log_time(const record::McapReader& reader) {
  if (reader.statistics() && reader.statistics()->message_count > 0) {
    return reader.statistics()->message_start_time;
  }
  std::uint64_t t = UINT64_MAX;
  reader.for_each_message(record::Order::kFile,
                          [&](const record::MessageView& m) { t = std::min(t, m.log_time_ns); });
  return t == UINT64_MAX ? 0 : t;
}

[[nodiscard]] std::uint64_t last_log_time(const record::McapReader& reader) {
  if (reader.statistics() && reader.statistics()->message_count > 0) {
    return reader.statistics()->message_end_time;
  }
  std::uint64_t t = 0;
  reader.for_each_message(record::Order::kFile,
                          [&](const record::MessageView& m) { t = std::max(t, m.log_time_ns); });
  return t;
}

[[nodiscard]] double seconds_since(std::uint64_t t, std::uint64_t t0) {
  return t >= t0 ? static_cast<double>(t - t0) * 1e-9 : -static_cast<double>(t0 - t) * 1e-9;
}

// The recorded configuration, with --set overrides applied (and validated).
[[nodiscard]] std::optional<config::LoadedConfig> recorded_config(
    const record::McapReader& reader, const std::vector<std::string>& overrides) {
  const std::vector<record::MessageView> m = messages_on(reader, kConfigTopic);
  if (m.empty()) {
    if (!overrides.empty()) {
      throw std::runtime_error(
          fmt::format("{}: no /config channel to apply --set to", reader.path().string()));
    }
    return std::nullopt;
  }
  const v1::SystemConfig recorded = decode<v1::SystemConfig>(reader, m.back());
  std::string text;
  pb::TextFormat::PrintToString(recorded, &text);
  return config::load_config_text(text, reader.path().string() + " (/config)", overrides);
}

// --- summary -------------------------------------------------------------------------------

struct SideStats {
  std::uint64_t messages{0};
  std::uint64_t cycles{0};
  std::uint64_t missing{0};
  std::uint64_t restarts{0};
  std::uint64_t out_of_order{0};
  std::uint64_t cycles_dropped{0};  // the node's own count (telemetry queue)
  std::uint64_t flight_records{0};
  std::uint64_t first_sequence{0};
  std::uint64_t last_sequence{0};
  std::uint64_t session_id{0};
  bool any{false};
  std::map<std::string, std::uint64_t> modes{};
  // Wake-up latency of every cycle, and per second of the node's clock its cycles and the
  // deadlines it skipped (overruns: a cycle's sample time is its deadline on the loop's grid,
  // so a gap of n periods means n - 1 skipped; within one session).
  std::vector<std::int64_t> wakeups_ns{};
  std::map<std::int64_t, std::pair<std::uint64_t, std::uint64_t>> per_second{};
  std::int64_t last_sample_ns{0};

  void add(const v1::Telemetry& t) {
    ++messages;
    cycles_dropped = std::max(cycles_dropped, t.cycles_dropped());
    if (t.flight_record_size() > 0) ++flight_records;
    const double period_ns = t.loop().period_s() * 1e9;
    for (const v1::CycleRecord& c : t.cycles()) {
      ++cycles;
      ++modes[v1::NodeMode_Name(c.mode())];
      wakeups_ns.push_back(c.wakeup_latency_ns());
      auto& second = per_second[c.sample_time_ns() / 1'000'000'000];
      ++second.first;
      if (any && t.session_id() == session_id && c.sequence() == last_sequence + 1 &&
          period_ns > 0.0 && c.sample_time_ns() > last_sample_ns) {
        const double periods = static_cast<double>(c.sample_time_ns() - last_sample_ns) / period_ns;
        const auto skipped = static_cast<std::int64_t>(std::llround(periods)) - 1;
        if (skipped > 0) second.second += static_cast<std::uint64_t>(skipped);
      }
      last_sample_ns = c.sample_time_ns();
      if (!any) {
        first_sequence = c.sequence();
        session_id = t.session_id();
      } else if (t.session_id() != session_id) {
        ++restarts;
        session_id = t.session_id();
      } else if (c.sequence() > last_sequence + 1) {
        missing += c.sequence() - last_sequence - 1;
      } else if (c.sequence() <= last_sequence) {
        ++out_of_order;
      }
      any = true;
      last_sequence = c.sequence();
    }
  }
  [[nodiscard]] json to_json() const {
    return {{"telemetry_messages", messages},
            {"cycles", cycles},
            {"cycles_missing", missing},
            {"cycles_out_of_order", out_of_order},
            {"restarts", restarts},
            {"cycles_dropped_by_node", cycles_dropped},
            {"flight_records", flight_records},
            {"first_sequence", any ? json(first_sequence) : json(nullptr)},
            {"last_sequence", any ? json(last_sequence) : json(nullptr)},
            {"modes", modes},
            {"wakeup_latency", wakeup_json()},
            {"overruns", overruns_json()}};
  }
  // Nearest-rank quantiles and a histogram of every cycle's wake-up latency.
  [[nodiscard]] json wakeup_json() const {
    if (wakeups_ns.empty()) return nullptr;
    std::vector<std::int64_t> v = wakeups_ns;
    std::sort(v.begin(), v.end());
    const auto quantile_us = [&v](double q) {
      const auto rank = static_cast<std::size_t>(std::ceil(q * static_cast<double>(v.size())));
      return static_cast<double>(v[std::clamp<std::size_t>(rank, 1, v.size()) - 1]) * 1e-3;
    };
    json bins = json::array();
    const std::int64_t edges_us[] = {0, 50, 100, 200, 500, 1000, 2000, 5000};
    const std::size_t n = std::size(edges_us);
    for (std::size_t i = 0; i < n; ++i) {
      const std::int64_t lo = edges_us[i] * 1000;
      const bool last = i + 1 == n;
      const std::int64_t hi = last ? 0 : edges_us[i + 1] * 1000;
      const auto from = std::lower_bound(v.begin(), v.end(), lo);
      const auto to = last ? v.end() : std::lower_bound(v.begin(), v.end(), hi);
      bins.push_back({{"from_us", edges_us[i]},
                      {"to_us", last ? json(nullptr) : json(edges_us[i + 1])},
                      {"cycles", static_cast<std::uint64_t>(to - from)}});
    }
    // Negative latencies (a clock step) are not binned above; counted apart.
    const auto negative = static_cast<std::uint64_t>(
        std::lower_bound(v.begin(), v.end(), std::int64_t{0}) - v.begin());
    return {{"p50_us", quantile_us(0.5)},
            {"p99_us", quantile_us(0.99)},
            {"p999_us", quantile_us(0.999)},
            {"max_us", static_cast<double>(v.back()) * 1e-3},
            {"histogram", bins},
            {"negative", negative}};
  }
  // Skipped deadlines in all, and how many seconds (with at least one cycle recorded) had how
  // many.
  [[nodiscard]] json overruns_json() const {
    std::uint64_t total = 0;
    std::uint64_t worst = 0;
    const std::uint64_t edges[] = {0, 1, 2, 10, 100};
    std::vector<std::uint64_t> seconds(std::size(edges), 0);
    for (const auto& [second, counts] : per_second) {
      total += counts.second;
      worst = std::max(worst, counts.second);
      std::size_t bin = 0;
      while (bin + 1 < std::size(edges) && counts.second >= edges[bin + 1]) ++bin;
      ++seconds[bin];
    }
    json bins = json::array();
    for (std::size_t i = 0; i < std::size(edges); ++i) {
      const bool last = i + 1 == std::size(edges);
      bins.push_back({{"from", edges[i]},
                      {"to", last ? json(nullptr) : json(edges[i + 1] - 1)},
                      {"seconds", seconds[i]}});
    }
    return {{"total", total},
            {"seconds", per_second.size()},
            {"worst_second", worst},
            {"seconds_histogram", bins}};
  }
};

[[nodiscard]] json optional_number(bool has, double v) { return has ? json(v) : json(nullptr); }

[[nodiscard]] json summary_json(const record::McapReader& reader) {
  const std::uint64_t t0 = first_log_time(reader);
  const std::uint64_t t1 = last_log_time(reader);
  std::map<std::uint16_t, std::uint64_t> counts;
  SideStats master;
  SideStats slave;
  json alarms = json::array();
  std::map<std::string, std::uint64_t> by_severity;
  json changes = json::array();
  json stability = json::array();
  std::optional<std::uint64_t> drops;
  std::string drops_source;
  std::uint64_t total = 0;
  reader.for_each_message(record::Order::kLogTime, [&](const record::MessageView& m) {
    ++counts[m.channel->id];
    ++total;
    const std::string& topic = m.channel->topic;
    const double t = seconds_since(m.log_time_ns, t0);
    if (topic == kMasterTopic || topic == kSlaveTopic) {
      (topic == kMasterTopic ? master : slave).add(decode<v1::Telemetry>(reader, m));
    } else if (topic == kAlarmTopic) {
      const v1::Alarm a = decode<v1::Alarm>(reader, m);
      const std::string severity = v1::Alarm::Severity_Name(a.severity());
      ++by_severity[severity];
      json evidence = json::array();
      for (const v1::Evidence& e : a.evidence()) {
        evidence.push_back({{"name", e.name()}, {"value", e.value()}, {"unit", e.unit()}});
      }
      alarms.push_back({{"time_s", t},
                        {"severity", severity},
                        {"kind", a.kind()},
                        {"side", a.side()},
                        {"message", a.message()},
                        {"action", a.action()},
                        {"master_sequence", a.master_sequence()},
                        {"evidence", evidence}});
    } else if (topic == kChangeTopic) {
      const v1::ParameterChangeRecord r = decode<v1::ParameterChangeRecord>(reader, m);
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
        requested["gains"] = {{"kpm", g.kpm()}, {"kps", g.kps()}, {"kdm", g.kdm()},
                              {"kds", g.kds()}, {"kvm", g.kvm()}, {"kvs", g.kvs()},
                              {"kfm", g.kfm()}};
      }
      changes.push_back({{"time_s", t},
                         {"requested_by", q.requested_by()},
                         {"dry_run", q.dry_run()},
                         {"requested", requested},
                         {"accepted", r.reply().accepted()},
                         {"change_id", r.reply().change_id()},
                         {"apply_at_master_sequence", r.reply().apply_at_master_sequence()},
                         {"reason", r.reply().reason()}});
    } else if (topic == kStabilityTopic) {
      const v1::StabilityReport s = decode<v1::StabilityReport>(reader, m);
      stability.push_back(
          {{"time_s", t},
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
           {"reason", s.reason()}});
    }
    // The recorder's drops, from the newest supervisor message that carries them.
    if (topic.rfind("/supervisor/", 0) == 0 && m.schema != nullptr) {
      const pb::Descriptor* d =
          pb::DescriptorPool::generated_pool()->FindMessageTypeByName(m.schema->name);
      const pb::FieldDescriptor* f = d ? d->FindFieldByName("recording_drops") : nullptr;
      if (f != nullptr && f->cpp_type() == pb::FieldDescriptor::CPPTYPE_UINT64) {
        std::unique_ptr<pb::Message> msg(
            pb::MessageFactory::generated_factory()->GetPrototype(d)->New());
        if (msg->ParseFromArray(m.data.data(), static_cast<int>(m.data.size()))) {
          drops = msg->GetReflection()->GetUInt64(*msg, f);
          drops_source = topic;
        }
      }
    }
  });
  json channels = json::array();
  for (const auto& [id, ch] : reader.channels()) {
    const auto s = reader.schemas().find(ch.schema_id);
    channels.push_back(
        {{"topic", ch.topic},
         {"schema", s == reader.schemas().end() ? json(nullptr) : json(s->second.name)},
         {"message_encoding", ch.message_encoding},
         {"messages", counts[id]}});
  }
  json j = {{"file", reader.path().string()},
            {"file_size", reader.file_size()},
            {"library", reader.header().library},
            {"indexed", reader.indexed()},
            {"messages", total},
            {"start_log_time_ns", t0},
            {"end_log_time_ns", t1},
            {"duration_s", total > 0 ? seconds_since(t1, t0) : 0.0},
            {"channels", channels},
            {"recorder_drops", drops ? json(*drops) : json(nullptr)},
            {"recorder_drops_source", drops ? json(drops_source) : json(nullptr)},
            {"nodes", {{"master", master.to_json()}, {"slave", slave.to_json()}}},
            {"alarms", {{"count", alarms.size()}, {"by_severity", by_severity}, {"list", alarms}}},
            {"parameter_changes", changes},
            {"stability", stability}};
  return j;
}

[[nodiscard]] std::string margin_text(const json& v) {
  return v.is_null() ? "-" : fmt::format("{:.3f}", v.get<double>());
}

void print_summary(const json& j, std::ostream& out) {
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
  }
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
  const json& st = j["stability"];
  out << fmt::format("stability: {} report{}\n", st.size(), st.size() == 1 ? "" : "s");
  if (st.empty()) return;
  out << "  time (s)  verdict    min zeta  round trip  slave margin  master margin  reports\n";
  // Compact: a row per change of verdict, round trip or (by 0.001) damping ratio or margins.
  std::size_t i = 0;
  while (i < st.size()) {
    std::size_t k = i + 1;
    auto same = [&](const json& a, const json& b) {
      auto close = [](const json& x, const json& y) {
        if (x.is_null() || y.is_null()) return x.is_null() == y.is_null();
        return std::abs(x.get<double>() - y.get<double>()) < 1e-3;
      };
      return a["verdict"] == b["verdict"] && a["round_trip_samples"] == b["round_trip_samples"] &&
             close(a["min_damping_ratio"], b["min_damping_ratio"]) &&
             close(a["slave_margin"], b["slave_margin"]) &&
             close(a["master_margin"], b["master_margin"]);
    };
    while (k < st.size() && same(st[i], st[k])) ++k;
    const json& r = st[i];
    out << fmt::format("  {:>8.3f}  {:<9}  {:>8.4f}  {:>10}  {:>12}  {:>13}  {}\n",
                       r["time_s"].get<double>(), r["verdict"].get<std::string>(),
                       r["min_damping_ratio"].get<double>(), r["round_trip_samples"].get<int>(),
                       margin_text(r["slave_margin"]), margin_text(r["master_margin"]), k - i);
    i = k;
  }
}

// --- --print -------------------------------------------------------------------------------

// Messages of a schema, decoded through the FileDescriptorSet the file carries (so files of
// other versions print too).
class SchemaDecoder {
 public:
  explicit SchemaDecoder(const record::Schema& schema) {
    if (schema.encoding != "protobuf") {
      throw std::runtime_error(
          fmt::format("schema '{}' has encoding '{}', not protobuf", schema.name, schema.encoding));
    }
    pb::FileDescriptorSet set;
    if (!set.ParseFromString(schema.data)) {
      throw std::runtime_error(
          fmt::format("schema '{}': its FileDescriptorSet does not parse", schema.name));
    }
    for (const pb::FileDescriptorProto& f : set.file()) {
      if (pool_.BuildFile(f) == nullptr) {
        throw std::runtime_error(
            fmt::format("schema '{}': file {} does not build", schema.name, f.name()));
      }
    }
    const pb::Descriptor* d = pool_.FindMessageTypeByName(schema.name);
    if (d == nullptr) {
      throw std::runtime_error(
          fmt::format("schema '{}': no such message in its descriptors", schema.name));
    }
    prototype_ = factory_.GetPrototype(d);
  }
  [[nodiscard]] std::unique_ptr<pb::Message> decode(std::string_view data) const {
    std::unique_ptr<pb::Message> m(prototype_->New());
    if (!m->ParseFromArray(data.data(), static_cast<int>(data.size()))) return nullptr;
    return m;
  }

 private:
  pb::DescriptorPool pool_{};
  pb::DynamicMessageFactory factory_{&pool_};
  const pb::Message* prototype_{nullptr};
};

int print_channel(const record::McapReader& reader, const ReplayArgs& a, std::ostream& out) {
  if (!has_topic(reader, a.channel)) {
    throw std::runtime_error(
        fmt::format("{}: no channel '{}' (channels: {})", a.file, a.channel, channel_list(reader)));
  }
  std::map<std::uint16_t, std::unique_ptr<SchemaDecoder>> decoders;
  pb::TextFormat::Printer printer;
  printer.SetSingleLineMode(true);
  pb::util::JsonPrintOptions options;
  options.preserve_proto_field_names = true;
  reader.for_each_message(record::Order::kLogTime, [&](const record::MessageView& m) {
    if (m.channel->topic != a.channel) return;
    if (m.schema == nullptr) {
      throw std::runtime_error(fmt::format("{}: channel {} has no schema", a.file, a.channel));
    }
    auto& d = decoders[m.schema->id];
    if (!d) d = std::make_unique<SchemaDecoder>(*m.schema);
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

int write_cycles_csv(const record::McapReader& reader, const ReplayArgs& a, std::ostream& out) {
  if (!has_topic(reader, kMasterTopic) && !has_topic(reader, kSlaveTopic)) {
    throw std::runtime_error(fmt::format("{}: no {} or {} channel (channels: {})", a.file,
                                         kMasterTopic, kSlaveTopic, channel_list(reader)));
  }
  std::ofstream file;
  std::ostream* os = &out;
  if (a.out_path) {
    file.open(*a.out_path);
    if (!file) throw std::runtime_error(fmt::format("cannot write '{}'", *a.out_path));
    os = &file;
  }
  const std::vector<record::MessageView> master = messages_on(reader, kMasterTopic);
  const std::vector<record::MessageView> slave = messages_on(reader, kSlaveTopic);
  // Time from the master's first cycle (the slave's when there is no master).
  std::optional<std::int64_t> origin;
  for (const std::vector<record::MessageView>* side : {&master, &slave}) {
    for (const record::MessageView& m : *side) {
      const v1::Telemetry t = decode<v1::Telemetry>(reader, m);
      if (t.cycles_size() > 0) {
        origin = t.cycles(0).sample_time_ns();
        break;
      }
    }
    if (origin) break;
  }
  *os << "node,time_s,sequence,mode,position_m,velocity_m_per_s,force_N,command_N,"
         "peer_sequence,peer_position_m,peer_age_ns,coupling_weight,flags,wakeup_latency_ns,"
         "round_trip_ns,master_sequence,parameter_change_id\n";
  std::string line;
  for (const std::vector<record::MessageView>* side : {&master, &slave}) {
    const char* node = side == &master ? "master" : "slave";
    for (const record::MessageView& m : *side) {
      const v1::Telemetry t = decode<v1::Telemetry>(reader, m);
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

// --- --recover -----------------------------------------------------------------------------

int recover(const ReplayArgs& a, std::ostream& out) {
  if (!std::filesystem::exists(a.file)) {
    throw std::runtime_error(fmt::format("{}: no such file", a.file));
  }
  if (std::filesystem::exists(a.recover_path) &&
      std::filesystem::equivalent(a.file, a.recover_path)) {
    throw std::runtime_error(
        fmt::format("--recover {}: the output must not be the damaged file itself", a.file));
  }
  const record::RecoveryReport r = record::recover_file(a.file, a.recover_path);
  const record::McapReader written = record::McapReader::open(a.recover_path);
  std::map<std::string, std::uint64_t> per_topic;
  for (const auto& [id, ch] : written.channels()) per_topic[ch.topic] = 0;
  written.for_each_message(record::Order::kFile,
                           [&](const record::MessageView& m) { ++per_topic[m.channel->topic]; });
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

// --- --speed: re-published as if live ------------------------------------------------------

struct LiveItem {
  int kind{0};  // 0 master telemetry, 1 slave telemetry, 2 report, 3 alarm
  std::uint64_t log_time_ns{0};
  std::string_view data{};
};

// How the summary stream's monitors and node summaries are set up: as teleop-supervisor sets
// up its own from the same configuration (supervisor_app.cpp).
struct SummarySetup {
  double period_s{1e-3};
  double oscillation_threshold_m{0.0};
  FixtureParams master_fixture{};
  FixtureParams slave_fixture{};
};

[[nodiscard]] double encoder_count_m(const sim::EncoderParams& e) {
  return 2.0 * std::numbers::pi * e.metres_per_radian / (e.counts_per_rev * e.transmission_ratio);
}

[[nodiscard]] SummarySetup summary_setup(const std::optional<config::LoadedConfig>& cfg,
                                         std::ostream& err) {
  SummarySetup s;
  s.oscillation_threshold_m = 2.0 * encoder_count_m(sim::EncoderParams{});
  if (!cfg) return s;
  const v1::Supervisor& sup = cfg->config.supervisor();
  try {
    const TeleopParams params = config::to_teleop_params(*cfg);
    s.period_s = 1.0 / params.sample_rate_hz;
    s.master_fixture = params.master_fixture;
    s.slave_fixture = params.slave_fixture;
    // The master's encoder count, as the supervisor takes it.
    s.oscillation_threshold_m =
        2.0 * encoder_count_m(config::to_node_setup(*cfg, transport::Role::kMaster).sim.encoder);
  } catch (const std::exception& e) {
    err << fmt::format(
        "teleopctl replay: the recorded /config does not describe the teleoperator ({}); the "
        "summary stream's monitors use defaults\n",
        e.what());
  }
  if (sup.has_oscillation_threshold_m()) s.oscillation_threshold_m = sup.oscillation_threshold_m();
  return s;
}

// What the summary stream shows at a position of the replay: the file's messages up to that
// log time, fed as teleop-supervisor feeds what it receives (fill_status in supervisor_app.cpp),
// with the recorded log times for its clock.
class ReplaySummary {
 public:
  enum Kind { kMaster = 0, kSlave = 1, kReport = 2, kAlarm = 3, kRecordedStatus = 4 };
  struct Item {
    Kind kind{kMaster};
    std::uint64_t log_time_ns{0};
    std::string_view data{};
  };

  ReplaySummary(const SummarySetup& setup, std::vector<Item> items)
      : items_(std::move(items)),
        master_(true, setup.master_fixture, setup),
        slave_(false, setup.slave_fixture, setup) {}

  // Everything logged at or before `log_time_ns` applied; a time earlier than the last one (a
  // seek back) starts again from the beginning of the file.
  void advance_to(std::uint64_t log_time_ns) {
    if (log_time_ns < applied_until_ns_) reset();
    applied_until_ns_ = log_time_ns;
    while (next_ < items_.size() && items_[next_].log_time_ns <= log_time_ns) {
      apply(items_[next_]);
      ++next_;
    }
  }

  void fill(v1::SupervisorStatus& s) const {
    const auto now = static_cast<std::int64_t>(applied_until_ns_);
    s.set_time_ns(now);
    s.set_source("replay");
    if (report_) *s.mutable_report() = *report_;
    for (const v1::Alarm& a : alarms_) *s.add_recent_alarms() = a;
    if (recorded_) {
      s.set_recording_file(recorded_->recording_file());
      s.set_recorded_messages(recorded_->recorded_messages());
      s.set_recording_drops(recorded_->recording_drops());
      s.set_recording_bytes(recorded_->recording_bytes());
    }
    master_.fill(*s.mutable_master(), now);
    slave_.fill(*s.mutable_slave(), now);
    s.set_master_alive(s.master().alive());
    s.set_slave_alive(s.slave().alive());
    s.set_client_may_command(false);  // a replay cannot be commanded
  }

 private:
  static constexpr std::size_t kAlarmsShown = 20;

  struct Side {
    Side(bool is_master, const FixtureParams& fixture, const SummarySetup& setup)
        : is_master_side(is_master),
          builder(is_master, fixture.position_m, fixture.stiffness_N_per_m),
          oscillation(setup.period_s, 0.5, setup.oscillation_threshold_m),
          passivity(setup.period_s) {}
    void reset() {
      builder.reset();
      oscillation.clear();
      passivity.reset();
      session_id = 0;
    }
    void add(const v1::Telemetry& t, std::uint64_t log_time_ns) {
      // A restarted node (a new session) starts its summary again, as in the supervisor.
      if (session_id != 0 && t.session_id() != session_id) reset();
      session_id = t.session_id();
      for (const v1::CycleRecord& c : t.cycles()) {
        supervisor::feed_monitors(c, is_master_side, oscillation, passivity);
      }
      builder.add(t, static_cast<std::int64_t>(log_time_ns));
    }
    void fill(v1::NodeSummary& out, std::int64_t now_ns) const {
      builder.fill(out, now_ns, supervisor::read_monitors(oscillation, passivity));
    }
    bool is_master_side;
    supervisor::NodeSummaryBuilder builder;
    supervisor::OscillationMonitor oscillation;
    supervisor::PassivityObserver passivity;
    std::uint64_t session_id{0};
  };

  void reset() {
    master_.reset();
    slave_.reset();
    report_.reset();
    alarms_.clear();
    recorded_.reset();
    next_ = 0;
    applied_until_ns_ = 0;
  }

  // A message that does not decode is left out of the summary (it is still re-published).
  void apply(const Item& it) {
    const auto parse = [&](pb::Message& m) {
      return m.ParseFromArray(it.data.data(), static_cast<int>(it.data.size()));
    };
    switch (it.kind) {
      case kMaster:
      case kSlave: {
        v1::Telemetry t;
        if (parse(t)) (it.kind == kMaster ? master_ : slave_).add(t, it.log_time_ns);
        break;
      }
      case kReport: {
        v1::StabilityReport r;
        if (parse(r)) report_ = std::move(r);
        break;
      }
      case kAlarm: {
        v1::Alarm a;
        if (parse(a)) {
          alarms_.push_front(std::move(a));
          while (alarms_.size() > kAlarmsShown) alarms_.pop_back();
        }
        break;
      }
      case kRecordedStatus: {
        v1::SupervisorStatus st;
        if (parse(st)) recorded_ = std::move(st);
        break;
      }
    }
  }

  std::vector<Item> items_;
  std::size_t next_{0};
  std::uint64_t applied_until_ns_{0};
  Side master_;
  Side slave_;
  std::optional<v1::StabilityReport> report_{};
  std::deque<v1::Alarm> alarms_{};  // newest first
  std::optional<v1::SupervisorStatus> recorded_{};
};

// The messages the summary stream is built from, in log-time order: those of the topics it
// reads whose schema is the one it decodes.
[[nodiscard]] std::vector<ReplaySummary::Item> summary_items(const record::McapReader& reader) {
  std::vector<ReplaySummary::Item> items;
  reader.for_each_message(record::Order::kLogTime, [&](const record::MessageView& m) {
    const std::string& t = m.channel->topic;
    const std::string schema = m.schema ? m.schema->name : std::string();
    auto is = [&](const pb::Descriptor* d) { return schema == d->full_name(); };
    std::optional<ReplaySummary::Kind> kind;
    if (t == kMasterTopic && is(v1::Telemetry::descriptor())) kind = ReplaySummary::kMaster;
    if (t == kSlaveTopic && is(v1::Telemetry::descriptor())) kind = ReplaySummary::kSlave;
    if (t == kStabilityTopic && is(v1::StabilityReport::descriptor())) {
      kind = ReplaySummary::kReport;
    }
    if (t == kAlarmTopic && is(v1::Alarm::descriptor())) kind = ReplaySummary::kAlarm;
    if (t == kStatusTopic && is(v1::SupervisorStatus::descriptor())) {
      kind = ReplaySummary::kRecordedStatus;
    }
    if (kind) items.push_back({*kind, m.log_time_ns, m.data});
  });
  return items;
}

int replay_live(const record::McapReader& reader, const ReplayArgs& a, std::ostream& out,
                std::ostream& err) {
  const std::optional<config::LoadedConfig> cfg = recorded_config(reader, a.overrides);
  const v1::SystemConfig sc = cfg ? cfg->config : v1::SystemConfig{};
  auto endpoint = [](const std::optional<std::string>& flag, const std::string& configured,
                     const std::string& fallback) {
    if (flag) return *flag;
    return configured.empty() ? fallback : configured;
  };
  const std::string master_ep =
      endpoint(a.master_endpoint, sc.master().node().telemetry_endpoint(),
               config::default_endpoints(transport::Role::kMaster).telemetry);
  const std::string slave_ep =
      endpoint(a.slave_endpoint, sc.slave().node().telemetry_endpoint(),
               config::default_endpoints(transport::Role::kSlave).telemetry);
  const std::string report_ep =
      endpoint(a.report_endpoint, sc.supervisor().report_endpoint(), kDefaultReport);

  std::vector<LiveItem> items;
  reader.for_each_message(record::Order::kLogTime, [&](const record::MessageView& m) {
    const std::string& t = m.channel->topic;
    const int kind = t == kMasterTopic      ? 0
                     : t == kSlaveTopic     ? 1
                     : t == kStabilityTopic ? 2
                     : t == kAlarmTopic     ? 3
                                            : -1;
    if (kind >= 0) items.push_back({kind, m.log_time_ns, m.data});
  });
  const std::uint64_t t0 = first_log_time(reader);
  const double duration_s = seconds_since(last_log_time(reader), t0);
  auto pos_of = [&](std::size_t i) { return seconds_since(items[i].log_time_ns, t0); };
  ReplaySummary summary(summary_setup(cfg, err), summary_items(reader));

  // Plaintext (the replay holds no node's keys); off loopback only with security.insecure.
  transport::LinkSecurity security;
  security.insecure = sc.security().insecure();
  zmq::context_t ctx(1);
  auto publisher = [&](const std::string& ep) {
    // XPUB: a PUB that also sees its subscriptions, so "status" can say who listens.
    zmq::socket_t s(ctx, zmq::socket_type::xpub);
    s.set(zmq::sockopt::linger, 0);
    s.set(zmq::sockopt::sndhwm, 100000);
    s.set(zmq::sockopt::xpub_verbose, 1);
    // Its only inbound traffic is the handshake and subscriptions (see zmq_sockets.hpp).
    s.set(zmq::sockopt::maxmsgsize, transport::kMaxPublisherInboundBytes);
    (void)transport::apply_link_security(ctx, s, ep, transport::LinkRole::kServer, security);
    try {
      s.bind(ep);
    } catch (const zmq::error_t& e) {
      throw std::runtime_error(fmt::format("{}: cannot bind: {}", ep, e.what()));
    }
    return s;
  };
  std::array<zmq::socket_t, 3> pubs{publisher(master_ep), publisher(slave_ep),
                                    publisher(report_ep)};
  zmq::socket_t control = [&] {
    try {
      return transport::make_command_server(ctx, a.control, security);
    } catch (const zmq::error_t& e) {
      throw std::runtime_error(fmt::format("--control {}: cannot bind: {}", a.control, e.what()));
    }
  }();

  using Clock = std::chrono::steady_clock;
  bool playing = !a.start_paused;
  bool stopped = false;
  double speed = a.speed;
  double anchor_pos = 0.0;
  Clock::time_point anchor_wall = Clock::now();
  std::size_t next = 0;
  std::array<std::uint64_t, 4> sent{};
  std::array<std::uint64_t, 3> subscriptions{};
  auto position = [&] {
    const double p =
        playing
            ? anchor_pos + std::chrono::duration<double>(Clock::now() - anchor_wall).count() * speed
            : anchor_pos;
    return std::min(p, duration_s);
  };
  auto send_until = [&](double p) {
    while (next < items.size() && pos_of(next) <= p) {
      const LiveItem& it = items[next];
      if (it.kind <= 1) {
        (void)pubs[static_cast<std::size_t>(it.kind)].send(
            zmq::buffer(it.data.data(), it.data.size()), zmq::send_flags::dontwait);
      } else {
        const char* tag = it.kind == 2 ? "report" : "alarm";
        (void)pubs[2].send(zmq::buffer(std::string_view(tag)),
                           zmq::send_flags::sndmore | zmq::send_flags::dontwait);
        (void)pubs[2].send(zmq::buffer(it.data.data(), it.data.size()), zmq::send_flags::dontwait);
      }
      ++sent[static_cast<std::size_t>(it.kind)];
      ++next;
    }
  };
  auto status = [&](const char* state, double p) {
    return fmt::format(
        "{} at {:.6f} s of {:.6f} s; speed {:g}; sent {} messages, the file has {}: "
        "master={} slave={} report={} alarm={}; subscriptions: master={} slave={} report={}",
        state, p, duration_s, speed, sent[0] + sent[1] + sent[2] + sent[3], items.size(), sent[0],
        sent[1], sent[2], sent[3], subscriptions[0], subscriptions[1], subscriptions[2]);
  };
  auto state_name = [&] {
    return next >= items.size() ? "finished" : playing ? "playing" : "paused";
  };
  // The summary stream (as teleop-supervisor's, topic "status" on the report endpoint), every
  // 100 ms of wall time whether playing, paused or finished and held.
  const std::chrono::milliseconds summary_period{100};
  Clock::time_point next_summary = Clock::now();
  auto publish_summary = [&] {
    const double p = position();
    summary.advance_to(t0 + static_cast<std::uint64_t>(std::llround(std::max(0.0, p) * 1e9)));
    v1::SupervisorStatus st;
    summary.fill(st);
    v1::ReplayPosition* r = st.mutable_replay();
    r->set_file(a.file);
    r->set_state(state_name());
    r->set_position_s(p);
    r->set_duration_s(duration_s);
    r->set_speed(speed);
    r->set_control_endpoint(a.control);
    const std::string bytes = st.SerializeAsString();
    (void)pubs[2].send(zmq::str_buffer("status"),
                       zmq::send_flags::sndmore | zmq::send_flags::dontwait);
    (void)pubs[2].send(zmq::buffer(bytes), zmq::send_flags::dontwait);
  };
  out << fmt::format(
             "replaying {} ({} messages, {:.3f} s) at speed {:g}: master telemetry on {}, slave "
             "telemetry on {}, reports and alarms on {}; control on {}{}\n",
             a.file, items.size(), duration_s, speed, master_ep, slave_ep, report_ep, a.control,
             playing ? "" : " (paused: send 'resume')")
      << std::flush;

  while (!stopped) {
    if (playing) {
      const double p = position();
      send_until(p);
      if (next >= items.size()) {
        anchor_pos = duration_s;
        playing = false;
        if (!a.hold) break;
      }
    }
    if (Clock::now() >= next_summary) {
      publish_summary();
      next_summary = std::max(next_summary + summary_period, Clock::now());
    }
    // Sleep until the next message or summary is due or a request or subscription arrives.
    const auto to_summary =
        std::chrono::ceil<std::chrono::milliseconds>(next_summary - Clock::now()).count();
    long timeout_ms = std::clamp(static_cast<long>(to_summary), 0L, 100L);
    if (playing && next < items.size()) {
      const double wait_s = (pos_of(next) - position()) / speed;
      timeout_ms = std::clamp(static_cast<long>(std::ceil(wait_s * 1e3)), 0L, timeout_ms);
    }
    std::array<zmq::pollitem_t, 4> poll_items{{{control.handle(), 0, ZMQ_POLLIN, 0},
                                               {pubs[0].handle(), 0, ZMQ_POLLIN, 0},
                                               {pubs[1].handle(), 0, ZMQ_POLLIN, 0},
                                               {pubs[2].handle(), 0, ZMQ_POLLIN, 0}}};
    try {
      (void)zmq::poll(poll_items.data(), poll_items.size(), std::chrono::milliseconds(timeout_ms));
    } catch (const zmq::error_t& e) {
      if (e.num() == EINTR) continue;
      throw;
    }
    zmq::message_t msg;
    for (std::size_t i = 0; i < pubs.size(); ++i) {
      while (transport::receive_whole(pubs[i], msg).parts > 0) {
        if (msg.size() > 0 && static_cast<const unsigned char*>(msg.data())[0] == 1) {
          ++subscriptions[i];
        }
      }
    }
    // The whole request (every part), so the control socket can always answer: a multi-part
    // one is refused (issue 14 finding 4's sibling).
    const transport::Received got = transport::receive_whole(control, msg);
    if (got.parts == 0) continue;
    if (got.parts != 1) {
      (void)transport::send_noexcept(
          control,
          fmt::format("error: malformed request: {} parts (a request is one frame)", got.parts));
      continue;
    }
    const std::string request = msg.to_string();
    std::string reply;
    // Everything due up to now goes out first, so the reply's position and counts agree.
    const double p = position();
    if (playing) send_until(p);
    const std::vector<std::string> words = split(request, ' ');
    const std::string& verb = words.front();
    try {
      if (verb == "pause" && words.size() == 1) {
        anchor_pos = p;
        playing = false;
        reply = status(next < items.size() ? "paused" : "finished", p);
      } else if (verb == "resume" && words.size() == 1) {
        anchor_pos = p;
        anchor_wall = Clock::now();
        playing = next < items.size();
        reply = status(state_name(), p);
      } else if (verb == "toggle" && words.size() == 1) {
        // Pause when playing, resume when paused: a console's key that never acts on a state
        // it has not seen yet.
        anchor_pos = p;
        anchor_wall = Clock::now();
        playing = !playing && next < items.size();
        reply = status(state_name(), p);
      } else if (verb == "seek" && words.size() == 2 && !words[1].empty()) {
        // "seek 12.5" goes to 12.5 s; "seek +5" / "seek -5" moves from where the replay is
        // (clamped to the file), so that keys pressed quickly add up.
        const bool relative = words[1].front() == '+' || words[1].front() == '-';
        // (from_chars takes no '+')
        double s = parse_number(words[1].front() == '+' ? words[1].substr(1) : words[1], "seek");
        if (relative) s = std::max(0.0, p + s);
        if (s < 0.0) throw UsageError("seek: a position from 0 s on (+S/-S: relative)");
        anchor_pos = std::min(s, duration_s);
        anchor_wall = Clock::now();
        next = 0;
        while (next < items.size() && pos_of(next) < anchor_pos) ++next;
        reply = status(state_name(), anchor_pos);
      } else if (verb == "speed" && words.size() == 2 && !words[1].empty()) {
        // "speed 2" plays at 2x; "speed x2" / "speed x0.5" multiplies the speed in force.
        const bool factor = words[1].front() == 'x';
        double x = parse_number(factor ? words[1].substr(1) : words[1], "speed");
        if (factor) x *= speed;
        if (!(x > 0.0) || !std::isfinite(x)) throw UsageError("speed: must be positive");
        anchor_pos = p;
        anchor_wall = Clock::now();
        speed = x;
        reply = status(state_name(), p);
      } else if (verb == "status" && words.size() == 1) {
        reply = status(state_name(), p);
      } else if (verb == "stop" && words.size() == 1) {
        stopped = true;
        reply = status("stopped", p);
      } else {
        reply = fmt::format(
            "error: unknown request '{}' (pause, resume, toggle, seek SECONDS|+S|-S, "
            "speed X|xF, status, stop)",
            request);
      }
    } catch (const std::exception& e) {
      reply = fmt::format("error: {}", e.what());
    }
    (void)transport::send_noexcept(control, reply);
    // A console sees a pause, seek or change of speed at once, not up to 100 ms later.
    if (verb != "status") next_summary = Clock::now();
  }
  out << status(stopped ? "stopped" : "finished", position()) << "\n";
  (void)err;
  return kExitOk;
}

// --- --resimulate --------------------------------------------------------------------------

struct Outcome {
  double tracking_rms_m{0.0};
  double max_penetration_m{0.0};
  scene::Oscillation oscillation{};
  std::size_t cycles{0};
  bool fault{false};
};

[[nodiscard]] json oscillation_json(const scene::Oscillation& o) {
  return {{"detected", o.detected},
          {"amplitude_m", o.amplitude_m},
          {"frequency_hz", o.frequency_hz},
          {"previous_amplitude_m", o.previous_amplitude_m}};
}

[[nodiscard]] json analysis_json(const TeleopParams& params) {
  supervisor::StabilityGuard guard(params);
  const supervisor::Assessment a = guard.assess(guard.configured_inputs());
  return {{"verdict", std::string(stability::to_string(a.verdict))},
          {"min_damping_ratio", a.min_damping_ratio},
          {"round_trip_samples", a.inputs.round_trip_samples},
          {"slave_fixture_stiffness_N_per_m", a.inputs.slave_fixture_N_per_m},
          {"master_fixture_stiffness_N_per_m", a.inputs.master_fixture_N_per_m},
          {"max_stable_slave_stiffness_N_per_m",
           a.max_slave_N_per_m ? json(*a.max_slave_N_per_m) : json(nullptr)},
          {"max_stable_master_stiffness_N_per_m",
           a.max_master_N_per_m ? json(*a.max_master_N_per_m) : json(nullptr)},
          {"slave_margin", a.slave_margin() ? json(*a.slave_margin()) : json(nullptr)},
          {"master_margin", a.master_margin() ? json(*a.master_margin()) : json(nullptr)}};
}

[[nodiscard]] double oscillation_threshold_m(const device::SimDeviceConfig& c) {
  if (!c.quantize_position) return 1e-5;
  const double count_m = 2.0 * std::numbers::pi * c.encoder.metres_per_radian /
                         (c.encoder.counts_per_rev * c.encoder.transmission_ratio);
  return std::max(1e-5, 1.5 * count_m);
}

// The slave's tracking of the master states it received (alpha x_m - x_s), its deepest point
// in its fixture and its oscillation, from its sensed positions: the same measures for the
// recording and for the resimulation.
struct OutcomeAccumulator {
  double alpha{1.0};
  FixtureParams fixture{};
  double sum_sq{0.0};
  std::size_t tracked{0};
  Outcome o{};
  std::vector<double> positions{};
  void add(double slave_m, std::optional<double> master_m) {
    positions.push_back(slave_m);
    if (master_m) {
      const double e = alpha * *master_m - slave_m;
      sum_sq += e * e;
      ++tracked;
    }
    if (fixture.stiffness_N_per_m > 0.0) {
      o.max_penetration_m = std::max(o.max_penetration_m, slave_m - fixture.position_m);
    }
  }
  [[nodiscard]] Outcome finish(double period_s, double threshold_m) {
    o.cycles = positions.size();
    o.tracking_rms_m = tracked > 0 ? std::sqrt(sum_sq / static_cast<double>(tracked)) : 0.0;
    const double duration = static_cast<double>(positions.size()) * period_s;
    if (positions.size() > 4) {
      o.oscillation = scene::detect_oscillation(positions, period_s, std::min(1.0, 0.25 * duration),
                                                threshold_m);
    }
    return o;
  }
};

[[nodiscard]] json outcome_json(const Outcome& o) {
  return {{"cycles", o.cycles},
          {"tracking_error_rms_m", o.tracking_rms_m},
          {"max_penetration_slave_m", o.max_penetration_m},
          {"oscillation", oscillation_json(o.oscillation)},
          {"fault", o.fault}};
}

[[nodiscard]] bool coupled(int mode) { return mode == v1::ENGAGED || mode == v1::CLUTCHED; }

int resimulate(const record::McapReader& reader, const ReplayArgs& a, std::ostream& out) {
  const std::optional<config::LoadedConfig> recorded = recorded_config(reader, {});
  if (!recorded) {
    throw std::runtime_error(
        fmt::format("{}: no /config channel: --resimulate needs the "
                    "recorded configuration (channels: {})",
                    a.file, channel_list(reader)));
  }
  const config::LoadedConfig cfg = *recorded_config(reader, a.overrides);
  const std::vector<RecordedCycle> master = read_recorded_cycles(a.file, true);
  const std::vector<RecordedCycle> slave = read_recorded_cycles(a.file, false);
  if (master.empty()) {
    throw std::runtime_error(fmt::format("{}: no master cycles to replay ({} is empty or missing)",
                                         a.file, kMasterTopic));
  }
  const TeleopParams params_before = config::to_teleop_params(*recorded);
  const TeleopParams params = config::to_teleop_params(cfg);

  // The law and the slave device as the lockstep simulator (with a scene) or a node builds them.
  control::LawParams law;
  device::SimDeviceConfig slave_cfg;
  device::SimDeviceConfig slave_cfg_before;
  double master0 = master.front().position_m;
  double slave0 = slave.empty() ? 0.0 : slave.front().position_m;
  if (cfg.config.has_scene()) {
    const scene::SceneSetup setup = config::to_scene_setup(cfg);
    if (setup.force_device) {
      throw std::runtime_error(
          fmt::format("{}: a force device scene has no slave to resimulate", a.file));
    }
    law = setup.law;
    slave_cfg = setup.slave;
    slave_cfg_before = config::to_scene_setup(*recorded).slave;
    master0 = setup.master.initial_position_m;
    slave0 = setup.slave.initial_position_m;
    if (setup.equilibrium_perturbation_m) {
      const scene::Equilibrium eq =
          scene::static_equilibrium(setup.teleop, setup.equilibrium_push_N);
      master0 = eq.master_m;
      slave0 = eq.slave_m + *setup.equilibrium_perturbation_m;
      law.clutch_fade_s = 0.0;
    }
  } else {
    const config::NodeSetup node = config::to_node_setup(cfg, transport::Role::kSlave);
    law = node.settings.law;
    slave_cfg = node.sim;
    slave_cfg.hold_scene_until_engaged = false;
    slave_cfg_before = config::to_node_setup(*recorded, transport::Role::kSlave).sim;
  }
  const double rate = params.sample_rate_hz;
  const double period_s = 1.0 / rate;
  const std::chrono::nanoseconds period{std::llround(1e9 / rate)};
  slave_cfg.period = period;
  slave_cfg.initial_position_m = slave0;

  // What happened: the recorded slave, measured as the resimulation will be.
  OutcomeAccumulator before{params_before.scaling.position, params_before.slave_fixture};
  for (const RecordedCycle& c : slave) {
    before.add(c.position_m,
               coupled(c.mode) ? std::optional<double>(c.peer_position_m) : std::nullopt);
  }
  const Outcome recorded_outcome =
      before.finish(1.0 / params_before.sample_rate_hz, oscillation_threshold_m(slave_cfg_before));

  // What would have happened: the recorded master motion through the slave side of the law
  // (lockstep.cpp's loop with the master device replaced by the recording).
  device::SimDevice device(slave_cfg);
  for (const device::Status s : {device.configure(), device.activate()}) {
    if (!s.ok()) throw std::runtime_error(fmt::format("slave device: {}", s.message));
  }
  control::MasterLaw master_law(law);
  control::SlaveLaw slave_law(law);
  master_law.reset(master0);
  slave_law.reset(slave0);
  control::VelocityEstimator slave_velocity(period_s, law.velocity_cutoff_hz);
  slave_velocity.reset(slave0);
  const std::size_t delay = static_cast<std::size_t>(params.round_trip_delay_samples);
  std::vector<control::PeerState> in_flight(delay + 1,
                                            control::PeerState{master0, 0.0, 0.0, false, true});
  OutcomeAccumulator after{params.scaling.position, params.slave_fixture};
  bool fault = false;
  for (std::size_t k = 0; k < master.size(); ++k) {
    device::Sample ss{};
    (void)device.read(ss);
    const control::PeerState slave_state{ss.position_m, slave_velocity.step(ss.position_m),
                                         ss.force_N, false, !slave_law.faulted()};
    master_law.set_clutch(master[k].mode == v1::CLUTCHED);
    (void)master_law.step(master[k].position_m, slave_state);
    control::PeerState sent = master_law.peer_state();
    sent.valid = sent.valid && coupled(master[k].mode);
    in_flight[k % (delay + 1)] = sent;
    const control::PeerState& received = in_flight[(k + 1) % (delay + 1)];
    const control::Command cs = slave_law.step(ss.position_m, ss.force_N, received);
    fault = fault || cs.flags.input_fault;
    (void)device.write(device::Command{cs.force_N});
    (void)device.advance(period);
    const bool following = received.valid && !received.clutched;
    after.add(ss.position_m, following ? std::optional<double>(received.position_m) : std::nullopt);
  }
  Outcome resimulated = after.finish(period_s, oscillation_threshold_m(slave_cfg));
  resimulated.fault = fault;

  json j = {
      {"file", a.file},
      {"overrides", a.overrides},
      {"master_cycles", master.size()},
      {"duration_s", static_cast<double>(master.size()) * period_s},
      {"round_trip_samples", delay},
      {"recorded",
       {{"analysis", analysis_json(params_before)}, {"outcome", outcome_json(recorded_outcome)}}},
      {"resimulated",
       {{"analysis", analysis_json(params)}, {"outcome", outcome_json(resimulated)}}}};
  if (a.json) {
    out << j.dump(2) << "\n";
  } else {
    out << fmt::format(
        "{}: the recorded master motion ({} cycles, {:.3f} s) through the slave "
        "side of the law{}\n",
        a.file, master.size(), j["duration_s"].get<double>(),
        a.overrides.empty() ? " as recorded" : " with:");
    for (const std::string& o : a.overrides) out << "  --set " << o << "\n";
    const json& ra = j["recorded"]["analysis"];
    const json& na = j["resimulated"]["analysis"];
    auto num = [](const json& v, const char* f) {
      return v.is_null() ? std::string("-") : fmt::format(fmt::runtime(f), v.get<double>());
    };
    auto osc = [](const Outcome& o) {
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
    row("slave tracking error rms (mm)",
        fmt::format("{:.4g}", recorded_outcome.tracking_rms_m * 1e3),
        fmt::format("{:.4g}", resimulated.tracking_rms_m * 1e3));
    row("max slave fixture penetration (mm)",
        fmt::format("{:.4g}", recorded_outcome.max_penetration_m * 1e3),
        fmt::format("{:.4g}", resimulated.max_penetration_m * 1e3));
    row("slave oscillation", osc(recorded_outcome), osc(resimulated));
    if (resimulated.fault) out << "  the resimulated slave law latched a fault\n";
  }
  if (resimulated.fault) return 5;
  return resimulated.oscillation.detected ? 3 : kExitOk;
}

int run(const ReplayArgs& a, std::ostream& out, std::ostream& err) {
  if (a.action == Action::kRecover) return recover(a, out);
  const record::McapReader reader = open_session(a.file);
  switch (a.action) {
    case Action::kSummary: {
      const json j = summary_json(reader);
      if (a.json) {
        out << j.dump(2) << "\n";
      } else {
        print_summary(j, out);
      }
      return kExitOk;
    }
    case Action::kPrint:
      return print_channel(reader, a, out);
    case Action::kCsv:
      return write_cycles_csv(reader, a, out);
    case Action::kLive:
      return replay_live(reader, a, out, err);
    case Action::kResimulate:
      return resimulate(reader, a, out);
    case Action::kRecover:
      break;
  }
  return kExitOk;
}

}  // namespace

bool is_mcap_file(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  char magic[8] = {};
  f.read(magic, sizeof magic);
  return f.gcount() == 8 && std::string_view(magic, 8) == std::string_view("\x89MCAP0\r\n", 8);
}

std::vector<RecordedCycle> read_recorded_cycles(const std::string& path, bool master) {
  const record::McapReader reader = open_session(path);
  const std::string topic = master ? kMasterTopic : kSlaveTopic;
  if (!has_topic(reader, topic)) {
    throw std::runtime_error(
        fmt::format("{}: no channel '{}' (channels: {})", path, topic, channel_list(reader)));
  }
  std::vector<RecordedCycle> cycles;
  for (const record::MessageView& m : messages_on(reader, topic)) {
    const v1::Telemetry t = decode<v1::Telemetry>(reader, m);
    for (const v1::CycleRecord& c : t.cycles()) {
      cycles.push_back({t.session_id(), c.sequence(), c.sample_time_ns(), c.mode(), c.position_m(),
                        c.velocity_m_per_s(), c.force_n(), c.command_n(), c.peer_sequence(),
                        c.peer_position_m()});
    }
  }
  return cycles;
}

std::string replay_usage() {
  return "usage: teleopctl replay FILE.mcap [--json]\n"
         "       teleopctl replay FILE.mcap --print CHANNEL [--json]\n"
         "       teleopctl replay FILE.mcap --csv [--out FILE.csv]\n"
         "       teleopctl replay FILE.mcap --recover OUT.mcap [--json]\n"
         "       teleopctl replay FILE.mcap --speed X [--control ENDPOINT] [--paused] [--hold]\n"
         "                        [--master-telemetry EP] [--slave-telemetry EP] [--report EP]\n"
         "                        [--set PATH=VALUE]...\n"
         "       teleopctl replay FILE.mcap --resimulate [--set PATH=VALUE]... [--json]\n\n"
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
         "                 penetration and oscillation, next to what the recording shows\n"
         "Exit: 0 ok, 1 bad file (not MCAP, damaged: try --recover) or unknown channel, 2 usage;\n"
         "--resimulate: 3 the resimulated slave oscillates, 5 its law latched a fault.\n";
}

int run_replay(const std::vector<std::string>& args, std::ostream& out, std::ostream& err) {
  ReplayArgs a;
  try {
    for (const std::string& arg : args) {
      if (arg == "--help" || arg == "-h") {
        out << replay_usage();
        return kExitOk;
      }
    }
    a = parse_replay_args(args);
  } catch (const UsageError& e) {
    err << "teleopctl replay: " << e.what() << "\n" << replay_usage();
    return kExitUsage;
  }
  return run_guarded("replay", err, [&] { return run(a, out, err); });
}

}  // namespace teleop::ctl
