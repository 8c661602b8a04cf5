// The progress of long work on a terminal (issue 17, "CLI conventions"): one line on stderr,
// "simulate: 37%", redrawn at most ten times a second and erased when the work is done. Never
// when stderr is not a terminal (a pipe, a file, a test) nor under --json, so that no script
// reads it.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <ostream>
#include <string>
#include <utility>

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

  // Work in parts (passes over a file, then a computation): the part between `begin` and `end`
  // of the whole, as a callback of its own fraction, or of its bytes done of a total. Empty
  // when the line is not shown, so that the work skips the calls.
  [[nodiscard]] std::function<void(double fraction)> part(double begin, double end);
  [[nodiscard]] std::function<void(std::uint64_t done, std::uint64_t total)> part_bytes(
      double begin, double end);

 private:
  std::ostream& err_;
  std::string label_;
  bool enabled_;
  bool drawn_{false};
  std::chrono::steady_clock::time_point next_draw_{};
};

// Consecutive parts of one progress line, each given the time it takes (in any one unit, as
// measured): each call hands out the next part (see ProgressLine::part).
class ProgressParts {
 public:
  ProgressParts(ProgressLine& line, double total_time) : line_(line), total_(total_time) {}
  [[nodiscard]] std::function<void(std::uint64_t done, std::uint64_t total)> bytes(double time);
  [[nodiscard]] std::function<void(double fraction)> fraction(double time);

 private:
  [[nodiscard]] std::pair<double, double> next(double time);
  ProgressLine& line_;
  double total_;
  double at_{0.0};
};

[[nodiscard]] bool stderr_is_terminal();

}  // namespace teleop::ctl
