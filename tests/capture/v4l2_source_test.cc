// The v4l2 source against a scripted fake driver (buffers in memory, a script
// of frames and events): formats, driver timestamps, dropped and corrupt
// frames, a camera that vanishes and comes back, start-up failures, and the
// order of the V4L2 calls. The fake also checks that the source uses the
// driver as V4L2 requires (no buffer queued twice, nothing mapped at close).
// Its own test binary: it replaces the global operator new to count
// allocations per frame.
#include "capture/v4l2_source.h"

#include <linux/videodev2.h>
#include <poll.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <ctime>
#include <deque>
#include <memory>
#include <new>
#include <optional>
#include <random>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "common/config_error.h"
#include "support/allocation_counter.h"

namespace hg::capture {
namespace {

using std::chrono::milliseconds;

constexpr int kWidth = 64;
constexpr int kHeight = 48;
constexpr char kPath[] = "/dev/video7";
constexpr std::uint32_t kOffsetStep = 1u << 20;  // mmap offset of buffer i: i * kOffsetStep.
constexpr std::uint32_t kMonotonicFlags =
    V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC | V4L2_BUF_FLAG_TSTAMP_SRC_SOE;

/// How the fake camera disappears.
enum class Vanish {
  kPollError,        ///< poll() reports POLLERR (vb2 after the queue's error flag is set).
  kDequeueNoDevice,  ///< poll() wakes up, VIDIOC_DQBUF answers ENODEV.
};

/// One entry of the fake driver's script: a frame, or the camera vanishing.
struct ScriptItem {
  std::vector<std::uint8_t> bytes;
  std::uint32_t sequence = 0;
  std::int64_t monotonic_ns = 0;  // Multiple of 1 us (struct timeval).
  std::uint32_t flags = kMonotonicFlags;
  std::optional<Vanish> vanish;
  int failed_opens = 0;  // After vanishing, Open() fails this often before it is back.
};

/// The fake camera: what its driver offers, its script, its state, and the log
/// of the calls it received. Shared by the test and the device the source owns.
struct FakeCamera {
  std::vector<std::uint32_t> formats = {V4L2_PIX_FMT_GREY, V4L2_PIX_FMT_YUYV, V4L2_PIX_FMT_MJPEG};
  std::uint32_t width = kWidth;  // The one size the driver offers.
  std::uint32_t height = kHeight;
  std::uint32_t line_padding = 0;  // bytesperline beyond the pixels (raw formats).
  std::vector<std::uint32_t> rates = {30, 15};
  bool metadata_only = false;
  int open_error = 0;
  bool busy = false;  // Another program streams: S_FMT answers EBUSY.
  std::uint32_t max_buffers = 8;
  std::deque<ScriptItem> script;
  bool record = true;
  std::vector<std::string> calls;       // ioctls and (un)mappings; poll as "poll".
  std::vector<std::string> violations;  // Misuse of the driver by the source.

  bool open = false;
  bool gone = false;
  int failed_opens_left = 0;
  bool streaming = false;
  v4l2_pix_format pix{};
  std::vector<std::vector<std::uint8_t>> buffers;
  std::vector<bool> mapped;
  std::deque<std::uint32_t> queued;  // Filled in this order.
  int exposure_auto = V4L2_EXPOSURE_APERTURE_PRIORITY;
  int exposure_absolute = 0;
  v4l2_fract interval{1, 30};

  [[nodiscard]] int Mapped() const {
    return static_cast<int>(std::count(mapped.begin(), mapped.end(), true));
  }
  [[nodiscard]] std::vector<std::string> CallsWithoutPoll() const {
    std::vector<std::string> out;
    for (const std::string& c : calls) {
      if (c != "poll") out.push_back(c);
    }
    return out;
  }
  [[nodiscard]] int Count(const std::string& call) const {
    return static_cast<int>(std::count(calls.begin(), calls.end(), call));
  }
};

class FakeDevice final : public V4l2Device {
 public:
  explicit FakeDevice(std::shared_ptr<FakeCamera> camera) : c_(std::move(camera)) {}

  int Open() override {
    Log("open");
    if (c_->open) Violation("open while open");
    if (c_->failed_opens_left > 0) {
      --c_->failed_opens_left;
      return ENOENT;
    }
    if (c_->open_error != 0) return c_->open_error;
    c_->gone = false;
    c_->open = true;
    c_->pix = Pix(c_->formats.front());
    return 0;
  }
  void Close() override {
    Log("close");
    if (c_->Mapped() > 0) Violation("closed with buffers mapped");
    c_->open = false;
    c_->streaming = false;
    c_->buffers.clear();
    c_->mapped.clear();
    c_->queued.clear();
  }
  int QueryCap(v4l2_capability* cap) override {
    Log("QUERYCAP");
    if (const int e = Usable()) return e;
    *cap = {};
    const std::uint32_t node = c_->metadata_only ? V4L2_CAP_META_CAPTURE : V4L2_CAP_VIDEO_CAPTURE;
    cap->device_caps = node | V4L2_CAP_STREAMING;
    cap->capabilities =
        V4L2_CAP_VIDEO_CAPTURE | V4L2_CAP_META_CAPTURE | V4L2_CAP_STREAMING | V4L2_CAP_DEVICE_CAPS;
    return 0;
  }
  int SetFormat(v4l2_format* format) override {
    Log("S_FMT");
    if (const int e = Usable()) return e;
    if (format->type != V4L2_BUF_TYPE_VIDEO_CAPTURE) return EINVAL;
    if (c_->busy || c_->streaming || !c_->buffers.empty()) return EBUSY;
    // As drivers do: an unsupported request is adjusted, not refused.
    std::uint32_t fourcc = format->fmt.pix.pixelformat;
    if (std::find(c_->formats.begin(), c_->formats.end(), fourcc) == c_->formats.end()) {
      fourcc = c_->formats.front();
    }
    c_->pix = Pix(fourcc);
    format->fmt.pix = c_->pix;
    return 0;
  }
  int GetFormat(v4l2_format* format) override {
    Log("G_FMT");
    if (const int e = Usable()) return e;
    if (format->type != V4L2_BUF_TYPE_VIDEO_CAPTURE) return EINVAL;
    format->fmt.pix = c_->pix;
    return 0;
  }
  int SetParm(v4l2_streamparm* parm) override {
    const v4l2_fract asked = parm->parm.capture.timeperframe;
    Log("S_PARM " + std::to_string(asked.numerator) + "/" + std::to_string(asked.denominator));
    if (const int e = Usable()) return e;
    if (c_->streaming) return EBUSY;
    if (asked.numerator == 0 || asked.denominator == 0) return EINVAL;
    const double rate = static_cast<double>(asked.denominator) / asked.numerator;
    std::uint32_t best = c_->rates.front();
    for (std::uint32_t r : c_->rates) {
      if (std::abs(r - rate) < std::abs(best - rate)) best = r;
    }
    c_->interval = {1, best};
    parm->parm.capture.capability = V4L2_CAP_TIMEPERFRAME;
    parm->parm.capture.timeperframe = c_->interval;
    return 0;
  }
  int SetControl(v4l2_control* control) override {
    if (const int e = Usable()) return e;
    if (control->id == V4L2_CID_EXPOSURE_AUTO) {
      Log("S_CTRL exposure_auto=" + std::to_string(control->value));
      c_->exposure_auto = control->value;
      return 0;
    }
    if (control->id == V4L2_CID_EXPOSURE_ABSOLUTE) {
      Log("S_CTRL exposure_absolute=" + std::to_string(control->value));
      // UVC: the manual exposure time is inactive while auto exposure is on.
      if (c_->exposure_auto != V4L2_EXPOSURE_MANUAL) return EACCES;
      c_->exposure_absolute = control->value;
      return 0;
    }
    Log("S_CTRL ?");
    return EINVAL;
  }
  int RequestBuffers(v4l2_requestbuffers* request) override {
    Log("REQBUFS " + std::to_string(request->count));
    if (const int e = Usable()) return e;
    if (request->memory != V4L2_MEMORY_MMAP || request->type != V4L2_BUF_TYPE_VIDEO_CAPTURE) {
      return EINVAL;
    }
    if (c_->streaming) return EBUSY;
    if (c_->Mapped() > 0) {
      Violation("REQBUFS with buffers mapped");
      return EBUSY;
    }
    const std::uint32_t n = std::min(request->count, c_->max_buffers);
    c_->buffers.assign(n, std::vector<std::uint8_t>(c_->pix.sizeimage, 0));
    c_->mapped.assign(n, false);
    c_->queued.clear();
    request->count = n;
    return 0;
  }
  int QueryBuffer(v4l2_buffer* buffer) override {
    Log("QUERYBUF " + std::to_string(buffer->index));
    if (const int e = Usable()) return e;
    if (buffer->index >= c_->buffers.size() || buffer->memory != V4L2_MEMORY_MMAP) return EINVAL;
    buffer->length = static_cast<std::uint32_t>(c_->buffers[buffer->index].size());
    buffer->m.offset = buffer->index * kOffsetStep;
    return 0;
  }
  int Map(std::size_t length, std::uint32_t offset, void** address) override {
    const std::uint32_t i = offset / kOffsetStep;
    Log("mmap " + std::to_string(i));
    if (const int e = Usable()) return e;
    if (offset % kOffsetStep != 0 || i >= c_->buffers.size() || length != c_->buffers[i].size()) {
      Violation("mmap of an unknown buffer");
      return EINVAL;
    }
    if (c_->mapped[i]) Violation("buffer mapped twice");
    c_->mapped[i] = true;
    *address = c_->buffers[i].data();
    return 0;
  }
  int Unmap(void* address, std::size_t length) override {
    // Works on a vanished camera too: the memory lives until unmapped.
    for (std::size_t i = 0; i < c_->buffers.size(); ++i) {
      if (c_->buffers[i].data() == address && c_->mapped[i]) {
        Log("munmap " + std::to_string(i));
        if (length != c_->buffers[i].size()) Violation("munmap with the wrong length");
        c_->mapped[i] = false;
        return 0;
      }
    }
    Log("munmap ?");
    Violation("munmap of an address that is not mapped");
    return EINVAL;
  }
  int QueueBuffer(v4l2_buffer* buffer) override {
    Log("QBUF " + std::to_string(buffer->index));
    if (const int e = Usable()) return e;
    if (buffer->type != V4L2_BUF_TYPE_VIDEO_CAPTURE || buffer->memory != V4L2_MEMORY_MMAP ||
        buffer->index >= c_->buffers.size()) {
      Violation("QBUF of an unknown buffer");
      return EINVAL;
    }
    if (std::find(c_->queued.begin(), c_->queued.end(), buffer->index) != c_->queued.end()) {
      Violation("buffer queued twice");
      return EINVAL;
    }
    if (!c_->mapped[buffer->index]) Violation("QBUF of an unmapped buffer");
    c_->queued.push_back(buffer->index);
    return 0;
  }
  int DequeueBuffer(v4l2_buffer* buffer) override {
    Log("DQBUF");
    if (const int e = Usable()) return e;
    if (!c_->streaming) return EINVAL;
    if (c_->script.empty() || c_->queued.empty()) return EAGAIN;
    if (c_->script.front().vanish == Vanish::kDequeueNoDevice) {
      GoAway();
      return ENODEV;
    }
    if (c_->script.front().vanish) return EAGAIN;
    const ScriptItem& item = c_->script.front();
    const std::uint32_t i = c_->queued.front();
    c_->queued.pop_front();
    std::vector<std::uint8_t>& memory = c_->buffers[i];
    if (item.bytes.size() > memory.size()) ADD_FAILURE() << "script frame larger than a buffer";
    const std::size_t n = std::min(item.bytes.size(), memory.size());
    std::copy_n(item.bytes.begin(), n, memory.begin());
    *buffer = {};
    buffer->type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buffer->memory = V4L2_MEMORY_MMAP;
    buffer->index = i;
    buffer->bytesused = static_cast<std::uint32_t>(n);
    buffer->length = static_cast<std::uint32_t>(memory.size());
    buffer->m.offset = i * kOffsetStep;
    buffer->field = V4L2_FIELD_NONE;
    buffer->flags = item.flags | V4L2_BUF_FLAG_MAPPED;
    buffer->sequence = item.sequence;
    buffer->timestamp.tv_sec = static_cast<time_t>(item.monotonic_ns / 1'000'000'000);
    buffer->timestamp.tv_usec =
        static_cast<suseconds_t>((item.monotonic_ns % 1'000'000'000) / 1000);
    c_->script.pop_front();
    return 0;
  }
  int StreamOn(v4l2_buf_type type) override {
    Log("STREAMON");
    if (const int e = Usable()) return e;
    if (type != V4L2_BUF_TYPE_VIDEO_CAPTURE || c_->buffers.empty()) return EINVAL;
    c_->streaming = true;
    return 0;
  }
  int StreamOff(v4l2_buf_type type) override {
    Log("STREAMOFF");
    if (const int e = Usable()) return e;
    c_->streaming = false;
    c_->queued.clear();
    return 0;
  }
  int Poll(std::chrono::milliseconds timeout, short* revents) override {
    Log("poll");
    if (!c_->open) {
      Violation("poll on a closed device");
      *revents = POLLNVAL;
      return 0;
    }
    if (c_->gone || !c_->streaming) {
      *revents = POLLERR;
      return 0;
    }
    if (!c_->script.empty()) {
      const ScriptItem& item = c_->script.front();
      if (item.vanish == Vanish::kPollError) {
        GoAway();
        *revents = POLLERR;
        return 0;
      }
      if (item.vanish || !c_->queued.empty()) {
        *revents = POLLIN | POLLRDNORM;
        return 0;
      }
    }
    std::this_thread::sleep_for(std::min(timeout, milliseconds(1)));
    *revents = 0;
    return 0;
  }

 private:
  static std::uint32_t BytesPerLine(std::uint32_t fourcc, std::uint32_t padding,
                                    std::uint32_t width) {
    if (fourcc == V4L2_PIX_FMT_MJPEG) return 0;
    return (fourcc == V4L2_PIX_FMT_YUYV ? 2 : 1) * width + padding;
  }
  v4l2_pix_format Pix(std::uint32_t fourcc) const {
    v4l2_pix_format p{};
    p.width = c_->width;
    p.height = c_->height;
    p.pixelformat = fourcc;
    p.field = V4L2_FIELD_NONE;
    p.bytesperline = BytesPerLine(fourcc, c_->line_padding, c_->width);
    p.sizeimage = fourcc == V4L2_PIX_FMT_MJPEG ? 65536 : p.bytesperline * c_->height;
    return p;
  }
  /// 0 when ioctls can work: EBADF when closed (a bug of the caller), ENODEV
  /// once the camera is gone.
  int Usable() {
    if (!c_->open) {
      Violation("call on a closed device: " + c_->calls.back());
      return EBADF;
    }
    return c_->gone ? ENODEV : 0;
  }
  void GoAway() {
    c_->failed_opens_left = c_->script.front().failed_opens;
    c_->script.pop_front();
    c_->gone = true;
  }
  void Log(const std::string& call) {
    if (c_->record) c_->calls.push_back(call);
  }
  void Violation(const std::string& what) { c_->violations.push_back(what); }

  std::shared_ptr<FakeCamera> c_;
};

V4l2Options Options(V4l2Options::Format format) {
  V4l2Options o;
  o.device = kPath;
  o.format = format;
  o.width = kWidth;
  o.height = kHeight;
  return o;
}

V4l2DeviceFactory FactoryFor(const std::shared_ptr<FakeCamera>& camera) {
  return [camera](const std::string& path) -> std::unique_ptr<V4l2Device> {
    EXPECT_EQ(path, kPath);
    return std::make_unique<FakeDevice>(camera);
  };
}

std::int64_t ClockNs(clockid_t clock) {
  timespec t{};
  clock_gettime(clock, &t);
  return static_cast<std::int64_t>(t.tv_sec) * 1'000'000'000 + t.tv_nsec;
}

std::int64_t RealtimeMinusMonotonic() {
  const std::int64_t r = ClockNs(CLOCK_REALTIME);
  return r - ClockNs(CLOCK_MONOTONIC);
}

// Frame k's driver timestamp: 100 s of monotonic time plus k periods of 30 Hz.
std::int64_t MonotonicNs(int k) { return 100'000'000'000 + std::int64_t{k} * 33'333'000; }

std::uint8_t GreyAt(int u, int v, int k) {
  return static_cast<std::uint8_t>(u * 3 + v * 5 + k * 7);
}

ScriptItem GreyFrame(int k, std::uint32_t sequence, std::uint32_t padding = 0) {
  ScriptItem item;
  item.sequence = sequence;
  item.monotonic_ns = MonotonicNs(k);
  for (int v = 0; v < kHeight; ++v) {
    for (int u = 0; u < kWidth; ++u) item.bytes.push_back(GreyAt(u, v, k));
    item.bytes.insert(item.bytes.end(), padding, 0xEE);  // Must not show up in the image.
  }
  return item;
}

// YUYV test pattern in video range (Y 16..235, U and V 16..240).
struct Yuv {
  int y0, y1, u, v;
};
Yuv YuvAt(int pair, int row, int k) {
  return {16 + (pair * 6 + row * 2 + k) % 220, 16 + (pair * 6 + 3 + row * 2 + k) % 220,
          16 + (row * 7 + pair * 5 + k) % 225, 16 + (pair * 11 + row * 3 + 2 * k) % 225};
}

ScriptItem YuyvFrame(int k, std::uint32_t sequence, std::uint32_t padding = 0) {
  ScriptItem item;
  item.sequence = sequence;
  item.monotonic_ns = MonotonicNs(k);
  for (int v = 0; v < kHeight; ++v) {
    for (int pair = 0; pair < kWidth / 2; ++pair) {
      const Yuv p = YuvAt(pair, v, k);
      for (int b : {p.y0, p.u, p.y1, p.v}) item.bytes.push_back(static_cast<std::uint8_t>(b));
    }
    item.bytes.insert(item.bytes.end(), padding, 0xEE);
  }
  return item;
}

// ITU-R BT.601, video range, in floating point: the oracle for YUYV.
void Bt601ToRgb(int y, int u, int v, int rgb[3]) {
  const double c = 1.164383 * (y - 16);
  const double r = c + 1.596027 * (v - 128);
  const double g = c - 0.391762 * (u - 128) - 0.812968 * (v - 128);
  const double b = c + 2.017232 * (u - 128);
  for (int i = 0; const double x : {r, g, b}) {
    rgb[i++] = static_cast<int>(std::lround(std::clamp(x, 0.0, 255.0)));
  }
}

// MJPEG test picture: red grows to the right, blue downwards (a swapped
// channel order shows), green constant.
cv::Mat Picture(int width, int height, int k) {
  cv::Mat bgr(height, width, CV_8UC3);
  for (int v = 0; v < height; ++v) {
    for (int u = 0; u < width; ++u) {
      bgr.at<cv::Vec3b>(v, u) =
          cv::Vec3b(static_cast<std::uint8_t>(40 + 3 * v + k), static_cast<std::uint8_t>(100),
                    static_cast<std::uint8_t>(30 + 2 * u + k));
    }
  }
  return bgr;
}

std::vector<std::uint8_t> Jpeg(const cv::Mat& bgr) {
  std::vector<std::uint8_t> bytes;
  EXPECT_TRUE(cv::imencode(".jpg", bgr, bytes, {cv::IMWRITE_JPEG_QUALITY, 95}));
  return bytes;
}

ScriptItem MjpegFrame(int k, std::uint32_t sequence, int width = kWidth, int height = kHeight) {
  ScriptItem item;
  item.sequence = sequence;
  item.monotonic_ns = MonotonicNs(k);
  item.bytes = Jpeg(Picture(width, height, k));
  item.bytes.insert(item.bytes.end(), 200, 0);  // UVC payloads end in padding.
  return item;
}

ScriptItem VanishItem(Vanish how, int failed_opens) {
  ScriptItem item;
  item.vanish = how;
  item.failed_opens = failed_opens;
  return item;
}

// The stamp is the driver's monotonic time moved to CLOCK_REALTIME.
void ExpectDriverStamp(const Frame& frame, int k, std::int64_t offset_before,
                       std::int64_t offset_after) {
  const std::int64_t slack = 1'000'000;  // Reading two clocks is not instantaneous.
  EXPECT_GE(frame.stamp_ns, MonotonicNs(k) + std::min(offset_before, offset_after) - slack);
  EXPECT_LE(frame.stamp_ns, MonotonicNs(k) + std::max(offset_before, offset_after) + slack);
}

void ExpectGreyFrame(const Frame& frame, int k) {
  ASSERT_EQ(frame.kind, FrameKind::kMono);
  ASSERT_EQ(frame.grey.width, kWidth);
  ASSERT_EQ(frame.grey.height, kHeight);
  ASSERT_EQ(frame.grey.pixels.size(), std::size_t{kWidth * kHeight});
  int wrong = 0;
  for (int v = 0; v < kHeight; ++v) {
    for (int u = 0; u < kWidth; ++u) wrong += frame.grey.At(u, v) != GreyAt(u, v, k);
  }
  EXPECT_EQ(wrong, 0) << "frame " << k;
}

void ExpectMjpegFrame(const Frame& frame, int k) {
  ASSERT_EQ(frame.kind, FrameKind::kRgb);
  ASSERT_EQ(frame.rgb.width, kWidth);
  ASSERT_EQ(frame.rgb.height, kHeight);
  const cv::Mat bgr = Picture(kWidth, kHeight, k);
  double sum = 0.0;
  int worst = 0;
  for (int v = 0; v < kHeight; ++v) {
    for (int u = 0; u < kWidth; ++u) {
      const cv::Vec3b want = bgr.at<cv::Vec3b>(v, u);
      const std::uint8_t* got = frame.rgb.Pixel(u, v);
      for (int c = 0; c < 3; ++c) {
        const int d = std::abs(int{got[c]} - int{want[2 - c]});
        sum += d;
        worst = std::max(worst, d);
      }
    }
  }
  // JPEG is lossy: close on average, never far on a smooth picture.
  EXPECT_LT(sum / (kWidth * kHeight * 3), 2.0) << "frame " << k;
  EXPECT_LE(worst, 16) << "frame " << k;
}

TEST(V4l2SourceTest, GreyFramesAreMonoWithDriverTimestamps) {
  auto camera = std::make_shared<FakeCamera>();
  camera->line_padding = 16;  // bytesperline > width: rows are copied one by one.
  for (int k = 0; k < 3; ++k) camera->script.push_back(GreyFrame(k, k, 16));
  V4l2Source source(Options(V4l2Options::Format::kGrey), FactoryFor(camera));
  EXPECT_TRUE(source.streaming());
  Frame frame;
  for (int k = 0; k < 3; ++k) {
    const std::int64_t before = RealtimeMinusMonotonic();
    ASSERT_TRUE(source.Next(&frame, milliseconds(500)));
    const std::int64_t after = RealtimeMinusMonotonic();
    ExpectGreyFrame(frame, k);
    ExpectDriverStamp(frame, k, before, after);
    EXPECT_EQ(frame.index, static_cast<std::uint64_t>(k));
  }
  EXPECT_FALSE(source.Next(&frame, milliseconds(30)));  // The script ended: silence.
  EXPECT_EQ(source.corrupt_frames(), 0u);
  EXPECT_EQ(source.dropped_frames(), 0u);
  EXPECT_TRUE(camera->violations.empty()) << camera->violations.front();
}

TEST(V4l2SourceTest, YuyvFramesAreRgbInBt601VideoRange) {
  auto camera = std::make_shared<FakeCamera>();
  camera->line_padding = 8;
  for (int k = 0; k < 2; ++k) camera->script.push_back(YuyvFrame(k, k, 8));
  V4l2Source source(Options(V4l2Options::Format::kYuyv), FactoryFor(camera));
  Frame frame;
  for (int k = 0; k < 2; ++k) {
    const std::int64_t before = RealtimeMinusMonotonic();
    ASSERT_TRUE(source.Next(&frame, milliseconds(500)));
    const std::int64_t after = RealtimeMinusMonotonic();
    ASSERT_EQ(frame.kind, FrameKind::kRgb);
    ASSERT_EQ(frame.rgb.width, kWidth);
    ASSERT_EQ(frame.rgb.height, kHeight);
    ASSERT_EQ(frame.rgb.pixels.size(), std::size_t{kWidth * kHeight * 3});
    int worst = 0;
    for (int v = 0; v < kHeight; ++v) {
      for (int u = 0; u < kWidth; ++u) {
        const Yuv p = YuvAt(u / 2, v, k);
        int want[3];
        Bt601ToRgb(u % 2 == 0 ? p.y0 : p.y1, p.u, p.v, want);
        for (int c = 0; c < 3; ++c) {
          worst = std::max(worst, std::abs(int{frame.rgb.Pixel(u, v)[c]} - want[c]));
        }
      }
    }
    EXPECT_LE(worst, 2) << "frame " << k;  // Fixed-point rounding only.
    ExpectDriverStamp(frame, k, before, after);
    EXPECT_EQ(frame.index, static_cast<std::uint64_t>(k));
  }
  EXPECT_EQ(source.corrupt_frames(), 0u);
  EXPECT_TRUE(camera->violations.empty()) << camera->violations.front();
}

TEST(V4l2SourceTest, MjpegFramesAreDecodedToRgb) {
  auto camera = std::make_shared<FakeCamera>();
  for (int k = 0; k < 3; ++k) camera->script.push_back(MjpegFrame(k, k));
  V4l2Source source(Options(V4l2Options::Format::kMjpeg), FactoryFor(camera));
  Frame frame;
  for (int k = 0; k < 3; ++k) {
    const std::int64_t before = RealtimeMinusMonotonic();
    ASSERT_TRUE(source.Next(&frame, milliseconds(500)));
    const std::int64_t after = RealtimeMinusMonotonic();
    ExpectMjpegFrame(frame, k);
    ExpectDriverStamp(frame, k, before, after);
    EXPECT_EQ(frame.index, static_cast<std::uint64_t>(k));
  }
  EXPECT_EQ(source.corrupt_frames(), 0u);
  EXPECT_TRUE(camera->violations.empty()) << camera->violations.front();
}

TEST(V4l2SourceTest, SequenceGapsAreCountedAsDroppedFrames) {
  auto camera = std::make_shared<FakeCamera>();
  const std::vector<std::uint32_t> sequences = {0, 1, 3, 4, 7};
  for (std::size_t k = 0; k < sequences.size(); ++k) {
    camera->script.push_back(GreyFrame(static_cast<int>(k), sequences[k]));
  }
  V4l2Source source(Options(V4l2Options::Format::kGrey), FactoryFor(camera));
  Frame frame;
  for (std::size_t k = 0; k < sequences.size(); ++k) {
    ASSERT_TRUE(source.Next(&frame, milliseconds(500)));
    ExpectGreyFrame(frame, static_cast<int>(k));
    EXPECT_EQ(frame.index, sequences[k]);  // Indices skip the dropped frames.
  }
  EXPECT_EQ(source.dropped_frames(), 3u);
  EXPECT_EQ(source.corrupt_frames(), 0u);
  // The status carries them as the transport's underruns.
  const TransportStats stats = source.transport_stats();
  EXPECT_EQ(stats.completed, sequences.size());
  EXPECT_EQ(stats.underruns, 3u);
  EXPECT_EQ(stats.failed, 0u);
  EXPECT_EQ(stats.resends, 0u);
}

TEST(V4l2SourceTest, CorruptMjpegFramesAreCountedAndSkipped) {
  auto camera = std::make_shared<FakeCamera>();
  camera->script.push_back(MjpegFrame(0, 0));
  // Cut short in transfer: no end marker, zero padding. libjpeg decodes this
  // (the missing rows grey); only the marker check catches it.
  ScriptItem truncated = MjpegFrame(1, 1);
  const std::vector<std::uint8_t> whole = Jpeg(Picture(kWidth, kHeight, 1));
  truncated.bytes.assign(whole.begin(), whole.begin() + static_cast<long>(whole.size() * 4 / 5));
  truncated.bytes.insert(truncated.bytes.end(), 300, 0);
  camera->script.push_back(truncated);
  // Markers right, content garbage: once where no decoder recognises it, once
  // where the JPEG decoder starts and fails. Neither may deliver the previous
  // frame again.
  std::mt19937_64 rng(7);
  for (const std::vector<std::uint8_t>& head :
       {std::vector<std::uint8_t>{0xFF, 0xD8, 0x00},
        std::vector<std::uint8_t>{0xFF, 0xD8, 0xFF, 0xDB}}) {
    ScriptItem garbage = MjpegFrame(2, static_cast<std::uint32_t>(camera->script.size()));
    garbage.bytes = head;
    for (int i = 0; i < 1500; ++i) garbage.bytes.push_back(static_cast<std::uint8_t>(rng()));
    garbage.bytes.push_back(0xFF);
    garbage.bytes.push_back(0xD9);
    camera->script.push_back(garbage);
  }
  // A valid JPEG of another size.
  camera->script.push_back(MjpegFrame(3, 4, kWidth / 2, kHeight / 2));
  // A valid JPEG in a buffer the driver flags as damaged.
  ScriptItem flagged = MjpegFrame(4, 5);
  flagged.flags |= V4L2_BUF_FLAG_ERROR;
  camera->script.push_back(flagged);
  camera->script.push_back(MjpegFrame(6, 6));

  V4l2Source source(Options(V4l2Options::Format::kMjpeg), FactoryFor(camera));
  Frame frame;
  ASSERT_TRUE(source.Next(&frame, milliseconds(500)));
  ExpectMjpegFrame(frame, 0);
  ASSERT_TRUE(source.Next(&frame, milliseconds(2000)));  // Skips the five bad ones.
  ExpectMjpegFrame(frame, 6);
  EXPECT_EQ(frame.index, 6u);
  EXPECT_EQ(source.corrupt_frames(), 5u);
  EXPECT_EQ(source.dropped_frames(), 0u);  // Corrupt is not dropped.
  EXPECT_EQ(source.transport_stats().failed, 5u);
  EXPECT_EQ(source.transport_stats().completed, 2u);
  EXPECT_EQ(source.transport_stats().underruns, 0u);
  EXPECT_FALSE(source.Next(&frame, milliseconds(30)));
  EXPECT_EQ(camera->queued.size(), camera->buffers.size());  // Every buffer went back.
  EXPECT_TRUE(camera->violations.empty()) << camera->violations.front();
}

TEST(V4l2SourceTest, ShortRawBufferIsCorrupt) {
  auto camera = std::make_shared<FakeCamera>();
  ScriptItem short_frame = YuyvFrame(0, 0);
  short_frame.bytes.resize(short_frame.bytes.size() - 1);
  camera->script.push_back(short_frame);
  camera->script.push_back(YuyvFrame(1, 1));
  V4l2Source source(Options(V4l2Options::Format::kYuyv), FactoryFor(camera));
  Frame frame;
  ASSERT_TRUE(source.Next(&frame, milliseconds(500)));
  EXPECT_EQ(frame.index, 1u);
  EXPECT_EQ(source.corrupt_frames(), 1u);
}

bool Contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

class V4l2VanishTest : public ::testing::TestWithParam<Vanish> {};

TEST_P(V4l2VanishTest, CameraThatVanishesIsReopenedAndFramesFlowAgain) {
  auto camera = std::make_shared<FakeCamera>();
  camera->script.push_back(GreyFrame(0, 0));
  camera->script.push_back(GreyFrame(1, 1));
  camera->script.push_back(VanishItem(GetParam(), 2));
  // Back after re-enumeration: the driver counts from 0 again.
  camera->script.push_back(GreyFrame(10, 0));
  camera->script.push_back(GreyFrame(11, 1));
  V4l2Source source(Options(V4l2Options::Format::kGrey), FactoryFor(camera));
  Frame frame;
  ASSERT_TRUE(source.Next(&frame, milliseconds(500)));
  ExpectGreyFrame(frame, 0);
  ASSERT_TRUE(source.Next(&frame, milliseconds(500)));
  ExpectGreyFrame(frame, 1);

  const int opens_before = camera->Count("open");
  EXPECT_FALSE(source.Next(&frame, milliseconds(500)));
  EXPECT_FALSE(source.streaming());
  EXPECT_TRUE(source.failing());  // Its status: failed while it reopens.
  EXPECT_EQ(source.disconnects(), 1u);
  EXPECT_FALSE(camera->open);  // Everything released: unmapped and closed.
  EXPECT_EQ(camera->Mapped(), 0);

  // The source keeps trying (backoff 100, 200, 400 ms): the third open works.
  bool got = false;
  for (int i = 0; i < 200 && !got; ++i) got = source.Next(&frame, milliseconds(50));
  ASSERT_TRUE(got);
  ExpectGreyFrame(frame, 10);
  EXPECT_EQ(frame.index, 2u);  // Indices go on across the reconnection.
  EXPECT_TRUE(source.streaming());
  EXPECT_FALSE(source.failing());
  EXPECT_EQ(source.reconnects(), 1u);
  EXPECT_EQ(camera->Count("open") - opens_before, 3);
  ASSERT_TRUE(source.Next(&frame, milliseconds(500)));
  ExpectGreyFrame(frame, 11);
  EXPECT_EQ(frame.index, 3u);
  EXPECT_EQ(source.dropped_frames(), 0u);
  EXPECT_EQ(source.corrupt_frames(), 0u);
  EXPECT_TRUE(camera->violations.empty()) << camera->violations.front();
}

// A camera that comes back offering another size (another model plugged in,
// a firmware reset to its default mode) stays failed, since the calibration is
// for the old size, and the log says why, once, not at every retry; when the
// size is right again it streams again and the log says so.
TEST(V4l2SourceTest, CameraBackWithAnotherSizeStaysFailedAndTheLogSaysWhy) {
  auto camera = std::make_shared<FakeCamera>();
  camera->script.push_back(GreyFrame(0, 0));
  camera->script.push_back(VanishItem(Vanish::kPollError, 1));
  camera->script.push_back(GreyFrame(1, 0));
  V4l2Source source(Options(V4l2Options::Format::kGrey), FactoryFor(camera));
  Frame frame;
  ASSERT_TRUE(source.Next(&frame, milliseconds(500)));
  ::testing::internal::CaptureStderr();
  EXPECT_FALSE(source.Next(&frame, milliseconds(500)));
  camera->width = kWidth / 2;
  const int opens_before = camera->Count("open");
  bool got = false;
  for (int i = 0; i < 30 && !got; ++i) got = source.Next(&frame, milliseconds(50));
  EXPECT_FALSE(got);
  EXPECT_TRUE(source.failing());
  EXPECT_GE(camera->Count("open") - opens_before, 3);  // It kept trying.
  camera->width = kWidth;
  for (int i = 0; i < 100 && !got; ++i) got = source.Next(&frame, milliseconds(50));
  const std::string log = ::testing::internal::GetCapturedStderr();
  ASSERT_TRUE(got) << log;
  ExpectGreyFrame(frame, 1);
  EXPECT_FALSE(source.failing());
  EXPECT_TRUE(Contains(log, "camera lost (poll: error or hang-up)")) << log;
  const std::string why = "cannot reopen (retrying up to every 2000 ms): format: asked for GREY " +
                          std::to_string(kWidth) + "x" + std::to_string(kHeight) +
                          " (the calibrated size), the driver gives GREY " +
                          std::to_string(kWidth / 2) + "x" + std::to_string(kHeight);
  const std::size_t first = log.find(why);
  EXPECT_NE(first, std::string::npos) << log;
  EXPECT_EQ(log.find(why, first + 1), std::string::npos) << "said at every retry:\n" << log;
  EXPECT_TRUE(Contains(log, "reopened, streaming again")) << log;
}

INSTANTIATE_TEST_SUITE_P(Ways, V4l2VanishTest,
                         ::testing::Values(Vanish::kPollError, Vanish::kDequeueNoDevice),
                         [](const ::testing::TestParamInfo<Vanish>& param_info) {
                           return param_info.param == Vanish::kPollError
                                      ? std::string("PollError")
                                      : std::string("DqbufEnodev");
                         });

// The message of the ConfigError the constructor throws ("" if none).
std::string StartupError(const std::shared_ptr<FakeCamera>& camera, const V4l2Options& options) {
  try {
    V4l2Source source(options, FactoryFor(camera));
  } catch (const common::ConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(V4l2SourceTest, SizeTheDriverCannotDeliverIsAConfigError) {
  auto camera = std::make_shared<FakeCamera>();
  V4l2Options options = Options(V4l2Options::Format::kYuyv);
  options.width = 80;
  options.height = 60;
  const std::string error = StartupError(camera, options);
  EXPECT_PRED2(Contains, error, "/dev/video7: format: asked for YUYV 80x60");
  EXPECT_PRED2(Contains, error, "the driver gives YUYV 64x48");
  EXPECT_PRED2(Contains, error, "v4l2-ctl --list-formats-ext");
  EXPECT_FALSE(camera->open);
  EXPECT_EQ(camera->Count("REQBUFS 4"), 0);  // Failed before any buffer.
  EXPECT_TRUE(camera->violations.empty()) << camera->violations.front();
}

TEST(V4l2SourceTest, FormatTheDriverLacksIsAConfigError) {
  auto camera = std::make_shared<FakeCamera>();
  camera->formats = {V4L2_PIX_FMT_YUYV};
  const std::string error = StartupError(camera, Options(V4l2Options::Format::kMjpeg));
  EXPECT_PRED2(Contains, error, "format: asked for MJPG 64x48");
  EXPECT_PRED2(Contains, error, "the driver gives YUYV 64x48");
  EXPECT_FALSE(camera->open);
}

TEST(V4l2SourceTest, OtherStartupFailuresSayWhatIsWrong) {
  {
    auto camera = std::make_shared<FakeCamera>();
    camera->open_error = EACCES;
    EXPECT_PRED2(Contains, StartupError(camera, Options(V4l2Options::Format::kGrey)),
                 "/dev/video7: device: cannot open: Permission denied (is the user in "
                 "group video");
  }
  {
    // Absent or busy is not misconfigured: not a ConfigError, so systemd
    // restarts the daemon.
    for (const bool busy : {false, true}) {
      auto camera = std::make_shared<FakeCamera>();
      camera->open_error = busy ? 0 : ENOENT;
      camera->busy = busy;
      std::string error;
      try {
        V4l2Source source(Options(V4l2Options::Format::kGrey), FactoryFor(camera));
      } catch (const common::ConfigError& e) {
        ADD_FAILURE() << "ConfigError: " << e.what();
      } catch (const std::runtime_error& e) {
        error = e.what();
      }
      EXPECT_PRED2(Contains, error,
                   busy ? "/dev/video7: format: the driver refused GREY 64x48 (VIDIOC_S_FMT: "
                          "Device or resource busy (another program is using the camera))"
                        : "/dev/video7: device: cannot open: No such file or directory");
      EXPECT_FALSE(camera->open);
    }
  }
  {
    auto camera = std::make_shared<FakeCamera>();
    camera->metadata_only = true;
    EXPECT_PRED2(Contains, StartupError(camera, Options(V4l2Options::Format::kGrey)),
                 "device: not a streaming video capture node");
    EXPECT_FALSE(camera->open);
  }
  {
    auto camera = std::make_shared<FakeCamera>();
    V4l2Options options = Options(V4l2Options::Format::kGrey);
    options.frame_rate_hz = 25.0;  // The driver offers 30 and 15.
    EXPECT_PRED2(Contains, StartupError(camera, options),
                 "frame_rate_hz: asked for 25 Hz, the driver gives 30 Hz");
    EXPECT_FALSE(camera->open);
  }
  {
    auto camera = std::make_shared<FakeCamera>();
    camera->max_buffers = 1;
    EXPECT_PRED2(Contains, StartupError(camera, Options(V4l2Options::Format::kGrey)),
                 "buffers: the driver granted 1 mmap buffers");
    EXPECT_FALSE(camera->open);
    EXPECT_EQ(camera->Mapped(), 0);
    EXPECT_EQ(camera->CallsWithoutPoll().back(), "close");
    EXPECT_TRUE(camera->violations.empty()) << camera->violations.front();
  }
  {
    auto camera = std::make_shared<FakeCamera>();
    V4l2Options options = Options(V4l2Options::Format::kGrey);
    options.buffers = 1;
    EXPECT_PRED2(Contains, StartupError(camera, options), "/dev/video7: buffers: 1 is not in");
    EXPECT_TRUE(camera->calls.empty());  // Rejected before opening anything.
  }
}

TEST(V4l2SourceTest, CallsFollowTheV4l2StreamingOrder) {
  auto camera = std::make_shared<FakeCamera>();
  camera->script.push_back(GreyFrame(0, 0));
  camera->script.push_back(GreyFrame(1, 1));
  V4l2Options options = Options(V4l2Options::Format::kGrey);
  options.buffers = 3;
  options.frame_rate_hz = 15.0;
  options.exposure = 120;
  {
    V4l2Source source(options, FactoryFor(camera));
    EXPECT_EQ(camera->exposure_auto, V4L2_EXPOSURE_MANUAL);
    EXPECT_EQ(camera->exposure_absolute, 120);
    EXPECT_EQ(camera->interval.denominator, 15u);
    Frame frame;
    ASSERT_TRUE(source.Next(&frame, milliseconds(500)));
    ASSERT_TRUE(source.Next(&frame, milliseconds(500)));
  }
  const std::vector<std::string> expected = {
      "open", "QUERYCAP", "S_FMT", "G_FMT", "S_PARM 1/15", "S_CTRL exposure_auto=1",
      "S_CTRL exposure_absolute=120", "REQBUFS 3",
      // Every buffer queried and mapped, then every buffer queued, then streaming.
      "QUERYBUF 0", "mmap 0", "QUERYBUF 1", "mmap 1", "QUERYBUF 2", "mmap 2", "QBUF 0", "QBUF 1",
      "QBUF 2", "STREAMON",
      // Each filled buffer (oldest first) goes back at once.
      "DQBUF", "QBUF 0", "DQBUF", "QBUF 1",
      // Shutdown.
      "STREAMOFF", "munmap 0", "munmap 1", "munmap 2", "REQBUFS 0", "close"};
  EXPECT_EQ(camera->CallsWithoutPoll(), expected);
  // Each DQBUF came after a poll that saw the buffer ready.
  const auto first_dqbuf = std::find(camera->calls.begin(), camera->calls.end(), "DQBUF");
  ASSERT_NE(first_dqbuf, camera->calls.end());
  EXPECT_EQ(*(first_dqbuf - 1), "poll");
  EXPECT_TRUE(camera->violations.empty()) << camera->violations.front();
}

TEST(V4l2SourceTest, WithoutDriverTimestampsTheDequeueTimeLessOnePeriodIsUsed) {
  auto camera = std::make_shared<FakeCamera>();
  ScriptItem item = GreyFrame(0, 0);
  item.flags = V4L2_BUF_FLAG_TIMESTAMP_UNKNOWN;
  camera->script.push_back(item);
  V4l2Options options = Options(V4l2Options::Format::kGrey);
  options.frame_rate_hz = 30.0;
  V4l2Source source(options, FactoryFor(camera));
  Frame frame;
  const std::int64_t before = ClockNs(CLOCK_REALTIME);
  ASSERT_TRUE(source.Next(&frame, milliseconds(500)));
  const std::int64_t after = ClockNs(CLOCK_REALTIME);
  const std::int64_t period = 1'000'000'000 / 30;
  EXPECT_GE(frame.stamp_ns, before - period - 1);
  EXPECT_LE(frame.stamp_ns, after - period + 1);
}

TEST(V4l2SourceTest, StopEndsABlockedNext) {
  auto camera = std::make_shared<FakeCamera>();  // Streams, but no frame ever comes.
  V4l2Source source(Options(V4l2Options::Format::kGrey), FactoryFor(camera));
  std::thread stopper([&source] {
    std::this_thread::sleep_for(milliseconds(50));
    source.Stop();
  });
  Frame frame;
  // An hour: only Stop() can end it within the test's timeout.
  EXPECT_FALSE(source.Next(&frame, std::chrono::hours(1)));
  stopper.join();
  EXPECT_FALSE(source.Next(&frame, milliseconds(0)));
}

TEST(V4l2SourceTest, NoAllocationPerFrameAfterWarmUp) {
  for (const V4l2Options::Format format :
       {V4l2Options::Format::kGrey, V4l2Options::Format::kYuyv}) {
    auto camera = std::make_shared<FakeCamera>();
    camera->record = false;
    camera->line_padding = 4;
    for (int k = 0; k < 12; ++k) {
      camera->script.push_back(format == V4l2Options::Format::kGrey ? GreyFrame(k, k, 4)
                                                                    : YuyvFrame(k, k, 4));
    }
    V4l2Source source(Options(format), FactoryFor(camera));
    Frame frame;
    for (int k = 0; k < 2; ++k) ASSERT_TRUE(source.Next(&frame, milliseconds(500)));
    long allocations = 0;
    int frames = 0;
    for (int k = 2; k < 12; ++k) {
      const hg::testing::AllocationCounter counter;
      const bool ok = source.Next(&frame, milliseconds(500));
      allocations += counter.count();
      frames += ok;
    }
    EXPECT_EQ(frames, 10);
    EXPECT_EQ(allocations, 0) << "format " << static_cast<int>(format);
  }
}

}  // namespace
}  // namespace hg::capture
