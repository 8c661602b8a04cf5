// `teleopctl analyze` and `teleopctl simulate` on configurations with several task-space axes
// (issue 18), through the real binary: verdicts and plane limits against the one-axis analyser
// on the same numbers, final positions against the static force balance done here by hand, and
// the refusals naming the field or option.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include "tests/integration/cli_harness.hpp"

namespace {

using nlohmann::json;
using teleop::test::CliResult;
using teleop::test::teleopctl;

std::string example(const std::string& name) {
  return std::string(TELEOP_SOURCE_DIR) + "/examples/" + name;
}

std::string slurp(const std::string& path) {
  std::ifstream f(path);
  return std::string((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
}

std::string temp_file(const std::string& name, const std::string& text) {
  const std::string path = ::testing::TempDir() + name;
  std::ofstream(path) << text;
  return path;
}

// `text` with `from` replaced by `to` (which must occur).
std::string replaced(std::string text, const std::string& from, const std::string& to) {
  const std::size_t at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  if (at != std::string::npos) text.replace(at, from.size(), to);
  return text;
}

// The last row of a CSV file by column name.
std::vector<std::pair<std::string, double>> last_csv_row(const std::string& path) {
  std::istringstream lines(slurp(path));
  std::string header;
  std::string line;
  std::string last;
  std::getline(lines, header);
  while (std::getline(lines, line)) {
    if (!line.empty()) last = line;
  }
  std::vector<std::pair<std::string, double>> row;
  std::istringstream h(header);
  std::istringstream v(last);
  std::string name;
  std::string value;
  while (std::getline(h, name, ',') && std::getline(v, value, ',')) {
    row.emplace_back(name, std::stod(value));
  }
  return row;
}

double column(const std::vector<std::pair<std::string, double>>& row, const std::string& name) {
  for (const auto& [n, v] : row) {
    if (n == name) return v;
  }
  ADD_FAILURE() << "no column " << name;
  return NAN;
}

json analyze_json(const std::string& path) {
  const CliResult r = teleopctl("analyze " + path + " --json", false);
  EXPECT_EQ(r.exit_code, 0) << r.out;
  return json::parse(r.out);
}

// The one-axis analyser's limit of a side's fixture.
double one_axis_limit(const std::string& path, const char* side) {
  const CliResult r = teleopctl("analyze " + path + " --max-stiffness " + side + " --json", false);
  EXPECT_EQ(r.exit_code, 0) << r.out;
  return json::parse(r.out)["limits"][0]["max_stable_stiffness_N_per_m"].get<double>();
}

TEST(TeleopctlAxes, FiveBarPlaneLimitIsTheOneAxisLimitOfTheSameNumbers) {
  // examples/five_bar: M = 0.25 kg and B = 5 Ns/m on both axes of both sides, scalar gains, the
  // default band on each axis, the master plane's normal along x: the x axis is the one-axis
  // loop below, its fixture the plane.
  const json j = analyze_json(example("five_bar.textproto"));
  EXPECT_EQ(j["verdict"], "stable");
  EXPECT_EQ(j["axes"], 2);
  EXPECT_EQ(j["decoupled"], true);
  for (const char* key :
       {"spectral_radius", "stability_margin", "min_damping_ratio", "humans_evaluated",
        "band_exhaustive", "worst_human", "eigenvalues", "planes", "limiting_plane", "structure"}) {
    EXPECT_TRUE(j.contains(key)) << key;
  }
  EXPECT_NEAR(j["stability_margin"].get<double>(), 1.0 - j["spectral_radius"].get<double>(), 1e-12);
  ASSERT_EQ(j["worst_human"].size(), 2u);
  ASSERT_EQ(j["planes"].size(), 1u);
  const json& plane = j["planes"][0];
  EXPECT_EQ(plane["side"], "master");
  EXPECT_EQ(plane["index"], 0);
  EXPECT_EQ(plane["limiting"], true);
  EXPECT_EQ(j["limiting_plane"]["side"], "master");

  const std::string one_axis = temp_file("five_bar_x.textproto", R"(sample_rate_hz: 1000
master { device { mass_kg: 0.25 damping_Ns_per_m: 5 } fixture { stiffness_N_per_m: 125 position_m: 0.03 } }
slave { device { mass_kg: 0.25 damping_Ns_per_m: 5 } }
gains { kpm: 600 kps: 600 kdm: 10 kds: 10 }
velocity_filter { cutoff_hz: 200 }
)");
  const double expected = one_axis_limit(one_axis, "master");
  // The one-axis search stops within its 1 N/m tolerance; the plane's crossing is exact.
  EXPECT_NEAR(plane["max_stable_stiffness_N_per_m"].get<double>(), expected, 1.0 + 1e-6 * expected);
  EXPECT_GT(expected, 125.0);
}

TEST(TeleopctlAxes, DiagonalThreeAxisSlavePlaneAlongZIsTheOneAxisLimit) {
  // Diagonal masses (a different loop on each axis), scalar gains, the default band on every
  // axis, the slave plane's normal along z: axis z is the one-axis loop below, its wall the
  // plane; x and y are free loops, better damped than z.
  const std::string three = temp_file("diag3.textproto", R"(sample_rate_hz: 1000
axes: 3
master { device { mass_matrix_kg: [0.03, 0.04, 0.05] damping_Ns_per_m: 0.4 } }
slave { device { mass_matrix_kg: [0.02, 0.03, 0.04] damping_Ns_per_m: 0.5 }
        fixture { plane { normal: [0, 0, 1] offset_m: 0.01 stiffness_N_per_m: 800 } } }
gains { kpm: 600 kps: 600 kdm: 2 kds: 2 }
velocity_filter { cutoff_hz: 200 }
)");
  const std::string one = temp_file("iso1.textproto", R"(sample_rate_hz: 1000
master { device { mass_kg: 0.05 damping_Ns_per_m: 0.4 } }
slave { device { mass_kg: 0.04 damping_Ns_per_m: 0.5 } fixture { stiffness_N_per_m: 800 position_m: 0.01 } }
gains { kpm: 600 kps: 600 kdm: 2 kds: 2 }
velocity_filter { cutoff_hz: 200 }
)");
  const json j = analyze_json(three);
  const CliResult r1 = teleopctl("analyze " + one + " --json", false);
  const json j1 = json::parse(r1.out);
  EXPECT_EQ(j["verdict"], j1["verdict"]);
  EXPECT_NEAR(j["min_damping_ratio"].get<double>(), j1["min_damping_ratio"].get<double>(), 1e-9);
  ASSERT_EQ(j["planes"].size(), 1u);
  const double expected = one_axis_limit(one, "slave");
  EXPECT_NEAR(j["planes"][0]["max_stable_stiffness_N_per_m"].get<double>(), expected,
              1.0 + 1e-6 * expected);
  EXPECT_EQ(j["planes"][0]["side"], "slave");
}

TEST(TeleopctlAxes, Cartesian3IsAnalysedWholeWithBothPlaneLimits) {
  // The shipped bands with 2 points per parameter (the test's time: the full bands take over a
  // second here, many in a sanitizer build).
  const json j = analyze_json(example("cartesian3.textproto") +
                              " --set human.band_per_axis[0].points_per_axis=2"
                              " --set human.band_per_axis[1].points_per_axis=2"
                              " --set human.band_per_axis[2].points_per_axis=2");
  EXPECT_EQ(j["verdict"], "stable");
  EXPECT_EQ(j["decoupled"], false);  // the master's mass matrix couples x and y
  ASSERT_EQ(j["planes"].size(), 2u);
  // The limiting plane is the one nearest its limit: the largest stiffness / limit.
  double worst = 0.0;
  std::size_t worst_index = 0;
  for (std::size_t i = 0; i < 2; ++i) {
    const json& p = j["planes"][i];
    EXPECT_EQ(p["side"], "slave");
    EXPECT_EQ(p["index"], i);
    ASSERT_TRUE(p["max_stable_stiffness_N_per_m"].is_number()) << p.dump();
    const double ratio =
        p["stiffness_N_per_m"].get<double>() / p["max_stable_stiffness_N_per_m"].get<double>();
    EXPECT_LT(ratio, 1.0);  // stable as configured: each plane below its limit
    if (ratio > worst) {
      worst = ratio;
      worst_index = i;
    }
  }
  EXPECT_EQ(j["limiting_plane"]["index"], worst_index);
  EXPECT_EQ(j["planes"][worst_index]["limiting"], true);

  // The text report, on the scene (the same loop with one fixed human).
  const CliResult text = teleopctl("analyze " + example("scenes/cartesian3_planes.textproto"));
  EXPECT_EQ(text.exit_code, 0) << text.out;
  for (const char* s : {"stable (3 axes)", "analysed whole", "the fixed human, per axis",
                        "axis 2: m_h = 0.012 kg, b_h = 0.76 Ns/m, k_h = 70 N/m", "slave plane 1",
                        "<- limiting", "band search exhaustive", "margin"}) {
    EXPECT_NE(text.out.find(s), std::string::npos) << s << "\n" << text.out;
  }
}

TEST(TeleopctlAxes, OneAxisOptionsAreRefused) {
  const std::string f = example("five_bar.textproto");
  for (const char* opt : {"--max-stiffness slave", "--rates 500", "--plot x.svg"}) {
    const CliResult r = teleopctl("analyze " + f + " " + opt);
    EXPECT_EQ(r.exit_code, 2) << opt << "\n" << r.out;
    EXPECT_NE(r.out.find(std::string(opt).substr(0, std::string(opt).find(' '))), std::string::npos)
        << r.out;
  }
  const std::string scene = example("scenes/five_bar_plane.textproto");
  EXPECT_EQ(teleopctl("simulate " + scene + " --seed 3").exit_code, 2);
}

// A session file of the two-axis scene (the three-axis one is tested in test_replay.cpp): the
// replay summary reads two axes on both nodes, and resimulating it gives the record back.
TEST(TeleopctlAxes, FiveBarSceneWritesASessionThatResimulatesExactly) {
  const std::string mcap = ::testing::TempDir() + "five_bar_plane.mcap";
  const std::string scene = example("scenes/five_bar_plane.textproto");
  ASSERT_EQ(teleopctl("simulate " + scene + " --duration 1 --out " + mcap).exit_code, 0);
  const CliResult summary = teleopctl("replay " + mcap + " --json", false);
  ASSERT_EQ(summary.exit_code, 0) << summary.out;
  const json j = json::parse(summary.out);
  EXPECT_EQ(j["nodes"]["master"]["axes"].get<int>(), 2);
  EXPECT_EQ(j["nodes"]["slave"]["cycles"].get<int>(), 1000);
  const CliResult r = teleopctl("replay " + mcap + " --resimulate --json", false);
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const json d = json::parse(r.out)["deviation"];
  EXPECT_EQ(d["cycles_compared"].get<int>(), 1000);
  EXPECT_EQ(d["max_abs_position_m"].get<double>(), 0.0);
}

TEST(TeleopctlAxes, FiveBarSceneSettlesAtTheForceBalance) {
  const std::string csv = ::testing::TempDir() + "five_bar_plane.csv";
  const CliResult r = teleopctl(
      "simulate " + example("scenes/five_bar_plane.textproto") + " --json --out " + csv, false);
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const json j = json::parse(r.out);
  EXPECT_EQ(j["predicted"]["verdict"], "stable");
  EXPECT_EQ(j["oscillation"]["detected"], false);
  EXPECT_EQ(j["master_oscillation"]["detected"], false);
  // At rest the slave (free) is where the master is, so the coupling carries nothing; the
  // master holds the push F (4 N along (2, 1)/sqrt 5) against the hand's spring k_h = 70 N/m
  // and, along x past p = 0.03 m, the plane's K = 125 N/m:
  //   F_x = k_h x + K (x - p)  ->  x = (F_x + K p) / (k_h + K);   F_y = k_h y.
  const double fx = 4.0 * 2.0 / std::sqrt(5.0);
  const double fy = 4.0 * 1.0 / std::sqrt(5.0);
  const double x = (fx + 125.0 * 0.03) / (70.0 + 125.0);
  const double y = fy / 70.0;
  const auto row = last_csv_row(csv);
  EXPECT_NEAR(column(row, "master_position_m[0]"), x, 1e-6);
  EXPECT_NEAR(column(row, "master_position_m[1]"), y, 1e-6);
  EXPECT_NEAR(column(row, "slave_position_m[0]"), x, 1e-6);
  EXPECT_NEAR(column(row, "slave_position_m[1]"), y, 1e-6);
  EXPECT_NEAR(j["final"]["master_position_m"][0].get<double>(), x, 1e-6);
  // The deepest penetration is at least the final one (7.6 mm).
  EXPECT_GE(j["max_penetration_master_m"].get<double>(), x - 0.03 - 1e-9);
}

TEST(TeleopctlAxes, Cartesian3SceneSettlesInTheCornerAtTheForceBalance) {
  const std::string csv = ::testing::TempDir() + "cartesian3_planes.csv";
  const std::string plot = ::testing::TempDir() + "cartesian3_planes.svg";
  const CliResult r = teleopctl("simulate " + example("scenes/cartesian3_planes.textproto") +
                                    " --json --out " + csv + " --plot " + plot,
                                false);
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const json j = json::parse(r.out);
  EXPECT_EQ(j["predicted"]["verdict"], "stable");
  EXPECT_EQ(j["oscillation"]["detected"], false);
  const auto row = last_csv_row(csv);
  double xs[3];
  double xm[3];
  for (int i = 0; i < 3; ++i) {
    xs[i] = column(row, "slave_position_m[" + std::to_string(i) + "]");
    xm[i] = column(row, "master_position_m[" + std::to_string(i) + "]");
  }
  // The planes' normals (0, 0, -1) and (1, 1, 0)/sqrt 2 and the tangent t = (1, -1, 0)/sqrt 2
  // are orthogonal, every spring is isotropic: the balance splits along them. Along a normal
  // n (push F = 20 n.d, d = (1, 1, -1)/sqrt 3; k_h = 70, coupling k_c = 600, plane K at p):
  //   (k_h + k_c) m - k_c s = F,   -k_c m + (k_c + K) s = K p   (Cramer's rule below).
  const auto slave_along = [](double f, double k, double p) {
    const double kh = 70.0;
    const double kc = 600.0;
    const double det = (kh + kc) * (kc + k) - kc * kc;
    return ((kh + kc) * k * p + kc * f) / det;
  };
  const double f_floor = 20.0 / std::sqrt(3.0);       // d . (0, 0, -1)
  const double f_wall = 20.0 * 2.0 / std::sqrt(6.0);  // d . (1, 1, 0)/sqrt 2
  const double s_floor = slave_along(f_floor, 1500.0, 0.01);
  const double s_wall = slave_along(f_wall, 1000.0, 0.02);
  EXPECT_NEAR(-xs[2] - 0.01, s_floor - 0.01, 1e-6);  // 6.2 mm into the floor
  EXPECT_NEAR((xs[0] + xs[1]) / std::sqrt(2.0) - 0.02, s_wall - 0.02, 1e-6);  // 12.6 mm
  EXPECT_NEAR((xs[0] - xs[1]) / std::sqrt(2.0), 0.0, 1e-6);
  EXPECT_NEAR((xm[0] - xm[1]) / std::sqrt(2.0), 0.0, 1e-6);
  // The master along the floor's normal: m = (F + k_c s) / (k_h + k_c).
  EXPECT_NEAR(-xm[2], (f_floor + 600.0 * s_floor) / 670.0, 1e-6);
  const std::string svg = slurp(plot);
  EXPECT_NE(svg.find("<svg"), std::string::npos);
  EXPECT_NE(svg.find("slave position [2]"), std::string::npos);
}

TEST(TeleopctlAxes, BadDirectionIsRefusedNamingTheField) {
  const std::string text = slurp(example("scenes/five_bar_plane.textproto"));
  const std::string field = "human_force_direction: [2, 1]";
  for (const auto& [name, bad, says] :
       std::vector<std::tuple<std::string, std::string, std::string>>{
           {"size", "human_force_direction: [1, 0, 0]", "must have 2 values"},
           {"zero", "human_force_direction: [0, 0]", "must not be zero"},
           {"nan", "human_force_direction: [nan, 1]", "human_force_direction"},
           {"inf", "human_force_direction: [1, inf]", "human_force_direction"},
           {"missing", "", "required with scene.human_force"}}) {
    const std::string path = temp_file("bad_" + name + ".textproto", replaced(text, field, bad));
    for (const char* command : {"simulate ", "analyze "}) {
      const CliResult r = teleopctl(command + path);
      EXPECT_EQ(r.exit_code, 1) << name << "\n" << r.out;
      EXPECT_NE(r.out.find("scene.human_force_direction"), std::string::npos) << r.out;
      EXPECT_NE(r.out.find(says), std::string::npos) << r.out;
    }
  }
}

TEST(TeleopctlAxes, SceneFieldsTheNAxisSimulatorLacksAreRefused) {
  const std::string text = slurp(example("scenes/five_bar_plane.textproto"));
  const std::string band = temp_file(
      "band.textproto",
      replaced(text,
               "human { fixed { mass_kg: 0.012 damping_Ns_per_m: 0.76 stiffness_N_per_m: 70 } }",
               ""));
  CliResult r = teleopctl("simulate " + band);
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find("human.fixed"), std::string::npos) << r.out;
  const std::string tissue = temp_file(
      "tissue.textproto",
      replaced(text, "scene {", "scene {\n  environment { tissue { stiffness_N_per_m: 100 } }"));
  r = teleopctl("simulate " + tissue);
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find("scene.environment_plane"), std::string::npos) << r.out;
  const std::string seeded =
      temp_file("seeded.textproto", replaced(text, "scene {", "scene {\n  seed: 4"));
  r = teleopctl("simulate " + seeded);
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find("scene.seed"), std::string::npos) << r.out;
  // One axis: the n-axis scene field is refused by the one-axis simulator, named.
  const std::string one = temp_file(
      "one.textproto", replaced(slurp(example("scenes/paddles_slave_fixture_stable.textproto")),
                                "scene {", "scene {\n  human_force_direction: [1]"));
  r = teleopctl("simulate " + one);
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find("scene.human_force_direction"), std::string::npos) << r.out;
}

TEST(TeleopctlAxes, EnvironmentPlaneHoldsTheSlaveAtTheForceBalance) {
  // The five-bar scene without its master plane, the slave pushing into a tissue plane along x
  // at 0.02 m, 400 N/m. At rest along x: (k_h + k_c) m - k_c s = F_x,
  // -k_c m + (k_c + K) s = K p.
  std::string text = slurp(example("scenes/five_bar_plane.textproto"));
  // y's damping differs (a different loop on each axis; the statics are the same).
  text = replaced(text, "damping_Ns_per_m_per_axis: [5, 5]", "damping_Ns_per_m_per_axis: [5, 6]");
  text = replaced(text,
                  "fixture { plane { normal: [1, 0] offset_m: 0.03 stiffness_N_per_m: 125 } }", "");
  text = replaced(text, "scene {",
                  "scene {\n  environment_plane { normal: [1, 0] offset_m: 0.02 "
                  "stiffness_N_per_m: 400 }");
  const std::string path = temp_file("env.textproto", text);
  const CliResult r = teleopctl("simulate " + path + " --json", false);
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const json j = json::parse(r.out);
  const double f = 4.0 * 2.0 / std::sqrt(5.0);
  const double det = 670.0 * 1000.0 - 600.0 * 600.0;
  const double s = (670.0 * 400.0 * 0.02 + 600.0 * f) / det;
  const double m = (f * 1000.0 + 600.0 * 400.0 * 0.02) / det;
  EXPECT_NEAR(j["final"]["slave_position_m"][0].get<double>(), s, 1e-6);
  EXPECT_NEAR(j["final"]["master_position_m"][0].get<double>(), m, 1e-6);
  EXPECT_NEAR(j["final"]["slave_position_m"][1].get<double>(), 4.0 / std::sqrt(5.0) / 70.0, 1e-6);
}

}  // namespace

namespace {

TEST(TeleopctlAxes, EquilibriumStartIsTheForceBalanceAndSettlesBack) {
  // A constant 4 N push and the slave displaced 0.1 mm along the push at t = 0: the run starts
  // at the five-bar scene's balance (as in FiveBarSceneSettlesAtTheForceBalance) and returns
  // to it.
  std::string text = slurp(example("scenes/five_bar_plane.textproto"));
  text = replaced(text, "human_force { ramp { from_N: 0 to_N: 4 start_s: 0.2 duration_s: 0.5 } }",
                  "human_force { constant { force_N: 4 } }\n  equilibrium_perturbation_m: 0.0001");
  const std::string path = temp_file("equilibrium.textproto", text);
  const CliResult r = teleopctl("simulate " + path + " --json", false);
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const json j = json::parse(r.out);
  const double x = (4.0 * 2.0 / std::sqrt(5.0) + 125.0 * 0.03) / (70.0 + 125.0);
  const double y = 4.0 / std::sqrt(5.0) / 70.0;
  ASSERT_TRUE(j.contains("equilibrium")) << r.out;
  EXPECT_NEAR(j["equilibrium"]["master_m"][0].get<double>(), x, 1e-9);
  EXPECT_NEAR(j["equilibrium"]["master_m"][1].get<double>(), y, 1e-9);
  EXPECT_NEAR(j["final"]["slave_position_m"][0].get<double>(), x, 1e-6);
  EXPECT_NEAR(j["final"]["slave_position_m"][1].get<double>(), y, 1e-6);
  // A ramp cannot start at an equilibrium: refused, named.
  const std::string ramp =
      temp_file("equilibrium_ramp.textproto",
                replaced(slurp(example("scenes/five_bar_plane.textproto")), "scene {",
                         "scene {\n  equilibrium_perturbation_m: 0.0001"));
  const CliResult bad = teleopctl("simulate " + ramp);
  EXPECT_EQ(bad.exit_code, 1) << bad.out;
  EXPECT_NE(bad.out.find("scene.equilibrium_perturbation_m"), std::string::npos) << bad.out;
}

}  // namespace

// Hostile `--set`s on the three-axis scene, through the binary (issue 18's attack on the n-axis
// inputs): each refused with exit 1 naming the field and the value, none ends the process
// otherwise; a push direction written with subnormal elements is the same direction.
TEST(TeleopctlAxes, HostileSetsAreRefusedNamingTheField) {
  const std::string scene = example("scenes/cartesian3_planes.textproto");
  std::string nine;
  for (int i = 2; i < 9; ++i) {
    nine += " --set 'slave.fixture.plane[" + std::to_string(i) +
            "]={normal: [0, 1, 0] offset_m: 0.05 stiffness_N_per_m: 100}'";
  }
  for (const auto& [sets, says] : std::vector<std::pair<std::string, std::string>>{
           {"--set 'master.device.mass_matrix_kg[0]=nan'",
            "master.device.mass_matrix_kg[0]: must be finite, got nan"},
           {"--set 'master.device.mass_matrix_kg[0]=1e308'",
            "master.device.mass_matrix_kg[0]: must be in [-1000, 1000] kg"},
           {nine, "slave.fixture.plane: at most 8 planes a side, got 9"},
           {"--set 'gains.kds_matrix[99]=1'", "gains.kds_matrix[99]: no such element"},
           {"--set 'gains.kds_matrix[-1]=1'", "bad index in 'kds_matrix[-1]'"},
           {"--set 'gains.kds_matrix[1e20]=1'", "bad index in 'kds_matrix[1e20]'"},
           {"--set axes=2147483648", "axes: cannot parse '2147483648': out of range"},
           {"--set axes=7", "axes: must be in [1, 6]"},
           {"--set 'scene.human_force_direction=0,-0,0'",
            "scene.human_force_direction: must not be zero"},
           {"--set 'slave.fixture.plane[1].normal=1e308,1,0'",
            "slave.fixture.plane[1].normal[0]: must be in [-1e+06, 1e+06]"},
           {"--set 'gains.kpm=0' --set 'gains.kpm_matrix=1e7,1e7,1e7,1e7,1e7,1e7,1e7,1e7,1e7'",
            "gains.kpm_matrix: its largest eigenvalue"},
       }) {
    for (const char* command : {"analyze ", "simulate "}) {
      const CliResult r = teleopctl(command + scene + " " + sets);
      EXPECT_EQ(r.exit_code, 1) << command << sets << "\n" << r.out;
      EXPECT_NE(r.out.find(says), std::string::npos) << command << sets << "\n" << r.out;
    }
  }
  // (1, 1, -1) written as 1e-320 each: the example's direction exactly, the same final position.
  const CliResult plain = teleopctl("simulate " + scene + " --json", false);
  const CliResult tiny = teleopctl(
      "simulate " + scene + " --set 'scene.human_force_direction=1e-320,1e-320,-1e-320' --json",
      false);
  ASSERT_EQ(plain.exit_code, 0) << plain.out;
  ASSERT_EQ(tiny.exit_code, 0) << tiny.out;
  const json a = json::parse(plain.out);
  const json b = json::parse(tiny.out);
  EXPECT_EQ(b["push_direction"], a["push_direction"]);
  EXPECT_EQ(b["final"], a["final"]);
}
