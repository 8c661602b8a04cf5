#include "common/stability/human_grid.hpp"

namespace teleop::stability {

namespace {

double grid_value(const ParameterBand& band, double force_N, int i, int count) {
  const double lo = band.lower.at(force_N);
  const double hi = band.upper.at(force_N);
  if (count <= 1) return lo;
  return lo + (hi - lo) * static_cast<double>(i) / static_cast<double>(count - 1);
}

}  // namespace

std::vector<HumanSample> human_samples(const HumanModel& model) {
  std::vector<HumanSample> out;
  switch (model.kind) {
    case HumanKind::kNone:
      out.push_back(HumanSample{});
      break;
    case HumanKind::kFixed:
      out.push_back(HumanSample{false, 0.0, model.fixed});
      break;
    case HumanKind::kBand: {
      const HumanBand& b = model.band;
      const int n = b.points_per_axis;
      out.reserve(b.force_levels_N.size() * static_cast<std::size_t>(n * n * n));
      for (const double f : b.force_levels_N) {
        for (int im = 0; im < n; ++im) {
          for (int ib = 0; ib < n; ++ib) {
            for (int ik = 0; ik < n; ++ik) {
              out.push_back(HumanSample{
                  true,
                  f,
                  {grid_value(b.mass_kg, f, im, n), grid_value(b.damping_Ns_per_m, f, ib, n),
                   grid_value(b.stiffness_N_per_m, f, ik, n)}});
            }
          }
        }
      }
      break;
    }
  }
  return out;
}

}  // namespace teleop::stability
