#include "supervisor/teleopctl/status_command.hpp"

#include <fmt/core.h>
#include <google/protobuf/util/json_util.h>

#include "common/config/config_loader.hpp"
#include "common/config/node_loader.hpp"
#include "supervisor/teleopctl/cli_args.hpp"
#include "supervisor/teleopctl/node_command.hpp"
#include "supervisor/teleopctl/set_command.hpp"

namespace teleop::ctl {

std::string estop_usage() {
  return "usage: teleopctl estop [CONFIG] [--master HOST:PORT] [--slave HOST:PORT] [--key FILE]\n"
         "                      [--timeout-ms N]\n\n"
         "E-stop to both nodes, each directly on its command endpoint (from CONFIG, the flags,\n"
         "or the loopback defaults 5562 and 5563), and the mode each confirms. With CONFIG's\n"
         "security keys, --key is this client's key file. Exit 0 when both confirm safe, 3 when\n"
         "a node answered otherwise, 4 when a node did not answer.\n";
}

int run_estop(const std::vector<std::string>& args, std::ostream& out, std::ostream& err) {
  std::string config_path;
  std::string master = "tcp://127.0.0.1:5562";
  std::string slave = "tcp://127.0.0.1:5563";
  std::string key;
  int timeout_ms = 2000;
  bool master_set = false;
  bool slave_set = false;
  ArgCursor cur(args);
  while (cur.next()) {
    const std::string& a = cur.arg();
    if (a == "--master") {
      master = to_endpoint(cur.value("--master"));
      master_set = true;
    } else if (a == "--slave") {
      slave = to_endpoint(cur.value("--slave"));
      slave_set = true;
    } else if (a == "--key") {
      key = cur.value("--key");
    } else if (a == "--timeout-ms") {
      timeout_ms = parse_timeout_ms(cur.value("--timeout-ms"));
    } else if (a.rfind("--", 0) == 0) {
      throw UsageError("unknown option '" + a + "'");
    } else if (config_path.empty()) {
      config_path = a;
    } else {
      throw UsageError("unexpected argument '" + a + "'");
    }
  }
  return run_guarded("estop", err, [&]() -> int {
    NodeClientKeys master_keys;
    NodeClientKeys slave_keys;
    if (!config_path.empty()) {
      const config::LoadedConfig c = config::load_config_file(config_path);
      if (!master_set)
        master = config::to_node_setup(c, transport::Role::kMaster).endpoints.command;
      if (!slave_set) slave = config::to_node_setup(c, transport::Role::kSlave).endpoints.command;
      if (!key.empty()) {
        master_keys = {key, c.config.security().master_public_key()};
        slave_keys = {key, c.config.security().slave_public_key()};
      }
    }
    int rc = kExitOk;
    // Both are sent whatever the first answers: an e-stop never waits on the other node.
    for (const auto& [name, endpoint, keys] :
         {std::tuple{"master", master, master_keys}, std::tuple{"slave", slave, slave_keys}}) {
      const auto reply = send_node_command(endpoint, v1::NodeCommand::ESTOP, keys, timeout_ms);
      if (!reply) {
        out << name << " " << endpoint << ": NO REPLY within " << timeout_ms << " ms\n";
        rc = kExitNoReply;
        continue;
      }
      const bool safe = reply->mode() == v1::SAFE || reply->mode() == v1::FAULT;
      out << name << " " << endpoint << ": " << v1::NodeMode_Name(reply->mode()) << " ("
          << reply->mode_reason() << ")\n";
      if (!safe && rc == kExitOk) rc = kExitRefused;
    }
    return rc;
  });
}

std::string status_usage() {
  return "usage: teleopctl status [--json] [--supervisor HOST:PORT] [--key FILE]\n"
         "                       [--server-key KEY|FILE] [--timeout-ms N]\n\n"
         "The supervisor's status (default 127.0.0.1:5567): its stability report (verdict,\n"
         "minimum damping ratio, round trip, fixtures against their limits), whether each node's\n"
         "telemetry is arriving, the recording (file, messages, drops) and the newest alarms.\n"
         "--json prints teleop.v1.SupervisorStatus as JSON (proto/teleop/v1/supervisor.proto,\n"
         "field names in lowerCamelCase). Exit 0, 1 error, 4 no reply.\n";
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
    v1::SupervisorRequest req;
    req.mutable_status();
    const auto reply =
        supervisor_request(sup.endpoint, req, sup.timeout_ms, sup.key, sup.server_key);
    if (!reply) {
      err << "teleopctl status: no reply from the supervisor at " << sup.endpoint << " within "
          << sup.timeout_ms << " ms\n";
      return kExitNoReply;
    }
    const v1::SupervisorStatus& s = reply->status();
    if (json) {
      std::string text;
      google::protobuf::util::JsonPrintOptions o;
      o.always_print_primitive_fields = true;
      (void)google::protobuf::util::MessageToJsonString(s, &text, o);
      out << text << "\n";
      return kExitOk;
    }
    // README "Before engage": the experiment banner and any configuration mismatch first.
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
    if (r.has_max_stable_slave_stiffness_n_per_m()) {
      out << fmt::format("  slave fixture {:.0f} N/m of {:.0f} N/m (margin {:.0f} %)\n",
                         r.slave_fixture_stiffness_n_per_m(),
                         r.max_stable_slave_stiffness_n_per_m(), 100.0 * r.slave_margin());
    }
    if (r.has_max_stable_master_stiffness_n_per_m()) {
      out << fmt::format("  master fixture {:.0f} N/m of {:.0f} N/m (margin {:.0f} %)\n",
                         r.master_fixture_stiffness_n_per_m(),
                         r.max_stable_master_stiffness_n_per_m(), 100.0 * r.master_margin());
    }
    out << "nodes: master " << (s.master_alive() ? "alive" : "SILENT") << ", slave "
        << (s.slave_alive() ? "alive" : "SILENT") << "\n";
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
