// NodeCore under the issue-14 findings 6, 10 and 11 (the node core), with a fake clock:
//  - a stall: the cycle after a late wake-up must not run engaged on the peer state of before
//    the stall (peer age from the clock read at the cycle, not from the cycle's deadline);
//  - clutch indexing: clutch, move the master, unclutch: no pull back, the slave stays;
//  - re-engagement after a safe in the demo's physics (a 1.5 N push against a 0.5 N centring
//    cap): the simulated operator follows the guidance once the coupling ended.
// Expected values are the rules and hand arithmetic of the law (master_law.hpp,
// slave_law.hpp) written out here, not read from the code under test.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "common/device/sim_device.hpp"
#include "common/node/node_core.hpp"
#include "common/rt/loop_timing.hpp"

namespace teleop::node {
namespace {

using namespace std::chrono_literals;
using transport::Role;

constexpr double kKp = 600.0;  // K_pm = K_ps
constexpr double kKd = 2.0;    // K_dm = K_ds

NodeSettings settings(Role role) {
  NodeSettings s;
  s.role = role;
  s.period = 1ms;
  s.law.period_s = 1e-3;
  s.law.gains = Gains{kKp, kKp, kKd, kKd, 0, 0, 0};
  s.machine.peer_timeout = 30ms;
  s.machine.engage_ramp = 20ms;
  s.safe_ramp = 10ms;
  s.session_id = role == Role::kMaster ? 11 : 22;
  s.config_fingerprint = 0x5eed;  // the same configuration on both sides (arm needs it)
  return s;
}

// A master handle held rigidly by a hand that the test moves: the position is prescribed and
// the command is the force the hand feels (the actuator pushes the handle along +x).
class ScriptedDevice final : public device::HapticDevice {
 public:
  device::Status configure() override { return device::Status::Ok(); }
  device::Status activate() override { return device::Status::Ok(); }
  device::Status deactivate() override { return device::Status::Ok(); }
  device::Status read(device::Sample& s) noexcept override {
    s.sequence = ++sequence_;
    s.position_m = position_m;
    s.force_N = 0.0;
    s.flags = 0;
    return device::Status::Ok();
  }
  device::Status write(const device::Command& c) noexcept override {
    command_N = c.force_N;
    return device::Status::Ok();
  }
  double position_m{0.0};
  double command_N{0.0};

 private:
  std::uint64_t sequence_{0};
};

device::SimDeviceConfig slave_config() {
  device::SimDeviceConfig c = device::SimDeviceConfig::paddle_slave(sim::Environment::free_space());
  c.quantize_position = false;
  return c;
}

device::SimDeviceConfig human_master_config(double push_N) {
  sim::HumanParams h;
  h.impedance = HumanImpedance{0.012, 0.76, 70.0};
  h.profile = sim::ForceProfile::constant(push_N);
  device::SimDeviceConfig c = device::SimDeviceConfig::paddle_master(h);
  c.quantize_position = false;
  c.hold_scene_until_engaged = true;
  return c;
}

device::HapticDevice& init(device::HapticDevice& d) {
  EXPECT_TRUE(d.configure().ok());
  EXPECT_TRUE(d.activate().ok());
  return d;
}

// Master and slave NodeCores stepped together at 1 kHz; each gets the other's state of the
// previous cycle, arrived 0.3 ms after it was sent. The master's loop is a LoopTiming driven
// by the test's clock (as PeriodicLoop drives it), so a stall is a late wake-up.
template <typename MasterDevice>
struct Rig {
  Rig(MasterDevice& master_device, NodeSettings master_settings, NodeSettings slave_settings,
      sim::Environment env = sim::Environment::free_space())
      : slave_dev([&] {
          device::SimDeviceConfig c = slave_config();
          c.plant.environment = env;
          return c;
        }()),
        master_dev(master_device),
        master(master_settings, init(master_dev)),
        slave(slave_settings, init(slave_dev)),
        timing(1ms, now) {}

  // One cycle of both. `late`: the master wakes that much after its deadline (a stall: its
  // link thread stalled too unless `fresh_arrival`, which hands it the slave's newest state as
  // if read from the socket just before the cycle, i.e. a stale state with a fresh arrival).
  void cycle(std::chrono::nanoseconds late = 0ns, bool fresh_arrival = false) {
    const std::chrono::nanoseconds deadline = timing.next_deadline();
    const std::chrono::nanoseconds clock = deadline + late;
    if (late == 0ns || fresh_arrival) {
      PeerSample sample = to_master;
      if (fresh_arrival) sample.arrival_ns = (clock - 100us).count();
      if (sample.state.sequence != 0) master.peer_in().write(sample);
    }
    if (to_slave.state.sequence != 0 && !slave_silent) slave.peer_in().write(to_slave);
    (void)timing.woke(clock);
    master.step(deadline, &timing);
    timing.finished(clock + 50us);
    slave.step(clock);
    now = timing.next_deadline() - 1ms;
    (void)master.state_out().read(to_slave.state);
    to_slave.arrival_ns = (clock + 300us).count();
    (void)slave.state_out().read(to_master.state);
    to_master.arrival_ns = (clock + 300us).count();
    while (auto r = master.telemetry_out().try_pop()) m.push_back(*r);
    while (auto r = slave.telemetry_out().try_pop()) s.push_back(*r);
  }
  void command(NodeCore& n, Command c) { ASSERT_TRUE(n.post_command(c)); }
  void both(Command c) {
    command(master, c);
    command(slave, c);
    cycle();
  }
  void engage() {
    for (int i = 0; i < 3; ++i) cycle();
    both(Command::kArm);
    both(Command::kEngage);
    for (int i = 0;
         i < 3000 && !(master.mode() == Mode::kEngaged && slave.mode() == Mode::kEngaged); ++i) {
      cycle();
    }
    ASSERT_EQ(master.mode(), Mode::kEngaged);
    ASSERT_EQ(slave.mode(), Mode::kEngaged);
  }

  device::SimDevice slave_dev;
  MasterDevice& master_dev;
  NodeCore master;
  NodeCore slave;
  std::chrono::nanoseconds now{1s};
  rt::LoopTiming timing;
  PeerSample to_master{};
  PeerSample to_slave{};
  bool slave_silent{false};
  std::vector<CycleRecord> m;
  std::vector<CycleRecord> s;
};

// ---- Finding 6: stalls ----------------------------------------------------------------------

struct StallCase {
  std::chrono::milliseconds stall;
  bool fresh_arrival;
};

class NodeCoreStall : public ::testing::TestWithParam<StallCase> {};

TEST_P(NodeCoreStall, TheFirstCycleAfterALateWakeUpIsSafeAndItsCommandTheSafeRamp) {
  device::SimDevice hand(human_master_config(1.0));
  Rig<device::SimDevice> r(hand, settings(Role::kMaster), settings(Role::kSlave),
                           sim::Environment::tissue(500.0, 1.0, 0.001));
  ASSERT_NO_FATAL_FAILURE(r.engage());
  for (int i = 0; i < 300; ++i) r.cycle();
  const double before_N = r.m.back().command_N;
  ASSERT_GT(std::abs(before_N), 0.05);  // pushing into the tissue: the master feels it
  const std::size_t first = r.m.size();
  r.cycle(GetParam().stall, GetParam().fresh_arrival);
  ASSERT_EQ(r.m.size(), first + 1);
  const CycleRecord& c = r.m[first];
  // The rule: a wake-up later than the peer timeout (30 ms) goes safe before any
  // command is written. The safe command ramps linearly from the last command written (the one
  // the device held through the stall) to 0 over safe_ramp: its first value is that command.
  EXPECT_EQ(c.mode, Mode::kSafe);
  EXPECT_STREQ(r.master.mode_reason(), "own loop stalled past the peer timeout");
  EXPECT_EQ(c.command_N, before_N);
  EXPECT_EQ(c.coupling_weight, 1.0);
  // Peer age from the clock: at least the stall (unless a state arrived just before).
  if (!GetParam().fresh_arrival) {
    EXPECT_GE(c.peer_age_ns, std::chrono::nanoseconds(GetParam().stall).count());
  }
  // F(k) = F0 (1 - k T / 10 ms) on the clock: 0 from 10 ms on.
  for (int k = 1; k <= 12; ++k) {
    r.cycle();
    const double expected = before_N * std::max(0.0, 1.0 - k * 1e-3 / 10e-3);
    EXPECT_NEAR(r.m.back().command_N, expected, 1e-12) << k;
  }
  EXPECT_EQ(r.master.mode(), Mode::kSafe);
}

INSTANTIATE_TEST_SUITE_P(Stalls, NodeCoreStall,
                         ::testing::Values(StallCase{200ms, false}, StallCase{200ms, true},
                                           StallCase{1000ms, false}, StallCase{1000ms, true},
                                           StallCase{31ms, true}),
                         [](const ::testing::TestParamInfo<StallCase>& i) {
                           return std::to_string(i.param.stall.count()) + "ms" +
                                  (i.param.fresh_arrival ? "StaleStateFreshArrival"
                                                         : "LinkStalledToo");
                         });

TEST(NodeCoreStallSiblings, AWakeUpWithinThePeerTimeoutStaysEngaged) {
  device::SimDevice hand(human_master_config(0.5));
  Rig<device::SimDevice> r(hand, settings(Role::kMaster), settings(Role::kSlave));
  ASSERT_NO_FATAL_FAILURE(r.engage());
  for (int i = 0; i < 100; ++i) r.cycle();
  r.cycle(25ms, true);  // late, but within 30 ms, with the peer's state fresh
  EXPECT_EQ(r.m.back().mode, Mode::kEngaged);
  for (int i = 0; i < 100; ++i) r.cycle();
  EXPECT_EQ(r.master.mode(), Mode::kEngaged);
}

TEST(NodeCoreStallSiblings, ALateWakeUpWhileAligningOrClutchedGoesSafe) {
  for (const bool clutched : {false, true}) {
    // Aligning: the master starts 10 mm off, so it aligns for a while (30 N/m guidance).
    device::SimDeviceConfig cfg = human_master_config(0.0);
    cfg.initial_position_m = clutched ? 0.0 : 0.010;
    device::SimDevice hand(cfg);
    Rig<device::SimDevice> r(hand, settings(Role::kMaster), settings(Role::kSlave));
    for (int i = 0; i < 3; ++i) r.cycle();
    r.both(Command::kArm);
    r.both(Command::kEngage);
    if (clutched) {
      for (int i = 0; i < 200 && r.master.mode() != Mode::kEngaged; ++i) r.cycle();
      r.command(r.master, Command::kClutch);
      r.cycle();
      ASSERT_EQ(r.master.mode(), Mode::kClutched);
    } else {
      for (int i = 0; i < 5; ++i) r.cycle();
      ASSERT_EQ(r.master.mode(), Mode::kAligning);
    }
    r.cycle(200ms, true);
    EXPECT_EQ(r.m.back().mode, Mode::kSafe) << (clutched ? "clutched" : "aligning");
  }
}

TEST(NodeCoreStallSiblings, ABurstOfOverrunsGoesSafeOnceTheLostTimePassesThePeerTimeout) {
  // The documented rule (node_core.hpp): debt += (gap - T) - gap / 2 per cycle, floored at 0;
  // safe when the debt exceeds the peer timeout. Cycles 20 ms apart (each within the timeout,
  // the peer fresh): debt 19 - 10 = 9 ms a cycle -> 9, 18, 27, 36 ms: safe at the 4th.
  device::SimDevice hand(human_master_config(0.5));
  Rig<device::SimDevice> r(hand, settings(Role::kMaster), settings(Role::kSlave));
  ASSERT_NO_FATAL_FAILURE(r.engage());
  for (int i = 0; i < 100; ++i) r.cycle();
  for (int k = 1; k <= 3; ++k) {
    r.cycle(19ms, true);  // the next deadline is 1 ms after the last clock: a 20 ms gap
    EXPECT_EQ(r.m.back().mode, Mode::kEngaged) << k;
  }
  r.cycle(19ms, true);
  EXPECT_EQ(r.m.back().mode, Mode::kSafe);
  EXPECT_STREQ(r.master.mode_reason(), "own loop overran in a burst");
}

TEST(NodeCoreStallSiblings, OverrunsSpreadOutNeverAccumulate) {
  // One 20 ms gap in every 40 cycles: +9 ms, then -0.5 ms per on-time cycle: drained in 18.
  device::SimDevice hand(human_master_config(0.5));
  Rig<device::SimDevice> r(hand, settings(Role::kMaster), settings(Role::kSlave));
  ASSERT_NO_FATAL_FAILURE(r.engage());
  for (int burst = 0; burst < 20; ++burst) {
    r.cycle(19ms, true);
    for (int i = 0; i < 39; ++i) r.cycle();
  }
  EXPECT_EQ(r.master.mode(), Mode::kEngaged);
}

TEST(NodeCoreStallSiblings, APeerStallSendsTheOtherSafeAfterThePeerTimeoutOnTheClock) {
  device::SimDevice hand(human_master_config(0.5));
  Rig<device::SimDevice> r(hand, settings(Role::kMaster), settings(Role::kSlave));
  ASSERT_NO_FATAL_FAILURE(r.engage());
  for (int i = 0; i < 50; ++i) r.cycle();
  const std::int64_t last_arrival = r.to_master.arrival_ns;
  // The slave stalls: the master hears nothing (its own loop on time).
  PeerSample frozen = r.to_master;
  std::size_t from = r.m.size();
  for (int i = 0; i < 40; ++i) {
    r.to_master = frozen;
    r.cycle();
  }
  std::size_t safe = from;
  while (safe < r.m.size() && r.m[safe].mode != Mode::kSafe) ++safe;
  ASSERT_LT(safe, r.m.size());
  const std::int64_t clock_ns = r.m[safe].sample_time_ns;  // on time: deadline == clock
  EXPECT_GT(clock_ns - last_arrival, 30'000'000);
  EXPECT_LE(r.m[safe - 1].sample_time_ns - last_arrival, 30'000'000);
  EXPECT_STREQ(r.master.mode_reason(), "peer timeout");
}

// ---- Finding 10: clutch indexing ------------------------------------------------------------

// Moves the scripted hand linearly from its position to `to_m` over `ms` cycles.
template <typename R>
void move_hand(R& r, ScriptedDevice& hand, double to_m, int ms) {
  const double from = hand.position_m;
  for (int k = 1; k <= ms; ++k) {
    hand.position_m = from + (to_m - from) * k / ms;
    r.cycle();
  }
}

TEST(NodeCoreClutch, UnclutchAbsorbsTheOffsetNoPullBackAndTheSlaveStays) {
  ScriptedDevice hand;
  Rig<ScriptedDevice> r(hand, settings(Role::kMaster), settings(Role::kSlave));
  ASSERT_NO_FATAL_FAILURE(r.engage());
  for (int i = 0; i < 300; ++i) r.cycle();  // at rest at 0, coupled
  const double slave_at_clutch = r.slave_dev.truth().state.position_m;
  ASSERT_LT(std::abs(slave_at_clutch), 1e-6);
  r.command(r.master, Command::kClutch);
  r.cycle();
  ASSERT_EQ(r.master.mode(), Mode::kClutched);
  constexpr double d = 0.010;  // the operator indexes the handle 10 mm
  move_hand(r, hand, d, 200);
  for (int i = 0; i < 100; ++i) r.cycle();
  // While clutched the slave holds x_hold = 0 (its law's spring to the held reference).
  double slave_excursion = 0.0;
  for (const CycleRecord& c : r.s) {
    if (c.mode == Mode::kEngaged)
      slave_excursion = std::max(slave_excursion, std::abs(c.position_m));
  }
  EXPECT_LT(slave_excursion, 1e-4);
  r.command(r.master, Command::kUnclutch);
  r.cycle();
  ASSERT_EQ(r.master.mode(), Mode::kEngaged);
  const std::size_t after = r.m.size();
  for (int i = 0; i < 500; ++i) r.cycle();
  // Hand arithmetic at unclutch: offset = x_m - x_hold = d, published x_r = x_m - d = 0, the
  // slave at ~0: K_pm (x_r - x_s) ~ 0, v_m = v_s ~ 0: the hand feels ~0 N (not -K_pm d = -6 N).
  double worst_N = 0.0;
  for (std::size_t i = after; i < r.m.size(); ++i) {
    EXPECT_EQ(r.m[i].mode, Mode::kEngaged);
    worst_N = std::max(worst_N, std::abs(r.m[i].command_N));
  }
  EXPECT_LT(worst_N, kKp * 1e-4);  // |F| < K_pm * 0.1 mm = 0.06 N
  EXPECT_LT(std::abs(r.slave_dev.truth().state.position_m), 1e-4);
  // Indexing works: the next 2 mm of the hand move the slave 2 mm from where it was.
  move_hand(r, hand, d + 0.002, 100);
  for (int i = 0; i < 400; ++i) r.cycle();
  EXPECT_NEAR(r.slave_dev.truth().state.position_m, 0.002, 1e-4);
  EXPECT_LT(std::abs(r.m.back().command_N), kKp * 1e-4);
}

TEST(NodeCoreClutch, AClutchWhileTheSlaveIsInItsFixtureResumesTheSameContactForce) {
  // The slave's virtual fixture at 2 mm, 1500 N/m. Engaged with the hand at 4 mm, the slave
  // rests where its spring and the fixture balance:
  //   K_ps (x_r - x_s) = K_sVF (x_s - p)  ->  x_s = (600*4 + 1500*2) / 2100 mm = 2.5714 mm,
  // and the hand feels F = -K_pm (x_r - x_s) = -600 * 1.4286 mm = -0.857 N.
  NodeSettings ms = settings(Role::kMaster);
  NodeSettings ss = settings(Role::kSlave);
  ms.law.slave_fixture = ss.law.slave_fixture = FixtureParams{1500.0, 0.002};
  ScriptedDevice hand;
  Rig<ScriptedDevice> r(hand, ms, ss);
  ASSERT_NO_FATAL_FAILURE(r.engage());
  move_hand(r, hand, 0.004, 200);
  for (int i = 0; i < 800; ++i) r.cycle();
  constexpr double xs = (600.0 * 0.004 + 1500.0 * 0.002) / 2100.0;
  constexpr double contact_N = -kKp * (0.004 - xs);
  ASSERT_NEAR(r.slave_dev.truth().state.position_m, xs, 2e-5);
  ASSERT_NEAR(r.m.back().command_N, contact_N, 0.02);
  // Clutch, retract the hand to 0, unclutch: the slave stays in the fixture and the hand
  // feels the same contact again (offset -4 mm absorbed), not a pull toward the slave.
  r.command(r.master, Command::kClutch);
  r.cycle();
  move_hand(r, hand, 0.0, 200);
  for (int i = 0; i < 100; ++i) r.cycle();
  EXPECT_NEAR(r.slave_dev.truth().state.position_m, xs, 2e-5);
  r.command(r.master, Command::kUnclutch);
  r.cycle();
  const std::size_t after = r.m.size();
  for (int i = 0; i < 500; ++i) r.cycle();
  // The coupling faded out while clutched and fades back in over clutch_fade_s (from 0 toward
  // the contact force, never beyond it); from then on the same contact force.
  const auto fade = static_cast<std::size_t>(std::ceil(ms.law.clutch_fade_s / 1e-3)) + 2;
  for (std::size_t i = after; i < r.m.size(); ++i) {
    if (i < after + fade) {
      ASSERT_LE(std::abs(r.m[i].command_N), std::abs(contact_N) + 0.02) << i - after;
    } else {
      ASSERT_NEAR(r.m[i].command_N, contact_N, 0.02) << i - after;
    }
  }
  for (std::size_t i = r.s.size() - 500; i < r.s.size(); ++i) {
    ASSERT_NEAR(r.s[i].position_m, xs, 2e-5) << i;
  }
}

TEST(NodeCoreClutch, UnclutchDoesNotRestartTheEngageRampOrTheCentring) {
  // The engage ramp blends the centring spring (toward x_s) into the law. After unclutch the
  // weight must stay 1: a restarted ramp would pull the hand toward the slave's position.
  ScriptedDevice hand;
  Rig<ScriptedDevice> r(hand, settings(Role::kMaster), settings(Role::kSlave));
  ASSERT_NO_FATAL_FAILURE(r.engage());
  for (int i = 0; i < 100; ++i) r.cycle();
  r.command(r.master, Command::kClutch);
  r.cycle();
  move_hand(r, hand, 0.010, 100);
  r.command(r.master, Command::kUnclutch);
  r.cycle();
  EXPECT_EQ(r.m.back().coupling_weight, 1.0);
}

// ---- Finding 11: re-engagement after a safe --------------------------------------------------

TEST(NodeCoreReEngage, AfterAnEStopTheDemoReAlignsAndEngagesAgainWithTheErrorFalling) {
  // The demo's physics (examples/live.textproto): a 1.5 N push, tissue at 4 mm, the slave's
  // fixture at 6 mm. After the e-stop the master rests at the human's equilibrium
  // 1.5 N / 70 N/m = 21 mm while the slave (released on clear) sits near the tissue: a gap the
  // 0.5 N centring cap could never close against a 1.5 N hand (it balances at
  // (1.5 - 0.5) / 70 = 14 mm). The cooperating operator yields to the guidance instead.
  NodeSettings ms = settings(Role::kMaster);
  NodeSettings ss = settings(Role::kSlave);
  ms.law.slave_fixture = ss.law.slave_fixture = FixtureParams{1500.0, 0.006};
  ms.machine.engage_ramp = ss.machine.engage_ramp = 200ms;
  device::SimDevice hand(human_master_config(1.5));
  Rig<device::SimDevice> r(hand, ms, ss, sim::Environment::tissue(200.0, 1.0, 0.004));
  ASSERT_NO_FATAL_FAILURE(r.engage());
  for (int i = 0; i < 2000; ++i) r.cycle();
  r.both(Command::kEStop);
  ASSERT_EQ(r.master.mode(), Mode::kSafe);
  for (int i = 0; i < 1000; ++i) r.cycle();
  EXPECT_GT(r.m.back().position_m, 0.015);  // the hand pushed the free master away
  r.both(Command::kClear);
  for (int i = 0; i < 500; ++i) r.cycle();
  r.both(Command::kArm);
  r.both(Command::kEngage);
  ASSERT_EQ(r.master.mode(), Mode::kAligning);
  const std::size_t start = r.m.size() - 1;
  const double initial_gap = std::abs(r.m[start].alignment_error_m);
  EXPECT_GT(initial_gap, 0.010);
  // The telemetry's error is alpha x_m - x_s of the cycle's own positions.
  EXPECT_NEAR(r.m[start].alignment_error_m, r.m[start].position_m - r.m[start].peer_position_m,
              1e-12);
  int cycles = 0;
  for (; cycles < 10000 && r.master.mode() != Mode::kEngaged; ++cycles) r.cycle();
  ASSERT_EQ(r.master.mode(), Mode::kEngaged) << "gap " << r.m.back().alignment_error_m;
  // Bound: the clamped guidance (0.5 N) lowers the push by 5/s * 0.5 N = 2.5 N/s until the
  // spring takes over, then the gap falls with time constant (k_h + k_c) / (r k_c) = 0.67 s:
  // from 1.5 N about 0.5 s clamped and ~1.2 s (ln(4 mm / 2 mm) * 0.67 * 2.5) on the spring.
  EXPECT_LT(cycles, 4000);
  // The error fell while aligning: each 100 ms smaller than the previous 100 ms's.
  double previous = initial_gap;
  for (std::size_t i = start + 100; i < r.m.size() && r.m[i].mode == Mode::kAligning; i += 100) {
    EXPECT_LT(std::abs(r.m[i].alignment_error_m), previous) << i - start;
    previous = std::abs(r.m[i].alignment_error_m);
  }
  EXPECT_LE(std::abs(r.m.back().alignment_error_m), 0.002);
  for (int i = 0; i < 3000; ++i) r.cycle();
  EXPECT_EQ(r.master.mode(), Mode::kEngaged);
  EXPECT_EQ(r.slave.mode(), Mode::kEngaged);
  // Engaged again, the operator takes the scene's 1.5 N up again: the slave presses past the
  // tissue (4 mm) as in the first engagement.
  EXPECT_FALSE(hand.truth().operator_cooperating);
  EXPECT_NEAR(hand.truth().human_push_N, 1.5, 1e-9);
  EXPECT_GT(r.slave_dev.truth().state.position_m, 0.004);
}

TEST(NodeCoreReEngage, TheOperatorHoldsThePushWhileNothingGuidesAndYieldsToTheGuidance) {
  // SimDevice's cooperating operator: dF_h*/dt = 5/s * F_actuator once a coupling ended.
  device::SimDeviceConfig cfg = human_master_config(1.5);
  device::SimDevice d(cfg);
  ASSERT_TRUE(d.configure().ok());
  ASSERT_TRUE(d.activate().ok());
  d.on_engaged();
  for (int i = 0; i < 10; ++i) (void)d.tick(1ms);
  EXPECT_NEAR(d.truth().human_push_N, 1.5, 1e-12);
  d.on_disengaged();
  for (int i = 0; i < 100; ++i) (void)d.tick(1ms);  // 0 N from the actuator: held
  EXPECT_NEAR(d.truth().human_push_N, 1.5, 1e-12);
  ASSERT_TRUE(d.write(device::Command{-0.5}).ok());
  for (int i = 0; i < 200; ++i) (void)d.tick(1ms);  // -0.5 N for 0.2 s: -0.5 N less push
  EXPECT_NEAR(d.truth().human_push_N, 1.5 - 5.0 * 0.5 * 0.199, 1e-9);
  // Engaged again: back to the scene's push linearly over 1 s.
  ASSERT_TRUE(d.write(device::Command{0.0}).ok());
  const double held = 1.5 - 5.0 * 0.5 * 0.2;
  d.on_engaged();
  (void)d.tick(1ms);
  EXPECT_NEAR(d.truth().human_push_N, held, 1e-9);
  for (int i = 0; i < 499; ++i) (void)d.tick(1ms);
  EXPECT_NEAR(d.truth().human_push_N, held + 0.5 * (1.5 - held), 1e-3);
  for (int i = 0; i < 600; ++i) (void)d.tick(1ms);
  EXPECT_NEAR(d.truth().human_push_N, 1.5, 1e-12);
}

}  // namespace
}  // namespace teleop::node
