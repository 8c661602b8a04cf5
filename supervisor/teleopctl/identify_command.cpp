#include "supervisor/teleopctl/identify_command.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <nlohmann/json.hpp>
#include <optional>
#include <ostream>
#include <stdexcept>
#include <utility>

#include "common/core/teleop_axes.hpp"
#include "common/session/session_reader.hpp"
#include "supervisor/teleopctl/cli_args.hpp"
#include "supervisor/teleopctl/csv_table.hpp"
#include "supervisor/teleopctl/identify_axes_command.hpp"
#include "supervisor/teleopctl/identify_rules.hpp"
#include "supervisor/teleopctl/progress_line.hpp"
#include "supervisor/teleopctl/svg_plot.hpp"
#include "teleop/v1/node_state.pb.h"

namespace teleop::ctl {

namespace {

using nlohmann::json;

using identify_rules::kExitNotIdentified;
using identify_rules::kMinRangeSteps;
using identify_rules::kPoorFit;
// The measured-against-fitted plot shows this much of the first run.
constexpr double kPlotWindow_s = 4.0;
// A row of `teleopctl simulate --out` is written after the physics step: its time, true
// positions and the human's and environment's forces are at the step's end, its commands were
// held over the step, and its *_sensed_m are the samples the laws read at the step's start, one
// row earlier.
constexpr std::size_t kSimulateSensedLag = 1;

struct IdentifyArgs {
  std::vector<std::string> files{};
  std::optional<std::string> device{};  // master | slave
  CsvColumns columns{};
  bool custom_columns{false};
  stability::IdentifyOptions options{};
  bool json{false};
  std::optional<std::string> plot_path{};  // --plot FILE.svg
  // Several comma-separated --position columns: the n-axis fit (identify_axes_command.hpp).
  std::optional<IdentifyAxesArgs> axes{};
  // --mass and --damping for session files of several axes (their models; given: either flag).
  stability::IdentifyAxesOptions axes_options{};
  bool axes_models_given{false};
};

[[nodiscard]] int parse_count(const std::string& text, const char* flag, int min) {
  int v = 0;
  const auto [p, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (ec != std::errc{} || p != text.data() + text.size() || v < min) {
    throw UsageError(fmt::format("{}: '{}' is not an integer >= {}", flag, text, min));
  }
  return v;
}

// --mass per-axis|coupled (default coupled) and --damping diagonal|full (default diagonal).
[[nodiscard]] stability::IdentifyAxesOptions axes_models(
    const std::optional<std::string>& mass, const std::optional<std::string>& damping) {
  if (mass && *mass != "per-axis" && *mass != "coupled") {
    throw UsageError(fmt::format("--mass: '{}' is neither per-axis nor coupled", *mass));
  }
  if (damping && *damping != "diagonal" && *damping != "full") {
    throw UsageError(fmt::format("--damping: '{}' is neither diagonal nor full", *damping));
  }
  stability::IdentifyAxesOptions o;
  o.mass = mass.value_or("coupled") == "coupled" ? stability::MassModel::kCoupled
                                                 : stability::MassModel::kPerAxis;
  o.damping = damping.value_or("diagonal") == "full" ? stability::DampingModel::kFull
                                                     : stability::DampingModel::kDiagonal;
  return o;
}

// `--position x0,x1,...`: one column per task axis, as many --force (and --held-force)
// expressions; the mass model per-axis or coupled (default), the damping diagonal (default) or
// full.
[[nodiscard]] IdentifyAxesArgs parse_axes_args(const IdentifyArgs& a, const std::string& position,
                                               const std::optional<std::string>& force,
                                               const std::optional<std::string>& held,
                                               const std::optional<std::string>& mass,
                                               const std::optional<std::string>& damping) {
  IdentifyAxesArgs x;
  x.files = a.files;
  x.device = a.device;
  x.time = a.columns.time;
  x.rate_hz = a.columns.rate_hz;
  x.json = a.json;
  x.options.filter = a.options;
  x.position = split(position, ',');
  const std::size_t n = x.position.size();
  if (n > static_cast<std::size_t>(kMaxAxes)) {
    throw UsageError(fmt::format("--position: {} columns, at most {} axes", n, kMaxAxes));
  }
  for (const std::string& p : x.position) {
    if (p.empty()) throw UsageError(fmt::format("--position '{}': an empty column", position));
  }
  if (!force) throw UsageError("--position and --force go together (--held-force is optional)");
  x.force = split(*force, ',');
  if (held) x.held_force = split(*held, ',');
  for (const auto& [flag, list] :
       {std::pair<const char*, const std::vector<std::string>*>{"--force", &x.force},
        {"--held-force", &x.held_force}}) {
    if (!list->empty() && list->size() != n) {
      throw UsageError(fmt::format("{}: {} expressions for {} --position columns (one per axis)",
                                   flag, list->size(), n));
    }
  }
  if (a.plot_path) throw UsageError("--plot draws one axis: not with several --position columns");
  for (const std::string& f : a.files) {
    if (record::is_mcap_file(f)) {
      throw UsageError(
          fmt::format("{}: a session file gives its own axes: no --position columns", f));
    }
  }
  const stability::IdentifyOptions filter = x.options.filter;
  x.options = axes_models(mass, damping);
  x.options.filter = filter;
  return x;
}

[[nodiscard]] IdentifyArgs parse_identify_args(const std::vector<std::string>& args) {
  IdentifyArgs a;
  std::optional<std::string> position;
  std::optional<std::string> force;
  std::optional<std::string> held;
  std::optional<std::string> mass;
  std::optional<std::string> damping;
  ArgCursor c(args);
  while (c.next()) {
    const std::string& arg = c.arg();
    if (arg == "--device") {
      const std::string& v = c.value("--device");
      if (v != "master" && v != "slave") {
        throw UsageError(fmt::format("--device: '{}' is neither master nor slave", v));
      }
      a.device = v;
    } else if (arg == "--time") {
      a.columns.time = c.value("--time");
    } else if (arg == "--rate") {
      const std::string& v = c.value("--rate");
      a.columns.rate_hz = parse_number(v, "--rate");
      if (!(a.columns.rate_hz > 0.0)) {
        throw UsageError(fmt::format("--rate: '{}' is not a positive rate in Hz", v));
      }
    } else if (arg == "--position") {
      position = c.value("--position");
    } else if (arg == "--force") {
      force = c.value("--force");
    } else if (arg == "--held-force") {
      held = c.value("--held-force");
    } else if (arg == "--passes") {
      a.options.smoothing_passes = parse_count(c.value("--passes"), "--passes", 1);
    } else if (arg == "--trim") {
      a.options.trim_samples =
          static_cast<std::size_t>(parse_count(c.value("--trim"), "--trim", 0));
    } else if (arg == "--raw-force") {
      a.options.smooth_force = false;
    } else if (arg == "--json") {
      a.json = true;
    } else if (arg == "--plot") {
      a.plot_path = svg_plot_path(c.value("--plot"));
    } else if (arg == "--mass") {
      mass = c.value("--mass");
    } else if (arg == "--damping") {
      damping = c.value("--damping");
    } else if (!arg.empty() && arg.front() == '-') {
      throw UsageError(fmt::format("unknown option '{}'", arg));
    } else {
      a.files.push_back(arg);
    }
  }
  if (a.files.empty()) throw UsageError("at least one FILE.csv is required");
  if (position && position->find(',') != std::string::npos) {
    a.axes = parse_axes_args(a, *position, force, held, mass, damping);
    return a;
  }
  if (mass || damping) {
    const bool sessions =
        !position && std::all_of(a.files.begin(), a.files.end(),
                                 [](const auto& f) { return record::is_mcap_file(f); });
    if (!sessions) {
      throw UsageError(
          "--mass and --damping are for several axes (comma-separated --position columns, or "
          "session files of several axes)");
    }
    a.axes_options = axes_models(mass, damping);
    a.axes_models_given = true;
  }
  a.custom_columns = position || force || held;
  if (a.custom_columns) {
    if (!position || !force) {
      throw UsageError("--position and --force go together (--held-force is optional)");
    }
    a.columns.position = *position;
    a.columns.force = *force;
    a.columns.held_force = held.value_or("");
  } else if (a.device.value_or("master") == "master") {
    // The master is pushed by the human's F_h (sampled) and by -F_am (held over each period).
    a.columns.position = "master_sensed_m";
    a.columns.force = "human_force_N";
    a.columns.held_force = "-master_force_N";
    a.columns.position_lag_rows = kSimulateSensedLag;
  } else {
    // The slave by F_as (held) and by -F_e from its environment (sampled).
    a.columns.position = "slave_sensed_m";
    a.columns.force = "-environment_force_N";
    a.columns.held_force = "slave_force_N";
    a.columns.position_lag_rows = kSimulateSensedLag;
  }
  return a;
}

// A session file's cycles of one node as runs: each stretch of consecutive cycles (same
// session, same number of axes, sequences one apart, sample times one period apart to 1 %, not
// FAULT). A cycle records the position and load-cell force sampled at its start and the command
// it wrote, held until the next sample, so sample k pairs cycle k's position and force with
// cycle k-1's command. The slave's load cell reads its push on the environment: the force on the
// device is its negative. Stretches too short to fit or without motion (a node waiting to be
// armed) are left out and counted. One-axis cycles give `runs`; cycles of n > 1 axes (issue 18)
// give `axes_runs`, each axis as the one axis above.
struct McapRuns {
  int axes{1};
  std::vector<stability::Series> runs{};
  std::vector<stability::SeriesAxes> axes_runs{};
  std::vector<std::string> names{};
  std::size_t short_runs{0};  // too short to fit, or motionless (disarmed): left out
};

using Cycles = std::vector<record::RecordedCycleAxes>;

// The cycles' period: the median step between consecutive sample times, ns.
[[nodiscard]] double median_period_ns(const std::string& path, const Cycles& cycles, bool master) {
  if (cycles.size() < 2) {
    throw std::runtime_error(fmt::format("{}: {} cycles of the {} recorded, too few to identify",
                                         path, cycles.size(), master ? "master" : "slave"));
  }
  std::vector<std::int64_t> steps;
  for (std::size_t i = 1; i < cycles.size(); ++i) {
    steps.push_back(cycles[i].cycle.sample_time_ns - cycles[i - 1].cycle.sample_time_ns);
  }
  std::nth_element(steps.begin(), steps.begin() + static_cast<long>(steps.size() / 2), steps.end());
  const double period_ns = static_cast<double>(steps[steps.size() / 2]);
  if (!(period_ns > 0.0)) {
    throw std::runtime_error(fmt::format("{}: the cycles' sample times do not advance", path));
  }
  return period_ns;
}

// Cycles [begin, end) as one run of `axes` axes (the samples begin + 1 .. end - 1), or nullopt
// when it is too short to fit or does not move.
[[nodiscard]] std::optional<stability::SeriesAxes> axes_run(const Cycles& cycles, std::size_t begin,
                                                            std::size_t end, double period_ns,
                                                            double sign,
                                                            const stability::IdentifyOptions& o) {
  const int n = cycles[begin].cycle.axes;
  const auto rows = static_cast<Eigen::Index>(end - begin - 1);
  if (rows <= 0 || stability::usable_rows(static_cast<std::size_t>(rows), true, o) == 0) {
    return std::nullopt;
  }
  stability::SeriesAxes s;
  s.period_s = period_ns * 1e-9;
  s.position_m.resize(rows, n);
  s.force_N.resize(rows, n);
  s.held_force_N.resize(rows, n);
  for (std::size_t k = begin + 1; k < end; ++k) {
    const auto r = static_cast<Eigen::Index>(k - begin - 1);
    for (int i = 0; i < n; ++i) {
      const auto a = static_cast<std::size_t>(i);
      s.position_m(r, i) = cycles[k].cycle.position_m[a];
      s.force_N(r, i) = sign * cycles[k].cycle.force_N[a];
      s.held_force_N(r, i) = cycles[k - 1].cycle.command_N[a];
    }
  }
  const bool moves =
      ((s.position_m.colwise().maxCoeff() - s.position_m.colwise().minCoeff()).array() > 0.0).any();
  if (!moves) return std::nullopt;
  return s;
}

[[nodiscard]] McapRuns read_runs_mcap(const std::string& path, bool master,
                                      const stability::IdentifyOptions& options,
                                      const BytesRead& read) {
  const Cycles cycles = record::SessionReader::open(path).cycles_axes(master, read);
  const double period_ns = median_period_ns(path, cycles, master);
  const double sign = master ? 1.0 : -1.0;
  const char* side = master ? "master" : "slave";
  McapRuns out;
  out.axes = 0;
  for (const record::RecordedCycleAxes& c : cycles) out.axes = std::max(out.axes, c.cycle.axes);
  std::size_t begin = 0;
  auto close_run = [&](std::size_t end) {  // cycles [begin, end)
    if (end > begin + 1 && cycles[begin].cycle.axes == out.axes) {
      std::optional<stability::SeriesAxes> s =
          axes_run(cycles, begin, end, period_ns, sign, options);
      if (s) {
        out.names.push_back(fmt::format("{} {} cycles {}..{}", path, side,
                                        cycles[begin].cycle.sequence,
                                        cycles[end - 1].cycle.sequence));
        if (out.axes == 1) {
          // One axis: the one-axis fit's series, as before several axes.
          stability::Series one;
          one.period_s = s->period_s;
          one.position_m.assign(s->position_m.data(), s->position_m.data() + s->position_m.size());
          one.force_N.assign(s->force_N.data(), s->force_N.data() + s->force_N.size());
          one.held_force_N.assign(s->held_force_N.data(),
                                  s->held_force_N.data() + s->held_force_N.size());
          out.runs.push_back(std::move(one));
        } else {
          out.axes_runs.push_back(std::move(*s));
        }
      } else {
        ++out.short_runs;
      }
    } else if (end > begin) {
      ++out.short_runs;
    }
    begin = end;
  };
  for (std::size_t i = 0; i < cycles.size(); ++i) {
    const record::RecordedCycleAxes& c = cycles[i];
    if (c.cycle.mode == node::Mode::kFault) {
      close_run(i);
      begin = i + 1;
      continue;
    }
    if (i > begin) {
      const record::RecordedCycleAxes& p = cycles[i - 1];
      const double dt = static_cast<double>(c.cycle.sample_time_ns - p.cycle.sample_time_ns);
      if (c.session_id != p.session_id || c.cycle.axes != p.cycle.axes ||
          c.cycle.sequence != p.cycle.sequence + 1 || std::abs(dt - period_ns) > 0.01 * period_ns) {
        close_run(i);
      }
    }
  }
  close_run(cycles.size());
  if (out.names.empty()) {
    throw std::runtime_error(fmt::format(
        "{}: no stretch of consecutive {} cycles long enough and moving to identify ({} cycles)",
        path, side, cycles.size()));
  }
  return out;
}

// The fit as `--set` overrides: they replace the file's values wherever the file sets them
// (a pasted `master { device { ... } }` would be a second master section).
[[nodiscard]] std::vector<std::string> set_overrides(const std::string& side, double mass_kg,
                                                     double damping_Ns_per_m) {
  return {fmt::format("{}.device.mass_kg={:.4g}", side, mass_kg),
          fmt::format("{}.device.damping_Ns_per_m={:.4g}", side, damping_Ns_per_m)};
}

[[nodiscard]] std::string set_line(const std::vector<std::string>& overrides) {
  std::string line;
  for (const std::string& o : overrides) line += (line.empty() ? "--set " : " --set ") + o;
  return line;
}

}  // namespace

stability::Series read_series_csv(
    const std::string& path, const CsvColumns& columns,
    const std::function<void(std::uint64_t done, std::uint64_t total)>& read) {
  const Csv csv = read_csv(path, read);
  stability::Series s;
  s.position_m = column(csv, path, columns.position, "position");
  s.force_N = evaluate(csv, path, columns.force, "force");
  if (!columns.held_force.empty()) {
    s.held_force_N = evaluate(csv, path, columns.held_force, "held force");
  }
  if (columns.rate_hz > 0.0) {
    s.period_s = 1.0 / columns.rate_hz;
  } else {
    s.time_s = column(csv, path, columns.time, "time (or give --rate)");
  }
  const std::size_t lag = columns.position_lag_rows;
  if (lag > 0) {
    const std::size_t rows = s.position_m.size();
    if (rows <= lag) {
      throw std::runtime_error(fmt::format("{}: {} rows, fewer than the position lag", path, rows));
    }
    s.position_m.erase(s.position_m.begin(), s.position_m.begin() + static_cast<long>(lag));
    auto drop_tail = [&](std::vector<double>& v) {
      if (!v.empty()) v.resize(rows - lag);
    };
    drop_tail(s.force_N);
    drop_tail(s.held_force_N);
    drop_tail(s.time_s);
  }
  return s;
}

std::string identify_usage() {
  return "usage: teleopctl identify FILE.csv|FILE.mcap... [--device master|slave] [--passes N]\n"
         "                          [--trim N] [--time COL | --rate HZ]\n"
         "                          [--position COL --force EXPR [--held-force EXPR]]\n"
         "                          [--raw-force] [--json] [--plot FILE.svg]\n"
         "       teleopctl identify FILE.csv... --position X0,X1,.. --force F0,F1,..\n"
         "                          [--held-force H0,H1,..] [--mass coupled|per-axis]\n"
         "                          [--damping diagonal|full] [--device D] [--json] ...\n\n"
         "Identifies a device's mass and damping, m x'' + b x' = F, by least squares over one\n"
         "or more recorded runs (stacked), from the position smoothed by a multiple-pass\n"
         "three-point moving average and differentiated twice, and prints them as --set\n"
         "overrides (PATH=VALUE: for teleopctl analyze|simulate, the nodes and the supervisor;\n"
         "they replace the file's values). Drive the device with a force that varies over a\n"
         "band of frequencies (a random push, examples/scenes/identify_excitation.textproto);\n"
         "a free decay cannot separate m from b. With too little excitation (r^2 below 0.9, or\n"
         "the position moving over fewer than 10 steps of its resolution) nothing is\n"
         "identified: it says why and exits 4.\n\n"
         "A session file (teleop-supervisor's recording or 'teleopctl simulate --out FILE.mcap')\n"
         "gives the device's cycles from /master/telemetry or /slave/telemetry: position_m, the\n"
         "load cell's force_N (on the slave the force on the device is -force_N: the cell reads\n"
         "its push on the environment) and the command_N held over the period before each\n"
         "sample; each stretch of consecutive cycles is a run.\n\n"
         "Several axes (CSV files): comma-separated --position columns, one per task axis, and\n"
         "as many --force (and --held-force) expressions fit M x'' + B x' = F with the mass\n"
         "matrix M coupled (symmetric, default) or per-axis (diagonal) and B diagonal (default)\n"
         "or full, printed as --set overrides of device.mass_matrix_kg and\n"
         "device.damping_Ns_per_m_per_axis. Drive every axis with its own force. A session\n"
         "file of a node with several axes gives them itself (each axis's position_m, force_N\n"
         "and command_N as above; no --position), --mass and --damping as for CSV files.\n\n"
         "options:\n"
         "  --device D       which paddle of a session file or of a 'teleopctl simulate --out'\n"
         "                   CSV (default master). CSV master: position master_sensed_m, force "
         "human_force_N and the\n"
         "                   held actuator force -master_force_N; slave: slave_sensed_m,\n"
         "                   -environment_force_N and slave_force_N\n"
         "  --position COL   any CSV with a header: the position column, m\n"
         "  --force EXPR     the external force along +x sampled with the position, N: a\n"
         "                   column, or signed columns such as 'load_N-bias_N'\n"
         "  --held-force EXPR  a force held over the period ending at each row (an actuator\n"
         "                   command), centred on the row before it is added\n"
         "  --time COL       sample times, uniform (default time_s)\n"
         "  --rate HZ        the sample rate instead of a time column\n"
         "  --passes N       moving-average passes per smoothing stage (default 8; more at\n"
         "                   higher sample rates)\n"
         "  --trim N         further samples dropped at each end of each run (default 0)\n"
         "  --raw-force      do not smooth the force like the regressors\n"
         "  --mass M         several axes: coupled (default) or per-axis\n"
         "  --damping B      several axes: diagonal (default) or full\n"
         "  --json           machine-readable output\n"
         "  --plot F.svg     the first run's position (mm) and its measured force against the\n"
         "                   fitted m x'' + b x' (N), first 4 s\n"
         "  --help           this text\n"
         "Exit: 0 identified, 1 unreadable data or a fit no device has (check the force's sign),\n"
         "2 usage, 4 not identified (too little excitation: nothing to use).\n";
}

namespace {

// Every run of every file: a session file's stretches of consecutive cycles, or a CSV file.
struct Runs {
  std::vector<stability::Series> runs{};
  std::vector<std::string> names{};
  std::size_t short_runs{0};
  // Session files of n > 1 axes (issue 18): their runs, fitted by identify_axes_runs.
  int axes{1};
  std::vector<stability::SeriesAxes> axes_runs{};
};

// Reading the files and the fit in the time they take (measured on a 300 s session, 300 000
// samples: reading a node's cycles 0.35 s, the fit 0.06 s).
constexpr double kIdentifyReadFile = 0.35;
constexpr double kIdentifyFit = 0.06;

[[nodiscard]] Runs read_runs(const IdentifyArgs& a, ProgressParts& parts) {
  Runs out;
  for (const std::string& file : a.files) {
    const auto read = parts.bytes(kIdentifyReadFile);
    if (record::is_mcap_file(file)) {
      if (a.custom_columns || a.columns.rate_hz > 0.0 || a.columns.time != "time_s") {
        throw std::runtime_error(fmt::format(
            "{}: a session file: --position, --force, --held-force, --time and --rate are "
            "for CSV files",
            file));
      }
      McapRuns m = read_runs_mcap(file, a.device.value_or("master") == "master", a.options, read);
      if (&file != &a.files.front() && m.axes != out.axes) {
        throw std::runtime_error(
            fmt::format("{}: cycles of {} axes, the files before {}", file, m.axes, out.axes));
      }
      out.axes = m.axes;
      for (std::size_t i = 0; i < m.runs.size(); ++i) out.runs.push_back(std::move(m.runs[i]));
      for (std::size_t i = 0; i < m.axes_runs.size(); ++i) {
        out.axes_runs.push_back(std::move(m.axes_runs[i]));
      }
      for (const std::string& name : m.names) out.names.push_back(name);
      out.short_runs += m.short_runs;
    } else {
      if (out.axes != 1) {
        throw std::runtime_error(
            fmt::format("{}: a CSV file among session files of {} axes", file, out.axes));
      }
      out.runs.push_back(read_series_csv(file, a.columns, read));
      out.names.push_back(file);
    }
  }
  return out;
}

// The fit, its errors naming the file behind "run N".
[[nodiscard]] stability::IdentifyResult fit(const Runs& runs,
                                            const stability::IdentifyOptions& options) {
  try {
    return stability::identify(runs.runs, options);
  } catch (const std::invalid_argument& e) {
    std::string message = e.what();
    for (std::size_t i = runs.names.size(); i-- > 0;) {
      const std::string tag = fmt::format("run {}:", i + 1);
      const std::size_t at = message.find(tag);
      if (at != std::string::npos) {
        message.replace(at, tag.size(), fmt::format("run {} ({}):", i + 1, runs.names[i]));
        break;
      }
    }
    throw std::runtime_error(message);
  }
}

[[nodiscard]] bool physical(const stability::IdentifyResult& r) {
  return r.mass_kg > 0.0 && r.damping_Ns_per_m >= 0.0;
}

// How far the device moved over its runs (identify_rules.hpp).
using Excitation = identify_rules::Motion;

[[nodiscard]] Excitation excitation(const Runs& runs) {
  std::vector<std::vector<double>> positions;
  for (const stability::Series& s : runs.runs) positions.push_back(s.position_m);
  return identify_rules::motion_of(positions);
}

// Why the data do not determine the parameters (empty: they do).
[[nodiscard]] std::vector<std::string> refusals(const stability::IdentifyResult& r,
                                                const Excitation& e) {
  std::vector<std::string> why;
  if (e.quantised() && e.steps() < kMinRangeSteps) {
    why.push_back(fmt::format(
        "the position moved over {:.3g} mm, {:.1f} steps of its resolution ({:.4g} mm, an "
        "encoder count): fewer than {:g}, so quantisation dominates the accelerations",
        e.range_m * 1e3, e.steps(), e.step_m * 1e3, kMinRangeSteps));
  }
  if (r.r_squared < kPoorFit) {
    why.push_back(fmt::format(
        "r^2 = {:.3f} is below {}: the mass-damper model explains the force poorly (too little "
        "excitation, friction, contact, a missing force column?)",
        r.r_squared, kPoorFit));
  }
  return why;
}

[[nodiscard]] std::vector<std::string> fit_warnings(std::size_t short_runs) {
  std::vector<std::string> warnings;
  if (short_runs > 0) {
    warnings.push_back(fmt::format(
        "{} stretch{} of consecutive cycles too short to fit or motionless left out (sequence "
        "gaps, restarts, overruns or faults split a session)",
        short_runs, short_runs == 1 ? "" : "es"));
  }
  return warnings;
}

// What was fitted, for output.
struct Fitted {
  const IdentifyArgs& args;
  const Runs& runs;
  const stability::IdentifyResult& result;
  std::optional<std::string> side{};
  Excitation excitation{};
  std::string unphysical{};            // why no device has these parameters, or ""
  std::vector<std::string> refused{};  // why the data do not determine them
  std::vector<std::string> warnings{};
  [[nodiscard]] bool identified() const { return unphysical.empty() && refused.empty(); }
};

void print_json(const Fitted& f, std::ostream& out) {
  const stability::IdentifyResult& r = f.result;
  const IdentifyArgs& a = f.args;
  const bool ok = f.identified();
  std::vector<std::string> reasons = f.refused;
  if (!f.unphysical.empty()) reasons.push_back(f.unphysical);
  json j = {
      {"device", f.side ? json(*f.side) : json(nullptr)},
      {"identified", ok},
      {"reasons", reasons},
      {"mass_kg", ok ? json(r.mass_kg) : json(nullptr)},
      {"damping_Ns_per_m", ok ? json(r.damping_Ns_per_m) : json(nullptr)},
      {"r_squared", r.r_squared},
      {"residual_rms_N", r.residual_rms_N},
      {"samples", r.samples},
      {"condition_number", r.condition_number},
      {"position_range_m", f.excitation.range_m},
      {"position_step_m", f.excitation.quantised() ? json(f.excitation.step_m) : json(nullptr)},
      {"smoothing_passes", a.options.smoothing_passes},
      {"trim_samples", a.options.trim_samples},
      {"smooth_force", a.options.smooth_force},
      {"runs", json::array()},
      {"warnings", f.warnings},
      {"set",
       ok && f.side ? json(set_overrides(*f.side, r.mass_kg, r.damping_Ns_per_m)) : json(nullptr)}};
  for (std::size_t i = 0; i < r.runs.size(); ++i) {
    j["runs"].push_back({{"file", f.runs.names[i]},
                         {"samples", r.runs[i].samples},
                         {"r_squared", r.runs[i].r_squared}});
  }
  out << j.dump(2) << "\n";
}

void print_text(const Fitted& f, std::ostream& out) {
  const stability::IdentifyResult& r = f.result;
  const IdentifyArgs& a = f.args;
  const std::string what = f.side ? *f.side + " device" : "device";
  out << (f.identified() ? "identified " + what + ": " : "NOT IDENTIFIED (" + what + "): ");
  out << fmt::format("{} run{}, {} samples ({} smoothing passes, trim {})\n", r.runs.size(),
                     r.runs.size() == 1 ? "" : "s", r.samples, a.options.smoothing_passes,
                     a.options.trim_samples);
  if (f.identified()) {
    out << fmt::format("  mass              {:.4g} kg\n", r.mass_kg);
    out << fmt::format("  damping           {:.4g} Ns/m\n", r.damping_Ns_per_m);
  }
  out << fmt::format("  r^2               {:.4f} (residual rms {:.3g} N)\n", r.r_squared,
                     r.residual_rms_N);
  out << fmt::format("  condition number  {:.3g}\n", r.condition_number);
  out << fmt::format("  position range    {:.4g} mm", f.excitation.range_m * 1e3);
  out << (f.excitation.quantised() ? fmt::format(" ({:.1f} steps of {:.4g} mm)\n",
                                                 f.excitation.steps(), f.excitation.step_m * 1e3)
                                   : std::string("\n"));
  if (r.runs.size() > 1) {
    for (std::size_t i = 0; i < r.runs.size(); ++i) {
      out << fmt::format("  run {}: {}: {} samples, r^2 {:.4f}\n", i + 1, f.runs.names[i],
                         r.runs[i].samples, r.runs[i].r_squared);
    }
  }
  for (const std::string& w : f.warnings) out << "  warning: " << w << "\n";
  if (!f.identified()) {
    for (const std::string& why : f.refused) out << "  not identified: " << why << "\n";
    if (!f.unphysical.empty()) out << "  not identified: " << f.unphysical << "\n";
    out << "  no parameters to use: drive the device with a force varying over 0.5-10 Hz that\n"
           "  moves it several millimetres (examples/scenes/identify_excitation.textproto)\n";
    return;
  }
  if (f.side) {
    out << "configuration (--set overrides; they replace the file's values):\n  "
        << set_line(set_overrides(*f.side, r.mass_kg, r.damping_Ns_per_m)) << "\n";
  } else {
    out << "configuration (--set overrides; they replace the file's values), for the master:\n  "
        << set_line(set_overrides("master", r.mass_kg, r.damping_Ns_per_m))
        << "\nor for the slave:\n  "
        << set_line(set_overrides("slave", r.mass_kg, r.damping_Ns_per_m)) << "\n";
  }
}

// The first run, at most kPlotWindow_s of it: its position, and its force (as fitted: smoothed
// like the regressors unless --raw-force) against m x'' + b x'.
void write_fit_plot(const std::string& path, const Fitted& f) {
  const stability::Series& run = f.runs.runs.front();
  const stability::RegressionRows rows = stability::regression_rows(run, f.args.options);
  const double period_s = run.time_s.empty() ? run.period_s
                                             : (run.time_s.back() - run.time_s.front()) /
                                                   static_cast<double>(run.time_s.size() - 1);
  const double t0 = run.time_s.empty() ? 0.0 : run.time_s.front();
  // Rows up to kPlotWindow_s after the run's first sample (a round end for the time axis).
  const auto window_end = static_cast<std::size_t>(std::floor(kPlotWindow_s / period_s + 1e-9));
  const std::size_t n = std::min(
      rows.force.size(), window_end > rows.first_sample ? window_end - rows.first_sample + 1 : 1);
  const stability::IdentifyResult& r = f.result;
  Chart chart = position_force_chart(
      f.identified()
          ? fmt::format("Identified {}: m = {:.4g} kg, b = {:.4g} Ns/m, r² = {:.3f}",
                        f.side.value_or("device"), r.mass_kg, r.damping_Ns_per_m, r.r_squared)
          : fmt::format("{}: NOT IDENTIFIED (r² = {:.3f})", f.side.value_or("device"), r.r_squared),
      fmt::format("{}: {:.3g} s of {:.3g} s shown", f.runs.names.front(),
                  static_cast<double>(n) * period_s,
                  static_cast<double>(rows.force.size()) * period_s));
  Series x{"measured position", {}, line_colour(0), true};
  Series measured{
      f.args.options.smooth_force ? "measured force (smoothed as the fit)" : "measured force",
      {},
      "#000000",
      true};
  Series fitted{"fitted m x'' + b x'", {}, line_colour(1), true};
  fitted.dashed = true;
  const std::size_t stride = plot_stride(n);
  for (std::size_t i = 0; i < n; i += stride) {
    const std::size_t k = rows.first_sample + i;
    const double t = t0 + static_cast<double>(k) * period_s;
    x.points.emplace_back(t, 1e3 * run.position_m[k]);
    measured.points.emplace_back(t, rows.force[i]);
    fitted.points.emplace_back(
        t, r.mass_kg * rows.acceleration[i] + r.damping_Ns_per_m * rows.velocity[i]);
  }
  chart.panels[0].series.push_back(std::move(x));
  chart.panels[1].series = {std::move(measured), std::move(fitted)};
  if (!f.refused.empty()) chart.notes.push_back("not identified:");
  if (f.excitation.quantised() && f.excitation.steps() < kMinRangeSteps) {
    chart.notes.push_back(fmt::format("motion over {:.1f} encoder counts (fewer than {:g})",
                                      f.excitation.steps(), kMinRangeSteps));
  }
  if (r.r_squared < kPoorFit) {
    chart.notes.push_back(fmt::format("r² = {:.3f} (below {:g})", r.r_squared, kPoorFit));
  }
  write_svg(path, chart);
}

// The runs read and fitted under a progress line, erased before anything is printed.
struct Read {
  Runs runs;
  stability::IdentifyResult result;
};

[[nodiscard]] Read read_and_fit(const IdentifyArgs& a, std::ostream& err) {
  ProgressLine progress(err, "identify", !a.json && stderr_is_terminal());
  ProgressParts parts(progress,
                      static_cast<double>(a.files.size()) * kIdentifyReadFile + kIdentifyFit);
  Runs runs = read_runs(a, parts);
  // The fit reports nothing as it goes: the line shows where it starts.
  if (const auto fitting = parts.fraction(kIdentifyFit)) fitting(0.0);
  if (runs.axes > 1) return {std::move(runs), {}};  // identify_axes_runs fits them
  stability::IdentifyResult r = fit(runs, a.options);
  return {std::move(runs), std::move(r)};
}

// Session files of n > 1 axes: the n-axis fit and report of identify_axes_command.hpp, the
// runs named by file and cycles.
int identify_session_axes(const IdentifyArgs& a, const Runs& runs, std::ostream& out,
                          std::ostream& err) {
  if (a.plot_path) {
    throw std::runtime_error(fmt::format(
        "--plot draws one axis: the session records {} axes (not with several axes)", runs.axes));
  }
  IdentifyAxesArgs x;
  x.files = runs.names;
  x.device = a.device.value_or("master");
  x.json = a.json;
  x.options = a.axes_options;
  x.options.filter = a.options;
  return identify_axes_runs(x, runs.axes_runs, out, err);
}

int identify(const IdentifyArgs& a, std::ostream& out, std::ostream& err) {
  if (a.axes) return identify_axes(*a.axes, out, err);
  const Read read = read_and_fit(a, err);
  if (read.runs.axes > 1) return identify_session_axes(a, read.runs, out, err);
  if (a.axes_models_given) {
    throw std::runtime_error(
        "--mass and --damping are for several axes: the session files record one");
  }
  const Runs& runs = read.runs;
  const stability::IdentifyResult& r = read.result;
  Fitted f{a, runs, r};
  f.side = a.custom_columns ? a.device : std::optional<std::string>(a.device.value_or("master"));
  f.excitation = excitation(runs);
  if (!physical(r)) {
    f.unphysical = fmt::format(
        "the fit gives mass {:.4g} kg and damping {:.4g} Ns/m, which no device has: check the "
        "force's sign and columns",
        r.mass_kg, r.damping_Ns_per_m);
  }
  f.refused = refusals(r, f.excitation);
  f.warnings = fit_warnings(runs.short_runs);
  if (a.json) {
    print_json(f, out);
  } else {
    print_text(f, out);
  }
  if (a.plot_path) write_fit_plot(*a.plot_path, f);
  // A poor fit first: its parameters mean nothing, signs included. A good fit no device has
  // is a sign or column mistake.
  if (!f.refused.empty()) {
    err << "teleopctl identify: not identified, too little excitation: " << f.refused.front()
        << "\n";
    return kExitNotIdentified;
  }
  if (!f.unphysical.empty()) {
    err << "teleopctl identify: " << f.unphysical << "\n";
    return kExitError;
  }
  return kExitOk;
}

}  // namespace

int run_identify(const std::vector<std::string>& args, std::ostream& out, std::ostream& err) {
  return run_parsed("identify", args, identify_usage, out, err, parse_identify_args,
                    [&](const IdentifyArgs& a) { return identify(a, out, err); });
}

}  // namespace teleop::ctl
