#include "common/sim/sensors.hpp"

#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>

namespace teleop::sim {

namespace {

void require(bool ok, const char* field, const char* what) {
  if (!ok) throw std::invalid_argument(std::string(field) + " " + what);
}

}  // namespace

Encoder::Encoder(const EncoderParams& params) {
  require(params.counts_per_rev > 0, "encoder.counts_per_rev", "must be positive");
  require(std::isfinite(params.transmission_ratio) && params.transmission_ratio > 0.0,
          "encoder.transmission_ratio", "must be positive and finite");
  require(std::isfinite(params.metres_per_radian) && params.metres_per_radian > 0.0,
          "encoder.metres_per_radian", "must be positive and finite");
  step_m_ = 2.0 * std::numbers::pi * params.metres_per_radian /
            (static_cast<double>(params.counts_per_rev) * params.transmission_ratio);
}

std::int64_t Encoder::counts(double position_m) const noexcept {
  return static_cast<std::int64_t>(std::llround(position_m / step_m_));
}

double Encoder::read_m(double position_m) const noexcept {
  return static_cast<double>(counts(position_m)) * step_m_;
}

void NormalSource::reseed(std::uint64_t seed) noexcept {
  engine_.seed(seed);
  has_spare_ = false;
  spare_ = 0.0;
}

double NormalSource::uniform_open() noexcept {
  // 53 random bits, shifted off zero by half a quantum.
  return (static_cast<double>(engine_() >> 11) + 0.5) * 0x1.0p-53;
}

double NormalSource::next() noexcept {
  if (has_spare_) {
    has_spare_ = false;
    return spare_;
  }
  const double r = std::sqrt(-2.0 * std::log(uniform_open()));
  const double theta = 2.0 * std::numbers::pi * uniform_open();
  spare_ = r * std::sin(theta);
  has_spare_ = true;
  return r * std::cos(theta);
}

LoadCell::LoadCell(const LoadCellParams& params, std::uint64_t seed)
    : params_(params), noise_(seed) {
  require(std::isfinite(params.noise_std_N) && params.noise_std_N >= 0.0, "load_cell.noise_std_N",
          "must be >= 0 and finite");
  require(std::isfinite(params.range_N) && params.range_N > 0.0, "load_cell.range_N",
          "must be positive and finite");
  require(std::isfinite(params.bias_N), "load_cell.bias_N", "must be finite");
  require(std::isfinite(params.resolution_N) && params.resolution_N >= 0.0,
          "load_cell.resolution_N", "must be >= 0 and finite");
}

LoadCellReading LoadCell::measure(double true_force_N) noexcept {
  double f = true_force_N + params_.bias_N;
  if (params_.noise_std_N > 0.0) f += params_.noise_std_N * noise_.next();
  LoadCellReading r;
  if (!(f <= params_.range_N)) {  // also catches NaN
    r.clipped = true;
    f = std::isnan(f) ? 0.0 : params_.range_N;
  } else if (f < -params_.range_N) {
    r.clipped = true;
    f = -params_.range_N;
  }
  if (params_.resolution_N > 0.0) f = std::round(f / params_.resolution_N) * params_.resolution_N;
  r.force_N = f;
  return r;
}

Amplifier::Amplifier(const AmplifierParams& params) : params_(params) {
  require(std::isfinite(params.max_force_N) && params.max_force_N > 0.0, "amplifier.max_force_N",
          "must be positive and finite");
}

AmplifierOutput Amplifier::apply(double command_N) const noexcept {
  AmplifierOutput out;
  if (!std::isfinite(command_N)) {
    out.rejected = true;
    return out;
  }
  out.force_N = command_N;
  if (command_N > params_.max_force_N) {
    out.force_N = params_.max_force_N;
    out.saturated = true;
  } else if (command_N < -params_.max_force_N) {
    out.force_N = -params_.max_force_N;
    out.saturated = true;
  }
  return out;
}

}  // namespace teleop::sim
