// The exact stiffness limit of one fixture plane of the n-axis loop (analysis_axes.hpp): the
// plane adds K n n^T, a rank-one term, so the loop's characteristic polynomial is
// det(zI - A0) (1 - K G(z)) with G = c^T (zI - A0)^-1 b; a mode meets the admissible boundary
// where G is real and positive there, at K = 1/G. Each interval between crossings is confirmed
// with one spectrum, as exact_limit.cpp does for one axis.
#include <fmt/format.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <complex>
#include <limits>
#include <numbers>
#include <optional>
#include <stdexcept>

#include "common/stability/analysis_axes.hpp"
#include "common/stability/axes_detail.hpp"
#include "common/stability/crossings.hpp"

namespace teleop::stability {

using detail::normal_axis;
using detail::parallel_for;

namespace {
using Mat = Eigen::MatrixXd;
}  // namespace

namespace {

using Cd = std::complex<double>;
constexpr double kPi = std::numbers::pi;

// One block A(K) = A0 + K b c^T. G(z) = c^T (zI - A0)^-1 b through the Hessenberg form of A0,
// so each point of the boundary costs O(N^2); det(zI - A0)'s phase comes with the pivots.
class RankOneAxes {
 public:
  struct Point {
    double theta{0.0};
    Cd g{};
    Cd p0_phase{1.0, 0.0};
    bool ok{false};
  };

  RankOneAxes(const Mat& a0, const Eigen::VectorXd& b, const Eigen::VectorXd& c) {
    const Eigen::HessenbergDecomposition<Mat> hd(a0);
    h_ = hd.matrixH();
    const Mat q = hd.matrixQ();
    qb_ = q.transpose() * b;
    qc_ = q.transpose() * c;
  }

  [[nodiscard]] int order() const { return static_cast<int>(h_.rows()); }

  [[nodiscard]] Point eval(double theta, const AdmissibleBoundary& boundary) const {
    Point p;
    p.theta = theta;
    const int n = order();
    const Cd z = boundary.at(theta);
    thread_local std::vector<Cd> u;
    thread_local std::vector<Cd> y;
    u.assign(static_cast<size_t>(n * n), Cd{});
    y.resize(static_cast<size_t>(n));
    auto at = [n](int i, int j) { return static_cast<size_t>(i * n + j); };
    for (int i = 0; i < n; ++i) {
      for (int j = std::max(0, i - 1); j < n; ++j) u[at(i, j)] = -h_(i, j);
      u[at(i, i)] += z;
      y[static_cast<size_t>(i)] = qb_(i);
    }
    Cd phase(1.0, 0.0);
    for (int k = 0; k < n; ++k) {
      if (k + 1 < n && std::norm(u[at(k + 1, k)]) > std::norm(u[at(k, k)])) {
        for (int j = k; j < n; ++j) std::swap(u[at(k, j)], u[at(k + 1, j)]);
        std::swap(y[static_cast<size_t>(k)], y[static_cast<size_t>(k + 1)]);
        phase = -phase;
      }
      const Cd piv = u[at(k, k)];
      const double mag = std::abs(piv);
      if (!(mag > 0.0) || !std::isfinite(mag)) return p;
      phase *= piv / mag;
      if (k + 1 < n) {
        const Cd l = u[at(k + 1, k)] / piv;
        if (l != Cd{}) {
          for (int j = k + 1; j < n; ++j) u[at(k + 1, j)] -= l * u[at(k, j)];
          y[static_cast<size_t>(k + 1)] -= l * y[static_cast<size_t>(k)];
        }
      }
    }
    Cd g{};
    for (int i = n - 1; i >= 0; --i) {
      Cd s = y[static_cast<size_t>(i)];
      for (int j = i + 1; j < n; ++j) s -= u[at(i, j)] * y[static_cast<size_t>(j)];
      y[static_cast<size_t>(i)] = s / u[at(i, i)];
      g += qc_(i) * y[static_cast<size_t>(i)];
    }
    p.g = g;
    p.p0_phase = phase;
    p.ok = std::isfinite(g.real()) && std::isfinite(g.imag());
    return p;
  }

 private:
  Mat h_{};
  Eigen::VectorXd qb_{};
  Eigen::VectorXd qc_{};
};

// More than an eighth of a turn between two phases: the sampler splits the interval.
bool turns_too_far(Cd a, Cd b) {
  const double dot = a.real() * b.real() + a.imag() * b.imag();
  constexpr double kCosEighth = 0.70710678118654752;
  return dot < kCosEighth * std::abs(a) * std::abs(b);
}

struct CrossingList {
  std::vector<double> stiffness_N_per_m{};  // ascending, in (0, cap]
  bool unresolved{false};
};

class AxesCrossingFinder {
 public:
  AxesCrossingFinder(const RankOneAxes& loop, double required, double cap)
      : loop_(loop), boundary_(required), cap_(cap) {}

  CrossingList run() {
    const int order = loop_.order();
    const int intervals = 4 * order + 8;
    const double first = kPi / intervals;
    std::vector<double> grid{0.0};
    for (int k = 12; k >= 1; --k) grid.push_back(std::ldexp(first, -k));
    for (int j = 1; j <= intervals; ++j) grid.push_back(j == intervals ? kPi : kPi * j / intervals);
    std::vector<RankOneAxes::Point> s{eval(grid.front())};
    for (std::size_t j = 1; j < grid.size(); ++j) refine(s.back(), eval(grid[j]), s, 0);
    // The real-axis ends: G is real there.
    for (const RankOneAxes::Point* end : {&s.front(), &s.back()}) {
      if (end->ok) add(end->g.real());
    }
    for (std::size_t j = 0; j + 1 < s.size(); ++j) {
      const RankOneAxes::Point& a = s[j];
      const RankOneAxes::Point& b = s[j + 1];
      const bool at_end = j == 0 || j + 2 == s.size();
      if (!a.ok || !b.ok || at_end) {
        if (at_end) inner_end(a, b, j == 0);
        continue;
      }
      sign_change(a, b);
    }
    for (std::size_t j = 1; j + 1 < s.size(); ++j) touch(s[j - 1], s[j], s[j + 1]);
    std::sort(out_.stiffness_N_per_m.begin(), out_.stiffness_N_per_m.end());
    return out_;
  }

 private:
  RankOneAxes::Point eval(double theta) {
    RankOneAxes::Point p = loop_.eval(theta, boundary_);
    if (!p.ok) {  // a mode of A0 exactly here: a hair beside
      p = loop_.eval(theta == 0.0 ? 1e-9 : (theta >= kPi ? kPi - 1e-9 : theta + 1e-13), boundary_);
    }
    if (!p.ok) out_.unresolved = true;
    return p;
  }

  void refine(const RankOneAxes::Point& a, const RankOneAxes::Point& b,
              std::vector<RankOneAxes::Point>& out, int depth) {
    const bool split = a.ok && b.ok &&
                       (turns_too_far(a.p0_phase, b.p0_phase) ||
                        turns_too_far(a.p0_phase * a.g, b.p0_phase * b.g));
    if (split && b.theta - a.theta > 1e-12 && depth < 60) {
      const RankOneAxes::Point mid = eval(0.5 * (a.theta + b.theta));
      refine(a, mid, out, depth + 1);
      refine(mid, b, out, depth + 1);
      return;
    }
    if (split) out_.unresolved = true;
    out.push_back(b);
  }

  // At the ends Im G is 0 identically: look for a sign change just inside.
  void inner_end(const RankOneAxes::Point& a, const RankOneAxes::Point& b, bool at_zero) {
    const RankOneAxes::Point a2 = at_zero ? eval(b.theta * 1e-6) : a;
    const RankOneAxes::Point b2 = at_zero ? b : eval(kPi - (kPi - a.theta) * 1e-6);
    if (a2.ok && b2.ok) sign_change(a2, b2);
  }

  void sign_change(RankOneAxes::Point a, RankOneAxes::Point b) {
    if (!(a.g.real() > 0.0 || b.g.real() > 0.0)) return;  // K = 1/G < 0 here
    if ((a.g.imag() > 0.0) == (b.g.imag() > 0.0) || a.g.imag() == 0.0 || b.g.imag() == 0.0) return;
    for (int it = 0; it < 80 && b.theta - a.theta > 4e-16 * (1.0 + b.theta); ++it) {
      const RankOneAxes::Point m = eval(0.5 * (a.theta + b.theta));
      if (!m.ok) break;
      ((m.g.imag() > 0.0) == (a.g.imag() > 0.0) ? a : b) = m;
    }
    const RankOneAxes::Point& best = std::abs(a.g.imag()) < std::abs(b.g.imag()) ? a : b;
    add(best.g.real());
  }

  static double sin_arg(Cd g) {
    const double a = std::abs(g);
    return a > 0.0 && std::isfinite(a) ? g.imag() / a : 0.0;
  }

  // A mode that touches the boundary and returns, or two crossings closer together than the
  // samples (a narrow unstable window of stiffness: issue 15's 1325-1357 N/m), as
  // crossings.cpp's add_touches: |sin arg G| has a local minimum at a sample with the same sign
  // on both sides. A golden-section search between the neighbours looks for the sign flip: found,
  // the crossing on each side of it; not found but G real to 1e-9 there, the touch itself.
  void touch(const RankOneAxes::Point& l, const RankOneAxes::Point& m,
             const RankOneAxes::Point& r) {
    if (!l.ok || !m.ok || !r.ok || !(m.g.real() > 0.0)) return;
    const double f0 = sin_arg(l.g);
    const double f1 = sin_arg(m.g);
    const double f2 = sin_arg(r.g);
    const double sign = f1 > 0.0 ? 1.0 : -1.0;
    if (!(sign * f0 > 0.0 && sign * f1 > 0.0 && sign * f2 > 0.0)) return;
    if (!(std::abs(f1) < std::abs(f0) && std::abs(f1) < std::abs(f2) && std::abs(f1) < 0.3)) {
      return;
    }
    constexpr double kGolden = 0.6180339887498949;
    double lo = l.theta;
    double hi = r.theta;
    RankOneAxes::Point best = m;
    RankOneAxes::Point x1 = eval(hi - kGolden * (hi - lo));
    RankOneAxes::Point x2 = eval(lo + kGolden * (hi - lo));
    for (int it = 0; it < 50 && hi - lo > 1e-10 * kPi; ++it) {
      for (const RankOneAxes::Point* x : {&x1, &x2}) {
        if (!x->ok) return;
        if (sign * sin_arg(x->g) <= 0.0) {  // two crossings, one on each side of x
          if (x->g.imag() == 0.0) {
            add(x->g.real());
          } else {
            sign_change(l, *x);
            sign_change(*x, r);
          }
          return;
        }
        if (std::abs(sin_arg(x->g)) < std::abs(sin_arg(best.g))) best = *x;
      }
      if (sign * sin_arg(x1.g) < sign * sin_arg(x2.g)) {
        hi = x2.theta;
        x2 = x1;
        x1 = eval(hi - kGolden * (hi - lo));
      } else {
        lo = x1.theta;
        x1 = x2;
        x2 = eval(lo + kGolden * (hi - lo));
      }
    }
    if (std::abs(sin_arg(best.g)) < 1e-9) add(best.g.real());
  }

  void add(double g_real) {
    if (!(g_real > 0.0)) return;
    const double k = 1.0 / g_real;
    if (std::isfinite(k) && k > 1e-9 && k <= cap_) out_.stiffness_N_per_m.push_back(k);
  }

  const RankOneAxes& loop_;
  AdmissibleBoundary boundary_;
  double cap_;
  CrossingList out_{};
};

// One human's outcome for the plane.
struct HumanPlaneOutcome {
  double limit{std::numeric_limits<double>::infinity()};  // infinity: passes up to the cap
  bool fails_at_zero{false};
  bool invalid{false};
  bool unresolved{false};
  std::string reason{};
};

bool meets(const Spectrum& s, double required) {
  return s.verdict == Verdict::kStable && s.min_damping_ratio >= required;
}

class PlaneSearch {
 public:
  PlaneSearch(const TeleopAxesParams& p, Side side, std::size_t plane, const AxesEvaluator& ev,
              double cap)
      : p_(p), side_(side), ev_(ev), cap_(cap), required_(p.analysis.required_damping_ratio) {
    const auto& planes = side == Side::kMaster ? p.master_planes : p.slave_planes;
    std::vector<bool> others(planes.size(), true);
    others[plane] = false;
    const Mat own = plane_stiffness_matrix(planes, p.axes, others);
    const Mat other_side =
        plane_stiffness_matrix(side == Side::kMaster ? p.slave_planes : p.master_planes, p.axes);
    base_m_ = side == Side::kMaster ? own : other_side;
    base_s_ = side == Side::kMaster ? other_side : own;
    normal_ = planes[plane].normal;
  }

  [[nodiscard]] Mat km(double k) const {
    return side_ == Side::kMaster ? Mat(base_m_ + k * normal_ * normal_.transpose()) : base_m_;
  }
  [[nodiscard]] Mat ks(double k) const {
    return side_ == Side::kSlave ? Mat(base_s_ + k * normal_ * normal_.transpose()) : base_s_;
  }

  [[nodiscard]] HumanPlaneOutcome human_limit(const HumanChoice& h) const {
    HumanPlaneOutcome o;
    const std::vector<AxesBlock> at0 = ev_.blocks(h, km(0.0), ks(0.0));
    const std::vector<AxesBlock> at1 = ev_.blocks(h, km(1.0), ks(1.0));
    const AxesBlock* varying = nullptr;
    Eigen::VectorXd b;
    Eigen::VectorXd c;
    for (std::size_t i = 0; i < at0.size(); ++i) {
      const Mat diff = at1[i].a - at0[i].a;
      if (diff.isZero(0.0)) {
        // Independent of this plane: it must meet the requirement as it stands.
        const Spectrum s =
            compute_spectrum(at0[i].a, ev_.period_s(), at0[i].structural_zeros, false);
        if (!meets(s, required_)) {
          o.fails_at_zero = true;
          o.invalid = s.verdict == Verdict::kInvalid;
          o.reason = o.invalid
                         ? s.invalid_reason
                         : "a part of the loop the plane does not enter fails the requirement";
          return o;
        }
        continue;
      }
      varying = &at0[i];
      const int pos = side_ == Side::kMaster ? at0[i].master_position : at0[i].slave_position;
      c = Eigen::VectorXd::Zero(diff.cols());
      c.segment(pos, p_.axes) = normal_;
      b = diff * c;  // diff = b c^T with |c| = 1
    }
    if (varying == nullptr) return o;  // the plane enters no block: no limit from it
    const Mat& a0 = varying->a;
    const int zeros = varying->structural_zeros;
    auto admissible = [&](double k) {
      return meets(compute_spectrum(a0 + k * b * c.transpose(), ev_.period_s(), zeros, false),
                   required_);
    };
    double lo = 0.0;
    if (!admissible(0.0)) {
      const Spectrum s0 = compute_spectrum(a0, ev_.period_s(), zeros, false);
      const double tol = p_.analysis.stiffness_tolerance_N_per_m;
      if (s0.verdict == Verdict::kUncertain && admissible(tol)) {
        lo = tol;  // a rigid-body mode at z = 1 exactly at K = 0
      } else {
        o.fails_at_zero = true;
        o.invalid = s0.verdict == Verdict::kInvalid;
        o.reason = o.invalid ? s0.invalid_reason
                             : "fails the requirement with the plane at zero stiffness";
        return o;
      }
    }
    const RankOneAxes loop(a0, b, c);
    const CrossingList cl = AxesCrossingFinder(loop, required_, cap_).run();
    o.unresolved = cl.unresolved;
    std::vector<double> cs;
    for (const double k : cl.stiffness_N_per_m) {
      if (k > lo * (1.0 + 1e-12)) cs.push_back(k);
    }
    auto edge = [&](std::size_t j) { return j == 0 ? lo : cs[j - 1]; };
    for (std::size_t j = 0; j <= cs.size(); ++j) {
      const double from = edge(j);
      const double to = j < cs.size() ? cs[j] : cap_;
      const double probe = j < cs.size() ? 0.5 * (from + to) : std::min(cap_, from * 1.001 + 1e-9);
      if (admissible(probe)) continue;
      // No crossing found below a failing stiffness: one was missed; bisect on spectra.
      o.limit = j == 0 ? bisect(admissible, lo, probe) : from;
      return o;
    }
    if (!admissible(cap_)) o.limit = bisect(admissible, edge(cs.size()), cap_);
    return o;
  }

 private:
  template <class Admissible>
  double bisect(const Admissible& admissible, double pass, double fail) const {
    const double tol = p_.analysis.stiffness_tolerance_N_per_m;
    for (double k = std::max(pass * 1.01, pass + tol); k < fail; k *= 1.01) {
      if (!admissible(k)) {
        fail = k;
        break;
      }
      pass = k;
    }
    while (fail - pass > std::max(tol, 1e-12 * fail)) {
      const double mid = 0.5 * (pass + fail);
      (admissible(mid) ? pass : fail) = mid;
    }
    return pass;
  }

  const TeleopAxesParams& p_;
  Side side_;
  const AxesEvaluator& ev_;
  double cap_;
  double required_;
  Mat base_m_{};
  Mat base_s_{};
  Eigen::VectorXd normal_{};
};

// The limiting stiffness from the crossing, stepped down until the spectrum with error bounds
// shows every mode inside the region by more than its bound.
void step_down(const PlaneSearch& search, const AxesEvaluator& ev, const HumanChoice& h,
               double crossing, double required, PlaneLimit& out) {
  out.limit_crossing_N_per_m = crossing;
  for (int i = 0; i < 9; ++i) {
    const double k = crossing * (1.0 - 1e-11 * std::pow(4.0, i));
    const Spectrum s = ev.spectrum(h, search.km(k), search.ks(k), true);
    if (meets(s, required)) {
      out.max_stable_stiffness_N_per_m = k;
      return;
    }
  }
  out.max_stable_stiffness_N_per_m = crossing * (1.0 - 1e-6);
  out.uncertain = true;
  out.reason = "at the limit a mode lies within its error bound of the boundary";
}

// A decoupled loop and a plane along one axis with no other stiff plane there: the one-axis
// exact limit on that axis, the other axes checked as they stand.
std::optional<PlaneLimit> axis_limit(const TeleopAxesParams& p, Side side, std::size_t plane,
                                     const AxesEvaluator& ev, const AxesAnalysisOptions& options) {
  if (!ev.decoupled()) return std::nullopt;
  const auto& planes = side == Side::kMaster ? p.master_planes : p.slave_planes;
  const int axis = normal_axis(planes[plane].normal);
  for (std::size_t i = 0; i < planes.size(); ++i) {
    if (i != plane && planes[i].stiffness_N_per_m != 0.0 && normal_axis(planes[i].normal) == axis) {
      return std::nullopt;
    }
  }
  PlaneLimit out{side, plane};
  const Mat kmvf = plane_stiffness_matrix(p.master_planes, p.axes);
  const Mat ksvf = plane_stiffness_matrix(p.slave_planes, p.axes);
  for (int j = 0; j < p.axes; ++j) {
    const BandResult band =
        ev.axis_evaluator(j).sweep(kmvf(j, j), ksvf(j, j), p.analysis.required_damping_ratio);
    out.humans_evaluated += ev.axis_evaluator(j).human_count();
    out.worst_human.push_back(ev.axis_evaluator(j).human(band.worst_index));
    if (j != axis && !meets_requirement(band, p.analysis.required_damping_ratio)) {
      out.invalid = band.verdict == Verdict::kInvalid;
      out.reason = fmt::format("axis {} fails the requirement whatever the plane's stiffness{}", j,
                               out.invalid ? ": " + band.invalid_reason : "");
      return out;
    }
  }
  SearchOptions so;
  so.max_stiffness_N_per_m = options.max_stiffness_N_per_m;
  const StiffnessLimit l = max_stable_stiffness(ev.axis_params(axis), side, so);
  out.max_stable_stiffness_N_per_m = l.max_stable_stiffness_N_per_m;
  out.limit_crossing_N_per_m = l.limit_crossing_N_per_m;
  out.reason = l.reason;
  out.invalid = l.invalid;
  out.uncertain = l.uncertain;
  if (l.worst_human) out.worst_human[static_cast<size_t>(axis)] = *l.worst_human;
  return out;
}

}  // namespace

namespace {
PlaneLimit whole_loop_limit(const TeleopAxesParams& params, Side side, std::size_t plane,
                            const AxesEvaluator& ev, const AxesAnalysisOptions& options);
}  // namespace

PlaneLimit plane_stiffness_limit(const TeleopAxesParams& params, Side side, std::size_t plane,
                                 const AxesAnalysisOptions& options) {
  PlaneLimit out{side, plane};
  if (const std::string why = check_axes_params(params); !why.empty()) {
    out.invalid = true;
    out.reason = why;
    return out;
  }
  const auto& planes = side == Side::kMaster ? params.master_planes : params.slave_planes;
  if (plane >= planes.size()) {
    throw std::invalid_argument(fmt::format("{}_planes has no plane {}",
                                            side == Side::kMaster ? "master" : "slave", plane));
  }
  if (options.decouple) {
    if (const std::optional<detail::PlaneFrame> f =
            detail::in_plane_frame(params, &planes[plane])) {
      // The same loop in the planes' frame, where this plane lies along an axis; its stiffness
      // there is |n|^2 times the configured one (the frame's limits are scaled back).
      const double scale = (side == Side::kMaster ? f->master_scale : f->slave_scale)[plane];
      AxesAnalysisOptions o = options;
      o.max_stiffness_N_per_m *= scale;
      PlaneLimit l = plane_stiffness_limit(f->params, side, plane, o);
      if (l.max_stable_stiffness_N_per_m) *l.max_stable_stiffness_N_per_m /= scale;
      if (l.limit_crossing_N_per_m) *l.limit_crossing_N_per_m /= scale;
      return l;
    }
  }
  try {
    std::optional<AxesEvaluator> ev;
    ev.emplace(params, options, side == Side::kMaster, side == Side::kSlave);
    if (ev->decoupled()) {
      if (auto l = axis_limit(params, side, plane, *ev, options)) return *l;
      AxesAnalysisOptions whole = options;
      whole.decouple = false;  // the crossing search needs the whole loop's matrices
      ev.reset();
      ev.emplace(params, whole, side == Side::kMaster, side == Side::kSlave);
    }
    return whole_loop_limit(params, side, plane, *ev, options);

  } catch (const std::exception& e) {
    // The exact plant of a human's master not positive definite, say: no model, no limit.
    out.invalid = true;
    out.reason = e.what();
    return out;
  }
}

namespace {

PlaneLimit whole_loop_limit(const TeleopAxesParams& params, Side side, std::size_t plane,
                            const AxesEvaluator& ev, const AxesAnalysisOptions& options) {
  PlaneLimit out{side, plane};
  const auto& planes = side == Side::kMaster ? params.master_planes : params.slave_planes;
  const PlaneSearch search(params, side, plane, ev, options.max_stiffness_N_per_m);
  std::vector<HumanChoice> humans =
      ev.human_matters()
          ? ev.candidates()
          : std::vector<HumanChoice>{HumanChoice(static_cast<size_t>(params.axes), 0)};
  if (ev.human_matters()) {
    // Walked grids: the refined worst human at the configured stiffness too.
    const AxesBandResult band = ev.sweep(search.km(planes[plane].stiffness_N_per_m),
                                         search.ks(planes[plane].stiffness_N_per_m));
    if (!band.exhaustive) humans.push_back(band.worst);
  }
  std::vector<HumanPlaneOutcome> outcomes(humans.size());
  parallel_for(humans.size(), [&](std::size_t i) {
    try {
      outcomes[i] = search.human_limit(humans[i]);
    } catch (const std::exception& e) {  // a worker thread must not throw
      outcomes[i].fails_at_zero = true;
      outcomes[i].invalid = true;
      outcomes[i].reason = std::string("the loop with one of the band's humans: ") + e.what();
    }
  });
  out.humans_evaluated = humans.size();
  std::size_t worst = 0;
  for (std::size_t i = 0; i < outcomes.size(); ++i) {
    const HumanPlaneOutcome& o = outcomes[i];
    if (o.fails_at_zero) {
      out.invalid = o.invalid;
      out.reason = o.reason;
      worst = i;
      break;
    }
    if (o.limit < outcomes[worst].limit) worst = i;
  }
  if (ev.human_matters()) {
    for (int j = 0; j < params.axes; ++j) {
      out.worst_human.push_back(ev.human(j, humans[worst][static_cast<size_t>(j)]));
    }
  }
  const HumanPlaneOutcome& w = outcomes[worst];
  if (w.fails_at_zero) return out;
  if (!std::isfinite(w.limit)) {
    out.reason = fmt::format("meets the requirement for every stiffness up to {:g} N/m",
                             options.max_stiffness_N_per_m);
    return out;
  }
  step_down(search, ev, humans[worst], w.limit, params.analysis.required_damping_ratio, out);
  if (w.unresolved) {
    out.reason = (out.reason.empty() ? "" : out.reason + "; ") +
                 "the boundary passes close to a mode the sampler could not separate";
  }
  return out;
}

}  // namespace

}  // namespace teleop::stability
