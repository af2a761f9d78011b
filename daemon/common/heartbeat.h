#pragma once
/// @file
/// Liveness counters per long-lived thread ("stage"), read by the watchdog.
///
/// Every stage loop beats once per iteration, idle iterations included (a
/// capture thread whose wait for a frame timed out still beats). A counter
/// that did not move between two checks therefore means a stuck thread, not a
/// quiet camera, and the watchdog stops feeding systemd so that the daemon is
/// restarted and the controllers see silence, which they treat as "stop".

#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <string>
#include <utility>

#include "common/check.h"

namespace hg::common {

/// A fixed table of per-stage beat counters.
///
/// Thread safety: Register() is set-up only (before any stage or watchdog
/// thread starts). Beat() is thread-safe, lock-free and allocation-free; any
/// number of threads may beat (normally each stage beats its own id).
/// AllMoved() and the accessors are for one checking thread at a time.
class Heartbeats {
 public:
  /// Most stages one table holds; storage is fixed so that Beat() never
  /// touches memory that may move.
  static constexpr int kCapacity = 64;

  Heartbeats() = default;
  Heartbeats(const Heartbeats&) = delete;
  Heartbeats& operator=(const Heartbeats&) = delete;

  /// Adds a stage and returns its id (0, 1, 2, ... in call order). `name` is
  /// what the watchdog reports when the stage stalls (e.g. "capture cam0").
  /// Precondition: no thread is beating or checking yet; fewer than
  /// kCapacity stages so far (checked: aborts otherwise).
  ///
  /// `allowance`: how long the stage may go without a beat before a check
  /// counts it stalled (0: it must beat between any two checks). For a stage
  /// whose iterations may take seconds without being stuck and that no safety
  /// output waits for (tracking with many particles).
  int Register(std::string name, std::chrono::steady_clock::duration allowance =
                                     std::chrono::steady_clock::duration{}) {
    HG_CHECK(size_ < kCapacity);
    names_[size_] = std::move(name);
    seen_[size_] = counters_[size_].beats.load(std::memory_order_relaxed);
    allowance_[size_] = allowance;
    moved_at_[size_] = std::chrono::steady_clock::now();
    return size_++;
  }

  /// Records one loop iteration of stage `id`. Relaxed: the watchdog only
  /// needs to see that the counter eventually moved, not any ordering with
  /// the stage's data. Precondition: `id` came from Register() (checked).
  void Beat(int id) noexcept {
    HG_CHECK(id >= 0 && id < size_);
    counters_[id].beats.fetch_add(1, std::memory_order_relaxed);
  }

  /// True iff every registered stage beat since the previous call (for the
  /// first call: since it was registered). Otherwise false, and when
  /// `stalled` is not null it receives the names of the stages that did not
  /// beat, separated by ", " (cleared first; its capacity is reused, so
  /// steady checking does not allocate). With no stage registered: true.
  bool AllMoved(std::string* stalled) {
    if (stalled != nullptr) stalled->clear();
    bool all = true;
    const std::chrono::steady_clock::time_point at = std::chrono::steady_clock::now();
    for (int i = 0; i < size_; ++i) {
      const std::uint64_t now = counters_[i].beats.load(std::memory_order_relaxed);
      if (now != seen_[i]) moved_at_[i] = at;
      if (now == seen_[i] && at - moved_at_[i] >= allowance_[i]) {
        all = false;
        if (stalled != nullptr) {
          if (!stalled->empty()) stalled->append(", ");
          stalled->append(names_[i]);
        }
      }
      seen_[i] = now;
    }
    return all;
  }

  /// Number of registered stages.
  [[nodiscard]] int size() const { return size_; }

  /// Name given to Register(). Precondition: 0 <= id < size().
  [[nodiscard]] const std::string& name(int id) const {
    HG_CHECK(id >= 0 && id < size_);
    return names_[id];
  }

  /// Beats of stage `id` so far (diagnostics and tests). Thread-safe.
  [[nodiscard]] std::uint64_t beats(int id) const {
    HG_CHECK(id >= 0 && id < size_);
    return counters_[id].beats.load(std::memory_order_relaxed);
  }

 private:
  // One cache line per counter: stages on different cores do not contend.
  struct alignas(64) Counter {
    std::atomic<std::uint64_t> beats{0};
  };

  std::array<Counter, kCapacity> counters_{};
  std::array<std::uint64_t, kCapacity> seen_{};  // Checker only: counts at the previous check.
  // Checker only: when a check last saw the counter move (or registration).
  std::array<std::chrono::steady_clock::time_point, kCapacity> moved_at_{};
  std::array<std::chrono::steady_clock::duration, kCapacity> allowance_{};  // Set-up only.
  std::array<std::string, kCapacity> names_{};
  int size_ = 0;  // Written at set-up only.
};

}  // namespace hg::common
