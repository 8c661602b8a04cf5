// teleopctl: the operator's console: analyze, simulate, launch, node, keygen, set, identify,
// replay.
#include <iostream>
#include <string>
#include <vector>

#include "common/core/version.hpp"
#include "supervisor/teleopctl/analyze_command.hpp"
#include "supervisor/teleopctl/bridge_command.hpp"
#include "supervisor/teleopctl/console_command.hpp"
#include "supervisor/teleopctl/identify_command.hpp"
#include "supervisor/teleopctl/keygen_command.hpp"
#include "supervisor/teleopctl/node_command.hpp"
#include "supervisor/teleopctl/relay_command.hpp"
#include "supervisor/teleopctl/replay_command.hpp"
#include "supervisor/teleopctl/set_command.hpp"
#include "supervisor/teleopctl/simulate_command.hpp"
#include "supervisor/teleopctl/status_command.hpp"

namespace {

void usage(std::ostream& os) {
  os << "usage: teleopctl COMMAND [ARGS]\n\n"
        "commands:\n"
        "  analyze    stability of a teleoperator configuration (see 'teleopctl analyze --help')\n"
        "  simulate   play a scene on simulated devices (see 'teleopctl simulate --help')\n"
        "  launch     run master and slave on loopback, engaged (see 'teleopctl launch --help')\n"
        "  node       one command to one node: arm, engage, estop, ... ('teleopctl node --help')\n"
        "  keygen     a CURVE key pair for a node or client (see 'teleopctl keygen --help')\n"
        "  set        a guarded parameter change through the supervisor ('teleopctl set --help')\n"
        "  identify   a device's mass and damping by least squares ('teleopctl identify --help')\n"
        "  replay     a recorded session: summary, CSV, re-publish, resimulate ('replay --help')\n"
        "  estop      e-stop to both nodes directly (see 'teleopctl estop --help')\n"
        "  status     the supervisor's status, --json for scripts ('teleopctl status --help')\n"
        "  console    the operator's full-screen console, live or on a replay ('--help')\n"
        "  relay      a fault-injecting relay for one direction of a node link ('--help')\n"
        "  bridge     the live view in Foxglove: a WebSocket server on loopback ('--help')\n"
        "  help       this text\n\n"
        "options:\n"
        "  --version  print the version and exit\n"
        "  -h, --help this text\n\n"
        "Every option that takes a value also takes it after an '=' (--timeout-ms=500); --json\n"
        "makes a command's output one JSON document with snake_case keys.\n";
}

// analyze and simulate: their arguments parsed, then run (the library keeps the two halves
// apart, for the tests).
int run_analyze_command(const std::vector<std::string>& args, std::ostream& out,
                        std::ostream& err) {
  return teleop::ctl::run_analyze(teleop::ctl::parse_analyze_args(args), out, err);
}

int run_simulate_command(const std::vector<std::string>& args, std::ostream& out,
                         std::ostream& err) {
  return teleop::ctl::run_simulate(teleop::ctl::parse_simulate_args(args), out, err);
}

}  // namespace

int main(int argc, char** argv) {
  const std::vector<std::string> args(argv + 1, argv + argc);
  if (args.empty() || args[0] == "help" || args[0] == "--help" || args[0] == "-h") {
    usage(args.empty() ? std::cerr : std::cout);
    return args.empty() ? teleop::ctl::kExitUsage : 0;
  }
  if (args[0] == "--version" || args[0] == "version") {
    std::cout << "teleopctl " << teleop::version() << "\n";
    return 0;
  }
  // The commands: name, usage, runner.
  struct Simple {
    const char* name;
    std::string (*usage)();
    int (*run)(const std::vector<std::string>&, std::ostream&, std::ostream&);
  };
  for (const Simple& c :
       {Simple{"analyze", teleop::ctl::analyze_usage, run_analyze_command},
        Simple{"simulate", teleop::ctl::simulate_usage, run_simulate_command},
        Simple{"launch", teleop::ctl::launch_usage, teleop::ctl::run_launch},
        Simple{"node", teleop::ctl::node_usage, teleop::ctl::run_node_command},
        Simple{"keygen", teleop::ctl::keygen_usage, teleop::ctl::run_keygen},
        Simple{"set", teleop::ctl::set_usage, teleop::ctl::run_set},
        Simple{"identify", teleop::ctl::identify_usage, teleop::ctl::run_identify},
        Simple{"replay", teleop::ctl::replay_usage, teleop::ctl::run_replay},
        Simple{"estop", teleop::ctl::estop_usage, teleop::ctl::run_estop},
        Simple{"status", teleop::ctl::status_usage, teleop::ctl::run_status},
        Simple{"console", teleop::ctl::console_usage, teleop::ctl::run_console},
        Simple{"relay", teleop::ctl::relay_usage, teleop::ctl::run_relay},
        Simple{"bridge", teleop::ctl::bridge_usage, teleop::ctl::run_bridge}}) {
    if (args[0] != c.name) continue;
    const std::vector<std::string> rest(args.begin() + 1, args.end());
    if (!rest.empty() && (rest[0] == "--help" || rest[0] == "-h")) {
      std::cout << c.usage();
      return 0;
    }
    try {
      return c.run(rest, std::cout, std::cerr);
    } catch (const teleop::ctl::UsageError& e) {
      std::cerr << "teleopctl " << c.name << ": " << e.what() << "\n" << c.usage();
      return teleop::ctl::kExitUsage;
    }
  }
  std::cerr << "teleopctl: unknown command '" << args[0] << "'\n";
  usage(std::cerr);
  return teleop::ctl::kExitUsage;
}
