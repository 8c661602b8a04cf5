// PlantAxes::step never allocates (docs/architecture.md §4.3), also when it computes a mode's
// propagators on first use: malloc, calloc, realloc and free are interposed and counted
// (tests/support/alloc_counter.hpp, as test_control_rt.cpp). Sanitizer builds replace the
// allocator themselves, so they leave this binary out.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <numbers>

#include "common/sim/plant_axes.hpp"
#include "tests/support/alloc_counter.hpp"

namespace teleop::sim {
namespace {

TEST(PlantAxesRt, CounterSeesAllocations) { EXPECT_EQ(teleop::test::count_malloc_and_free(), 2); }

// The busiest configuration: 3 axes with friction on each (diagonal mass), a coupled human
// stiffness, four planes (so 16 x 7 modes, more than the 64 slots: some are computed inside
// step()), ramped exogenous forces, 10 000 periods of a PD loop.
TEST(PlantAxesRt, StepNeverAllocates) {
  PlantAxesParams p;
  p.device.mass_kg = Eigen::Vector3d(0.036, 0.25, 0.04).asDiagonal();
  p.device.damping_Ns_per_m = Eigen::Vector3d(0.49, 5.0, 0.41);
  p.device.coulomb_N = Eigen::Vector3d(0.05, 0.2, 0.03);
  Eigen::MatrixXd kh(3, 3);
  kh << 100.0, 20.0, 0.0, 20.0, 150.0, 10.0, 0.0, 10.0, 80.0;
  p.human.stiffness_N_per_m = kh;
  p.planes.push_back({Eigen::Vector3d::UnitX(), 0.03, 2000.0, 2.0});
  p.planes.push_back({Eigen::Vector3d::UnitY(), 0.03, 125.0, 0.0});
  p.planes.push_back({Eigen::Vector3d::UnitZ(), 0.035, 1e5, 20.0});
  p.planes.push_back({Eigen::Vector3d(1.0, 1.0, 0.0).normalized(), 0.045, 3000.0, 1.0});
  PlantAxes plant(p, std::chrono::milliseconds(1));
  AxesVector u(3);
  AxesVector f(3);
  AxesVector r(3);
  teleop::test::start_counting(false);
  for (int k = 0; k < 10000; ++k) {
    for (int i = 0; i < 3; ++i) {
      const double xd =
          0.02 + 0.02 * std::sin(2.0 * std::numbers::pi * (1.5 + 0.3 * i) * k * 1e-3 + i);
      u(i) = 1000.0 * (xd - plant.state().position_m(i)) - 3.0 * plant.state().velocity_m_per_s(i);
      f(i) = 0.3 * std::cos(5.0 * k * 1e-3 + i);
      r(i) = i == 1 ? 20.0 : -10.0;
    }
    plant.step(u, f, r);
  }
  const long calls = teleop::test::stop_counting();
  EXPECT_EQ(calls, 0);
  EXPECT_GT(plant.total_events(), 300U);
  EXPECT_GT(plant.late_modes(), 0U);  // the lazy path ran inside the window
}

}  // namespace
}  // namespace teleop::sim
