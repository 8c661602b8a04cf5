// The one parameter space (issue 14 finding 1): every field's sign and ceiling, endpoints, and
// the same rules for the file, `--set`, and a live ParameterUpdate.
#include <google/protobuf/descriptor.h>
#include <gtest/gtest.h>

#include <cmath>
#include <set>
#include <string>

#include "common/config/config_loader.hpp"
#include "common/config/node_loader.hpp"
#include "common/config/parameter_space.hpp"
#include "tests/unit/config/config_test_util.hpp"

namespace teleop::config {
namespace {

namespace pb = google::protobuf;
using testing::Contains;
using testing::error_of;
using testing::kFullConfig;

const pb::FieldDescriptor* field(const char* full_name) {
  return pb::DescriptorPool::generated_pool()->FindFieldByName(full_name);
}

std::string load_error(const std::vector<std::string>& sets) {
  return error_of([&] { (void)load_config_text(kFullConfig, "TEST", sets); });
}

// A misspelt rule would silently check nothing: every rule names a real field.
TEST(ParameterSpace, EveryRuleNamesAFieldOfTheSchema) {
  for (const std::string_view name : ruled_fields()) {
    EXPECT_NE(field(std::string(name).c_str()), nullptr) << name;
  }
}

// Every floating-point field of the configuration has a rule, or is on this list of values
// whose sign is free and which cannot overflow the model (positions, offsets, scene inputs).
// A new field must be given a rule or added here deliberately.
TEST(ParameterSpace, EveryFloatingPointFieldOfTheConfigurationHasARuleOrIsListedAsFree) {
  const std::set<std::string> sign_free{
      "teleop.v1.Analysis.required_damping_ratio",  // [0, 1): check_ranges' own rule
      "teleop.v1.EStopSchedule.press_at_s",
      "teleop.v1.EStopSchedule.release_at_s",
      "teleop.v1.Scene.equilibrium_perturbation_m",
      "teleop.v1.ConstantForce.force_N",
      "teleop.v1.RampForce.from_N",
      "teleop.v1.RampForce.to_N",
      "teleop.v1.RampForce.start_s",
      "teleop.v1.RampForce.duration_s",
      "teleop.v1.SinusoidForce.offset_N",
      "teleop.v1.SinusoidForce.amplitude_N",
      "teleop.v1.SinusoidForce.frequency_hz",
      "teleop.v1.SinusoidForce.phase_rad",
      "teleop.v1.TraceForce.time_s",
      "teleop.v1.TraceForce.force_N",
      "teleop.v1.Tissue.stiffness_N_per_m",
      "teleop.v1.Tissue.damping_Ns_per_m",
      "teleop.v1.Tissue.position_m",
      "teleop.v1.RigidWall.position_m",
      "teleop.v1.MaliciousUser.force_level_N",
      "teleop.v1.ForceDeviceScene.grip_stiffness_N_per_m",
      "teleop.v1.ForceDeviceScene.grip_damping_Ns_per_m",
      "teleop.v1.ForceDeviceScene.tissue_position_m",
      "teleop.v1.PositionSinusoid.offset_m",
      "teleop.v1.PositionSinusoid.amplitude_m",
      "teleop.v1.PositionSinusoid.frequency_hz",
      "teleop.v1.PositionSinusoid.phase_rad",
      "teleop.v1.PositionTrace.time_s",
      "teleop.v1.PositionTrace.position_m",
  };
  std::set<const pb::Descriptor*> seen;
  std::vector<const pb::Descriptor*> todo{teleop::v1::SystemConfig::descriptor()};
  std::vector<std::string> missing;
  while (!todo.empty()) {
    const pb::Descriptor* type = todo.back();
    todo.pop_back();
    if (!seen.insert(type).second) continue;
    for (int i = 0; i < type->field_count(); ++i) {
      const pb::FieldDescriptor* f = type->field(i);
      if (f->message_type() != nullptr) todo.push_back(f->message_type());
      if (f->cpp_type() != pb::FieldDescriptor::CPPTYPE_DOUBLE) continue;
      if (rule_for(f) == nullptr && sign_free.count(f->full_name()) == 0) {
        missing.push_back(f->full_name());
      }
    }
  }
  EXPECT_TRUE(missing.empty()) << [&] {
    std::string s = "fields without a rule:";
    for (const auto& m : missing) s += " " + m;
    return s;
  }();
}

TEST(ParameterSpace, GainsAreFiniteNonNegativeAndBelowTheirCeilings) {
  const auto* kps = field("teleop.v1.Gains.kps");
  EXPECT_EQ(check_value(kps, 600.0), "");
  EXPECT_EQ(check_value(kps, 0.0), "");
  EXPECT_EQ(check_value(kps, 1e7), "");
  EXPECT_EQ(check_value(kps, -5.0), "must be >= 0, got -5");
  EXPECT_EQ(check_value(kps, std::nan("")), "must be finite, got nan");
  EXPECT_EQ(check_value(kps, -INFINITY), "must be finite, got -inf");
  EXPECT_EQ(check_value(kps, 1e308).rfind("must be in [0, 1e+07] N/m (", 0), 0u);
  EXPECT_NE(check_value(kps, 1e308).find("), got 1e+308"), std::string::npos);
  EXPECT_NE(check_value(kps, std::nextafter(1e7, 2e7)), "");
  for (const char* damping : {"kdm", "kds", "kvm", "kvs"}) {
    const auto* f = field((std::string("teleop.v1.Gains.") + damping).c_str());
    EXPECT_EQ(check_value(f, 1e5), "") << damping;
    EXPECT_NE(check_value(f, 2e5), "") << damping;
    EXPECT_EQ(check_value(f, -1e-9), "must be >= 0, got -1e-09") << damping;
  }
  EXPECT_NE(check_value(field("teleop.v1.Gains.kfm"), 1e308), "");
}

TEST(ParameterSpace, MassesRatesAndScalingsThatOverflowTheModelAreRefused) {
  const auto* mass = field("teleop.v1.Device.mass_kg");
  EXPECT_EQ(check_value(mass, 0.04), "");
  EXPECT_EQ(check_value(mass, -1.0), "must be > 0, got -1");
  EXPECT_EQ(check_value(mass, 0.0), "must be > 0, got 0");
  EXPECT_NE(check_value(mass, 1e-300), "");  // 1/m overflows
  EXPECT_NE(check_value(mass, 1e308), "");
  const auto* rate = field("teleop.v1.SystemConfig.sample_rate_hz");
  EXPECT_EQ(check_value(rate, 1000.0), "");
  EXPECT_NE(check_value(rate, 1e-300), "");
  EXPECT_NE(check_value(rate, 1e308), "");
  const auto* alpha = field("teleop.v1.Scaling.position");
  EXPECT_EQ(check_value(alpha, -2.0), "");  // a mirrored axis
  EXPECT_NE(check_value(alpha, 1e-300), "");
  EXPECT_NE(check_value(alpha, 1e308), "");
  EXPECT_NE(check_value(field("teleop.v1.VelocityFilter.cutoff_hz"), 1e308), "");
  EXPECT_NE(check_value(field("teleop.v1.HumanImpedance.mass_kg"), 1e308), "");
  // Integer fields by the same rules.
  EXPECT_NE(check_value(field("teleop.v1.ForceLoop.sensor_average_samples"), 2e9), "");
}

TEST(ParameterSpace, TheLoaderAppliesTheRulesToTheFileAndToSetNamingTheOrigin) {
  EXPECT_TRUE(
      Contains(load_error({"gains.kps=1e308"}), "--set gains.kps=1e308: gains.kps: must be in"));
  EXPECT_TRUE(Contains(load_error({"gains.kps=-5"}),
                       "--set gains.kps=-5: gains.kps: must be >= 0, got -5"));
  EXPECT_TRUE(
      Contains(load_error({"master.device.mass_kg=1e308"}), "master.device.mass_kg: must be in"));
  EXPECT_TRUE(Contains(load_error({"force_loop.sensor_average_samples=2000000000"}),
                       "force_loop.sensor_average_samples: must be <= 1e+05 samples"));
  EXPECT_TRUE(Contains(error_of([] { (void)load_config_text("gains { kps: 1e308 }\n", "FILE"); }),
                       "FILE:1:9: gains.kps: must be in [0, 1e+07] N/m"));
  // The supervisor's fields too.
  EXPECT_TRUE(Contains(load_error({"supervisor.escalation_ms=1e308"}),
                       "supervisor.escalation_ms: must be in"));
  EXPECT_TRUE(Contains(load_error({"supervisor.passivity_threshold_J=-1"}),
                       "supervisor.passivity_threshold_J: must be > 0"));
}

TEST(ParameterSpace, AHumanBandIsHeldToTheFixedHumansCeilingsAtEveryForceLevel) {
  EXPECT_TRUE(Contains(load_error({"human.band.stiffness_N_per_m.upper.slope_per_N=1e6"}),
                       "human.band.stiffness_N_per_m.upper: must be <= 1e+07 at force level 11 N"));
  EXPECT_TRUE(Contains(load_error({"human.band.force_levels_N=2,5,1e308"}),
                       "human.band.force_levels_N[2]: must be in"));
}

// An n-axis update (a RETUNE to a node of 3 axes with one master and two slave planes): the
// sizes from the node's configuration, each value by its configuration field's rule, the gains
// by the matrix rules (symmetric positive semidefinite), every problem named.
TEST(ParameterSpace, AnNAxisUpdateIsCheckedAgainstTheNodesAxesPlanesAndTheMatrixRules) {
  v1::ParameterUpdate u;
  u.set_change_id(2);
  u.set_axes(3);
  for (int i = 0; i < 9; ++i) u.mutable_gains()->add_kps_matrix(i % 4 == 0 ? 600.0 : 0.0);
  u.add_master_plane_stiffness_n_per_m(0.0);
  u.add_slave_plane_stiffness_n_per_m(800.0);
  u.add_slave_plane_stiffness_n_per_m(1500.0);
  u.set_ramp_ms(200);
  EXPECT_EQ(check_parameter_update_axes(u, 3, 1, 2), "");
  // The one-axis check refuses it by name.
  EXPECT_TRUE(Contains(check_parameter_update(u), "axes (3): an n-axis field"));
  EXPECT_TRUE(
      Contains(check_parameter_update(u), "slave_plane_stiffness_N_per_m: an n-axis field"));
  // Another node: axes and plane counts.
  EXPECT_TRUE(Contains(check_parameter_update_axes(u, 2, 1, 2),
                       "axes: an update for 3 axes, this one has 2"));
  EXPECT_TRUE(Contains(check_parameter_update_axes(u, 3, 1, 1),
                       "slave_plane_stiffness_N_per_m: one stiffness per plane of the side (1 in "
                       "the configuration), got 2"));
  // A value out of its range or not finite, named with its index.
  u.set_slave_plane_stiffness_n_per_m(1, 2e7);
  EXPECT_TRUE(Contains(check_parameter_update_axes(u, 3, 1, 2),
                       "slave_plane_stiffness_N_per_m[1]: must be"));
  u.set_slave_plane_stiffness_n_per_m(1, std::nan(""));
  EXPECT_TRUE(Contains(check_parameter_update_axes(u, 3, 1, 2),
                       "slave_plane_stiffness_N_per_m[1]: must be finite, got nan"));
  u.set_slave_plane_stiffness_n_per_m(1, 1500.0);
  // kps with -700 off the diagonal (0, 1) and (1, 0): eigenvalue 600 - 700 < 0.
  u.mutable_gains()->set_kps_matrix(1, -700.0);
  u.mutable_gains()->set_kps_matrix(3, -700.0);
  EXPECT_TRUE(Contains(check_parameter_update_axes(u, 3, 1, 2),
                       "gains.kps_matrix: not positive semidefinite: its smallest eigenvalue is "
                       "-100"));
  // A matrix of the wrong size.
  u.mutable_gains()->clear_kps_matrix();
  u.mutable_gains()->add_kps_matrix(600.0);
  EXPECT_TRUE(Contains(check_parameter_update_axes(u, 3, 1, 2), "gains.kps_matrix"));
  // Twenty thousand NaNs: one line for the field.
  v1::ParameterUpdate big = u;
  big.mutable_gains()->clear_kps_matrix();
  for (int i = 0; i < 20000; ++i) big.mutable_gains()->add_kfm_matrix(std::nan(""));
  EXPECT_TRUE(Contains(check_parameter_update_axes(big, 3, 1, 2),
                       "gains.kfm_matrix[0]: must be "
                       "finite, got nan"));
  EXPECT_LT(check_parameter_update_axes(big, 3, 1, 2).size(), 300U);
  // The one-axis fixture fields have no place in it.
  u.mutable_gains()->clear_kps_matrix();
  u.set_slave_fixture_stiffness_n_per_m(100.0);
  EXPECT_TRUE(Contains(check_parameter_update_axes(u, 3, 1, 2), "one-axis fields"));
}

TEST(ParameterSpace, ALiveUpdateIsCheckedByTheRulesOfTheConfigurationsFields) {
  v1::ParameterUpdate u;
  u.set_change_id(1);
  u.mutable_gains()->set_kps(600);
  u.set_slave_fixture_stiffness_n_per_m(1500);
  u.set_ramp_ms(200);
  EXPECT_EQ(check_parameter_update(u), "");
  u.mutable_gains()->set_kps(1e308);
  EXPECT_EQ(check_parameter_update(u).rfind("gains.kps: must be in [0, 1e+07] N/m", 0), 0u)
      << check_parameter_update(u);
  u.mutable_gains()->set_kps(-5);
  u.set_ramp_ms(-1);
  EXPECT_EQ(check_parameter_update(u),
            "gains.kps: must be >= 0, got -5; ramp_ms: must be >= 0, got -1");
  u.mutable_gains()->set_kps(600);
  u.set_ramp_ms(10);
  u.set_slave_fixture_position_m(std::nan(""));
  EXPECT_EQ(check_parameter_update(u), "slave_fixture_position_m: must be finite, got nan");
}

TEST(ParameterSpace, EndpointsNeedAPortIn1To65535) {
  EXPECT_EQ(check_endpoint("tcp://127.0.0.1:5560"), "");
  EXPECT_EQ(check_endpoint("tcp://*:5560"), "");
  EXPECT_EQ(check_endpoint("tcp://[::1]:5560"), "");
  EXPECT_EQ(check_endpoint("ipc:///tmp/teleop.sock"), "");
  EXPECT_EQ(check_endpoint("tcp://127.0.0.1:99999"),
            "port must be a number in 1-65535 (peers connect to it), got \"99999\"");
  EXPECT_NE(check_endpoint("tcp://127.0.0.1:0"), "");
  EXPECT_NE(check_endpoint("tcp://127.0.0.1:-1"), "");
  EXPECT_NE(check_endpoint("tcp://127.0.0.1:*"), "");  // the peer could not find it
  EXPECT_NE(check_endpoint("tcp://127.0.0.1:55x"), "");
  EXPECT_NE(check_endpoint("tcp://127.0.0.1"), "");
  EXPECT_NE(check_endpoint("tcp://:5560"), "");
  EXPECT_NE(check_endpoint("udp://127.0.0.1:5560"), "");
  EXPECT_NE(check_endpoint(""), "");
}

TEST(ParameterSpace, EndpointsClashOnTheSamePortOfTheSameOrEveryAddress) {
  EXPECT_TRUE(endpoints_clash("tcp://127.0.0.1:5560", "tcp://127.0.0.1:5560"));
  EXPECT_TRUE(endpoints_clash("tcp://localhost:5560", "tcp://127.0.0.1:5560"));
  EXPECT_TRUE(endpoints_clash("tcp://*:5560", "tcp://127.0.0.1:5560"));
  EXPECT_TRUE(endpoints_clash("tcp://10.0.0.1:5560", "tcp://0.0.0.0:5560"));
  EXPECT_FALSE(endpoints_clash("tcp://10.0.0.1:5560", "tcp://10.0.0.2:5560"));  // two hosts
  EXPECT_FALSE(endpoints_clash("tcp://127.0.0.1:5560", "tcp://127.0.0.1:5561"));
  EXPECT_TRUE(endpoints_clash("ipc:///tmp/a", "ipc:///tmp/a"));
  EXPECT_FALSE(endpoints_clash("ipc:///tmp/a", "ipc:///tmp/b"));
}

TEST(ParameterSpace, EveryBoundEndpointIsDistinctDefaultsIncluded) {
  EXPECT_TRUE(Contains(load_error({"master.node.command_endpoint=tcp://127.0.0.1:5560"}),
                       "master.node.command_endpoint: \"tcp://127.0.0.1:5560\" is also "
                       "master.node.state_endpoint (its default): every bound endpoint must be "
                       "distinct"));
  EXPECT_TRUE(Contains(load_error({"slave.node.state_endpoint=tcp://127.0.0.1:7000",
                                   "supervisor.report_endpoint=tcp://*:7000"}),
                       "supervisor.report_endpoint: \"tcp://*:7000\" is also "
                       "slave.node.state_endpoint: every bound endpoint must be distinct"));
  EXPECT_TRUE(Contains(load_error({"slave.node.command_endpoint=tcp://127.0.0.1:99999"}),
                       "slave.node.command_endpoint: port must be a number in 1-65535"));
  EXPECT_TRUE(Contains(load_error({"master.node.peer_state_endpoint=tcp://127.0.0.1:70000"}),
                       "master.node.peer_state_endpoint: port must be a number in 1-65535"));
  // Two hosts on the same port numbers (examples/two_machines) are fine.
  EXPECT_NO_THROW((void)load_config_file(std::string(TELEOP_SOURCE_DIR) +
                                         "/examples/two_machines/system.textproto"));
}

}  // namespace
}  // namespace teleop::config
