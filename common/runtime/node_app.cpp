#include "common/runtime/node_app.hpp"

#include <sched.h>
#include <signal.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>
#include <sys/random.h>
#include <unistd.h>

#include <cmath>
#include <deque>
#include <functional>
#include <iostream>
#include <optional>
#include <stdexcept>
#include <type_traits>
#include <zmq.hpp>

#include "common/config/parameter_space.hpp"
#include "common/device/sim_device.hpp"
#include "common/device/sim_device_axes.hpp"
#include "common/device/usb_device_axes.hpp"
#include "common/rt/cpu_dma_latency.hpp"
#include "common/runtime/command_authority.hpp"
#include "common/runtime/node_retune.hpp"
#include "common/telemetry/cycle_codec.hpp"
#include "common/transport/socket_monitor.hpp"
#include "common/transport/zap_handler.hpp"
#include "common/transport/zmq_security.hpp"
#include "common/transport/zmq_sockets.hpp"
#include "teleop/v1/telemetry.pb.h"

namespace teleop::runtime {
namespace {

using namespace std::chrono_literals;
using transport::Role;

using telemetry::to_proto;
v1::NodeRole to_proto(Role r) {
  return r == Role::kMaster ? v1::MASTER
                            : (r == Role::kSlave ? v1::SLAVE : v1::NODE_ROLE_UNSPECIFIED);
}

std::optional<node::Command> to_command(v1::NodeCommand::Kind k) {
  switch (k) {
    case v1::NodeCommand::ARM:
      return node::Command::kArm;
    case v1::NodeCommand::ENGAGE:
      return node::Command::kEngage;
    case v1::NodeCommand::DISENGAGE:
      return node::Command::kDisengage;
    case v1::NodeCommand::CLUTCH:
      return node::Command::kClutch;
    case v1::NodeCommand::UNCLUTCH:
      return node::Command::kUnclutch;
    case v1::NodeCommand::CLEAR:
      return node::Command::kClear;
    case v1::NodeCommand::ESTOP:
      return node::Command::kEStop;
    default:
      return std::nullopt;
  }
}

// Whether this process may run a thread at SCHED_FIFO `priority` (tried on a scratch thread).
bool fifo_permitted(int priority) {
  bool ok = false;
  std::thread probe([&ok, priority] {
    sched_param p{};
    p.sched_priority = priority;
    ok = pthread_setschedparam(pthread_self(), SCHED_FIFO, &p) == 0;
  });
  probe.join();
  return ok;
}

// A link thread's body, run again (after a pause) whenever it throws: no exception ends a thread
// (std::terminate would abort the node), whatever a peer sends (issue 14 finding 4).
template <typename Body>
std::function<void()> keep_running(const char* name, const std::atomic<bool>& running, Body body) {
  return [name, &running, body = std::move(body)]() mutable {
    while (running.load()) {
      try {
        body();
        return;
      } catch (const std::exception& e) {
        spdlog::error("{} thread: {} (carrying on)", name, e.what());
      } catch (...) {
        spdlog::error("{} thread: unknown exception (carrying on)", name);
      }
      std::this_thread::sleep_for(10ms);
    }
  };
}

// docs/nodes.md "Before engage": a refused arm or engage, with both fingerprints (and both
// parameter changes) named.
template <class Core>
std::string coupling_refusal_message(const Core& core) {
  const auto& s = core.settings();
  std::string m = std::string(core.last_coupling_refusal()) + " (own configuration fingerprint " +
                  config::fingerprint_hex(s.config_fingerprint) + ", peer's " +
                  (core.peer_fingerprint() == 0 ? std::string("none")
                                                : config::fingerprint_hex(core.peer_fingerprint()));
  if (core.active_change_id() != core.peer_change_id()) {
    m += "; own parameter change " + std::to_string(core.active_change_id()) + ", peer's " +
         std::to_string(core.peer_change_id());
  }
  return m + ")";
}

// docs/nodes.md "Before engage": the fingerprints and the check at start, in every telemetry
// message.
template <class Core>
void fill_configuration(v1::Telemetry& t, const Core& core, const config::NodeSetup& setup) {
  t.set_config_fingerprint(setup.settings.config_fingerprint);
  t.set_peer_config_fingerprint(core.peer_fingerprint());
  v1::ConfigurationCheck* c = t.mutable_configuration_check();
  c->set_permits_coupling(setup.settings.permits_coupling);
  c->set_reason(setup.settings.coupling_refusal);
  c->set_peer_parameter_change_id(core.peer_change_id());
  if (setup.check) {
    c->set_verdict(setup.check->verdict);
    c->set_min_damping_ratio(setup.check->min_damping_ratio);
    c->set_required_damping_ratio(setup.check->required_damping_ratio);
    c->set_round_trip_samples(setup.check->round_trip_samples);
    c->set_allow_unstable(setup.check->allow_unstable);
  }
}

}  // namespace

std::unique_ptr<device::HapticDeviceAxes> open_axes_device(
    const config::NodeSetup& setup, const device::UsbDeviceAxes::TransportFactory& open_usb) {
  std::unique_ptr<device::HapticDeviceAxes> dev;
  if (setup.device_kind == device::DeviceKind::kUsb) {
    dev = std::make_unique<device::UsbDeviceAxes>(setup.usb_axes, open_usb);
  } else {
    dev = std::make_unique<device::SimDeviceAxes>(setup.sim_axes);
  }
  if (const device::Status s = dev->configure(); !s.ok()) {
    throw std::runtime_error(std::string("device: ") + s.message);
  }
  if (const device::Status s = dev->activate(); !s.ok()) {
    throw std::runtime_error(std::string("device: ") + s.message);
  }
  return dev;
}

std::uint64_t random_session_id() {
  std::uint64_t id = 0;
  while (id == 0) {
    if (getrandom(&id, sizeof(id), 0) != static_cast<ssize_t>(sizeof(id))) {
      throw std::runtime_error("getrandom failed: cannot draw a session id");
    }
  }
  return id;
}

namespace {

// The receiver's link statistics, read by the telemetry thread.
struct LinkCounters {
  std::atomic<std::uint64_t> accepted{0};
  std::array<std::atomic<std::uint64_t>, static_cast<std::size_t>(transport::Rejection::kCount)>
      rejected{};
  std::atomic<std::uint64_t> lost{0};
};

void fill_loop_stats(v1::LoopStats& l, const node::LoopSnapshot& stats,
                     std::chrono::nanoseconds period) {
  l.set_period_s(std::chrono::duration<double>(period).count());
  l.set_cycles(stats.cycles);
  l.set_overruns(stats.overruns);
  l.set_wakeup_p50_ns(stats.wakeup_p50_ns);
  l.set_wakeup_p99_ns(stats.wakeup_p99_ns);
  l.set_wakeup_p999_ns(stats.wakeup_p999_ns);
  l.set_wakeup_max_ns(stats.wakeup_max_ns);
  l.set_compute_p50_ns(stats.compute_p50_ns);
  l.set_compute_p99_ns(stats.compute_p99_ns);
  l.set_compute_max_ns(stats.compute_max_ns);
}

void fill_link_stats(v1::LinkStats& k, const LinkCounters& link, const node::LoopSnapshot& stats,
                     std::chrono::nanoseconds period, const transport::ConnectionCounts& conn) {
  using R = transport::Rejection;
  auto rej = [&link](R r) { return link.rejected[static_cast<std::size_t>(r)].load(); };
  k.set_accepted(link.accepted.load());
  k.set_rejected_malformed(rej(R::kMalformed));
  k.set_rejected_non_finite(rej(R::kNonFinite));
  k.set_rejected_wrong_role(rej(R::kWrongRole));
  k.set_rejected_stale(rej(R::kStale));
  k.set_rejected_wrong_session(rej(R::kWrongSession));
  k.set_rejected_wrong_axes(rej(R::kWrongAxes));
  k.set_lost(link.lost.load());
  const double expected = static_cast<double>(link.accepted.load() + link.lost.load());
  k.set_loss_fraction(expected > 0 ? static_cast<double>(link.lost.load()) / expected : 0.0);
  k.set_round_trip_ns(stats.round_trip_ns);
  k.set_round_trip_p50_ns(stats.round_trip_p50_ns);
  k.set_round_trip_p99_ns(stats.round_trip_p99_ns);
  k.set_round_trip_samples(transport::RoundTripEstimator::samples(
      std::chrono::nanoseconds(stats.round_trip_ns), period));
  k.set_one_way_latency_ns(stats.round_trip_ns / 2);
  k.set_peer_session_id(stats.peer_session_id);
  k.set_peer_restarts(stats.peer_restarts);
  k.set_peer_age_ns(stats.peer_age_ns);
  k.set_connections_accepted(conn.accepted);
  k.set_connections_closed(conn.closed);
  k.set_handshakes_failed(conn.handshakes_failed);
  k.set_handshakes_refused_auth(conn.auth_failed);
  k.set_connections_cut_over_budget(conn.cut_over_budget);
}

// The flight recorder: the telemetry thread's ring of the last 10 s of cycles at full rate,
// handed over once (then started afresh) after a safe or fault mode, or when requested.
class FlightRecorder {
 public:
  explicit FlightRecorder(std::chrono::nanoseconds period)
      : capacity_(static_cast<std::size_t>(10.0e9 / static_cast<double>(period.count()))) {}

  void keep(const v1::CycleRecord& c) {
    ring_.push_back(c);
    while (ring_.size() > capacity_) ring_.pop_front();
  }
  // The first safe or fault mode since the last hand-over names the record.
  void note_mode(node::Mode mode, const char* reason) {
    if ((mode == node::Mode::kSafe || mode == node::Mode::kFault) && reason_.empty()) {
      reason_ = std::string(node::to_string(mode)) + ": " + reason;
    }
  }
  void request() {
    if (reason_.empty()) reason_ = "requested";
  }
  void hand_over_into(v1::Telemetry& t) {
    if (reason_.empty()) return;
    for (const v1::CycleRecord& c : ring_) *t.add_flight_record() = c;
    t.set_flight_record_reason(reason_);
    spdlog::info("flight record handed over: {} cycles ({})", ring_.size(), reason_);
    reason_.clear();
  }

 private:
  std::size_t capacity_;
  std::deque<v1::CycleRecord> ring_{};
  std::string reason_{};
};

void refuse(v1::NodeCommandReply& reply, const std::string& message) {
  reply.set_ok(false);
  reply.set_message(message);
}

// A RETUNE: refused when its change number is not newer than the newest taken (a replayed or
// reused one could bring back values that no longer hold: the supervisor lowered them since)
// or a value is unusable; otherwise posted to the loop.
template <class Core>
void apply_retune(Core& core, const v1::ParameterUpdate& update, std::uint64_t& newest_retune_id,
                  v1::NodeCommandReply& reply) {
  if (update.change_id() != 0 && update.change_id() <= newest_retune_id) {
    refuse(reply, "parameter update refused: change " + std::to_string(update.change_id()) +
                      " is not newer than change " + std::to_string(newest_retune_id) +
                      " already taken (replayed or reused change number)");
    spdlog::warn("{}", reply.message());
    return;
  }
  std::string why;
  const auto r = retune_of(core, update, why);
  if (!r) {
    refuse(reply, "parameter update refused: " + why);
  } else {
    core.post_retune(*r);
    newest_retune_id = r->id;
    reply.set_ok(true);
    reply.set_message("change " + std::to_string(r->id) + " applies at master sequence " +
                      std::to_string(r->apply_at_master_sequence));
  }
  spdlog::info("RETUNE {}: {}", update.change_id(), reply.message());
}

// A mode command: posted to the loop, answered once the loop took it and ran one more cycle
// (so that the reply's mode reflects it), or after 500 ms.
template <class Core>
void apply_mode_command(Core& core, node::Command c, v1::NodeCommandReply& reply) {
  const std::uint64_t refusals = core.coupling_refusals();
  if (!core.post_command(c)) {
    refuse(reply, "command queue full");
    return;
  }
  const std::uint64_t ticket = core.commands_posted();
  const auto deadline = std::chrono::steady_clock::now() + 500ms;
  while (core.commands_applied() < ticket && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(200us);
  }
  // One more cycle so the mode reflects the command.
  const std::uint32_t cycle = core.state_published().load();
  const auto until = std::chrono::steady_clock::now() + 100ms;
  while (core.state_published().load() == cycle && std::chrono::steady_clock::now() < until) {
    std::this_thread::sleep_for(100us);
  }
  reply.set_ok(core.commands_applied() >= ticket);
  if (!reply.ok()) reply.set_message("the loop did not take the command within 500 ms");
  if (core.coupling_refusals() != refusals) refuse(reply, coupling_refusal_message(core));
}

}  // namespace

struct NodeApp::Impl {
  // Two I/O threads: the peer link on one, the service endpoints on the other (IoLane).
  zmq::context_t ctx{transport::kNodeIoThreads};
  std::optional<transport::ZapHandler> zap{};
  CommandAuthority authority{};
  std::uint64_t newest_retune_id{0};  // the command thread's: the newest change number taken
  transport::LinkSecurity server_security{};
  transport::LinkSecurity client_security{};
  // SCHED_FIFO priority of the link threads and ZeroMQ's I/O threads (0: none).
  int link_priority{0};
  std::optional<zmq::socket_t> state_pub{};
  std::optional<zmq::socket_t> state_sub{};
  std::optional<zmq::socket_t> command_rep{};
  std::optional<zmq::socket_t> telemetry_pub{};
  std::optional<transport::SocketMonitor> monitor{};
  std::optional<rt::CpuDmaLatency> dma{};
  std::unique_ptr<rt::PeriodicLoop> loop{};
  std::atomic<bool> running{false};
  std::thread sender{};
  std::thread receiver{};
  std::thread commands{};
  std::thread telemetry{};

  LinkCounters link{};
  // Asks the telemetry thread's flight recorder for its ring.
  std::atomic<bool> flight_request{false};
};

NodeApp::NodeApp(config::NodeSetup setup, std::unique_ptr<device::HapticDevice> device,
                 NodeAppOptions options)
    : setup_(std::move(setup)), device_(std::move(device)), options_(std::move(options)) {
  if (!device_) throw std::invalid_argument("node needs a device");
  if (setup_.settings.session_id == 0) setup_.settings.session_id = random_session_id();
  core_ = std::make_unique<node::NodeCore>(setup_.settings, *device_);
  impl_ = std::make_unique<Impl>();
}

NodeApp::NodeApp(config::NodeSetup setup, std::unique_ptr<device::HapticDeviceAxes> device,
                 NodeAppOptions options)
    : setup_(std::move(setup)), axes_device_(std::move(device)), options_(std::move(options)) {
  if (!axes_device_) throw std::invalid_argument("node needs a device");
  if (setup_.axes != axes_device_->axes()) {
    throw std::invalid_argument("NodeSetup.axes: " + std::to_string(setup_.axes) +
                                " but the device has " + std::to_string(axes_device_->axes()));
  }
  if (setup_.settings.session_id == 0) setup_.settings.session_id = random_session_id();
  // One source for what both cores' settings share.
  node::NodeAxesSettings& a = setup_.axes_settings;
  a.role = setup_.settings.role;
  a.period = setup_.settings.period;
  a.session_id = setup_.settings.session_id;
  a.config_fingerprint = setup_.settings.config_fingerprint;
  a.permits_coupling = setup_.settings.permits_coupling;
  a.coupling_refusal = setup_.settings.coupling_refusal;
  axes_core_ = std::make_unique<node::NodeCoreAxes>(a, *axes_device_);
  impl_ = std::make_unique<Impl>();
}

NodeApp::~NodeApp() { stop(); }

void NodeApp::start() {
  set_up_link_security();
  set_link_thread_priority();
  open_endpoints();
  hold_cpu_dma_latency();
  start_link_threads();
  start_loop();
}

void NodeApp::set_up_link_security() {
  Impl& m = *impl_;
  // Keys first: a bad key file is a setup error, before anything binds.
  std::optional<transport::CurveKeyPair> own;
  if (!setup_.keys.secret_key_file.empty()) {
    own = transport::load_secret_key_file(setup_.keys.secret_key_file);
    if (!setup_.keys.own_public_key.empty() && own->public_z85 != setup_.keys.own_public_key) {
      throw std::invalid_argument("secret key file " + setup_.keys.secret_key_file +
                                  " does not belong to the public key configured for this node "
                                  "in security");
    }
  }
  m.server_security.insecure = setup_.keys.insecure;
  m.server_security.own = own;
  // The supervisor and read-only consoles connect too; command_allowed() decides per request.
  m.server_security.allowed_client_keys =
      own ? admitted_client_keys(setup_.keys) : setup_.keys.allowed_client_keys;
  m.client_security.insecure = setup_.keys.insecure;
  m.client_security.own = own;
  if (!setup_.keys.peer_public_key.empty()) {
    m.client_security.server_public_key = setup_.keys.peer_public_key;
  }
}

void NodeApp::set_link_thread_priority() {
  Impl& m = *impl_;
  // The link threads and ZeroMQ's I/O threads run just below the loop (issue 8 "RT priorities
  // per thread"): under load they must not starve, or states queue and conflate away. Set
  // before the first socket starts the I/O threads; refusals are only warnings here.
  int link_priority = setup_.rt.fifo_priority > 10 ? setup_.rt.fifo_priority - 10 : 0;
  // libzmq asserts (aborts) when its I/O threads cannot take the policy: probe first.
  if (link_priority > 0 && !fifo_permitted(link_priority)) link_priority = 0;
  if (link_priority > 0) {
    m.ctx.set(zmq::ctxopt::thread_sched_policy, SCHED_FIFO);
    m.ctx.set(zmq::ctxopt::thread_priority, link_priority);
  }
  m.link_priority = link_priority;
}

void NodeApp::open_endpoints() {
  Impl& m = *impl_;
  m.zap.emplace(m.ctx);
  using transport::IoLane;
  m.state_pub.emplace(transport::make_state_publisher(m.ctx, setup_.endpoints.state,
                                                      m.server_security, IoLane::kPeerLink));
  m.command_rep.emplace(transport::make_command_server(m.ctx, setup_.endpoints.command,
                                                       m.server_security, IoLane::kService));
  m.telemetry_pub.emplace(transport::make_telemetry_publisher(m.ctx, setup_.endpoints.telemetry,
                                                              m.server_security, IoLane::kService));
  m.state_sub.emplace(transport::make_state_subscriber(m.ctx, setup_.endpoints.peer_state,
                                                       m.client_security, IoLane::kPeerLink));
  // Connections, closures and failed handshakes on every endpoint, counted in telemetry.
  m.monitor.emplace(
      m.ctx,
      std::vector<zmq::socket_t*>{&*m.state_pub, &*m.command_rep, &*m.telemetry_pub, &*m.state_sub},
      setup_.settings.role == Role::kMaster ? "master" : "slave",
      // Each client within its budget (issue 14 finding 5; the state subscriber connects out).
      std::vector<transport::InboundBudget>{transport::kSubscriberBudget,
                                            transport::kCommandClientBudget,
                                            transport::kSubscriberBudget,
                                            {}});
  // Who may do what on the command endpoint (CURVE: each request carries its caller's key).
  m.authority = command_authority(
      setup_.keys,
      transport::choose_mechanism(setup_.endpoints.command, transport::LinkRole::kServer,
                                  m.server_security) == transport::LinkMechanism::kCurve);
  for (const std::string& w : authority_warnings(m.authority)) spdlog::warn("{}", w);
}

void NodeApp::hold_cpu_dma_latency() {
  Impl& m = *impl_;
  if (setup_.cpu_dma_latency_us < 0) return;
  m.dma.emplace(setup_.cpu_dma_latency_us);
  if (m.dma->refusal()) {
    if (setup_.rt.required) {
      throw std::runtime_error("real-time settings refused (rt.required is set):\n  " +
                               *m.dma->refusal());
    }
    refused_.push_back(*m.dma->refusal());
  }
}

void NodeApp::start_link_threads() {
  Impl& m = *impl_;
  m.running = true;
  m.sender = std::thread(keep_running("sender", m.running, [this] { run_state_sender(); }));
  m.receiver = std::thread(keep_running("receiver", m.running, [this] { run_peer_receiver(); }));
  m.commands = std::thread(keep_running("commands", m.running, [this] { run_command_server(); }));
  m.telemetry =
      std::thread(keep_running("telemetry", m.running, [this] { run_telemetry_publisher(); }));
}

void NodeApp::start_loop() {
  Impl& m = *impl_;
  const auto hook = options_.after_step;
  if (axes_core_) {
    m.loop = std::make_unique<rt::PeriodicLoop>(
        setup_.settings.period, setup_.rt, [this, hook](std::chrono::nanoseconds deadline) {
          axes_core_->step(deadline, &impl_->loop->timing());
          if (hook) hook();
        });
  } else {
    m.loop = std::make_unique<rt::PeriodicLoop>(setup_.settings.period, setup_.rt,
                                                [this, hook](std::chrono::nanoseconds deadline) {
                                                  core_->step(deadline, &impl_->loop->timing());
                                                  if (hook) hook();
                                                });
  }
  try {
    m.loop->start();
  } catch (...) {
    stop();
    throw;
  }
  for (const std::string& s : m.loop->refused()) refused_.push_back(s);
  for (const std::string& s : refused_) spdlog::warn("real-time setting refused: {}", s);
}

void NodeApp::apply_link_thread_priority() const {
  const rt::RtSettings link_rt{impl_->link_priority, false, -1, false};
  if (link_rt.fifo_priority > 0) (void)rt::apply_rt_settings(link_rt);
}

void NodeApp::run_state_sender() {
  if (axes_core_) {
    send_states(*axes_core_);
  } else {
    send_states(*core_);
  }
}

// One send per loop cycle, woken by the loop's counter (a futex wake, no lock).
template <class Core>
void NodeApp::send_states(Core& core) {
  Impl& m = *impl_;
  apply_link_thread_priority();
  std::uint32_t seen = core.state_published().load(std::memory_order_acquire);
  transport::NodeStateRecord state;
  while (m.running.load()) {
    core.state_published().wait(seen, std::memory_order_acquire);
    seen = core.state_published().load(std::memory_order_acquire);
    if (!m.running.load()) break;
    if (!core.state_out().read(state)) continue;
    const std::string bytes = transport::encode(state);
    // Never throws (a refused send is one state less; the next cycle sends the next one).
    (void)transport::send_noexcept(*m.state_pub, bytes);
  }
}

void NodeApp::run_peer_receiver() {
  if (axes_core_) {
    receive_states(*axes_core_);
  } else {
    receive_states(*core_);
  }
}

// Every frame that arrived goes through the filter (each one counted); only the newest
// accepted state reaches the loop, so it never works through a backlog. A state of another
// number of axes than this node's is rejected (kWrongAxes).
template <class Core>
void NodeApp::receive_states(Core& core) {
  Impl& m = *impl_;
  apply_link_thread_priority();
  const Role expected = setup_.settings.role == Role::kMaster ? Role::kSlave : Role::kMaster;
  transport::PeerStateFilter filter(expected, axes());
  zmq::message_t frame;
  while (m.running.load()) {
    if (!transport::wait_readable(*m.state_sub, 20ms)) continue;
    std::optional<node::PeerSample> newest;
    for (transport::Received got;
         (got = transport::receive_whole(*m.state_sub, frame)).parts > 0;) {
      const auto arrival = rt::PeriodicLoop::monotonic_now();
      // A multi-part message is no state: counted as malformed (an empty frame).
      const auto accepted = filter.accept(
          got.parts == 1 ? std::string_view(static_cast<const char*>(frame.data()), frame.size())
                         : std::string_view());
      if (!accepted) continue;
      if (accepted->new_session) {
        spdlog::info("peer {} session {:016x}", expected == Role::kMaster ? "master" : "slave",
                     accepted->record.session_id);
      }
      newest = node::PeerSample{accepted->record, arrival.count()};
    }
    if (newest) core.peer_in().write(*newest);
    for (std::size_t i = 0; i < m.link.rejected.size(); ++i) {
      m.link.rejected[i].store(filter.rejected(static_cast<transport::Rejection>(i)));
    }
    m.link.accepted.store(filter.accepted());
    m.link.lost.store(filter.lost());
  }
}

void NodeApp::run_command_server() {
  if (axes_core_) {
    serve_commands(*axes_core_);
  } else {
    serve_commands(*core_);
  }
}

// Applies each command through the loop and replies with the mode the loop reached.
template <class Core>
void NodeApp::serve_commands(Core& core) {
  Impl& m = *impl_;
  while (m.running.load()) {
    if (!transport::wait_readable(*m.command_rep, 50ms)) continue;
    zmq::message_t request;
    // The whole request (every part), so the socket can always answer (issue 14 finding 4:
    // a 2-part request left the REP mid-request and its reply threw EFSM, aborting the node).
    const transport::Received got = transport::receive_whole(*m.command_rep, request);
    if (!got.error.empty()) spdlog::warn("command endpoint: {}", got.error);
    if (got.parts == 0) continue;
    v1::NodeCommand cmd;
    v1::NodeCommandReply reply;
    reply.set_role(to_proto(setup_.settings.role));
    if (got.parts != 1) {
      refuse(reply,
             "malformed command: " + std::to_string(got.parts) + " parts (a command is one frame)");
    } else if (!cmd.ParseFromArray(request.data(), static_cast<int>(request.size()))) {
      refuse(reply, "malformed command");
    } else if (const std::string refusal = command_refusal(
                   m.authority, cmd.kind(), caller_key(request, m.authority.authenticated));
               !refusal.empty()) {
      refuse(reply, refusal);
      reply.set_refused_unauthorized(true);
      spdlog::warn("{}", refusal);
    } else {
      answer_command(core, cmd, reply);
    }
    reply.set_mode(to_proto(core.mode()));
    reply.set_mode_reason(core.mode_reason());
    reply.set_pid(static_cast<std::uint32_t>(::getpid()));
    reply.set_session_id(setup_.settings.session_id);
    const std::string out = reply.SerializeAsString();
    std::string why;
    if (!transport::send_noexcept(*m.command_rep, out, zmq::send_flags::dontwait, &why)) {
      spdlog::warn("command endpoint: reply not sent: {}", why);
    }
  }
}

template <class Core>
void NodeApp::answer_command(Core& core, const v1::NodeCommand& cmd, v1::NodeCommandReply& reply) {
  Impl& m = *impl_;
  if (cmd.kind() == v1::NodeCommand::STATUS) {
    reply.set_ok(true);
  } else if (cmd.kind() == v1::NodeCommand::RETUNE) {
    apply_retune(core, cmd.update(), m.newest_retune_id, reply);
  } else if (cmd.kind() == v1::NodeCommand::FLIGHT_RECORD) {
    m.flight_request.store(true);
    reply.set_ok(true);
    reply.set_message("flight record in the next telemetry message");
  } else if (cmd.kind() == v1::NodeCommand::SHUTDOWN) {
    shutdown_.store(true);
    reply.set_ok(true);
    reply.set_message("shutting down");
  } else if (const auto c = to_command(cmd.kind())) {
    apply_mode_command(core, *c, reply);
    spdlog::info("command {} -> {} ({})", v1::NodeCommand::Kind_Name(cmd.kind()),
                 node::to_string(core.mode()), core.mode_reason());
  } else {
    refuse(reply, "unknown command");
  }
}

void NodeApp::run_telemetry_publisher() {
  if (axes_core_) {
    publish_telemetry(*axes_core_);
  } else {
    publish_telemetry(*core_);
  }
}

// Every cycle's record (each axis of it), batched at telemetry_rate_hz with the loop and link
// statistics; mode changes logged.
template <class Core>
void NodeApp::publish_telemetry(Core& core) {
  Impl& m = *impl_;
  const auto period =
      std::chrono::nanoseconds(static_cast<long long>(1e9 / setup_.telemetry_rate_hz));
  auto next = std::chrono::steady_clock::now() + period;
  node::LoopSnapshot stats{};
  // What the law runs: ActiveLaw for one axis, ActiveLawAxes for several.
  std::conditional_t<std::is_same_v<Core, node::NodeCore>, node::ActiveLaw, node::ActiveLawAxes>
      active{};
  node::Mode last_mode = node::Mode::kDisarmed;
  v1::Telemetry t;
  FlightRecorder flight(setup_.settings.period);
  while (m.running.load()) {
    std::this_thread::sleep_until(next);
    next += period;
    t.Clear();
    t.set_session_id(setup_.settings.session_id);
    t.set_role(to_proto(setup_.settings.role));
    t.set_pid(static_cast<std::uint32_t>(::getpid()));
    t.set_device(setup_.device_kind == device::DeviceKind::kSim ? "sim" : "usb");
    while (const auto rec = core.telemetry_out().try_pop()) {
      v1::CycleRecord* c = t.add_cycles();
      to_proto(*rec, *c);
      if (rec->mode != last_mode) {
        spdlog::info("{} -> {} ({})", node::to_string(last_mode), node::to_string(rec->mode),
                     rec->reason);
        flight.note_mode(rec->mode, rec->reason);
        last_mode = rec->mode;
      }
      flight.keep(*c);
    }
    (void)core.stats_out().read(stats);
    (void)core.active_out().read(active);
    fill_active(*t.mutable_active(), active);
    t.set_mode(to_proto(core.mode()));
    t.set_mode_reason(core.mode_reason());
    fill_configuration(t, core, setup_);
    t.set_sent_time_ns(rt::PeriodicLoop::monotonic_now().count());
    t.set_cycles_dropped(core.telemetry_out().dropped());
    fill_loop_stats(*t.mutable_loop(), stats, setup_.settings.period);
    fill_link_stats(*t.mutable_link(), m.link, stats, setup_.settings.period, m.monitor->counts());
    v1::RtStatus* r = t.mutable_rt();
    r->set_fifo_priority(setup_.rt.fifo_priority);
    r->set_memory_locked(setup_.rt.lock_memory);
    r->set_cpu(setup_.rt.cpu);
    r->set_cpu_dma_latency_us(m.dma && m.dma->held() ? setup_.cpu_dma_latency_us : -1);
    for (const std::string& s : refused_) r->add_refused(s);
    if (m.flight_request.exchange(false)) flight.request();
    flight.hand_over_into(t);
    const std::string bytes = t.SerializeAsString();
    (void)transport::send_noexcept(*m.telemetry_pub, bytes);
  }
}

void NodeApp::stop() {
  if (!impl_) return;
  Impl& m = *impl_;
  if (m.loop) m.loop->stop();
  std::atomic<std::uint32_t>* published = nullptr;
  if (axes_device_) {
    device::CommandAxes zero;
    zero.force_N = device::AxisVector::Zero(axes_device_->axes());
    (void)axes_device_->write(zero);
    (void)axes_device_->deactivate();
    published = &axes_core_->state_published();
  } else {
    (void)device_->write(device::Command{0.0});
    (void)device_->deactivate();
    published = &core_->state_published();
  }
  m.running = false;
  published->fetch_add(1);
  published->notify_all();
  for (std::thread* t : {&m.sender, &m.receiver, &m.commands, &m.telemetry}) {
    if (t->joinable()) t->join();
  }
  if (m.monitor) m.monitor->stop();
  m.state_pub.reset();
  m.state_sub.reset();
  m.command_rep.reset();
  m.telemetry_pub.reset();
}

}  // namespace teleop::runtime
