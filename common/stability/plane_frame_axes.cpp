// The planes' frame of an isotropic n-axis teleoperator (axes_detail.hpp): there the axes
// decouple and each is the one-axis loop, so the one-axis engine analyses a tilted plane too.
#include <Eigen/Core>
#include <algorithm>
#include <cstddef>
#include <optional>
#include <vector>

#include "common/stability/axes_detail.hpp"

namespace teleop::stability::detail {

namespace {

using Mat = Eigen::MatrixXd;
using Vec = Eigen::VectorXd;

// m == m(0, 0) I, exactly.
bool is_scalar(const Mat& m) {
  for (Eigen::Index i = 0; i < m.rows(); ++i) {
    for (Eigen::Index j = 0; j < m.cols(); ++j) {
      if (m(i, j) != (i == j ? m(0, 0) : 0.0)) return false;
    }
  }
  return true;
}

bool is_constant(const Vec& v) { return v.size() == 0 || (v.array() == v(0)).all(); }

bool isotropic(const TeleopAxesParams& p) {
  const GainsAxes& g = p.gains;
  for (const Mat* m : {&p.master_device.mass_kg, &p.slave_device.mass_kg, &g.kpm, &g.kps, &g.kdm,
                       &g.kds, &g.kvm, &g.kvs, &g.kfm}) {
    if (!is_scalar(*m)) return false;
  }
  if (!is_constant(p.master_device.damping_Ns_per_m) ||
      !is_constant(p.slave_device.damping_Ns_per_m)) {
    return false;
  }
  // A band varies each axis's human on its own: diag(h_x, h_y, h_z) is not isotropic.
  if (p.human.kind == HumanKind::kBand) return false;
  if (p.human.kind == HumanKind::kFixed) {
    const HumanImpedanceAxes& h = p.human.fixed;
    for (const Mat* m : {&h.mass_kg, &h.damping_Ns_per_m, &h.stiffness_N_per_m}) {
      if (!is_scalar(*m)) return false;
    }
  }
  return true;
}

// The direction (index into `dirs`) of `n`: an existing one when n == +-d exactly, a new one
// when n is orthogonal to every existing one exactly, -1 otherwise.
int direction_of(const Vec& n, std::vector<Vec>& dirs) {
  for (std::size_t i = 0; i < dirs.size(); ++i) {
    if (n == dirs[i] || n == -dirs[i]) return static_cast<int>(i);
  }
  for (const Vec& d : dirs) {
    if (n.dot(d) != 0.0) return -1;
  }
  dirs.push_back(n);
  return static_cast<int>(dirs.size()) - 1;
}

}  // namespace

std::optional<PlaneFrame> in_plane_frame(const TeleopAxesParams& p,
                                         const PlaneFixtureParams* searched) {
  if (!isotropic(p)) return std::nullopt;
  // First which direction each considered plane has (-1: left out), then the copy.
  std::vector<Vec> dirs;
  std::vector<int> master_dir;
  std::vector<int> slave_dir;
  bool tilted = false;
  for (const bool master : {true, false}) {
    for (const PlaneFixtureParams& pl : master ? p.master_planes : p.slave_planes) {
      int d = -1;
      if (pl.stiffness_N_per_m != 0.0 || &pl == searched) {
        d = direction_of(pl.normal, dirs);
        if (d < 0) return std::nullopt;
        tilted = tilted || normal_axis(pl.normal) < 0;
      }
      (master ? master_dir : slave_dir).push_back(d);
    }
  }
  if (!tilted) return std::nullopt;
  PlaneFrame f{p, {}, {}};
  for (const bool master : {true, false}) {
    auto& planes = master ? f.params.master_planes : f.params.slave_planes;
    auto& scale = master ? f.master_scale : f.slave_scale;
    const std::vector<int>& dir = master ? master_dir : slave_dir;
    for (std::size_t i = 0; i < planes.size(); ++i) {
      PlaneFixtureParams& pl = planes[i];
      // K n n^T = K |n|^2 e e^T in the frame whose axis e is n / |n|.
      scale.push_back(dir[i] < 0 ? 1.0 : pl.normal.squaredNorm());
      pl.normal = Vec::Unit(p.axes, std::max(dir[i], 0));
      pl.stiffness_N_per_m *= scale.back();
    }
  }
  return f;
}

}  // namespace teleop::stability::detail
