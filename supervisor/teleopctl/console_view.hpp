// The operator console's screen (issue 6), drawn from the supervisor's summary stream: a pure
// function from what the console knows to rows of text, so that what the screen shows is
// tested without a terminal, and the terminal front end (console_command.cpp) only copies the
// rows out. ASCII only, no colour: it works in any 80x24 terminal.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "teleop/v1/supervisor.pb.h"

namespace teleop::ctl {

struct ConsoleView {
  // The newest summary, and how long ago (console's clock) it arrived.
  std::optional<v1::SupervisorStatus> status{};
  std::int64_t status_age_ns{0};
  std::string source{};  // where the summary comes from, e.g. "tcp://127.0.0.1:5566"
  bool replay{false};    // watching `teleopctl replay --speed`: replay keys, no commands
  bool read_only{false};
  // Feedback of the last commands, oldest first (the last two are shown).
  std::vector<std::string> messages{};
  // The line being typed (set, seek), shown with its prompt; empty: none.
  std::string prompt{};
  bool help{false};
  std::string clock{};  // wall clock HH:MM:SS
};

// The screen, `rows` lines of at most `cols` characters.
[[nodiscard]] std::vector<std::string> render_console(const ConsoleView& view, int rows, int cols);

// One small scrolling plot: `rows` x `width` characters of two traces (each bucket's min..max
// band), 'm' for the first, 's' for the second, '#' where both; newest on the right, the
// shared range autoscaled. Empty traces give blank rows.
[[nodiscard]] std::vector<std::string> render_plot(const v1::Trace& a, const v1::Trace& b, int rows,
                                                   int width, double scale);

// The margin bar: `width` characters, filled in proportion to configured / maximum, '|' at
// the maximum; beyond it (unstable) the bar ends in '!'.
[[nodiscard]] std::string margin_bar(double configured, double maximum, int width);

}  // namespace teleop::ctl
