// teleopctl bridge (issue 17 "Live view in Foxglove", docs/foxglove.md) over the real master,
// slave and supervisor on simulated devices, read by the official Foxglove WebSocket client
// (@foxglove/ws-protocol, tests/ws_js/check.mjs, which decodes every message with protobufjs
// against the schema the channel advertised). Judged here against numbers that do not come
// from the bridge: the configured 1 kHz, the static equilibrium of the paper's law with this
// file's gains, fixture and human (solved below), the nodes' own telemetry (tapped directly),
// and the wall clock. Also: hostile WebSocket clients never end the bridge, and the bridge
// refuses to listen off loopback unless told.
#include <arpa/inet.h>
#include <google/protobuf/descriptor.h>
#include <google/protobuf/text_format.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>

#include "foxglove/Log.pb.h"
#include "tests/integration/cli_harness.hpp"
#include "tests/integration/node_harness.hpp"

namespace teleop::test {
namespace {

namespace fs = std::filesystem;
using Json = nlohmann::json;

constexpr double kRateHz = 1000.0;
constexpr double kFixtureK = 1000.0;  // slave fixture, N/m
constexpr double kFixtureP = 0.005;   // its position, m
constexpr double kPushN = 0.5;        // the human's exogenous force F_h*
constexpr double kHumanK = 70.0;      // human stiffness, N/m
constexpr double kKpm = 600.0;
constexpr double kKps = 600.0;

// The static equilibrium of the three-channel law (docs/architecture.md §2.3, α = β = 1,
// K_fm = 0, velocities 0) with the slave pressed into its fixture:
//   master: F_h* - k_h x_m = K_pm (x_m - x_s)          (human force = actuator force)
//   slave:  K_ps (x_m - x_s) = K_f (x_s - p)           (coupling force = fixture force)
// Two linear equations in x_m, x_s, solved by Cramer's rule.
struct Equilibrium {
  double master_m;
  double slave_m;
  double human_force_N;
};
Equilibrium equilibrium() {
  // (k_h + K_pm) x_m - K_pm x_s = F_h*;   K_ps x_m - (K_ps + K_f) x_s = -K_f p
  const double a11 = kHumanK + kKpm, a12 = -kKpm, b1 = kPushN;
  const double a21 = kKps, a22 = -(kKps + kFixtureK), b2 = -kFixtureK * kFixtureP;
  const double det = a11 * a22 - a12 * a21;
  const double xm = (b1 * a22 - a12 * b2) / det;
  const double xs = (a11 * b2 - b1 * a21) / det;
  return {xm, xs, kPushN - kHumanK * xm};
}

struct SystemPorts {
  Ports nodes{};
  int report{free_port()};
  int request{free_port()};
  int bridge{free_port()};
};

std::string system_config(const SystemPorts& p, const fs::path& record_dir,
                          const std::string& extra = "") {
  return "round_trip_delay_samples: 2\n" + extra +
         paddles_system(node_section(p.nodes, true, "", 80), node_section(p.nodes, false, "", 80),
                        "fixture { stiffness_N_per_m: 1000 position_m: 0.005 }", kPushN) +
         "supervisor { report_endpoint: \"" + tcp(p.report) + "\" request_endpoint: \"" +
         tcp(p.request) + "\" record_dir: \"" + record_dir.string() + "\" }\n";
}

bool linked(const v1::Telemetry& t) { return t.link().accepted() > 0; }

// Master, slave, supervisor and the bridge from one file; both nodes engaged and settled.
class BridgeSystem {
 public:
  // `extra`: more of the file (e.g. kAllowUnauthenticatedRetune for a guarded change).
  explicit BridgeSystem(const std::string& extra = "") {
    config_ =
        dir_.write("system.textproto", system_config(ports_, dir_.path() / "sessions", extra));
    supervisor_ = std::make_unique<Process>(
        SUPERVISOR_BIN, std::vector<std::string>{config_.string()}, dir_.path() / "supervisor.log");
    master_ = std::make_unique<Process>(MASTER_BIN, std::vector<std::string>{config_.string()},
                                        dir_.path() / "master.log");
    slave_ = std::make_unique<Process>(SLAVE_BIN, std::vector<std::string>{config_.string()},
                                       dir_.path() / "slave.log");
  }

  void start_engaged_with_bridge() {
    ASSERT_TRUE(mt.wait_for(linked) && st.wait_for(linked)) << logs();
    ASSERT_TRUE(eventually([&] {
      const auto s = supervisor_status(ctx, ports_.request);
      return s && s->master_alive() && s->slave_alive();
    })) << logs();
    for (const auto kind : {v1::NodeCommand::ARM, v1::NodeCommand::ENGAGE}) {
      for (const int port : {ports_.nodes.master_command, ports_.nodes.slave_command}) {
        const auto r = send_command(ctx, tcp(port), kind);
        ASSERT_TRUE(r.has_value()) << "no reply from " << port;
        ASSERT_TRUE(r->ok()) << r->message();
      }
    }
    ASSERT_TRUE(st.wait_for_mode(v1::ENGAGED)) << logs();
    // Settled: 1.5 s of the slave's own cycles engaged (the slowest mode of this loop decays
    // in well under 0.5 s).
    const auto cycles = st.cycles();
    ASSERT_FALSE(cycles.empty());
    const std::uint64_t engaged_at = cycles.back().sequence();
    ASSERT_TRUE(st.wait_for([&](const v1::Telemetry& t) {
      return t.cycles_size() > 0 && t.cycles(t.cycles_size() - 1).sequence() > engaged_at + 1500;
    })) << logs();
    bridge_ =
        std::make_unique<Process>(TELEOPCTL_PATH,
                                  std::vector<std::string>{"bridge", config_.string(), "--port",
                                                           std::to_string(ports_.bridge)},
                                  dir_.path() / "bridge.log");
    ASSERT_TRUE(eventually([&] { return bridge_->log().find("on ws://") != std::string::npos; }))
        << bridge_->log();
  }

  // tests/ws_js/check.mjs on the bridge: its JSON summary (null when it printed none).
  Json js_check(double window_s, const std::string& topics, int& exit_code) const {
    const CliResult r = run(std::string(NODE_BIN) + " " + WS_JS_DIR +
                                "/check.mjs ws://127.0.0.1:" + std::to_string(ports_.bridge) + " " +
                                exact(window_s) + " " + topics,
                            false);
    exit_code = r.exit_code;
    // The summary is the last line.
    std::string out = r.out;
    while (!out.empty() && out.back() == '\n') out.pop_back();
    const auto nl = out.rfind('\n');
    const Json j = Json::parse(nl == std::string::npos ? out : out.substr(nl + 1), nullptr, false);
    if (j.is_discarded()) std::cout << "check.mjs printed:\n" << r.out << "\n";
    return j.is_discarded() ? Json::object() : j;
  }

  [[nodiscard]] int bridge_port() const { return ports_.bridge; }
  [[nodiscard]] int request_port() const { return ports_.request; }
  [[nodiscard]] const fs::path& config_file() const { return config_; }
  [[nodiscard]] const fs::path& dir() const { return dir_.path(); }
  [[nodiscard]] int slave_command_port() const { return ports_.nodes.slave_command; }
  [[nodiscard]] Process& bridge() { return *bridge_; }
  [[nodiscard]] std::string logs() const {
    return "--- master\n" + master_->log() + "--- slave\n" + slave_->log() + "--- supervisor\n" +
           supervisor_->log() + (bridge_ ? "--- bridge\n" + bridge_->log() : std::string());
  }

  zmq::context_t ctx{1};

 private:
  TempDir dir_{};
  SystemPorts ports_{};
  fs::path config_{};

 public:
  TelemetryTap mt{ctx, tcp(ports_.nodes.master_telemetry)};
  TelemetryTap st{ctx, tcp(ports_.nodes.slave_telemetry)};

 private:
  std::unique_ptr<Process> supervisor_;
  std::unique_ptr<Process> master_;
  std::unique_ptr<Process> slave_;
  std::unique_ptr<Process> bridge_;
};

bool js_client_installed() {
  return std::string(NODE_BIN).size() > 0 &&
         fs::exists(fs::path(WS_JS_DIR) / "node_modules" / "@foxglove" / "ws-protocol" /
                    "package.json");
}
constexpr const char* kInstallJs =
    "the live bridge check needs node and tests/ws_js/node_modules (run scripts/install-deps.sh, "
    "or npm ci --prefix tests/ws_js)";

std::int64_t wall_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

const Json* channel(const Json& summary, const std::string& topic) {
  for (const Json& c : summary["channels"]) {
    if (c["topic"] == topic) return &c;
  }
  return nullptr;
}

// The cycle channels' rate is the nodes' loop rate: their timestamps are the cycles' sample
// times, so a loop that a loaded host delays (the suite runs two tests at once on two cores)
// shows a lower rate with every sequence number still present. What the bridge owes is every
// cycle (count == sequence span, asserted separately) and never more than the loop made: the
// rate may sit below the configured one, never above it by more than the clock's jitter.
void expect_cycle_rate(double rate, double configured_hz, const std::string& what) {
  EXPECT_LE(rate, 1.02 * configured_hz) << what;
  EXPECT_GE(rate, 0.5 * configured_hz) << what;
}

// Rate of a topic over its window from the message timestamps, per second.
double rate_hz(const Json& t) {
  const double span_s =
      (t["last_receive_ns"].get<double>() - t["first_receive_ns"].get<double>()) * 1e-9;
  return span_s > 0 ? (t["count"].get<double>() - 1.0) / span_s : 0.0;
}

TEST(BridgeLive, FoxgloveClientDecodesEveryCycleAt1kHzWithTheEquilibriumOfTheLaw) {
  ASSERT_TRUE(js_client_installed()) << kInstallJs;
  BridgeSystem sys;
  ASSERT_NO_FATAL_FAILURE(sys.start_engaged_with_bridge());
  const std::int64_t before_ns = wall_ns();
  int code = -1;
  const Json s = sys.js_check(
      2.0, "/slave/cycle /master/cycle /supervisor/stability /supervisor/status", code);
  ASSERT_EQ(code, 0) << s.dump(1) << sys.logs();
  ASSERT_TRUE(s.is_object());
  EXPECT_TRUE(s["errors"].empty()) << s["errors"];

  // The handshake and the session's channels, each with its protobuf schema.
  EXPECT_EQ(s["subprotocol"], "foxglove.websocket.v1");
  ASSERT_TRUE(s["serverInfo"].is_object());
  EXPECT_EQ(s["serverInfo"]["op"], "serverInfo");
  const std::vector<std::pair<std::string, std::string>> expected = {
      {"/master/cycle", "teleop.v1.CycleRecord"},
      {"/slave/cycle", "teleop.v1.CycleRecord"},
      {"/master/telemetry", "teleop.v1.Telemetry"},
      {"/slave/telemetry", "teleop.v1.Telemetry"},
      {"/supervisor/stability", "teleop.v1.StabilityReport"},
      {"/supervisor/alarms", "teleop.v1.Alarm"},
      {"/supervisor/log", "foxglove.Log"},
      {"/supervisor/status", "teleop.v1.SupervisorStatus"},
      {"/config", "teleop.v1.SystemConfig"},
      {"/supervisor/parameter_changes", "teleop.v1.ParameterChangeRecord"}};
  for (const auto& [topic, type] : expected) {
    const Json* c = channel(s, topic);
    ASSERT_NE(c, nullptr) << topic << " not advertised: " << s["channels"];
    EXPECT_EQ((*c)["schemaName"], type) << topic;
    EXPECT_EQ((*c)["encoding"], "protobuf") << topic;
    EXPECT_EQ((*c)["schemaEncoding"], "protobuf") << topic;
    EXPECT_GT((*c)["schemaBytes"].get<int>(), 100) << topic;
  }

  // The shipped layout names only channels the bridge advertises, and fields of their schemas.
  std::ifstream layout_file(fs::path(TELEOP_SOURCE_DIR) / "examples/foxglove/teleop-layout.json");
  const Json layout = Json::parse(layout_file, nullptr, false);
  ASSERT_TRUE(layout.is_object()) << "examples/foxglove/teleop-layout.json is not JSON";
  int paths = 0;
  (void)foxglove::Log::descriptor();  // linked, so the generated pool knows it
  for (const auto& [id, panel] : layout["configById"].items()) {
    std::vector<std::string> refs;
    for (const Json& p : panel.value("paths", Json::array())) refs.push_back(p["value"]);
    for (const char* key : {"topicPath", "topicToRender"}) {
      if (panel.contains(key)) refs.push_back(panel[key]);
    }
    for (const std::string& ref : refs) {
      ++paths;
      const auto dot = ref.find('.');
      const std::string topic = ref.substr(0, dot);
      const Json* c = channel(s, topic);
      ASSERT_NE(c, nullptr) << id << ": " << topic << " is not advertised by the bridge";
      if (dot == std::string::npos) continue;
      const auto* d = google::protobuf::DescriptorPool::generated_pool()->FindMessageTypeByName(
          (*c)["schemaName"].get<std::string>());
      ASSERT_NE(d, nullptr) << (*c)["schemaName"];
      EXPECT_NE(d->FindFieldByName(ref.substr(dot + 1)), nullptr)
          << id << ": " << ref << " names no field of " << d->full_name();
    }
  }
  EXPECT_GE(paths, 10);

  const Equilibrium eq = equilibrium();
  std::cout << "equilibrium of the law: x_m " << eq.master_m * 1e3 << " mm, x_s "
            << eq.slave_m * 1e3 << " mm, F_h " << eq.human_force_N << " N\n";
  for (const std::string topic : {"/slave/cycle", "/master/cycle"}) {
    const Json& t = s["topics"][topic];
    ASSERT_TRUE(t.is_object()) << topic;
    const double rate = rate_hz(t);
    std::cout << topic << ": " << t["count"] << " messages, " << rate << " Hz, position "
              << t["position_m"]["mean"].get<double>() * 1e3 << " mm ["
              << t["position_m"]["min"].get<double>() * 1e3 << ", "
              << t["position_m"]["max"].get<double>() * 1e3 << "], force " << t["force_N"]["mean"]
              << " N\n";
    // One message per control cycle: every sequence number once, in order, at the
    // configured rate (the timestamps are the cycles' sample times on the wall clock).
    EXPECT_EQ(t["sequence_steps_not_one"], 0) << topic;
    EXPECT_EQ(t["last_sequence"].get<double>() - t["first_sequence"].get<double>() + 1.0,
              t["count"].get<double>())
        << topic;
    EXPECT_GT(t["count"].get<int>(), 1900) << topic;  // 2 s at 1 kHz
    expect_cycle_rate(rate, kRateHz, topic);
    EXPECT_TRUE(t["receive_nondecreasing"].get<bool>()) << topic;
    // Wall-clock UTC timestamps: within a few seconds of this test's own clock.
    EXPECT_NEAR(t["first_receive_ns"].get<double>(), static_cast<double>(before_ns), 5e9) << topic;
    EXPECT_EQ(t["modes"].size(), 1U) << t["modes"];
    EXPECT_TRUE(t["modes"].contains("ENGAGED")) << t["modes"];
  }
  // The static equilibrium: within 0.1 mm (the encoder and the load cell's noise are far
  // below that) and the human's force on the handle within 10 mN.
  const Json& slave = s["topics"]["/slave/cycle"];
  const Json& master = s["topics"]["/master/cycle"];
  EXPECT_NEAR(slave["position_m"]["mean"].get<double>(), eq.slave_m, 1e-4);
  EXPECT_NEAR(master["position_m"]["mean"].get<double>(), eq.master_m, 1e-4);
  EXPECT_NEAR(master["force_N"]["mean"].get<double>(), eq.human_force_N, 0.01);
  // The slave touches nothing physical (the fixture is virtual): its load cell reads ~0.
  EXPECT_NEAR(slave["force_N"]["mean"].get<double>(), 0.0, 0.01);

  // The same cycle as the node's own telemetry says, field for field.
  const Json& last = slave["last"];
  const auto seq = std::stoull(last["sequence"].get<std::string>());
  bool found = false;
  for (const v1::CycleRecord& c : sys.st.cycles()) {
    if (c.sequence() != seq) continue;
    found = true;
    EXPECT_EQ(last["position_m"].get<double>(), c.position_m());
    EXPECT_EQ(last["force_N"].get<double>(), c.force_n());
    EXPECT_EQ(last["command_N"].get<double>(), c.command_n());
    EXPECT_EQ(std::stoll(last["sample_time_ns"].get<std::string>()), c.sample_time_ns());
  }
  EXPECT_TRUE(found) << "cycle " << seq << " not in the slave's own telemetry";

  // The stability report (latched: the newest at once), consistent with the file.
  const Json& report = s["topics"]["/supervisor/stability"];
  ASSERT_TRUE(report.is_object()) << "no stability report";
  const Json& r = report["last"];
  EXPECT_EQ(r["verdict"], "stable");
  EXPECT_EQ(r["slave_fixture_stiffness_N_per_m"].get<double>(), kFixtureK);
  const double max_k = r["max_stable_slave_stiffness_N_per_m"].get<double>();
  EXPECT_GT(max_k, kFixtureK);
  EXPECT_NEAR(r["slave_margin"].get<double>(), 1.0 - kFixtureK / max_k, 1e-12);
  // The supervisor's summary, ten times a second.
  const Json& status = s["topics"]["/supervisor/status"];
  ASSERT_TRUE(status.is_object()) << "no status";
  EXPECT_NEAR(rate_hz(status), 10.0, 2.0);

  // SIGTERM: a clean stop that reports what it served.
  sys.bridge().signal(SIGTERM);
  EXPECT_EQ(sys.bridge().wait(), 0) << sys.bridge().log();
  EXPECT_NE(sys.bridge().log().find("stopped; 1 connection(s)"), std::string::npos)
      << sys.bridge().log();
}

// An alarm reaches Foxglove twice: as teleop.v1.Alarm and as foxglove.Log for the Log panel.
// The slave e-stopped directly makes the supervisor raise "node_state: went SAFE" (WARNING).
TEST(BridgeLive, AnAlarmArrivesAsAlarmAndAsFoxgloveLogWithItsSeverity) {
  ASSERT_TRUE(js_client_installed()) << kInstallJs;
  BridgeSystem sys;
  ASSERT_NO_FATAL_FAILURE(sys.start_engaged_with_bridge());
  int code = -1;
  Json s;
  // Four seconds of listening: the e-stop's alarm comes within ~0.1 s on a quiet host, later on
  // a loaded one (CI's runs saw only a slave overrun alarm within 0.5 s, and once, under ASan on
  // a host whose loops woke 6.5 ms late, only overrun and loss alarms within 2 s).
  std::thread client([&] { s = sys.js_check(4.0, "/supervisor/log /supervisor/alarms", code); });
  // Once the client has subscribed to both (the bridge says so), the e-stop.
  const bool subscribed = eventually([&] {
    const std::string log = sys.bridge().log();
    return log.find("subscribed to /supervisor/log") != std::string::npos &&
           log.find("subscribed to /supervisor/alarms") != std::string::npos;
  });
  if (subscribed) {
    const auto r = send_command(sys.ctx, tcp(sys.slave_command_port()), v1::NodeCommand::ESTOP);
    EXPECT_TRUE(r.has_value() && r->ok());
  }
  client.join();
  ASSERT_TRUE(subscribed) << sys.logs();
  ASSERT_EQ(code, 0) << s.dump(1) << sys.logs();
  const auto find = [&](const std::string& topic, const std::function<bool(const Json&)>& pred) {
    for (const Json& m : s["topics"][topic].value("all", Json::array())) {
      if (pred(m)) return m;
    }
    return Json();
  };
  const Json alarm = find("/supervisor/alarms", [](const Json& m) {
    return m["kind"] == "node_state" && m["side"] == "slave" &&
           m["message"].get<std::string>().rfind("went SAFE", 0) == 0;
  });
  ASSERT_FALSE(alarm.is_null()) << s["topics"].dump(1);
  EXPECT_EQ(alarm["severity"], "WARNING");
  const std::string text = "node_state: " + alarm["message"].get<std::string>();
  const Json log = find("/supervisor/log", [&](const Json& m) { return m["message"] == text; });
  ASSERT_FALSE(log.is_null()) << text << "\n" << s["topics"]["/supervisor/log"].dump(1);
  EXPECT_EQ(log["level"], "WARNING");
  EXPECT_EQ(log["name"], "teleop-supervisor/slave");
  // Its timestamp is the wall clock, within seconds of this test's.
  const double seconds = std::stod(log["timestamp"]["seconds"].get<std::string>());
  EXPECT_NEAR(seconds, static_cast<double>(wall_ns()) * 1e-9, 10.0);
}

// The summary check.mjs printed last in a client's log (null when it printed none).
Json summary_in(const std::string& log) {
  const auto at = log.rfind("\n{");
  return Json::parse(at == std::string::npos ? log : log.substr(at + 1), nullptr, false);
}

// The gains of a decoded teleop.v1.SystemConfig against the file's, field by field.
void expect_gains(const Json& gains, const v1::Gains& file, const std::string& what) {
  const auto* d = v1::Gains::descriptor();
  const auto* r = v1::Gains::GetReflection();
  for (int i = 0; i < d->field_count(); ++i) {
    const auto* f = d->field(i);
    if (f->is_repeated()) continue;  // the n-axis forms (issue 18), absent from a one-axis file
    ASSERT_TRUE(gains.contains(f->name())) << what << ": no gains." << f->name() << " in " << gains;
    EXPECT_EQ(gains[f->name()].get<double>(), r->GetDouble(file, f)) << what << ": " << f->name();
  }
}

// /config is the configuration in force, latched: a client that subscribes after the bridge
// sent it gets it at once (the bridge sends each configuration once; the supervisor's repeats
// every second are not new messages), equal to the file. A guarded `teleopctl set` then
// arrives on /supervisor/parameter_changes as the supervisor decided it, with the new values,
// followed by /config again with them and the rest of the file unchanged.
TEST(BridgeLive, TheConfigurationInForceIsLatchedAndAGuardedChangeArrivesWithItsValues) {
  ASSERT_TRUE(js_client_installed()) << kInstallJs;
  // Plaintext loopback: the supervisor's retunes need the opt-in.
  BridgeSystem sys(kAllowUnauthenticatedRetune);
  ASSERT_NO_FATAL_FAILURE(sys.start_engaged_with_bridge());
  // The file as written, read here with protobuf's own text parser.
  v1::SystemConfig file;
  {
    std::ifstream in(sys.config_file());
    std::stringstream text;
    text << in.rdbuf();
    ASSERT_TRUE(google::protobuf::TextFormat::ParseFromString(text.str(), &file));
  }
  ASSERT_EQ(file.gains().kps(), kKps);
  const std::string url = "ws://127.0.0.1:" + std::to_string(sys.bridge_port());
  const auto client = [&](const std::string& name, const std::vector<std::string>& topics) {
    std::vector<std::string> args = {"WS_CHECK_BOUND_S=40", NODE_BIN,
                                     std::string(WS_JS_DIR) + "/check.mjs", url, "1"};
    args.insert(args.end(), topics.begin(), topics.end());
    return std::make_unique<Process>("/usr/bin/env", args, sys.dir() / name);
  };
  // A first client takes the configuration as the bridge got it from the supervisor.
  auto first = client("first.log", {"/config:1"});
  ASSERT_EQ(first->wait(), 0) << first->log() << sys.logs();
  const Json one = summary_in(first->log());
  ASSERT_TRUE(one.is_object()) << first->log();
  ASSERT_EQ(one["topics"]["/config"]["count"], 1) << one.dump(1);
  const Json& sent = one["topics"]["/config"]["last"];

  // The second client: the same message at once, from the latch (its timestamp is when the
  // bridge received it, before this client existed).
  auto second = client("second.log", {"/config:2", "/supervisor/parameter_changes:1"});
  ASSERT_TRUE(eventually([&] {
    return second->log().find("first message on /config") != std::string::npos ||
           second->exited().has_value();
  })) << second->log();
  ASSERT_FALSE(second->exited().has_value()) << second->log();
  const std::string sup = " --supervisor 127.0.0.1:" + std::to_string(sys.request_port());
  const std::string set = "set slave.fixture.stiffness_N_per_m=800 gains.kps=550" + sup;
  CliResult r = teleopctl(set);
  // A refusal for a round trip a host stall made long is the supervisor right; asked again.
  for (int i = 0; i < 20 && r.exit_code == 3 && r.out.find("round trip") != std::string::npos;
       ++i) {
    std::cout << "refused (host stall?), asked again: " << r.out;
    std::this_thread::sleep_for(std::chrono::milliseconds(250));
    r = teleopctl(set);
  }
  ASSERT_EQ(r.exit_code, 0) << r.out << sys.logs();
  ASSERT_EQ(second->wait(), 0) << second->log() << sys.logs();
  const Json s = summary_in(second->log());
  ASSERT_TRUE(s.is_object()) << second->log();
  EXPECT_TRUE(s["errors"].empty()) << s["errors"];
  const Json* config_channel = channel(s, "/config");
  ASSERT_NE(config_channel, nullptr);
  EXPECT_EQ((*config_channel)["schemaName"], "teleop.v1.SystemConfig");

  const Json& configs = s["topics"]["/config"]["all"];
  ASSERT_EQ(configs.size(), 2U) << configs.dump(1);
  // The latched configuration: the one the first client got, with the same timestamp, and the
  // file's rate, gains and fixture.
  EXPECT_EQ(configs[0], sent);
  EXPECT_EQ(s["topics"]["/config"]["first_receive_ns"],
            one["topics"]["/config"]["first_receive_ns"]);
  EXPECT_EQ(configs[0]["sample_rate_hz"].get<double>(), file.sample_rate_hz());
  EXPECT_EQ(configs[0]["sample_rate_hz"].get<double>(), kRateHz);
  expect_gains(configs[0]["gains"], file.gains(), "latched /config");
  EXPECT_EQ(configs[0]["slave"]["fixture"]["stiffness_N_per_m"].get<double>(), kFixtureK);
  EXPECT_EQ(configs[0]["round_trip_delay_samples"].get<double>(), 2.0);

  std::cout << "latched /config: sample_rate_hz " << configs[0]["sample_rate_hz"] << ", gains "
            << configs[0]["gains"].dump() << ", slave fixture "
            << configs[0]["slave"]["fixture"].dump() << "\n/config after the change: gains "
            << configs[1]["gains"].dump() << ", slave fixture "
            << configs[1]["slave"]["fixture"].dump() << "\n";

  // The change as the supervisor decided it: applied, with what was asked.
  const Json* applied = nullptr;
  for (const Json& c : s["topics"]["/supervisor/parameter_changes"]["all"]) {
    if (c["reply"]["accepted"].get<bool>()) applied = &c;
  }
  ASSERT_NE(applied, nullptr) << s["topics"]["/supervisor/parameter_changes"].dump(1);
  EXPECT_EQ((*applied)["request"]["slave_fixture_stiffness_N_per_m"].get<double>(), 800.0);
  // teleopctl set sends every gain: those in force, kps changed.
  v1::SystemConfig expected = file;
  expected.mutable_slave()->mutable_fixture()->set_stiffness_n_per_m(800.0);
  expected.mutable_gains()->set_kps(550.0);
  expect_gains((*applied)["request"]["gains"], expected.gains(), "the request");
  EXPECT_FALSE((*applied)["request"]["dry_run"].get<bool>());
  EXPECT_NE(std::stoull((*applied)["reply"]["change_id"].get<std::string>()), 0U);
  EXPECT_EQ((*applied)["reply"]["prediction"]["slave_fixture_stiffness_N_per_m"].get<double>(),
            800.0);
  // The teleopctl's own output names the same change.
  EXPECT_NE(r.out.find("change " + (*applied)["reply"]["change_id"].get<std::string>() +
                       " applies at master sequence " +
                       (*applied)["reply"]["apply_at_master_sequence"].get<std::string>()),
            std::string::npos)
      << r.out;

  // /config again: the new values, everything else as in the file.
  const Json& now = configs[1];
  EXPECT_EQ(now["slave"]["fixture"]["stiffness_N_per_m"].get<double>(), 800.0);
  EXPECT_EQ(now["slave"]["fixture"]["position_m"].get<double>(), kFixtureP);
  expect_gains(now["gains"], expected.gains(), "/config after the change");
  EXPECT_EQ(now["sample_rate_hz"].get<double>(), kRateHz);
  Json unchanged_now = now;
  Json unchanged_then = configs[0];
  for (Json* j : {&unchanged_now, &unchanged_then}) {
    j->erase("gains");
    (*j)["slave"]["fixture"].erase("stiffness_N_per_m");
  }
  EXPECT_EQ(unchanged_now, unchanged_then);
  EXPECT_GE(s["topics"]["/config"]["last_receive_ns"].get<double>(),
            s["topics"]["/supervisor/parameter_changes"]["first_receive_ns"].get<double>());

  // A bridge started after the change serves the configuration in force, not the file: the
  // supervisor sends it again every second.
  const int late_port = free_port();
  Process late(TELEOPCTL_PATH,
               {"bridge", sys.config_file().string(), "--port", std::to_string(late_port)},
               sys.dir() / "late-bridge.log");
  ASSERT_TRUE(eventually([&] { return late.log().find("on ws://") != std::string::npos; }))
      << late.log();
  Process third("/usr/bin/env",
                {"WS_CHECK_BOUND_S=40", NODE_BIN, std::string(WS_JS_DIR) + "/check.mjs",
                 "ws://127.0.0.1:" + std::to_string(late_port), "1", "/config:1"},
                sys.dir() / "third.log");
  ASSERT_EQ(third.wait(), 0) << third.log() << late.log();
  const Json t = summary_in(third.log());
  ASSERT_TRUE(t.is_object()) << third.log();
  EXPECT_EQ(t["topics"]["/config"]["last"], now) << t["topics"]["/config"].dump(1);
}

// Secure by default (the launch's ephemeral CURVE keys): a bridge given no key finds the live
// launch's console key, as the console does, and serves every cycle; one that finds no launch
// is a plaintext client the nodes never answer, so Foxglove sees the channels but no message.
TEST(BridgeLive, ServesALaunchOverItsCurveKeysAndNothingWithoutThem) {
  ASSERT_TRUE(js_client_installed()) << kInstallJs;
  TempDir dir;
  const SystemPorts p;
  const fs::path runtime = dir.path() / "runtime";
  const fs::path config = dir.write("system.textproto", system_config(p, dir.path() / "sessions"));
  const std::string env = "TELEOP_RUNTIME_DIR=" + runtime.string();
  Process launch("/usr/bin/env",
                 {env, std::string("TELEOP_MASTER_BIN=") + MASTER_BIN,
                  std::string("TELEOP_SLAVE_BIN=") + SLAVE_BIN,
                  std::string("TELEOP_SUPERVISOR_BIN=") + SUPERVISOR_BIN, TELEOPCTL_PATH, "launch",
                  config.string(), "--record-dir", (dir.path() / "sessions").string()},
                 dir.path() / "launch.log");
  struct CtrlCAtEnd {  // SIGKILL would orphan the launch's nodes
    Process& p;
    ~CtrlCAtEnd() {
      p.signal(SIGINT);
      (void)p.wait();
    }
  } stop_launch{launch};
  ASSERT_TRUE(eventually([&] {
    return launch.log().find("Ctrl-C stops both nodes.") != std::string::npos;
  })) << launch.log();
  const auto check = [&](const std::string& runtime_env, int port, int& code) {
    Process bridge(
        "/usr/bin/env",
        {runtime_env, TELEOPCTL_PATH, "bridge", config.string(), "--port", std::to_string(port)},
        dir.path() / ("bridge-" + std::to_string(port) + ".log"));
    EXPECT_TRUE(eventually([&] { return bridge.log().find("on ws://") != std::string::npos; }))
        << bridge.log();
    const CliResult r =
        run("WS_CHECK_BOUND_S=4 " + std::string(NODE_BIN) + " " + WS_JS_DIR +
                "/check.mjs ws://127.0.0.1:" + std::to_string(port) + " 1 /slave/cycle",
            false);
    code = r.exit_code;
    bridge.signal(SIGTERM);
    EXPECT_EQ(bridge.wait(), 0) << bridge.log();
    return Json::parse(
        r.out.substr(r.out.rfind("\n{") == std::string::npos ? 0 : r.out.rfind("\n{")), nullptr,
        false);
  };
  int code = -1;
  const Json keyed = check(env, free_port(), code);
  ASSERT_EQ(code, 0) << keyed.dump(1) << launch.log();
  const Json& t = keyed["topics"]["/slave/cycle"];
  EXPECT_EQ(t["sequence_steps_not_one"], 0);
  expect_cycle_rate(rate_hz(t), kRateHz, "/slave/cycle");
  EXPECT_TRUE(t["modes"].contains("ENGAGED")) << t["modes"];
  // No launch under this runtime directory: a plaintext client, refused by every endpoint.
  const Json plain =
      check("TELEOP_RUNTIME_DIR=" + (dir.path() / "none").string(), free_port(), code);
  EXPECT_EQ(code, 2) << plain.dump(1);
  ASSERT_TRUE(plain.is_object());
  EXPECT_NE(channel(plain, "/slave/cycle"), nullptr);
  EXPECT_FALSE(plain["topics"].contains("/slave/cycle")) << plain["topics"];
}

// Raw bytes to the bridge's port: a connection, `bytes`, a short read, closed.
void send_raw(int port, const std::string& bytes) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(static_cast<std::uint16_t>(port));
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a)) == 0) {
    (void)::send(fd, bytes.data(), bytes.size(), MSG_NOSIGNAL);
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  ::close(fd);
}

std::string handshake() {
  return "GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
         "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n"
         "Sec-WebSocket-Protocol: foxglove.websocket.v1\r\n\r\n";
}

// A masked client text frame (RFC 6455 §5.2), payload under 126 bytes.
std::string text_frame(const std::string& payload, bool masked = true) {
  std::string f = "\x81";
  f += static_cast<char>((masked ? 0x80 : 0x00) | payload.size());
  const char mask[4] = {1, 2, 3, 4};
  if (masked) f.append(mask, 4);
  for (std::size_t i = 0; i < payload.size(); ++i) {
    f += masked ? static_cast<char>(payload[i] ^ mask[i % 4]) : payload[i];
  }
  return f;
}

TEST(BridgeLive, HostileWebSocketClientsNeverEndTheBridge) {
  ASSERT_TRUE(js_client_installed()) << kInstallJs;
  BridgeSystem sys;
  ASSERT_NO_FATAL_FAILURE(sys.start_engaged_with_bridge());
  const int port = sys.bridge_port();
  send_raw(port, std::string("\x16\x03\x01\x02\x00 TLS hello to a plain port", 30));
  send_raw(port, "GET / HTTP/1.1\r\nHost: x\r\n\r\n");  // HTTP, no upgrade
  send_raw(port, handshake() + text_frame("{not json"));
  send_raw(port, handshake() + text_frame(R"({"op":"subscribe","subscriptions":[{"id":-1}]})"));
  send_raw(port, handshake() + text_frame(R"({"op":"subscribe"})", false));  // unmasked
  send_raw(port, handshake() + std::string("\x82\xFF\x7F\xFF\xFF\xFF\xFF\xFF\xFF\xFFmask", 14));
  send_raw(port, handshake() + text_frame(R"({"op":"unsubscribe","subscriptionIds":[1e300]})"));
  ASSERT_FALSE(sys.bridge().exited().has_value()) << sys.bridge().log();
  // A proper client is still served, every cycle.
  int code = -1;
  const Json s = sys.js_check(1.0, "/slave/cycle", code);
  ASSERT_EQ(code, 0) << s.dump(1) << sys.logs();
  const Json& t = s["topics"]["/slave/cycle"];
  EXPECT_EQ(t["sequence_steps_not_one"], 0);
  expect_cycle_rate(rate_hz(t), kRateHz, "/slave/cycle");
  EXPECT_FALSE(sys.bridge().exited().has_value()) << sys.bridge().log();
}

TEST(BridgeCli, RefusesANonLoopbackAddressUnlessAllowedAndNamesAPortInUse) {
  const CliResult off = teleopctl("bridge --address 0.0.0.0 --duration-s 1");
  EXPECT_EQ(off.exit_code, 2) << off.out;
  EXPECT_NE(off.out.find("not a loopback address"), std::string::npos) << off.out;
  EXPECT_NE(off.out.find("ssh -L 8765:127.0.0.1:8765"), std::string::npos) << off.out;
  // Loopback in any spelling is fine; a port in use is named.
  const int port = free_port();
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(static_cast<std::uint16_t>(port));
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ASSERT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a)), 0);
  ASSERT_EQ(::listen(fd, 1), 0);
  const CliResult busy =
      teleopctl("bridge --address 127.0.0.1 --port " + std::to_string(port) + " --duration-s 1");
  ::close(fd);
  EXPECT_EQ(busy.exit_code, 1) << busy.out;
  EXPECT_NE(busy.out.find("cannot listen on 127.0.0.1:" + std::to_string(port)), std::string::npos)
      << busy.out;
}

}  // namespace
}  // namespace teleop::test
