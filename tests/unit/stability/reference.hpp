// An independent high-precision reference for the stability tests: 50-digit arithmetic, the
// ZOH by an unscaled Taylor series, the closed loop as a transfer-function polynomial (the
// paper's block diagram, eqs. 21-27) and its roots by Aberth-Ehrlich iteration. It shares no
// code and no realisation with the engine under test.
#pragma once

#include <algorithm>
#include <boost/math/constants/constants.hpp>
#include <boost/multiprecision/cpp_bin_float.hpp>
#include <boost/multiprecision/cpp_complex.hpp>
#include <complex>
#include <utility>
#include <vector>

namespace teleop::reference {

using Real = boost::multiprecision::cpp_bin_float_50;
using Complex = boost::multiprecision::cpp_complex_50;
using Poly = std::vector<Real>;  // ascending powers of z

struct Zoh {
  Real phi[2][2];
  Real gamma[2];
};

// exp([[A, B], [0, 0]] T) by the plain Taylor series: no scaling and squaring, 50 digits.
inline Zoh zoh(const Real& m, const Real& b, const Real& k, const Real& t) {
  const Real a[2][2] = {{Real(0), Real(1)}, {-k / m, -b / m}};
  Real term[2][2] = {{Real(1), Real(0)}, {Real(0), Real(1)}};  // (A t)^n / n!
  Zoh z{};
  Real integral[2][2] = {{t, Real(0)}, {Real(0), t}};  // sum A^n t^{n+1}/(n+1)!
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 2; ++j) z.phi[i][j] = term[i][j];
  for (int n = 1; n < 2000; ++n) {
    Real next[2][2];
    for (int i = 0; i < 2; ++i)
      for (int j = 0; j < 2; ++j)
        next[i][j] = (a[i][0] * term[0][j] + a[i][1] * term[1][j]) * t / n;
    Real biggest = 0;
    for (int i = 0; i < 2; ++i)
      for (int j = 0; j < 2; ++j) {
        term[i][j] = next[i][j];
        z.phi[i][j] += term[i][j];
        integral[i][j] += term[i][j] * t / (n + 1);
        biggest = std::max(biggest, Real(abs(term[i][j])));
      }
    if (n > 10 && biggest < Real("1e-60")) break;
  }
  z.gamma[0] = integral[0][1] / m;
  z.gamma[1] = integral[1][1] / m;
  return z;
}

inline Poly mul(const Poly& p, const Poly& q) {
  Poly r(p.size() + q.size() - 1, Real(0));
  for (std::size_t i = 0; i < p.size(); ++i)
    for (std::size_t j = 0; j < q.size(); ++j) r[i + j] += p[i] * q[j];
  return r;
}
inline Poly add(Poly p, const Poly& q, const Real& scale = Real(1)) {
  if (q.size() > p.size()) p.resize(q.size(), Real(0));
  for (std::size_t i = 0; i < q.size(); ++i) p[i] += scale * q[i];
  return p;
}
inline Poly shift(const Poly& p, int d) {  // p * z^d
  Poly r(static_cast<std::size_t>(d), Real(0));
  r.insert(r.end(), p.begin(), p.end());
  return r;
}

// X(z)/U(z) = N(z)/D(z) of the ZOH plant, from C adj(zI - phi) gamma.
inline void plant_tf(const Zoh& z, Poly& num, Poly& den) {
  den = {z.phi[0][0] * z.phi[1][1] - z.phi[0][1] * z.phi[1][0], -(z.phi[0][0] + z.phi[1][1]),
         Real(1)};
  num = {z.phi[0][1] * z.gamma[1] - z.phi[1][1] * z.gamma[0], z.gamma[0]};
}

struct LoopSpec {
  double t{0.002};
  double mm{0.04}, bm{0.41}, mh{0}, bh{0}, kh{0};
  double ms{0.036}, bs{0.49};
  double kpm{0}, kps{0}, kdm{0}, kds{0}, kvm{0}, kvs{0};
  double alpha{1}, beta{1};
  double kmvf{0}, ksvf{0};
  double cutoff_hz{0};
  int delay{0};
};

// The low-pass pole r = e^{-2 pi fc T} and gain a = 1 - r (r = 0, a = 1: no filter).
inline std::pair<Real, Real> velocity_filter(const LoopSpec& s) {
  if (s.cutoff_hz <= 0) return {Real(0), Real(1)};
  const Real r = exp(-2 * boost::math::constants::pi<Real>() * Real(s.cutoff_hz) * Real(s.t));
  return {r, 1 - r};
}

// Characteristic polynomial of the bilateral loop (docs/architecture.md §2.4-2.5): with
// V(z) = a(z-1)/(T(z-r)), [D_m(z-r) + N_m P_mm] z^d [D_s(z-r) + N_s Q_ss] - N_m P_ms N_s Q_sm.
inline Poly bilateral_polynomial(const LoopSpec& s) {
  const Real t(s.t);
  const auto [r, a] = velocity_filter(s);
  Poly nm, dm, ns, ds;
  plant_tf(zoh(Real(s.mm) + s.mh, Real(s.bm) + s.bh, Real(s.kh), t), nm, dm);
  plant_tf(zoh(Real(s.ms), Real(s.bs), Real(0), t), ns, ds);
  const Poly zr = {-r, Real(1)};
  const Poly z1 = {Real(-1), Real(1)};
  const Real at = a / t;
  const Real beta(s.beta), alpha(s.alpha);
  const Poly pmm = add(mul({beta * s.kpm + s.kmvf}, zr), mul({at * (beta * s.kdm + s.kvm)}, z1));
  const Poly pms = add(mul({beta / alpha * s.kpm}, zr), mul({beta / alpha * at * s.kdm}, z1));
  const Poly qsm = add(mul({alpha * s.kps}, zr), mul({alpha * at * s.kds}, z1));
  const Poly qss = add(mul({Real(s.kps) + s.ksvf}, zr), mul({at * (Real(s.kds) + s.kvs)}, z1));
  const Poly left = add(mul(dm, zr), mul(nm, pmm));
  const Poly right = shift(add(mul(ds, zr), mul(ns, qss)), s.delay);
  return add(mul(left, right), mul(mul(nm, pms), mul(ns, qsm)), Real(-1));
}

// The master with its human and wall alone (the slave does not follow): D_m(z-r) + N_m P_mm.
inline Poly master_polynomial(const LoopSpec& s) {
  const Real t(s.t);
  const auto [r, a] = velocity_filter(s);
  Poly nm, dm;
  plant_tf(zoh(Real(s.mm) + s.mh, Real(s.bm) + s.bh, Real(s.kh), t), nm, dm);
  const Poly zr = {-r, Real(1)};
  const Poly z1 = {Real(-1), Real(1)};
  const Real beta(s.beta);
  const Poly pmm = add(mul({beta * s.kpm + s.kmvf}, zr), mul({a / t * (beta * s.kdm + s.kvm)}, z1));
  return add(mul(dm, zr), mul(nm, pmm));
}

// The slave alone (master unactuated): D_s(z-r) + N_s Q_ss.
inline Poly slave_polynomial(const LoopSpec& s) {
  const Real t(s.t);
  const auto [r, a] = velocity_filter(s);
  Poly ns, ds;
  plant_tf(zoh(Real(s.ms), Real(s.bs), Real(0), t), ns, ds);
  const Poly zr = {-r, Real(1)};
  const Poly z1 = {Real(-1), Real(1)};
  const Poly qss = add(mul({Real(s.kps) + s.ksvf}, zr), mul({a / t * (Real(s.kds) + s.kvs)}, z1));
  return add(mul(ds, zr), mul(ns, qss));
}

// All roots by Aberth-Ehrlich; exact zero roots (a z^k factor) are split off first.
inline std::vector<Complex> roots(Poly p) {
  while (p.size() > 1 && p.back() == 0) p.pop_back();
  std::vector<Complex> out;
  std::size_t lead_zeros = 0;
  while (lead_zeros + 1 < p.size() && abs(p[lead_zeros]) < Real("1e-45") * abs(p.back())) {
    ++lead_zeros;
  }
  for (std::size_t i = 0; i < lead_zeros; ++i) out.emplace_back(0);
  p.erase(p.begin(), p.begin() + static_cast<long>(lead_zeros));
  const std::size_t n = p.size() - 1;
  if (n == 0) return out;
  std::vector<Complex> z(n);
  for (std::size_t i = 0; i < n; ++i) {
    const double ang =
        2.0 * 3.141592653589793 * (static_cast<double>(i) + 0.25) / static_cast<double>(n);
    z[i] = Complex(Real(0.9 * std::cos(ang)), Real(0.9 * std::sin(ang)));
  }
  auto eval = [&](const Complex& x, Complex& f, Complex& df) {
    f = Complex(0);
    df = Complex(0);
    for (std::size_t i = p.size(); i-- > 0;) {
      df = df * x + f;
      f = f * x + Complex(p[i]);
    }
  };
  for (int iter = 0; iter < 500; ++iter) {
    Real biggest = 0;
    for (std::size_t i = 0; i < n; ++i) {
      Complex f, df;
      eval(z[i], f, df);
      const Complex ratio = f / df;
      Complex sum(0);
      for (std::size_t j = 0; j < n; ++j)
        if (j != i) sum += Complex(1) / (z[i] - z[j]);
      const Complex w = ratio / (Complex(1) - ratio * sum);
      z[i] -= w;
      biggest = std::max(biggest, Real(abs(w)));
    }
    if (biggest < Real("1e-40")) break;
  }
  out.insert(out.end(), z.begin(), z.end());
  return out;
}

inline std::complex<double> to_double(const Complex& c) {
  return {static_cast<double>(c.real()), static_cast<double>(c.imag())};
}

inline double spectral_radius(const std::vector<Complex>& rts) {
  double r = 0;
  for (const Complex& c : rts) r = std::max(r, static_cast<double>(abs(c)));
  return r;
}

}  // namespace teleop::reference
