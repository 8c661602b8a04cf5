// The sampled-data teleoperator with n task-space axes (issue 18 "Stability") as x(k+1) = A x(k),
// linearised about an equilibrium on the active fixture planes: the block generalisation of
// discrete_model.hpp's one axis (docs/architecture.md §2.9). Every scalar of the one-axis model
// becomes an n x n matrix: the plants (zoh_axes.hpp, the human's impedance added to the master),
// the gains, and the planes' stiffness sum K n n^T over the active planes of each side.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "common/core/teleop_axes.hpp"
#include "common/stability/discrete_model.hpp"
#include "common/stability/zoh_axes.hpp"

namespace teleop::stability {

// What is wrong with an n-axis teleoperator, naming the field (empty when nothing is): sizes,
// finiteness (NaN or infinity anywhere), symmetric positive definite masses, unit plane
// normals, non-negative damping and stiffness, the human band per axis.
[[nodiscard]] std::string check_axes_params(const TeleopAxesParams& p);

// Sum of K n n^T over the planes that are active (`active` empty: every plane), n x n.
[[nodiscard]] Eigen::MatrixXd plane_stiffness_matrix(const std::vector<PlaneFixtureParams>& planes,
                                                     int axes,
                                                     const std::vector<bool>& active = {});

// One block of the n-axis loop, as ModelBlock for one axis.
struct AxesBlock {
  Eigen::MatrixXd a{};
  // Eigenvalues the paper's realisation (4n states per side and d n delay states) has that are
  // identically zero and this realisation leaves out.
  int structural_zeros{0};
  bool includes_master{false};
  int master_position{-1};  // first of the n master (slave) position states, -1 if absent
  int slave_position{-1};
};

// Everything that does not depend on the human or the plane stiffnesses, computed once.
class DiscreteModelAxes {
 public:
  // Throws std::invalid_argument with check_axes_params's message. `*_planes_used`: analyse as
  // if that side's planes may be stiff even if configured at 0 (a stiffness search there).
  explicit DiscreteModelAxes(const TeleopAxesParams& params, bool master_planes_used = false,
                             bool slave_planes_used = false);

  [[nodiscard]] Structure structure() const { return structure_; }
  [[nodiscard]] bool human_matters() const { return structure_ != Structure::kSlaveOnly; }
  [[nodiscard]] int axes() const { return n_; }
  [[nodiscard]] double period_s() const { return period_s_; }
  [[nodiscard]] const TeleopAxesParams& params() const { return p_; }

  // The master with the human's impedance added (pass zero matrices for no human).
  [[nodiscard]] ZohPlantAxes master_plant(const HumanImpedanceAxes& human) const;

  // The blocks whose spectra together are the loop's, for the plane stiffness matrices of each
  // side (plane_stiffness_matrix of the active planes).
  [[nodiscard]] std::vector<AxesBlock> build(const ZohPlantAxes& master_plant,
                                             const Eigen::MatrixXd& master_planes_N_per_m,
                                             const Eigen::MatrixXd& slave_planes_N_per_m) const;

 private:
  [[nodiscard]] AxesBlock build_block(bool with_master, bool with_slave,
                                      const ZohPlantAxes& master_plant, const Eigen::MatrixXd& kmvf,
                                      const Eigen::MatrixXd& ksvf) const;

  TeleopAxesParams p_;
  int n_{1};
  double period_s_{0.0};
  double filter_r_{0.0};
  double filter_a_{1.0};
  ZohPlantAxes slave_plant_{};
  Structure structure_{Structure::kBilateral};
};

}  // namespace teleop::stability
