// SVG charts for `teleopctl analyze|simulate|replay|identify --plot FILE.svg`: no plotting
// library, figures a paper would accept (docs/cli.md "Plots"):
//  - round ticks (1, 2 or 5 times a power of ten) and a light grid;
//  - one or more panels stacked over a shared x axis, each with its own y axis and unit
//    (positions in mm above forces in N);
//  - legends in a column right of the plotting area, never over the traces;
//  - the z-plane: equal axes, the unit circle, markers coloured by a value (grip force) with a
//    colour bar, unstable eigenvalues ringed, an inset near z = 1.
// The output is plain XML with classes a test can find: "title", "panel", "x-tick", "y-tick",
// "y-label", "legend" (and its "legend-box" rect), "unit-circle", "unstable", "no-limit",
// "inset", "colour-bar".
#pragma once

#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace teleop::ctl {

// Round ticks covering [lo, hi]: the step is the smallest of 1, 2, 5 x 10^k not below
// (hi - lo) / target_intervals, the axis runs from the multiple of the step at or below lo to
// the one at or above hi, and values are k x step (no 0.30000000000000004). lo == hi is
// widened to a unit-wide window around it; non-finite bounds give [0, 1].
struct Ticks {
  double lo{0.0};
  double hi{1.0};
  double step{0.2};
  std::vector<double> values{};
};
[[nodiscard]] Ticks nice_ticks(double lo, double hi, int target_intervals = 5);
// The smallest 1, 2 or 5 x 10^k >= raw (raw > 0).
[[nodiscard]] double nice_step(double raw);
// A tick's text: as many decimals as the step needs, no "-0".
[[nodiscard]] std::string tick_label(double value, double step);

// kDot: a smaller, slightly transparent circle for dense clouds.
enum class Marker { kNone, kCircle, kDot, kRing, kTriangle };

struct Series {
  std::string label{};
  std::vector<std::pair<double, double>> points{};  // non-finite points break the line
  std::string colour{"#0072b2"};
  bool line{true};
  bool dashed{false};
  Marker marker{Marker::kNone};
  // Per point: a value coloured on the chart's colour scale (markers only; empty: `colour`).
  std::vector<double> values{};
  // The class attribute of each marker (e.g. "unstable"), for readers of the SVG.
  std::string kind{};
};

// A colour bar for Series::values: viridis from lo to hi.
struct ColourScale {
  std::string label{};
  double lo{0.0};
  double hi{1.0};
};

struct Panel {
  std::string y_label{};  // with its unit, e.g. "position (mm)"
  std::vector<Series> series{};
  bool include_zero{false};  // the y axis reaches 0
};

// z-plane: a zoomed copy of the main plot over [x0, x1] x [y0, y1], drawn right of it.
struct Inset {
  std::string label{};
  double x0{0.0};
  double x1{1.0};
  double y0{0.0};
  double y1{1.0};
};

struct Chart {
  std::string title{};
  std::string subtitle{};
  std::string x_label{};
  std::vector<Panel> panels{};
  // z-plane: one panel, equal axes, the unit circle (its legend entry included).
  bool unit_circle{false};
  std::optional<Inset> inset{};
  std::optional<ColourScale> colour_scale{};
  std::vector<std::string> notes{};  // lines under the legend
};

[[nodiscard]] std::string render_svg(const Chart& chart);

// The colour of t in [0, 1] (clamped) on the viridis map, as "#rrggbb".
[[nodiscard]] std::string scale_colour(double t);

// Colour-blind-safe line colours (Okabe-Ito), cycled.
[[nodiscard]] std::string line_colour(std::size_t i);

// Two panels over one time axis (s): positions (mm) above forces (N), series to be added.
[[nodiscard]] Chart position_force_chart(std::string title, std::string subtitle);

// A dashed horizontal line at y over [x0, x1] in one panel (a fixture's position, a bound).
void add_level(Chart& chart, std::size_t panel, std::string label, double y, double x0, double x1,
               std::string colour);

// Every how many samples a trace of `samples` keeps to stay near kMaxPlotPoints points (a
// 520-pixel-wide panel shows no more).
inline constexpr std::size_t kMaxPlotPoints = 2500;
[[nodiscard]] std::size_t plot_stride(std::size_t samples);

// Writes the SVG to `path` (std::runtime_error when it cannot).
void write_svg(const std::string& path, const Chart& chart);

}  // namespace teleop::ctl
