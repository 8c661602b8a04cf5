// Issue 15's example: 500 Hz, a fixed human; stable up to about 1325 N/m of slave fixture,
// unstable to about 1357 N/m, stable again above (each by the 50-digit reference in
// test_exact_limits.cpp). Shared by the stability and the supervisor's guard tests.
#pragma once

#include "common/core/teleop_params.hpp"

namespace teleop::test {

inline TeleopParams window_example() {
  TeleopParams p;
  p.sample_rate_hz = 500.0;
  p.master_device = {0.04, 0.41};
  p.slave_device = {0.036, 0.49};
  p.gains = Gains{1018.83, 141.622, 2.71629, 0.68129, 0, 0, 0};
  p.scaling = {1.0, 2.0};
  p.velocity_cutoff_hz = 100.0;
  p.human.kind = HumanKind::kFixed;
  p.human.fixed = {0.01, 3.179, 300.0};
  return p;
}

}  // namespace teleop::test
