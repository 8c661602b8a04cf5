#include "supervisor/core/escalation.hpp"

namespace teleop::supervisor {

std::string_view to_string(EscalationState s) noexcept {
  switch (s) {
    case EscalationState::kWatching:
      return "watching";
    case EscalationState::kLowering:
      return "lowering";
    case EscalationState::kLowered:
      return "lowered";
    case EscalationState::kDisengaged:
      return "disengaged";
  }
  return "?";
}

bool EscalationLadder::settle(std::int64_t now_ns) noexcept {
  if (state_ != EscalationState::kLowering || now_ns < settles_at_ns_) return false;
  state_ = EscalationState::kLowered;
  return true;
}

EscalationAction EscalationLadder::on_finding(std::int64_t now_ns,
                                              std::int64_t lasting_ns) noexcept {
  if (lasting_ns < escalation_ns_) return EscalationAction::kWarn;
  switch (state_) {
    case EscalationState::kWatching:
      state_ = EscalationState::kLowering;
      settles_at_ns_ = now_ns + settle_ns_;
      return EscalationAction::kLowerFixtures;
    case EscalationState::kLowered:
      state_ = EscalationState::kDisengaged;
      return EscalationAction::kDisengage;
    case EscalationState::kLowering:
    case EscalationState::kDisengaged:
      return EscalationAction::kNone;
  }
  return EscalationAction::kNone;
}

void EscalationLadder::end_check(std::int64_t now_ns, bool any_finding) noexcept {
  const bool settled =
      state_ == EscalationState::kLowered || state_ == EscalationState::kDisengaged;
  if (!any_finding && settled && now_ns - settles_at_ns_ > 2 * escalation_ns_) {
    state_ = EscalationState::kWatching;
  }
}

}  // namespace teleop::supervisor
