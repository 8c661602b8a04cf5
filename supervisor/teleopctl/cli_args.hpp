// What every teleopctl command shares: its command-line reading and its error reporting.
#pragma once

#include <ostream>
#include <stdexcept>
#include <string>
#include <vector>

#include "common/config/config_loader.hpp"

namespace teleop::ctl {

// Bad command line: exit code 2 and the usage text.
class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

inline constexpr int kExitOk = 0;
inline constexpr int kExitError = 1;  // bad configuration or I/O
inline constexpr int kExitUsage = 2;

// A finite number, the whole of `text`; otherwise UsageError naming `what`.
[[nodiscard]] double parse_number(const std::string& text, const std::string& what);
// --timeout-ms: whole milliseconds in [1, 60000] (0 or less would mean "never wait" or "wait
// for ever" to ZeroMQ).
[[nodiscard]] int parse_timeout_ms(const std::string& text);
[[nodiscard]] std::vector<std::string> split(const std::string& s, char separator);

// Walks the arguments; value() takes the one after the current flag.
class ArgCursor {
 public:
  explicit ArgCursor(const std::vector<std::string>& args) : args_(args) {}
  [[nodiscard]] bool next() { return ++i_ < args_.size(); }
  [[nodiscard]] const std::string& arg() const { return args_[i_]; }
  [[nodiscard]] const std::string& value(const char* flag);

 private:
  const std::vector<std::string>& args_;
  std::size_t i_{static_cast<std::size_t>(-1)};
};

// Runs a command body, turning configuration and other errors into a message and exit 1.
template <typename Body>
int run_guarded(const char* command, std::ostream& err, Body&& body) {
  try {
    return body();
  } catch (const config::ConfigError& e) {
    err << "teleopctl " << command << ": invalid configuration:\n" << e.what() << "\n";
  } catch (const std::exception& e) {
    err << "teleopctl " << command << ": " << e.what() << "\n";
  }
  return kExitError;
}

}  // namespace teleop::ctl
