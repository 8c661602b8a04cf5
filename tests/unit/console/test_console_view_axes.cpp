// The console's screen for nodes of several task-space axes (issue 18; console_view.hpp): at
// 80x24, each node row shows the norms of the newest cycle's position and force, a row under it
// the command's norm and the worst axes by |force| and by |tracking error|, and the per-axis
// table (key t) one row per axis. The norms and worst axes here are worked by hand from the
// numbers the summary is given; a one-axis summary renders as before (no axis rows).
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "supervisor/teleopctl/console_view.hpp"

namespace teleop::ctl {
namespace {

// Positions (3, 4, 0) mm: |x| = 5 mm. Forces (0.3, -1.2, 0.4) N: |F| = sqrt(1.69) = 1.3 N, the
// largest |F| on axis 1. Commands (0.6, 0.8, 0) N: |u| = 1 N. Tracking errors (0.1, -0.05,
// 0.3) mm: the largest on axis 2.
void fill(v1::NodeSummary& n, double sign) {
  n.set_alive(true);
  n.set_mode(v1::ENGAGED);
  n.set_loop_rate_hz(1000.0);
  n.mutable_loop()->set_cycles(100);
  n.set_axes(3);
  for (const double x : {3e-3, 4e-3, 0.0}) n.add_positions_m(sign * x);
  for (const double f : {0.3, -1.2, 0.4}) n.add_forces_n(sign * f);
  for (const double u : {0.6, 0.8, 0.0}) n.add_commands_n(sign * u);
  for (const double e : {0.1e-3, -0.05e-3, 0.3e-3}) n.add_tracking_errors_m(e);
}

ConsoleView three_axes() {
  ConsoleView v;
  v1::SupervisorStatus s;
  fill(*s.mutable_master(), 1.0);
  fill(*s.mutable_slave(), -1.0);
  s.set_master_alive(true);
  s.set_slave_alive(true);
  v.status = s;
  return v;
}

std::string screen(const std::vector<std::string>& rows) {
  std::string s;
  for (const std::string& r : rows) s += r + "\n";
  return s;
}

const std::string* row_starting(const std::vector<std::string>& rows, const std::string& p) {
  for (const std::string& r : rows) {
    if (r.rfind(p, 0) == 0) return &r;
  }
  return nullptr;
}

TEST(ConsoleViewAxes, NormsAndTheWorstAxisOfEachNodeAt80x24) {
  const std::vector<std::string> rows = render_console(three_axes(), 24, 80);
  ASSERT_EQ(rows.size(), 24U);
  for (const std::string& r : rows) EXPECT_LE(r.size(), 80U) << r;
  const std::string all = screen(rows);
  const std::string* master = row_starting(rows, "master ENGAGED");
  const std::string* slave = row_starting(rows, "slave  ENGAGED");
  ASSERT_NE(master, nullptr) << all;
  ASSERT_NE(slave, nullptr) << all;
  EXPECT_NE(master->find("|x| 5.00mm |F|1.30N"), std::string::npos) << *master;
  EXPECT_NE(slave->find("|x| 5.00mm |F|1.30N"), std::string::npos) << *slave;
  EXPECT_NE(all.find("3 axes |u| 1.00N  worst: F axis 1 -1.20N, e axis 2 +0.30mm"),
            std::string::npos)
      << all;
  EXPECT_NE(all.find("3 axes |u| 1.00N  worst: F axis 1 +1.20N, e axis 2 +0.30mm"),
            std::string::npos)
      << all;
  EXPECT_EQ(row_starting(rows, "axis 0"), nullptr) << all;  // the table is off
}

TEST(ConsoleViewAxes, TheTableShowsOneRowPerAxis) {
  ConsoleView v = three_axes();
  v.axes_table = true;
  const std::vector<std::string> rows = render_console(v, 24, 80);
  ASSERT_EQ(rows.size(), 24U);
  const std::string all = screen(rows);
  for (const std::string& r : rows) EXPECT_LE(r.size(), 80U) << r;
  // axis 1: master x 4.00 mm, F -1.20 N, u 0.80 N; slave the negatives; e -0.050 mm.
  const std::string* a1 = row_starting(rows, "axis 1");
  ASSERT_NE(a1, nullptr) << all;
  EXPECT_EQ(*a1, "axis 1         4.00  -1.20   0.80        -4.00   1.20  -0.80     -0.050") << all;
  ASSERT_NE(row_starting(rows, "axis 0"), nullptr) << all;
  ASSERT_NE(row_starting(rows, "axis 2"), nullptr) << all;
  EXPECT_EQ(row_starting(rows, "axis 3"), nullptr) << all;
  EXPECT_NE(all.find("master x mm"), std::string::npos) << all;
}

// One axis (axes 0, no lists): the node row as before, no axis rows even with the table on.
TEST(ConsoleViewAxes, AOneAxisNodeRendersAsBefore) {
  ConsoleView v;
  v1::SupervisorStatus s;
  for (v1::NodeSummary* n : {s.mutable_master(), s.mutable_slave()}) {
    n->set_alive(true);
    n->set_mode(v1::ENGAGED);
    n->mutable_loop()->set_cycles(100);
    n->set_position_m(1.5e-3);
    n->set_force_n(0.25);
  }
  v.status = s;
  const std::vector<std::string> off = render_console(v, 24, 80);
  v.axes_table = true;
  const std::vector<std::string> on = render_console(v, 24, 80);
  EXPECT_EQ(off, on);
  const std::string* master = row_starting(off, "master ENGAGED");
  ASSERT_NE(master, nullptr);
  EXPECT_NE(master->find(" x +1.50mm F+0.25N"), std::string::npos) << *master;
  EXPECT_EQ(screen(off).find("axes"), std::string::npos) << screen(off);
}

// The stability rows of n > 1 axes: the limiting plane against its limit (1000 of 4000 N/m,
// margin 1 - 1000/4000 = 75 %), then every plane's share of its limit. A one-axis report's
// "fixture none" would say nothing about the planes in force.
TEST(ConsoleViewAxes, TheStabilityRowsShowTheLimitingPlaneAndEveryPlanesShare) {
  ConsoleView v = three_axes();
  v1::StabilityReport& r = *v.status->mutable_report();
  r.set_verdict("stable");
  r.set_axes(3);
  const auto plane = [&](const char* side, unsigned index, double k, double limit, bool lim) {
    v1::PlaneMargin* p = r.add_planes();
    p->set_side(side);
    p->set_index(index);
    p->set_stiffness_n_per_m(k);
    p->set_max_stable_stiffness_n_per_m(limit);
    p->set_fraction_of_limit(k / limit);
    p->set_margin(1.0 - k / limit);
    p->set_limiting(lim);
  };
  plane("slave", 0, 1500.0, 6000.0, false);  // 25 %
  plane("slave", 1, 1000.0, 4000.0, false);  // 25 %
  plane("master", 0, 500.0, 1000.0, true);   // 50 %: limiting
  const std::vector<std::string> rows = render_console(v, 24, 80);
  for (const std::string& row : rows) EXPECT_LE(row.size(), 80U) << row;
  const std::string all = screen(rows);
  EXPECT_EQ(all.find("fixture none"), std::string::npos) << all;
  const std::string* limiting = row_starting(rows, "master plane 0 fixture    500 of   1000 N/m");
  ASSERT_NE(limiting, nullptr) << all;
  EXPECT_NE(limiting->find("margin   50%"), std::string::npos) << *limiting;
  const std::string* shares = row_starting(rows, "planes s0 25% s1 25% m0 50%");
  EXPECT_NE(shares, nullptr) << all;
}

}  // namespace
}  // namespace teleop::ctl
