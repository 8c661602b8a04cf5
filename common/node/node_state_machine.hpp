// A node's operating state (issue 4 "Node states and commands"): disarmed -> armed -> aligning
// -> engaged, plus clutched, safe and fault. Pure logic stepped once per cycle with the
// cycle's time and inputs, so tests drive it with a fake clock. RT-safe: no allocation, no
// lock, no exception.
#pragma once

#include <chrono>
#include <cstdint>

#include "common/core/defaults.hpp"
#include "common/core/rt_safe.hpp"

namespace teleop::node {

enum class Mode : std::uint8_t { kDisarmed, kArmed, kAligning, kEngaged, kClutched, kSafe, kFault };
// The mode on the wire and in telemetry: teleop.v1.NodeMode (node_state.proto) numbers the
// same modes from 1 (DISARMED = 1 ... FAULT = 7; 0 is unspecified). Written once, here.
TELEOP_RT [[nodiscard]] constexpr int wire_mode(Mode m) noexcept { return static_cast<int>(m) + 1; }
// The mode of a wire value; an unknown or unspecified one reads as disarmed.
TELEOP_RT [[nodiscard]] constexpr Mode mode_from_wire(int wire) noexcept {
  return wire >= 1 && wire <= wire_mode(Mode::kFault) ? static_cast<Mode>(wire - 1)
                                                      : Mode::kDisarmed;
}
enum class Command : std::uint8_t {
  kNone,
  kArm,
  kEngage,
  kDisengage,
  kClutch,
  kUnclutch,
  kClear,
  kEStop
};

TELEOP_RT [[nodiscard]] const char* to_string(Mode m) noexcept;

struct StateMachineParams {
  std::chrono::nanoseconds peer_timeout{defaults::kPeerTimeout};
  std::chrono::nanoseconds engage_ramp{defaults::kEngageRamp};
};

// The reason the machine gives on entering kFault for a device fault (one object: a core may
// compare the pointer and name the device's own message instead).
// An array, not a pointer to a literal: the address is the one inline object's in every
// translation unit. A `const char*` initialised with "device fault" is folded to each unit's own
// copy of the literal, equal only where the linker merges strings (not under ASan, which pads
// each literal: the n-axis core's pointer comparison failed there).
inline constexpr char kDeviceFaultReason[] = "device fault";

struct CycleInputs {
  std::chrono::nanoseconds now{0};
  Command command{Command::kNone};
  std::chrono::nanoseconds peer_age{0};  // since the newest accepted peer state arrived
  bool peer_seen{false};                 // any peer state accepted this session
  bool aligned{false};                   // within the alignment tolerance of the peer
  bool device_fault{false};              // device fault or e-stop bit
  bool law_fault{false};                 // the control law latched a fault
  // The peer is safe or faulted, or restarted (a new session): coupling ends in safe.
  bool peer_failed{false};
  // The peer left coupling by command (disarmed or armed): coupling ends in armed.
  bool peer_disengaged{false};
  // The node's own loop stalled (woke later than the peer timeout after its previous cycle,
  // or overran in a burst): whatever it knows of the peer and its device is that old, so
  // coupling ends in safe at once, before a command is written. Non-null: why (static).
  const char* own_stall{nullptr};
  // Why arm and engage are refused now (docs/nodes.md "Before engage": the configuration's own
  // analysis, the peer's configuration fingerprint or parameter change); nullptr: permitted.
  // A static string (or one that outlives the machine).
  const char* coupling_refusal{nullptr};
};

struct CycleOutputs {
  Mode mode{Mode::kDisarmed};
  double coupling_weight{0.0};  // 0..1: engage ramp; 0 outside engaged
  bool centring{false};         // aligning: the weak centring force guides the operator
  bool actuators_enabled{false};
  const char* reason{""};  // why the last transition happened (static string)
  bool refused{false};     // this cycle's command was refused by coupling_refusal
};

// What entering a mode requires of the node, by transition (entry_actions): the machine
// decides them, the node (NodeCore::enter) carries them out.
struct EntryActions {
  // A fresh law (no offset, no stale filter state, the coupling fading in): entering aligning,
  // engaged (except from clutched: unclutching keeps the operator's indexing offset, which the
  // law absorbs), disarmed and fault.
  bool reset_law{false};
  // Entering aligning: a peer restart seen before this coupling no longer ends it.
  bool forget_peer_restart{false};
  // Entering engaged from outside a coupling (not from clutched): the device's scene starts,
  // or the simulated operator takes it up again (HapticDevice::on_engaged).
  bool device_engaged{false};
  // Leaving engaged or clutched for a mode without coupling (HapticDevice::on_disengaged).
  bool device_disengaged{false};
  // Entering safe: the safe ramp starts now, from the last command written.
  bool start_safe_ramp{false};
};

// The entry actions of the transition from `from` to `to` (from != to). RT-safe.
TELEOP_RT [[nodiscard]] constexpr EntryActions entry_actions(Mode from, Mode to) noexcept {
  const bool was_coupled = from == Mode::kEngaged || from == Mode::kClutched;
  const bool coupled = to == Mode::kEngaged || to == Mode::kClutched;
  EntryActions a;
  a.reset_law = to == Mode::kAligning || (to == Mode::kEngaged && from != Mode::kClutched) ||
                to == Mode::kDisarmed || to == Mode::kFault;
  a.forget_peer_restart = to == Mode::kAligning;
  a.device_engaged = to == Mode::kEngaged && !was_coupled;
  a.device_disengaged = was_coupled && !coupled;
  a.start_safe_ramp = to == Mode::kSafe;
  return a;
}

// Called by the machine once for every transition, within step() (RT thread).
class EntryHandler {
 public:
  TELEOP_RT virtual void on_enter(Mode from, Mode to, const EntryActions& actions) noexcept = 0;

 protected:
  EntryHandler() = default;
  EntryHandler(const EntryHandler&) = default;
  EntryHandler& operator=(const EntryHandler&) = default;
  ~EntryHandler() = default;
};

class NodeStateMachine {
 public:
  explicit NodeStateMachine(const StateMachineParams& params) noexcept : params_(params) {}

  // The handler step() calls on each transition (nullptr: none); it must outlive the machine.
  void set_entry_handler(EntryHandler* handler) noexcept { on_enter_ = handler; }

  // RT-safe. A transition (a new mode) calls the entry handler once, with entry_actions().
  TELEOP_RT [[nodiscard]] CycleOutputs step(const CycleInputs& in) noexcept;
  [[nodiscard]] Mode mode() const noexcept { return mode_; }

 private:
  TELEOP_RT void go(Mode m, const char* why, std::chrono::nanoseconds now) noexcept;
  // While aligning, engaged or clutched: an own stall, a stale, failed, restarted (or, once
  // coupled, disengaged) peer ends the coupling. True when it did.
  TELEOP_RT bool coupling_lost(const CycleInputs& in, bool peer_fresh,
                               bool peer_may_disengage) noexcept;

  StateMachineParams params_{};
  Mode mode_{Mode::kDisarmed};
  const char* reason_{"start"};
  std::chrono::nanoseconds engaged_at_{0};
  EntryHandler* on_enter_{nullptr};
};

}  // namespace teleop::node
