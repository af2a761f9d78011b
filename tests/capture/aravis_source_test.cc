// The `aravis` source against real GigE Vision implementations on 127.0.0.1:
// Aravis' fake camera inside the test process (serving known images through a
// fill callback) and the arv-fake-gv-camera-0.8 program as a child process
// (killed and restarted). Run through tests/publish/in_netns.sh: a private
// network namespace with only loopback, where broadcast discovery on lo finds
// the fake cameras and nothing leaves the machine.
#include <arv.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <new>
#include <optional>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "capture/aravis_source.h"
#include "support/allocation_counter.h"

namespace hg::capture {
namespace {

using Clock = std::chrono::steady_clock;
using std::chrono::milliseconds;
using Pixel = AravisOptions::Pixel;

constexpr int kSensor = 2048;  // The fake camera's sensor is 2048 x 2048.

// Colours of the Bayer mosaic the fake camera serves: every red site holds
// kRed, and so on, so a correct demosaic gives exactly this colour inside.
constexpr std::uint8_t kRed = 200;
constexpr std::uint8_t kGreen = 100;
constexpr std::uint8_t kBlue = 50;

std::int64_t RealtimeNowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

// Mono8 value (and red of RGB8) of pixel (u, v) in the frame with offset k.
std::uint8_t Ramp(int u, int v, int k) { return static_cast<std::uint8_t>(u + 3 * v + k); }

// Aravis' fake GigE Vision camera, in this process, on 127.0.0.1.
class InProcessCamera {
 public:
  explicit InProcessCamera(const char* serial)
      : camera_(arv_gv_fake_camera_new("127.0.0.1", serial)) {
    fake_ = arv_gv_fake_camera_get_fake_camera(camera_);
    arv_fake_camera_set_fill_pattern(fake_, &InProcessCamera::Fill, this);
  }
  ~InProcessCamera() { g_object_unref(camera_); }
  InProcessCamera(const InProcessCamera&) = delete;
  InProcessCamera& operator=(const InProcessCamera&) = delete;

  [[nodiscard]] bool running() const { return arv_gv_fake_camera_is_running(camera_); }
  [[nodiscard]] ArvFakeCamera* fake() const { return fake_; }

 private:
  // Runs on the fake camera's stream thread for every frame it sends. The
  // buffer was allocated for the full payload, and the fake camera has set
  // the image's width, height and pixel format.
  static void Fill(ArvBuffer* buffer, void* self, guint32 /*exposure_us*/, guint32 /*gain*/,
                   ArvPixelFormat format) {
    auto* camera = static_cast<InProcessCamera*>(self);
    const int k = camera->frames_.fetch_add(1);
    const int w = arv_buffer_get_image_width(buffer);
    const int h = arv_buffer_get_image_height(buffer);
    auto* data =
        static_cast<std::uint8_t*>(const_cast<void*>(arv_buffer_get_data(buffer, nullptr)));
    // Site colours of the 2x2 Bayer block at the origin, row-major.
    auto block = [](ArvPixelFormat f) -> std::array<std::uint8_t, 4> {
      if (f == ARV_PIXEL_FORMAT_BAYER_RG_8) return {kRed, kGreen, kGreen, kBlue};
      if (f == ARV_PIXEL_FORMAT_BAYER_GB_8) return {kGreen, kBlue, kRed, kGreen};
      if (f == ARV_PIXEL_FORMAT_BAYER_GR_8) return {kGreen, kRed, kBlue, kGreen};
      return {kBlue, kGreen, kGreen, kRed};  // BayerBG8
    };
    for (int v = 0; v < h; ++v) {
      for (int u = 0; u < w; ++u) {
        const std::size_t i = static_cast<std::size_t>(v) * w + u;
        if (format == ARV_PIXEL_FORMAT_MONO_8) {
          data[i] = Ramp(u, v, k);
        } else if (format == ARV_PIXEL_FORMAT_RGB_8_PACKED) {
          data[3 * i] = Ramp(u, v, k);
          data[3 * i + 1] = static_cast<std::uint8_t>(255 - Ramp(u, v, k));
          data[3 * i + 2] = 77;
        } else {
          data[i] = block(format)[(v % 2) * 2 + (u % 2)];
        }
      }
    }
  }

  ArvGvFakeCamera* camera_;
  ArvFakeCamera* fake_;
  std::atomic<int> frames_{0};
};

// arv-fake-gv-camera-0.8 as a child process.
class CameraProcess {
 public:
  explicit CameraProcess(const char* serial) {
    pid_ = fork();
    if (pid_ == 0) {
      execl(HG_ARV_FAKE_GV_CAMERA, HG_ARV_FAKE_GV_CAMERA, "-i", "127.0.0.1", "-s", serial,
            static_cast<char*>(nullptr));
      _exit(127);
    }
  }
  ~CameraProcess() { Kill(); }
  CameraProcess(const CameraProcess&) = delete;
  CameraProcess& operator=(const CameraProcess&) = delete;

  [[nodiscard]] bool started() const { return pid_ > 0; }
  // SIGSTOP: the camera stops answering (a pulled cable) but its process
  // stays; Kill() still ends it.
  void Pause() {
    if (pid_ > 0) kill(pid_, SIGSTOP);
  }
  // SIGKILL: the camera vanishes as with a pulled cable, without a goodbye.
  void Kill() {
    if (pid_ <= 0) return;
    kill(pid_, SIGKILL);
    waitpid(pid_, nullptr, 0);
    pid_ = -1;
  }

 private:
  pid_t pid_ = -1;
};

// Calls Next() until it delivers a frame or `limit` passes.
bool NextWithin(AravisSource* source, Frame* frame, milliseconds limit) {
  const Clock::time_point end = Clock::now() + limit;
  while (Clock::now() < end) {
    if (source->Next(frame, milliseconds(50))) return true;
  }
  return false;
}

AravisOptions FakeOptions(const std::string& device, Pixel pixel) {
  AravisOptions o;
  o.device = device;
  o.pixel_format = pixel;
  o.frame_rate_hz = 10.0;
  o.width = kSensor;
  o.height = kSensor;
  // Generous for a loaded machine: a 12 MB RGB8 frame through loopback
  // takes a while. The watchdog tests set their own.
  o.frame_timeout = milliseconds(1000);
  return o;
}

TEST(AravisSourceTest, DeliversKnownMonoImagesWithIncreasingStamps) {
  InProcessCamera camera("HGMONO");
  ASSERT_TRUE(camera.running()) << "cannot serve a fake camera on 127.0.0.1:3956";
  // Selected by serial number: found by broadcast discovery on lo.
  AravisOptions options = FakeOptions("HGMONO", Pixel::kMono8);
  options.socket_buffer_bytes = 8 << 20;
  options.packet_size = 8000;  // Loopback's MTU is 64 KiB: "jumbo" packets pass.
  AravisSource source(options);
  Frame frame;
  ASSERT_TRUE(NextWithin(&source, &frame, milliseconds(15000)));
  std::int64_t last_stamp = 0;
  std::int64_t last_device_stamp = -1;
  int last_offset = -1;
  std::uint64_t last_index = 0;
  long allocations = 0;
  for (int n = 0; n < 6; ++n) {
    if (n > 0) {
      // Counted on this thread only (Aravis' and the fake camera's own threads
      // allocate as they please), from the steady state on: the frame's
      // buffers exist.
      const bool got = [&] {
        const hg::testing::AllocationCounter counter(
            hg::testing::AllocationCounter::Threads::kThis);
        const bool ok = NextWithin(&source, &frame, milliseconds(5000));
        if (n >= 2) allocations += counter.count();
        return ok;
      }();
      ASSERT_TRUE(got) << "frame " << n;
    }
    ASSERT_EQ(frame.kind, FrameKind::kMono);
    ASSERT_EQ(frame.grey.width, kSensor);
    ASSERT_EQ(frame.grey.height, kSensor);
    ASSERT_EQ(frame.grey.pixels.size(), std::size_t{kSensor} * kSensor);
    const int k = frame.grey.At(0, 0);
    int wrong = 0;
    for (int v = 0; v < kSensor; ++v) {
      for (int u = 0; u < kSensor; ++u) wrong += frame.grey.At(u, v) != Ramp(u, v, k);
    }
    EXPECT_EQ(wrong, 0) << "frame " << n;
    // Frames follow each other (newest wins, so some may be skipped).
    EXPECT_GT(k, last_offset);
    EXPECT_GT(frame.stamp_ns, last_stamp);
    // Stamped before it was delivered (at or before the end of exposure).
    EXPECT_LE(frame.stamp_ns, RealtimeNowNs());
    // The camera's own timestamp is kept, and it advances too.
    EXPECT_GT(frame.device_stamp_ns, last_device_stamp) << "frame " << n;
    last_device_stamp = frame.device_stamp_ns;
    if (n > 0) {
      EXPECT_GT(frame.index, last_index);
    }
    last_offset = k;
    last_stamp = frame.stamp_ns;
    last_index = frame.index;
  }
  EXPECT_EQ(allocations, 0) << "Next() allocated in steady state";
  const AravisSource::Stats stats = source.stats();
  EXPECT_TRUE(stats.connected);
  EXPECT_GE(stats.completed, 6u);
  EXPECT_EQ(stats.reconnects, 0u);
}

// The thread that calls Next() held up for longer than the frame timeout (a
// loaded machine) finds the frames that arrived meanwhile: the camera is not
// lost, and no reconnection follows.
TEST(AravisSourceTest, ACallerHeldUpPastTheTimeoutTakesTheFramesThatArrived) {
  InProcessCamera camera("HGLATE");
  ASSERT_TRUE(camera.running()) << "cannot serve a fake camera on 127.0.0.1:3956";
  AravisOptions options = FakeOptions("HGLATE", Pixel::kMono8);
  options.frame_timeout = milliseconds(400);
  AravisSource source(options);
  Frame frame;
  ASSERT_TRUE(NextWithin(&source, &frame, milliseconds(15000)));
  const std::int64_t first = frame.stamp_ns;
  for (int late = 0; late < 3; ++late) {
    std::this_thread::sleep_for(milliseconds(900));
    ASSERT_TRUE(source.Next(&frame, milliseconds(0))) << "held up " << late;
    EXPECT_GT(frame.stamp_ns, first);
  }
  const AravisSource::Stats stats = source.stats();
  EXPECT_TRUE(stats.connected);
  EXPECT_EQ(stats.reconnects, 0u);
}

TEST(AravisSourceTest, ConvertsRgbAndEveryBayerPattern) {
  InProcessCamera camera("HGCOLOUR");
  ASSERT_TRUE(camera.running());
  std::mt19937_64 rng(20240611);
  std::uniform_int_distribution<int> coord(2, kSensor - 3);  // Demosaic borders aside.
  for (const Pixel pixel :
       {Pixel::kRGB8, Pixel::kBayerRG8, Pixel::kBayerGB8, Pixel::kBayerGR8, Pixel::kBayerBG8}) {
    SCOPED_TRACE(static_cast<int>(pixel));
    // Opened by address: no discovery needed.
    AravisOptions options = FakeOptions("127.0.0.1", pixel);
    options.debayer = true;
    AravisSource source(options);
    Frame frame;
    // The first frame may still have been filled in the previous format.
    ASSERT_TRUE(NextWithin(&source, &frame, milliseconds(15000)));
    long allocations = 0;
    for (int n = 0; n < 3; ++n) {
      const bool got = [&] {
        const hg::testing::AllocationCounter counter(
            hg::testing::AllocationCounter::Threads::kThis);
        const bool ok = NextWithin(&source, &frame, milliseconds(5000));
        if (n > 0) allocations += counter.count();
        return ok;
      }();
      ASSERT_TRUE(got);
      ASSERT_EQ(frame.kind, FrameKind::kRgb);
      ASSERT_EQ(frame.rgb.width, kSensor);
      ASSERT_EQ(frame.rgb.height, kSensor);
      const int k = frame.rgb.Pixel(0, 0)[0];
      int wrong = 0;
      for (int s = 0; s < 5000; ++s) {
        const int u = coord(rng);
        const int v = coord(rng);
        const std::uint8_t* p = frame.rgb.Pixel(u, v);
        if (pixel == Pixel::kRGB8) {
          const std::uint8_t r = Ramp(u, v, k);
          wrong += p[0] != r || p[1] != 255 - r || p[2] != 77;
        } else {
          wrong += p[0] != kRed || p[1] != kGreen || p[2] != kBlue;
        }
      }
      EXPECT_EQ(wrong, 0) << "frame " << n;
    }
    EXPECT_EQ(allocations, 0) << "Next() allocated in steady state";
  }
}

// Without `debayer` (the default) a Bayer mosaic arrives as it was sent, one
// byte per photosite, for the background model to compare site by site.
TEST(AravisSourceTest, PassesBayerMosaicsOnRaw) {
  InProcessCamera camera("HGMOSAIC");
  ASSERT_TRUE(camera.running());
  for (const Pixel pixel : {Pixel::kBayerRG8, Pixel::kBayerBG8}) {
    SCOPED_TRACE(static_cast<int>(pixel));
    AravisSource source(FakeOptions("127.0.0.1", pixel));
    Frame frame;
    // The first frame may still have been filled in the previous format.
    ASSERT_TRUE(NextWithin(&source, &frame, milliseconds(15000)));
    ASSERT_TRUE(NextWithin(&source, &frame, milliseconds(5000)));
    ASSERT_EQ(frame.kind, FrameKind::kMono);
    ASSERT_EQ(frame.grey.width, kSensor);
    ASSERT_EQ(frame.grey.height, kSensor);
    // Row-major sites of the 2x2 block at the origin.
    const std::array<std::uint8_t, 4> block =
        pixel == Pixel::kBayerRG8 ? std::array<std::uint8_t, 4>{kRed, kGreen, kGreen, kBlue}
                                  : std::array<std::uint8_t, 4>{kBlue, kGreen, kGreen, kRed};
    long wrong = 0;
    for (int v = 0; v < kSensor; ++v) {
      for (int u = 0; u < kSensor; ++u) wrong += frame.grey.At(u, v) != block[(v % 2) * 2 + u % 2];
    }
    EXPECT_EQ(wrong, 0);
  }
}

TEST(AravisSourceTest, WrongSizeFramesAreCorruptAndTheSourceRecovers) {
  InProcessCamera camera("HGSIZE");
  ASSERT_TRUE(camera.running());
  AravisOptions options = FakeOptions("127.0.0.1", Pixel::kMono8);
  options.frame_timeout = milliseconds(300);
  AravisSource source(options);
  Frame frame;
  ASSERT_TRUE(NextWithin(&source, &frame, milliseconds(15000)));
  ASSERT_EQ(source.corrupt_frames(), 0u);
  // Another application narrows the image behind the source's back.
  ASSERT_TRUE(arv_fake_camera_write_register(camera.fake(), ARV_FAKE_CAMERA_REGISTER_WIDTH, 1024));
  // Frames of 1024 x 2048 are refused; with no good frame the watchdog calls
  // the connection lost, and reopening sets the full sensor again.
  const Clock::time_point end = Clock::now() + std::chrono::seconds(20);
  bool recovered = false;
  while (Clock::now() < end && !recovered) {
    if (source.Next(&frame, milliseconds(50))) {
      ASSERT_EQ(frame.grey.width, kSensor);  // Never a frame of the wrong size.
      recovered = source.stats().reconnects > 0;
    }
  }
  EXPECT_TRUE(recovered);
  EXPECT_GT(source.corrupt_frames(), 0u);
  EXPECT_EQ(source.stats().failed, source.corrupt_frames());
  EXPECT_TRUE(source.stats().connected);
}

TEST(AravisSourceTest, SoftwareTriggerDrivesTheCamera) {
  InProcessCamera camera("HGTRIG");
  ASSERT_TRUE(camera.running());
  AravisOptions options = FakeOptions("127.0.0.1", Pixel::kMono8);
  options.trigger = AravisOptions::Trigger::kSoftware;
  options.frame_rate_hz = 8.0;
  AravisSource source(options);
  Frame frame;
  ASSERT_TRUE(NextWithin(&source, &frame, milliseconds(15000)));
  // In software trigger mode the fake camera sends a frame only per trigger:
  // frames keep coming because the source triggers.
  EXPECT_TRUE(arv_fake_camera_is_in_software_trigger_mode(camera.fake()));
  for (int n = 0; n < 4; ++n) ASSERT_TRUE(NextWithin(&source, &frame, milliseconds(5000)));
  EXPECT_TRUE(source.stats().connected);
}

// A software-triggered camera that stops answering (cable pulled): a trigger
// command to it waits for Aravis' command timeouts (2.5 s), which must not
// hold up the source's stop beyond its release grace (it took 1.8-3.7 s, past
// what a daemon's SIGTERM allows).
TEST(AravisSourceTest, ASoftwareTriggeredCameraThatStopsAnsweringDoesNotHoldUpTheStop) {
  if (access(HG_ARV_FAKE_GV_CAMERA, X_OK) != 0) GTEST_SKIP() << "no arv-fake-gv-camera-0.8";
  CameraProcess camera("HGTRIGSTOP");
  ASSERT_TRUE(camera.started());
  AravisOptions options = FakeOptions("127.0.0.1", Pixel::kMono8);
  options.trigger = AravisOptions::Trigger::kSoftware;
  options.frame_rate_hz = 8.0;
  auto source = std::make_unique<AravisSource>(options);
  Frame frame;
  ASSERT_TRUE(NextWithin(source.get(), &frame, milliseconds(20000)));
  ASSERT_TRUE(NextWithin(source.get(), &frame, milliseconds(5000)));
  camera.Pause();
  // Long enough for a trigger to be sent to the silent camera and wait.
  std::this_thread::sleep_for(milliseconds(400));
  const Clock::time_point before = Clock::now();
  source->Stop();
  source.reset();
  const Clock::duration took = Clock::now() - before;
  EXPECT_LT(took, AravisSource::kReleaseGrace + milliseconds(400))
      << std::chrono::duration_cast<milliseconds>(took).count() << " ms";
}

// A hardware-triggered camera without pulses delivers nothing: the source
// reopens it (it may be a dead connection) with a growing backoff, says so once
// rather than twice per reopen, and reports failing throughout instead of
// `starting` after every reopen.
TEST(AravisSourceTest, AHardwareTriggerWithoutPulsesIsReopenedQuietlyAndFailing) {
  InProcessCamera camera("HGNOPULSE");
  ASSERT_TRUE(camera.running());
  AravisOptions options = FakeOptions("127.0.0.1", Pixel::kMono8);
  options.trigger = AravisOptions::Trigger::kHardware;
  options.frame_rate_hz.reset();
  options.frame_timeout = milliseconds(200);
  ::testing::internal::CaptureStderr();
  AravisSource source(options);
  Frame frame;
  int failing_seen_after_first_loss = 0;
  int not_failing_after_first_loss = 0;
  bool lost_once = false;
  const Clock::time_point end = Clock::now() + milliseconds(3500);
  while (Clock::now() < end) {
    EXPECT_FALSE(source.Next(&frame, milliseconds(50)));
    if (source.failing()) lost_once = true;
    if (lost_once)
      (source.failing() ? failing_seen_after_first_loss : not_failing_after_first_loss)++;
  }
  const AravisSource::Stats stats = source.stats();
  const std::string log = ::testing::internal::GetCapturedStderr();
  auto count = [&log](const std::string& part) {
    int n = 0;
    for (std::size_t at = log.find(part); at != std::string::npos; at = log.find(part, at + 1)) ++n;
    return n;
  };
  EXPECT_TRUE(lost_once) << log;
  EXPECT_EQ(not_failing_after_first_loss, 0) << log;
  EXPECT_GT(failing_seen_after_first_loss, 0);
  // 200 ms silent, then reopened after 0.1, 0.2, 0.4, 0.8, 1.6 s: four or five
  // reopens in 3.5 s, not one every 0.3 s.
  EXPECT_GE(stats.reconnects, 1u);
  EXPECT_LE(stats.reconnects, 5u) << log;
  EXPECT_EQ(count("no frame within 200 ms of opening (hardware trigger: no pulses on Line0?)"), 1)
      << log;
  EXPECT_EQ(count("connection lost"), 0) << log;
  EXPECT_EQ(count("reconnected"), 0) << log;
}

TEST(AravisSourceTest, AbsentCameraIsNoErrorAndARestartedCameraIsReconnected) {
  if (access(HG_ARV_FAKE_GV_CAMERA, X_OK) != 0) GTEST_SKIP() << "no arv-fake-gv-camera-0.8";
  AravisOptions options = FakeOptions("127.0.0.1", Pixel::kMono8);
  // Long enough that a 4 MB frame gets through a loaded two-core machine
  // (200 ms made the source reconnect in a loop there), short enough to show
  // that the loss is noticed long before Aravis' heartbeat would.
  options.frame_timeout = milliseconds(1000);
  // Declared first so that the source (destroyed first) releases a live
  // camera: releasing a dead one waits for Aravis' command timeouts.
  std::optional<CameraProcess> camera;
  // No camera yet: construction does not throw and Next() times out.
  AravisSource source(options);
  Frame frame;
  const Clock::time_point before = Clock::now();
  EXPECT_FALSE(source.Next(&frame, milliseconds(50)));
  EXPECT_LT(Clock::now() - before, milliseconds(1000));  // Not blocked by the opening.
  EXPECT_FALSE(source.stats().connected);
  // Once an attempt to open it failed, the source says it is failing (the
  // camera's status then reads `failed`, not `starting`).
  for (const Clock::time_point end = Clock::now() + milliseconds(10000);
       !source.failing() && Clock::now() < end;) {
    std::this_thread::sleep_for(milliseconds(10));
  }
  EXPECT_TRUE(source.failing());

  camera.emplace("HGPROC");
  ASSERT_TRUE(camera->started());
  ASSERT_TRUE(NextWithin(&source, &frame, milliseconds(20000)));
  ASSERT_TRUE(NextWithin(&source, &frame, milliseconds(5000)));
  EXPECT_TRUE(source.stats().connected);
  EXPECT_FALSE(source.failing());
  EXPECT_EQ(frame.grey.width, kSensor);

  // The camera dies: no frame, and the source says so within the frame
  // timeout (plus a margin for a loaded machine), long before Aravis' own
  // heartbeat would notice.
  camera->Kill();
  const Clock::time_point killed = Clock::now();
  Clock::duration noticed = std::chrono::seconds(100);
  int frames_after_kill = 0;
  while (Clock::now() - killed < std::chrono::seconds(5)) {
    // Frames already on their way may still arrive right after the kill.
    if (source.Next(&frame, milliseconds(50))) ++frames_after_kill;
    if (!source.stats().connected) {
      noticed = Clock::now() - killed;
      break;
    }
  }
  EXPECT_LE(frames_after_kill, 2);
  EXPECT_LT(noticed, options.frame_timeout + milliseconds(1000));
  EXPECT_TRUE(source.failing());
  EXPECT_FALSE(source.Next(&frame, milliseconds(50)));

  // The camera comes back: the source reopens it by itself.
  camera.reset();
  camera.emplace("HGPROC");
  ASSERT_TRUE(NextWithin(&source, &frame, milliseconds(30000)));
  for (int n = 0; n < 3; ++n) ASSERT_TRUE(NextWithin(&source, &frame, milliseconds(5000)));
  const AravisSource::Stats stats = source.stats();
  EXPECT_TRUE(stats.connected);
  EXPECT_GE(stats.reconnects, 1u);
  EXPECT_FALSE(source.failing());
  EXPECT_EQ(frame.grey.width, kSensor);
}

TEST(AravisSourceTest, ACameraOfAnotherSizeThanCalibratedIsNotUsed) {
  InProcessCamera camera("HGOTHER");
  ASSERT_TRUE(camera.running());
  // Calibrated at 1920 x 1080, but the sensor is 2048 x 2048: the camera is
  // refused when opened (it sees nothing) instead of streaming images the
  // calibration does not describe.
  AravisOptions options = FakeOptions("127.0.0.1", Pixel::kMono8);
  options.width = 1920;
  options.height = 1080;
  AravisSource source(options);
  Frame frame;
  EXPECT_FALSE(NextWithin(&source, &frame, milliseconds(1500)));
  EXPECT_FALSE(source.stats().connected);
  EXPECT_EQ(source.stats().completed, 0u);
}

TEST(AravisSourceTest, StopEndsAWaitingNext) {
  AravisSource source(FakeOptions("127.0.0.1", Pixel::kMono8));  // No camera.
  std::thread stopper([&] {
    std::this_thread::sleep_for(milliseconds(100));
    source.Stop();
  });
  Frame frame;
  const Clock::time_point before = Clock::now();
  EXPECT_FALSE(source.Next(&frame, std::chrono::seconds(30)));
  EXPECT_LT(Clock::now() - before, std::chrono::seconds(10));
  stopper.join();
  EXPECT_FALSE(source.Next(&frame, milliseconds(10)));
}

}  // namespace
}  // namespace hg::capture
