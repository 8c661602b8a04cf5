// The n-axis plant (common/sim/plant_axes.hpp) against Eigen's own matrix exponential, the
// one-axis Plant (n = 1, and three decoupled axes), closed-form plane crossings, energy
// conservation of a lossless bounce, rotation invariance, and its validation.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <chrono>
#include <cmath>
#include <numbers>
#include <random>
#include <stdexcept>
#include <string>
#include <unsupported/Eigen/MatrixFunctions>
#include <vector>

#include "common/sim/plant.hpp"
#include "common/sim/plant_axes.hpp"

namespace teleop::sim {
namespace {

using std::chrono::milliseconds;

constexpr double kT = 1e-3;

AxesVector vec(std::initializer_list<double> values) {
  AxesVector v(static_cast<Eigen::Index>(values.size()));
  Eigen::Index i = 0;
  for (const double e : values) v(i++) = e;
  return v;
}

Eigen::VectorXd dyn(const AxesVector& v) { return v; }

PlantAxesParams device(const Eigen::MatrixXd& mass, const Eigen::VectorXd& damping) {
  PlantAxesParams p;
  p.device.mass_kg = mass;
  p.device.damping_Ns_per_m = damping;
  p.device.coulomb_N = Eigen::VectorXd::Zero(mass.rows());
  return p;
}

// A coupled 3 x 3 mass matrix (symmetric positive definite) and a coupled human.
Eigen::MatrixXd coupled_mass() {
  Eigen::MatrixXd m(3, 3);
  m << 0.30, 0.05, -0.02, 0.05, 0.25, 0.04, -0.02, 0.04, 0.40;
  return m;
}

// The reference: x(T), v(T) of M x'' + B x' + K x = g0 + g1 t from Eigen's expm of the
// augmented system [x; v; g0; g1] (unsupported/Eigen/MatrixFunctions, Pade with scaling and
// squaring: independent of the plant's Taylor series and doublings).
struct Reference {
  Eigen::MatrixXd phi;  // 4n x 4n
  int n;
  Reference(const Eigen::MatrixXd& m, const Eigen::MatrixXd& b, const Eigen::MatrixXd& k,
            double period_s)
      : n(static_cast<int>(m.rows())) {
    const Eigen::MatrixXd minv = m.inverse();
    Eigen::MatrixXd z = Eigen::MatrixXd::Zero(4 * n, 4 * n);
    z.block(0, n, n, n).setIdentity();
    z.block(n, 0, n, n) = -minv * k;
    z.block(n, n, n, n) = -minv * b;
    z.block(n, 2 * n, n, n) = minv;
    z.block(2 * n, 3 * n, n, n).setIdentity();
    phi = (z * period_s).exp();
  }
  void step(Eigen::VectorXd& x, Eigen::VectorXd& v, const Eigen::VectorXd& g0,
            const Eigen::VectorXd& g1) const {
    Eigen::VectorXd s(4 * n);
    s << x, v, g0, g1;
    const Eigen::VectorXd r = phi * s;
    x = r.head(n);
    v = r.segment(n, n);
  }
};

TEST(PlantAxesFree, CoupledMassMatchesEigenMatrixExponential) {
  const Eigen::MatrixXd m = coupled_mass();
  const Eigen::Vector3d b(2.0, 0.5, 3.0);
  PlantAxesParams p = device(m, b);
  Eigen::MatrixXd mh(3, 3);
  mh << 0.01, 0.002, 0.0, 0.002, 0.02, 0.0, 0.0, 0.0, 0.01;
  Eigen::MatrixXd bh(3, 3);
  bh << 1.5, 0.3, 0.1, 0.3, 1.0, -0.2, 0.1, -0.2, 2.0;
  Eigen::MatrixXd kh(3, 3);
  kh << 250.0, 40.0, 0.0, 40.0, 300.0, 20.0, 0.0, 20.0, 200.0;
  p.human = {mh, bh, kh};
  PlantAxes plant(p, milliseconds(1));
  const Reference ref(m + mh, Eigen::MatrixXd(b.asDiagonal()) + bh, kh, kT);
  PlantAxesState s0{vec({0.01, -0.02, 0.005}), vec({0.1, 0.0, -0.2})};
  plant.reset(s0);
  Eigen::VectorXd x = dyn(s0.position_m);
  Eigen::VectorXd v = dyn(s0.velocity_m_per_s);
  double worst = 0.0;
  for (int k = 0; k < 400; ++k) {
    const double t = k * kT;
    const AxesVector u = vec({std::sin(20.0 * t), 0.5 * std::cos(13.0 * t), -0.3});
    const AxesVector f = vec({1.0, -0.5, 0.2 * t});
    const AxesVector r = vec({3.0 * std::cos(7.0 * t), 0.0, -2.0});
    plant.step(u, f, r);
    ref.step(x, v, dyn(u) + dyn(f), dyn(r));
    worst = std::max(
        worst, (dyn(plant.state().position_m) - x).cwiseAbs().maxCoeff() / x.cwiseAbs().maxCoeff());
    worst = std::max(worst, (dyn(plant.state().velocity_m_per_s) - v).cwiseAbs().maxCoeff() /
                                v.cwiseAbs().maxCoeff());
    EXPECT_EQ(plant.output().events, 0);
  }
  EXPECT_LT(worst, 1e-12);
}

// ---- n = 1 against Plant ----

struct OneAxisCase {
  const char* name;
  double mass_kg, damping, coulomb_N;
  HumanImpedance human;
  bool tissue;
  double k_e, b_e, p_e;
  double slope_N_per_s;  // exogenous ramp within each period
};

// A sampled PD pushing 1 cm past the surface and back (as bench_plant's scenes).
double pd(double n, double x, double v) {
  const double xd = 0.02 + 0.02 * std::sin(2.0 * std::numbers::pi * 1.5 * n * kT);
  return 300.0 * (xd - x) - 3.0 * v;
}

TEST(PlantAxesOneAxis, EqualsPlant) {
  const OneAxisCase cases[] = {
      {"free with a finger", 0.040, 0.41, 0.0, {0.008, 1.5, 250.0}, false, 0, 0, 0, 0.0},
      {"tissue 2 kN/m", 0.036, 0.49, 0.0, {}, true, 2000.0, 2.0, 0.03, 0.0},
      {"tissue 1e5 N/m", 0.036, 0.49, 0.0, {}, true, 1e5, 20.0, 0.03, 0.0},
      {"Coulomb, tissue", 0.036, 0.49, 0.05, {}, true, 2000.0, 2.0, 0.03, 0.0},
      {"Coulomb, VP tissue, human, ramp",
       0.25,
       5.0,
       0.2,
       {0.01, 2.0, 100.0},
       true,
       125.0,
       0.0,
       0.03,
       40.0},
      {"Coulomb free, ramp", 0.25, 5.0, 0.4, {}, false, 0, 0, 0, -30.0},
  };
  for (const OneAxisCase& c : cases) {
    SCOPED_TRACE(c.name);
    PlantParams one;
    one.device = {c.mass_kg, c.damping};
    one.coulomb_friction_N = c.coulomb_N;
    one.human = c.human;
    if (c.tissue) one.environment = Environment::tissue(c.k_e, c.b_e, c.p_e);
    Plant plant(one, milliseconds(1));
    PlantAxesParams p =
        device(Eigen::MatrixXd::Constant(1, 1, c.mass_kg), Eigen::VectorXd::Constant(1, c.damping));
    p.device.coulomb_N = Eigen::VectorXd::Constant(1, c.coulomb_N);
    p.human = {Eigen::MatrixXd::Constant(1, 1, c.human.mass_kg),
               Eigen::MatrixXd::Constant(1, 1, c.human.damping_Ns_per_m),
               Eigen::MatrixXd::Constant(1, 1, c.human.stiffness_N_per_m)};
    if (c.tissue) p.planes.push_back({Eigen::VectorXd::Ones(1), c.p_e, c.k_e, c.b_e});
    PlantAxes axes(p, milliseconds(1));
    double dx = 0.0;
    double dv = 0.0;
    double df = 0.0;
    int events = 0;
    int rests = 0;
    for (int k = 0; k < 1500; ++k) {
      const double u = pd(k, plant.state().position_m, plant.state().velocity_m_per_s);
      const double f = 0.5 * std::sin(3.0 * k * kT);
      const PlantOutput& o = plant.step(u, f, c.slope_N_per_s);
      const PlantAxesOutput& oa = axes.step(vec({u}), vec({f}), vec({c.slope_N_per_s}));
      dx = std::max(dx, std::abs(axes.state().position_m(0) - plant.state().position_m));
      dv =
          std::max(dv, std::abs(axes.state().velocity_m_per_s(0) - plant.state().velocity_m_per_s));
      df = std::max(df, std::abs(-oa.environment_force_N(0) - o.environment_force_N));
      df = std::max(df, std::abs(oa.human_force_N(0) - o.human_force_N));
      EXPECT_EQ(oa.events, o.events) << "step " << k;
      EXPECT_EQ(oa.contact_mask != 0, o.in_contact) << "step " << k;
      EXPECT_EQ(oa.stuck_mask != 0, o.resting) << "step " << k;
      events += o.events;
      rests += o.resting ? 1 : 0;
    }
    EXPECT_LT(dx, 1e-14);
    EXPECT_LT(dv, 1e-12);
    EXPECT_LT(df, 1e-9);
    if (c.tissue || c.coulomb_N > 0.0) {
      EXPECT_GT(events, 0);  // the comparison saw switches
    }
    if (c.coulomb_N > 0.0) {
      EXPECT_GT(rests, 0);
    }
  }
}

// ---- three decoupled axes against three Plants ----

TEST(PlantAxesDiagonal, ThreeAxesEqualThreePlants) {
  struct Axis {
    double m, b, c;
    HumanImpedance h;
    double k_e, b_e, p_e;
    double phase;
  };
  const Axis axes[] = {{0.036, 0.49, 0.05, {}, 2000.0, 2.0, 0.03, 0.0},
                       {0.25, 5.0, 0.2, {0.01, 2.0, 100.0}, 125.0, 0.0, 0.03, 1.0},
                       {0.04, 0.41, 0.03, {0.008, 1.5, 250.0}, 1e5, 20.0, 0.035, 2.0}};
  std::vector<Plant> plants;
  PlantAxesParams p = device(Eigen::MatrixXd::Zero(3, 3), Eigen::VectorXd::Zero(3));
  p.device.coulomb_N = Eigen::VectorXd::Zero(3);
  p.human = {Eigen::MatrixXd::Zero(3, 3), Eigen::MatrixXd::Zero(3, 3), Eigen::MatrixXd::Zero(3, 3)};
  for (int i = 0; i < 3; ++i) {
    const Axis& a = axes[i];
    PlantParams one;
    one.device = {a.m, a.b};
    one.coulomb_friction_N = a.c;
    one.human = a.h;
    one.environment = Environment::tissue(a.k_e, a.b_e, a.p_e);
    plants.emplace_back(one, milliseconds(1));
    p.device.mass_kg(i, i) = a.m;
    p.device.damping_Ns_per_m(i) = a.b;
    p.device.coulomb_N(i) = a.c;
    p.human.mass_kg(i, i) = a.h.mass_kg;
    p.human.damping_Ns_per_m(i, i) = a.h.damping_Ns_per_m;
    p.human.stiffness_N_per_m(i, i) = a.h.stiffness_N_per_m;
    p.planes.push_back({Eigen::Vector3d::Unit(i), a.p_e, a.k_e, a.b_e});
  }
  // A fourth plane never reached: 16 contact sets x 7 stuck sets > 64 slots, so some modes
  // are computed inside step().
  p.planes.push_back({Eigen::Vector3d(1.0, 1.0, 1.0).normalized(), 1.0, 1000.0, 0.0});
  PlantAxes plant(p, milliseconds(1));
  double dx = 0.0;
  int mixed = 0;  // steps ending with some axes stuck and others moving
  for (int k = 0; k < 1500; ++k) {
    AxesVector u(3);
    AxesVector f(3);
    AxesVector r(3);
    for (int i = 0; i < 3; ++i) {
      const auto s = static_cast<std::size_t>(i);
      const double xd =
          0.02 + 0.02 * std::sin(2.0 * std::numbers::pi * 1.5 * k * kT + axes[i].phase);
      u(i) = 300.0 * (xd - plants[s].state().position_m) - 3.0 * plants[s].state().velocity_m_per_s;
      f(i) = 0.3 * std::cos(5.0 * k * kT + i);
      r(i) = i == 1 ? 20.0 : 0.0;
      plants[s].step(u(i), f(i), r(i));
    }
    const PlantAxesOutput& o = plant.step(u, f, r);
    for (int i = 0; i < 3; ++i) {
      dx = std::max(dx, std::abs(plant.state().position_m(i) -
                                 plants[static_cast<std::size_t>(i)].state().position_m));
    }
    if (o.stuck_mask != 0 && o.stuck_mask != 7U) ++mixed;
  }
  EXPECT_LT(dx, 1e-13);
  EXPECT_GT(mixed, 10);
  EXPECT_GT(plant.late_modes(), 0U);
}

// ---- a tilted plane ----

// Constant velocity into a plane n^T x = p (stiffness k, no damping) with M = m I, no B: the
// normal component is free flight until t* = (p - n^T x0) / (n^T v0), then
// d(t) = (v_n / w) sin(w (t - t*)) with w = sqrt(k / m); the tangential part keeps its velocity.
TEST(PlantAxesPlane, EntryTimeOfConstantVelocityTrajectory) {
  const double m = 0.2;
  const double k = 4000.0;
  const double w = std::sqrt(k / m);
  PlantAxesParams p = device(Eigen::Matrix3d::Identity() * m, Eigen::VectorXd::Zero(3));
  const Eigen::Vector3d n = Eigen::Vector3d(1.0, -2.0, 0.5).normalized();
  const double offset = 0.01;
  p.planes.push_back({n, offset, k, 0.0});
  PlantAxes plant(p, milliseconds(1));
  const Eigen::Vector3d v0(0.3, -0.2, 0.1);
  const double vn = n.dot(v0);
  ASSERT_GT(vn, 0.0);
  const double t_star = 3.37131e-3;  // inside the fourth period
  const Eigen::Vector3d x0 = n * offset - v0 * t_star + Eigen::Vector3d(0.002, 0.001, 0.0).cross(n);
  ASSERT_NEAR(n.dot(x0) + vn * t_star, offset, 1e-15);
  plant.reset({x0, v0});
  const AxesVector zero = AxesVector::Zero(3);
  for (int step = 1; step <= 8; ++step) {
    const PlantAxesOutput& o = plant.step(zero);
    const double t = step * kT;
    if (step == 4) {
      ASSERT_EQ(o.events, 1);
      EXPECT_NEAR(o.first_event_s, t_star - 3 * kT, 2.0 * std::ldexp(kT, -36));
    } else {
      EXPECT_EQ(o.events, 0) << step;
    }
    Eigen::Vector3d expected = x0 + v0 * t;
    if (t > t_star) {
      // Replace the free normal motion past the plane by the oscillation inside it.
      const double d = vn / w * std::sin(w * (t - t_star));
      expected += n * (offset + d - n.dot(expected));
    }
    EXPECT_LT((dyn(plant.state().position_m) - expected).norm(), 1e-13) << step;
  }
}

// Constant force from rest, coupled M, no damping: x(t) = x0 + a t^2 / 2 with a = M^-1 F;
// the plane n^T x = p is entered at t* = sqrt(2 (p - n^T x0) / n^T a).
TEST(PlantAxesPlane, EntryTimeOfConstantForceTrajectory) {
  PlantAxesParams p = device(coupled_mass(), Eigen::VectorXd::Zero(3));
  const Eigen::Vector3d n = Eigen::Vector3d(0.3, 1.0, -0.4).normalized();
  p.planes.push_back({n, 0.002, 3000.0, 5.0});
  PlantAxes plant(p, milliseconds(1));
  const Eigen::Vector3d force(0.5, 1.0, -0.2);
  const Eigen::Vector3d a = coupled_mass().inverse() * force;
  const double an = n.dot(a);
  ASSERT_GT(an, 0.0);
  const double t_star = std::sqrt(2.0 * 0.002 / an);  // from x0 = 0
  plant.reset({AxesVector::Zero(3), AxesVector::Zero(3)});
  const int entry_step = static_cast<int>(t_star / kT);
  for (int step = 0; step <= entry_step; ++step) {
    const PlantAxesOutput& o = plant.step(force);
    if (step < entry_step) {
      ASSERT_EQ(o.events, 0) << step;
    } else {
      ASSERT_GE(o.events, 1);
      EXPECT_NEAR(o.first_event_s, t_star - entry_step * kT, 2.0 * std::ldexp(kT, -36));
      EXPECT_EQ(o.contact_mask, 1U);
    }
  }
}

double energy(const Eigen::MatrixXd& m, const ContactPlane& plane, const PlantAxesState& s) {
  const Eigen::VectorXd v = dyn(s.velocity_m_per_s);
  const double d = std::max(0.0, plane.normal.dot(dyn(s.position_m)) - plane.offset_m);
  return 0.5 * v.dot(m * v) + 0.5 * plane.stiffness_N_per_m * d * d;
}

// No damping anywhere: kinetic plus plane energy is constant through entry, contact and exit.
TEST(PlantAxesPlane, LosslessBounceConservesEnergy) {
  const Eigen::MatrixXd m = coupled_mass();
  PlantAxesParams p = device(m, Eigen::VectorXd::Zero(3));
  p.planes.push_back({Eigen::Vector3d(1.0, 1.0, 0.0).normalized(), 0.004, 20000.0, 0.0});
  p.planes.push_back({Eigen::Vector3d(0.0, -0.6, 0.8), 0.5, 5000.0, 0.0});  // never reached
  PlantAxes plant(p, milliseconds(1));
  plant.reset({AxesVector::Zero(3), vec({0.2, 0.1, -0.05})});
  const double e0 = energy(m, p.planes[0], plant.state());
  double worst = 0.0;
  int contact_steps = 0;
  bool left = false;
  for (int k = 0; k < 200; ++k) {
    const PlantAxesOutput& o = plant.step(AxesVector::Zero(3));
    contact_steps += o.contact_mask != 0 ? 1 : 0;
    left = left || (contact_steps > 0 && o.contact_mask == 0);
    worst = std::max(worst, std::abs(energy(m, p.planes[0], plant.state()) - e0) / e0);
  }
  EXPECT_GT(contact_steps, 3);
  EXPECT_TRUE(left);
  // Leaving: the normal velocity reversed.
  EXPECT_LT(p.planes[0].normal.dot(dyn(plant.state().velocity_m_per_s)), 0.0);
  EXPECT_LT(worst, 1e-12);
}

// Rotating M, the planes, the start and the forces rotates the trajectory (B isotropic).
TEST(PlantAxesPlane, RotationInvariance) {
  std::mt19937 rng(7);
  std::normal_distribution<double> g(0.0, 1.0);
  Eigen::Matrix3d random;
  for (int i = 0; i < 9; ++i) random(i / 3, i % 3) = g(rng);
  Eigen::Matrix3d r = Eigen::HouseholderQR<Eigen::Matrix3d>(random).householderQ();
  if (r.determinant() < 0.0) r.col(0) *= -1.0;
  const Eigen::MatrixXd m = coupled_mass();
  PlantAxesParams a = device(m, Eigen::VectorXd::Constant(3, 1.5));
  a.planes.push_back({Eigen::Vector3d(1.0, 0.2, 0.0).normalized(), 0.003, 8000.0, 4.0});
  a.planes.push_back({Eigen::Vector3d(-0.3, 1.0, 0.5).normalized(), 0.002, 2000.0, 1.0});
  PlantAxesParams b = a;
  b.device.mass_kg = r * m * r.transpose();
  b.device.mass_kg = 0.5 * (b.device.mass_kg + b.device.mass_kg.transpose()).eval();
  for (ContactPlane& plane : b.planes) plane.normal = r * plane.normal;
  PlantAxes pa(a, milliseconds(1));
  PlantAxes pb(b, milliseconds(1));
  const Eigen::Vector3d v0(0.05, 0.08, 0.0);
  pa.reset({AxesVector::Zero(3), v0});
  pb.reset({AxesVector::Zero(3), r * v0});
  double worst = 0.0;
  unsigned seen = 0;
  for (int k = 0; k < 300; ++k) {
    const Eigen::Vector3d f(std::sin(0.02 * k), 0.4 * std::cos(0.03 * k), 0.1);
    const Eigen::Vector3d slope(5.0, -3.0, 0.0);
    const Eigen::Vector3d rf = r * f;
    const Eigen::Vector3d rs = r * slope;
    seen |= pa.step(f, AxesVector::Zero(3), slope).contact_mask;
    pb.step(rf, AxesVector::Zero(3), rs);
    worst = std::max(worst, (r * dyn(pa.state().position_m) - dyn(pb.state().position_m)).norm());
  }
  EXPECT_EQ(seen, 3U);  // both planes touched
  EXPECT_LT(worst, 1e-14);
}

// Friction holds axis 1 while axis 0 (frictionless, M diagonal, no damping) is pushed into a
// tilted plane n = (cos a, sin a) at speed v: inside, d(t) = (v cos a / w) sin(w (t - t_e)) with
// w = sqrt(k cos^2 a / m0), and the plane pushes axis 1 by k d sin a. Axis 1 breaks free when
// that reaches C_1: at t_b = t_e + asin(w C_1 / (k sin a v cos a)) / w.
TEST(PlantAxesFriction, StuckAxisBreaksFreeWhenThePlanePushExceedsFriction) {
  const double m0 = 0.1;
  const double k = 3000.0;
  const double c1 = 0.6;
  const double angle = 0.5;
  const double v = 0.2;
  PlantAxesParams p =
      device(Eigen::Vector2d(m0, 0.3).asDiagonal().toDenseMatrix(), Eigen::VectorXd::Zero(2));
  p.device.coulomb_N = Eigen::Vector2d(0.0, c1);
  const Eigen::Vector2d n(std::cos(angle), std::sin(angle));
  p.planes.push_back({n, 0.0, k, 0.0});
  PlantAxes plant(p, milliseconds(1));
  const double t_e = 0.4e-3;  // entry inside the first period
  const double x0 = -v * t_e;
  plant.reset({vec({x0, 0.0}), vec({v, 0.0})});
  const double w = std::sqrt(k * n(0) * n(0) / m0);
  const double t_b = t_e + std::asin(w * c1 / (k * n(1) * v * n(0))) / w;
  const int break_step = static_cast<int>(t_b / kT);
  ASSERT_GT(break_step, 0);
  for (int step = 0; step <= break_step; ++step) {
    const PlantAxesOutput& o = plant.step(AxesVector::Zero(2));
    if (step < break_step) {
      EXPECT_EQ(o.stuck_mask, 2U) << step;
      EXPECT_EQ(plant.state().position_m(1), 0.0);  // held exactly
      const double t = (step + 1) * kT;
      const double d = v * n(0) / w * std::sin(w * (t - t_e));
      EXPECT_NEAR(plant.state().position_m(0), d / n(0), 1e-15) << step;
    } else {
      ASSERT_EQ(o.events, 1);
      EXPECT_NEAR(o.first_event_s, t_b - break_step * kT, 2.0 * std::ldexp(kT, -36));
      EXPECT_EQ(o.stuck_mask, 0U);
      EXPECT_LT(plant.state().velocity_m_per_s(1), 0.0);  // pushed away from the plane
    }
  }
}

// ---- coupled contact and friction against a brute-force reference ----

// An independent n-axis reference: the same piecewise ODE and switching rules (plant_axes.hpp)
// integrated by classical RK4 in long double with a fine fixed step, every switch located by
// bisection on the step length, forces written out term by term; no matrix exponential, no
// dyadic grid, no code shared with the plant. Diagonal mass (friction needs it).
class ReferenceAxes {
 public:
  using Real = long double;
  using V = Eigen::Matrix<Real, Eigen::Dynamic, 1, 0, kMaxAxes, 1>;
  ReferenceAxes(const PlantAxesParams& p, Real period_s, int steps_per_period)
      : p_(p),
        n_(static_cast<int>(p.device.mass_kg.rows())),
        period_(period_s),
        h_(period_s / steps_per_period),
        x_(V::Zero(n_)),
        v_(V::Zero(n_)),
        kh_(p.human.stiffness_N_per_m.cast<Real>()),
        bh_(p.human.damping_Ns_per_m.cast<Real>()),
        b_(p.device.damping_Ns_per_m.cast<Real>()) {
    for (const ContactPlane& pl : p.planes) normals_.push_back(pl.normal.cast<Real>());
  }
  [[nodiscard]] const V& x() const { return x_; }

  void step(const Eigen::VectorXd& u, const Eigen::VectorXd& f0, const Eigen::VectorXd& f1) {
    g0_ = (u + f0).cast<Real>();
    g1_ = f1.cast<Real>();
    Real tau = 0;
    for (int events = 0; tau < period_ && events < 10000; ++events) {
      const Mode m = begin(tau);
      if (m.stuck == (1U << n_) - 1U) {
        const V p = applied(x_, v_, tau, m.contact);
        Real wait = std::numeric_limits<Real>::infinity();
        for (int i = 0; i < n_; ++i) {
          if (g1_(i) > 0) wait = std::min(wait, (fc(i) - p(i)) / g1_(i));
          if (g1_(i) < 0) wait = std::min(wait, (-fc(i) - p(i)) / g1_(i));
        }
        if (!(tau + wait < period_)) return;
        tau += std::max<Real>(wait, 0) * (1 + 1e-15L) + 1e-18L;
        continue;
      }
      tau = slide(m, tau);
    }
  }

 private:
  struct Mode {
    unsigned contact{0};
    unsigned stuck{0};
    std::vector<int> sign;
  };
  [[nodiscard]] Real fc(int i) const { return p_.device.coulomb_N(i); }
  [[nodiscard]] Real depth(std::size_t j, const V& x) const {
    return normals_[j].dot(x) - p_.planes[j].offset_m;
  }
  [[nodiscard]] unsigned touching(const V& x, const V& v) const {
    unsigned mask = 0;
    for (std::size_t j = 0; j < p_.planes.size(); ++j) {
      const ContactPlane& pl = p_.planes[j];
      const Real d = depth(j, x);
      if (d > 0 && pl.stiffness_N_per_m * d + pl.damping_Ns_per_m * normals_[j].dot(v) > 0) {
        mask |= 1U << j;
      }
    }
    return mask;
  }
  // Every force but friction.
  [[nodiscard]] V applied(const V& x, const V& v, Real tau, unsigned contact) const {
    V f = g0_ + g1_ * tau;
    f -= kh_ * x;
    f -= bh_ * v;
    f -= b_.cwiseProduct(v);
    for (std::size_t j = 0; j < p_.planes.size(); ++j) {
      if ((contact & (1U << j)) == 0) continue;
      const ContactPlane& pl = p_.planes[j];
      const V& n = normals_[j];
      f -= (pl.stiffness_N_per_m * depth(j, x) + pl.damping_Ns_per_m * n.dot(v)) * n;
    }
    return f;
  }
  [[nodiscard]] V accel(const V& x, const V& v, Real tau, const Mode& m) const {
    V a = applied(x, v, tau, m.contact);
    for (int i = 0; i < n_; ++i) {
      const Real mass = Real{p_.device.mass_kg(i, i)} + p_.human.mass_kg(i, i);
      a(i) = (m.stuck & (1U << i)) != 0
                 ? 0
                 : (a(i) - m.sign[static_cast<std::size_t>(i)] * fc(i)) / mass;
    }
    return a;
  }
  void rk4(V& x, V& v, Real tau, Real h, const Mode& m) const {
    const V k1x = v;
    const V k1v = accel(x, v, tau, m);
    const V k2x = v + h / 2 * k1v;
    const V k2v = accel(x + h / 2 * k1x, k2x, tau + h / 2, m);
    const V k3x = v + h / 2 * k2v;
    const V k3v = accel(x + h / 2 * k2x, k3x, tau + h / 2, m);
    const V k4x = v + h * k3v;
    const V k4v = accel(x + h * k3x, k4x, tau + h, m);
    x += h / 6 * (k1x + 2 * k2x + 2 * k3x + k4x);
    v += h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v);
  }
  [[nodiscard]] bool still(const Mode& m, const V& x, const V& v, Real tau) const {
    for (int i = 0; i < n_; ++i) {
      const int s = m.sign[static_cast<std::size_t>(i)];
      if (s != 0 && s * v(i) <= 0) return false;
    }
    if (touching(x, v) != m.contact) return false;
    const V p = applied(x, v, tau, m.contact);
    for (int i = 0; i < n_; ++i) {
      if ((m.stuck & (1U << i)) != 0 && !(p(i) >= -fc(i) && p(i) <= fc(i))) return false;
    }
    return true;
  }
  Mode begin(Real tau) const {
    Mode m;
    m.sign.assign(static_cast<std::size_t>(n_), 0);
    m.contact = touching(x_, v_);
    const V p = applied(x_, v_, tau, m.contact);
    for (int i = 0; i < n_; ++i) {
      if (!(fc(i) > 0)) continue;
      int& s = m.sign[static_cast<std::size_t>(i)];
      if (v_(i) != 0) {
        s = v_(i) > 0 ? 1 : -1;
      } else if (p(i) >= -fc(i) && p(i) <= fc(i)) {
        m.stuck |= 1U << i;
      } else {
        s = p(i) > 0 ? 1 : -1;
      }
    }
    return m;
  }
  Real slide(const Mode& m, Real tau) {
    while (tau < period_) {
      const Real h = std::min(h_, period_ - tau);
      V x = x_;
      V v = v_;
      rk4(x, v, tau, h, m);
      if (still(m, x, v, tau + h)) {
        x_ = x;
        v_ = v;
        tau += h;
        continue;
      }
      Real lo = 0;
      Real hi = h;
      for (int i = 0; i < 200 && hi - lo > std::numeric_limits<Real>::epsilon() * h; ++i) {
        const Real mid = (lo + hi) / 2;
        V xm = x_;
        V vm = v_;
        rk4(xm, vm, tau, mid, m);
        (still(m, xm, vm, tau + mid) ? lo : hi) = mid;
      }
      rk4(x_, v_, tau, hi, m);
      for (int i = 0; i < n_; ++i) {
        const int s = m.sign[static_cast<std::size_t>(i)];
        if (s != 0 && s * v_(i) <= 0) v_(i) = 0;
      }
      return tau + hi;
    }
    return tau;
  }

  PlantAxesParams p_;
  int n_;
  Real period_;
  Real h_;
  V x_;
  V v_;
  V g0_;
  V g1_;
  Eigen::Matrix<Real, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxAxes, kMaxAxes> kh_;
  Eigen::Matrix<Real, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxAxes, kMaxAxes> bh_;
  V b_;
  std::vector<V> normals_;
};

// Three axes, diagonal mass, friction on each, a coupled human stiffness and damping and two
// tilted planes (so held and sliding axes are coupled through K and B), driven by a sampled PD.
TEST(PlantAxesFriction, CoupledContactAndStickSlipMatchBruteForceReference) {
  PlantAxesParams p = device(Eigen::Vector3d(0.05, 0.08, 0.04).asDiagonal().toDenseMatrix(),
                             Eigen::Vector3d(0.5, 1.0, 0.4));
  p.device.coulomb_N = Eigen::Vector3d(0.08, 0.15, 0.05);
  Eigen::MatrixXd kh(3, 3);
  kh << 60.0, 25.0, 0.0, 25.0, 80.0, -15.0, 0.0, -15.0, 50.0;
  Eigen::MatrixXd bh(3, 3);
  bh << 0.5, 0.2, 0.0, 0.2, 0.4, 0.1, 0.0, 0.1, 0.3;
  p.human = {Eigen::MatrixXd::Zero(3, 3), bh, kh};
  p.planes.push_back({Eigen::Vector3d(1.0, 0.5, 0.2).normalized(), 0.012, 3000.0, 3.0});
  p.planes.push_back({Eigen::Vector3d(-0.2, 0.3, 1.0).normalized(), 0.010, 1500.0, 0.0});
  PlantAxes plant(p, milliseconds(1));
  ReferenceAxes ref(p, kT, 100);
  double worst = 0.0;
  int mixed = 0;
  unsigned contacts = 0;
  for (int k = 0; k < 800; ++k) {
    const double t = k * kT;
    Eigen::Vector3d xd(0.02 * std::sin(30.0 * t), 0.015 * std::sin(6.0 * t + 1.0),
                       0.02 * std::sin(12.0 * t + 2.0));
    const Eigen::VectorXd x = dyn(plant.state().position_m);
    const Eigen::VectorXd v = dyn(plant.state().velocity_m_per_s);
    const Eigen::VectorXd u = 150.0 * (xd - x) - 1.0 * v;
    const Eigen::Vector3d f(0.1, -0.05, 0.0);
    const Eigen::Vector3d slope(0.0, 30.0 * std::cos(4.0 * t), -20.0);
    const PlantAxesOutput& o = plant.step(u, f, slope);
    ref.step(u, f, slope);
    worst = std::max(
        worst, (dyn(plant.state().position_m) - ref.x().cast<double>()).cwiseAbs().maxCoeff());
    if (o.stuck_mask != 0 && o.stuck_mask != 7U) ++mixed;
    contacts |= o.contact_mask;
  }
  EXPECT_EQ(contacts, 3U);
  EXPECT_GT(mixed, 5);
  EXPECT_GT(plant.total_events(), 50U);
  EXPECT_LT(worst, 1e-12);
}

// ---- validation ----

TEST(PlantAxesValidation, OneAxisConversion) {
  PlantParams one;
  one.device = {0.04, 0.4};
  one.coulomb_friction_N = 0.05;
  one.human = {0.008, 1.5, 250.0};
  one.environment = Environment::tissue(1000.0, 1.0, 0.02);
  const PlantAxesParams p = to_axes(one);
  EXPECT_EQ(p.device.mass_kg(0, 0), 0.04);
  EXPECT_EQ(p.device.damping_Ns_per_m(0), 0.4);
  EXPECT_EQ(p.device.coulomb_N(0), 0.05);
  EXPECT_EQ(p.human.mass_kg(0, 0), 0.008);
  EXPECT_EQ(p.human.damping_Ns_per_m(0, 0), 1.5);
  EXPECT_EQ(p.human.stiffness_N_per_m(0, 0), 250.0);
  ASSERT_EQ(p.planes.size(), 1U);
  EXPECT_EQ(p.planes[0].normal(0), 1.0);
  EXPECT_EQ(p.planes[0].offset_m, 0.02);
  EXPECT_EQ(p.planes[0].stiffness_N_per_m, 1000.0);
  EXPECT_EQ(p.planes[0].damping_Ns_per_m, 1.0);
  one.environment = Environment::rigid_wall(0.02);
  try {
    (void)to_axes(one);
    ADD_FAILURE() << "a rigid wall accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("environment.kind"), std::string::npos);
  }
  one.environment = Environment::free_space();
  one.method = SteppingMethod::kSubSteps;
  try {
    (void)to_axes(one);
    ADD_FAILURE() << "sub-steps accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("method"), std::string::npos);
  }
}

void expect_error(const PlantAxesParams& p, const std::string& field) {
  try {
    const PlantAxes plant(p, milliseconds(1));
    ADD_FAILURE() << "accepted; expected an error naming " << field;
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
  }
}

TEST(PlantAxesValidation, ErrorsNameTheField) {
  const PlantAxesParams ok = device(coupled_mass(), Eigen::VectorXd::Ones(3));
  EXPECT_NO_THROW(PlantAxes(ok, milliseconds(1)));
  const double nan = std::numeric_limits<double>::quiet_NaN();
  PlantAxesParams p = ok;
  p.device.mass_kg(0, 1) = 0.2;  // not symmetric
  expect_error(p, "device.mass_kg");
  p = ok;
  p.device.mass_kg(2, 2) = -1.0;  // not positive definite
  expect_error(p, "device.mass_kg");
  p = ok;
  p.device.mass_kg = Eigen::MatrixXd::Identity(7, 7);
  expect_error(p, "device.mass_kg");
  p = ok;
  p.device.damping_Ns_per_m(1) = nan;
  expect_error(p, "device.damping_Ns_per_m");
  p = ok;
  p.device.damping_Ns_per_m = Eigen::VectorXd::Ones(2);
  expect_error(p, "device.damping_Ns_per_m");
  p = ok;
  p.device.coulomb_N = Eigen::Vector3d(0.1, 0.0, 0.0);  // coupled M with friction
  expect_error(p, "device.coulomb_N");
  p = ok;
  p.device.coulomb_N = Eigen::Vector3d(-0.1, 0.0, 0.0);
  expect_error(p, "device.coulomb_N");
  p = ok;
  p.human.stiffness_N_per_m = -Eigen::MatrixXd::Identity(3, 3);
  expect_error(p, "human.stiffness_N_per_m");
  p = ok;
  p.human.damping_Ns_per_m = Eigen::MatrixXd::Identity(2, 2);
  expect_error(p, "human.damping_Ns_per_m");
  p = ok;
  p.human.mass_kg = Eigen::MatrixXd::Constant(3, 3, std::numeric_limits<double>::infinity());
  expect_error(p, "human.mass_kg");
  p = ok;
  p.planes.assign(5, {Eigen::Vector3d::UnitX(), 0.0, 100.0, 0.0});
  expect_error(p, "planes");
  p = ok;
  p.planes = {{Eigen::Vector3d::UnitX(), 0.0, 100.0, 0.0}, {Eigen::Vector3d(1, 1, 0), 0, 1, 0}};
  expect_error(p, "planes[1].normal");
  p = ok;
  p.planes = {{Eigen::Vector3d::UnitX(), nan, 100.0, 0.0}};
  expect_error(p, "planes[0].offset_m");
  p = ok;
  p.planes = {{Eigen::Vector3d::UnitX(), 0.0, -100.0, 0.0}};
  expect_error(p, "planes[0].stiffness_N_per_m");
  p = ok;
  p.planes = {{Eigen::Vector3d::UnitX(), 0.0, 100.0, nan}};
  expect_error(p, "planes[0].damping_Ns_per_m");
  try {
    const PlantAxes plant(ok, std::chrono::nanoseconds(0));
    ADD_FAILURE() << "a zero period accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("period"), std::string::npos);
  }
  // A diagonal total mass with friction is fine, also with a coupled human stiffness.
  p = device(Eigen::Matrix3d(Eigen::Vector3d(0.1, 0.2, 0.3).asDiagonal()),
             Eigen::VectorXd::Ones(3));
  p.device.coulomb_N = Eigen::Vector3d(0.1, 0.0, 0.2);
  p.human.stiffness_N_per_m = Eigen::Matrix3d::Constant(10.0) + Eigen::Matrix3d::Identity();
  EXPECT_NO_THROW(PlantAxes(p, milliseconds(1)));
}

}  // namespace
}  // namespace teleop::sim
