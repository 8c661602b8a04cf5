// `--set path=value` overrides and the listing of set fields.
#include <google/protobuf/util/message_differencer.h>
#include <gtest/gtest.h>

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

std::string override_error(LoadedConfig& config, const std::string& assignment) {
  return error_of([&] { apply_override(config, assignment); });
}

TEST(ConfigOverride, SetsAScalar) {
  LoadedConfig config = load_config_text(kFullConfig, "TEST");
  apply_override(config, "gains.kps=800");
  EXPECT_EQ(to_teleop_params(config).gains.kps, 800.0);
  apply_override(config, " slave.fixture.stiffness_N_per_m = 2.5e3 ");
  EXPECT_EQ(to_teleop_params(config).slave_fixture.stiffness_N_per_m, 2500.0);
  apply_override(config, "round_trip_delay_samples=7");
  EXPECT_EQ(to_teleop_params(config).round_trip_delay_samples, 7);
  apply_override(config, "gains.kdm=+5");
  EXPECT_EQ(to_teleop_params(config).gains.kdm, 5.0);
}

TEST(ConfigOverride, OverridesPassedToTheLoaderApplyInOrder) {
  const LoadedConfig config = load_config_text(
      kFullConfig, "TEST", {"gains={kps: 800 kdm: 2}", "gains.kpm=10", "gains.kps=900"});
  const TeleopParams p = to_teleop_params(config);
  EXPECT_EQ(p.gains.kps, 900.0);  // the field after its section
  EXPECT_EQ(p.gains.kpm, 10.0);
  EXPECT_EQ(p.gains.kdm, 2.0);
  EXPECT_EQ(p.gains.kds, 0.0);  // the section replaced the file's
}

// Issue 14: `--set a=1 --set a=2` kept the last silently. An error naming both assignments (the
// path as the loader reads it: spaces around the dots do not make it another path).
TEST(ConfigOverride, ARepeatedPathIsAnErrorNamingBothAssignments) {
  const std::string error = error_of([] {
    (void)load_config_text(kFullConfig, "TEST",
                           {"gains.kps=800", "gains.kpm=10", " gains . kps = 900"});
  });
  EXPECT_EQ(error,
            "--set  gains . kps = 900: gains.kps: already set by --set gains.kps=800 (give each "
            "path once)");
  // Another path, or a section and then a field in it, is no repetition.
  EXPECT_NO_THROW((void)load_config_text(kFullConfig, "TEST", {"gains.kps=800", "gains.kpm=800"}));
}

TEST(ConfigOverride, CreatesAbsentSections) {
  LoadedConfig config = load_config_text(kMinimalConfig, "TEST");
  apply_override(config, "scaling.force=0.5");
  apply_override(config, "velocity_filter.cutoff_hz=200");
  const TeleopParams p = to_teleop_params(config);
  EXPECT_EQ(p.scaling.force, 0.5);
  EXPECT_EQ(p.scaling.position, 1.0);
  EXPECT_EQ(p.velocity_cutoff_hz, 200.0);
}

TEST(ConfigOverride, SelectingAOneofMemberSwitchesIt) {
  LoadedConfig config = load_config_text(kFullConfig, "TEST");  // a band human
  apply_override(config, "human.fixed.mass_kg=0.02");
  const TeleopParams p = to_teleop_params(config);
  ASSERT_EQ(p.human.kind, HumanKind::kFixed);
  EXPECT_EQ(p.human.fixed.mass_kg, 0.02);
  EXPECT_EQ(p.human.fixed.damping_Ns_per_m, 0.0);
  EXPECT_EQ(p.human.fixed.stiffness_N_per_m, 0.0);

  apply_override(config, "human.none={}");
  EXPECT_EQ(to_teleop_params(config).human.kind, HumanKind::kNone);
}

TEST(ConfigOverride, RepeatedScalarTakesACommaList) {
  LoadedConfig config = load_config_text(kFullConfig, "TEST");
  apply_override(config, "human.band.force_levels_N=2, 5,8");
  EXPECT_EQ(to_teleop_params(config).human.band.force_levels_N, (std::vector<double>{2, 5, 8}));
  apply_override(config, "human.band.force_levels_N=3");
  EXPECT_EQ(to_teleop_params(config).human.band.force_levels_N, (std::vector<double>{3}));
}

TEST(ConfigOverride, SectionTakesABracedBody) {
  LoadedConfig config = load_config_text(kFullConfig, "TEST");
  apply_override(config, "gains={kpm: 1 kps: 2}");
  const TeleopParams p = to_teleop_params(config);
  EXPECT_EQ(p.gains.kpm, 1.0);
  EXPECT_EQ(p.gains.kps, 2.0);
  EXPECT_EQ(p.gains.kdm, 0.0);  // replaced, not merged
  EXPECT_TRUE(Contains(override_error(config, "gains={kpx: 1}"),
                       "--set gains={kpx: 1}: gains: cannot parse the section"));
}

TEST(ConfigOverride, ErrorsNameTheAssignmentAndPath) {
  LoadedConfig config = load_config_text(kFullConfig, "TEST");
  EXPECT_TRUE(Contains(override_error(config, "gains.kpx=1"),
                       "--set gains.kpx=1: gains.kpx: unknown field 'kpx' in teleop.v1.Gains "
                       "(did you mean 'kpm' or 'kps'?)"));
  EXPECT_TRUE(
      Contains(override_error(config, "gainz.kps=1"),
               "--set gainz.kps=1: gainz: unknown field 'gainz' in teleop.v1.SystemConfig"));
  EXPECT_TRUE(Contains(override_error(config, "gains.kps=abc"),
                       "--set gains.kps=abc: gains.kps: cannot parse 'abc': not a number"));
  EXPECT_TRUE(Contains(override_error(config, "gains.kps="), "gains.kps: cannot parse"));
  EXPECT_TRUE(Contains(override_error(config, "gains.kps=1x"), "gains.kps: cannot parse '1x'"));
  EXPECT_TRUE(Contains(override_error(config, "gains.kps=1e999"), "gains.kps: cannot parse"));
  EXPECT_TRUE(Contains(override_error(config, "round_trip_delay_samples=1.5"),
                       "round_trip_delay_samples: cannot parse '1.5': not an integer"));
  EXPECT_TRUE(Contains(override_error(config, "round_trip_delay_samples=99999999999"),
                       "round_trip_delay_samples: cannot parse '99999999999': out of range"));
  EXPECT_TRUE(Contains(override_error(config, "human.band.force_levels_N=2,x"),
                       "human.band.force_levels_N: cannot parse element 2 'x'"));
  EXPECT_TRUE(Contains(override_error(config, "gains=5"),
                       "--set gains=5: gains: is a section (teleop.v1.Gains), not a scalar"));
  EXPECT_TRUE(Contains(override_error(config, "gains.kps.x=1"),
                       "gains.kps: is a scalar, it has no field 'x'"));
  EXPECT_TRUE(
      Contains(override_error(config, "gains.kps"), "--set gains.kps: expected PATH=VALUE"));
  EXPECT_TRUE(Contains(override_error(config, "=5"), "empty path"));
  EXPECT_TRUE(Contains(override_error(config, "gains..kps=5"), "empty field name"));
}

TEST(ConfigOverride, AFailedOverrideChangesNothing) {
  LoadedConfig config = load_config_text(kFullConfig, "TEST");  // a band human
  const std::string before = config.config.SerializeAsString();
  (void)override_error(config, "human.fixed.mass_kg=abc");
  (void)override_error(config, "human.fixed.mass=1");
  EXPECT_EQ(config.config.SerializeAsString(), before);
  EXPECT_TRUE(config.overridden.empty());
}

TEST(ConfigOverride, InvalidOverriddenValuesNameTheOverride) {
  const std::string nan_error =
      error_of([] { (void)load_config_text(kFullConfig, "TEST", {"gains.kps=nan"}); });
  EXPECT_EQ(nan_error, "--set gains.kps=nan: gains.kps: must be finite, got nan");

  EXPECT_EQ(
      error_of([] { (void)load_config_text(kFullConfig, "TEST", {"master.device.mass_kg=-1"}); }),
      "--set master.device.mass_kg=-1: master.device.mass_kg: must be > 0, got -1");

  // Sections an override creates are attributed to it too.
  EXPECT_TRUE(Contains(error_of([] {
                         (void)load_config_text(kMinimalConfig, "TEST",
                                                {"human.band.points_per_axis=3"});
                       }),
                       "--set human.band.points_per_axis=3: human.band.force_levels_N: missing"));
  EXPECT_TRUE(Contains(error_of([] {
                         (void)load_config_text(kMinimalConfig, "TEST",
                                                {"velocity_filter.cutoff_hz=-600"});
                       }),
                       "--set velocity_filter.cutoff_hz=-600: velocity_filter.cutoff_hz: must be "
                       ">= 0"));
}

TEST(ConfigOverride, FileValuesStillCiteTheFileAfterOverrides) {
  std::string text = kFullConfig;
  const std::size_t at = text.find("cutoff_hz: 200");
  ASSERT_NE(at, std::string::npos);
  text.replace(at, 14, "cutoff_hz: -20");
  const std::string error = error_of([&] {
    (void)load_config_text(text, "TEST", {"gains.kps=800", "sample_rate_hz=300"});
  });
  EXPECT_TRUE(Contains(error, "TEST:8:19: velocity_filter.cutoff_hz: must be >= 0")) << error;
  const LoadedConfig config = load_config_text(kFullConfig, "TEST", {"gains.kps=800"});
  const LoadedConfig copy = config;  // copies share the parse locations
  EXPECT_NO_THROW(validate(copy));
  EXPECT_EQ(to_teleop_params(copy).sample_rate_hz, 500.0);
  EXPECT_EQ(to_teleop_params(copy).gains.kps, 800.0);
}

TEST(ConfigOverride, OverrideCanRepairAnInvalidFile) {
  const std::string text = std::string(kMinimalConfig) + "analysis { required_damping_ratio: 2 }";
  EXPECT_NO_THROW((void)load_config_text(text, "TEST", {"analysis.required_damping_ratio=0.05"}));
}

// ---------------------------------------------------------------------------------------------
// set_fields

TEST(ConfigSetFields, ListsEverySetScalarAsAnAssignment) {
  const std::vector<FieldAssignment> fields =
      set_fields(load_config_text(kFullConfig, "TEST").config);
  const auto value_of = [&](const std::string& path) -> std::string {
    for (const FieldAssignment& field : fields) {
      if (field.path == path) return field.value;
    }
    return "<absent>";
  };
  EXPECT_EQ(value_of("sample_rate_hz"), "500");
  EXPECT_EQ(value_of("gains.kps"), "700");
  EXPECT_EQ(value_of("master.device.damping_Ns_per_m"), "0.41");
  EXPECT_EQ(value_of("master.fixture"), "{}");  // present, stiffness 0
  EXPECT_EQ(value_of("human.band.force_levels_N"), "2,5,8,11,14,17,20");
  EXPECT_EQ(value_of("human.band.mass_kg.lower.intercept"), "0.003");
  EXPECT_EQ(value_of("human.band.mass_kg.lower.slope_per_N"), "<absent>");  // 0 is unset
  EXPECT_EQ(value_of("force_loop.sensor_average_samples"), "40");
}

TEST(ConfigSetFields, ReapplyingTheListReproducesTheConfiguration) {
  for (const std::string& text :
       {std::string(kFullConfig), std::string(kMinimalConfig) + "human { none {} }",
        std::string(kMinimalConfig) + "human { fixed { mass_kg: 0.1 } } scaling {}"}) {
    const LoadedConfig original = load_config_text(text, "TEST");
    LoadedConfig rebuilt = load_config_text("", "EMPTY");
    for (const FieldAssignment& field : set_fields(original.config)) {
      apply_override(rebuilt, field.path + "=" + field.value);
    }
    EXPECT_TRUE(google::protobuf::util::MessageDifferencer::Equals(original.config, rebuilt.config))
        << "original: " << original.config.ShortDebugString()
        << "\nrebuilt: " << rebuilt.config.ShortDebugString();
  }
}

}  // namespace
}  // namespace teleop::config
