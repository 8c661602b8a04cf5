// Shared helpers of the control tests.
#pragma once

#include "common/control/command.hpp"
#include "common/control/law_params.hpp"

namespace teleop::control::test {

inline constexpr double kPeriod_s = 1e-3;

// T = 1 ms, every gain 0, unit scaling, no fixture, no limit, no clutch fade.
[[nodiscard]] inline LawParams bare_params() {
  LawParams p;
  p.period_s = kPeriod_s;
  p.clutch_fade_s = 0.0;
  return p;
}

[[nodiscard]] inline PeerState peer(double position_m, double velocity_m_per_s = 0.0,
                                    double force_N = 0.0, bool clutched = false) {
  PeerState s;
  s.position_m = position_m;
  s.velocity_m_per_s = velocity_m_per_s;
  s.force_N = force_N;
  s.clutched = clutched;
  s.valid = true;
  return s;
}

}  // namespace teleop::control::test
