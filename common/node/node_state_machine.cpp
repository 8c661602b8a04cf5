#include "common/node/node_state_machine.hpp"

#include <algorithm>

namespace teleop::node {

const char* to_string(Mode m) noexcept {
  switch (m) {
    case Mode::kDisarmed:
      return "disarmed";
    case Mode::kArmed:
      return "armed";
    case Mode::kAligning:
      return "aligning";
    case Mode::kEngaged:
      return "engaged";
    case Mode::kClutched:
      return "clutched";
    case Mode::kSafe:
      return "safe";
    case Mode::kFault:
      return "fault";
  }
  return "fault";
}

void NodeStateMachine::go(Mode m, const char* why, std::chrono::nanoseconds now) noexcept {
  // Unclutching continues the engagement (the law absorbs the clutch offset): the coupling
  // ramps in only when engaging from alignment.
  if (m == Mode::kEngaged && mode_ != Mode::kEngaged && mode_ != Mode::kClutched) {
    engaged_at_ = now;
  }
  mode_ = m;
  reason_ = why;
}

bool NodeStateMachine::coupling_lost(const CycleInputs& in, bool peer_fresh,
                                     bool peer_may_disengage) noexcept {
  if (in.own_stall != nullptr) {
    go(Mode::kSafe, in.own_stall, in.now);
  } else if (!peer_fresh) {
    go(Mode::kSafe, "peer timeout", in.now);
  } else if (in.peer_failed) {
    go(Mode::kSafe, "peer safe, faulted or restarted", in.now);
  } else if (peer_may_disengage && in.peer_disengaged) {
    go(Mode::kArmed, "peer disengaged", in.now);
  } else {
    return false;
  }
  return true;
}

CycleOutputs NodeStateMachine::step(const CycleInputs& in) noexcept {
  const Mode from = mode_;
  const bool peer_fresh = in.peer_seen && in.peer_age <= params_.peer_timeout;
  bool refused = false;
  // Safety first, from any state: e-stop and faults win over everything else.
  if (in.command == Command::kEStop && mode_ != Mode::kFault) {
    go(Mode::kSafe, "e-stop", in.now);
  } else if ((in.device_fault || in.law_fault) && mode_ != Mode::kFault) {
    go(Mode::kFault, in.device_fault ? kDeviceFaultReason : "control law fault", in.now);
  } else {
    switch (mode_) {
      case Mode::kDisarmed:
        if (in.command == Command::kArm) {
          if (in.coupling_refusal != nullptr) {
            reason_ = in.coupling_refusal;
            refused = true;
          } else {
            go(Mode::kArmed, "arm", in.now);
          }
        } else if (in.command == Command::kEngage && in.coupling_refusal != nullptr) {
          // Not armed anyway; the configuration's refusal is the reason that matters.
          reason_ = in.coupling_refusal;
          refused = true;
        }
        break;
      case Mode::kArmed:
        if (in.command == Command::kEngage) {
          if (in.coupling_refusal != nullptr) {
            reason_ = in.coupling_refusal;
            refused = true;
          } else if (peer_fresh) {
            go(Mode::kAligning, "engage: aligning", in.now);
          } else {
            reason_ = "engage refused: no fresh peer state";
          }
        } else if (in.command == Command::kDisengage) {
          go(Mode::kDisarmed, "disarm", in.now);
        }
        break;
      case Mode::kAligning:
        if (coupling_lost(in, peer_fresh, false)) break;
        if (in.command == Command::kDisengage) {
          go(Mode::kArmed, "disengage", in.now);
        } else if (in.aligned) {
          go(Mode::kEngaged, "aligned", in.now);
        }
        break;
      case Mode::kEngaged:
        if (coupling_lost(in, peer_fresh, true)) break;
        if (in.command == Command::kDisengage) {
          go(Mode::kArmed, "disengage", in.now);
        } else if (in.command == Command::kClutch) {
          go(Mode::kClutched, "clutch", in.now);
        }
        break;
      case Mode::kClutched:
        if (coupling_lost(in, peer_fresh, true)) break;
        if (in.command == Command::kDisengage) {
          go(Mode::kArmed, "disengage", in.now);
        } else if (in.command == Command::kUnclutch) {
          go(Mode::kEngaged, "unclutch", in.now);
        }
        break;
      case Mode::kSafe:
        // Latched: only an operator's clear leaves it, and then to disarmed (re-engaging
        // needs arm, engage and alignment again).
        if (in.command == Command::kClear) go(Mode::kDisarmed, "cleared", in.now);
        break;
      case Mode::kFault:
        if (in.command == Command::kClear) {
          if (in.device_fault || in.law_fault) {
            reason_ = "clear refused: fault still present";
          } else {
            go(Mode::kDisarmed, "cleared", in.now);
          }
        }
        break;
    }
  }

  // At most one transition per step: its entry actions, once.
  if (mode_ != from && on_enter_ != nullptr)
    on_enter_->on_enter(from, mode_, entry_actions(from, mode_));

  CycleOutputs out;
  out.mode = mode_;
  out.reason = reason_;
  out.refused = refused;
  out.actuators_enabled =
      mode_ == Mode::kAligning || mode_ == Mode::kEngaged || mode_ == Mode::kClutched;
  out.centring = mode_ == Mode::kAligning;
  if (mode_ == Mode::kEngaged || mode_ == Mode::kClutched) {
    const double ramp = static_cast<double>(params_.engage_ramp.count());
    const double since = static_cast<double>((in.now - engaged_at_).count());
    out.coupling_weight = ramp <= 0.0 ? 1.0 : std::clamp(since / ramp, 0.0, 1.0);
  }
  return out;
}

}  // namespace teleop::node
