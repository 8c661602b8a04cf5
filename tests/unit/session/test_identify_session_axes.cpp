// `teleopctl identify FILE.mcap` of a node with several axes (issue 18): a session written here
// through the live session recorder from an exact ZOH simulation of a 3-axis device with a
// known coupled mass matrix and diagonal damping (common/sim/PlantAxes, checked on its own
// against Eigen's matrix exponential), each axis driven by its own multisine, as the CSV test
// (tests/unit/console/test_identify_axes_command.cpp) does. Each cycle records the position
// sampled at its start and the command it then holds for a period (how a node records), so the
// command must be paired with the next cycle's position. The command must give back the masses
// and dampings the device was built with, to the CSV test's tolerances.
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <numbers>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "common/record/session.hpp"
#include "common/record/session_recorder.hpp"
#include "common/sim/plant_axes.hpp"
#include "supervisor/teleopctl/identify_command.hpp"
#include "teleop/v1/telemetry.pb.h"

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

// The CSV test's device.
[[nodiscard]] Eigen::MatrixXd true_mass() {
  Eigen::MatrixXd m(3, 3);
  m << 0.050, 0.012, -0.008, 0.012, 0.040, 0.006, -0.008, 0.006, 0.060;
  return m;
}
[[nodiscard]] Eigen::VectorXd true_damping() { return Eigen::Vector3d(0.45, 0.35, 0.60); }

struct Session {
  bool master{true};
  int gap_after{-1};  // >= 0: the sequence jumps by 5 after this cycle (two runs)
};

// 1 kHz, 20 s, 3 axes, the CSV test's excitation: cycle k records x(kT) and the command u_k it
// holds over [kT, (k+1)T]; no load-cell force (0 N). 50 cycles per telemetry message. The slave
// records the same device (its load cell reads 0 N, whose negative is still 0).
fs::path write_session(const std::string& name, const Session& how) {
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
  const std::unique_ptr<record::SessionSink> sink = record::make_session_recorder_at(path);
  const std::string_view topic = record::topic::telemetry(how.master);
  v1::Telemetry t;
  std::uint64_t sequence = 1;
  sim::AxesVector u(kAxes);
  for (int k = 0; k < kSamples; ++k) {
    const double time_s = k * kPeriodS;
    for (int i = 0; i < kAxes; ++i) {
      double s = 0.0;
      for (int j = 0; j < 8; ++j) {
        s += 0.3 * std::sin(2.0 * std::numbers::pi * freq[i][j] * time_s + phase[i][j]);
      }
      u(i) = s;
    }
    v1::CycleRecord* c = t.add_cycles();
    c->set_sequence(sequence);
    sequence += (k == how.gap_after) ? 5 : 1;
    c->set_sample_time_ns(1'000'000LL * k);
    c->set_mode(v1::ENGAGED);
    c->set_axes(kAxes);
    const sim::AxesVector& x = plant.state().position_m;
    for (int i = 0; i < kAxes; ++i) {
      c->add_positions_m(x(i));
      c->add_velocities_m_per_s(plant.state().velocity_m_per_s(i));
      c->add_forces_n(0.0);
      c->add_commands_n(u(i));
      c->add_peer_positions_m(0.0);
    }
    plant.step(u);
    if (t.cycles_size() == 50) {
      t.set_session_id(11);
      sink->record(topic, "teleop.v1.Telemetry", 1'000'000LL * k, t.SerializeAsString());
      t.Clear();
    }
  }
  return path;
}

void expect_device(const nlohmann::json& j) {
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
}

TEST(IdentifySessionAxes, GivesBackTheCoupledMassAndDampingOfTheRecordedDevice) {
  const fs::path mcap = write_session("identify_session_axes.mcap", {});
  const Ran r = run({mcap.string(), "--json"});
  ASSERT_EQ(r.rc, 0) << r.out << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_TRUE(j["identified"].get<bool>());
  EXPECT_EQ(j["axes"].get<int>(), 3);
  EXPECT_EQ(j["device"], "master");
  EXPECT_EQ(j["mass_model"], "coupled");
  expect_device(j);
  EXPECT_GT(j["r_squared"].get<double>(), 0.999);
  ASSERT_EQ(j["files"].size(), 1U);
  EXPECT_EQ(j["files"][0], mcap.string() + " master cycles 1..20000");
  // The text report prints the same --set overrides as the CSV path.
  const Ran text = run({mcap.string()});
  ASSERT_EQ(text.rc, 0) << text.err;
  for (const std::string& s : j["set"].get<std::vector<std::string>>()) {
    EXPECT_NE(text.out.find("--set '" + s + "'"), std::string::npos) << text.out;
  }
  EXPECT_NE(text.out.find("master.device.mass_matrix_kg="), std::string::npos) << text.out;
}

// The slave's session, split in two runs by a sequence gap, and the per-axis mass model: the
// runs are named by their cycles, the per-axis model is used (and fits worse than the coupled
// device, as in the CSV test).
TEST(IdentifySessionAxes, SlaveRunsSplitAtAGapAndTheMassModelFlag) {
  const fs::path mcap = write_session("identify_session_axes_slave.mcap", {false, 9999});
  const Ran coupled = run({mcap.string(), "--device", "slave", "--json"});
  ASSERT_EQ(coupled.rc, 0) << coupled.err;
  const nlohmann::json j = nlohmann::json::parse(coupled.out);
  EXPECT_EQ(j["device"], "slave");
  ASSERT_EQ(j["files"].size(), 2U);
  EXPECT_EQ(j["files"][0], mcap.string() + " slave cycles 1..10000");
  EXPECT_EQ(j["files"][1], mcap.string() + " slave cycles 10005..20004");
  expect_device(j);
  const Ran per_axis = run({mcap.string(), "--device", "slave", "--json", "--mass", "per-axis"});
  const nlohmann::json jp = nlohmann::json::parse(per_axis.out);
  EXPECT_EQ(jp["mass_model"], "per-axis");
  EXPECT_GT(jp["residual_rms_N"].get<double>(), 10.0 * j["residual_rms_N"].get<double>());
  // One axis of it cannot be drawn.
  const Ran plot = run({mcap.string(), "--device", "slave", "--plot", "fit.svg"});
  EXPECT_EQ(plot.rc, 1);
  EXPECT_NE(plot.err.find("--plot draws one axis"), std::string::npos) << plot.err;
  // Columns are for CSV files.
  const Ran columns = run({mcap.string(), "--position", "a,b,c", "--force", "x,y,z"});
  EXPECT_EQ(columns.rc, 2);
}

// One axis (n = 1) reads as before several axes: a one-axis session (the scalar fields, axes
// unset) of an exact ZOH 1-axis device (m 0.04 kg, b 0.41 Ns/m, the paper's master paddle)
// gives the one-axis report, and the same samples as a CSV through the unchanged CSV path
// (--position, --force, --held-force: the command of the row before) give the same fit.
TEST(IdentifySessionAxes, AOneAxisSessionFitsAsTheCsvPathOfTheSameSamples) {
  constexpr int kSamples = 10000;
  sim::PlantAxesParams p;
  p.device.mass_kg = Eigen::MatrixXd::Constant(1, 1, 0.040);
  p.device.damping_Ns_per_m = Eigen::VectorXd::Constant(1, 0.41);
  p.device.coulomb_N = Eigen::VectorXd::Zero(1);
  sim::PlantAxes plant(p, std::chrono::microseconds(1000));
  plant.reset({sim::AxesVector::Zero(1), sim::AxesVector::Zero(1)});
  const fs::path mcap = fs::path(::testing::TempDir()) / "identify_session_one_axis.mcap";
  const fs::path csv = fs::path(::testing::TempDir()) / "identify_session_one_axis.csv";
  {
    const std::unique_ptr<record::SessionSink> sink = record::make_session_recorder_at(mcap);
    std::ofstream f(csv);
    f.precision(17);
    f << "x,f,u_before\n";
    v1::Telemetry t;
    double u_before = 0.0;
    sim::AxesVector u(1);
    for (int k = 0; k < kSamples; ++k) {
      const double time_s = k * 1e-3;
      u(0) = 0.3 * std::sin(2.0 * std::numbers::pi * 0.7 * time_s) +
             0.2 * std::sin(2.0 * std::numbers::pi * 3.1 * time_s + 1.0) +
             0.1 * std::sin(2.0 * std::numbers::pi * 8.3 * time_s + 2.0);
      const double x = plant.state().position_m(0);
      v1::CycleRecord* c = t.add_cycles();
      c->set_sequence(static_cast<std::uint64_t>(k + 1));
      c->set_sample_time_ns(1'000'000LL * k);
      c->set_mode(v1::ENGAGED);
      c->set_position_m(x);
      c->set_force_n(0.0);
      c->set_command_n(u(0));
      if (k > 0) f << x << ",0," << u_before << "\n";  // sample k: the command of cycle k-1
      u_before = u(0);
      plant.step(u);
      if (t.cycles_size() == 100) {
        t.set_session_id(5);
        sink->record(record::topic::kMasterTelemetry, "teleop.v1.Telemetry", 1'000'000LL * k,
                     t.SerializeAsString());
        t.Clear();
      }
    }
  }
  const Ran session = run({mcap.string(), "--json"});
  const Ran table = run({csv.string(), "--position", "x", "--force", "f", "--held-force",
                         "u_before", "--rate", "1000", "--device", "master", "--json"});
  ASSERT_EQ(session.rc, 0) << session.out << session.err;
  ASSERT_EQ(table.rc, 0) << table.out << table.err;
  const nlohmann::json js = nlohmann::json::parse(session.out);
  const nlohmann::json jc = nlohmann::json::parse(table.out);
  EXPECT_FALSE(js.contains("axes"));  // the one-axis report
  EXPECT_EQ(js["samples"], jc["samples"]);
  // The same samples; the period from the sample times (1e6 ns) or from --rate: to rounding.
  EXPECT_NEAR(js["mass_kg"].get<double>(), jc["mass_kg"].get<double>(), 1e-9);
  EXPECT_NEAR(js["damping_Ns_per_m"].get<double>(), jc["damping_Ns_per_m"].get<double>(), 1e-9);
  // And the device's own numbers (the filters' bias well below 1 %).
  EXPECT_NEAR(js["mass_kg"].get<double>(), 0.040, 0.01 * 0.040);
  EXPECT_NEAR(js["damping_Ns_per_m"].get<double>(), 0.41, 0.01 * 0.41);
}

}  // namespace
}  // namespace teleop::ctl
