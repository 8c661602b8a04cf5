#include "supervisor/teleopctl/keygen_command.hpp"

#include <nlohmann/json.hpp>
#include <optional>
#include <ostream>

#include "common/transport/zmq_security.hpp"
#include "supervisor/teleopctl/cli_args.hpp"

namespace teleop::ctl {

std::string keygen_usage() {
  return "usage: teleopctl keygen NAME [--force] [--json]\n\n"
         "Writes a CURVE key pair for one node:\n"
         "  NAME.key  public and secret key, mode 0600; point security.secret_key_file at it\n"
         "  NAME.pub  the public key: give it to the peer (its allowed client keys, or the\n"
         "            server key it connects with)\n"
         "and prints the public key.\n\n"
         "options:\n"
         "  --force   replace existing NAME.key and NAME.pub (the old key stops working)\n"
         "  --json    print {secret_key_file, public_key_file, public_key} as JSON\n"
         "  --help    this text\n";
}

int run_keygen(const std::vector<std::string>& args, std::ostream& out, std::ostream& err) {
  std::optional<std::string> name;
  bool force = false;
  bool json = false;
  try {
    ArgCursor cursor(args);
    while (cursor.next()) {
      const std::string& arg = cursor.arg();
      if (arg == "--help" || arg == "-h") {
        out << keygen_usage();
        return kExitOk;
      }
      if (arg == "--force") {
        force = true;
      } else if (arg == "--json") {
        json = true;
      } else if (!arg.empty() && arg.front() == '-') {
        throw UsageError("unknown option '" + arg + "'");
      } else if (name) {
        throw UsageError("one NAME only, got '" + *name + "' and '" + arg + "'");
      } else {
        name = arg;
      }
    }
    if (!name || name->empty()) throw UsageError("NAME is required");
  } catch (const UsageError& e) {
    err << "teleopctl keygen: " << e.what() << "\n" << keygen_usage();
    return kExitUsage;
  }
  return run_guarded("keygen", err, [&] {
    const transport::CurveKeyPair keys = transport::generate_curve_keypair();
    const transport::KeyFilePaths paths = transport::write_key_files(*name, keys, force);
    if (json) {
      out << nlohmann::json{{"secret_key_file", paths.secret_file.string()},
                            {"public_key_file", paths.public_file.string()},
                            {"public_key", keys.public_z85}}
                 .dump()
          << "\n";
      return kExitOk;
    }
    out << "wrote " << paths.secret_file.string() << " (secret, mode 0600) and "
        << paths.public_file.string() << "\n"
        << "public-key = " << keys.public_z85 << "\n";
    return kExitOk;
  });
}

}  // namespace teleop::ctl
