// Identification of an n-axis device's mass matrix and damping from recorded task-space motion
// (issue 18 "identify"): Abbott-Okamura §4.1, eqs. 32-35, in vector form. The free device obeys
//   M x'' + B x' = F                                                     (eq. 32, n axes)
// with M the n x n mass matrix (symmetric), B the damping (diagonal, or full when asked) and F
// the external force on it in task space. Each axis i contributes one equation per sample,
//   sum_j M_ij x_j'' + sum_j B_ij x_j' = F_i,
// linear in the unknown entries of M and B; stacking every axis's equations of every sample of
// every run gives D p = F and p = D^+ F through the SVD, as the one-axis eqs. 33-35.
// (For n > 1 D is not formed: the R factor of [D F] is accumulated by blocks of rows, and the
// SVD of its P x P corner gives the same solution and singular values.)
//
// Each axis's position and force go through exactly the one-axis identify()'s filters
// (identify.hpp: the multiple-pass three-point moving average, the five-point differences, the
// force smoothed alike, a held force centred on the sample), so the fitted equation is eq. 32
// through one common linear filter on every channel and holds exactly for any coupling. With
// n = 1 the regression matrix, its column scaling and the SVD are the one-axis identify()'s
// and the numbers are identical.
//
// Two mass models: per axis (M diagonal: n masses, each axis's equation alone, n independent
// one-axis fits when B is diagonal too) and coupled (M symmetric: the n(n+1)/2 entries on and
// above the diagonal; M_ij with i != j appears in the equations of both axis i and axis j).
//
// Excitation: every axis must move and be driven by a varying force, else the fit is refused
// naming the axis; then the condition number of D with unit-norm columns must stay below 1e8
// (the one-axis bound), else the data do not separate some combination of the parameters (for
// example two axes always driven by the same force on a symmetric device move alike, and
// M_11 - M_12 + M_22 is not determined): the refusal names the parameter that dominates the
// least-determined combination.
//
// Plain data in, plain data out; no I/O. Not RT-safe: an offline tool.
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <vector>

#include "common/stability/identify.hpp"

namespace teleop::stability {

// One recorded n-axis run at a uniform sample rate: Series with a column per task axis.
struct SeriesAxes {
  // Sample period, s. Used when time_s is empty.
  double period_s{0.0};
  // Sample times, s (optional), as Series::time_s.
  std::vector<double> time_s{};
  // Task-space position, m: samples x n (row k is x at sample k).
  Eigen::MatrixXd position_m{};
  // External force in task space sampled at the same instants, N: samples x n.
  Eigen::MatrixXd force_N{};
  // Optional (0 x 0: none): a force held over the period ending at each sample, N: samples x n,
  // centred on the sample as Series::held_force_N.
  Eigen::MatrixXd held_force_N{};
};

enum class MassModel {
  kPerAxis,  // M diagonal
  kCoupled,  // M symmetric, full
};

enum class DampingModel {
  kDiagonal,  // B diagonal (the device model of issue 18)
  kFull,      // B any n x n matrix
};

struct IdentifyAxesOptions {
  IdentifyOptions filter{};  // smoothing, trimming, force smoothing: as the one-axis identify()
  MassModel mass{MassModel::kCoupled};
  DampingModel damping{DampingModel::kDiagonal};
};

struct IdentifyAxesResult {
  Eigen::MatrixXd mass_kg{};           // n x n, symmetric (diagonal for kPerAxis)
  Eigen::MatrixXd damping_Ns_per_m{};  // n x n (diagonal for kDiagonal)
  // Whether the fitted M is symmetric positive definite (a fit can come out indefinite on poor
  // data; it is reported, not refused).
  bool mass_positive_definite{false};
  // Over every axis's rows: 1 - SS_res / SS_tot with SS_tot about each axis's own mean.
  double r_squared{0.0};
  double residual_rms_N{0.0};
  Eigen::VectorXd axis_r_squared{};       // n: axis i's equation alone
  Eigen::VectorXd axis_residual_rms_N{};  // n
  std::size_t samples{0};                 // rows per axis, all runs (D has n x samples rows)
  std::size_t parameters{0};              // columns of D
  // Of D with unit-norm columns, as IdentifyResult::condition_number.
  double condition_number{0.0};
};

// Throws std::invalid_argument naming the run, the axis and the problem: no runs, axes that
// differ between runs or are not 1..kMaxAxes, mismatched sizes, a non-finite value (with its
// sample and axis), a bad period, too few samples, an axis that never moves or is never driven,
// or data that cannot separate the parameters (naming the least-determined one).
[[nodiscard]] IdentifyAxesResult identify_axes(const std::vector<SeriesAxes>& runs,
                                               const IdentifyAxesOptions& options = {});

}  // namespace teleop::stability
