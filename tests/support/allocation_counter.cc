#include "support/allocation_counter.h"

#include <atomic>
#include <cstdlib>
#include <new>

namespace {
std::atomic<bool> g_all_threads{false};
thread_local bool t_this_thread = false;
std::atomic<long> g_allocations{0};
}  // namespace

void* operator new(std::size_t size) {
  if (t_this_thread || g_all_threads.load(std::memory_order_relaxed)) {
    g_allocations.fetch_add(1, std::memory_order_relaxed);
  }
  if (void* p = std::malloc(size == 0 ? 1 : size)) return p;
  throw std::bad_alloc();
}
// operator new above allocates with malloc, so free is the matching release;
// GCC cannot see that through the replacement and warns where it inlines.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
#pragma GCC diagnostic pop

namespace hg::testing {

AllocationCounter::AllocationCounter(Threads threads)
    : threads_(threads), start_(g_allocations.load()) {
  if (threads_ == Threads::kAll) {
    g_all_threads.store(true);
  } else {
    t_this_thread = true;
  }
}

AllocationCounter::~AllocationCounter() {
  if (threads_ == Threads::kAll) {
    g_all_threads.store(false);
  } else {
    t_this_thread = false;
  }
}

long AllocationCounter::count() const { return g_allocations.load() - start_; }

}  // namespace hg::testing
