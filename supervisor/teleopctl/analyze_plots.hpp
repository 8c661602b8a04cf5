// The figures of `teleopctl analyze --plot FILE.svg` (docs/cli.md "Plots"): the z-plane of one
// configuration and the maximum stable fixture stiffness against the sample rate or a swept
// parameter.
#pragma once

#include <nlohmann/json.hpp>
#include <string>

#include "common/core/teleop_params.hpp"
#include "common/stability/analyzer.hpp"
#include "supervisor/teleopctl/svg_plot.hpp"

namespace teleop::ctl {

// Every eigenvalue over the human model (the paper's Fig. 6) at the configured fixtures,
// coloured by the grip force each human was drawn at, those with |z| > 1 ringed (class
// "unstable"), the verdict in the title and an inset around z = 1.
[[nodiscard]] Chart z_plane_chart(const TeleopParams& params,
                                  const stability::AnalysisResult& result);

// What `analyze --max-stiffness --plot` draws: the limits as `--json` prints them.
struct LimitsPlot {
  std::string side{};       // "master" | "slave"
  std::string swept{};      // the --sweep PATH, "" without one
  bool one_rate{true};      // a single rate: the limit against the swept value
  nlohmann::json limits{};  // limit_json() entries, with the swept value under `swept`
  std::string subtitle{};
};
// Limits as lines with markers, rates without a limit as triangles on the axis (class
// "no-limit"), the passivity bound dashed where the analysis gives one (master side).
[[nodiscard]] Chart limits_chart(const LimitsPlot& plot);

// "gains.kps (N/m)": a configuration path with the unit of its field ("(dimensionless)" when
// it has none).
[[nodiscard]] std::string axis_label_with_unit(const std::string& path);
// The unit alone ("" when the field has none).
[[nodiscard]] std::string unit_of(const std::string& path);

}  // namespace teleop::ctl
