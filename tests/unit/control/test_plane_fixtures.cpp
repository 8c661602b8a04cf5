// Plane fixtures (common/control/plane_fixtures.hpp) against hand-worked forces: a tilted plane
// in 2-D and 3-D, two planes meeting at an edge (the forces sum), outside and on the plane
// exactly 0, and n = 1 with normal (+1) bit for bit the one-axis UnilateralFixture.
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstdint>
#include <random>

#include "common/control/fixture.hpp"
#include "common/control/plane_fixtures.hpp"

namespace teleop::control {
namespace {

AxisVector vec2(double a, double b) {
  AxisVector v(2);
  v << a, b;
  return v;
}

AxisVector vec3(double a, double b, double c) {
  AxisVector v(3);
  v << a, b, c;
  return v;
}

TEST(PlaneFixtures, TiltedPlaneIn2D) {
  // n = (3, 4)/5, p = 0.01 m, K = 1000 N/m. At x = (0.02, 0.01): n^T x = (0.06 + 0.04)/5 = 0.02,
  // penetration 0.01 m, |F| = 10 N along -n: F = (-6, -8) N.
  PlaneSet set;
  set.add({vec2(0.6, 0.8), 0.01, 1000.0});
  const PlaneSetOutput out = set.evaluate(vec2(0.02, 0.01));
  ASSERT_EQ(out.force_N.size(), 2);
  EXPECT_NEAR(out.force_N(0), -6.0, 1e-12);
  EXPECT_NEAR(out.force_N(1), -8.0, 1e-12);
  EXPECT_NEAR(out.penetration_m, 0.01, 1e-15);
  EXPECT_EQ(out.deepest_plane, 0);
  // The force is along the normal: no tangential part.
  EXPECT_NEAR(-0.8 * out.force_N(0) + 0.6 * out.force_N(1), 0.0, 1e-12);
}

TEST(PlaneFixtures, TiltedPlaneIn3D) {
  // n = (1, 2, 2)/3, p = -0.003 m, K = 600 N/m. At x = (0.003, 0.003, 0.0015):
  // n^T x = (0.003 + 0.006 + 0.003)/3 = 0.004, penetration 0.007 m, |F| = 4.2 N,
  // F = -4.2 (1, 2, 2)/3 = (-1.4, -2.8, -2.8) N.
  PlaneSet set;
  set.add({vec3(1.0 / 3.0, 2.0 / 3.0, 2.0 / 3.0), -0.003, 600.0});
  const PlaneSetOutput out = set.evaluate(vec3(0.003, 0.003, 0.0015));
  EXPECT_NEAR(out.force_N(0), -1.4, 1e-12);
  EXPECT_NEAR(out.force_N(1), -2.8, 1e-12);
  EXPECT_NEAR(out.force_N(2), -2.8, 1e-12);
  EXPECT_NEAR(out.penetration_m, 0.007, 1e-15);
}

TEST(PlaneFixtures, TwoPlanesAtAnEdgeSum) {
  // A floor z > 0.01 (normal +z, K = 500) and a wall x > 0.02 (normal +x, K = 2000) meet at an
  // edge. At (0.025, 0, 0.013): wall penetration 0.005 -> -10 N on x; floor 0.003 -> -1.5 N on
  // z. Deepest: the wall (0.005 > 0.003).
  PlaneSet set;
  set.add({vec3(0.0, 0.0, 1.0), 0.01, 500.0});
  set.add({vec3(1.0, 0.0, 0.0), 0.02, 2000.0});
  const PlaneSetOutput both = set.evaluate(vec3(0.025, 0.0, 0.013));
  EXPECT_NEAR(both.force_N(0), -10.0, 1e-12);
  EXPECT_EQ(both.force_N(1), 0.0);
  EXPECT_NEAR(both.force_N(2), -1.5, 1e-12);
  EXPECT_NEAR(both.penetration_m, 0.005, 1e-15);
  EXPECT_EQ(both.deepest_plane, 1);
  EXPECT_NEAR(both.plane_penetration_m[0], 0.003, 1e-15);
  EXPECT_NEAR(both.plane_penetration_m[1], 0.005, 1e-15);

  // Inside the floor only: the wall adds nothing.
  const PlaneSetOutput floor = set.evaluate(vec3(0.015, 0.0, 0.013));
  EXPECT_EQ(floor.force_N(0), 0.0);
  EXPECT_NEAR(floor.force_N(2), -1.5, 1e-12);
  EXPECT_EQ(floor.deepest_plane, 0);
  EXPECT_EQ(floor.plane_penetration_m[1], 0.0);
}

TEST(PlaneFixtures, OutsideAndOnThePlaneExactlyZero) {
  PlaneSet set;
  set.add({vec2(0.6, 0.8), 0.01, 1000.0});
  // (0.006, 0.0075): n^T x = 0.0036 + 0.006 = 0.0096 < 0.01, just outside.
  for (const AxisVector& x : {vec2(0.0, 0.0), vec2(-1.0, -1.0), vec2(0.006, 0.0075)}) {
    const PlaneSetOutput out = set.evaluate(x);
    EXPECT_EQ(out.force_N(0), 0.0);
    EXPECT_EQ(out.force_N(1), 0.0);
    EXPECT_EQ(out.penetration_m, 0.0);
    EXPECT_EQ(out.deepest_plane, -1);
  }
  // Exactly on an axis-aligned plane: n^T x = p exactly, nothing.
  PlaneSet wall;
  wall.add({vec3(0.0, 1.0, 0.0), 0.02, 3000.0});
  const PlaneSetOutput on = wall.evaluate(vec3(0.5, 0.02, -0.3));
  EXPECT_EQ(on.force_N, AxisVector::Zero(3));
  EXPECT_EQ(on.penetration_m, 0.0);
  EXPECT_EQ(on.deepest_plane, -1);
  // A plane of zero stiffness is absent.
  PlaneSet soft;
  soft.add({vec3(0.0, 1.0, 0.0), 0.0, 0.0});
  const PlaneSetOutput none = soft.evaluate(vec3(0.0, 1.0, 0.0));
  EXPECT_EQ(none.force_N, AxisVector::Zero(3));
  EXPECT_EQ(none.penetration_m, 0.0);
  // No planes: nothing, of the right size.
  EXPECT_EQ(PlaneSet{}.force(vec3(1.0, 2.0, 3.0)), AxisVector::Zero(3));
}

TEST(PlaneFixtures, AtMostEightPlanes) {
  PlaneSet set;
  for (int i = 0; i < kMaxPlanes; ++i) set.add({vec2(1.0, 0.0), 0.1 * i, 1.0});
  EXPECT_EQ(set.size(), kMaxPlanes);
  EXPECT_THROW(set.add({vec2(1.0, 0.0), 0.0, 1.0}), std::invalid_argument);
}

std::uint64_t bits(double v) { return std::bit_cast<std::uint64_t>(v); }

TEST(PlaneFixtures, OneAxisIsUnilateralFixtureBitForBit) {
  std::mt19937_64 rng(18);
  std::uniform_real_distribution<double> position(-0.05, 0.05);
  std::uniform_real_distribution<double> stiffness(0.0, 5000.0);
  int inside = 0;
  for (int trial = 0; trial < 200; ++trial) {
    const FixtureParams f{trial % 17 == 0 ? 0.0 : stiffness(rng), position(rng)};
    const UnilateralFixture one(f);
    PlaneSet set;
    AxisVector normal(1);
    normal << 1.0;
    set.add({normal, f.position_m, f.stiffness_N_per_m});
    for (int k = 0; k < 500; ++k) {
      AxisVector x(1);
      x << position(rng);
      const FixtureOutput a = one.evaluate(x(0));
      const PlaneSetOutput b = set.evaluate(x);
      // The plane pushes with -K (x - p); the one-axis fixture reports K (x - p).
      ASSERT_EQ(bits(0.0 - b.force_N(0)), bits(a.force_N)) << "x = " << x(0);
      ASSERT_EQ(bits(b.penetration_m), bits(a.penetration_m));
      inside += a.penetration_m > 0.0;
    }
  }
  EXPECT_GT(inside, 10000);  // both branches ran
  EXPECT_LT(inside, 90000);
}

}  // namespace
}  // namespace teleop::control
