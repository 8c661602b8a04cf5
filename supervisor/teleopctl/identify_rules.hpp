// What `teleopctl identify` trusts, with one axis or several (identify_command.cpp,
// identify_axes_command.cpp): how well the model must explain the force, how far the position
// must move in steps of its resolution, and how that resolution is read from the data.
#pragma once

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace teleop::ctl::identify_rules {

// A fit below this explains too little of the force to trust (the paper's were 0.91 and 0.92):
// the parameters are not printed.
inline constexpr double kPoorFit = 0.9;
// A motion over fewer steps of the position's resolution (encoder counts) than this is refused:
// the quantisation, +-1/2 step, is then more than 5 % of the range, and after smoothing the
// staircase still dominates x'' (noise in a regressor biases its coefficient towards 0).
inline constexpr double kMinRangeSteps = 10.0;
// The data do not determine the parameters (too little excitation): nothing printed to paste.
inline constexpr int kExitNotIdentified = 4;

// How far a position moved: the largest range over its runs, and its resolution as the data
// show it (the smallest step between two distinct positions: an encoder count; 0 for a
// continuous sensor).
struct Motion {
  double range_m{0.0};
  double step_m{0.0};
  [[nodiscard]] bool quantised() const { return step_m > 0.0; }
  [[nodiscard]] double steps() const { return quantised() ? range_m / step_m : 0.0; }
};

// One position series per run.
[[nodiscard]] inline Motion motion_of(const std::vector<std::vector<double>>& runs) {
  Motion m;
  double smallest = std::numeric_limits<double>::infinity();
  for (std::vector<double> x : runs) {
    std::sort(x.begin(), x.end());
    if (x.empty()) continue;
    m.range_m = std::max(m.range_m, x.back() - x.front());
    // Steps below this are rounding of one position computed two ways, not resolution.
    const double rounding = 1e-9 * std::max(std::abs(x.front()), std::abs(x.back()));
    for (std::size_t i = 1; i < x.size(); ++i) {
      const double d = x[i] - x[i - 1];
      if (d > rounding) smallest = std::min(smallest, d);
    }
  }
  // A resolution finer than a millionth of the motion is a continuous sensor.
  if (std::isfinite(smallest) && smallest > 1e-6 * m.range_m) m.step_m = smallest;
  return m;
}

}  // namespace teleop::ctl::identify_rules
