// The other protobuf messages a process takes from the network: NodeCommand on a node's command
// socket (common/runtime/node_app.cpp), SupervisorRequest on the supervisor's request socket and
// Telemetry from the nodes (supervisor/daemon/supervisor_app.cpp), and the replies the clients
// (teleopctl) parse. Their validation (to_retune, read_only_refusal, on_telemetry) sits in
// anonymous namespaces or private members, so what is reachable is the parse itself.
//
// Input: [u8 selector][message bytes]. Checked: a message that parses re-serialises to bytes that
// parse back to the same message (the same bytes again).
#include <google/protobuf/message.h>
#include <google/protobuf/stubs/logging.h>

#include <memory>
#include <string>

#include "fuzz/harness/fuzz_check.hpp"
#include "teleop/v1/supervisor.pb.h"
#include "teleop/v1/telemetry.pb.h"

namespace teleop::fuzz {
namespace {

std::unique_ptr<google::protobuf::Message> make(std::uint8_t selector) {
  switch (selector % 5U) {
    case 0:
      return std::make_unique<v1::NodeCommand>();
    case 1:
      return std::make_unique<v1::SupervisorRequest>();
    case 2:
      return std::make_unique<v1::Telemetry>();
    case 3:
      return std::make_unique<v1::NodeCommandReply>();
    default:
      return std::make_unique<v1::SupervisorReply>();
  }
}

}  // namespace

int commands(const std::uint8_t* data, std::size_t size) {
  // protobuf logs every string field with invalid UTF-8 it parses: noise at 30k runs/s.
  static const bool quiet = [] {
    google::protobuf::SetLogHandler(nullptr);
    return true;
  }();
  (void)quiet;
  if (size == 0) return 0;
  const std::unique_ptr<google::protobuf::Message> m = make(data[0]);
  if (!m->ParseFromArray(data + 1, static_cast<int>(size - 1))) return 0;
  std::string once;
  TELEOP_FUZZ_CHECK(m->SerializeToString(&once), "a parsed message does not serialise");
  const std::unique_ptr<google::protobuf::Message> again = make(data[0]);
  TELEOP_FUZZ_CHECK(again->ParseFromString(once), "re-serialised message does not parse");
  std::string twice;
  TELEOP_FUZZ_CHECK(again->SerializeToString(&twice), "a parsed message does not serialise");
  // Bytes, not MessageDifferencer: NaN must survive too. No map fields, so the order is fixed.
  TELEOP_FUZZ_CHECK(once == twice, "serialise/parse changed the message");
  (void)m->ShortDebugString();
  return 0;
}

}  // namespace teleop::fuzz
