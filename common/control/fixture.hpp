// Unilateral virtual fixture (eq. 7): F = K (x - p) for x > p, else 0.
#pragma once

#include "common/core/rt_safe.hpp"
#include "common/core/teleop_params.hpp"

namespace teleop::control {

struct FixtureOutput {
  double force_N{0.0};
  double penetration_m{0.0};
};

class UnilateralFixture {
 public:
  explicit UnilateralFixture(const FixtureParams& params) noexcept : params_(params) {}

  // A fixture with zero stiffness is absent: no term, no penetration.
  TELEOP_RT [[nodiscard]] bool active() const noexcept { return params_.stiffness_N_per_m != 0.0; }

  // RT-safe.
  TELEOP_RT [[nodiscard]] FixtureOutput evaluate(double position_m) const noexcept {
    FixtureOutput out;
    if (active() && position_m > params_.position_m) {
      out.penetration_m = position_m - params_.position_m;
      out.force_N = params_.stiffness_N_per_m * out.penetration_m;
    }
    return out;
  }

  [[nodiscard]] const FixtureParams& params() const noexcept { return params_; }

 private:
  FixtureParams params_{};
};

}  // namespace teleop::control
