// `--set` replaces a value whichever form the file gave it in (issue 18): a device's damping
// written for every axis (damping_Ns_per_m) is replaced by a --set of its per-axis form, a
// scalar gain by its matrix, a mass matrix by the every-axis mass, and the numbers read are the
// override's, not the file's and not a refusal of "both forms given".
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <filesystem>
#include <string>

#include "common/config/axes_config.hpp"
#include "common/config/config_loader.hpp"

namespace teleop::config {
namespace {

const std::filesystem::path kCartesian3 =
    std::filesystem::path(TELEOP_SOURCE_DIR) / "examples" / "cartesian3.textproto";

// cartesian3's slave gives damping_Ns_per_m (every axis) and its master a coupled
// mass_matrix_kg: each replaced by the other form.
TEST(OverrideForms, APerAxisOverrideReplacesTheEveryAxisValueOfTheFile) {
  const AxesConfig c = to_axes_config(load_config_file(
      kCartesian3,
      {"slave.device.damping_Ns_per_m_per_axis=0.45,0.35,0.6", "master.device.mass_kg=0.07"}));
  EXPECT_EQ(c.teleop.slave_device.damping_Ns_per_m, Eigen::Vector3d(0.45, 0.35, 0.6));
  EXPECT_EQ(c.teleop.master_device.mass_kg, 0.07 * Eigen::Matrix3d::Identity());
}

TEST(OverrideForms, AMatrixGainReplacesTheScalarGainOfTheFile) {
  const AxesConfig c =
      to_axes_config(load_config_file(kCartesian3, {"gains.kpm_matrix=500,10,0,10,600,0,0,0,700"}));
  Eigen::Matrix3d want;
  want << 500, 10, 0, 10, 600, 0, 0, 0, 700;
  EXPECT_EQ(c.teleop.gains.kpm, want);
}

// An element of one form (an index) is an edit of that form, not a replacement: the other
// form stays, and giving both is still refused by name.
TEST(OverrideForms, AnIndexedOverrideOfTheOtherFormIsStillRefused) {
  try {
    (void)load_config_file(kCartesian3, {"slave.device.damping_Ns_per_m_per_axis[0]=0.4"});
    FAIL() << "no error";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("damping_Ns_per_m_per_axis"), std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace teleop::config
