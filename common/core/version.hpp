// teleop's version: the project version CMake was configured with (CMakeLists.txt `project`).
// `--version` of every program prints it, and a recorded session names it. The number comes
// from a header CMake generates (common/core/version_number.hpp.in), so that only the files that
// include this one see it.
#pragma once

#include <string_view>

#include "common/core/version_number.hpp"  // generated in the build tree

namespace teleop {

inline constexpr std::string_view kVersion = TELEOP_VERSION;

}  // namespace teleop
