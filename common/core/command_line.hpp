// Reading a program's command line, the same way for teleopctl and the three daemons:
// `--name value` and `--name=value` for every option that takes a value, a clear error for a
// flag given a value it does not take.
#pragma once

#include <cstddef>
#include <stdexcept>
#include <string>
#include <vector>

namespace teleop::cli {

// Bad command line: the program prints it with its usage text and exits 2.
class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Walks the arguments. An argument `--name=value` reads as the flag `--name` (arg()) whose
// value() is `value`; a flag given `=value` that the command never asks the value of is a
// UsageError ("--json takes no value"). value() after `--name` alone takes the next argument.
class ArgCursor {
 public:
  explicit ArgCursor(const std::vector<std::string>& args) : args_(args) {}
  // The next argument; false after the last. Throws UsageError when the previous argument
  // carried an `=value` nobody read.
  [[nodiscard]] bool next();
  [[nodiscard]] const std::string& arg() const { return flag_; }
  [[nodiscard]] const std::string& value(const char* flag);

 private:
  const std::vector<std::string>& args_;
  std::size_t i_{static_cast<std::size_t>(-1)};
  std::string flag_;
  std::string inline_value_;
  bool has_inline_value_{false};
  bool inline_value_taken_{false};
};

}  // namespace teleop::cli
