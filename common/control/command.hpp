// What the control laws exchange with their peer and hand to their actuator.
#pragma once

namespace teleop::control {

// The newest state received from the other side (and, from peer_state(), the state to send).
struct PeerState {
  double position_m{0.0};        // sender's coordinates (the master's net of its clutch offset)
  double velocity_m_per_s{0.0};  // the sender's own filtered velocity
  double force_N{0.0};           // slave -> master: measured environment force F_e (for K_fm)
  bool clutched{false};          // master -> slave: the master is indexing, hold the reference
  bool valid{false};             // false: nothing received yet, or the sender is faulted
};

struct CommandFlags {
  bool saturated{false};          // an actuator (or slave force) limit clipped the command
  bool rate_limited{false};       // the actuator rate limit clipped the command
  bool limit_violation{false};    // slave outside its position or velocity limits: safe command
  bool reference_limited{false};  // slave reference outside the position limits: clamped
  bool input_fault{false};        // non-finite input seen: 0 N, latched until reset()
};

// One sample's actuator command and what explains it.
struct Command {
  double force_N{0.0};          // to the actuator (after limits)
  double fixture_force_N{0.0};  // this side's virtual-fixture force K (x - p), >= 0
  double penetration_m{0.0};    // x - p inside the fixture, else 0 (0 when there is no fixture)
  CommandFlags flags{};
};

}  // namespace teleop::control
