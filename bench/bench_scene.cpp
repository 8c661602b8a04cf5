// Real-time factor of the lockstep simulator (issue target: the bilateral scene without output
// at least 1000x real time on one core, an hour of 1 kHz teleoperation in under 3.6 s).
// The counter `realtime_factor` is simulated seconds per wall-clock second.
#include <benchmark/benchmark.h>

#include "common/scene/lockstep.hpp"

namespace {

using namespace teleop;

scene::SceneSetup bilateral_scene(bool ideal) {
  scene::SceneSetup s;
  s.duration_s = 10.0;
  s.ideal = ideal;
  s.output_rate_hz = 1.0;  // "without output": one row a second
  TeleopParams& p = s.teleop;
  p.sample_rate_hz = 1000.0;
  p.master_device = {0.040, 0.41};
  p.slave_device = {0.036, 0.49};
  p.gains = {600.0, 600.0, 2.0, 2.0, 0.0, 0.0, 0.0};
  p.velocity_cutoff_hz = 200.0;
  p.slave_fixture = {1500.0, 0.005};
  p.human.kind = HumanKind::kFixed;
  p.human.fixed = {0.012, 0.76, 70.0};
  s.law = control::from_teleop_params(p);
  s.master.plant.device = p.master_device;
  s.slave.plant.device = p.slave_device;
  sim::HumanParams h;
  h.profile = sim::ForceProfile::ramp(0.0, 2.0, 0.2, 0.5);
  h.impedance = p.human.fixed;
  s.master.human = h;
  s.master.quantize_position = !ideal;
  s.slave.quantize_position = !ideal;
  return s;
}

void BM_BilateralScene(benchmark::State& state) {
  const scene::SceneSetup s = bilateral_scene(state.range(0) == 1);
  double simulated = 0.0;
  for (auto _ : state) {
    const scene::SimulationResult r = scene::simulate(s);
    benchmark::DoNotOptimize(r.summary.oscillation.amplitude_m);
    simulated += r.summary.duration_s;
  }
  state.counters["realtime_factor"] = benchmark::Counter(simulated, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_BilateralScene)->Arg(1)->Arg(0)->ArgName("ideal")->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
