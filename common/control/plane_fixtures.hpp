// Forbidden-region fixtures in task space (issue 18 "Fixtures"; docs/architecture.md §2.3 "n
// axes"): up to kMaxPlanes half-space planes per side. A plane (unit normal n, offset p,
// stiffness K) bounds the region n^T x > p; inside it the fixture pushes the device with
//
//   F = -K (n^T x - p) n,
//
// outside (and on the plane) with nothing. Planes add: near an edge where two regions overlap
// the forces sum. With one axis and the normal (+1) a plane is the one-axis UnilateralFixture
// (fixture.hpp) with the same arithmetic: penetration x - p, force -(K (x - p)), so
// -force is bit for bit UnilateralFixture's K (x - p). A plane of zero stiffness is absent (no
// force, no penetration), as a one-axis fixture of zero stiffness is.
//
// Storage is fixed-capacity (Eigen's fixed-maximum dynamic types): evaluating allocates nothing.
#pragma once

#include <Eigen/Core>
#include <array>

#include "common/core/fixed_axes.hpp"
#include "common/core/rt_safe.hpp"
#include "common/core/teleop_axes.hpp"

namespace teleop::control {

// A task-space vector (m, m/s or N) or matrix with at most kMaxAxes entries per dimension.
using AxisVector = FixedAxisVector;
using AxisMatrix = FixedAxisMatrix;

inline constexpr int kMaxPlanes = kMaxPlanesPerSide;

struct Plane {
  AxisVector normal{};  // n entries, unit length
  double offset_m{0.0};
  double stiffness_N_per_m{0.0};
};

struct PlaneSetOutput {
  AxisVector force_N{};       // sum of -K (n^T x - p) n over the planes x is inside of
  double penetration_m{0.0};  // the deepest plane's n^T x - p (0 when inside none)
  int deepest_plane{-1};      // its index (-1 when inside none)
  std::array<double, kMaxPlanes> plane_penetration_m{};  // per plane, 0 outside
};

class PlaneSet {
 public:
  PlaneSet() = default;

  // Setup: throws std::invalid_argument when the set already holds kMaxPlanes planes. The
  // plane's fields are checked by validate(LawAxesParams) (law_axes_params.hpp).
  void add(const Plane& plane);
  void clear() noexcept { count_ = 0; }

  [[nodiscard]] int size() const noexcept { return count_; }
  [[nodiscard]] bool empty() const noexcept { return count_ == 0; }
  [[nodiscard]] const Plane& plane(int i) const noexcept {
    return planes_[static_cast<std::size_t>(i)];
  }
  // A guarded change's stiffness for plane i (0 <= i < size(), validated by the caller; normal
  // and offset stay). RT-safe.
  TELEOP_RT void set_stiffness(int i, double stiffness_N_per_m) noexcept {
    planes_[static_cast<std::size_t>(i)].stiffness_N_per_m = stiffness_N_per_m;
  }

  // Every plane's normal must have x.size() entries. RT-safe.
  TELEOP_RT [[nodiscard]] PlaneSetOutput evaluate(const AxisVector& x) const noexcept {
    PlaneSetOutput out;
    out.force_N = AxisVector::Zero(x.size());
    for (int i = 0; i < count_; ++i) {
      const Plane& p = planes_[static_cast<std::size_t>(i)];
      if (p.stiffness_N_per_m == 0.0) continue;
      double along_m = 0.0;
      for (Eigen::Index j = 0; j < x.size(); ++j) along_m += p.normal(j) * x(j);
      if (!(along_m > p.offset_m)) continue;
      const double penetration_m = along_m - p.offset_m;
      const double magnitude_N = p.stiffness_N_per_m * penetration_m;
      for (Eigen::Index j = 0; j < x.size(); ++j) out.force_N(j) += -(magnitude_N * p.normal(j));
      out.plane_penetration_m[static_cast<std::size_t>(i)] = penetration_m;
      if (penetration_m > out.penetration_m) {
        out.penetration_m = penetration_m;
        out.deepest_plane = i;
      }
    }
    return out;
  }

  // The force alone. RT-safe.
  TELEOP_RT [[nodiscard]] AxisVector force(const AxisVector& x) const noexcept {
    return evaluate(x).force_N;
  }

 private:
  std::array<Plane, kMaxPlanes> planes_{};
  int count_{0};
};

}  // namespace teleop::control
