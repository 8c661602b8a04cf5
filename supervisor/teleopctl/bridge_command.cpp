#include "supervisor/teleopctl/bridge_command.hpp"

#include <arpa/inet.h>
#include <signal.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <zmq.hpp>

#include "common/bridge/foxglove_server.hpp"
#include "common/config/config_loader.hpp"
#include "common/config/node_loader.hpp"
#include "common/record/proto_schema.hpp"
#include "common/record/session.hpp"
#include "common/transport/zmq_security.hpp"
#include "common/transport/zmq_sockets.hpp"
#include "foxglove/Log.pb.h"
#include "supervisor/core/session_output.hpp"
#include "supervisor/teleopctl/cli_args.hpp"
#include "supervisor/teleopctl/local_launch.hpp"
#include "supervisor/teleopctl/node_command.hpp"
#include "teleop/v1/config.pb.h"
#include "teleop/v1/supervisor.pb.h"
#include "teleop/v1/telemetry.pb.h"

namespace teleop::ctl {
namespace {

std::atomic<bool> g_stop{false};
extern "C" void on_bridge_signal(int) { g_stop = true; }

std::int64_t wall_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

struct BridgeArgs {
  std::string config_path{};
  std::string address{"127.0.0.1"};
  int port{8765};
  bool allow_remote{false};
  std::string report{"tcp://127.0.0.1:5566"};
  std::string master_telemetry{};
  std::string slave_telemetry{};
  bool report_set{false};
  std::string key{};
  double duration_s{0.0};
};

// A server key for one endpoint (Z85 or a .pub file), empty for plaintext.
struct Source {
  std::string endpoint{};
  std::string server_key{};
};

struct Sources {
  Source master{};
  Source slave{};
  Source supervisor{};
  bool insecure{false};
};

zmq::socket_t subscriber(zmq::context_t& ctx, const Source& src, const std::string& key_file,
                         bool insecure, bool supervisor) {
  transport::LinkSecurity sec = transport::client_security(key_file, src.server_key);
  sec.insecure = insecure;
  zmq::socket_t s(ctx, zmq::socket_type::sub);
  s.set(zmq::sockopt::linger, 0);
  s.set(zmq::sockopt::rcvhwm, 10000);
  // A node's telemetry with its flight record (10 s of cycles) is ~1-2 MB.
  s.set(zmq::sockopt::maxmsgsize, std::int64_t{16} << 20);
  (void)transport::apply_link_security(ctx, s, src.endpoint, transport::LinkRole::kClient, sec);
  if (supervisor) {
    for (const char* topic : {"report", "alarm", "status", "config", "parameter_change"}) {
      s.set(zmq::sockopt::subscribe, topic);
    }
  } else {
    s.set(zmq::sockopt::subscribe, "");
  }
  s.connect(src.endpoint);
  return s;
}

bridge::ChannelSpec protobuf_channel(std::string_view topic, const google::protobuf::Descriptor* d,
                                     bool latched = false) {
  bridge::ChannelSpec spec{std::string(topic), d->full_name(), record::file_descriptor_set(d)};
  spec.latched = latched;
  return spec;
}

// One node's feed: its telemetry as recorded, and each cycle of it as a message of its own,
// stamped with the cycle's sample time on this host's wall clock.
class NodeFeed {
 public:
  NodeFeed(bridge::FoxgloveServer& server, bool master)
      : server_(server),
        telemetry_(server.add_channel(
            protobuf_channel(record::topic::telemetry(master), v1::Telemetry::descriptor()))),
        cycle_(server.add_channel(
            protobuf_channel(record::topic::cycle(master), v1::CycleRecord::descriptor()))) {}

  void take(const zmq::message_t& msg) {
    const std::int64_t now = wall_ns();
    const std::string_view bytes(static_cast<const char*>(msg.data()), msg.size());
    server_.publish(telemetry_, static_cast<std::uint64_t>(now), bytes);
    if (!server_.has_subscribers(cycle_)) return;
    v1::Telemetry t;
    if (!t.ParseFromArray(msg.data(), static_cast<int>(msg.size()))) {
      ++malformed_;
      return;
    }
    // The node's monotonic clock to this host's wall clock: the smallest (receive - sent)
    // seen in this node session (the least delayed message), so cycles keep their spacing.
    if (t.session_id() != session_) {
      session_ = t.session_id();
      has_offset_ = false;
    }
    // (A flag and a value, not std::optional: GCC 12 at -O3 calls the optional's value "maybe
    // uninitialized" here, an error in a Release build with TELEOP_WERROR.)
    const std::int64_t candidate = now - t.sent_time_ns();
    if (!has_offset_ || candidate < offset_ns_) offset_ns_ = candidate;
    has_offset_ = true;
    std::string out;
    v1::CycleRecord one;
    for (const v1::CycleRecord& c : t.cycles()) {
      std::int64_t stamp = c.sample_time_ns() + offset_ns_;
      stamp = std::max(stamp, last_stamp_ + 1);  // never backwards on the channel
      last_stamp_ = stamp;
      one = c;
      one.set_session_id(t.session_id());  // as the recording's per-cycle channels carry it
      if (!one.SerializeToString(&out)) continue;
      server_.publish(cycle_, static_cast<std::uint64_t>(stamp), out);
    }
  }

  [[nodiscard]] std::uint64_t malformed() const { return malformed_; }

 private:
  bridge::FoxgloveServer& server_;
  std::uint32_t telemetry_;
  std::uint32_t cycle_;
  std::uint64_t session_{0};
  bool has_offset_{false};
  std::int64_t offset_ns_{0};
  std::int64_t last_stamp_{std::numeric_limits<std::int64_t>::min() + 1};
  std::uint64_t malformed_{0};
};

class SupervisorFeed {
 public:
  explicit SupervisorFeed(bridge::FoxgloveServer& server)
      : server_(server),
        stability_(server.add_channel(
            // Published when the model changes: a new subscriber gets the newest at once.
            protobuf_channel(record::topic::kStability, v1::StabilityReport::descriptor(), true))),
        alarms_(
            server.add_channel(protobuf_channel(record::topic::kAlarms, v1::Alarm::descriptor()))),
        status_(server.add_channel(
            protobuf_channel(record::topic::kStatus, v1::SupervisorStatus::descriptor()))),
        log_(
            server.add_channel(protobuf_channel(record::topic::kLog, foxglove::Log::descriptor()))),
        // The configuration in force: the supervisor sends it at start, when a change applies
        // and every second; a new subscriber gets the newest at once.
        config_(server.add_channel(
            protobuf_channel(record::topic::kConfig, v1::SystemConfig::descriptor(), true))),
        changes_(server.add_channel(protobuf_channel(record::topic::kParameterChanges,
                                                     v1::ParameterChangeRecord::descriptor()))) {}

  void take(std::string_view topic, const zmq::message_t& body) {
    const std::string_view bytes(static_cast<const char*>(body.data()), body.size());
    const auto now = static_cast<std::uint64_t>(wall_ns());
    if (topic == "report") publish_report(now, std::string(bytes));
    if (topic == "parameter_change") server_.publish(changes_, now, bytes);
    // Once per configuration: its repetitions for late joiners are not new messages.
    if (topic == "config" && bytes != last_config_) {
      server_.publish(config_, now, bytes);
      last_config_ = std::string(bytes);
    }
    if (topic == "alarm") {
      server_.publish(alarms_, now, bytes);
      v1::Alarm a;
      if (server_.has_subscribers(log_) &&
          a.ParseFromArray(body.data(), static_cast<int>(body.size()))) {
        // The same foxglove.Log the recording writes (supervisor/core/session_output.hpp).
        server_.publish(
            log_, now,
            supervisor::to_foxglove_log(a, static_cast<std::int64_t>(now)).SerializeAsString());
      }
    }
    if (topic == "status") {
      server_.publish(status_, now, bytes);
      // The report in force, from the summary: a bridge started after the supervisor's last
      // report (it publishes one only when the model changes) still has it within 0.1 s.
      v1::SupervisorStatus st;
      if (st.ParseFromArray(body.data(), static_cast<int>(body.size())) && st.has_report()) {
        publish_report(now, st.report().SerializeAsString());
      }
    }
  }

 private:
  bridge::FoxgloveServer& server_;
  std::uint32_t stability_;
  std::uint32_t alarms_;
  std::uint32_t status_;
  std::uint32_t log_;
  std::uint32_t config_;
  std::uint32_t changes_;
  std::string last_report_{};
  std::string last_config_{};

  // A report once: the same report from the summary again is not a new message.
  void publish_report(std::uint64_t now, std::string bytes) {
    if (bytes == last_report_) return;
    server_.publish(stability_, now, bytes);
    last_report_ = std::move(bytes);
  }
};

// Whole messages from one socket without waiting; `take(parts)` gets each.
template <typename Take>
void drain(zmq::socket_t& s, Take&& take) {
  for (int budget = 0; budget < 1000; ++budget) {
    std::vector<zmq::message_t> parts;
    zmq::message_t part;
    try {
      if (!s.recv(part, zmq::recv_flags::dontwait)) return;
      bool more = part.more();
      parts.push_back(std::move(part));
      while (more && parts.size() < 8) {
        zmq::message_t next;
        if (!s.recv(next, zmq::recv_flags::dontwait)) break;
        more = next.more();
        parts.push_back(std::move(next));
      }
    } catch (const zmq::error_t&) {
      return;
    }
    take(parts);
  }
}

Sources resolve_sources(BridgeArgs& a) {
  if (a.key.empty()) {
    // No key: a live `teleopctl launch` serving this supervisor lends its keys, unless the
    // configuration names keys of its own.
    bool from_launch = true;
    std::string endpoint = a.report;
    if (!a.config_path.empty()) {
      const config::LoadedConfig c = config::load_config_file(a.config_path);
      from_launch = config_has_no_keys(c.config);
      if (!a.report_set && !c.config.supervisor().report_endpoint().empty()) {
        endpoint = c.config.supervisor().report_endpoint();
      }
    }
    if (from_launch) {
      if (const auto l = find_local_launch(endpoint)) {
        a.config_path = l->config_file.string();
        a.key = l->console_key_file;
      }
    }
  }
  Sources s;
  s.master.endpoint = config::default_endpoints(transport::Role::kMaster).telemetry;
  s.slave.endpoint = config::default_endpoints(transport::Role::kSlave).telemetry;
  s.supervisor.endpoint = a.report;
  if (!a.config_path.empty()) {
    const config::LoadedConfig c = config::load_config_file(a.config_path);
    s.master.endpoint = config::to_node_setup(c, transport::Role::kMaster).endpoints.telemetry;
    s.slave.endpoint = config::to_node_setup(c, transport::Role::kSlave).endpoints.telemetry;
    if (!a.report_set && !c.config.supervisor().report_endpoint().empty()) {
      s.supervisor.endpoint = c.config.supervisor().report_endpoint();
    }
    if (!a.key.empty()) {
      s.master.server_key = c.config.security().master_public_key();
      s.slave.server_key = c.config.security().slave_public_key();
      s.supervisor.server_key = c.config.security().supervisor_public_key();
    }
    s.insecure = c.config.security().insecure();
  }
  if (!a.master_telemetry.empty()) s.master.endpoint = a.master_telemetry;
  if (!a.slave_telemetry.empty()) s.slave.endpoint = a.slave_telemetry;
  return s;
}

int serve(const BridgeArgs& a, const Sources& src, std::ostream& out) {
  bridge::ServerOptions options;
  options.address = a.address;
  options.port = static_cast<std::uint16_t>(a.port);
  options.name = "teleop (teleopctl bridge)";
  options.metadata = {{"master_telemetry", src.master.endpoint},
                      {"slave_telemetry", src.slave.endpoint},
                      {"supervisor_report", src.supervisor.endpoint}};
  options.on_event = [&out](const std::string& line) {
    try {
      out << "teleopctl bridge: " << line << std::endl;
    } catch (...) {
    }
  };
  bridge::FoxgloveServer server(options);
  NodeFeed master(server, true);
  NodeFeed slave(server, false);
  SupervisorFeed supervisor(server);

  zmq::context_t ctx(1);
  zmq::socket_t master_sub = subscriber(ctx, src.master, a.key, src.insecure, false);
  zmq::socket_t slave_sub = subscriber(ctx, src.slave, a.key, src.insecure, false);
  zmq::socket_t sup_sub = subscriber(ctx, src.supervisor, a.key, src.insecure, true);
  out << "teleopctl bridge: Foxglove WebSocket (foxglove.websocket.v1) on ws://" << a.address << ":"
      << server.port() << " from master " << src.master.endpoint << ", slave " << src.slave.endpoint
      << ", supervisor " << src.supervisor.endpoint << std::endl;

  const auto start = std::chrono::steady_clock::now();
  while (!g_stop.load()) {
    if (a.duration_s > 0.0 &&
        std::chrono::steady_clock::now() - start >= std::chrono::duration<double>(a.duration_s)) {
      break;
    }
    zmq::pollitem_t items[] = {{master_sub.handle(), 0, ZMQ_POLLIN, 0},
                               {slave_sub.handle(), 0, ZMQ_POLLIN, 0},
                               {sup_sub.handle(), 0, ZMQ_POLLIN, 0}};
    try {
      (void)zmq::poll(items, 3, std::chrono::milliseconds(100));
    } catch (const zmq::error_t&) {
      continue;  // EINTR: the signal handler set g_stop
    }
    drain(master_sub, [&](const std::vector<zmq::message_t>& p) {
      if (p.size() == 1) master.take(p[0]);
    });
    drain(slave_sub, [&](const std::vector<zmq::message_t>& p) {
      if (p.size() == 1) slave.take(p[0]);
    });
    drain(sup_sub, [&](const std::vector<zmq::message_t>& p) {
      if (p.size() != 2) return;
      supervisor.take(std::string_view(static_cast<const char*>(p[0].data()), p[0].size()), p[1]);
    });
  }
  const bridge::ServerStats s = server.stats();
  out << "teleopctl bridge: stopped; " << s.connections << " connection(s), " << s.messages_sent
      << " message(s) sent, " << s.messages_dropped << " dropped (slow clients), " << s.bad_requests
      << " bad request(s) answered, " << master.malformed() + slave.malformed()
      << " malformed telemetry message(s)" << std::endl;
  return kExitOk;
}

}  // namespace

bool is_loopback_address(const std::string& address) {
  in_addr v4{};
  if (inet_pton(AF_INET, address.c_str(), &v4) == 1) {
    return (ntohl(v4.s_addr) >> 24) == 127;
  }
  in6_addr v6{};
  if (inet_pton(AF_INET6, address.c_str(), &v6) == 1) {
    static const in6_addr loopback = IN6ADDR_LOOPBACK_INIT;
    return std::equal(std::begin(v6.s6_addr), std::end(v6.s6_addr), std::begin(loopback.s6_addr));
  }
  return false;
}

std::string bridge_usage() {
  return "usage: teleopctl bridge [CONFIG] [--port N] [--address IP [--allow-remote]]\n"
         "                        [--report HOST:PORT] [--master-telemetry HOST:PORT]\n"
         "                        [--slave-telemetry HOST:PORT] [--key FILE]\n"
         "                        [--duration-s S]\n\n"
         "The live view in Foxglove: a Foxglove WebSocket server (subprotocol\n"
         "foxglove.websocket.v1) on ws://127.0.0.1:8765 (--port, 0: any free port) serving\n"
         "the channels of a recorded session live, protobuf with their schemas:\n"
         "/master/cycle and /slave/cycle (one teleop.v1.CycleRecord per control cycle),\n"
         "/master/telemetry, /slave/telemetry, /supervisor/stability, /supervisor/alarms,\n"
         "/supervisor/log (the alarms as foxglove.Log), /supervisor/status, /config (the\n"
         "configuration in force, again when a change applies) and\n"
         "/supervisor/parameter_changes (each change the supervisor decided). It subscribes\n"
         "to the nodes' telemetry and the supervisor's report endpoint like the console\n"
         "(CONFIG gives the endpoints and the servers' keys; --key is this client's key, a\n"
         "read-only console key is enough; without one, the keys of a live\n"
         "`teleopctl launch`) and sends nothing to the teleoperator. The WebSocket side has no\n"
         "authentication: it listens on loopback only unless --allow-remote is given with a\n"
         "non-loopback --address; from another machine use an SSH tunnel:\n"
         "  ssh -L 8765:127.0.0.1:8765 USER@RIG   then open ws://localhost:8765 in Foxglove.\n"
         "Runs until SIGINT/SIGTERM or --duration-s. Layout: examples/foxglove/"
         "teleop-layout.json.\n";
}

int run_bridge(const std::vector<std::string>& args, std::ostream& out, std::ostream& err) {
  BridgeArgs a;
  ArgCursor cur(args);
  while (cur.next()) {
    const std::string& arg = cur.arg();
    if (arg == "--port") {
      const double p = parse_number(cur.value("--port"), "--port");
      if (!(p >= 0 && p <= 65535 && p == static_cast<int>(p))) {
        throw UsageError("--port must be a whole number in [0, 65535]");
      }
      a.port = static_cast<int>(p);
    } else if (arg == "--address") {
      a.address = cur.value("--address");
      if (a.address == "localhost") a.address = "127.0.0.1";
    } else if (arg == "--allow-remote") {
      a.allow_remote = true;
    } else if (arg == "--report") {
      a.report = to_endpoint(cur.value("--report"));
      a.report_set = true;
    } else if (arg == "--master-telemetry") {
      a.master_telemetry = to_endpoint(cur.value("--master-telemetry"));
    } else if (arg == "--slave-telemetry") {
      a.slave_telemetry = to_endpoint(cur.value("--slave-telemetry"));
    } else if (arg == "--key") {
      a.key = cur.value("--key");
    } else if (arg == "--duration-s") {
      a.duration_s = parse_number(cur.value("--duration-s"), "--duration-s");
      if (!(a.duration_s > 0.0)) throw UsageError("--duration-s must be > 0");
    } else {
      take_only_positional(arg, a.config_path);
    }
  }
  if (!is_loopback_address(a.address) && !a.allow_remote) {
    throw UsageError("--address " + a.address +
                     " is not a loopback address: the WebSocket side has no authentication, "
                     "so anyone who reaches the port sees the teleoperator live. Reach it "
                     "through an SSH tunnel (ssh -L 8765:127.0.0.1:8765 USER@RIG), or add "
                     "--allow-remote on a network you trust");
  }
  return run_guarded("bridge", err, [&]() -> int {
    const Sources src = resolve_sources(a);
    struct sigaction sa {};
    sa.sa_handler = on_bridge_signal;
    sigaction(SIGINT, &sa, nullptr);
    sigaction(SIGTERM, &sa, nullptr);
    return serve(a, src, out);
  });
}

}  // namespace teleop::ctl
