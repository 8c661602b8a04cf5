// Counts calls of the C allocator (malloc, calloc, realloc, free, aligned_alloc, memalign,
// posix_memalign) made by one thread, by interposing them: an operator new counter would miss
// C allocations, and libstdc++'s operator new ends in malloc anyway. The interposers forward
// to glibc's __libc_* entry points. Include this header in exactly one translation unit of a
// test binary that is not built with AddressSanitizer (ASan owns malloc).
#pragma once

#include <pthread.h>

#include <atomic>
#include <cerrno>
#include <cstddef>
#include <cstdlib>

namespace teleop::test {

struct AllocCounter {
  std::atomic<bool> counting{false};
  std::atomic<bool> any_thread{true};
  pthread_t thread{};
  std::atomic<long> calls{0};
};

inline AllocCounter& alloc_counter() {
  static AllocCounter counter;
  return counter;
}

// Counts the calling thread's allocations from now on (or every thread's).
inline void start_counting(bool this_thread_only) {
  AllocCounter& c = alloc_counter();
  c.thread = pthread_self();
  c.any_thread.store(!this_thread_only);
  c.calls.store(0);
  c.counting.store(true);
}

inline long stop_counting() {
  alloc_counter().counting.store(false);
  return alloc_counter().calls.load();
}

// The counter's own check: one malloc and one free in a window, through volatile pointers so
// that the compiler cannot pair up and elide the calls. A working counter gives 2.
inline long count_malloc_and_free() {
  void* (*volatile do_malloc)(std::size_t) = &std::malloc;
  void (*volatile do_free)(void*) = &std::free;
  start_counting(false);
  do_free(do_malloc(64));
  return stop_counting();
}

inline void count_allocator_call() noexcept {
  AllocCounter& c = alloc_counter();
  if (!c.counting.load(std::memory_order_relaxed)) return;
  if (c.any_thread.load(std::memory_order_relaxed) || pthread_equal(pthread_self(), c.thread)) {
    c.calls.fetch_add(1, std::memory_order_relaxed);
  }
}

}  // namespace teleop::test

extern "C" {
void* __libc_malloc(std::size_t size) noexcept;
void* __libc_calloc(std::size_t count, std::size_t size) noexcept;
void* __libc_realloc(void* ptr, std::size_t size) noexcept;
void __libc_free(void* ptr) noexcept;
void* __libc_memalign(std::size_t alignment, std::size_t size) noexcept;

void* malloc(std::size_t size) noexcept {
  teleop::test::count_allocator_call();
  return __libc_malloc(size);
}
void* calloc(std::size_t count, std::size_t size) noexcept {
  teleop::test::count_allocator_call();
  return __libc_calloc(count, size);
}
void* realloc(void* ptr, std::size_t size) noexcept {
  teleop::test::count_allocator_call();
  return __libc_realloc(ptr, size);
}
void free(void* ptr) noexcept {
  teleop::test::count_allocator_call();
  __libc_free(ptr);
}
void* aligned_alloc(std::size_t alignment, std::size_t size) noexcept {
  teleop::test::count_allocator_call();
  return __libc_memalign(alignment, size);
}
void* memalign(std::size_t alignment, std::size_t size) noexcept {
  teleop::test::count_allocator_call();
  return __libc_memalign(alignment, size);
}
int posix_memalign(void** out, std::size_t alignment, std::size_t size) noexcept {
  teleop::test::count_allocator_call();
  if (alignment < sizeof(void*) || (alignment & (alignment - 1)) != 0) return EINVAL;
  void* p = __libc_memalign(alignment, size);
  if (p == nullptr) return ENOMEM;
  *out = p;
  return 0;
}
}  // extern "C"
