// The black box: frames pushed by a capture thread are dumped as a recording
// that reads back exactly; a dump racing with pushes never writes a torn
// image; pushing allocates nothing. This file replaces the global operator new
// of black_box_test to count calls while a test asks for it.
#include "pipeline/black_box.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <mutex>
#include <new>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "capture/recording.h"
#include "capture/replay_source.h"
#include "common/config_error.h"
#include "geometry/camera_yaml.h"
#include "support/allocation_counter.h"

void* operator new[](std::size_t size) { return operator new(size); }
[[gnu::noinline]] void operator delete[](void* p) noexcept { std::free(p); }
[[gnu::noinline]] void operator delete[](void* p, std::size_t) noexcept { std::free(p); }

namespace hg::pipeline {
namespace {

namespace fs = std::filesystem;
using capture::Frame;
using capture::FrameKind;

geometry::CameraModel Camera(const std::string& name, int width, int height) {
  geometry::CameraModel m;
  m.name = name;
  m.width = width;
  m.height = height;
  m.K << 100, 0, (width - 1) / 2.0, 0, 100, (height - 1) / 2.0, 0, 0, 1;
  return m;
}

// Frame `n` of a camera: every byte a function of n (so a mixture of two
// frames is visible), stamps and index from n too.
void MakeFrame(FrameKind kind, int width, int height, std::uint64_t n, std::uint64_t seed,
               Frame* frame) {
  frame->kind = kind;
  std::mt19937_64 rng(seed * 1'000'003 + n);
  if (kind == FrameKind::kRgb) {
    frame->rgb.width = width;
    frame->rgb.height = height;
    frame->rgb.pixels.resize(static_cast<std::size_t>(width) * height * 3);
    for (auto& p : frame->rgb.pixels) p = static_cast<std::uint8_t>(rng());
  } else {
    frame->grey.width = width;
    frame->grey.height = height;
    frame->grey.pixels.resize(static_cast<std::size_t>(width) * height);
    for (auto& p : frame->grey.pixels) p = static_cast<std::uint8_t>(rng());
  }
  frame->stamp_ns = 1'700'000'000'000'000'000 + static_cast<std::int64_t>(n) * 33'333'333 +
                    static_cast<std::int64_t>(seed);
  frame->index = 1000 + n;
}

// Frame `n` with one byte value all over: a torn copy would mix two values.
void MakeUniformFrame(int width, int height, std::uint64_t n, Frame* frame) {
  frame->kind = FrameKind::kMono;
  frame->grey.width = width;
  frame->grey.height = height;
  frame->grey.pixels.assign(static_cast<std::size_t>(width) * height,
                            static_cast<std::uint8_t>(n % 251));
  frame->stamp_ns = 1'000'000 + static_cast<std::int64_t>(n);
  frame->index = n;
}

class BlackBoxTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           std::string("hg_black_box_")
               .append(std::to_string(::getpid()))
               .append("_")
               .append(::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

TEST(BlackBoxSizingTest, SlotsAndBytes) {
  EXPECT_EQ(BlackBoxSlots(2.0, 30.0), 61U);
  EXPECT_EQ(BlackBoxSlots(0.1, 25.0), 4U);                    // ceil(2.5) + 1.
  EXPECT_EQ(BlackBoxSlotBytes(3, 3, FrameKind::kMono), 16U);  // 9 bytes in whole words.
  EXPECT_EQ(BlackBoxSlotBytes(1920, 1080, FrameKind::kRgb), 1920U * 1080U * 3U);
  const std::vector<BlackBoxCamera> cameras = {{Camera("a", 64, 48), FrameKind::kMask, 10.0},
                                               {Camera("b", 32, 24), FrameKind::kRgb, 20.0}};
  EXPECT_EQ(BlackBoxBytes(cameras, 1.0), 11U * 64 * 48 + 21U * 32 * 24 * 3);
  EXPECT_EQ(BlackBoxFolderName(1'700'000'000'123'456'789), "20231114T221320.123Z");
}

TEST(BlackBoxSizingTest, RefusesMoreMemoryThanAllowed) {
  BlackBoxOptions o;
  o.seconds = 10.0;
  o.max_memory_mb = 100.0;
  // 10 s of Full HD RGB at 30 Hz: 1.9 GB.
  try {
    BlackBox box(o, {{Camera("door", 1920, 1080), FrameKind::kRgb, 30.0}});
    FAIL() << "expected a ConfigError";
  } catch (const common::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("max_memory_mb = 100"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("door 301 x 1920x1080 rgb"), std::string::npos)
        << e.what();
  }
}

// Pushes more frames than the rings hold, dumps, and reads the recording
// back: the newest frames of each camera, pixel for pixel, with their stamps
// and indices, and the calibration.
TEST_F(BlackBoxTest, DumpReadsBackExactly) {
  BlackBoxOptions o;
  o.seconds = 0.5;
  o.directory = dir_.string();
  const std::vector<BlackBoxCamera> cameras = {{Camera("grey", 37, 21), FrameKind::kMono, 20.0},
                                               {Camera("colour", 16, 12), FrameKind::kRgb, 10.0},
                                               {Camera("mask", 8, 8), FrameKind::kMask, 10.0}};
  const FrameKind kinds[] = {FrameKind::kMono, FrameKind::kRgb, FrameKind::kMask};
  BlackBox box(o, cameras);
  ASSERT_EQ(box.slots(0), 11U);
  ASSERT_EQ(box.slots(1), 6U);
  const std::uint64_t pushed[] = {25, 4, 6};  // The colour ring is not full.
  Frame frame;
  for (int c = 0; c < 3; ++c) {
    for (std::uint64_t n = 0; n < pushed[c]; ++n) {
      MakeFrame(kinds[c], cameras[c].model.width, cameras[c].model.height, n, c, &frame);
      // The first camera has a clock of its own (GigE Vision), the others none.
      frame.device_stamp_ns = c == 0 ? 5'000'000 + static_cast<std::int64_t>(n) : -1;
      box.Push(c, frame);
    }
  }
  // Another size than the camera's is not kept.
  MakeFrame(FrameKind::kRgb, 64, 64, 99, 0, &frame);
  box.Push(2, frame);
  EXPECT_EQ(box.oversized(2), 1U);

  const BlackBoxDump dump = box.DumpTo((dir_ / "dump").string(), "test");
  EXPECT_TRUE(dump.error.empty()) << dump.error;
  EXPECT_EQ(dump.torn, 0U);
  EXPECT_EQ(dump.frames, 11U + 4U + 6U);
  ASSERT_EQ(capture::RecordingCameraNames(dump.directory),
            (std::vector<std::string>{"grey", "colour", "mask"}));
  for (int c = 0; c < 3; ++c) {
    const capture::RecordingCamera rec =
        capture::ReadRecordingCamera(dump.directory, cameras[c].model.name);
    EXPECT_EQ(rec.layout, capture::RecordingLayout::kRecord);
    EXPECT_EQ(rec.kind, kinds[c]);
    EXPECT_EQ(rec.width, cameras[c].model.width);
    const std::uint64_t kept = std::min<std::uint64_t>(pushed[c], box.slots(c));
    ASSERT_EQ(rec.frames.size(), kept);
    capture::ReplaySource source(rec, capture::SimClock{});
    for (std::size_t i = 0; i < rec.frames.size(); ++i) {
      const std::uint64_t n = pushed[c] - kept + i;
      Frame expected, got;
      MakeFrame(kinds[c], cameras[c].model.width, cameras[c].model.height, n, c, &expected);
      EXPECT_EQ(rec.frames[i].stamp_ns, expected.stamp_ns);
      EXPECT_EQ(rec.frames[i].source_index, expected.index);
      // The camera's own stamp is kept (it was dropped: an empty column).
      EXPECT_EQ(rec.frames[i].device_stamp_ns,
                c == 0 ? std::optional<std::int64_t>(5'000'000 + static_cast<std::int64_t>(n))
                       : std::nullopt);
      ASSERT_TRUE(source.ReadFrame(static_cast<int>(i), &got));
      EXPECT_EQ(got.kind, kinds[c]);
      if (kinds[c] == FrameKind::kRgb) {
        EXPECT_EQ(got.rgb.pixels, expected.rgb.pixels) << "frame " << n;
      } else {
        EXPECT_EQ(got.grey.pixels, expected.grey.pixels) << "frame " << n;
      }
    }
  }
  const auto models =
      geometry::LoadCamerasFile((fs::path(dump.directory) / "cameras.yaml").string());
  ASSERT_EQ(models.size(), 3U);
  EXPECT_EQ(models[1].name, "colour");
  EXPECT_EQ(models[1].K, cameras[1].model.K);
}

// A capture thread pushes while dumps copy the ring, first paced (a frame
// every 50 us), then as fast as it can: every frame written is one whole
// frame (one byte value over the image), in order; torn slots are skipped and
// counted, never written.
TEST_F(BlackBoxTest, DumpDuringPushesWritesNoTornFrame) {
  BlackBoxOptions o;
  o.seconds = 1.0;
  o.directory = dir_.string();
  constexpr int kWidth = 96, kHeight = 64;
  BlackBox box(o, {{Camera("cam", kWidth, kHeight), FrameKind::kMono, 30.0}});
  std::atomic<bool> stop{false};
  std::atomic<bool> paced{true};
  std::thread capture([&] {
    Frame frame;
    for (std::uint64_t n = 0; !stop.load(std::memory_order_relaxed); ++n) {
      MakeUniformFrame(kWidth, kHeight, n, &frame);
      box.Push(0, frame);
      if (paced.load(std::memory_order_relaxed)) {
        std::this_thread::sleep_for(std::chrono::microseconds(50));
      }
    }
  });
  // A failed assertion returns early: the capture thread still stops and joins.
  struct JoinOnExit {
    std::atomic<bool>* stop;
    std::thread* thread;
    ~JoinOnExit() {
      stop->store(true);
      if (thread->joinable()) thread->join();
    }
  } join_on_exit{&stop, &capture};
  while (box.pushed(0) < 3 * box.slots(0)) std::this_thread::yield();
  std::uint64_t torn = 0, frames = 0, paced_frames = 0;
  for (int d = 0; d < 6; ++d) {
    if (d == 3) {
      paced_frames = frames;
      paced.store(false);
    }
    const BlackBoxDump dump = box.DumpTo((dir_ / ("dump" + std::to_string(d))).string(), "race");
    ASSERT_TRUE(dump.error.empty()) << dump.error;
    torn += dump.torn;
    frames += dump.frames;
    const capture::RecordingCamera rec = capture::ReadRecordingCamera(dump.directory, "cam");
    EXPECT_EQ(rec.lost, dump.torn);
    capture::ReplaySource source(rec, capture::SimClock{});
    std::int64_t previous = -1;
    for (std::size_t i = 0; i < rec.frames.size(); ++i) {
      Frame got;
      ASSERT_TRUE(source.ReadFrame(static_cast<int>(i), &got));
      const std::uint64_t n = rec.frames[i].source_index;
      EXPECT_EQ(rec.frames[i].stamp_ns, 1'000'000 + static_cast<std::int64_t>(n));
      const auto value = static_cast<std::uint8_t>(n % 251);
      const auto bad = std::count_if(got.grey.pixels.begin(), got.grey.pixels.end(),
                                     [&](std::uint8_t p) { return p != value; });
      ASSERT_EQ(bad, 0) << "frame " << n << " of dump " << d << " is torn";
      EXPECT_GT(static_cast<std::int64_t>(n), previous);
      previous = static_cast<std::int64_t>(n);
    }
  }
  stop.store(true);
  capture.join();
  EXPECT_GT(paced_frames, 0U);
  // Not asserted: how many slots were torn depends on the scheduler.
  std::printf("6 dumps during pushes: %llu frames written, %llu torn slots skipped\n",
              static_cast<unsigned long long>(frames), static_cast<unsigned long long>(torn));
}

TEST_F(BlackBoxTest, PushAllocatesNothing) {
  BlackBoxOptions o;
  o.seconds = 0.2;
  o.directory = dir_.string();
  BlackBox box(o, {{Camera("a", 64, 48), FrameKind::kRgb, 30.0},
                   {Camera("b", 33, 17), FrameKind::kMono, 30.0}});
  Frame rgb, mono, too_big;
  MakeFrame(FrameKind::kRgb, 64, 48, 1, 0, &rgb);
  MakeFrame(FrameKind::kMono, 33, 17, 1, 1, &mono);
  MakeFrame(FrameKind::kRgb, 65, 48, 1, 1, &too_big);
  long allocations = 0;
  {
    const hg::testing::AllocationCounter counter;
    for (int i = 0; i < 100; ++i) {
      box.Push(0, rgb);
      box.Push(1, mono);
      box.Push(1, too_big);
    }
    allocations = counter.count();
  }
  EXPECT_EQ(allocations, 0);
  EXPECT_EQ(box.pushed(0), 100U);
  EXPECT_EQ(box.oversized(1), 100U);
}

// RequestDump runs on the writer thread into directory/<UTC time>/; a request
// while one runs is refused.
TEST_F(BlackBoxTest, RequestedDumpGoesToATimeNamedFolder) {
  BlackBoxOptions o;
  o.seconds = 0.2;
  o.directory = dir_.string();
  o.low_priority = false;
  std::atomic<int> reported{0};
  o.on_dump = [&](const BlackBoxDump&) { reported.fetch_add(1); };
  BlackBox box(o, {{Camera("a", 16, 16), FrameKind::kMask, 30.0}});
  Frame frame;
  for (std::uint64_t n = 0; n < 3; ++n) {
    MakeFrame(FrameKind::kMask, 16, 16, n, 0, &frame);
    box.Push(0, frame);
  }
  ASSERT_TRUE(box.RequestDump("SIGUSR1"));
  box.WaitIdle();
  const std::optional<BlackBoxDump> dump = box.LastDump();
  ASSERT_TRUE(dump.has_value());
  EXPECT_EQ(reported.load(), 1);
  EXPECT_EQ(dump->reason, "SIGUSR1");
  EXPECT_EQ(dump->frames, 3U);
  EXPECT_EQ(fs::path(dump->directory).parent_path(), dir_);
  EXPECT_EQ(fs::path(dump->directory).filename().string().size(), 20U);  // 20231114T221320.123Z
  EXPECT_EQ(capture::ReadRecordingCamera(dump->directory, "a").frames.size(), 3U);
  EXPECT_EQ(box.dumps(), 1U);
}

// A dump asked for while another is written is copied at once, not after
// the first is written: it holds the frames of the moment it was asked for,
// none pushed later. A third request while one is written and one waits is
// refused.
TEST_F(BlackBoxTest, DumpAskedForDuringAnotherIsCopiedAtOnce) {
  BlackBoxOptions o;
  o.seconds = 0.5;  // 16 slots.
  o.directory = dir_.string();
  o.low_priority = false;
  std::mutex mutex;
  std::condition_variable cv;
  bool release = false;
  std::vector<BlackBoxDump> dumps;
  o.on_dump = [&](const BlackBoxDump& d) {
    std::unique_lock<std::mutex> lock(mutex);
    dumps.push_back(d);
    cv.notify_all();
    cv.wait(lock, [&] { return release; });  // The first dump's writing lasts.
  };
  BlackBox box(o, {{Camera("a", 16, 16), FrameKind::kMask, 30.0}});
  // Lets the writer go on however the test ends (a failed assertion would
  // otherwise leave the box's destructor waiting for the first dump).
  struct Release {
    std::mutex& mutex;
    std::condition_variable& cv;
    bool& release;
    ~Release() {
      {
        const std::lock_guard<std::mutex> lock(mutex);
        release = true;
      }
      cv.notify_all();
    }
  } const release_at_end{mutex, cv, release};
  Frame frame;
  auto push = [&](std::uint64_t from, std::uint64_t to) {
    for (std::uint64_t n = from; n < to; ++n) {
      MakeFrame(FrameKind::kMask, 16, 16, n, 0, &frame);
      box.Push(0, frame);
    }
  };
  auto wait_copies = [&](std::uint64_t n) {
    for (int i = 0; i < 12000 && box.copies() < n; ++i)
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    return box.copies();
  };
  push(0, 3);
  ASSERT_TRUE(box.RequestDump("SIGUSR1"));
  {
    // The writer holds the first dump (it waits in on_dump): the copy is
    // done and the copied dump taken up, not waiting any more.
    std::unique_lock<std::mutex> lock(mutex);
    ASSERT_TRUE(cv.wait_for(lock, std::chrono::seconds(60), [&] { return !dumps.empty(); }));
  }
  ASSERT_EQ(box.copies(), 1U);
  push(3, 6);
  ASSERT_TRUE(box.accepting()) << "the first dump is being written, none waits";
  ASSERT_TRUE(box.RequestDump("degraded"));
  ASSERT_EQ(wait_copies(2), 2U) << "copied while the first dump is still written";
  EXPECT_FALSE(box.accepting());
  EXPECT_FALSE(box.RequestDump("SIGUSR1")) << "one written, one waiting";
  EXPECT_EQ(box.refused_requests(), 1U);
  push(6, 9);
  {
    const std::lock_guard<std::mutex> lock(mutex);
    release = true;
  }
  cv.notify_all();
  box.WaitIdle();
  ASSERT_EQ(dumps.size(), 2U);
  EXPECT_EQ(dumps[0].reason, "SIGUSR1");
  EXPECT_EQ(dumps[0].frames, 3U);
  EXPECT_EQ(dumps[1].reason, "degraded");
  EXPECT_EQ(dumps[1].frames, 6U);
  const std::int64_t fifth = 1'700'000'000'000'000'000 + 5 * 33'333'333;  // MakeFrame's stamp.
  EXPECT_EQ(dumps[1].last_ns, fifth) << "frames pushed after the request are not in it";
  EXPECT_NE(dumps[0].directory, dumps[1].directory);
  const auto second = capture::ReadRecordingCamera(dumps[1].directory, "a");
  ASSERT_EQ(second.frames.size(), 6U);
  EXPECT_EQ(second.frames.back().stamp_ns, fifth);
  EXPECT_TRUE(box.accepting());
}

}  // namespace
}  // namespace hg::pipeline

namespace hg::pipeline {
namespace {

// The turn from ok to degraded dumps, at most once per interval; a turn
// inside the interval (here: a missed deadline, then a camera lost 0.4 s
// later) is dumped when the interval is over, not forgotten while the status
// stays degraded. Cycles before the first ok one (cameras starting) are no turn.
TEST(DegradedDumpTriggerTest, ATurnInsideTheIntervalIsDumpedAfterIt) {
  using Clock = DegradedDumpTrigger::Clock;
  using std::chrono::milliseconds;
  const Clock::time_point t0{};
  DegradedDumpTrigger trigger(milliseconds(1000));
  EXPECT_FALSE(trigger.due());
  trigger.Observe(true);  // Starting.
  EXPECT_FALSE(trigger.ShouldDump(t0, true));
  trigger.Observe(false);
  trigger.Observe(true);  // The deadline miss.
  EXPECT_FALSE(trigger.ShouldDump(t0, /*accepting=*/false)) << "two dumps in flight";
  EXPECT_TRUE(trigger.due());
  ASSERT_TRUE(trigger.ShouldDump(t0 + milliseconds(20), true));
  trigger.Dumped(t0 + milliseconds(20));
  EXPECT_FALSE(trigger.ShouldDump(t0 + milliseconds(40), true));
  trigger.Observe(false);
  trigger.Observe(true);  // The camera lost, and it stays lost.
  EXPECT_TRUE(trigger.due()) << "dumped at shutdown inside the interval";
  for (int ms = 420; ms < 1020; ms += 20) {
    trigger.Observe(true);
    EXPECT_FALSE(trigger.ShouldDump(t0 + milliseconds(ms), true)) << ms;
  }
  trigger.Observe(true);
  ASSERT_TRUE(trigger.ShouldDump(t0 + milliseconds(1020), true));
  trigger.Dumped(t0 + milliseconds(1020));
  for (int ms = 1040; ms < 5000; ms += 20) {
    trigger.Observe(true);  // Degraded throughout: no new turn, no new dump.
    EXPECT_FALSE(trigger.ShouldDump(t0 + milliseconds(ms), true)) << ms;
  }
}

}  // namespace
}  // namespace hg::pipeline
