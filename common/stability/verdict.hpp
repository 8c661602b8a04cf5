#pragma once

#include <string_view>

namespace teleop::stability {

// A verdict within the numerical error of its computation is kUncertain, never a guess.
enum class Verdict { kStable, kUnstable, kUncertain };

[[nodiscard]] constexpr std::string_view to_string(Verdict v) {
  switch (v) {
    case Verdict::kStable:
      return "stable";
    case Verdict::kUnstable:
      return "unstable";
    case Verdict::kUncertain:
      return "uncertain";
  }
  return "uncertain";
}

}  // namespace teleop::stability
