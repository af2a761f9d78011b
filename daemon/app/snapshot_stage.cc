#include "app/snapshot_stage.h"

#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <ctime>
#include <utility>

#include "common/check.h"

namespace hg::app {
namespace {

/// Longest wait for a snapshot: the thread beats its heartbeat at least this often.
constexpr long kWaitNs = 100'000'000L;

}  // namespace

SnapshotStage::SnapshotStage(std::string name, Consumer consumer, common::Heartbeats* heartbeats,
                             int nice, std::chrono::steady_clock::duration stall_allowance)
    : consumer_(std::move(consumer)), heartbeats_(heartbeats), nice_(nice) {
  HG_CHECK(sem_init(&offered_, 0, 0) == 0);
  if (heartbeats_ != nullptr) heartbeat_ = heartbeats_->Register(name, stall_allowance);
}

SnapshotStage::~SnapshotStage() {
  Stop();
  sem_destroy(&offered_);
}

void SnapshotStage::Start() {
  HG_CHECK(!thread_.joinable());
  stop_.store(false);
  thread_ = std::thread([this] { Loop(); });
}

void SnapshotStage::Stop() {
  stop_.store(true);
  if (thread_.joinable()) {
    sem_post(&offered_);  // Wakes the thread at once.
    thread_.join();
  }
}

void SnapshotStage::Offer(const std::shared_ptr<const pipeline::OccupancySnapshot>& snapshot) {
  slot_.BeginWrite() = snapshot;  // A reference count, no allocation.
  slot_.Publish();
  sem_post(&offered_);  // Lock-free; a futex wake only when the thread waits.
}

void SnapshotStage::Loop() {
  // Per thread on Linux; raising one's own niceness needs no privilege.
  if (nice_ > 0) (void)setpriority(PRIO_PROCESS, static_cast<id_t>(syscall(SYS_gettid)), nice_);
  while (!stop_.load(std::memory_order_relaxed)) {
    if (heartbeat_ >= 0) heartbeats_->Beat(heartbeat_);
    timespec until{};
    clock_gettime(CLOCK_MONOTONIC, &until);
    until.tv_nsec += kWaitNs;
    if (until.tv_nsec >= 1'000'000'000L) {
      until.tv_nsec -= 1'000'000'000L;
      ++until.tv_sec;
    }
    if (sem_clockwait(&offered_, CLOCK_MONOTONIC, &until) != 0) continue;  // Timeout or signal.
    while (sem_trywait(&offered_) == 0) {
    }  // The newest snapshot stands for every post so far.
    if (stop_.load(std::memory_order_relaxed)) break;
    std::shared_ptr<const pipeline::OccupancySnapshot>* newest = slot_.TakeNewest();
    if (newest == nullptr || !*newest) continue;
    consumer_(**newest);
    delivered_.fetch_add(1, std::memory_order_relaxed);
    newest->reset();  // The pipeline may reuse the snapshot from now on.
  }
}

}  // namespace hg::app
