// The recording format: what RecordingWriter writes reads back exactly
// (pixels, stamps, device stamps, indices, calibration), write errors are
// counted and the recording goes on, a cut-short index still reads, bad
// indexes are reported with file and line, and the replay source plays the
// record layout in real time and as fast as possible, and the synth layout as
// before.
#include "capture/recording.h"

#include <sys/resource.h>

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "capture/replay_source.h"
#include "common/config_error.h"
#include "geometry/camera_yaml.h"
#include "silhouette/mask_io.h"
#include "support/handmade_images.h"

namespace hg::capture {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

geometry::CameraModel Camera(const std::string& name, int width, int height) {
  geometry::CameraModel m;
  m.name = name;
  m.width = width;
  m.height = height;
  m.K << 90.5, 0, (width - 1) / 2.0, 0, 91.25, (height - 1) / 2.0, 0, 0, 1;
  m.distortion = {-0.1, 0.01, 0.001, -0.002, 0.0};
  m.t_CW = Eigen::Vector3d(0.1, -0.2, 3.0);
  return m;
}

Frame RandomFrame(FrameKind kind, int width, int height, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  Frame f;
  f.kind = kind;
  std::vector<std::uint8_t>& pixels = kind == FrameKind::kRgb ? f.rgb.pixels : f.grey.pixels;
  if (kind == FrameKind::kRgb) {
    f.rgb.width = width;
    f.rgb.height = height;
    pixels.resize(static_cast<std::size_t>(width) * height * 3);
  } else {
    f.grey.width = width;
    f.grey.height = height;
    pixels.resize(static_cast<std::size_t>(width) * height);
  }
  for (auto& p : pixels) p = static_cast<std::uint8_t>(rng());
  if (kind == FrameKind::kMask) {
    for (auto& p : pixels) p = p > 127 ? 255 : 0;
  }
  return f;
}

class RecordingTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           std::string("hg_recording_")
               .append(std::to_string(::getpid()))
               .append("_")
               .append(::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

// Every kind of frame in every image format: file extensions per format
// (mono, rgb, mask).
struct FormatCase {
  ImageFormat format;
  const char* extension[3];
};
constexpr FormatCase kFormats[] = {{ImageFormat::kPng, {"png", "png", "png"}},
                                   {ImageFormat::kPnm, {"pgm", "ppm", "pgm"}},
                                   {ImageFormat::kAuto, {"pgm", "ppm", "png"}}};

// Writes 4 frames of a mono, an RGB and a mask camera and reads them back:
// pixels, stamps, device stamps, indices, file names and calibration.
void CheckRoundTrip(ImageFormat format, const char* const (&extension)[3], const std::string& dir) {
  const std::vector<geometry::CameraModel> models = {Camera("mono", 31, 17), Camera("rgb", 20, 10),
                                                     Camera("mask", 16, 9)};
  const FrameKind kinds[] = {FrameKind::kMono, FrameKind::kRgb, FrameKind::kMask};
  const std::int64_t t0 = 1'700'000'000'000'000'000;
  std::vector<std::vector<Frame>> written(3);
  {
    RecordingWriter writer(dir, models, "test", "a note", format);
    for (int c = 0; c < 3; ++c) {
      for (std::uint64_t i = 0; i < 4; ++i) {
        Frame f = RandomFrame(kinds[c], models[c].width, models[c].height, 10 * c + i);
        // The mask camera starts first: it sets recording time 0.
        f.stamp_ns =
            t0 + static_cast<std::int64_t>(i) * 40'000'000 + (c == 2 ? 0 : 7'000'000 * c + 1);
        f.index = 500 + i;
        // Camera 1 has a device clock (as a GigE Vision camera): the writer
        // takes the frame's own device stamp.
        f.device_stamp_ns = c == 1 ? 123'456'789 + static_cast<std::int64_t>(i) : -1;
        ASSERT_TRUE(writer.Write(c, 2 * i, f)) << writer.stats(c).last_error;
        written[c].push_back(f);
      }
    }
    std::string error;
    EXPECT_TRUE(writer.Finish(&error)) << error;
    EXPECT_EQ(writer.stats(1).kept, 4U);
  }
  EXPECT_EQ(RecordingCameraNames(dir), (std::vector<std::string>{"mono", "rgb", "mask"}));
  const auto cameras = geometry::LoadCamerasFile(dir + "/cameras.yaml");
  ASSERT_EQ(cameras.size(), 3U);
  EXPECT_EQ(cameras[0].K, models[0].K);
  EXPECT_EQ(cameras[0].distortion, models[0].distortion);
  EXPECT_EQ(cameras[0].t_CW, models[0].t_CW);

  for (int c = 0; c < 3; ++c) {
    const RecordingCamera rec = ReadRecordingCamera(dir, models[c].name);
    EXPECT_EQ(rec.layout, RecordingLayout::kRecord);
    EXPECT_EQ(rec.kind, kinds[c]);
    EXPECT_EQ(rec.width, models[c].width);
    EXPECT_EQ(rec.height, models[c].height);
    EXPECT_EQ(rec.start_ns, t0);
    EXPECT_EQ(rec.lost, 0U);
    EXPECT_NEAR(rec.rate_hz, 25.0, 1e-9);
    ASSERT_EQ(rec.frames.size(), 4U);
    ReplaySource source(rec, SimClock{});  // Epoch 0: stamps are recording times.
    for (std::size_t i = 0; i < 4; ++i) {
      const RecordedFrame& rf = rec.frames[i];
      EXPECT_EQ(rf.stamp_ns, written[c][i].stamp_ns);
      EXPECT_EQ(rf.time_ns, written[c][i].stamp_ns - t0);
      EXPECT_EQ(rf.source_index, 500 + i);
      EXPECT_EQ(rf.device_stamp_ns.has_value(), c == 1);
      if (c == 1) {
        EXPECT_EQ(*rf.device_stamp_ns, 123'456'789 + static_cast<std::int64_t>(i));
      }
      char name[32];
      std::snprintf(name, sizeof(name), "%06zu.%s", 2 * i, extension[c]);
      EXPECT_EQ(rf.file, std::string("frames/") + models[c].name + "/" + name);
      Frame got;
      ASSERT_TRUE(source.ReadFrame(static_cast<int>(i), &got));
      EXPECT_EQ(got.kind, kinds[c]);
      EXPECT_EQ(got.stamp_ns, rf.time_ns);
      EXPECT_EQ(got.index, 500 + i);
      EXPECT_EQ(got.device_stamp_ns, c == 1 ? 123'456'789 + static_cast<std::int64_t>(i) : -1);
      if (kinds[c] == FrameKind::kRgb) {
        EXPECT_EQ(got.rgb.width, models[c].width);
        EXPECT_EQ(got.rgb.pixels, written[c][i].rgb.pixels);
      } else {
        EXPECT_EQ(got.grey.width, models[c].width);
        EXPECT_EQ(got.grey.pixels, written[c][i].grey.pixels);
      }
    }
  }
}

TEST_F(RecordingTest, WritesAndReadsBackEveryKindExactly) {
  for (const FormatCase& format : kFormats) {
    SCOPED_TRACE(ToString(format.format));
    CheckRoundTrip(format.format, format.extension, (dir_ / ToString(format.format)).string());
  }
}

// A frame whose file cannot be written (a folder stands where it would go)
// is counted with the reason; the frames after it are kept, the index skips
// its number, and the manifest reports the loss.
TEST_F(RecordingTest, WriteErrorIsCountedAndTheRecordingGoesOn) {
  RecordingWriter writer(dir_.string(), {Camera("cam", 8, 6)}, "test", "", ImageFormat::kPnm);
  fs::create_directories(dir_ / "frames" / "cam" / "000001.pgm");
  for (std::uint64_t i = 0; i < 3; ++i) {
    Frame f = RandomFrame(FrameKind::kMono, 8, 6, i);
    f.stamp_ns = 1000 + static_cast<std::int64_t>(i);
    EXPECT_EQ(writer.Write(0, i, f), i != 1);
  }
  writer.CountLost(0, FrameLoss::kQueueFull, 2);
  EXPECT_EQ(writer.stats(0).kept, 2U);
  EXPECT_EQ(writer.stats(0).write_errors, 1U);
  EXPECT_EQ(writer.stats(0).lost(), 3U);
  EXPECT_NE(writer.stats(0).last_error.find("000001.pgm"), std::string::npos)
      << writer.stats(0).last_error;
  ASSERT_TRUE(writer.Finish());
  const RecordingCamera rec = ReadRecordingCamera(dir_.string(), "cam");
  ASSERT_EQ(rec.frames.size(), 2U);
  EXPECT_EQ(rec.frames[1].file, "frames/cam/000002.pgm");
  EXPECT_EQ(rec.lost, 3U);
  // A frame of another size than the camera's first is refused.
  EXPECT_FALSE(writer.Write(0, 5, RandomFrame(FrameKind::kMono, 9, 6, 1)));
}

// The disk fills in the middle of an index line (here: a file size limit,
// RLIMIT_FSIZE, which cuts the write where it is reached, as a full disk
// does), then has room again: the line is cut back, the frame counted lost
// and its image removed, and the lines after it follow whole lines. Half a
// line with the next one glued on made the whole recording unreadable.
TEST_F(RecordingTest, AnIndexLineCutByAFullDiskIsUndone) {
  RecordingWriter writer(dir_.string(), {Camera("cam", 4, 3)}, "test", "", ImageFormat::kPnm);
  const fs::path index = dir_ / "frames" / "cam" / "index.csv";
  Frame f = RandomFrame(FrameKind::kMono, 4, 3, 1);
  f.stamp_ns = 1'795'000'000'000'000'000;
  ASSERT_TRUE(writer.Write(0, 0, f));
  ASSERT_TRUE(writer.Write(0, 1, f));
  const auto size = static_cast<rlim_t>(fs::file_size(index));
  rlimit before{};
  ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &before), 0);
  const auto old_handler = std::signal(SIGXFSZ, SIG_IGN);
  rlimit limit = before;
  limit.rlim_cur = size + 20;  // Room for 20 bytes of the next line, not all of it.
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &limit), 0);
  const bool written = writer.Write(0, 2, f);
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &before), 0);
  std::signal(SIGXFSZ, old_handler);
  EXPECT_FALSE(written);
  EXPECT_EQ(fs::file_size(index), size);
  EXPECT_FALSE(fs::exists(dir_ / "frames" / "cam" / "000002.pgm"));
  EXPECT_EQ(writer.stats(0).write_errors, 1U);
  ASSERT_TRUE(writer.Write(0, 3, f));
  ASSERT_TRUE(writer.Finish());
  const RecordingCamera rec = ReadRecordingCamera(dir_.string(), "cam");
  ASSERT_EQ(rec.frames.size(), 3U);
  EXPECT_EQ(rec.frames[2].file, "frames/cam/000003.pgm");
}

TEST_F(RecordingTest, RefusesAFolderThatHoldsARecording) {
  { RecordingWriter writer(dir_.string(), {Camera("cam", 8, 6)}, "test"); }
  EXPECT_THROW(RecordingWriter(dir_.string(), {Camera("cam", 8, 6)}, "test"), common::ConfigError);
}

// A recording of camera "cam" (8 x 6 masks) with two frames, stamped 5000 and 5001.
void WriteTwoMasks(const fs::path& dir) {
  RecordingWriter writer(dir.string(), {Camera("cam", 8, 6)}, "test");
  for (std::uint64_t i = 0; i < 2; ++i) {
    Frame f = RandomFrame(FrameKind::kMask, 8, 6, i);
    f.stamp_ns = 5000 + static_cast<std::int64_t>(i);
    ASSERT_TRUE(writer.Write(0, i, f));
  }
}

// A half-written last index line (a crash while writing) is left out; a bad
// line is an error naming the file and the line.
TEST_F(RecordingTest, CutShortIndexReadsAndBadLinesAreReported) {
  WriteTwoMasks(dir_);
  const fs::path index = dir_ / "frames" / "cam" / "index.csv";
  std::ofstream(index, std::ios::app) << "2,5002,,2,0000";  // No newline: cut short.
  EXPECT_EQ(ReadRecordingCamera(dir_.string(), "cam").frames.size(), 2U);
  std::ofstream(index, std::ios::app) << "02.png\nthree,5003,,3,000003.png\n";
  try {
    (void)ReadRecordingCamera(dir_.string(), "cam");
    FAIL() << "expected a ConfigError";
  } catch (const common::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find(index.string() + ":5: "), std::string::npos) << e.what();
  }
  EXPECT_THROW((void)ReadRecordingCamera(dir_.string(), "nope"), common::ConfigError);
}

// Real time: frame i at its recording time after the clock's start, stamped
// with the clock's epoch plus that time. Fast: every frame at once, in order,
// stamped on delivery.
TEST_F(RecordingTest, ReplaysRecordLayoutInRealTimeAndFast) {
  {
    RecordingWriter writer(dir_.string(), {Camera("cam", 8, 6)}, "test");
    for (std::uint64_t i = 0; i < 5; ++i) {
      Frame f = RandomFrame(FrameKind::kMono, 8, 6, i);
      f.stamp_ns = 9'000'000'000 + static_cast<std::int64_t>(i) * 50'000'000;  // 20 Hz.
      f.index = i;
      ASSERT_TRUE(writer.Write(0, i, f));
    }
  }
  const RecordingCamera rec = ReadRecordingCamera(dir_.string(), "cam");
  {
    const SimClock clock = SimClock::Now();
    ReplaySource source(rec, clock, ReplayPacing::kRealtime);
    Frame f;
    std::vector<std::uint64_t> got;
    for (int tries = 0; tries < 100 && got.size() < 5; ++tries) {
      if (!source.Next(&f, 100ms)) continue;
      EXPECT_EQ(f.stamp_ns, clock.epoch_ns + static_cast<std::int64_t>(f.index) * 50'000'000);
      got.push_back(f.index);
    }
    EXPECT_FALSE(got.empty());
    EXPECT_TRUE(std::is_sorted(got.begin(), got.end()));
    EXPECT_EQ(got.back(), 4U);
    EXPECT_FALSE(source.Next(&f, 50ms)) << "the recording has ended";
  }
  {
    // The clock starts an hour from now: real time would deliver nothing.
    SimClock clock = SimClock::Now();
    clock.start += std::chrono::hours(1);
    ReplaySource source(rec, clock, ReplayPacing::kFast);
    Frame f;
    for (std::uint64_t i = 0; i < 5; ++i) {
      const std::int64_t before = std::chrono::duration_cast<std::chrono::nanoseconds>(
                                      std::chrono::system_clock::now().time_since_epoch())
                                      .count();
      ASSERT_TRUE(source.Next(&f, 10ms));
      EXPECT_EQ(f.index, i);
      EXPECT_GE(f.stamp_ns, before);
    }
    EXPECT_FALSE(source.Next(&f, 10ms));
  }
}

// Five frames at 20 Hz (0 to 200 ms); a loop from 0.1 s plays frames 2, 3, 4
// again and again, each repetition 150 ms later (100 ms from frame 2 to frame
// 4, plus one interval), with frame counters 5 higher per repetition.
class ReplayLoopTest : public RecordingTest {
 protected:
  RecordingCamera Write5() {
    {
      RecordingWriter writer(dir_.string(), {Camera("cam", 8, 6)}, "test");
      for (std::uint64_t i = 0; i < 5; ++i) {
        Frame f = RandomFrame(FrameKind::kMono, 8, 6, i);
        f.stamp_ns = 9'000'000'000 + static_cast<std::int64_t>(i) * 50'000'000;
        f.index = i;
        EXPECT_TRUE(writer.Write(0, i, f));
      }
    }
    return ReadRecordingCamera(dir_.string(), "cam");
  }
  static std::int64_t LoopTimeNs(std::uint64_t index) {
    return static_cast<std::int64_t>(index % 5) * 50'000'000 +
           static_cast<std::int64_t>(index / 5) * 150'000'000;
  }
};

TEST_F(ReplayLoopTest, LoopsFromItsStartWithCaptureTimesGoingOn) {
  const RecordingCamera rec = Write5();
  // As fast as consumed: every frame in play order, the loop's frames again.
  {
    ReplaySource source(
        rec, SimClock::Now(),
        ReplayOptions{.pacing = ReplayPacing::kFast, .loop = true, .loop_start_s = 0.1});
    Frame f;
    std::vector<std::uint64_t> got;
    for (int i = 0; i < 11; ++i) {
      ASSERT_TRUE(source.Next(&f, 10ms));
      got.push_back(f.index);
      EXPECT_EQ(f.grey.pixels, RandomFrame(FrameKind::kMono, 8, 6, f.index % 5).grey.pixels)
          << f.index;
    }
    EXPECT_EQ(got, (std::vector<std::uint64_t>{0, 1, 2, 3, 4, 7, 8, 9, 12, 13, 14}));
  }
  // Real time: stamped with the clock's epoch plus the loop's times, past the
  // recording's end.
  {
    const SimClock clock = SimClock::Now();
    ReplaySource source(rec, clock, ReplayOptions{.loop = true, .loop_start_s = 0.1});
    Frame f;
    std::vector<std::uint64_t> got;
    const auto until = std::chrono::steady_clock::now() + 700ms;
    while (std::chrono::steady_clock::now() < until) {
      if (!source.Next(&f, 50ms)) continue;
      EXPECT_EQ(f.stamp_ns, clock.epoch_ns + LoopTimeNs(f.index)) << f.index;
      EXPECT_TRUE(f.index < 5 || f.index % 5 >= 2) << f.index;
      got.push_back(f.index);
    }
    ASSERT_FALSE(got.empty());
    EXPECT_TRUE(std::is_sorted(got.begin(), got.end()));
    EXPECT_GE(got.back(), 12U) << "700 ms reach the third repetition (from 400 ms)";
  }
}

// Two cameras of one recording, the second of which dropped its last frame:
// with one loop period for both (the longer), each repetition plays their
// frames at the same times again, however many go by.
TEST_F(ReplayLoopTest, CamerasSharingALoopPeriodStayInStep) {
  {
    RecordingWriter writer(dir_.string(), {Camera("a", 8, 6), Camera("b", 8, 6)}, "test");
    for (std::uint64_t i = 0; i < 5; ++i) {
      for (int c = 0; c < 2; ++c) {
        if (c == 1 && i == 4) continue;
        Frame f = RandomFrame(FrameKind::kMono, 8, 6, i);
        f.stamp_ns = 9'000'000'000 + static_cast<std::int64_t>(i) * 50'000'000;
        f.index = i;
        EXPECT_TRUE(writer.Write(c, i, f));
      }
    }
  }
  const RecordingCamera a = ReadRecordingCamera(dir_.string(), "a");
  const RecordingCamera b = ReadRecordingCamera(dir_.string(), "b");
  ASSERT_EQ(b.frames.size(), 4U);
  EXPECT_EQ(LoopLengthNs(a, 0.1), 150'000'000);
  EXPECT_EQ(LoopLengthNs(b, 0.1), 100'000'000);
  const std::int64_t period = std::max(LoopLengthNs(a, 0.1), LoopLengthNs(b, 0.1));
  const SimClock clock = SimClock::Now();
  ReplaySource sa(a, clock,
                  ReplayOptions{.loop = true, .loop_start_s = 0.1, .loop_period_ns = period});
  ReplaySource sb(b, clock,
                  ReplayOptions{.loop = true, .loop_start_s = 0.1, .loop_period_ns = period});
  // Each camera's frames at the recording's times plus whole periods.
  for (auto [source, stride] : {std::pair{&sa, 5U}, std::pair{&sb, 4U}}) {
    Frame f;
    int looped = 0;
    const auto until = std::chrono::steady_clock::now() + 700ms;
    while (std::chrono::steady_clock::now() < until) {
      if (!source->Next(&f, 50ms)) continue;
      const std::uint64_t frame = f.index % stride;
      const std::uint64_t repetition = f.index / stride;
      EXPECT_EQ(f.stamp_ns, clock.epoch_ns + static_cast<std::int64_t>(frame) * 50'000'000 +
                                static_cast<std::int64_t>(repetition) * period)
          << "camera with " << stride << " frames, frame " << f.index;
      looped += repetition >= 2 ? 1 : 0;
    }
    EXPECT_GT(looped, 0) << "700 ms reach the second repetition (from 400 ms)";
  }
  // The camera's own length, never shorter: a shorter period is not taken
  // (its repetitions would overlap, capture times stepping back).
  ReplaySource own(a, clock, ReplayOptions{.loop = true, .loop_start_s = 0.1, .loop_period_ns = 1});
  Frame f;
  int repeated = 0;
  for (const auto until = std::chrono::steady_clock::now() + 1000ms;
       std::chrono::steady_clock::now() < until && repeated < 3;) {
    if (!own.Next(&f, 50ms) || f.index < 5) continue;
    EXPECT_EQ(f.stamp_ns, clock.epoch_ns + static_cast<std::int64_t>(f.index % 5) * 50'000'000 +
                              static_cast<std::int64_t>(f.index / 5) * LoopLengthNs(a, 0.1))
        << "frame " << f.index;
    ++repeated;
  }
  EXPECT_EQ(repeated, 3);
}

// Capture times that step back (a host clock set back while recording) can
// leave a loop with no length: refused, rather than a capture thread spinning
// for ever on frames that are always due.
TEST_F(ReplayLoopTest, ALoopWhoseTimesStepBackIsRefused) {
  {
    RecordingWriter writer(dir_.string(), {Camera("cam", 8, 6)}, "test");
    for (std::uint64_t i = 0; i < 5; ++i) {
      Frame f = RandomFrame(FrameKind::kMono, 8, 6, i);
      f.stamp_ns =
          9'000'000'000 + (i < 3 ? static_cast<std::int64_t>(i) * 50'000'000 : -500'000'000);
      f.index = i;
      EXPECT_TRUE(writer.Write(0, i, f));
    }
  }
  const RecordingCamera rec = ReadRecordingCamera(dir_.string(), "cam");
  try {
    (void)ReplaySource(rec, SimClock::Now(), ReplayOptions{.loop = true, .loop_start_s = 0.0});
    ADD_FAILURE() << "no error";
  } catch (const common::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("stepped back"), std::string::npos) << e.what();
  }
  EXPECT_NO_THROW(ReplaySource(rec, SimClock::Now(), ReplayOptions{}));
}

TEST_F(ReplayLoopTest, PreloadedFramesNeedNoFilesAndUnreadableOnesCountEachTime) {
  RecordingCamera rec = Write5();
  // Frame 3 is garbage on disk.
  std::ofstream(dir_ / rec.frames[3].file, std::ios::trunc) << "not an image";
  ReplaySource source(
      rec, SimClock::Now(),
      ReplayOptions{
          .pacing = ReplayPacing::kFast, .preload = true, .loop = true, .loop_start_s = 0.1});
  EXPECT_EQ(source.preloaded_bytes(), 4U * 8 * 6);
  fs::remove_all(dir_);  // Played from memory from here on.
  Frame f;
  std::vector<std::uint64_t> got;
  for (int i = 0; i < 8; ++i) {
    if (!source.Next(&f, 10ms)) continue;
    EXPECT_EQ(f.grey.pixels, RandomFrame(FrameKind::kMono, 8, 6, f.index % 5).grey.pixels);
    got.push_back(f.index);
  }
  // Play order 0 1 2 [3] 4 7 [8] 9: the unreadable frame, twice.
  EXPECT_EQ(got, (std::vector<std::uint64_t>{0, 1, 2, 4, 7, 9}));
  EXPECT_EQ(source.corrupt_frames(), 2U);
}

TEST_F(ReplayLoopTest, ALoopOfFewerThanTwoFramesIsRefused) {
  const RecordingCamera rec = Write5();
  EXPECT_THROW(ReplaySource(rec, SimClock::Now(), ReplayOptions{.loop = true, .loop_start_s = 0.2}),
               common::ConfigError);
  // Without loop the start is not looked at; a loop from frame 3 is fine.
  EXPECT_NO_THROW(ReplaySource(rec, SimClock::Now(), ReplayOptions{.loop_start_s = 9.0}));
  EXPECT_NO_THROW(
      ReplaySource(rec, SimClock::Now(), ReplayOptions{.loop = true, .loop_start_s = 0.15}));
}

// The synth layout's frame times: i / rate_hz plus the camera's offset, the
// instant the simulator rendered (`hullguard replay` digests depend on them).
// A negative offset is a frame taken earlier, never a period later.
TEST_F(RecordingTest, ReadsTheSynthLayout) {
  fs::create_directories(dir_ / "masks" / "a");
  std::ofstream(dir_ / "manifest.yaml")
      << "synth: {format: 1, scene: t, rate_hz: 30, start_s: 0, frames: 3, masks: true, "
         "colour: false}\ncameras:\n  - {name: a, time_offset_s: 0.04}\n  - {name: b, "
         "time_offset_s: -0.006}\n";
  silhouette::WriteGreyImage((dir_ / "masks" / "a" / "000001.png").string(),
                             common::ImageU8(6, 4, 255));
  const RecordingCamera rec = ReadRecordingCamera(dir_.string(), "a");
  EXPECT_EQ(rec.layout, RecordingLayout::kSynth);
  EXPECT_EQ(rec.kind, FrameKind::kMask);
  ASSERT_EQ(rec.frames.size(), 3U);
  const RecordingCamera early = ReadRecordingCamera(dir_.string(), "b");
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(rec.frames[i].time_ns,
              std::chrono::duration_cast<std::chrono::nanoseconds>(
                  std::chrono::duration<double>(i / 30.0) + std::chrono::duration<double>(0.04))
                  .count());
    EXPECT_NEAR(static_cast<double>(early.frames[i].time_ns), (i / 30.0 - 0.006) * 1e9, 1.0);
  }
  EXPECT_EQ(rec.frames[1].file, "masks/a/000001.png");
  ReplaySource source(rec, SimClock{});
  Frame f;
  EXPECT_FALSE(source.ReadFrame(0, &f));  // Missing file.
  ASSERT_TRUE(source.ReadFrame(1, &f));
  EXPECT_EQ(f.grey.width, 6);
  EXPECT_EQ(f.stamp_ns, rec.frames[1].time_ns);
  EXPECT_EQ(RecordingCameraNames(dir_.string()), (std::vector<std::string>{"a", "b"}));
}

// Frames that are no 8-bit image of the camera are unreadable, counted as
// such: a 16-bit mask (a plain 8-bit decode would scale its 255 to 0, and the
// foreground would read as background) and a folder where a frame should be.
TEST_F(RecordingTest, SixteenBitAndFolderFramesAreUnreadable) {
  fs::create_directories(dir_ / "masks" / "a");
  std::ofstream(dir_ / "manifest.yaml")
      << "synth: {format: 1, scene: t, rate_hz: 30, start_s: 0, frames: 3, masks: true, "
         "colour: false}\ncameras:\n  - {name: a}\n";
  {
    std::ofstream pgm(dir_ / "masks" / "a" / "000000.png", std::ios::binary);
    pgm << "P5\n6 4\n65535\n";  // A 16-bit PGM, all 255, under a frame's name.
    for (int i = 0; i < 6 * 4; ++i) pgm << '\0' << '\xff';
  }
  fs::create_directories(dir_ / "masks" / "a" / "000001.png");
  silhouette::WriteGreyImage((dir_ / "masks" / "a" / "000002.png").string(),
                             common::ImageU8(6, 4, 255));
  const RecordingCamera rec = ReadRecordingCamera(dir_.string(), "a");
  ReplaySource source(rec, SimClock{});
  Frame f;
  EXPECT_FALSE(source.ReadFrame(0, &f));
  EXPECT_FALSE(source.ReadFrame(1, &f));
  ASSERT_TRUE(source.ReadFrame(2, &f));
  EXPECT_EQ(f.grey.pixels, std::vector<std::uint8_t>(6 * 4, 255));
}

// A binary PGM mask with a maxval below 255 is scaled (a 0/1 mask, maxval 1,
// decodes as raw 0/1: all background, every person free), as in hullguard carve.
TEST_F(RecordingTest, PgmMasksWithASmallMaxvalAreScaled) {
  fs::create_directories(dir_ / "masks" / "a");
  std::ofstream(dir_ / "manifest.yaml")
      << "synth: {format: 1, scene: t, rate_hz: 30, start_s: 0, frames: 1, masks: true, "
         "colour: false}\ncameras:\n  - {name: a}\n";
  std::ofstream(dir_ / "masks" / "a" / "000000.png", std::ios::binary)
      << "P5\n6 4\n1\n"
      << std::string(12, '\1') << std::string(12, '\0');
  ReplaySource source(ReadRecordingCamera(dir_.string(), "a"), SimClock{});
  Frame f;
  ASSERT_TRUE(source.ReadFrame(0, &f));
  std::vector<std::uint8_t> expected(6 * 4, 0);
  std::fill(expected.begin(), expected.begin() + 12, 255);
  EXPECT_EQ(f.grey.pixels, expected);
}

// A mask frame with transparent pixels (an alpha channel, which the grey
// decode drops: a keyed-out background would read as drawn) is unreadable;
// so is an opaque RGBA one: a colour image is no mask.
TEST_F(RecordingTest, MaskFramesWithTransparentPixelsAreUnreadable) {
  fs::create_directories(dir_ / "masks" / "a");
  std::ofstream(dir_ / "manifest.yaml")
      << "synth: {format: 1, scene: t, rate_hz: 30, start_s: 0, frames: 2, masks: true, "
         "colour: false}\ncameras:\n  - {name: a}\n";
  cv::Mat rgba(4, 6, CV_8UC4, cv::Scalar(0, 0, 0, 0));
  rgba(cv::Rect(1, 1, 3, 2)).setTo(cv::Scalar(255, 255, 255, 255));
  ASSERT_TRUE(cv::imwrite((dir_ / "masks" / "a" / "000000.png").string(), rgba));
  ASSERT_TRUE(cv::imwrite((dir_ / "masks" / "a" / "000001.png").string(),
                          cv::Mat(4, 6, CV_8UC4, cv::Scalar(255, 255, 255, 255))));
  ReplaySource source(ReadRecordingCamera(dir_.string(), "a"), SimClock{});
  Frame f;
  EXPECT_FALSE(source.ReadFrame(0, &f));
  EXPECT_FALSE(source.ReadFrame(1, &f));
}

// A frame must be of its camera's kind: a colour image where a mask or a
// grey image should be (a grey decode would make a mask of a camera image, a
// person darker than the threshold free) is unreadable, and so is a grey
// image for a colour camera; the frames of the right kind read.
TEST_F(RecordingTest, FramesOfAnotherColourKindAreUnreadable) {
  fs::create_directories(dir_ / "masks" / "a");
  fs::create_directories(dir_ / "colour" / "a");
  const cv::Mat grey(4, 6, CV_8UC1, cv::Scalar(255));
  const cv::Mat colour(4, 6, CV_8UC3, cv::Scalar(40, 90, 200));
  for (const char* folder : {"masks", "colour"}) {
    ASSERT_TRUE(cv::imwrite((dir_ / folder / "a" / "000000.png").string(), grey));
    ASSERT_TRUE(cv::imwrite((dir_ / folder / "a" / "000001.png").string(), colour));
  }
  for (const bool masks : {true, false}) {
    std::ofstream(dir_ / "manifest.yaml")
        << "synth: {format: 1, scene: t, rate_hz: 30, start_s: 0, frames: 2, masks: "
        << (masks ? "true" : "false") << ", colour: " << (masks ? "false" : "true")
        << "}\ncameras:\n  - {name: a}\n";
    ReplaySource source(ReadRecordingCamera(dir_.string(), "a"), SimClock{});
    Frame f;
    EXPECT_EQ(source.ReadFrame(0, &f), masks) << "grey, masks " << masks;
    EXPECT_EQ(source.ReadFrame(1, &f), !masks) << "colour, masks " << masks;
  }
}

// A colour frame whose pixels index past its palette decodes as black
// without a word: unreadable, as a damaged one. One within it reads.
TEST_F(RecordingTest, PaletteFramesIndexingPastThePaletteAreUnreadable) {
  fs::create_directories(dir_ / "colour" / "a");
  std::ofstream(dir_ / "colour" / "a" / "000000.png", std::ios::binary)
      << testing::PalettePng(6, 4, 1);
  std::ofstream(dir_ / "colour" / "a" / "000001.png", std::ios::binary)
      << testing::PalettePng(6, 4, 200);
  std::ofstream(dir_ / "colour" / "a" / "000002.png", std::ios::binary)
      << testing::PaletteBmp(6, 4, 200);
  std::ofstream(dir_ / "manifest.yaml")
      << "synth: {format: 1, scene: t, rate_hz: 30, start_s: 0, frames: 3, masks: false, "
         "colour: true}\ncameras:\n  - {name: a}\n";
  ReplaySource source(ReadRecordingCamera(dir_.string(), "a"), SimClock{});
  Frame f;
  ASSERT_TRUE(source.ReadFrame(0, &f));
  EXPECT_EQ(f.rgb.pixels, std::vector<std::uint8_t>(6 * 4 * 3, 255));
  EXPECT_FALSE(source.ReadFrame(1, &f));
  EXPECT_FALSE(source.ReadFrame(2, &f));
}

// A frame file of a few bytes whose header states a huge image is refused
// before decoding (a decoder would allocate what it states: 1 GiB here, or
// abort the daemon on an allocation failure), and so is one of another size
// than the recording states; a named pipe in place of a frame is refused
// at once instead of blocking the read until someone writes into it.
TEST_F(RecordingTest, HugeHeadersAndPipesAreRefusedBeforeReading) {
  fs::create_directories(dir_ / "masks" / "a");
  std::ofstream(dir_ / "manifest.yaml")
      << "synth: {format: 1, scene: t, rate_hz: 30, start_s: 0, frames: 4, masks: true, "
         "colour: false}\ncameras:\n  - {name: a}\n";
  // A whole, valid PNG of 32768 x 32768 grey pixels (IHDR, an empty IDAT, IEND).
  const auto chunk = [](const std::string& type, const std::string& data) {
    std::string c;
    for (int shift = 24; shift >= 0; shift -= 8) c += static_cast<char>(data.size() >> shift);
    c += type + data + std::string(4, '\0');  // The CRC is not checked before decoding.
    return c;
  };
  const std::string ihdr = std::string("\0\0\x80\0\0\0\x80\0", 8) + std::string("\x08\0\0\0\0", 5);
  std::ofstream(dir_ / "masks" / "a" / "000000.png", std::ios::binary)
      << "\x89PNG\r\n\x1a\n"
      << chunk("IHDR", ihdr) << chunk("IDAT", "")
      << std::string("\0\0\0\0IEND\xae\x42\x60\x82", 12);
  // A JPEG and a PGM stating 60000 x 60000.
  std::ofstream(dir_ / "masks" / "a" / "000001.png", std::ios::binary)
      << std::string("\xff\xd8\xff\xc0\0\x0b\x08\xea\x60\xea\x60\x01\x01\x11\0\xff\xd9", 17);
  std::ofstream(dir_ / "masks" / "a" / "000002.png", std::ios::binary) << "P5\n60000 60000\n255\n"
                                                                       << std::string(16, '\0');
  ASSERT_EQ(::mkfifo((dir_ / "masks" / "a" / "000003.png").c_str(), 0600), 0);
  RecordingCamera rec = ReadRecordingCamera(dir_.string(), "a");
  Frame f;
  std::vector<unsigned char> bytes;
  std::string path;
  for (std::size_t i = 0; i < 4; ++i)
    EXPECT_FALSE(LoadRecordedFrame(rec, i, &f, &bytes, &path)) << i;
  EXPECT_LT(bytes.capacity(), 4096U) << "read only the few bytes of the files";
  // A stated size (record layout) refuses a frame of another size.
  ASSERT_TRUE(cv::imwrite((dir_ / "masks" / "a" / "000000.png").string(),
                          cv::Mat(4, 6, CV_8UC1, cv::Scalar(255))));
  EXPECT_TRUE(LoadRecordedFrame(rec, 0, &f, &bytes, &path));
  rec.width = 6;
  rec.height = 5;
  EXPECT_FALSE(LoadRecordedFrame(rec, 0, &f, &bytes, &path));
  // A pipe for the manifest is an error naming it, not a read that blocks.
  fs::remove(dir_ / "manifest.yaml");
  ASSERT_EQ(::mkfifo((dir_ / "manifest.yaml").c_str(), 0600), 0);
  try {
    (void)ReadRecordingCamera(dir_.string(), "a");
    ADD_FAILURE() << "expected a ConfigError";
  } catch (const common::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("manifest.yaml"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("not a regular file"), std::string::npos) << e.what();
  }
}

// A synth manifest claiming more frame sets than any recording holds is an
// error naming the file, not an allocation of gigabytes.
TEST_F(RecordingTest, ASynthManifestOfBillionsOfFramesIsRefused) {
  fs::create_directories(dir_ / "masks" / "a");
  std::ofstream(dir_ / "manifest.yaml")
      << "synth: {format: 1, scene: t, rate_hz: 30, start_s: 0, frames: 2000000000, masks: true, "
         "colour: false}\ncameras:\n  - {name: a}\n";
  try {
    (void)ReadRecordingCamera(dir_.string(), "a");
    ADD_FAILURE() << "expected a ConfigError";
  } catch (const common::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("manifest.yaml:1"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("1 <= frames <= 1000000"), std::string::npos) << e.what();
  }
}

// A mask frame in Sun raster, which OpenCV decodes as all zeros when 8-bit
// grey (the person read as background), is unreadable; the same frame as PNG
// reads as written.
TEST_F(RecordingTest, SunRasterFramesAreUnreadable) {
  fs::create_directories(dir_ / "masks" / "a");
  std::ofstream(dir_ / "manifest.yaml")
      << "synth: {format: 1, scene: t, rate_hz: 30, start_s: 0, frames: 2, masks: true, "
         "colour: false}\ncameras:\n  - {name: a}\n";
  const cv::Mat all(4, 6, CV_8UC1, cv::Scalar(255));
  ASSERT_TRUE(cv::imwrite((dir_ / "masks" / "a" / "000000.ras").string(), all));
  fs::rename(dir_ / "masks" / "a" / "000000.ras", dir_ / "masks" / "a" / "000000.png");
  ASSERT_TRUE(cv::imwrite((dir_ / "masks" / "a" / "000001.png").string(), all));
  ReplaySource source(ReadRecordingCamera(dir_.string(), "a"), SimClock{});
  Frame f;
  EXPECT_FALSE(source.ReadFrame(0, &f));
  ASSERT_TRUE(source.ReadFrame(1, &f));
  EXPECT_EQ(f.grey.pixels, std::vector<std::uint8_t>(6 * 4, 255));
}

// A frame file cut short (a disk full while recording, a copy interrupted) is
// unreadable, whatever its format, and is refused before a decoder sees it:
// libjpeg would fill the missing rows with grey and call it a frame, and libpng
// prints its complaint on stderr, where the daemon's log would carry it once per
// frame read.
TEST_F(RecordingTest, FramesCutShortAreUnreadableAndQuiet) {
  const fs::path frames = dir_ / "masks" / "a";
  fs::create_directories(frames);
  constexpr int kFrames = 9;
  std::ofstream(dir_ / "manifest.yaml")
      << "synth: {format: 1, scene: t, rate_hz: 30, start_s: 0, frames: " << kFrames
      << ", masks: true, colour: false}\ncameras:\n  - {name: a}\n";
  common::ImageU8 image(64, 48, 0);
  for (int v = 0; v < image.height; ++v) {
    for (int u = 0; u < image.width; ++u) image.At(u, v) = static_cast<std::uint8_t>(u * v);
  }
  const cv::Mat mat(image.height, image.width, CV_8UC1, image.pixels.data());
  // Writes frame `index` encoded as `extension`, less its last `cut` bytes
  // (kHalf: less half of them).
  constexpr int kHalf = -1;
  auto write = [&](int index, const char* extension, int cut) {
    std::vector<unsigned char> bytes;
    ASSERT_TRUE(cv::imencode(extension, mat, bytes));
    bytes.resize(bytes.size() - (cut == kHalf ? bytes.size() / 2 : static_cast<std::size_t>(cut)));
    char name[16];
    std::snprintf(name, sizeof(name), "%06d.png", index);  // The synth layout's names.
    std::ofstream(frames / name, std::ios::binary)
        .write(reinterpret_cast<const char*>(bytes.data()),
               static_cast<std::streamsize>(bytes.size()));
  };
  // Whole frames in three formats, then each cut: by its trailer only and by
  // half of it.
  write(0, ".png", 0);
  write(1, ".pgm", 0);
  write(2, ".jpg", 0);
  write(3, ".png", 12);  // Without the IEND chunk.
  write(4, ".png", kHalf);
  write(5, ".pgm", 1);
  write(6, ".jpg", 2);  // Without the end-of-image marker.
  write(7, ".jpg", kHalf);
  {  // A whole JPEG with zero padding after its end marker, as some writers leave.
    std::vector<unsigned char> bytes;
    ASSERT_TRUE(cv::imencode(".jpg", mat, bytes));
    bytes.resize(bytes.size() + 16, 0);
    std::ofstream(frames / "000008.png", std::ios::binary)
        .write(reinterpret_cast<const char*>(bytes.data()),
               static_cast<std::streamsize>(bytes.size()));
  }
  const RecordingCamera rec = ReadRecordingCamera(dir_.string(), "a");
  ReplaySource source(rec, SimClock{});
  Frame f;
  ::testing::internal::CaptureStderr();
  std::vector<bool> read;
  for (int i = 0; i < kFrames; ++i) read.push_back(source.ReadFrame(i, &f));
  const std::string printed = ::testing::internal::GetCapturedStderr();
  EXPECT_EQ(read, (std::vector<bool>{true, true, true, false, false, false, false, false, true}));
  EXPECT_EQ(printed, "");
}

// Numbers of a manifest or an index that would put frames at meaningless
// times are errors naming the file and the line.
TEST_F(RecordingTest, MeaninglessRatesOffsetsAndStampsAreRefused) {
  auto synth = [&](const std::string& rate, const std::string& offset) {
    fs::remove_all(dir_);
    fs::create_directories(dir_ / "masks" / "a");
    std::ofstream(dir_ / "manifest.yaml")
        << "synth: {format: 1, scene: t, rate_hz: " << rate
        << ", start_s: 0, frames: 3, masks: true, colour: false}\ncameras:\n  - {name: a, "
           "time_offset_s: "
        << offset << "}\n";
    try {
      (void)ReadRecordingCamera(dir_.string(), "a");
      return std::string();
    } catch (const common::ConfigError& e) {
      return std::string(e.what());
    }
  };
  EXPECT_EQ(synth("30", "0.01"), "");
  for (const char* rate : {".inf", ".nan", "0", "1e6", "1e-300", "0.09"}) {
    EXPECT_NE(synth(rate, "0").find("manifest.yaml:1: synth: needs 0.1 <= rate_hz <= 1000"),
              std::string::npos)
        << rate;
  }
  for (const char* offset : {".nan", ".inf", "1e30", "abc"}) {
    EXPECT_NE(synth("30", offset).find("manifest.yaml:3: time_offset_s:"), std::string::npos)
        << offset << ": " << synth("30", offset);
  }

  fs::remove_all(dir_);
  WriteTwoMasks(dir_);
  const fs::path index = dir_ / "frames" / "cam" / "index.csv";
  const std::string good = [&] {
    std::ifstream in(index);
    return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  }();
  for (const std::string& line :
       {std::string("2,9223372036854775807,,2,000002.png\n"), std::string("2,0,,2,000002.png\n"),
        std::string("2,-5,,2,000002.png\n")}) {
    std::ofstream(index, std::ios::trunc) << good << line;
    try {
      (void)ReadRecordingCamera(dir_.string(), "cam");
      ADD_FAILURE() << "accepted " << line;
    } catch (const common::ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find(index.string() + ":4: stamp_ns"), std::string::npos)
          << e.what();
    }
  }
}

}  // namespace
}  // namespace hg::capture
