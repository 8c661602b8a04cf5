// teleop-master: the master side of the teleoperator (issue 4). All of it is common/runtime.
#include "common/runtime/node_app.hpp"

int main(int argc, char** argv) {
  return teleop::runtime::run_node_main(teleop::transport::Role::kMaster, argc, argv);
}
