#include "common/stability/analyzer.hpp"

#include <algorithm>
#include <atomic>
#include <limits>
#include <string>
#include <thread>
#include <vector>

namespace teleop::stability {

LoopEvaluator::LoopEvaluator(const TeleopParams& params, bool master_wall_used,
                             bool slave_wall_used)
    : model_(params, master_wall_used, slave_wall_used) {
  human_matters_ = model_.human_matters() && params.human.kind != HumanKind::kNone;
  if (model_.human_matters()) {
    humans_ = human_samples(params.human);
  } else {
    humans_.push_back(HumanSample{});  // the slave alone: any human gives the same spectrum
  }
  master_plants_.reserve(humans_.size());
  for (const HumanSample& h : humans_) master_plants_.push_back(model_.master_plant(h.impedance));
}

Spectrum LoopEvaluator::spectrum(std::size_t human, double kmvf, double ksvf,
                                 bool estimate_error) const {
  const std::vector<ModelBlock> blocks = model_.build(master_plants_[human], kmvf, ksvf);
  std::vector<Spectrum> parts;
  parts.reserve(blocks.size());
  for (const ModelBlock& b : blocks) {
    parts.push_back(compute_spectrum(b.a, model_.period_s(), b.structural_zeros, estimate_error));
  }
  return parts.size() == 1 ? parts.front() : merge(parts);
}

namespace {
std::atomic<unsigned> g_analysis_threads{0};  // 0: every core
}  // namespace

void set_analysis_threads(unsigned threads) { g_analysis_threads = threads; }

unsigned analysis_threads(std::size_t work_items, std::size_t minimum_for_parallel) {
  if (work_items < minimum_for_parallel) return 1U;
  const unsigned set = g_analysis_threads.load();
  return std::clamp(set == 0 ? std::thread::hardware_concurrency() : set, 1U, 8U);
}

BandResult LoopEvaluator::sweep(double kmvf, double ksvf, double required) const {
  BandResult result;
  result.min_damping_ratio = 2.0;
  double failing_zeta = 3.0;
  bool any_uncertain = false;
  bool any_unstable = false;
  bool any_invalid = false;
  // Blocks without the master do not depend on the human: their spectrum is computed once.
  std::optional<Spectrum> human_free;
  for (const ModelBlock& b : model_.build(master_plants_[0], kmvf, ksvf)) {
    if (!b.includes_master) {
      human_free = compute_spectrum(b.a, model_.period_s(), b.structural_zeros, false);
    }
  }
  // Each human's spectra on the machine's cores (humans are independent), then the worst
  // case in human order, so the result does not depend on the threads.
  struct PerHuman {
    double zeta{2.0};
    double radius{0.0};
    bool invalid{false};
    bool unstable{false};
    bool uncertain{false};
    bool fails{false};
    std::string invalid_reason{};
  };
  std::vector<PerHuman> per(humans_.size());
  auto one = [&](std::size_t i) {
    PerHuman& h = per[i];
    for (const ModelBlock& b : model_.build(master_plants_[i], kmvf, ksvf)) {
      const Spectrum s = b.includes_master || !human_free
                             ? compute_spectrum(b.a, model_.period_s(), b.structural_zeros, false)
                             : *human_free;
      h.zeta = std::min(h.zeta, s.min_damping_ratio);
      h.radius = std::max(h.radius, s.spectral_radius);
      if (s.verdict == Verdict::kInvalid && !h.invalid) {
        h.invalid = true;
        h.invalid_reason = s.invalid_reason;
      }
      h.unstable = h.unstable || s.verdict == Verdict::kUnstable;
      h.uncertain = h.uncertain || s.verdict == Verdict::kUncertain;
      h.fails = h.fails || s.verdict != Verdict::kStable;
    }
    h.fails = h.fails || !(h.zeta >= required);
  };
  const std::size_t n = humans_.size();
  const unsigned threads = analysis_threads(n, 64);
  std::atomic<std::size_t> next{0};
  auto work = [&] {
    for (std::size_t i = next++; i < n; i = next++) one(i);
  };
  std::vector<std::thread> pool;
  for (unsigned t = 1; t < threads; ++t) pool.emplace_back(work);
  work();
  for (std::thread& t : pool) t.join();
  for (std::size_t i = 0; i < n; ++i) {
    const PerHuman& h = per[i];
    if (h.invalid && !any_invalid) {
      any_invalid = true;
      result.invalid_reason = h.invalid_reason;
      result.failing_index = i;
    }
    any_unstable = any_unstable || h.unstable;
    any_uncertain = any_uncertain || h.uncertain;
    if (h.zeta < result.min_damping_ratio) {
      result.min_damping_ratio = h.zeta;
      result.worst_index = i;
    }
    if (h.radius > result.spectral_radius) {
      result.spectral_radius = h.radius;
      result.radius_index = i;
    }
    if (h.fails && h.zeta < failing_zeta) {
      failing_zeta = h.zeta;
      result.failing_index = i;
    }
  }
  result.verdict = any_invalid     ? Verdict::kInvalid
                   : any_unstable  ? Verdict::kUnstable
                   : any_uncertain ? Verdict::kUncertain
                                   : Verdict::kStable;
  if (any_invalid) {
    result.min_damping_ratio = std::numeric_limits<double>::quiet_NaN();
    result.spectral_radius = std::numeric_limits<double>::quiet_NaN();
  }
  return result;
}

bool meets_requirement(const BandResult& r, double required_damping_ratio) {
  // Written so that a NaN damping ratio fails.
  return r.verdict == Verdict::kStable && r.min_damping_ratio >= required_damping_ratio;
}

AnalysisResult analyze(const TeleopParams& params) {
  const LoopEvaluator ev(params);
  const double kmvf = params.master_fixture.stiffness_N_per_m;
  const double ksvf = params.slave_fixture.stiffness_N_per_m;
  AnalysisResult out;
  out.structure = ev.model().structure();
  out.humans_evaluated = ev.model().human_matters() ? ev.human_count() : 0;
  BandResult band;
  if (ev.human_count() == 1) {
    out.spectrum = ev.spectrum(0, kmvf, ksvf, true);
    band = {out.spectrum.verdict, out.spectrum.min_damping_ratio, out.spectrum.spectral_radius, 0};
    band.invalid_reason = out.spectrum.invalid_reason;
  } else {
    band = ev.sweep(kmvf, ksvf);
    out.spectrum = ev.spectrum(band.worst_index, kmvf, ksvf, true);
  }
  out.verdict = band.verdict;
  out.invalid_reason = band.invalid_reason;
  // The detailed spectrum carries error bounds; it may only make the verdict less certain.
  if (out.verdict == Verdict::kStable && out.spectrum.verdict != Verdict::kStable) {
    out.verdict = out.spectrum.verdict;
    out.invalid_reason = out.spectrum.invalid_reason;
  }
  if (out.spectrum.verdict == Verdict::kInvalid && out.verdict != Verdict::kInvalid) {
    out.verdict = Verdict::kInvalid;
    out.invalid_reason = out.spectrum.invalid_reason;
  }
  out.spectral_radius = band.spectral_radius;
  out.min_damping_ratio = band.min_damping_ratio;
  if (out.verdict == Verdict::kInvalid) {
    out.spectral_radius = std::numeric_limits<double>::quiet_NaN();
    out.min_damping_ratio = std::numeric_limits<double>::quiet_NaN();
  }
  if (ev.human_matters()) {
    out.worst_human = ev.human(band.worst_index);
    out.radius_human = ev.human(band.radius_index);
  }
  return out;
}

}  // namespace teleop::stability
