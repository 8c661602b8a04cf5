#include "supervisor/teleopctl/launch_isolation.hpp"

#include <fmt/core.h>
#include <signal.h>
#include <sys/wait.h>

#include <chrono>
#include <stdexcept>
#include <thread>

#include "common/config/node_loader.hpp"
#include "common/core/defaults.hpp"
#include "supervisor/teleopctl/set_command.hpp"
#include "teleop/v1/supervisor.pb.h"

namespace teleop::ctl {
namespace {

using namespace std::chrono_literals;

std::string exit_text(int status) {
  if (WIFEXITED(status)) return fmt::format("exit status {}", WEXITSTATUS(status));
  if (WIFSIGNALED(status)) return fmt::format("signal {}", WTERMSIG(status));
  return "ended";
}

}  // namespace

std::string shift_endpoint_port(const std::string& endpoint, int by) {
  const std::string scheme = "tcp://";
  const std::size_t colon = endpoint.rfind(':');
  if (endpoint.rfind(scheme, 0) != 0 || colon == std::string::npos || colon < scheme.size()) {
    throw std::invalid_argument("--instance moves TCP ports: endpoint '" + endpoint +
                                "' is not tcp://HOST:PORT");
  }
  const std::string port_text = endpoint.substr(colon + 1);
  int port = 0;
  for (const char c : port_text) {
    if (c < '0' || c > '9' || port > 65535) {
      throw std::invalid_argument("--instance moves TCP ports: endpoint '" + endpoint +
                                  "' has no numeric port");
    }
    port = port * 10 + (c - '0');
  }
  if (port_text.empty()) {
    throw std::invalid_argument("--instance moves TCP ports: endpoint '" + endpoint +
                                "' has no numeric port");
  }
  const int shifted = port + by;
  if (shifted < 1 || shifted > 65535) {
    throw std::invalid_argument(
        fmt::format("--instance: endpoint '{}' moved by {} is port {}, outside 1..65535", endpoint,
                    by, shifted));
  }
  return endpoint.substr(0, colon + 1) + std::to_string(shifted);
}

std::string supervisor_request_endpoint(const config::LoadedConfig& loaded) {
  const std::string& e = loaded.config.supervisor().request_endpoint();
  return e.empty() ? std::string(defaults::kSupervisorRequestEndpoint) : e;
}

std::string supervisor_report_endpoint(const config::LoadedConfig& loaded) {
  const std::string& e = loaded.config.supervisor().report_endpoint();
  return e.empty() ? std::string(defaults::kSupervisorReportEndpoint) : e;
}

std::vector<std::string> instance_overrides(const config::LoadedConfig& loaded, int instance) {
  if (instance < 0 || instance > kMaxInstance) {
    throw std::invalid_argument(
        fmt::format("--instance must be in 0..{}, got {}", kMaxInstance, instance));
  }
  if (instance == 0) return {};
  const int by = kInstancePortStride * instance;
  std::vector<std::string> out;
  for (const auto& [side, role] : {std::pair{"master", transport::Role::kMaster},
                                   std::pair{"slave", transport::Role::kSlave}}) {
    const config::NodeSetup s = config::to_node_setup(loaded, role);
    const std::string prefix = std::string(side) + ".node.";
    out.push_back(prefix + "state_endpoint=" + shift_endpoint_port(s.endpoints.state, by));
    out.push_back(prefix +
                  "peer_state_endpoint=" + shift_endpoint_port(s.endpoints.peer_state, by));
    out.push_back(prefix + "command_endpoint=" + shift_endpoint_port(s.endpoints.command, by));
    out.push_back(prefix + "telemetry_endpoint=" + shift_endpoint_port(s.endpoints.telemetry, by));
  }
  out.push_back("supervisor.report_endpoint=" +
                shift_endpoint_port(supervisor_report_endpoint(loaded), by));
  out.push_back("supervisor.request_endpoint=" +
                shift_endpoint_port(supervisor_request_endpoint(loaded), by));
  return out;
}

std::string command_refusal(v1::NodeCommand::Kind kind, const v1::NodeCommandReply& reply) {
  const v1::NodeMode m = reply.mode();
  bool reached = true;
  std::string wants;
  switch (kind) {
    case v1::NodeCommand::ARM:
      reached = m == v1::ARMED;
      wants = "arm needs a DISARMED node";
      break;
    case v1::NodeCommand::ENGAGE:
      reached = m == v1::ALIGNING || m == v1::ENGAGED;
      wants = "engage needs an ARMED node and a fresh peer state";
      break;
    case v1::NodeCommand::DISENGAGE:
      reached = m == v1::ARMED || m == v1::DISARMED;
      wants = "disengage leaves ALIGNING, ENGAGED, CLUTCHED (to ARMED) or ARMED (to DISARMED)";
      break;
    case v1::NodeCommand::CLUTCH:
      reached = m == v1::CLUTCHED;
      wants = "clutch needs an ENGAGED node";
      break;
    case v1::NodeCommand::UNCLUTCH:
      reached = m == v1::ENGAGED;
      wants = "unclutch needs a CLUTCHED node";
      break;
    case v1::NodeCommand::CLEAR:
      reached = m == v1::DISARMED;
      wants = "clear leaves SAFE, or FAULT once the fault is gone";
      break;
    case v1::NodeCommand::ESTOP:
      reached = m == v1::SAFE || m == v1::FAULT;
      wants = "e-stop must reach SAFE";
      break;
    default:
      return {};
  }
  if (reached) return {};
  return fmt::format(
      "the node is {} ({}): {}", v1::NodeMode_Name(m),
      reply.mode_reason().empty() ? std::string("no reason given") : reply.mode_reason(), wants);
}

std::string confirm_own_processes(std::vector<LaunchedProcess>& processes, int bound_ms) {
  const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(bound_ms);
  while (true) {
    bool all = true;
    for (LaunchedProcess& p : processes) {
      if (p.confirmed) continue;
      all = false;
      int status = 0;
      if (::waitpid(p.pid, &status, WNOHANG) == p.pid) {
        p.exited = true;
        p.exit_status = status;
        return fmt::format(
            "{} (pid {}) exited at start ({}); see its message above (an "
            "endpoint in use: another teleoperator on these ports? then stop it "
            "or use --instance N)",
            p.name, p.pid, exit_text(status));
      }
      std::uint32_t answered_pid = 0;
      std::uint64_t session = 0;
      bool answered = false;
      if (p.supervisor) {
        v1::SupervisorRequest req;
        req.mutable_status();
        const auto r =
            supervisor_request(p.endpoint, req, 300, p.keys.secret_key_file, p.keys.server_key);
        if (r && r->has_status()) {
          answered = true;
          answered_pid = r->status().pid();
        }
      } else {
        const auto r = send_node_command(p.endpoint, v1::NodeCommand::STATUS, p.keys, 300);
        if (r) {
          answered = true;
          answered_pid = r->pid();
          session = r->session_id();
        }
      }
      if (!answered) continue;
      if (answered_pid != static_cast<std::uint32_t>(p.pid)) {
        // Whoever holds the endpoint, this launch's process cannot have it: it is not ours.
        return fmt::format(
            "{} is answered by another process ({}), not by the {} this launch started (pid "
            "{}): another teleoperator runs on these ports; stop it, or launch this one with "
            "--instance N",
            p.endpoint,
            answered_pid == 0 ? std::string("one that does not say its pid")
                              : fmt::format("pid {}", answered_pid),
            p.name, p.pid);
      }
      p.session_id = session;
      p.confirmed = true;
    }
    if (all) return {};
    if (std::chrono::steady_clock::now() >= until) {
      for (const LaunchedProcess& p : processes) {
        if (!p.confirmed) {
          return fmt::format("{} (pid {}) did not answer on {} within {} ms", p.name, p.pid,
                             p.endpoint, bound_ms);
        }
      }
    }
    std::this_thread::sleep_for(20ms);
  }
}

}  // namespace teleop::ctl
