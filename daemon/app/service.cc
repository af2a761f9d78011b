#include "app/service.h"

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <utility>

#include <systemd/sd-daemon.h>

#include "common/check.h"
#include "common/log.h"

namespace hg::app {

ServiceNotifier::ServiceNotifier() {
  const char* socket = std::getenv("NOTIFY_SOCKET");
  enabled_ = socket != nullptr && socket[0] != '\0';
  std::uint64_t usec = 0;
  // sd_watchdog_enabled also checks WATCHDOG_PID against getpid(), so a
  // child that inherited the environment does not believe it must ping.
  if (enabled_ && sd_watchdog_enabled(/*unset_environment=*/0, &usec) > 0 && usec > 0) {
    watchdog_interval_ = std::chrono::microseconds(usec);
  }
}

bool ServiceNotifier::Send(const char* message) const {
  if (!enabled_) return false;
  const int result = sd_notify(/*unset_environment=*/0, message);
  if (result <= 0 && !failure_logged_->exchange(true)) {
    // Once: systemd would then never see READY=1 or a watchdog ping.
    log::Warn(
        "NOTIFY_SOCKET={} is set but notifying it failed ({}): systemd sees no READY=1, "
        "STATUS= or watchdog ping",
        std::getenv("NOTIFY_SOCKET"), result < 0 ? std::strerror(-result) : "no socket");
  }
  return result > 0;
}

bool ServiceNotifier::Ready() const { return Send("READY=1"); }

bool ServiceNotifier::Stopping() const { return Send("STOPPING=1"); }

bool ServiceNotifier::WatchdogPing() const { return Send("WATCHDOG=1"); }

bool ServiceNotifier::Status(const std::string& text) const {
  if (!enabled_) return false;
  std::string message = "STATUS=" + text;
  std::replace(message.begin(), message.end(), '\n', ' ');
  return Send(message.c_str());
}

namespace {

std::chrono::microseconds CheckPeriod(const ServiceNotifier& notifier,
                                      std::chrono::milliseconds fallback) {
  // Half the timeout: one late or missed check still leaves a ping in time.
  const auto period = notifier.WatchdogInterval() ? *notifier.WatchdogInterval() / 2
                                                  : std::chrono::microseconds(fallback);
  return std::max(period, std::chrono::microseconds(1000));
}

}  // namespace

ServiceWatchdog::ServiceWatchdog(common::Heartbeats& heartbeats, const ServiceNotifier& notifier,
                                 std::chrono::milliseconds fallback_period)
    : heartbeats_(heartbeats),
      notifier_(notifier),
      period_(CheckPeriod(notifier, fallback_period)) {}

ServiceWatchdog::~ServiceWatchdog() { Stop(); }

void ServiceWatchdog::Start() {
  HG_CHECK(!thread_.joinable());
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = false;
  }
  thread_ = std::thread([this] { Loop(); });
}

void ServiceWatchdog::Stop() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  if (thread_.joinable()) thread_.join();
}

void ServiceWatchdog::SetStatus(std::string text) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    status_ = std::move(text);
    status_dirty_ = true;
  }
  wake_.notify_all();
}

void ServiceWatchdog::Loop() {
  // Reused across checks.
  std::string stalled_names;
  std::string last_reported;
  std::string status;
  auto next_check = std::chrono::steady_clock::now() + period_;
  while (true) {
    bool send_status = false;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      wake_.wait_until(lock, next_check, [this] { return stop_ || status_dirty_; });
      if (stop_) return;
      if (status_dirty_ && !stalled_.load(std::memory_order_relaxed)) {
        status = status_;
        send_status = true;
      }
      status_dirty_ = false;
    }
    if (send_status) notifier_.Status(status);
    const auto now = std::chrono::steady_clock::now();
    if (now < next_check) continue;
    // From now, not from the missed tick: after a long delay of this thread
    // (suspend, overload) the stages get a whole period before the next check
    // instead of being checked back to back and reported stalled.
    next_check = now + period_;
    Check(&stalled_names, &last_reported);
  }
}

void ServiceWatchdog::Check(std::string* stalled_names, std::string* last_reported) {
  if (heartbeats_.AllMoved(stalled_names)) {
    if (stalled_.load(std::memory_order_relaxed)) {
      log::Warn("watchdog: all stages move again (were stalled: {})", *last_reported);
      last_reported->clear();
      std::string status;
      {
        std::lock_guard<std::mutex> lock(mutex_);
        status = status_;
        status_dirty_ = false;
      }
      stalled_.store(false, std::memory_order_release);
      notifier_.Status(status.empty() ? std::string("running") : status);
    }
    healthy_checks_.fetch_add(1, std::memory_order_relaxed);
    notifier_.WatchdogPing();
    return;
  }
  stalled_.store(true, std::memory_order_release);
  if (*stalled_names == *last_reported) return;
  *last_reported = *stalled_names;
  log::Error("watchdog: stalled stages: {}; {}", *stalled_names,
             notifier_.WatchdogInterval()
                 ? "not feeding the systemd watchdog, systemd restarts the daemon"
                 : "no systemd watchdog, nothing restarts the daemon");
  notifier_.Status("STALLED: " + *stalled_names +
                   (notifier_.WatchdogInterval() ? " (watchdog not fed, restart pending)" : ""));
}

}  // namespace hg::app
