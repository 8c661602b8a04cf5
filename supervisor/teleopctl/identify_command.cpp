#include "supervisor/teleopctl/identify_command.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <optional>
#include <ostream>
#include <stdexcept>
#include <utility>

#include "supervisor/teleopctl/cli_args.hpp"
#include "supervisor/teleopctl/replay_command.hpp"
#include "teleop/v1/node_state.pb.h"

namespace teleop::ctl {

namespace {

using nlohmann::json;

// A fit below this explains too little of the force to trust (the paper's were 0.91 and 0.92).
constexpr double kPoorFit = 0.9;
// A row of `teleopctl simulate --out` is written after the physics step: its time, true
// positions and the human's and environment's forces are at the step's end, its commands were
// held over the step, and its *_sensed_m are the samples the laws read at the step's start, one
// row earlier.
constexpr std::size_t kSimulateSensedLag = 1;

struct Csv {
  std::vector<std::string> names{};
  std::vector<std::vector<double>> columns{};
};

[[nodiscard]] std::string trim_cr(std::string line) {
  if (!line.empty() && line.back() == '\r') line.pop_back();
  return line;
}

[[nodiscard]] Csv read_csv(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(fmt::format("cannot read '{}'", path));
  Csv csv;
  std::string line;
  if (!std::getline(in, line)) throw std::runtime_error(fmt::format("{}: empty file", path));
  csv.names = split(trim_cr(line), ',');
  csv.columns.resize(csv.names.size());
  std::size_t line_no = 1;
  while (std::getline(in, line)) {
    ++line_no;
    line = trim_cr(line);
    if (line.empty()) continue;
    const std::vector<std::string> cells = split(line, ',');
    if (cells.size() != csv.names.size()) {
      throw std::runtime_error(fmt::format("{}:{}: {} cells, the header has {}", path, line_no,
                                           cells.size(), csv.names.size()));
    }
    for (std::size_t c = 0; c < cells.size(); ++c) {
      const std::string& cell = cells[c];
      double v = 0.0;
      const char* last = cell.data() + cell.size();
      const auto [ptr, ec] = std::from_chars(cell.data(), last, v);
      if (ec != std::errc{} || ptr != last || !std::isfinite(v)) {
        throw std::runtime_error(fmt::format("{}:{}: column '{}': '{}' is not a finite number",
                                             path, line_no, csv.names[c], cell));
      }
      csv.columns[c].push_back(v);
    }
  }
  if (csv.columns.empty() || csv.columns.front().empty()) {
    throw std::runtime_error(fmt::format("{}: no data rows", path));
  }
  return csv;
}

[[nodiscard]] const std::vector<double>& column(const Csv& csv, const std::string& path,
                                                const std::string& name, const char* what) {
  for (std::size_t c = 0; c < csv.names.size(); ++c) {
    if (csv.names[c] == name) return csv.columns[c];
  }
  std::string known;
  for (const std::string& n : csv.names) known += (known.empty() ? "" : ", ") + n;
  throw std::runtime_error(
      fmt::format("{}: no column '{}' for the {} (columns: {})", path, name, what, known));
}

// Sum of signed columns: an exact column name, or terms joined by '+' and '-'.
[[nodiscard]] std::vector<double> evaluate(const Csv& csv, const std::string& path,
                                           const std::string& expression, const char* what) {
  const std::size_t rows = csv.columns.front().size();
  for (const std::string& n : csv.names) {
    if (n == expression) return column(csv, path, expression, what);
  }
  std::vector<double> sum(rows, 0.0);
  std::size_t i = 0;
  while (i < expression.size()) {
    double sign = 1.0;
    if (expression[i] == '+' || expression[i] == '-') {
      sign = expression[i] == '-' ? -1.0 : 1.0;
      ++i;
    }
    const std::size_t end = expression.find_first_of("+-", i);
    const std::string name = expression.substr(i, end == std::string::npos ? end : end - i);
    if (name.empty()) {
      throw std::runtime_error(fmt::format("the {} '{}' has an empty term", what, expression));
    }
    const std::vector<double>& c = column(csv, path, name, what);
    for (std::size_t r = 0; r < rows; ++r) sum[r] += sign * c[r];
    i = end == std::string::npos ? expression.size() : end;
  }
  return sum;
}

struct IdentifyArgs {
  std::vector<std::string> files{};
  std::optional<std::string> device{};  // master | slave
  CsvColumns columns{};
  bool custom_columns{false};
  stability::IdentifyOptions options{};
  bool json{false};
};

[[nodiscard]] int parse_count(const std::string& text, const char* flag, int min) {
  int v = 0;
  const auto [p, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (ec != std::errc{} || p != text.data() + text.size() || v < min) {
    throw UsageError(fmt::format("{}: '{}' is not an integer >= {}", flag, text, min));
  }
  return v;
}

[[nodiscard]] IdentifyArgs parse_identify_args(const std::vector<std::string>& args) {
  IdentifyArgs a;
  std::optional<std::string> position;
  std::optional<std::string> force;
  std::optional<std::string> held;
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
    } else if (!arg.empty() && arg.front() == '-') {
      throw UsageError(fmt::format("unknown option '{}'", arg));
    } else {
      a.files.push_back(arg);
    }
  }
  if (a.files.empty()) throw UsageError("at least one FILE.csv is required");
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
// session, sequences one apart, sample times one period apart to 1 %, not FAULT). A cycle
// records the position and load-cell force sampled at its start and the command it wrote, held
// until the next sample, so sample k pairs cycle k's position and force with cycle k-1's
// command. The slave's load cell reads its push on the environment: the force on the device is
// its negative. Stretches too short to fit or without motion (a node waiting to be armed) are
// left out and counted.
struct McapRuns {
  std::vector<stability::Series> runs{};
  std::vector<std::string> names{};
  std::size_t short_runs{0};  // too short to fit, or motionless (disarmed): left out
};

[[nodiscard]] McapRuns read_runs_mcap(const std::string& path, bool master,
                                      const stability::IdentifyOptions& options) {
  const std::vector<RecordedCycle> cycles = read_recorded_cycles(path, master);
  if (cycles.size() < 2) {
    throw std::runtime_error(fmt::format("{}: {} cycles of the {} recorded, too few to identify",
                                         path, cycles.size(), master ? "master" : "slave"));
  }
  std::vector<std::int64_t> steps;
  for (std::size_t i = 1; i < cycles.size(); ++i) {
    steps.push_back(cycles[i].sample_time_ns - cycles[i - 1].sample_time_ns);
  }
  std::nth_element(steps.begin(), steps.begin() + static_cast<long>(steps.size() / 2), steps.end());
  const double period_ns = static_cast<double>(steps[steps.size() / 2]);
  if (!(period_ns > 0.0)) {
    throw std::runtime_error(fmt::format("{}: the cycles' sample times do not advance", path));
  }
  const double sign = master ? 1.0 : -1.0;
  McapRuns out;
  std::size_t begin = 0;
  auto close_run = [&](std::size_t end) {  // cycles [begin, end)
    if (end > begin + 1) {
      stability::Series s;
      s.period_s = period_ns * 1e-9;
      for (std::size_t k = begin + 1; k < end; ++k) {
        s.position_m.push_back(cycles[k].position_m);
        s.force_N.push_back(sign * cycles[k].force_N);
        s.held_force_N.push_back(cycles[k - 1].command_N);
      }
      const auto [lo, hi] = std::minmax_element(s.position_m.begin(), s.position_m.end());
      if (stability::usable_rows(s.position_m.size(), true, options) > 0 && *lo != *hi) {
        out.names.push_back(fmt::format("{} {} cycles {}..{}", path, master ? "master" : "slave",
                                        cycles[begin].sequence, cycles[end - 1].sequence));
        out.runs.push_back(std::move(s));
      } else {
        ++out.short_runs;
      }
    } else if (end > begin) {
      ++out.short_runs;
    }
    begin = end;
  };
  for (std::size_t i = 0; i < cycles.size(); ++i) {
    const RecordedCycle& c = cycles[i];
    if (c.mode == v1::FAULT) {
      close_run(i);
      begin = i + 1;
      continue;
    }
    if (i > begin) {
      const RecordedCycle& p = cycles[i - 1];
      const double dt = static_cast<double>(c.sample_time_ns - p.sample_time_ns);
      if (c.session_id != p.session_id || c.sequence != p.sequence + 1 ||
          std::abs(dt - period_ns) > 0.01 * period_ns) {
        close_run(i);
      }
    }
  }
  close_run(cycles.size());
  if (out.runs.empty()) {
    throw std::runtime_error(fmt::format(
        "{}: no stretch of consecutive {} cycles long enough and moving to identify ({} cycles)",
        path, master ? "master" : "slave", cycles.size()));
  }
  return out;
}

[[nodiscard]] std::string config_line(const std::optional<std::string>& side, double mass_kg,
                                      double damping_Ns_per_m) {
  const std::string device = fmt::format("device {{ mass_kg: {:.4g} damping_Ns_per_m: {:.4g} }}",
                                         mass_kg, damping_Ns_per_m);
  return side ? fmt::format("{} {{ {} }}", *side, device) : device;
}

}  // namespace

stability::Series read_series_csv(const std::string& path, const CsvColumns& columns) {
  const Csv csv = read_csv(path);
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
         "                          [--raw-force] [--json]\n\n"
         "Identifies a device's mass and damping, m x'' + b x' = F, by least squares over one\n"
         "or more recorded runs (stacked), from the position smoothed by a multiple-pass\n"
         "three-point moving average and differentiated twice, and prints the configuration\n"
         "line to paste. Drive the device with a force that varies over a band of frequencies\n"
         "(a random push); a free decay cannot separate m from b.\n\n"
         "A session file (teleop-supervisor's recording or 'teleopctl simulate --out FILE.mcap')\n"
         "gives the device's cycles from /master/telemetry or /slave/telemetry: position_m, the\n"
         "load cell's force_N (on the slave the force on the device is -force_N: the cell reads\n"
         "its push on the environment) and the command_N held over the period before each\n"
         "sample; each stretch of consecutive cycles is a run.\n\n"
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
         "  --json           machine-readable output\n"
         "  --help           this text\n";
}

namespace {

// The runs of every file, stacked, each named after its file.
struct LoadedRuns {
  std::vector<stability::Series> runs;
  std::vector<std::string> names;
  std::size_t short_runs = 0;  // stretches of a session file too short to fit (left out)
};

LoadedRuns load_runs(const IdentifyArgs& a) {
  LoadedRuns l;
  for (const std::string& file : a.files) {
    if (!is_mcap_file(file)) {
      l.runs.push_back(read_series_csv(file, a.columns));
      l.names.push_back(file);
      continue;
    }
    if (a.custom_columns || a.columns.rate_hz > 0.0 || a.columns.time != "time_s") {
      throw std::runtime_error(
          fmt::format("{}: a session file: --position, --force, --held-force, --time and --rate "
                      "are for CSV files",
                      file));
    }
    McapRuns m = read_runs_mcap(file, a.device.value_or("master") == "master", a.options);
    for (std::size_t i = 0; i < m.runs.size(); ++i) {
      l.runs.push_back(std::move(m.runs[i]));
      l.names.push_back(m.names[i]);
    }
    l.short_runs += m.short_runs;
  }
  return l;
}

// stability::identify, with the file behind "run N" named in its errors.
stability::IdentifyResult identify_runs(const LoadedRuns& l,
                                        const stability::IdentifyOptions& options) {
  try {
    return stability::identify(l.runs, options);
  } catch (const std::invalid_argument& e) {
    std::string message = e.what();
    for (std::size_t i = l.names.size(); i-- > 0;) {
      const std::string tag = fmt::format("run {}:", i + 1);
      const std::size_t at = message.find(tag);
      if (at != std::string::npos) {
        message.replace(at, tag.size(), fmt::format("run {} ({}):", i + 1, l.names[i]));
        break;
      }
    }
    throw std::runtime_error(message);
  }
}

// What run_identify reports.
struct IdentifyReport {
  std::optional<std::string> side;  // none: a CSV with custom columns and no --device
  stability::IdentifyResult result;
  std::vector<std::string> run_names;
  bool valid = false;  // a mass and damping a device can have
  std::vector<std::string> warnings;
  std::string line;  // the configuration line to paste
};

std::vector<std::string> identify_warnings(const stability::IdentifyResult& r, bool valid,
                                           std::size_t short_runs) {
  std::vector<std::string> warnings;
  if (!valid) {
    warnings.push_back(fmt::format(
        "the fit gives mass {:.4g} kg and damping {:.4g} Ns/m, which no device has: check the "
        "force's sign and columns",
        r.mass_kg, r.damping_Ns_per_m));
  }
  if (r.r_squared < kPoorFit) {
    warnings.push_back(fmt::format(
        "r^2 = {:.3f} is below {}: the mass-damper model explains the force poorly (friction, "
        "contact, a missing force column, too little excitation?)",
        r.r_squared, kPoorFit));
  }
  if (short_runs > 0) {
    warnings.push_back(fmt::format(
        "{} stretch{} of consecutive cycles too short to fit or motionless left out (sequence "
        "gaps, restarts, overruns or faults split a session)",
        short_runs, short_runs == 1 ? "" : "es"));
  }
  return warnings;
}

void print_identify_json(std::ostream& out, const IdentifyReport& rep,
                         const stability::IdentifyOptions& options) {
  const stability::IdentifyResult& r = rep.result;
  json j = {{"device", rep.side ? json(*rep.side) : json(nullptr)},
            {"mass_kg", r.mass_kg},
            {"damping_Ns_per_m", r.damping_Ns_per_m},
            {"r_squared", r.r_squared},
            {"residual_rms_N", r.residual_rms_N},
            {"samples", r.samples},
            {"condition_number", r.condition_number},
            {"smoothing_passes", options.smoothing_passes},
            {"trim_samples", options.trim_samples},
            {"smooth_force", options.smooth_force},
            {"runs", json::array()},
            {"warnings", rep.warnings},
            {"config", rep.valid ? json(rep.line) : json(nullptr)}};
  for (std::size_t i = 0; i < r.runs.size(); ++i) {
    j["runs"].push_back({{"file", rep.run_names[i]},
                         {"samples", r.runs[i].samples},
                         {"r_squared", r.runs[i].r_squared}});
  }
  out << j.dump(2) << "\n";
}

void print_identify_text(std::ostream& out, const IdentifyReport& rep,
                         const stability::IdentifyOptions& options) {
  const stability::IdentifyResult& r = rep.result;
  out << fmt::format("identified {}: {} run{}, {} samples ({} smoothing passes, trim {})\n",
                     rep.side ? *rep.side + " device" : "device", r.runs.size(),
                     r.runs.size() == 1 ? "" : "s", r.samples, options.smoothing_passes,
                     options.trim_samples);
  out << fmt::format("  mass              {:.4g} kg\n", r.mass_kg);
  out << fmt::format("  damping           {:.4g} Ns/m\n", r.damping_Ns_per_m);
  out << fmt::format("  r^2               {:.4f} (residual rms {:.3g} N)\n", r.r_squared,
                     r.residual_rms_N);
  out << fmt::format("  condition number  {:.3g}\n", r.condition_number);
  if (r.runs.size() > 1) {
    for (std::size_t i = 0; i < r.runs.size(); ++i) {
      out << fmt::format("  run {}: {}: {} samples, r^2 {:.4f}\n", i + 1, rep.run_names[i],
                         r.runs[i].samples, r.runs[i].r_squared);
    }
  }
  for (const std::string& w : rep.warnings) out << "  warning: " << w << "\n";
  if (rep.valid) {
    out << (rep.side ? "configuration to paste:\n"
                     : "configuration to paste (inside master { } or slave { }):\n")
        << "  " << rep.line << "\n";
  }
}

}  // namespace

int run_identify(const std::vector<std::string>& args, std::ostream& out, std::ostream& err) {
  IdentifyArgs a;
  try {
    for (const std::string& arg : args) {
      if (arg == "--help" || arg == "-h") {
        out << identify_usage();
        return kExitOk;
      }
    }
    a = parse_identify_args(args);
  } catch (const UsageError& e) {
    err << "teleopctl identify: " << e.what() << "\n" << identify_usage();
    return kExitUsage;
  }
  return run_guarded("identify", err, [&] {
    LoadedRuns loaded = load_runs(a);
    IdentifyReport rep;
    rep.result = identify_runs(loaded, a.options);
    rep.run_names = std::move(loaded.names);
    rep.side =
        a.custom_columns ? a.device : std::optional<std::string>(a.device.value_or("master"));
    rep.valid = rep.result.mass_kg > 0.0 && rep.result.damping_Ns_per_m >= 0.0;
    rep.warnings = identify_warnings(rep.result, rep.valid, loaded.short_runs);
    rep.line = config_line(rep.side, rep.result.mass_kg, rep.result.damping_Ns_per_m);
    if (a.json) {
      print_identify_json(out, rep, a.options);
    } else {
      print_identify_text(out, rep, a.options);
    }
    if (!rep.valid) {
      err << "teleopctl identify: " << rep.warnings.front() << "\n";
      return kExitError;
    }
    return kExitOk;
  });
}

}  // namespace teleop::ctl
