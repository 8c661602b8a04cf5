#include "common/stability/analysis_axes.hpp"

#include <fmt/format.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <complex>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <thread>

#include "common/stability/axes_detail.hpp"

namespace teleop::stability {

using detail::normal_axis;
using detail::parallel_for;

namespace {

using Mat = Eigen::MatrixXd;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

bool is_diagonal(const Mat& m) {
  for (Eigen::Index i = 0; i < m.rows(); ++i) {
    for (Eigen::Index j = 0; j < m.cols(); ++j) {
      if (i != j && m(i, j) != 0.0) return false;
    }
  }
  return true;
}

// Nothing couples the axes: every matrix diagonal, every plane of non-zero stiffness (or every
// plane of a side searched) along an axis.
bool axes_decouple(const TeleopAxesParams& p, bool master_used, bool slave_used) {
  const GainsAxes& g = p.gains;
  for (const Mat* m : {&p.master_device.mass_kg, &p.slave_device.mass_kg, &g.kpm, &g.kps, &g.kdm,
                       &g.kds, &g.kvm, &g.kvs, &g.kfm}) {
    if (!is_diagonal(*m)) return false;
  }
  if (p.human.kind == HumanKind::kFixed) {
    const HumanImpedanceAxes& h = p.human.fixed;
    for (const Mat* m : {&h.mass_kg, &h.damping_Ns_per_m, &h.stiffness_N_per_m}) {
      if (!is_diagonal(*m)) return false;
    }
  }
  for (const auto& [planes, used] :
       {std::pair{&p.master_planes, master_used}, std::pair{&p.slave_planes, slave_used}}) {
    for (const PlaneFixtureParams& pl : *planes) {
      if ((pl.stiffness_N_per_m != 0.0 || used) && normal_axis(pl.normal) < 0) return false;
    }
  }
  return true;
}

// Axis j of a decoupled teleoperator as the one-axis teleoperator (its planes' stiffness summed
// into the one fixture of each side).
TeleopParams one_axis_params(const TeleopAxesParams& p, int j) {
  TeleopParams a;
  a.sample_rate_hz = p.sample_rate_hz;
  a.master_device = {p.master_device.mass_kg(j, j), p.master_device.damping_Ns_per_m(j)};
  a.slave_device = {p.slave_device.mass_kg(j, j), p.slave_device.damping_Ns_per_m(j)};
  a.master_fixture.stiffness_N_per_m = plane_stiffness_matrix(p.master_planes, p.axes)(j, j);
  a.slave_fixture.stiffness_N_per_m = plane_stiffness_matrix(p.slave_planes, p.axes)(j, j);
  const GainsAxes& g = p.gains;
  a.gains = {g.kpm(j, j), g.kps(j, j), g.kdm(j, j), g.kds(j, j),
             g.kvm(j, j), g.kvs(j, j), g.kfm(j, j)};
  a.scaling = p.scaling;
  a.velocity_cutoff_hz = p.velocity_cutoff_hz;
  a.round_trip_delay_samples = p.round_trip_delay_samples;
  a.human.kind = p.human.kind;
  if (p.human.kind == HumanKind::kFixed) {
    const HumanImpedanceAxes& h = p.human.fixed;
    a.human.fixed = {h.mass_kg(j, j), h.damping_Ns_per_m(j, j), h.stiffness_N_per_m(j, j)};
  }
  if (p.human.kind == HumanKind::kBand)
    a.human.band = p.human.band_per_axis[static_cast<size_t>(j)];
  a.analysis = p.analysis;
  return a;
}

bool same_bound(const ParameterBand& a, const ParameterBand& b) {
  return a.lower.intercept == b.lower.intercept && a.lower.slope_per_N == b.lower.slope_per_N &&
         a.upper.intercept == b.upper.intercept && a.upper.slope_per_N == b.upper.slope_per_N;
}

// Two one-axis loops with the same spectrum for every human of their (same) band.
bool same_loop(const TeleopParams& a, const TeleopParams& b) {
  const HumanBand& x = a.human.band;
  const HumanBand& y = b.human.band;
  const bool same_band =
      x.force_levels_N == y.force_levels_N && x.points_per_axis == y.points_per_axis &&
      same_bound(x.mass_kg, y.mass_kg) && same_bound(x.damping_Ns_per_m, y.damping_Ns_per_m) &&
      same_bound(x.stiffness_N_per_m, y.stiffness_N_per_m);
  const HumanImpedance& h = a.human.fixed;
  const HumanImpedance& g = b.human.fixed;
  return a.master_device.mass_kg == b.master_device.mass_kg &&
         a.master_device.damping_Ns_per_m == b.master_device.damping_Ns_per_m &&
         a.slave_device.mass_kg == b.slave_device.mass_kg &&
         a.slave_device.damping_Ns_per_m == b.slave_device.damping_Ns_per_m &&
         a.master_fixture.stiffness_N_per_m == b.master_fixture.stiffness_N_per_m &&
         a.slave_fixture.stiffness_N_per_m == b.slave_fixture.stiffness_N_per_m &&
         a.gains == b.gains && a.human.kind == b.human.kind && h.mass_kg == g.mass_kg &&
         h.damping_Ns_per_m == g.damping_Ns_per_m && h.stiffness_N_per_m == g.stiffness_N_per_m &&
         (a.human.kind != HumanKind::kBand || same_band);
}

Verdict worse(Verdict a, Verdict b) {
  auto rank = [](Verdict v) {
    switch (v) {
      case Verdict::kStable:
        return 0;
      case Verdict::kUncertain:
        return 1;
      case Verdict::kUnstable:
        return 2;
      case Verdict::kInvalid:
        return 3;
    }
    return 3;
  };
  return rank(a) >= rank(b) ? a : b;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// AxesEvaluator

struct AxesEvaluator::PerHuman {
  double zeta{2.0};
  double radius{0.0};
  Verdict verdict{Verdict::kStable};
  std::string invalid_reason{};
};

AxesEvaluator::AxesEvaluator(const TeleopAxesParams& params, const AxesAnalysisOptions& options,
                             bool master_planes_used, bool slave_planes_used)
    : n_(params.axes),
      period_s_(params.period_s()),
      kind_(params.human.kind),
      max_product_(options.max_product_humans),
      refine_(options.refine_walked_band),
      fixed_(params.human.fixed) {
  if (const std::string why = check_axes_params(params); !why.empty()) {
    throw std::invalid_argument(why);
  }
  if (options.decouple && axes_decouple(params, master_planes_used, slave_planes_used)) {
    // Axes with the same one-axis loop share one evaluator (isotropic tangent axes).
    for (int j = 0; j < n_; ++j) {
      axis_params_.push_back(one_axis_params(params, j));
      std::size_t source = per_axis_.size();
      for (int i = 0; i < j; ++i) {
        if (same_loop(axis_params_[static_cast<size_t>(i)], axis_params_.back())) {
          source = axis_source_[static_cast<size_t>(i)];
          break;
        }
      }
      if (source == per_axis_.size()) {
        per_axis_.push_back(std::make_unique<LoopEvaluator>(axis_params_.back(), master_planes_used,
                                                            slave_planes_used));
        human_matters_ = human_matters_ || per_axis_.back()->human_matters();
      }
      axis_source_.push_back(source);
    }
    return;
  }
  model_ = std::make_unique<DiscreteModelAxes>(params, master_planes_used, slave_planes_used);
  human_matters_ = model_->human_matters() && kind_ != HumanKind::kNone;
  for (int j = 0; j < n_; ++j) {
    HumanModel one;
    one.kind = human_matters_ && kind_ == HumanKind::kBand ? HumanKind::kBand : HumanKind::kNone;
    if (one.kind == HumanKind::kBand) one.band = params.human.band_per_axis[static_cast<size_t>(j)];
    grids_.push_back(human_samples(one));
  }
  if (!human_matters_ || kind_ != HumanKind::kBand) {
    single_plant_ = model_->master_plant(
        human_matters_
            ? fixed_
            : HumanImpedanceAxes{Mat::Zero(n_, n_), Mat::Zero(n_, n_), Mat::Zero(n_, n_)});
  }
}

Structure AxesEvaluator::structure() const {
  if (model_) return model_->structure();
  Structure most = Structure::kSlaveOnly;
  for (const auto& ev : per_axis_) {
    const Structure s = ev->model().structure();
    auto rank = [](Structure x) {
      return x == Structure::kBilateral    ? 3
             : x == Structure::kDecoupled  ? 2
             : x == Structure::kMasterOnly ? 1
                                           : 0;
    };
    if (rank(s) > rank(most)) most = s;
  }
  return most;
}

AxesEvaluator::~AxesEvaluator() = default;

std::size_t AxesEvaluator::grid_size(int axis) const {
  return decoupled() ? per_axis(axis).human_count() : grids_[static_cast<size_t>(axis)].size();
}

const HumanSample& AxesEvaluator::human(int axis, std::size_t i) const {
  return decoupled() ? per_axis(axis).human(i) : grids_[static_cast<size_t>(axis)][i];
}

const TeleopParams& AxesEvaluator::axis_params(int axis) const {
  return axis_params_.at(static_cast<size_t>(axis));
}

const LoopEvaluator& AxesEvaluator::axis_evaluator(int axis) const { return per_axis(axis); }

std::vector<AxesBlock> AxesEvaluator::blocks(const HumanChoice& h, const Mat& kmvf,
                                             const Mat& ksvf) const {
  if (!model_) throw std::logic_error("AxesEvaluator::blocks: the axes are analysed one by one");
  if (single_plant_) return model_->build(*single_plant_, kmvf, ksvf);
  HumanImpedanceAxes z{Mat::Zero(n_, n_), Mat::Zero(n_, n_), Mat::Zero(n_, n_)};
  for (int j = 0; j < n_; ++j) {
    const HumanImpedance& one = human(j, h[static_cast<size_t>(j)]).impedance;
    z.mass_kg(j, j) = one.mass_kg;
    z.damping_Ns_per_m(j, j) = one.damping_Ns_per_m;
    z.stiffness_N_per_m(j, j) = one.stiffness_N_per_m;
  }
  return model_->build(model_->master_plant(z), kmvf, ksvf);
}

Spectrum AxesEvaluator::spectrum(const HumanChoice& h, const Mat& kmvf, const Mat& ksvf,
                                 bool estimate_error) const {
  std::vector<Spectrum> parts;
  if (decoupled()) {
    parts.reserve(static_cast<size_t>(n_));  // a copied part refers to an earlier one
    for (int j = 0; j < n_; ++j) {
      const auto uj = static_cast<size_t>(j);
      // An axis with the same loop, human and planes as an earlier one (the free tangent axes
      // of an isotropic loop) has the same spectrum: copied, not computed again.
      int same = -1;
      for (int i = 0; i < j && same < 0; ++i) {
        const auto ui = static_cast<size_t>(i);
        if (axis_source_[ui] == axis_source_[uj] && h[ui] == h[uj] && kmvf(i, i) == kmvf(j, j) &&
            ksvf(i, i) == ksvf(j, j)) {
          same = i;
        }
      }
      parts.push_back(same >= 0
                          ? parts[static_cast<size_t>(same)]
                          : per_axis(j).spectrum(h[uj], kmvf(j, j), ksvf(j, j), estimate_error));
    }
  } else {
    for (const AxesBlock& b : blocks(h, kmvf, ksvf)) {
      parts.push_back(compute_spectrum(b.a, period_s_, b.structural_zeros, estimate_error));
    }
  }
  return parts.size() == 1 ? parts.front() : merge(parts);
}

AxesEvaluator::PerHuman AxesEvaluator::evaluate(const HumanChoice& h, const Mat& kmvf,
                                                const Mat& ksvf,
                                                const std::optional<Spectrum>& human_free) const {
  PerHuman r;
  std::vector<AxesBlock> loop;
  try {
    loop = blocks(h, kmvf, ksvf);
  } catch (const std::exception& e) {
    // A band line that leaves the master with the human not positive definite, say: this
    // human's loop is not a model at all, and a worker thread must not throw.
    r.verdict = Verdict::kInvalid;
    r.zeta = kNaN;
    r.radius = kNaN;
    r.invalid_reason = std::string("the loop with one of the band's humans: ") + e.what();
    return r;
  }
  for (const AxesBlock& b : loop) {
    const Spectrum s = b.includes_master || !human_free
                           ? compute_spectrum(b.a, period_s_, b.structural_zeros, false)
                           : *human_free;
    r.zeta = std::min(r.zeta, s.min_damping_ratio);
    r.radius = std::max(r.radius, s.spectral_radius);
    if (s.verdict == Verdict::kInvalid && r.verdict != Verdict::kInvalid) {
      r.invalid_reason = s.invalid_reason;
    }
    r.verdict = worse(r.verdict, s.verdict);
  }
  return r;
}

std::vector<HumanChoice> AxesEvaluator::candidates() const {
  std::vector<std::size_t> sizes;
  std::size_t product = 1;
  std::size_t largest = 1;
  for (int j = 0; j < n_; ++j) {
    sizes.push_back(grid_size(j));
    largest = std::max(largest, sizes.back());
    product = product > max_product_ ? product : product * sizes.back();
  }
  std::vector<HumanChoice> out;
  if (product <= max_product_) {
    HumanChoice c(static_cast<size_t>(n_), 0);
    for (std::size_t k = 0; k < product; ++k) {
      out.push_back(c);
      for (std::size_t j = 0; j < c.size(); ++j) {  // mixed-radix increment
        if (++c[j] < sizes[j]) break;
        c[j] = 0;
      }
    }
    return out;
  }
  for (std::size_t i = 0; i < largest; ++i) {
    HumanChoice c;
    for (const std::size_t s : sizes) c.push_back(i % s);
    out.push_back(c);
  }
  return out;
}

AxesBandResult AxesEvaluator::sweep_decoupled(const Mat& kmvf, const Mat& ksvf) const {
  AxesBandResult r;
  r.min_damping_ratio = 2.0;
  r.worst.assign(static_cast<size_t>(n_), 0);
  r.radius_worst.assign(static_cast<size_t>(n_), 0);
  std::vector<std::optional<BandResult>> done(static_cast<size_t>(n_));
  for (int j = 0; j < n_; ++j) {
    const auto uj = static_cast<size_t>(j);
    // Each axis's band alone (the axes are independent, so the worst over their product is
    // the worst axis's worst); an axis like an earlier one is not swept again.
    for (int i = 0; i < j && !done[uj]; ++i) {
      const auto ui = static_cast<size_t>(i);
      if (axis_source_[ui] == axis_source_[uj] && kmvf(i, i) == kmvf(j, j) &&
          ksvf(i, i) == ksvf(j, j)) {
        done[uj] = done[ui];
      }
    }
    if (!done[uj]) {
      done[uj] = per_axis(j).sweep(kmvf(j, j), ksvf(j, j), 0.0);
      r.humans_evaluated += per_axis(j).human_count();
    }
    const BandResult& b = *done[uj];
    r.worst[uj] = b.worst_index;
    r.radius_worst[uj] = b.radius_index;
    if (b.verdict == Verdict::kInvalid && r.verdict != Verdict::kInvalid) {
      r.invalid_reason = "axis " + std::to_string(j) + ": " + b.invalid_reason;
    }
    r.verdict = worse(r.verdict, b.verdict);
    r.min_damping_ratio = std::min(r.min_damping_ratio, b.min_damping_ratio);
    r.spectral_radius = std::max(r.spectral_radius, b.spectral_radius);
  }
  return r;
}

AxesBandResult AxesEvaluator::sweep(const Mat& kmvf, const Mat& ksvf) const {
  AxesBandResult r;
  if (decoupled()) {
    r = sweep_decoupled(kmvf, ksvf);
  } else {
    // Blocks without the master do not depend on the human: computed once.
    std::optional<Spectrum> human_free;
    for (const AxesBlock& b : blocks(HumanChoice(static_cast<size_t>(n_), 0), kmvf, ksvf)) {
      if (!b.includes_master) {
        human_free = compute_spectrum(b.a, period_s_, b.structural_zeros, false);
      }
    }
    r.min_damping_ratio = 2.0;
    const std::vector<HumanChoice> start = candidates();
    bool first = true;
    // The worst case over a list of humans, folded into r (in list order: thread-independent).
    auto fold = [&](const std::vector<HumanChoice>& list) {
      std::vector<PerHuman> per(list.size());
      parallel_for(list.size(),
                   [&](std::size_t i) { per[i] = evaluate(list[i], kmvf, ksvf, human_free); });
      bool improved = false;
      for (std::size_t i = 0; i < list.size(); ++i) {
        const PerHuman& h = per[i];
        if (h.verdict == Verdict::kInvalid && r.verdict != Verdict::kInvalid) {
          r.invalid_reason = h.invalid_reason;
        }
        r.verdict = worse(r.verdict, h.verdict);
        if (first || h.zeta < r.min_damping_ratio) {
          improved = improved || !first;
          r.min_damping_ratio = h.zeta;
          r.worst = list[i];
        }
        if (first || h.radius > r.spectral_radius) {
          r.spectral_radius = h.radius;
          r.radius_worst = list[i];
        }
        first = false;
      }
      r.humans_evaluated += list.size();
      return improved;
    };
    fold(start);
    // Walked together, the grids miss combinations: refine one axis at a time around the worst
    // until no axis lowers the damping ratio (a local search, flagged not exhaustive).
    std::size_t product = 1;
    for (int j = 0; j < n_ && product <= max_product_; ++j) product *= grid_size(j);
    const bool walked = product > max_product_;
    r.exhaustive = !walked;
    // An axis's line is scanned again only when another axis's human changed since.
    std::vector<HumanChoice> scanned_around(static_cast<size_t>(n_));
    for (int round = 0; walked && refine_ && round < 2 * n_; ++round) {
      bool changed = false;
      for (int j = 0; j < n_; ++j) {
        HumanChoice context = r.worst;
        context[static_cast<size_t>(j)] = 0;
        if (context == scanned_around[static_cast<size_t>(j)]) continue;
        scanned_around[static_cast<size_t>(j)] = context;
        std::vector<HumanChoice> line;
        for (std::size_t i = 0; i < grid_size(j); ++i) {
          HumanChoice c = r.worst;
          c[static_cast<size_t>(j)] = i;
          if (c != r.worst) line.push_back(c);
        }
        changed = fold(line) || changed;
      }
      if (!changed) break;
    }
  }
  if (r.verdict == Verdict::kInvalid) {
    r.min_damping_ratio = kNaN;
    r.spectral_radius = kNaN;
  }
  return r;
}

// ---------------------------------------------------------------------------------------------
// analyze_axes

namespace {

AxesAnalysis invalid_analysis(std::string why) {
  AxesAnalysis out;
  out.verdict = Verdict::kInvalid;
  out.invalid_reason = std::move(why);
  out.spectral_radius = out.stability_margin = out.min_damping_ratio = kNaN;
  return out;
}

// `params` analysed; `configured` (the same loop, perhaps in another frame) for the plane limits.
AxesAnalysis analyze_valid(const TeleopAxesParams& params, const TeleopAxesParams& configured,
                           const AxesAnalysisOptions& options);

}  // namespace

AxesAnalysis analyze_axes(const TeleopAxesParams& params, const AxesAnalysisOptions& options) {
  if (std::string why = check_axes_params(params); !why.empty()) {
    return invalid_analysis(std::move(why));
  }
  // The plane-limit search's resolution: NaN or infinity is not a configuration to call stable.
  if (const double tol = params.analysis.stiffness_tolerance_N_per_m;
      !std::isfinite(tol) || !(tol > 0.0)) {
    return invalid_analysis("analysis.stiffness_tolerance_N_per_m must be positive and finite");
  }
  try {
    // Isotropic with tilted planes: the same loop in the planes' frame, axis by axis.
    if (options.decouple) {
      if (const std::optional<detail::PlaneFrame> f = detail::in_plane_frame(params)) {
        return analyze_valid(f->params, params, options);
      }
    }
    return analyze_valid(params, params, options);
  } catch (const std::exception& e) {
    return invalid_analysis(e.what());
  }
}

namespace {

AxesAnalysis analyze_valid(const TeleopAxesParams& params, const TeleopAxesParams& configured,
                           const AxesAnalysisOptions& options) {
  AxesAnalysis out;
  const AxesEvaluator ev(params, options);
  const Mat kmvf = plane_stiffness_matrix(params.master_planes, params.axes);
  const Mat ksvf = plane_stiffness_matrix(params.slave_planes, params.axes);
  out.structure = ev.structure();
  out.decoupled = ev.decoupled();
  bool single = true;
  for (int j = 0; j < params.axes; ++j) single = single && ev.grid_size(j) == 1;
  AxesBandResult band;
  if (single) {
    // One human: its spectrum with error bounds is the whole analysis (as analyze() does).
    band.worst = band.radius_worst = HumanChoice(static_cast<size_t>(params.axes), 0);
    out.spectrum = ev.spectrum(band.worst, kmvf, ksvf, true);
    band.verdict = out.spectrum.verdict;
    band.min_damping_ratio = out.spectrum.min_damping_ratio;
    band.spectral_radius = out.spectrum.spectral_radius;
    band.invalid_reason = out.spectrum.invalid_reason;
    band.humans_evaluated = ev.human_matters() ? 1 : 0;
  } else {
    band = ev.sweep(kmvf, ksvf);
    out.spectrum = ev.spectrum(band.worst, kmvf, ksvf, true);
  }
  out.humans_evaluated = band.humans_evaluated;
  out.band_exhaustive = band.exhaustive;
  out.verdict = band.verdict;
  out.invalid_reason = band.invalid_reason;
  // The detailed spectrum carries error bounds: it may only make the verdict less certain.
  if (out.verdict == Verdict::kStable && out.spectrum.verdict != Verdict::kStable) {
    out.verdict = out.spectrum.verdict;
  }
  if (out.spectrum.verdict == Verdict::kInvalid && out.verdict != Verdict::kInvalid) {
    out.verdict = Verdict::kInvalid;
  }
  if (out.verdict == Verdict::kInvalid && out.invalid_reason.empty()) {
    out.invalid_reason = out.spectrum.invalid_reason;
  }
  out.spectral_radius = band.spectral_radius;
  out.min_damping_ratio = band.min_damping_ratio;
  if (out.verdict == Verdict::kInvalid) {
    out.spectral_radius = kNaN;
    out.min_damping_ratio = kNaN;
  }
  out.stability_margin = 1.0 - out.spectral_radius;
  if (ev.human_matters()) {
    for (int j = 0; j < params.axes; ++j) {
      out.worst_human.push_back(ev.human(j, band.worst[static_cast<size_t>(j)]));
      out.radius_human.push_back(ev.human(j, band.radius_worst[static_cast<size_t>(j)]));
    }
  }
  if (!options.plane_limits) return out;
  double closest = -1.0;
  for (const Side side : {Side::kMaster, Side::kSlave}) {
    const auto& planes = side == Side::kMaster ? configured.master_planes : configured.slave_planes;
    for (std::size_t i = 0; i < planes.size(); ++i) {
      if (planes[i].stiffness_N_per_m == 0.0) continue;
      out.plane_limits.push_back(plane_stiffness_limit(configured, side, i, options));
      const PlaneLimit& l = out.plane_limits.back();
      const double ratio = l.max_stable_stiffness_N_per_m && *l.max_stable_stiffness_N_per_m > 0.0
                               ? planes[i].stiffness_N_per_m / *l.max_stable_stiffness_N_per_m
                               : -1.0;
      if (ratio > closest) {
        closest = ratio;
        out.limiting_plane = out.plane_limits.size() - 1;
      }
    }
  }
  return out;
}

}  // namespace

}  // namespace teleop::stability
