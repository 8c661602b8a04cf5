// Real-time factor of the n-axis lockstep simulator (issue 18 target: the 3-axis scene at least
// 1000x real time on one core). The scene: bench_scene.cpp's bilateral teleoperator on every
// axis, the masses coupled, a slave plane tilted 45 degrees at 5 mm, the operator pushing 2 N
// into it from rest; ten simulated seconds a run, one row kept a second. The counter
// `realtime_factor` is simulated seconds per wall-clock second.
//
//   build/bench/bench_scene_axes
#include <benchmark/benchmark.h>

#include <cmath>

#include "common/scene/lockstep_axes.hpp"

namespace {

using namespace teleop;

scene::AxesSceneSetup scene_of(int n) {
  scene::AxesSceneSetup s;
  s.duration_s = 10.0;
  s.output_rate_hz = 1.0;
  TeleopAxesParams& p = s.teleop;
  p.axes = n;
  p.sample_rate_hz = 1000.0;
  const Eigen::MatrixXd id = Eigen::MatrixXd::Identity(n, n);
  Eigen::MatrixXd coupling = Eigen::MatrixXd::Zero(n, n);
  for (int i = 0; i + 1 < n; ++i) coupling(i, i + 1) = coupling(i + 1, i) = 0.004;
  p.master_device = {0.040 * id + coupling, Eigen::VectorXd::Constant(n, 0.41),
                     Eigen::VectorXd::Zero(n)};
  p.slave_device = {0.036 * id + coupling, Eigen::VectorXd::Constant(n, 0.49),
                    Eigen::VectorXd::Zero(n)};
  p.gains = {600.0 * id, 600.0 * id, 2.0 * id, 2.0 * id, 0.0 * id, 0.0 * id, 0.0 * id};
  p.velocity_cutoff_hz = 200.0;
  Eigen::VectorXd normal = Eigen::VectorXd::Zero(n);
  normal(0) = 1.0;
  if (n > 1) normal(1) = 1.0;
  normal.normalize();
  p.slave_planes.push_back({normal, 0.005, 1500.0});
  p.human.kind = HumanKind::kFixed;
  p.human.fixed = {0.012 * id, 0.76 * id, 70.0 * id};
  s.push_direction = normal;
  s.push_profile = sim::ForceProfile::ramp(0.0, 2.0, 0.2, 0.5);
  return s;
}

void BM_AxesScene(benchmark::State& state) {
  const scene::AxesSceneSetup s = scene_of(static_cast<int>(state.range(0)));
  double simulated = 0.0;
  for (auto _ : state) {
    const scene::AxesSimulationResult r = scene::simulate_axes(s);
    benchmark::DoNotOptimize(r.summary.oscillation.amplitude_m);
    simulated += r.summary.duration_s;
  }
  state.counters["realtime_factor"] = benchmark::Counter(simulated, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_AxesScene)->Arg(1)->Arg(3)->Arg(6)->ArgName("axes")->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
