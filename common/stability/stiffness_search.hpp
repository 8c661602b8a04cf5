// Maximum stable fixture stiffness: the largest K such that every stiffness in [0, K] meets
// the required damping ratio for every human of the model, to the configured tolerance.
#pragma once

#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "common/core/teleop_params.hpp"
#include "common/stability/analyzer.hpp"
#include "common/stability/human_grid.hpp"

namespace teleop::stability {

enum class Side { kMaster, kSlave };

struct SearchOptions {
  double max_stiffness_N_per_m{1e9};  // above this a limit is reported as "none"
  double growth{1.2};  // geometric scan factor before bisection: fine enough not to step
                       // over the dips of a non-monotone damping ratio
};

struct StiffnessLimit {
  std::optional<double> max_stable_stiffness_N_per_m{};
  std::string reason{};                             // why there is no finite limit, or a caveat
  std::optional<HumanSample> worst_human{};         // the human whose loop sets the limit
  std::optional<double> passivity_limit_N_per_m{};  // Colgate-Schenkel, master wall only
  std::string passivity_reason{};                   // why there is no passivity bound (master side)
  double other_fixture_N_per_m{0.0};  // the other side's fixture, held at its configured value
  long evaluations{0};                // single-human spectra computed
  int band_verifications{0};          // whole-band sweeps
  // The model is not finite (verdict invalid): no limit, and the reason says why.
  bool invalid{false};
  // Exact limits (docs/stability-limits.md): G evaluated along the admissible boundary, the
  // crossings found, and intervals whose one spectrum disagreed with the crossings found (a
  // crossing the sampler missed; the limit then comes from a scan inside that interval).
  long boundary_points{0};
  long crossings_found{0};
  int fallbacks{0};
  // The limit is a crossing where a mode only touches the boundary within the numerical error.
  bool uncertain{false};
  // Every stiffness in (0, cap] at which some human's mode meets the boundary, ascending: the
  // margins below and above a value in force (nearest_crossings).
  std::vector<double> crossings_N_per_m{};
  // The crossing the limit stands on; the limit is below it by the step that a spectrum with
  // error bounds needed to show every mode inside (the model's rounding).
  std::optional<double> limit_crossing_N_per_m{};
};

// The nearest crossings strictly below and at-or-above `stiffness` (empty where there is none).
struct NearestCrossings {
  std::optional<double> below_N_per_m{};
  std::optional<double> above_N_per_m{};
};
[[nodiscard]] NearestCrossings nearest_crossings(const StiffnessLimit& limit, double stiffness);

// Searches on the current worst human (geometric scan, then bisection), verifies the whole
// band at the answer and at halvings below it, and repeats with whichever human fails there
// until the band agrees. The other side's fixture is held at its configured value.
// What both searches for one side's fixture stiffness start from: the loop with that fixture
// variable, the other side's fixture held at its configured stiffness.
struct SideSearch {
  SideSearch(const TeleopParams& params, Side side);

  const TeleopParams& params;
  Side side;
  LoopEvaluator ev;
  double other_N_per_m;      // the other side's fixture stiffness
  double required;           // the required damping ratio
  double tolerance_N_per_m;  // the stiffness tolerance

  // The master's and the slave's fixture stiffness when the searched one is k.
  [[nodiscard]] double master_k(double k) const {
    return side == Side::kMaster ? k : other_N_per_m;
  }
  [[nodiscard]] double slave_k(double k) const { return side == Side::kSlave ? k : other_N_per_m; }
  // The whole band at stiffness k.
  [[nodiscard]] BandResult band(double k) const {
    return ev.sweep(master_k(k), slave_k(k), required);
  }
  // The limit before any search: the other fixture named, and the master's passivity bound
  // filled in (master side only).
  [[nodiscard]] StiffnessLimit start_limit() const;
};

// Why a configuration has no limit at its lower end.
[[nodiscard]] std::string lower_end_failure(const BandResult& at_zero, double required, Side side,
                                            double other_N_per_m);

// The lower end both searches start from: the whole band at K = 0, or at the tolerance when a
// rigid-body mode sits at z = 1 exactly at K = 0 (then `out.reason` says the limit is over
// (0, K]). Empty when there is no limit; `out` then holds the reason, `invalid` and the human.
struct LowerEnd {
  double stiffness_N_per_m{0.0};
  BandResult band{};
};
[[nodiscard]] std::optional<LowerEnd> find_lower_end(const std::function<BandResult(double)>& band,
                                                     const SideSearch& search, StiffnessLimit& out);

[[nodiscard]] StiffnessLimit max_stable_stiffness_scan(const TeleopParams& params, Side side,
                                                       const SearchOptions& options = {});

// Exact: for each human, every stiffness at which a mode crosses the admissible boundary (the
// unit circle, or the constant-zeta spiral for a required damping ratio), each interval between
// crossings confirmed with one spectrum; the answer is the first crossing out of the region
// over the band, whatever lies between the crossings. Humans are shared between threads.
[[nodiscard]] StiffnessLimit max_stable_stiffness(const TeleopParams& params, Side side,
                                                  const SearchOptions& options = {});

// b > K T / 2 + |B| for the master wall (with the master's own position and velocity gains
// counted in K and B): the conservative colocated bound the paper compares with (Fig. 14).
// Empty when the master is not passive at any stiffness (|B| >= b).
[[nodiscard]] std::optional<double> master_passivity_limit(const TeleopParams& params);

}  // namespace teleop::stability
