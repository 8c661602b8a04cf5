// What identify() (identify.cpp) and identify_axes() (identify_axes.cpp) share: the bounds
// that decide when a run cannot be identified, and the number format of their messages.
#pragma once

#include <sstream>
#include <string>

namespace teleop::stability::detail {

// A condition number of the column-normalised D above this means x'' and x' are proportional
// to within 1e-8 of a unit vector: m and b cannot be told apart.
inline constexpr double kMaxConditionNumber = 1e8;
// Derivatives this small against the position's scale are rounding, not motion.
inline constexpr double kNegligibleRelative = 1e-10;
inline constexpr int kMaxSmoothingPasses = 1000;

// A number as an error message prints it (the stream's default format).
[[nodiscard]] inline std::string str(double value) {
  std::ostringstream os;
  os << value;
  return os.str();
}

}  // namespace teleop::stability::detail
