// teleopctl: the operator's console: `analyze` and `simulate`; launch, console and replay
// arrive with the runtime.
#include <iostream>
#include <string>
#include <vector>

#include "supervisor/teleopctl/analyze_command.hpp"
#include "supervisor/teleopctl/simulate_command.hpp"

namespace {

void usage(std::ostream& os) {
  os << "usage: teleopctl COMMAND [ARGS]\n\n"
        "commands:\n"
        "  analyze    stability of a teleoperator configuration (see 'teleopctl analyze --help')\n"
        "  simulate   play a scene on simulated devices (see 'teleopctl simulate --help')\n"
        "  help       this text\n";
}

}  // namespace

int main(int argc, char** argv) {
  const std::vector<std::string> args(argv + 1, argv + argc);
  if (args.empty() || args[0] == "help" || args[0] == "--help" || args[0] == "-h") {
    usage(args.empty() ? std::cerr : std::cout);
    return args.empty() ? teleop::ctl::kExitUsage : 0;
  }
  if (args[0] == "analyze") {
    const std::vector<std::string> rest(args.begin() + 1, args.end());
    if (!rest.empty() && (rest[0] == "--help" || rest[0] == "-h")) {
      std::cout << teleop::ctl::analyze_usage();
      return 0;
    }
    try {
      const teleop::ctl::AnalyzeOptions options = teleop::ctl::parse_analyze_args(rest);
      return teleop::ctl::run_analyze(options, std::cout, std::cerr);
    } catch (const teleop::ctl::UsageError& e) {
      std::cerr << "teleopctl analyze: " << e.what() << "\n" << teleop::ctl::analyze_usage();
      return teleop::ctl::kExitUsage;
    }
  }
  if (args[0] == "simulate") {
    const std::vector<std::string> rest(args.begin() + 1, args.end());
    if (!rest.empty() && (rest[0] == "--help" || rest[0] == "-h")) {
      std::cout << teleop::ctl::simulate_usage();
      return 0;
    }
    try {
      return teleop::ctl::run_simulate(teleop::ctl::parse_simulate_args(rest), std::cout,
                                       std::cerr);
    } catch (const teleop::ctl::UsageError& e) {
      std::cerr << "teleopctl simulate: " << e.what() << "\n" << teleop::ctl::simulate_usage();
      return teleop::ctl::kExitUsage;
    }
  }
  std::cerr << "teleopctl: unknown command '" << args[0] << "'\n";
  usage(std::cerr);
  return teleop::ctl::kExitUsage;
}
