// Worst-case-human analysis of one teleoperator (Abbott-Okamura Fig. 5).
#pragma once

#include <cstddef>
#include <optional>
#include <string>
#include <vector>

#include "common/core/teleop_params.hpp"
#include "common/stability/discrete_model.hpp"
#include "common/stability/human_grid.hpp"
#include "common/stability/spectrum.hpp"

namespace teleop::stability {

// The worst case over every human at one pair of fixture stiffnesses.
struct BandResult {
  Verdict verdict{Verdict::kStable};  // unstable if any human is, else uncertain if any is
  double min_damping_ratio{1.0};
  double spectral_radius{0.0};
  std::size_t worst_index{0};   // the human with the lowest damping ratio
  std::size_t radius_index{0};  // the human with the largest spectral radius
  // A human that fails the requirement (the lowest damping ratio among those that do), if any.
  std::optional<std::size_t> failing_index{};
  // Why the verdict is invalid (a non-finite model for some human), empty otherwise.
  std::string invalid_reason{};
};

// Holds what does not change between evaluations: the model structure, the humans and their
// discretised master plants, so a stiffness search pays only for the eigenvalues.
class LoopEvaluator {
 public:
  explicit LoopEvaluator(const TeleopParams& params, bool master_wall_used = false,
                         bool slave_wall_used = false);

  [[nodiscard]] const DiscreteModel& model() const { return model_; }
  [[nodiscard]] std::size_t human_count() const { return humans_.size(); }
  [[nodiscard]] const HumanSample& human(std::size_t i) const { return humans_[i]; }
  [[nodiscard]] bool human_matters() const { return human_matters_; }

  [[nodiscard]] Spectrum spectrum(std::size_t human, double master_fixture_N_per_m,
                                  double slave_fixture_N_per_m, bool estimate_error) const;
  // `required_damping_ratio` only decides `failing_index`.
  [[nodiscard]] BandResult sweep(double master_fixture_N_per_m, double slave_fixture_N_per_m,
                                 double required_damping_ratio = 0.0) const;

 private:
  DiscreteModel model_;
  bool human_matters_{true};
  std::vector<HumanSample> humans_{};
  std::vector<ZohPlant> master_plants_{};
};

struct AnalysisResult {
  Verdict verdict{Verdict::kStable};
  double spectral_radius{0.0};
  double min_damping_ratio{1.0};
  std::optional<HumanSample> worst_human{};   // empty when the human does not matter
  std::optional<HumanSample> radius_human{};  // the human with the largest spectral radius
  Spectrum spectrum{};                        // of the worst human's loop, with error bounds
  Structure structure{Structure::kBilateral};
  std::size_t humans_evaluated{0};
  // Why the verdict is invalid, empty otherwise.
  std::string invalid_reason{};
};

// How many threads a band sweep or a stiffness limit may use (default: every core, at most 8).
// A process that shares the machine with real-time loops (the supervisor, the nodes) sets 1:
// bursts on every core delayed the nodes' link threads and grew the round trip it measures.
void set_analysis_threads(unsigned threads);
[[nodiscard]] unsigned analysis_threads(std::size_t work_items, std::size_t minimum_for_parallel);

// The configured teleoperator as it stands (its own fixture stiffnesses).
[[nodiscard]] AnalysisResult analyze(const TeleopParams& params);

// True when a band result meets the configured requirement (stable and zeta >= required).
[[nodiscard]] bool meets_requirement(const BandResult& r, double required_damping_ratio);

}  // namespace teleop::stability
