// The Python module `teleop` (docs/python.md): thin bindings over the libraries teleopctl uses.
// Sessions come from common/session, the analyses from teleopctl's analyze (the same JSON
// documents, hence the same field names), the simulation from common/scene through
// config::to_scene_setup. Configuration text goes through config::parse_config_text /
// parse_config_file and the analysis' own builder, the one validation path; its errors become
// ValueError with the message teleopctl prints under "invalid configuration:".
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cerrno>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "common/config/config_loader.hpp"
#include "common/config/scene_loader.hpp"
#include "common/core/version.hpp"
#include "common/scene/lockstep.hpp"
#include "common/session/session_reader.hpp"
#include "python/session_columns.hpp"
#include "supervisor/teleopctl/analyze_command.hpp"
#include "supervisor/teleopctl/json_output.hpp"
#include "supervisor/teleopctl/simulate_command.hpp"

namespace py = pybind11;
using nlohmann::json;

namespace teleop::python {

namespace {

// Source name of configuration text given as a string (a file given as a path keeps its name).
constexpr const char* kTextSource = "<text>";

py::object to_python(const json& j) {
  switch (j.type()) {
    case json::value_t::null:
    case json::value_t::discarded:
      return py::none();
    case json::value_t::boolean:
      return py::bool_(j.get<bool>());
    case json::value_t::number_integer:
      return py::int_(j.get<std::int64_t>());
    case json::value_t::number_unsigned:
      return py::int_(j.get<std::uint64_t>());
    case json::value_t::number_float:
      return py::float_(j.get<double>());
    case json::value_t::string:
      return py::str(j.get<std::string>());
    case json::value_t::array: {
      py::list l;
      for (const json& e : j) l.append(to_python(e));
      return l;
    }
    case json::value_t::object:
    case json::value_t::binary:
      break;
  }
  py::dict d;
  for (const auto& [k, v] : j.items()) d[py::str(k)] = to_python(v);
  return d;
}

// A Python value as the VALUE of `--set PATH=VALUE`: numbers in their shortest round-trip form,
// booleans as true/false, sequences as comma lists, strings as written.
std::string override_value(const py::handle& v) {
  if (py::isinstance<py::bool_>(v)) return v.cast<bool>() ? "true" : "false";
  if (py::isinstance<py::str>(v)) return v.cast<std::string>();
  if (py::isinstance<py::float_>(v) || py::isinstance<py::int_>(v)) return py::repr(v);
  if (py::hasattr(v, "__index__")) return py::repr(py::int_(py::reinterpret_borrow<py::object>(v)));
  if (py::hasattr(v, "__float__")) {
    return py::repr(py::float_(py::reinterpret_borrow<py::object>(v)));
  }
  if (py::isinstance<py::list>(v) || py::isinstance<py::tuple>(v)) {
    std::string s;
    for (const py::handle e : v) s += (s.empty() ? "" : ",") + override_value(e);
    return s;
  }
  throw py::type_error("an override's value must be a number, bool, string or list, not " +
                       std::string(py::str(py::type::of(v).attr("__name__"))));
}

// `overrides` (a dict PATH -> value, a list of "PATH=VALUE" strings, or None) then the keyword
// arguments (PATH=value), in order: as --set would apply them.
std::vector<std::string> collect_overrides(const py::object& overrides, const py::kwargs& kwargs) {
  std::vector<std::string> sets;
  if (py::isinstance<py::dict>(overrides)) {
    for (const auto& [k, v] : overrides.cast<py::dict>()) {
      sets.push_back(std::string(py::str(k)) + "=" + override_value(v));
    }
  } else if (py::isinstance<py::str>(overrides)) {
    sets.push_back(overrides.cast<std::string>());
  } else if (!overrides.is_none()) {
    for (const py::handle s : overrides) sets.push_back(py::str(s).cast<std::string>());
  }
  for (const auto& [k, v] : kwargs)
    sets.push_back(std::string(py::str(k)) + "=" + override_value(v));
  return sets;
}

// Configuration text (str) or a file (os.PathLike: its name in messages, as teleopctl's).
config::LoadedConfig parse_config(const py::object& source, const std::vector<std::string>& sets) {
  if (py::hasattr(source, "__fspath__")) {
    const std::string path = py::str(source.attr("__fspath__")());
    return config::parse_config_file(path, sets);
  }
  if (!py::isinstance<py::str>(source)) {
    throw py::type_error("configuration: give its text (str) or a path (pathlib.Path)");
  }
  return config::parse_config_text(source.cast<std::string>(), kTextSource, sets);
}

template <typename T>
py::array_t<T> to_array(const std::vector<T>& v) {
  return py::array_t<T>(static_cast<py::ssize_t>(v.size()), v.data());
}

py::object analyze(const py::object& config, const py::object& overrides, const py::kwargs& kw) {
  const config::LoadedConfig cfg = parse_config(config, collect_overrides(overrides, kw));
  if (cfg.config.has_force_loop() && !cfg.config.has_gains()) {
    throw py::value_error(cfg.source_name +
                          " describes a force loop (force_loop) and no teleoperator (no gains): "
                          "analyse it with teleop.analyze_force_loop");
  }
  json doc;
  {
    const py::gil_scoped_release unlocked;
    doc = ctl::analysis_document(cfg);
  }
  return to_python(doc);
}

py::object analyze_force_loop(const py::object& config, const py::object& overrides,
                              const py::kwargs& kw) {
  const config::LoadedConfig cfg = parse_config(config, collect_overrides(overrides, kw));
  return to_python(ctl::force_loop_document(cfg));
}

std::optional<ctl::Sweep> sweep_of(const py::object& sweep) {
  if (sweep.is_none()) return std::nullopt;
  if (py::isinstance<py::str>(sweep)) return ctl::parse_sweep(sweep.cast<std::string>());
  const auto t = sweep.cast<py::tuple>();
  if (t.size() != 4)
    throw py::value_error("sweep: give (PATH, FROM, TO, STEP) or 'PATH=FROM:TO:STEP'");
  return ctl::parse_sweep(py::str(t[0]).cast<std::string>() + "=" + override_value(t[1]) + ":" +
                          override_value(t[2]) + ":" + override_value(t[3]));
}

py::object max_stiffness(const py::object& config, const std::string& side_name,
                         const std::optional<std::vector<double>>& rates_hz,
                         const py::object& sweep, const py::object& overrides,
                         const py::kwargs& kw) {
  stability::Side side = stability::Side::kSlave;
  if (side_name == "master") {
    side = stability::Side::kMaster;
  } else if (side_name != "slave") {
    throw py::value_error("side takes 'slave' or 'master', not '" + side_name + "'");
  }
  const std::vector<double> rates = rates_hz.value_or(std::vector<double>{});
  for (const double hz : rates) {
    if (!(hz > 0.0))
      throw py::value_error("rates_hz: " + std::to_string(hz) + " Hz is not positive");
  }
  const std::optional<ctl::Sweep> s = sweep_of(sweep);
  const config::LoadedConfig cfg = parse_config(config, collect_overrides(overrides, kw));
  json doc;
  {
    const py::gil_scoped_release unlocked;
    doc = ctl::limits_document(cfg, side, rates, s).document;
  }
  return to_python(doc);
}

py::object simulate(const py::object& scene_source, const py::object& overrides,
                    const py::kwargs& kw) {
  const config::LoadedConfig cfg = parse_config(scene_source, collect_overrides(overrides, kw));
  const scene::SceneSetup setup = config::to_scene_setup(cfg);
  scene::SimulationResult r;
  json summary;
  {
    const py::gil_scoped_release unlocked;
    r = scene::simulate(setup);
    summary = ctl::simulation_document(cfg, setup, r);
  }
  py::dict out;
  const std::size_t n = r.columns.size();
  const std::size_t rows = n == 0 ? 0 : r.rows.size() / n;
  for (std::size_t c = 0; c < n; ++c) {
    py::array_t<double> a(static_cast<py::ssize_t>(rows));
    auto w = a.mutable_unchecked<1>();
    for (std::size_t k = 0; k < rows; ++k) w(static_cast<py::ssize_t>(k)) = r.rows[k * n + c];
    out[py::str(r.columns[c])] = a;
  }
  out["summary"] = to_python(summary);
  return out;
}

py::object column_array(const Column& c) {
  switch (c.kind) {
    case Column::Kind::kDouble:
      return to_array(c.doubles);
    case Column::Kind::kSigned:
      return to_array(c.signed_values);
    case Column::Kind::kUnsigned:
      return to_array(c.unsigned_values);
    case Column::Kind::kBool:
      return to_array(c.signed_values).attr("astype")("bool");
    case Column::Kind::kEnum:
      return to_array(c.signed_values).attr("astype")("int32");
    case Column::Kind::kString:
      return py::cast(c.strings);
  }
  return py::none();
}

// Each stamped message as its --json form (proto field names) with its log time.
template <typename T>
py::list stamped_list(const std::vector<record::Stamped<T>>& messages) {
  py::list l;
  for (const record::Stamped<T>& s : messages) {
    json j = ctl::proto_json(s.message);
    j["log_time_ns"] = s.log_time_ns;
    l.append(to_python(j));
  }
  return l;
}

py::dict channels_dict(const std::vector<ChannelColumns>& channels, std::uint64_t first_log_ns,
                       py::dict& enums) {
  py::dict out;
  for (const ChannelColumns& ch : channels) {
    py::dict d;
    d["log_time_ns"] = to_array(ch.log_time_ns);
    d["publish_time_ns"] = to_array(ch.publish_time_ns);
    std::vector<double> log_s(ch.log_time_ns.size());
    std::vector<double> time_s(ch.publish_time_ns.size());
    for (std::size_t i = 0; i < log_s.size(); ++i) {
      log_s[i] = 1e-9 * static_cast<double>(ch.log_time_ns[i] - first_log_ns);
      // Differences in integers first: ns since the epoch do not fit a double exactly.
      time_s[i] = 1e-9 * static_cast<double>(static_cast<std::int64_t>(ch.publish_time_ns[i] -
                                                                       ch.publish_time_ns[0]));
    }
    d["log_time_s"] = to_array(log_s);
    d["time_s"] = to_array(time_s);
    py::dict names;
    for (const Column& c : ch.columns) {
      d[py::str(c.name)] = column_array(c);
      if (c.kind == Column::Kind::kEnum) names[py::str(c.name)] = py::cast(c.enum_names);
    }
    out[py::str(ch.topic)] = d;
    enums[py::str(ch.topic)] = names;
  }
  return out;
}

py::object open_session(const py::object& path_like) {
  const std::string path = py::str(py::module_::import("os").attr("fspath")(path_like));
  if (!std::filesystem::exists(path)) {
    const py::object e = py::module_::import("builtins")
                             .attr("FileNotFoundError")(ENOENT, "no such session file", path);
    PyErr_SetObject(PyExc_FileNotFoundError, e.ptr());
    throw py::error_already_set();
  }
  std::optional<record::SessionReader> session;
  std::vector<ChannelColumns> channels;
  {
    const py::gil_scoped_release unlocked;
    session.emplace(record::SessionReader::open(path));
    channels = read_channel_columns(*session);
  }
  py::dict out;
  out["path"] = path;
  out["library"] = session->mcap().header().library;
  py::dict enums;
  out["channels"] = channels_dict(channels, session->first_log_time_ns(), enums);
  out["enums"] = enums;
  const std::optional<v1::SystemConfig> cfg = session->config();
  std::string text;
  if (cfg) google::protobuf::TextFormat::PrintToString(*cfg, &text);
  out["config_text"] = cfg ? py::object(py::str(text)) : py::none();
  out["alarms"] = stamped_list(session->alarms());
  out["parameter_changes"] = stamped_list(session->parameter_changes());
  out["reports"] = stamped_list(session->reports());
  return out;
}

}  // namespace

}  // namespace teleop::python

PYBIND11_MODULE(teleop, m) {
  using namespace teleop::python;
  m.doc() =
      "teleop: sessions, analysis and simulation of the bilateral teleoperator "
      "(docs/python.md)";
  m.attr("__version__") = std::string(teleop::version());
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const teleop::config::ConfigError& e) {
      PyErr_SetString(PyExc_ValueError, e.what());
    } catch (const teleop::cli::UsageError& e) {
      PyErr_SetString(PyExc_ValueError, e.what());
    }
  });
  m.def("analyze", &analyze, py::arg("config"), py::arg("overrides") = py::none(),
        "The stability analysis of a configuration (text or pathlib.Path) with --set style "
        "overrides (a dict or keyword arguments such as **{'gains.kps': 500}): the document "
        "`teleopctl analyze --json` prints, as a dict.");
  m.def("analyze_force_loop", &analyze_force_loop, py::arg("config"),
        py::arg("overrides") = py::none(),
        "The force loop's analysis: `teleopctl analyze --force-loop --json`, as a dict.");
  m.def("max_stiffness", &max_stiffness, py::arg("config"), py::arg("side") = "slave",
        py::arg("rates_hz") = py::none(), py::arg("sweep") = py::none(),
        py::arg("overrides") = py::none(),
        "The largest stable fixture stiffness of one side ('slave' or 'master') at each rate "
        "and swept value: `teleopctl analyze --max-stiffness SIDE --rates ... --sweep ... "
        "--json`, as a dict.");
  m.def("simulate", &simulate, py::arg("scene"), py::arg("overrides") = py::none(),
        "Runs a scene in lockstep (as `teleopctl simulate`): a dict of numpy arrays, one per "
        "time series (time_s, positions, forces, commands ...), and 'summary' (the --json "
        "document).");
  m.def("open_session", &open_session, py::arg("path"),
        "Reads a session file (MCAP): channels as numpy arrays per field, the configuration "
        "text, alarms, parameter changes and stability reports.");
}
