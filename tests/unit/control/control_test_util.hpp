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

// Every feature on, so every branch of a step runs: fixtures, filter, force channel, limits,
// clutch fades (T = 1 ms).
[[nodiscard]] inline LawParams busy_params() {
  LawParams p;
  p.period_s = kPeriod_s;
  p.gains = {
      .kpm = 400.0, .kps = 500.0, .kdm = 4.0, .kds = 5.0, .kvm = 1.0, .kvs = 1.5, .kfm = 0.5};
  p.scaling = {.position = 1.5, .force = 0.8};
  p.master_fixture = {800.0, 0.01};
  p.slave_fixture = {1000.0, 0.015};
  p.velocity_cutoff_hz = 200.0;
  p.master_actuator = {4.0, 2000.0};
  p.slave_actuator = {6.0, 3000.0};
  p.slave_limits = {-0.03, 0.03, 0.5, 5.0};
  p.clutch_fade_s = 0.02;
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
