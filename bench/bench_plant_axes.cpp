// Cost of one PlantAxes period (issue 18, "Simulation"): n = 1, 3, 6 axes with a coupled mass,
// free and in contact with a tilted plane, driven by a sampled PD about a point 1 cm inside
// the plane (so the contact case enters, bounces and settles in it), and the construction
// (every mode's propagators). One iteration = one simulated millisecond.
//
//   build/bench/bench_plant_axes [benchmark flags]
#include <benchmark/benchmark.h>

#include <chrono>
#include <cmath>

#include "common/sim/plant_axes.hpp"

namespace {

using namespace teleop::sim;

// A coupled, well-conditioned mass (0.2 kg on the diagonal, 0.02 kg between neighbours),
// 2 Ns/m per axis, a finger-like human stiffness of 100 N/m per axis.
PlantAxesParams params(int n, bool contact) {
  PlantAxesParams p;
  p.device.mass_kg = Eigen::MatrixXd::Identity(n, n) * 0.2;
  for (int i = 0; i + 1 < n; ++i) {
    p.device.mass_kg(i, i + 1) = 0.02;
    p.device.mass_kg(i + 1, i) = 0.02;
  }
  p.device.damping_Ns_per_m = Eigen::VectorXd::Constant(n, 2.0);
  p.device.coulomb_N = Eigen::VectorXd::Zero(n);
  p.human.stiffness_N_per_m = Eigen::MatrixXd::Identity(n, n) * 100.0;
  if (contact) {
    p.planes.push_back({Eigen::VectorXd::Ones(n).normalized(), 0.01, 2000.0, 2.0});
  }
  return p;
}

void BM_PlantAxesStep(benchmark::State& state) {
  const auto n = static_cast<int>(state.range(0));
  const bool contact = state.range(1) != 0;
  PlantAxes plant(params(n, contact), std::chrono::milliseconds(1));
  // The target: 1 cm past the plane along its normal (or the same point in free space).
  const AxesVector target = AxesVector::Ones(n) * (0.02 / std::sqrt(static_cast<double>(n)));
  AxesVector u(n);
  std::uint64_t steps = 0;
  for (auto _ : state) {
    const PlantAxesState& s = plant.state();
    for (int i = 0; i < n; ++i) {
      u(i) = 400.0 * (target(i) - s.position_m(i)) - 4.0 * s.velocity_m_per_s(i);
    }
    benchmark::DoNotOptimize(plant.step(u));
    if (++steps % 1000 == 0) plant.reset({AxesVector::Zero(n), AxesVector::Zero(n)});
  }
  state.counters["events_per_step"] =
      static_cast<double>(plant.total_events()) / static_cast<double>(steps);
  state.SetLabel(std::string(contact ? "plane" : "free") + ", n = " + std::to_string(n));
}
BENCHMARK(BM_PlantAxesStep)->ArgsProduct({{1, 3, 6}, {0, 1}});

void BM_PlantAxesConstruct(benchmark::State& state) {
  const auto n = static_cast<int>(state.range(0));
  const PlantAxesParams p = params(n, true);
  for (auto _ : state) {
    PlantAxes plant(p, std::chrono::milliseconds(1));
    benchmark::DoNotOptimize(plant.state());
  }
}
BENCHMARK(BM_PlantAxesConstruct)->Arg(1)->Arg(3)->Arg(6)->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
