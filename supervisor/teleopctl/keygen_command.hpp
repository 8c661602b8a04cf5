// `teleopctl keygen NAME`: a CURVE key pair for one node, as NAME.key (secret, mode 0600) and
// NAME.pub (what the peer is given).
#pragma once

#include <iosfwd>
#include <string>
#include <vector>

namespace teleop::ctl {

[[nodiscard]] std::string keygen_usage();

// Handles the whole command, usage errors included, since keygen has no options worth
// returning to a caller. Exit codes: 0 written (the public key is printed on `out`), 1 I/O
// error or refusal to overwrite, 2 usage (`--help` prints the usage on `out` and returns 0).
int run_keygen(const std::vector<std::string>& args, std::ostream& out, std::ostream& err);

}  // namespace teleop::ctl
