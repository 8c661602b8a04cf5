// Issue 14 finding 3 and "Consistency and stability before engage", against the real
// teleop-master, teleop-slave and teleop-supervisor processes on loopback: a slave started
// with other gains than the master, a configuration the analyser calls unstable, a peer that
// restarts with another configuration, an older peer without a fingerprint, and a
// supervisor-approved change (which must never trip the check). Every refusal is read from the
// command replies and from every telemetry cycle the nodes published; nothing waits for time
// to pass.
#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>

#include "common/config/control_fingerprint.hpp"
#include "teleop/v1/node_state.pb.h"
#include "tests/integration/cli_harness.hpp"
#include "tests/integration/node_harness.hpp"

namespace teleop::test {
namespace {

namespace fs = std::filesystem;

struct SystemPorts {
  Ports nodes{};
  int report{free_port()};
  int request{free_port()};
};

// The paper's paddles (node_harness), the supervisor on its ports, no recording.
std::string system_config(const SystemPorts& p, const std::string& slave_extra = "",
                          const std::string& extra = "") {
  // Real-time loops where the kernel permits them: a starved loop's peer timeout is not the
  // subject here.
  return paddles_system(node_section(p.nodes, true, "", 80), node_section(p.nodes, false, "", 80),
                        slave_extra, 0.0) +
         "supervisor { report_endpoint: \"" + tcp(p.report) + "\" request_endpoint: \"" +
         tcp(p.request) + "\" record: false }\n" + extra;
}

// TELEOP_HOSTILE_NODE_DIR=DIR runs DIR/teleop-master and DIR/teleop-slave instead (the
// binaries of an older build: how these tests were shown to fail before the fix).
std::string node_bin(const char* built, const char* name) {
  const char* dir = std::getenv("TELEOP_HOSTILE_NODE_DIR");
  return dir == nullptr ? std::string(built) : std::string(dir) + "/" + name;
}

class System {
 public:
  System(const TempDir& dir, const std::string& text) : dir_(dir) {
    config_ = dir.write("system.textproto", text);
  }
  void start_master(const std::vector<std::string>& sets = {}) {
    master_ = start(node_bin(MASTER_BIN, "teleop-master"), sets, "master.log");
  }
  void start_slave(const std::vector<std::string>& sets = {},
                   const std::string& log = "slave.log") {
    slave_ = start(node_bin(SLAVE_BIN, "teleop-slave"), sets, log);
  }
  void start_supervisor() { supervisor_ = start(SUPERVISOR_BIN, {}, "supervisor.log"); }
  std::unique_ptr<Process>& master() { return master_; }
  std::unique_ptr<Process>& slave() { return slave_; }
  [[nodiscard]] const fs::path& config() const { return config_; }
  [[nodiscard]] std::string logs() const {
    std::string s;
    for (const auto* p : {&master_, &slave_, &supervisor_}) {
      if (*p) s += (*p)->log() + "\n";
    }
    return s;
  }

 private:
  std::unique_ptr<Process> start(const std::string& bin, const std::vector<std::string>& sets,
                                 const std::string& log) {
    std::vector<std::string> args{config_.string()};
    for (const std::string& s : sets) {
      args.push_back("--set");
      args.push_back(s);
    }
    return std::make_unique<Process>(bin, args, dir_.path() / log);
  }
  const TempDir& dir_;
  fs::path config_;
  std::unique_ptr<Process> master_;
  std::unique_ptr<Process> slave_;
  std::unique_ptr<Process> supervisor_;
};

bool linked(const v1::Telemetry& t) { return t.link().accepted() > 0; }

std::string hex(std::uint64_t f) { return config::fingerprint_hex(f); }

// No cycle armed, aligning, engaged or clutched, and no force written, in `cycles`.
void expect_never_armed(const std::vector<v1::CycleRecord>& cycles, const char* who,
                        std::size_t from = 0) {
  ASSERT_GT(cycles.size(), from) << who;
  for (std::size_t i = from; i < cycles.size(); ++i) {
    const v1::CycleRecord& c = cycles[i];
    ASSERT_TRUE(c.mode() == v1::DISARMED || c.mode() == v1::SAFE)
        << who << " cycle " << c.sequence() << " was " << v1::NodeMode_Name(c.mode());
    ASSERT_EQ(c.command_n(), 0.0) << who << " cycle " << c.sequence();
  }
}

// Until both taps have cycles at least as new as the master's newest command reply
// (`since_ns` on the master's clock): the check then covers what followed the commands.
void wait_cycles_after(const TelemetryTap& mt, const TelemetryTap& st, std::int64_t since_ns) {
  for (const TelemetryTap* t : {&mt, &st}) {
    ASSERT_TRUE(t->wait_for([&](const v1::Telemetry& m) {
      return m.cycles_size() > 0 && m.cycles(m.cycles_size() - 1).sample_time_ns() > since_ns;
    }));
  }
}

std::int64_t newest_time(const TelemetryTap& t) {
  const auto c = t.cycles();
  return c.empty() ? 0 : c.back().sample_time_ns();
}

TEST(HostileEngage, ASlaveWithOtherGainsIsRefusedArmAndEngageOnBothWithBothFingerprints) {
  TempDir dir;
  SystemPorts ports;
  System sys(dir, system_config(ports));
  // What each process reads: the file, and the file with the slave's position gain changed.
  const std::uint64_t file_fp = config::control_fingerprint(config::load_config_file(sys.config()));
  const std::uint64_t slave_fp =
      config::control_fingerprint(config::load_config_file(sys.config(), {"gains.kps=900"}));
  ASSERT_NE(file_fp, slave_fp);
  zmq::context_t ctx(1);
  TelemetryTap mt(ctx, tcp(ports.nodes.master_telemetry));
  TelemetryTap st(ctx, tcp(ports.nodes.slave_telemetry));
  // The nodes alone first: the supervisor, once it hears the slave's gains in force that it
  // never approved, e-stops both (finding 2's audit), and the refusals are the nodes' own.
  sys.start_master();
  sys.start_slave({"gains.kps=900"});
  ASSERT_TRUE(mt.wait_for(linked)) << sys.logs();
  ASSERT_TRUE(st.wait_for(linked)) << sys.logs();

  // Arm and engage, three rounds, on both: every reply refused, naming both fingerprints.
  for (int round = 0; round < 3; ++round) {
    for (const auto kind : {v1::NodeCommand::ARM, v1::NodeCommand::ENGAGE}) {
      for (const int port : {ports.nodes.master_command, ports.nodes.slave_command}) {
        const auto r = send_command(ctx, tcp(port), kind);
        ASSERT_TRUE(r.has_value()) << "no reply from " << port;
        EXPECT_FALSE(r->ok()) << v1::NodeCommand::Kind_Name(kind) << " " << port << ": "
                              << r->message();
        EXPECT_EQ(r->mode(), v1::DISARMED);
        EXPECT_NE(r->message().find("fingerprint differs"), std::string::npos) << r->message();
        EXPECT_NE(r->message().find(hex(file_fp)), std::string::npos) << r->message();
        EXPECT_NE(r->message().find(hex(slave_fp)), std::string::npos) << r->message();
      }
    }
  }
  ASSERT_NO_FATAL_FAILURE(wait_cycles_after(mt, st, newest_time(mt)));
  // Never armed, never engaged, no force: every cycle of both nodes.
  ASSERT_NO_FATAL_FAILURE(expect_never_armed(mt.cycles(), "master"));
  ASSERT_NO_FATAL_FAILURE(expect_never_armed(st.cycles(), "slave"));
  // Each node's telemetry: its own fingerprint and the one its peer sent.
  EXPECT_EQ(mt.last()->config_fingerprint(), file_fp);
  EXPECT_EQ(st.last()->config_fingerprint(), slave_fp);
  EXPECT_EQ(mt.last()->peer_config_fingerprint(), slave_fp);
  EXPECT_EQ(st.last()->peer_config_fingerprint(), file_fp);

  // The supervisor: an alarm naming the three fingerprints and the differing field.
  sys.start_supervisor();
  std::optional<v1::Alarm> alarm;
  std::string mismatch;
  ASSERT_TRUE(eventually([&] {
    const auto s = supervisor_status(ctx, ports.request);
    if (!s) return false;
    for (const v1::Alarm& a : s->recent_alarms()) {
      if (!alarm && a.kind() == "configuration") alarm = a;  // the newest
    }
    // The mismatch in force names all three once the supervisor heard both nodes (its first
    // alarm may predate the master's telemetry).
    mismatch = s->configuration_mismatch();
    return alarm.has_value() && mismatch.find("master ") != std::string::npos;
  })) << sys.logs();
  EXPECT_NE(mismatch.find("supervisor " + hex(file_fp) + ", master " + hex(file_fp) + ", slave " +
                          hex(slave_fp)),
            std::string::npos)
      << mismatch;
  EXPECT_NE(mismatch.find("gains.kps (supervisor 600, master 600, slave 900)"), std::string::npos)
      << mismatch;
  std::cout << "supervisor: " << alarm->side() << ": " << alarm->message() << "\n"
            << "in force: " << mismatch << "\n";
  EXPECT_EQ(alarm->side(), "slave");
  EXPECT_GE(alarm->severity(), v1::Alarm::WARNING);
  EXPECT_NE(alarm->message().find("supervisor " + hex(file_fp)), std::string::npos);
  EXPECT_NE(alarm->message().find("slave " + hex(slave_fp)), std::string::npos);
  EXPECT_NE(alarm->message().find("gains.kps (supervisor 600"), std::string::npos)
      << alarm->message();
  EXPECT_EQ(alarm->message().find("gains.kpm"), std::string::npos) << "only kps differs";
}

// The slave fixture far above the stiffest one the analyser calls stable at one sample of
// round trip (`teleopctl analyze --max-stiffness slave`, an independent path: the CLI's
// stiffness search, not the node's check).
double slave_stiffness_limit(const fs::path& config) {
  const CliResult r =
      teleopctl("analyze " + config.string() +
                    " --set round_trip_delay_samples=1 --max-stiffness slave --json",
                false);
  EXPECT_EQ(r.exit_code, 0) << r.out;
  const nlohmann::json j = nlohmann::json::parse(r.out, nullptr, false);
  try {
    return j.at("limits").at(0).at("max_stable_stiffness_N_per_m").get<double>();
  } catch (const std::exception&) {
    ADD_FAILURE() << "no stiffness limit in: " << r.out;
    return 0.0;
  }
}

TEST(HostileEngage, AConfigurationPredictedUnstableIsRefusedArmWithTheVerdict) {
  TempDir dir;
  SystemPorts ports;
  System probe(dir, system_config(ports));
  const double limit = slave_stiffness_limit(probe.config());
  ASSERT_GT(limit, 100.0);
  const double stiff = 4.0 * limit;
  std::cout << "slave fixture limit " << limit << " N/m; starting with " << stiff << " N/m\n";
  System sys(dir, system_config(ports, "fixture { stiffness_N_per_m: " + exact(stiff) +
                                           " position_m: 0.005 }"));
  zmq::context_t ctx(1);
  TelemetryTap mt(ctx, tcp(ports.nodes.master_telemetry));
  TelemetryTap st(ctx, tcp(ports.nodes.slave_telemetry));
  sys.start_master();
  sys.start_slave();
  ASSERT_TRUE(mt.wait_for(linked)) << sys.logs();
  ASSERT_TRUE(st.wait_for(linked)) << sys.logs();
  // Both nodes agree on the configuration: it is their own analysis that refuses.
  EXPECT_EQ(mt.last()->config_fingerprint(), st.last()->config_fingerprint());
  for (const TelemetryTap* t : {&mt, &st}) {
    const v1::ConfigurationCheck c = t->last()->configuration_check();
    EXPECT_EQ(c.verdict(), "unstable");
    EXPECT_FALSE(c.permits_coupling());
    EXPECT_EQ(c.round_trip_samples(), 1);
    EXPECT_LT(c.min_damping_ratio(), 0.0);
  }
  for (const auto kind : {v1::NodeCommand::ARM, v1::NodeCommand::ENGAGE}) {
    for (const int port : {ports.nodes.master_command, ports.nodes.slave_command}) {
      const auto r = send_command(ctx, tcp(port), kind);
      ASSERT_TRUE(r.has_value());
      EXPECT_FALSE(r->ok()) << r->message();
      EXPECT_EQ(r->mode(), v1::DISARMED);
      EXPECT_NE(r->message().find("analysis says unstable"), std::string::npos) << r->message();
      EXPECT_NE(r->message().find("damping ratio -"), std::string::npos) << r->message();
      EXPECT_NE(r->message().find("allow_unstable"), std::string::npos) << r->message();
    }
  }
  ASSERT_NO_FATAL_FAILURE(wait_cycles_after(mt, st, newest_time(mt)));
  ASSERT_NO_FATAL_FAILURE(expect_never_armed(mt.cycles(), "master"));
  ASSERT_NO_FATAL_FAILURE(expect_never_armed(st.cycles(), "slave"));
}

TEST(HostileEngage, TheExperimentFlagArmsItAndStatusShowsTheBanner) {
  TempDir dir;
  SystemPorts ports;
  System probe(dir, system_config(ports));
  const double limit = slave_stiffness_limit(probe.config());
  ASSERT_GT(limit, 100.0);
  const double stiff = 4.0 * limit;
  System sys(
      dir,
      system_config(ports, "fixture { stiffness_N_per_m: " + exact(stiff) + " position_m: 0.005 }",
                    "experiment { allow_unstable: true }\n"));
  zmq::context_t ctx(1);
  TelemetryTap mt(ctx, tcp(ports.nodes.master_telemetry));
  TelemetryTap st(ctx, tcp(ports.nodes.slave_telemetry));
  sys.start_supervisor();
  sys.start_master();
  sys.start_slave();
  ASSERT_TRUE(mt.wait_for(linked)) << sys.logs();
  ASSERT_TRUE(st.wait_for(linked)) << sys.logs();
  for (const int port : {ports.nodes.master_command, ports.nodes.slave_command}) {
    const auto r = send_command(ctx, tcp(port), v1::NodeCommand::ARM);
    ASSERT_TRUE(r.has_value());
    EXPECT_TRUE(r->ok()) << r->message();
    EXPECT_EQ(r->mode(), v1::ARMED) << r->mode_reason();
  }
  const v1::ConfigurationCheck c = mt.last()->configuration_check();
  EXPECT_EQ(c.verdict(), "unstable");
  EXPECT_TRUE(c.allow_unstable());
  EXPECT_TRUE(c.permits_coupling());
  // `teleopctl status`: the banner first, naming the flag and the verdict.
  CliResult status;
  ASSERT_TRUE(eventually([&] {
    status = teleopctl("status --supervisor 127.0.0.1:" + std::to_string(ports.request), false);
    return status.exit_code == 0 && status.out.find("EXPERIMENT") != std::string::npos &&
           status.out.find("master and slave") != std::string::npos;
  })) << status.out
      << sys.logs();
  std::cout << status.out;
  EXPECT_EQ(status.out.rfind("EXPERIMENT: experiment.allow_unstable is set", 0), 0u) << status.out;
  EXPECT_NE(status.out.find("master analysis: unstable"), std::string::npos) << status.out;
}

TEST(HostileEngage, APeerRestartedWithAnotherConfigurationNeverReEngages) {
  TempDir dir;
  SystemPorts ports;
  System sys(dir, system_config(ports));
  zmq::context_t ctx(1);
  TelemetryTap mt(ctx, tcp(ports.nodes.master_telemetry));
  TelemetryTap st(ctx, tcp(ports.nodes.slave_telemetry));
  sys.start_master();
  sys.start_slave();
  ASSERT_TRUE(mt.wait_for(linked)) << sys.logs();
  ASSERT_TRUE(st.wait_for(linked)) << sys.logs();
  for (const auto kind : {v1::NodeCommand::ARM, v1::NodeCommand::ENGAGE}) {
    for (const int port : {ports.nodes.master_command, ports.nodes.slave_command}) {
      const auto r = send_command(ctx, tcp(port), kind);
      ASSERT_TRUE(r.has_value() && r->ok()) << (r ? r->message() : "no reply");
    }
  }
  ASSERT_TRUE(mt.wait_for_mode(v1::ENGAGED)) << sys.logs();
  const std::uint64_t first_session = mt.last()->link().peer_session_id();
  // The slave dies and comes back with another position gain (a new session, a new
  // fingerprint): the master goes safe, and nothing brings it back to coupling.
  sys.slave()->signal(SIGKILL);
  (void)sys.slave()->wait();
  ASSERT_TRUE(mt.wait_for_mode(v1::SAFE, 10s)) << sys.logs();
  const std::size_t safe_at = mt.cycles().size();
  TelemetryTap st2(ctx, tcp(ports.nodes.slave_telemetry));
  sys.start_slave({"gains.kps=900"}, "slave2.log");
  ASSERT_TRUE(mt.wait_for([&](const v1::Telemetry& t) {
    return t.link().peer_session_id() != 0 && t.link().peer_session_id() != first_session;
  })) << sys.logs();
  for (const auto kind : {v1::NodeCommand::CLEAR, v1::NodeCommand::ARM, v1::NodeCommand::ENGAGE}) {
    for (const int port : {ports.nodes.master_command, ports.nodes.slave_command}) {
      const auto r = send_command(ctx, tcp(port), kind);
      ASSERT_TRUE(r.has_value());
      if (kind != v1::NodeCommand::CLEAR) {
        EXPECT_FALSE(r->ok()) << r->message();
        EXPECT_NE(r->message().find("fingerprint differs"), std::string::npos) << r->message();
      }
    }
  }
  ASSERT_NO_FATAL_FAILURE(wait_cycles_after(mt, st2, newest_time(mt)));
  // From the moment it went safe: safe or disarmed only, never armed or coupled, no force
  // once the safe ramp is over.
  const auto c = mt.cycles();
  bool cleared = false;
  for (std::size_t i = safe_at; i < c.size(); ++i) {
    ASSERT_TRUE(c[i].mode() == v1::SAFE || c[i].mode() == v1::DISARMED)
        << "master cycle " << c[i].sequence() << " " << v1::NodeMode_Name(c[i].mode());
    cleared = cleared || c[i].mode() == v1::DISARMED;
  }
  EXPECT_TRUE(cleared) << "the clear did not reach the master";
  ASSERT_NO_FATAL_FAILURE(expect_never_armed(st2.cycles(), "restarted slave"));
}

// zlib's crc32, bit by bit (the older node's checksum over its body).
std::uint32_t crc32_of(const std::string& b) {
  std::uint32_t crc = 0xFFFFFFFFu;
  for (const char ch : b) {
    crc ^= static_cast<unsigned char>(ch);
    for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
  }
  return crc ^ 0xFFFFFFFFu;
}

TEST(HostileEngage, AnOlderPeerWithoutAFingerprintIsRefusedArm) {
  TempDir dir;
  SystemPorts ports;
  System sys(dir, system_config(ports));
  zmq::context_t ctx(1);
  // An older slave: binds the slave's state endpoint and sends well-formed states (role, a
  // session, rising sequences, the checksum) without fields 16 and 17.
  std::atomic<bool> running{true};
  std::thread old_slave([&] {
    zmq::socket_t pub(ctx, zmq::socket_type::pub);
    pub.set(zmq::sockopt::linger, 0);
    pub.bind(tcp(ports.nodes.slave_state));
    std::uint64_t seq = 0;
    while (running.load()) {
      v1::NodeState m;
      m.set_session_id(0x0123'4567'89ab'cdefULL);
      m.set_sequence(++seq);
      m.set_role(v1::SLAVE);
      m.set_mode(v1::DISARMED);
      m.set_crc32(crc32_of(m.SerializeAsString()));
      const std::string bytes = m.SerializeAsString();
      (void)pub.send(zmq::buffer(bytes), zmq::send_flags::dontwait);
      std::this_thread::sleep_for(1ms);
    }
  });
  TelemetryTap mt(ctx, tcp(ports.nodes.master_telemetry));
  sys.start_master();
  const bool link = mt.wait_for(linked);
  std::optional<v1::NodeCommandReply> r;
  if (link) r = send_command(ctx, tcp(ports.nodes.master_command), v1::NodeCommand::ARM);
  running = false;
  old_slave.join();
  ASSERT_TRUE(link) << sys.logs();
  ASSERT_TRUE(r.has_value());
  EXPECT_FALSE(r->ok());
  EXPECT_EQ(r->mode(), v1::DISARMED);
  EXPECT_NE(r->message().find("sends no configuration fingerprint"), std::string::npos)
      << r->message();
  EXPECT_NE(r->message().find("peer's none"), std::string::npos) << r->message();
  EXPECT_EQ(mt.last()->peer_config_fingerprint(), 0u);
}

TEST(HostileEngage, ASupervisorApprovedChangeNeverTripsTheCheck) {
  TempDir dir;
  SystemPorts ports;
  // Plaintext loopback: the supervisor's retunes need the opt-in (finding 2).
  System sys(dir, system_config(ports, "", kAllowUnauthenticatedRetune));
  zmq::context_t ctx(1);
  TelemetryTap mt(ctx, tcp(ports.nodes.master_telemetry));
  TelemetryTap st(ctx, tcp(ports.nodes.slave_telemetry));
  sys.start_supervisor();
  sys.start_master();
  sys.start_slave();
  ASSERT_TRUE(mt.wait_for(linked)) << sys.logs();
  ASSERT_TRUE(st.wait_for(linked)) << sys.logs();
  ASSERT_TRUE(eventually([&] {
    const auto s = supervisor_status(ctx, ports.request);
    return s && s->master_alive() && s->slave_alive();
  }));
  auto engage = [&] {
    for (const auto kind : {v1::NodeCommand::ARM, v1::NodeCommand::ENGAGE}) {
      for (const int port : {ports.nodes.master_command, ports.nodes.slave_command}) {
        const auto r = send_command(ctx, tcp(port), kind);
        ASSERT_TRUE(r.has_value() && r->ok()) << (r ? r->message() : "no reply");
      }
    }
    ASSERT_TRUE(mt.wait_for_mode(v1::ENGAGED)) << sys.logs();
    ASSERT_TRUE(st.wait_for_mode(v1::ENGAGED)) << sys.logs();
  };
  ASSERT_NO_FATAL_FAILURE(engage());
  const CliResult set = teleopctl("set gains.kps=500 gains.kpm=500 --supervisor 127.0.0.1:" +
                                  std::to_string(ports.request));
  ASSERT_EQ(set.exit_code, 0) << set.out;
  for (const TelemetryTap* t : {&mt, &st}) {
    ASSERT_TRUE(t->wait_for([](const v1::Telemetry& m) {
      return m.active().change_id() == 1 && m.active().ramp_progress() >= 1.0;
    })) << sys.logs();
  }
  EXPECT_EQ(mt.last()->mode(), v1::ENGAGED);
  const std::size_t before = mt.cycles().size();
  for (const int port : {ports.nodes.master_command, ports.nodes.slave_command}) {
    ASSERT_TRUE(send_command(ctx, tcp(port), v1::NodeCommand::DISENGAGE).has_value());
  }
  ASSERT_NO_FATAL_FAILURE(engage());  // under the change: permitted
  // Seen in the master's own cycles: armed after the disengage, then engaged again.
  ASSERT_TRUE(mt.wait_for([&](const v1::Telemetry&) {
    const auto c = mt.cycles();
    bool armed = false;
    for (std::size_t i = before; i < c.size(); ++i) {
      armed = armed || c[i].mode() == v1::ARMED;
      if (armed && c[i].mode() == v1::ENGAGED) return true;
    }
    return false;
  })) << sys.logs();
  const auto s = supervisor_status(ctx, ports.request);
  ASSERT_TRUE(s.has_value());
  EXPECT_TRUE(s->configuration_mismatch().empty()) << s->configuration_mismatch();
  for (const v1::Alarm& a : s->recent_alarms()) EXPECT_NE(a.kind(), "configuration") << a.message();
}

}  // namespace
}  // namespace teleop::test
