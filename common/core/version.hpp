// The project's version (CMakeLists.txt `project(teleop VERSION ...)`), compiled in once
// (version.cpp.in, configured by CMake): session files name it in their MCAP header and
// metadata.
#pragma once

#include <string_view>

namespace teleop {

// "0.1.0".
[[nodiscard]] std::string_view version() noexcept;

}  // namespace teleop
