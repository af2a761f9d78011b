#pragma once
/// @file
/// Counts global operator new calls for the "no allocation per frame after
/// warm-up" tests. Linking this (any use of AllocationCounter) replaces the
/// program's global operator new with a counting one over malloc.

namespace hg::testing {

/// Counts the allocations made while it is alive, on every thread or only on
/// the thread that made it (when libraries' own threads allocate as they
/// please). One counter at a time per program.
class AllocationCounter {
 public:
  enum class Threads { kAll, kThis };
  explicit AllocationCounter(Threads threads = Threads::kAll);
  ~AllocationCounter();
  AllocationCounter(const AllocationCounter&) = delete;
  AllocationCounter& operator=(const AllocationCounter&) = delete;

  /// Allocations counted so far.
  [[nodiscard]] long count() const;

 private:
  Threads threads_;
  long start_;
};

}  // namespace hg::testing
