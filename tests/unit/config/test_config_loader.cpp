// Parsing, validation and conversion of SystemConfig text.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "common/config/config_loader.hpp"
#include "tests/unit/config/config_test_util.hpp"

namespace teleop::config {
namespace {

using testing::Contains;
using testing::error_of;
using testing::kFullConfig;
using testing::kMinimalConfig;
using testing::load_error;

// ---------------------------------------------------------------------------------------------
// The full configuration reaches the plain structs field by field.

TEST(ConfigLoad, EveryFieldReachesTeleopParams) {
  const TeleopParams p = to_teleop_params(load_config_text(kFullConfig, "TEST"));
  EXPECT_EQ(p.sample_rate_hz, 500.0);
  EXPECT_EQ(p.master_device.mass_kg, 0.040);
  EXPECT_EQ(p.master_device.damping_Ns_per_m, 0.41);
  EXPECT_EQ(p.slave_device.mass_kg, 0.036);
  EXPECT_EQ(p.slave_device.damping_Ns_per_m, 0.49);
  EXPECT_EQ(p.master_fixture.stiffness_N_per_m, 0.0);
  EXPECT_EQ(p.slave_fixture.stiffness_N_per_m, 1500.0);
  EXPECT_EQ(p.slave_fixture.position_m, 0.002);
  EXPECT_EQ(p.gains.kpm, 600.0);
  EXPECT_EQ(p.gains.kps, 700.0);
  EXPECT_EQ(p.gains.kdm, 2.0);
  EXPECT_EQ(p.gains.kds, 3.0);
  EXPECT_EQ(p.gains.kvm, 0.1);
  EXPECT_EQ(p.gains.kvs, 0.2);
  EXPECT_EQ(p.gains.kfm, 0.5);
  EXPECT_EQ(p.scaling.position, 2.0);
  EXPECT_EQ(p.scaling.force, 0.5);
  EXPECT_EQ(p.velocity_cutoff_hz, 200.0);
  EXPECT_EQ(p.round_trip_delay_samples, 3);
  ASSERT_EQ(p.human.kind, HumanKind::kBand);
  EXPECT_EQ(p.human.band.force_levels_N,
            (std::vector<double>{2.0, 5.0, 8.0, 11.0, 14.0, 17.0, 20.0}));
  EXPECT_EQ(p.human.band.points_per_axis, 5);
  EXPECT_EQ(p.human.band.mass_kg.upper.intercept, 0.012);
  EXPECT_EQ(p.human.band.damping_Ns_per_m.lower.slope_per_N, 0.08);
  EXPECT_EQ(p.human.band.stiffness_N_per_m.upper.slope_per_N, 45.0);
  EXPECT_EQ(p.analysis.required_damping_ratio, 0.1);
  EXPECT_EQ(p.analysis.stiffness_tolerance_N_per_m, 0.5);
}

TEST(ConfigLoad, ForceLoopReachesForceLoopParams) {
  const ForceLoopParams f = to_force_loop_params(load_config_text(kFullConfig, "TEST"));
  EXPECT_EQ(f.mass_kg, 0.25);
  EXPECT_EQ(f.damping_Ns_per_m, 5.0);
  EXPECT_EQ(f.kp, 5.0);
  EXPECT_EQ(f.ki, 0.0);
  EXPECT_EQ(f.sample_rate_hz, 1000.0);
  EXPECT_EQ(f.environment_stiffness_N_per_m, 125.0);
  EXPECT_EQ(f.environment_damping_Ns_per_m, 0.1);
  EXPECT_EQ(f.sensor_average_samples, 40);
}

TEST(ConfigLoad, FixedHumanAndNoHuman) {
  const std::string base = kMinimalConfig;
  const TeleopParams fixed = to_teleop_params(load_config_text(
      base + "human { fixed { mass_kg: 0.01 damping_Ns_per_m: 2 stiffness_N_per_m: 300 } }",
      "TEST"));
  ASSERT_EQ(fixed.human.kind, HumanKind::kFixed);
  EXPECT_EQ(fixed.human.fixed.mass_kg, 0.01);
  EXPECT_EQ(fixed.human.fixed.damping_Ns_per_m, 2.0);
  EXPECT_EQ(fixed.human.fixed.stiffness_N_per_m, 300.0);

  const TeleopParams none = to_teleop_params(load_config_text(base + "human { none {} }", "TEST"));
  EXPECT_EQ(none.human.kind, HumanKind::kNone);
}

// ---------------------------------------------------------------------------------------------
// Defaults when sections are absent.

TEST(ConfigDefaults, AbsentSectionsTakeDocumentedDefaults) {
  const TeleopParams p = to_teleop_params(load_config_text(kMinimalConfig, "TEST"));
  EXPECT_EQ(p.scaling.position, 1.0);
  EXPECT_EQ(p.scaling.force, 1.0);
  EXPECT_EQ(p.velocity_cutoff_hz, 0.0);
  EXPECT_EQ(p.round_trip_delay_samples, 0);
  EXPECT_EQ(p.master_fixture.stiffness_N_per_m, 0.0);
  EXPECT_EQ(p.slave_fixture.stiffness_N_per_m, 0.0);
  EXPECT_EQ(p.master_device.damping_Ns_per_m, 0.0);
  EXPECT_EQ(p.analysis.required_damping_ratio, 0.0);
  EXPECT_EQ(p.analysis.stiffness_tolerance_N_per_m, 1.0);

  // The default band: 7 force levels x 4 points per axis, the lines of the issue.
  ASSERT_EQ(p.human.kind, HumanKind::kBand);
  EXPECT_EQ(p.human.band.force_levels_N,
            (std::vector<double>{2.0, 5.0, 8.0, 11.0, 14.0, 17.0, 20.0}));
  EXPECT_EQ(p.human.band.points_per_axis, 4);
  EXPECT_EQ(p.human.band.mass_kg.lower.intercept, 0.003);
  EXPECT_EQ(p.human.band.mass_kg.upper.intercept, 0.012);
  EXPECT_EQ(p.human.band.damping_Ns_per_m.lower.intercept, 0.6);
  EXPECT_EQ(p.human.band.damping_Ns_per_m.upper.slope_per_N, 0.25);
  EXPECT_EQ(p.human.band.stiffness_N_per_m.lower.slope_per_N, 10.0);
  EXPECT_EQ(p.human.band.stiffness_N_per_m.upper.intercept, 100.0);
}

TEST(ConfigDefaults, PartlyGivenSectionsKeepTheirOtherDefaults) {
  const std::string text = std::string(kMinimalConfig) +
                           "scaling { force: 2 }\n"
                           "analysis { required_damping_ratio: 0.2 }\n"
                           "human { band { force_levels_N: 3\n"
                           "  mass_kg { lower { intercept: 0.01 } upper { intercept: 0.02 } }\n"
                           "  damping_Ns_per_m { lower {} upper { intercept: 1 } }\n"
                           "  stiffness_N_per_m { lower {} upper { intercept: 10 } } } }\n"
                           "force_loop { mass_kg: 1 sample_rate_hz: 100 }\n";
  const LoadedConfig config = load_config_text(text, "TEST");
  const TeleopParams p = to_teleop_params(config);
  EXPECT_EQ(p.scaling.position, 1.0);
  EXPECT_EQ(p.scaling.force, 2.0);
  EXPECT_EQ(p.analysis.stiffness_tolerance_N_per_m, 1.0);
  EXPECT_EQ(p.human.band.points_per_axis, 4);
  EXPECT_EQ(to_force_loop_params(config).sensor_average_samples, 50);
}

// ---------------------------------------------------------------------------------------------
// Syntax and unknown fields: file, 1-based line and column, field.

TEST(ConfigSyntax, UnknownFieldNamesLineColumnAndField) {
  const std::string text =
      "sample_rate_hz: 500\n"
      "gains {\n"
      "  kpm: 600\n"
      "  kpx: 600\n"
      "}\n";
  const std::string error = load_error(text);
  EXPECT_TRUE(Contains(error, "TEST:4:3: gains.kpx: unknown field 'kpx' in teleop.v1.Gains"));
  EXPECT_TRUE(Contains(error, "did you mean 'kpm' or 'kps'?"));
}

TEST(ConfigSyntax, UnknownTopLevelFieldOnLaterLine) {
  const std::string error = load_error(std::string(kMinimalConfig) + "\n\n  sample_rate: 5\n");
  EXPECT_TRUE(Contains(error,
                       "TEST:7:3: sample_rate: unknown field 'sample_rate' in "
                       "teleop.v1.SystemConfig"));
  EXPECT_TRUE(Contains(error, "did you mean 'sample_rate_hz'"));
}

TEST(ConfigSyntax, UnknownFieldInDeepSectionNamesItsPath) {
  const std::string error =
      load_error("master {\n  device { mass_kg: 1 }\n  fixture { stiffness: 3 }\n}\n");
  EXPECT_TRUE(Contains(error,
                       "TEST:3:13: master.fixture.stiffness: unknown field 'stiffness' "
                       "in teleop.v1.Fixture"));
}

TEST(ConfigSyntax, FieldNamesAreCaseSensitive) {
  EXPECT_TRUE(Contains(load_error("master { device { mass_kg: 1 damping_ns_per_m: 1 } }"),
                       "TEST:1:30: master.device.damping_ns_per_m: unknown field"));
}

TEST(ConfigSyntax, BadValueNamesFieldAndPosition) {
  EXPECT_TRUE(Contains(load_error("gains {\n kpm: 1\n kps: abc }"),
                       "TEST:3:7: gains.kps: Expected double, got: abc"));
  EXPECT_TRUE(Contains(load_error("round_trip_delay_samples: 1.5"),
                       "TEST:1:27: round_trip_delay_samples: Expected integer"));
}

TEST(ConfigSyntax, FieldGivenTwiceIsAnError) {
  EXPECT_TRUE(
      Contains(load_error("gains { kps: 1\n kps: 2 }"), "TEST:2:2: gains.kps: set more than once"));
}

TEST(ConfigSyntax, TwoHumanKindsAreAnError) {
  EXPECT_TRUE(Contains(load_error("human {\n fixed {}\n none {} }"),
                       "TEST:3:2: human.none: 'fixed' is already set"));
}

TEST(ConfigSyntax, UnterminatedSectionIsAnError) {
  EXPECT_TRUE(Contains(load_error("gains { kps: 1 "),
                       "TEST:1:16: gains: Expected identifier, got: end of input"));
}

// ---------------------------------------------------------------------------------------------
// NaN and infinities: protobuf's text parser accepts them; the loader must not.

class NonFinite : public ::testing::TestWithParam<const char*> {};

TEST_P(NonFinite, RejectedNamingFieldAndLine) {
  const std::string value = GetParam();
  const std::string text =
      "sample_rate_hz: 500\n"
      "master { device { mass_kg: 0.04 } }\n"
      "slave { device { mass_kg: 0.036 } }\n"
      "gains { kpm: 600\n"
      "  kps: " +
      value + " }\n";
  EXPECT_TRUE(Contains(load_error(text), "TEST:5:3: gains.kps: must be finite, got " +
                                             std::string(value == "inf" ? "inf" : value)));
}

INSTANTIATE_TEST_SUITE_P(ConfigValidation, NonFinite, ::testing::Values("nan", "inf", "-inf"));

TEST(ConfigValidation, NonFiniteAnywhereIsRejected) {
  EXPECT_TRUE(Contains(load_error("analysis { required_damping_ratio: nan }"),
                       "TEST:1:12: analysis.required_damping_ratio: must be finite"));
  EXPECT_TRUE(Contains(load_error("master { fixture {\n position_m: -inf } }"),
                       "TEST:2:2: master.fixture.position_m: must be finite, got -inf"));
  EXPECT_TRUE(Contains(load_error("force_loop { mass_kg: 1 sample_rate_hz: infinity }"),
                       "force_loop.sample_rate_hz: must be finite, got inf"));
}

TEST(ConfigValidation, NonFiniteListElementNamesItsIndex) {
  const std::string text =
      "human { band {\n"
      "  force_levels_N: [2, nan, 8]\n"
      "  mass_kg { lower { intercept: 0.003 } upper { intercept: 0.012 } }\n"
      "  damping_Ns_per_m { lower {} upper { intercept: 1 } }\n"
      "  stiffness_N_per_m { lower {} upper { intercept: 10 } } } }\n";
  EXPECT_TRUE(Contains(load_error(text),
                       "TEST:2:3: human.band.force_levels_N[1]: must be finite, got nan"));
}

TEST(ConfigValidation, ListElementErrorsPointAtTheElementWhenWrittenSeparately) {
  const std::string text =
      "human { band {\n"
      "  force_levels_N: 2\n"
      "  force_levels_N: inf\n"
      "  force_levels_N: 8 } }\n";
  EXPECT_TRUE(Contains(load_error(text),
                       "TEST:3:3: human.band.force_levels_N[1]: must be finite, got inf"));
}

// ---------------------------------------------------------------------------------------------
// Ranges.

class BadMass : public ::testing::TestWithParam<const char*> {};

TEST_P(BadMass, DeviceMassMustBePositive) {
  const std::string value = GetParam();
  const std::string text = "sample_rate_hz: 500\nslave { device {\n  mass_kg: " + value + " } }\n";
  EXPECT_TRUE(
      Contains(load_error(text), "TEST:3:3: slave.device.mass_kg: must be > 0, got " + value));
}

TEST_P(BadMass, ForceLoopMassMustBePositive) {
  const std::string value = GetParam();
  EXPECT_TRUE(Contains(load_error("force_loop { sample_rate_hz: 1000 mass_kg: " + value + " }"),
                       "TEST:1:35: force_loop.mass_kg: must be > 0, got " + value));
}

INSTANTIATE_TEST_SUITE_P(ConfigValidation, BadMass, ::testing::Values("0", "-0.04"));

TEST(ConfigValidation, MissingDeviceMassPointsAtTheDevice) {
  EXPECT_TRUE(
      Contains(load_error("sample_rate_hz: 500\nmaster {\n  device { damping_Ns_per_m: 1 } }\n"),
               "TEST:3:3: master.device.mass_kg: missing"));
}

TEST(ConfigValidation, HumanMayBeMasslessButNotNegative) {
  const std::string base = kMinimalConfig;
  EXPECT_NO_THROW((void)load_config_text(base + "human { fixed { stiffness_N_per_m: 300 } }", "T"));
  EXPECT_TRUE(Contains(load_error(base + "human { fixed { mass_kg: -0.01 } }"),
                       "human.fixed.mass_kg: must be >= 0, got -0.01"));
  EXPECT_TRUE(Contains(load_error(base + "human { fixed { damping_Ns_per_m: -2 } }"),
                       "human.fixed.damping_Ns_per_m: must be >= 0"));
  EXPECT_TRUE(Contains(load_error(base + "human { fixed { stiffness_N_per_m: -1 } }"),
                       "human.fixed.stiffness_N_per_m: must be >= 0"));
}

TEST(ConfigValidation, NegativeDampingAndStiffnessRejected) {
  EXPECT_TRUE(Contains(load_error("master { device { mass_kg: 1 damping_Ns_per_m: -0.4 } }"),
                       "master.device.damping_Ns_per_m: must be >= 0, got -0.4"));
  EXPECT_TRUE(Contains(load_error("slave { fixture { stiffness_N_per_m: -1500 } }"),
                       "slave.fixture.stiffness_N_per_m: must be >= 0, got -1500"));
  EXPECT_TRUE(Contains(
      load_error("force_loop { mass_kg: 1 sample_rate_hz: 1 environment_damping_Ns_per_m: -1 }"),
      "force_loop.environment_damping_Ns_per_m: must be >= 0"));
}

TEST(ConfigValidation, SampleRatesMustBePositive) {
  EXPECT_TRUE(Contains(load_error("sample_rate_hz: 0"), "TEST:1:1: sample_rate_hz: must be > 0"));
  EXPECT_TRUE(Contains(load_error("force_loop { mass_kg: 1 sample_rate_hz: -1000 }"),
                       "force_loop.sample_rate_hz: must be > 0"));
  EXPECT_TRUE(Contains(load_error("force_loop { mass_kg: 1 }"),
                       "TEST:1:1: force_loop.sample_rate_hz: missing"));
}

TEST(ConfigValidation, CutoffMustNotBeNegative) {
  // Any cutoff >= 0 defines the discrete low-pass; one above Nyquist is allowed so a rate sweep
  // (--rates 250,...) can keep the configured filter.
  const std::string base = "sample_rate_hz: 500\n";
  EXPECT_NO_THROW((void)load_config_text(base + "velocity_filter { cutoff_hz: 400 }", "T"));
  EXPECT_TRUE(Contains(load_error(base + "velocity_filter { cutoff_hz: -1 }"),
                       "TEST:2:19: velocity_filter.cutoff_hz: must be >= 0"));
}

TEST(ConfigValidation, DelayWithinLimits) {
  EXPECT_NO_THROW((void)load_config_text("round_trip_delay_samples: 1000", "T"));
  EXPECT_TRUE(Contains(load_error("round_trip_delay_samples: -1"),
                       "round_trip_delay_samples: must be in [0, 1000], got -1"));
  EXPECT_TRUE(Contains(load_error("round_trip_delay_samples: 1001"),
                       "round_trip_delay_samples: must be in [0, 1000], got 1001"));
}

TEST(ConfigValidation, OtherRanges) {
  EXPECT_TRUE(Contains(load_error("scaling { position: 0 }"), "scaling.position: must not be 0"));
  EXPECT_NO_THROW((void)load_config_text("scaling { position: -1 force: 0 }", "T"));
  EXPECT_TRUE(Contains(load_error("analysis { required_damping_ratio: 1 }"),
                       "analysis.required_damping_ratio: must be in [0, 1), got 1"));
  EXPECT_TRUE(Contains(load_error("analysis { required_damping_ratio: -0.1 }"),
                       "analysis.required_damping_ratio: must be in [0, 1)"));
  EXPECT_TRUE(Contains(load_error("analysis { stiffness_tolerance_N_per_m: 0 }"),
                       "analysis.stiffness_tolerance_N_per_m: must be > 0"));
  EXPECT_TRUE(
      Contains(load_error("force_loop { mass_kg: 1 sample_rate_hz: 1 sensor_average_samples: 0 }"),
               "force_loop.sensor_average_samples: must be >= 1, got 0"));
  EXPECT_TRUE(Contains(load_error("human {}"), "TEST:1:1: human: give one of fixed, band or none"));
}

TEST(ConfigValidation, EveryProblemIsReported) {
  const std::string error =
      load_error("sample_rate_hz: -5\nmaster { device { mass_kg: 0 } }\ngains { kps: nan }\n");
  EXPECT_TRUE(Contains(error, "TEST:1:1: sample_rate_hz: must be > 0"));
  EXPECT_TRUE(Contains(error, "TEST:2:19: master.device.mass_kg: must be > 0"));
  EXPECT_TRUE(Contains(error, "TEST:3:9: gains.kps: must be finite"));
}

// ---------------------------------------------------------------------------------------------
// Human bands.

std::string band_config(const std::string& mass, const std::string& damping,
                        const std::string& stiffness, const std::string& extra = "") {
  return "human { band { force_levels_N: [2, 5, 8, 11, 14, 17, 20] " + extra +
         "\n"
         "  mass_kg { " +
         mass +
         " }\n"
         "  damping_Ns_per_m { " +
         damping +
         " }\n"
         "  stiffness_N_per_m { " +
         stiffness + " } } }\n";
}

const std::string kMassOk = "lower { intercept: 0.003 } upper { intercept: 0.012 }";
const std::string kDampingOk =
    "lower { intercept: 0.6 slope_per_N: 0.08 } upper { intercept: 2 slope_per_N: 0.25 }";
const std::string kStiffnessOk =
    "lower { intercept: 50 slope_per_N: 10 } upper { intercept: 100 slope_per_N: 45 }";

TEST(ConfigBand, TheIssuesBandIsValid) {
  EXPECT_NO_THROW((void)load_config_text(band_config(kMassOk, kDampingOk, kStiffnessOk), "T"));
}

TEST(ConfigBand, LowerAboveUpperRejected) {
  const std::string stiffness = "lower { intercept: 200 } upper { intercept: 100 slope_per_N: 1 }";
  EXPECT_TRUE(Contains(load_error(band_config(kMassOk, kDampingOk, stiffness)),
                       "TEST:4:3: human.band.stiffness_N_per_m: lower bound 200 exceeds upper "
                       "bound 102 at force level 2 N"));
}

TEST(ConfigBand, LinesCrossingInsideTheForceRangeRejected) {
  // Lower below upper up to 11 N, above it from 14 N on (the lines cross at 12 N).
  const std::string damping =
      "lower { intercept: 0.5 slope_per_N: 0.25 } upper { intercept: 2 slope_per_N: 0.125 }";
  EXPECT_TRUE(Contains(load_error(band_config(kMassOk, damping, kStiffnessOk)),
                       "human.band.damping_Ns_per_m: lower bound 4 exceeds upper bound 3.75 at "
                       "force level 14 N"));
}

TEST(ConfigBand, LowerMassMustStayPositiveAtEveryLevel) {
  const std::string mass = "lower { intercept: 0.003 slope_per_N: -0.0005 } upper { intercept: 1 }";
  EXPECT_TRUE(Contains(load_error(band_config(mass, kDampingOk, kStiffnessOk)),
                       "human.band.mass_kg.lower: must be > 0 at force level 8 N"));
}

TEST(ConfigBand, LowerDampingAndStiffnessMustNotBeNegative) {
  EXPECT_TRUE(
      Contains(load_error(band_config(kMassOk, "lower { intercept: -1 } upper {}", kStiffnessOk)),
               "human.band.damping_Ns_per_m.lower: must be >= 0 at force level 2 N"));
  EXPECT_NO_THROW(
      (void)load_config_text(band_config(kMassOk, "lower {} upper {}", kStiffnessOk), "T"));
}

TEST(ConfigBand, StructureRules) {
  EXPECT_TRUE(
      Contains(load_error(band_config(kMassOk, kDampingOk, kStiffnessOk, "points_per_axis: 1")),
               "human.band.points_per_axis: must be in [2, 100], got 1"));
  EXPECT_TRUE(Contains(load_error(band_config(kMassOk, kDampingOk, "lower {}")),
                       "human.band.stiffness_N_per_m.upper: missing"));
  EXPECT_TRUE(
      Contains(load_error("human { band {\n"
                          "  mass_kg { lower { intercept: 1 } upper { intercept: 2 } } } }"),
               "TEST:1:9: human.band.force_levels_N: missing"));
  EXPECT_TRUE(Contains(load_error("human { band { force_levels_N: [2, -1] } }"),
                       "human.band.force_levels_N[1]: must be >= 0, got -1"));
  EXPECT_TRUE(Contains(load_error("human { band { force_levels_N: 2 } }"),
                       "human.band.damping_Ns_per_m: missing"));
}

// ---------------------------------------------------------------------------------------------
// Sections the command needs.

TEST(ConfigSections, MissingSectionNamed) {
  const LoadedConfig no_gains = load_config_text(
      "sample_rate_hz: 500\nmaster { device { mass_kg: 1 } }\nslave { device { mass_kg: 1 } }\n",
      "examples/x.textproto");
  EXPECT_EQ(error_of([&] { (void)to_teleop_params(no_gains); }),
            "examples/x.textproto: missing section 'gains' (needed to analyse the teleoperator)");

  const LoadedConfig only_force_loop = load_config_text(
      "force_loop { mass_kg: 1 sample_rate_hz: 1000 }\nmaster { fixture {} }", "F");
  const std::string error = error_of([&] { (void)to_teleop_params(only_force_loop); });
  EXPECT_TRUE(Contains(error, "F: missing section 'sample_rate_hz'"));
  EXPECT_TRUE(Contains(error, "F: missing section 'master.device'"));
  EXPECT_TRUE(Contains(error, "F: missing section 'slave.device'"));
  EXPECT_TRUE(Contains(error, "F: missing section 'gains'"));

  EXPECT_TRUE(
      Contains(error_of([] { (void)to_force_loop_params(load_config_text(kMinimalConfig, "M")); }),
               "M: missing section 'force_loop'"));
}

// ---------------------------------------------------------------------------------------------
// Files.

TEST(ConfigFiles, ShippedForceLoopExampleLoads) {
  const std::filesystem::path path =
      std::filesystem::path(TELEOP_SOURCE_DIR) / "examples" / "force_loop.textproto";
  const ForceLoopParams f = to_force_loop_params(load_config_file(path));
  EXPECT_EQ(f.mass_kg, 0.25);
  EXPECT_EQ(f.damping_Ns_per_m, 5.0);
  EXPECT_EQ(f.kp, 5.0);
  EXPECT_EQ(f.ki, 0.0);
  EXPECT_EQ(f.sample_rate_hz, 1000.0);
  EXPECT_EQ(f.environment_stiffness_N_per_m, 125.0);
  EXPECT_EQ(f.environment_damping_Ns_per_m, 0.1);
  EXPECT_EQ(f.sensor_average_samples, 50);
}

TEST(ConfigFiles, EveryShippedExampleLoads) {
  int count = 0;
  for (const auto& entry :
       std::filesystem::directory_iterator(std::filesystem::path(TELEOP_SOURCE_DIR) / "examples")) {
    if (entry.path().extension() != ".textproto") continue;
    SCOPED_TRACE(entry.path().string());
    EXPECT_NO_THROW((void)load_config_file(entry.path()));
    ++count;
  }
  EXPECT_GE(count, 1);
}

TEST(ConfigFiles, ErrorsNameTheFileAsGiven) {
  const std::filesystem::path path =
      std::filesystem::temp_directory_path() /
      ("teleop_test_config_bad_" + std::to_string(::getpid()) + ".textproto");
  {
    std::ofstream out(path);
    out << "# comment\nsample_rate_hz: nan\n";
  }
  EXPECT_TRUE(Contains(error_of([&] { (void)load_config_file(path); }),
                       path.string() + ":2:1: sample_rate_hz: must be finite, got nan"));
  std::filesystem::remove(path);
}

TEST(ConfigFiles, MissingFileNamed) {
  EXPECT_TRUE(Contains(error_of([] { (void)load_config_file("/nonexistent/teleop.textproto"); }),
                       "/nonexistent/teleop.textproto: cannot open"));
  EXPECT_TRUE(
      Contains(error_of([] { (void)load_config_file(TELEOP_SOURCE_DIR); }), "is a directory"));
}

}  // namespace
}  // namespace teleop::config
