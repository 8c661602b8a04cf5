// What the master and the slave halves of the law share (master_law.hpp, slave_law.hpp): the
// parameters, the velocity filter, the side's fixture, the actuator limiter, the coupling's
// fade step and the fault latch. Each law keeps its own state in a struct of its own, reset
// with `state_ = {}`. Everything here is RT-safe (no allocation, lock, exception or I/O) but
// the constructor, which validates the parameters.
#pragma once

#include <algorithm>
#include <cmath>

#include "common/control/actuator_limiter.hpp"
#include "common/control/command.hpp"
#include "common/control/fixture.hpp"
#include "common/control/law_params.hpp"
#include "common/control/velocity_estimator.hpp"
#include "common/core/rt_safe.hpp"

namespace teleop::control {

class LawCore {
 public:
  enum class Side { kMaster, kSlave };

  // Throws std::invalid_argument naming the field (validate()).
  LawCore(const LawParams& params, Side side)
      : params_(validated(params)),
        side_(side),
        estimator_(params.period_s, params.velocity_cutoff_hz),
        fixture_(side == Side::kMaster ? params.master_fixture : params.slave_fixture),
        limiter_(side == Side::kMaster ? params.master_actuator : params.slave_actuator,
                 params.period_s),
        fade_step_(params.clutch_fade_s > 0.0
                       ? std::min(1.0, params.period_s / params.clutch_fade_s)
                       : 1.0) {}

  // New gains and this side's fixture from the next step on.
  TELEOP_RT void retune(const Gains& gains, const FixtureParams& fixture) noexcept {
    params_.gains = gains;
    (side_ == Side::kMaster ? params_.master_fixture : params_.slave_fixture) = fixture;
    fixture_ = UnilateralFixture(fixture);
  }

  // A valid peer state with a non-finite field: a fault.
  TELEOP_RT [[nodiscard]] static bool bad_peer(const PeerState& p) noexcept {
    return p.valid && !(std::isfinite(p.position_m) && std::isfinite(p.velocity_m_per_s) &&
                        std::isfinite(p.force_N));
  }

  // Latches the fault: a 0 N command with flags.input_fault, now and at every step until
  // reset().
  TELEOP_RT [[nodiscard]] Command latch_fault() noexcept {
    faulted_ = true;
    limiter_.set_last_output(0.0);
    Command out;
    out.flags.input_fault = true;
    return out;
  }

  // Clears the latch and the limiter's memory; the filter at rest at the next sample, or at
  // `position_m` when it is finite.
  TELEOP_RT void reset() noexcept {
    faulted_ = false;
    limiter_.set_last_output(0.0);
    estimator_.reset();
  }
  TELEOP_RT void reset(double position_m) noexcept {
    faulted_ = false;
    limiter_.set_last_output(0.0);
    if (std::isfinite(position_m)) {
      estimator_.reset(position_m);
    } else {
      estimator_.reset();
    }
  }

  // The coupling weight one sample on, towards 1 (fading in) or 0 (fading out).
  TELEOP_RT [[nodiscard]] double faded(double weight, bool in) const noexcept {
    return in ? std::min(1.0, weight + fade_step_) : std::max(0.0, weight - fade_step_);
  }

  [[nodiscard]] const LawParams& params() const noexcept { return params_; }
  [[nodiscard]] bool faulted() const noexcept { return faulted_; }
  [[nodiscard]] double fade_step() const noexcept { return fade_step_; }
  [[nodiscard]] VelocityEstimator& estimator() noexcept { return estimator_; }
  [[nodiscard]] const VelocityEstimator& estimator() const noexcept { return estimator_; }
  [[nodiscard]] const UnilateralFixture& fixture() const noexcept { return fixture_; }
  [[nodiscard]] ActuatorLimiter& limiter() noexcept { return limiter_; }

 private:
  [[nodiscard]] static const LawParams& validated(const LawParams& params) {
    validate(params);
    return params;
  }

  LawParams params_{};
  Side side_;
  VelocityEstimator estimator_;
  UnilateralFixture fixture_;
  ActuatorLimiter limiter_;
  double fade_step_{1.0};  // weight change per sample
  bool faulted_{false};
};

// What both laws expose of their shared core, and the fault latch they share.
class LawBase {
 public:
  [[nodiscard]] bool faulted() const noexcept { return core_.faulted(); }
  [[nodiscard]] double velocity_m_per_s() const noexcept {
    return core_.estimator().velocity_m_per_s();
  }
  [[nodiscard]] const LawParams& params() const noexcept { return core_.params(); }

 protected:
  // Throws std::invalid_argument naming the field (validate()).
  LawBase(const LawParams& params, LawCore::Side side) : core_(params, side) {}
  TELEOP_RT [[nodiscard]] Command latch_fault() noexcept { return core_.latch_fault(); }

  LawCore core_;
};

}  // namespace teleop::control
