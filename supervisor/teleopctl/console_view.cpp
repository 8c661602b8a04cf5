#include "supervisor/teleopctl/console_view.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <filesystem>

namespace teleop::ctl {
namespace {

// The message area above the key line: at least 3 rows, and up to 6 when the alarms leave
// them free, so that a prediction and its verdict are on screen whole.
constexpr int kMinMessageRows = 3;
constexpr int kMaxMessageRows = 6;
constexpr std::size_t kAlarmIndent = 9;  // continuation rows start under the message
// An alarm whose rows do not all fit shows them a page at a time, each for this long, with
// " [p/N]" at the end of the page's first row.
constexpr double kAlarmPageSeconds = 3.0;
constexpr int kPageMarkWidth = 6;  // " [p/N]" for N up to 9

std::string fit(std::string s, int cols) {
  if (cols <= 0) return {};
  if (s.size() > static_cast<std::size_t>(cols)) s.resize(static_cast<std::size_t>(cols));
  return s;
}

std::string pad(std::string s, std::size_t width) {
  if (s.size() > width) s.resize(width);
  s.append(width - s.size(), ' ');
  return s;
}

// Word wrap to `cols`: breaks at the last space that fits, or at the width when that space
// would leave more than half the row empty; continuation rows indented by `indent`.
std::vector<std::string> wrap(const std::string& text, int cols, std::size_t indent = 0) {
  const auto width = static_cast<std::size_t>(std::max(1, cols));
  if (indent + 8 > width) indent = 0;
  std::vector<std::string> out;
  std::string rest = text;
  std::string lead;
  while (lead.size() + rest.size() > width) {
    const std::size_t room = width - lead.size();
    std::size_t cut = rest.rfind(' ', room);
    std::size_t next = cut + 1;
    // No space in the row's second half (a long path): cut at the width rather than leave
    // most of the row empty.
    if (cut == std::string::npos || cut < room / 2) {
      cut = room;
      next = room;
    }
    out.push_back(lead + rest.substr(0, cut));
    rest = rest.substr(next);
    lead.assign(indent, ' ');
  }
  out.push_back(lead + rest);
  return out;
}

std::string mode_name(const v1::NodeSummary& n) {
  if (n.mode() == v1::NODE_MODE_UNSPECIFIED && !n.alive()) return "-";
  const std::string name = v1::NodeMode_Name(n.mode());
  return n.alive() ? name : "SILENT";
}

std::string rt_text(const v1::RtStatus& rt) {
  // Compact: FIFO priority (or OTHER), "lock" for locked memory, "c<N>" for a pinned CPU,
  // "!<N>" for settings the kernel refused.
  std::string s = rt.fifo_priority() > 0 ? fmt::format("FIFO{}", rt.fifo_priority()) : "OTHER";
  if (rt.memory_locked()) s += " lock";
  if (rt.cpu() >= 0 && rt.fifo_priority() > 0) s += fmt::format(" c{}", rt.cpu());
  if (rt.refused_size() > 0) s += fmt::format(" !{}", rt.refused_size());
  return s;
}

bool stopped(const v1::NodeSummary& n) { return n.mode() == v1::SAFE || n.mode() == v1::FAULT; }

// A node of n > 1 task-space axes whose summary holds every per-axis list whole.
bool several_axes(const v1::NodeSummary& n) {
  const int a = static_cast<int>(n.axes());
  return a > 1 && n.positions_m_size() == a && n.forces_n_size() == a && n.commands_n_size() == a &&
         n.tracking_errors_m_size() == a;
}

double norm(const google::protobuf::RepeatedField<double>& v) {
  double s = 0.0;
  for (const double x : v) s += x * x;
  return std::sqrt(s);
}

// The axis of the largest magnitude (the first of equals).
int largest(const google::protobuf::RepeatedField<double>& v) {
  int k = 0;
  for (int i = 1; i < v.size(); ++i) {
    if (std::abs(v.Get(i)) > std::abs(v.Get(k))) k = i;
  }
  return k;
}

std::string node_row(const char* name, const v1::NodeSummary& n) {
  if (n.mode() == v1::NODE_MODE_UNSPECIFIED && !n.alive() && n.loop().cycles() == 0) {
    return fmt::format("{:<6} -  (no telemetry yet)", name);
  }
  std::string row =
      fmt::format("{:<6} {:<9} {:>6.1f} {:>5.0f}us {:>5}/{:<4} {:<14}", name, mode_name(n),
                  n.loop_rate_hz(), static_cast<double>(n.loop().wakeup_p99_ns()) * 1e-3,
                  n.loop().overruns(), n.overruns_last_minute(), pad(rt_text(n.rt()), 14));
  if (stopped(n) || !n.alive()) {
    // The reason: add_node_rows.
  } else if (n.mode() == v1::ALIGNING) {
    // What the operator is being guided to close: alpha x_m - x_s.
    row += fmt::format(" x{:+6.2f}mm gap{:+6.2f}mm", n.position_m() * 1e3,
                       n.alignment_error_m() * 1e3);
  } else if (several_axes(n)) {
    row +=
        fmt::format(" |x|{:5.2f}mm |F|{:4.2f}N", norm(n.positions_m()) * 1e3, norm(n.forces_n()));
  } else {
    row += fmt::format(" x{:+6.2f}mm F{:+5.2f}N", n.position_m() * 1e3, n.force_n());
  }
  return row;
}

// Under the node row of a node of several axes: the command's norm and the worst axes.
std::string axes_row(const v1::NodeSummary& n) {
  const int f = largest(n.forces_n());
  const int e = largest(n.tracking_errors_m());
  return fmt::format("       {} axes |u|{:5.2f}N  worst: F axis {} {:+.2f}N, e axis {} {:+.2f}mm",
                     n.axes(), norm(n.commands_n()), f, n.forces_n(f), e,
                     n.tracking_errors_m(e) * 1e3);
}

// One row per axis of both nodes (the axes of the node with more; "-" where a node has none).
void add_axes_table(std::vector<std::string>& lines, const v1::SupervisorStatus& s) {
  const v1::NodeSummary& m = s.master();
  const v1::NodeSummary& l = s.slave();
  const bool has_m = several_axes(m);
  const bool has_s = several_axes(l);
  if (!has_m && !has_s) return;
  lines.push_back(fmt::format("{:<6}{:>13} {:>6} {:>6}{:>13} {:>6} {:>6} {:>10}", "axis",
                              "master x mm", "F N", "u N", "slave x mm", "F N", "u N", "e mm"));
  const int axes = static_cast<int>(std::max(has_m ? m.axes() : 0U, has_s ? l.axes() : 0U));
  auto side = [](const v1::NodeSummary& n, bool has, int k) {
    if (!has || k >= static_cast<int>(n.axes())) return fmt::format("{:>27}", "-");
    // + 0.0: a negative zero prints as 0.00.
    return fmt::format("{:>13.2f} {:>6.2f} {:>6.2f}", n.positions_m(k) * 1e3 + 0.0,
                       n.forces_n(k) + 0.0, n.commands_n(k) + 0.0);
  };
  for (int k = 0; k < axes; ++k) {
    const v1::NodeSummary& e = has_m && k < static_cast<int>(m.axes()) ? m : l;
    lines.push_back(fmt::format("axis {}{}{} {:>+10.3f}", k, side(m, has_m, k), side(l, has_s, k),
                                e.tracking_errors_m(k) * 1e3));
  }
}

std::string link_row(const v1::SupervisorStatus& s) {
  const v1::LinkStats& m = s.master().link();
  const v1::LinkStats& l = s.slave().link();
  return fmt::format(
      "link   rtt {:.2f} p99 {:.2f} ms {} smp  loss m{:.2f}% s{:.2f}%  age m{:.1f} s{:.1f} ms",
      static_cast<double>(m.round_trip_ns()) * 1e-6,
      static_cast<double>(std::max(m.round_trip_p99_ns(), l.round_trip_p99_ns())) * 1e-6,
      std::max(m.round_trip_samples(), l.round_trip_samples()), 100.0 * m.loss_fraction(),
      100.0 * l.loss_fraction(), static_cast<double>(m.peer_age_ns()) * 1e-6,
      static_cast<double>(l.peer_age_ns()) * 1e-6);
}

std::string fixture_row(const char* side, double configured, bool has_max, double maximum,
                        double margin, int cols, std::optional<double> below,
                        std::optional<double> above) {
  if (!(configured > 0.0)) return fmt::format("{:<6} fixture none", side);
  if (!has_max) return fmt::format("{:<6} fixture {:.0f} N/m (no finite limit)", side, configured);
  const std::string head =
      fmt::format("{:<6} fixture {:>6.0f} of {:>6.0f} N/m ", side, configured, maximum);
  // The distances to the nearest crossings below and above (docs/stability-limits.md).
  const std::string tail =
      fmt::format(" margin {:>4.0f}% x{}/{}", 100.0 * margin,
                  below ? fmt::format("-{:.0f}", configured - *below) : std::string("-"),
                  above ? fmt::format("+{:.0f}", *above - configured) : std::string("+"));
  const int width = std::max(10, cols - static_cast<int>(head.size() + tail.size()));
  return head + margin_bar(configured, maximum, width) + tail;
}

std::string short_severity(v1::Alarm::Severity s) {
  switch (s) {
    case v1::Alarm::INFO:
      return "INFO";
    case v1::Alarm::WARNING:
      return "WARN";
    case v1::Alarm::ACTION:
      return "ACTN";
    case v1::Alarm::CRITICAL:
      return "CRIT";
    default:
      return "?";
  }
}

// A node's row, and its reason after it: on the row when it fits whole; else, for a node in
// safe or fault (whose banner says the reason whole), a pointer to the banner; else on detail
// rows under it, word-wrapped.
void add_node_rows(std::vector<std::string>& lines, const char* name, const v1::NodeSummary& n,
                   int cols) {
  std::string row = node_row(name, n);
  const std::string& reason = n.mode_reason();
  if ((!stopped(n) && n.alive()) || reason.empty() ||
      static_cast<int>(row.size() + 1 + reason.size()) <= cols) {
    if ((stopped(n) || !n.alive()) && !reason.empty()) row += " " + reason;
    lines.push_back(row);
    if (several_axes(n) && n.alive() && !stopped(n) && n.mode() != v1::ALIGNING) {
      lines.push_back(axes_row(n));
    }
    return;
  }
  if (stopped(n)) {
    lines.push_back(row + " (reason above)");
    return;
  }
  lines.push_back(row);
  constexpr std::size_t kDetailIndent = 7;  // under the state column
  for (const std::string& w : wrap(reason, cols - static_cast<int>(kDetailIndent))) {
    lines.push_back(std::string(kDetailIndent, ' ') + w);
  }
}

// docs/cli.md "console": one banner per node in safe or fault, naming the reason whole
// (wrapped); one for both when they stopped for the same reason.
void add_stop_banners(std::vector<std::string>& lines, const v1::SupervisorStatus& s, int cols) {
  auto reason = [](const v1::NodeSummary& n) {
    return (n.mode_reason().empty() ? std::string("no reason given") : n.mode_reason()) +
           (n.alive() ? "" : " (last known: the node is silent)");
  };
  std::vector<std::string> banners;
  const v1::NodeSummary& m = s.master();
  const v1::NodeSummary& sl = s.slave();
  if (stopped(m) && stopped(sl) && m.mode() == sl.mode() && reason(m) == reason(sl)) {
    banners.push_back(
        fmt::format("!! {} MASTER AND SLAVE: {}", v1::NodeMode_Name(m.mode()), reason(m)));
  } else {
    for (const auto& [side, n] : {std::pair{"MASTER", &m}, std::pair{"SLAVE", &sl}}) {
      if (stopped(*n)) {
        banners.push_back(
            fmt::format("!! {} {}: {}", v1::NodeMode_Name(n->mode()), side, reason(*n)));
      }
    }
  }
  for (const std::string& b : banners) {
    for (const std::string& w : wrap(b, cols, 3)) lines.push_back(w);
  }
}

// One entry of the alarm list: an alarm, or a run of warnings of one kind, side and message
// (the condition; the evidence may differ; not necessarily consecutive), shown as its newest
// with the count.
struct AlarmEntry {
  const v1::Alarm* newest;
  int count;
  std::int64_t oldest_ns;
};

std::vector<AlarmEntry> group_alarms(const ConsoleView& view, const v1::SupervisorStatus& s) {
  std::vector<const v1::Alarm*> all;
  if (view.alarm_history.empty()) {
    for (const v1::Alarm& a : s.recent_alarms()) all.push_back(&a);
  } else {
    for (const v1::Alarm& a : view.alarm_history) all.push_back(&a);
  }
  std::vector<AlarmEntry> out;
  for (const v1::Alarm* a : all) {  // newest first
    AlarmEntry* group = nullptr;
    for (AlarmEntry& e : out) {
      if (a->severity() == v1::Alarm::WARNING && e.newest->severity() == v1::Alarm::WARNING &&
          e.newest->kind() == a->kind() && e.newest->side() == a->side() &&
          e.newest->message() == a->message()) {
        group = &e;
        break;
      }
    }
    if (group) {
      ++group->count;
      group->oldest_ns = a->time_ns();
    } else {
      out.push_back({a, 1, a->time_ns()});
    }
  }
  return out;
}

std::string alarm_row(const AlarmEntry& entry, const ConsoleView& view, std::int64_t now_ns) {
  const v1::Alarm& a = *entry.newest;
  std::string ev;
  for (const v1::Evidence& e : a.evidence()) {
    ev += fmt::format(" {}={:.3g}{}", e.name(), e.value(), e.unit());
  }
  std::string repeats;
  if (entry.count > 1) {
    repeats = fmt::format(" x{} in {:.0f}s", entry.count,
                          static_cast<double>(a.time_ns() - entry.oldest_ns) * 1e-9);
    // The newest on the wall clock, live only (a replay's alarms are of another day).
    if (!view.replay && view.clock_s >= 0.0) {
      const double age_s = static_cast<double>(now_ns - a.time_ns() + view.status_age_ns) * 1e-9;
      // The second it happened in (1 us of slack for the subtraction's rounding).
      const long at_s = std::lround(std::floor(view.clock_s - age_s + 1e-6));
      const long wall = (at_s % 86400 + 86400) % 86400;
      repeats += fmt::format(", last {:02}:{:02}:{:02}", wall / 3600, wall / 60 % 60, wall % 60);
    }
  }
  return fmt::format("{:>7.1f}s {} {} {}{}: {}{}{}",
                     -static_cast<double>(now_ns - a.time_ns()) * 1e-9,
                     short_severity(a.severity()), a.kind(), a.side(), repeats, a.message(), ev,
                     a.action().empty() ? "" : " -> " + a.action());
}

double trace_lo(const v1::Trace& t, int width) {
  double lo = INFINITY;
  const int n = t.min_size();
  for (int i = std::max(0, n - width); i < n; ++i) lo = std::min(lo, static_cast<double>(t.min(i)));
  return lo;
}

double trace_hi(const v1::Trace& t, int width) {
  double hi = -INFINITY;
  const int n = t.max_size();
  for (int i = std::max(0, n - width); i < n; ++i) hi = std::max(hi, static_cast<double>(t.max(i)));
  return hi;
}

std::string plot_title(const char* name, const v1::Trace& a, const v1::Trace& b, int width,
                       double scale) {
  const double lo = std::min(trace_lo(a, width), trace_lo(b, width)) * scale;
  const double hi = std::max(trace_hi(a, width), trace_hi(b, width)) * scale;
  if (!std::isfinite(lo) || !std::isfinite(hi)) return fit(name, width);
  return fit(fmt::format("{} {:.3g}..{:.3g}", name, lo, hi), width);
}

std::vector<std::string> help_lines(bool replay) {
  if (replay) {
    return {
        "Watching a replay (teleopctl replay FILE --speed X): the session as the",
        "supervisor saw it; nothing here commands a robot.",
        "",
        "  space   pause / resume",
        "  , .     seek back / forward 5 s     < >  seek back / forward 30 s",
        "  [ ]     speed halved / doubled      0    back to the start",
        "  g       go to a time (s): Enter sends it, Esc cancels",
        "  ?       this help (any key closes)  q    quit (the replay goes on)",
        "  t       nodes of several axes: the per-axis table on / off",
    };
  }
  return {
      "Commands go to the supervisor, which forwards them to both nodes; each node's",
      "answer is shown below, and the node rows then show the state they report.",
      "",
      "  x   E-STOP both nodes: always available (here too; Ctrl-X while typing),",
      "      straight to the nodes when the supervisor does not answer.",
      "      Leaving safe: l clear, a arm, e engage.",
      "  a   arm            e  engage (aligning, then engaged)   d  disengage",
      "  c   clutch         u  unclutch                          l  clear a stop",
      "  s   set gains or a fixture stiffness, e.g. gains.kps=2000 or",
      "      slave.fixture.stiffness_N_per_m=800: the supervisor's prediction comes",
      "      first; y applies it, any other key cancels. Unstable is refused.",
      "  r   start / stop recording the session",
      "  ?   this help (any key closes)   q  quit the console (the system goes on)",
      "  t   nodes of several axes: the per-axis table (one row per axis) on / off",
      "",
      "A read-only console (read-only key or --read-only) can watch and e-stop only.",
  };
}

}  // namespace

void AlarmHistory::merge(const v1::SupervisorStatus& s) {
  if (s.time_ns() < last_status_ns_) alarms_.clear();
  last_status_ns_ = s.time_ns();
  std::vector<v1::Alarm> fresh;
  for (const v1::Alarm& a : s.recent_alarms()) {  // newest first
    // Older than the newest already kept: kept already (the summary came ten times a second).
    if (!alarms_.empty() && a.time_ns() < alarms_.front().time_ns()) break;
    if (!seen(a)) fresh.push_back(a);
  }
  alarms_.insert(alarms_.begin(), fresh.begin(), fresh.end());
  if (alarms_.size() > capacity_) alarms_.resize(capacity_);
}

bool AlarmHistory::seen(const v1::Alarm& a) const {
  const std::string bytes = a.SerializeAsString();
  for (const v1::Alarm& h : alarms_) {
    if (h.time_ns() < a.time_ns()) return false;  // newest first: only older ones from here
    if (h.time_ns() == a.time_ns() && h.SerializeAsString() == bytes) return true;
  }
  return false;
}

std::string margin_bar(double configured, double maximum, int width) {
  const int inner = std::max(3, width - 2);
  std::string bar(static_cast<std::size_t>(inner), '.');
  const double ratio = maximum > 0.0 ? configured / maximum : INFINITY;
  if (!(ratio <= 1.0)) {  // beyond the limit, or not a number: never drawn as a safe margin
    std::fill(bar.begin(), bar.end(), '#');
    bar.back() = '!';
  } else {
    const int filled = static_cast<int>(std::lround(std::max(0.0, ratio) * (inner - 1)));
    std::fill(bar.begin(), bar.begin() + filled, '#');
    bar.back() = '|';
  }
  return "[" + bar + "]";
}

std::vector<std::string> render_plot(const v1::Trace& a, const v1::Trace& b, int rows, int width,
                                     double scale) {
  std::vector<std::string> out(static_cast<std::size_t>(std::max(0, rows)),
                               std::string(static_cast<std::size_t>(std::max(0, width)), ' '));
  if (rows <= 0 || width <= 0) return out;
  double lo = std::min(trace_lo(a, width), trace_lo(b, width)) * scale;
  double hi = std::max(trace_hi(a, width), trace_hi(b, width)) * scale;
  if (!std::isfinite(lo) || !std::isfinite(hi)) return out;
  if (hi - lo < 1e-12 * std::max(1.0, std::abs(hi))) {
    lo -= 0.5;
    hi += 0.5;
  }
  auto row_of = [&](double v) {
    const double r = (hi - v) / (hi - lo) * (rows - 1);
    return std::clamp(static_cast<int>(std::lround(r)), 0, rows - 1);
  };
  for (const auto& [trace, mark] : {std::pair{&a, 'm'}, std::pair{&b, 's'}}) {
    const int n = std::min(trace->min_size(), trace->max_size());
    for (int i = std::max(0, n - width); i < n; ++i) {
      const int col = width - (n - i);
      const int top = row_of(static_cast<double>(trace->max(i)) * scale);
      const int bottom = row_of(static_cast<double>(trace->min(i)) * scale);
      for (int r = top; r <= bottom; ++r) {
        char& c = out[static_cast<std::size_t>(r)][static_cast<std::size_t>(col)];
        c = (c == ' ' || c == mark) ? mark : '#';
      }
    }
  }
  return out;
}

namespace {

std::string header_line(const ConsoleView& view, const v1::SupervisorStatus& s, int cols) {
  std::string header;
  if (view.replay) {
    const v1::ReplayPosition& r = s.replay();
    header = fmt::format("TELEOP REPLAY  {} {:.1f}/{:.1f} s  x{:g}  {}",
                         r.state().empty() ? "?" : r.state(), r.position_s(), r.duration_s(),
                         r.speed(), std::filesystem::path(r.file()).filename().string());
  } else {
    header = fmt::format("TELEOP CONSOLE  live {}  [{}]", view.source,
                         view.read_only ? "read-only" : "read-write");
  }
  if (!view.status) {
    header += "  WAITING FOR THE SUMMARY";
  } else if (view.status_age_ns > 1'000'000'000) {
    header +=
        fmt::format("  NO SUMMARY FOR {:.1f} s", static_cast<double>(view.status_age_ns) * 1e-9);
  }
  const std::string clock = view.clock.empty() ? "" : " " + view.clock;
  if (static_cast<int>(header.size() + clock.size()) < cols) {
    header = pad(header, static_cast<std::size_t>(cols) - clock.size()) + clock;
  }
  return header;
}

// Plots: positions, forces, penetration; 'm' master, 's' slave.
void add_plots(std::vector<std::string>& lines, const v1::SupervisorStatus& s, int rows, int cols) {
  const int plot_rows = std::clamp(4 + (rows - 24) / 4, 4, 8);
  const int width = std::max(8, (cols - 2) / 3);
  struct Panel {
    const char* name;
    const v1::Trace* a;
    const v1::Trace* b;
    double scale;
  };
  const Panel panels[] = {
      {"x mm", &s.master().position_trace_m(), &s.slave().position_trace_m(), 1e3},
      {"F N", &s.master().force_trace_n(), &s.slave().force_trace_n(), 1.0},
      {"pen mm", &s.master().penetration_trace_m(), &s.slave().penetration_trace_m(), 1e3},
  };
  std::string titles;
  std::vector<std::string> plot(static_cast<std::size_t>(plot_rows));
  for (const Panel& p : panels) {
    const std::string sep = titles.empty() ? "" : " ";
    titles +=
        sep + pad(plot_title(p.name, *p.a, *p.b, width, p.scale), static_cast<std::size_t>(width));
    const std::vector<std::string> rows_of = render_plot(*p.a, *p.b, plot_rows, width, p.scale);
    for (int r = 0; r < plot_rows; ++r) {
      plot[static_cast<std::size_t>(r)] += sep + rows_of[static_cast<std::size_t>(r)];
    }
  }
  lines.push_back(titles);
  for (const std::string& l : plot) lines.push_back(l);
}

// n > 1 axes, in the two rows one axis gives its two fixtures: the limiting plane against its
// limit (as a fixture row), then every plane's share of its limit ("s1 22%": slave plane 1).
void add_planes(std::vector<std::string>& lines, const v1::StabilityReport& r, int cols) {
  const v1::PlaneMargin* limiting = nullptr;
  std::string shares = "planes";
  for (const v1::PlaneMargin& p : r.planes()) {
    if (p.limiting() || limiting == nullptr) limiting = &p;
    shares += fmt::format(" {}{} ", p.side() == "master" ? "m" : "s", p.index());
    shares += p.has_fraction_of_limit() ? fmt::format("{:.0f}%", 100.0 * p.fraction_of_limit())
                                        : std::string("no limit");
  }
  if (limiting == nullptr) {
    lines.emplace_back("planes none");
    lines.emplace_back("");
    return;
  }
  const std::string name = fmt::format("{} plane {}", limiting->side(), limiting->index());
  lines.push_back(fixture_row(name.c_str(), limiting->stiffness_n_per_m(),
                              limiting->has_max_stable_stiffness_n_per_m(),
                              limiting->max_stable_stiffness_n_per_m(), limiting->margin(), cols,
                              std::nullopt, std::nullopt));
  if (static_cast<int>(shares.size()) > cols) shares.resize(static_cast<std::size_t>(cols));
  lines.push_back(shares);
}

// The verdict and each fixture's stiffness against its limit.
void add_stability(std::vector<std::string>& lines, const v1::StabilityReport& r, int cols) {
  if (r.verdict().empty()) {
    lines.emplace_back("stability: no report yet");
  } else {
    std::string verdict = r.verdict();
    std::transform(verdict.begin(), verdict.end(), verdict.begin(),
                   [](unsigned char c) { return static_cast<char>(std::toupper(c)); });
    lines.push_back(
        fmt::format("stability {}  zeta min {:.4f} (required {:.4f})  model: rtt {} smp, {:.1f} Hz",
                    verdict, r.min_damping_ratio(), r.required_damping_ratio(),
                    r.round_trip_samples(), r.sample_rate_hz()));
  }
  if (r.axes() > 1) {
    add_planes(lines, r, cols);
    return;
  }
  auto opt = [](bool has, double v) { return has ? std::optional<double>(v) : std::nullopt; };
  lines.push_back(fixture_row(
      "slave", r.slave_fixture_stiffness_n_per_m(), r.has_max_stable_slave_stiffness_n_per_m(),
      r.max_stable_slave_stiffness_n_per_m(), r.slave_margin(), cols,
      opt(r.has_slave_crossing_below_n_per_m(), r.slave_crossing_below_n_per_m()),
      opt(r.has_slave_crossing_above_n_per_m(), r.slave_crossing_above_n_per_m())));
  lines.push_back(fixture_row(
      "master", r.master_fixture_stiffness_n_per_m(), r.has_max_stable_master_stiffness_n_per_m(),
      r.max_stable_master_stiffness_n_per_m(), r.master_margin(), cols,
      opt(r.has_master_crossing_below_n_per_m(), r.master_crossing_below_n_per_m()),
      opt(r.has_master_crossing_above_n_per_m(), r.master_crossing_above_n_per_m())));
}

std::string monitors_row(const v1::SupervisorStatus& s) {
  auto osc = [](const v1::NodeSummary& n) {
    return fmt::format(
        "{:.3f}{}", n.oscillation_amplitude_m() * 1e3,
        n.oscillating() ? fmt::format(" OSC@{:.0f}Hz", n.oscillation_frequency_hz()) : "");
  };
  return fmt::format("monitors  oscillation m {} s {} mm  passivity m {:+.4f} s {:+.4f} J",
                     osc(s.master()), osc(s.slave()), s.master().passivity_energy_j(),
                     s.slave().passivity_energy_j());
}

std::string recorder_row(const v1::SupervisorStatus& s) {
  if (s.recording_file().empty()) {
    return fmt::format("recorder  off{}",
                       s.record_dir().empty() ? "" : " (r starts one in " + s.record_dir() + ")");
  }
  return fmt::format("recorder  {}{}  {:.1f} MB  {} msgs  {} drops",
                     s.recording_error().empty() ? "" : "STOPPED: ",
                     std::filesystem::path(s.recording_file()).filename().string(),
                     static_cast<double>(s.recording_bytes()) / 1e6, s.recorded_messages(),
                     s.recording_drops());
}

// Everything between the banners and the alarms when the help is not shown.
void add_system_rows(std::vector<std::string>& lines, const v1::SupervisorStatus& s,
                     std::size_t alarms, std::size_t entries, int rows, int cols, bool axes_table) {
  lines.push_back(fmt::format("{:<6} {:<9} {:>6} {:>7} {:>10} {:<14} {}", "node", "state",
                              "rate Hz", "wake p99", "overruns/1m", "RT", "now"));
  add_node_rows(lines, "master", s.master(), cols);
  add_node_rows(lines, "slave", s.slave(), cols);
  if (axes_table) add_axes_table(lines, s);
  lines.push_back(link_row(s));
  add_plots(lines, s, rows, cols);
  add_stability(lines, s.report(), cols);
  lines.push_back(monitors_row(s));
  lines.push_back(recorder_row(s));
  lines.push_back(fmt::format(
      "alarms (newest first): {}{}", alarms,
      entries < alarms ? fmt::format(", shown as {} with repeated warnings grouped", entries)
                       : ""));
}

// Messages, bottom up: the prompt, then the newest message's rows, ... (word-wrapped), at most
// kMaxMessageRows.
std::vector<std::string> message_area(const ConsoleView& view, int cols) {
  std::vector<std::string> area;
  if (!view.prompt.empty()) area.push_back(view.prompt);
  for (auto m = view.messages.rbegin();
       m != view.messages.rend() && static_cast<int>(area.size()) < kMaxMessageRows; ++m) {
    const std::vector<std::string> wrapped = wrap(*m, cols);
    for (auto w = wrapped.rbegin();
         w != wrapped.rend() && static_cast<int>(area.size()) < kMaxMessageRows; ++w) {
      area.push_back(*w);
    }
  }
  return area;
}

// One alarm on `take` rows: whole when it fits; else word-wrapped narrower (room for the
// mark) and shown a page of `take` rows at a time, the page turning every kAlarmPageSeconds
// of the wall clock (the first page when the clock is unknown), so that the whole text is read
// in turn in the same rows.
void add_alarm_rows(std::vector<std::string>& lines, const std::string& text, int take,
                    const ConsoleView& view, int cols) {
  const std::vector<std::string> whole = wrap(text, cols, kAlarmIndent);
  if (static_cast<int>(whole.size()) <= take || cols < 2 * kPageMarkWidth) {
    for (int r = 0; r < std::min(take, static_cast<int>(whole.size())); ++r) {
      lines.push_back(whole[static_cast<std::size_t>(r)]);
    }
    return;
  }
  const std::vector<std::string> rows = wrap(text, cols - kPageMarkWidth, kAlarmIndent);
  const auto per_page = static_cast<std::size_t>(take);
  const std::size_t pages = std::min<std::size_t>(9, (rows.size() + per_page - 1) / per_page);
  const std::size_t page =
      view.clock_s < 0.0
          ? 0
          : static_cast<std::size_t>(std::floor(view.clock_s / kAlarmPageSeconds)) % pages;
  for (std::size_t r = 0; r < per_page; ++r) {
    const std::size_t at = page * per_page + r;
    std::string row = at < rows.size() ? rows[at] : std::string();
    if (r == 0) {
      row = pad(row, static_cast<std::size_t>(cols - kPageMarkWidth)) +
            fmt::format(" [{}/{}]", page + 1, pages);
    }
    lines.push_back(row);
  }
}

// Alarms, newest first, each on as many rows as it needs while every later one still gets
// one; one that still does not fit pages through its rows (add_alarm_rows).
void add_alarms(std::vector<std::string>& lines, const ConsoleView& view,
                const std::vector<AlarmEntry>& entries, std::int64_t now_ns, int room, int cols) {
  const int alarms = static_cast<int>(entries.size());
  for (int i = 0; i < alarms && room > 0; ++i) {
    const std::string text = alarm_row(entries[static_cast<std::size_t>(i)], view, now_ns);
    const int needs = static_cast<int>(wrap(text, cols, kAlarmIndent).size());
    const int later = std::min(alarms - i - 1, room - 1);
    const int take = std::clamp(needs, 1, room - later);
    add_alarm_rows(lines, text, take, view, cols);
    room -= take;
  }
}

// What is left above the key line: the alarms, then the messages at the bottom.
void add_alarms_and_messages(std::vector<std::string>& lines, const ConsoleView& view,
                             const v1::SupervisorStatus& s, const std::vector<AlarmEntry>& entries,
                             int rows, int cols) {
  const int free_rows = std::max(0, rows - static_cast<int>(lines.size()) - 1);
  std::vector<std::string> area = message_area(view, cols);
  const int alarms = view.help ? 0 : static_cast<int>(entries.size());
  const int message_rows =
      std::min(free_rows, std::clamp(static_cast<int>(area.size()), kMinMessageRows,
                                     std::max(kMinMessageRows, free_rows - alarms)));
  area.resize(static_cast<std::size_t>(std::max(0, message_rows)));
  if (alarms > 0) add_alarms(lines, view, entries, s.time_ns(), free_rows - message_rows, cols);
  while (static_cast<int>(lines.size()) < rows - message_rows - 1) lines.emplace_back("");
  for (auto l = area.rbegin(); l != area.rend(); ++l) lines.push_back(*l);
}

std::string key_line(const ConsoleView& view) {
  if (view.replay) {
    return "space pause/resume  , . seek 5s  < > 30s  [ ] speed  0 start  g go to  ? q quit";
  }
  if (!view.prompt.empty()) return "typing: Enter sends  Esc cancels  Ctrl-X E-STOP";
  if (view.read_only) return "READ-ONLY  x E-STOP  ? help  q quit";
  return "x E-STOP a arm e engage d disengage c/u clutch l clear s set r rec ? help q quit";
}

}  // namespace

std::vector<std::string> render_console(const ConsoleView& view, int rows, int cols) {
  std::vector<std::string> lines;
  const v1::SupervisorStatus empty;
  const v1::SupervisorStatus& s = view.status ? *view.status : empty;
  const std::vector<AlarmEntry> entries = group_alarms(view, s);
  lines.push_back(header_line(view, s, cols));
  add_stop_banners(lines, s, cols);
  // docs/nodes.md "Before engage": an experiment arming what the analysis refuses, and nodes whose
  // configurations differ, above everything else.
  if (!s.experiment_banner().empty()) lines.push_back("!! " + s.experiment_banner());
  if (!s.configuration_mismatch().empty()) {
    lines.push_back("!! CONFIGURATION MISMATCH: " + s.configuration_mismatch());
  }
  if (view.help) {
    lines.emplace_back("");
    for (const std::string& l : help_lines(view.replay)) lines.push_back(l);
  } else {
    const std::size_t alarms = view.alarm_history.empty()
                                   ? static_cast<std::size_t>(s.recent_alarms_size())
                                   : view.alarm_history.size();
    add_system_rows(lines, s, alarms, entries.size(), rows, cols, view.axes_table);
  }
  add_alarms_and_messages(lines, view, s, entries, rows, cols);
  lines.push_back(key_line(view));
  // Fit: at most `rows` lines (the key line kept last), each at most `cols` characters.
  if (static_cast<int>(lines.size()) > rows && rows > 0) {
    lines.erase(lines.begin() + (rows - 1), lines.end() - 1);
  }
  for (std::string& l : lines) l = fit(l, cols);
  return lines;
}

}  // namespace teleop::ctl
