// identify_axes (issue 18 "identify") on one minute of n-axis data at 1 kHz: the coupled mass
// with a diagonal or a full damping matrix. The data are a seeded random walk driven by random
// forces (the cost does not depend on the fit's quality).
#include <benchmark/benchmark.h>

#include <Eigen/Core>
#include <random>

#include "common/stability/identify_axes.hpp"

namespace {

using teleop::stability::DampingModel;
using teleop::stability::IdentifyAxesOptions;
using teleop::stability::SeriesAxes;

[[nodiscard]] SeriesAxes minute(Eigen::Index n) {
  constexpr Eigen::Index kSamples = 60000;
  std::mt19937_64 engine(1);
  std::normal_distribution<double> normal;
  SeriesAxes s;
  s.period_s = 1e-3;
  s.position_m.resize(kSamples, n);
  s.force_N.resize(kSamples, n);
  Eigen::VectorXd x = Eigen::VectorXd::Zero(n);
  Eigen::VectorXd v = Eigen::VectorXd::Zero(n);
  for (Eigen::Index k = 0; k < kSamples; ++k) {
    for (Eigen::Index i = 0; i < n; ++i) {
      v(i) = 0.99 * v(i) + 1e-3 * normal(engine);
      x(i) += v(i) * 1e-3;
      s.force_N(k, i) = normal(engine);
    }
    s.position_m.row(k) = x.transpose();
  }
  return s;
}

void BM_IdentifyAxesMinute(benchmark::State& state) {
  const std::vector<SeriesAxes> runs = {minute(state.range(0))};
  IdentifyAxesOptions o;
  o.damping = state.range(1) != 0 ? DampingModel::kFull : DampingModel::kDiagonal;
  for (auto _ : state) benchmark::DoNotOptimize(teleop::stability::identify_axes(runs, o));
}
BENCHMARK(BM_IdentifyAxesMinute)
    ->ArgsProduct({{1, 3, 6}, {0, 1}})
    ->ArgNames({"axes", "full_B"})
    ->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
