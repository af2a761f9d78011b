#pragma once
/// @file
/// A thread that hands the newest occupancy snapshot to a consumer (the DDS
/// publisher), so that the fusion thread never waits on the network.

#include <semaphore.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <thread>

#include "common/heartbeat.h"
#include "common/latest_value.h"
#include "pipeline/snapshot.h"

namespace hg::app {

/// The fusion thread offers each snapshot (Offer: a copy of the shared pointer
/// into a lock-free latest-value slot and a semaphore post); the stage's
/// thread takes the newest one and calls the consumer with it. A consumer
/// slower than the cycle skips to the newest snapshot (counted in skipped()).
/// The thread beats its heartbeat at least every 100 ms while it runs.
///
/// Thread safety: construct, Start(), Stop() and destroy from one owning
/// thread; Offer() from one producer thread; skipped() and delivered() from any.
class SnapshotStage {
 public:
  using Consumer = std::function<void(const pipeline::OccupancySnapshot&)>;

  /// `heartbeats` may be null; otherwise the stage registers itself as `name`.
  /// `nice` > 0 lowers the thread's priority (setpriority, no privilege needed;
  /// on failure it keeps the default).
  /// `stall_allowance`: how long a consumer call may keep the heartbeat still
  /// before the watchdog counts the stage stalled (common::Heartbeats::Register).
  SnapshotStage(std::string name, Consumer consumer, common::Heartbeats* heartbeats, int nice = 0,
                std::chrono::steady_clock::duration stall_allowance = {});
  ~SnapshotStage();
  SnapshotStage(const SnapshotStage&) = delete;
  SnapshotStage& operator=(const SnapshotStage&) = delete;

  void Start();
  /// Returns once the thread has ended (a consumer call in progress finishes).
  void Stop();
  /// Never blocks and does not allocate.
  void Offer(const std::shared_ptr<const pipeline::OccupancySnapshot>& snapshot);

  /// Snapshots overwritten before the consumer took them.
  [[nodiscard]] std::uint64_t skipped() const { return slot_.drops(); }
  /// Snapshots handed to the consumer.
  [[nodiscard]] std::uint64_t delivered() const {
    return delivered_.load(std::memory_order_relaxed);
  }

 private:
  void Loop();

  Consumer consumer_;
  common::Heartbeats* heartbeats_;
  int nice_;
  int heartbeat_ = -1;
  common::LatestValue<std::shared_ptr<const pipeline::OccupancySnapshot>> slot_;
  sem_t offered_;  // Posted per Offer; the thread waits on it with a timeout.
  std::atomic<bool> stop_{false};
  std::atomic<std::uint64_t> delivered_{0};
  std::thread thread_;
};

}  // namespace hg::app
