// Secure by default on one machine (issue 14, "authority" and finding 7): `teleopctl launch`
// with a configuration that has no keys of its own generates ephemeral CURVE keys for the
// master, the slave, the supervisor and the local console, so even loopback is authenticated,
// and writes them with the configuration the processes run into a per-launch directory:
//
//   ROOT/launch-PID/          mode 0700, removed when the launch ends
//     master.key .pub, slave.key .pub, supervisor.key .pub, console.key .pub   (.key 0600)
//     launch.textproto        the configuration in force, keys included (what clients read)
//
// ROOT is $TELEOP_RUNTIME_DIR, else $XDG_RUNTIME_DIR/teleop, else /tmp/teleop-UID (0700,
// owned by this user: refused otherwise). `teleopctl console`, `status`, `set`, `estop` and
// `node` given no key find the live launch whose endpoint they address (the default one, the
// flag's or their CONFIG's) and use its console key and its servers' public keys.
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "common/config/config_loader.hpp"

namespace teleop::ctl {

// ROOT above (not created).
[[nodiscard]] std::filesystem::path local_runtime_root();

// True when the configuration names no key at all (no public key, no client key, no secret
// key file): then launch generates its own.
[[nodiscard]] bool config_has_no_keys(const v1::SystemConfig& c);

// A launch's keys on disk; the directory goes when this does.
class LaunchKeys {
 public:
  // Creates ROOT/launch-PID with fresh key pairs (removing directories of launches that are
  // gone). Throws std::runtime_error naming the path on any problem.
  LaunchKeys();
  ~LaunchKeys();
  LaunchKeys(const LaunchKeys&) = delete;
  LaunchKeys& operator=(const LaunchKeys&) = delete;

  // The --set overrides that give the processes these keys.
  [[nodiscard]] const std::vector<std::string>& overrides() const { return overrides_; }
  // Writes launch.textproto (the configuration in force, with these keys) for the clients.
  void publish(const v1::SystemConfig& in_force) const;

  [[nodiscard]] const std::filesystem::path& dir() const { return dir_; }
  [[nodiscard]] std::string console_key_file() const;
  [[nodiscard]] const std::string& master_public() const { return master_public_; }
  [[nodiscard]] const std::string& slave_public() const { return slave_public_; }

 private:
  std::filesystem::path dir_{};
  std::vector<std::string> overrides_{};
  std::string master_public_{};
  std::string slave_public_{};
};

// A live local launch as a client sees it.
struct LocalLaunch {
  std::filesystem::path config_file{};  // launch.textproto
  std::string console_key_file{};       // console.key
  config::LoadedConfig config{};
};

// The live launch one of whose endpoints (node command, supervisor request or report) is
// `endpoint`; the newest when several are. Never throws: an unreadable directory is skipped.
[[nodiscard]] std::optional<LocalLaunch> find_local_launch(const std::string& endpoint);

}  // namespace teleop::ctl
