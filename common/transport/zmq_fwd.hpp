// cppzmq's context and socket types, declared for the headers that only name them (the
// definitions, <zmq.hpp>, stay in the .cpp files).
#pragma once

namespace zmq {
class context_t;
class socket_t;
}  // namespace zmq
