// n-axis identification (issue 18 "identify"; Abbott-Okamura eqs. 32-35 in vector form).
// Expected values come from physics: the mass and damping the simulated devices are built with,
// a closed-form coupled steady-state response written out here, and the one-axis identify() on
// the same data for n = 1 - never from identify_axes() itself.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <chrono>
#include <cmath>
#include <complex>
#include <cstdint>
#include <iostream>
#include <numbers>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "common/sim/plant_axes.hpp"
#include "common/stability/identify.hpp"
#include "common/stability/identify_axes.hpp"

namespace teleop::stability {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kPeriodS = 1e-3;

// A tone per axis per frequency: amplitude (N), frequency (Hz), phase (rad).
struct Tone {
  double amplitude_N;
  double frequency_hz;
  double phase_rad;
};

// Seeded multisine excitation per axis: `tones` tones over [f_lo, f_hi] Hz, log-spaced, each
// axis offset in frequency so that no two axes share a tone, random phases. The phases come
// from the raw 64-bit engine output (portable across standard libraries).
[[nodiscard]] std::vector<std::vector<Tone>> multisine(int axes, std::uint64_t seed, int tones,
                                                       double f_lo, double f_hi,
                                                       double amplitude_N) {
  std::mt19937_64 engine(seed);
  std::vector<std::vector<Tone>> out(static_cast<std::size_t>(axes));
  for (int i = 0; i < axes; ++i) {
    for (int k = 0; k < tones; ++k) {
      const double frac = (static_cast<double>(k) + (static_cast<double>(i) + 0.5) / axes) / tones;
      const double f = f_lo * std::pow(f_hi / f_lo, frac);
      const double phase = static_cast<double>(engine() >> 11) * 0x1.0p-53 * 2.0 * kPi;
      out[static_cast<std::size_t>(i)].push_back({amplitude_N, f, phase});
    }
  }
  return out;
}

[[nodiscard]] double force_at(const std::vector<Tone>& tones, double t) {
  double f = 0.0;
  for (const Tone& k : tones)
    f += k.amplitude_N * std::sin(2.0 * kPi * k.frequency_hz * t + k.phase_rad);
  return f;
}

// The device simulated exactly (ZOH) by PlantAxes, its actuator force u_k held over period k;
// sample k records x(kT) and, as held_force_N, the force held over the period ending there
// (nothing before the first sample). The load cell reads nothing (force_N zero). Positions
// optionally quantised to `count_m` (an encoder in task space).
[[nodiscard]] SeriesAxes zoh_run(const Eigen::MatrixXd& mass, const Eigen::VectorXd& damping,
                                 const std::vector<std::vector<Tone>>& tones, int samples,
                                 double count_m = 0.0) {
  const Eigen::Index n = mass.rows();
  sim::PlantAxesParams p;
  p.device.mass_kg = mass;
  p.device.damping_Ns_per_m = damping;
  p.device.coulomb_N = Eigen::VectorXd::Zero(n);
  sim::PlantAxes plant(p, std::chrono::microseconds(1000));
  sim::PlantAxesState s0{sim::AxesVector::Zero(n), sim::AxesVector::Zero(n)};
  plant.reset(s0);
  SeriesAxes s;
  s.period_s = kPeriodS;
  s.position_m = Eigen::MatrixXd::Zero(samples, n);
  s.force_N = Eigen::MatrixXd::Zero(samples, n);
  s.held_force_N = Eigen::MatrixXd::Zero(samples, n);
  sim::AxesVector u(n);
  for (int k = 1; k < samples; ++k) {
    const double t = (k - 1) * kPeriodS;
    for (Eigen::Index i = 0; i < n; ++i) u(i) = force_at(tones[static_cast<std::size_t>(i)], t);
    plant.step(u);
    s.held_force_N.row(k) = u.transpose();
    for (Eigen::Index i = 0; i < n; ++i) {
      const double x = plant.state().position_m(i);
      s.position_m(k, i) = count_m > 0.0 ? count_m * std::round(x / count_m) : x;
    }
  }
  return s;
}

// The coupled test device: SPD mass with off-diagonals up to 1/3 of the diagonal, B diagonal
// (b/m about 10 /s, as the paper's paddles).
[[nodiscard]] Eigen::MatrixXd coupled_mass() {
  Eigen::MatrixXd m(3, 3);
  m << 0.30, 0.08, -0.05, 0.08, 0.25, 0.06, -0.05, 0.06, 0.40;
  return m;
}
[[nodiscard]] Eigen::VectorXd damping3() { return Eigen::Vector3d(3.0, 2.2, 4.5); }

// Largest relative error of the diagonal, and of the off-diagonals against the largest entry.
void expect_matrix_near(const Eigen::MatrixXd& got, const Eigen::MatrixXd& want, double rel,
                        const char* what) {
  ASSERT_EQ(got.rows(), want.rows()) << what;
  ASSERT_EQ(got.cols(), want.cols()) << what;
  const double scale = want.cwiseAbs().maxCoeff();
  for (Eigen::Index i = 0; i < want.rows(); ++i) {
    for (Eigen::Index j = 0; j < want.cols(); ++j) {
      const double tol = i == j ? rel * std::abs(want(i, j)) : rel * scale;
      EXPECT_NEAR(got(i, j), want(i, j), tol) << what << "(" << i + 1 << "," << j + 1 << ")";
    }
  }
}

[[nodiscard]] std::string message_of(const std::vector<SeriesAxes>& runs,
                                     const IdentifyAxesOptions& o = {}) {
  try {
    (void)identify_axes(runs, o);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "(no error)";
}

// --- n = 1: the one-axis identify() on the same data ----------------------------------------

[[nodiscard]] Series one_axis(const SeriesAxes& s) {
  Series out;
  out.period_s = s.period_s;
  out.time_s = s.time_s;
  for (Eigen::Index k = 0; k < s.position_m.rows(); ++k) {
    out.position_m.push_back(s.position_m(k, 0));
    out.force_N.push_back(s.force_N(k, 0));
    if (s.held_force_N.size() > 0) out.held_force_N.push_back(s.held_force_N(k, 0));
  }
  return out;
}

// Same rows, same column scaling, same SVD: the numbers are identical, not merely close.
TEST(IdentifyAxes, OneAxisGivesTheOneAxisIdentifyNumbers) {
  Eigen::MatrixXd m(1, 1);
  m << 0.040;
  const Eigen::VectorXd b = Eigen::VectorXd::Constant(1, 0.41);
  std::vector<SeriesAxes> runs = {zoh_run(m, b, multisine(1, 7, 8, 0.5, 12.0, 0.3), 4000, 1e-5),
                                  zoh_run(m, b, multisine(1, 8, 6, 1.0, 15.0, 0.2), 3000, 1e-5)};
  runs[1].force_N.col(0).setLinSpaced(0.0, 0.05);  // a load cell reading as well
  const IdentifyResult one = identify({one_axis(runs[0]), one_axis(runs[1])});
  for (const MassModel mass : {MassModel::kPerAxis, MassModel::kCoupled}) {
    for (const DampingModel damping : {DampingModel::kDiagonal, DampingModel::kFull}) {
      IdentifyAxesOptions o;
      o.mass = mass;
      o.damping = damping;
      const IdentifyAxesResult r = identify_axes(runs, o);
      EXPECT_EQ(r.mass_kg(0, 0), one.mass_kg);
      EXPECT_EQ(r.damping_Ns_per_m(0, 0), one.damping_Ns_per_m);
      EXPECT_EQ(r.r_squared, one.r_squared);
      EXPECT_EQ(r.residual_rms_N, one.residual_rms_N);
      EXPECT_EQ(r.condition_number, one.condition_number);
      EXPECT_EQ(r.samples, one.samples);
      EXPECT_EQ(r.parameters, 2U);
    }
  }
  // And the quantised paddle is identified at all (the one-axis test's bound, 1 %).
  EXPECT_NEAR(one.mass_kg, 0.040, 0.01 * 0.040);
  EXPECT_NEAR(one.damping_Ns_per_m, 0.41, 0.01 * 0.41);
}

// --- closed form: the coupled steady state ------------------------------------------------

// M x'' + B x' = F with F_i = sum A sin(w t + phi) per axis. Each tone's steady state is
// Im((-M w^2 + i B w)^{-1} A e^{i(w t + phi)} e_i); a device started on its steady state (x and
// x' at t = 0 taken from it) stays on it, so x(t) is the sum of the tones' steady states,
// sampled here with the force sampled at the same instants (a load cell).
[[nodiscard]] SeriesAxes closed_form_run(const Eigen::MatrixXd& mass,
                                         const Eigen::MatrixXd& damping,
                                         const std::vector<std::vector<Tone>>& tones, int samples) {
  const Eigen::Index n = mass.rows();
  SeriesAxes s;
  s.period_s = kPeriodS;
  s.position_m = Eigen::MatrixXd::Zero(samples, n);
  s.force_N = Eigen::MatrixXd::Zero(samples, n);
  using Complex = std::complex<double>;
  for (Eigen::Index i = 0; i < n; ++i) {
    for (const Tone& tone : tones[static_cast<std::size_t>(i)]) {
      const double w = 2.0 * kPi * tone.frequency_hz;
      const Eigen::MatrixXcd z =
          (-w * w) * mass.cast<Complex>() + Complex(0.0, w) * damping.cast<Complex>();
      const Eigen::VectorXcd h = z.partialPivLu().solve(Eigen::VectorXcd::Unit(n, i));
      for (int k = 0; k < samples; ++k) {
        const double t = k * kPeriodS;
        const Complex e = tone.amplitude_N * std::exp(Complex(0.0, w * t + tone.phase_rad));
        for (Eigen::Index j = 0; j < n; ++j) s.position_m(k, j) += (h(j) * e).imag();
        s.force_N(k, i) += e.imag();
      }
    }
  }
  return s;
}

// The filters are applied alike to every channel, so the fitted equation is eq. 32 through one
// linear filter: exact up to the five-point difference's error, (wT)^4 / 30 of the velocity
// and twice that of the acceleration, 2e-6 at 15 Hz and 1 kHz. A 1e-5 bound is that with margin.
TEST(IdentifyAxes, CoupledClosedFormIsRecoveredExactly) {
  const Eigen::MatrixXd m = coupled_mass();
  Eigen::MatrixXd b = damping3().asDiagonal();
  const auto tones = multisine(3, 11, 6, 0.7, 15.0, 0.5);
  const SeriesAxes s = closed_form_run(m, b, tones, 5000);
  const IdentifyAxesResult r = identify_axes({s});
  expect_matrix_near(r.mass_kg, m, 1e-5, "M");
  expect_matrix_near(r.damping_Ns_per_m, b, 1e-5, "B");
  EXPECT_TRUE(r.mass_positive_definite);
  EXPECT_GT(r.r_squared, 1.0 - 1e-9);
  EXPECT_EQ(r.parameters, 6U + 3U);
  EXPECT_EQ(r.samples, 5000U - 2U * (2U * 8U + 4U));
  // A full damping matrix (here with off-diagonals) is recovered when asked for.
  b(0, 1) = 0.4;
  b(2, 0) = -0.3;
  IdentifyAxesOptions full;
  full.damping = DampingModel::kFull;
  const IdentifyAxesResult f = identify_axes({closed_form_run(m, b, tones, 5000)}, full);
  expect_matrix_near(f.mass_kg, m, 1e-5, "M (full B)");
  expect_matrix_near(f.damping_Ns_per_m, b, 1e-5, "B (full)");
  EXPECT_EQ(f.parameters, 6U + 9U);
}

// --- the exact ZOH plant ------------------------------------------------------------------

// PlantAxes with the actuator force held over each period. The held force is centred on the
// sample as (h[k] + h[k+1]) / 2, whose response to a tone is cos(wT/2) against the staircase's
// fundamental sinc(wT/2) (both with the same half-period delay): the force is read low by
// 1 - cos(wT/2)/sinc(wT/2) = (wT)^2/12 + O((wT)^4), and M and B with it. At the top tone,
// 15 Hz, that is 7.4e-4; the other tones weigh in less. Bound: 1e-3 of each diagonal entry
// and 1e-3 of the largest entry for the off-diagonals.
TEST(IdentifyAxes, CoupledMassFromTheZohPlant) {
  const Eigen::MatrixXd m = coupled_mass();
  const Eigen::MatrixXd b = damping3().asDiagonal();
  const SeriesAxes s = zoh_run(m, damping3(), multisine(3, 21, 8, 0.5, 15.0, 1.0), 6000);
  const IdentifyAxesResult r = identify_axes({s});
  std::cout << "ZOH plant: M\n" << r.mass_kg << "\nB\n" << r.damping_Ns_per_m << "\n";
  expect_matrix_near(r.mass_kg, m, 1e-3, "M");
  expect_matrix_near(r.damping_Ns_per_m, b, 1e-3, "B");
  EXPECT_GT(r.r_squared, 0.9999);
  for (Eigen::Index i = 0; i < 3; ++i) EXPECT_GT(r.axis_r_squared(i), 0.9999);
  EXPECT_LT(r.condition_number, 100.0);
  // Per axis on a coupled device is the wrong model: the diagonal masses cannot absorb the
  // coupling, and the fit says so (a far larger residual).
  IdentifyAxesOptions per_axis;
  per_axis.mass = MassModel::kPerAxis;
  const IdentifyAxesResult d = identify_axes({s}, per_axis);
  EXPECT_GT(d.residual_rms_N, 10.0 * r.residual_rms_N);
}

// Encoder counts of q in task space: white quantisation noise of variance q^2/12 on x, which
// the acceleration filter h (8 passes, difference, 8 passes, difference) turns into noise of
// variance q^2/12 * sum h_k^2 on x''. Noise in a regressor attenuates its coefficient by
// var(noise) / var(x'') (errors in variables). Both are computed here independently of the code
// under test: h by convolving the stencils, var(x'') from the noise-free run's filtered x.
// Bound per diagonal entry: the ZOH bias (1e-3) plus 3 times that attenuation (the quantisation
// noise is not exactly white at these counts; 3 covers it and the sampling scatter).
[[nodiscard]] std::vector<double> convolve(const std::vector<double>& a,
                                           const std::vector<double>& b) {
  std::vector<double> out(a.size() + b.size() - 1, 0.0);
  for (std::size_t i = 0; i < a.size(); ++i) {
    for (std::size_t j = 0; j < b.size(); ++j) out[i + j] += a[i] * b[j];
  }
  return out;
}

TEST(IdentifyAxes, QuantisedPositionsWithinTheErrorsInVariablesBound) {
  std::vector<double> h = {1.0};
  const std::vector<double> average = {1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0};
  const std::vector<double> difference = {-1.0 / 12e-3, 8.0 / 12e-3, 0.0, -8.0 / 12e-3,
                                          1.0 / 12e-3};
  for (int pass = 0; pass < 2; ++pass) {
    for (int k = 0; k < 8; ++k) h = convolve(h, average);
    h = convolve(h, difference);
  }
  double h2 = 0.0;
  for (const double v : h) h2 += v * v;

  const Eigen::MatrixXd m = coupled_mass();
  const auto tones = multisine(3, 31, 8, 0.5, 15.0, 1.0);
  const double count_m = 2e-5;  // 20 um
  const SeriesAxes exact = zoh_run(m, damping3(), tones, 6000);
  const SeriesAxes quantised = zoh_run(m, damping3(), tones, 6000, count_m);
  const IdentifyAxesResult r = identify_axes({quantised});
  const double noise_var = count_m * count_m / 12.0 * h2;
  for (Eigen::Index i = 0; i < 3; ++i) {
    // var(x''_i) from the noise-free positions through h.
    double sum = 0.0;
    double sq = 0.0;
    int rows = 0;
    for (Eigen::Index k = static_cast<Eigen::Index>(h.size()); k < exact.position_m.rows(); ++k) {
      double a = 0.0;
      for (std::size_t j = 0; j < h.size(); ++j)
        a += h[j] * exact.position_m(k - static_cast<Eigen::Index>(j), i);
      sum += a;
      sq += a * a;
      ++rows;
    }
    const double var_a = sq / rows - (sum / rows) * (sum / rows);
    const double bound = 1e-3 + 3.0 * noise_var / var_a;
    std::cout << "axis " << i + 1 << ": attenuation bound " << bound << ", M_ii rel err "
              << (r.mass_kg(i, i) - m(i, i)) / m(i, i) << ", B_ii rel err "
              << (r.damping_Ns_per_m(i, i) - damping3()(i)) / damping3()(i) << "\n";
    EXPECT_LT(bound, 0.05);  // the bound is a meaningful one
    EXPECT_NEAR(r.mass_kg(i, i), m(i, i), bound * m(i, i));
    EXPECT_NEAR(r.damping_Ns_per_m(i, i), damping3()(i), bound * damping3()(i));
  }
}

// On a device whose mass is diagonal the coupled fit finds no coupling and agrees with the
// per-axis fit; per axis with diagonal B is n independent one-axis fits (block-diagonal D), so
// each axis matches identify() on that axis alone to rounding.
TEST(IdentifyAxes, CoupledAndPerAxisAgreeOnADiagonalDevice) {
  const Eigen::MatrixXd m = Eigen::Vector3d(0.30, 0.25, 0.40).asDiagonal();
  const SeriesAxes s = zoh_run(m, damping3(), multisine(3, 41, 8, 0.5, 15.0, 1.0), 5000);
  IdentifyAxesOptions per_axis;
  per_axis.mass = MassModel::kPerAxis;
  const IdentifyAxesResult c = identify_axes({s});
  const IdentifyAxesResult d = identify_axes({s}, per_axis);
  expect_matrix_near(c.mass_kg, m, 1e-3, "coupled M");
  expect_matrix_near(d.mass_kg, m, 1e-3, "per-axis M");
  expect_matrix_near(c.mass_kg, d.mass_kg, 1e-3, "coupled against per axis");
  expect_matrix_near(c.damping_Ns_per_m, d.damping_Ns_per_m, 1e-3, "B");
  EXPECT_EQ(d.parameters, 6U);
  for (Eigen::Index i = 0; i < 3; ++i) {
    SeriesAxes axis;
    axis.period_s = s.period_s;
    axis.position_m = s.position_m.col(i);
    axis.force_N = s.force_N.col(i);
    axis.held_force_N = s.held_force_N.col(i);
    const IdentifyResult one = identify({one_axis(axis)});
    EXPECT_NEAR(d.mass_kg(i, i), one.mass_kg, 1e-12 * one.mass_kg) << i;
    EXPECT_NEAR(d.damping_Ns_per_m(i, i), one.damping_Ns_per_m, 1e-12 * one.damping_Ns_per_m) << i;
    EXPECT_NEAR(d.axis_r_squared(i), one.r_squared, 1e-12) << i;
  }
}

// --- refusals -------------------------------------------------------------------------------

TEST(IdentifyAxesErrors, AnAxisNeverDrivenIsNamed) {
  auto tones = multisine(3, 51, 6, 0.5, 15.0, 1.0);
  tones[1] = {{0.0, 1.0, 0.0}};  // axis 2: no force at all
  // Coupled: axis 2 moves through the coupling but is never driven.
  const std::string coupled = message_of({zoh_run(coupled_mass(), damping3(), tones, 1000)});
  EXPECT_NE(coupled.find("run 1: axis 2 is never driven"), std::string::npos) << coupled;
  std::cout << coupled << "\n";
  // Diagonal: axis 2 never moves.
  const Eigen::MatrixXd diag = Eigen::Vector3d(0.30, 0.25, 0.40).asDiagonal();
  const std::string still = message_of({zoh_run(diag, damping3(), tones, 1000)});
  EXPECT_NE(still.find("run 1: axis 2 never moves"), std::string::npos) << still;
}

// Two axes of a symmetric device always driven by the same force move alike: the direction
// x_1 - x_2 is never excited and M_11 - M_12 + M_22 (and B_11 - B_22 ...) are not determined.
TEST(IdentifyAxesErrors, AnUnexcitedDirectionIsRefused) {
  Eigen::MatrixXd m(2, 2);
  m << 0.3, 0.1, 0.1, 0.3;
  const Eigen::VectorXd b = Eigen::Vector2d(2.0, 2.0);
  auto tones = multisine(2, 61, 6, 0.5, 15.0, 1.0);
  tones[1] = tones[0];
  const SeriesAxes s = zoh_run(m, b, tones, 1500);
  const std::string what = message_of({s});
  std::cout << what << "\n";
  EXPECT_NE(what.find("do not excite every direction"), std::string::npos) << what;
  EXPECT_NE(what.find("M("), std::string::npos) << what;
  // Per axis the same data are fine for each axis alone (but fit the wrong model).
  IdentifyAxesOptions per_axis;
  per_axis.mass = MassModel::kPerAxis;
  const IdentifyAxesResult r = identify_axes({s}, per_axis);
  EXPECT_NEAR(r.mass_kg(0, 0), 0.4, 0.01);  // M_11 + M_12: the axes move together
}

TEST(IdentifyAxesErrors, NonFiniteAndMalformedInputIsNamed) {
  const SeriesAxes good =
      zoh_run(coupled_mass(), damping3(), multisine(3, 71, 6, 0.5, 15.0, 1.0), 200);
  SeriesAxes bad = good;
  bad.position_m(5, 1) = std::nan("");
  EXPECT_NE(message_of({good, bad}).find("run 2: position_m[5] axis 2 is not finite"),
            std::string::npos)
      << message_of({good, bad});
  bad = good;
  bad.held_force_N(9, 2) = INFINITY;
  EXPECT_NE(message_of({bad}).find("held_force_N[9] axis 3 is not finite"), std::string::npos);
  bad = good;
  bad.force_N(0, 0) = -INFINITY;
  EXPECT_NE(message_of({bad}).find("force_N[0] axis 1 is not finite"), std::string::npos);
  bad = good;
  bad.force_N.conservativeResize(199, 3);
  EXPECT_NE(message_of({bad}).find("force_N is 199 x 3"), std::string::npos);
  bad = good;
  bad.position_m.conservativeResize(200, 2);
  EXPECT_NE(message_of({good, bad}).find("run 2: position_m has 2 axes but run 1 has 3"),
            std::string::npos);
  bad = good;
  bad.period_s = std::nan("");
  EXPECT_NE(message_of({bad}).find("run 1: axis 1: period_s must be positive"), std::string::npos)
      << message_of({bad});
  EXPECT_NE(message_of({}).find("no runs"), std::string::npos);
  IdentifyAxesOptions passes;
  passes.filter.smoothing_passes = 0;
  EXPECT_NE(message_of({good}, passes).find("filter.smoothing_passes must be in [1, 1000], got 0"),
            std::string::npos);
  bad = good;
  bad.position_m.conservativeResize(30, 3);
  bad.force_N.conservativeResize(30, 3);
  bad.held_force_N.conservativeResize(30, 3);
  EXPECT_NE(message_of({bad}).find("axis 1: too few samples"), std::string::npos)
      << message_of({bad});
  EXPECT_NE(message_of({SeriesAxes{1e-3, {}, Eigen::MatrixXd::Zero(50, 7), {}, {}}}).find("7 axes"),
            std::string::npos);
}

}  // namespace
}  // namespace teleop::stability
