#include "supervisor/teleopctl/svg_plot.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

namespace teleop::ctl {

namespace {

constexpr double kWidth = 640.0;
constexpr double kHeight = 480.0;
constexpr double kMargin = 80.0;

// Tick labels: plain digits up to a million, otherwise four significant digits.
std::string tick(double v) {
  if (std::abs(v) >= 100.0 && std::abs(v) < 1e6) return fmt::format("{:.0f}", v);
  return fmt::format("{:.4g}", v);
}

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
      default:
        out += c;
    }
  }
  return out;
}

}  // namespace

std::string render_svg(const Chart& chart) {
  double x0 = std::numeric_limits<double>::infinity();
  double x1 = -x0;
  double y0 = x0;
  double y1 = -x0;
  for (const Series& s : chart.series) {
    for (const auto& [x, y] : s.points) {
      if (!std::isfinite(x) || !std::isfinite(y)) continue;
      x0 = std::min(x0, x);
      x1 = std::max(x1, x);
      y0 = std::min(y0, y);
      y1 = std::max(y1, y);
    }
  }
  if (chart.unit_circle) {
    const double r = std::max({1.05, std::abs(x0), std::abs(x1), std::abs(y0), std::abs(y1)});
    x0 = y0 = -r;
    x1 = y1 = r;
  }
  if (!std::isfinite(x0)) {
    x0 = y0 = 0.0;
    x1 = y1 = 1.0;
  }
  if (x1 == x0) x1 = x0 + 1.0;
  if (y1 == y0) y1 = y0 + 1.0;
  if (!chart.unit_circle) y0 = std::min(y0, 0.0);
  const double pw = (chart.unit_circle ? kHeight : kWidth) - 2.0 * kMargin;
  const double ph = kHeight - 2.0 * kMargin;
  auto px = [&](double x) { return kMargin + (x - x0) / (x1 - x0) * pw; };
  auto py = [&](double y) { return kHeight - kMargin - (y - y0) / (y1 - y0) * ph; };

  std::string svg = fmt::format(
      "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{0}\" height=\"{1}\" "
      "viewBox=\"0 0 {0} {1}\" font-family=\"sans-serif\" font-size=\"12\">\n"
      "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n",
      kWidth, kHeight);
  svg += fmt::format("<text x=\"{}\" y=\"24\" font-size=\"15\">{}</text>\n", kMargin,
                     escape(chart.title));
  svg += fmt::format(
      "<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"#444\"/>\n",
      kMargin, kMargin, pw, ph);
  for (int i = 0; i <= 4; ++i) {
    const double xv = x0 + (x1 - x0) * i / 4.0;
    const double yv = y0 + (y1 - y0) * i / 4.0;
    svg += fmt::format("<text x=\"{:.1f}\" y=\"{:.1f}\" text-anchor=\"middle\">{}</text>\n", px(xv),
                       kHeight - kMargin + 16.0, tick(xv));
    svg += fmt::format("<text x=\"{:.1f}\" y=\"{:.1f}\" text-anchor=\"end\">{}</text>\n",
                       kMargin - 6.0, py(yv) + 4.0, tick(yv));
  }
  svg += fmt::format("<text x=\"{:.1f}\" y=\"{:.1f}\" text-anchor=\"middle\">{}</text>\n",
                     kMargin + pw / 2.0, kHeight - 16.0, escape(chart.x_label));
  svg += fmt::format(
      "<text x=\"16\" y=\"{:.1f}\" transform=\"rotate(-90 16 {:.1f})\" "
      "text-anchor=\"middle\">{}</text>\n",
      kMargin + ph / 2.0, kMargin + ph / 2.0, escape(chart.y_label));
  if (chart.unit_circle) {
    svg += fmt::format(
        "<circle cx=\"{:.2f}\" cy=\"{:.2f}\" r=\"{:.2f}\" fill=\"none\" stroke=\"#888\" "
        "stroke-dasharray=\"4 3\"/>\n",
        px(0.0), py(0.0), px(1.0) - px(0.0));
    svg += fmt::format(
        "<line x1=\"{:.2f}\" y1=\"{:.2f}\" x2=\"{:.2f}\" y2=\"{:.2f}\" "
        "stroke=\"#ccc\"/>\n",
        px(x0), py(0.0), px(x1), py(0.0));
  }
  double legend_y = kMargin + 14.0;
  for (const Series& s : chart.series) {
    if (s.line) {
      std::string path;
      for (const auto& [x, y] : s.points) {
        if (!std::isfinite(x) || !std::isfinite(y)) continue;
        path += fmt::format("{}{:.2f},{:.2f} ", path.empty() ? "M" : "L", px(x), py(y));
      }
      svg += fmt::format("<path d=\"{}\" fill=\"none\" stroke=\"{}\" stroke-width=\"2\"/>\n", path,
                         s.colour);
    }
    // Markers for scatter plots and short lines; a long time series is a line alone.
    for (const auto& [x, y] : s.points) {
      if (s.line && s.points.size() > 200) break;
      if (!std::isfinite(x) || !std::isfinite(y)) continue;
      svg += fmt::format("<circle cx=\"{:.2f}\" cy=\"{:.2f}\" r=\"2.5\" fill=\"{}\"/>\n", px(x),
                         py(y), s.colour);
    }
    svg += fmt::format("<text x=\"{:.1f}\" y=\"{:.1f}\" fill=\"{}\">{}</text>\n", kMargin + 8.0,
                       legend_y, s.colour, escape(s.label));
    legend_y += 16.0;
  }
  svg += "</svg>\n";
  return svg;
}

}  // namespace teleop::ctl
