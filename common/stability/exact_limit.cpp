// The exact maximum fixture stiffness (docs/stability-limits.md): crossings of the admissible
// boundary per human, every interval between them confirmed with one spectrum.
#include <fmt/format.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <exception>
#include <limits>
#include <mutex>
#include <optional>
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
constexpr double kMaxStepDown = 1e-6;

struct HumanOutcome {
  double limit{std::numeric_limits<double>::infinity()};  // infinity: passes up to the cap
  bool uncertain{false};
  bool fallback{false};
  long spectra{0};
  long boundary_points{0};
  long crossings{0};
};

// One human's loop and its crossings, found once.
struct HumanCrossings {
  std::optional<RankOneLoop> loop{};
  CrossingSearch search{};
  int outside_at_zero{-1};  // modes outside the region at K = 0 (-1: on the boundary)
  long spectra{0};
};

class ExactSearch {
 public:
  ExactSearch(const SideSearch& search, double cap)
      : p_(search.params),
        side_(search.side),
        ev_(search.ev),
        other_(search.other_N_per_m),
        cap_(cap) {}

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

  [[nodiscard]] HumanCrossings crossings(std::size_t human) const {
    HumanCrossings h;
    h.loop.emplace(loop(human));
    h.search = h.loop->crossings(p_.analysis.required_damping_ratio, cap_);
    if (h.loop->order() <= kSpectrumOrderLimit) {
      // The lower end by this human's spectrum: 0 meets the requirement, 1 fails it, -1 within
      // the error of the boundary (a rigid-body mode at z = 1) or not finite.
      const Spectrum s = ev_.spectrum(human, kmvf(0.0), ksvf(0.0), false);
      h.spectra = 1;
      h.outside_at_zero = s.verdict == Verdict::kStable
                              ? (s.min_damping_ratio >= p_.analysis.required_damping_ratio ? 0 : 1)
                          : s.verdict == Verdict::kUnstable ? 1
                                                            : -1;
    } else {
      h.outside_at_zero = h.loop->modes_outside(h.search, 0.0, &h.search.boundary_points);
    }
    return h;
  }

  // Whether stiffness k meets the requirement for this human: by one spectrum, or by counting
  // the modes outside the region along the boundary (the other blocks do not depend on k and
  // met the requirement at the lower end).
  bool admissible(std::size_t human, const HumanCrossings& h, double k, bool by_spectrum,
                  HumanOutcome& o) const {
    if (by_spectrum) {
      ++o.spectra;
      const Spectrum s = ev_.spectrum(human, kmvf(k), ksvf(k), false);
      return s.verdict == Verdict::kStable &&
             s.min_damping_ratio >= p_.analysis.required_damping_ratio;
    }
    return h.loop->modes_outside(h.search, k, &o.boundary_points) == 0;
  }

  // The first stiffness above `lo` (known admissible) that fails for this human, given that
  // none above `best` matters; each interval between crossings is confirmed once.
  HumanOutcome human_limit(std::size_t human, const HumanCrossings& h, double lo, double best,
                           bool by_spectrum) const {
    HumanOutcome o;
    o.crossings = static_cast<long>(h.search.crossings.size());
    std::vector<Crossing> cs;
    for (const Crossing& c : h.search.crossings) {
      if (c.stiffness_N_per_m > lo * (1.0 + 1e-12)) cs.push_back(c);
    }
    // Interval j runs from edge(j) to edge(j + 1): lo, the crossings, the cap.
    auto edge = [&](std::size_t j) { return j == 0 ? lo : cs[j - 1].stiffness_N_per_m; };
    for (std::size_t j = 0; j <= cs.size(); ++j) {
      const double from = edge(j);
      if (from > best) return o;  // this human cannot lower the answer
      const double to = j < cs.size() ? cs[j].stiffness_N_per_m : cap_;
      // Inside the interval (just above the last crossing for the open end).
      const double probe = j < cs.size() ? 0.5 * (from + to) : std::min(cap_, from * 1.001 + 1e-9);
      if (j > 0 && cs[j - 1].near_double && from <= best) {
        // A mode touches the boundary here: at that stiffness it is on it.
        o.limit = from;
        o.uncertain = true;
        return o;
      }
      if (admissible(human, h, probe, by_spectrum, o)) continue;
      if (j == 0) {
        // No crossing found below a failing stiffness: one was missed. Find it by scan.
        o.fallback = true;
        o.limit = scan(human, h, lo, probe, o);
        return o;
      }
      o.limit = from;
      o.uncertain = cs[j - 1].near_double;
      return o;
    }
    // The last interval runs to the cap: it must pass there too, else a crossing was missed.
    if (!admissible(human, h, cap_, by_spectrum, o)) {
      o.fallback = true;
      o.limit = scan(human, h, edge(cs.size()), cap_, o);
    }
    return o;
  }

  // The old way inside one interval, by spectra: geometric scan, then bisection.
  double scan(std::size_t human, const HumanCrossings& h, double lo, double fail,
              HumanOutcome& o) const {
    const double tol = p_.analysis.stiffness_tolerance_N_per_m;
    const bool by_spectrum = h.loop->order() <= kSpectrumOrderLimit;
    double pass = lo;
    for (double k = std::max(lo * 1.01, lo + tol); k < fail; k *= 1.01) {
      if (!admissible(human, h, k, by_spectrum, o)) {
        fail = k;
        break;
      }
      pass = k;
    }
    while (fail - pass > tol) {
      const double mid = 0.5 * (pass + fail);
      if (mid <= pass || mid >= fail) break;
      (admissible(human, h, mid, by_spectrum, o) ? pass : fail) = mid;
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

// Runs f(i) for i in [0, n) on the machine's cores.
template <class F>
void parallel_for(std::size_t n, const F& f) {
  std::atomic<std::size_t> next{0};
  std::mutex error_mutex;
  std::exception_ptr error;
  auto work = [&] {
    for (std::size_t i = next++; i < n; i = next++) {
      try {
        f(i);
      } catch (...) {
        const std::lock_guard<std::mutex> lock(error_mutex);
        error = std::current_exception();
        return;
      }
    }
  };
  const unsigned threads = analysis_threads(n, 16);
  std::vector<std::thread> pool;
  for (unsigned t = 1; t < threads; ++t) pool.emplace_back(work);
  work();
  for (std::thread& t : pool) t.join();
  if (error) std::rethrow_exception(error);
}

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

// Whether the human changes the block the stiffness enters (else one human stands for all),
// and how many blocks the loop has.
struct BlockLayout {
  bool human_free{false};
  std::size_t blocks{0};
};

BlockLayout block_layout(const LoopEvaluator& ev, Side side) {
  BlockLayout l{!ev.human_matters(), 0};
  const ZohPlant plant = ev.model().master_plant(ev.human(0).impedance);
  for (const ModelBlock& b : ev.model().build(plant, 0.0, 0.0)) {
    ++l.blocks;
    const int position = side == Side::kMaster ? b.master_position : b.slave_position;
    if (position >= 0 && !b.includes_master) l.human_free = true;
  }
  return l;
}

// The lower end: with one block, every human's count of modes outside at K = 0 (free with
// the crossings); otherwise, or when any count is not 0, the whole band's spectra at K = 0
// as the search always had it (a rigid-body mode at z = 1 exactly moves the lower end to the
// tolerance). Empty when there is no limit (`out` says why).
std::optional<double> lower_end(const SideSearch& search, const std::vector<HumanCrossings>& found,
                                std::size_t blocks, StiffnessLimit& out) {
  bool all_inside = blocks == 1;
  for (const HumanCrossings& h : found) all_inside = all_inside && h.outside_at_zero == 0;
  if (all_inside) return 0.0;
  auto sweep = [&](double k) {
    ++out.band_verifications;
    return search.band(k);
  };
  const std::optional<LowerEnd> lower = find_lower_end(sweep, search, out);
  if (!lower) return std::nullopt;
  return lower->stiffness_N_per_m;
}

// Each human's first exit, its intervals confirmed by counting modes along the boundary.
std::vector<HumanOutcome> human_limits(const ExactSearch& search,
                                       const std::vector<HumanCrossings>& found, double k_lo) {
  std::vector<HumanOutcome> outcomes(found.size());
  std::atomic<double> best{std::numeric_limits<double>::infinity()};
  parallel_for(found.size(), [&](std::size_t i) {
    // Up to 24 states every interval is confirmed with one spectrum; past that by counting
    // modes along the boundary (an eigenvalue decomposition of the whole chain per interval
    // would cost more than everything else), the limiting human again by spectra below.
    outcomes[i] = search.human_limit(i, found[i], k_lo, best.load(),
                                     found[i].loop->order() <= kSpectrumOrderLimit);
    double seen = best.load();
    while (outcomes[i].limit < seen && !best.compare_exchange_weak(seen, outcomes[i].limit)) {
    }
  });
  return outcomes;
}

// Every human's crossings, ascending, those within 1e-12 of each other once; the counts of
// finding them.
void collect_crossings(StiffnessLimit& out, const std::vector<HumanCrossings>& found) {
  for (const HumanCrossings& h : found) {
    out.boundary_points += h.search.boundary_points;
    out.evaluations += h.spectra;
  }
  for (const HumanCrossings& h : found) {
    for (const Crossing& c : h.search.crossings)
      out.crossings_N_per_m.push_back(c.stiffness_N_per_m);
  }
  std::sort(out.crossings_N_per_m.begin(), out.crossings_N_per_m.end());
  out.crossings_N_per_m.erase(
      std::unique(out.crossings_N_per_m.begin(), out.crossings_N_per_m.end(),
                  [](double a, double b) { return b - a <= 1e-12 * b; }),
      out.crossings_N_per_m.end());
}

// The limiting human (the first of the lowest limits); every human's counts added to `out`.
std::size_t tally_outcomes(StiffnessLimit& out, const std::vector<HumanOutcome>& outcomes) {
  std::size_t worst = 0;
  for (std::size_t i = 0; i < outcomes.size(); ++i) {
    const HumanOutcome& o = outcomes[i];
    out.evaluations += o.spectra;
    out.boundary_points += o.boundary_points;
    out.crossings_found += o.crossings;
    out.fallbacks += o.fallback ? 1 : 0;
    if (o.limit < outcomes[worst].limit) worst = i;
  }
  return worst;
}

// Past 24 states, the limiting human's intervals again, each with one spectrum (its eigenvalues,
// not a count): where they disagree, the spectra decide and the disagreement is a fallback.
void confirm_by_spectra(const ExactSearch& search, std::size_t worst, const HumanCrossings& found,
                        double k_lo, HumanOutcome& outcome, StiffnessLimit& out) {
  HumanOutcome confirmed =
      search.human_limit(worst, found, k_lo, std::numeric_limits<double>::infinity(), true);
  out.evaluations += confirmed.spectra;
  if (confirmed.limit != outcome.limit) {
    ++out.fallbacks;
    confirmed.fallback = true;
  }
  confirmed.limit = std::min(confirmed.limit, outcome.limit);
  outcome = confirmed;
}

struct Answer {
  double stiffness_N_per_m{0.0};
  bool certain{false};
};

// The crossing `limit` comes from the double-precision model, whose entries carry rounding (at
// high rates phi - I holds few digits): step down from it until a spectrum with error bounds
// shows every mode inside the region by more than its bound.
Answer step_down(const SideSearch& search, const std::vector<HumanOutcome>& outcomes, double limit,
                 double k_lo, StiffnessLimit& out) {
  double answer = limit * (1.0 - kRoundDown);
  bool certain = false;
  // Every human whose own crossing lies within the step of the worst one is checked: its
  // true crossing could lie under the answer too.
  std::vector<std::size_t> near;
  for (std::size_t i = 0; i < outcomes.size(); ++i) {
    if (outcomes[i].limit <= limit * (1.0 + kMaxStepDown)) near.push_back(i);
  }
  auto certain_at = [&](double k) {
    for (const std::size_t i : near) {
      ++out.evaluations;
      if (!certainly_admissible(search.ev.spectrum(i, search.master_k(k), search.slave_k(k), true),
                                search.required)) {
        return false;
      }
    }
    return true;
  };
  // At most 1e-6 below the crossing (the model's rounding needed 3e-7 at 80 kHz): past that
  // the doubt is another mode within its bound of the boundary (a marginal one), not the
  // crossing's, and stepping further would not remove it.
  double doubtful = limit;
  for (int i = 0; i < 9 && answer > k_lo; ++i) {
    if (certain_at(answer)) {
      certain = true;
      break;
    }
    doubtful = answer;
    answer = limit * (1.0 - kRoundDown * std::pow(4.0, i + 1));
  }
  // Closer: bisect between the last doubtful stiffness and the first certain one.
  for (int i = 0; certain && i < 4 && doubtful > answer; ++i) {
    const double mid = 0.5 * (answer + doubtful);
    (certain_at(mid) ? answer : doubtful) = mid;
  }
  if (!certain) answer = limit * (1.0 - kMaxStepDown);
  return {answer, certain};
}

}  // namespace

NearestCrossings nearest_crossings(const StiffnessLimit& limit, double stiffness) {
  NearestCrossings n;
  const std::vector<double>& c = limit.crossings_N_per_m;
  const auto it = std::lower_bound(c.begin(), c.end(), stiffness);
  if (it != c.end()) n.above_N_per_m = *it;
  if (it != c.begin()) n.below_N_per_m = *std::prev(it);
  return n;
}

StiffnessLimit max_stable_stiffness(const TeleopParams& params, Side side,
                                    const SearchOptions& options) {
  const SideSearch side_search(params, side);
  const LoopEvaluator& ev = side_search.ev;
  const double cap = options.max_stiffness_N_per_m;
  StiffnessLimit out = side_search.start_limit();
  const BlockLayout layout = block_layout(ev, side);
  const std::size_t humans = layout.human_free ? 1 : ev.human_count();
  const ExactSearch search(side_search, cap);
  std::vector<HumanCrossings> found(humans);
  try {
    parallel_for(humans, [&](std::size_t i) { found[i] = search.crossings(i); });
  } catch (const std::exception& e) {
    // Not a rank-one loop (cannot happen with this model): the scan answers instead.
    StiffnessLimit scanned = max_stable_stiffness_scan(params, side, options);
    scanned.reason = (scanned.reason.empty() ? "" : scanned.reason + "; ") +
                     "exact crossings unavailable (" + e.what() + "), scanned instead";
    return scanned;
  }
  const std::optional<double> lower = lower_end(side_search, found, layout.blocks, out);
  if (!lower) return out;
  const double k_lo = *lower;
  std::vector<HumanOutcome> outcomes = human_limits(search, found, k_lo);
  collect_crossings(out, found);
  const std::size_t worst = tally_outcomes(out, outcomes);
  if (std::isfinite(outcomes[worst].limit) && found[worst].loop->order() > kSpectrumOrderLimit) {
    confirm_by_spectra(search, worst, found[worst], k_lo, outcomes[worst], out);
  }
  const HumanOutcome& w = outcomes[worst];
  if (ev.human_matters()) out.worst_human = ev.human(worst);
  if (!std::isfinite(w.limit)) {
    out.reason = fmt::format("meets the requirement for every stiffness up to {:g} N/m", cap);
    return out;
  }
  out.limit_crossing_N_per_m = w.limit;
  // Counted along the boundary (past 24 states): no per-mode bound to step by, so the full
  // step.
  const Answer answer = found[worst].loop->order() <= kSpectrumOrderLimit
                            ? step_down(side_search, outcomes, w.limit, k_lo, out)
                            : Answer{w.limit * (1.0 - kMaxStepDown), true};
  out.max_stable_stiffness_N_per_m = std::max(k_lo, answer.stiffness_N_per_m);
  out.uncertain = w.uncertain || !answer.certain;
  if (w.uncertain) {
    out.reason = "a mode touches the boundary at the limit within the numerical error";
  } else if (!answer.certain) {
    out.reason = (out.reason.empty() ? "" : out.reason + "; ") +
                 "at the limit a mode lies within its error bound of the boundary";
  }
  return out;
}

}  // namespace teleop::stability
