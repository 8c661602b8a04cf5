// Command lines from the integration tests, as a user runs them: a shell command's stdout and
// exit status through popen, the real teleopctl binary (TELEOPCTL_PATH, defined per test
// target by CMake), and numbers written so that the command parses back the same double.
#pragma once

#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <string>

namespace teleop::test {

struct CliResult {
  int exit_code{-1};  // -1: no exit status (popen failed, or the command was killed)
  std::string out{};
};

// A shell command line exactly as given (any redirection is the caller's): its stdout.
inline CliResult capture(const std::string& cmd) {
  CliResult r;
  FILE* pipe = popen(cmd.c_str(), "r");
  if (pipe == nullptr) return r;
  std::array<char, 4096> buf{};
  std::size_t n = 0;
  while ((n = fread(buf.data(), 1, buf.size(), pipe)) > 0) r.out.append(buf.data(), n);
  const int status = pclose(pipe);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

// A shell command line; stdout captured, stderr too when `merge_stderr` (else discarded).
inline CliResult run(const std::string& cmd, bool merge_stderr = true) {
  return capture(cmd + (merge_stderr ? " 2>&1" : " 2>/dev/null"));
}

// teleopctl with `args` (a shell command line's arguments), as run() runs it (every
// integration binary has TELEOPCTL_PATH: teleop_live_test() in CMakeLists.txt).
inline CliResult teleopctl(const std::string& args, bool merge_stderr = true) {
  return run(std::string(TELEOPCTL_PATH) + " " + args, merge_stderr);
}

// A number as text that parses back to the same double.
inline std::string exact(double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.17g", v);
  return buf;
}

}  // namespace teleop::test
