#include "supervisor/teleopctl/svg_plot.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <fstream>
#include <limits>
#include <stdexcept>
#include <utility>

namespace teleop::ctl {

namespace {

constexpr double kWidth = 820.0;
constexpr double kLeft = 84.0;            // room for the y ticks and the y label
constexpr double kTop = 64.0;             // title and subtitle above
constexpr double kBottom = 56.0;          // x ticks and the x label below
constexpr double kPlotWidth = 500.0;      // time series and sweeps
constexpr double kColumnX = 604.0;        // the legend column, right of the traces
constexpr double kColumnWidth = 206.0;    // to the right edge, less a margin
constexpr double kPanelGap = 30.0;        // between stacked panels
constexpr double kSquare = 440.0;         // the z-plane
constexpr double kInsetSide = 170.0;      // the z-plane's inset
constexpr double kLegendRow = 17.0;       // one legend line
constexpr std::size_t kLegendChars = 25;  // wrap legend text here (about 6.5 px a character)
constexpr std::size_t kNoteChars = 31;    // and the smaller notes under it
// Tolerance when rounding bounds to multiples of the step, relative to the step.
constexpr double kTickSlack = 1e-9;

std::string escape(const std::string& s) {
  std::string out;
  for (const char c : s) {
    switch (c) {
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '&':
        out += "&amp;";
        break;
      case '"':
        out += "&quot;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

// Plot coordinates to pixels within one panel's frame.
struct Frame {
  double left{0.0};
  double top{0.0};
  double width{1.0};
  double height{1.0};
  Ticks x{};
  Ticks y{};
  [[nodiscard]] double px(double v) const { return left + (v - x.lo) / (x.hi - x.lo) * width; }
  [[nodiscard]] double py(double v) const {
    return top + height - (v - y.lo) / (y.hi - y.lo) * height;
  }
};

struct Bounds {
  double lo{std::numeric_limits<double>::infinity()};
  double hi{-std::numeric_limits<double>::infinity()};
  void add(double v) {
    if (!std::isfinite(v)) return;
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
};

// Text split into lines of at most `width` characters at spaces.
std::vector<std::string> wrap(const std::string& text, std::size_t width) {
  std::vector<std::string> lines;
  std::string line;
  std::size_t i = 0;
  while (i < text.size()) {
    std::size_t end = text.find(' ', i);
    if (end == std::string::npos) end = text.size();
    const std::string word = text.substr(i, end - i);
    if (!line.empty() && line.size() + 1 + word.size() > width) {
      lines.push_back(line);
      line.clear();
    }
    line += (line.empty() ? "" : " ") + word;
    i = end + 1;
  }
  if (!line.empty() || lines.empty()) lines.push_back(line);
  return lines;
}

void marker(std::string& svg, Marker m, double x, double y, const std::string& colour,
            const std::string& kind) {
  const std::string cls = kind.empty() ? std::string() : fmt::format(" class=\"{}\"", kind);
  switch (m) {
    case Marker::kNone:
      return;
    case Marker::kCircle:
      svg += fmt::format("<circle{} cx=\"{:.2f}\" cy=\"{:.2f}\" r=\"2.6\" fill=\"{}\"/>\n", cls, x,
                         y, colour);
      return;
    case Marker::kDot:
      svg += fmt::format(
          "<circle{} cx=\"{:.2f}\" cy=\"{:.2f}\" r=\"2.2\" fill=\"{}\" fill-opacity=\"0.75\"/>\n",
          cls, x, y, colour);
      return;
    case Marker::kRing:
      svg += fmt::format(
          "<circle{} cx=\"{:.2f}\" cy=\"{:.2f}\" r=\"5.5\" fill=\"none\" stroke=\"{}\" "
          "stroke-width=\"1.6\"/>\n",
          cls, x, y, colour);
      return;
    case Marker::kTriangle:
      svg += fmt::format(
          "<path{} d=\"M{:.2f},{:.2f} L{:.2f},{:.2f} L{:.2f},{:.2f} Z\" fill=\"white\" "
          "stroke=\"{}\" stroke-width=\"1.6\"/>\n",
          cls, x, y - 9.0, x + 5.0, y - 1.0, x - 5.0, y - 1.0, colour);
      return;
  }
}

// The series' colour at point i (its value on the scale when it has values).
std::string point_colour(const Series& s, std::size_t i, const std::optional<ColourScale>& scale) {
  if (!scale || i >= s.values.size()) return s.colour;
  const double span = scale->hi - scale->lo;
  return scale_colour(span > 0.0 ? (s.values[i] - scale->lo) / span : 0.5);
}

void draw_series(std::string& svg, const Frame& f, const Series& s,
                 const std::optional<ColourScale>& scale, bool keep_kind) {
  if (s.line) {
    std::string path;
    bool pen_down = false;
    for (const auto& [x, y] : s.points) {
      if (!std::isfinite(x) || !std::isfinite(y)) {
        pen_down = false;
        continue;
      }
      path += fmt::format("{}{:.2f},{:.2f} ", pen_down ? "L" : "M", f.px(x), f.py(y));
      pen_down = true;
    }
    if (!path.empty()) {
      svg += fmt::format(
          "<path d=\"{}\" fill=\"none\" stroke=\"{}\" stroke-width=\"1.5\" "
          "stroke-linejoin=\"round\"{}/>\n",
          path, s.colour, s.dashed ? " stroke-dasharray=\"6 4\"" : "");
    }
  }
  for (std::size_t i = 0; i < s.points.size(); ++i) {
    const auto& [x, y] = s.points[i];
    if (!std::isfinite(x) || !std::isfinite(y)) continue;
    marker(svg, s.marker, f.px(x), f.py(y), point_colour(s, i, scale),
           keep_kind ? s.kind : std::string());
  }
}

// Grid, frame, ticks and the y label of one panel; x tick labels on the bottom panel only.
void draw_axes(std::string& svg, const Frame& f, bool x_labels, const std::string& y_label,
               double font_size = 12.0) {
  for (const double v : f.x.values) {
    svg += fmt::format(
        "<line x1=\"{0:.2f}\" y1=\"{1:.2f}\" x2=\"{0:.2f}\" y2=\"{2:.2f}\" stroke=\"#e4e4e4\"/>\n",
        f.px(v), f.top, f.top + f.height);
  }
  for (const double v : f.y.values) {
    svg += fmt::format(
        "<line x1=\"{1:.2f}\" y1=\"{0:.2f}\" x2=\"{2:.2f}\" y2=\"{0:.2f}\" stroke=\"#e4e4e4\"/>\n",
        f.py(v), f.left, f.left + f.width);
  }
  svg += fmt::format(
      "<rect x=\"{:.2f}\" y=\"{:.2f}\" width=\"{:.2f}\" height=\"{:.2f}\" fill=\"none\" "
      "stroke=\"#333\"/>\n",
      f.left, f.top, f.width, f.height);
  const double bottom = f.top + f.height;
  for (const double v : f.x.values) {
    svg += fmt::format(
        "<line x1=\"{0:.2f}\" y1=\"{1:.2f}\" x2=\"{0:.2f}\" y2=\"{2:.2f}\" stroke=\"#333\"/>\n",
        f.px(v), bottom, bottom + 4.0);
    if (!x_labels) continue;
    svg += fmt::format(
        "<text class=\"x-tick\" x=\"{:.2f}\" y=\"{:.2f}\" text-anchor=\"middle\" "
        "font-size=\"{}\">{}</text>\n",
        f.px(v), bottom + 6.0 + font_size, font_size, tick_label(v, f.x.step));
  }
  for (const double v : f.y.values) {
    svg += fmt::format(
        "<line x1=\"{1:.2f}\" y1=\"{0:.2f}\" x2=\"{2:.2f}\" y2=\"{0:.2f}\" stroke=\"#333\"/>\n",
        f.py(v), f.left - 4.0, f.left);
    svg += fmt::format(
        "<text class=\"y-tick\" x=\"{:.2f}\" y=\"{:.2f}\" text-anchor=\"end\" "
        "font-size=\"{}\">{}</text>\n",
        f.left - 7.0, f.py(v) + font_size / 3.0, font_size, tick_label(v, f.y.step));
  }
  if (!y_label.empty()) {
    const double x = f.left - 58.0;
    const double y = f.top + f.height / 2.0;
    svg += fmt::format(
        "<text class=\"y-label\" x=\"{0:.2f}\" y=\"{1:.2f}\" transform=\"rotate(-90 {0:.2f} "
        "{1:.2f})\" text-anchor=\"middle\" font-size=\"13\">{2}</text>\n",
        x, y, escape(y_label));
  }
}

// Traces stay inside their frame; a marker on its edge shows whole (pad pixels beyond it).
void clip(std::string& svg, const Frame& f, const std::string& id, double pad = 6.0) {
  svg += fmt::format(
      "<clipPath id=\"{}\"><rect x=\"{:.2f}\" y=\"{:.2f}\" width=\"{:.2f}\" "
      "height=\"{:.2f}\"/></clipPath>\n",
      id, f.left - pad, f.top - pad, f.width + 2.0 * pad, f.height + 2.0 * pad);
}

struct LegendEntry {
  std::string label{};
  std::string colour{};
  bool line{false};
  bool dashed{false};
  Marker marker{Marker::kNone};
};

LegendEntry entry_of(const Series& s, const std::optional<ColourScale>& scale) {
  // A series coloured by value shows the scale's middle colour.
  const std::string colour = (scale && !s.values.empty()) ? scale_colour(0.5) : s.colour;
  return {s.label, colour, s.line, s.dashed, s.marker};
}

// A boxed legend at (x, y) in the right-hand column; returns its bottom.
double draw_legend(std::string& svg, double x, double y, const std::vector<LegendEntry>& entries,
                   const std::vector<std::string>& notes = {}) {
  std::string body;
  double row = y + 16.0;
  for (const LegendEntry& e : entries) {
    const double mid = row - 4.0;
    if (e.line) {
      body += fmt::format(
          "<line x1=\"{:.2f}\" y1=\"{:.2f}\" x2=\"{:.2f}\" y2=\"{:.2f}\" stroke=\"{}\" "
          "stroke-width=\"1.8\"{}/>\n",
          x + 8.0, mid, x + 32.0, mid, e.colour, e.dashed ? " stroke-dasharray=\"6 4\"" : "");
    }
    marker(body, e.marker, x + 20.0, e.marker == Marker::kTriangle ? mid + 5.0 : mid, e.colour, "");
    for (const std::string& line : wrap(e.label, kLegendChars)) {
      body += fmt::format("<text x=\"{:.2f}\" y=\"{:.2f}\" font-size=\"12\">{}</text>\n", x + 40.0,
                          row, escape(line));
      row += kLegendRow - 2.0;
    }
    row += 2.0;
  }
  for (const std::string& note : notes) {
    for (const std::string& line : wrap(note, kNoteChars)) {
      body +=
          fmt::format("<text x=\"{:.2f}\" y=\"{:.2f}\" font-size=\"11\" fill=\"#555\">{}</text>\n",
                      x + 8.0, row, escape(line));
      row += kLegendRow - 3.0;
    }
  }
  const double bottom = row - 6.0;
  svg += "<g class=\"legend\">\n";
  svg += fmt::format(
      "<rect class=\"legend-box\" x=\"{:.2f}\" y=\"{:.2f}\" width=\"{:.2f}\" height=\"{:.2f}\" "
      "fill=\"white\" stroke=\"#999\"/>\n",
      x, y, kColumnWidth, bottom - y);
  svg += body + "</g>\n";
  return bottom;
}

// A horizontal colour bar at (x, y) with round ticks; returns its bottom.
double draw_colour_bar(std::string& svg, double x, double y, const ColourScale& s) {
  const double width = kColumnWidth - 16.0;
  const double lo = s.lo;
  const double hi = s.hi > s.lo ? s.hi : s.lo + 1.0;
  svg += "<g class=\"colour-bar\">\n<linearGradient id=\"scale\">\n";
  for (int i = 0; i <= 10; ++i) {
    svg += fmt::format("<stop offset=\"{:.1f}\" stop-color=\"{}\"/>\n", i / 10.0,
                       scale_colour(i / 10.0));
  }
  svg += "</linearGradient>\n";
  svg += fmt::format("<text x=\"{:.2f}\" y=\"{:.2f}\" font-size=\"12\">{}</text>\n", x, y + 12.0,
                     escape(s.label));
  const double bar = y + 18.0;
  svg += fmt::format(
      "<rect x=\"{:.2f}\" y=\"{:.2f}\" width=\"{:.2f}\" height=\"12\" fill=\"url(#scale)\" "
      "stroke=\"#333\"/>\n",
      x, bar, width);
  const Ticks t = nice_ticks(lo, hi, 4);
  for (const double v : t.values) {
    if (v < lo - kTickSlack * t.step || v > hi + kTickSlack * t.step) continue;
    const double px = x + (v - lo) / (hi - lo) * width;
    svg += fmt::format(
        "<line x1=\"{0:.2f}\" y1=\"{1:.2f}\" x2=\"{0:.2f}\" y2=\"{2:.2f}\" stroke=\"#333\"/>\n"
        "<text x=\"{0:.2f}\" y=\"{3:.2f}\" text-anchor=\"middle\" font-size=\"11\">{4}</text>\n",
        px, bar + 12.0, bar + 16.0, bar + 28.0, tick_label(v, t.step));
  }
  svg += "</g>\n";
  return bar + 32.0;
}

std::string header(const Chart& chart, double height) {
  std::string svg = fmt::format(
      "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{0}\" height=\"{1}\" "
      "viewBox=\"0 0 {0} {1}\" font-family=\"DejaVu Sans, Helvetica, Arial, sans-serif\" "
      "font-size=\"12\">\n"
      "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n",
      kWidth, height);
  svg += fmt::format(
      "<text class=\"title\" x=\"{}\" y=\"26\" font-size=\"16\" font-weight=\"bold\">{}</text>\n",
      kLeft - 60.0, escape(chart.title));
  if (!chart.subtitle.empty()) {
    svg += fmt::format(
        "<text class=\"subtitle\" x=\"{}\" y=\"46\" font-size=\"12\" fill=\"#444\">{}</text>\n",
        kLeft - 60.0, escape(chart.subtitle));
  }
  return svg;
}

void x_label(std::string& svg, const Frame& f, const std::string& text) {
  svg += fmt::format(
      "<text class=\"x-label\" x=\"{:.2f}\" y=\"{:.2f}\" text-anchor=\"middle\" "
      "font-size=\"13\">{}</text>\n",
      f.left + f.width / 2.0, f.top + f.height + 44.0, escape(text));
}

// Round ticks inside [lo, hi], the axis exactly [lo, hi] (a window that must keep its aspect).
Ticks ticks_within(double lo, double hi, int target_intervals) {
  Ticks t = nice_ticks(lo, hi, target_intervals);
  std::vector<double> inside;
  for (const double v : t.values) {
    if (v >= lo - kTickSlack * t.step && v <= hi + kTickSlack * t.step) inside.push_back(v);
  }
  t.values = inside;
  t.lo = lo;
  t.hi = hi;
  return t;
}

// The z-plane: a square, the unit circle, the legend, colour bar and inset in the column.
std::string render_z_plane(const Chart& chart) {
  const Panel& panel = chart.panels.front();
  double r = 1.05;
  for (const Series& s : panel.series) {
    for (const auto& [x, y] : s.points) {
      if (std::isfinite(x) && std::isfinite(y)) r = std::max({r, std::abs(x), std::abs(y)});
    }
  }
  // Steps of 0.2 up to |z| = 1.2, then 0.5 (the circle fills the square).
  const Ticks t = nice_ticks(-r, r, 12);
  const Frame f{kLeft, kTop, kSquare, kSquare, t, t};
  const double height = kTop + kSquare + kBottom;
  std::string svg = header(chart, height);
  svg += "<g class=\"panel\">\n";
  clip(svg, f, "main", 0.0);
  draw_axes(svg, f, true, panel.y_label);
  x_label(svg, f, chart.x_label);
  const double radius = f.px(1.0) - f.px(0.0);
  svg += "<g clip-path=\"url(#main)\">\n";
  svg += fmt::format(
      "<line x1=\"{:.2f}\" y1=\"{:.2f}\" x2=\"{:.2f}\" y2=\"{:.2f}\" stroke=\"#bbb\"/>\n", f.left,
      f.py(0.0), f.left + f.width, f.py(0.0));
  svg += fmt::format(
      "<circle class=\"unit-circle\" cx=\"{:.2f}\" cy=\"{:.2f}\" r=\"{:.2f}\" fill=\"none\" "
      "stroke=\"#666\" stroke-width=\"1.2\" stroke-dasharray=\"5 3\"/>\n",
      f.px(0.0), f.py(0.0), radius);
  for (const Series& s : panel.series) draw_series(svg, f, s, chart.colour_scale, true);
  if (chart.inset) {
    const Inset& in = *chart.inset;
    svg += fmt::format(
        "<rect class=\"inset-region\" x=\"{:.2f}\" y=\"{:.2f}\" width=\"{:.2f}\" "
        "height=\"{:.2f}\" fill=\"none\" stroke=\"#333\" stroke-width=\"0.8\"/>\n",
        f.px(in.x0), f.py(in.y1), f.px(in.x1) - f.px(in.x0), f.py(in.y0) - f.py(in.y1));
  }
  svg += "</g>\n</g>\n";

  std::vector<LegendEntry> entries;
  for (const Series& s : panel.series) entries.push_back(entry_of(s, chart.colour_scale));
  entries.push_back({"unit circle |z| = 1", "#666", true, true, Marker::kNone});
  double y = draw_legend(svg, kColumnX - 40.0, kTop, entries, chart.notes);
  if (chart.colour_scale) y = draw_colour_bar(svg, kColumnX - 32.0, y + 10.0, *chart.colour_scale);
  if (chart.inset) {
    const Inset& in = *chart.inset;
    const Ticks ix = ticks_within(in.x0, in.x1, 6);
    const Ticks iy = ticks_within(in.y0, in.y1, 6);
    const double top = std::max(y + 36.0, kTop + kSquare - kInsetSide);
    const Frame g{kColumnX + 6.0, top, kInsetSide, kInsetSide, ix, iy};
    svg += "<g class=\"inset\">\n";
    svg += fmt::format("<text x=\"{:.2f}\" y=\"{:.2f}\" font-size=\"12\">{}</text>\n",
                       g.left - 46.0, top - 8.0, escape(in.label));
    clip(svg, g, "inset", 0.0);
    draw_axes(svg, g, true, "", 10.0);
    svg += "<g clip-path=\"url(#inset)\">\n";
    svg += fmt::format(
        "<circle cx=\"{:.2f}\" cy=\"{:.2f}\" r=\"{:.2f}\" fill=\"none\" stroke=\"#666\" "
        "stroke-width=\"1.2\" stroke-dasharray=\"5 3\"/>\n",
        g.px(0.0), g.py(0.0), g.px(1.0) - g.px(0.0));
    for (const Series& s : panel.series) draw_series(svg, g, s, chart.colour_scale, false);
    svg += "</g>\n</g>\n";
  }
  svg += "</svg>\n";
  return svg;
}

// Panels stacked over one x axis, each with its legend in the column on its right.
std::string render_panels(const Chart& chart) {
  const std::size_t n = std::max<std::size_t>(1, chart.panels.size());
  const double panel_height = n == 1 ? 340.0 : 210.0;
  const double height = kTop + static_cast<double>(n) * panel_height +
                        static_cast<double>(n - 1) * kPanelGap + kBottom;
  Bounds xb;
  for (const Panel& p : chart.panels) {
    for (const Series& s : p.series) {
      for (const auto& [x, y] : s.points) {
        if (std::isfinite(y)) xb.add(x);
      }
    }
  }
  // Up to eight intervals along the 500-pixel axis: 0-7 s in steps of 1 s, not 0-8 in 2.
  const Ticks xt = nice_ticks(xb.lo, xb.hi, 8);
  std::string svg;
  double legend_bottom = 0.0;  // a long legend makes the figure taller, never cut off
  for (std::size_t i = 0; i < chart.panels.size(); ++i) {
    const Panel& p = chart.panels[i];
    Bounds yb;
    if (p.include_zero) yb.add(0.0);
    for (const Series& s : p.series) {
      for (const auto& [x, y] : s.points) {
        if (std::isfinite(x)) yb.add(y);
      }
    }
    const double top = kTop + static_cast<double>(i) * (panel_height + kPanelGap);
    const Frame f{kLeft, top, kPlotWidth, panel_height, xt, nice_ticks(yb.lo, yb.hi, 5)};
    const std::string id = fmt::format("panel{}", i);
    svg += fmt::format("<g class=\"panel\" id=\"{}\">\n", id);
    clip(svg, f, id + "-clip");
    draw_axes(svg, f, i + 1 == chart.panels.size(), p.y_label);
    svg += fmt::format("<g clip-path=\"url(#{}-clip)\">\n", id);
    for (const Series& s : p.series) draw_series(svg, f, s, chart.colour_scale, true);
    svg += "</g>\n";
    if (i + 1 == chart.panels.size()) x_label(svg, f, chart.x_label);
    svg += "</g>\n";
    std::vector<LegendEntry> entries;
    for (const Series& s : p.series) entries.push_back(entry_of(s, chart.colour_scale));
    legend_bottom = std::max(
        legend_bottom,
        draw_legend(svg, kColumnX, top, entries,
                    i + 1 == chart.panels.size() ? chart.notes : std::vector<std::string>{}));
  }
  return header(chart, std::max(height, std::ceil(legend_bottom + 12.0))) + svg + "</svg>\n";
}

}  // namespace

double nice_step(double raw) {
  if (!(raw > 0.0) || !std::isfinite(raw)) return 1.0;
  const double magnitude = std::pow(10.0, std::floor(std::log10(raw)));
  for (const double m : {1.0, 2.0, 5.0, 10.0}) {
    if (m * magnitude >= raw * (1.0 - kTickSlack)) return m * magnitude;
  }
  return 10.0 * magnitude;
}

Ticks nice_ticks(double lo, double hi, int target_intervals) {
  if (!std::isfinite(lo) || !std::isfinite(hi)) {
    lo = 0.0;
    hi = 1.0;
  }
  if (hi < lo) std::swap(lo, hi);
  if (hi == lo) {
    lo -= 0.5;
    hi += 0.5;
  }
  Ticks t;
  t.step = nice_step((hi - lo) / std::max(1, target_intervals));
  const double first = std::floor(lo / t.step + kTickSlack);
  const double last = std::ceil(hi / t.step - kTickSlack);
  for (double k = first; k <= last; k += 1.0) t.values.push_back(k * t.step);
  t.lo = t.values.front();
  t.hi = t.values.back();
  return t;
}

std::string tick_label(double value, double step) {
  const int decimals =
      step > 0.0 ? std::max(0, static_cast<int>(-std::floor(std::log10(step) + kTickSlack))) : 0;
  const double rounded = std::abs(value) < step * kTickSlack * 1e3 ? 0.0 : value;
  return fmt::format("{:.{}f}", rounded + 0.0, decimals);
}

std::string scale_colour(double t) {
  // Viridis (matplotlib's) at t = 0, 0.1, ..., 1, linearly interpolated.
  static constexpr std::array<std::array<double, 3>, 11> kStops{{
      {0.267004, 0.004874, 0.329415},
      {0.282623, 0.140926, 0.457517},
      {0.253935, 0.265254, 0.529983},
      {0.206756, 0.371758, 0.553117},
      {0.163625, 0.471133, 0.558148},
      {0.127568, 0.566949, 0.550556},
      {0.134692, 0.658636, 0.517649},
      {0.266941, 0.748751, 0.440573},
      {0.477504, 0.821444, 0.318195},
      {0.741388, 0.873449, 0.149561},
      {0.993248, 0.906157, 0.143936},
  }};
  if (!std::isfinite(t)) t = 0.5;
  t = std::clamp(t, 0.0, 1.0) * 10.0;
  const auto i = std::min<std::size_t>(9, static_cast<std::size_t>(t));
  const double u = t - static_cast<double>(i);
  std::array<int, 3> rgb{};
  for (std::size_t c = 0; c < 3; ++c) {
    rgb[c] = static_cast<int>(
        std::lround(255.0 * (kStops[i][c] + u * (kStops[i + 1][c] - kStops[i][c]))));
  }
  return fmt::format("#{:02x}{:02x}{:02x}", rgb[0], rgb[1], rgb[2]);
}

std::string line_colour(std::size_t i) {
  static constexpr std::array<const char*, 7> kColours{"#0072b2", "#d55e00", "#009e73", "#cc79a7",
                                                       "#e69f00", "#56b4e9", "#000000"};
  return kColours[i % kColours.size()];
}

std::string render_svg(const Chart& chart) {
  if (chart.panels.empty()) {
    Chart empty = chart;
    empty.panels.emplace_back();
    return render_panels(empty);
  }
  return chart.unit_circle ? render_z_plane(chart) : render_panels(chart);
}

Chart position_force_chart(std::string title, std::string subtitle) {
  Chart chart;
  chart.title = std::move(title);
  chart.subtitle = std::move(subtitle);
  chart.x_label = "time (s)";
  chart.panels = {Panel{"position (mm)", {}, false}, Panel{"force (N)", {}, true}};
  return chart;
}

void add_level(Chart& chart, std::size_t panel, std::string label, double y, double x0, double x1,
               std::string colour) {
  Series s{std::move(label), {{x0, y}, {x1, y}}, std::move(colour), true};
  s.dashed = true;
  chart.panels.at(panel).series.push_back(std::move(s));
}

std::size_t plot_stride(std::size_t samples) {
  return std::max<std::size_t>(1, (samples + kMaxPlotPoints - 1) / kMaxPlotPoints);
}

void write_svg(const std::string& path, const Chart& chart) {
  std::ofstream f(path);
  f << render_svg(chart);
  if (!f) throw std::runtime_error(fmt::format("cannot write '{}'", path));
}

}  // namespace teleop::ctl
