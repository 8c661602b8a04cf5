// Issue 18: what the RT thread does with a NodeStateRecord (fill it per axis with set_axis, and
// copy it whole across threads) makes no allocation, at every axis count. This binary interposes
// the C allocator (tests/support/alloc_counter.hpp), so the sanitizer build leaves it out.
#include <gtest/gtest.h>

#include <cstdlib>
#include <new>
#include <type_traits>

#include "common/transport/node_state_codec.hpp"
#include "tests/support/alloc_counter.hpp"

namespace teleop::transport {
namespace {

// LatestValue hands records between threads by copy: that needs a trivially copyable record.
static_assert(std::is_trivially_copyable_v<NodeStateRecord>);

TEST(NodeStateAxesRealTime, CounterSeesAllocations) {
  // Through a volatile pointer, so the compiler cannot pair up and elide the calls.
  void* (*volatile do_malloc)(std::size_t) = &std::malloc;
  void (*volatile do_free)(void*) = &std::free;
  teleop::test::start_counting(false);
  do_free(do_malloc(64));
  EXPECT_EQ(teleop::test::stop_counting(), 2);
}

TEST(NodeStateAxesRealTime, FillingAndCopyingRecordsDoesNotAllocate) {
  NodeStateRecord records[2]{};
  volatile double sink = 0.0;
  teleop::test::start_counting(false);
  for (int step = 0; step < 10000; ++step) {
    NodeStateRecord& r = records[step % 2];
    r.sequence = static_cast<std::uint64_t>(step) + 1;
    r.axes = 1 + step % kMaxAxes;
    for (int j = 0; j < r.axes; ++j) {
      r.set_axis(static_cast<std::size_t>(j), 1e-6 * step, -1e-3 * j, 0.1 * j);
    }
    records[(step + 1) % 2] = r;
    sink = sink + records[(step + 1) % 2].positions_m[0];
  }
  EXPECT_EQ(teleop::test::stop_counting(), 0);
  // set_axis(0, ...) wrote axis 0 to the scalar fields too.
  EXPECT_EQ(records[0].position_m, records[0].positions_m[0]);
  EXPECT_EQ(records[1].force_N, records[1].forces_N[0]);
  EXPECT_NE(static_cast<double>(sink), 0.0);
}

}  // namespace
}  // namespace teleop::transport
