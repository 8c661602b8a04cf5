// The supervisor's audit of the parameters in force (issue 14 "Authority"): what a node's
// telemetry reports against what the supervisor approved, its own changes (waiting, ramping,
// a newer target taken into a ramp) never a mismatch, anything else named field by field.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <stdexcept>

#include "supervisor/core/parameter_audit.hpp"

namespace teleop::supervisor {
namespace {

// The file's values: the paddles' gains, a 1000 N/m slave wall.
ApprovedParameters file_values() {
  ApprovedParameters p;
  p.gains = Gains{600, 600, 2, 2, 0, 0, 0};
  p.slave_fixture_N_per_m = 1000;
  return p;
}

v1::ActiveParameters active(std::uint64_t id, const ApprovedParameters& p, double progress = 1.0) {
  v1::ActiveParameters a;
  a.set_change_id(id);
  v1::Gains* g = a.mutable_gains();
  g->set_kpm(p.gains.kpm);
  g->set_kps(p.gains.kps);
  g->set_kdm(p.gains.kdm);
  g->set_kds(p.gains.kds);
  g->set_kvm(p.gains.kvm);
  g->set_kvs(p.gains.kvs);
  g->set_kfm(p.gains.kfm);
  a.set_master_fixture_stiffness_n_per_m(p.master_fixture_N_per_m);
  a.set_slave_fixture_stiffness_n_per_m(p.slave_fixture_N_per_m);
  a.set_ramp_progress(progress);
  return a;
}

TEST(ParameterAudit, TheFilesValuesAreChangeZero) {
  const ParameterAudit audit(file_values());
  EXPECT_TRUE(audit.check(active(0, file_values())).empty());
}

TEST(ParameterAudit, AnUnapprovedValueUnderChangeZeroIsNamedWithBothValues) {
  const ParameterAudit audit(file_values());
  ApprovedParameters hostile = file_values();
  hostile.slave_fixture_N_per_m = 9000;
  const auto m = audit.check(active(0, hostile));
  ASSERT_EQ(m.size(), 1u);
  EXPECT_EQ(m[0].field, "slave_fixture_stiffness_N_per_m");
  EXPECT_EQ(m[0].in_force, 9000);
  EXPECT_EQ(m[0].approved, 1000);
  EXPECT_NE(describe(m).find("slave_fixture_stiffness_N_per_m 9000 in force under change 0 "
                             "(approved 1000)"),
            std::string::npos)
      << describe(m);
}

TEST(ParameterAudit, AChangeNumberNeverApprovedIsAMismatchWhateverItsValues) {
  const ParameterAudit audit(file_values());
  const auto m = audit.check(active(7, file_values()));
  ASSERT_EQ(m.size(), 1u);
  EXPECT_EQ(m[0].field, "change_id");
  EXPECT_EQ(m[0].in_force, 7);
}

TEST(ParameterAudit, ItsOwnChangeWaitingRampingAndSettledIsNeverAMismatch) {
  ParameterAudit audit(file_values());
  ApprovedParameters next = file_values();
  next.slave_fixture_N_per_m = 500;
  next.gains.kps = 550;
  audit.approve(1, next);
  // Waiting for the apply point: the old values, change 0.
  EXPECT_TRUE(audit.check(active(0, file_values())).empty());
  // Ramping: every value between the two.
  for (const double w : {0.0, 0.25, 0.5, 0.999}) {
    ApprovedParameters mid = file_values();
    mid.slave_fixture_N_per_m = 1000 + w * (500 - 1000);
    mid.gains.kps = 600 + w * (550 - 600);
    EXPECT_TRUE(audit.check(active(1, mid, w)).empty()) << w;
  }
  EXPECT_TRUE(audit.check(active(1, next)).empty());
}

TEST(ParameterAudit, ANewerTargetTakenIntoARampUnderWayIsNotAMismatch) {
  ParameterAudit audit(file_values());
  ApprovedParameters one = file_values();
  one.slave_fixture_N_per_m = 700;
  ApprovedParameters two = file_values();
  two.slave_fixture_N_per_m = 900;
  audit.approve(1, one);
  audit.approve(2, two);
  // The node settled change 1's ramp on change 2's values.
  EXPECT_TRUE(audit.check(active(1, two)).empty());
  // But never an older change's values under a newer number.
  EXPECT_FALSE(audit.check(active(2, one)).empty());
}

TEST(ParameterAudit, ARampOutsideEveryApprovedValueIsAMismatch) {
  ParameterAudit audit(file_values());
  ApprovedParameters next = file_values();
  next.slave_fixture_N_per_m = 500;
  audit.approve(1, next);
  ApprovedParameters beyond = file_values();
  beyond.slave_fixture_N_per_m = 1500;
  const auto m = audit.check(active(1, beyond, 0.5));
  ASSERT_EQ(m.size(), 1u);
  EXPECT_EQ(m[0].field, "slave_fixture_stiffness_N_per_m");
  EXPECT_EQ(m[0].approved, 1000);
}

TEST(ParameterAudit, NonFiniteValuesOrProgressNeverPass) {
  ParameterAudit audit(file_values());
  ApprovedParameters nan = file_values();
  nan.gains.kps = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(audit.check(active(0, nan)).empty());
  EXPECT_FALSE(audit.check(active(0, nan, 0.5)).empty());
  ApprovedParameters inf = file_values();
  inf.slave_fixture_N_per_m = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(audit.check(active(0, inf, std::numeric_limits<double>::quiet_NaN())).empty());
}

TEST(ParameterAudit, AChangeNumberIsApprovedOnce) {
  ParameterAudit audit(file_values());
  ApprovedParameters next = file_values();
  next.slave_fixture_N_per_m = 500;
  audit.approve(1, next);
  EXPECT_NO_THROW(audit.approve(1, next));
  ApprovedParameters other = next;
  other.slave_fixture_N_per_m = 600;
  EXPECT_THROW(audit.approve(1, other), std::logic_error);
}

TEST(ParameterAudit, AnOlderApprovedChangeInForceAfterANewerOneIsAMismatch) {
  ParameterAudit audit(file_values());
  ApprovedParameters one = file_values();
  one.slave_fixture_N_per_m = 2000;
  ApprovedParameters two = file_values();
  two.slave_fixture_N_per_m = 500;
  audit.approve(1, one);
  audit.approve(2, two);
  EXPECT_TRUE(audit.check(active(1, one), 1).empty());
  const auto m = audit.check(active(1, one), 2);
  ASSERT_EQ(m.size(), 1u);
  EXPECT_EQ(m[0].field, "change_id");
  EXPECT_NE(m[0].why.find("change 1 in force after change 2"), std::string::npos) << m[0].why;
}

}  // namespace
}  // namespace teleop::supervisor
