#pragma once

#include <string_view>

namespace teleop::stability {

// A verdict within the numerical error of its computation is kUncertain, never a guess.
// kInvalid: the model itself is not a number (a matrix entry or an eigenvalue is NaN or
// infinite, e.g. a gain of 1e308): nothing can be said, and it never counts as stable.
enum class Verdict { kStable, kUnstable, kUncertain, kInvalid };

[[nodiscard]] constexpr std::string_view to_string(Verdict v) {
  switch (v) {
    case Verdict::kStable:
      return "stable";
    case Verdict::kUnstable:
      return "unstable";
    case Verdict::kUncertain:
      return "uncertain";
    case Verdict::kInvalid:
      return "invalid";
  }
  return "uncertain";
}

}  // namespace teleop::stability
