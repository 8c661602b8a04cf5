// The supervisor's comparison of the nodes' configuration fingerprints with its own
// (docs/nodes.md "Before engage"): silent when all agree, and otherwise naming every fingerprint
// and the fields telemetry shows to differ.
#include <gtest/gtest.h>

#include "supervisor/core/configuration_check.hpp"

namespace teleop::supervisor {
namespace {

v1::Telemetry node(std::uint64_t fingerprint, double kps, std::uint64_t change = 0,
                   double ramp = 1.0) {
  v1::Telemetry t;
  t.set_config_fingerprint(fingerprint);
  v1::ActiveParameters* a = t.mutable_active();
  a->set_change_id(change);
  a->mutable_gains()->set_kpm(600);
  a->mutable_gains()->set_kps(kps);
  a->mutable_gains()->set_kdm(2);
  a->mutable_gains()->set_kds(2);
  a->set_slave_fixture_stiffness_n_per_m(1000);
  a->set_ramp_progress(ramp);
  return t;
}

ApprovedConfiguration file() {
  ApprovedConfiguration a;
  a.gains = Gains{600, 600, 2, 2, 0, 0, 0};
  a.slave_fixture_N_per_m = 1000;
  return a;
}

TEST(ConfigurationCheck, AllAgreeIsSilent) {
  const v1::Telemetry m = node(0xaa, 600);
  const v1::Telemetry s = node(0xaa, 600);
  EXPECT_TRUE(compare_configurations(0xaa, file(), &m, &s).message.empty());
  EXPECT_TRUE(compare_configurations(0xaa, file(), nullptr, nullptr).message.empty());
}

TEST(ConfigurationCheck, ASlaveWithOtherGainsIsNamedWithTheField) {
  const v1::Telemetry m = node(0xaa, 600);
  const v1::Telemetry s = node(0xbb, 900);
  const ConfigurationMismatch r = compare_configurations(0xaa, file(), &m, &s);
  EXPECT_EQ(r.side, "slave");
  EXPECT_NE(r.message.find("supervisor 00000000000000aa, master 00000000000000aa, slave "
                           "00000000000000bb"),
            std::string::npos)
      << r.message;
  EXPECT_NE(r.message.find("differing: gains.kps (supervisor 600, master 600, slave 900)"),
            std::string::npos)
      << r.message;
  EXPECT_EQ(r.message.find("gains.kpm"), std::string::npos) << r.message;
}

TEST(ConfigurationCheck, ADifferenceOutsideTheGainsIsStillAnAlarmAndAnOlderNodeIsNamed) {
  const v1::Telemetry m = node(0xcc, 600);
  const v1::Telemetry s = node(0, 600);
  const ConfigurationMismatch r = compare_configurations(0xaa, file(), &m, &s);
  EXPECT_EQ(r.side, "system");
  EXPECT_NE(r.message.find("slave none (an older node?)"), std::string::npos) << r.message;
  EXPECT_NE(r.message.find("difference is elsewhere"), std::string::npos) << r.message;
}

TEST(ConfigurationCheck, MidRampOrOtherChangeValuesAreNotComparedAsFields) {
  // A node mid-ramp, or under another change than the approved one, has values that are
  // neither: the fingerprints still say so, but no field is named from them.
  const v1::Telemetry m = node(0xaa, 600);
  const v1::Telemetry s = node(0xbb, 750, 0, 0.5);
  const ConfigurationMismatch r = compare_configurations(0xaa, file(), &m, &s);
  EXPECT_EQ(r.message.find("gains.kps"), std::string::npos) << r.message;
}

TEST(ConfigurationCheck, TheExperimentBannerNamesTheNodesAndTheirVerdicts) {
  EXPECT_TRUE(experiment_banner(false, nullptr, nullptr).empty());
  v1::Telemetry m = node(0xaa, 600);
  m.mutable_configuration_check()->set_allow_unstable(true);
  m.mutable_configuration_check()->set_verdict("unstable");
  m.mutable_configuration_check()->set_min_damping_ratio(-0.0125);
  const std::string b = experiment_banner(false, &m, nullptr);
  EXPECT_EQ(b.rfind("EXPERIMENT: experiment.allow_unstable is set on the master", 0), 0u) << b;
  EXPECT_NE(b.find("master analysis: unstable (least damping ratio -0.0125"), std::string::npos)
      << b;
  EXPECT_FALSE(experiment_banner(true, nullptr, nullptr).empty());
}

}  // namespace
}  // namespace teleop::supervisor
