// Issue 15 "Done when": seeded random teleoperators (both sides, fixed and band humans, filter,
// force scaling, round trips of 0-20 samples, required damping ratio 0-0.3), the exact limit
// against the independent 50-digit reference (tests/unit/stability/campaign.hpp's RefLoop:
// the loop as a transfer-function polynomial of the paper's block diagram; Schur-Cohn for
// zeta = 0, Aberth-Ehrlich roots and their damping ratios otherwise), over every human:
//  - the reference is admissible at the engine's answer (never above), and the limit's crossing
//    is the reference's to 1e-8 (a defect otherwise; those off by 1e-9 to 1e-8 are counted), and
//  - a dense scan of the reference below the answer (x1.02 for zeta = 0, x1.1 otherwise, from
//    1e-3 N/m) finds no exit (the answer is the first crossing, never above a window);
//  - where the engine has no limit, the reference is not admissible just above zero.
// Prints one line per disagreement and a summary with run times against the old scan.
//
//   build/bench/bench_exact_limits [--cases N] [--seed S] [--case I]
#include <fmt/format.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "common/stability/human_grid.hpp"
#include "tests/unit/stability/campaign.hpp"

namespace {

using namespace teleop;
using namespace teleop::stability;
using campaign::Rng;

struct Case {
  TeleopParams p;
  Side side{Side::kSlave};
};

Case make_case(std::uint64_t seed, int index) {
  Rng rng(seed * 1000003ULL + static_cast<std::uint64_t>(index));
  Case c;
  TeleopParams& p = c.p;
  p.sample_rate_hz = rng.log_uniform(200.0, 5000.0);
  p.master_device = {rng.log_uniform(0.01, 0.5), rng.log_uniform(0.05, 5.0)};
  p.slave_device = {rng.log_uniform(0.01, 0.5), rng.log_uniform(0.05, 5.0)};
  p.gains.kpm = rng.log_uniform(20.0, 3000.0);
  p.gains.kps = rng.log_uniform(20.0, 3000.0);
  p.gains.kdm = rng.log_uniform(0.05, 8.0);
  p.gains.kds = rng.log_uniform(0.05, 8.0);
  p.scaling = {rng.uniform(0.5, 2.0), rng.chance(0.15) ? 0.0 : rng.uniform(0.5, 3.0)};
  p.velocity_cutoff_hz = rng.chance(0.5) ? 0.0 : rng.log_uniform(20.0, 0.4 * p.sample_rate_hz);
  p.round_trip_delay_samples = rng.integer(0, 20);
  p.analysis.required_damping_ratio = rng.chance(0.5) ? 0.0 : rng.uniform(0.0, 0.3);
  c.side = rng.chance(0.5) ? Side::kSlave : Side::kMaster;
  // The other side's fixture: none, or a modest one.
  if (rng.chance(0.3)) {
    (c.side == Side::kSlave ? p.master_fixture : p.slave_fixture).stiffness_N_per_m =
        rng.log_uniform(10.0, 500.0);
  }
  if (rng.chance(0.3)) {
    p.human.kind = HumanKind::kBand;
    p.human.band = default_human_band();
    p.human.band.points_per_axis = 2;
    p.human.band.force_levels_N = {1.0, 4.0};
  } else {
    p.human.kind = HumanKind::kFixed;
    p.human.fixed = {rng.log_uniform(0.005, 0.5), rng.log_uniform(0.5, 10.0),
                     rng.log_uniform(10.0, 1000.0)};
  }
  return c;
}

// The reference over every human of the case.
class BandReference {
 public:
  explicit BandReference(const Case& c) : c_(c) {
    const Structure structure =
        DiscreteModel(c.p, c.side == Side::kMaster, c.side == Side::kSlave).structure();
    const std::vector<HumanSample> humans = human_samples(c.p.human);
    for (const HumanSample& h : humans) {
      TeleopParams q = c.p;
      q.human.kind = HumanKind::kFixed;
      q.human.fixed = h.impedance;
      loops_.emplace_back(q, structure);
    }
  }
  [[nodiscard]] bool admissible(double k) const {
    const double zeta = c_.p.analysis.required_damping_ratio;
    const double other = c_.side == Side::kMaster ? c_.p.slave_fixture.stiffness_N_per_m
                                                  : c_.p.master_fixture.stiffness_N_per_m;
    for (const campaign::RefLoop& l : loops_) {
      const campaign::Poly q = c_.side == Side::kMaster ? l.reduced_polynomial(k, other)
                                                        : l.reduced_polynomial(other, k);
      if (zeta == 0.0 && q.size() <= 61) {
        if (!campaign::schur_stable(q)) return false;
        continue;
      }
      const campaign::RefSpectrum s = campaign::analyse_roots(reference::roots(q));
      if (!(s.radius_margin > 0.0 && s.min_damping_ratio >= zeta)) return false;
    }
    return true;
  }
  [[nodiscard]] std::size_t humans() const { return loops_.size(); }

 private:
  Case c_;
  std::vector<campaign::RefLoop> loops_;
};

struct Outcome {
  bool compared{false};
  bool no_limit{false};
  std::string defect{};
  double engine_ms{0.0};
  double scan_ms{0.0};
  bool scan_above{false};  // the old scan's answer lies above the exact one by > 1e-6
  double step_down{0.0};   // (crossing - limit) / crossing
  bool beyond_1e9{false};  // the crossing within 1e-8 of the reference's but not 1e-9
};

Outcome run(std::uint64_t seed, int index) {
  const Case c = make_case(seed, index);
  Outcome o;
  const auto t0 = std::chrono::steady_clock::now();
  const StiffnessLimit l = max_stable_stiffness(c.p, c.side);
  const auto t1 = std::chrono::steady_clock::now();
  const StiffnessLimit s = max_stable_stiffness_scan(c.p, c.side);
  const auto t2 = std::chrono::steady_clock::now();
  o.engine_ms = std::chrono::duration<double, std::milli>(t1 - t0).count();
  o.scan_ms = std::chrono::duration<double, std::milli>(t2 - t1).count();
  const BandReference ref(c);
  const double zeta = c.p.analysis.required_damping_ratio;
  if (!l.max_stable_stiffness_N_per_m) {
    o.no_limit = true;
    if (l.reason.find("every stiffness up to") != std::string::npos) return o;  // none to cap
    if (l.reason.find("marginal") != std::string::npos) return o;
    if (ref.admissible(1e-6))
      o.defect = "engine: no limit (" + l.reason + "); reference admissible at 1e-6";
    return o;
  }
  o.compared = true;
  const double k = *l.max_stable_stiffness_N_per_m;
  if (s.max_stable_stiffness_N_per_m && *s.max_stable_stiffness_N_per_m > k * (1 + 1e-6)) {
    o.scan_above = true;
  }
  const double crossing = l.limit_crossing_N_per_m.value_or(k);
  o.step_down = (crossing - k) / crossing;
  if (!ref.admissible(k)) {
    o.defect = fmt::format("reference not admissible at the engine's {:.10g} N/m", k);
  } else if (!ref.admissible(crossing * (1 - 1e-8)) || ref.admissible(crossing * (1 + 1e-8))) {
    o.defect =
        fmt::format("the limit's crossing {:.10g} N/m is not the reference's to 1e-8", crossing);
  } else {
    // Within 1e-9 (the bar), or between 1e-9 and 1e-8 (the model's own rounding).
    o.beyond_1e9 = !ref.admissible(crossing * (1 - 1e-9)) || ref.admissible(crossing * (1 + 1e-9));
    const double growth = zeta == 0.0 ? 1.02 : 1.1;
    for (double x = 1e-3; x < k; x *= growth) {
      if (!ref.admissible(x)) {
        o.defect = fmt::format(
            "reference leaves the region at {:.6g} N/m, below the engine's {:.10g}", x, k);
        break;
      }
    }
  }
  return o;
}

}  // namespace

int main(int argc, char** argv) {
  int cases = 200;
  std::uint64_t seed = 15;
  int only = -1;
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--cases") == 0 && i + 1 < argc) cases = std::atoi(argv[++i]);
    if (std::strcmp(argv[i], "--seed") == 0 && i + 1 < argc)
      seed = std::strtoull(argv[++i], nullptr, 10);
    if (std::strcmp(argv[i], "--case") == 0 && i + 1 < argc) only = std::atoi(argv[++i]);
  }
  std::vector<Outcome> out(static_cast<std::size_t>(std::max(cases, only + 1)));
  std::atomic<int> next{only >= 0 ? only : 0};
  const int end = only >= 0 ? only + 1 : cases;
  std::mutex print;
  auto work = [&] {
    for (int i = next++; i < end; i = next++) {
      const Outcome o = run(seed, i);
      out[static_cast<std::size_t>(i)] = o;
      if (!o.defect.empty()) {
        const std::lock_guard<std::mutex> lock(print);
        const Case c = make_case(seed, i);
        fmt::print("DEFECT case {} ({} side, zeta {:.3f}, delay {}, {} human): {}\n", i,
                   c.side == Side::kSlave ? "slave" : "master", c.p.analysis.required_damping_ratio,
                   c.p.round_trip_delay_samples,
                   c.p.human.kind == HumanKind::kBand ? "band" : "fixed", o.defect);
      }
    }
  };
  std::vector<std::thread> pool;
  for (unsigned t = 1; t < std::max(1U, std::thread::hardware_concurrency()); ++t)
    pool.emplace_back(work);
  work();
  for (std::thread& t : pool) t.join();
  int compared = 0, none = 0, defects = 0, scan_above = 0, beyond_1e9 = 0;
  double engine_ms = 0.0, scan_ms = 0.0, step_down = 0.0;
  for (int i = (only >= 0 ? only : 0); i < end; ++i) {
    const Outcome& o = out[static_cast<std::size_t>(i)];
    compared += o.compared ? 1 : 0;
    none += o.no_limit ? 1 : 0;
    defects += o.defect.empty() ? 0 : 1;
    scan_above += o.scan_above ? 1 : 0;
    beyond_1e9 += o.beyond_1e9 ? 1 : 0;
    engine_ms += o.engine_ms;
    scan_ms += o.scan_ms;
    step_down = std::max(step_down, o.step_down);
  }
  const int n = end - (only >= 0 ? only : 0);
  fmt::print(
      "{} cases (seed {}): {} limits compared with the reference, {} without a limit; defects {} "
      "(a limit above the reference's first exit, or a crossing off by more than 1e-8); "
      "crossings off by 1e-9 to 1e-8: {}; the old scan above the exact limit in {} cases; largest "
      "step below the crossing {:.2g} (relative); mean run time exact {:.2f} ms, scan {:.2f} ms "
      "(two cases at a time)\n",
      n, seed, compared, none, defects, beyond_1e9, scan_above, step_down, engine_ms / n,
      scan_ms / n);
  return defects == 0 ? 0 : 1;
}
