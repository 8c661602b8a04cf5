// The sampled-data teleoperator of docs/architecture.md §2.5 as x(k+1) = A x(k), linearised about
// the equilibrium inside the fixtures (the paper's "dual system": fixtures lumped into the position
// gains, exogenous F_h* and F_e constant).
#pragma once

#include <Eigen/Core>
#include <optional>
#include <vector>

#include "common/core/teleop_params.hpp"
#include "common/stability/zoh.hpp"

namespace teleop::stability {

// Which parts of the loop interact, decided from the gains (docs/architecture.md §2.6).
enum class Structure {
  kBilateral,   // master and slave feed back on each other: one block, the delay enters
  kDecoupled,   // one side ignores the other: master block (with its human) and slave block
  kSlaveOnly,   // master unactuated: the slave alone, no human needed
  kMasterOnly,  // the slave does not follow: the master, its human and its wall alone
};

[[nodiscard]] const char* to_string(Structure s);

// The structure from the decisions the one-axis and the n-axis models make alike: both sides
// feed back on each other (bilateral), else both are in the loop (decoupled), else the master
// alone if it is actuated, else the slave alone.
[[nodiscard]] Structure structure_of(bool master_feels_slave, bool slave_follows_master,
                                     bool master_actuated, bool slave_in_loop);

// The blocks of a structure, in their order: build_block(with_master, with_slave) for each.
template <class Block, class BuildBlock>
[[nodiscard]] std::vector<Block> blocks_of(Structure s, const BuildBlock& build_block) {
  std::vector<Block> blocks;
  switch (s) {
    case Structure::kBilateral:
      blocks.push_back(build_block(true, true));
      break;
    case Structure::kDecoupled:
      blocks.push_back(build_block(true, false));
      blocks.push_back(build_block(false, true));
      break;
    case Structure::kSlaveOnly:
      blocks.push_back(build_block(false, true));
      break;
    case Structure::kMasterOnly:
      blocks.push_back(build_block(true, false));
      break;
  }
  return blocks;
}

// One block of the closed loop: the matrix and how many of the paper's states it leaves out.
struct ModelBlock {
  Eigen::MatrixXd a{};
  // Eigenvalues the paper's realisation has that are identically zero: the held exogenous
  // inputs F_h*(k-1), F_e(k-1) and the X(k-2) of a controller with no velocity term.
  int structural_zeros{0};
  bool includes_master{false};
  // Where the round-trip delay chain sits (stiffness crossings eliminate it as z^-d):
  // states [delay_first, delay_first + delay) hold x_m(k-1) ... x_m(k-d), fed from
  // `delay_source` (the master position); only the last of them is read by other rows.
  int delay_first{-1};
  int delay{0};
  int delay_source{-1};
  // The position state each side's fixture stiffness multiplies (-1 when the side is absent).
  int master_position{-1};
  int slave_position{-1};
};

// Everything about the loop that does not depend on the human or on fixture stiffness,
// computed once; build() is then cheap enough to call for every human of a band.
class DiscreteModel {
 public:
  // `master_wall_used` / `slave_wall_used`: analyse as if that fixture may be non-zero (a
  // stiffness search on that side) even if the configuration's fixture there is 0.
  explicit DiscreteModel(const TeleopParams& params, bool master_wall_used = false,
                         bool slave_wall_used = false);

  [[nodiscard]] Structure structure() const { return structure_; }
  [[nodiscard]] bool human_matters() const { return structure_ != Structure::kSlaveOnly; }
  [[nodiscard]] double period_s() const { return period_s_; }

  // Master (+human) plant for one human; pass a zero impedance for "no human".
  [[nodiscard]] ZohPlant master_plant(const HumanImpedance& human) const;

  // The blocks whose spectra together form the loop's spectrum.
  [[nodiscard]] std::vector<ModelBlock> build(const ZohPlant& master_plant,
                                              double master_fixture_N_per_m,
                                              double slave_fixture_N_per_m) const;

 private:
  [[nodiscard]] ModelBlock build_block(bool with_master, bool with_slave,
                                       const ZohPlant& master_plant, double kmvf,
                                       double ksvf) const;

  TeleopParams p_;
  double period_s_{0.0};
  double filter_r_{0.0};  // low-pass pole e^{-2 pi fc T}; 0 for a plain backward difference
  double filter_a_{1.0};  // 1 - r
  ZohPlant slave_plant_{};
  Structure structure_{Structure::kBilateral};
};

}  // namespace teleop::stability
