// What every teleopctl command shares: its command-line reading and its error reporting.
#pragma once

#include <ostream>
#include <stdexcept>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include "common/config/config_loader.hpp"
#include "common/core/command_line.hpp"

namespace teleop::ctl {

// Bad command line: exit code 2 and the usage text.
using cli::UsageError;
// Walks the arguments; `--name=value` reads as `--name value` (common/core/command_line.hpp).
using cli::ArgCursor;

inline constexpr int kExitOk = 0;
inline constexpr int kExitError = 1;  // bad configuration or I/O
inline constexpr int kExitUsage = 2;

// A finite number, the whole of `text`; otherwise UsageError naming `what`.
[[nodiscard]] double parse_number(const std::string& text, const std::string& what);
// --timeout-ms: whole milliseconds in [1, 60000] (0 or less would mean "never wait" or "wait
// for ever" to ZeroMQ).
[[nodiscard]] int parse_timeout_ms(const std::string& text);
[[nodiscard]] std::vector<std::string> split(const std::string& s, char separator);
// --plot FILE.svg: the plots are SVG; any other name is a UsageError (a PNG comes from the SVG:
// `rsvg-convert -o FILE.png FILE.svg`).
[[nodiscard]] std::string svg_plot_path(const std::string& path);

// The last branch of an option loop that takes one positional argument: an unknown option
// (an argument starting with `option_prefix`) and a second positional argument are
// UsageErrors, the first positional argument goes to `only`.
void take_only_positional(const std::string& arg, std::string& only,
                          std::string_view option_prefix = "--");

// `--set PATH=VALUE` or `--set=PATH=VALUE`, the current argument of `cur`: its override
// appended to `overrides` (true); false when the argument is something else.
bool take_set_option(ArgCursor& cur, std::vector<std::string>& overrides);

// What the commands on one configuration or scene file share: that file (the one positional
// argument), its --set overrides and --json.
struct FileCommandArgs {
  std::string& path;
  std::vector<std::string>& overrides;
  bool& json;
};

// Walks `args` for such a command: --set and --json into `common`, the command's own options
// through `take_own(cursor)` (false: not one of them), anything else is the file; an unknown
// option (starting with '-') or a second file is a UsageError.
template <typename TakeOwn>
void parse_file_command_args(const std::vector<std::string>& args, const FileCommandArgs& common,
                             TakeOwn&& take_own) {
  ArgCursor cur(args);
  while (cur.next()) {
    if (take_set_option(cur, common.overrides)) continue;
    if (cur.arg() == "--json") {
      common.json = true;
    } else if (!take_own(cur)) {
      take_only_positional(cur.arg(), common.path, "-");
    }
  }
}

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

// A command that reads all its arguments first: --help or -h anywhere among `args` prints
// `usage()` (exit 0); a UsageError from `parse(args)` prints the message and the usage (exit 2);
// otherwise `run(parsed)` runs guarded as above.
template <typename Parse, typename Run>
int run_parsed(const char* command, const std::vector<std::string>& args, std::string (*usage)(),
               std::ostream& out, std::ostream& err, Parse&& parse, Run&& run) {
  std::invoke_result_t<Parse&, const std::vector<std::string>&> parsed;
  try {
    for (const std::string& arg : args) {
      if (arg == "--help" || arg == "-h") {
        out << usage();
        return kExitOk;
      }
    }
    parsed = parse(args);
  } catch (const UsageError& e) {
    err << "teleopctl " << command << ": " << e.what() << "\n" << usage();
    return kExitUsage;
  }
  return run_guarded(command, err, [&] { return run(parsed); });
}

}  // namespace teleop::ctl
