// Issue 14 finding 1, "absurd parameters are stable", against the shipped binaries: one
// parameter space (common/config/parameter_space.hpp) checked by `teleopctl analyze`, by
// every node at start, by the supervisor before it analyses a `teleopctl set`, and by a node
// for a RETUNE sent straight to its command endpoint. Expected refusals are physics, not the
// code: a gain of 1e308 N/m or a negative gain is no teleoperator; port 99999 does not exist.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <functional>
#include <regex>
#include <string>
#include <vector>

#include "tests/integration/cli_harness.hpp"
#include "tests/integration/node_harness.hpp"

namespace teleop::test {
namespace {

namespace fs = std::filesystem;

const std::string kLive = std::string(TELEOP_SOURCE_DIR) + "/examples/live.textproto";

bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

// --- teleopctl analyze ------------------------------------------------------------------------

// The reported case: kps = 1e308 overflowed the spectral radius and printed "stable, zeta
// 1.0000". Refused, exit 1, naming the field and the value, in text and in --json, and in the
// stiffness search.
TEST(HostileParams, AnalyzeWithAGainOf1e308IsAnErrorNamingTheField) {
  for (const std::string extra :
       {"", " --json", " --max-stiffness slave", " --max-stiffness master --json"}) {
    const CliResult r = teleopctl("analyze " + kLive + " --set gains.kps=1e308" + extra);
    EXPECT_EQ(r.exit_code, 1) << extra << "\n" << r.out;
    EXPECT_TRUE(contains(r.out, "gains.kps")) << extra << "\n" << r.out;
    EXPECT_TRUE(contains(r.out, "1e+308")) << extra << "\n" << r.out;
    EXPECT_FALSE(contains(r.out, ": stable")) << extra << "\n" << r.out;
    EXPECT_FALSE(contains(r.out, "\"stable\": true")) << extra << "\n" << r.out;
  }
}

// Siblings: every kind of quantity that can overflow the model or make no physical sense.
TEST(HostileParams, AnalyzeRefusesEveryAbsurdValueNamingItsField) {
  const std::vector<std::pair<std::string, std::string>> cases{
      {"gains.kps=-5", "gains.kps: must be >= 0"},
      {"gains.kvm=-1", "gains.kvm: must be >= 0"},
      {"gains.kdm=1e300", "gains.kdm: must be in"},
      {"gains.kfm=1e308", "gains.kfm: must be in"},
      {"master.device.mass_kg=1e308", "master.device.mass_kg: must be in"},
      {"slave.device.mass_kg=1e-300", "slave.device.mass_kg: must be in"},
      {"slave.device.damping_Ns_per_m=-0.1", "slave.device.damping_Ns_per_m: must be >= 0"},
      {"slave.fixture.stiffness_N_per_m=1e308", "slave.fixture.stiffness_N_per_m: must be in"},
      {"sample_rate_hz=1e308", "sample_rate_hz: must be in"},
      {"sample_rate_hz=1e-300", "sample_rate_hz: must be in"},
      {"velocity_filter.cutoff_hz=1e308", "velocity_filter.cutoff_hz: must be in"},
      {"scaling.position=1e308", "scaling.position: must be in"},
      {"scaling.position=1e-300", "scaling.position: |value| must be >="},
      {"scaling.force=1e308", "scaling.force: must be in"},
      {"human.fixed.mass_kg=1e308", "human.fixed.mass_kg: must be in"},
      {"human.fixed.stiffness_N_per_m=1e308", "human.fixed.stiffness_N_per_m: must be in"},
      {"link.peer_timeout_ms=1e308", "link.peer_timeout_ms: must be in"},
      {"supervisor.escalation_ms=1e308", "supervisor.escalation_ms: must be in"},
      {"supervisor.change_ramp_ms=-1", "supervisor.change_ramp_ms: must be >= 0"},
      {"master.node.command_endpoint=tcp://127.0.0.1:99999", "master.node.command_endpoint: port"},
      {"slave.node.telemetry_endpoint=tcp://127.0.0.1:5560",
       "slave.node.telemetry_endpoint: \"tcp://127.0.0.1:5560\" is also "
       "master.node.state_endpoint"},
  };
  for (const auto& [set, expected] : cases) {
    const CliResult r = teleopctl("analyze " + kLive + " --set " + set);
    EXPECT_EQ(r.exit_code, 1) << set << "\n" << r.out;
    EXPECT_TRUE(contains(r.out, expected)) << set << " should say '" << expected << "'\n" << r.out;
  }
}

// A human band whose lines reach absurd values at a force level: its ceiling, by force level.
TEST(HostileParams, AnalyzeRefusesAHumanBandBeyondTheHumanCeilings) {
  const CliResult r = teleopctl(
      "analyze " + kLive +
      " --set 'human.band={force_levels_N: [1, 1000] mass_kg { lower { intercept: 0.001 } upper "
      "{ intercept: 0.01 slope_per_N: 1e6 } } damping_Ns_per_m { lower {} upper { intercept: 1 } "
      "} stiffness_N_per_m { lower {} upper { intercept: 100 } } }'");
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_TRUE(contains(r.out, "human.band.mass_kg.upper: must be <= 100 at force level 1 N"))
      << r.out;
}

// The sweep and the rates of a stiffness search go through the same rules point by point.
TEST(HostileParams, SweepAndRatesBeyondTheCeilingsAreErrorsNamingTheField) {
  CliResult r =
      teleopctl("analyze " + kLive + " --max-stiffness slave --sweep gains.kps=0:1e308:2e307");
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_TRUE(contains(r.out, "gains.kps: must be in")) << r.out;
  r = teleopctl("analyze " + kLive + " --max-stiffness slave --rates 1000,1e300");
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_TRUE(contains(r.out, "sample_rate_hz: must be in")) << r.out;
}

// `--set a=1 --set a=2` kept the last silently: an error naming both assignments.
TEST(HostileParams, ARepeatedSetPathIsAnErrorNamingBothAssignments) {
  const CliResult r =
      teleopctl("analyze " + kLive + " --set gains.kps=600 --set 'gains . kps=700'");
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_TRUE(
      contains(r.out, "--set gains . kps=700: gains.kps: already set by --set gains.kps=600"))
      << r.out;
  // teleopctl set: a usage error before anything is sent.
  const CliResult s = teleopctl("set gains.kps=500 gains.kps=700 --supervisor 127.0.0.1:1");
  EXPECT_EQ(s.exit_code, 2) << s.out;
  EXPECT_TRUE(contains(s.out, "gains.kps is set twice")) << s.out;
}

// --- node processes ---------------------------------------------------------------------------

std::string node_config(const Ports& p) {
  return paddles_system(node_section(p, true), node_section(p, false), "", 0.0);
}

// A node given an absurd parameter exits 1 naming the field before it binds anything: no
// "session ..." line (logged once its endpoints are bound), and its own ports still free.
TEST(HostileParams, NodesRefuseToStartWithAbsurdParametersNamingTheFieldAndBindNothing) {
  const std::vector<std::pair<std::string, std::string>> cases{
      {"gains.kps=1e308", "gains.kps: must be in"},
      {"gains.kps=-5", "gains.kps: must be >= 0"},
      {"gains.kds=-2", "gains.kds: must be >= 0"},
      {"master.device.mass_kg=1e308", "master.device.mass_kg: must be in"},
      {"slave.device.mass_kg=1e308", "slave.device.mass_kg: must be in"},
      {"master.node.command_endpoint=tcp://127.0.0.1:99999",
       "master.node.command_endpoint: port must be a number in 1-65535"},
      {"slave.node.state_endpoint=tcp://127.0.0.1:99999",
       "slave.node.state_endpoint: port must be a number in 1-65535"},
      {"link.safe_ramp_ms=1e308", "link.safe_ramp_ms: must be in"},
  };
  for (const bool master : {true, false}) {
    for (const auto& [set, expected] : cases) {
      TempDir dir;
      const Ports ports;
      const fs::path config = dir.write("system.textproto", node_config(ports));
      Process node(master ? MASTER_BIN : SLAVE_BIN, {config.string(), "--set", set},
                   dir.path() / "node.log");
      const int code = node.wait();
      const std::string log = node.log();
      EXPECT_EQ(code, 1) << (master ? "master " : "slave ") << set << "\n" << log;
      EXPECT_TRUE(contains(log, expected)) << set << " should say '" << expected << "'\n" << log;
      EXPECT_FALSE(contains(log, "session ")) << "started: " << set << "\n" << log;
    }
  }
}

// Two identical endpoints: within one node, and across the nodes and the supervisor (the
// master alone would bind its own fine, and the slave or supervisor then fails or, on a
// wildcard, shares it). Each refused by either node, naming both fields.
TEST(HostileParams, NodesRefuseToStartWithTwoIdenticalEndpointsNamingBoth) {
  const Ports p;
  const std::vector<std::pair<std::string, std::string>> cases{
      {"master.node.command_endpoint=" + tcp(p.master_state),
       "master.node.command_endpoint: \"" + tcp(p.master_state) +
           "\" is also master.node.state_endpoint"},
      {"slave.node.command_endpoint=" + tcp(p.master_telemetry),
       "slave.node.command_endpoint: \"" + tcp(p.master_telemetry) +
           "\" is also master.node.telemetry_endpoint"},
      {"supervisor.request_endpoint=tcp://*:" + std::to_string(p.slave_state),
       "supervisor.request_endpoint: \"tcp://*:" + std::to_string(p.slave_state) +
           "\" is also slave.node.state_endpoint"},
  };
  for (const bool master : {true, false}) {
    for (const auto& [set, expected] : cases) {
      TempDir dir;
      const fs::path config = dir.write("system.textproto", node_config(p));
      Process node(master ? MASTER_BIN : SLAVE_BIN, {config.string(), "--set", set},
                   dir.path() / "node.log");
      const int code = node.wait();
      const std::string log = node.log();
      EXPECT_EQ(code, 1) << (master ? "master " : "slave ") << set << "\n" << log;
      EXPECT_TRUE(contains(log, expected)) << set << " should say '" << expected << "'\n" << log;
      EXPECT_FALSE(contains(log, "session ")) << "started: " << set << "\n" << log;
    }
  }
}

// --- live changes -----------------------------------------------------------------------------

bool linked(const v1::Telemetry& t) { return t.link().accepted() > 0; }

// No cycle of either node ever ran a parameter change, and the gains in force are the file's.
void expect_parameters_untouched(const TelemetryTap& tap, const char* name) {
  for (const auto& c : tap.cycles()) {
    ASSERT_EQ(c.parameter_change_id(), 0u) << name << " applied a change";
  }
  const auto last = tap.last();
  ASSERT_TRUE(last.has_value());
  EXPECT_EQ(last->active().change_id(), 0u) << name;
  EXPECT_EQ(last->active().gains().kps(), 600.0) << name;
  EXPECT_EQ(last->active().gains().kpm(), 600.0) << name;
  EXPECT_EQ(last->active().slave_fixture_stiffness_n_per_m(), 0.0) << name;
}

// A RETUNE straight to a node's command endpoint (plaintext loopback, as every client can):
// refused by the node's own validation, whatever the supervisor would have said.
TEST(HostileParams, ARetuneWithAbsurdValuesSentStraightToANodeIsRefusedByTheNode) {
  TempDir dir;
  const Ports ports;
  const fs::path config =
      dir.write("system.textproto", node_config(ports) + kAllowUnauthenticatedRetune);
  zmq::context_t ctx(1);
  TelemetryTap mt(ctx, tcp(ports.master_telemetry));
  TelemetryTap st(ctx, tcp(ports.slave_telemetry));
  Process master(MASTER_BIN, {config.string()}, dir.path() / "master.log");
  Process slave(SLAVE_BIN, {config.string()}, dir.path() / "slave.log");
  ASSERT_TRUE(mt.wait_for(linked)) << master.log();
  ASSERT_TRUE(st.wait_for(linked)) << slave.log();

  struct Case {
    const char* what;
    std::function<void(v1::ParameterUpdate&)> set;
    const char* expected;
  };
  const std::vector<Case> cases{
      {"kps 1e308", [](v1::ParameterUpdate& u) { u.mutable_gains()->set_kps(1e308); },
       "gains.kps: must be in"},
      {"kps -5", [](v1::ParameterUpdate& u) { u.mutable_gains()->set_kps(-5.0); },
       "gains.kps: must be >= 0"},
      {"kvs -1", [](v1::ParameterUpdate& u) { u.mutable_gains()->set_kvs(-1.0); },
       "gains.kvs: must be >= 0"},
      {"kfm nan", [](v1::ParameterUpdate& u) { u.mutable_gains()->set_kfm(std::nan("")); },
       "gains.kfm: must be finite"},
      {"slave fixture 1e308",
       [](v1::ParameterUpdate& u) { u.set_slave_fixture_stiffness_n_per_m(1e308); },
       "slave_fixture_stiffness_N_per_m: must be in"},
      {"ramp 1e308", [](v1::ParameterUpdate& u) { u.set_ramp_ms(1e308); }, "ramp_ms: must be in"},
  };
  for (const Case& c : cases) {
    for (const int port : {ports.master_command, ports.slave_command}) {
      zmq::socket_t s(ctx, zmq::socket_type::req);
      s.set(zmq::sockopt::linger, 0);
      s.set(zmq::sockopt::rcvtimeo, 5000);
      s.connect(tcp(port));
      v1::NodeCommand cmd;
      cmd.set_kind(v1::NodeCommand::RETUNE);
      v1::ParameterUpdate& u = *cmd.mutable_update();
      u.set_change_id(7);
      v1::Gains& g = *u.mutable_gains();  // the file's gains, then the hostile value
      g.set_kpm(600);
      g.set_kps(600);
      g.set_kdm(2);
      g.set_kds(2);
      u.set_ramp_ms(10);
      c.set(u);
      const std::string bytes = cmd.SerializeAsString();
      s.send(zmq::buffer(bytes), zmq::send_flags::none);
      zmq::message_t reply;
      ASSERT_TRUE(s.recv(reply)) << c.what << ": no reply\n" << master.log() << slave.log();
      v1::NodeCommandReply r;
      ASSERT_TRUE(r.ParseFromArray(reply.data(), static_cast<int>(reply.size())));
      EXPECT_FALSE(r.ok()) << c.what << " accepted by port " << port;
      EXPECT_TRUE(contains(r.message(), c.expected))
          << c.what << " should say '" << c.expected << "': " << r.message();
    }
  }
  // Two hundred further cycles on both: nothing was ever applied.
  const std::size_t m0 = mt.cycles().size();
  const std::size_t s0 = st.cycles().size();
  ASSERT_TRUE(
      eventually([&] { return mt.cycles().size() >= m0 + 200 && st.cycles().size() >= s0 + 200; }));
  expect_parameters_untouched(mt, "master");
  expect_parameters_untouched(st, "slave");
}

// `teleopctl set gains.kps=1e308` and `=-5` through a live supervisor over engaged nodes:
// refused with the reason (the field, its rule, the value) before any analysis; neither node
// ever runs a change.
TEST(HostileParams, TeleopctlSetOfAbsurdValuesIsRefusedByTheSupervisorAndTheNodesNeverChange) {
  TempDir dir;
  const Ports ports;
  const int report = free_port();
  const int request = free_port();
  const std::string text = node_config(ports) + "supervisor { report_endpoint: \"" + tcp(report) +
                           "\" request_endpoint: \"" + tcp(request) + "\" record: false }\n";
  const fs::path config = dir.write("system.textproto", text);
  zmq::context_t ctx(1);
  TelemetryTap mt(ctx, tcp(ports.master_telemetry));
  TelemetryTap st(ctx, tcp(ports.slave_telemetry));
  Process supervisor(SUPERVISOR_BIN, {config.string()}, dir.path() / "supervisor.log");
  Process master(MASTER_BIN, {config.string()}, dir.path() / "master.log");
  Process slave(SLAVE_BIN, {config.string()}, dir.path() / "slave.log");
  const auto logs = [&] {
    return "--- master\n" + master.log() + "--- slave\n" + slave.log() + "--- supervisor\n" +
           supervisor.log();
  };
  ASSERT_TRUE(mt.wait_for(linked)) << logs();
  ASSERT_TRUE(st.wait_for(linked)) << logs();
  ASSERT_TRUE(eventually([&] {
    const auto s = supervisor_status(ctx, request);
    return s && s->master_alive() && s->slave_alive();
  })) << logs();
  for (const auto kind : {v1::NodeCommand::ARM, v1::NodeCommand::ENGAGE}) {
    for (const int port : {ports.master_command, ports.slave_command}) {
      const auto r = send_command(ctx, tcp(port), kind);
      ASSERT_TRUE(r.has_value() && r->ok()) << logs();
    }
  }
  ASSERT_TRUE(mt.wait_for_mode(v1::ENGAGED)) << logs();
  ASSERT_TRUE(st.wait_for_mode(v1::ENGAGED)) << logs();

  const std::string target = " --supervisor 127.0.0.1:" + std::to_string(request);
  const std::vector<std::pair<std::string, std::string>> cases{
      {"gains.kps=1e308", "refused: gains.kps: must be in [0, 1e+07] N/m"},
      {"gains.kps=-5", "refused: gains.kps: must be >= 0, got -5"},
      {"gains.kvm=-0.5", "refused: gains.kvm: must be >= 0, got -0.5"},
      {"slave.fixture.stiffness_N_per_m=1e308", "refused: slave_fixture_stiffness_N_per_m"},
      {"master.fixture.stiffness_N_per_m=-100", "refused: master_fixture_stiffness_N_per_m"},
  };
  for (const auto& [set, expected] : cases) {
    for (const std::string dry : {" --dry-run", ""}) {
      const CliResult r = teleopctl("set " + set + dry + target);
      EXPECT_EQ(r.exit_code, 3) << set << dry << "\n" << r.out;
      EXPECT_TRUE(contains(r.out, expected)) << set << dry << " should say '" << expected << "'\n"
                                             << r.out;
    }
  }
  const std::size_t m0 = mt.cycles().size();
  const std::size_t s0 = st.cycles().size();
  ASSERT_TRUE(
      eventually([&] { return mt.cycles().size() >= m0 + 200 && st.cycles().size() >= s0 + 200; }));
  expect_parameters_untouched(mt, "master");
  expect_parameters_untouched(st, "slave");
  EXPECT_EQ(mt.last()->mode(), v1::ENGAGED) << logs();
  EXPECT_EQ(st.last()->mode(), v1::ENGAGED) << logs();
}

}  // namespace
}  // namespace teleop::test
