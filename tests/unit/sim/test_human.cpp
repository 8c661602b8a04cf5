// Force profiles by hand values, profile sampling, the malicious user's schedule.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <set>
#include <stdexcept>
#include <string>
#include <tuple>

#include "common/sim/human.hpp"

namespace teleop::sim {
namespace {

TEST(ForceProfile, Constant) {
  const ForceProfile p = ForceProfile::constant(2.5);
  EXPECT_EQ(p.at(0.0), 2.5);
  EXPECT_EQ(p.at(100.0), 2.5);
}

TEST(ForceProfile, RampHoldsBeforeAndAfter) {
  const ForceProfile p = ForceProfile::ramp(1.0, 3.0, 0.5, 2.0);
  EXPECT_EQ(p.at(0.0), 1.0);
  EXPECT_EQ(p.at(0.5), 1.0);
  EXPECT_DOUBLE_EQ(p.at(1.0), 1.5);
  EXPECT_DOUBLE_EQ(p.at(1.5), 2.0);
  EXPECT_EQ(p.at(2.5), 3.0);
  EXPECT_EQ(p.at(9.0), 3.0);
  const ForceProfile step = ForceProfile::ramp(0.0, 4.0, 1.0, 0.0);
  EXPECT_EQ(step.at(0.999), 0.0);
  EXPECT_EQ(step.at(1.0), 4.0);
}

TEST(ForceProfile, Sinusoid) {
  const ForceProfile p = ForceProfile::sinusoid(1.0, 0.5, 2.0);
  EXPECT_DOUBLE_EQ(p.at(0.0), 1.0);
  EXPECT_DOUBLE_EQ(p.at(0.125), 1.5);  // quarter period of 2 Hz
  EXPECT_NEAR(p.at(0.25), 1.0, 1e-15);
  EXPECT_DOUBLE_EQ(p.at(0.375), 0.5);
  const ForceProfile cosine = ForceProfile::sinusoid(0.0, 2.0, 1.0, std::numbers::pi / 2);
  EXPECT_DOUBLE_EQ(cosine.at(0.0), 2.0);
}

TEST(ForceProfile, TraceInterpolatesAndHoldsItsEnds) {
  const ForceProfile p = ForceProfile::trace({1.0, 2.0, 4.0}, {0.0, 2.0, -2.0});
  EXPECT_EQ(p.at(0.0), 0.0);
  EXPECT_EQ(p.at(1.0), 0.0);
  EXPECT_DOUBLE_EQ(p.at(1.5), 1.0);
  EXPECT_EQ(p.at(2.0), 2.0);
  EXPECT_DOUBLE_EQ(p.at(3.0), 0.0);
  EXPECT_DOUBLE_EQ(p.at(3.5), -1.0);
  EXPECT_EQ(p.at(10.0), -2.0);
}

TEST(ForceProfile, ValidationNamesTheField) {
  const auto message = [](const ForceProfile& p) {
    try {
      p.validate();
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_NE(message(ForceProfile::trace({1.0, 1.0}, {0.0, 1.0})).find("profile.times_s[1]"),
            std::string::npos);
  EXPECT_NE(message(ForceProfile::trace({1.0}, {0.0, 1.0})).find("profile.values_N"),
            std::string::npos);
  EXPECT_NE(message(ForceProfile::ramp(0.0, 1.0, 0.0, -1.0)).find("profile.duration_s"),
            std::string::npos);
  EXPECT_EQ(message(ForceProfile::sinusoid(0.0, 1.0, 3.0)), "");
}

TEST(Human, SamplesTheProfilePerPeriod) {
  HumanParams p;
  p.profile = ForceProfile::ramp(0.0, 10.0, 0.0, 1.0);  // 10 N/s
  const Human held(p);
  const PeriodForce h = held.exogenous(0.25, 0.001);
  EXPECT_DOUBLE_EQ(h.force_N, 2.5);
  EXPECT_EQ(h.slope_N_per_s, 0.0);
  p.sampling = ProfileSampling::kFirstOrderHold;
  const Human linear(p);
  const PeriodForce l = linear.exogenous(0.25, 0.001);
  EXPECT_DOUBLE_EQ(l.force_N, 2.5);
  EXPECT_NEAR(l.slope_N_per_s, 10.0, 1e-9);
}

TEST(MaliciousUser, VisitsEveryCornerFirstThenTheWholeGrid) {
  const HumanBand band = default_human_band();  // 4 points per axis
  const double level = 8.0;
  const MaliciousUser user({band, level, 0.5});
  ASSERT_EQ(user.size(), 64U);
  std::set<std::tuple<double, double, double>> corners;
  for (const double m : {band.mass_kg.lower.at(level), band.mass_kg.upper.at(level)}) {
    for (const double b :
         {band.damping_Ns_per_m.lower.at(level), band.damping_Ns_per_m.upper.at(level)}) {
      for (const double k :
           {band.stiffness_N_per_m.lower.at(level), band.stiffness_N_per_m.upper.at(level)}) {
        corners.insert({m, b, k});
      }
    }
  }
  ASSERT_EQ(corners.size(), 8U);
  std::set<std::tuple<double, double, double>> seen_corners;
  std::set<std::tuple<double, double, double>> seen;
  // Walk the schedule by time, as the device does.
  for (int visit = 0; visit < 64; ++visit) {
    const std::size_t i = user.index_at(visit * 0.5 + 0.25);
    EXPECT_EQ(i, static_cast<std::size_t>(visit));
    const HumanImpedance& z = user.impedance(i);
    const std::tuple<double, double, double> key{z.mass_kg, z.damping_Ns_per_m,
                                                 z.stiffness_N_per_m};
    if (visit < 8) {
      EXPECT_TRUE(user.is_corner(i));
      EXPECT_TRUE(corners.count(key)) << "visit " << visit;
      seen_corners.insert(key);
    } else {
      EXPECT_FALSE(corners.count(key)) << "visit " << visit;
    }
    seen.insert(key);
  }
  EXPECT_EQ(seen_corners, corners);
  EXPECT_EQ(seen.size(), 64U);
  // Then it starts over, and the boundaries fall exactly on multiples of the dwell.
  EXPECT_EQ(user.index_at(64 * 0.5), 0U);
  EXPECT_EQ(user.index_at(0.5), 1U);
  EXPECT_EQ(user.index_at(0.4999), 0U);
}

TEST(MaliciousUser, ThroughHumanReportsWhereItIs) {
  const Human h(HumanParams::malicious_pushing(default_human_band(), 5.0, 2.0));
  EXPECT_EQ(h.exogenous(3.0, 0.001).force_N, 5.0);
  EXPECT_EQ(h.malicious_index_at(3.0), std::optional<std::size_t>(1));
  const HumanImpedance z = h.impedance_at(3.0);
  EXPECT_EQ(z.mass_kg, h.malicious()->impedance(1).mass_kg);
  EXPECT_EQ(Human(HumanParams{}).malicious_index_at(3.0), std::nullopt);
}

TEST(MaliciousUser, RejectsABandItCannotWalk) {
  HumanBand band = default_human_band();
  band.points_per_axis = 1;
  EXPECT_THROW(MaliciousUser({band, 5.0, 1.0}), std::invalid_argument);
  band = default_human_band();
  EXPECT_THROW(MaliciousUser({band, 5.0, 0.0}), std::invalid_argument);
  band.stiffness_N_per_m.upper = {10.0, 0.0};  // upper below lower
  try {
    MaliciousUser user({band, 5.0, 1.0});
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("stiffness_N_per_m"), std::string::npos);
  }
}

}  // namespace
}  // namespace teleop::sim
