// The one configuration pipeline (common/config/system_compiler.hpp): one validation from the
// file to the typed system, the nodes' laws and devices the simulator's, the supervisor's
// defaults.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <string>

#include "common/config/control_fingerprint.hpp"
#include "common/config/node_loader.hpp"
#include "common/config/resimulation_loader.hpp"
#include "common/config/scene_loader.hpp"
#include "common/config/system_compiler.hpp"

namespace teleop::config {
namespace {

using transport::Role;

const std::string kPaddles =
    "sample_rate_hz: 1000\n"
    "master { device { mass_kg: 0.040 damping_Ns_per_m: 0.41 } }\n"
    "slave { device { mass_kg: 0.036 damping_Ns_per_m: 0.49 actuator { max_force_N: 4 } }\n"
    "        fixture { stiffness_N_per_m: 1500 position_m: 0.006 }\n"
    "        limits { max_position_m: 0.05 max_force_N: 3 } }\n"
    "gains { kpm: 600 kps: 600 kdm: 2 kds: 2 }\n"
    "human { fixed { mass_kg: 0.01 damping_Ns_per_m: 1 stiffness_N_per_m: 100 } }\n";

const std::string kScene =
    "scene { duration_s: 0.5 seed: 7\n"
    "        human_force { constant { force_N: 1.5 } }\n"
    "        environment { tissue { stiffness_N_per_m: 300 damping_Ns_per_m: 1 "
    "position_m: 0.01 } } }\n";

std::string examples(const char* name) {
  return std::string(TELEOP_SOURCE_DIR) + "/examples/" + name;
}

// A node's start in node_main.cpp: the file compiled, its node taken, its own analysis fed the
// compiled teleoperator; validate() runs once.
TEST(SystemCompiler, ANodeStartValidatesTheFileOnce) {
  const std::uint64_t before = validation_count();
  const CompiledSystem system = compile_system_file(examples("live.textproto"));
  const NodeSetup slave = system.node(Role::kSlave);
  const ConfigurationCheck check = check_configuration(system.teleop(), system.allow_unstable());
  EXPECT_EQ(validation_count() - before, 1U);
  EXPECT_TRUE(check.permits_coupling) << check.refusal;
  EXPECT_GT(slave.settings.law.slave_fixture.stiffness_N_per_m, 0.0);
}

// Each reader of a parsed file validates it once, whatever it builds from it.
TEST(SystemCompiler, EachReaderValidatesOnce) {
  const LoadedConfig parsed = parse_config_text(kPaddles + kScene, "paddles.textproto");
  std::uint64_t before = validation_count();
  (void)compile_system(parsed);
  EXPECT_EQ(validation_count() - before, 1U) << "compile_system";
  before = validation_count();
  (void)to_node_setup(parsed, Role::kMaster);
  EXPECT_EQ(validation_count() - before, 1U) << "to_node_setup";
  before = validation_count();
  (void)to_scene_setup(parsed);
  EXPECT_EQ(validation_count() - before, 1U) << "to_scene_setup";
  before = validation_count();
  (void)control_fingerprint(parsed);
  EXPECT_EQ(validation_count() - before, 1U) << "control_fingerprint";
}

// `replay --resimulate` validates the recorded configuration once, with a scene or without;
// overrides make another configuration, and that one is validated once more. The simulated
// slave it builds is the node's (without a scene) or the lockstep simulator's (with one).
TEST(SystemCompiler, AResimulationValidatesEachConfigurationOnce) {
  for (const std::string& text : {kPaddles, kPaddles + kScene}) {
    const LoadedConfig recorded = parse_config_text(text, "recorded.textproto");
    std::uint64_t before = validation_count();
    const auto same = to_resimulation(recorded, recorded, 0.001, 0.002);
    EXPECT_EQ(validation_count() - before, 1U) << text;
    ASSERT_TRUE(same.has_value());
    const LoadedConfig changed = parse_config_text(text, "recorded.textproto",
                                                   {"gains.kps=500", "slave.device.mass_kg=0.05"});
    before = validation_count();
    const auto other = to_resimulation(changed, recorded, 0.001, 0.002);
    EXPECT_EQ(validation_count() - before, 2U) << text;
    ASSERT_TRUE(other.has_value());
    EXPECT_EQ(other->setup.law.gains.kps, 500.0);
    EXPECT_EQ(same->setup.law.gains.kps, recorded.config.gains().kps());
    EXPECT_EQ(other->setup.slave.plant.device.mass_kg, 0.05);
    // The recording's own slave, whatever the overrides.
    for (const auto* r : {&*same, &*other}) {
      EXPECT_EQ(r->recorded_slave.plant.device.mass_kg, recorded.config.slave().device().mass_kg());
    }
  }
}

// An invalid file never becomes a system: the compile names the field.
TEST(SystemCompiler, AnInvalidFileIsRefusedNamingTheField) {
  const LoadedConfig parsed =
      parse_config_text(kPaddles, "bad.textproto", {"slave.fixture.stiffness_N_per_m=-5"});
  try {
    (void)compile_system(parsed);
    FAIL() << "compiled a negative fixture stiffness";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("slave.fixture.stiffness_N_per_m"), std::string::npos)
        << e.what();
  }
}

// The live node runs what the lockstep simulator runs for the same file: the same law (with
// the hardware's limits) and the same simulated sides; only the node holds its scene until it
// engages and takes its period from the rate.
TEST(SystemCompiler, TheNodesLawAndDevicesAreTheSimulators) {
  const LoadedConfig parsed = parse_config_text(kPaddles + kScene, "paddles.textproto");
  const CompiledSystem system = compile_system(parsed);
  const scene::SceneSetup scene = to_scene_setup(parsed);
  for (const Role role : {Role::kMaster, Role::kSlave}) {
    const control::LawParams& live = system.node(role).settings.law;
    EXPECT_EQ(live.slave_fixture.stiffness_N_per_m, scene.law.slave_fixture.stiffness_N_per_m);
    EXPECT_EQ(live.slave_fixture.position_m, scene.law.slave_fixture.position_m);
    EXPECT_EQ(live.slave_actuator.max_force_N, scene.law.slave_actuator.max_force_N);
    EXPECT_EQ(live.slave_limits.max_position_m, scene.law.slave_limits.max_position_m);
    EXPECT_EQ(live.slave_limits.max_force_N, scene.law.slave_limits.max_force_N);
    EXPECT_EQ(live.gains.kps, scene.law.gains.kps);
    EXPECT_EQ(live.period_s, scene.law.period_s);
  }
  // The file's numbers, not a copy of either path's: the slave's fixture, actuator and
  // workspace as written.
  const control::LawParams& law = system.node(Role::kSlave).settings.law;
  EXPECT_EQ(law.slave_fixture.stiffness_N_per_m, 1500.0);
  EXPECT_EQ(law.slave_fixture.position_m, 0.006);
  EXPECT_EQ(law.slave_actuator.max_force_N, 4.0);
  EXPECT_EQ(law.slave_limits.max_position_m, 0.05);
  EXPECT_EQ(law.slave_limits.max_force_N, 3.0);
  const NodeSetup& slave = system.node(Role::kSlave);
  EXPECT_EQ(slave.sim.seed, scene.slave.seed);
  EXPECT_EQ(slave.sim.seed, 8U);  // scene.seed + 1 for the slave
  EXPECT_EQ(slave.sim.amplifier.max_force_N, 4.0);
  EXPECT_TRUE(slave.sim.hold_scene_until_engaged);
  EXPECT_FALSE(scene.slave.hold_scene_until_engaged);
  const NodeSetup& master = system.node(Role::kMaster);
  ASSERT_TRUE(master.sim.human.has_value());
  EXPECT_EQ(master.sim.human->impedance.stiffness_N_per_m, 100.0);
  EXPECT_EQ(master.sim.human->profile.at(0.2), 1.5);
}

// Without a scene: no push, free space, the paddle's actuator (16.5 N, Abbott-Okamura §4.1).
TEST(SystemCompiler, WithoutASceneTheHumanHoldsStillInFreeSpace) {
  const CompiledSystem system = compile_system(
      parse_config_text(kPaddles, "paddles.textproto", {"slave.device.actuator={}"}));
  const NodeSetup& master = system.node(Role::kMaster);
  ASSERT_TRUE(master.sim.human.has_value());
  EXPECT_EQ(master.sim.human->profile.at(1.0), 0.0);
  EXPECT_EQ(master.settings.law.master_actuator.max_force_N, 16.5);
  EXPECT_EQ(system.node(Role::kSlave).settings.law.slave_actuator.max_force_N, 16.5);
}

// Both nodes carry the same fingerprint: either would refuse to couple with the other if not.
TEST(SystemCompiler, BothNodesCarryOneFingerprint) {
  const CompiledSystem system = compile_system(parse_config_text(kPaddles, "paddles.textproto"));
  EXPECT_NE(system.node(Role::kMaster).settings.config_fingerprint, 0U);
  EXPECT_EQ(system.node(Role::kMaster).settings.config_fingerprint,
            system.node(Role::kSlave).settings.config_fingerprint);
}

// The supervisor's defaults (config.proto): endpoints 5566/5567, 2 encoder counts of the
// master's oscillation, 5 mJ and 2 mW, 500 ms of escalation, 200 ms ramps.
TEST(SystemCompiler, TheSupervisorsDefaultsAreTheDocumentedOnes) {
  const CompiledSystem system = compile_system(
      parse_config_text(kPaddles, "paddles.textproto",
                        {"master.device.encoder={counts_per_rev: 1000 transmission_ratio: 10 "
                         "metres_per_radian: 0.1}"}));
  const SupervisorSettings& s = system.supervisor();
  EXPECT_EQ(s.report_endpoint, "tcp://127.0.0.1:5566");
  EXPECT_EQ(s.request_endpoint, "tcp://127.0.0.1:5567");
  // One count: 2 pi 0.1 m / (1000 * 10) = 6.2832e-5 m; two of them.
  EXPECT_NEAR(s.oscillation_threshold_m, 2.0 * 2.0 * std::numbers::pi * 0.1 / 10000.0, 1e-15);
  EXPECT_EQ(s.passivity_threshold_J, 0.005);
  EXPECT_EQ(s.passivity_power_threshold_W, 0.002);
  EXPECT_EQ(s.escalation_ms, 500.0);
  EXPECT_EQ(s.change_ramp_ms, 200.0);
  const CompiledSystem set = compile_system(parse_config_text(
      kPaddles, "paddles.textproto",
      {"supervisor.escalation_ms=800", "supervisor.report_endpoint=tcp://127.0.0.1:6000"}));
  EXPECT_EQ(set.supervisor().escalation_ms, 800.0);
  EXPECT_EQ(set.supervisor().report_endpoint, "tcp://127.0.0.1:6000");
}

}  // namespace
}  // namespace teleop::config
