#include "supervisor/daemon/supervisor_app.hpp"

#include <fmt/core.h>
#include <signal.h>
#include <spdlog/sinks/rotating_file_sink.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <deque>
#include <filesystem>
#include <iostream>
#include <map>
#include <optional>
#include <zmq.hpp>

#include "common/config/node_loader.hpp"
#include "common/transport/socket_monitor.hpp"
#include "common/transport/zap_handler.hpp"
#include "common/transport/zmq_security.hpp"
#include "common/transport/zmq_sockets.hpp"
#include "supervisor/core/session_output.hpp"
#include "teleop/v1/config.pb.h"
#include "teleop/v1/supervisor.pb.h"
#include "teleop/v1/telemetry.pb.h"

namespace teleop::supervisor {
namespace {

using namespace std::chrono_literals;

std::int64_t monotonic_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

}  // namespace

// The sockets and the loop around SupervisorCore: the core's ports are these sockets.
struct SupervisorApp::Impl final : SupervisorPorts {
  Impl(config::CompiledSystem system, SupervisorOptions options)
      : loaded(system.source()),
        own_key(loaded.config.supervisor().secret_key_file().empty()
                    ? std::nullopt
                    : std::optional<transport::CurveKeyPair>(transport::load_secret_key_file(
                          loaded.config.supervisor().secret_key_file()))),
        core(std::move(system), with_pid(std::move(options)), *this) {}
  // A file as loaded: one axis as above, several as n axes (SupervisorCore's own choice).
  Impl(const config::LoadedConfig& config, SupervisorOptions options)
      : loaded(config),
        own_key(loaded.config.supervisor().secret_key_file().empty()
                    ? std::nullopt
                    : std::optional<transport::CurveKeyPair>(transport::load_secret_key_file(
                          loaded.config.supervisor().secret_key_file()))),
        core(config, with_pid(std::move(options)), *this) {}

  // The process id, and the offset that puts the session's log times on the wall clock (UTC):
  // the core's clock is CLOCK_MONOTONIC (monotonic_ns()).
  static SupervisorOptions with_pid(SupervisorOptions o) {
    o.pid = static_cast<std::uint32_t>(::getpid());
    o.log_time_offset_ns = wall_clock_ns() - monotonic_ns();
    return o;
  }

  // --- SupervisorPorts -----------------------------------------------------------------------
  std::optional<v1::NodeCommandReply> command(Side side, const v1::NodeCommand& c) override {
    transport::LinkSecurity sec;
    sec.insecure = loaded.config.security().insecure();
    sec.own = own_key;
    const std::string& key = side == Side::kMaster ? loaded.config.security().master_public_key()
                                                   : loaded.config.security().slave_public_key();
    if (own_key && !key.empty()) sec.server_public_key = key;
    zmq::socket_t client =
        transport::make_command_client(ctx, core.node(side).endpoints.command, sec, 500ms);
    const auto bytes = transport::request_reply(client, c.SerializeAsString());
    if (!bytes) return std::nullopt;
    v1::NodeCommandReply r;
    if (!r.ParseFromString(*bytes)) return std::nullopt;
    return r;
  }
  void report(const v1::StabilityReport& r) override { publish("report", r.SerializeAsString()); }
  void alarm(const v1::Alarm& a) override { publish("alarm", a.SerializeAsString()); }
  void status(const v1::SupervisorStatus& s) override { publish("status", s.SerializeAsString()); }
  void config(const v1::SystemConfig& c) override { publish("config", c.SerializeAsString()); }
  void parameter_change(const v1::ParameterChangeRecord& r) override {
    publish("parameter_change", r.SerializeAsString());
  }

  // One topic-tagged message on the report endpoint; never throws (a refused send is dropped,
  // as a full queue drops it).
  void publish(std::string_view topic, const std::string& bytes) {
    if (!report_pub) return;
    if (transport::send_noexcept(*report_pub, topic,
                                 zmq::send_flags::sndmore | zmq::send_flags::dontwait)) {
      (void)transport::send_noexcept(*report_pub, bytes);
    }
  }

  // --- sockets -------------------------------------------------------------------------------
  zmq::socket_t subscribe(const std::string& endpoint, const std::string& server_key) {
    transport::LinkSecurity sec;
    sec.insecure = loaded.config.security().insecure();
    sec.own = own_key;
    if (own_key && !server_key.empty()) sec.server_public_key = server_key;
    zmq::socket_t s(ctx, zmq::socket_type::sub);
    s.set(zmq::sockopt::linger, 0);
    s.set(zmq::sockopt::rcvhwm, 10000);
    // A node's telemetry with its flight record (10 s of cycles) is ~1-2 MB.
    s.set(zmq::sockopt::maxmsgsize, std::int64_t{16} << 20);
    (void)transport::apply_link_security(ctx, s, endpoint, transport::LinkRole::kClient, sec);
    s.set(zmq::sockopt::subscribe, "");
    s.connect(endpoint);
    return s;
  }

  transport::LinkSecurity server_security() const {
    transport::LinkSecurity sec;
    sec.insecure = loaded.config.security().insecure();
    sec.own = own_key;
    for (const std::string& k : loaded.config.security().client_public_keys()) {
      sec.allowed_client_keys.push_back(k);
    }
    // Read-only consoles connect too; what they may ask is decided per request.
    for (const std::string& k : core.read_only_keys()) sec.allowed_client_keys.push_back(k);
    return sec;
  }

  // Binds, connects and announces; then loop() until `stop`. Nothing a client or a node sends
  // ends the supervisor: an iteration that throws is logged and the loop goes on (issue 14
  // finding 4); a failure to start is the caller's.
  void run(const std::atomic<bool>& stop) {
    start();
    while (!stop.load()) {
      try {
        loop(stop);
      } catch (const std::exception& e) {
        spdlog::error("main loop: {} (carrying on)", e.what());
      }
    }
    spdlog::info("stopping");
  }

  void start() {
    zap.emplace(ctx);
    report_pub.emplace(
        transport::make_telemetry_publisher(ctx, core.report_endpoint(), server_security()));
    request_rep.emplace(
        transport::make_command_server(ctx, core.request_endpoint(), server_security()));
    // Each client within its budget (issue 14 finding 5).
    monitor.emplace(ctx, std::vector<zmq::socket_t*>{&*report_pub, &*request_rep}, "supervisor",
                    std::vector<transport::InboundBudget>{transport::kSubscriberBudget,
                                                          transport::kCommandClientBudget});
    master_sub.emplace(subscribe(core.node(Side::kMaster).endpoints.telemetry,
                                 loaded.config.security().master_public_key()));
    slave_sub.emplace(subscribe(core.node(Side::kSlave).endpoints.telemetry,
                                loaded.config.security().slave_public_key()));
    core.start(monotonic_ns());
    spdlog::info("supervising master {} and slave {}; reports on {}, requests on {}",
                 core.node(Side::kMaster).endpoints.telemetry,
                 core.node(Side::kSlave).endpoints.telemetry, core.report_endpoint(),
                 core.request_endpoint());
  }

  void receive_telemetry() {
    zmq::message_t msg;
    for (const Side side : {Side::kMaster, Side::kSlave}) {
      zmq::socket_t& sock = side == Side::kMaster ? *master_sub : *slave_sub;
      for (transport::Received got; (got = transport::receive_whole(sock, msg)).parts > 0;) {
        v1::Telemetry t;
        if (got.parts != 1 || !t.ParseFromArray(msg.data(), static_cast<int>(msg.size()))) {
          continue;
        }
        core.on_telemetry(side, t, monotonic_ns());
      }
    }
  }

  // The whole request, every part of it, so the socket can always answer (issue 14 finding 4:
  // a 2-part request made the reply throw EFSM, which ended the supervisor).
  void answer_request() {
    zmq::message_t msg;
    const transport::Received got = transport::receive_whole(*request_rep, msg);
    if (got.parts == 0) return;
    v1::SupervisorRequest req;
    v1::SupervisorReply reply;
    std::string key;
    try {
      const char* uid = msg.gets("User-Id");
      if (uid != nullptr) key = uid;
    } catch (const zmq::error_t&) {
      // No ZAP user id (plaintext on loopback): a local client, not read-only.
    }
    if (got.parts != 1) {
      reply.set_error("malformed request: " + std::to_string(got.parts) +
                      " parts (a request is one frame)");
    } else if (!req.ParseFromArray(msg.data(), static_cast<int>(msg.size()))) {
      reply.set_error("malformed request");
    } else {
      reply = core.on_request(req, key, monotonic_ns());
    }
    const std::string out = reply.SerializeAsString();
    std::string why;
    if (!transport::send_noexcept(*request_rep, out, zmq::send_flags::dontwait, &why)) {
      spdlog::warn("request endpoint: reply not sent: {}", why);
    }
  }

  void loop(const std::atomic<bool>& stop) {
    while (!stop.load()) {
      iterations.fetch_add(1, std::memory_order_relaxed);
      core.tick(monotonic_ns());
      zmq::pollitem_t items[] = {{master_sub->handle(), 0, ZMQ_POLLIN, 0},
                                 {slave_sub->handle(), 0, ZMQ_POLLIN, 0},
                                 {request_rep->handle(), 0, ZMQ_POLLIN, 0}};
      try {
        (void)zmq::poll(items, 3, 20ms);
      } catch (const zmq::error_t&) {
        continue;
      }
      receive_telemetry();
      answer_request();
      // A stall inside this iteration (e.g. in the poll) counts too.
      core.tick(monotonic_ns());
    }
  }

  config::LoadedConfig loaded;
  std::optional<transport::CurveKeyPair> own_key{};
  zmq::context_t ctx{1};
  std::optional<transport::ZapHandler> zap{};
  std::optional<zmq::socket_t> report_pub{};
  std::optional<zmq::socket_t> request_rep{};
  std::optional<zmq::socket_t> master_sub{};
  std::optional<zmq::socket_t> slave_sub{};
  // After the sockets: stopped (destroyed) before they close.
  std::optional<transport::SocketMonitor> monitor{};
  SupervisorCore core;
  std::atomic<std::uint64_t> iterations{0};  // the watchdog's heartbeat
};

SupervisorApp::SupervisorApp(config::CompiledSystem system, SupervisorOptions options)
    : impl_(std::make_unique<Impl>(std::move(system), std::move(options))) {}

SupervisorApp::SupervisorApp(const config::LoadedConfig& config, SupervisorOptions options)
    : impl_(std::make_unique<Impl>(config, std::move(options))) {}

SupervisorApp::~SupervisorApp() = default;

void SupervisorApp::run(const std::atomic<bool>& stop) { impl_->run(stop); }

std::uint64_t SupervisorApp::loop_iterations() const noexcept {
  return impl_->iterations.load(std::memory_order_relaxed);
}

}  // namespace teleop::supervisor
