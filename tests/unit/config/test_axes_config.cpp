// Several task-space axes in the configuration (issue 18 "Configuration", "Shipped examples";
// common/config/axes_config.hpp): old files unchanged, each rule named, `--set` by index, the
// one-axis tools' refusal, and the two shipped n-axis examples.
#include <google/protobuf/io/coded_stream.h>
#include <google/protobuf/io/zero_copy_stream_impl_lite.h>
#include <google/protobuf/util/message_differencer.h>
#include <gtest/gtest.h>

#include <charconv>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <string>
#include <vector>

#include "common/config/axes_config.hpp"
#include "common/config/config_loader.hpp"
#include "common/config/scene_loader.hpp"
#include "common/config/system_compiler.hpp"
#include "common/core/teleop_axes.hpp"
#include "tests/unit/config/config_test_util.hpp"

namespace teleop::config {
namespace {

using testing::Contains;
using testing::error_of;
using testing::kFullConfig;
using testing::kMinimalConfig;

std::string example(const std::string& name) {
  return std::string(TELEOP_SOURCE_DIR) + "/examples/" + name;
}

std::uint64_t fnv1a(const std::string& bytes) {
  std::uint64_t h = 0xcbf29ce484222325ULL;
  for (const char c : bytes) {
    h ^= static_cast<unsigned char>(c);
    h *= 0x100000001b3ULL;
  }
  return h;
}

std::string deterministic_bytes(const teleop::v1::SystemConfig& config) {
  std::string bytes;
  {
    google::protobuf::io::StringOutputStream stream(&bytes);
    google::protobuf::io::CodedOutputStream coded(&stream);
    coded.SetSerializationDeterministic(true);
    config.SerializeToCodedStream(&coded);
  }
  return bytes;
}

std::string shortest(double v) {
  char buffer[64];
  const auto result = std::to_chars(buffer, buffer + sizeof buffer, v);
  return std::string(buffer, result.ptr);
}

// Every number of a TeleopParams, one a line: the golden values below hash this text.
std::string params_text(const TeleopParams& p) {
  std::string s;
  const auto add = [&](const char* name, double v) {
    s += std::string(name) + "=" + shortest(v) + "\n";
  };
  add("rate", p.sample_rate_hz);
  add("mm", p.master_device.mass_kg);
  add("bm", p.master_device.damping_Ns_per_m);
  add("ms", p.slave_device.mass_kg);
  add("bs", p.slave_device.damping_Ns_per_m);
  add("kmf", p.master_fixture.stiffness_N_per_m);
  add("pmf", p.master_fixture.position_m);
  add("ksf", p.slave_fixture.stiffness_N_per_m);
  add("psf", p.slave_fixture.position_m);
  const Gains& g = p.gains;
  for (const double v : {g.kpm, g.kps, g.kdm, g.kds, g.kvm, g.kvs, g.kfm}) add("g", v);
  add("alpha", p.scaling.position);
  add("beta", p.scaling.force);
  add("fc", p.velocity_cutoff_hz);
  add("d", p.round_trip_delay_samples);
  add("hk", static_cast<int>(p.human.kind));
  add("hm", p.human.fixed.mass_kg);
  add("hb", p.human.fixed.damping_Ns_per_m);
  add("hs", p.human.fixed.stiffness_N_per_m);
  for (const double f : p.human.band.force_levels_N) add("F", f);
  add("ppa", p.human.band.points_per_axis);
  for (const ParameterBand* b :
       {&p.human.band.mass_kg, &p.human.band.damping_Ns_per_m, &p.human.band.stiffness_N_per_m}) {
    add("li", b->lower.intercept);
    add("ls", b->lower.slope_per_N);
    add("ui", b->upper.intercept);
    add("us", b->upper.slope_per_N);
  }
  add("zeta", p.analysis.required_damping_ratio);
  add("tol", p.analysis.stiffness_tolerance_N_per_m);
  return s;
}

// Each shipped one-axis example before the n-axis fields existed (commit 3cf96df): its
// deterministic wire bytes (length and FNV-1a 64; the same bytes `protoc --encode` gives from
// that commit's config.proto) and the FNV-1a 64 of params_text(to_teleop_params) (0: no
// teleoperator in the file).
struct Golden {
  const char* file;
  std::size_t bytes;
  std::uint64_t bytes_hash;
  std::uint64_t params_hash;
};
const Golden kGolden[] = {
    {"force_loop.textproto", 58, 0xcf7c250ffe2d884fULL, 0},
    {"live.textproto", 290, 0x22edb2f41b196a83ULL, 1270265188326831463ULL},
    {"paddles.textproto", 322, 0xc932e330cf76dc3bULL, 5895952198845623584ULL},
    {"scenes/force_free_motion.textproto", 134, 0xa4a4c507a332c0bULL, 0},
    {"scenes/force_tissue.textproto", 731, 0x91eb368b4b62258aULL, 0},
    {"scenes/identify_excitation.textproto", 48163, 0xdffd00110298103bULL, 2893300829788969648ULL},
    {"scenes/paddles_master_fixture.textproto", 198, 0x7d9b2b5752c96274ULL,
     16233178277675701855ULL},
    {"scenes/paddles_slave_fixture_stable.textproto", 198, 0xb593f8a40a1c06cULL,
     16013222958867369723ULL},
    {"scenes/paddles_slave_fixture_unstable.textproto", 198, 0x8778fcf51dda27b4ULL,
     15796888064177634489ULL},
    {"scenes/paddles_unilateral.textproto", 169, 0xa8e7042ed859e0efULL, 6948190028588771588ULL},
    {"two_machines/system.textproto", 769, 0x604acc16d32dd8a4ULL, 9006195770567357614ULL},
};

// Exact equality of every field (the n = 1 contract is bit-identical, not close).
void expect_same(const TeleopAxesParams& a, const TeleopAxesParams& b) {
  EXPECT_EQ(a.axes, b.axes);
  EXPECT_EQ(a.sample_rate_hz, b.sample_rate_hz);
  for (const auto& [x, y] : {std::pair{&a.master_device, &b.master_device},
                             std::pair{&a.slave_device, &b.slave_device}}) {
    EXPECT_EQ(x->mass_kg, y->mass_kg);
    EXPECT_EQ(x->damping_Ns_per_m, y->damping_Ns_per_m);
    EXPECT_EQ(x->coulomb_N, y->coulomb_N);
  }
  for (const auto& [x, y] : {std::pair{&a.master_planes, &b.master_planes},
                             std::pair{&a.slave_planes, &b.slave_planes}}) {
    ASSERT_EQ(x->size(), y->size());
    for (std::size_t i = 0; i < x->size(); ++i) {
      EXPECT_EQ((*x)[i].normal, (*y)[i].normal);
      EXPECT_EQ((*x)[i].offset_m, (*y)[i].offset_m);
      EXPECT_EQ((*x)[i].stiffness_N_per_m, (*y)[i].stiffness_N_per_m);
    }
  }
  EXPECT_EQ(a.gains.kpm, b.gains.kpm);
  EXPECT_EQ(a.gains.kps, b.gains.kps);
  EXPECT_EQ(a.gains.kdm, b.gains.kdm);
  EXPECT_EQ(a.gains.kds, b.gains.kds);
  EXPECT_EQ(a.gains.kvm, b.gains.kvm);
  EXPECT_EQ(a.gains.kvs, b.gains.kvs);
  EXPECT_EQ(a.gains.kfm, b.gains.kfm);
  EXPECT_EQ(a.scaling.position, b.scaling.position);
  EXPECT_EQ(a.scaling.force, b.scaling.force);
  EXPECT_EQ(a.velocity_cutoff_hz, b.velocity_cutoff_hz);
  EXPECT_EQ(a.round_trip_delay_samples, b.round_trip_delay_samples);
  EXPECT_EQ(a.human.kind, b.human.kind);
  EXPECT_EQ(a.human.fixed.mass_kg, b.human.fixed.mass_kg);
  EXPECT_EQ(a.human.fixed.damping_Ns_per_m, b.human.fixed.damping_Ns_per_m);
  EXPECT_EQ(a.human.fixed.stiffness_N_per_m, b.human.fixed.stiffness_N_per_m);
  ASSERT_EQ(a.human.band_per_axis.size(), b.human.band_per_axis.size());
  for (std::size_t i = 0; i < a.human.band_per_axis.size(); ++i) {
    const HumanBand& x = a.human.band_per_axis[i];
    const HumanBand& y = b.human.band_per_axis[i];
    EXPECT_EQ(x.force_levels_N, y.force_levels_N);
    EXPECT_EQ(x.points_per_axis, y.points_per_axis);
    for (const auto& [u, v] :
         {std::pair{&x.mass_kg, &y.mass_kg}, std::pair{&x.damping_Ns_per_m, &y.damping_Ns_per_m},
          std::pair{&x.stiffness_N_per_m, &y.stiffness_N_per_m}}) {
      EXPECT_EQ(u->lower.intercept, v->lower.intercept);
      EXPECT_EQ(u->lower.slope_per_N, v->lower.slope_per_N);
      EXPECT_EQ(u->upper.intercept, v->upper.intercept);
      EXPECT_EQ(u->upper.slope_per_N, v->upper.slope_per_N);
    }
  }
  EXPECT_EQ(a.analysis.required_damping_ratio, b.analysis.required_damping_ratio);
  EXPECT_EQ(a.analysis.stiffness_tolerance_N_per_m, b.analysis.stiffness_tolerance_N_per_m);
}

// ---------------------------------------------------------------------------------------------
// Old files

TEST(AxesConfigCompat, EveryShippedOneAxisExampleKeepsItsBytesAndItsTeleopParams) {
  for (const Golden& g : kGolden) {
    SCOPED_TRACE(g.file);
    const LoadedConfig loaded = load_config_file(example(g.file));
    const std::string bytes = deterministic_bytes(loaded.config);
    EXPECT_EQ(bytes.size(), g.bytes);
    EXPECT_EQ(fnv1a(bytes), g.bytes_hash);
    if (g.params_hash == 0) continue;
    const TeleopParams params = to_teleop_params(loaded);
    EXPECT_EQ(fnv1a(params_text(params)), g.params_hash);
    // The n-axis reading of a one-axis file is the one-axis teleoperator embedded.
    expect_same(to_axes_params(loaded), to_axes(params));
  }
}

TEST(AxesConfigCompat, OneAxisWithoutNewFieldsIsToAxesOfTheOneAxisParams) {
  const std::vector<std::string> variants{
      kFullConfig,
      kMinimalConfig,
      std::string(kMinimalConfig) + "human { fixed { mass_kg: 0.01 damping_Ns_per_m: 1 } }\n",
      std::string(kMinimalConfig) + "human { none {} }\naxes: 1\n",
      "sample_rate_hz: 1000\n"
      "master { device { mass_kg: 0.04 kinematics { cartesian {} } } }\n"
      "slave { device { mass_kg: 0.036 } }\n"
      "gains { kpm: 100 kps: 100 }\n",
  };
  for (const std::string& text : variants) {
    SCOPED_TRACE(text);
    const LoadedConfig loaded = load_config_text(text, "TEST");
    const TeleopAxesParams axes = to_axes_params(loaded);
    expect_same(axes, to_axes(to_teleop_params(loaded)));
    // The one-axis fixture is the plane normal (+1) at its position, kept at stiffness 0.
    ASSERT_EQ(axes.master_planes.size(), 1U);
    EXPECT_EQ(axes.master_planes[0].normal(0), 1.0);
  }
}

// The one field TeleopParams does not carry: the simulated device's Coulomb friction, which the
// n-axis form keeps (to_axes has no way to know it and gives 0).
TEST(AxesConfigCompat, CoulombFrictionIsKeptWhereToAxesCannotKnowIt) {
  const LoadedConfig loaded = load_config_text(
      "sample_rate_hz: 1000\n"
      "master { device { mass_kg: 0.04 coulomb_friction_N: 0.1 } }\n"
      "slave { device { mass_kg: 0.036 } }\n"
      "gains { kpm: 100 kps: 100 }\n",
      "TEST");
  TeleopAxesParams axes = to_axes_params(loaded);
  EXPECT_EQ(axes.master_device.coulomb_N, Eigen::VectorXd::Constant(1, 0.1));
  axes.master_device.coulomb_N.setZero();
  expect_same(axes, to_axes(to_teleop_params(loaded)));
}

// The n-axis forms of one axis read to the same numbers as the scalar ones.
TEST(AxesConfigCompat, OneAxisWrittenInTheNAxisFormsGivesTheSameParameters) {
  const LoadedConfig scalar = load_config_text(kFullConfig, "TEST");
  const LoadedConfig vector = load_config_text(
      kFullConfig, "TEST",
      {"master.device={mass_matrix_kg: [0.040] damping_Ns_per_m_per_axis: [0.41]}",
       "slave.fixture={plane { normal: [2] offset_m: 0.002 stiffness_N_per_m: 1500 }}",
       "gains={kpm_per_axis: [600] kps_matrix: [700] kdm: 2 kds: 3 kvm: 0.1 kvs: 0.2 kfm: 0.5}"});
  expect_same(to_axes_params(vector), to_axes_params(scalar));
  // ... which the one-axis tools refuse rather than ignore.
  const std::string error = error_of([&] { (void)to_teleop_params(vector); });
  EXPECT_TRUE(Contains(error,
                       "--set master.device={mass_matrix_kg: [0.040] "
                       "damping_Ns_per_m_per_axis: [0.41]}: master.device.mass_matrix_kg: "
                       "an n-axis field, given with axes: 1"));
  EXPECT_TRUE(Contains(error, "slave.fixture.plane: an n-axis field"));
  EXPECT_TRUE(Contains(error, "gains.kps_matrix: an n-axis field"));
}

// ---------------------------------------------------------------------------------------------
// Validation: each rule names its field

const std::string kThreeAxes =
    "sample_rate_hz: 1000\n"                                                                // 1
    "axes: 3\n"                                                                             // 2
    "master { device { mass_matrix_kg: [0.05, 0.005, 0, 0.005, 0.05, 0, 0, 0, 0.06] } }\n"  // 3
    "slave { device { mass_kg: 0.04 } }\n"                                                  // 4
    "gains { kpm: 600 kps: 600 }\n";                                                        // 5

std::string load_error_of(const std::string& text) {
  return error_of([&] { (void)load_config_text(text, "T"); });
}

std::string three_axes_error(const std::vector<std::string>& sets) {
  return error_of([&] { (void)load_config_text(kThreeAxes, "T", sets); });
}

TEST(AxesConfigValidation, TheThreeAxisBaseLoads) {
  const TeleopAxesParams p = to_axes_params(load_config_text(kThreeAxes, "T"));
  EXPECT_EQ(p.axes, 3);
  EXPECT_EQ(p.slave_device.mass_kg, 0.04 * Eigen::MatrixXd::Identity(3, 3));
  EXPECT_EQ(p.gains.kpm, 600.0 * Eigen::MatrixXd::Identity(3, 3));
  EXPECT_TRUE(p.master_planes.empty());         // no fixture: no plane on several axes
  ASSERT_EQ(p.human.band_per_axis.size(), 3U);  // the default band on every axis
  EXPECT_EQ(p.human.band_per_axis[2].force_levels_N, default_human_band().force_levels_N);
}

TEST(AxesConfigValidation, AxesMustBe1To6) {
  EXPECT_TRUE(Contains(three_axes_error({"axes=7"}), "--set axes=7: axes: must be in [1, 6]"));
  EXPECT_TRUE(Contains(three_axes_error({"axes=0"}), "axes: must be > 0, got 0"));
}

TEST(AxesConfigValidation, MassMatrixMustBeSymmetricPositiveDefiniteOfTheRightSize) {
  // Indefinite: eigenvalues 0.05 +- 0.1.
  EXPECT_TRUE(Contains(
      three_axes_error({"master.device.mass_matrix_kg=0.05, 0.1, 0, 0.1, 0.05, 0, 0, 0, 0.06"}),
      "master.device.mass_matrix_kg: not positive definite: its smallest eigenvalue is -0.05"));
  // Asymmetric: names the two elements.
  EXPECT_TRUE(Contains(three_axes_error({"master.device.mass_matrix_kg[1]=0.006"}),
                       "--set master.device.mass_matrix_kg[1]=0.006: master.device.mass_matrix_kg: "
                       "not symmetric: element [1] (row 0, column 1) is 0.006 but element [3] "
                       "(row 1, column 0) is 0.005"));
  // A symmetric difference within 1e-9 of the largest element is rounding: symmetrised.
  const LoadedConfig rounded =
      load_config_text(kThreeAxes, "T", {"master.device.mass_matrix_kg[1]=0.00500000000001"});
  const Eigen::MatrixXd m = to_axes_params(rounded).master_device.mass_kg;
  EXPECT_EQ(m(0, 1), m(1, 0));
  // Wrong size for axes: 3 (neither 9 nor 3 elements).
  EXPECT_TRUE(Contains(three_axes_error({"master.device.mass_matrix_kg=0.05, 0.05, 0.06, 0.1"}),
                       "master.device.mass_matrix_kg: must have 9 elements (3 x 3, row-major) or "
                       "3 (the diagonal) for axes: 3, got 4"));
  // A NaN element is named by its index.
  EXPECT_TRUE(Contains(three_axes_error({"master.device.mass_matrix_kg[8]=nan"}),
                       "master.device.mass_matrix_kg[8]: must be finite, got nan"));
  // Positive definite but lighter than the 0.1 g a device mass may be along some direction.
  EXPECT_TRUE(Contains(three_axes_error({"slave.device={mass_matrix_kg: [0.04, 0.04, 0.00005]}"}),
                       "slave.device.mass_matrix_kg: its eigenvalues (the masses along its "
                       "principal directions) must be in [0.0001, 1000] kg"));
  // Both forms in the file is refused; a --set of one form replaces the other
  // (test_override_forms).
  std::string both = kThreeAxes;
  both.replace(both.find("mass_kg: 0.04"), 13, "mass_kg: 0.04 mass_matrix_kg: [0.04, 0.04, 0.04]");
  EXPECT_TRUE(Contains(load_error_of(both),
                       "slave.device.mass_matrix_kg: give mass_kg (every axis) or mass_matrix_kg, "
                       "not both"));
  EXPECT_TRUE(Contains(three_axes_error({"slave.device={}"}),
                       "slave.device.mass_kg: missing (a device needs its mass"));
}

TEST(AxesConfigValidation, PerAxisListsHaveOneElementPerAxis) {
  EXPECT_TRUE(Contains(three_axes_error({"slave.device.damping_Ns_per_m_per_axis=1, 2"}),
                       "slave.device.damping_Ns_per_m_per_axis: must have 3 elements (one per "
                       "axis, axes: 3), got 2"));
  EXPECT_TRUE(Contains(three_axes_error({"slave.device.coulomb_N_per_axis=0.1, -0.1, 0"}),
                       "slave.device.coulomb_N_per_axis[1]: must be >= 0, got -0.1"));
  EXPECT_TRUE(Contains(three_axes_error({"gains.kdm_per_axis=1, 2, 3, 4"}),
                       "gains.kdm_per_axis: must have 3 elements"));
  std::string both = kThreeAxes;
  both.replace(both.find("kpm: 600"), 8, "kpm: 600 kpm_per_axis: [1, 2, 3]");
  EXPECT_TRUE(Contains(load_error_of(both),
                       "gains.kpm_per_axis: give one of kpm (every axis), kpm_per_axis or "
                       "kpm_matrix"));
}

TEST(AxesConfigValidation, GainMatricesAreSymmetricPositiveSemidefinite) {
  // Eigenvalues 700 and -100 on the x-y block: pushes away along (1, -1).
  EXPECT_TRUE(Contains(three_axes_error({"gains.kps=0",
                                         "gains.kps_matrix=300,400,0,400,300,0,0,0,"
                                         "300"}),
                       "gains.kps_matrix: not positive semidefinite: its smallest eigenvalue is "
                       "-100"));
  EXPECT_TRUE(Contains(three_axes_error({"gains.kdm_matrix=2,1,0,0,2,0,0,0,2"}),
                       "gains.kdm_matrix: not symmetric: element [1]"));
  EXPECT_TRUE(Contains(three_axes_error({"gains.kdm_matrix=2,0,0,0,2,0,0,0"}),
                       "gains.kdm_matrix: must have 9 elements (3 x 3 row-major, axes: 3), got 8"));
  // Semidefinite (a null direction) is allowed: a gain may be 0 along an axis.
  const LoadedConfig ok = load_config_text(kThreeAxes, "T", {"gains.kdm_matrix=1,1,0,1,1,0,0,0,0"});
  EXPECT_EQ(to_axes_params(ok).gains.kdm(0, 1), 1.0);
}

TEST(AxesConfigValidation, PlaneNormalsAreFiniteNonZeroAndOfTheRightSize) {
  EXPECT_TRUE(Contains(
      three_axes_error({"slave.fixture.plane[0]={normal: [0, 0, 0] stiffness_N_per_m: 100}"}),
      "slave.fixture.plane[0].normal: must not be zero (a plane needs a direction)"));
  EXPECT_TRUE(Contains(three_axes_error({"slave.fixture.plane[0]={normal: [1, 0]}"}),
                       "slave.fixture.plane[0].normal: must have 3 elements (one per axis, axes: "
                       "3), got 2"));
  EXPECT_TRUE(Contains(three_axes_error({"slave.fixture.plane[0]={normal: [1, nan, 0]}"}),
                       "slave.fixture.plane[0].normal[1]: must be finite, got nan"));
  EXPECT_TRUE(Contains(three_axes_error({"slave.fixture.plane[0]={normal: [1, 0, 0] "
                                         "stiffness_N_per_m: -5}"}),
                       "slave.fixture.plane[0].stiffness_N_per_m: must be >= 0, got -5"));
  // An element of a repeated section written in the file is named by its line and column.
  EXPECT_TRUE(Contains(load_error_of("sample_rate_hz: 1000\n"
                                     "axes: 2\n"
                                     "master { device { mass_kg: 0.04 } }\n"
                                     "slave { device { mass_kg: 0.04 }\n"
                                     "  fixture { plane { normal: [1, 0] }\n"
                                     "            plane { normal: [0, 0] } } }\n"
                                     "gains { kpm: 1 kps: 1 }\n"),
                       "T:6:21: slave.fixture.plane[1].normal: must not be zero"));
  // The one-axis wall has no direction on several axes.
  EXPECT_TRUE(Contains(three_axes_error({"slave.fixture.stiffness_N_per_m=1500"}),
                       "slave.fixture.stiffness_N_per_m: the one-axis wall; with axes: 3 give the "
                       "fixture as fixture.plane"));
}

TEST(AxesConfigValidation, NormalsAreNormalisedAndOffsetsAreDistancesAlongThem) {
  const TeleopAxesParams p = to_axes_params(load_config_text(
      kThreeAxes, "T", {"slave.fixture.plane[0]={normal: [3, 0, 4] offset_m: 0.01}"}));
  ASSERT_EQ(p.slave_planes.size(), 1U);
  // (3, 0, 4) / 5, by hand.
  EXPECT_DOUBLE_EQ(p.slave_planes[0].normal(0), 0.6);
  EXPECT_EQ(p.slave_planes[0].normal(1), 0.0);
  EXPECT_DOUBLE_EQ(p.slave_planes[0].normal(2), 0.8);
  EXPECT_NEAR(p.slave_planes[0].normal.norm(), 1.0, 1e-15);
  EXPECT_EQ(p.slave_planes[0].offset_m, 0.01);
  // Tiny elements (their squares underflow) still give a unit normal, (1, 0, 1) / sqrt(2).
  const TeleopAxesParams tiny = to_axes_params(
      load_config_text(kThreeAxes, "T", {"slave.fixture.plane[0]={normal: [1e-160, 0, 1e-160]}"}));
  EXPECT_NEAR(tiny.slave_planes[0].normal(0), std::sqrt(0.5), 1e-15);
  EXPECT_NEAR(tiny.slave_planes[0].normal(2), std::sqrt(0.5), 1e-15);
}

const std::string kFiveBar =
    "sample_rate_hz: 1000\n"
    "axes: 2\n"
    "master { device { mass_kg: 0.25 kinematics { five_bar { base_separation_m: 0.1\n"
    "  proximal_m: [0.15, 0.15] distal_m: [0.2, 0.2]\n"
    "  home_joint_rad: [2.0943951023931953, 1.0471975511965976] } } } }\n"
    "slave { device { mass_kg: 0.25 } }\n"
    "gains { kpm: 100 kps: 100 }\n";

std::string five_bar_error(const std::vector<std::string>& sets) {
  return error_of([&] { (void)load_config_text(kFiveBar, "T", sets); });
}

TEST(AxesConfigValidation, AFiveBarMustBeValidOnTwoAxesAndAwayFromSingularityAtHome) {
  EXPECT_NO_THROW((void)load_config_text(kFiveBar, "T"));
  EXPECT_TRUE(Contains(five_bar_error({"axes=3"}),
                       "master.device.kinematics.five_bar: a five-bar linkage moves its end point "
                       "on 2 task axes: set axes: 2, got axes: 3"));
  EXPECT_TRUE(Contains(five_bar_error({"master.device.kinematics.five_bar.distal_m=0.2"}),
                       "master.device.kinematics.five_bar.distal_m: must have 2 elements (one per "
                       "arm of the linkage), got 1"));
  EXPECT_TRUE(Contains(five_bar_error({"master.device.kinematics.five_bar.proximal_m[1]=0"}),
                       "master.device.kinematics.five_bar.proximal_m[1]: must be > 0, got 0"));
  // Distal links of 5 cm cannot bridge the elbows 25 cm apart.
  EXPECT_TRUE(Contains(five_bar_error({"master.device.kinematics.five_bar.distal_m=0.05,0.05"}),
                       "master.device.kinematics.five_bar.home_joint_rad: the linkage does not "
                       "assemble at home"));
  // Distal links of 0.1253 m bridging elbows 0.25 m apart: nearly in line, |sin| of their
  // angle 2 (0.125) sqrt(0.1253^2 - 0.125^2) / 0.1253^2 = 0.138 by hand, below the default 0.2.
  const std::string near =
      five_bar_error({"master.device.kinematics.five_bar.distal_m=0.1253,0.1253"});
  EXPECT_TRUE(
      Contains(near, "master.device.kinematics.five_bar.home_joint_rad: the home pose is "));
  EXPECT_TRUE(Contains(near, "below min_singularity_distance 0.2"));
  EXPECT_TRUE(Contains(five_bar_error({"master.device.kinematics={}"}),
                       "master.device.kinematics: give cartesian {} or five_bar { ... }"));
}

TEST(AxesConfigValidation, HumanBandPerAxis) {
  const std::string band =
      "{force_levels_N: [2] mass_kg {lower {intercept: 0.003} upper {intercept: 0.012}} "
      "damping_Ns_per_m {lower {intercept: 1} upper {intercept: 2}} "
      "stiffness_N_per_m {lower {intercept: 50} upper {intercept: 100}}}";
  const std::vector<std::string> three{"human.band_per_axis[0]=" + band,
                                       "human.band_per_axis[1]=" + band,
                                       "human.band_per_axis[2]=" + band};
  const TeleopAxesParams p = to_axes_params(load_config_text(kThreeAxes, "T", three));
  ASSERT_EQ(p.human.band_per_axis.size(), 3U);
  EXPECT_EQ(p.human.band_per_axis[1].damping_Ns_per_m.upper.intercept, 2.0);
  EXPECT_EQ(p.human.band_per_axis[1].points_per_axis, 4);  // the default
  EXPECT_TRUE(Contains(three_axes_error({three[0], three[1]}),
                       "human.band_per_axis: must have 3 bands (one per axis, axes: 3), got 2"));
  // Each band is checked as human.band is, and named by its index.
  std::vector<std::string> bad = three;
  bad.push_back("human.band_per_axis[1].mass_kg.lower.intercept=0.02");
  EXPECT_TRUE(Contains(three_axes_error(bad),
                       "human.band_per_axis[1].mass_kg: lower bound 0.02 exceeds upper bound "
                       "0.012"));
  bad = three;
  bad.push_back("human.none={}");
  EXPECT_TRUE(Contains(three_axes_error(bad),
                       "human.band_per_axis: give human.fixed, human.band, "
                       "human.none or human.band_per_axis, not two"));
}

// ---------------------------------------------------------------------------------------------
// `--set` by index

TEST(AxesConfigOverride, SetReachesAnElementByIndex) {
  LoadedConfig config = load_config_text(kThreeAxes, "T");
  apply_override(config, "master.device.mass_matrix_kg[8]=0.3");
  validate(config);
  EXPECT_EQ(to_axes_params(config).master_device.mass_kg(2, 2), 0.3);
  EXPECT_EQ(config.config.master().device().mass_matrix_kg_size(), 9);  // one replaced
  // The element after the last appends; a section element likewise.
  apply_override(config, "slave.fixture.plane[0]={normal: [0, 0, -1] offset_m: 0.01}");
  apply_override(config, "slave.fixture.plane[1].normal=1,1,0");
  apply_override(config, "slave.fixture.plane[1].stiffness_N_per_m=1000");
  apply_override(config, "slave.fixture.plane[0].stiffness_N_per_m=1500");
  const TeleopAxesParams p = to_axes_params(config);
  ASSERT_EQ(p.slave_planes.size(), 2U);
  EXPECT_EQ(p.slave_planes[0].stiffness_N_per_m, 1500.0);
  EXPECT_EQ(p.slave_planes[0].offset_m, 0.01);
  EXPECT_EQ(p.slave_planes[1].stiffness_N_per_m, 1000.0);
  EXPECT_DOUBLE_EQ(p.slave_planes[1].normal(0), std::sqrt(0.5));
  apply_override(config, "slave.fixture.plane[1].normal[2]=1");
  EXPECT_EQ(config.config.slave().fixture().plane(1).normal(2), 1.0);
}

TEST(AxesConfigOverride, BadIndicesAreNamedAndChangeNothing) {
  LoadedConfig config = load_config_text(kThreeAxes, "T");
  const std::string before = config.config.SerializeAsString();
  const auto error = [&](const std::string& assignment) {
    return error_of([&] { apply_override(config, assignment); });
  };
  EXPECT_EQ(error("master.device.mass_matrix_kg[10]=1"),
            "--set master.device.mass_matrix_kg[10]=1: master.device.mass_matrix_kg[10]: no such "
            "element: master.device.mass_matrix_kg has 9 (give [9] to add one)");
  EXPECT_EQ(error("slave.fixture.plane[1].offset_m=1"),
            "--set slave.fixture.plane[1].offset_m=1: slave.fixture.plane[1]: no such element: "
            "slave.fixture.plane has 0 (give [0] to add one)");
  EXPECT_TRUE(Contains(error("slave.fixture.plane.offset_m=1"),
                       "slave.fixture.plane: is a repeated section: name the element, e.g. "
                       "slave.fixture.plane[0].offset_m"));
  EXPECT_TRUE(Contains(error("gains.kpm[0]=1"), "gains.kpm: is not repeated: it takes no [index]"));
  EXPECT_TRUE(Contains(error("master.device.mass_matrix_kg[-1]=1"), "bad index"));
  EXPECT_TRUE(Contains(error("master.device.mass_matrix_kg[x]=1"), "bad index"));
  EXPECT_TRUE(Contains(error("master.device.mass_matrix_kg[1=1"), "bad index"));
  EXPECT_TRUE(Contains(error("master.device.mass_matrix_kg[0]=1,2"),
                       "master.device.mass_matrix_kg[0]: cannot parse '1,2'"));
  EXPECT_EQ(config.config.SerializeAsString(), before);
  EXPECT_TRUE(config.overridden.empty());
}

// Listing the set fields (set_fields) writes repeated sections by index; applied to an empty
// configuration they reproduce it.
TEST(AxesConfigOverride, SetFieldsOfAnNAxisFileRoundTrip) {
  for (const char* name : {"five_bar.textproto", "cartesian3.textproto"}) {
    SCOPED_TRACE(name);
    const LoadedConfig loaded = load_config_file(example(name));
    LoadedConfig rebuilt = parse_config_text("", "EMPTY");
    for (const FieldAssignment& a : set_fields(loaded.config)) {
      apply_override(rebuilt, a.path + "=" + a.value);
    }
    EXPECT_TRUE(google::protobuf::util::MessageDifferencer::Equals(rebuilt.config, loaded.config));
  }
}

// ---------------------------------------------------------------------------------------------
// The one-axis tools refuse several axes

TEST(AxesConfigOneAxisTools, RefuseSeveralAxesNamingAxes) {
  const std::string text = std::string(kThreeAxes) + "scene { duration_s: 1 }\n";
  const LoadedConfig loaded = load_config_text(text, "T");
  const char* expected = "T:2:1: axes: 3 axes; this is the one-axis path";
  EXPECT_TRUE(Contains(error_of([&] { (void)to_teleop_params(loaded); }), expected));  // analyze
  EXPECT_TRUE(Contains(error_of([&] { (void)compile_system(loaded); }), expected));    // nodes
  EXPECT_TRUE(Contains(error_of([&] { (void)to_scene_setup(loaded); }), expected));    // simulate
  for (const char* name : {"five_bar.textproto", "cartesian3.textproto"}) {
    EXPECT_TRUE(Contains(error_of([&] { (void)compile_system_file(example(name)); }), "axes: "));
  }
}

// ---------------------------------------------------------------------------------------------
// The shipped n-axis examples load with the numbers written in them

TEST(AxesConfigExamples, FiveBarLoadsWithThePapersNumbers) {
  const AxesConfig c = to_axes_config(load_config_file(example("five_bar.textproto")));
  const TeleopAxesParams& p = c.teleop;
  EXPECT_EQ(p.axes, 2);
  EXPECT_EQ(p.sample_rate_hz, 1000.0);  // T = 1 ms
  for (const DeviceAxesParams* d : {&p.master_device, &p.slave_device}) {
    EXPECT_EQ(d->mass_kg, 0.25 * Eigen::Matrix2d::Identity());  // M_m = 0.25 kg
    EXPECT_EQ(d->damping_Ns_per_m, Eigen::Vector2d(5.0, 5.0));  // B_m = 5 Ns/m
    EXPECT_EQ(d->coulomb_N, Eigen::Vector2d::Zero());
  }
  ASSERT_EQ(p.master_planes.size(), 1U);  // the tissue: 3 cm along X, k_x = 125 N/m
  EXPECT_EQ(p.master_planes[0].normal, Eigen::Vector2d(1.0, 0.0));
  EXPECT_EQ(p.master_planes[0].offset_m, 0.03);
  EXPECT_EQ(p.master_planes[0].stiffness_N_per_m, 125.0);
  EXPECT_TRUE(p.slave_planes.empty());
  EXPECT_EQ(p.gains.kpm, 600.0 * Eigen::Matrix2d::Identity());
  EXPECT_EQ(p.gains.kds, 10.0 * Eigen::Matrix2d::Identity());
  EXPECT_EQ(p.gains.kfm, Eigen::Matrix2d::Zero());
  ASSERT_EQ(p.human.band_per_axis.size(), 2U);

  for (const KinematicsConfig* k : {&c.master_kinematics, &c.slave_kinematics}) {
    ASSERT_EQ(k->kind, KinematicsConfig::Kind::kFiveBar);
    EXPECT_EQ(k->five_bar.base_separation_m, 0.1);
    EXPECT_EQ(k->five_bar.proximal_m[1], 0.15);
    EXPECT_EQ(k->five_bar.distal_m[0], 0.2);
    // Home at q = (120, 60) degrees, by hand: elbows at (-+(0.05 + 0.15 cos 60), 0.15 sin 60) =
    // (-+0.125, 0.1299), the end point on the y axis sqrt(0.2^2 - 0.125^2) = 0.1561 above them.
    const double elbow_y = 0.15 * std::sqrt(3.0) / 2.0;
    const double rise = std::sqrt(0.2 * 0.2 - 0.125 * 0.125);
    EXPECT_NEAR(k->home_end_m.x(), 0.0, 1e-15);
    EXPECT_NEAR(k->home_end_m.y(), elbow_y + rise, 1e-15);
    // Transmission angles by hand: between the distal links (+-0.125, rise) |sin| =
    // 2 (0.125) rise / 0.2^2; between proximal (-0.075, elbow_y) and distal (0.125, rise),
    // |cross| / (0.15 * 0.2). The smaller is the distance (0.93).
    const double distal = 2.0 * 0.125 * rise / 0.04;
    const double proximal = std::abs(-0.075 * rise - elbow_y * 0.125) / 0.03;
    EXPECT_NEAR(k->home_singularity_distance, std::min(distal, proximal), 1e-12);
    EXPECT_NEAR(k->home_singularity_distance, 0.93, 0.01);
  }
}

TEST(AxesConfigExamples, Cartesian3LoadsWithTheNumbersWrittenInIt) {
  const AxesConfig c = to_axes_config(load_config_file(example("cartesian3.textproto")));
  const TeleopAxesParams& p = c.teleop;
  EXPECT_EQ(p.axes, 3);
  Eigen::Matrix3d master;
  master << 0.05, 0.005, 0, 0.005, 0.05, 0, 0, 0, 0.06;
  EXPECT_EQ(p.master_device.mass_kg, master);
  EXPECT_EQ(p.slave_device.mass_kg,
            Eigen::Vector3d(0.04, 0.04, 0.045).asDiagonal().toDenseMatrix());
  EXPECT_EQ(p.master_device.damping_Ns_per_m, Eigen::Vector3d(0.4, 0.4, 0.5));
  EXPECT_EQ(p.slave_device.damping_Ns_per_m, Eigen::Vector3d(0.5, 0.5, 0.5));
  EXPECT_EQ(c.master_kinematics.kind, KinematicsConfig::Kind::kCartesian);
  EXPECT_TRUE(p.master_planes.empty());
  ASSERT_EQ(p.slave_planes.size(), 2U);
  EXPECT_EQ(p.slave_planes[0].normal, Eigen::Vector3d(0, 0, -1));
  EXPECT_EQ(p.slave_planes[0].offset_m, 0.01);
  EXPECT_EQ(p.slave_planes[0].stiffness_N_per_m, 1500.0);
  EXPECT_NEAR((p.slave_planes[1].normal - Eigen::Vector3d(1, 1, 0) / std::sqrt(2.0)).norm(), 0.0,
              1e-16);
  EXPECT_EQ(p.slave_planes[1].offset_m, 0.02);
  EXPECT_EQ(p.slave_planes[1].stiffness_N_per_m, 1000.0);
  EXPECT_EQ(p.gains.kps, 600.0 * Eigen::Matrix3d::Identity());
  EXPECT_EQ(p.gains.kdm, Eigen::Vector3d(2, 2, 2.5).asDiagonal().toDenseMatrix());
  EXPECT_EQ(p.gains.kds, p.gains.kdm);  // the same, written as a matrix
  EXPECT_EQ(p.velocity_cutoff_hz, 200.0);
  ASSERT_EQ(p.human.kind, HumanKind::kBand);
  ASSERT_EQ(p.human.band_per_axis.size(), 3U);
  EXPECT_EQ(p.human.band_per_axis[0].stiffness_N_per_m.lower.intercept, 50.0);
  EXPECT_EQ(p.human.band_per_axis[2].stiffness_N_per_m.lower.intercept, 80.0);
  EXPECT_EQ(p.human.band_per_axis[2].stiffness_N_per_m.upper.slope_per_N, 60.0);
  EXPECT_EQ(p.human.band_per_axis[2].force_levels_N.size(), 7U);
}

}  // namespace
}  // namespace teleop::config
