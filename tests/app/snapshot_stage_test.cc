#include "app/snapshot_stage.h"

#include <atomic>
#include <chrono>
#include <memory>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

namespace hg::app {
namespace {

using namespace std::chrono_literals;
using Snapshot = pipeline::OccupancySnapshot;

std::shared_ptr<const Snapshot> Numbered(std::uint64_t sequence) {
  auto s = std::make_shared<Snapshot>();
  s->sequence = sequence;
  return s;
}

template <class Pred>
bool WaitFor(Pred pred) {
  for (const auto end = std::chrono::steady_clock::now() + 5s;
       std::chrono::steady_clock::now() < end;) {
    if (pred()) return true;
    std::this_thread::sleep_for(1ms);
  }
  return pred();
}

// Offered one at a time, every snapshot reaches the consumer, in order.
TEST(SnapshotStageTest, DeliversEverySnapshotOfferedInTurn) {
  std::vector<std::uint64_t> seen;
  std::atomic<std::uint64_t> last{0};
  SnapshotStage stage(
      "publish",
      [&](const Snapshot& s) {
        seen.push_back(s.sequence);
        last.store(s.sequence);
      },
      nullptr);
  stage.Start();
  for (std::uint64_t i = 1; i <= 50; ++i) {
    stage.Offer(Numbered(i));
    ASSERT_TRUE(WaitFor([&] { return last.load() == i; })) << i;
  }
  stage.Stop();
  ASSERT_EQ(seen.size(), 50U);
  for (std::uint64_t i = 0; i < 50; ++i) EXPECT_EQ(seen[i], i + 1);
  EXPECT_EQ(stage.delivered(), 50U);
  EXPECT_EQ(stage.skipped(), 0U);
}

// A consumer stuck on the network holds up neither Offer() nor the snapshots'
// owner: offers go on at once, the stage skips to the newest, and the
// snapshots it skipped are released.
TEST(SnapshotStageTest, AStuckConsumerNeverHoldsUpTheOffers) {
  std::atomic<bool> release{false};
  std::atomic<std::uint64_t> last{0};
  SnapshotStage stage(
      "publish",
      [&](const Snapshot& s) {
        while (!release.load()) std::this_thread::sleep_for(1ms);
        last.store(s.sequence);
      },
      nullptr);
  stage.Start();
  std::weak_ptr<const Snapshot> early;
  const auto start = std::chrono::steady_clock::now();
  for (std::uint64_t i = 1; i <= 1000; ++i) {
    auto s = Numbered(i);
    if (i == 500) early = s;
    stage.Offer(s);
  }
  EXPECT_LT(std::chrono::steady_clock::now() - start, 1s);
  EXPECT_TRUE(early.expired()) << "a skipped snapshot is still held";
  release.store(true);
  ASSERT_TRUE(WaitFor([&] { return last.load() == 1000; }));
  stage.Stop();
  EXPECT_GT(stage.skipped(), 900U);
  EXPECT_LE(stage.delivered(), 3U);
}

// The stage's heartbeat moves while it waits for snapshots, and stops with
// a consumer that hangs (the watchdog then stops its pings).
TEST(SnapshotStageTest, HeartbeatMovesWhileWaitingAndStopsWhenTheConsumerHangs) {
  common::Heartbeats heartbeats;
  std::atomic<bool> hang{false}, release{false};
  SnapshotStage stage(
      "publish",
      [&](const Snapshot&) {
        hang.store(true);
        while (!release.load()) std::this_thread::sleep_for(1ms);
      },
      &heartbeats);
  ASSERT_EQ(heartbeats.size(), 1);
  EXPECT_EQ(heartbeats.name(0), "publish");
  stage.Start();
  const std::uint64_t before = heartbeats.beats(0);
  ASSERT_TRUE(WaitFor([&] { return heartbeats.beats(0) >= before + 3; }));  // Idle, 100 ms each.
  stage.Offer(Numbered(1));
  ASSERT_TRUE(WaitFor([&] { return hang.load(); }));
  const std::uint64_t hung = heartbeats.beats(0);
  std::this_thread::sleep_for(350ms);
  EXPECT_EQ(heartbeats.beats(0), hung);
  release.store(true);
  stage.Stop();
}

}  // namespace
}  // namespace hg::app
