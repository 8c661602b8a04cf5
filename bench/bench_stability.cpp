// Speed of the stability engine (issue targets on a 2-core machine: one configuration <= 10 us,
// the 448-human band <= 5 ms, a maximum-stiffness search over that band <= 50 ms).
#include <benchmark/benchmark.h>

#include "common/stability/analyzer.hpp"
#include "common/stability/stiffness_search.hpp"

namespace {

using namespace teleop;
using namespace teleop::stability;

TeleopParams paddles(HumanKind human) {
  TeleopParams p;
  p.sample_rate_hz = 500.0;
  p.master_device = {0.040, 0.41};
  p.slave_device = {0.036, 0.49};
  p.gains = {600.0, 600.0, 2.0, 2.0, 0.0, 0.0, 0.0};
  p.velocity_cutoff_hz = 200.0;
  p.slave_fixture.stiffness_N_per_m = 1500.0;
  p.human.kind = human;
  p.human.fixed = {0.010, 2.0, 300.0};
  p.human.band = default_human_band();
  return p;
}

// One configuration, one human: model, eigenvalues with error bounds, damping ratios.
void BM_AnalyzeOneConfiguration(benchmark::State& state) {
  const TeleopParams p = paddles(HumanKind::kFixed);
  for (auto _ : state) benchmark::DoNotOptimize(analyze(p));
}
BENCHMARK(BM_AnalyzeOneConfiguration)->Unit(benchmark::kMicrosecond);

// The same, reusing the discretised plants (what a sweep pays per human).
void BM_SpectrumOneHuman(benchmark::State& state) {
  const TeleopParams p = paddles(HumanKind::kFixed);
  const LoopEvaluator ev(p);
  for (auto _ : state) benchmark::DoNotOptimize(ev.spectrum(0, 0.0, 1500.0, false));
}
BENCHMARK(BM_SpectrumOneHuman)->Unit(benchmark::kMicrosecond);

// The default 448-human band, worst case at the configured stiffness.
void BM_BandSweep448(benchmark::State& state) {
  const TeleopParams p = paddles(HumanKind::kBand);
  for (auto _ : state) benchmark::DoNotOptimize(analyze(p));
}
BENCHMARK(BM_BandSweep448)->Unit(benchmark::kMillisecond);

void BM_MaxStiffnessSlaveBand448(benchmark::State& state) {
  const TeleopParams p = paddles(HumanKind::kBand);
  for (auto _ : state) benchmark::DoNotOptimize(max_stable_stiffness(p, Side::kSlave));
}
BENCHMARK(BM_MaxStiffnessSlaveBand448)->Unit(benchmark::kMillisecond);

void BM_MaxStiffnessMasterBand448(benchmark::State& state) {
  TeleopParams p = paddles(HumanKind::kBand);
  p.slave_fixture.stiffness_N_per_m = 0.0;
  for (auto _ : state) benchmark::DoNotOptimize(max_stable_stiffness(p, Side::kMaster));
}
BENCHMARK(BM_MaxStiffnessMasterBand448)->Unit(benchmark::kMillisecond);

// The old scan (x1.2, bisection, verified halvings) on the same band, for comparison.
void BM_MaxStiffnessSlaveBand448Scan(benchmark::State& state) {
  const TeleopParams p = paddles(HumanKind::kBand);
  for (auto _ : state) benchmark::DoNotOptimize(max_stable_stiffness_scan(p, Side::kSlave));
}
BENCHMARK(BM_MaxStiffnessSlaveBand448Scan)->Unit(benchmark::kMillisecond);

// Issue 15: the band at 1 kHz (the 3 ms target) and a 200-sample round trip.
void BM_MaxStiffnessSlaveBand448At1kHz(benchmark::State& state) {
  TeleopParams p = paddles(HumanKind::kBand);
  p.sample_rate_hz = 1000.0;
  for (auto _ : state) benchmark::DoNotOptimize(max_stable_stiffness(p, Side::kSlave));
}
BENCHMARK(BM_MaxStiffnessSlaveBand448At1kHz)->Unit(benchmark::kMillisecond);

void BM_MaxStiffnessSlaveBand448RoundTrip200(benchmark::State& state) {
  TeleopParams p = paddles(HumanKind::kBand);
  p.sample_rate_hz = 1000.0;
  p.master_device = {0.04, 2.0};
  p.slave_device = {0.036, 2.0};
  p.gains = {20.0, 20.0, 1.0, 1.0, 0.0, 0.0, 0.0};
  p.velocity_cutoff_hz = 0.0;
  p.round_trip_delay_samples = 200;
  for (auto _ : state) benchmark::DoNotOptimize(max_stable_stiffness(p, Side::kSlave));
}
BENCHMARK(BM_MaxStiffnessSlaveBand448RoundTrip200)->Unit(benchmark::kMillisecond)->Iterations(1);

}  // namespace

BENCHMARK_MAIN();
