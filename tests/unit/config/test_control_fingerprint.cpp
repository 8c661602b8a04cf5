// The configuration fingerprint (docs/nodes.md "Before engage"): canonical (the same values written
// differently give the same fingerprint) and complete (a change of any control-relevant field
// gives another; the list of those fields is looped over, so a field added to the set without
// a change here fails), and blind to what is not control-relevant (endpoints, scene, RT).
#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <set>
#include <string>

#include "common/config/control_fingerprint.hpp"

namespace teleop::config {
namespace {

// Every section the set reads, every value written (with a fixed human).
constexpr const char* kBase =
    "sample_rate_hz: 1000\n"
    "master { device { mass_kg: 0.040 damping_Ns_per_m: 0.41 actuator { max_force_N: 16.5 "
    "max_rate_N_per_s: 20000 } } fixture { stiffness_N_per_m: 0 position_m: 0.01 } }\n"
    "slave { device { mass_kg: 0.036 damping_Ns_per_m: 0.49 actuator { max_force_N: 16.5 "
    "max_rate_N_per_s: 20000 } } fixture { stiffness_N_per_m: 300 position_m: 0.002 }\n"
    "  limits { min_position_m: -0.05 max_position_m: 0.05 max_velocity_m_per_s: 1 "
    "max_force_N: 10 } }\n"
    "gains { kpm: 600 kps: 600 kdm: 2 kds: 2 kvm: 0.1 kvs: 0.1 kfm: 0.2 }\n"
    "scaling { position: 1 force: 1 }\n"
    "velocity_filter { cutoff_hz: 200 }\n"
    "round_trip_delay_samples: 1\n"
    "human { fixed { mass_kg: 0.012 damping_Ns_per_m: 0.76 stiffness_N_per_m: 70 } }\n"
    "analysis { required_damping_ratio: 0.01 stiffness_tolerance_N_per_m: 1 }\n"
    "link { peer_timeout_ms: 30 safe_ramp_ms: 10 engage_ramp_ms: 20 alignment_tolerance_m: "
    "0.002 centring_stiffness_N_per_m: 30 centring_damping_Ns_per_m: 0.3 centring_max_force_N: "
    "0.5 }\n";

// The same values, written otherwise: other order, exponents, trailing zeros, defaults left
// out (scaling 1 and 1, link defaults 30/10/..., round trip as written), comments.
constexpr const char* kBaseRewritten =
    "# the same teleoperator\n"
    "link { centring_max_force_N: 5e-1 engage_ramp_ms: 20.0 }\n"
    "gains { kfm: 0.20 kvs: 1e-1 kvm: 0.1 kds: 2.0 kdm: 2 kps: 6e2 kpm: 600.000 }\n"
    "analysis { stiffness_tolerance_N_per_m: 1.0 required_damping_ratio: 1e-2 }\n"
    "human { fixed { stiffness_N_per_m: 70 damping_Ns_per_m: 0.760 mass_kg: 1.2e-2 } }\n"
    "round_trip_delay_samples: 1\n"
    "velocity_filter { cutoff_hz: 2e2 }\n"
    "slave { limits { max_force_N: 10 max_velocity_m_per_s: 1.0 max_position_m: 5e-2 "
    "min_position_m: -5e-2 } fixture { position_m: 2e-3 stiffness_N_per_m: 3e2 }\n"
    "  device { actuator { max_rate_N_per_s: 2e4 max_force_N: 16.50 } damping_Ns_per_m: 0.49 "
    "mass_kg: 0.0360 } }\n"
    "master { fixture { position_m: 1e-2 } device { actuator { max_rate_N_per_s: 20000.0 "
    "max_force_N: 16.5 } mass_kg: 4e-2 damping_Ns_per_m: 4.1e-1 } }\n"
    "sample_rate_hz: 1e3\n";

std::uint64_t fp(const std::string& text, const std::vector<std::string>& set = {}) {
  return control_fingerprint(load_config_text(text, "test.textproto", set));
}

TEST(ControlFingerprint, EqualValuesWrittenDifferentlyGiveTheSameFingerprint) {
  EXPECT_EQ(fp(kBase), fp(kBaseRewritten));
  // And field by field: the canonical lists are identical.
  const auto a = control_fields(load_config_text(kBase, "a"));
  const auto b = control_fields(load_config_text(kBaseRewritten, "b"));
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].path, b[i].path);
    EXPECT_EQ(a[i].value, b[i].value) << a[i].path;
  }
  // -0 is 0.
  EXPECT_EQ(fp(kBase, {"master.fixture.stiffness_N_per_m=-0"}), fp(kBase));
}

TEST(ControlFingerprint, WhatTheLawDoesNotDependOnLeavesItAlone) {
  const std::uint64_t base = fp(kBase);
  for (const std::string& s :
       {std::string("master.node.command_endpoint=tcp://127.0.0.1:41401"),
        std::string("slave.node.telemetry_rate_hz=25"),
        std::string("master.node.rt.fifo_priority=10"),
        std::string("scene={duration_s: 9 seed: 4}"), std::string("supervisor.change_ramp_ms=50"),
        std::string("slave.device.coulomb_friction_N=0.01")}) {
    EXPECT_EQ(fp(kBase, {s}), base) << s;
  }
}

// A new value for each control-relevant field (PATH=VALUE for --set), all different from the
// base's and valid.
const std::map<std::string, std::string>& changes() {
  static const std::map<std::string, std::string> c = {
      {"sample_rate_hz", "999"},
      {"master.device.mass_kg", "0.041"},
      {"master.device.damping_Ns_per_m", "0.42"},
      {"slave.device.mass_kg", "0.037"},
      {"slave.device.damping_Ns_per_m", "0.5"},
      {"master.fixture.stiffness_N_per_m", "1"},
      {"master.fixture.position_m", "0.011"},
      {"slave.fixture.stiffness_N_per_m", "301"},
      {"slave.fixture.position_m", "0.003"},
      {"gains.kpm", "601"},
      {"gains.kps", "601"},
      {"gains.kdm", "2.1"},
      {"gains.kds", "2.1"},
      {"gains.kvm", "0.11"},
      {"gains.kvs", "0.11"},
      {"gains.kfm", "0.21"},
      {"scaling.position", "1.5"},
      {"scaling.force", "0.5"},
      {"velocity_filter.cutoff_hz", "150"},
      {"round_trip_delay_samples", "2"},
      {"human.fixed.mass_kg", "0.013"},
      {"human.fixed.damping_Ns_per_m", "0.77"},
      {"human.fixed.stiffness_N_per_m", "71"},
      {"human.band.force_levels_N", "2,5,9"},
      {"human.band.points_per_axis", "3"},
      {"human.band.mass_kg.lower.intercept", "0.004"},
      {"human.band.mass_kg.lower.slope_per_N", "0.0001"},
      {"human.band.mass_kg.upper.intercept", "0.013"},
      {"human.band.mass_kg.upper.slope_per_N", "0.0001"},
      {"human.band.damping_Ns_per_m.lower.intercept", "0.7"},
      {"human.band.damping_Ns_per_m.lower.slope_per_N", "0.09"},
      {"human.band.damping_Ns_per_m.upper.intercept", "2.1"},
      {"human.band.damping_Ns_per_m.upper.slope_per_N", "0.26"},
      {"human.band.stiffness_N_per_m.lower.intercept", "51"},
      {"human.band.stiffness_N_per_m.lower.slope_per_N", "11"},
      {"human.band.stiffness_N_per_m.upper.intercept", "101"},
      {"human.band.stiffness_N_per_m.upper.slope_per_N", "46"},
      {"human.none", "{}"},
      {"analysis.required_damping_ratio", "0.02"},
      {"analysis.stiffness_tolerance_N_per_m", "0.5"},
      {"master.device.actuator.max_force_N", "16"},
      {"master.device.actuator.max_rate_N_per_s", "19000"},
      {"slave.device.actuator.max_force_N", "16"},
      {"slave.device.actuator.max_rate_N_per_s", "19000"},
      {"slave.limits.min_position_m", "-0.04"},
      {"slave.limits.max_position_m", "0.04"},
      {"slave.limits.max_velocity_m_per_s", "0.9"},
      {"slave.limits.max_force_N", "9"},
      {"link.peer_timeout_ms", "31"},
      {"link.engage_ramp_ms", "21"},
      {"link.safe_ramp_ms", "11"},
      {"link.alignment_tolerance_m", "0.003"},
      {"link.centring_stiffness_N_per_m", "31"},
      {"link.centring_damping_Ns_per_m", "0.31"},
      {"link.centring_max_force_N", "0.6"},
      {"experiment.allow_unstable", "true"},
  };
  return c;
}

// The default band as written in a file (what an absent human means, here explicit).
constexpr const char* kBand =
    "human { band { force_levels_N: [2, 5, 8] points_per_axis: 2\n"
    "  mass_kg { lower { intercept: 0.003 } upper { intercept: 0.012 } }\n"
    "  damping_Ns_per_m { lower { intercept: 0.6 slope_per_N: 0.08 } upper { intercept: 2 "
    "slope_per_N: 0.25 } }\n"
    "  stiffness_N_per_m { lower { intercept: 50 slope_per_N: 10 } upper { intercept: 100 "
    "slope_per_N: 45 } } } }\n";

TEST(ControlFingerprint, EveryControlRelevantFieldChangesIt) {
  // Both kinds of human, so that every field of the set is listed by one of the bases.
  std::set<std::string> covered;
  std::string band_base = kBase;
  const std::string fixed_line =
      "human { fixed { mass_kg: 0.012 damping_Ns_per_m: 0.76 stiffness_N_per_m: 70 } }\n";
  band_base.replace(band_base.find(fixed_line), fixed_line.size(), kBand);
  for (const std::string& base : {std::string(kBase), band_base}) {
    const LoadedConfig loaded = load_config_text(base, "base");
    const std::uint64_t before = control_fingerprint(loaded);
    for (const ControlField& f : control_fields(loaded)) {
      covered.insert(f.path);
      const auto it = changes().find(f.path);
      ASSERT_NE(it, changes().end()) << "no change written for the field " << f.path;
      const std::uint64_t after = fp(base, {f.path + "=" + it->second});
      EXPECT_NE(after, before) << f.path << " changed to " << it->second;
    }
  }
  // The human's kind itself (fixed -> none).
  EXPECT_NE(fp(kBase, {"human.none={}"}), fp(kBase));
  covered.insert("human.none");
  // Every change written here is of a field of the set (no stale entries).
  for (const auto& [path, value] : changes()) EXPECT_EQ(covered.count(path), 1u) << path;
}

TEST(ControlFingerprint, NeverZeroAndShownAsSixteenHexDigits) {
  EXPECT_NE(fp(kBase), 0u);
  EXPECT_EQ(fingerprint_hex(0x1aULL), "000000000000001a");
}

TEST(ControlFingerprint, TheNodesOwnCheckRefusesAnUnstableConfigurationUnlessTheExperimentFlag) {
  // A slave fixture of 30000 N/m against 600 N/m position gains at 1 kHz and one sample of
  // round trip: far beyond the paper's stable stiffness (Fig. 6: some thousand N/m).
  const LoadedConfig unstable =
      load_config_text(kBase, "u", {"slave.fixture.stiffness_N_per_m=30000"});
  const ConfigurationCheck c = check_configuration(to_teleop_params(unstable), false);
  EXPECT_FALSE(c.permits_coupling);
  EXPECT_EQ(c.verdict, "unstable");
  EXPECT_EQ(c.round_trip_samples, 1);
  EXPECT_NE(c.refusal.find("unstable"), std::string::npos) << c.refusal;
  EXPECT_NE(c.refusal.find("damping ratio"), std::string::npos) << c.refusal;
  const ConfigurationCheck forced = check_configuration(to_teleop_params(unstable), true);
  EXPECT_TRUE(forced.permits_coupling);
  EXPECT_EQ(forced.verdict, "unstable");
  EXPECT_TRUE(forced.refusal.empty());
  // The base is stable with damping to spare; asking for more than it has refuses it.
  const ConfigurationCheck ok =
      check_configuration(to_teleop_params(load_config_text(kBase, "b")), false);
  EXPECT_TRUE(ok.permits_coupling) << ok.refusal;
  EXPECT_EQ(ok.verdict, "stable");
  const LoadedConfig demanding =
      load_config_text(kBase, "d",
                       {"analysis.required_damping_ratio=" +
                        std::to_string(std::min(0.99, ok.min_damping_ratio + 0.05))});
  const ConfigurationCheck d = check_configuration(to_teleop_params(demanding), false);
  EXPECT_EQ(d.verdict, "stable");
  EXPECT_FALSE(d.permits_coupling);
  // At least one sample of round trip even when the file says 0 (two free-running loops).
  const LoadedConfig zero = load_config_text(kBase, "z", {"round_trip_delay_samples=0"});
  EXPECT_EQ(check_configuration(to_teleop_params(zero), false).round_trip_samples, 1);
}

}  // namespace
}  // namespace teleop::config
