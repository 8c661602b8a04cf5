// The plots' building blocks (supervisor/teleopctl/svg_plot.hpp): round ticks against tick sets
// computed by hand, and the structure of the SVG a chart renders to, read back by libxml2.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "supervisor/teleopctl/svg_plot.hpp"
#include "tests/unit/console/svg_test_util.hpp"

namespace teleop::ctl {
namespace {

using test::SvgElement;

void expect_ticks(double lo, double hi, int intervals, double step,
                  const std::vector<double>& values) {
  const Ticks t = nice_ticks(lo, hi, intervals);
  EXPECT_DOUBLE_EQ(t.step, step) << "[" << lo << ", " << hi << "]";
  ASSERT_EQ(t.values.size(), values.size()) << "[" << lo << ", " << hi << "]";
  for (std::size_t i = 0; i < values.size(); ++i) {
    EXPECT_NEAR(t.values[i], values[i], 1e-12 * std::max(1.0, std::abs(values[i])))
        << "[" << lo << ", " << hi << "] tick " << i;
  }
  EXPECT_DOUBLE_EQ(t.lo, values.front());
  EXPECT_DOUBLE_EQ(t.hi, values.back());
}

// Each set by hand: raw step (hi - lo) / intervals, the next of 1, 2, 5 x 10^k at or above it,
// the axis widened to the multiples of the step around [lo, hi].
TEST(NiceTicks, HandComputedSets) {
  // raw 0.2: step 0.2 exactly
  expect_ticks(0.0, 1.0, 5, 0.2, {0.0, 0.2, 0.4, 0.6, 0.8, 1.0});
  // raw 1.86 -> 2; 9.3 rounds up to 10
  expect_ticks(0.0, 9.3, 5, 2.0, {0, 2, 4, 6, 8, 10});
  // the z-plane's [-1.05, 1.05]: raw 0.35 -> 0.5, widened to +-1.5
  expect_ticks(-1.05, 1.05, 6, 0.5, {-1.5, -1.0, -0.5, 0.0, 0.5, 1.0, 1.5});
  // rates 500..5000 Hz: raw 900 -> 1000, from 0
  expect_ticks(500.0, 5000.0, 5, 1000.0, {0, 1000, 2000, 3000, 4000, 5000});
  // raw 0.05 -> 0.05; 1.1 / 0.05 = 22.000000000000004 must not add a tick at 1.15
  expect_ticks(0.9, 1.1, 4, 0.05, {0.9, 0.95, 1.0, 1.05, 1.1});
  // all negative: raw 0.56 -> 1
  expect_ticks(-3.2, -0.4, 5, 1.0, {-4, -3, -2, -1, 0});
  // small numbers: raw 0.0024667 -> 0.005
  expect_ticks(0.0013, 0.0087, 3, 0.005, {0.0, 0.005, 0.01});
  // a force trace: raw 0.85 -> 1
  expect_ticks(-1.7, 2.55, 5, 1.0, {-2, -1, 0, 1, 2, 3});
  // one value: a unit-wide window around it, raw 0.2
  expect_ticks(2.5, 2.5, 5, 0.2, {2.0, 2.2, 2.4, 2.6, 2.8, 3.0});
  // nothing finite: [0, 1]
  expect_ticks(std::nan(""), 1.0, 5, 0.2, {0.0, 0.2, 0.4, 0.6, 0.8, 1.0});
}

TEST(NiceTicks, StepsAreOneTwoOrFiveTimesAPowerOfTen) {
  EXPECT_DOUBLE_EQ(nice_step(0.3), 0.5);
  EXPECT_DOUBLE_EQ(nice_step(1.0), 1.0);
  EXPECT_DOUBLE_EQ(nice_step(1.01), 2.0);
  EXPECT_DOUBLE_EQ(nice_step(2.0), 2.0);
  EXPECT_DOUBLE_EQ(nice_step(7.0), 10.0);
  EXPECT_DOUBLE_EQ(nice_step(0.002), 0.002);
  EXPECT_DOUBLE_EQ(nice_step(4321.0), 5000.0);
  for (double raw = 1e-4; raw < 1e5; raw *= 1.37) {
    const double s = nice_step(raw);
    EXPECT_TRUE(test::round_step(s)) << raw << " -> " << s;
    EXPECT_GE(s, raw * (1.0 - 1e-9));
    EXPECT_LT(s, 2.5 * raw) << raw;  // never more than the next 1-2-5 step
  }
}

TEST(NiceTicks, LabelsHaveTheDecimalsOfTheStep) {
  EXPECT_EQ(tick_label(0.30000000000000004, 0.1), "0.3");
  EXPECT_EQ(tick_label(0.95, 0.05), "0.95");
  EXPECT_EQ(tick_label(-0.0, 1.0), "0");
  EXPECT_EQ(tick_label(-0.0, 0.5), "0.0");
  EXPECT_EQ(tick_label(-1e-17, 0.2), "0.0");
  EXPECT_EQ(tick_label(2500.0, 500.0), "2500");
  EXPECT_EQ(tick_label(0.005, 0.005), "0.005");
  EXPECT_EQ(tick_label(-1.5, 0.5), "-1.5");
}

Chart two_panels() {
  Chart c = position_force_chart("A title", "a subtitle");
  Series a{"master", {}, line_colour(0), true};
  Series b{"human force", {}, line_colour(1), true};
  for (int i = 0; i <= 100; ++i) {
    const double t = 0.037 * i;
    a.points.emplace_back(t, 3.3 * std::sin(t));
    b.points.emplace_back(t, 1.7 * std::cos(3 * t));
  }
  c.panels[0].series.push_back(a);
  c.panels[1].series.push_back(b);
  return c;
}

TEST(SvgChart, StackedPanelsWithUnitsRoundTicksAndLegendsRightOfTheTraces) {
  const SvgElement svg = test::parse_svg(render_svg(two_panels()));
  ASSERT_EQ(svg.with_class("title").size(), 1U);
  EXPECT_EQ(svg.with_class("title").front()->text, "A title");
  const auto panels = svg.with_class("panel");
  ASSERT_EQ(panels.size(), 2U);
  EXPECT_EQ(panels[0]->with_class("y-label").front()->text, "position (mm)");
  EXPECT_EQ(panels[1]->with_class("y-label").front()->text, "force (N)");
  // The time ticks once, under the bottom panel: 0 to 3.7 s in up to 8 intervals, raw 0.4625
  // -> 0.5 s.
  EXPECT_TRUE(panels[0]->with_class("x-tick").empty());
  std::vector<double> x;
  ASSERT_TRUE(test::tick_values(panels[1]->with_class("x-tick"), x));
  EXPECT_EQ(x, (std::vector<double>{0, 0.5, 1, 1.5, 2, 2.5, 3, 3.5, 4}));
  // 3.3 sin(t) over [0, 3.7]: from 3.3 sin(3.7) = -1.748 to 3.3; raw (3.3 + 1.748) / 5 = 1.01
  // -> step 2, from -2 to 4.
  std::vector<double> y;
  ASSERT_TRUE(test::tick_values(panels[0]->with_class("y-tick"), y));
  EXPECT_EQ(y, (std::vector<double>{-2, 0, 2, 4}));
  EXPECT_EQ(svg.with_class("x-label").front()->text, "time (s)");
  // Each legend box starts right of every trace's points.
  const auto boxes = svg.with_class("legend-box");
  ASSERT_EQ(boxes.size(), 2U);
  for (const SvgElement* panel : panels) {
    for (const SvgElement* path : panel->named("path")) {
      const std::string& d = path->attrs.at("d");
      for (std::size_t at = d.find_first_of("ML"); at != std::string::npos;
           at = d.find_first_of("ML", at + 1)) {
        const double px = std::stod(d.substr(at + 1));
        for (const SvgElement* b : boxes) EXPECT_LT(px, b->num("x"));
      }
    }
  }
}

TEST(SvgChart, BreaksLinesAtMissingPointsAndEscapesText) {
  Chart c;
  c.title = "a < b & c";
  Series s{"x", {{0, 1}, {1, 2}, {2, std::nan("")}, {3, 1}, {4, 2}}, "#000", true};
  c.panels.push_back(Panel{"y (N)", {s}, false});
  const SvgElement svg = test::parse_svg(render_svg(c));
  EXPECT_EQ(svg.with_class("title").front()->text, "a < b & c");
  const auto paths = svg.with_class("panel").front()->named("path");
  ASSERT_EQ(paths.size(), 1U);
  const std::string& d = paths.front()->attrs.at("d");
  EXPECT_EQ(std::count(d.begin(), d.end(), 'M'), 2);  // two pieces
  EXPECT_EQ(std::count(d.begin(), d.end(), 'L'), 2);
}

TEST(SvgChart, ViridisEndsAndMiddle) {
  // matplotlib's viridis: #440154 at 0, #21918c at 0.5, #fde725 at 1.
  EXPECT_EQ(scale_colour(0.0), "#440154");
  EXPECT_EQ(scale_colour(0.5), "#21918c");
  EXPECT_EQ(scale_colour(1.0), "#fde725");
  EXPECT_EQ(scale_colour(-3.0), scale_colour(0.0));
  EXPECT_EQ(scale_colour(7.0), scale_colour(1.0));
}

}  // namespace
}  // namespace teleop::ctl
