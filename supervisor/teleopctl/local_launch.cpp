#include "supervisor/teleopctl/local_launch.hpp"

#include <errno.h>
#include <fmt/core.h>
#include <google/protobuf/text_format.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstdlib>
#include <cstring>
#include <fstream>

#include "common/config/node_loader.hpp"
#include "common/core/defaults.hpp"
#include "common/transport/zmq_security.hpp"

namespace teleop::ctl {
namespace {

namespace fs = std::filesystem;

constexpr const char* kPrefix = "launch-";
constexpr const char* kConfigName = "launch.textproto";

bool process_alive(long pid) {
  if (pid <= 0) return false;
  return ::kill(static_cast<pid_t>(pid), 0) == 0 || errno == EPERM;
}

// The pid a launch directory is named after; 0 when it is not one.
long launch_pid(const fs::path& dir) {
  const std::string name = dir.filename().string();
  if (name.rfind(kPrefix, 0) != 0) return 0;
  char* end = nullptr;
  const long pid = std::strtol(name.c_str() + 7, &end, 10);
  return end != nullptr && *end == '\0' ? pid : 0;
}

// A directory only this user can enter: created 0700, or an existing one checked (a
// directory, not a symlink, owned by this user, no access for group or others).
void private_dir(const fs::path& p) {
  if (::mkdir(p.c_str(), 0700) != 0 && errno != EEXIST) {
    throw std::runtime_error(fmt::format("cannot create {}: {}", p.string(), std::strerror(errno)));
  }
  struct stat st {};
  if (::lstat(p.c_str(), &st) != 0 || !S_ISDIR(st.st_mode)) {
    throw std::runtime_error(fmt::format("{} is not a directory", p.string()));
  }
  if (st.st_uid != ::getuid()) {
    throw std::runtime_error(fmt::format(
        "{} belongs to another user (uid {}): refusing to keep keys there", p.string(), st.st_uid));
  }
  if ((st.st_mode & 077) != 0) {
    throw std::runtime_error(
        fmt::format("{} has mode {:04o}: group or others can enter it (run: chmod 700 {})",
                    p.string(), st.st_mode & 07777, p.string()));
  }
}

std::string supervisor_request_endpoint(const v1::SystemConfig& c) {
  return c.supervisor().request_endpoint().empty()
             ? std::string(defaults::kSupervisorRequestEndpoint)
             : c.supervisor().request_endpoint();
}
std::string supervisor_report_endpoint(const v1::SystemConfig& c) {
  return c.supervisor().report_endpoint().empty() ? std::string(defaults::kSupervisorReportEndpoint)
                                                  : c.supervisor().report_endpoint();
}

}  // namespace

fs::path local_runtime_root() {
  if (const char* d = std::getenv("TELEOP_RUNTIME_DIR"); d != nullptr && *d != '\0') return d;
  if (const char* d = std::getenv("XDG_RUNTIME_DIR"); d != nullptr && *d != '\0') {
    return fs::path(d) / "teleop";
  }
  return fs::path("/tmp") / ("teleop-" + std::to_string(::getuid()));
}

bool config_has_no_keys(const v1::SystemConfig& c) {
  const v1::Security& s = c.security();
  return s.master_public_key().empty() && s.slave_public_key().empty() &&
         s.supervisor_public_key().empty() && s.client_public_keys_size() == 0 &&
         s.read_only_client_public_keys_size() == 0 &&
         c.master().node().secret_key_file().empty() &&
         c.slave().node().secret_key_file().empty() && c.supervisor().secret_key_file().empty();
}

LaunchKeys::LaunchKeys() {
  const fs::path root = local_runtime_root();
  private_dir(root);
  // Directories of launches that are gone (killed before they could clean up).
  std::error_code ec;
  for (const fs::directory_entry& e : fs::directory_iterator(root, ec)) {
    const long pid = launch_pid(e.path());
    if (pid > 0 && !process_alive(pid)) fs::remove_all(e.path(), ec);
  }
  dir_ = root / (std::string(kPrefix) + std::to_string(::getpid()));
  fs::remove_all(dir_, ec);  // this pid's, from a launch long gone
  private_dir(dir_);
  std::string keys[4];
  const char* names[4] = {"master", "slave", "supervisor", "console"};
  for (int i = 0; i < 4; ++i) {
    const transport::CurveKeyPair k = transport::generate_curve_keypair();
    (void)transport::write_key_files(dir_ / names[i], k, true);
    keys[i] = k.public_z85;
  }
  master_public_ = keys[0];
  slave_public_ = keys[1];
  overrides_ = {
      "security.master_public_key=" + keys[0],
      "security.slave_public_key=" + keys[1],
      "security.supervisor_public_key=" + keys[2],
      // The supervisor and the local console may command the nodes (and the supervisor).
      "security.client_public_keys=" + keys[2] + "," + keys[3],
      "master.node.secret_key_file=" + (dir_ / "master.key").string(),
      "slave.node.secret_key_file=" + (dir_ / "slave.key").string(),
      "supervisor.secret_key_file=" + (dir_ / "supervisor.key").string(),
  };
}

LaunchKeys::~LaunchKeys() {
  std::error_code ec;
  fs::remove_all(dir_, ec);
}

std::string LaunchKeys::console_key_file() const { return (dir_ / "console.key").string(); }

void LaunchKeys::publish(const v1::SystemConfig& in_force) const {
  std::string text;
  google::protobuf::TextFormat::PrintToString(in_force, &text);
  const fs::path tmp = dir_ / (std::string(kConfigName) + ".tmp");
  {
    std::ofstream out(tmp);
    out << "# The configuration of the teleopctl launch with pid " << ::getpid()
        << " (keys generated for it); removed when it ends.\n"
        << text;
    if (!out) throw std::runtime_error("cannot write " + tmp.string());
  }
  fs::rename(tmp, dir_ / kConfigName);
}

std::optional<LocalLaunch> find_local_launch(const std::string& endpoint) {
  std::optional<LocalLaunch> found;
  long found_pid = 0;
  std::error_code ec;
  const fs::path root = local_runtime_root();
  struct stat st {};
  // Only a private root of this user's is trusted.
  if (::lstat(root.c_str(), &st) != 0 || !S_ISDIR(st.st_mode) || st.st_uid != ::getuid() ||
      (st.st_mode & 077) != 0) {
    return std::nullopt;
  }
  for (const fs::directory_entry& e : fs::directory_iterator(root, ec)) {
    const long pid = launch_pid(e.path());
    if (pid <= 0 || !process_alive(pid) || (found && pid < found_pid)) continue;
    const fs::path file = e.path() / kConfigName;
    if (!fs::exists(file, ec)) continue;
    try {
      LocalLaunch l;
      l.config_file = file;
      l.console_key_file = (e.path() / "console.key").string();
      l.config = config::load_config_file(file);
      const v1::SystemConfig& c = l.config.config;
      const bool match =
          config::to_node_setup(l.config, transport::Role::kMaster).endpoints.command == endpoint ||
          config::to_node_setup(l.config, transport::Role::kSlave).endpoints.command == endpoint ||
          supervisor_request_endpoint(c) == endpoint || supervisor_report_endpoint(c) == endpoint;
      if (match) {
        found = std::move(l);
        found_pid = pid;
      }
    } catch (const std::exception&) {
    }
  }
  return found;
}

}  // namespace teleop::ctl
