// Issue 14, findings 6, 10 and 11 against the real teleop-master and teleop-slave processes:
//  - HostileCoreStall: SIGSTOP a node while engaged, SIGCONT: its first cycle after the gap
//    is SAFE, never ENGAGED on the peer state of before the stall;
//  - HostileCoreClutch: clutch, let the operator move the master, unclutch: the master is not
//    pulled back and the slave stays where it was;
//  - HostileCoreReEngage: examples/live.textproto's physics: engaged, e-stop, clear, arm,
//    engage: ENGAGED again, the alignment error falling in telemetry meanwhile.
// Deadlines come from the nodes' telemetry timestamps; waits are for conditions, bounded only
// against a hang (the SIGSTOP's length is the fault injected, not an assertion).
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <regex>
#include <sstream>

#include "tests/integration/node_harness.hpp"

namespace teleop::test {
namespace {

// The nodes run at SCHED_FIFO 80 as the shipped demo asks (used where the kernel permits):
// these tests are about stalls injected on purpose, not the machine's own load.
std::string paddles(const Ports& p, const std::string& scene, const std::string& slave_extra = "",
                    const std::string& extra = "") {
  return "sample_rate_hz: 1000\n"
         "master { device { mass_kg: 0.040 damping_Ns_per_m: 0.41 } " +
         node_section(p, true, "", 80) +
         " }\n"
         "slave { device { mass_kg: 0.036 damping_Ns_per_m: 0.49 } " +
         slave_extra + " " + node_section(p, false, "", 80) +
         " }\n"
         "gains { kpm: 600 kps: 600 kdm: 2 kds: 2 }\n"
         "velocity_filter { cutoff_hz: 200 }\n"
         "human { fixed { mass_kg: 0.012 damping_Ns_per_m: 0.76 stiffness_N_per_m: 70 } }\n" +
         scene + "link { engage_ramp_ms: 20 }\n" + extra;
}

class Pair {
 public:
  Pair(const TempDir& dir, const std::string& text) : dir_(dir) {
    config_ = dir.write("system.textproto", text);
  }
  void start() {
    master_ = std::make_unique<Process>(MASTER_BIN, std::vector<std::string>{config_.string()},
                                        dir_.path() / "master.log");
    slave_ = std::make_unique<Process>(SLAVE_BIN, std::vector<std::string>{config_.string()},
                                       dir_.path() / "slave.log");
  }
  Process& master() { return *master_; }
  Process& slave() { return *slave_; }

 private:
  const TempDir& dir_;
  std::filesystem::path config_;
  std::unique_ptr<Process> master_;
  std::unique_ptr<Process> slave_;
};

void command(zmq::context_t& ctx, int port, v1::NodeCommand::Kind kind) {
  const auto r = send_command(ctx, tcp(port), kind);
  ASSERT_TRUE(r.has_value()) << "no reply from " << port;
  ASSERT_TRUE(r->ok()) << r->message();
}

void both(zmq::context_t& ctx, const Ports& p, v1::NodeCommand::Kind kind) {
  ASSERT_NO_FATAL_FAILURE(command(ctx, p.master_command, kind));
  ASSERT_NO_FATAL_FAILURE(command(ctx, p.slave_command, kind));
}

void start_and_engage(Pair& pair, zmq::context_t& ctx, const Ports& p, const TelemetryTap& mt,
                      const TelemetryTap& st) {
  pair.start();
  const auto linked = [](const v1::Telemetry& t) { return t.link().accepted() > 0; };
  ASSERT_TRUE(mt.wait_for(linked)) << pair.master().log();
  ASSERT_TRUE(st.wait_for(linked)) << pair.slave().log();
  ASSERT_NO_FATAL_FAILURE(both(ctx, p, v1::NodeCommand::ARM));
  ASSERT_NO_FATAL_FAILURE(both(ctx, p, v1::NodeCommand::ENGAGE));
  ASSERT_TRUE(mt.wait_for_mode(v1::ENGAGED)) << pair.master().log();
  ASSERT_TRUE(st.wait_for_mode(v1::ENGAGED)) << pair.slave().log();
}

// Waits until the tap holds a cycle newer than `t_ns` by `span_ns`.
bool cycles_until(const TelemetryTap& tap, std::int64_t t_ns, std::int64_t span_ns = 0) {
  return tap.wait_for([&](const v1::Telemetry&) {
    const auto c = tap.cycles();
    return !c.empty() && c.back().sample_time_ns() >= t_ns + span_ns;
  });
}

// ---- Finding 6 -------------------------------------------------------------------------------

struct StallCase {
  bool stop_master;
  int stall_ms;
};

class HostileCoreStall : public ::testing::TestWithParam<StallCase> {};

TEST_P(HostileCoreStall, TheFirstCycleAfterTheGapIsSafeNeverEngagedOnStaleData) {
  const StallCase k = GetParam();
  TempDir dir;
  Ports ports;
  // Pushing 1 N into tissue 1 mm ahead of the slave: the master's command is ~1 N engaged.
  Pair pair(dir, paddles(ports,
                         "scene { duration_s: 30 seed: 1 human_force { constant { force_N: 1 } } "
                         "environment { tissue { stiffness_N_per_m: 500 damping_Ns_per_m: 1 "
                         "position_m: 0.001 } } }\n"));
  zmq::context_t ctx(1);
  TelemetryTap mt(ctx, tcp(ports.master_telemetry));
  TelemetryTap st(ctx, tcp(ports.slave_telemetry));
  ASSERT_NO_FATAL_FAILURE(start_and_engage(pair, ctx, ports, mt, st));
  TelemetryTap& stalled_tap = k.stop_master ? mt : st;
  TelemetryTap& other_tap = k.stop_master ? st : mt;
  Process& stalled = k.stop_master ? pair.master() : pair.slave();
  // Settled engaged for 300 ms of the node's own cycles.
  const std::int64_t engaged_at = stalled_tap.cycles().back().sample_time_ns();
  ASSERT_TRUE(cycles_until(stalled_tap, engaged_at, 300'000'000));
  ASSERT_EQ(stalled_tap.cycles().back().mode(), v1::ENGAGED)
      << " (" << stalled_tap.last()->mode_reason() << ", x "
      << stalled_tap.cycles().back().position_m() << " m, v "
      << stalled_tap.cycles().back().velocity_m_per_s() << ", F "
      << stalled_tap.cycles().back().command_n() << " N)";

  HostTiming::instance().injecting(true);  // the stall is this test's
  stalled.signal(SIGSTOP);
  std::this_thread::sleep_for(std::chrono::milliseconds(k.stall_ms));  // the stall injected
  stalled.signal(SIGCONT);
  // The stalled node's cycles resume; take 100 ms of them.
  ASSERT_TRUE(stalled_tap.wait_for([&](const v1::Telemetry&) {
    const auto c = stalled_tap.cycles();
    for (std::size_t i = 0; i < c.size(); ++i) {
      if (c[i].wakeup_latency_ns() > 100'000'000) {
        return c.back().sample_time_ns() >
               c[i].sample_time_ns() + k.stall_ms * 1'000'000LL + 100'000'000;
      }
    }
    return false;
  })) << stalled.log();
  const auto c = stalled_tap.cycles();
  std::size_t gap = 0;
  while (c[gap].wakeup_latency_ns() <= 100'000'000) ++gap;
  const v1::CycleRecord& after = c[gap];
  std::cout << (k.stop_master ? "master" : "slave") << " stopped " << k.stall_ms
            << " ms: first cycle after the gap woke "
            << static_cast<double>(after.wakeup_latency_ns()) / 1e6 << " ms late, mode "
            << v1::NodeMode_Name(after.mode()) << ", command " << after.command_n()
            << " N (before: " << c[gap - 1].command_n() << " N), peer age "
            << static_cast<double>(after.peer_age_ns()) / 1e6 << " ms\n";
  // The stall is the one injected (the wake-up at least most of it late).
  EXPECT_GT(after.wakeup_latency_ns(), (k.stall_ms - 50) * 1'000'000LL);
  EXPECT_EQ(c[gap - 1].mode(), v1::ENGAGED);
  EXPECT_EQ(after.mode(), v1::SAFE);
  // No cycle after the gap is engaged or clutched.
  for (std::size_t i = gap; i < c.size(); ++i) {
    ASSERT_NE(c[i].mode(), v1::ENGAGED) << i - gap;
    ASSERT_NE(c[i].mode(), v1::CLUTCHED) << i - gap;
  }
  // The master's command written in it is the safe ramp's start (the last command, held by
  // the device through the stall, at most), ramping to 0 within safe_ramp (10 ms) + 2 cycles
  // of clock; the slave's is its safe hold (its own spring and damping, no master).
  if (k.stop_master) {
    EXPECT_LE(std::abs(after.command_n()), std::abs(c[gap - 1].command_n()) + 1e-12);
    std::size_t zero = gap;
    while (zero < c.size() && c[zero].command_n() != 0.0) ++zero;
    ASSERT_LT(zero, c.size());
    // On the node's own schedule: the zero cycle's deadline (its wake-up latency is the
    // host's; CI once saw it 0.8 ms late on a cycle whose deadline was on time).
    const std::int64_t clock_gap = after.sample_time_ns() + after.wakeup_latency_ns();
    EXPECT_LE(c[zero].sample_time_ns() - clock_gap, 12'000'000)
        << "zero cycle woke " << c[zero].wakeup_latency_ns() << " ns late";
  }
  const std::optional<v1::Telemetry> last = stalled_tap.last();
  ASSERT_TRUE(last.has_value());
  EXPECT_EQ(last->mode(), v1::SAFE);
  // The other node was not stalled: it went safe on the peer timeout (30 ms after the stalled
  // node's last state), during the stall.
  const auto o = other_tap.cycles();
  const auto safe = std::find_if(o.begin(), o.end(),
                                 [](const v1::CycleRecord& r) { return r.mode() == v1::SAFE; });
  ASSERT_NE(safe, o.end());
  // Its age is on its clock (deadline + wake-up latency); on the deadline it is at most one
  // period past the timeout (the previous cycle's clock was within it).
  EXPECT_GT(safe->peer_age_ns(), 30'000'000);
  EXPECT_LE(safe->peer_age_ns() - safe->wakeup_latency_ns(), 30'000'000 + 2'000'000);
}

INSTANTIATE_TEST_SUITE_P(Stalls, HostileCoreStall,
                         ::testing::Values(StallCase{true, 200}, StallCase{true, 1000},
                                           StallCase{false, 200}),
                         [](const ::testing::TestParamInfo<StallCase>& i) {
                           return std::string(i.param.stop_master ? "Master" : "Slave") +
                                  std::to_string(i.param.stall_ms) + "ms";
                         });

// ---- Host-timing evidence (docs/testing.md "Host stalls") -------------------------------------

// An undisturbed engaged pair leaves no evidence; both nodes stopped together for 100 ms, as a
// virtual machine's host stops its guest, leave the late wake-ups in the nodes' own telemetry;
// and the file scripts/test.sh looks for is named after the test, '/' as '_'.
TEST(HostTimingEvidence, BothNodesStoppedTogetherAreTheHostsStallAndAnUndisturbedPairIsNot) {
  TempDir dir;
  Ports ports;
  Pair pair(dir, paddles(ports, "scene { duration_s: 30 seed: 1 }\n"));
  zmq::context_t ctx(1);
  TelemetryTap mt(ctx, tcp(ports.master_telemetry));
  TelemetryTap st(ctx, tcp(ports.slave_telemetry));
  ASSERT_NO_FATAL_FAILURE(start_and_engage(pair, ctx, ports, mt, st));
  const std::int64_t engaged_at = mt.cycles().back().sample_time_ns();
  ASSERT_TRUE(cycles_until(mt, engaged_at, 300'000'000));
  ASSERT_TRUE(cycles_until(st, st.cycles().back().sample_time_ns(), 50'000'000));
  EXPECT_EQ(HostTiming::instance().evidence(), "");

  pair.master().signal(SIGSTOP);
  pair.slave().signal(SIGSTOP);
  std::this_thread::sleep_for(100ms);  // the stall injected, standing in for the host's
  pair.slave().signal(SIGCONT);
  pair.master().signal(SIGCONT);
  const auto stalled_seen = [](const TelemetryTap& tap) {
    return tap.wait_for([&](const v1::Telemetry&) {
      for (const v1::CycleRecord& c : tap.cycles()) {
        if (c.wakeup_latency_ns() > 50'000'000) return true;
      }
      return false;
    });
  };
  ASSERT_TRUE(stalled_seen(mt));
  ASSERT_TRUE(stalled_seen(st));
  const std::string evidence = HostTiming::instance().evidence();
  std::cout << "evidence: " << evidence << "\n";
  EXPECT_NE(evidence.find(tcp(ports.master_telemetry) + " woke "), std::string::npos) << evidence;
  EXPECT_NE(evidence.find(tcp(ports.slave_telemetry) + " woke "), std::string::npos) << evidence;
  EXPECT_NE(evidence.find("telemetry silent"), std::string::npos) << evidence;

  const std::filesystem::path file =
      write_host_timing_evidence(dir.path() / "host-timing", "Suite/Case.Name/1", evidence);
  EXPECT_EQ(file, dir.path() / "host-timing" / "Suite_Case.Name_1");
  std::ifstream in(file);
  std::string line;
  std::getline(in, line);
  EXPECT_EQ(line, evidence);
  HostTiming::instance().clear();  // the stall was this test's own
}

// ---- Finding 10 ------------------------------------------------------------------------------

// One clutch, move, unclutch run. A host stall past the peer timeout (this VM's hypervisor
// stops both cores for 30 ms and more at times) rightly sends the pair safe in the middle of
// it; the run then says so, with the telemetry's evidence (a wake-up latency or peer age past
// the timeout), and is tried again rather than read as a law that pulled.
struct ClutchRun {
  bool host_stalled{false};
  std::string stall_evidence;
  double slave_worst_m{0.0};
  double force_worst_N{0.0};
  double master_worst_m{0.0};
  std::int64_t worst_at_ns{0};
  std::vector<std::string> left_engaged;  // modes and reasons of cycles that were not ENGAGED
};

// The largest wake-up latency or peer age in `c` past `from_ns`, with what it was.
std::pair<std::int64_t, std::string> worst_stall(const std::vector<v1::CycleRecord>& c,
                                                 std::int64_t from_ns, const char* node) {
  std::pair<std::int64_t, std::string> worst{0, ""};
  for (const v1::CycleRecord& r : c) {
    if (r.sample_time_ns() < from_ns) continue;
    for (const auto& [v, what] :
         {std::pair<std::int64_t, const char*>{r.wakeup_latency_ns(), "wake-up latency"},
          {r.peer_age_ns(), "peer age"}}) {
      if (v > worst.first) {
        worst = {v, std::string(node) + " " + what + " " + std::to_string(v / 1'000'000) + " ms"};
      }
    }
  }
  return worst;
}

void clutch_run(ClutchRun& out) {
  TempDir dir;
  Ports ports;
  // The operator's push: 0 until 1.0 s of scene time (from engagement), then up to 1 N over
  // 0.3 s. Clutched before it, the free master moves to the hand's equilibrium
  // d = 1 N / 70 N/m = 14.3 mm (K_vm = 0: nothing else acts on it) while the slave holds.
  Pair pair(dir, paddles(ports,
                         "scene { duration_s: 30 seed: 1 human_force { ramp { from_N: 0 to_N: 1 "
                         "start_s: 1.0 duration_s: 0.3 } } }\n"));
  zmq::context_t ctx(1);
  TelemetryTap mt(ctx, tcp(ports.master_telemetry));
  TelemetryTap st(ctx, tcp(ports.slave_telemetry));
  ASSERT_NO_FATAL_FAILURE(start_and_engage(pair, ctx, ports, mt, st));
  ASSERT_NO_FATAL_FAILURE(command(ctx, ports.master_command, v1::NodeCommand::CLUTCH));
  ASSERT_TRUE(mt.wait_for_mode(v1::CLUTCHED));
  const auto clutched = mt.cycles();
  const std::size_t clutch_at = static_cast<std::size_t>(
      std::find_if(clutched.begin(), clutched.end(),
                   [](const v1::CycleRecord& r) { return r.mode() == v1::CLUTCHED; }) -
      clutched.begin());
  const double master_at_clutch = clutched[clutch_at].position_m();
  ASSERT_LT(std::abs(master_at_clutch), 1e-3) << "the push started before the clutch";
  const double slave_at_clutch = st.cycles().back().position_m();
  constexpr double d = 1.0 / 70.0;
  // The master settles at the hand's equilibrium.
  ASSERT_TRUE(mt.wait_for([&](const v1::Telemetry&) {
    const auto c = mt.cycles();
    return !c.empty() && std::abs(c.back().position_m() - d) < 3e-4 &&
           std::abs(c.back().velocity_m_per_s()) < 2e-3;
  })) << "the master did not reach "
      << d << " (" << mt.last()->mode_reason() << ", x " << mt.cycles().back().position_m()
      << " m, v " << mt.cycles().back().velocity_m_per_s() << ", F "
      << mt.cycles().back().command_n() << " N)";
  ASSERT_NO_FATAL_FAILURE(command(ctx, ports.master_command, v1::NodeCommand::UNCLUTCH));
  ASSERT_TRUE(mt.wait_for_mode(v1::ENGAGED));
  const std::int64_t unclutch_t = mt.cycles().back().sample_time_ns();
  ASSERT_TRUE(cycles_until(mt, unclutch_t, 500'000'000));
  ASSERT_TRUE(cycles_until(st, unclutch_t, 500'000'000));
  const auto m = mt.cycles();
  const auto s = st.cycles();
  // While clutched the slave held where it was.
  for (const v1::CycleRecord& r : s) {
    if (r.sample_time_ns() > clutched[clutch_at].sample_time_ns()) {
      out.slave_worst_m = std::max(out.slave_worst_m, std::abs(r.position_m() - slave_at_clutch));
    }
  }
  for (const v1::CycleRecord& r : m) {
    if (r.sample_time_ns() <= unclutch_t) continue;
    if (std::abs(r.command_n()) > out.force_worst_N) {
      out.worst_at_ns = r.sample_time_ns() - unclutch_t;
    }
    out.force_worst_N = std::max(out.force_worst_N, std::abs(r.command_n()));
    out.master_worst_m = std::max(out.master_worst_m, std::abs(r.position_m() - d));
    if (r.mode() != v1::ENGAGED && out.left_engaged.size() < 3) {
      out.left_engaged.push_back(v1::NodeMode_Name(r.mode()) + " at " +
                                 std::to_string((r.sample_time_ns() - unclutch_t) / 1'000'000) +
                                 " ms");
    }
  }
  // The peer timeout is 30 ms: a wake-up or a peer state that late is the host's, not the law's.
  const std::int64_t from = clutched[clutch_at].sample_time_ns();
  const auto wm = worst_stall(m, from, "master");
  const auto ws = worst_stall(s, from, "slave");
  const auto& w = wm.first >= ws.first ? wm : ws;
  out.host_stalled = w.first > 25'000'000;
  out.stall_evidence = w.second;
}

TEST(HostileCoreClutch, UnclutchAfterTheOperatorMovedTheMasterPullsNothingBack) {
  ClutchRun run;
  for (int attempt = 1; attempt <= 3; ++attempt) {
    run = ClutchRun{};
    ASSERT_NO_FATAL_FAILURE(clutch_run(run));
    if (!run.host_stalled) break;
    std::cout << "attempt " << attempt << ": the host stalled (" << run.stall_evidence
              << "); tried again\n";
  }
  ASSERT_FALSE(run.host_stalled) << "three runs in a row with a host stall: " << run.stall_evidence;
  constexpr double d = 1.0 / 70.0;
  std::cout << "clutch: master moved " << d * 1e3
            << " mm; after unclutch |F| <= " << run.force_worst_N << " N at "
            << static_cast<double>(run.worst_at_ns) / 1e6 << " ms, master within "
            << run.master_worst_m * 1e3 << " mm of where it was, slave within "
            << run.slave_worst_m * 1e3 << " mm\n";
  // Engaged throughout after the unclutch.
  EXPECT_TRUE(run.left_engaged.empty()) << run.left_engaged.front();
  // After unclutch, hand arithmetic: offset = x_m - x_hold absorbed, so x_r - x_s = x_hold -
  // x_s ~ 0 and v ~ 0: the law's force is only its damping terms, ~0 N (not the pull back
  // K_pm d = 8.6 N, limited by the actuator, the issue's -1.45 N on the hand).
  // The old law's pull back is K_pm d = 8.6 N (actuator-limited) and dragged the slave 15.6 mm;
  // what remains is the coupling error the slave's drift while clutched leaves (K_pm * 0.3 mm =
  // 0.18 N measured) plus damping transients of the two loops: both bounded at a tenth of the
  // pull back (force below 0.1 K_pm d, slave within 0.1 d), an order of magnitude.
  constexpr double kpm = 600.0;
  EXPECT_LT(run.slave_worst_m, 0.1 * d);
  EXPECT_LT(run.force_worst_N, 0.1 * kpm * d);
  EXPECT_LT(run.master_worst_m, 1e-3);
}

// ---- Finding 11 ------------------------------------------------------------------------------

// examples/live.textproto with this test's ports in place of its node sections.
std::string live_demo(const Ports& p) {
  std::ifstream in(std::string(TELEOP_SOURCE_DIR) + "/examples/live.textproto");
  std::stringstream ss;
  ss << in.rdbuf();
  std::string text = ss.str();
  const std::regex node_line(R"(\n  node \{[^\n]*\}\n)");
  std::smatch m;
  std::string out;
  for (const bool master : {true, false}) {
    if (!std::regex_search(text, m, node_line)) return "";
    out += m.prefix().str() + "\n  " + node_section(p, master, "", 80) + "\n";
    text = m.suffix().str();
  }
  return out + text;
}

TEST(HostileCoreReEngage, TheShippedDemoReEngagesAfterAnEStopWithTheAlignmentErrorFalling) {
  TempDir dir;
  Ports ports;
  const std::string text = live_demo(ports);
  ASSERT_NE(text.find("human_force { ramp { from_N: 0 to_N: 1.5"), std::string::npos) << text;
  ASSERT_NE(text.find(std::to_string(ports.slave_command)), std::string::npos) << text;
  Pair pair(dir, text);
  zmq::context_t ctx(1);
  TelemetryTap mt(ctx, tcp(ports.master_telemetry));
  TelemetryTap st(ctx, tcp(ports.slave_telemetry));
  ASSERT_NO_FATAL_FAILURE(start_and_engage(pair, ctx, ports, mt, st));
  // The push ramps to 1.5 N by 2.5 s of scene time: wait for it (the slave in the tissue).
  const std::int64_t engaged_t = mt.cycles().back().sample_time_ns();
  ASSERT_TRUE(cycles_until(mt, engaged_t, 2'700'000'000));
  ASSERT_EQ(mt.cycles().back().mode(), v1::ENGAGED)
      << " (" << mt.last()->mode_reason() << ", x " << mt.cycles().back().position_m() << " m, v "
      << mt.cycles().back().velocity_m_per_s() << ", F " << mt.cycles().back().command_n() << " N)";
  ASSERT_NO_FATAL_FAILURE(command(ctx, ports.master_command, v1::NodeCommand::ESTOP));
  ASSERT_TRUE(mt.wait_for_mode(v1::SAFE));
  ASSERT_TRUE(st.wait_for_mode(v1::SAFE));
  // The free master drifts to the hand's equilibrium 1.5 N / 70 N/m = 21 mm.
  ASSERT_TRUE(mt.wait_for([&](const v1::Telemetry&) {
    const auto c = mt.cycles();
    return !c.empty() && c.back().position_m() > 0.018;
  }));
  ASSERT_NO_FATAL_FAILURE(both(ctx, ports, v1::NodeCommand::CLEAR));
  ASSERT_NO_FATAL_FAILURE(both(ctx, ports, v1::NodeCommand::ARM));
  ASSERT_NO_FATAL_FAILURE(both(ctx, ports, v1::NodeCommand::ENGAGE));
  ASSERT_TRUE(mt.wait_for_mode(v1::ALIGNING, 5s));
  // Bound: the 0.5 N-capped guidance lowers the cooperating push at 5/s * 0.5 N = 2.5 N/s,
  // then the gap closes with the time constant (k_h + k_c) / (r k_c) = 100 / 150 s: ~2 s from
  // 17 mm to the 2 mm tolerance (sim_device.hpp); 6 s leaves room for a loaded machine.
  ASSERT_TRUE(mt.wait_for_mode(v1::ENGAGED, 20s)) << "still aligning";
  ASSERT_TRUE(st.wait_for_mode(v1::ENGAGED, 5s));
  const auto c = mt.cycles();
  const std::size_t align = static_cast<std::size_t>(
      std::find_if(std::find_if(c.begin(), c.end(),
                                [](const v1::CycleRecord& r) { return r.mode() == v1::SAFE; }),
                   c.end(), [](const v1::CycleRecord& r) { return r.mode() == v1::ALIGNING; }) -
      c.begin());  // the alignment after the e-stop, not the first engagement's
  ASSERT_LT(align, c.size());
  std::size_t engaged = align;
  while (c[engaged].mode() != v1::ENGAGED) ++engaged;
  const double aligning_s =
      static_cast<double>(c[engaged].sample_time_ns() - c[align].sample_time_ns()) * 1e-9;
  std::cout << "re-engaged " << aligning_s << " s after engage; alignment error "
            << c[align].alignment_error_m() * 1e3 << " mm -> "
            << c[engaged - 1].alignment_error_m() * 1e3 << " mm\n";
  EXPECT_LT(aligning_s, 6.0);
  EXPECT_GT(std::abs(c[align].alignment_error_m()), 0.010);
  EXPECT_LE(std::abs(c[engaged].alignment_error_m()), 0.002);  // coupled within the tolerance
  // Visible and falling: every 200 ms of aligning the error is smaller than 200 ms before.
  double previous = std::abs(c[align].alignment_error_m());
  std::int64_t next_t = c[align].sample_time_ns() + 200'000'000;
  for (std::size_t i = align; i < engaged; ++i) {
    ASSERT_EQ(c[i].mode(), v1::ALIGNING);
    if (c[i].sample_time_ns() >= next_t) {
      EXPECT_LT(std::abs(c[i].alignment_error_m()), previous) << i - align;
      previous = std::abs(c[i].alignment_error_m());
      next_t += 200'000'000;
    }
  }
  // Engaged again and staying so for a second, the slave pressing into the tissue again.
  const std::int64_t t = c.back().sample_time_ns();
  ASSERT_TRUE(cycles_until(mt, t, 1'500'000'000));
  EXPECT_EQ(mt.cycles().back().mode(), v1::ENGAGED);
  EXPECT_EQ(st.cycles().back().mode(), v1::ENGAGED);
  EXPECT_GT(st.cycles().back().position_m(), 0.004);
}

}  // namespace
}  // namespace teleop::test
