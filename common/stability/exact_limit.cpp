// The exact maximum fixture stiffness (docs/stability-limits.md): crossings of the admissible
// boundary per human, every interval between them confirmed with one spectrum.
#include <fmt/format.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <mutex>
#include <thread>

#include "common/stability/analyzer.hpp"
#include "common/stability/crossings.hpp"
#include "common/stability/stiffness_search.hpp"

namespace teleop::stability {

namespace {

// Above this order a spectrum costs more than counting modes along the boundary.
constexpr int kSpectrumOrderLimit = 24;
// The answer is the crossing, rounded down by this much so that it never lies above the true
// value (the crossings agree with a 50-digit reference to about 1e-13 relative).
constexpr double kRoundDown = 1e-11;

struct HumanOutcome {
  double limit{std::numeric_limits<double>::infinity()};  // infinity: passes up to the cap
  bool uncertain{false};
  bool fallback{false};
  long spectra{0};
  long boundary_points{0};
  long crossings{0};
};

class ExactSearch {
 public:
  ExactSearch(const TeleopParams& params, Side side, const LoopEvaluator& ev, double other,
              double cap)
      : p_(params), side_(side), ev_(ev), other_(other), cap_(cap) {}

  [[nodiscard]] double kmvf(double k) const { return side_ == Side::kMaster ? k : other_; }
  [[nodiscard]] double ksvf(double k) const { return side_ == Side::kSlave ? k : other_; }

  // The block the stiffness enters, for one human, as a rank-one loop.
  [[nodiscard]] RankOneLoop loop(std::size_t human) const {
    const ZohPlant plant = ev_.model().master_plant(ev_.human(human).impedance);
    const std::vector<ModelBlock> at_zero = ev_.model().build(plant, kmvf(0.0), ksvf(0.0));
    const std::vector<ModelBlock> at_one = ev_.model().build(plant, kmvf(1.0), ksvf(1.0));
    for (std::size_t b = 0; b < at_zero.size(); ++b) {
      const int position =
          side_ == Side::kMaster ? at_zero[b].master_position : at_zero[b].slave_position;
      if (position >= 0) return RankOneLoop(at_zero[b], at_one[b], position);
    }
    throw std::invalid_argument("the searched fixture is in no block of the loop");
  }

  // Whether stiffness k meets the requirement for this human; counts its cost.
  bool admissible(std::size_t human, const RankOneLoop& loop, double k, HumanOutcome& o) const {
    const double required = p_.analysis.required_damping_ratio;
    if (loop.order() <= kSpectrumOrderLimit) {
      ++o.spectra;
      const Spectrum s = ev_.spectrum(human, kmvf(k), ksvf(k), false);
      return s.verdict == Verdict::kStable && s.min_damping_ratio >= required;
    }
    // The other blocks do not depend on k and met the requirement at the lower end.
    return loop.modes_outside(k, required, &o.boundary_points) == 0;
  }

  // The first stiffness above `lo` (known admissible) that fails for this human, given that
  // none below `best` matters.
  HumanOutcome human_limit(std::size_t human, double lo, double best) const {
    HumanOutcome o;
    const RankOneLoop l = loop(human);
    const CrossingSearch found = l.crossings(p_.analysis.required_damping_ratio, cap_);
    o.boundary_points += found.boundary_points;
    o.crossings = static_cast<long>(found.crossings.size());
    std::vector<Crossing> cs;
    for (const Crossing& c : found.crossings) {
      if (c.stiffness_N_per_m > lo * (1.0 + 1e-12)) cs.push_back(c);
    }
    // Interval j runs from edge(j) to edge(j + 1): lo, the crossings, the cap.
    auto edge = [&](std::size_t j) { return j == 0 ? lo : cs[j - 1].stiffness_N_per_m; };
    for (std::size_t j = 0; j <= cs.size(); ++j) {
      const double from = edge(j);
      if (from > best) return o;  // this human cannot lower the answer
      const double to = j < cs.size() ? cs[j].stiffness_N_per_m : cap_;
      // One spectrum inside the interval (just above the last crossing for the open end).
      const double probe = j < cs.size() ? 0.5 * (from + to) : std::min(cap_, from * 1.001 + 1e-9);
      if (admissible(human, l, probe, o)) continue;
      if (j == 0) {
        // No crossing found below a failing stiffness: one was missed. Find it by scan.
        o.fallback = true;
        o.limit = scan(human, l, lo, probe, o);
        return o;
      }
      o.limit = from;
      o.uncertain = cs[j - 1].near_double;
      return o;
    }
    // The last interval runs to the cap: it must pass there too, else a crossing was missed.
    if (!admissible(human, l, cap_, o)) {
      o.fallback = true;
      o.limit = scan(human, l, edge(cs.size()), cap_, o);
    }
    return o;
  }

  // The old way inside one interval: geometric scan, then bisection to the tolerance.
  double scan(std::size_t human, const RankOneLoop& l, double lo, double fail,
              HumanOutcome& o) const {
    const double tol = p_.analysis.stiffness_tolerance_N_per_m;
    double pass = lo;
    for (double k = std::max(lo * 1.01, lo + tol); k < fail; k *= 1.01) {
      if (!admissible(human, l, k, o)) {
        fail = k;
        break;
      }
      pass = k;
    }
    while (fail - pass > tol) {
      const double mid = 0.5 * (pass + fail);
      if (mid <= pass || mid >= fail) break;
      (admissible(human, l, mid, o) ? pass : fail) = mid;
    }
    return pass;
  }

 private:
  const TeleopParams& p_;
  Side side_;
  const LoopEvaluator& ev_;
  double other_;
  double cap_;
};

// Every mode inside the admissible region by more than its error bound: the disc of that
// radius about it stays inside (checked at its four extreme points for the damping ratio).
bool certainly_admissible(const Spectrum& s, double required) {
  if (s.verdict != Verdict::kStable) return false;
  for (const Mode& m : s.modes) {
    if (m.structural) continue;
    if (!(m.abs_z + m.error < 1.0)) return false;
    if (required > 0.0) {
      for (const std::complex<double> d :
           {std::complex<double>(m.error, 0.0), std::complex<double>(-m.error, 0.0),
            std::complex<double>(0.0, m.error), std::complex<double>(0.0, -m.error)}) {
        if (!(damping_ratio(m.z + d) >= required)) return false;
      }
    }
  }
  return true;
}

std::string failure_reason(const BandResult& r, double required, Side side, double other) {
  const char* name = side == Side::kMaster ? "master" : "slave";
  const std::string with_other =
      other == 0.0 ? std::string("no fixture at all")
                   : fmt::format("no {} fixture (the {} fixture at {:g} N/m as configured)", name,
                                 side == Side::kMaster ? "slave" : "master", other);
  if (r.verdict == Verdict::kInvalid) {
    return fmt::format("invalid model with {}: {}", with_other, r.invalid_reason);
  }
  if (r.verdict == Verdict::kUnstable) {
    return fmt::format("unstable with {} (minimum damping ratio {:.4g})", with_other,
                       r.min_damping_ratio);
  }
  if (r.verdict == Verdict::kUncertain) {
    return fmt::format(
        "marginal with {}: an eigenvalue lies on the unit circle within the numerical error",
        with_other);
  }
  return fmt::format(
      "with {} the minimum damping ratio {:.4g} is already below the required {:.4g}", with_other,
      r.min_damping_ratio, required);
}

}  // namespace

StiffnessLimit max_stable_stiffness(const TeleopParams& params, Side side,
                                    const SearchOptions& options) {
  const LoopEvaluator ev(params, side == Side::kMaster, side == Side::kSlave);
  const double other = side == Side::kMaster ? params.slave_fixture.stiffness_N_per_m
                                             : params.master_fixture.stiffness_N_per_m;
  const double required = params.analysis.required_damping_ratio;
  const double tol = params.analysis.stiffness_tolerance_N_per_m;
  const double cap = options.max_stiffness_N_per_m;
  StiffnessLimit out;
  out.other_fixture_N_per_m = other;
  if (side == Side::kMaster) {
    out.passivity_limit_N_per_m = master_passivity_limit(params);
    if (!out.passivity_limit_N_per_m) {
      out.passivity_reason =
          "not passive at any stiffness: the master's virtual damping |beta kdm + kvm| is not "
          "below its device damping b";
    }
  }
  auto sweep = [&](double k) {
    ++out.band_verifications;
    return ev.sweep(side == Side::kMaster ? k : other, side == Side::kSlave ? k : other, required);
  };

  // The lower end, as the search always had it: the whole band at K = 0 (every block, the
  // ones the stiffness does not enter included); a rigid-body mode at z = 1 exactly at K = 0
  // moves the lower end to the tolerance.
  BandResult lo_band = sweep(0.0);
  double k_lo = 0.0;
  if (!meets_requirement(lo_band, required)) {
    const BandResult tiny =
        lo_band.verdict == Verdict::kUncertain ? sweep(tol) : BandResult{Verdict::kUnstable};
    if (lo_band.verdict == Verdict::kUncertain && meets_requirement(tiny, required)) {
      k_lo = tol;
      out.reason = "marginal rigid-body mode at zero stiffness; limit taken over (0, K]";
    } else {
      out.reason = failure_reason(lo_band, required, side, other);
      out.invalid = lo_band.verdict == Verdict::kInvalid;
      if (ev.human_matters()) out.worst_human = ev.human(lo_band.failing_index.value_or(0));
      return out;
    }
  }

  const ExactSearch search(params, side, ev, other, cap);
  // The stiffness enters a block without the master (slave alone, or the decoupled slave):
  // the human does not change it, one loop serves the band.
  bool human_free = !ev.human_matters();
  {
    const ZohPlant plant = ev.model().master_plant(ev.human(0).impedance);
    for (const ModelBlock& b : ev.model().build(plant, 0.0, 0.0)) {
      const int position = side == Side::kMaster ? b.master_position : b.slave_position;
      if (position >= 0 && !b.includes_master) human_free = true;
    }
  }
  const std::size_t humans = human_free ? 1 : ev.human_count();
  std::vector<HumanOutcome> outcomes(humans);
  std::atomic<double> best{std::numeric_limits<double>::infinity()};
  std::atomic<std::size_t> next{0};
  std::mutex error_mutex;
  std::string error;
  auto work = [&] {
    for (std::size_t i = next++; i < humans; i = next++) {
      try {
        outcomes[i] = search.human_limit(i, k_lo, best.load());
      } catch (const std::exception& e) {
        const std::lock_guard<std::mutex> lock(error_mutex);
        error = e.what();
        return;
      }
      double seen = best.load();
      while (outcomes[i].limit < seen && !best.compare_exchange_weak(seen, outcomes[i].limit)) {
      }
    }
  };
  const unsigned threads =
      humans < 16 ? 1U : std::clamp(std::thread::hardware_concurrency(), 1U, 8U);
  std::vector<std::thread> pool;
  for (unsigned t = 1; t < threads; ++t) pool.emplace_back(work);
  work();
  for (std::thread& t : pool) t.join();
  if (!error.empty()) {
    // Not a rank-one loop (cannot happen with this model): the scan answers instead.
    StiffnessLimit scanned = max_stable_stiffness_scan(params, side, options);
    scanned.reason = (scanned.reason.empty() ? "" : scanned.reason + "; ") +
                     "exact crossings unavailable (" + error + "), scanned instead";
    return scanned;
  }
  std::size_t worst = 0;
  for (std::size_t i = 0; i < humans; ++i) {
    const HumanOutcome& o = outcomes[i];
    out.evaluations += o.spectra;
    out.boundary_points += o.boundary_points;
    out.crossings_found += o.crossings;
    out.fallbacks += o.fallback ? 1 : 0;
    if (o.limit < outcomes[worst].limit) worst = i;
  }
  const HumanOutcome& w = outcomes[worst];
  if (ev.human_matters()) out.worst_human = ev.human(worst);
  if (!std::isfinite(w.limit)) {
    out.reason = fmt::format("meets the requirement for every stiffness up to {:g} N/m", cap);
    return out;
  }
  // The crossing comes from the double-precision model, whose entries carry rounding (at high
  // rates phi - I holds few digits): step down from it until a spectrum with error bounds
  // shows every mode inside the region by more than its bound.
  double answer = w.limit * (1.0 - kRoundDown);
  bool certain = false;
  if (search.loop(worst).order() <= kSpectrumOrderLimit) {
    for (int i = 0; i < 12 && answer > k_lo; ++i) {
      ++out.evaluations;
      const double k = answer;
      const Spectrum s = ev.spectrum(worst, side == Side::kMaster ? k : other,
                                     side == Side::kSlave ? k : other, true);
      if (certainly_admissible(s, required)) {
        certain = true;
        break;
      }
      answer = w.limit * (1.0 - kRoundDown * std::pow(8.0, i + 1));
    }
  } else {
    certain = true;  // counted along the boundary: no per-mode bound to step by
  }
  out.max_stable_stiffness_N_per_m = std::max(k_lo, answer);
  out.uncertain = w.uncertain || !certain;
  if (w.uncertain) {
    out.reason = "a mode touches the boundary at the limit within the numerical error";
  }
  return out;
}

}  // namespace teleop::stability
