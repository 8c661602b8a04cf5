// An independent reference for the plant: the same piecewise ODE and the same switching rules
// (documented in common/sim/plant.hpp) integrated by classical RK4 in long double with a fine
// fixed step, every switch located by bisection on the step length (RK4 restarted from the step
// start each time). It shares no code with the plant: no matrix exponential, no dyadic grid, the
// right-hand side written out force by force. Slow on purpose; used by the tests and by
// bench/bench_plant.cpp.
#pragma once

#include <algorithm>
#include <cmath>
#include <limits>

#include "common/sim/plant.hpp"

namespace teleop::sim::reference {

using Real = long double;

class ReferencePlant {
 public:
  ReferencePlant(const PlantParams& p, Real period_s, int steps_per_period)
      : p_(p), period_(period_s), h_(period_s / steps_per_period) {}

  void reset(Real x, Real v) {
    x_ = x;
    v_ = v;
  }
  [[nodiscard]] Real x() const { return x_; }
  [[nodiscard]] Real v() const { return v_; }

  // One period with actuator force u held and exogenous force f0 + f1 tau.
  void step(Real u, Real f0 = 0, Real f1 = 0) {
    u_ = u;
    f0_ = f0;
    f1_ = f1;
    Real tau = 0;
    for (int events = 0; tau < period_ && events < 10000; ++events) {
      const Mode mode = begin(tau);
      if (mode.resting) {
        const Real p = net(x_, tau, mode.contact);
        Real wait = std::numeric_limits<Real>::infinity();
        if (f1_ > 0 && !mode.at_wall) wait = (fc() - p) / f1_;
        if (f1_ < 0) wait = (-fc() - p) / f1_;
        if (!(tau + wait < period_)) return;
        // Just past the bound, so that begin() sees the device leave rest.
        tau += std::max<Real>(wait, 0) * (1 + 1e-15L) + 1e-18L;
        continue;
      }
      tau = slide(mode, tau);
    }
  }

 private:
  struct Mode {
    bool resting{false};
    bool at_wall{false};
    bool contact{false};
    int sign{0};
  };

  [[nodiscard]] Real fc() const { return p_.coulomb_friction_N; }
  [[nodiscard]] Real mass() const { return Real{p_.device.mass_kg} + p_.human.mass_kg; }
  [[nodiscard]] bool tissue() const { return p_.environment.kind == EnvironmentKind::kTissue; }
  [[nodiscard]] bool wall() const { return p_.environment.kind == EnvironmentKind::kRigidWall; }
  [[nodiscard]] Real surface() const { return p_.environment.position_m; }

  [[nodiscard]] bool touching(Real x, Real v) const {
    if (!tissue()) return false;
    const Real depth = x - surface();
    return depth > 0 && Real{p_.environment.stiffness_N_per_m} * depth +
                                Real{p_.environment.damping_Ns_per_m} * v >
                            0;
  }

  // Everything but friction and the wall reaction, at v = 0.
  [[nodiscard]] Real net(Real x, Real tau, bool contact) const {
    Real f = u_ + f0_ + f1_ * tau - Real{p_.human.stiffness_N_per_m} * x;
    if (contact) f -= Real{p_.environment.stiffness_N_per_m} * (x - surface());
    return f;
  }

  [[nodiscard]] Real accel(Real x, Real v, Real tau, const Mode& m) const {
    Real f = u_ + f0_ + f1_ * tau;
    f -= (Real{p_.device.damping_Ns_per_m} + p_.human.damping_Ns_per_m) * v;
    f -= Real{p_.human.stiffness_N_per_m} * x;
    f -= m.sign * fc();
    if (m.contact) {
      f -= Real{p_.environment.stiffness_N_per_m} * (x - surface()) +
           Real{p_.environment.damping_Ns_per_m} * v;
    }
    return f / mass();
  }

  void rk4(Real& x, Real& v, Real tau, Real h, const Mode& m) const {
    const Real k1x = v;
    const Real k1v = accel(x, v, tau, m);
    const Real k2x = v + h / 2 * k1v;
    const Real k2v = accel(x + h / 2 * k1x, k2x, tau + h / 2, m);
    const Real k3x = v + h / 2 * k2v;
    const Real k3v = accel(x + h / 2 * k2x, k3x, tau + h / 2, m);
    const Real k4x = v + h * k3v;
    const Real k4v = accel(x + h * k3x, k4x, tau + h, m);
    x += h / 6 * (k1x + 2 * k2x + 2 * k3x + k4x);
    v += h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v);
  }

  [[nodiscard]] bool still(const Mode& m, Real x, Real v) const {
    if (m.sign != 0 && m.sign * v <= 0) return false;
    if (touching(x, v) != m.contact) return false;
    if (wall() && x >= surface()) return false;
    return true;
  }

  Mode begin(Real tau) {
    Mode m;
    if (wall() && (x_ > surface() || (x_ == surface() && v_ >= 0))) {
      x_ = surface();
      v_ = 0;
      m.at_wall = true;
    }
    if (v_ == 0 && (fc() > 0 || m.at_wall)) {
      m.contact = touching(x_, 0);
      const Real p = net(x_, tau, m.contact);
      const Real upper = m.at_wall ? std::numeric_limits<Real>::infinity() : fc();
      if (p >= -fc() && p <= upper) {
        m.resting = true;
        return m;
      }
      m.at_wall = false;
      m.sign = fc() > 0 ? (p > 0 ? 1 : -1) : 0;
      return m;
    }
    m.sign = fc() > 0 ? (v_ > 0 ? 1 : -1) : 0;
    m.contact = touching(x_, v_);
    return m;
  }

  // Integrates until the period ends or the mode changes; returns the new time.
  Real slide(const Mode& m, Real tau) {
    while (tau < period_) {
      const Real h = std::min(h_, period_ - tau);
      Real x = x_;
      Real v = v_;
      rk4(x, v, tau, h, m);
      if (still(m, x, v)) {
        x_ = x;
        v_ = v;
        tau += h;
        continue;
      }
      Real lo = 0;
      Real hi = h;
      for (int i = 0; i < 200 && hi - lo > std::numeric_limits<Real>::epsilon() * h; ++i) {
        const Real mid = (lo + hi) / 2;
        Real xm = x_;
        Real vm = v_;
        rk4(xm, vm, tau, mid, m);
        (still(m, xm, vm) ? lo : hi) = mid;
      }
      rk4(x_, v_, tau, hi, m);
      if (m.sign != 0 && m.sign * v_ <= 0) v_ = 0;
      return tau + hi;
    }
    return tau;
  }

  PlantParams p_;
  Real period_;
  Real h_;
  Real x_{0};
  Real v_{0};
  Real u_{0};
  Real f0_{0};
  Real f1_{0};
};

}  // namespace teleop::sim::reference
