#pragma once
/// @file
/// Fail-fast invariant checks. A broken invariant aborts the process: the daemon
/// restarts and controllers see a silent stream, which they treat as "stop".

#include <cstdio>
#include <cstdlib>

namespace hg::common::internal {
[[noreturn]] inline void CheckFailed(const char* expr, const char* file, int line) {
  std::fprintf(stderr, "HG_CHECK failed: %s at %s:%d\n", expr, file, line);
  std::abort();
}
}  // namespace hg::common::internal

/// Aborts with a message when `cond` is false. Always on, also in Release builds.
#define HG_CHECK(cond)                                                \
  do {                                                                \
    if (!(cond)) [[unlikely]]                                         \
      ::hg::common::internal::CheckFailed(#cond, __FILE__, __LINE__); \
  } while (false)
