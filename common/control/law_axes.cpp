#include "common/control/law_axes.hpp"

#include <algorithm>
#include <cstddef>
#include <utility>

namespace teleop::control {
namespace {

const LawAxesParams& validated(const LawAxesParams& params) {
  validate(params);
  return params;
}

template <std::size_t... I>
std::array<VelocityEstimator, kMaxAxes> make_estimators(const LawAxesParams& p,
                                                        std::index_sequence<I...> /*axes*/) {
  return {((void)I, VelocityEstimator(p.period_s, p.velocity_cutoff_hz))...};
}

// Axis i's limits; the unused axes have none.
ActuatorLimits axis_limits(const ActuatorLimitsAxes& l, int axes, std::size_t i) {
  const auto a = static_cast<Eigen::Index>(i);
  if (a >= axes) return {};
  return {l.max_force_N(a), l.max_rate_N_per_s(a)};
}

template <std::size_t... I>
std::array<ActuatorLimiter, kMaxAxes> make_limiters(const LawAxesParams& p, LawAxesCore::Side side,
                                                    std::index_sequence<I...> /*axes*/) {
  const ActuatorLimitsAxes& l =
      side == LawAxesCore::Side::kMaster ? p.master_actuator : p.slave_actuator;
  return {ActuatorLimiter(axis_limits(l, p.axes, I), p.period_s)...};
}

}  // namespace

LawAxesCore::LawAxesCore(const LawAxesParams& params, Side side)
    : params_(validated(params)),
      side_(side),
      estimators_(make_estimators(params, std::make_index_sequence<kMaxAxes>{})),
      limiters_(make_limiters(params, side, std::make_index_sequence<kMaxAxes>{})),
      planes_(side == Side::kMaster ? params.master_planes : params.slave_planes),
      fade_step_(params.clutch_fade_s > 0.0 ? std::min(1.0, params.period_s / params.clutch_fade_s)
                                            : 1.0) {}

void LawAxesCore::retune(const LawGainsAxes& gains, const PlaneSet& planes) noexcept {
  params_.gains = gains;
  (side_ == Side::kMaster ? params_.master_planes : params_.slave_planes) = planes;
  planes_ = planes;
}

CommandAxes LawAxesCore::latch_fault() noexcept {
  faulted_ = true;
  for (ActuatorLimiter& l : limiters_) l.set_last_output(0.0);
  CommandAxes out;
  out.force_N = AxisVector::Zero(params_.axes);
  out.fixture_force_N = AxisVector::Zero(params_.axes);
  out.flags.input_fault = true;
  return out;
}

void LawAxesCore::reset() noexcept {
  faulted_ = false;
  for (ActuatorLimiter& l : limiters_) l.set_last_output(0.0);
  for (VelocityEstimator& e : estimators_) e.reset();
}

void LawAxesCore::reset(const AxisVector& position_m) noexcept {
  faulted_ = false;
  for (ActuatorLimiter& l : limiters_) l.set_last_output(0.0);
  for (std::size_t i = 0; i < estimators_.size(); ++i) {
    const auto a = static_cast<Eigen::Index>(i);
    if (a < position_m.size() && std::isfinite(position_m(a))) {
      estimators_[i].reset(position_m(a));
    } else {
      estimators_[i].reset();
    }
  }
}

}  // namespace teleop::control
