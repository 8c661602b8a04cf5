// Guarded parameter changes of a three-axis teleoperator with the real processes (issue 18, the
// supervisor's guard per plane; docs/supervisor.md "The supervisor with several axes"):
// `teleopctl set slave.planes[1].stiffness_N_per_m=500` through teleop-supervisor reaches both
// nodes, ramps in (seen in both nodes' own telemetry, ActiveParameters), and the slave settles
// at the penetration solved by hand for the softer wall; a RETUNE straight to a node from an
// identity that is not the supervisor's is refused and changes nothing. Every wait is for a
// condition in the nodes' telemetry, bounded only against a hang.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <csignal>
#include <memory>
#include <optional>
#include <regex>
#include <string>
#include <vector>

#include "tests/integration/cartesian3_harness.hpp"
#include "tests/integration/cli_harness.hpp"
#include "tests/integration/node_harness.hpp"

namespace teleop::test {
namespace {

// cartesian3 (tilted wall n = (1, 1, 0) / sqrt(2), K = 1000 N/m at p = 0.02 m) with the human
// pushing 10 N along n from 0.8 s after engagement; `extra`: the supervisor and security.
std::string system_text(const Ports& p, const std::string& extra) {
  return cartesian3_system(p,
                           "scene { duration_s: 60 human_force { trace { time_s: [0, 0.3, 0.8] "
                           "force_N: [0, 0, 10] } } human_force_direction: [1, 1, 0] }",
                           "link { engage_ramp_ms: 20 }\n" + extra);
}

// The supervisor on `report` and `request`, not recording, with a `ramp_ms` change ramp, and the
// nodes taking its plaintext RETUNEs.
std::string supervised(int report, int request, int ramp_ms) {
  return "supervisor { report_endpoint: \"" + tcp(report) + "\" request_endpoint: \"" +
         tcp(request) + "\" record: false change_ramp_ms: " + std::to_string(ramp_ms) +
         " }\nsecurity { allow_unauthenticated_retune: true }\n";
}

// The slave's penetration into the wall along n at rest, by hand (test_nodes_axes.cpp's
// derivation): (k_h + k_c) x_m - k_c x_s = F and -k_c x_m + (k_c + K) x_s = K p, so
// x_s = (k_c F + (k_h + k_c) K p) / ((k_h + k_c)(k_c + K) - k_c^2), penetration x_s - p.
double penetration_by_hand(double K) {
  const double k_h = 70.0;
  const double k_c = 600.0;
  const double p = 0.02;
  const double F = 10.0;
  return (k_c * F + (k_h + k_c) * K * p) / ((k_h + k_c) * (k_c + K) - k_c * k_c) - p;
}

// The mean penetration of the slave's engaged cycles with master sequence in [from, to).
double mean_penetration(const std::vector<v1::CycleRecord>& cycles, std::uint64_t from,
                        std::uint64_t to, long& count) {
  double sum = 0.0;
  count = 0;
  for (const v1::CycleRecord& c : cycles) {
    if (c.master_sequence() < from || c.master_sequence() >= to || c.mode() != v1::ENGAGED) {
      continue;
    }
    sum += c.fixture_penetration_m();
    ++count;
  }
  return count == 0 ? 0.0 : sum / static_cast<double>(count);
}

std::uint64_t newest_master_sequence(const TelemetryTap& tap) {
  const auto t = tap.last();
  return t && t->cycles_size() > 0 ? t->cycles(t->cycles_size() - 1).master_sequence() : 0;
}

bool linked(const v1::Telemetry& t) { return t.link().accepted() > 0; }

void arm_and_engage(zmq::context_t& ctx, const Ports& p) {
  for (const auto kind : {v1::NodeCommand::ARM, v1::NodeCommand::ENGAGE}) {
    for (const int port : {p.master_command, p.slave_command}) {
      const auto r = send_command(ctx, tcp(port), kind);
      ASSERT_TRUE(r.has_value()) << "no reply from " << port;
      ASSERT_TRUE(r->ok()) << r->message();
    }
  }
}

TEST(RetuneAxes, TeleopctlSetSoftensATiltedPlaneOnBothNodesRampedAndThePenetrationMoves) {
  TempDir dir;
  Ports ports;
  const int report = free_port();
  const int request = free_port();
  const auto config =
      dir.write("cartesian3.textproto", system_text(ports, supervised(report, request, 400)));
  zmq::context_t ctx(1);
  TelemetryTap mt(ctx, tcp(ports.master_telemetry));
  TelemetryTap st(ctx, tcp(ports.slave_telemetry));
  Process supervisor(SUPERVISOR_BIN, {config.string()}, dir.path() / "supervisor.log");
  Process master(MASTER_BIN, {config.string()}, dir.path() / "master.log");
  Process slave(SLAVE_BIN, {config.string()}, dir.path() / "slave.log");
  auto logs = [&] {
    return "--- master\n" + master.log() + "--- slave\n" + slave.log() + "--- supervisor\n" +
           supervisor.log();
  };
  ASSERT_TRUE(mt.wait_for(linked)) << logs();
  ASSERT_TRUE(st.wait_for(linked)) << logs();
  ASSERT_NO_FATAL_FAILURE(arm_and_engage(ctx, ports));
  ASSERT_TRUE(st.wait_for_mode(v1::ENGAGED)) << logs();
  // The file's values in force on both nodes: change 0, the tilted wall (plane 1) at 1000 N/m.
  for (const TelemetryTap* tap : {&mt, &st}) {
    ASSERT_TRUE(tap->wait_for([](const v1::Telemetry& t) {
      return t.active().axes() == 3 && t.active().slave_plane_stiffness_n_per_m_size() == 2;
    })) << logs();
    EXPECT_EQ(tap->last()->active().change_id(), 0U);
    EXPECT_EQ(tap->last()->active().slave_plane_stiffness_n_per_m(1), 1000.0);
  }
  // Settled into the wall at 1000 N/m (3 s after engagement).
  const std::uint64_t s0 = newest_master_sequence(st);
  ASSERT_TRUE(
      st.wait_for([&](const v1::Telemetry&) { return newest_master_sequence(st) > s0 + 3000; },
                  std::chrono::seconds(60)))
      << logs();
  long n_before = 0;
  const double before = mean_penetration(st.cycles(), s0 + 2500, s0 + 3000, n_before);
  ASSERT_GT(n_before, 100) << logs();
  EXPECT_NEAR(before, penetration_by_hand(1000.0), 0.05 * penetration_by_hand(1000.0));

  const CliResult set = teleopctl("set slave.planes[1].stiffness_N_per_m=500 --supervisor " +
                                  tcp(request) + " --timeout-ms 5000");
  ASSERT_EQ(set.exit_code, 0) << set.out << logs();
  EXPECT_NE(set.out.find("accepted"), std::string::npos) << set.out;
  // Both nodes run change 1 with the wall at 500 N/m once the ramp is over, and on the way
  // each value lies on the straight line from 1000 to 500 at the ramp's progress.
  std::vector<std::pair<double, double>> ramp;  // (progress, stiffness) seen mid-ramp
  for (const TelemetryTap* tap : {&mt, &st}) {
    ASSERT_TRUE(tap->wait_for(
        [&](const v1::Telemetry& t) {
          const v1::ActiveParameters& a = t.active();
          if (a.change_id() == 1 && a.ramp_progress() > 0.0 && a.ramp_progress() < 1.0 &&
              a.slave_plane_stiffness_n_per_m_size() == 2) {
            ramp.emplace_back(a.ramp_progress(), a.slave_plane_stiffness_n_per_m(1));
          }
          return a.change_id() == 1 && a.ramp_progress() == 1.0;
        },
        std::chrono::seconds(30)))
        << logs();
    const std::optional<v1::Telemetry> last = tap->last();
    ASSERT_TRUE(last.has_value());
    const v1::ActiveParameters& a = last->active();
    EXPECT_EQ(a.slave_plane_stiffness_n_per_m(1), 500.0);
    EXPECT_EQ(a.slave_plane_stiffness_n_per_m(0), 1500.0);  // the floor as it was
  }
  EXPECT_FALSE(ramp.empty()) << "no telemetry message during the 400 ms ramp";
  for (const auto& [progress, k] : ramp) EXPECT_NEAR(k, 1000.0 - 500.0 * progress, 1e-9);
  // Settled again (2 s on): deeper into the softer wall, as solved by hand.
  const std::uint64_t s1 = newest_master_sequence(st);
  ASSERT_TRUE(
      st.wait_for([&](const v1::Telemetry&) { return newest_master_sequence(st) > s1 + 2500; },
                  std::chrono::seconds(60)))
      << logs();
  long n_after = 0;
  const double after = mean_penetration(st.cycles(), s1 + 2000, s1 + 2500, n_after);
  ASSERT_GT(n_after, 100) << logs();
  EXPECT_NEAR(after, penetration_by_hand(500.0), 0.05 * penetration_by_hand(500.0));
  EXPECT_GT(penetration_by_hand(500.0) - penetration_by_hand(1000.0), 0.005);  // 6.4 mm deeper
  // The supervisor approved what the nodes run: both engaged throughout, no e-stop.
  EXPECT_EQ(mt.last()->mode(), v1::ENGAGED) << logs();
  EXPECT_EQ(st.last()->mode(), v1::ENGAGED) << logs();
}

// Plaintext without security.allow_unauthenticated_retune: a well-formed three-axis RETUNE
// (the wall at 9000 N/m) straight to each node is refused as not the supervisor's, and the
// file's values stay in force past its apply point.
TEST(RetuneAxes, AnNAxisRetuneFromAnotherIdentityIsRefusedAndNothingChanges) {
  TempDir dir;
  Ports ports;
  const auto config = dir.write("cartesian3.textproto", system_text(ports, ""));
  zmq::context_t ctx(1);
  TelemetryTap mt(ctx, tcp(ports.master_telemetry));
  TelemetryTap st(ctx, tcp(ports.slave_telemetry));
  Process master(MASTER_BIN, {config.string()}, dir.path() / "master.log");
  Process slave(SLAVE_BIN, {config.string()}, dir.path() / "slave.log");
  ASSERT_TRUE(mt.wait_for(linked)) << master.log();
  ASSERT_TRUE(st.wait_for(linked)) << slave.log();
  ASSERT_NO_FATAL_FAILURE(arm_and_engage(ctx, ports));
  ASSERT_TRUE(st.wait_for_mode(v1::ENGAGED)) << slave.log();
  const std::uint64_t at = newest_master_sequence(st) + 50;
  v1::NodeCommand c;
  c.set_kind(v1::NodeCommand::RETUNE);
  v1::ParameterUpdate& u = *c.mutable_update();
  u.set_change_id(1);
  u.set_axes(3);
  for (int i = 0; i < 9; ++i) {
    const double d = i % 4 == 0 ? 1.0 : 0.0;
    u.mutable_gains()->add_kpm_matrix(600.0 * d);
    u.mutable_gains()->add_kps_matrix(600.0 * d);
  }
  u.add_slave_plane_stiffness_n_per_m(1500.0);
  u.add_slave_plane_stiffness_n_per_m(9000.0);
  u.set_apply_at_master_sequence(at);
  for (const int port : {ports.master_command, ports.slave_command}) {
    const auto r = send_command(ctx, tcp(port), c);
    ASSERT_TRUE(r.has_value()) << port;
    EXPECT_FALSE(r->ok()) << r->message();
    EXPECT_TRUE(r->refused_unauthorized()) << r->message();
  }
  for (const TelemetryTap* tap : {&mt, &st}) {
    ASSERT_TRUE(tap->wait_for([&](const v1::Telemetry&) {
      return newest_master_sequence(*tap) > at + 100;
    })) << master.log()
        << slave.log();
    const std::optional<v1::Telemetry> last = tap->last();
    ASSERT_TRUE(last.has_value());
    const v1::ActiveParameters& a = last->active();
    EXPECT_EQ(a.change_id(), 0U);
    ASSERT_EQ(a.slave_plane_stiffness_n_per_m_size(), 2);
    EXPECT_EQ(a.slave_plane_stiffness_n_per_m(1), 1000.0);
    for (const v1::CycleRecord& cyc : tap->cycles()) ASSERT_EQ(cyc.parameter_change_id(), 0U);
  }
}

// A supervisor killed (kill -9) after a guarded change and started again on the running nodes
// adopts the change in force, as for one axis: the nodes stay engaged (no e-stop in their own
// cycles from the restart on), its log says change 1 was adopted, and the next `teleopctl set`
// is change 2.
TEST(RetuneAxes, ASupervisorRestartedAfterAChangeAdoptsItAndTheNodesStayEngaged) {
  TempDir dir;
  Ports ports;
  const int report = free_port();
  const int request = free_port();
  const auto config =
      dir.write("cartesian3.textproto", system_text(ports, supervised(report, request, 50)));
  zmq::context_t ctx(1);
  TelemetryTap mt(ctx, tcp(ports.master_telemetry));
  TelemetryTap st(ctx, tcp(ports.slave_telemetry));
  auto first = std::make_unique<Process>(SUPERVISOR_BIN, std::vector<std::string>{config.string()},
                                         dir.path() / "supervisor1.log");
  Process master(MASTER_BIN, {config.string()}, dir.path() / "master.log");
  Process slave(SLAVE_BIN, {config.string()}, dir.path() / "slave.log");
  std::unique_ptr<Process> second;
  auto logs = [&] {
    return "--- master\n" + master.log() + "--- slave\n" + slave.log() + "--- supervisor\n" +
           first->log() + "--- restarted supervisor\n" + (second ? second->log() : "");
  };
  ASSERT_TRUE(mt.wait_for(linked)) << logs();
  ASSERT_TRUE(st.wait_for(linked)) << logs();
  ASSERT_NO_FATAL_FAILURE(arm_and_engage(ctx, ports));
  ASSERT_TRUE(st.wait_for_mode(v1::ENGAGED)) << logs();
  const CliResult set = teleopctl("set slave.planes[1].stiffness_N_per_m=500 --supervisor " +
                                  tcp(request) + " --timeout-ms 5000");
  ASSERT_EQ(set.exit_code, 0) << set.out << logs();
  for (const TelemetryTap* tap : {&mt, &st}) {
    ASSERT_TRUE(tap->wait_for(
        [](const v1::Telemetry& t) {
          return t.active().change_id() == 1 && t.active().ramp_progress() == 1.0;
        },
        std::chrono::seconds(30)))
        << logs();
  }
  first->signal(SIGKILL);
  (void)first->wait();
  const std::size_t m0 = mt.cycles().size();
  const std::size_t s0 = st.cycles().size();
  second = std::make_unique<Process>(SUPERVISOR_BIN, std::vector<std::string>{config.string()},
                                     dir.path() / "supervisor2.log");
  ASSERT_TRUE(eventually([&] {
    const auto status = supervisor_status(ctx, request);
    return status && status->master_alive() && status->slave_alive();
  })) << logs();
  const std::uint64_t s1 = newest_master_sequence(st);
  ASSERT_TRUE(st.wait_for([&](const v1::Telemetry&) {
    return newest_master_sequence(st) > s1 + 300;
  })) << logs();
  EXPECT_NE(second->log().find("change 1 in force, adopted"), std::string::npos) << logs();
  EXPECT_EQ(second->log().find("unapproved"), std::string::npos) << logs();
  for (const auto& [tap, from] : {std::pair{&mt, m0}, std::pair{&st, s0}}) {
    const std::vector<v1::CycleRecord> cycles = tap->cycles();
    for (std::size_t i = from; i < cycles.size(); ++i) {
      ASSERT_EQ(cycles[i].mode(), v1::ENGAGED) << "cycle " << cycles[i].sequence() << logs();
    }
  }
  const CliResult again = teleopctl("set slave.planes[1].stiffness_N_per_m=600 --supervisor " +
                                    tcp(request) + " --timeout-ms 5000");
  ASSERT_EQ(again.exit_code, 0) << again.out << logs();
  for (const TelemetryTap* tap : {&mt, &st}) {
    ASSERT_TRUE(tap->wait_for(
        [](const v1::Telemetry& t) {
          return t.active().change_id() == 2 && t.active().ramp_progress() == 1.0 &&
                 t.active().slave_plane_stiffness_n_per_m_size() == 2 &&
                 t.active().slave_plane_stiffness_n_per_m(1) == 600.0;
        },
        std::chrono::seconds(30)))
        << logs();
  }
}

// The n-axis escalation ladder live: scene 3b of the papers' paddles on every axis (500 Hz, a
// slave plane along z at 4000 N/m, the human ramping a 2 N push into it along z), the round trip
// pinned at 3 samples, where the plane's limit is 896 N/m (`teleopctl analyze` of the one-axis
// scene: the isotropic reduction). The nodes run it as the experiment it is; the wall buzzes.
// The supervisor's oscillation monitor (it sees about 30 Hz, 2 mm along z) lowers the plane by
// a guarded change to half its limit (448 N/m) that both nodes run; then the buzz stops (2e-8 mm
// peak-to-peak here), or both nodes are disengaged. A host
// whose measured round trip outgrows the pinned 3 samples first makes the model itself miss
// its requirement: then both nodes are disengaged at once, also a right answer.
TEST(RetuneAxes, ABuzzingPlaneIsLoweredByTheLadderOnBothNodesAndTheBuzzStopsOrTheyDisengage) {
  TempDir dir;
  Ports ports;
  const int report = free_port();
  const int request = free_port();
  const std::string config_text =
      "sample_rate_hz: 500\n"
      "axes: 3\n"
      "round_trip_delay_samples: 3\n"
      "master { device { mass_kg: 0.040 damping_Ns_per_m: 0.41 } " +
      node_section(ports, true) +
      " }\n"
      "slave { device { mass_kg: 0.036 damping_Ns_per_m: 0.49 } "
      "fixture { plane { normal: [0, 0, 1] offset_m: 0.005 stiffness_N_per_m: 4000 } } " +
      node_section(ports, false) +
      " }\n"
      "gains { kpm: 600 kps: 600 kdm: 2 kds: 2 }\n"
      "velocity_filter { cutoff_hz: 200 }\n"
      "human { fixed { mass_kg: 0.012 damping_Ns_per_m: 0.76 stiffness_N_per_m: 70 } }\n"
      "scene { duration_s: 60 human_force { ramp { from_N: 0 to_N: 2 start_s: 0.2 "
      "duration_s: 0.5 } } human_force_direction: [0, 0, 1] }\n"
      "link { engage_ramp_ms: 20 }\n"
      "experiment { allow_unstable: true }\n" +
      supervised(report, request, 200);
  const auto config = dir.write("buzz3.textproto", config_text);
  zmq::context_t ctx(1);
  TelemetryTap mt(ctx, tcp(ports.master_telemetry));
  TelemetryTap st(ctx, tcp(ports.slave_telemetry));
  Process supervisor(SUPERVISOR_BIN, {config.string()}, dir.path() / "supervisor.log");
  Process master(MASTER_BIN, {config.string()}, dir.path() / "master.log");
  Process slave(SLAVE_BIN, {config.string()}, dir.path() / "slave.log");
  auto logs = [&] {
    return "--- master\n" + master.log() + "--- slave\n" + slave.log() + "--- supervisor\n" +
           supervisor.log();
  };
  ASSERT_TRUE(mt.wait_for(linked)) << logs();
  ASSERT_TRUE(st.wait_for(linked)) << logs();
  ASSERT_TRUE(eventually([&] {
    const auto status = supervisor_status(ctx, request);
    return status && status->master_alive() && status->slave_alive();
  })) << logs();
  ASSERT_NO_FATAL_FAILURE(arm_and_engage(ctx, ports));
  ASSERT_TRUE(st.wait_for_mode(v1::ENGAGED)) << logs();
  // The supervisor's first action on it: the ladder's lowering, or the round-trip guard's
  // disengagement.
  std::optional<v1::Alarm> acted;
  ASSERT_TRUE(eventually(
      [&] {
        const auto status = supervisor_status(ctx, request);
        if (!status) return false;
        for (const v1::Alarm& a : status->recent_alarms()) {
          if ((a.severity() == v1::Alarm::ACTION && a.kind() == "oscillation") ||
              (a.severity() == v1::Alarm::CRITICAL && a.kind() == "round_trip")) {
            acted = a;
          }
        }
        return acted.has_value();
      },
      std::chrono::seconds(30)))
      << logs();
  std::cout << acted->kind() << ": " << acted->message() << " -> " << acted->action() << "\n";
  if (acted->kind() == "round_trip") {
    EXPECT_NE(acted->action().find("disengaged both nodes"), std::string::npos) << logs();
    for (const TelemetryTap* tap : {&mt, &st}) {
      EXPECT_TRUE(tap->wait_for([](const v1::Telemetry& t) { return t.mode() != v1::ENGAGED; }))
          << logs();
    }
    return;
  }
  // Either side may see it first (the coupled loop oscillates as a whole), along z.
  EXPECT_TRUE(acted->side() == "slave" || acted->side() == "master") << acted->side();
  EXPECT_NE(acted->message().find(acted->side() + " axis 2: oscillation"), std::string::npos)
      << acted->message();
  std::smatch m;
  ASSERT_TRUE(
      std::regex_search(acted->action(), m, std::regex(R"(slave plane 0 4000 -> (\d+) N/m)")))
      << acted->action();
  const double lowered = std::stod(m[1]);
  EXPECT_LE(lowered, 0.5 * 896.1);  // half the plane's limit at 3 samples
  EXPECT_GT(lowered, 0.0);
  // Both nodes run the lowered plane (change 1, ramped in), unless the ladder's next step
  // disengaged them first.
  for (const TelemetryTap* tap : {&mt, &st}) {
    ASSERT_TRUE(tap->wait_for(
        [&](const v1::Telemetry& t) {
          return (t.active().change_id() == 1 && t.active().ramp_progress() == 1.0 &&
                  t.active().slave_plane_stiffness_n_per_m_size() == 1 &&
                  std::abs(t.active().slave_plane_stiffness_n_per_m(0) - lowered) < 1.0) ||
                 t.mode() == v1::ARMED;
        },
        std::chrono::seconds(30)))
        << logs();
  }
  // Then 1.5 s more of the slave's own cycles: still engaged with the plane quiet (the z
  // position's peak-to-peak over the last 0.5 s under 0.1 mm), or disengaged.
  const std::uint64_t s0 = newest_master_sequence(st);
  ASSERT_TRUE(st.wait_for([&](const v1::Telemetry&) {
    return newest_master_sequence(st) > s0 + 750;
  })) << logs();
  const std::vector<v1::CycleRecord> cycles = st.cycles();
  double lo = 1e9;
  double hi = -1e9;
  bool engaged = true;
  for (const v1::CycleRecord& c : cycles) {
    if (c.master_sequence() <= s0 + 500) continue;
    engaged = engaged && c.mode() == v1::ENGAGED;
    if (c.positions_m_size() == 3) {
      lo = std::min(lo, c.positions_m(2));
      hi = std::max(hi, c.positions_m(2));
    }
  }
  std::cout << "lowered to " << lowered << " N/m; then " << (engaged ? "engaged" : "disengaged")
            << ", z peak-to-peak " << (hi - lo) * 1e3 << " mm\n";
  if (engaged) {
    EXPECT_LT(hi - lo, 1e-4) << logs();
  }
}

}  // namespace
}  // namespace teleop::test
