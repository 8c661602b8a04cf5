// Run time against error for the plant's stepping methods (issue 3, "Proof"): contact and
// friction scenes - a slave paddle driven by a sampled PD (held per period, as a controller
// would) along x_d(t) that pushes 1 cm past a surface and back - stepped with event location and
// with N = 1..32 frozen-mode sub-steps, against an independent fine RK4 reference
// (tests/unit/sim/reference_plant.hpp, 4000 steps per period, long double, switches bisected).
// Prints the error table with nanoseconds per simulated millisecond, then the Google Benchmark
// timings of the same loops.
//
//   build/bench/bench_plant [--no-table] [benchmark flags]
#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <numbers>
#include <vector>

#include "common/sim/plant.hpp"
#include "tests/unit/sim/reference_plant.hpp"

namespace {

using namespace teleop;
using namespace teleop::sim;

constexpr double kPeriodS = 1e-3;
constexpr int kScenePeriods = 1000;  // 1 s

struct Scene {
  const char* name;
  PlantParams params;
  double kp_N_per_m;
  double kd_Ns_per_m;
  double centre_m;  // x_d = centre + amplitude sin(2 pi 1.5 t): surface at centre + amplitude/2
  double amplitude_m;
};

std::vector<Scene> scenes() {
  PlantParams paddle;
  paddle.device = {0.036, 0.49};
  paddle.coulomb_friction_N = 0.05;
  PlantParams vp;
  vp.device = {0.25, 5.0};
  vp.coulomb_friction_N = 0.2;
  std::vector<Scene> s;
  s.push_back({"tissue 2 kN/m", paddle, 300.0, 3.0, 0.02, 0.02});
  s.back().params.environment = Environment::tissue(2000.0, 2.0, 0.03);
  s.push_back({"VP tissue 125 N/m", vp, 500.0, 10.0, 0.02, 0.02});
  s.back().params.environment = Environment::tissue(125.0, 0.0, 0.03);
  s.push_back({"stiff wall 1e5 N/m", paddle, 300.0, 3.0, 0.02, 0.02});
  s.back().params.environment = Environment::tissue(1e5, 20.0, 0.03);
  s.push_back({"rigid wall", paddle, 300.0, 3.0, 0.02, 0.02});
  s.back().params.environment = Environment::rigid_wall(0.03);
  return s;
}

double desired_m(const Scene& s, int n) {
  return s.centre_m + s.amplitude_m * std::sin(2.0 * std::numbers::pi * 1.5 * n * kPeriodS);
}

struct Method {
  SteppingMethod method;
  int substeps;
};

std::vector<Method> methods() {
  std::vector<Method> m;
  for (const int n : {1, 2, 4, 8, 16, 32}) m.push_back({SteppingMethod::kSubSteps, n});
  m.push_back({SteppingMethod::kEventLocation, 1});
  return m;
}

PlantParams with(PlantParams p, const Method& m) {
  p.method = m.method;
  p.substeps = m.substeps;
  return p;
}

struct Trace {
  std::vector<double> x;
  std::vector<double> f;  // force on the environment
};

double command(const Scene& s, int n, double x, double v) {
  return s.kp_N_per_m * (desired_m(s, n) - x) - s.kd_Ns_per_m * v;
}

Trace reference_trace(const Scene& s) {
  reference::ReferencePlant ref(s.params, kPeriodS, 4000);
  Trace t;
  const Environment& env = s.params.environment;
  for (int n = 0; n < kScenePeriods; ++n) {
    const auto x = static_cast<double>(ref.x());
    const auto v = static_cast<double>(ref.v());
    const double u = command(s, n, x, v);
    ref.step(u);
    const auto xr = static_cast<double>(ref.x());
    const auto vr = static_cast<double>(ref.v());
    t.x.push_back(xr);
    double f = 0.0;
    if (env.kind == EnvironmentKind::kTissue && xr > env.position_m) {
      f = std::max(0.0, env.stiffness_N_per_m * (xr - env.position_m) + env.damping_Ns_per_m * vr);
    } else if (env.kind == EnvironmentKind::kRigidWall && xr >= env.position_m && vr == 0.0) {
      f = std::max(0.0, command(s, n, x, v));  // resting on the wall: it takes the push
    }
    t.f.push_back(f);
  }
  return t;
}

struct Result {
  double x_error_m{0.0};
  double f_error_N{0.0};
  double ns_per_ms{0.0};
};

Result measure(const Scene& s, const Method& m, const Trace& ref) {
  Result r;
  Plant plant(with(s.params, m), std::chrono::milliseconds(1));
  for (int n = 0; n < kScenePeriods; ++n) {
    const PlantState& st = plant.state();
    const PlantOutput& out = plant.step(command(s, n, st.position_m, st.velocity_m_per_s));
    const auto i = static_cast<std::size_t>(n);
    r.x_error_m = std::max(r.x_error_m, std::abs(plant.state().position_m - ref.x[i]));
    r.f_error_N = std::max(r.f_error_N, std::abs(out.environment_force_N - ref.f[i]));
  }
  // Timing: the same closed loop, repeated, best of 5.
  double best = 1e300;
  for (int rep = 0; rep < 5; ++rep) {
    Plant p(with(s.params, m), std::chrono::milliseconds(1));
    double sink = 0.0;
    const auto t0 = std::chrono::steady_clock::now();
    for (int n = 0; n < kScenePeriods; ++n) {
      const PlantState& st = p.state();
      sink += p.step(command(s, n, st.position_m, st.velocity_m_per_s)).environment_force_N;
    }
    const auto t1 = std::chrono::steady_clock::now();
    benchmark::DoNotOptimize(sink);
    best = std::min(best, std::chrono::duration<double, std::nano>(t1 - t0).count());
  }
  r.ns_per_ms = best / kScenePeriods;
  return r;
}

void print_table() {
  const std::vector<Scene> all = scenes();
  std::printf(
      "Plant stepping: max |x - x_ref| (m) / max |F_e - F_e,ref| (N) over 1 s, and ns per\n"
      "simulated ms (1 kHz, closed-loop PD, friction on; reference: RK4 4000 steps/period)\n\n");
  std::printf("| method |");
  for (const Scene& s : all) std::printf(" %s: x err | F err | ns/ms |", s.name);
  std::printf("\n|---|");
  for (std::size_t i = 0; i < all.size(); ++i) std::printf("---|---|---|");
  std::printf("\n");
  std::vector<Trace> refs;
  for (const Scene& s : all) refs.push_back(reference_trace(s));
  for (const Method& m : methods()) {
    if (m.method == SteppingMethod::kEventLocation) {
      std::printf("| event location |");
    } else {
      std::printf("| substeps %d |", m.substeps);
    }
    for (std::size_t i = 0; i < all.size(); ++i) {
      const Result r = measure(all[i], m, refs[i]);
      std::printf(" %.1e | %.1e | %.0f |", r.x_error_m, r.f_error_N, r.ns_per_ms);
    }
    std::printf("\n");
  }
  std::printf("\n");
}

// One benchmark iteration = one simulated millisecond of the scene's closed loop.
void BM_PlantScene(benchmark::State& state) {
  const std::vector<Scene> all = scenes();
  const Scene& s = all[static_cast<std::size_t>(state.range(0))];
  const int n_sub = static_cast<int>(state.range(1));
  const Method m = n_sub == 0 ? Method{SteppingMethod::kEventLocation, 1}
                              : Method{SteppingMethod::kSubSteps, n_sub};
  Plant plant(with(s.params, m), std::chrono::milliseconds(1));
  int n = 0;
  for (auto _ : state) {
    const PlantState& st = plant.state();
    benchmark::DoNotOptimize(plant.step(command(s, n, st.position_m, st.velocity_m_per_s)));
    if (++n == kScenePeriods) {
      n = 0;
      plant.reset({});
    }
  }
  state.SetLabel(std::string(s.name) +
                 (n_sub == 0 ? ", event location" : ", substeps " + std::to_string(n_sub)));
}

void scene_args(benchmark::internal::Benchmark* b) {
  for (int scene = 0; scene < 4; ++scene) {
    for (const int n : {0, 1, 2, 4, 8, 16, 32}) b->Args({scene, n});
  }
}
BENCHMARK(BM_PlantScene)->Apply(scene_args);

// The cheapest case, for the real-time-factor budget: free space, event location.
void BM_PlantFreeStep(benchmark::State& state) {
  PlantParams p;
  p.device = {0.040, 0.41};
  p.human = {0.008, 1.5, 250.0};
  Plant plant(p, std::chrono::milliseconds(1));
  double u = 0.0;
  for (auto _ : state) {
    u = -u + 0.1;
    benchmark::DoNotOptimize(plant.step(u, 1.0));
  }
}
BENCHMARK(BM_PlantFreeStep);

}  // namespace

int main(int argc, char** argv) {
  bool table = true;
  std::vector<char*> args;
  for (int i = 0; i < argc; ++i) {
    if (std::strcmp(argv[i], "--no-table") == 0) {
      table = false;
    } else {
      args.push_back(argv[i]);
    }
  }
  if (table) print_table();
  int n = static_cast<int>(args.size());
  benchmark::Initialize(&n, args.data());
  if (benchmark::ReportUnrecognizedArguments(n, args.data())) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
