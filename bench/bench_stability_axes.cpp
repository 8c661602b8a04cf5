// Speed of the n-axis stability analysis (issue 18 targets on this 2-core machine: one 3-axis
// configuration analysed <= 20 us, the 448-human band <= 10 ms). docs/benchmarks.md has the
// numbers and the command.
#include <benchmark/benchmark.h>

#include "common/stability/analysis_axes.hpp"

namespace {

using namespace teleop;
using namespace teleop::stability;
using Mat = Eigen::MatrixXd;
using Vec = Eigen::VectorXd;

Mat eye(double v) { return Mat::Identity(3, 3) * v; }

// Three isotropic paddle axes (the paper's paddles on every axis, 1 kHz, 200 Hz filter, one
// sample of round trip), a master plane along z and a slave plane along -y.
TeleopAxesParams isotropic(HumanKind human) {
  TeleopAxesParams a;
  a.axes = 3;
  a.sample_rate_hz = 1000.0;
  a.master_device = {eye(0.040), Vec::Constant(3, 0.41), Vec::Zero(3)};
  a.slave_device = {eye(0.036), Vec::Constant(3, 0.49), Vec::Zero(3)};
  a.master_planes = {{Vec::Unit(3, 2), 0.0, 800.0}};
  a.slave_planes = {{-Vec::Unit(3, 1), 0.0, 500.0}};
  a.gains = {eye(300.0), eye(300.0), eye(1.5), eye(1.5), eye(0.1), eye(0.1), eye(0.0)};
  a.velocity_cutoff_hz = 200.0;
  a.round_trip_delay_samples = 1;
  a.human.kind = human;
  a.human.fixed = {eye(0.010), eye(2.0), eye(300.0)};
  a.human.band_per_axis.assign(3, default_human_band());
  return a;
}

// The same with a coupled task-space mass matrix, coupled gains and a tilted master plane: the
// whole 3-axis model (21 states).
TeleopAxesParams coupled(HumanKind human) {
  TeleopAxesParams a = isotropic(human);
  Mat m(3, 3);
  m << 0.30, 0.05, -0.02, 0.05, 0.22, 0.04, -0.02, 0.04, 0.18;
  Mat k(3, 3);
  k << 1.0, 0.2, 0.0, 0.2, 0.8, -0.1, 0.0, -0.1, 1.2;
  a.master_device.mass_kg = 0.2 * m;
  a.slave_device.mass_kg = 0.15 * m;
  a.gains.kpm = a.gains.kps = 250.0 * k;
  a.gains.kdm = a.gains.kds = 1.2 * k;
  Vec n(3);
  n << 0.6, 0.0, 0.8;
  a.master_planes = {{n, 0.0, 800.0}};
  return a;
}

void BM_AxesIsotropicOneConfiguration(benchmark::State& state) {
  const TeleopAxesParams a = isotropic(HumanKind::kFixed);
  for (auto _ : state) benchmark::DoNotOptimize(analyze_axes(a));
}
BENCHMARK(BM_AxesIsotropicOneConfiguration)->Unit(benchmark::kMicrosecond);

// The isotropic loop with both planes tilted, orthogonal to each other (exactly: 0.6 * 0.8 -
// 0.8 * 0.6 = 0): analysed in the planes' frame axis by axis; `whole` = the 21-state model.
void BM_AxesIsotropicTiltedOneConfiguration(benchmark::State& state) {
  TeleopAxesParams a = isotropic(HumanKind::kFixed);
  Vec m(3);
  m << 0.6, 0.0, 0.8;
  Vec s(3);
  s << 0.8, 0.0, -0.6;
  a.master_planes[0].normal = m;
  a.slave_planes[0].normal = s;
  AxesAnalysisOptions o;
  o.decouple = state.range(0) == 0;
  for (auto _ : state) benchmark::DoNotOptimize(analyze_axes(a, o));
  state.SetLabel(o.decouple ? "planes' frame" : "whole");
}
BENCHMARK(BM_AxesIsotropicTiltedOneConfiguration)->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);

void BM_AxesCoupledOneConfiguration(benchmark::State& state) {
  const TeleopAxesParams a = coupled(HumanKind::kFixed);
  for (auto _ : state) benchmark::DoNotOptimize(analyze_axes(a));
}
BENCHMARK(BM_AxesCoupledOneConfiguration)->Unit(benchmark::kMicrosecond);

// 448 humans per axis; decoupled axis by axis, the worst over the product is exact.
void BM_AxesIsotropicBand(benchmark::State& state) {
  const TeleopAxesParams a = isotropic(HumanKind::kBand);
  for (auto _ : state) benchmark::DoNotOptimize(analyze_axes(a));
}
BENCHMARK(BM_AxesIsotropicBand)->Unit(benchmark::kMillisecond);

// Coupled: the 448 humans of the axes' grids walked together, then the refinement axis by axis.
void BM_AxesCoupledBand(benchmark::State& state) {
  const TeleopAxesParams a = coupled(HumanKind::kBand);
  std::size_t humans = 0;
  for (auto _ : state) {
    const AxesAnalysis r = analyze_axes(a);
    humans = r.humans_evaluated;
    benchmark::DoNotOptimize(r);
  }
  state.counters["humans"] = static_cast<double>(humans);
}
BENCHMARK(BM_AxesCoupledBand)->Unit(benchmark::kMillisecond);

// The same without the refinement: the 448 humans of the walked grids alone.
void BM_AxesCoupledBandWalkedOnly(benchmark::State& state) {
  const TeleopAxesParams a = coupled(HumanKind::kBand);
  AxesAnalysisOptions o;
  o.refine_walked_band = false;
  for (auto _ : state) benchmark::DoNotOptimize(analyze_axes(a, o));
}
BENCHMARK(BM_AxesCoupledBandWalkedOnly)->Unit(benchmark::kMillisecond);

// The exact limit of the tilted master plane, fixed human (coupled crossing search).
void BM_AxesCoupledPlaneLimit(benchmark::State& state) {
  const TeleopAxesParams a = coupled(HumanKind::kFixed);
  for (auto _ : state) benchmark::DoNotOptimize(plane_stiffness_limit(a, Side::kMaster, 0));
}
BENCHMARK(BM_AxesCoupledPlaneLimit)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
