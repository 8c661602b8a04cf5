#include "common/control/plane_fixtures.hpp"

#include <stdexcept>
#include <string>

namespace teleop::control {

void PlaneSet::add(const Plane& plane) {
  if (count_ >= kMaxPlanes) {
    throw std::invalid_argument("PlaneSet: at most " + std::to_string(kMaxPlanes) + " planes");
  }
  planes_[static_cast<std::size_t>(count_)] = plane;
  ++count_;
}

}  // namespace teleop::control
