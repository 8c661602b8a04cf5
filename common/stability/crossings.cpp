#include "common/stability/crossings.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <stdexcept>

namespace teleop::stability {

namespace {

using Cd = std::complex<double>;
constexpr double kPi = std::numbers::pi;
// Neighbouring samples along the boundary differ by less than a quarter turn in the phase of
// every tracked function (det(zI - A(0)) and the numerator of G, or the loop's determinant at
// K): the phase of G then turns by less than pi between them, so a crossing is one sign change
// of sin(arg G), and a count of zeros is an unwrapped phase.
constexpr double kMinWidth = 1e-12;  // rad: the finest the sampler splits
constexpr int kCoreCapacity = 16;    // the core is 6x6 at most in this model

// The principal argument in (-pi, pi], -0 read as +0 (so -1 - 0i is at +pi, as the axis
// crossings below count it).
double argument(Cd c) { return std::atan2(c.imag() + 0.0, c.real()); }

// More than a quarter turn from `from` to `to`, or more than an eighth with `strict` (scale-free:
// no square roots, no atan2). Strict near the real axis: a mode pair close to z = 1 (a slow
// mode at a high rate) turns the phase by about 3/2 pi within one interval, which would read
// as a quarter turn back.
bool too_far(Cd from, Cd to, bool strict) {
  const double dot = from.real() * to.real() + from.imag() * to.imag();
  if (dot < 0.0) return true;
  constexpr double kCos2EighthTurn = 0.85355339059327373;  // cos^2(pi / 8)
  return strict && dot * dot < kCos2EighthTurn * std::norm(from) * std::norm(to);
}

// The width of the first and last intervals of the initial grid, where too_far is strict.
double end_zone(int order) { return kPi / (4 * order + 8); }

// Uniform in theta (4 per mode and 8 more), and geometric below the first step down to 1/4096
// of it: a slow mode at a high rate sits at theta = omega T, and several such modes together can
// turn the phase by whole turns within the first uniform step, which no phase test sees.
std::vector<double> initial_grid(int order) {
  const int intervals = 4 * order + 8;
  const double first = kPi / intervals;
  std::vector<double> grid{0.0};
  for (int k = 12; k >= 1; --k) grid.push_back(std::ldexp(first, -k));
  for (int j = 1; j <= intervals; ++j) grid.push_back(j == intervals ? kPi : kPi * j / intervals);
  return grid;
}

Cd unit(Cd c) {
  const double a = std::sqrt(std::norm(c));
  return a > 0.0 && std::isfinite(a) ? c / a : Cd(1.0, 0.0);
}

}  // namespace

AdmissibleBoundary::AdmissibleBoundary(double required_damping_ratio) {
  const double z = std::clamp(required_damping_ratio, 0.0, 0.999999);
  kappa_ = z / std::sqrt((1.0 - z) * (1.0 + z));
}

std::complex<double> AdmissibleBoundary::at(double theta) const {
  const double r = std::exp(-kappa_ * theta);
  if (theta == 0.0) return {1.0, 0.0};
  if (theta == kPi) return {-r, 0.0};  // exactly real: G is real there
  return std::polar(r, theta);
}

RankOneLoop::RankOneLoop(const ModelBlock& at_zero, const ModelBlock& at_one, int position_state) {
  const Eigen::MatrixXd& a0 = at_zero.a;
  const auto n = static_cast<int>(a0.rows());
  if (at_one.a.rows() != n || at_one.a.cols() != n || position_state < 0 || position_state >= n) {
    throw std::invalid_argument("rank-one loop: the two blocks do not match");
  }
  const Eigen::MatrixXd diff = at_one.a - a0;
  for (int j = 0; j < n; ++j) {
    if (j != position_state && !diff.col(j).isZero(0.0)) {
      throw std::invalid_argument("rank-one loop: the stiffness enters more than one column");
    }
  }
  delay_ = at_zero.delay;
  const int first = at_zero.delay_first;
  std::vector<int> core;
  for (int i = 0; i < n; ++i) {
    if (delay_ == 0 || i < first || i >= first + delay_) core.push_back(i);
  }
  m_ = static_cast<int>(core.size());
  if (m_ > kCoreCapacity) throw std::invalid_argument("rank-one loop: core too large");
  auto core_index = [&](int state) {
    const auto it = std::find(core.begin(), core.end(), state);
    if (it == core.end()) throw std::invalid_argument("rank-one loop: state in the delay chain");
    return static_cast<int>(it - core.begin());
  };
  core_.resize(m_, m_);
  u_.resize(m_);
  link_ = Eigen::VectorXd::Zero(m_);
  for (int a = 0; a < m_; ++a) {
    u_(a) = diff(core[static_cast<std::size_t>(a)], position_state);
    for (int b = 0; b < m_; ++b) {
      core_(a, b) = a0(core[static_cast<std::size_t>(a)], core[static_cast<std::size_t>(b)]);
    }
  }
  position_ = core_index(position_state);
  if (delay_ > 0) {
    for (int i = first; i < first + delay_; ++i) {
      if (diff(i, position_state) != 0.0) {
        throw std::invalid_argument("rank-one loop: the stiffness enters the delay chain");
      }
    }
    const int last = first + delay_ - 1;
    for (int a = 0; a < m_; ++a) {
      const int row = core[static_cast<std::size_t>(a)];
      link_(a) = a0(row, last);
      for (int j = first; j < last; ++j) {
        if (a0(row, j) != 0.0) {
          throw std::invalid_argument("rank-one loop: an inner delayed state is read");
        }
      }
    }
    source_ = core_index(at_zero.delay_source);
  }
  neg_core_.resize(static_cast<std::size_t>(m_ * m_));
  u_rm_.resize(static_cast<std::size_t>(m_));
  link_rm_.resize(static_cast<std::size_t>(m_));
  for (int a = 0; a < m_; ++a) {
    for (int b = 0; b < m_; ++b) neg_core_[static_cast<std::size_t>(a * m_ + b)] = -core_(a, b);
    u_rm_[static_cast<std::size_t>(a)] = u_(a);
    link_rm_[static_cast<std::size_t>(a)] = link_(a);
  }
}

namespace {

// The bordered matrix B = [[M, u], [e_p^T, 0]] eliminated with partial pivoting, solving
// B y = e_last. det B = P1, the numerator of G (det(M - K u e_p^T) = det M + K det B), and
// y_last = det M / det B = P0 / P1 (Cramer): both stay finite where M is singular (a mode of
// A(0) on the boundary), where G itself has a pole. Fixed sizes (the core is 2 to 6 states) let
// the compiler unroll it, and the complex arithmetic is written out on real and imaginary
// parts (std::complex's operators check for infinities and NaNs on every product, which
// doubled the cost).
template <int kM>
bool solve(const std::vector<double>& neg_core, const std::vector<double>& u,
           const std::vector<double>& link, int source, int position, int m, Cd z, Cd zd,
           Cd& p1_phase_out, Cd& r_out) {
  constexpr int kCap = (kM > 0 ? kM : kCoreCapacity) + 1;
  const int n = (kM > 0 ? kM : m) + 1;  // bordered size
  const int c = n;                      // the right-hand side's column
  // Plain arrays: indexed by int without conversions, rows swapped element by element.
  double re[kCap][kCap + 1] = {};
  double im[kCap][kCap + 1] = {};
  const int core = n - 1;
  for (int i = 0; i < core; ++i) {
    for (int j = 0; j < core; ++j) re[i][j] = neg_core[static_cast<std::size_t>(i * m + j)];
    re[i][i] += z.real();
    im[i][i] += z.imag();
    re[i][core] = u[static_cast<std::size_t>(i)];
    if (source >= 0) {
      // Column `source` times z^d: (z^d (z e_s - A_core e_s) - link). r = P0 / P1 is unchanged
      // (both determinants gain z^d), P1's phase gains d theta, and z^d never overflows where
      // z^-d would (|z|^-d = e^{d kappa theta} passes 1e308 at d kappa pi > 709).
      const double a = re[i][source];
      const double b = im[i][source];
      re[i][source] = zd.real() * a - zd.imag() * b - link[static_cast<std::size_t>(i)];
      im[i][source] = zd.real() * b + zd.imag() * a;
    }
  }
  re[core][position] = 1.0;
  if (position == source) {  // the scaled column crosses the border row too
    re[core][position] = zd.real();
    im[core][position] = zd.imag();
  }
  re[core][c] = 1.0;  // e_last
  // The phase of det B as the product of the pivots, rescaled by powers of two (exact) so it
  // neither overflows nor underflows; the pivots' inverses kept for the back substitution.
  double ph_re = 1.0;
  double ph_im = 0.0;
  double inv_re[kCap] = {};
  double inv_im[kCap] = {};
  for (int k = 0; k < n; ++k) {
    int piv = k;
    double best = re[k][k] * re[k][k] + im[k][k] * im[k][k];
    for (int i = k + 1; i < n; ++i) {
      const double v = re[i][k] * re[i][k] + im[i][k] * im[i][k];
      if (v > best) {
        best = v;
        piv = i;
      }
    }
    if (!(best > 0.0) || !std::isfinite(best)) return false;
    if (piv != k) {
      for (int j = 0; j <= c; ++j) {
        std::swap(re[k][j], re[piv][j]);
        std::swap(im[k][j], im[piv][j]);
      }
      ph_re = -ph_re;
      ph_im = -ph_im;
    }
    const double pr = re[k][k];
    const double pi = im[k][k];
    const double nr = ph_re * pr - ph_im * pi;
    ph_im = ph_re * pi + ph_im * pr;
    ph_re = nr;
    const double scale = std::abs(ph_re) + std::abs(ph_im);
    if (scale > 0x1p+500 || scale < 0x1p-500) {
      int e = 0;
      (void)std::frexp(scale, &e);
      ph_re = std::ldexp(ph_re, -e);
      ph_im = std::ldexp(ph_im, -e);
    }
    const double r = 1.0 / best;
    const double inv_r = pr * r;  // 1 / pivot
    const double inv_i = -pi * r;
    inv_re[k] = inv_r;
    inv_im[k] = inv_i;
    for (int i = k + 1; i < n; ++i) {
      const double fr = re[i][k] * inv_r - im[i][k] * inv_i;
      const double fi = re[i][k] * inv_i + im[i][k] * inv_r;
      if (fr == 0.0 && fi == 0.0) continue;
      for (int j = k + 1; j <= c; ++j) {
        re[i][j] -= fr * re[k][j] - fi * im[k][j];
        im[i][j] -= fr * im[k][j] + fi * re[k][j];
      }
    }
  }
  // Only the last unknown is wanted: the last row of the triangular system alone.
  const double ar = re[n - 1][c];
  const double ai = im[n - 1][c];
  r_out = Cd(ar * inv_re[n - 1] - ai * inv_im[n - 1], ar * inv_im[n - 1] + ai * inv_re[n - 1]);
  p1_phase_out = unit(Cd(ph_re, ph_im));
  return true;
}

}  // namespace

BoundaryPoint RankOneLoop::evaluate(double theta, const AdmissibleBoundary& boundary) const {
  BoundaryPoint p;
  p.theta = theta;
  for (int attempt = 0; attempt < 2; ++attempt) {
    const double t = p.theta;
    const Cd z = boundary.at(t);
    // z^d = |z|^d e^{i d theta}, formed from theta (no complex power of a rounded z).
    Cd zd(1.0, 0.0);
    if (delay_ > 0) {
      const double d = static_cast<double>(delay_);
      zd = std::polar(std::exp(-d * boundary.decay_per_radian() * t), d * t);
    }
    // The fixed-size elimination for the core's size (2 to 6 states), else the general one.
    using Solver = bool (*)(const std::vector<double>&, const std::vector<double>&,
                            const std::vector<double>&, int, int, int, Cd, Cd, Cd&, Cd&);
    static constexpr Solver kSolvers[] = {solve<0>, solve<0>, solve<2>, solve<3>,
                                          solve<4>, solve<5>, solve<6>};
    const Solver solver = m_ >= 2 && m_ <= 6 ? kSolvers[m_] : solve<0>;
    const bool ok = solver(neg_core_, u_rm_, link_rm_, delay_ > 0 ? source_ : -1, position_, m_, z,
                           zd, p.p1_phase, p.r);
    if (ok) return p;
    // A mode of A(0) exactly here: look a hair beside it.
    p.singular = true;
    p.theta = t == 0.0 ? 1e-9 : (t == kPi ? kPi - 1e-9 : t + 1e-13);
  }
  p.r = Cd(std::numeric_limits<double>::quiet_NaN(), 0.0);
  return p;
}

namespace {

// Samples of the boundary's upper half, refined until every tracked phase moves by at most
// kMaxPhaseStep between neighbours.
template <class Track, class Eval>
void refine(const BoundaryPoint& a, const BoundaryPoint& b, std::vector<BoundaryPoint>& out,
            bool& unresolved, const Track& track, const Eval& eval, double zone, int depth = 0) {
  const auto ta = track(a);
  const auto tb = track(b);
  const bool strict = a.theta < zone * (1.0 + 1e-9) || b.theta > kPi - zone * (1.0 + 1e-9);
  bool split = false;
  for (std::size_t i = 0; i < ta.size(); ++i) split = split || too_far(ta[i], tb[i], strict);
  if (split && b.theta - a.theta > kMinWidth && depth < 64) {
    const BoundaryPoint mid = eval(0.5 * (a.theta + b.theta));
    refine(a, mid, out, unresolved, track, eval, zone, depth + 1);
    refine(mid, b, out, unresolved, track, eval, zone, depth + 1);
    return;
  }
  if (split) unresolved = true;
  out.push_back(b);
}

double sin_arg(Cd g) {
  const double a = std::sqrt(std::norm(g));
  return a > 0.0 && std::isfinite(a) ? g.imag() / a : 0.0;
}

// The phases a crossing search keeps resolved: det M and the numerator of G (-det M G).
std::array<Cd, 2> crossing_phases(const BoundaryPoint& p) {
  return {p.p1_phase, p.p1_phase * p.r};  // P1 and P0 = P1 r: compared by too_far
}

// sin(arg G) at a sample: its sign changes where G is real.
double sin_arg_g(const BoundaryPoint& x) { return sin_arg(x.r); }

// RankOneLoop::crossings, step by step, into `out`.
class CrossingFinder {
 public:
  CrossingFinder(const RankOneLoop& loop, double required_damping_ratio,
                 double max_stiffness_N_per_m, CrossingSearch& out)
      : loop_(loop),
        boundary_(required_damping_ratio),
        max_stiffness_(max_stiffness_N_per_m),
        out_(out) {
    out_.required_damping_ratio = required_damping_ratio;
  }

  // The initial grid, refined: the phase of det M turns by about pi per mode inside the region.
  void sample_boundary() {
    std::vector<BoundaryPoint>& s = out_.samples;
    const std::vector<double> grid = initial_grid(loop_.order());
    const auto eval = [this](double theta) { return this->eval(theta); };
    s.reserve(grid.size() * 2);
    s.push_back(eval(grid.front()));
    for (std::size_t j = 1; j < grid.size(); ++j) {
      const BoundaryPoint next = eval(grid[j]);
      const BoundaryPoint prev = s.back();
      refine(prev, next, s, out_.unresolved, crossing_phases, eval, end_zone(loop_.order()));
    }
  }

  // The real-axis ends of the boundary (z = 1, z = -|z(pi)|), where G is real.
  void add_ends() {
    const std::vector<BoundaryPoint>& s = out_.samples;
    for (const BoundaryPoint* end : {&s.front(), &s.back()}) {
      if (!end->singular) add(end->theta, Cd(end->r.real(), 0.0), false);
    }
  }

  // The samples with the ends moved just inside: at the ends sin(arg G) is 0 identically.
  [[nodiscard]] std::vector<BoundaryPoint> inner_samples() {
    std::vector<BoundaryPoint> inner = out_.samples;
    if (inner.size() >= 2) {
      inner.front() = eval(inner[1].theta * 1e-6);
      inner.back() = eval(kPi - (kPi - inner[inner.size() - 2].theta) * 1e-6);
    }
    return inner;
  }

  // A crossing between neighbours where sin(arg G) changes sign.
  void add_sign_changes(const std::vector<BoundaryPoint>& inner) {
    for (std::size_t j = 0; j + 1 < inner.size(); ++j) {
      const BoundaryPoint& a = inner[j];
      const BoundaryPoint& b = inner[j + 1];
      const double fa = sin_arg_g(a);
      const double fb = sin_arg_g(b);
      if (!(a.r.real() < 0.0 || b.r.real() < 0.0)) continue;  // a root here has K < 0
      if ((fa > 0.0) != (fb > 0.0) && fa != 0.0 && fb != 0.0) {
        const BoundaryPoint c = root(a, b);
        add(c.theta, c.r, false);
      }
    }
  }

  // A mode that touches the boundary and returns: |sin(arg G)| has a local minimum at a
  // sample with no sign change on either side.
  void add_touches(const std::vector<BoundaryPoint>& inner) {
    for (std::size_t j = 1; j + 1 < inner.size(); ++j) {
      const double f0 = sin_arg_g(inner[j - 1]);
      const double f1 = sin_arg_g(inner[j]);
      const double f2 = sin_arg_g(inner[j + 1]);
      const double sign = f1 > 0.0 ? 1.0 : -1.0;
      if (!(sign * f0 > 0.0 && sign * f2 > 0.0 && sign * f1 > 0.0)) continue;
      if (!(std::abs(f1) < std::abs(f0) && std::abs(f1) < std::abs(f2) && std::abs(f1) < 0.3)) {
        continue;
      }
      if (!(inner[j].r.real() < 0.0)) continue;
      add_touch(inner[j - 1], inner[j], inner[j + 1], sign);
    }
  }

  void sort_crossings() {
    std::sort(out_.crossings.begin(), out_.crossings.end(),
              [](const Crossing& x, const Crossing& y) {
                return x.stiffness_N_per_m < y.stiffness_N_per_m;
              });
  }

 private:
  BoundaryPoint eval(double theta) {
    ++out_.boundary_points;
    BoundaryPoint p = loop_.evaluate(theta, boundary_);
    if (!std::isfinite(p.r.real()) || !std::isfinite(p.r.imag())) out_.unresolved = true;
    return p;
  }

  // A crossing at K = 1/G = -r, real and positive there.
  void add(double theta, Cd r, bool near_double) {
    const double k = -r.real();
    if (!std::isfinite(k)) return;
    if (!(k > 1e-9) || k > max_stiffness_) return;
    out_.crossings.push_back({k, boundary_.at(theta), near_double});
  }

  // The root of sin(arg G) in [a, b] (a sign change), by the Illinois method.
  BoundaryPoint root(BoundaryPoint a, BoundaryPoint b) {
    double fa = sin_arg_g(a);
    double fb = sin_arg_g(b);
    int side = 0;
    for (int it = 0; it < 100 && b.theta - a.theta > 4e-16 * (1.0 + b.theta); ++it) {
      double t = (a.theta * fb - b.theta * fa) / (fb - fa);
      if (!(t > a.theta && t < b.theta)) t = 0.5 * (a.theta + b.theta);
      const BoundaryPoint c = eval(t);
      const double fc = sin_arg_g(c);
      if (fc == 0.0) return c;
      if ((fc > 0.0) == (fb > 0.0)) {
        b = c;
        fb = fc;
        if (side == -1) fa *= 0.5;
        side = -1;
      } else {
        a = c;
        fa = fc;
        if (side == 1) fb *= 0.5;
        side = 1;
      }
    }
    return std::abs(fa) < std::abs(fb) ? a : b;
  }

  // Golden-section search for the minimum of |sin(arg G)| between `left` and `right` around
  // `middle`: two crossings where it changes sign, one near-double crossing where it reaches 0.
  void add_touch(const BoundaryPoint& left, const BoundaryPoint& middle, const BoundaryPoint& right,
                 double sign) {
    BoundaryPoint lo = left;
    BoundaryPoint hi = right;
    BoundaryPoint best = middle;
    constexpr double kGolden = 0.6180339887498949;
    BoundaryPoint x1 = eval(hi.theta - kGolden * (hi.theta - lo.theta));
    BoundaryPoint x2 = eval(lo.theta + kGolden * (hi.theta - lo.theta));
    for (int it = 0; it < 50 && hi.theta - lo.theta > 1e-10 * kPi; ++it) {
      for (const BoundaryPoint* x : {&x1, &x2}) {
        if (sign * sin_arg_g(*x) <= 0.0) {
          // Two crossings, one on each side of x.
          const BoundaryPoint first = root(left, *x);
          const BoundaryPoint second = root(*x, right);
          add(first.theta, first.r, false);
          add(second.theta, second.r, false);
          return;
        }
        if (std::abs(sin_arg_g(*x)) < std::abs(sin_arg_g(best))) best = *x;
      }
      if (sign * sin_arg_g(x1) < sign * sin_arg_g(x2)) {
        hi = x2;
        x2 = x1;
        x1 = eval(hi.theta - kGolden * (hi.theta - lo.theta));
      } else {
        lo = x1;
        x1 = x2;
        x2 = eval(lo.theta + kGolden * (hi.theta - lo.theta));
      }
    }
    if (std::abs(sin_arg_g(best)) < 1e-9) add(best.theta, best.r, true);
  }

  const RankOneLoop& loop_;
  const AdmissibleBoundary boundary_;
  double max_stiffness_;
  CrossingSearch& out_;
};

}  // namespace

CrossingSearch RankOneLoop::crossings(double required_damping_ratio,
                                      double max_stiffness_N_per_m) const {
  CrossingSearch out;
  CrossingFinder finder(*this, required_damping_ratio, max_stiffness_N_per_m, out);
  finder.sample_boundary();
  finder.add_ends();
  const std::vector<BoundaryPoint> inner = finder.inner_samples();
  finder.add_sign_changes(inner);
  finder.add_touches(inner);
  finder.sort_crossings();
  return out;
}

int RankOneLoop::modes_outside(const CrossingSearch& search, double stiffness_N_per_m,
                               long* boundary_points) const {
  const AdmissibleBoundary boundary(search.required_damping_ratio);
  const std::vector<BoundaryPoint>& s = search.samples;
  if (s.size() < 2) return -1;
  bool unresolved = false;
  bool on_boundary = false;
  auto eval = [&](double theta) {
    if (boundary_points != nullptr) ++*boundary_points;
    return evaluate(theta, boundary);
  };
  // det(M - K u e^T) = det M (1 - K G).
  auto track = [&](const BoundaryPoint& p) {
    const Cd factor = p.r + stiffness_N_per_m;  // det(M - K u e^T) = P1 (r + K)
    // A mode within 1e-9 N/m of stiffness of this point of the boundary: on it.
    if (std::abs(factor) <= 1e-9 * (1.0 + stiffness_N_per_m)) on_boundary = true;
    return std::array<Cd, 1>{p.p1_phase * factor};
  };
  // The unwrapped phase: its principal values at the two ends, plus a turn for each crossing
  // of the negative real axis (each step is under a quarter turn, so a change of sign of the
  // imaginary part with a negative real part is such a crossing, and its sense is the sign's).
  std::vector<BoundaryPoint> fine;
  long turns = 0;
  Cd first{};
  Cd last{};
  for (std::size_t j = 0; j + 1 < s.size(); ++j) {
    fine.clear();
    fine.push_back(s[j]);
    refine(s[j], s[j + 1], fine, unresolved, track, eval, end_zone(order()));
    if (j == 0) first = track(fine.front())[0];
    for (std::size_t i = 0; i + 1 < fine.size(); ++i) {
      const Cd a = track(fine[i])[0];
      const Cd b = track(fine[i + 1])[0];
      if (a.real() + b.real() < 0.0 && (a.imag() < 0.0) != (b.imag() < 0.0)) {
        turns += a.imag() >= 0.0 ? 1 : -1;  // upper to lower half: counter-clockwise past pi
      }
    }
    last = track(fine.back())[0];
  }
  const double turned = argument(last) - argument(first) + 2.0 * kPi * static_cast<double>(turns);
  if (unresolved || on_boundary || !std::isfinite(turned)) return -1;
  // Zeros inside = (arg change of z^d det(M - K u e^T) along the upper half) / pi; the tracked
  // P1 already carries the z^d (the scaled column).
  const double inside = turned / kPi;
  const double rounded = std::round(inside);
  if (std::abs(inside - rounded) > 0.25) return -1;
  const int outside = order() - static_cast<int>(rounded);
  return outside < 0 ? -1 : outside;
}

int RankOneLoop::modes_outside(double stiffness_N_per_m, double required_damping_ratio,
                               long* boundary_points) const {
  CrossingSearch grid;
  grid.required_damping_ratio = required_damping_ratio;
  const AdmissibleBoundary boundary(required_damping_ratio);
  for (const double theta : initial_grid(order())) {
    if (boundary_points != nullptr) ++*boundary_points;
    grid.samples.push_back(evaluate(theta, boundary));
  }
  return modes_outside(grid, stiffness_N_per_m, boundary_points);
}

}  // namespace teleop::stability
