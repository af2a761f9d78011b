#pragma once
/// @file
/// hullguardd as a systemd service: readiness and status notifications, and a
/// watchdog that feeds systemd only while every stage of the daemon makes
/// progress (docs/operations.md).

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include "common/heartbeat.h"

namespace hg::app {

/// Thin wrapper over sd_notify(3) for the service manager's notification
/// socket. Every call is a no-op returning false when NOTIFY_SOCKET was unset
/// at construction (the daemon run by hand or in tests), so callers never
/// branch on "are we under systemd".
///
/// Thread-safe: each notification is one datagram on a fresh socket.
class ServiceNotifier {
 public:
  /// Reads NOTIFY_SOCKET, WATCHDOG_USEC and WATCHDOG_PID once. The
  /// environment is left untouched (not unset), so a ServiceNotifier made
  /// later sees the same values.
  ServiceNotifier();

  /// Whether NOTIFY_SOCKET was set.
  [[nodiscard]] bool enabled() const { return enabled_; }

  /// READY=1: start-up is complete. For Type=notify units, systemd arms the
  /// watchdog only from here on; TimeoutStartSec bounds the time before.
  bool Ready() const;
  /// STOPPING=1: shutdown has begun (TimeoutStopSec now applies).
  bool Stopping() const;
  /// STATUS=text, shown by `systemctl status`. Newlines become spaces (the
  /// protocol is one assignment per line).
  bool Status(const std::string& text) const;
  /// WATCHDOG=1: keeps systemd from killing the service for WatchdogSec.
  bool WatchdogPing() const;

  /// The service manager's watchdog timeout (WatchdogSec), when it expects
  /// pings from this process (WATCHDOG_USEC set, WATCHDOG_PID unset or ours,
  /// NOTIFY_SOCKET set); std::nullopt otherwise.
  [[nodiscard]] std::optional<std::chrono::microseconds> WatchdogInterval() const {
    return watchdog_interval_;
  }

 private:
  bool Send(const char* message) const;

  bool enabled_ = false;
  std::optional<std::chrono::microseconds> watchdog_interval_;
  // A failed notification was logged (shared by copies: once per process).
  std::shared_ptr<std::atomic<bool>> failure_logged_ = std::make_shared<std::atomic<bool>>(false);
};

/// Feeds the systemd watchdog from the daemon's heartbeats.
///
/// A thread checks Heartbeats::AllMoved() every WatchdogSec / 2, or every
/// `fallback_period` when systemd expects no pings (then the checks only
/// log). While every stage moved it sends WATCHDOG=1. When some stage did not
/// move it sends no ping, so systemd kills and restarts the daemon after
/// WatchdogSec; it logs the stalled stages to stderr and puts them in STATUS=
/// once per stall (again only if the set of stalled stages changes). Should
/// the stages move again before systemd acts, pinging resumes and the health
/// status is restored.
///
/// With WatchdogSec = W and checks every W / 2, a stage that stops at time t
/// is last pinged for before t + W / 2, so systemd acts by t + 1.5 W.
///
/// Start it once every stage thread is running, and stop it before stopping
/// them: a stage that has legitimately ended would otherwise read as stalled.
///
/// Thread safety: Start(), Stop() and the destructor from one owning thread;
/// SetStatus() and the accessors from any thread.
class ServiceWatchdog {
 public:
  /// `heartbeats` must outlive this object, and no other thread may call its
  /// AllMoved() while the watchdog runs. `notifier` is copied.
  ServiceWatchdog(common::Heartbeats& heartbeats, const ServiceNotifier& notifier,
                  std::chrono::milliseconds fallback_period = std::chrono::seconds(1));
  ~ServiceWatchdog();
  ServiceWatchdog(const ServiceWatchdog&) = delete;
  ServiceWatchdog& operator=(const ServiceWatchdog&) = delete;

  /// Starts the checking thread; the first check is one period later.
  /// Precondition: not running.
  void Start();
  /// Ends the thread and returns promptly (it waits on a condition variable,
  /// never sleeps a whole period). Idempotent.
  void Stop();

  /// Sets the one-line health text for STATUS= (the daemon calls it about
  /// once a second). Sent by the watchdog thread at its next wake-up, which
  /// is immediate; held back while a stall is reported, and re-sent when the
  /// stall ends, so `systemctl status` keeps naming a stalled stage.
  void SetStatus(std::string text);

  /// Time between checks.
  [[nodiscard]] std::chrono::microseconds period() const { return period_; }
  /// Whether the latest check found a stalled stage.
  [[nodiscard]] bool stalled() const { return stalled_.load(std::memory_order_acquire); }
  /// Checks that found every stage moving (each one is a WATCHDOG=1 when
  /// systemd expects pings).
  [[nodiscard]] std::uint64_t healthy_checks() const {
    return healthy_checks_.load(std::memory_order_relaxed);
  }

 private:
  void Loop();
  void Check(std::string* stalled_names, std::string* last_reported);

  common::Heartbeats& heartbeats_;
  const ServiceNotifier notifier_;
  const std::chrono::microseconds period_;

  std::mutex mutex_;
  std::condition_variable wake_;
  bool stop_ = false;          // Guarded by mutex_.
  std::string status_;         // Guarded by mutex_.
  bool status_dirty_ = false;  // Guarded by mutex_.

  std::atomic<bool> stalled_{false};
  std::atomic<std::uint64_t> healthy_checks_{0};
  std::thread thread_;
};

}  // namespace hg::app
