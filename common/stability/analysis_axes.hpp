// Worst-case-human stability analysis of the n-axis teleoperator (issue 18 "Stability";
// docs/architecture.md §2.9) and the exact stiffness limit of one fixture plane.
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "common/core/teleop_axes.hpp"
#include "common/stability/analyzer.hpp"
#include "common/stability/discrete_model_axes.hpp"
#include "common/stability/human_grid.hpp"
#include "common/stability/spectrum.hpp"
#include "common/stability/stiffness_search.hpp"

namespace teleop::stability {

struct AxesAnalysisOptions {
  // Analyse axis by axis with the one-axis engine when nothing couples the axes (every matrix
  // diagonal, every active plane's normal along an axis). Off: the whole n-axis model always.
  bool decouple{true};
  // Also compute every stiff plane's limit (plane_stiffness_limit) and name the limiting one.
  bool plane_limits{false};
  // A coupled loop with a band: every combination of the axes' grids when there are at most
  // this many, else the axes' grids walked together plus a refinement axis by axis.
  std::size_t max_product_humans{4096};
  // Refine walked grids axis by axis (off: the walked grids alone, cheaper and coarser).
  bool refine_walked_band{true};
  double max_stiffness_N_per_m{1e9};  // plane limits above this are "none"
};

// One human per axis: an index into each axis's grid (human_samples of that axis's band).
using HumanChoice = std::vector<std::size_t>;

struct AxesBandResult {
  Verdict verdict{Verdict::kStable};
  double min_damping_ratio{1.0};
  double spectral_radius{0.0};
  HumanChoice worst{};         // the lowest damping ratio
  HumanChoice radius_worst{};  // the largest spectral radius
  std::size_t humans_evaluated{0};
  // Every combination of the axes' humans was covered (axis by axis when they decouple).
  bool exhaustive{true};
  std::string invalid_reason{};
};

// What stays fixed across a band and a stiffness search: the model (plants, filter, structure)
// or, when the axes decouple, one one-axis LoopEvaluator per axis; the humans of every axis.
class AxesEvaluator {
 public:
  explicit AxesEvaluator(const TeleopAxesParams& params, const AxesAnalysisOptions& options = {},
                         bool master_planes_used = false, bool slave_planes_used = false);
  ~AxesEvaluator();
  AxesEvaluator(const AxesEvaluator&) = delete;
  AxesEvaluator& operator=(const AxesEvaluator&) = delete;

  [[nodiscard]] bool decoupled() const { return !axis_source_.empty(); }
  [[nodiscard]] bool human_matters() const { return human_matters_; }
  [[nodiscard]] int axes() const { return n_; }
  [[nodiscard]] double period_s() const { return period_s_; }
  [[nodiscard]] std::size_t grid_size(int axis) const;
  [[nodiscard]] const HumanSample& human(int axis, std::size_t i) const;
  // The one-axis teleoperator of axis `axis` (meaningful when the axes decouple).
  [[nodiscard]] const TeleopParams& axis_params(int axis) const;
  [[nodiscard]] const LoopEvaluator& axis_evaluator(int axis) const;
  // The most coupled structure of the loop (of any axis when they decouple).
  [[nodiscard]] Structure structure() const;

  // The loop's blocks for one human per axis at the given plane stiffness matrices.
  [[nodiscard]] std::vector<AxesBlock> blocks(const HumanChoice& human, const Eigen::MatrixXd& kmvf,
                                              const Eigen::MatrixXd& ksvf) const;
  [[nodiscard]] Spectrum spectrum(const HumanChoice& human, const Eigen::MatrixXd& kmvf,
                                  const Eigen::MatrixXd& ksvf, bool estimate_error) const;
  // The worst case over the humans (see AxesAnalysisOptions::max_product_humans).
  [[nodiscard]] AxesBandResult sweep(const Eigen::MatrixXd& kmvf,
                                     const Eigen::MatrixXd& ksvf) const;
  // The humans a coupled sweep starts from (every combination, or the grids walked together).
  [[nodiscard]] std::vector<HumanChoice> candidates() const;

 private:
  struct PerHuman;
  [[nodiscard]] PerHuman evaluate(const HumanChoice& h, const Eigen::MatrixXd& kmvf,
                                  const Eigen::MatrixXd& ksvf,
                                  const std::optional<Spectrum>& human_free) const;
  [[nodiscard]] AxesBandResult sweep_decoupled(const Eigen::MatrixXd& kmvf,
                                               const Eigen::MatrixXd& ksvf) const;
  [[nodiscard]] const LoopEvaluator& per_axis(int axis) const {
    return *per_axis_[axis_source_[static_cast<std::size_t>(axis)]];
  }

  int n_{1};
  double period_s_{0.0};
  HumanKind kind_{HumanKind::kNone};
  bool human_matters_{false};
  std::size_t max_product_{0};
  bool refine_{true};
  HumanImpedanceAxes fixed_{};
  std::vector<std::vector<HumanSample>> grids_{};  // per axis
  std::unique_ptr<DiscreteModelAxes> model_{};     // the whole loop (not built when decoupled)
  std::optional<ZohPlantAxes> single_plant_{};     // the master plant when there is one human
  std::vector<TeleopParams> axis_params_{};        // decoupled: each axis's one-axis loop
  std::vector<std::unique_ptr<LoopEvaluator>> per_axis_{};  // one per distinct axis loop
  std::vector<std::size_t> axis_source_{};                  // axis -> its evaluator in per_axis_
};

// The stiffness limit of one plane, the others held at their configured stiffness.
struct PlaneLimit {
  Side side{Side::kMaster};
  std::size_t plane{0};
  std::optional<double> max_stable_stiffness_N_per_m{};
  std::optional<double> limit_crossing_N_per_m{};  // where a mode meets the boundary
  std::string reason{};                            // why there is no finite limit, or a caveat
  bool invalid{false};
  bool uncertain{false};
  std::vector<HumanSample> worst_human{};  // per axis, the human that sets the limit
  std::size_t humans_evaluated{0};
};

struct AxesAnalysis {
  Verdict verdict{Verdict::kStable};
  double spectral_radius{0.0};
  double stability_margin{1.0};  // 1 - spectral radius
  double min_damping_ratio{1.0};
  std::vector<HumanSample> worst_human{};   // per axis; empty when the human does not matter
  std::vector<HumanSample> radius_human{};  // per axis, the largest spectral radius
  Spectrum spectrum{};                      // of the worst human's loop, with error bounds
  Structure structure{Structure::kBilateral};
  bool decoupled{false};  // analysed axis by axis
  std::size_t humans_evaluated{0};
  bool band_exhaustive{true};
  std::vector<PlaneLimit> plane_limits{};  // with AxesAnalysisOptions::plane_limits
  // Index into plane_limits of the plane closest to its limit (largest stiffness / limit).
  std::optional<std::size_t> limiting_plane{};
  std::string invalid_reason{};  // why the verdict is invalid, naming the field when one is bad
};

// Every plane of non-zero stiffness active (the equilibrium in the corner of all of them, as the
// one-axis model lumps its fixture). Never throws for a bad configuration: invalid, with reason.
[[nodiscard]] AxesAnalysis analyze_axes(const TeleopAxesParams& params,
                                        const AxesAnalysisOptions& options = {});

// The largest stiffness of plane `plane` of `side` such that every stiffness in [0, K] meets the
// required damping ratio for every human considered. The plane adds K n n^T, a rank-one term,
// so the characteristic polynomial is det(zI - A0) (1 - K c^T (zI - A0)^-1 b): a mode meets the
// boundary where G = c^T (zI - A0)^-1 b is real and positive, at K = 1/G.
[[nodiscard]] PlaneLimit plane_stiffness_limit(const TeleopAxesParams& params, Side side,
                                               std::size_t plane,
                                               const AxesAnalysisOptions& options = {});

}  // namespace teleop::stability
