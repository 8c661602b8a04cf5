// TELEOP_RT marks a function that runs on a node's real-time thread (docs/architecture.md
// §4.1, §4.6): it allocates nothing, takes no lock, does no I/O and never throws. Write it
// first in the declaration, and declare the function noexcept:
//
//   TELEOP_RT [[nodiscard]] double step(double position_m) noexcept;
//
// It expands to nothing; scripts/check-rt.sh reads it. For every marked function it requires
// `noexcept` and finds the body (in the class, or `Class::name` in a source file of the same
// directory), which must not name any of the forbidden calls (new, malloc, std::string,
// locks, printf/spdlog/fmt, throw, growing a container, ...). Mark what a marked function
// calls too; the allocation-counting tests (§4.3) check the whole path at run time.
#pragma once

#define TELEOP_RT
