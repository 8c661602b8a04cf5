// A node's operating state (issue 4 "Node states and commands"): disarmed -> armed -> aligning
// -> engaged, plus clutched, safe and fault. Pure logic stepped once per cycle with the
// cycle's time and inputs, so tests drive it with a fake clock. RT-safe: no allocation, no
// lock, no exception.
#pragma once

#include <chrono>
#include <cstdint>

#include "common/core/defaults.hpp"

namespace teleop::node {

enum class Mode : std::uint8_t { kDisarmed, kArmed, kAligning, kEngaged, kClutched, kSafe, kFault };
// The mode on the wire and in telemetry: teleop.v1.NodeMode (node_state.proto) numbers the
// same modes from 1 (DISARMED = 1 ... FAULT = 7; 0 is unspecified). Written once, here.
[[nodiscard]] constexpr int wire_mode(Mode m) noexcept { return static_cast<int>(m) + 1; }
// The mode of a wire value; an unknown or unspecified one reads as disarmed.
[[nodiscard]] constexpr Mode mode_from_wire(int wire) noexcept {
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

[[nodiscard]] const char* to_string(Mode m) noexcept;

struct StateMachineParams {
  std::chrono::nanoseconds peer_timeout{defaults::kPeerTimeout};
  std::chrono::nanoseconds engage_ramp{defaults::kEngageRamp};
};

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

class NodeStateMachine {
 public:
  explicit NodeStateMachine(const StateMachineParams& params) noexcept : params_(params) {}

  // RT-safe.
  [[nodiscard]] CycleOutputs step(const CycleInputs& in) noexcept;
  [[nodiscard]] Mode mode() const noexcept { return mode_; }

 private:
  void go(Mode m, const char* why, std::chrono::nanoseconds now) noexcept;
  // While aligning, engaged or clutched: an own stall, a stale, failed, restarted (or, once
  // coupled, disengaged) peer ends the coupling. True when it did.
  bool coupling_lost(const CycleInputs& in, bool peer_fresh, bool peer_may_disengage) noexcept;

  StateMachineParams params_{};
  Mode mode_{Mode::kDisarmed};
  const char* reason_{"start"};
  std::chrono::nanoseconds engaged_at_{0};
};

}  // namespace teleop::node
