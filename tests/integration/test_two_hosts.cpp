// Master and slave as two hosts on one machine (issue 8): each node in its own network
// namespace, the two joined by a veth pair, one `teleopctl relay` per direction adding 2-3 ms
// (2.5 ± 0.5 ms, uniform, in order) on the receiving host, and the supervisor on the master's host
// reaching the slave across the link. Every process reads the same system file, as on two
// real machines. Expected values: the round trip from the delays put in (4-10 ms plus the
// loops' own cycles), and the maximum stable stiffness from `teleopctl analyze` for the
// round trip the supervisor measured.
//
// Needs root (network namespaces); without it, or without `ip netns`, the test is skipped and
// says why.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <sched.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>

#include "tests/integration/cli_harness.hpp"
#include "tests/integration/node_harness.hpp"

namespace teleop::test {
namespace {

namespace fs = std::filesystem;

int sh(const std::string& command) {
  const int rc = std::system((command + " >/dev/null 2>&1").c_str());
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : 128;
}

// Two namespaces and a veth pair between them, removed again on destruction. The calling
// thread is moved into the master's namespace (as if the test ran on the master's host) and
// back at the end; processes it starts inherit that namespace unless started through
// `ip netns exec`.
class TwoHosts {
 public:
  // The master's host at SUBNET + master_host, the slave's at SUBNET + slave_host.
  explicit TwoHosts(std::string subnet = "10.77." + std::to_string(::getpid() % 250) + ".",
                    int master_host = 1, int slave_host = 2)
      : tag_(std::to_string(::getpid() % 100000)),
        master_ns_("tm" + tag_),
        slave_ns_("ts" + tag_),
        master_ip_(subnet + std::to_string(master_host)),
        slave_ip_(subnet + std::to_string(slave_host)) {}
  ~TwoHosts() {
    if (home_ >= 0) {
      (void)::setns(home_, CLONE_NEWNET);
      ::close(home_);
    }
    (void)sh("ip netns del " + master_ns_);
    (void)sh("ip netns del " + slave_ns_);
  }
  TwoHosts(const TwoHosts&) = delete;
  TwoHosts& operator=(const TwoHosts&) = delete;

  // Empty on success, else why the two hosts could not be made.
  std::string make() {
    if (::geteuid() != 0) return "network namespaces need root";
    if (sh("ip netns add " + master_ns_) != 0) return "ip netns add failed (no iproute2?)";
    if (sh("ip netns add " + slave_ns_) != 0) return "ip netns add failed";
    const std::string vm = "vm" + tag_;
    const std::string vs = "vs" + tag_;
    for (const std::string& c :
         {"ip link add " + vm + " type veth peer name " + vs,
          "ip link set " + vm + " netns " + master_ns_, "ip link set " + vs + " netns " + slave_ns_,
          "ip -n " + master_ns_ + " addr add " + master_ip() + "/24 dev " + vm,
          "ip -n " + slave_ns_ + " addr add " + slave_ip() + "/24 dev " + vs,
          "ip -n " + master_ns_ + " link set " + vm + " up",
          "ip -n " + slave_ns_ + " link set " + vs + " up",
          "ip -n " + master_ns_ + " link set lo up", "ip -n " + slave_ns_ + " link set lo up"}) {
      if (sh(c) != 0) return "failed: " + c;
    }
    if (sh("ip netns exec " + slave_ns_ + " true") != 0) {
      return "the namespaces cannot run commands";
    }
    home_ = ::open("/proc/self/ns/net", O_RDONLY | O_CLOEXEC);
    const int fd = ::open(("/run/netns/" + master_ns_).c_str(), O_RDONLY | O_CLOEXEC);
    if (home_ < 0 || fd < 0 || ::setns(fd, CLONE_NEWNET) != 0) {
      if (fd >= 0) ::close(fd);
      return "setns into the master's namespace failed";
    }
    ::close(fd);
    return "";
  }
  [[nodiscard]] const std::string& master_ip() const { return master_ip_; }
  [[nodiscard]] const std::string& slave_ip() const { return slave_ip_; }
  [[nodiscard]] const std::string& slave_ns() const { return slave_ns_; }

 private:
  std::string tag_;
  std::string master_ns_;
  std::string slave_ns_;
  std::string master_ip_;
  std::string slave_ip_;
  int home_{-1};
};

std::string at(const std::string& ip, int port) {
  return "tcp://" + ip + ":" + std::to_string(port);
}

std::vector<std::string> words(const std::string& line) {
  std::vector<std::string> out;
  std::istringstream in(line);
  for (std::string w; in >> w;) out.push_back(w);
  return out;
}

TEST(TwoHosts, TheSupervisorMeasuresTheRoundTripAcrossTheLinkAndLowersTheLimitToAnalyze) {
  TwoHosts hosts;
  if (const std::string why = hosts.make(); !why.empty()) GTEST_SKIP() << why;
  TempDir dir;
  const Ports p;
  const int relay_to_slave = free_port();   // bound on the slave's host
  const int relay_to_master = free_port();  // bound on the master's host
  const int report = free_port();
  const int request = free_port();
  const std::string m = hosts.master_ip();
  const std::string s = hosts.slave_ip();
  auto node = [](const std::string& ip, int state, int command, int telemetry, int relay) {
    return "node { state_endpoint: \"" + at(ip, state) + "\" command_endpoint: \"" +
           at(ip, command) + "\" telemetry_endpoint: \"" + at(ip, telemetry) +
           "\" peer_state_endpoint: \"" + at("127.0.0.1", relay) +
           "\" telemetry_rate_hz: 100 rt { fifo_priority: 80 lock_memory: false "
           "cpu_dma_latency_us: -1 } }";
  };
  const fs::path config = dir.write(
      "system.textproto",
      paddles_system(node(m, p.master_state, p.master_command, p.master_telemetry, relay_to_master),
                     node(s, p.slave_state, p.slave_command, p.slave_telemetry, relay_to_slave),
                     "fixture { stiffness_N_per_m: 3500 position_m: 0.005 }", 0.5) +
          "supervisor { report_endpoint: \"" + tcp(report) + "\" request_endpoint: \"" +
          tcp(request) + "\" record: false }\n" +
          // Plaintext: the relay forwards frames as they are and cannot take part in CURVE.
          // The supervisor's changes without keys: opted in by name.
          "security { insecure: true allow_unauthenticated_retune: true }\n");
  // 2-3 ms each way (within the 2-5 ms), in order as on one TCP connection (the link's own
  // transport).
  const std::string delay = " --delay-ms 2.5 --jitter-ms 0.5 --in-order";
  const std::vector<std::string> on_slave_host = {"netns", "exec", hosts.slave_ns()};
  auto slave_host = [&](const std::string& binary, const std::vector<std::string>& args) {
    std::vector<std::string> all = on_slave_host;
    all.push_back(binary);
    all.insert(all.end(), args.begin(), args.end());
    return all;
  };
  // The slave's host: the slave and the relay that brings it the master's states.
  Process relay_ms(
      "/sbin/ip",
      slave_host(TELEOPCTL_PATH, words("relay --from " + at(m, p.master_state) + " --to " +
                                       tcp(relay_to_slave) + delay + " --seed 5")),
      dir.path() / "relay_ms.log");
  Process slave("/sbin/ip", slave_host(SLAVE_BIN, {config.string()}), dir.path() / "slave.log");
  // The master's host: the master, its relay, the supervisor (and this test).
  Process relay_sm(TELEOPCTL_PATH,
                   words("relay --from " + at(s, p.slave_state) + " --to " + tcp(relay_to_master) +
                         delay + " --seed 6"),
                   dir.path() / "relay_sm.log");
  Process master(MASTER_BIN, {config.string()}, dir.path() / "master.log");
  Process supervisor(SUPERVISOR_BIN, {config.string()}, dir.path() / "supervisor.log");
  const auto logs = [&] {
    return "--- master\n" + master.log() + "--- slave\n" + slave.log() + "--- supervisor\n" +
           supervisor.log() + "--- relay to slave\n" + relay_ms.log() + "--- relay to master\n" +
           relay_sm.log();
  };

  zmq::context_t ctx(1);
  TelemetryTap mt(ctx, at(m, p.master_telemetry));
  TelemetryTap st(ctx, at(s, p.slave_telemetry));
  ASSERT_TRUE(mt.wait_for([](const v1::Telemetry& t) { return t.link().accepted() > 0; }))
      << logs();
  ASSERT_TRUE(st.wait_for([](const v1::Telemetry& t) { return t.link().accepted() > 0; }))
      << logs();
  for (const auto kind : {v1::NodeCommand::ARM, v1::NodeCommand::ENGAGE}) {
    for (const std::string& endpoint : {at(m, p.master_command), at(s, p.slave_command)}) {
      const auto r = send_command(ctx, endpoint, kind);
      ASSERT_TRUE(r.has_value() && r->ok()) << endpoint << "\n" << logs();
    }
  }
  ASSERT_TRUE(mt.wait_for_mode(v1::ENGAGED)) << logs();
  ASSERT_TRUE(st.wait_for_mode(v1::ENGAGED)) << logs();

  // Two seconds of engaged cycles on the master's clock, so the round trip's p99 has settled.
  const std::int64_t engaged_at = mt.cycles().back().sample_time_ns();
  ASSERT_TRUE(mt.wait_for([&](const v1::Telemetry& t) {
    return t.cycles_size() > 0 &&
           t.cycles(t.cycles_size() - 1).sample_time_ns() > engaged_at + 2'000'000'000;
  })) << logs();
  // The link across the hosts: at least 2 + 2 ms; at most 3 + 3 ms plus a cycle of each loop
  // and the relays' scheduling. The nodes' quantiles are upper edges of their histogram's
  // bins (8.19, 10.32, 13.00 ms ...): the bounds are the bins holding 4 and 9 ms.
  const v1::LinkStats link = mt.last()->link();
  EXPECT_GE(link.round_trip_p50_ns(), 4'000'000) << link.DebugString();
  EXPECT_LE(link.round_trip_p50_ns(), 10'400'000) << link.DebugString();
  EXPECT_GE(link.round_trip_p99_ns(), link.round_trip_p50_ns());
  // The tail is the host's scheduling as much as the link's: with the rest of the suite
  // running beside it, p99 reached 12.3 and 16.4 ms (the relays' threads waited for a core).
  // Bounded loosely; the model below takes whatever was measured.
  EXPECT_LE(link.round_trip_p99_ns(), 33'000'000) << link.DebugString();

  // The supervisor's model takes the round trip it measured (the larger of the two nodes'
  // p99s, in whole samples rounded up), and its limit is what the offline analyser gives for
  // that many samples.
  std::optional<v1::SupervisorStatus> status;
  ASSERT_TRUE(eventually([&] {
    status = supervisor_status(ctx, request);
    return status && status->report().round_trip_samples() >= 5 &&
           status->report().measured_round_trip_ns() > 0;
  })) << logs();
  const v1::StabilityReport& r = status->report();
  const int samples = r.round_trip_samples();
  EXPECT_EQ(samples, static_cast<int>(
                         std::ceil(static_cast<double>(r.measured_round_trip_ns()) / 1e6 - 1e-9)))
      << r.DebugString();
  EXPECT_GE(r.measured_round_trip_ns(), 4'000'000);
  // On a loaded host the p99 can reach a round trip with no stable stiffness at all (12
  // samples once, with the rest of the suite beside it): then the analyser has no limit, the
  // supervisor has none either, and the guard halves the wall.
  const auto limit = [&](int n) -> std::optional<double> {
    const CliResult a = teleopctl("analyze " + config.string() +
                                      " --max-stiffness slave --json --set "
                                      "round_trip_delay_samples=" +
                                      std::to_string(n),
                                  false);
    EXPECT_TRUE(a.exit_code == 0 || a.exit_code == 3) << a.out;
    const nlohmann::json v =
        nlohmann::json::parse(a.out).at("limits").at(0).at("max_stable_stiffness_N_per_m");
    if (!v.is_number()) return std::nullopt;
    return v.get<double>();
  };
  const std::optional<double> analysed = limit(samples);
  const std::optional<double> one_sample = limit(1);
  ASSERT_TRUE(one_sample.has_value());
  if (analysed) {
    ASSERT_TRUE(r.has_max_stable_slave_stiffness_n_per_m()) << r.DebugString();
    EXPECT_NEAR(r.max_stable_slave_stiffness_n_per_m(), *analysed, 1e-3 * *analysed);
    EXPECT_LT(*analysed, *one_sample);
  } else {
    EXPECT_FALSE(r.has_max_stable_slave_stiffness_n_per_m()) << r.DebugString();
  }
  std::cout << "across the veth with 2-3 ms each way: round trip p50 "
            << static_cast<double>(link.round_trip_p50_ns()) * 1e-6 << " ms, p99 "
            << static_cast<double>(link.round_trip_p99_ns()) * 1e-6 << " ms; supervisor model "
            << samples << " samples, slave limit "
            << (analysed ? std::to_string(*analysed) + " N/m" : std::string("none"))
            << "; one sample: " << *one_sample << " N/m\n";
  // The 3500 N/m wall is within the one-sample limit but not within this one: the guard
  // lowered it (an ACTION naming the grown round trip), and the slave runs with what it put
  // in force, below the new limit, or half the wall where there is no limit.
  if (analysed) {
    ASSERT_LT(*analysed, 3500.0);
  }
  ASSERT_GT(*one_sample, 3500.0);
  ASSERT_TRUE(st.wait_for([&](const v1::Telemetry& t) {
    return t.active().change_id() > 0 && t.active().ramp_progress() == 1.0;
  })) << logs();
  const double in_force = st.last()->active().slave_fixture_stiffness_n_per_m();
  // (Half the limit of the round trip the guard first saw grow; the model may have grown
  // further since without the lowered wall leaving its limit.)
  if (analysed) {
    EXPECT_LT(in_force, *analysed);
  } else {
    EXPECT_LE(in_force, 0.5 * 3500.0 + 1e-6);
  }
  std::cout << "the guard lowered the wall from 3500 to " << in_force << " N/m\n";
  if (analysed) {
    EXPECT_EQ(mt.last()->mode(), v1::ENGAGED);
    EXPECT_EQ(st.last()->mode(), v1::ENGAGED);
  } else {
    // No stable stiffness at that round trip: the supervisor's escalation may disengage.
    std::cout << "modes now " << v1::NodeMode_Name(mt.last()->mode()) << "/"
              << v1::NodeMode_Name(st.last()->mode()) << "\n";
  }
}

// docs/deploy.md's walk-through from two fresh machines to an engaged teleoperator, on two
// namespaces with the example's own addresses (192.168.50.10 and .20): keys from
// `teleopctl keygen`, pasted into examples/two_machines/system.textproto in place of its
// placeholders, the file otherwise as shipped (CURVE on every link); the slave's host runs
// teleop-slave, the master's teleop-master and teleop-supervisor; a console key arms and
// engages both nodes and reads the supervisor's status.
TEST(TwoHosts, TheTwoMachineExampleEngagesWithKeysFromKeygen) {
  TwoHosts hosts("192.168.50.", 10, 20);
  if (const std::string why = hosts.make(); !why.empty()) GTEST_SKIP() << why;
  TempDir dir;
  const fs::path keys = dir.path() / "keys";
  fs::create_directories(keys);
  std::map<std::string, std::string> public_keys;
  for (const std::string name : {"master", "slave", "supervisor", "console"}) {
    const CliResult k = teleopctl("keygen " + (keys / name).string(), false);
    ASSERT_EQ(k.exit_code, 0) << k.out;
    std::ifstream in(keys / (name + ".pub"));
    for (std::string line; std::getline(in, line);) {
      if (line.rfind("public-key = ", 0) == 0) public_keys[name] = line.substr(13);
    }
    ASSERT_EQ(public_keys[name].size(), 40u) << name;
  }
  std::ifstream example(fs::path(TELEOP_SOURCE_DIR) / "examples/two_machines/system.textproto");
  std::stringstream text;
  text << example.rdbuf();
  std::string config = text.str();
  const auto replace_all = [&config](const std::string& from, const std::string& to) {
    std::size_t n = 0;
    for (std::size_t at = config.find(from); at != std::string::npos;
         at = config.find(from, at + to.size())) {
      config.replace(at, from.size(), to);
      ++n;
    }
    return n;
  };
  EXPECT_EQ(replace_all("REPLACEwithMASTERpublicKEYfromKEYGEN0000", public_keys["master"]), 1u);
  EXPECT_EQ(replace_all("REPLACEwithSLAVEpublicKEYfromKEYGEN00000", public_keys["slave"]), 1u);
  EXPECT_EQ(replace_all("REPLACEwithSUPERVISORpublicKEYfromKEYGEN", public_keys["supervisor"]), 2u);
  EXPECT_EQ(replace_all("REPLACEwithCONSOLEpublicKEYfromKEYGEN000", public_keys["console"]), 1u);
  // This test's own directories in place of /etc/teleop/keys and /var/lib/teleop.
  EXPECT_GE(replace_all("/etc/teleop/keys/", keys.string() + "/"), 3u);
  EXPECT_EQ(replace_all("/var/lib/teleop/sessions", (dir.path() / "sessions").string()), 1u);
  // No real-time privileges are needed for the walk-through (refusals are warnings).
  const fs::path file = dir.write("system.textproto", config);

  Process slave("/sbin/ip", {"netns", "exec", hosts.slave_ns(), SLAVE_BIN, file.string()},
                dir.path() / "slave.log");
  Process master(MASTER_BIN, {file.string()}, dir.path() / "master.log");
  Process supervisor(SUPERVISOR_BIN, {file.string()}, dir.path() / "supervisor.log");
  const auto logs = [&] {
    return "--- master\n" + master.log() + "--- slave\n" + slave.log() + "--- supervisor\n" +
           supervisor.log();
  };
  const std::string console = " --key " + (keys / "console.key").string();
  const auto status = [&]() -> std::optional<nlohmann::json> {
    const CliResult r =
        teleopctl("status --json --supervisor 192.168.50.10:5567" + console + " --server-key " +
                      (keys / "supervisor.pub").string() + " --timeout-ms 1000",
                  false);
    if (r.exit_code != 0) return std::nullopt;
    return nlohmann::json::parse(r.out);
  };
  // Both nodes' telemetry reaches the supervisor and the link carries states both ways.
  std::optional<nlohmann::json> s;
  ASSERT_TRUE(eventually([&] {
    s = status();
    return s && s->contains("master") && s->contains("slave") &&
           (*s)["master"].value("alive", false) && (*s)["slave"].value("alive", false);
  })) << (s ? s->dump(1) : std::string("no status"))
      << logs();
  for (const char* command : {"arm", "engage"}) {
    for (const auto& [endpoint, pub] :
         {std::pair{std::string("192.168.50.10:5562"), std::string("master.pub")},
          std::pair{std::string("192.168.50.20:5563"), std::string("slave.pub")}}) {
      const CliResult r = teleopctl("node " + endpoint + " " + command + console +
                                    " --server-key " + (keys / pub).string());
      ASSERT_EQ(r.exit_code, 0) << endpoint << " " << command << ": " << r.out << logs();
    }
  }
  ASSERT_TRUE(eventually([&] {
    s = status();
    return s && (*s)["master"].value("mode", "") == "ENGAGED" &&
           (*s)["slave"].value("mode", "") == "ENGAGED";
  })) << (s ? s->dump(1) : std::string("no status"))
      << logs();
  // The supervisor records the session in the configured directory and analyses the
  // configuration it runs: stable with the measured round trip.
  EXPECT_EQ((*s)["report"].value("verdict", ""), "stable") << s->dump(1);
  EXPECT_GE((*s)["report"].value("round_trip_samples", 0), 2) << s->dump(1);
  EXPECT_NE(s->value("recording_file", "").find((dir.path() / "sessions").string()),
            std::string::npos)
      << s->dump(1);
  std::cout << "two machines engaged over CURVE: round trip "
            << (*s)["master"]["link"].value("round_trip_ns", "?") << " ns on the master\n";
}

}  // namespace
}  // namespace teleop::test
