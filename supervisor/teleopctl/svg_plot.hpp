// Minimal SVG charts for `teleopctl analyze --plot`: no plotting library is needed for a
// scatter in the z-plane and a line chart.
#pragma once

#include <string>
#include <utility>
#include <vector>

namespace teleop::ctl {

struct Series {
  std::string label{};
  std::vector<std::pair<double, double>> points{};
  std::string colour{"#1f77b4"};
  bool line{true};  // false: markers only
};

struct Chart {
  std::string title{};
  std::string x_label{};
  std::string y_label{};
  std::vector<Series> series{};
  bool unit_circle{false};  // z-plane: equal axes and the unit circle
};

[[nodiscard]] std::string render_svg(const Chart& chart);

}  // namespace teleop::ctl
