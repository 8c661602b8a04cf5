// Cost of one cycle of the simulated n-axis device (issue 18, "Devices"): read, write, tick at
// n = 1, 3, 6, a master held by a human (coupled-free diagonal mass, a sinusoidal push) with
// quantised encoders, Cartesian or through the five-bar on axes 0 and 1, and a noisy load cell.
// One iteration = one simulated millisecond. The difference to bench_plant_axes's free step is
// the device's own work (encoders, kinematics, load cell, amplifier).
//
//   build/bench/bench_device_axes [benchmark flags]
#include <benchmark/benchmark.h>

#include <chrono>
#include <string>

#include "common/device/sim_device_axes.hpp"

namespace {

using namespace teleop;
using namespace teleop::device;

SimDeviceAxesConfig master(int n, bool five_bar) {
  SimDeviceAxesConfig c;
  c.plant.device.mass_kg = Eigen::MatrixXd::Identity(n, n) * 0.2;
  c.plant.device.damping_Ns_per_m = Eigen::VectorXd::Constant(n, 2.0);
  SimHumanAxes h;
  h.impedance.mass_kg = Eigen::MatrixXd::Identity(n, n) * 0.1;
  h.impedance.damping_Ns_per_m = Eigen::MatrixXd::Identity(n, n) * 2.0;
  h.impedance.stiffness_N_per_m = Eigen::MatrixXd::Identity(n, n) * 100.0;
  h.direction = Eigen::VectorXd::Ones(n).normalized();
  h.profile = sim::ForceProfile::sinusoid(0.0, 1.0, 1.0);
  c.human = h;
  c.load_cell.noise_std_N = 0.02;
  if (five_bar) {
    c.kinematics = DeviceKinematics::kFiveBar;
    c.five_bar.base_separation_m = 0.1;
    c.five_bar.proximal_m[0] = c.five_bar.proximal_m[1] = 0.1;
    c.five_bar.distal_m[0] = c.five_bar.distal_m[1] = 0.15;
    c.five_bar_home_m = Eigen::Vector2d(0.0, 0.2);
    c.encoders.assign(static_cast<std::size_t>(n), sim::EncoderParams{4096, 1.0, 0.02});
  }
  return c;
}

void BM_SimDeviceAxesCycle(benchmark::State& state) {
  const auto n = static_cast<int>(state.range(0));
  const bool five_bar = state.range(1) != 0;
  const SimDeviceAxesConfig c = master(n, five_bar);
  SimDeviceAxes dev(c);
  if (!dev.configure().ok() || !dev.activate().ok()) {
    state.SkipWithError("configure failed");
    return;
  }
  SampleAxes s;
  CommandAxes command;
  command.force_N = AxisVector::Zero(n);
  for (auto _ : state) {
    benchmark::DoNotOptimize(dev.read(s));
    for (int i = 0; i < n; ++i) command.force_N(i) = -50.0 * s.position_m(i);
    benchmark::DoNotOptimize(dev.write(command));
    benchmark::DoNotOptimize(dev.tick(c.period));
  }
  state.SetLabel(std::string(five_bar ? "five-bar" : "cartesian") + ", n = " + std::to_string(n));
}
BENCHMARK(BM_SimDeviceAxesCycle)
    ->Args({1, 0})
    ->Args({3, 0})
    ->Args({6, 0})
    ->Args({2, 1})
    ->Args({6, 1});

}  // namespace

BENCHMARK_MAIN();
