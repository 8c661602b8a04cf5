// The operator console's screen (issue 6), drawn from the supervisor's summary stream: a pure
// function from what the console knows to rows of text, so that what the screen shows is
// tested without a terminal, and the terminal front end (console_command.cpp) only copies the
// rows out. ASCII only, no colour: it works in any 80x24 terminal.
#pragma once

#include <cstddef>
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
  std::string clock{};   // wall clock HH:MM:SS
  double clock_s{-1.0};  // the same, seconds since midnight (with fractions); < 0: unknown
  // Every alarm the console has seen, newest first (AlarmHistory); empty: the summary's own
  // (its newest 20).
  std::vector<v1::Alarm> alarm_history{};
  // Nodes of several task-space axes (issue 18): the per-axis table (key t) under the node rows.
  bool axes_table{false};
};

// The alarms of every summary received, newest first, each once: the summary carries only the
// supervisor's newest 20, so a burst of repeated warnings would otherwise push older alarms
// out of sight. A summary whose clock went back (a replay seeked back) starts the history over.
class AlarmHistory {
 public:
  explicit AlarmHistory(std::size_t capacity = 1000) : capacity_(capacity) {}
  void merge(const v1::SupervisorStatus& s);
  [[nodiscard]] const std::vector<v1::Alarm>& newest_first() const noexcept { return alarms_; }

 private:
  [[nodiscard]] bool seen(const v1::Alarm& a) const;
  std::size_t capacity_;
  std::vector<v1::Alarm> alarms_{};
  std::int64_t last_status_ns_{0};
};

// The screen's layout (render_console), in rows:
// - the header; then, each wrapped whole onto as many rows as it needs, a SAFE/FAULT banner
//   per node in safe or fault (with its reason), the experiment banner, a configuration
//   mismatch;
// - the node table (a node's reason that does not fit its row continues on detail rows
//   below it), the link, the plots (4 rows; one more per 4 rows the terminal has beyond 24, up
//   to 8), stability, monitors, recorder, the alarm count;
// - the alarms, newest first: warnings of one kind, side and message grouped into one entry
//   ("x37", when the newest was), every other alarm on its own, each word-wrapped onto the
//   rows it needs while every later one still gets one (one that needs more shows its rows a
//   page at a time, turning every 3 s of `clock_s`, " [p/N]" ending the page's first row);
//   every row the terminal has beyond these goes to the alarms;
// - at least 3 message rows, then the key line.
// - nodes of n > 1 task-space axes: the node row shows the norms |x| and |F| of the newest
//   cycle, and a row under it |u| (the command's norm) and the worst axes, "axis k" with the
//   largest |force| and "axis j" with the largest |tracking error| (alpha x_m - x_s); with
//   axes_table, a table under the node rows, one row per axis: each side's x, F and u and e.
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
