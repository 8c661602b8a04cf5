#include "supervisor/teleopctl/set_command.hpp"

#include <fmt/core.h>

#include <chrono>
#include <regex>
#include <thread>
#include <zmq.hpp>

#include "common/transport/zmq_security.hpp"
#include "common/transport/zmq_sockets.hpp"
#include "supervisor/teleopctl/cli_args.hpp"
#include "supervisor/teleopctl/json_output.hpp"
#include "supervisor/teleopctl/local_launch.hpp"
#include "supervisor/teleopctl/node_command.hpp"

namespace teleop::ctl {

std::optional<v1::SupervisorReply> supervisor_request(const std::string& endpoint,
                                                      const v1::SupervisorRequest& request,
                                                      int timeout_ms,
                                                      const std::string& secret_key_file,
                                                      const std::string& server_key) {
  zmq::context_t ctx(1);
  const transport::LinkSecurity security = transport::client_security(secret_key_file, server_key);
  zmq::socket_t client = transport::make_command_client(ctx, endpoint, security,
                                                        std::chrono::milliseconds(timeout_ms));
  const auto bytes = transport::request_reply(client, request.SerializeAsString());
  if (!bytes) return std::nullopt;
  v1::SupervisorReply reply;
  if (!reply.ParseFromString(*bytes)) return std::nullopt;
  return reply;
}

std::optional<v1::SupervisorReply> supervisor_request(const SupervisorClientFlags& sup,
                                                      const v1::SupervisorRequest& request) {
  return supervisor_request(sup.endpoint, request, sup.timeout_ms, sup.key, sup.server_key);
}

std::optional<v1::SupervisorReply> supervisor_status(const SupervisorClientFlags& sup) {
  v1::SupervisorRequest request;
  request.mutable_status();
  return supervisor_request(sup, request);
}

bool SupervisorClientFlags::take(ArgCursor& cur) {
  const std::string& a = cur.arg();
  if (a == "--supervisor") {
    endpoint = to_endpoint(cur.value("--supervisor"));
    endpoint_given = true;
  } else if (a == "--key") {
    key = cur.value("--key");
  } else if (a == "--server-key") {
    server_key = cur.value("--server-key");
  } else if (a == "--timeout-ms") {
    timeout_ms = parse_timeout_ms(cur.value("--timeout-ms"));
    timeout_given = true;
  } else {
    return false;
  }
  return true;
}

void SupervisorClientFlags::use_local_launch_keys() {
  if (!key.empty() || !server_key.empty()) return;
  if (const auto l = find_local_launch(endpoint)) {
    key = l->console_key_file;
    server_key = l->config.config.security().supervisor_public_key();
  }
}

namespace {

// Several axes: "master.planes[I].stiffness_N_per_m" / "slave.planes[I]..." and
// "gains.kps[I,J]", parsed; nullopt for any other path.
struct AxesPath {
  bool plane{false};
  bool slave{false};
  std::string gain{};
  unsigned index{0};  // the plane, or the row
  unsigned column{0};
};

std::optional<AxesPath> axes_path(const std::string& path) {
  static const std::regex plane(R"(^(master|slave)\.planes\[([0-9]{1,2})\]\.stiffness_N_per_m$)");
  static const std::regex gain(R"(^gains\.(kpm|kps|kdm|kds|kvm|kvs|kfm)\[([0-9]),([0-9])\]$)");
  std::smatch m;
  AxesPath p;
  if (std::regex_match(path, m, plane)) {
    p.plane = true;
    p.slave = m[1] == "slave";
    p.index = static_cast<unsigned>(std::stoul(m[2]));
    return p;
  }
  if (std::regex_match(path, m, gain)) {
    p.gain = m[1];
    p.index = static_cast<unsigned>(std::stoul(m[2]));
    p.column = static_cast<unsigned>(std::stoul(m[3]));
    return p;
  }
  return std::nullopt;
}

}  // namespace

std::pair<std::string, double> parse_setting(const std::string& text) {
  const auto eq = text.find('=');
  if (eq == std::string::npos) throw UsageError("expected PATH=VALUE, got '" + text + "'");
  const std::string path = text.substr(0, eq);
  static const char* kGains[] = {"kpm", "kps", "kdm", "kds", "kvm", "kvs", "kfm"};
  bool known =
      path == "master.fixture.stiffness_N_per_m" || path == "slave.fixture.stiffness_N_per_m";
  for (const char* g : kGains) known = known || path == std::string("gains.") + g;
  if (!known && !axes_path(path)) {
    throw UsageError("cannot change '" + path +
                     "' live (gains.*, master.fixture.stiffness_N_per_m and "
                     "slave.fixture.stiffness_N_per_m can be; with several axes "
                     "master.planes[I].stiffness_N_per_m, slave.planes[I].stiffness_N_per_m, "
                     "gains.kps[I,J] and gains.kps on every axis)");
  }
  return {path, parse_number(text.substr(eq + 1), path)};
}

v1::ParameterChangeRequest make_axes_change_request(
    const std::vector<std::pair<std::string, double>>& settings, bool dry_run,
    const std::string& requested_by) {
  v1::ParameterChangeRequest c;
  c.set_dry_run(dry_run);
  c.set_requested_by(requested_by);
  for (const auto& [path, value] : settings) {
    if (const std::optional<AxesPath> a = axes_path(path); a && a->plane) {
      v1::PlaneStiffnessChange& s = *c.add_plane_stiffness();
      s.set_slave(a->slave);
      s.set_plane(a->index);
      s.set_stiffness_n_per_m(value);
    } else if (a) {
      v1::GainElementChange& g = *c.add_gain_element();
      g.set_gain(a->gain);
      g.set_row(a->index);
      g.set_column(a->column);
      g.set_value(value);
    } else if (path.rfind("gains.", 0) == 0) {  // a scalar: every axis
      v1::GainElementChange& g = *c.add_gain_element();
      g.set_gain(path.substr(6));
      g.set_every_axis(true);
      g.set_value(value);
    } else {
      throw UsageError("'" + path + "' is a one-axis path; with several axes name the plane (" +
                       (path.rfind("slave", 0) == 0 ? "slave" : "master") +
                       ".planes[I].stiffness_N_per_m)");
    }
  }
  return c;
}

v1::ParameterChangeRequest make_change_request(
    const std::vector<std::pair<std::string, double>>& settings, const v1::Gains& gains_in_force,
    bool dry_run, const std::string& requested_by) {
  v1::ParameterChangeRequest c;
  c.set_dry_run(dry_run);
  c.set_requested_by(requested_by);
  bool any_gain = false;
  v1::Gains g = gains_in_force;
  for (const auto& [path, value] : settings) {
    if (axes_path(path)) {
      throw UsageError("'" + path +
                       "' names a plane or a gain element of several axes; this teleoperator "
                       "has one axis");
    }
    if (path == "master.fixture.stiffness_N_per_m") c.set_master_fixture_stiffness_n_per_m(value);
    if (path == "slave.fixture.stiffness_N_per_m") c.set_slave_fixture_stiffness_n_per_m(value);
    if (path.rfind("gains.", 0) == 0) {
      any_gain = true;
      const auto* f = g.GetDescriptor()->FindFieldByName(path.substr(6));
      g.GetReflection()->SetDouble(&g, f, value);
    }
  }
  if (any_gain) *c.mutable_gains() = g;
  return c;
}

// Several axes: the supervisor analyses a change beside its loop (seconds with a human band)
// and answers "pending"; its decision is then in its status, under the same request number.
static std::optional<v1::SupervisorReply> await_axes_decision(
    const SupervisorClientFlags& sup, const v1::ParameterChangeReply& pending, std::ostream& err) {
  err << pending.reason() << "\n";
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::minutes(2);
  while (std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    const auto status = supervisor_status(sup);
    if (!status) continue;  // one lost reply: ask again
    const v1::ParameterChangeReply& last = status->status().last_change();
    if (last.request_id() == pending.request_id()) {
      v1::SupervisorReply decided;
      *decided.mutable_change() = last;
      return decided;
    }
  }
  return std::nullopt;
}

std::string set_usage() {
  return "usage: teleopctl set PATH=VALUE... [--dry-run] [--supervisor HOST:PORT] [--key FILE]\n"
         "                    [--server-key KEY|FILE] [--timeout-ms N] [--json]\n\n"
         "Asks the supervisor to change the running teleoperator. It analyses the change first\n"
         "(with the measured round trip) and applies it only when the predicted minimum damping\n"
         "ratio meets the required one; both nodes then switch at an agreed master sequence,\n"
         "ramped. PATH: gains.kpm|kps|kdm|kds|kvm|kvs|kfm, master.fixture.stiffness_N_per_m,\n"
         "slave.fixture.stiffness_N_per_m. Several axes: master.planes[I].stiffness_N_per_m,\n"
         "slave.planes[I].stiffness_N_per_m (plane I of the side, from 0), gains.kps[I,J]\n"
         "(elements I,J and J,I: gain matrices stay symmetric), gains.kps (kps I on every\n"
         "axis); the supervisor analyses such a change beside its loop and this waits for its\n"
         "decision (up to 2 minutes). --dry-run only predicts. Supervisor default\n"
         "127.0.0.1:5567 (without --key and --server-key: the keys of a live `teleopctl launch`\n"
         "there, if any). --json prints the supervisor's teleop.v1.ParameterChangeReply "
         "(accepted,\n"
         "reason, change_id, apply_at_master_sequence, prediction) as JSON. Exit: 0 accepted,\n"
         "1 error, 2 usage, 3 refused, 4 no reply.\n";
}

int run_set(const std::vector<std::string>& args, std::ostream& out, std::ostream& err) {
  std::vector<std::pair<std::string, double>> sets;
  bool dry_run = false;
  bool json = false;
  SupervisorClientFlags sup;
  sup.timeout_ms = 5000;
  ArgCursor cur(args);
  while (cur.next()) {
    const std::string& a = cur.arg();
    if (a == "--dry-run") {
      dry_run = true;
    } else if (a == "--json") {
      json = true;
    } else if (sup.take(cur)) {
    } else if (a.rfind("--", 0) == 0) {
      throw UsageError("unknown option '" + a + "'");
    } else {
      sets.push_back(parse_setting(a));
    }
  }
  if (sets.empty()) throw UsageError("nothing to set");
  for (std::size_t i = 0; i < sets.size(); ++i) {
    for (std::size_t j = 0; j < i; ++j) {
      if (sets[i].first == sets[j].first) {
        throw UsageError(fmt::format("{} is set twice ({}={:g} and {}={:g}): give each path once",
                                     sets[i].first, sets[j].first, sets[j].second, sets[i].first,
                                     sets[i].second));
      }
    }
  }
  return run_guarded("set", err, [&]() -> int {
    sup.use_local_launch_keys();
    // The gains in force, so that a change of one gain keeps the others.
    const auto now = supervisor_status(sup);
    if (!now) {
      err << "teleopctl set: no reply from the supervisor at " << sup.endpoint << "\n";
      return kExitNoReply;
    }
    v1::SupervisorRequest req;
    const bool several = now->status().report().axes() > 1;
    *req.mutable_change() = several ? make_axes_change_request(sets, dry_run, "teleopctl set")
                                    : make_change_request(sets, now->status().report().gains(),
                                                          dry_run, "teleopctl set");
    auto reply = supervisor_request(sup, req);
    if (reply && reply->error().empty() && reply->change().pending()) {
      reply = await_axes_decision(sup, reply->change(), err);
    }
    if (!reply) {
      err << "teleopctl set: no reply from the supervisor at " << sup.endpoint << "\n";
      return kExitNoReply;
    }
    if (!reply->error().empty()) {
      err << "teleopctl set: " << reply->error() << "\n";
      return reply->refused_read_only() ? kExitRefused : kExitError;
    }
    const v1::ParameterChangeReply& r = reply->change();
    if (json) {
      out << proto_json(r).dump() << "\n";
      return r.accepted() ? kExitOk : kExitRefused;
    }
    const v1::StabilityReport& p = r.prediction();
    out << r.reason() << "\n";
    out << fmt::format(
               "  prediction: {}, minimum damping ratio {:.4f} (required {:.4f}), round "
               "trip {} samples",
               p.verdict(), p.min_damping_ratio(), p.required_damping_ratio(),
               p.round_trip_samples())
        << "\n";
    if (p.has_max_stable_slave_stiffness_n_per_m()) {
      out << fmt::format("  slave fixture {:.0f} N/m, maximum stable {:.0f} N/m\n",
                         p.slave_fixture_stiffness_n_per_m(),
                         p.max_stable_slave_stiffness_n_per_m());
    }
    if (p.has_max_stable_master_stiffness_n_per_m()) {
      out << fmt::format("  master fixture {:.0f} N/m, maximum stable {:.0f} N/m\n",
                         p.master_fixture_stiffness_n_per_m(),
                         p.max_stable_master_stiffness_n_per_m());
    }
    for (const v1::PlaneMargin& m : p.planes()) {
      out << fmt::format("  {} plane {}: {:.0f} N/m", m.side(), m.index(), m.stiffness_n_per_m());
      if (m.has_max_stable_stiffness_n_per_m()) {
        out << fmt::format(", maximum stable {:.0f} N/m", m.max_stable_stiffness_n_per_m());
      }
      out << "\n";
    }
    if (r.accepted() && !dry_run) {
      out << "  change " << r.change_id() << " applies at master sequence "
          << r.apply_at_master_sequence() << "\n";
    }
    return r.accepted() ? kExitOk : kExitRefused;
  });
}

}  // namespace teleop::ctl
