// Sensors and actuator of a simulated haptic paddle (Abbott-Okamura §4.1): an incremental
// encoder on the motor, a load cell at the handle and a current amplifier. Deterministic for a
// seed; the measure/apply calls are RT-safe (no allocation, no exception).
#pragma once

#include <cstdint>
#include <random>

#include "common/core/rt_safe.hpp"

namespace teleop::sim {

// Position along the handle's arc = motor angle / transmission ratio * metres per radian.
//
// counts_per_rev: counts per motor revolution as decoded (the paper's encoders: 500 per turn;
// use 2000 for x4 quadrature decoding of the same disc).
// transmission_ratio: motor turns per paddle turn. The paper does not give it. Haptic paddles
// drive a sector on the paddle from a small capstan on the motor shaft; single-stage capstan
// drives are 5:1 to 10:1, and a ~1 cm capstan on the paddle's ~10 cm sector gives ~10:1 - the
// upper end, which keeps the paddle backdrivable and makes its quantum 0.145 mm, the visible
// staircase the paper smooths before differentiating. A 10:1 drive would also fit the paper's
// 1.65 N/V = 5 N/A at 0.115 m (0.575 Nm/A at the paddle) with a motor torque constant of
// 57.5 mNm/A; the motor's constant is not in the paper either, so this is a documented
// assumption, configurable.
// metres_per_radian: 0.115 (1 rad of paddle = 115 mm of arc at the load cell).
struct EncoderParams {
  int counts_per_rev{500};
  double transmission_ratio{10.0};
  double metres_per_radian{0.115};
};

// Reads round(x / q) * q with q = 2 pi metres_per_radian / (counts_per_rev ratio): the origin
// sits at the centre of a count (as if indexed there), so a device at rest at 0 reads exactly 0
// and the quantisation error is within +-q/2, zero on average.
class Encoder {
 public:
  explicit Encoder(const EncoderParams& params);  // throws std::invalid_argument naming the field
  [[nodiscard]] double step_m() const noexcept { return step_m_; }
  TELEOP_RT [[nodiscard]] std::int64_t counts(double position_m) const noexcept;
  TELEOP_RT [[nodiscard]] double read_m(double position_m) const noexcept;

 private:
  double step_m_{0.0};
};

// Standard normal deviates from std::mt19937_64 by Box-Muller, written out so the sequence for a
// seed is the same with every standard library (std::normal_distribution's is not specified).
class NormalSource {
 public:
  explicit NormalSource(std::uint64_t seed) : engine_(seed) {}
  void reseed(std::uint64_t seed) noexcept;
  TELEOP_RT [[nodiscard]] double next() noexcept;

 private:
  TELEOP_RT [[nodiscard]] double uniform_open() noexcept;  // in (0, 1)
  std::mt19937_64 engine_;
  double spare_{0.0};
  bool has_spare_{false};
};

// The paper's Entran ELFS-T3E-10N: +-10 N.
struct LoadCellParams {
  double noise_std_N{0.0};
  double range_N{10.0};
  double bias_N{0.0};
  double resolution_N{0.0};  // quantum of the A/D chain; 0: continuous
};

struct LoadCellReading {
  double force_N{0.0};
  bool clipped{false};  // the true force plus bias and noise was outside +-range_N
};

// reading = clip(true + bias + noise, +-range), then quantised to resolution_N.
class LoadCell {
 public:
  LoadCell(const LoadCellParams& params, std::uint64_t seed);  // throws std::invalid_argument
  TELEOP_RT [[nodiscard]] LoadCellReading measure(double true_force_N) noexcept;
  void reseed(std::uint64_t seed) noexcept { noise_.reseed(seed); }
  [[nodiscard]] const LoadCellParams& params() const noexcept { return params_; }

 private:
  LoadCellParams params_{};
  NormalSource noise_;
};

// The paper's D/A (+-10 V) into current amplifiers at 1.65 N/V at the handle: at most 16.5 N.
struct AmplifierParams {
  double max_force_N{16.5};
};

struct AmplifierOutput {
  double force_N{0.0};
  bool saturated{false};
  bool rejected{false};  // non-finite command: nothing but 0 N reaches the motor
};

class Amplifier {
 public:
  explicit Amplifier(const AmplifierParams& params);  // throws std::invalid_argument
  TELEOP_RT [[nodiscard]] AmplifierOutput apply(double command_N) const noexcept;
  [[nodiscard]] const AmplifierParams& params() const noexcept { return params_; }

 private:
  AmplifierParams params_{};
};

}  // namespace teleop::sim
