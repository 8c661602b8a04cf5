#include "supervisor/teleopctl/status_command.hpp"

#include <fmt/core.h>

#include "common/config/config_loader.hpp"
#include "common/config/node_loader.hpp"
#include "common/core/defaults.hpp"
#include "supervisor/teleopctl/cli_args.hpp"
#include "supervisor/teleopctl/estop_fanout.hpp"
#include "supervisor/teleopctl/json_output.hpp"
#include "supervisor/teleopctl/local_launch.hpp"
#include "supervisor/teleopctl/node_command.hpp"
#include "supervisor/teleopctl/set_command.hpp"

namespace teleop::ctl {

std::string estop_usage() {
  return "usage: teleopctl estop [CONFIG] [--master HOST:PORT] [--slave HOST:PORT] [--key FILE]\n"
         "                      [--supervisor HOST:PORT | --no-supervisor] [--timeout-ms N] "
         "[--json]\n\n"
         "E-stop to both nodes at once, each directly on its command endpoint (from CONFIG, the\n"
         "flags, or the loopback defaults 5562 and 5563), and the mode each confirms; the\n"
         "supervisor (CONFIG's request endpoint, --supervisor, or 127.0.0.1:5567) is told in the\n"
         "same instant but never waited for. Each node's reply is awaited for --timeout-ms\n"
         "(default 500), all together: an unreachable node never delays the other. With CONFIG's\n"
         "security keys, --key is this client's key file (a read-only console key will do for an\n"
         "e-stop); without --key, the keys of a live `teleopctl launch` on these endpoints. Exit\n"
         "0 when both confirm safe, 3 when a node answered otherwise, 4 when a node did not\n"
         "answer (each named). --json prints the same as one JSON document (nodes.master,\n"
         "nodes.slave: outcome, mode, mode_reason, reply_s; supervisor: outcome).\n";
}

namespace {

// 0 when both nodes confirmed safe, 3 when one answered otherwise, 4 when one did not answer.
int estop_exit_code(const EstopResult& r) {
  int rc = kExitOk;
  for (const EstopOutcome& o : r.nodes) {
    if (!o.error.empty() || !o.reply) return kExitNoReply;
    if (!o.safe()) rc = kExitRefused;
  }
  return rc;
}

void print_estop(std::ostream& out, const EstopResult& r,
                 const std::optional<SupervisorTarget>& sup, int timeout_ms) {
  // The instant on this host's monotonic clock, the nodes' too: compare with their telemetry.
  out << fmt::format("e-stop sent at CLOCK_MONOTONIC {}.{:09d} s to both nodes{}\n",
                     r.sent_monotonic_ns / 1'000'000'000LL, r.sent_monotonic_ns % 1'000'000'000LL,
                     sup ? " and the supervisor" : "");
  for (const EstopOutcome& o : r.nodes) {
    if (!o.error.empty()) {
      out << o.name << " " << o.endpoint << ": NOT SENT: " << o.error << "\n";
    } else if (!o.reply) {
      out << o.name << " " << o.endpoint << ": NO REPLY within " << timeout_ms << " ms\n";
    } else {
      out << o.name << " " << o.endpoint << ": " << v1::NodeMode_Name(o.reply->mode()) << " ("
          << o.reply->mode_reason() << ")"
          << (o.via_supervisor
                  ? std::string(" through the supervisor (no direct reply)")
                  : fmt::format(" in {:.1f} ms", static_cast<double>(o.reply_ns) * 1e-6))
          << "\n";
    }
  }
  if (!sup) return;
  out << "supervisor " << sup->endpoint << ": ";
  if (!r.supervisor_error.empty()) {
    out << "not told: " << r.supervisor_error << "\n";
  } else if (!r.supervisor) {
    out << "told, no reply while the nodes answered (not waited for)\n";
  } else if (!r.supervisor->error().empty()) {
    out << "told, answered: " << r.supervisor->error() << "\n";
  } else {
    out << "told, confirmed\n";
  }
}

// The same as one JSON document: each node's outcome and the supervisor's.
nlohmann::json estop_json(const EstopResult& r, const std::optional<SupervisorTarget>& sup,
                          int timeout_ms) {
  nlohmann::json nodes = nlohmann::json::object();
  for (const EstopOutcome& o : r.nodes) {
    nlohmann::json n{
        {"endpoint", o.endpoint}, {"safe", o.safe()}, {"via_supervisor", o.via_supervisor}};
    if (!o.error.empty()) {
      n["outcome"] = "not_sent";
      n["error"] = o.error;
    } else if (!o.reply) {
      n["outcome"] = "no_reply";
    } else {
      n["outcome"] = "replied";
      n["mode"] = v1::NodeMode_Name(o.reply->mode());
      n["mode_reason"] = o.reply->mode_reason();
      n["reply_s"] = static_cast<double>(o.reply_ns) * 1e-9;
    }
    nodes[o.name] = std::move(n);
  }
  nlohmann::json j{{"sent_monotonic_ns", r.sent_monotonic_ns},
                   {"timeout_ms", timeout_ms},
                   {"nodes", std::move(nodes)},
                   {"supervisor", nullptr}};
  if (sup) {
    std::string outcome = "confirmed";
    if (!r.supervisor_error.empty()) {
      outcome = "not_told";
    } else if (!r.supervisor) {
      outcome = "told_no_reply";
    } else if (!r.supervisor->error().empty()) {
      outcome = "answered_error";
    }
    j["supervisor"] = {{"endpoint", sup->endpoint},
                       {"outcome", outcome},
                       {"error", !r.supervisor_error.empty() ? r.supervisor_error
                                 : r.supervisor              ? r.supervisor->error()
                                                             : std::string()}};
  }
  return j;
}

}  // namespace

int run_estop(const std::vector<std::string>& args, std::ostream& out, std::ostream& err) {
  std::string config_path;
  std::string master(defaults::kMasterCommandEndpoint);
  std::string slave(defaults::kSlaveCommandEndpoint);
  std::string supervisor(defaults::kSupervisorRequestEndpoint);
  std::string key;
  int timeout_ms = 500;
  bool master_set = false;
  bool slave_set = false;
  bool supervisor_set = false;
  bool tell_supervisor = true;
  bool json = false;
  ArgCursor cur(args);
  while (cur.next()) {
    const std::string& a = cur.arg();
    if (a == "--master") {
      master = to_endpoint(cur.value("--master"));
      master_set = true;
    } else if (a == "--slave") {
      slave = to_endpoint(cur.value("--slave"));
      slave_set = true;
    } else if (a == "--supervisor") {
      supervisor = to_endpoint(cur.value("--supervisor"));
      supervisor_set = true;
    } else if (a == "--no-supervisor") {
      tell_supervisor = false;
    } else if (a == "--json") {
      json = true;
    } else if (a == "--key") {
      key = cur.value("--key");
    } else if (a == "--timeout-ms") {
      timeout_ms = parse_timeout_ms(cur.value("--timeout-ms"));
    } else {
      take_only_positional(a, config_path);
    }
  }
  return run_guarded("estop", err, [&]() -> int {
    std::optional<config::LoadedConfig> c;
    if (!config_path.empty()) c = config::load_config_file(config_path);
    if (key.empty() && (!c || config_has_no_keys(c->config))) {
      // A local launch's keys, when one serves the node addressed.
      const std::string target =
          master_set || !c ? master
                           : config::to_node_setup(*c, transport::Role::kMaster).endpoints.command;
      if (auto l = find_local_launch(target)) {
        c = std::move(l->config);
        key = l->console_key_file;
      }
    }
    std::vector<EstopTarget> targets{{"master", master, {}}, {"slave", slave, {}}};
    std::optional<SupervisorTarget> sup;
    if (tell_supervisor) sup = SupervisorTarget{supervisor, key, ""};
    if (c) {
      if (!master_set) {
        targets[0].endpoint = config::to_node_setup(*c, transport::Role::kMaster).endpoints.command;
      }
      if (!slave_set) {
        targets[1].endpoint = config::to_node_setup(*c, transport::Role::kSlave).endpoints.command;
      }
      const v1::Security& s = c->config.security();
      if (!key.empty()) {
        targets[0].keys = {key, s.master_public_key()};
        targets[1].keys = {key, s.slave_public_key()};
      }
      if (sup) {
        if (!supervisor_set && !c->config.supervisor().request_endpoint().empty()) {
          sup->endpoint = c->config.supervisor().request_endpoint();
        }
        if (!key.empty()) sup->server_key = s.supervisor_public_key();
      }
    }
    // A client key without the supervisor's public key cannot be used with it: plaintext then.
    if (sup && sup->server_key.empty()) sup->key_file.clear();
    const EstopResult r = estop_everywhere(targets, sup, "teleopctl estop", timeout_ms);
    if (json) {
      out << estop_json(r, sup, timeout_ms).dump() << "\n";
    } else {
      print_estop(out, r, sup, timeout_ms);
    }
    return estop_exit_code(r);
  });
}

std::string status_usage() {
  return "usage: teleopctl status [--json] [--supervisor HOST:PORT] [--key FILE]\n"
         "                       [--server-key KEY|FILE] [--timeout-ms N]\n\n"
         "The supervisor's status (default 127.0.0.1:5567): its stability report (verdict,\n"
         "minimum damping ratio, round trip, fixtures against their limits), whether each node's\n"
         "telemetry is arriving, each node's mode and its reason, the recording (file, messages,\n"
         "drops) and the newest alarms.\n"
         "--json prints teleop.v1.SupervisorStatus as JSON (proto/teleop/v1/supervisor.proto,\n"
         "field names in lowerCamelCase). Without --key and --server-key, the keys of a live\n"
         "`teleopctl launch` whose supervisor is at that endpoint, if any. Exit 0, 1 error,\n"
         "4 no reply.\n";
}

int run_status(const std::vector<std::string>& args, std::ostream& out, std::ostream& err) {
  bool json = false;
  SupervisorClientFlags sup;
  ArgCursor cur(args);
  while (cur.next()) {
    const std::string& a = cur.arg();
    if (a == "--json") {
      json = true;
    } else if (sup.take(cur)) {
    } else {
      throw UsageError("unknown argument '" + a + "'");
    }
  }
  return run_guarded("status", err, [&]() -> int {
    sup.use_local_launch_keys();
    const auto reply = supervisor_status(sup);
    if (!reply) {
      err << "teleopctl status: no reply from the supervisor at " << sup.endpoint << " within "
          << sup.timeout_ms << " ms\n";
      return kExitNoReply;
    }
    const v1::SupervisorStatus& s = reply->status();
    if (json) {
      out << proto_json(s).dump() << "\n";
      return kExitOk;
    }
    // docs/nodes.md "Before engage": the experiment banner and any configuration mismatch first.
    if (!s.experiment_banner().empty()) out << s.experiment_banner() << "\n";
    if (!s.configuration_mismatch().empty()) {
      out << "CONFIGURATION MISMATCH: " << s.configuration_mismatch() << "\n";
    }
    auto fp = [](std::uint64_t f) {
      return f == 0 ? std::string("none") : fmt::format("{:016x}", f);
    };
    out << "configuration fingerprint: supervisor " << fp(s.config_fingerprint()) << ", master "
        << fp(s.master().config_fingerprint()) << ", slave " << fp(s.slave().config_fingerprint())
        << "\n";
    const v1::StabilityReport& r = s.report();
    out << fmt::format(
        "stability: {}, minimum damping ratio {:.4f} (required {:.4f}), round "
        "trip {} samples (measured {:.3f} ms)\n",
        r.verdict(), r.min_damping_ratio(), r.required_damping_ratio(), r.round_trip_samples(),
        static_cast<double>(r.measured_round_trip_ns()) * 1e-6);
    // One fixture's line: in force, its limit and margin, the nearest crossings about it.
    auto fixture = [&](const char* side, double in_force, double limit, double margin,
                       bool has_below, double below, bool has_above, double above) {
      out << fmt::format(
          "  {} fixture {:.0f} N/m of {:.0f} N/m (margin {:.0f} %; nearest crossings {} below, {} "
          "above)\n",
          side, in_force, limit, 100.0 * margin,
          has_below ? fmt::format("{:.1f} N/m", in_force - below) : std::string("none"),
          has_above ? fmt::format("{:.1f} N/m", above - in_force) : std::string("none"));
    };
    if (r.has_max_stable_slave_stiffness_n_per_m()) {
      fixture("slave", r.slave_fixture_stiffness_n_per_m(), r.max_stable_slave_stiffness_n_per_m(),
              r.slave_margin(), r.has_slave_crossing_below_n_per_m(),
              r.slave_crossing_below_n_per_m(), r.has_slave_crossing_above_n_per_m(),
              r.slave_crossing_above_n_per_m());
    }
    if (r.has_max_stable_master_stiffness_n_per_m()) {
      fixture("master", r.master_fixture_stiffness_n_per_m(),
              r.max_stable_master_stiffness_n_per_m(), r.master_margin(),
              r.has_master_crossing_below_n_per_m(), r.master_crossing_below_n_per_m(),
              r.has_master_crossing_above_n_per_m(), r.master_crossing_above_n_per_m());
    }
    out << "nodes: master " << (s.master_alive() ? "alive" : "SILENT") << ", slave "
        << (s.slave_alive() ? "alive" : "SILENT") << "\n";
    // Each node's mode and why (the last transition's reason), as its telemetry says.
    for (const auto& [name, n] :
         {std::pair{"master", &s.master()}, std::pair{"slave", &s.slave()}}) {
      out << "  " << name << ": " << v1::NodeMode_Name(n->mode())
          << (n->mode_reason().empty() ? std::string() : " (" + n->mode_reason() + ")") << "\n";
    }
    out << "recording: " << (s.recording_file().empty() ? "off" : s.recording_file()) << ", "
        << s.recorded_messages() << " messages, " << s.recording_drops() << " dropped\n";
    out << "alarms (newest first): " << s.recent_alarms_size() << "\n";
    for (const v1::Alarm& a : s.recent_alarms()) {
      out << "  " << v1::Alarm::Severity_Name(a.severity()) << " " << a.kind() << " " << a.side()
          << ": " << a.message() << (a.action().empty() ? "" : " -> " + a.action()) << "\n";
    }
    return kExitOk;
  });
}

}  // namespace teleop::ctl
