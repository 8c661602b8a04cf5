// Issue 7 "Numbers at the edges": the stability analyser against the independent 50-digit
// reference (tests/unit/stability/reference.hpp, extended in campaign.hpp) on seeded random and
// adversarial configurations. Prints, by class of case, the worst eigenvalue, damping-ratio and
// maximum-stiffness errors, how every verdict compares with the reference inside and outside
// the engine's own error bound, and the run time per case; then every case that shows an
// engine defect, with its full configuration.
//
//   build/bench/bench_campaign_analyser [--cases N] [--seed S] [--case I] [--verbose]
//
// --case I reruns one case of the campaign (as listed in a report) and prints its modes.
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "tests/unit/stability/campaign.hpp"

namespace {

using namespace teleop;
using namespace teleop::campaign;

struct Stats {
  int cases{0};
  std::array<int, 6> check{};               // by VerdictCheck
  std::array<int, 6> fast_check{};          // the eigenvalue-only path
  int stable{0}, unstable{0}, marginal{0};  // by the reference
  double max_dz{0.0};
  double max_dz_over_bound{0.0};
  double max_dz_outer{0.0};
  double max_dzeta{0.0};
  double max_dzeta_over_bound{0.0};
  double max_dzeta_min{0.0};
  int zeta_min_resolved{0};
  int bound_exceeded{0};  // modes with |dz| > the engine's bound
  int structure_mismatch{0};
  int ref_self_check_failed{0};
  int count_mismatch{0};
  double max_leftover{0.0};
  double engine_us{0.0};
  double reference_us{0.0};
  // Maximum stable stiffness.
  int searches{0};
  int finite{0};
  int kind_mismatch{0};
  int kind_justified{0};
  int stopped_early{0};
  int overcautious{0};  // uncertain although farther than twice the bound from the circle
  double max_abs_dk_over_tol{0.0};
  int past_crossing{0};
  int windows_missed{0};
  double max_rel_dk{0.0};
  double max_rel_dk_excess{0.0};  // (|dK| - tolerance)+ / K: beyond what the engine was asked
  double engine_ms{0.0};
  double reference_ms{0.0};
};

void add(Stats& s, const CaseResult& r) {
  ++s.cases;
  ++s.check[static_cast<std::size_t>(r.check)];
  ++s.fast_check[static_cast<std::size_t>(r.fast_check)];
  if (r.ref_marginal) {
    ++s.marginal;
  } else if (r.ref_verdict == stability::Verdict::kStable) {
    ++s.stable;
  } else {
    ++s.unstable;
  }
  s.max_dz = std::max(s.max_dz, r.max_dz);
  s.max_dz_over_bound = std::max(s.max_dz_over_bound, r.max_dz_over_bound);
  s.max_dz_outer = std::max(s.max_dz_outer, r.max_dz_outer);
  s.max_dzeta = std::max(s.max_dzeta, r.max_dzeta);
  s.max_dzeta_over_bound = std::max(s.max_dzeta_over_bound, r.max_dzeta_over_bound);
  if (r.min_zeta_resolved) {
    ++s.zeta_min_resolved;
    s.max_dzeta_min = std::max(s.max_dzeta_min, r.dzeta_min);
  }
  for (const ModeComparison& m : r.modes) s.bound_exceeded += m.dz > m.error_bound ? 1 : 0;
  s.structure_mismatch += r.engine_structure != r.expected ? 1 : 0;
  s.ref_self_check_failed += r.ref_self_check_failed ? 1 : 0;
  s.overcautious += r.check == VerdictCheck::kUncertainOutside && r.outside_twice_bound ? 1 : 0;
  s.count_mismatch += r.count_mismatch ? 1 : 0;
  s.max_leftover = std::max(s.max_leftover, r.leftover_root_abs);
  s.engine_us += r.engine_us;
  s.reference_us += r.reference_us;
}

void add(Stats& s, const LimitResult& l) {
  ++s.searches;
  s.finite += l.both_finite ? 1 : 0;
  s.kind_mismatch += l.kind_mismatch ? 1 : 0;
  s.kind_justified += l.kind_mismatch && l.kind_mismatch_justified ? 1 : 0;
  s.past_crossing += l.engine_stable_where_ref_unstable ? 1 : 0;
  s.stopped_early += l.stopped_early ? 1 : 0;
  if (l.both_finite)
    s.max_abs_dk_over_tol = std::max(s.max_abs_dk_over_tol, std::abs(l.abs_error) / l.tol);
  s.windows_missed += l.window_missed ? 1 : 0;
  if (l.both_finite && !l.window_missed) {
    s.max_rel_dk = std::max(s.max_rel_dk, std::abs(l.rel_error));
    s.max_rel_dk_excess =
        std::max(s.max_rel_dk_excess, std::max(0.0, std::abs(l.abs_error) - l.tol) / l.ref.pass);
  }
  s.engine_ms += l.engine_ms;
  s.reference_ms += l.reference_ms;
}

void merge_into(Stats& a, const Stats& b) {
  a.cases += b.cases;
  for (std::size_t i = 0; i < 6; ++i) {
    a.check[i] += b.check[i];
    a.fast_check[i] += b.fast_check[i];
  }
  a.stable += b.stable;
  a.unstable += b.unstable;
  a.marginal += b.marginal;
  a.max_dz = std::max(a.max_dz, b.max_dz);
  a.max_dz_over_bound = std::max(a.max_dz_over_bound, b.max_dz_over_bound);
  a.max_dz_outer = std::max(a.max_dz_outer, b.max_dz_outer);
  a.max_dzeta = std::max(a.max_dzeta, b.max_dzeta);
  a.max_dzeta_over_bound = std::max(a.max_dzeta_over_bound, b.max_dzeta_over_bound);
  a.max_dzeta_min = std::max(a.max_dzeta_min, b.max_dzeta_min);
  a.zeta_min_resolved += b.zeta_min_resolved;
  a.bound_exceeded += b.bound_exceeded;
  a.structure_mismatch += b.structure_mismatch;
  a.ref_self_check_failed += b.ref_self_check_failed;
  a.count_mismatch += b.count_mismatch;
  a.max_leftover = std::max(a.max_leftover, b.max_leftover);
  a.engine_us += b.engine_us;
  a.reference_us += b.reference_us;
  a.searches += b.searches;
  a.finite += b.finite;
  a.kind_mismatch += b.kind_mismatch;
  a.kind_justified += b.kind_justified;
  a.stopped_early += b.stopped_early;
  a.overcautious += b.overcautious;
  a.max_abs_dk_over_tol = std::max(a.max_abs_dk_over_tol, b.max_abs_dk_over_tol);
  a.past_crossing += b.past_crossing;
  a.windows_missed += b.windows_missed;
  a.max_rel_dk = std::max(a.max_rel_dk, b.max_rel_dk);
  a.max_rel_dk_excess = std::max(a.max_rel_dk_excess, b.max_rel_dk_excess);
  a.engine_ms += b.engine_ms;
  a.reference_ms += b.reference_ms;
}

std::string sci(double x) { return x == 0.0 ? std::string("0") : fmt::format("{:.1e}", x); }

void print_modes(const CaseResult& r) {
  fmt::print("  engine verdict {} (fast path {}), structure {}; reference radius 1 - {:.6e}\n",
             stability::to_string(r.engine.verdict), stability::to_string(r.fast_verdict),
             stability::to_string(r.engine_structure), r.ref.radius_margin);
  for (const ModeComparison& m : r.modes) {
    fmt::print(
        "  z_eng {: .17e}{:+.17e}i  z_ref {: .17e}{:+.17e}i  |dz| {:.2e} bound {:.2e}  "
        "dzeta {:.2e} (bound {:.2e})\n",
        m.engine.real(), m.engine.imag(), m.ref.real(), m.ref.imag(), m.dz, m.error_bound, m.dzeta,
        m.zeta_bound);
  }
  for (const RefRoot& root : r.ref.roots) {
    fmt::print("  ref root {: .20e}{:+.20e}i  1-|z| {: .6e}  zeta {:.10f}\n", root.z.real(),
               root.z.imag(), root.margin, root.zeta);
  }
}

}  // namespace

int main(int argc, char** argv) {
  int cases = 5000;
  std::uint64_t seed = 20260807;
  int only = -1;
  bool verbose = false;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--cases" && i + 1 < argc) {
      cases = std::atoi(argv[++i]);
    } else if (arg == "--seed" && i + 1 < argc) {
      seed = std::strtoull(argv[++i], nullptr, 10);
    } else if (arg == "--case" && i + 1 < argc) {
      only = std::atoi(argv[++i]);
    } else if (arg == "--verbose") {
      verbose = true;
    } else {
      fmt::print(stderr, "usage: {} [--cases N] [--seed S] [--case I] [--verbose]\n", argv[0]);
      return 2;
    }
  }

  if (only >= 0) {
    const Case c = make_case(seed, only);
    fmt::print("{}\n", describe(c));
    const CaseResult r = run_case(c);
    print_modes(r);
    fmt::print("  check: {}; fast path: {}\n", to_string(r.check), to_string(r.fast_check));
    if (c.search) {
      const LimitResult l = run_limit(c);
      fmt::print(
          "  {} limit: engine {} ({}), reference pass {:.17g} fail {:.17g} (kind {}{}); "
          "reference 1-rho at engine K {:.3e}, at K+tol {:.3e}\n",
          c.side == Side::kMaster ? "master" : "slave",
          l.engine.max_stable_stiffness_N_per_m
              ? fmt::format("{:.17g}", *l.engine.max_stable_stiffness_N_per_m)
              : std::string("none"),
          l.engine.reason, l.ref.pass, l.ref.fail, static_cast<int>(l.ref.kind),
          l.ref.marginal_at_zero ? ", marginal at 0" : "", l.ref_margin_at_engine,
          l.ref_margin_above_engine);
    }
    return 0;
  }

  std::array<Stats, kClassCount> by_class{};
  std::vector<std::string> defects;
  std::vector<std::string> notes;
  double worst_dk = 0.0;
  double worst_dz = 0.0;
  std::string worst_dz_case;
  std::string worst_dk_case;
  const auto start = std::chrono::steady_clock::now();
  for (int i = 0; i < cases; ++i) {
    const Case c = make_case(seed, i);
    const CaseResult r = run_case(c);
    Stats& s = by_class[static_cast<std::size_t>(c.cls)];
    add(s, r);
    bool bad = is_defect(r.check) || is_defect(r.fast_check) || r.count_mismatch ||
               r.engine_structure != r.expected || r.max_dz_over_bound > 1.0 ||
               r.leftover_root_abs > 1e-12;
    std::string why;
    if (is_defect(r.check)) why += fmt::format(" verdict {};", to_string(r.check));
    if (is_defect(r.fast_check))
      why += fmt::format(" fast-path verdict {};", to_string(r.fast_check));
    if (r.max_dz_over_bound > 1.0) why += fmt::format(" |dz|/bound {:.3g};", r.max_dz_over_bound);
    if (r.count_mismatch) why += " more modes than reference roots;";
    if (r.engine_structure != r.expected) why += " structure differs;";
    if (r.leftover_root_abs > 1e-12)
      why += fmt::format(" unmatched reference root |z| {:.3g};", r.leftover_root_abs);
    if (r.max_dz > worst_dz) {
      worst_dz = r.max_dz;
      worst_dz_case = describe(c);
      for (const ModeComparison& m : r.modes) {
        if (m.dz < r.max_dz) continue;
        worst_dz_case += fmt::format(
            "\n  z engine {:.17g}{:+.17g}i, reference {:.17g}{:+.17g}i: |dz| {:.3e}, engine "
            "bound {:.3e}, 1 - |z| (reference) {:.3e}",
            m.engine.real(), m.engine.imag(), m.ref.real(), m.ref.imag(), m.dz, m.error_bound,
            1.0 - std::abs(m.ref));
      }
    }
    LimitResult last_limit;
    if (c.search) {
      const LimitResult l = run_limit(c);
      last_limit = l;
      add(s, l);
      if ((l.kind_mismatch && !l.kind_mismatch_justified) || l.engine_stable_where_ref_unstable ||
          l.stopped_early) {
        bad = true;
        why += fmt::format(
            " limit: engine {} ({}), reference {} {:.17g} (1-rho at engine K {:.3e});",
            l.engine.max_stable_stiffness_N_per_m
                ? fmt::format("{:.17g}", *l.engine.max_stable_stiffness_N_per_m)
                : std::string("none"),
            l.engine.reason, static_cast<int>(l.ref.kind), l.ref.pass, l.ref_margin_at_engine);
      }
      if (l.window_missed) {
        notes.push_back(
            fmt::format("{}\n  {} limit: engine {:.17g} lies above an unstable "
                        "window the reference finds at {:.17g} N/m",
                        describe(c), c.side == Side::kMaster ? "master" : "slave",
                        *l.engine.max_stable_stiffness_N_per_m, l.ref.fail));
      }
    }
    const double excess =
        std::max(0.0, std::abs(last_limit.abs_error) - last_limit.tol) / last_limit.ref.pass;
    if (c.search && last_limit.both_finite && !last_limit.window_missed && excess > worst_dk) {
      worst_dk = excess;
      worst_dk_case = fmt::format(
          "{}\n  {} limit: engine {:.17g}, reference {:.17g} (relative {:.3e}); reference "
          "1 - rho at the engine's K {:.3e}, at K + tolerance {:.3e}",
          describe(c), c.side == Side::kMaster ? "master" : "slave",
          *last_limit.engine.max_stable_stiffness_N_per_m, last_limit.ref.pass,
          last_limit.rel_error, last_limit.ref_margin_at_engine,
          last_limit.ref_margin_above_engine);
    }
    if (bad) defects.push_back(fmt::format("{}\n ->{}", describe(c), why));
    if (verbose && bad) print_modes(r);
  }
  const double total_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

  fmt::print("analyser campaign: {} cases, seed {}, {:.1f} s\n\n", cases, seed, total_s);
  fmt::print(
      "columns: reference verdicts stable/unstable/marginal (|1 - rho| < 1e-25); worst |dz| over "
      "all modes and over |z| >= 0.5; worst |dz| / the engine's bound; worst |d zeta| where the "
      "bound resolves zeta (< 0.1) and / its first-order bound; worst |d min zeta|; maximum "
      "stiffness searches finite on both sides / run, worst relative dK, and the same after "
      "taking off the engine's absolute tolerance (1e-4 N/m); mean run time per case\n\n");
  fmt::print("{:<23} {:>5} {:>12} {:>8} {:>8} {:>6} {:>8} {:>6} {:>8} {:>7} {:>8} {:>6} {:>7}\n",
             "class", "cases", "ref s/u/m", "|dz|", "|dz|>.5", "dz/bd", "|dzeta|", "/bd", "|dzmin|",
             "K f/n", "rel dK", "us eng", "us ref");
  Stats all;
  for (int k = 0; k < kClassCount; ++k) merge_into(all, by_class[static_cast<std::size_t>(k)]);
  auto row = [](const char* name, const Stats& s) {
    fmt::print(
        "{:<23} {:>5} {:>12} {:>8} {:>8} {:>6.2f} {:>8} {:>6.3f} {:>8} {:>7} {:>8} {:>8} "
        "{:>6.0f} {:>7.0f}\n",
        name, s.cases, fmt::format("{}/{}/{}", s.stable, s.unstable, s.marginal), sci(s.max_dz),
        sci(s.max_dz_outer), s.max_dz_over_bound, sci(s.max_dzeta), s.max_dzeta_over_bound,
        sci(s.max_dzeta_min), fmt::format("{}/{}", s.finite, s.searches), sci(s.max_rel_dk),
        sci(s.max_rel_dk_excess), s.engine_us / std::max(1, s.cases),
        s.reference_us / std::max(1, s.cases));
  };
  for (int k = 0; k < kClassCount; ++k) {
    row(class_name(static_cast<CaseClass>(k)), by_class[static_cast<std::size_t>(k)]);
  }
  row("all", all);

  fmt::print("\nverdicts against the reference (analyze(), condition-number bounds):\n");
  fmt::print("{:<24} {:>9} {:>9} {:>7} | {:>9} {:>9} {:>7}\n", "class", "out:agree", "out:uncrt",
             "out:WRONG", "in:uncrt", "in:agree", "in:WRONG");
  auto vrow = [](const char* name, const std::array<int, 6>& v) {
    fmt::print("{:<24} {:>9} {:>9} {:>9} | {:>9} {:>9} {:>8}\n", name, v[0], v[1], v[2], v[3], v[4],
               v[5]);
  };
  for (int k = 0; k < kClassCount; ++k) {
    vrow(class_name(static_cast<CaseClass>(k)), by_class[static_cast<std::size_t>(k)].check);
  }
  vrow("all", all.check);
  fmt::print("\nverdicts of the eigenvalue-only path (stiffness search, band sweep):\n");
  for (int k = 0; k < kClassCount; ++k) {
    vrow(class_name(static_cast<CaseClass>(k)), by_class[static_cast<std::size_t>(k)].fast_check);
  }
  vrow("all", all.fast_check);

  fmt::print(
      "\nmodes beyond the engine's bound: {}; uncertain farther than twice the bound: {}; "
      "structure disagreements: {}; cases with more modes than reference roots: {}; largest "
      "unmatched (structural) reference root |z|: {}; reference self-check (Schur-Cohn against "
      "its roots) failures: {}\n",
      all.bound_exceeded, all.overcautious, all.structure_mismatch, all.count_mismatch,
      sci(all.max_leftover), all.ref_self_check_failed);
  fmt::print(
      "maximum stable stiffness: {} searches, {} finite on both sides; finite on one side only: "
      "{} ({} of them where the engine's lower end is within its error bound of the circle); "
      "{} engine limits past the reference's crossing outside the bound, {} stopped early "
      "(reference stable beyond twice the bound one tolerance above), {} above a narrow "
      "unstable window; worst relative dK {}, worst |dK| / tolerance {:.3g}; mean run time "
      "engine {:.1f} ms, reference {:.1f} ms\n",
      all.searches, all.finite, all.kind_mismatch, all.kind_justified, all.past_crossing,
      all.stopped_early, all.windows_missed, sci(all.max_rel_dk), all.max_abs_dk_over_tol,
      all.engine_ms / std::max(1, all.searches), all.reference_ms / std::max(1, all.searches));
  if (!worst_dz_case.empty()) fmt::print("worst eigenvalue case:\n{}\n", worst_dz_case);
  if (!worst_dk_case.empty()) {
    fmt::print("worst maximum-stiffness case (beyond the tolerance):\n{}\n", worst_dk_case);
  }
  fmt::print("\nengine defects: {}\n", defects.size());
  for (const std::string& d : defects) fmt::print("{}\n", d);
  if (!notes.empty()) {
    fmt::print(
        "\nnarrow unstable windows below the engine's limit (docs/stability-limits.md: what "
        "the old x1.2 scan missed):\n");
    for (const std::string& n : notes) fmt::print("{}\n", n);
  }
  return defects.empty() ? 0 : 1;
}
