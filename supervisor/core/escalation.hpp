// The supervisor's safety ladder for a misbehaving loop (sustained oscillation or an active
// port), as an explicit state machine driven by the check's clock:
//
//   kWatching --(a finding lasting escalation)--> kLowering      action kLowerFixtures
//   kLowering --(the lowered stiffness in force)--> kLowered     monitors cleared
//   kLowered --(a finding lasting escalation again)--> kDisengaged   action kDisengage
//   kLowered, kDisengaged --(nothing found for 2 x escalation)--> kWatching
//
// A finding younger than `escalation` is a warning in every state. In kLowering nothing
// escalates: only evidence from after the lowered stiffness came into force (the change's
// apply delay plus its ramp, `settle`) may. No I/O, no clock of its own: the caller passes
// `now` and carries out the actions.
#pragma once

#include <cstdint>
#include <string_view>

namespace teleop::supervisor {

enum class EscalationState { kWatching, kLowering, kLowered, kDisengaged };
enum class EscalationAction { kNone, kWarn, kLowerFixtures, kDisengage };

[[nodiscard]] std::string_view to_string(EscalationState s) noexcept;

class EscalationLadder {
 public:
  // `escalation_ns`: how long a finding must last before the supervisor acts on it;
  // `settle_ns`: from lowering to the lowered stiffness being in force.
  EscalationLadder(std::int64_t escalation_ns, std::int64_t settle_ns) noexcept
      : escalation_ns_(escalation_ns), settle_ns_(settle_ns) {}

  // First at each check: true when the lowered stiffness has just come into force (kLowering
  // -> kLowered); the caller then clears its monitors so that older evidence cannot escalate.
  [[nodiscard]] bool settle(std::int64_t now_ns) noexcept;

  // A finding on one node that has lasted `lasting_ns` (from its first check): what to do.
  [[nodiscard]] EscalationAction on_finding(std::int64_t now_ns, std::int64_t lasting_ns) noexcept;

  // Last at each check: whether any node had a finding. Clean long enough after the ladder
  // settled, it starts over.
  void end_check(std::int64_t now_ns, bool any_finding) noexcept;

  [[nodiscard]] EscalationState state() const noexcept { return state_; }
  // When the lowered stiffness is (or was) fully in force; 0 before any lowering.
  [[nodiscard]] std::int64_t settles_at_ns() const noexcept { return settles_at_ns_; }

 private:
  std::int64_t escalation_ns_;
  std::int64_t settle_ns_;
  EscalationState state_{EscalationState::kWatching};
  std::int64_t settles_at_ns_{0};
};

}  // namespace teleop::supervisor
