// Every --plot of teleopctl through its command (issue 17 "Plots people would put in a paper"),
// read back as XML: the verdict in the z-plane's title and one ring per eigenvalue outside the
// unit circle, the legend clear of the circle, round ticks, units on every axis, two panels
// (mm over N) for simulate, replay and identify, rates without a limit shown. And identify
// ("Smaller, found by a new user"): the shipped excitation scene recovers the configured
// paddles, too little excitation is refused (exit 4, no parameters), and the --set lines it
// prints apply to examples/live.textproto.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "common/config/config_loader.hpp"
#include "supervisor/teleopctl/analyze_command.hpp"
#include "supervisor/teleopctl/identify_command.hpp"
#include "supervisor/teleopctl/replay_command.hpp"
#include "supervisor/teleopctl/simulate_command.hpp"
#include "tests/unit/console/svg_test_util.hpp"

namespace teleop::ctl {
namespace {

using nlohmann::json;
using test::SvgElement;
namespace fs = std::filesystem;

const std::string kSource = TELEOP_SOURCE_DIR;

std::string example(const std::string& name) { return kSource + "/examples/" + name; }

struct Result {
  int exit_code{0};
  std::string out{};
  std::string err{};
};

Result ctl(const std::string& command, const std::vector<std::string>& args) {
  std::ostringstream out;
  std::ostringstream err;
  int rc = -1;
  try {
    if (command == "analyze") rc = run_analyze(parse_analyze_args(args), out, err);
    if (command == "simulate") rc = run_simulate(parse_simulate_args(args), out, err);
    if (command == "replay") rc = run_replay(args, out, err);
    if (command == "identify") rc = run_identify(args, out, err);
  } catch (const std::exception& e) {
    err << "usage error: " << e.what();
    rc = 2;
  }
  return {rc, out.str(), err.str()};
}

class TempDir {
 public:
  TempDir() {
    path_ = fs::path(::testing::TempDir()) /
            ("plots-" + std::to_string(::getpid()) + "-" +
             ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  [[nodiscard]] std::string file(const std::string& name) const { return (path_ / name).string(); }

 private:
  fs::path path_;
};

// Every axis of the plot has round, evenly spaced ticks that are multiples of their step.
void expect_round_ticks(const SvgElement& scope, const std::string& cls) {
  std::vector<double> v;
  ASSERT_TRUE(test::tick_values(scope.with_class(cls), v)) << cls << " labels are not numbers";
  ASSERT_GE(v.size(), 3U) << cls;
  const double step = std::abs(v[1] - v[0]);
  EXPECT_TRUE(test::round_step(step)) << cls << " step " << step;
  for (std::size_t i = 1; i < v.size(); ++i) {
    EXPECT_NEAR(std::abs(v[i] - v[i - 1]), step, 1e-9 * step) << cls << " tick " << i;
    EXPECT_NEAR(v[i] / step, std::round(v[i] / step), 1e-6) << cls << " " << v[i];
  }
}

// --- the z-plane -------------------------------------------------------------------------------

struct ZPlane {
  SvgElement svg{};
  json analysis{};
};

ZPlane z_plane(const TempDir& dir, const std::string& config, std::vector<std::string> sets) {
  const std::string plot = dir.file("z.svg");
  std::vector<std::string> args{config, "--plot", plot};
  std::vector<std::string> json_args{config, "--json"};
  for (const std::string& s : sets) {
    args.insert(args.end(), {"--set", s});
    json_args.insert(json_args.end(), {"--set", s});
  }
  const Result r = ctl("analyze", args);
  EXPECT_NE(r.exit_code, 1) << r.err;
  const Result j = ctl("analyze", json_args);
  return {test::read_svg(plot), json::parse(j.out)};
}

std::size_t outside_unit_circle(const json& analysis) {
  std::size_t n = 0;
  for (const json& m : analysis["eigenvalues"]) {
    if (m["structural"].get<bool>()) continue;
    const std::complex<double> z(m["z"][0].get<double>(), m["z"][1].get<double>());
    if (std::abs(z) > 1.0) ++n;
  }
  return n;
}

// The legend box lies wholly outside the unit circle: its nearest point is farther from the
// circle's centre than the radius.
void expect_legend_clear_of_circle(const SvgElement& svg) {
  const auto circles = svg.with_class("unit-circle");
  ASSERT_EQ(circles.size(), 1U);
  const double cx = circles[0]->num("cx");
  const double cy = circles[0]->num("cy");
  const double r = circles[0]->num("r");
  const auto boxes = svg.with_class("legend-box");
  ASSERT_EQ(boxes.size(), 1U);
  const SvgElement& b = *boxes[0];
  const double nx = std::clamp(cx, b.num("x"), b.num("x") + b.num("width"));
  const double ny = std::clamp(cy, b.num("y"), b.num("y") + b.num("height"));
  EXPECT_GT(std::hypot(nx - cx, ny - cy), r) << "the legend box crosses the unit circle";
}

// The paper's paddles at 500 Hz against a 4000 N/m slave wall, above the 2116 N/m the paper's
// analysis allows at that rate (examples/scenes/paddles_slave_fixture_unstable.textproto): an
// unstable loop, so at least one eigenvalue (a real one or a complex pair) outside the circle,
// each ringed, and no other.
TEST(ZPlanePlot, UnstableWallRingsEveryEigenvalueOutsideTheUnitCircle) {
  const TempDir dir;
  const ZPlane z = z_plane(dir, example("scenes/paddles_slave_fixture_unstable.textproto"), {});
  ASSERT_EQ(z.analysis["verdict"].get<std::string>(), "unstable");
  ASSERT_EQ(z.analysis["humans_evaluated"].get<int>(), 1);  // the cloud is this spectrum
  const std::size_t outside = outside_unit_circle(z.analysis);
  EXPECT_GE(outside, 1U);
  EXPECT_EQ(z.svg.with_class("unstable").size(), outside);
  EXPECT_NE(z.svg.with_class("title").front()->text.find("UNSTABLE"), std::string::npos);
  // Each ring sits outside the unit circle, in pixels too.
  const SvgElement& c = *z.svg.with_class("unit-circle").front();
  for (const SvgElement* ring : z.svg.with_class("unstable")) {
    EXPECT_GT(std::hypot(ring->num("cx") - c.num("cx"), ring->num("cy") - c.num("cy")), c.num("r"));
  }
  expect_legend_clear_of_circle(z.svg);
  const SvgElement& plane = *z.svg.with_class("panel").front();  // without the inset
  expect_round_ticks(plane, "x-tick");
  expect_round_ticks(plane, "y-tick");
}

// The same wall at 1500 N/m (below the limit): stable, nothing ringed.
TEST(ZPlanePlot, StableWallRingsNothingAndSaysStable) {
  const TempDir dir;
  const ZPlane z = z_plane(dir, example("scenes/paddles_slave_fixture_unstable.textproto"),
                           {"slave.fixture.stiffness_N_per_m=1500"});
  ASSERT_EQ(z.analysis["verdict"].get<std::string>(), "stable");
  EXPECT_EQ(outside_unit_circle(z.analysis), 0U);
  EXPECT_TRUE(z.svg.with_class("unstable").empty());
  const std::string title = z.svg.with_class("title").front()->text;
  EXPECT_NE(title.find("STABLE"), std::string::npos) << title;
  EXPECT_EQ(title.find("UNSTABLE"), std::string::npos) << title;
  expect_legend_clear_of_circle(z.svg);
}

// The human band of examples/paddles.textproto: markers coloured by grip force with a colour
// bar over the band's force levels, and an inset around z = 1 whose axes are round too.
TEST(ZPlanePlot, HumanBandColouredByGripForceWithAnInsetNearOne) {
  const TempDir dir;
  const ZPlane z = z_plane(dir, example("paddles.textproto"), {});
  ASSERT_GT(z.analysis["humans_evaluated"].get<int>(), 1);
  EXPECT_EQ(z.svg.with_class("colour-bar").size(), 1U);
  const auto insets = z.svg.with_class("inset");
  ASSERT_EQ(insets.size(), 1U);
  expect_round_ticks(*insets[0], "x-tick");
  expect_round_ticks(*insets[0], "y-tick");
  EXPECT_NE(insets[0]->text.find("z = 1"), std::string::npos);
  // More than one marker colour: the grip force varies.
  std::set<std::string> fills;
  for (const SvgElement* c : z.svg.named("circle")) {
    if (c->attrs.count("fill") && c->attrs.at("fill") != "none") fills.insert(c->attrs.at("fill"));
  }
  EXPECT_GT(fills.size(), 3U);
  expect_legend_clear_of_circle(z.svg);
}

// --- limits against the sample rate and a swept parameter --------------------------------------

TEST(LimitsPlot, RatesWithoutALimitAreMarkedAndThePassivityBoundDrawn) {
  const TempDir dir;
  const std::string plot = dir.file("limits.svg");
  const std::vector<std::string> rates{"--max-stiffness", "master", "--rates",
                                       "20,50,100,200,500,1000,2000"};
  // Without master damping the master side has a passivity bound, 2 b / T - K_pm (at least 0).
  std::vector<std::string> args{example("paddles.textproto"), "--set", "gains.kdm=0", "--plot",
                                plot};
  args.insert(args.end(), rates.begin(), rates.end());
  const Result r = ctl("analyze", args);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::vector<std::string> jargs{example("paddles.textproto"), "--set", "gains.kdm=0", "--json"};
  jargs.insert(jargs.end(), rates.begin(), rates.end());
  const json j = json::parse(ctl("analyze", jargs).out);
  std::size_t missing = 0;
  bool bound = false;
  for (const json& l : j["limits"]) {
    missing += l["max_stable_stiffness_N_per_m"].is_null() ? 1 : 0;
    bound =
        bound || (l.contains("passivity_limit_N_per_m") && !l["passivity_limit_N_per_m"].is_null());
  }
  // 20 Hz is far too slow for the paddles' 600 N/m coupling: no stiffness is stable there.
  EXPECT_GE(missing, 1U);
  const SvgElement svg = test::read_svg(plot);
  EXPECT_EQ(svg.with_class("no-limit").size(), missing);
  EXPECT_EQ(svg.with_class("x-label").front()->text, "sample rate (Hz)");
  EXPECT_EQ(svg.with_class("y-label").front()->text, "maximum stable stiffness (N/m)");
  expect_round_ticks(svg, "x-tick");
  expect_round_ticks(svg, "y-tick");
  ASSERT_TRUE(bound);
  bool dashed = false;
  for (const SvgElement* p : svg.named("path")) {
    dashed = dashed || p->attrs.count("stroke-dasharray") > 0;
  }
  EXPECT_TRUE(dashed) << "the passivity bound is drawn dashed";
  EXPECT_NE(svg.text.find("passivity bound"), std::string::npos);
  // Grid: a light line at every x tick inside the frame.
  std::size_t grid = 0;
  for (const SvgElement* l : svg.named("line")) grid += l->attrs.at("stroke") == "#e4e4e4";
  EXPECT_GE(grid, svg.with_class("x-tick").size() + svg.with_class("y-tick").size());
}

TEST(LimitsPlot, SweptAxisCarriesItsUnit) {
  const TempDir dir;
  const std::string plot = dir.file("sweep.svg");
  const Result r = ctl("analyze", {example("paddles.textproto"), "--max-stiffness", "slave",
                                   "--sweep", "gains.kds=0:4:1", "--plot", plot});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const SvgElement svg = test::read_svg(plot);
  EXPECT_EQ(svg.with_class("x-label").front()->text, "gains.kds (Ns/m)");
  expect_round_ticks(svg, "x-tick");
  // And a sweep over the round trip, a count of samples.
  const Result d = ctl("analyze", {example("paddles.textproto"), "--max-stiffness", "slave",
                                   "--sweep", "round_trip_delay_samples=0:4:1", "--plot", plot});
  ASSERT_EQ(d.exit_code, 0) << d.err;
  EXPECT_EQ(test::read_svg(plot).with_class("x-label").front()->text,
            "round_trip_delay_samples (samples)");
}

// --- time series: simulate, replay, identify ---------------------------------------------------

// Two panels, positions in mm over forces in N, one time axis with round ticks, each legend
// right of its panel's traces.
void expect_position_force_panels(const SvgElement& svg, std::size_t position_traces,
                                  std::size_t force_traces) {
  const auto panels = svg.with_class("panel");
  ASSERT_EQ(panels.size(), 2U);
  EXPECT_EQ(panels[0]->with_class("y-label").front()->text, "position (mm)");
  EXPECT_EQ(panels[1]->with_class("y-label").front()->text, "force (N)");
  EXPECT_EQ(svg.with_class("x-label").front()->text, "time (s)");
  EXPECT_EQ(panels[0]->named("path").size(), position_traces);
  EXPECT_EQ(panels[1]->named("path").size(), force_traces);
  expect_round_ticks(*panels[1], "x-tick");
  expect_round_ticks(*panels[0], "y-tick");
  expect_round_ticks(*panels[1], "y-tick");
  for (const SvgElement* panel : panels) {
    const SvgElement* frame = panel->named("rect").back();  // the frame after the clip's rect
    for (const SvgElement* box : svg.with_class("legend-box")) {
      EXPECT_GT(box->num("x"), frame->num("x") + frame->num("width"));
    }
  }
}

TEST(TimePlots, SimulateHasPositionAndForcePanels) {
  const TempDir dir;
  const std::string plot = dir.file("sim.svg");
  const Result r = ctl("simulate", {example("scenes/paddles_master_fixture.textproto"),
                                    "--duration", "1", "--plot", plot});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  // master and slave positions and the master's fixture (dashed, at 5 mm); the human's and the
  // environment's forces
  const SvgElement svg = test::read_svg(plot);
  expect_position_force_panels(svg, 3, 2);
  const auto fixture = svg.with_class("panel")[0]->named("path")[2];
  EXPECT_EQ(fixture->attrs.count("stroke-dasharray"), 1U);
  EXPECT_NE(svg.text.find("master fixture (2000 N/m)"), std::string::npos);
}

TEST(TimePlots, ReplayPlotsBothNodesFromTheRecording) {
  const TempDir dir;
  const std::string session = dir.file("s.mcap");
  ASSERT_EQ(ctl("simulate", {example("scenes/paddles_master_fixture.textproto"), "--duration", "1",
                             "--out", session, "--log-start-ns", "0"})
                .exit_code,
            0);
  const std::string plot = dir.file("replay.svg");
  const Result r = ctl("replay", {session, "--plot", plot});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const SvgElement svg = test::read_svg(plot);
  // both nodes' positions and the recorded configuration's master fixture (2000 N/m at 5 mm);
  // both load cells
  expect_position_force_panels(svg, 3, 2);
  EXPECT_NE(svg.text.find("master fixture (2000 N/m)"), std::string::npos);
  // 1 s of cycles: the time axis ends at 1 s.
  std::vector<double> t;
  ASSERT_TRUE(test::tick_values(svg.with_class("panel")[1]->with_class("x-tick"), t));
  EXPECT_DOUBLE_EQ(t.back(), 1.0);
  // A PNG name is refused like analyze's and simulate's.
  EXPECT_EQ(ctl("replay", {session, "--plot", dir.file("x.png")}).exit_code, 2);
  EXPECT_EQ(ctl("replay", {session, "--plot", plot, "--json"}).exit_code, 2);
}

// --- identify ----------------------------------------------------------------------------------

std::string simulate_session(const TempDir& dir, const std::string& scene,
                             const std::vector<std::string>& sets = {}) {
  const std::string session = dir.file("push.mcap");
  std::vector<std::string> args{scene, "--out", session, "--log-start-ns", "0"};
  for (const std::string& s : sets) args.insert(args.end(), {"--set", s});
  const Result r = ctl("simulate", args);
  // 3: the oscillation detector takes a random push for a sustained oscillation.
  EXPECT_TRUE(r.exit_code == 0 || r.exit_code == 3) << r.err;
  return session;
}

// The shipped scene drives the paper's paddles (master 0.040 kg, 0.41 Ns/m; slave 0.036 kg,
// 0.49 Ns/m). Tolerance 3 %: the identification itself is exact for a mass-damper through the
// common smoothing (common/stability/identify.hpp); what is left is the encoder's 0.1445 mm
// staircase in x'' (errors in variables, 0.6 % low on the mass with 8 passes at 1 kHz in
// test_identify's study) and the 200 Hz velocity filter the laws see but identify does not.
TEST(Identify, ExcitationSceneRecoversThePaddlesAndItsSetLinesMergeIntoAConfiguration) {
  const TempDir dir;
  const std::string session =
      simulate_session(dir, example("scenes/identify_excitation.textproto"));
  const struct {
    const char* device;
    double mass_kg;
    double damping_Ns_per_m;
  } cases[] = {{"master", 0.040, 0.41}, {"slave", 0.036, 0.49}};
  for (const auto& c : cases) {
    const std::string plot = dir.file(std::string(c.device) + ".svg");
    const Result r = ctl("identify", {session, "--device", c.device, "--json", "--plot", plot});
    ASSERT_EQ(r.exit_code, 0) << r.err << r.out;
    const json j = json::parse(r.out);
    ASSERT_TRUE(j["identified"].get<bool>());
    const double m = j["mass_kg"].get<double>();
    const double b = j["damping_Ns_per_m"].get<double>();
    EXPECT_NEAR(m / c.mass_kg, 1.0, 0.03) << c.device << " mass " << m;
    EXPECT_NEAR(b / c.damping_Ns_per_m, 1.0, 0.03) << c.device << " damping " << b;
    // The motion spans many encoder counts (0.1445 mm each).
    EXPECT_NEAR(j["position_step_m"].get<double>(), 2.0 * M_PI * 0.115 / 5000.0, 1e-9);
    EXPECT_GT(j["position_range_m"].get<double>() / j["position_step_m"].get<double>(), 10.0);

    // The --set lines, applied to the live configuration, replace its device section's values
    // (pasting a second `master { device { ... } }` would be "set more than once").
    std::vector<std::string> sets = j["set"].get<std::vector<std::string>>();
    ASSERT_EQ(sets.size(), 2U);
    const config::LoadedConfig live = config::parse_config_file(example("live.textproto"), sets);
    const TeleopParams p = config::to_teleop_params(live);
    const DeviceParams& d = std::string(c.device) == "master" ? p.master_device : p.slave_device;
    // printed to 4 significant digits: within half a unit of the 4th, 5e-4 relative
    EXPECT_NEAR(d.mass_kg, m, 5e-4 * m);
    EXPECT_NEAR(d.damping_Ns_per_m, b, 5e-4 * b);
    std::vector<std::string> analyze{example("live.textproto")};
    for (const std::string& s : sets) analyze.insert(analyze.end(), {"--set", s});
    EXPECT_EQ(ctl("analyze", analyze).exit_code, 0);
    // The text form prints the same overrides on one line.
    const Result text = ctl("identify", {session, "--device", c.device});
    EXPECT_NE(text.out.find("--set " + sets[0] + " --set " + sets[1]), std::string::npos)
        << text.out;

    // measured against fitted: position over two force traces
    const SvgElement svg = test::read_svg(plot);
    expect_position_force_panels(svg, 1, 2);
    EXPECT_NE(svg.with_class("title").front()->text.find("m = "), std::string::npos);
  }
}

// A push of 0.02 N at 2 Hz through the hand's 70 N/m moves the master about 0.3 mm, two encoder
// counts: identify refuses (exit 4) and prints no parameters and nothing to paste.
TEST(Identify, TooLittleMotionIsRefused) {
  const TempDir dir;
  const std::string scene = dir.file("small.textproto");
  std::ofstream(scene) << "sample_rate_hz: 1000\n"
                          "master { device { mass_kg: 0.040 damping_Ns_per_m: 0.41 } }\n"
                          "slave { device { mass_kg: 0.036 damping_Ns_per_m: 0.49 } }\n"
                          "gains { kps: 300 kds: 1 }\n"
                          "velocity_filter { cutoff_hz: 200 }\n"
                          "human { fixed { mass_kg: 0.012 damping_Ns_per_m: 0.76 "
                          "stiffness_N_per_m: 70 } }\n"
                          "scene { duration_s: 5 seed: 3 human_force { sinusoid { "
                          "amplitude_N: 0.02 frequency_hz: 2 } } }\n";
  const std::string session = simulate_session(dir, scene);
  const Result r = ctl("identify", {session, "--device", "master", "--json"});
  EXPECT_EQ(r.exit_code, 4) << r.err << r.out;
  const json j = json::parse(r.out);
  EXPECT_FALSE(j["identified"].get<bool>());
  EXPECT_TRUE(j["mass_kg"].is_null());
  EXPECT_TRUE(j["set"].is_null());
  EXPECT_LT(j["position_range_m"].get<double>() / j["position_step_m"].get<double>(), 10.0);
  const Result text = ctl("identify", {session, "--device", "master"});
  EXPECT_EQ(text.exit_code, 4);
  EXPECT_NE(text.out.find("NOT IDENTIFIED"), std::string::npos) << text.out;
  EXPECT_EQ(text.out.find("mass "), std::string::npos) << text.out;
  EXPECT_EQ(text.out.find("--set"), std::string::npos) << text.out;
  EXPECT_NE(text.err.find("too little excitation"), std::string::npos) << text.err;
}

// A force that has nothing to do with the motion (independent noise) with a continuous
// position: r^2 near 0, refused although the motion is large.
TEST(Identify, AForceTheMotionDoesNotExplainIsRefused) {
  const TempDir dir;
  const std::string csv = dir.file("noise.csv");
  {
    std::ofstream f(csv);
    f << "time_s,x_m,f_N\n";
    std::mt19937 rng(5);
    std::normal_distribution<double> noise(0.0, 1.0);
    f.precision(17);
    for (int k = 0; k < 5000; ++k) {
      const double t = 1e-3 * k;
      f << t << "," << 0.01 * std::sin(2 * M_PI * 1.3 * t) + 0.004 * std::sin(2 * M_PI * 4.1 * t)
        << "," << noise(rng) << "\n";
    }
  }
  const Result r =
      ctl("identify", {csv, "--position", "x_m", "--force", "f_N", "--device", "slave", "--json"});
  EXPECT_EQ(r.exit_code, 4) << r.err << r.out;
  const json j = json::parse(r.out);
  EXPECT_LT(j["r_squared"].get<double>(), 0.9);
  EXPECT_TRUE(j["position_step_m"].is_null());  // continuous: no encoder count to speak of
  EXPECT_NE(j["reasons"][0].get<std::string>().find("r^2"), std::string::npos);
}

}  // namespace
}  // namespace teleop::ctl
