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
// Neighbouring samples along the boundary differ by at most this much in the phase of every
// tracked function (det(zI - A(0)), the numerator of G, or the loop's determinant at K): a
// crossing is then a sign change of sin(arg G) between two samples, and a count of zeros is an
// unwrapped phase.
constexpr double kMaxPhaseStep = kPi / 4.0;
constexpr double kMinWidth = 1e-12;  // rad: the finest the sampler splits
constexpr int kCoreCapacity = 16;    // the core is 6x6 at most in this model

double step(Cd from, Cd to) { return std::arg(to * std::conj(from)); }

Cd unit(Cd c) {
  const double a = std::abs(c);
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
}

RankOneLoop::Point RankOneLoop::evaluate(std::complex<double> z) const {
  // [M | u] with M = zI - A_core - z^-d link e_source^T, eliminated with partial pivoting.
  const int m = m_;
  const int w = m + 1;
  std::array<Cd, kCoreCapacity*(kCoreCapacity + 1)> s{};
  for (int i = 0; i < m; ++i) {
    for (int j = 0; j < m; ++j) s[static_cast<std::size_t>(i * w + j)] = -core_(i, j);
    s[static_cast<std::size_t>(i * w + i)] += z;
    s[static_cast<std::size_t>(i * w + m)] = u_(i);
  }
  if (delay_ > 0) {
    const Cd zd = std::exp(-static_cast<double>(delay_) * std::log(z));
    for (int i = 0; i < m; ++i) s[static_cast<std::size_t>(i * w + source_)] -= zd * link_(i);
  }
  Point p;
  Cd phase(1.0, 0.0);
  for (int k = 0; k < m; ++k) {
    int piv = k;
    double best = std::abs(s[static_cast<std::size_t>(k * w + k)]);
    for (int i = k + 1; i < m; ++i) {
      const double v = std::abs(s[static_cast<std::size_t>(i * w + k)]);
      if (v > best) {
        best = v;
        piv = i;
      }
    }
    if (!(best > 0.0) || !std::isfinite(best)) {
      p.singular = true;
      p.p0_phase = phase;
      p.g = Cd(std::numeric_limits<double>::infinity(), 0.0);
      return p;
    }
    if (piv != k) {
      for (int j = k; j < w; ++j) {
        std::swap(s[static_cast<std::size_t>(k * w + j)], s[static_cast<std::size_t>(piv * w + j)]);
      }
      phase = -phase;
    }
    const Cd pivot = s[static_cast<std::size_t>(k * w + k)];
    phase *= pivot / best;
    const Cd inv = 1.0 / pivot;
    for (int i = k + 1; i < m; ++i) {
      const Cd f = s[static_cast<std::size_t>(i * w + k)] * inv;
      if (f == Cd(0.0, 0.0)) continue;
      for (int j = k + 1; j < w; ++j) {
        s[static_cast<std::size_t>(i * w + j)] -= f * s[static_cast<std::size_t>(k * w + j)];
      }
    }
  }
  std::array<Cd, kCoreCapacity> x{};
  for (int i = m - 1; i >= 0; --i) {
    Cd acc = s[static_cast<std::size_t>(i * w + m)];
    for (int j = i + 1; j < m; ++j)
      acc -= s[static_cast<std::size_t>(i * w + j)] * x[static_cast<std::size_t>(j)];
    x[static_cast<std::size_t>(i)] = acc / s[static_cast<std::size_t>(i * w + i)];
  }
  p.p0_phase = unit(phase);
  p.g = x[static_cast<std::size_t>(position_)];
  return p;
}

namespace {

// Samples of the boundary's upper half, refined until every tracked phase moves by at most
// kMaxPhaseStep between neighbours.
struct Sample {
  double theta{0.0};
  RankOneLoop::Point point{};
  std::array<Cd, 2> tracked{};  // unit phases
};

template <class Eval>
void refine(const Sample& a, const Sample& b, std::vector<Sample>& out, bool& unresolved,
            const Eval& eval, int depth = 0) {
  bool split = false;
  for (std::size_t i = 0; i < a.tracked.size(); ++i) {
    split = split || std::abs(step(a.tracked[i], b.tracked[i])) > kMaxPhaseStep;
  }
  if (split && b.theta - a.theta > kMinWidth && depth < 64) {
    const Sample mid = eval(0.5 * (a.theta + b.theta));
    refine(a, mid, out, unresolved, eval, depth + 1);
    refine(mid, b, out, unresolved, eval, depth + 1);
    return;
  }
  if (split) unresolved = true;
  out.push_back(b);
}

template <class Eval>
std::vector<Sample> sample_boundary(int order, bool& unresolved, const Eval& eval) {
  const int intervals = 8 * order + 16;
  std::vector<Sample> out;
  out.reserve(static_cast<std::size_t>(intervals) * 2);
  out.push_back(eval(0.0));
  for (int j = 1; j <= intervals; ++j) {
    const double theta = j == intervals ? kPi : kPi * j / intervals;
    const Sample next = eval(theta);
    const Sample prev = out.back();
    refine(prev, next, out, unresolved, eval);
  }
  return out;
}

double sin_arg(Cd g) {
  const double a = std::abs(g);
  return a > 0.0 && std::isfinite(a) ? g.imag() / a : 0.0;
}

}  // namespace

CrossingSearch RankOneLoop::crossings(double required_damping_ratio,
                                      double max_stiffness_N_per_m) const {
  const AdmissibleBoundary boundary(required_damping_ratio);
  CrossingSearch out;
  auto eval = [&](double theta) {
    ++out.boundary_points;
    Sample s;
    s.theta = theta;
    s.point = evaluate(boundary.at(theta));
    if (s.point.singular && theta > 0.0 && theta < kPi) {
      // A mode of A(0) exactly here: look a hair beside it.
      s.point = evaluate(boundary.at(theta + 1e-13));
    }
    s.tracked[0] = s.point.p0_phase;
    // det(M - K u e^T) = P0 + K P1 with P1 = -P0 G.
    s.tracked[1] = s.point.singular ? s.point.p0_phase : unit(-s.point.p0_phase * s.point.g);
    return s;
  };
  auto add = [&](double theta, Cd g, bool near_double) {
    if (!(g.real() > 0.0) || !std::isfinite(g.real())) return;
    const double k = 1.0 / g.real();
    if (!(k > 1e-9) || k > max_stiffness_N_per_m) return;
    out.crossings.push_back({k, boundary.at(theta), near_double});
  };
  // The real-axis ends of the boundary: z = 1 and z = -|z(pi)|, where G is real.
  for (const double end : {0.0, kPi}) {
    const Point p = evaluate(boundary.at(end));
    ++out.boundary_points;
    if (!p.singular) add(end, Cd(p.g.real(), 0.0), false);
  }
  std::vector<Sample> s = sample_boundary(order(), out.unresolved, eval);
  // At the ends sin(arg G) is 0 identically: take the sign just inside.
  if (s.size() >= 2) {
    s.front() = eval(s[1].theta * 1e-6);
    s.back() = eval(kPi - (kPi - s[s.size() - 2].theta) * 1e-6);
  }
  auto h = [](const Sample& x) { return sin_arg(x.point.g); };
  // The root of sin(arg G) in [a, b] (a sign change), by the Illinois method.
  auto root = [&](Sample a, Sample b) {
    double fa = h(a);
    double fb = h(b);
    int side = 0;
    for (int it = 0; it < 100 && b.theta - a.theta > 4e-16 * (1.0 + b.theta); ++it) {
      double t = (a.theta * fb - b.theta * fa) / (fb - fa);
      if (!(t > a.theta && t < b.theta)) t = 0.5 * (a.theta + b.theta);
      const Sample c = eval(t);
      const double fc = h(c);
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
  };
  for (std::size_t j = 0; j + 1 < s.size(); ++j) {
    const Sample& a = s[j];
    const Sample& b = s[j + 1];
    const double fa = h(a);
    const double fb = h(b);
    const bool positive = a.point.g.real() > 0.0 || b.point.g.real() > 0.0;
    if (!positive) continue;  // a root here has K < 0
    if ((fa > 0.0) != (fb > 0.0) && fa != 0.0 && fb != 0.0) {
      const Sample c = root(a, b);
      add(c.theta, c.point.g, false);
      continue;
    }
    // No sign change: a mode may touch the boundary and return between the two samples.
    if (std::min(std::abs(fa), std::abs(fb)) > 0.2) continue;
    Sample lo = a;
    Sample hi = b;
    Sample best = std::abs(fa) < std::abs(fb) ? a : b;
    const double sign = fa > 0.0 ? 1.0 : -1.0;
    // Golden-section search for the least sign * h on [a, b].
    constexpr double kGolden = 0.6180339887498949;
    Sample x1 = eval(hi.theta - kGolden * (hi.theta - lo.theta));
    Sample x2 = eval(lo.theta + kGolden * (hi.theta - lo.theta));
    bool split = false;
    for (int it = 0; it < 60 && !split; ++it) {
      for (const Sample* x : {&x1, &x2}) {
        if (sign * h(*x) <= 0.0) {
          // Two crossings: one on each side of x.
          const Sample first = root(a, *x);
          const Sample second = root(*x, b);
          add(first.theta, first.point.g, false);
          add(second.theta, second.point.g, false);
          split = true;
          break;
        }
        if (std::abs(h(*x)) < std::abs(h(best))) best = *x;
      }
      if (split || hi.theta - lo.theta < 1e-14) break;
      if (sign * h(x1) < sign * h(x2)) {
        hi = x2;
        x2 = x1;
        x1 = eval(hi.theta - kGolden * (hi.theta - lo.theta));
      } else {
        lo = x1;
        x1 = x2;
        x2 = eval(lo.theta + kGolden * (hi.theta - lo.theta));
      }
    }
    if (!split && std::abs(h(best)) < 1e-9) add(best.theta, best.point.g, true);
  }
  std::sort(out.crossings.begin(), out.crossings.end(), [](const Crossing& x, const Crossing& y) {
    return x.stiffness_N_per_m < y.stiffness_N_per_m;
  });
  return out;
}

int RankOneLoop::modes_outside(double stiffness_N_per_m, double required_damping_ratio,
                               long* boundary_points) const {
  const AdmissibleBoundary boundary(required_damping_ratio);
  bool unresolved = false;
  bool on_boundary = false;
  auto eval = [&](double theta) {
    if (boundary_points != nullptr) ++*boundary_points;
    Sample s;
    s.theta = theta;
    s.point = evaluate(boundary.at(theta));
    if (s.point.singular) {
      on_boundary = on_boundary || stiffness_N_per_m == 0.0;
      s.point = evaluate(boundary.at(theta == kPi ? theta - 1e-13 : theta + 1e-13));
    }
    // det(M - K u e^T) = P0 (1 - K G).
    const Cd factor = 1.0 - stiffness_N_per_m * s.point.g;
    if (std::abs(factor) == 0.0) on_boundary = true;
    s.tracked[0] = unit(s.point.p0_phase * factor);
    s.tracked[1] = s.tracked[0];
    return s;
  };
  const std::vector<Sample> s = sample_boundary(order(), unresolved, eval);
  if (unresolved || on_boundary) return -1;
  double turned = 0.0;
  for (std::size_t j = 0; j + 1 < s.size(); ++j) {
    turned += step(s[j].tracked[0], s[j + 1].tracked[0]);
  }
  // Zeros inside = (arg change of z^d det(M - K u e^T) along the upper half) / pi.
  const double inside = static_cast<double>(delay_) + turned / kPi;
  const double rounded = std::round(inside);
  if (std::abs(inside - rounded) > 0.25) return -1;
  const int outside = order() - static_cast<int>(rounded);
  return outside < 0 ? -1 : outside;
}

}  // namespace teleop::stability
