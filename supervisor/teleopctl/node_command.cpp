#include "supervisor/teleopctl/node_command.hpp"

#include <fcntl.h>
#include <fmt/core.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <sstream>
#include <thread>
#include <vector>
#include <zmq.hpp>

#include "common/config/config_loader.hpp"
#include "common/config/node_loader.hpp"
#include "common/telemetry/cycle_codec.hpp"
#include "common/transport/zmq_security.hpp"
#include "common/transport/zmq_sockets.hpp"
#include "supervisor/teleopctl/cli_args.hpp"
#include "supervisor/teleopctl/json_output.hpp"
#include "supervisor/teleopctl/launch_isolation.hpp"
#include "supervisor/teleopctl/local_launch.hpp"

namespace teleop::ctl {
namespace {

using namespace std::chrono_literals;

const std::map<std::string, v1::NodeCommand::Kind>& command_names() {
  static const std::map<std::string, v1::NodeCommand::Kind> names{
      {"arm", v1::NodeCommand::ARM},
      {"engage", v1::NodeCommand::ENGAGE},
      {"disengage", v1::NodeCommand::DISENGAGE},
      {"clutch", v1::NodeCommand::CLUTCH},
      {"unclutch", v1::NodeCommand::UNCLUTCH},
      {"clear", v1::NodeCommand::CLEAR},
      {"estop", v1::NodeCommand::ESTOP},
      {"e-stop", v1::NodeCommand::ESTOP},
      {"status", v1::NodeCommand::STATUS},
      {"shutdown", v1::NodeCommand::SHUTDOWN},
  };
  return names;
}

std::string mode_name(v1::NodeMode m) {
  std::string s = v1::NodeMode_Name(m);
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

std::string role_name(v1::NodeRole r) {
  return r == v1::MASTER ? "master" : (r == v1::SLAVE ? "slave" : "node");
}

volatile sig_atomic_t g_interrupted = 0;
extern "C" void on_interrupt(int) { g_interrupted = 1; }

// The process binaries: beside teleopctl when installed, or in the build tree.
std::string find_node_binary(const std::string& name) {
  const std::string env_name = name == "teleop-master"  ? "TELEOP_MASTER_BIN"
                               : name == "teleop-slave" ? "TELEOP_SLAVE_BIN"
                                                        : "TELEOP_SUPERVISOR_BIN";
  if (const char* env = std::getenv(env_name.c_str())) return env;
  std::error_code ec;
  const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", ec);
  const std::filesystem::path dir = self.parent_path();
  const std::filesystem::path sub = name == "teleop-master"  ? "master_node"
                                    : name == "teleop-slave" ? "slave_node"
                                                             : "supervisor/daemon";
  for (const std::filesystem::path& p : {dir / name, dir / ".." / ".." / sub / name}) {
    if (std::filesystem::exists(p, ec)) return std::filesystem::weakly_canonical(p).string();
  }
  throw std::runtime_error("cannot find " + name + " beside " + dir.string() + " (set " + env_name +
                           ")");
}

// --instance N: a whole number in 0..kMaxInstance.
int parse_instance(const std::string& text) {
  const double v = parse_number(text, "--instance");
  if (!(v >= 0.0 && v <= kMaxInstance) || v != static_cast<double>(static_cast<int>(v))) {
    throw UsageError("--instance must be a whole number in 0.." + std::to_string(kMaxInstance) +
                     ", got '" + text + "'");
  }
  return static_cast<int>(v);
}

// What is wrong with a node's reply to launch's arm or engage ("" when nothing): no reply, a
// refusal, or a reply from a process launch did not start.
std::string launch_reply_problem(v1::NodeCommand::Kind kind,
                                 const std::optional<v1::NodeCommandReply>& reply, pid_t pid) {
  if (!reply) return "no reply";
  if (reply->pid() != static_cast<std::uint32_t>(pid)) {
    return fmt::format("answered by pid {}, not by the node this launch started (pid {})",
                       reply->pid(), pid);
  }
  if (!reply->ok()) return reply->message().empty() ? reply->mode_reason() : reply->message();
  return command_refusal(kind, *reply);
}

// The keys of a live `teleopctl launch` (local_launch.hpp) for the node at `endpoint`; none
// when no launch serves it.
NodeClientKeys local_launch_keys(const std::string& endpoint) {
  const auto l = find_local_launch(endpoint);
  if (!l) return {};
  const v1::Security& s = l->config.config.security();
  const bool master =
      config::to_node_setup(l->config, transport::Role::kMaster).endpoints.command == endpoint;
  const bool slave =
      config::to_node_setup(l->config, transport::Role::kSlave).endpoints.command == endpoint;
  if (!master && !slave) return {};
  return {l->console_key_file, master ? s.master_public_key() : s.slave_public_key()};
}

// A configuration without keys of its own gets ephemeral ones (local_launch.hpp): their
// overrides are appended to `overrides` (what the processes are started with), `loaded` is
// reloaded with them and the configuration in force is published for the local clients.
std::unique_ptr<LaunchKeys> generate_launch_keys(const std::string& config_path,
                                                 std::vector<std::string>& overrides,
                                                 config::LoadedConfig& loaded) {
  if (!config_has_no_keys(loaded.config)) return nullptr;
  auto keys = std::make_unique<LaunchKeys>();
  for (const std::string& o : keys->overrides()) overrides.push_back(o);
  loaded = config::load_config_file(config_path, overrides);
  keys->publish(loaded.config);
  return keys;
}

// The launch's own client keys for one node (its console key); none without launch keys.
NodeClientKeys launch_client_keys(const LaunchKeys* keys, bool master) {
  if (!keys) return {};
  return {keys->console_key_file(), master ? keys->master_public() : keys->slave_public()};
}

// CURVE on a client socket when `keys` has any.
void secure_client_socket(zmq::context_t& ctx, zmq::socket_t& s, const std::string& endpoint,
                          const NodeClientKeys& keys) {
  if (keys.secret_key_file.empty()) return;
  transport::LinkSecurity sec;
  sec.own = transport::load_secret_key_file(keys.secret_key_file);
  sec.server_public_key = transport::load_public_key(keys.server_key);
  (void)transport::apply_link_security(ctx, s, endpoint, transport::LinkRole::kClient, sec);
}

// teleopctl launch's command line.
struct LaunchArgs {
  std::string config_path;
  std::vector<std::string> overrides;
  double duration_s = 0.0;
  bool engage = true;
  bool supervise = true;
  std::string record_dir = "sessions";
  bool record_dir_given = false;
  int instance = 0;
  bool plaintext = false;
  bool json = false;  // one JSON document per line (an "event" each) instead of the text
};

LaunchArgs parse_launch_args(const std::vector<std::string>& args) {
  LaunchArgs l;
  ArgCursor cur(args);
  while (cur.next()) {
    const std::string& a = cur.arg();
    if (take_set_option(cur, l.overrides)) continue;
    if (a == "--duration") {
      l.duration_s = parse_number(cur.value("--duration"), "--duration");
      if (!(l.duration_s > 0.0)) throw UsageError("--duration must be > 0");
    } else if (a == "--no-engage") {
      l.engage = false;
    } else if (a == "--no-supervisor") {
      l.supervise = false;
    } else if (a == "--plaintext") {
      l.plaintext = true;
    } else if (a == "--json") {
      l.json = true;
    } else if (a == "--record-dir") {
      l.record_dir = cur.value("--record-dir");
      l.record_dir_given = true;
    } else if (a == "--instance") {
      l.instance = parse_instance(cur.value("--instance"));
    } else {
      take_only_positional(a, l.config_path);
    }
  }
  if (l.config_path.empty()) throw UsageError("expected CONFIG");
  l.overrides.push_back("master.device.kind=SIM");
  l.overrides.push_back("slave.device.kind=SIM");
  return l;
}

// Instance N: every endpoint moved; `loaded` again so that the moved file is what is checked.
// Each moved path replaces the user's own --set of it (already moved with the rest).
void move_to_instance(LaunchArgs& a, config::LoadedConfig& loaded) {
  const std::vector<std::string> moved = instance_overrides(loaded, a.instance);
  auto path_of = [](const std::string& o) { return o.substr(0, o.find('=')); };
  std::erase_if(a.overrides, [&](const std::string& o) {
    return std::any_of(moved.begin(), moved.end(),
                       [&](const std::string& m) { return path_of(m) == path_of(o); });
  });
  a.overrides.insert(a.overrides.end(), moved.begin(), moved.end());
  loaded = config::load_config_file(a.config_path, a.overrides);
  if (!a.record_dir_given) a.record_dir = a.record_dir + "/instance-" + std::to_string(a.instance);
}

// What a launch runs: the configuration in force (checked before any process starts), the
// launch's own keys if it made any, each node's setup and how the launch reaches each node.
struct LaunchPlan {
  config::LoadedConfig loaded;
  std::unique_ptr<LaunchKeys> keys;  // removed (with their directory) when the launch ends
  config::NodeSetup master;
  config::NodeSetup slave;
  NodeClientKeys master_client;
  NodeClientKeys slave_client;
};

// Completes `a` (instance overrides and record directory, the launch keys' overrides).
LaunchPlan plan_launch(LaunchArgs& a, std::ostream& out) {
  LaunchPlan p;
  // Check the configuration here first: a bad file is reported once, before any process.
  p.loaded = config::load_config_file(a.config_path, a.overrides);
  if (a.instance > 0) move_to_instance(a, p.loaded);
  // Secure by default: keys of its own for a configuration without any (local_launch.hpp).
  p.keys = a.plaintext ? nullptr : generate_launch_keys(a.config_path, a.overrides, p.loaded);
  if (p.keys) {
    out << "CURVE keys generated for this launch in " << p.keys->dir().string()
        << " (removed when it ends; teleopctl console, status, set, estop and node find them)"
        << std::endl;
  }
  p.master_client = launch_client_keys(p.keys.get(), true);
  p.slave_client = launch_client_keys(p.keys.get(), false);
  p.master = config::to_node_setup(p.loaded, transport::Role::kMaster);
  p.slave = config::to_node_setup(p.loaded, transport::Role::kSlave);
  for (const std::string& e : {p.master.endpoints.state, p.slave.endpoints.state,
                               p.master.endpoints.command, p.slave.endpoints.command}) {
    if (!transport::is_loopback_endpoint(e)) {
      throw std::runtime_error("launch runs both nodes on this machine: endpoint " + e +
                               " is not loopback (start teleop-master and teleop-slave on "
                               "their machines instead)");
    }
  }
  return p;
}

void install_interrupt_handlers() {
  struct sigaction sa {};
  sa.sa_handler = on_interrupt;
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
}

// The processes a launch started (-1: not started).
struct LaunchedPids {
  pid_t master = -1;
  pid_t slave = -1;
  pid_t supervisor = -1;
};

// Every binary found before any process starts.
LaunchedPids spawn_processes(const LaunchArgs& a) {
  std::vector<std::string> node_args{a.config_path};
  for (const std::string& o : a.overrides) node_args.push_back("--set=" + o);
  const std::string master_bin = find_node_binary("teleop-master");
  const std::string slave_bin = find_node_binary("teleop-slave");
  const std::string supervisor_bin = a.supervise ? find_node_binary("teleop-supervisor") : "";
  LaunchedPids pids;
  pids.master = spawn_process(master_bin, node_args);
  pids.slave = spawn_process(slave_bin, node_args);
  if (a.supervise) {
    std::vector<std::string> sup_args = node_args;
    sup_args.push_back("--record-dir");
    sup_args.push_back(a.record_dir);
    pids.supervisor = spawn_process(supervisor_bin, sup_args);
  }
  return pids;
}

// Stops what the launch started; whether every process exited with 0.
bool stop_all(const LaunchedPids& pids) {
  // The supervisor first: it must not take the nodes' stop for a failure.
  int sup = 0;
  if (pids.supervisor > 0) {
    ::kill(pids.supervisor, SIGINT);
    ::waitpid(pids.supervisor, &sup, 0);
  }
  ::kill(pids.master, SIGINT);
  ::kill(pids.slave, SIGINT);
  int ms = 0;
  int ss = 0;
  ::waitpid(pids.master, &ms, 0);
  ::waitpid(pids.slave, &ss, 0);
  const bool sup_ok = pids.supervisor <= 0 || (WIFEXITED(sup) && WEXITSTATUS(sup) == 0);
  return sup_ok && WIFEXITED(ms) && WEXITSTATUS(ms) == 0 && WIFEXITED(ss) && WEXITSTATUS(ss) == 0;
}

bool node_exited(const LaunchedPids& pids) {
  int status = 0;
  return ::waitpid(pids.master, &status, WNOHANG) == pids.master ||
         ::waitpid(pids.slave, &status, WNOHANG) == pids.slave;
}

// The launched processes as confirm_own_processes() checks them: master, slave, supervisor.
std::vector<LaunchedProcess> own_processes(const LaunchPlan& plan, const LaunchedPids& pids) {
  std::vector<LaunchedProcess> own;
  auto add = [&](const std::string& name, pid_t pid, const std::string& endpoint, bool sup,
                 const NodeClientKeys& keys) {
    LaunchedProcess lp;
    lp.name = name;
    lp.pid = pid;
    lp.endpoint = endpoint;
    lp.supervisor = sup;
    lp.keys = keys;
    own.push_back(lp);
  };
  add("teleop-master", pids.master, plan.master.endpoints.command, false, plan.master_client);
  add("teleop-slave", pids.slave, plan.slave.endpoints.command, false, plan.slave_client);
  if (pids.supervisor > 0) {
    // The supervisor with the launch's console key and its public key (launch keys).
    NodeClientKeys supervisor_client;
    if (plan.keys) {
      supervisor_client = {plan.keys->console_key_file(),
                           plan.loaded.config.security().supervisor_public_key()};
    }
    add("teleop-supervisor", pids.supervisor, supervisor_request_endpoint(plan.loaded), true,
        supervisor_client);
  }
  return own;
}

void print_launched(std::ostream& out, int instance, const LaunchPlan& plan,
                    const LaunchedPids& pids) {
  out << fmt::format("instance {}: master pid {} (commands {}), slave pid {} (commands {})",
                     instance, pids.master, plan.master.endpoints.command, pids.slave,
                     plan.slave.endpoints.command);
  if (pids.supervisor > 0) {
    out << fmt::format(", supervisor pid {} (requests {}, reports {})", pids.supervisor,
                       supervisor_request_endpoint(plan.loaded),
                       supervisor_report_endpoint(plan.loaded));
  }
  out << std::endl;
}

nlohmann::json launched_json(int instance, const LaunchPlan& plan, const LaunchedPids& pids) {
  nlohmann::json j{{"event", "launched"},
                   {"instance", instance},
                   {"master", {{"pid", pids.master}, {"command", plan.master.endpoints.command}}},
                   {"slave", {{"pid", pids.slave}, {"command", plan.slave.endpoints.command}}},
                   {"supervisor", nullptr}};
  if (pids.supervisor > 0) {
    j["supervisor"] = {{"pid", pids.supervisor},
                       {"requests", supervisor_request_endpoint(plan.loaded)},
                       {"reports", supervisor_report_endpoint(plan.loaded)}};
  }
  return j;
}

zmq::socket_t subscribe_telemetry(zmq::context_t& ctx, const std::string& endpoint,
                                  const NodeClientKeys& keys) {
  zmq::socket_t s(ctx, zmq::socket_type::sub);
  s.set(zmq::sockopt::linger, 0);
  s.set(zmq::sockopt::conflate, 1);
  secure_client_socket(ctx, s, endpoint, keys);
  s.set(zmq::sockopt::subscribe, "");
  s.connect(endpoint);
  return s;
}

// The launched nodes' newest telemetry: only that of the nodes this launch started (their
// session ids, confirmed).
class LaunchTelemetry {
 public:
  LaunchTelemetry(const LaunchPlan& plan, std::uint64_t master_session, std::uint64_t slave_session)
      : master_sub_(subscribe_telemetry(ctx_, plan.master.endpoints.telemetry, plan.master_client)),
        slave_sub_(subscribe_telemetry(ctx_, plan.slave.endpoints.telemetry, plan.slave_client)),
        master_session_(master_session),
        slave_session_(slave_session) {}

  void poll() {
    for (auto [sock, dst, session] : {std::tuple{&master_sub_, &master_, master_session_},
                                      std::tuple{&slave_sub_, &slave_, slave_session_}}) {
      zmq::message_t msg;
      while (sock->recv(msg, zmq::recv_flags::dontwait)) {
        v1::Telemetry t;
        if (t.ParseFromArray(msg.data(), static_cast<int>(msg.size())) &&
            t.session_id() == session) {
          *dst = t;
        }
      }
    }
  }
  // Polls until both nodes have reported and `pred` holds (true), or `bound` or an interrupt.
  template <typename Pred>
  bool wait_until(Pred pred, std::chrono::milliseconds bound) {
    const auto until = std::chrono::steady_clock::now() + bound;
    while (!g_interrupted && std::chrono::steady_clock::now() < until) {
      poll();
      if (both() && pred()) return true;
      std::this_thread::sleep_for(10ms);
    }
    return false;
  }
  [[nodiscard]] bool both() const { return master_ && slave_; }
  [[nodiscard]] const v1::Telemetry& master() const { return *master_; }
  [[nodiscard]] const v1::Telemetry& slave() const { return *slave_; }

 private:
  zmq::context_t ctx_{1};
  zmq::socket_t master_sub_;
  zmq::socket_t slave_sub_;
  std::uint64_t master_session_;
  std::uint64_t slave_session_;
  std::optional<v1::Telemetry> master_{};
  std::optional<v1::Telemetry> slave_{};
};

// ARM, then ENGAGE, to both nodes; what is wrong with a reply goes to `err`.
void arm_and_engage(const LaunchPlan& plan, const LaunchedPids& pids, std::ostream& err) {
  for (const auto kind : {v1::NodeCommand::ARM, v1::NodeCommand::ENGAGE}) {
    for (const auto& [e, pid, keys] :
         {std::tuple{plan.master.endpoints.command, pids.master, plan.master_client},
          std::tuple{plan.slave.endpoints.command, pids.slave, plan.slave_client}}) {
      const auto reply = send_node_command(e, kind, keys, 2000);
      const std::string why = launch_reply_problem(kind, reply, pid);
      if (!why.empty()) {
        err << "teleopctl launch: " << v1::NodeCommand::Kind_Name(kind) << " " << e << ": " << why
            << "\n";
      }
    }
  }
}

// The newest cycle's position in mm: "+1.234" for one axis, "(+1.234, -0.500, +2.000)" for n
// (CycleRecord.axes > 1 carries each axis in positions_m and leaves position_m 0); 0 when the
// message has no cycle.
std::string position_mm_text(const v1::Telemetry& t) {
  if (t.cycles_size() == 0) return fmt::format("{:+8.3f}", 0.0);
  const v1::CycleRecord& c = t.cycles(t.cycles_size() - 1);
  if (c.axes() <= 1) return fmt::format("{:+8.3f}", c.position_m() * 1e3);
  // Through the codec: a record of more than 6 axes or mismatched lists is never printed.
  const std::optional<node::CycleRecordAxes> r = telemetry::axes_from_proto(c);
  if (!r) return "(a record of " + std::to_string(c.axes()) + " axes refused)";
  std::string out = "(";
  for (std::size_t i = 0; i < static_cast<std::size_t>(r->axes); ++i) {
    out += fmt::format("{}{:+.3f}", i == 0 ? "" : ", ", r->position_m[i] * 1e3);
  }
  return out + ")";
}

std::string launch_state_line(const v1::Telemetry& mt, const v1::Telemetry& st) {
  const auto& ml = mt.link();
  return fmt::format(
      "master {:<9} slave {:<9} x_m {} mm  x_s {} mm  round trip "
      "{:.3f} ms ({} samples)  loss {:.4f}  wake-up p99 {:.0f}/{:.0f} us  overruns "
      "{}/{}",
      mode_name(mt.mode()), mode_name(st.mode()), position_mm_text(mt), position_mm_text(st),
      static_cast<double>(ml.round_trip_ns()) * 1e-6, ml.round_trip_samples(), ml.loss_fraction(),
      static_cast<double>(mt.loop().wakeup_p99_ns()) * 1e-3,
      static_cast<double>(st.loop().wakeup_p99_ns()) * 1e-3, mt.loop().overruns(),
      st.loop().overruns());
}

// The same as launch_state_line, as one JSON document: position_m for one axis, positions_m
// (one entry per axis) for n > 1.
nlohmann::json launch_state_json(const v1::Telemetry& mt, const v1::Telemetry& st) {
  auto side = [](const v1::Telemetry& t) {
    nlohmann::json j{{"mode", mode_name(t.mode())},
                     {"wakeup_p99_s", static_cast<double>(t.loop().wakeup_p99_ns()) * 1e-9},
                     {"overruns", t.loop().overruns()}};
    const v1::CycleRecord* c = t.cycles_size() > 0 ? &t.cycles(t.cycles_size() - 1) : nullptr;
    if (c != nullptr && c->axes() > 1) {
      const std::optional<node::CycleRecordAxes> r = telemetry::axes_from_proto(*c);
      j["positions_m"] =
          r ? std::vector<double>(r->position_m.begin(), r->position_m.begin() + r->axes)
            : std::vector<double>{};
    } else {
      j["position_m"] = c != nullptr ? c->position_m() : 0.0;
    }
    return j;
  };
  const auto& ml = mt.link();
  return {{"event", "state"},
          {"master", side(mt)},
          {"slave", side(st)},
          {"round_trip_s", static_cast<double>(ml.round_trip_ns()) * 1e-9},
          {"round_trip_samples", ml.round_trip_samples()},
          {"loss_fraction", ml.loss_fraction()}};
}

// Both nodes' state once a second until Ctrl-C, `duration_s` (if > 0) or a node exiting.
void print_state_until_stopped(LaunchTelemetry& tel, const LaunchedPids& pids, double duration_s,
                               bool json, std::ostream& out) {
  const auto start = std::chrono::steady_clock::now();
  auto next_print = start;
  while (!g_interrupted && !node_exited(pids)) {
    tel.poll();
    const auto now = std::chrono::steady_clock::now();
    if (duration_s > 0.0 && now - start >= std::chrono::duration<double>(duration_s)) break;
    if (now >= next_print && tel.both()) {
      next_print += 1s;
      if (json) {
        out << launch_state_json(tel.master(), tel.slave()).dump() << std::endl;
      } else {
        out << launch_state_line(tel.master(), tel.slave()) << std::endl;
      }
    }
    std::this_thread::sleep_for(20ms);
  }
}

}  // namespace

std::string to_endpoint(const std::string& address) {
  if (address.find("://") != std::string::npos) return address;
  return "tcp://" + address;
}

std::optional<v1::NodeCommandReply> send_node_command(const std::string& endpoint,
                                                      v1::NodeCommand::Kind kind,
                                                      const NodeClientKeys& keys, int timeout_ms) {
  zmq::context_t ctx(1);
  const transport::LinkSecurity security =
      transport::client_security(keys.secret_key_file, keys.server_key);
  zmq::socket_t client = transport::make_command_client(ctx, endpoint, security,
                                                        std::chrono::milliseconds(timeout_ms));
  v1::NodeCommand c;
  c.set_kind(kind);
  const std::optional<std::string> bytes = transport::request_reply(client, c.SerializeAsString());
  if (!bytes) return std::nullopt;
  v1::NodeCommandReply reply;
  if (!reply.ParseFromString(*bytes)) return std::nullopt;
  return reply;
}

std::string node_usage() {
  return "usage: teleopctl node HOST:PORT COMMAND [--key FILE] [--server-key KEY|FILE]\n"
         "                     [--timeout-ms N] [--json]\n\n"
         "Sends one command straight to one node's command endpoint and prints the mode the node\n"
         "reached. COMMAND: arm, engage, disengage, clutch, unclutch, clear, estop, status,\n"
         "shutdown. Off loopback the node requires CURVE: --key is this client's key file\n"
         "(teleopctl keygen; its public key must be in the configuration's\n"
         "security.client_public_keys) and --server-key the node's public key. Without either,\n"
         "the keys of a live `teleopctl launch` whose node is at HOST:PORT, if any.\n"
         "Exit: 0 taken (the node reached the mode the command asks for), 1 error, 2 usage,\n"
         "3 refused by the node (its mode and reason printed: e.g. engage on a SAFE node),\n"
         "4 no reply. --json prints {endpoint, taken, refusal, reply: the node's\n"
         "teleop.v1.NodeCommandReply}.\n";
}

int run_node_command(const std::vector<std::string>& args, std::ostream& out, std::ostream& err) {
  std::vector<std::string> positional;
  NodeClientKeys keys;
  int timeout_ms = 2000;
  bool json = false;
  ArgCursor cur(args);
  while (cur.next()) {
    const std::string& a = cur.arg();
    if (a == "--json") {
      json = true;
    } else if (a == "--key") {
      keys.secret_key_file = cur.value("--key");
    } else if (a == "--server-key") {
      keys.server_key = cur.value("--server-key");
    } else if (a == "--timeout-ms") {
      timeout_ms = parse_timeout_ms(cur.value("--timeout-ms"));
    } else if (a.rfind("--", 0) == 0) {
      throw UsageError("unknown option '" + a + "'");
    } else {
      positional.push_back(a);
    }
  }
  if (positional.size() != 2) throw UsageError("expected HOST:PORT and COMMAND");
  const auto it = command_names().find(positional[1]);
  if (it == command_names().end()) throw UsageError("unknown command '" + positional[1] + "'");
  return run_guarded("node", err, [&] {
    const std::string endpoint = to_endpoint(positional[0]);
    if (keys.secret_key_file.empty() && keys.server_key.empty()) keys = local_launch_keys(endpoint);
    const auto reply = send_node_command(endpoint, it->second, keys, timeout_ms);
    if (!reply) {
      err << "teleopctl node: no reply from " << endpoint << " within " << timeout_ms
          << " ms (is the node running? are the keys right?)\n";
      return kExitNoReply;
    }
    // The loop took the command, but the state machine ignores what the mode does not allow.
    const std::string refusal = reply->ok() ? command_refusal(it->second, *reply) : "";
    const bool taken = reply->ok() && refusal.empty();
    if (json) {
      out << nlohmann::json{{"endpoint", endpoint},
                            {"taken", taken},
                            {"refusal", refusal},
                            {"reply", proto_json(*reply)}}
                 .dump()
          << "\n";
      return taken ? kExitOk : kExitRefused;
    }
    out << role_name(reply->role()) << " " << endpoint << ": " << mode_name(reply->mode());
    if (!reply->mode_reason().empty()) out << " (" << reply->mode_reason() << ")";
    if (!reply->message().empty()) out << ": " << reply->message();
    if (!refusal.empty()) out << ": refused: " << refusal;
    out << "\n";
    return taken ? kExitOk : kExitRefused;
  });
}

std::string launch_usage() {
  return "usage: teleopctl launch CONFIG [--set PATH=VALUE]... [--duration S] [--no-engage]\n"
         "                        [--record-dir DIR] [--no-supervisor] [--instance N] "
         "[--plaintext] [--json]\n\n"
         "Starts teleop-master and teleop-slave on loopback with simulated devices (the scene's\n"
         "human and environment, when CONFIG has a scene) and teleop-supervisor (recording the\n"
         "session in DIR, default ./sessions), arms and engages both nodes, and prints their\n"
         "state once a second until Ctrl-C (or --duration S), then stops all cleanly.\n\n"
         "Before arming, launch checks that every endpoint is answered by the very process it\n"
         "started (the pid in the reply): when another teleoperator holds a port, launch says\n"
         "which endpoint and which pid, stops what it started and exits 1.\n"
         "--instance N (0-99, default 0) runs a second (third...) teleoperator on this host:\n"
         "every port of CONFIG, given or default, moves up by 10*N (instance 1: nodes\n"
         "5570-5575, supervisor 5576/5577) and the default record directory is\n"
         "./sessions/instance-N. Launch prints the endpoints; address them as usual, e.g.\n"
         "'teleopctl status --supervisor 127.0.0.1:5577', 'teleopctl node 127.0.0.1:5572 estop'.\n"
         "\n"
         "When CONFIG names no keys, the launch generates CURVE keys for the master, the slave,\n"
         "the supervisor and the local console, so even loopback is authenticated; they live in\n"
         "$TELEOP_RUNTIME_DIR, $XDG_RUNTIME_DIR/teleop or /tmp/teleop-UID (launch-PID, mode\n"
         "0700), where teleopctl console, status, set, estop and node find them without flags,\n"
         "and are removed when the launch ends. --plaintext keeps the loopback links plaintext\n"
         "(no keys generated; the nodes then refuse every retune unless CONFIG sets\n"
         "security.allow_unauthenticated_retune).\n"
         "--json prints one JSON document per line instead of the text, each with an \"event\":\n"
         "launched (pids, endpoints), linked, engaged or not_engaged, state (once a second:\n"
         "both modes and positions, round trip, loss), stopped (clean).\n";
}

int run_launch(const std::vector<std::string>& args, std::ostream& out, std::ostream& err) {
  LaunchArgs a = parse_launch_args(args);
  // Under --json the text goes nowhere and each step is one JSON line on `out`.
  std::ostringstream no_text;
  std::ostream& text = a.json ? no_text : out;
  auto event = [&](nlohmann::json j) {
    if (a.json) out << j.dump() << std::endl;
  };
  return run_guarded("launch", err, [&]() -> int {
    const LaunchPlan plan = plan_launch(a, text);
    install_interrupt_handlers();
    const LaunchedPids pids = spawn_processes(a);
    // The processes answering must be the ones just started (finding 8 of issue 14): else
    // nothing is armed, and what this launch started is stopped.
    std::vector<LaunchedProcess> own = own_processes(plan, pids);
    const std::string why = confirm_own_processes(own, 10000);
    if (!why.empty()) {
      stop_all(pids);
      if (g_interrupted) return kExitOk;
      err << "teleopctl launch: refused: " << why << "\n";
      return kExitError;
    }
    print_launched(text, a.instance, plan, pids);
    event(launched_json(a.instance, plan, pids));
    LaunchTelemetry tel(plan, own[0].session_id, own[1].session_id);
    const bool linked = tel.wait_until(
        [&] { return tel.master().link().accepted() > 0 && tel.slave().link().accepted() > 0; },
        10s);
    if (!linked) {
      const bool exited = node_exited(pids);
      stop_all(pids);
      if (g_interrupted) return kExitOk;
      err << "teleopctl launch: "
          << (exited ? "a node exited at start (see its messages above)"
                     : "the nodes did not link within 10 s")
          << "\n";
      return kExitError;
    }
    const std::string master_session = fmt::format("{:016x}", tel.master().session_id());
    const std::string slave_session = fmt::format("{:016x}", tel.slave().session_id());
    text << "master and slave linked: master session " << master_session << ", slave session "
         << slave_session << "\n";
    event({{"event", "linked"},
           {"master_session", master_session},
           {"slave_session", slave_session}});
    if (a.engage) {
      arm_and_engage(plan, pids, err);
      const bool engaged = tel.wait_until(
          [&] { return tel.master().mode() == v1::ENGAGED && tel.slave().mode() == v1::ENGAGED; },
          10s);
      text << (engaged ? "engaged" : "not engaged within 10 s") << "\n";
      event({{"event", engaged ? "engaged" : "not_engaged"}});
    }
    text << "Ctrl-C stops both nodes.\n";
    print_state_until_stopped(tel, pids, a.duration_s, a.json, out);
    const bool clean = stop_all(pids);
    text << (clean ? "both nodes stopped cleanly" : "a node did not stop cleanly") << "\n";
    event({{"event", "stopped"}, {"clean", clean}});
    return clean ? kExitOk : kExitError;
  });
}

pid_t spawn_process(const std::string& binary, const std::vector<std::string>& args) {
  const pid_t parent = ::getpid();
  // The argument vector is built here, before the fork: the child of a process with threads
  // (the ZeroMQ context's, the telemetry readers') may call only async-signal-safe functions
  // until its exec, and an allocation there can wait forever on a lock another thread held
  // at the fork.
  std::vector<char*> argv;
  argv.reserve(args.size() + 2);
  argv.push_back(const_cast<char*>(binary.c_str()));
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  // Ctrl-C and the stop signals are held across the fork: a child that took one before its
  // exec ran launch's own handler (which only sets a flag), went on to start the node, and
  // nobody stopped that node (a launch refused at once hung in stop_all).
  sigset_t stops;
  sigset_t before;
  sigemptyset(&stops);
  sigaddset(&stops, SIGINT);
  sigaddset(&stops, SIGTERM);
  (void)::pthread_sigmask(SIG_BLOCK, &stops, &before);
  const pid_t pid = ::fork();
  if (pid == 0) {
    // The default actions first, then the signals let through: a stop sent meanwhile ends the
    // child here.
    struct sigaction dfl {};
    dfl.sa_handler = SIG_DFL;
    sigemptyset(&dfl.sa_mask);
    (void)::sigaction(SIGINT, &dfl, nullptr);
    (void)::sigaction(SIGTERM, &dfl, nullptr);
    // A launch that dies (kill -9) takes its processes with it (SIGTERM: a clean stop), so no
    // stale instance is left holding the ports.
    ::prctl(PR_SET_PDEATHSIG, SIGTERM);
    if (::getppid() != parent) ::_exit(127);
    (void)::pthread_sigmask(SIG_SETMASK, &before, nullptr);
    ::execv(argv[0], argv.data());
    ::_exit(127);
  }
  (void)::pthread_sigmask(SIG_SETMASK, &before, nullptr);
  if (pid < 0) throw std::runtime_error("fork failed");
  return pid;
}

}  // namespace teleop::ctl
