// `teleopctl identify` with several axes (issue 18 "identify"): a CSV written here from an exact
// ZOH simulation of a 3-axis device with a known coupled mass matrix and diagonal damping
// (common/sim/PlantAxes, checked on its own against Eigen's matrix exponential), driven on each
// axis by its own multisine. The command must give back the masses and dampings the device was
// built with, its --set overrides must load into examples/cartesian3.textproto as those numbers,
// and too little excitation, bad columns and mismatched lists are refused by name.
#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Core>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <numbers>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "common/config/axes_config.hpp"
#include "common/config/config_loader.hpp"
#include "common/sim/plant_axes.hpp"
#include "supervisor/teleopctl/identify_command.hpp"

namespace teleop::ctl {
namespace {

namespace fs = std::filesystem;

struct Ran {
  int rc{0};
  std::string out;
  std::string err;
};

Ran run(const std::vector<std::string>& args) {
  std::ostringstream out;
  std::ostringstream err;
  const int rc = run_identify(args, out, err);
  return {rc, out.str(), err.str()};
}

// The device: a symmetric positive definite mass with off-diagonals up to a third of the
// diagonal, and damping near the paper's paddles' b/m.
[[nodiscard]] Eigen::MatrixXd true_mass() {
  Eigen::MatrixXd m(3, 3);
  m << 0.050, 0.012, -0.008, 0.012, 0.040, 0.006, -0.008, 0.006, 0.060;
  return m;
}
[[nodiscard]] Eigen::VectorXd true_damping() { return Eigen::Vector3d(0.45, 0.35, 0.60); }

// 1 kHz, 20 s: the actuator force on axis i a sum of 8 sines over 0.5-10 Hz, the axes' tones
// interleaved so that no two axes share one, phases from a seeded engine; `amplitude_N` per
// tone. `idle_last`: the last axis has no actuator force (it moves only through the coupled mass).
// Columns: time_s, x0..x2 (true positions after each period), u0..u2 (the force held over the
// period ending at the row), zero (no sampled force).
fs::path write_run(const std::string& name, double amplitude_N, bool idle_last = false) {
  constexpr int kAxes = 3;
  constexpr int kSamples = 20000;
  constexpr double kPeriodS = 1e-3;
  std::mt19937_64 engine(7);
  double freq[kAxes][8];
  double phase[kAxes][8];
  for (int i = 0; i < kAxes; ++i) {
    for (int k = 0; k < 8; ++k) {
      freq[i][k] = 0.5 * std::pow(20.0, (k + (i + 0.5) / kAxes) / 8.0);
      phase[i][k] = static_cast<double>(engine() >> 11) * 0x1.0p-53 * 2.0 * std::numbers::pi;
    }
  }
  sim::PlantAxesParams p;
  p.device.mass_kg = true_mass();
  p.device.damping_Ns_per_m = true_damping();
  p.device.coulomb_N = Eigen::VectorXd::Zero(kAxes);
  sim::PlantAxes plant(p, std::chrono::microseconds(1000));
  plant.reset({sim::AxesVector::Zero(kAxes), sim::AxesVector::Zero(kAxes)});
  const fs::path path = fs::path(::testing::TempDir()) / name;
  std::ofstream f(path);
  f << "time_s,x0,x1,x2,u0,u1,u2,zero\n";
  f.precision(17);
  sim::AxesVector u(kAxes);
  for (int k = 1; k <= kSamples; ++k) {
    const double t = (k - 1) * kPeriodS;
    for (int i = 0; i < kAxes; ++i) {
      double s = 0.0;
      for (int j = 0; j < 8; ++j) {
        s += amplitude_N * std::sin(2.0 * std::numbers::pi * freq[i][j] * t + phase[i][j]);
      }
      u(i) = idle_last && i == kAxes - 1 ? 0.0 : s;
    }
    plant.step(u);
    const sim::AxesVector& x = plant.state().position_m;
    f << k * kPeriodS << "," << x(0) << "," << x(1) << "," << x(2) << "," << u(0) << "," << u(1)
      << "," << u(2) << ",0\n";
  }
  return path;
}

const std::vector<std::string> kColumns = {"--position",     "x0,x1,x2",     "--force",
                                           "zero,zero,zero", "--held-force", "u0,u1,u2"};

std::vector<std::string> args_with(const fs::path& csv, std::vector<std::string> more) {
  std::vector<std::string> a{csv.string()};
  a.insert(a.end(), kColumns.begin(), kColumns.end());
  a.insert(a.end(), more.begin(), more.end());
  return a;
}

// The mass matrix and damping the device was built with, to 0.5 % of the largest mass (the
// filters' bias at the top tone, 10 Hz at 1 kHz, is below 1e-3: test_identify_axes).
TEST(IdentifyAxesCommand, GivesBackTheCoupledMassAndDampingOfTheSimulatedDevice) {
  const fs::path csv = write_run("identify_axes_ok.csv", 0.3);
  const Ran r = run(args_with(csv, {"--device", "slave", "--json"}));
  ASSERT_EQ(r.rc, 0) << r.out << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_TRUE(j["identified"].get<bool>());
  EXPECT_EQ(j["axes"].get<int>(), 3);
  EXPECT_EQ(j["mass_model"], "coupled");
  const Eigen::MatrixXd m = true_mass();
  const Eigen::VectorXd b = true_damping();
  for (std::size_t i = 0; i < 3; ++i) {
    const auto ei = static_cast<Eigen::Index>(i);
    for (std::size_t k = 0; k < 3; ++k) {
      const auto ek = static_cast<Eigen::Index>(k);
      EXPECT_NEAR(j["mass_kg"][i][k].get<double>(), m(ei, ek), 0.005 * 0.060) << i << "," << k;
      const double want_b = i == k ? b(ei) : 0.0;
      EXPECT_NEAR(j["damping_Ns_per_m"][i][k].get<double>(), want_b, 0.01 * b(ei)) << i << "," << k;
    }
  }
  EXPECT_GT(j["r_squared"].get<double>(), 0.999);
  EXPECT_TRUE(j["mass_positive_definite"].get<bool>());
}

// The printed overrides put the fit into the n-axis configuration: loading cartesian3 with them
// gives the slave the identified matrix, to the 4 significant digits printed.
TEST(IdentifyAxesCommand, ItsSetOverridesLoadIntoTheThreeAxisExample) {
  const fs::path csv = write_run("identify_axes_set.csv", 0.3);
  const Ran r = run(args_with(csv, {"--device", "slave", "--json"}));
  ASSERT_EQ(r.rc, 0) << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  const auto sets = j["set"].get<std::vector<std::string>>();
  ASSERT_EQ(sets.size(), 2U);
  const config::AxesConfig c = config::to_axes_config(config::load_config_file(
      fs::path(TELEOP_SOURCE_DIR) / "examples" / "cartesian3.textproto", sets));
  const Eigen::MatrixXd m = true_mass();
  for (int i = 0; i < 3; ++i) {
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(c.teleop.slave_device.mass_kg(i, k), m(i, k), 0.005 * 0.060);
    }
    EXPECT_NEAR(c.teleop.slave_device.damping_Ns_per_m(i), true_damping()(i),
                0.01 * true_damping()(i));
  }
  // The text form prints the same overrides.
  const Ran text = run(args_with(csv, {"--device", "slave"}));
  ASSERT_EQ(text.rc, 0);
  for (const std::string& s : sets)
    EXPECT_NE(text.out.find("--set '" + s + "'"), std::string::npos);
}

// Per-axis mass: the diagonal of M alone cannot explain the coupled device's forces, so the fit
// is poorer than the coupled one (the off-diagonal masses carry force from one axis to another).
TEST(IdentifyAxesCommand, APerAxisMassFitsTheCoupledDeviceWorse) {
  const fs::path csv = write_run("identify_axes_per_axis.csv", 0.3);
  const Ran coupled = run(args_with(csv, {"--json"}));
  const Ran per_axis = run(args_with(csv, {"--json", "--mass", "per-axis"}));
  ASSERT_EQ(coupled.rc, 0) << coupled.err;
  const auto jc = nlohmann::json::parse(coupled.out);
  const auto jp = nlohmann::json::parse(per_axis.out);
  EXPECT_EQ(jp["mass_model"], "per-axis");
  EXPECT_GT(jp["residual_rms_N"].get<double>(), 10.0 * jc["residual_rms_N"].get<double>());
}

// An axis without a force of its own (a forgotten column, an actuator off) still moves through
// the coupled mass, but its equation has nothing to fit: refused naming the file and the axis,
// exit 1, no parameters printed.
TEST(IdentifyAxesCommand, AnAxisNeverDrivenIsRefusedNamingTheFileAndAxis) {
  const fs::path csv = write_run("identify_axes_idle.csv", 0.3, true);
  const Ran r = run(args_with(csv, {}));
  EXPECT_EQ(r.rc, 1);
  EXPECT_EQ(r.out.find("--set"), std::string::npos);
  EXPECT_NE(r.err.find("identify_axes_idle.csv"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("never driven"), std::string::npos) << r.err;
}

// A small push (0.03 mN per tone) moves every axis about 0.05-0.1 mm: with the positions
// rounded to 20 um encoder counts that is fewer than 10 counts, so nothing is identified (exit
// 4) and the reason names the axis.
TEST(IdentifyAxesCommand, TooLittleMotionForTheEncoderIsNotIdentified) {
  const fs::path fine = write_run("identify_axes_small.csv", 0.00003);
  const fs::path path = fs::path(::testing::TempDir()) / "identify_axes_small_counts.csv";
  {
    std::ifstream in(fine);
    std::ofstream out(path);
    std::string line;
    std::getline(in, line);
    out << line << "\n";
    out.precision(17);
    while (std::getline(in, line)) {
      std::vector<double> v;
      std::stringstream ss(line);
      std::string cell;
      while (std::getline(ss, cell, ',')) v.push_back(std::stod(cell));
      for (int i = 1; i <= 3; ++i)
        v[static_cast<std::size_t>(i)] = 20e-6 * std::round(v[static_cast<std::size_t>(i)] / 20e-6);
      for (std::size_t c = 0; c < v.size(); ++c) out << (c ? "," : "") << v[c];
      out << "\n";
    }
  }
  const Ran r = run(args_with(path, {}));
  EXPECT_EQ(r.rc, 4) << r.out << r.err;
  EXPECT_NE(r.out.find("NOT IDENTIFIED"), std::string::npos);
  EXPECT_NE(r.err.find("axis 0 moved over"), std::string::npos) << r.err;
}

TEST(IdentifyAxesCommand, BadListsAndColumnsAreUsageErrorsNamingTheFlag) {
  const fs::path csv = write_run("identify_axes_usage.csv", 0.3);
  const Ran short_force = run({csv.string(), "--position", "x0,x1,x2", "--force", "zero,zero"});
  EXPECT_EQ(short_force.rc, 2);
  EXPECT_NE(short_force.err.find("--force: 2 expressions for 3 --position columns"),
            std::string::npos)
      << short_force.err;
  const Ran seven = run({csv.string(), "--position", "x0,x1,x2,x0,x1,x2,x0", "--force",
                         "zero,zero,zero,zero,zero,zero,zero"});
  EXPECT_EQ(seven.rc, 2);
  EXPECT_NE(seven.err.find("at most 6 axes"), std::string::npos) << seven.err;
  const Ran empty = run({csv.string(), "--position", "x0,,x2", "--force", "zero,zero,zero"});
  EXPECT_EQ(empty.rc, 2);
  const Ran bad_mass = run(args_with(csv, {"--mass", "diagonalish"}));
  EXPECT_EQ(bad_mass.rc, 2);
  EXPECT_NE(bad_mass.err.find("--mass: 'diagonalish'"), std::string::npos) << bad_mass.err;
  const Ran one_axis_mass =
      run({csv.string(), "--position", "x0", "--force", "zero", "--mass", "coupled"});
  EXPECT_EQ(one_axis_mass.rc, 2);
  const Ran plot = run(args_with(csv, {"--plot", "fit.svg"}));
  EXPECT_EQ(plot.rc, 2);
  const Ran missing = run({csv.string(), "--position", "x0,x1,x9", "--force", "zero,zero,zero"});
  EXPECT_EQ(missing.rc, 1);
  EXPECT_NE(missing.err.find("no column 'x9' for the position of axis 2"), std::string::npos)
      << missing.err;
}

// A CSV with a NaN cell is refused naming the file, line and column (read before any fit).
TEST(IdentifyAxesCommand, ANonFiniteCellIsNamed) {
  const fs::path path = fs::path(::testing::TempDir()) / "identify_axes_nan.csv";
  {
    std::ofstream f(path);
    f << "time_s,x0,x1,u0,u1\n0.001,0,0,1,1\n0.002,nan,0,1,1\n";
  }
  const Ran r = run({path.string(), "--position", "x0,x1", "--force", "u0,u1"});
  EXPECT_EQ(r.rc, 1);
  EXPECT_NE(r.err.find(":3: column 'x0': 'nan' is not a finite number"), std::string::npos)
      << r.err;
}

}  // namespace
}  // namespace teleop::ctl
