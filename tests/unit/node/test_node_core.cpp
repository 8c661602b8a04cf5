// NodeCore, the RT step of a node, with simulated devices and a fake clock: peer states are
// handed over by hand, as the link threads would. Expected values come from the rules
// (timeout, linear safe ramp, centring spring) written out here, not from the code under test.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "common/device/sim_device.hpp"
#include "common/node/node_core.hpp"

namespace teleop::node {
namespace {

using namespace std::chrono_literals;
using transport::Role;

constexpr double kT = 1e-3;

NodeSettings settings(Role role) {
  NodeSettings s;
  s.role = role;
  s.period = 1ms;
  s.law.period_s = kT;
  s.law.gains = Gains{600, 600, 2, 2, 0, 0, 0};
  s.machine.peer_timeout = 30ms;
  s.machine.engage_ramp = 20ms;
  s.safe_ramp = 10ms;
  s.session_id = role == Role::kMaster ? 11 : 22;
  s.config_fingerprint = 0x5eed;  // the same configuration on both sides
  return s;
}

struct Pair {
  explicit Pair(double master_start_m = 0.0, double push_N = 0.0,
                sim::Environment environment = sim::Environment::free_space(),
                const NodeSettings& slave_settings = settings(Role::kSlave))
      : master_dev(master_config(master_start_m, push_N)),
        slave_dev(device::SimDeviceConfig::paddle_slave(environment)),
        master(settings(Role::kMaster), init(master_dev)),
        slave(slave_settings, init(slave_dev)) {}

  static device::SimDeviceConfig master_config(double start_m, double push_N) {
    sim::HumanParams h;
    h.impedance = HumanImpedance{0.012, 0.76, 70.0};
    h.profile = sim::ForceProfile::constant(push_N);
    device::SimDeviceConfig c = device::SimDeviceConfig::paddle_master(h);
    c.initial_position_m = start_m;
    c.quantize_position = false;
    c.hold_scene_until_engaged = true;
    return c;
  }
  static device::SimDevice& init(device::SimDevice& d) {
    EXPECT_TRUE(d.configure().ok());
    EXPECT_TRUE(d.activate().ok());
    return d;
  }

  // One cycle of both at now; each sees the other's state of the previous cycle (arrived
  // 0.3 ms after it was sent) unless that side is silenced.
  void cycle() {
    now += 1ms;
    if (deliver(master_out, master.peer_in(), master_silent)) {
      master_last_arrival_ns = master_out.arrival_ns;
    }
    (void)deliver(slave_out, slave.peer_in(), slave_silent);
    master.step(now);
    slave.step(now);
    (void)master.state_out().read(slave_out.state);
    slave_out.arrival_ns = (now + 300us).count();
    (void)slave.state_out().read(master_out.state);
    master_out.arrival_ns = (now + 300us).count();
    while (auto r = master.telemetry_out().try_pop()) master_records.push_back(*r);
    while (auto r = slave.telemetry_out().try_pop()) slave_records.push_back(*r);
  }
  // `out` holds the state the *other* side sent last cycle, for `in`.
  static bool deliver(const PeerSample& out, rt::LatestValue<PeerSample>& in, bool silent) {
    if (silent || out.state.sequence == 0) return false;
    in.write(out);
    return true;
  }
  void command_both(Command c) {
    ASSERT_TRUE(master.post_command(c));
    ASSERT_TRUE(slave.post_command(c));
    cycle();
  }
  void engage() {
    for (int i = 0; i < 3; ++i) cycle();  // link up
    command_both(Command::kArm);
    command_both(Command::kEngage);
    for (int i = 0;
         i < 2000 && !(master.mode() == Mode::kEngaged && slave.mode() == Mode::kEngaged); ++i) {
      cycle();
    }
    ASSERT_EQ(master.mode(), Mode::kEngaged);
    ASSERT_EQ(slave.mode(), Mode::kEngaged);
  }

  device::SimDevice master_dev;
  device::SimDevice slave_dev;
  NodeCore master;
  NodeCore slave;
  std::chrono::nanoseconds now{1s};
  PeerSample master_out{};                 // what the master receives next (the slave's state)
  PeerSample slave_out{};                  // what the slave receives next (the master's state)
  std::int64_t master_last_arrival_ns{0};  // of the newest state handed to the master
  bool master_silent{false};
  bool slave_silent{false};
  std::vector<CycleRecord> master_records;
  std::vector<CycleRecord> slave_records;
};

TEST(NodeCore, AligningGuidesTheMasterWithTheCentringSpringAndCouplesOnlyWhenAligned) {
  Pair p(0.010);
  for (int i = 0; i < 3; ++i) p.cycle();
  p.command_both(Command::kArm);
  p.command_both(Command::kEngage);
  ASSERT_EQ(p.master.mode(), Mode::kAligning);
  const std::size_t start = p.master_records.size() - 1;
  for (int i = 0; i < 3000 && p.master.mode() != Mode::kEngaged; ++i) p.cycle();
  ASSERT_EQ(p.master.mode(), Mode::kEngaged);
  const AlignmentParams a{};
  bool saw_clamp = false;
  for (std::size_t i = start; i < p.master_records.size(); ++i) {
    const CycleRecord& r = p.master_records[i];
    if (r.mode != Mode::kAligning) continue;
    // F = clamp(-k (x_m - x_s) - b v_m, +-F_max) with alpha = 1.
    const double f = std::clamp(-a.centring_stiffness_N_per_m * (r.position_m - r.peer_position_m) -
                                    a.centring_damping_Ns_per_m * r.velocity_m_per_s,
                                -a.centring_max_force_N, a.centring_max_force_N);
    ASSERT_NEAR(r.command_N, f, 1e-12) << i;
    saw_clamp = saw_clamp || std::abs(f) == a.centring_max_force_N;
  }
  // About 30 N/m * 10 mm = 0.3 N toward the slave: weak, below the 0.5 N clamp.
  EXPECT_LT(p.master_records[start].command_N, -0.2);
  EXPECT_FALSE(saw_clamp);
  // The first engaged cycle is within the tolerance of the slave.
  for (const CycleRecord& r : p.master_records) {
    if (r.mode == Mode::kEngaged) {
      EXPECT_LE(std::abs(r.position_m - r.peer_position_m), a.tolerance_m);
      break;
    }
  }
  // The slave held its place meanwhile (its law's spring, no master to follow).
  EXPECT_LT(std::abs(p.slave_dev.truth().state.position_m), 1e-4);
}

TEST(NodeCore, SilentPeerSafeAfterTheTimeoutAndTheMasterForceRampsLinearlyToZero) {
  // Pushing 1 N into tissue 1 mm ahead of the slave: the master feels the contact.
  Pair p(0.0, 1.0, sim::Environment::tissue(500.0, 1.0, 0.001));
  p.engage();
  for (int i = 0; i < 300; ++i) p.cycle();
  ASSERT_GT(std::abs(p.master_records.back().command_N), 0.05);
  p.master_silent = true;
  for (int i = 0; i < 60; ++i) p.cycle();
  std::size_t safe = 0;
  while (p.master_records[safe].mode != Mode::kSafe) ++safe;
  const CycleRecord& s = p.master_records[safe];
  const std::int64_t last_arrival = p.master_last_arrival_ns;  // the slave's last state
  // Safe at the first cycle whose peer age exceeds 30 ms.
  EXPECT_GT(s.sample_time_ns - last_arrival, 30'000'000);
  EXPECT_LE(p.master_records[safe - 1].sample_time_ns - last_arrival, 30'000'000);
  // F(k) = F0 (1 - k T / 10 ms) from the last engaged force F0, k cycles after entering safe.
  const double f0 = p.master_records[safe - 1].command_N;
  for (int k = 0; k <= 12; ++k) {
    const double expected = f0 * std::max(0.0, 1.0 - k * 1e-3 / 10e-3);
    EXPECT_NEAR(p.master_records[safe + static_cast<std::size_t>(k)].command_N, expected, 1e-12)
        << k;
  }
  EXPECT_EQ(p.master_records[safe + 10].command_N, 0.0);
  // The slave still hears the master, which is safe: it goes safe over the link and holds
  // with damping (its law without a master).
  EXPECT_EQ(p.slave.mode(), Mode::kSafe);
}

TEST(NodeCore, PeerRestartEStopAndDeviceFault) {
  {
    Pair p;
    p.engage();
    // The slave restarts: a new session id in its states.
    p.master_out.state.session_id = 99;
    p.master.peer_in().write(p.master_out);
    p.master_silent = true;  // keep the restarted id as the newest
    p.cycle();
    EXPECT_EQ(p.master.mode(), Mode::kSafe);
    EXPECT_STREQ(p.master.mode_reason(), "peer safe, faulted or restarted");
  }
  {
    Pair p;
    p.engage();
    ASSERT_TRUE(p.slave.post_command(Command::kEStop));
    p.cycle();
    EXPECT_EQ(p.slave.mode(), Mode::kSafe);
    p.cycle();
    p.cycle();
    EXPECT_EQ(p.master.mode(), Mode::kSafe);  // over the link
  }
  {
    Pair p;
    p.engage();
    p.master_dev.set_estop(true);  // the device's own e-stop bit
    p.cycle();
    p.cycle();
    EXPECT_EQ(p.master.mode(), Mode::kFault);
    EXPECT_EQ(p.master_records.back().command_N, 0.0);
    p.master_dev.set_estop(false);
    p.cycle();
    EXPECT_EQ(p.master.mode(), Mode::kFault);  // latched
    ASSERT_TRUE(p.master.post_command(Command::kClear));
    p.cycle();
    EXPECT_EQ(p.master.mode(), Mode::kDisarmed);
  }
}

TEST(NodeCore, EveryCycleIsInTelemetryAndTheRoundTripIsMeasuredFromEchoes) {
  Pair p;
  p.engage();
  for (int i = 0; i < 100; ++i) p.cycle();
  for (std::size_t i = 1; i < p.master_records.size(); ++i) {
    ASSERT_EQ(p.master_records[i].sequence, p.master_records[i - 1].sequence + 1);
    ASSERT_EQ(p.master_records[i].sample_time_ns - p.master_records[i - 1].sample_time_ns,
              1'000'000);
  }
  // Master sends at t, slave receives at t + 0.3 ms and echoes at its next cycle (t + 1 ms,
  // held 0.7 ms), the master receives at t + 1.3 ms: round trip 1.3 - 0.7 = 0.6 ms.
  EXPECT_EQ(p.master_records.back().round_trip_ns, 600'000);
  EXPECT_EQ(p.master.telemetry_out().dropped(), 0u);
}

TEST(NodeCore, AGuardedChangeAppliesAtTheAgreedMasterSequenceOnBothSidesRamped) {
  Pair p;
  p.engage();
  for (int i = 0; i < 50; ++i) p.cycle();
  const std::uint64_t at = p.master_records.back().sequence + 20;
  Retune r;
  r.id = 7;
  r.gains = Gains{300, 300, 1, 1, 0, 0, 0};
  r.slave_fixture = FixtureParams{1000.0, 0.004};
  r.apply_at_master_sequence = at;
  r.ramp = 10ms;
  p.master.post_retune(r);
  p.slave.post_retune(r);
  for (int i = 0; i < 60; ++i) p.cycle();
  auto first_with_id = [](const std::vector<CycleRecord>& recs) {
    for (const CycleRecord& c : recs) {
      if (c.parameter_change_id == 7) return c;
    }
    return CycleRecord{};
  };
  // Both switch when the master's sequence reaches `at` (the slave learns it one link hop
  // later, so at a later cycle of its own, but at the same master sequence).
  EXPECT_EQ(first_with_id(p.master_records).master_sequence, at);
  EXPECT_EQ(first_with_id(p.slave_records).master_sequence, at);
  ActiveLaw a;
  ASSERT_TRUE(p.slave.active_out().read(a));
  EXPECT_EQ(a.change_id, 7u);
  EXPECT_EQ(a.applied_at_master_sequence, at);
  EXPECT_DOUBLE_EQ(a.ramp_progress, 1.0);
  EXPECT_DOUBLE_EQ(a.gains.kps, 300.0);
  EXPECT_DOUBLE_EQ(a.slave_fixture.stiffness_N_per_m, 1000.0);
}

TEST(NodeCore, TheRampIsLinearFromTheValueInForce) {
  Pair p;
  p.engage();
  Retune r;
  r.id = 3;
  r.gains = settings(Role::kSlave).law.gains;
  r.slave_fixture = FixtureParams{1000.0, 0.004};
  r.apply_at_master_sequence = 0;  // at once
  r.ramp = 10ms;
  p.slave.post_retune(r);
  std::vector<double> k;
  for (int i = 0; i < 11; ++i) {
    p.cycle();
    ActiveLaw a;
    ASSERT_TRUE(p.slave.active_out().read(a));
    k.push_back(a.slave_fixture.stiffness_N_per_m);
  }
  // 0 -> 1000 N/m over 10 cycles: 100 N/m per cycle, from the cycle it applied.
  for (int i = 0; i <= 10; ++i) EXPECT_NEAR(k[static_cast<std::size_t>(i)], 100.0 * i, 1e-9) << i;
}

// Issue 16 review: a second change posted while the first one ramps waits for its own agreed
// sequence; the ramp in progress keeps its target. (The node had made the newest change the
// running ramp's target at once: each node switched when its own command thread posted it,
// so master and slave ran different values until the ramp ended.)
TEST(NodeCore, ASecondChangePostedDuringARampWaitsForItsOwnSequence) {
  Pair p;
  p.engage();
  Retune first;
  first.id = 3;
  first.gains = settings(Role::kSlave).law.gains;
  first.slave_fixture = FixtureParams{1000.0, 0.004};
  first.apply_at_master_sequence = 0;  // at once
  first.ramp = 10ms;
  p.slave.post_retune(first);
  std::vector<double> k;
  ActiveLaw a;
  for (int i = 0; i < 5; ++i) {
    p.cycle();
    // Written while a change ramps; the last value holds after.
    ActiveLaw now_in_force;
    if (p.slave.active_out().read(now_in_force)) a = now_in_force;
    k.push_back(a.slave_fixture.stiffness_N_per_m);
  }
  // Half way (400 N/m after the 5th cycle), the second change: 200 N/m, 20 cycles on.
  const std::uint64_t at = p.master_records.back().sequence + 20;
  Retune second = first;
  second.id = 4;
  second.slave_fixture = FixtureParams{200.0, 0.004};
  second.apply_at_master_sequence = at;
  p.slave.post_retune(second);
  for (int i = 0; i < 40; ++i) {
    p.cycle();
    // Written while a change ramps; the last value holds after.
    ActiveLaw now_in_force;
    if (p.slave.active_out().read(now_in_force)) a = now_in_force;
    k.push_back(a.slave_fixture.stiffness_N_per_m);
  }
  // The first ramp goes on to 1000 N/m, 100 N/m per cycle, as if nothing had come.
  for (int i = 0; i <= 10; ++i) EXPECT_NEAR(k[static_cast<std::size_t>(i)], 100.0 * i, 1e-9) << i;
  // Then change 4 from the master sequence `at`, down to 200 N/m over 10 cycles.
  std::uint64_t applied_at = 0;
  for (const CycleRecord& c : p.slave_records) {
    if (c.parameter_change_id == 4) {
      applied_at = c.master_sequence;
      break;
    }
  }
  EXPECT_EQ(applied_at, at);
  EXPECT_EQ(a.change_id, 4u);
  EXPECT_DOUBLE_EQ(a.slave_fixture.stiffness_N_per_m, 200.0);
}

// docs/nodes.md "Before engage" (issue 14 finding 3): arm and engage need the peer's fingerprint,
// equal to this node's, the same parameter change on both, and this node's own check passed.
NodeSettings slave_with(std::uint64_t fingerprint) {
  NodeSettings s = settings(Role::kSlave);
  s.config_fingerprint = fingerprint;
  return s;
}

bool ever_coupled(const std::vector<CycleRecord>& recs) {
  for (const CycleRecord& r : recs) {
    if (r.mode == Mode::kAligning || r.mode == Mode::kEngaged || r.mode == Mode::kClutched ||
        r.mode == Mode::kArmed) {
      return true;
    }
  }
  return false;
}

TEST(NodeCore, APeerWithAnotherFingerprintRefusesArmAndEngageOnBothSides) {
  Pair p(0.0, 0.0, sim::Environment::free_space(), slave_with(0xbad));
  for (int i = 0; i < 3; ++i) p.cycle();
  EXPECT_EQ(p.master.peer_fingerprint(), 0xbadu);
  EXPECT_EQ(p.slave.peer_fingerprint(), 0x5eedu);
  for (int k = 0; k < 5; ++k) {
    p.command_both(Command::kArm);
    p.command_both(Command::kEngage);
    for (int i = 0; i < 20; ++i) p.cycle();
  }
  EXPECT_EQ(p.master.mode(), Mode::kDisarmed);
  EXPECT_EQ(p.slave.mode(), Mode::kDisarmed);
  EXPECT_NE(std::string(p.master.mode_reason()).find("fingerprint differs"), std::string::npos)
      << p.master.mode_reason();
  EXPECT_NE(std::string(p.slave.mode_reason()).find("fingerprint differs"), std::string::npos);
  EXPECT_EQ(p.master.coupling_refusals(), 10u);  // five arms and five engages
  EXPECT_EQ(p.slave.coupling_refusals(), 10u);
  // Never armed, never coupled, no force, in any cycle.
  EXPECT_FALSE(ever_coupled(p.master_records));
  EXPECT_FALSE(ever_coupled(p.slave_records));
  for (const CycleRecord& r : p.master_records) ASSERT_EQ(r.command_N, 0.0);
  for (const CycleRecord& r : p.slave_records) ASSERT_EQ(r.command_N, 0.0);
}

TEST(NodeCore, APeerWithoutFingerprintOrNoPeerAtAllRefusesArm) {
  {
    Pair p;  // nothing delivered yet
    p.master_silent = p.slave_silent = true;
    p.command_both(Command::kArm);
    EXPECT_EQ(p.master.mode(), Mode::kDisarmed);
    EXPECT_NE(std::string(p.master.mode_reason()).find("no state from the peer"), std::string::npos)
        << p.master.mode_reason();
  }
  {
    // An older slave: its states carry no fingerprint (0 on the wire).
    Pair p(0.0, 0.0, sim::Environment::free_space(), slave_with(0));
    for (int i = 0; i < 3; ++i) p.cycle();
    p.command_both(Command::kArm);
    EXPECT_EQ(p.master.mode(), Mode::kDisarmed);
    EXPECT_NE(std::string(p.master.mode_reason()).find("sends no configuration fingerprint"),
              std::string::npos)
        << p.master.mode_reason();
  }
}

TEST(NodeCore, AFailedOwnCheckRefusesArmWithItsReason) {
  NodeSettings s = settings(Role::kSlave);
  s.permits_coupling = false;
  s.coupling_refusal = "arm and engage refused: the analysis says unstable (zeta -0.0123)";
  Pair p(0.0, 0.0, sim::Environment::free_space(), s);
  for (int i = 0; i < 3; ++i) p.cycle();
  p.command_both(Command::kArm);
  EXPECT_EQ(p.master.mode(), Mode::kArmed);  // the master's own check passed
  EXPECT_EQ(p.slave.mode(), Mode::kDisarmed);
  EXPECT_STREQ(p.slave.mode_reason(), s.coupling_refusal.c_str());
}

TEST(NodeCore, AnotherParameterChangeOnThePeerRefusesEngageButAnAgreedOneDoesNot) {
  Pair p;
  p.engage();
  for (int i = 0; i < 50; ++i) p.cycle();
  // A change on the master only (not what the supervisor does): both still engaged (the check
  // is at arm and engage), but once disengaged neither engages again.
  Retune r;
  r.id = 4;
  r.gains = Gains{500, 500, 2, 2, 0, 0, 0};
  r.apply_at_master_sequence = p.master_records.back().sequence + 5;
  p.master.post_retune(r);
  for (int i = 0; i < 30; ++i) p.cycle();
  EXPECT_EQ(p.master.mode(), Mode::kEngaged);
  p.command_both(Command::kDisengage);
  ASSERT_EQ(p.master.mode(), Mode::kArmed);
  p.command_both(Command::kEngage);
  for (int i = 0; i < 50; ++i) p.cycle();
  EXPECT_EQ(p.master.mode(), Mode::kArmed);
  EXPECT_EQ(p.slave.mode(), Mode::kArmed);
  EXPECT_NE(std::string(p.master.mode_reason()).find("another parameter change"), std::string::npos)
      << p.master.mode_reason();
  // The same change on the slave (as the supervisor sends it to both): engages again.
  p.slave.post_retune(r);
  for (int i = 0; i < 5; ++i) p.cycle();
  p.command_both(Command::kEngage);
  for (int i = 0; i < 2000 && p.master.mode() != Mode::kEngaged; ++i) p.cycle();
  EXPECT_EQ(p.master.mode(), Mode::kEngaged);
}

TEST(NodeCore, AGuardedChangeOnBothWhileEngagedNeverTripsTheCheck) {
  Pair p;
  p.engage();
  Retune r;
  r.id = 1;
  r.gains = Gains{400, 400, 2, 2, 0, 0, 0};
  r.apply_at_master_sequence = p.master_records.back().sequence + 20;
  r.ramp = 10ms;
  p.master.post_retune(r);
  p.slave.post_retune(r);
  for (int i = 0; i < 100; ++i) p.cycle();
  EXPECT_EQ(p.master.mode(), Mode::kEngaged);
  EXPECT_EQ(p.slave.mode(), Mode::kEngaged);
  // Disengage and engage again under the change: permitted.
  p.command_both(Command::kDisengage);
  p.command_both(Command::kEngage);
  for (int i = 0; i < 2000 && p.master.mode() != Mode::kEngaged; ++i) p.cycle();
  EXPECT_EQ(p.master.mode(), Mode::kEngaged);
  EXPECT_EQ(p.master.coupling_refusals(), 0u);
  EXPECT_EQ(p.slave.coupling_refusals(), 0u);
}

}  // namespace
}  // namespace teleop::node
