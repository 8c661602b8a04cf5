// The progress of long work on a terminal (issue 17, "CLI conventions"): one line on stderr,
// "simulate: 37%", redrawn at most ten times a second and erased when the work is done. Never
// when stderr is not a terminal (a pipe, a file, a test) nor under --json, so that no script
// reads it.
#pragma once

#include <chrono>
#include <cstddef>
#include <ostream>
#include <string>

namespace teleop::ctl {

class ProgressLine {
 public:
  // `enabled` false: does nothing (callers pass `!json && stderr_is_terminal()`).
  ProgressLine(std::ostream& err, std::string label, bool enabled);
  ~ProgressLine();
  ProgressLine(const ProgressLine&) = delete;
  ProgressLine& operator=(const ProgressLine&) = delete;

  // `fraction` of the work done, in [0, 1].
  void update(double fraction);
  // `done` of `total` steps.
  void update(std::size_t done, std::size_t total);

 private:
  std::ostream& err_;
  std::string label_;
  bool enabled_;
  bool drawn_{false};
  std::chrono::steady_clock::time_point next_draw_{};
};

[[nodiscard]] bool stderr_is_terminal();

}  // namespace teleop::ctl
