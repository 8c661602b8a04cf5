// The node's operating states: every transition of issue 4, and its deadlines read from the
// cycle times handed in (a fake clock), never by sleeping.
#include <gtest/gtest.h>

#include <string>

#include "common/node/node_state_machine.hpp"

namespace teleop::node {
namespace {

using std::chrono::milliseconds;
using std::chrono::nanoseconds;

struct Driver {
  NodeStateMachine sm{StateMachineParams{milliseconds(50), milliseconds(500)}};
  nanoseconds now{0};
  nanoseconds last_peer{0};
  bool peer_seen{true};
  bool aligned{false};
  bool device_fault{false};
  bool law_fault{false};

  // One 1 ms cycle; the peer's state arrives every cycle unless `peer_silent`.
  CycleOutputs cycle(Command c = Command::kNone, bool peer_silent = false) {
    now += milliseconds(1);
    if (!peer_silent) last_peer = now;
    return sm.step({now, c, now - last_peer, peer_seen, aligned, device_fault, law_fault});
  }
};

TEST(NodeStateMachine, ArmAlignEngageWithRamp) {
  Driver d;
  EXPECT_EQ(d.cycle().mode, Mode::kDisarmed);
  EXPECT_FALSE(d.cycle(Command::kEngage).actuators_enabled);  // not armed: ignored
  EXPECT_EQ(d.cycle(Command::kArm).mode, Mode::kArmed);
  CycleOutputs o = d.cycle(Command::kEngage);
  EXPECT_EQ(o.mode, Mode::kAligning);
  EXPECT_TRUE(o.centring);
  EXPECT_EQ(o.coupling_weight, 0.0);
  d.aligned = true;
  o = d.cycle();
  EXPECT_EQ(o.mode, Mode::kEngaged);
  EXPECT_EQ(o.coupling_weight, 0.0);  // the ramp starts at the engage instant
  for (int i = 0; i < 250; ++i) o = d.cycle();
  EXPECT_NEAR(o.coupling_weight, 0.5, 1e-12);  // 250 ms of a 500 ms ramp
  for (int i = 0; i < 300; ++i) o = d.cycle();
  EXPECT_EQ(o.coupling_weight, 1.0);
}

TEST(NodeStateMachine, EngageNeedsAFreshPeer) {
  Driver d;
  d.peer_seen = false;
  (void)d.cycle(Command::kArm);
  const CycleOutputs o = d.cycle(Command::kEngage);
  EXPECT_EQ(o.mode, Mode::kArmed);
  EXPECT_EQ(std::string(o.reason), "engage refused: no fresh peer state");
}

TEST(NodeStateMachine, PeerSilenceBeyondTheTimeoutGoesSafeAndLatches) {
  Driver d;
  d.aligned = true;
  (void)d.cycle(Command::kArm);
  (void)d.cycle(Command::kEngage);
  (void)d.cycle();
  ASSERT_EQ(d.sm.mode(), Mode::kEngaged);
  // Silent for 50 cycles: age 50 ms = the timeout, still engaged; the 51st goes safe.
  for (int i = 0; i < 50; ++i) ASSERT_EQ(d.cycle(Command::kNone, true).mode, Mode::kEngaged) << i;
  const CycleOutputs o = d.cycle(Command::kNone, true);
  EXPECT_EQ(o.mode, Mode::kSafe);
  EXPECT_FALSE(o.actuators_enabled);
  EXPECT_EQ(std::string(o.reason), "peer timeout");
  // The peer is back: still safe until an operator clears, then disarmed, not engaged.
  EXPECT_EQ(d.cycle().mode, Mode::kSafe);
  EXPECT_EQ(d.cycle(Command::kEngage).mode, Mode::kSafe);
  EXPECT_EQ(d.cycle(Command::kClear).mode, Mode::kDisarmed);
}

TEST(NodeStateMachine, EStopFromEveryStateAndFaultsLatch) {
  for (int steps = 0; steps < 5; ++steps) {
    Driver d;
    d.aligned = true;
    const Command path[] = {Command::kArm, Command::kEngage, Command::kNone, Command::kClutch};
    for (int i = 0; i < steps && i < 4; ++i) (void)d.cycle(path[i]);
    const CycleOutputs o = d.cycle(Command::kEStop);
    EXPECT_EQ(o.mode, Mode::kSafe) << steps;
    EXPECT_FALSE(o.actuators_enabled);
  }
  Driver d;
  (void)d.cycle(Command::kArm);
  d.device_fault = true;
  EXPECT_EQ(d.cycle().mode, Mode::kFault);
  EXPECT_EQ(d.cycle(Command::kClear).mode, Mode::kFault);  // cause still present
  d.device_fault = false;
  EXPECT_EQ(d.cycle().mode, Mode::kFault);  // latched until cleared
  EXPECT_EQ(d.cycle(Command::kClear).mode, Mode::kDisarmed);
}

// Release continues the engagement (issue 14, finding 10): the law absorbs the clutch offset
// and fades its own coupling back in (master_law.hpp); a restarted engage ramp would blend the
// centring spring back in and pull the hand toward the slave.
TEST(NodeStateMachine, ClutchHoldsEngagementAndReleaseKeepsTheEngageRampDone) {
  Driver d;
  d.aligned = true;
  (void)d.cycle(Command::kArm);
  (void)d.cycle(Command::kEngage);
  (void)d.cycle();
  for (int i = 0; i < 600; ++i) (void)d.cycle();
  EXPECT_EQ(d.cycle(Command::kClutch).mode, Mode::kClutched);
  CycleOutputs o = d.cycle(Command::kUnclutch);
  EXPECT_EQ(o.mode, Mode::kEngaged);
  EXPECT_EQ(o.coupling_weight, 1.0);
  EXPECT_EQ(d.cycle(Command::kDisengage).mode, Mode::kArmed);
}

// Issue 14, finding 6: the node's own stall ends any coupling in safe at once, naming why,
// even with the peer's state fresh; outside coupling there is nothing to end.
TEST(NodeStateMachine, AnOwnStallSendsAligningEngagedAndClutchedSafeAtOnce) {
  for (const int stage : {0, 1, 2}) {
    Driver d;
    d.aligned = stage > 0;
    (void)d.cycle(Command::kArm);
    (void)d.cycle(Command::kEngage);
    if (stage > 0) (void)d.cycle();
    if (stage == 2) (void)d.cycle(Command::kClutch);
    const Mode before = d.sm.mode();
    ASSERT_EQ(before, stage == 0 ? Mode::kAligning : stage == 1 ? Mode::kEngaged : Mode::kClutched);
    d.now += milliseconds(1);
    CycleInputs in{d.now, Command::kNone, nanoseconds(0), true, d.aligned, false, false};
    in.own_stall = "own loop stalled past the peer timeout";
    const CycleOutputs o = d.sm.step(in);
    EXPECT_EQ(o.mode, Mode::kSafe) << stage;
    EXPECT_STREQ(o.reason, "own loop stalled past the peer timeout");
    EXPECT_FALSE(o.actuators_enabled);
  }
  Driver d;
  (void)d.cycle(Command::kArm);
  d.now += milliseconds(1);
  CycleInputs in{d.now, Command::kNone, nanoseconds(0), true, false, false, false};
  in.own_stall = "own loop stalled past the peer timeout";
  EXPECT_EQ(d.sm.step(in).mode, Mode::kArmed);
}

}  // namespace
}  // namespace teleop::node

namespace teleop::node {
namespace {

// docs/nodes.md "Before engage": a configuration refusal (the node's own analysis, or the peer's
// fingerprint) refuses arm and engage, says why, and leaves the mode alone.
TEST(NodeStateMachine, ConfigurationRefusalRefusesArmAndEngage) {
  static const char* const kWhy = "arm and engage refused: configuration fingerprint differs";
  NodeStateMachine sm{StateMachineParams{milliseconds(50), milliseconds(500)}};
  CycleInputs in;
  in.peer_seen = true;
  in.aligned = true;
  in.coupling_refusal = kWhy;
  for (int i = 1; i <= 3; ++i) {
    in.now = milliseconds(i);
    in.command = i == 2 ? Command::kArm : Command::kNone;
    const CycleOutputs o = sm.step(in);
    EXPECT_EQ(o.mode, Mode::kDisarmed);
    EXPECT_FALSE(o.actuators_enabled);
    EXPECT_EQ(o.refused, i == 2);
    if (i >= 2) {
      EXPECT_STREQ(o.reason, kWhy);
    }
  }
  // Engage while disarmed: not armed anyway, and the configuration is said to be why.
  in.now = milliseconds(3);
  in.command = Command::kEngage;
  {
    const CycleOutputs e = sm.step(in);
    EXPECT_EQ(e.mode, Mode::kDisarmed);
    EXPECT_TRUE(e.refused);
    EXPECT_STREQ(e.reason, kWhy);
  }
  // Permitted: arm; refused again before engage: stays armed, refused, never aligning.
  in.coupling_refusal = nullptr;
  in.now = milliseconds(4);
  in.command = Command::kArm;
  ASSERT_EQ(sm.step(in).mode, Mode::kArmed);
  in.coupling_refusal = kWhy;
  in.now = milliseconds(5);
  in.command = Command::kEngage;
  const CycleOutputs o = sm.step(in);
  EXPECT_EQ(o.mode, Mode::kArmed);
  EXPECT_TRUE(o.refused);
  EXPECT_STREQ(o.reason, kWhy);
  EXPECT_FALSE(o.actuators_enabled);
  // E-stop and disengage are never refused.
  in.now = milliseconds(6);
  in.command = Command::kEStop;
  EXPECT_EQ(sm.step(in).mode, Mode::kSafe);
  in.now = milliseconds(7);
  in.command = Command::kClear;
  EXPECT_EQ(sm.step(in).mode, Mode::kDisarmed);
}

}  // namespace
}  // namespace teleop::node

namespace teleop::node {
namespace {

// The one mapping between node::Mode and the wire's teleop.v1.NodeMode, against the numbers
// node_state.proto gives (DISARMED = 1 ... FAULT = 7, 0 unspecified), read from the .proto.
// --- entry actions (the machine calls its handler once per transition) ------------------------

// Counts what the machine asked for, per action, and every transition seen.
struct Recorder final : EntryHandler {
  int transitions{0};
  int reset_law{0};
  int forget_peer_restart{0};
  int device_engaged{0};
  int device_disengaged{0};
  int start_safe_ramp{0};
  Mode last_from{Mode::kDisarmed};
  Mode last_to{Mode::kDisarmed};
  void on_enter(Mode from, Mode to, const EntryActions& a) noexcept override {
    ++transitions;
    last_from = from;
    last_to = to;
    reset_law += a.reset_law ? 1 : 0;
    forget_peer_restart += a.forget_peer_restart ? 1 : 0;
    device_engaged += a.device_engaged ? 1 : 0;
    device_disengaged += a.device_disengaged ? 1 : 0;
    start_safe_ramp += a.start_safe_ramp ? 1 : 0;
  }
};

struct RecordingDriver : Driver {
  Recorder rec;
  RecordingDriver() { sm.set_entry_handler(&rec); }
  // Arms, engages and aligns: disarmed -> armed -> aligning -> engaged.
  void engage() {
    (void)cycle(Command::kArm);
    (void)cycle(Command::kEngage);
    aligned = true;
    EXPECT_EQ(cycle().mode, Mode::kEngaged);
  }
};

TEST(NodeStateMachineEntry, EveryTransitionIntoSafeStartsTheSafeRampExactlyOnce) {
  RecordingDriver d;
  // Into safe by e-stop from engaged, then held there: one entry, whatever follows.
  d.engage();
  const int before = d.rec.transitions;
  EXPECT_EQ(d.cycle(Command::kEStop).mode, Mode::kSafe);
  for (int i = 0; i < 20; ++i) (void)d.cycle(Command::kEStop);        // e-stop again: still safe
  for (int i = 0; i < 100; ++i) (void)d.cycle(Command::kNone, true);  // silent peer
  EXPECT_EQ(d.rec.start_safe_ramp, 1);
  EXPECT_EQ(d.rec.transitions, before + 1);
  EXPECT_EQ(d.rec.last_to, Mode::kSafe);
  EXPECT_EQ(d.rec.device_disengaged, 1);  // it left a coupling
  // Cleared, engaged again, then into safe by peer timeout (50 ms): a second ramp.
  EXPECT_EQ(d.cycle(Command::kClear).mode, Mode::kDisarmed);
  d.aligned = false;
  d.engage();
  for (int i = 0; i < 60; ++i) (void)d.cycle(Command::kNone, true);
  EXPECT_EQ(d.sm.mode(), Mode::kSafe);
  EXPECT_EQ(d.rec.start_safe_ramp, 2);
  // From aligning by an own stall: a third; from disarmed by e-stop: a fourth.
  (void)d.cycle(Command::kClear);
  d.aligned = false;
  (void)d.cycle(Command::kArm);
  EXPECT_EQ(d.cycle(Command::kEngage).mode, Mode::kAligning);
  CycleInputs stalled{d.now + milliseconds(1), Command::kNone, nanoseconds(0), true};
  stalled.own_stall = "own loop stalled";
  EXPECT_EQ(d.sm.step(stalled).mode, Mode::kSafe);
  EXPECT_EQ(d.rec.start_safe_ramp, 3);
  (void)d.cycle(Command::kClear);
  (void)d.cycle(Command::kEStop);
  EXPECT_EQ(d.rec.start_safe_ramp, 4);
  EXPECT_EQ(d.rec.last_from, Mode::kDisarmed);
}

TEST(NodeStateMachineEntry, EveryTransitionIntoFaultResetsTheLawOnceAndEndsTheCoupling) {
  RecordingDriver d;
  d.engage();
  const int resets = d.rec.reset_law;
  d.device_fault = true;
  for (int i = 0; i < 50; ++i) EXPECT_EQ(d.cycle().mode, Mode::kFault);  // latched: one entry
  EXPECT_EQ(d.rec.reset_law, resets + 1);
  EXPECT_EQ(d.rec.device_disengaged, 1);
  EXPECT_EQ(d.rec.start_safe_ramp, 0);  // fault is 0 N at once, not a ramp
  // A clear while the fault is present leaves nothing to enter; once gone, disarmed (a reset).
  (void)d.cycle(Command::kClear);
  EXPECT_EQ(d.rec.last_to, Mode::kFault);
  d.device_fault = false;
  EXPECT_EQ(d.cycle(Command::kClear).mode, Mode::kDisarmed);
  EXPECT_EQ(d.rec.reset_law, resets + 2);
  // From safe into fault (a law fault): again exactly one reset, nothing to disengage.
  (void)d.cycle(Command::kEStop);
  d.law_fault = true;
  (void)d.cycle();
  (void)d.cycle();
  EXPECT_EQ(d.rec.last_from, Mode::kSafe);
  EXPECT_EQ(d.rec.last_to, Mode::kFault);
  EXPECT_EQ(d.rec.reset_law, resets + 3);
  EXPECT_EQ(d.rec.device_disengaged, 1);
}

TEST(NodeStateMachineEntry, EngagingResetsTheLawAndStartsTheDeviceButUnclutchingDoesNot) {
  RecordingDriver d;
  (void)d.cycle(Command::kArm);
  EXPECT_EQ(d.rec.reset_law, 0);  // arming changes nothing in the law
  (void)d.cycle(Command::kEngage);
  EXPECT_EQ(d.rec.reset_law, 1);  // aligning: a fresh law
  EXPECT_EQ(d.rec.forget_peer_restart, 1);
  EXPECT_EQ(d.rec.device_engaged, 0);
  d.aligned = true;
  (void)d.cycle();
  EXPECT_EQ(d.rec.reset_law, 2);  // engaged from aligning: fresh again
  EXPECT_EQ(d.rec.device_engaged, 1);
  (void)d.cycle(Command::kClutch);
  EXPECT_EQ(d.rec.device_disengaged, 0);  // clutched is still a coupling
  EXPECT_EQ(d.cycle(Command::kUnclutch).mode, Mode::kEngaged);
  EXPECT_EQ(d.rec.reset_law, 2);       // the law keeps the indexing offset
  EXPECT_EQ(d.rec.device_engaged, 1);  // the operator never let go
  EXPECT_EQ(d.cycle(Command::kDisengage).mode, Mode::kArmed);
  EXPECT_EQ(d.rec.device_disengaged, 1);
  EXPECT_EQ(d.rec.reset_law, 2);  // armed: the law is not running
  EXPECT_EQ(d.cycle(Command::kDisengage).mode, Mode::kDisarmed);
  EXPECT_EQ(d.rec.reset_law, 3);
  EXPECT_EQ(d.rec.transitions, 7);
}

// No handler: the machine runs the same (the handler is an observer of its transitions).
TEST(NodeStateMachineEntry, WithoutAHandlerTheModesAreTheSame) {
  Driver plain;
  RecordingDriver recorded;
  const Command script[] = {Command::kArm,    Command::kEngage, Command::kNone,
                            Command::kClutch, Command::kEStop,  Command::kClear};
  for (const Command c : script) {
    plain.aligned = recorded.aligned = c == Command::kNone;
    EXPECT_EQ(plain.cycle(c).mode, recorded.cycle(c).mode);
  }
}

TEST(WireMode, EveryModeHasTheProtoNumberAndBackAndUnknownReadsAsDisarmed) {
  const std::pair<Mode, int> proto[] = {
      {Mode::kDisarmed, 1}, {Mode::kArmed, 2}, {Mode::kAligning, 3}, {Mode::kEngaged, 4},
      {Mode::kClutched, 5}, {Mode::kSafe, 6},  {Mode::kFault, 7}};
  for (const auto& [mode, number] : proto) {
    EXPECT_EQ(wire_mode(mode), number);
    EXPECT_EQ(mode_from_wire(number), mode);
  }
  for (const int unknown : {0, -1, 8, 1000}) EXPECT_EQ(mode_from_wire(unknown), Mode::kDisarmed);
}

}  // namespace
}  // namespace teleop::node
