// Issue 14 finding 2 and "Authority", against the real processes: who may retune a node.
// Only the supervisor's authenticated identity (its CURVE key) may RETUNE; a plaintext node
// refuses every RETUNE unless security.allow_unauthenticated_retune; read-only keys may
// e-stop a node directly (the supervisor not needed) and nothing else; and the supervisor
// raises a CRITICAL alarm and e-stops both nodes when parameters it did not approve are in
// force, without a false alarm on its own guarded changes. Every wait is for a condition seen
// in the nodes' telemetry or the supervisor's status, bounded only against a hang; the
// parameters in force are read from the nodes' own telemetry (ActiveParameters).
#include <gtest/gtest.h>
#include <sys/time.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <iostream>
#include <memory>
#include <thread>

#include "common/transport/zmq_security.hpp"
#include "tests/integration/cli_harness.hpp"
#include "tests/integration/node_harness.hpp"

namespace teleop::test {
namespace {

namespace fs = std::filesystem;

// The file's values: the paddles' gains and a 200 N/m slave wall at 5 mm (soft, far below the
// analysed limit even at a grown round trip, so the supervisor never lowers it on its own and
// the change numbers below are the tests').
constexpr double kFileKps = 600.0;
constexpr double kFileSlaveFixture = 200.0;
// The hostile value of the finding: a 9000 N/m slave wall (the analyser calls it unstable).
constexpr double kHostileSlaveFixture = 9000.0;

struct SystemPorts {
  Ports nodes{};
  int report{free_port()};
  int request{free_port()};
};

using Secure = std::function<void(zmq::socket_t&)>;

struct Keys {
  fs::path key_file{};
  fs::path pub_file{};
  transport::CurveKeyPair pair{};
};

// The real `teleopctl keygen NAME` in `dir`, read back with the nodes' own loader.
Keys keygen(const TempDir& dir, const std::string& name) {
  const fs::path stem = dir.path() / name;
  const CliResult r = teleopctl("keygen " + stem.string());
  EXPECT_EQ(r.exit_code, 0) << r.out;
  Keys k;
  k.key_file = stem.string() + ".key";
  k.pub_file = stem.string() + ".pub";
  k.pair = transport::load_secret_key_file(k.key_file);
  return k;
}

Secure curve_as(const Keys& client, const Keys& server) {
  return [c = client.pair, s = server.pair.public_z85](zmq::socket_t& sock) {
    sock.set(zmq::sockopt::curve_serverkey, s);
    sock.set(zmq::sockopt::curve_publickey, c.public_z85);
    sock.set(zmq::sockopt::curve_secretkey, c.secret_z85);
  };
}

std::string quoted(const std::string& s) { return "\"" + s + "\""; }

// The paddles on these ports with a 200 N/m slave wall, the human pushing 0.5 N into it
// from engagement on, `node_extra(master)` in each node section, then `tail`.
std::string system_text(const SystemPorts& p, const std::function<std::string(bool)>& node_extra,
                        const std::string& tail) {
  // Real-time loops where the kernel permits them (as the other live tests): the link stays
  // fresh on a loaded host.
  return paddles_system(node_section(p.nodes, true, node_extra(true), 80),
                        node_section(p.nodes, false, node_extra(false), 80),
                        "fixture { stiffness_N_per_m: 200 position_m: 0.005 }", 0.5) +
         "supervisor { report_endpoint: \"" + tcp(p.report) + "\" request_endpoint: \"" +
         tcp(p.request) + "\" record: false }\n" + tail;
}

std::string no_extra(bool /*master*/) { return ""; }

// The master, the slave and (when asked) the supervisor from one file, each node's telemetry
// tapped (with `secure` when the nodes run CURVE).
class AuthoritySystem {
 public:
  AuthoritySystem(const TempDir& dir, const std::string& text, const SystemPorts& ports,
                  bool with_supervisor, const Secure& tap_master = {},
                  const Secure& tap_slave = {}) {
    config_ = dir.write("system.textproto", text);
    mt_ = std::make_unique<TelemetryTap>(ctx_, tcp(ports.nodes.master_telemetry), tap_master);
    st_ = std::make_unique<TelemetryTap>(ctx_, tcp(ports.nodes.slave_telemetry), tap_slave);
    if (with_supervisor) {
      supervisor_ = std::make_unique<Process>(
          SUPERVISOR_BIN, std::vector<std::string>{config_.string()}, dir.path() / "sup.log");
    }
    master_ = std::make_unique<Process>(MASTER_BIN, std::vector<std::string>{config_.string()},
                                        dir.path() / "master.log");
    slave_ = std::make_unique<Process>(SLAVE_BIN, std::vector<std::string>{config_.string()},
                                       dir.path() / "slave.log");
  }
  zmq::context_t& ctx() { return ctx_; }
  const TelemetryTap& mt() const { return *mt_; }
  const TelemetryTap& st() const { return *st_; }
  Process& master() { return *master_; }
  [[nodiscard]] const fs::path& config() const { return config_; }
  [[nodiscard]] std::string logs() const {
    std::string s = "--- master\n" + master_->log() + "--- slave\n" + slave_->log();
    if (supervisor_) s += "--- supervisor\n" + supervisor_->log();
    return s;
  }
  [[nodiscard]] bool linked() const {
    auto l = [](const v1::Telemetry& t) { return t.link().accepted() > 0; };
    return mt_->wait_for(l) && st_->wait_for(l);
  }
  // The master's newest sequence in telemetry.
  [[nodiscard]] std::uint64_t master_sequence() const {
    const auto t = mt_->last();
    return t && t->cycles_size() > 0 ? t->cycles(t->cycles_size() - 1).sequence() : 0;
  }

 private:
  zmq::context_t ctx_{1};
  fs::path config_;
  std::unique_ptr<TelemetryTap> mt_;
  std::unique_ptr<TelemetryTap> st_;
  std::unique_ptr<Process> supervisor_;
  std::unique_ptr<Process> master_;
  std::unique_ptr<Process> slave_;
};

std::optional<v1::NodeCommandReply> request(zmq::context_t& ctx, int port, const v1::NodeCommand& c,
                                            const Secure& secure = {}) {
  zmq::socket_t s(ctx, zmq::socket_type::req);
  s.set(zmq::sockopt::linger, 0);
  s.set(zmq::sockopt::rcvtimeo, 5000);
  if (secure) secure(s);
  s.connect(tcp(port));
  const std::string bytes = c.SerializeAsString();
  s.send(zmq::buffer(bytes), zmq::send_flags::none);
  zmq::message_t reply;
  if (!s.recv(reply)) return std::nullopt;
  v1::NodeCommandReply r;
  if (!r.ParseFromArray(reply.data(), static_cast<int>(reply.size()))) return std::nullopt;
  return r;
}

v1::NodeCommand command(v1::NodeCommand::Kind kind) {
  v1::NodeCommand c;
  c.set_kind(kind);
  return c;
}

// The finding's RETUNE: the file's gains with a 9000 N/m slave wall, applied at `at`, no ramp.
v1::NodeCommand hostile_retune(std::uint64_t change_id, std::uint64_t at) {
  v1::NodeCommand c = command(v1::NodeCommand::RETUNE);
  v1::ParameterUpdate* u = c.mutable_update();
  u->set_change_id(change_id);
  u->mutable_gains()->set_kpm(600);
  u->mutable_gains()->set_kps(600);
  u->mutable_gains()->set_kdm(2);
  u->mutable_gains()->set_kds(2);
  u->set_slave_fixture_stiffness_n_per_m(kHostileSlaveFixture);
  u->set_slave_fixture_position_m(0.005);
  u->set_apply_at_master_sequence(at);
  u->set_ramp_ms(0);
  return c;
}

// Until both nodes' telemetry shows cycles past master sequence `at` (the slave's by the master
// sequence it has seen): a change due at `at` would be in force by then.
bool both_past(const AuthoritySystem& sys, std::uint64_t at) {
  auto past = [at](const v1::Telemetry& t) {
    return t.cycles_size() > 0 && t.cycles(t.cycles_size() - 1).master_sequence() > at;
  };
  return sys.mt().wait_for(past) && sys.st().wait_for(past);
}

void expect_file_values_in_force(const TelemetryTap& tap, const char* node) {
  const auto t = tap.last();
  ASSERT_TRUE(t.has_value()) << node;
  EXPECT_EQ(t->active().change_id(), 0u) << node << ": " << t->active().DebugString();
  EXPECT_DOUBLE_EQ(t->active().gains().kps(), kFileKps) << node;
  EXPECT_DOUBLE_EQ(t->active().slave_fixture_stiffness_n_per_m(), kFileSlaveFixture) << node;
  for (const v1::CycleRecord& c : tap.cycles()) {
    ASSERT_EQ(c.parameter_change_id(), 0u)
        << node << " ran change " << c.parameter_change_id() << " at sequence " << c.sequence();
  }
}

void arm_and_engage(AuthoritySystem& sys, const SystemPorts& p, const Secure& master_as = {},
                    const Secure& slave_as = {}) {
  for (const auto kind : {v1::NodeCommand::ARM, v1::NodeCommand::ENGAGE}) {
    for (const auto& [port, secure] : {std::pair{p.nodes.master_command, master_as},
                                       std::pair{p.nodes.slave_command, slave_as}}) {
      const auto r = request(sys.ctx(), port, command(kind), secure);
      ASSERT_TRUE(r.has_value()) << "no reply from " << port << "\n" << sys.logs();
      ASSERT_TRUE(r->ok()) << r->message();
    }
  }
  ASSERT_TRUE(sys.mt().wait_for_mode(v1::ENGAGED)) << sys.logs();
  ASSERT_TRUE(sys.st().wait_for_mode(v1::ENGAGED)) << sys.logs();
}

bool has_alarm(const v1::SupervisorStatus& s, const std::string& kind) {
  return std::any_of(s.recent_alarms().begin(), s.recent_alarms().end(),
                     [&](const v1::Alarm& a) { return a.kind() == kind; });
}

std::optional<v1::Alarm> alarm_of(const v1::SupervisorStatus& s, const std::string& kind) {
  for (const v1::Alarm& a : s.recent_alarms()) {
    if (a.kind() == kind) return a;
  }
  return std::nullopt;
}

// (a) Plaintext, no opt-in: a RETUNE straight to each node is refused, naming why, and the
// nodes' parameters in force stay the file's past the change's apply point. The node says at
// start that it refuses retunes.

// `teleopctl set`, asked again while the supervisor says it has not heard both nodes yet: it
// starts with the nodes and hears their first telemetry a moment after the test's own taps
// do (longer under the sanitizers). Asked again too when it refused because it measured a
// loopback round trip of 8 samples or more: on loopback the round trip is 1-2 samples, so that
// is a host stall the supervisor rightly analysed (CI saw 16 samples once, and every fixture is
// unstable there); its window forgets the stall. Any other answer is returned at once.
bool stalled_round_trip(const CliResult& r) {
  const std::string key = "round trip ";
  const std::size_t at = r.out.find(key);
  if (r.exit_code != 3 || at == std::string::npos) return false;
  return std::atoi(r.out.c_str() + at + key.size()) >= 8;
}

CliResult set_once_both_heard(const std::string& args) {
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  CliResult r = teleopctl(args);
  while ((r.out.find("both nodes must be running") != std::string::npos || stalled_round_trip(r)) &&
         std::chrono::steady_clock::now() < until) {
    if (stalled_round_trip(r)) std::cout << "host stall, asked again: " << r.out;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    r = teleopctl(args);
  }
  return r;
}

TEST(HostileAuthority, PlaintextRetuneStraightToANodeIsRefusedAndNothingChanges) {
  TempDir dir;
  SystemPorts p;
  AuthoritySystem sys(dir, system_text(p, no_extra, ""), p, false);
  ASSERT_TRUE(sys.linked()) << sys.logs();
  ASSERT_NO_FATAL_FAILURE(arm_and_engage(sys, p));
  const std::uint64_t at = sys.master_sequence() + 50;
  for (const int port : {p.nodes.master_command, p.nodes.slave_command}) {
    const auto r = request(sys.ctx(), port, hostile_retune(1, at));
    ASSERT_TRUE(r.has_value()) << sys.logs();
    EXPECT_FALSE(r->ok()) << r->message();
    EXPECT_TRUE(r->refused_unauthorized()) << r->message();
    EXPECT_NE(r->message().find("allow_unauthenticated_retune"), std::string::npos) << r->message();
  }
  ASSERT_TRUE(both_past(sys, at + 50)) << sys.logs();
  expect_file_values_in_force(sys.mt(), "master");
  expect_file_values_in_force(sys.st(), "slave");
  EXPECT_EQ(sys.mt().mode(), v1::ENGAGED);
  EXPECT_NE(sys.master().log().find("plaintext command endpoint: every RETUNE is refused"),
            std::string::npos)
      << sys.master().log();
}

// A plaintext peer can put any "User-Id" into its own ZMTP metadata; the node must not take
// it for the supervisor's key. A raw ZMTP 3.0 NULL client claims the supervisor's key.
TEST(HostileAuthority, PlaintextClientClaimingTheSupervisorsUserIdIsStillRefused) {
  TempDir dir;
  SystemPorts p;
  const Keys supervisor = keygen(dir, "supervisor");
  AuthoritySystem sys(dir,
                      system_text(p, no_extra,
                                  "security { supervisor_public_key: " +
                                      quoted(supervisor.pair.public_z85) + " }\n"),
                      p, false);
  ASSERT_TRUE(sys.linked()) << sys.logs();
  const std::uint64_t at = sys.master_sequence() + 50;
  const std::string body = hostile_retune(1, at).SerializeAsString();
  // Greeting: signature, version 3.0, mechanism NULL, as-server 0, filler.
  std::string wire(64, '\0');
  wire[0] = static_cast<char>(0xFF);
  wire[9] = 0x7F;
  wire[10] = 3;
  wire[11] = 0;
  wire.replace(12, 4, "NULL");
  // READY with Socket-Type REQ and the claimed User-Id.
  auto property = [](const std::string& name, const std::string& value) {
    std::string s(1, static_cast<char>(name.size()));
    s += name;
    const std::uint32_t n = static_cast<std::uint32_t>(value.size());
    s += static_cast<char>(n >> 24);
    s += static_cast<char>((n >> 16) & 0xFF);
    s += static_cast<char>((n >> 8) & 0xFF);
    s += static_cast<char>(n & 0xFF);
    return s + value;
  };
  const std::string ready = std::string("\x05READY", 6) + property("Socket-Type", "REQ") +
                            property("User-Id", supervisor.pair.public_z85);
  wire += static_cast<char>(0x04);
  wire += static_cast<char>(ready.size());
  wire += ready;
  const std::size_t handshake = wire.size();
  // REQ: an empty delimiter frame, then the request (long frame: 8-byte size).
  wire += std::string("\x01\x00", 2);
  wire += static_cast<char>(0x02);
  for (int shift = 56; shift >= 0; shift -= 8) {
    wire += static_cast<char>((static_cast<std::uint64_t>(body.size()) >> shift) & 0xFF);
  }
  wire += body;
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = htons(static_cast<std::uint16_t>(p.nodes.slave_command));
  ASSERT_EQ(::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a)), 0);
  // The handshake first; the request only once the node's READY is in (sent before it, it
  // would land in the node's handshake and end the connection).
  std::string in;
  const auto until = std::chrono::steady_clock::now() + 5s;
  auto read_until = [&](const std::string& text) {
    while (in.find(text) == std::string::npos && std::chrono::steady_clock::now() < until) {
      char buf[4096];
      timeval tv{0, 100000};
      ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof(tv));
      const ssize_t n = ::recv(fd, buf, sizeof(buf), 0);
      if (n > 0) in.append(buf, static_cast<std::size_t>(n));
      if (n == 0) break;
    }
  };
  ASSERT_EQ(::send(fd, wire.data(), handshake, 0), static_cast<ssize_t>(handshake));
  read_until("READY");
  ASSERT_EQ(::send(fd, wire.data() + handshake, wire.size() - handshake, 0),
            static_cast<ssize_t>(wire.size() - handshake));
  // The reply (delimiter, reply frame) carries the refusal text.
  const std::string refused = "RETUNE refused";
  read_until(refused);
  ::close(fd);
  EXPECT_NE(in.find(refused), std::string::npos) << "reply bytes: " << in.size() << "\n"
                                                 << sys.logs();
  ASSERT_TRUE(both_past(sys, at + 50)) << sys.logs();
  expect_file_values_in_force(sys.st(), "slave");
}

// Master, slave, supervisor, console and viewer keys; the supervisor's key only as
// security.supervisor_public_key (the nodes admit it for that), the console's as a client,
// the viewer's read-only.
struct CurveKeys {
  explicit CurveKeys(const TempDir& dir)
      : master(keygen(dir, "master")),
        slave(keygen(dir, "slave")),
        supervisor(keygen(dir, "supervisor")),
        console(keygen(dir, "console")),
        viewer(keygen(dir, "viewer")) {}
  [[nodiscard]] std::string node_extra(bool is_master) const {
    return "secret_key_file: " + quoted((is_master ? master : slave).key_file.string());
  }
  [[nodiscard]] std::string security() const {
    return "security { master_public_key: " + quoted(master.pair.public_z85) +
           " slave_public_key: " + quoted(slave.pair.public_z85) +
           " supervisor_public_key: " + quoted(supervisor.pair.public_z85) +
           " client_public_keys: " + quoted(console.pair.public_z85) +
           " read_only_client_public_keys: " + quoted(viewer.pair.public_z85) + " }\n";
  }
  [[nodiscard]] std::string text(const SystemPorts& p) const {
    return system_text(
        p, [this](bool m) { return node_extra(m); }, security());
  }
  Keys master;
  Keys slave;
  Keys supervisor;
  Keys console;
  Keys viewer;
};

// (b) Under CURVE: a console key's RETUNE (and SHUTDOWN) straight to a node is refused; the
// supervisor's key is admitted and its RETUNE applied on both nodes.
TEST(HostileAuthority, UnderCurveAConsoleKeysRetuneIsRefusedAndTheSupervisorsKeysApplied) {
  TempDir dir;
  SystemPorts p;
  const CurveKeys k(dir);
  AuthoritySystem sys(dir, k.text(p), p, false, curve_as(k.console, k.master),
                      curve_as(k.console, k.slave));
  ASSERT_TRUE(sys.linked()) << sys.logs();
  ASSERT_NO_FATAL_FAILURE(
      arm_and_engage(sys, p, curve_as(k.console, k.master), curve_as(k.console, k.slave)));
  const std::uint64_t at = sys.master_sequence() + 50;
  for (const auto& [port, server] :
       {std::pair{p.nodes.master_command, &k.master}, std::pair{p.nodes.slave_command, &k.slave}}) {
    for (const auto& c : {hostile_retune(1, at), command(v1::NodeCommand::SHUTDOWN)}) {
      const auto r = request(sys.ctx(), port, c, curve_as(k.console, *server));
      ASSERT_TRUE(r.has_value()) << sys.logs();
      EXPECT_FALSE(r->ok()) << r->message();
      EXPECT_TRUE(r->refused_unauthorized()) << r->message();
      EXPECT_NE(r->message().find(k.console.pair.public_z85), std::string::npos) << r->message();
    }
  }
  ASSERT_TRUE(both_past(sys, at + 50)) << sys.logs();
  expect_file_values_in_force(sys.mt(), "master");
  expect_file_values_in_force(sys.st(), "slave");

  // The supervisor's key: the same change (a number never used) is taken by both.
  const std::uint64_t at2 = sys.master_sequence() + 50;
  for (const auto& [port, server] :
       {std::pair{p.nodes.master_command, &k.master}, std::pair{p.nodes.slave_command, &k.slave}}) {
    const auto r =
        request(sys.ctx(), port, hostile_retune(2, at2), curve_as(k.supervisor, *server));
    ASSERT_TRUE(r.has_value()) << sys.logs();
    EXPECT_TRUE(r->ok()) << r->message();
  }
  for (const TelemetryTap* tap : {&sys.mt(), &sys.st()}) {
    EXPECT_TRUE(tap->wait_for([](const v1::Telemetry& t) {
      return t.active().change_id() == 2 &&
             t.active().slave_fixture_stiffness_n_per_m() == kHostileSlaveFixture;
    })) << sys.logs();
  }
}

// (c) A read-only key reaches the nodes directly: its e-stop sends both SAFE (no supervisor is
// running), while its arm, engage, retune, clear, flight record and shutdown are refused.
TEST(HostileAuthority, ReadOnlyKeyEstopsTheNodesDirectlyButCannotArmEngageOrRetune) {
  TempDir dir;
  SystemPorts p;
  const CurveKeys k(dir);
  AuthoritySystem sys(dir, k.text(p), p, false, curve_as(k.console, k.master),
                      curve_as(k.console, k.slave));
  ASSERT_TRUE(sys.linked()) << sys.logs();
  auto as_viewer = [&](int port, const Keys& server, const v1::NodeCommand& c) {
    return request(sys.ctx(), port, c, curve_as(k.viewer, server));
  };
  // Disarmed: the viewer cannot arm.
  for (const auto& [port, server] :
       {std::pair{p.nodes.master_command, &k.master}, std::pair{p.nodes.slave_command, &k.slave}}) {
    const auto r = as_viewer(port, *server, command(v1::NodeCommand::ARM));
    ASSERT_TRUE(r.has_value()) << "a read-only key gets no reply\n" << sys.logs();
    EXPECT_FALSE(r->ok());
    EXPECT_TRUE(r->refused_unauthorized()) << r->message();
    EXPECT_EQ(r->mode(), v1::DISARMED);
    const auto s = as_viewer(port, *server, command(v1::NodeCommand::STATUS));
    ASSERT_TRUE(s.has_value());
    EXPECT_TRUE(s->ok()) << s->message();
  }
  // Armed by the console: the viewer cannot engage.
  for (const auto& [port, server] :
       {std::pair{p.nodes.master_command, &k.master}, std::pair{p.nodes.slave_command, &k.slave}}) {
    const auto r =
        request(sys.ctx(), port, command(v1::NodeCommand::ARM), curve_as(k.console, *server));
    ASSERT_TRUE(r.has_value() && r->ok()) << sys.logs();
  }
  for (const auto& [port, server] :
       {std::pair{p.nodes.master_command, &k.master}, std::pair{p.nodes.slave_command, &k.slave}}) {
    const auto r = as_viewer(port, *server, command(v1::NodeCommand::ENGAGE));
    ASSERT_TRUE(r.has_value());
    EXPECT_FALSE(r->ok());
    EXPECT_TRUE(r->refused_unauthorized()) << r->message();
    EXPECT_EQ(r->mode(), v1::ARMED);
  }
  // Engaged by the console: the viewer cannot retune, flight-record or shut down.
  for (const auto& [port, server] :
       {std::pair{p.nodes.master_command, &k.master}, std::pair{p.nodes.slave_command, &k.slave}}) {
    const auto r =
        request(sys.ctx(), port, command(v1::NodeCommand::ENGAGE), curve_as(k.console, *server));
    ASSERT_TRUE(r.has_value() && r->ok()) << sys.logs();
  }
  ASSERT_TRUE(sys.mt().wait_for_mode(v1::ENGAGED)) << sys.logs();
  ASSERT_TRUE(sys.st().wait_for_mode(v1::ENGAGED)) << sys.logs();
  const std::uint64_t at = sys.master_sequence() + 50;
  for (const auto& [port, server] :
       {std::pair{p.nodes.master_command, &k.master}, std::pair{p.nodes.slave_command, &k.slave}}) {
    for (const auto& c :
         {hostile_retune(1, at), command(v1::NodeCommand::FLIGHT_RECORD),
          command(v1::NodeCommand::SHUTDOWN), command(v1::NodeCommand::DISENGAGE)}) {
      const auto r = as_viewer(port, *server, c);
      ASSERT_TRUE(r.has_value());
      EXPECT_FALSE(r->ok()) << v1::NodeCommand::Kind_Name(c.kind());
      EXPECT_TRUE(r->refused_unauthorized()) << r->message();
      EXPECT_NE(r->message().find("read-only"), std::string::npos) << r->message();
    }
  }
  ASSERT_TRUE(both_past(sys, at + 50)) << sys.logs();
  expect_file_values_in_force(sys.mt(), "master");
  expect_file_values_in_force(sys.st(), "slave");
  EXPECT_EQ(sys.mt().mode(), v1::ENGAGED);
  EXPECT_EQ(sys.st().mode(), v1::ENGAGED);
  // The e-stop, straight from the read-only key to each node.
  for (const auto& [port, server] :
       {std::pair{p.nodes.master_command, &k.master}, std::pair{p.nodes.slave_command, &k.slave}}) {
    const auto r = as_viewer(port, *server, command(v1::NodeCommand::ESTOP));
    ASSERT_TRUE(r.has_value()) << sys.logs();
    EXPECT_TRUE(r->ok()) << r->message();
    EXPECT_EQ(r->mode(), v1::SAFE);
  }
  EXPECT_TRUE(sys.mt().wait_for_mode(v1::SAFE)) << sys.logs();
  EXPECT_TRUE(sys.st().wait_for_mode(v1::SAFE)) << sys.logs();
  // Cleared only by a client that may command.
  const auto clear = as_viewer(p.nodes.master_command, k.master, command(v1::NodeCommand::CLEAR));
  ASSERT_TRUE(clear.has_value());
  EXPECT_FALSE(clear->ok());
  EXPECT_EQ(clear->mode(), v1::SAFE);
}

// The plaintext system with the opt-in and a supervisor.
std::string opted_in(const SystemPorts& p) {
  return system_text(p, no_extra, kAllowUnauthenticatedRetune);
}

// Waits for the supervisor's status to hold `pred`.
bool status_holds(zmq::context_t& ctx, int port,
                  const std::function<bool(const v1::SupervisorStatus&)>& pred) {
  return eventually([&] {
    const auto s = supervisor_status(ctx, port);
    return s && pred(*s);
  });
}

// The first cycle at or after which `pred` holds, from the tap's record.
std::optional<v1::CycleRecord> first_cycle(
    const TelemetryTap& tap, const std::function<bool(const v1::CycleRecord&)>& pred) {
  for (const v1::CycleRecord& c : tap.cycles()) {
    if (pred(c)) return c;
  }
  return std::nullopt;
}

// (d) With the opt-in, an unapproved RETUNE applied straight to the nodes: the supervisor
// raises a CRITICAL alarm naming the node, the field, the value in force and the one approved,
// and e-stops both nodes, seen in their telemetry.
TEST(HostileAuthority, UnapprovedRetuneInForceRaisesCriticalAndDrivesBothNodesSafe) {
  TempDir dir;
  SystemPorts p;
  AuthoritySystem sys(dir, opted_in(p), p, true);
  ASSERT_TRUE(sys.linked()) << sys.logs();
  ASSERT_TRUE(status_holds(sys.ctx(), p.request, [](const v1::SupervisorStatus& s) {
    return s.master_alive() && s.slave_alive();
  })) << sys.logs();
  ASSERT_NO_FATAL_FAILURE(arm_and_engage(sys, p));
  EXPECT_NE(sys.master().log().find("ANY local client may retune this node"), std::string::npos)
      << sys.master().log();
  const std::uint64_t at = sys.master_sequence() + 50;
  for (const int port : {p.nodes.master_command, p.nodes.slave_command}) {
    const auto r = request(sys.ctx(), port, hostile_retune(7, at));
    ASSERT_TRUE(r.has_value() && r->ok()) << (r ? r->message() : "no reply");
  }
  ASSERT_TRUE(sys.mt().wait_for_mode(v1::SAFE)) << sys.logs();
  ASSERT_TRUE(sys.st().wait_for_mode(v1::SAFE)) << sys.logs();
  // An alarm for the slave naming what is in force and what was approved, and one (whichever
  // node's telemetry came first) with the e-stop as its action.
  std::optional<v1::Alarm> alarm;
  std::optional<v1::Alarm> acted;
  ASSERT_TRUE(status_holds(sys.ctx(), p.request, [&](const v1::SupervisorStatus& s) {
    for (const v1::Alarm& a : s.recent_alarms()) {
      if (a.kind() != "unapproved_parameters") continue;
      if (a.side() == "slave") alarm = a;
      if (a.action().find("e-stopped both nodes") != std::string::npos) acted = a;
    }
    return alarm && acted;
  })) << sys.logs();
  EXPECT_EQ(alarm->severity(), v1::Alarm::CRITICAL);
  EXPECT_EQ(acted->severity(), v1::Alarm::CRITICAL);
  EXPECT_NE(alarm->message().find("slave_fixture_stiffness_N_per_m 9000"), std::string::npos)
      << alarm->message();
  EXPECT_NE(alarm->message().find("change 7 was never approved"), std::string::npos)
      << alarm->message();
  bool named_in_force = false;
  bool named_approved = false;
  for (const v1::Evidence& e : alarm->evidence()) {
    named_in_force = named_in_force || (e.name() == "slave_fixture_stiffness_N_per_m in force" &&
                                        e.value() == kHostileSlaveFixture);
    named_approved = named_approved || (e.name() == "slave_fixture_stiffness_N_per_m approved" &&
                                        e.value() == kFileSlaveFixture);
  }
  EXPECT_TRUE(named_in_force && named_approved) << alarm->DebugString();
  // From the slave's own clock: the change in force, then SAFE.
  const auto applied =
      first_cycle(sys.st(), [](const v1::CycleRecord& c) { return c.parameter_change_id() == 7; });
  const auto safe =
      first_cycle(sys.st(), [](const v1::CycleRecord& c) { return c.mode() == v1::SAFE; });
  ASSERT_TRUE(applied && safe);
  EXPECT_GE(safe->sample_time_ns(), applied->sample_time_ns());
  std::cout << "unapproved change in force -> slave SAFE: "
            << static_cast<double>(safe->sample_time_ns() - applied->sample_time_ns()) * 1e-6
            << " ms\n";
  // Cleared with the values still in force: e-stopped again (a DISARMED cycle, then SAFE).
  const std::size_t before = sys.mt().cycles().size();
  const auto clear = request(sys.ctx(), p.nodes.master_command, command(v1::NodeCommand::CLEAR));
  ASSERT_TRUE(clear.has_value());
  EXPECT_TRUE(eventually([&] {
    const auto c = sys.mt().cycles();
    const auto disarmed =
        std::find_if(c.begin() + static_cast<std::ptrdiff_t>(before), c.end(),
                     [](const v1::CycleRecord& r) { return r.mode() == v1::DISARMED; });
    return disarmed != c.end() && std::any_of(disarmed, c.end(), [](const v1::CycleRecord& r) {
             return r.mode() == v1::SAFE;
           });
  })) << sys.logs();
}

// Siblings: a replayed or reused change number. After a guarded `teleopctl set` made change 1,
// a RETUNE numbered 1 again (the supervisor's bytes replayed, or its number reused with other
// values) is refused by both nodes and nothing changes; the supervisor's own next change is
// still taken.
TEST(HostileAuthority, ReplayedOrReusedChangeNumberIsRefusedByTheNodes) {
  TempDir dir;
  SystemPorts p;
  AuthoritySystem sys(dir, opted_in(p), p, true);
  ASSERT_TRUE(sys.linked()) << sys.logs();
  ASSERT_NO_FATAL_FAILURE(arm_and_engage(sys, p));
  const std::string sup = " --supervisor 127.0.0.1:" + std::to_string(p.request);
  const CliResult set = set_once_both_heard("set slave.fixture.stiffness_N_per_m=150" + sup);
  ASSERT_EQ(set.exit_code, 0) << set.out << sys.logs();
  for (const TelemetryTap* tap : {&sys.mt(), &sys.st()}) {
    ASSERT_TRUE(tap->wait_for([](const v1::Telemetry& t) {
      return t.active().change_id() == 1 && t.active().ramp_progress() >= 1.0;
    })) << sys.logs();
  }
  const std::uint64_t at = sys.master_sequence() + 50;
  for (const int port : {p.nodes.master_command, p.nodes.slave_command}) {
    const auto r = request(sys.ctx(), port, hostile_retune(1, at));
    ASSERT_TRUE(r.has_value());
    EXPECT_FALSE(r->ok());
    EXPECT_NE(r->message().find("change 1 is not newer than change 1"), std::string::npos)
        << r->message();
  }
  ASSERT_TRUE(both_past(sys, at + 50)) << sys.logs();
  for (const TelemetryTap* tap : {&sys.mt(), &sys.st()}) {
    const auto t = tap->last();
    ASSERT_TRUE(t.has_value());
    EXPECT_EQ(t->active().change_id(), 1u);
    EXPECT_EQ(t->active().slave_fixture_stiffness_n_per_m(), 150.0);
    EXPECT_EQ(t->mode(), v1::ENGAGED);
  }
  const CliResult next = set_once_both_heard("set slave.fixture.stiffness_N_per_m=250" + sup);
  ASSERT_EQ(next.exit_code, 0) << next.out << sys.logs();
  EXPECT_TRUE(sys.st().wait_for([](const v1::Telemetry& t) {
    return t.active().change_id() == 2 && t.active().slave_fixture_stiffness_n_per_m() == 250.0;
  })) << sys.logs();
}

// A sibling: an attacker (with the opt-in) takes the supervisor's next change number first.
// The supervisor never approved it: CRITICAL and both nodes safe; its own next change (whose
// number the slave now refuses) fails with the reason, and the one after (a number never
// sent) is taken and puts approved values back in force.
TEST(HostileAuthority, ChangeNumberTakenAheadOfTheSupervisorIsCaught) {
  TempDir dir;
  SystemPorts p;
  AuthoritySystem sys(dir, opted_in(p), p, true);
  ASSERT_TRUE(sys.linked()) << sys.logs();
  ASSERT_NO_FATAL_FAILURE(arm_and_engage(sys, p));
  const std::uint64_t at = sys.master_sequence() + 50;
  const auto r = request(sys.ctx(), p.nodes.slave_command, hostile_retune(1, at));
  ASSERT_TRUE(r.has_value() && r->ok());
  ASSERT_TRUE(sys.st().wait_for_mode(v1::SAFE)) << sys.logs();
  ASSERT_TRUE(sys.mt().wait_for_mode(v1::SAFE)) << sys.logs();
  std::optional<v1::Alarm> alarm;
  ASSERT_TRUE(status_holds(sys.ctx(), p.request, [&](const v1::SupervisorStatus& s) {
    alarm = alarm_of(s, "unapproved_parameters");
    return alarm.has_value();
  })) << sys.logs();
  EXPECT_EQ(alarm->side(), "slave");
  EXPECT_EQ(alarm->severity(), v1::Alarm::CRITICAL);
  const std::string sup = " --supervisor 127.0.0.1:" + std::to_string(p.request);
  const CliResult refused = set_once_both_heard("set slave.fixture.stiffness_N_per_m=200" + sup);
  EXPECT_NE(refused.exit_code, 0) << refused.out;
  EXPECT_NE(refused.out.find("not newer than change 1"), std::string::npos) << refused.out;
  // The master had taken that change (1): since issue 16's review the supervisor rolls it back
  // on both nodes as change 2, the approved values under a number the slave takes.
  EXPECT_NE(refused.out.find("rolled back on both nodes as change 2"), std::string::npos)
      << refused.out;
  const CliResult taken = set_once_both_heard("set slave.fixture.stiffness_N_per_m=200" + sup);
  ASSERT_EQ(taken.exit_code, 0) << taken.out << sys.logs();
  // Approved values back in force on the slave: the audit is satisfied again (change 2, the
  // roll-back, and 3, the second set, both carry them).
  EXPECT_TRUE(sys.st().wait_for([](const v1::Telemetry& t) {
    return t.active().change_id() == 3 && t.active().ramp_progress() >= 1.0 &&
           t.active().slave_fixture_stiffness_n_per_m() == kFileSlaveFixture;
  })) << sys.logs();
}

// (e) No false alarm on the supervisor's own changes: two guarded `teleopctl set`s, the second
// sent while the first is still waiting or ramping, applied on both nodes with no alarm of
// unapproved parameters and the nodes still engaged.
TEST(HostileAuthority, GuardedSetsThroughTheSupervisorRaiseNoFalseAlarm) {
  TempDir dir;
  SystemPorts p;
  AuthoritySystem sys(dir, opted_in(p), p, true);
  ASSERT_TRUE(sys.linked()) << sys.logs();
  ASSERT_NO_FATAL_FAILURE(arm_and_engage(sys, p));
  const std::string sup = " --supervisor 127.0.0.1:" + std::to_string(p.request);
  const CliResult first =
      set_once_both_heard("set slave.fixture.stiffness_N_per_m=150 gains.kps=550" + sup);
  ASSERT_EQ(first.exit_code, 0) << first.out << sys.logs();
  const CliResult second = set_once_both_heard("set slave.fixture.stiffness_N_per_m=250" + sup);
  ASSERT_EQ(second.exit_code, 0) << second.out << sys.logs();
  for (const TelemetryTap* tap : {&sys.mt(), &sys.st()}) {
    ASSERT_TRUE(tap->wait_for([](const v1::Telemetry& t) {
      return t.active().change_id() == 2 && t.active().ramp_progress() >= 1.0 &&
             t.active().slave_fixture_stiffness_n_per_m() == 250.0 &&
             t.active().gains().kps() == 550.0;
    })) << sys.logs();
  }
  // A second of telemetry after that, all heard by the supervisor (its status is built from
  // it): still engaged, no alarm.
  const std::uint64_t then = sys.master_sequence() + 1000;
  ASSERT_TRUE(both_past(sys, then)) << sys.logs();
  const auto s = supervisor_status(sys.ctx(), p.request);
  ASSERT_TRUE(s.has_value());
  EXPECT_FALSE(has_alarm(*s, "unapproved_parameters")) << s->DebugString();
  EXPECT_EQ(sys.mt().mode(), v1::ENGAGED);
  EXPECT_EQ(sys.st().mode(), v1::ENGAGED);
}

// (b, the real path) Under CURVE with the supervisor's key only in
// security.supervisor_public_key: `teleopctl set` through the supervisor is applied on both
// nodes, with no false alarm.
TEST(HostileAuthority, UnderCurveAGuardedSetThroughTheSupervisorIsApplied) {
  TempDir dir;
  SystemPorts p;
  const CurveKeys k(dir);
  std::string text = k.text(p);
  const std::string sup_open = "supervisor { ";
  text.insert(text.find(sup_open) + sup_open.size(),
              "secret_key_file: " + quoted(k.supervisor.key_file.string()) + " ");
  AuthoritySystem sys(dir, text, p, true, curve_as(k.console, k.master),
                      curve_as(k.console, k.slave));
  ASSERT_TRUE(sys.linked()) << sys.logs();
  ASSERT_NO_FATAL_FAILURE(
      arm_and_engage(sys, p, curve_as(k.console, k.master), curve_as(k.console, k.slave)));
  const CliResult set =
      set_once_both_heard("set slave.fixture.stiffness_N_per_m=150 --supervisor 127.0.0.1:" +
                          std::to_string(p.request) + " --key " + k.console.key_file.string() +
                          " --server-key " + k.supervisor.pub_file.string());
  ASSERT_EQ(set.exit_code, 0) << set.out << sys.logs();
  for (const TelemetryTap* tap : {&sys.mt(), &sys.st()}) {
    ASSERT_TRUE(tap->wait_for([](const v1::Telemetry& t) {
      return t.active().change_id() == 1 && t.active().ramp_progress() >= 1.0 &&
             t.active().slave_fixture_stiffness_n_per_m() == 150.0;
    })) << sys.logs();
  }
  EXPECT_EQ(sys.mt().mode(), v1::ENGAGED);
  EXPECT_EQ(sys.st().mode(), v1::ENGAGED);
}

}  // namespace
}  // namespace teleop::test
