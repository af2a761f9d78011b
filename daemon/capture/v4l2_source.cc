#include "capture/v4l2_source.h"

#include <fcntl.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <ctime>
#include <sstream>
#include <stdexcept>
#include <string_view>
#include <system_error>
#include <thread>
#include <utility>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "common/config_error.h"
#include "common/input_file.h"
#include "common/log.h"

namespace hg::capture {
namespace {

constexpr v4l2_buf_type kCapture = V4L2_BUF_TYPE_VIDEO_CAPTURE;
constexpr int kMaxBuffers = 32;
// Longest single wait inside Next(), so that Stop() is seen soon.
constexpr std::chrono::milliseconds kSlice{20};
// Reopening a lost camera: first try after kFirstRetry, then doubling up to
// kMaxRetry. USB re-enumeration takes about a second; polling a missing node
// every 2 s costs nothing.
constexpr std::chrono::milliseconds kFirstRetry{100};
constexpr std::chrono::milliseconds kMaxRetry{2000};
// A reopen failure is said again at most this often while it does not change.
constexpr std::chrono::seconds kRepeatLog{30};

/// The real device: one file descriptor, system calls retried on EINTR.
class SystemV4l2Device final : public V4l2Device {
 public:
  explicit SystemV4l2Device(std::string path) : path_(std::move(path)) {}
  ~SystemV4l2Device() override { Close(); }
  SystemV4l2Device(const SystemV4l2Device&) = delete;
  SystemV4l2Device& operator=(const SystemV4l2Device&) = delete;

  int Open() override {
    Close();
    const int fd = ::open(path_.c_str(), O_RDWR | O_NONBLOCK | O_CLOEXEC);
    if (fd < 0) return errno;
    fd_ = fd;
    return 0;
  }
  void Close() override {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }
  int QueryCap(v4l2_capability* cap) override { return Ioctl(VIDIOC_QUERYCAP, cap); }
  int SetFormat(v4l2_format* format) override { return Ioctl(VIDIOC_S_FMT, format); }
  int GetFormat(v4l2_format* format) override { return Ioctl(VIDIOC_G_FMT, format); }
  int SetParm(v4l2_streamparm* parm) override { return Ioctl(VIDIOC_S_PARM, parm); }
  int SetControl(v4l2_control* control) override { return Ioctl(VIDIOC_S_CTRL, control); }
  int RequestBuffers(v4l2_requestbuffers* request) override {
    return Ioctl(VIDIOC_REQBUFS, request);
  }
  int QueryBuffer(v4l2_buffer* buffer) override { return Ioctl(VIDIOC_QUERYBUF, buffer); }
  int Map(std::size_t length, std::uint32_t offset, void** address) override {
    if (fd_ < 0) return EBADF;
    // Read-only: capture buffers are only read, and vb2 asks no more.
    void* p = ::mmap(nullptr, length, PROT_READ, MAP_SHARED, fd_, static_cast<off_t>(offset));
    if (p == MAP_FAILED) return errno;
    *address = p;
    return 0;
  }
  int Unmap(void* address, std::size_t length) override {
    return ::munmap(address, length) == 0 ? 0 : errno;
  }
  int QueueBuffer(v4l2_buffer* buffer) override { return Ioctl(VIDIOC_QBUF, buffer); }
  int DequeueBuffer(v4l2_buffer* buffer) override { return Ioctl(VIDIOC_DQBUF, buffer); }
  int StreamOn(v4l2_buf_type type) override {
    int t = type;
    return Ioctl(VIDIOC_STREAMON, &t);
  }
  int StreamOff(v4l2_buf_type type) override {
    int t = type;
    return Ioctl(VIDIOC_STREAMOFF, &t);
  }
  int Poll(std::chrono::milliseconds timeout, short* revents) override {
    if (fd_ < 0) return EBADF;
    pollfd p{.fd = fd_, .events = POLLIN, .revents = 0};
    const int n = ::poll(&p, 1, static_cast<int>(timeout.count()));
    if (n < 0) return errno;
    *revents = n == 0 ? 0 : p.revents;
    return 0;
  }

 private:
  int Ioctl(unsigned long request, void* arg) {
    if (fd_ < 0) return EBADF;
    for (;;) {
      if (::ioctl(fd_, request, arg) == 0) return 0;
      if (errno != EINTR) return errno;
    }
  }

  std::string path_;
  int fd_ = -1;
};

std::uint32_t FourCc(V4l2Options::Format format) {
  switch (format) {
    case V4l2Options::Format::kGrey:
      return V4L2_PIX_FMT_GREY;
    case V4l2Options::Format::kYuyv:
      return V4L2_PIX_FMT_YUYV;
    case V4l2Options::Format::kMjpeg:
      return V4L2_PIX_FMT_MJPEG;
  }
  return 0;
}

std::string FourCcText(std::uint32_t fourcc) {
  std::string s(4, ' ');
  for (int i = 0; i < 4; ++i) {
    const char c = static_cast<char>((fourcc >> (8 * i)) & 0xff);
    s[i] = c >= 32 && c < 127 ? c : '?';
  }
  while (!s.empty() && s.back() == ' ') s.pop_back();
  return s;
}

std::string SizeText(std::uint32_t width, std::uint32_t height) {
  return std::to_string(width) + "x" + std::to_string(height);
}

std::string ErrnoText(int error) {
  std::string text = std::generic_category().message(error);
  switch (error) {
    case EACCES:
    case EPERM:
      text += " (is the user in group video, and does the unit's DeviceAllow grant the node?)";
      break;
    case ENOENT:
    case ENODEV:
    case ENXIO:
      text += " (unplugged? v4l2-ctl --list-devices lists the cameras)";
      break;
    case EBUSY:
      text += " (another program is using the camera)";
      break;
    default:
      break;
  }
  return text;
}

/// A number as a person writes it: 25, 7.5, 29.97.
std::string Number(double x) {
  std::ostringstream out;
  out << x;
  return out.str();
}

std::int64_t Nanoseconds(const timespec& t) {
  return static_cast<std::int64_t>(t.tv_sec) * 1'000'000'000 + t.tv_nsec;
}

std::int64_t RealtimeNs() {
  timespec t{};
  clock_gettime(CLOCK_REALTIME, &t);
  return Nanoseconds(t);
}

/// CLOCK_REALTIME - CLOCK_MONOTONIC now, read around one monotonic reading so
/// that the error is half the time between the two realtime readings.
std::int64_t RealtimeMinusMonotonicNs() {
  timespec r1{}, m{}, r2{};
  clock_gettime(CLOCK_REALTIME, &r1);
  clock_gettime(CLOCK_MONOTONIC, &m);
  clock_gettime(CLOCK_REALTIME, &r2);
  return Nanoseconds(r1) / 2 + Nanoseconds(r2) / 2 - Nanoseconds(m);
}

/// The frame interval numerator / denominator closest to 1 / rate_hz with a
/// small numerator (7.5 Hz -> 2/15), as UVC lists its intervals.
v4l2_fract FrameInterval(double rate_hz) {
  for (std::uint32_t n = 1; n <= 100; ++n) {
    const double d = std::round(rate_hz * n);
    if (d >= 1.0 && std::abs(d / n - rate_hz) <= 1e-6 * rate_hz) {
      return {n, static_cast<std::uint32_t>(d)};
    }
  }
  return {1000, static_cast<std::uint32_t>(std::max(1.0, std::round(rate_hz * 1000.0)))};
}

bool IsStreamingCapture(const v4l2_capability& cap) {
  const std::uint32_t caps =
      (cap.capabilities & V4L2_CAP_DEVICE_CAPS) != 0 ? cap.device_caps : cap.capabilities;
  return (caps & V4L2_CAP_VIDEO_CAPTURE) != 0 && (caps & V4L2_CAP_STREAMING) != 0;
}

}  // namespace

std::unique_ptr<V4l2Device> OpenSystemV4l2Device(const std::string& path) {
  return std::make_unique<SystemV4l2Device>(path);
}

V4l2Source::V4l2Source(V4l2Options options, V4l2DeviceFactory factory)
    : options_(std::move(options)) {
  const std::string& name = options_.device;
  auto bad = [&](const std::string& key, const std::string& problem) {
    throw common::ConfigError((name.empty() ? std::string("v4l2") : name) + ": " + key + ": " +
                              problem);
  };
  if (name.empty()) bad("device", "empty (expected a node such as /dev/video0)");
  if (options_.width < 1 || options_.height < 1 || options_.width > 16384 ||
      options_.height > 16384) {
    bad("size", SizeText(options_.width, options_.height) + " is not a camera size");
  }
  if (options_.format == V4l2Options::Format::kYuyv && options_.width % 2 != 0) {
    bad("format", "YUYV needs an even width, not " + std::to_string(options_.width));
  }
  if (options_.buffers < 2 || options_.buffers > kMaxBuffers) {
    bad("buffers", std::to_string(options_.buffers) + " is not in 2 .. 32");
  }
  if (options_.frame_rate_hz &&
      !(*options_.frame_rate_hz > 0.0 && *options_.frame_rate_hz <= 1000.0)) {
    bad("frame_rate_hz", Number(*options_.frame_rate_hz) + " is not in (0, 1000]");
  }
  if (options_.exposure && *options_.exposure < 1) {
    bad("exposure", std::to_string(*options_.exposure) + " is not positive");
  }
  if (!factory) bad("device", "no device factory");
  device_ = factory(name);
  if (!device_) bad("device", "cannot be created");
  mappings_.reserve(kMaxBuffers);
  backoff_ = kFirstRetry;
  std::string error;
  int call_error = 0;
  if (!Start(&error, &call_error)) {
    // An absent or busy camera is not a bad config: "cannot run", which
    // systemd restarts, rather than a config error, which it does not.
    if (call_error == ENOENT || call_error == ENODEV || call_error == ENXIO ||
        call_error == EBUSY) {
      throw std::runtime_error(name + ": " + error);
    }
    throw common::ConfigError(name + ": " + error);
  }
}

V4l2Source::~V4l2Source() { Shutdown(); }

bool V4l2Source::Start(std::string* error, int* call_error) {
  int e = 0;  // errno of the last call; 0 after a success.
  auto fail = [&](std::string message) {
    *error = std::move(message);
    *call_error = e;
    Shutdown();
    return false;
  };
  if ((e = device_->Open()) != 0) {
    *error = "device: cannot open: " + ErrnoText(e);
    *call_error = e;
    return false;
  }
  open_ = true;

  v4l2_capability cap{};
  if ((e = device_->QueryCap(&cap)) != 0) {
    return fail("device: not a V4L2 device (VIDIOC_QUERYCAP: " + ErrnoText(e) + ")");
  }
  if (!IsStreamingCapture(cap)) {
    return fail(
        "device: not a streaming video capture node (a UVC camera's second node carries only "
        "metadata: try the other /dev/videoN of the camera)");
  }

  // Exactly the calibrated size in the configured format, or nothing.
  const std::uint32_t fourcc = FourCc(options_.format);
  const auto width = static_cast<std::uint32_t>(options_.width);
  const auto height = static_cast<std::uint32_t>(options_.height);
  const std::string wanted = FourCcText(fourcc) + " " + SizeText(width, height);
  v4l2_format format{};
  format.type = kCapture;
  format.fmt.pix.width = width;
  format.fmt.pix.height = height;
  format.fmt.pix.pixelformat = fourcc;
  format.fmt.pix.field = V4L2_FIELD_NONE;
  if ((e = device_->SetFormat(&format)) != 0) {
    return fail("format: the driver refused " + wanted + " (VIDIOC_S_FMT: " + ErrnoText(e) + ")");
  }
  auto granted = [&](const v4l2_format& f) {
    return f.fmt.pix.pixelformat == fourcc && f.fmt.pix.width == width &&
           f.fmt.pix.height == height;
  };
  auto mismatch = [&](const v4l2_format& f) {
    return "format: asked for " + wanted + " (the calibrated size), the driver gives " +
           FourCcText(f.fmt.pix.pixelformat) + " " + SizeText(f.fmt.pix.width, f.fmt.pix.height) +
           "; v4l2-ctl --list-formats-ext lists what the camera offers";
  };
  if (!granted(format)) return fail(mismatch(format));
  // Read back what the driver holds (stride and image size included).
  v4l2_format held{};
  held.type = kCapture;
  if ((e = device_->GetFormat(&held)) != 0) {
    return fail("format: VIDIOC_G_FMT failed: " + ErrnoText(e));
  }
  if (!granted(held)) return fail(mismatch(held));
  pixel_format_ = fourcc;
  const std::uint32_t min_line = options_.format == V4l2Options::Format::kYuyv   ? 2 * width
                                 : options_.format == V4l2Options::Format::kGrey ? width
                                                                                 : 0;
  bytes_per_line_ = std::max(held.fmt.pix.bytesperline, min_line);

  frame_period_ = std::chrono::nanoseconds(0);
  if (options_.frame_rate_hz) {
    const double rate = *options_.frame_rate_hz;
    v4l2_streamparm parm{};
    parm.type = kCapture;
    parm.parm.capture.timeperframe = FrameInterval(rate);
    if ((e = device_->SetParm(&parm)) != 0) {
      return fail("frame_rate_hz: the driver cannot set the frame rate (VIDIOC_S_PARM: " +
                  ErrnoText(e) + ")");
    }
    const v4l2_fract t = parm.parm.capture.timeperframe;
    if ((parm.parm.capture.capability & V4L2_CAP_TIMEPERFRAME) == 0 || t.numerator == 0 ||
        t.denominator == 0) {
      return fail("frame_rate_hz: the driver cannot set the frame rate");
    }
    const double got = static_cast<double>(t.denominator) / t.numerator;
    if (std::abs(got - rate) > 0.01 * rate) {
      return fail("frame_rate_hz: asked for " + Number(rate) + " Hz, the driver gives " +
                  Number(got) + " Hz for " + wanted +
                  "; v4l2-ctl --list-formats-ext lists the rates");
    }
    frame_period_ = std::chrono::nanoseconds(
        static_cast<std::int64_t>(1e9 * t.numerator / static_cast<double>(t.denominator)));
  }

  if (options_.exposure) {
    v4l2_control control{.id = V4L2_CID_EXPOSURE_AUTO, .value = V4L2_EXPOSURE_MANUAL};
    if ((e = device_->SetControl(&control)) != 0) {
      return fail("exposure: the driver refused manual exposure (exposure_auto: " + ErrnoText(e) +
                  ")");
    }
    control = {.id = V4L2_CID_EXPOSURE_ABSOLUTE, .value = *options_.exposure};
    if ((e = device_->SetControl(&control)) != 0) {
      return fail("exposure: the driver refused exposure_time_absolute " +
                  std::to_string(*options_.exposure) + " (" + ErrnoText(e) +
                  "); v4l2-ctl --list-ctrls gives its range");
    }
  }

  v4l2_requestbuffers request{};
  request.count = static_cast<std::uint32_t>(options_.buffers);
  request.type = kCapture;
  request.memory = V4L2_MEMORY_MMAP;
  if ((e = device_->RequestBuffers(&request)) != 0) {
    return fail("buffers: the driver refused mmap buffers (VIDIOC_REQBUFS: " + ErrnoText(e) + ")");
  }
  buffers_requested_ = true;
  if (request.count < 2) {
    return fail("buffers: the driver granted " + std::to_string(request.count) +
                " mmap buffers, streaming needs at least 2");
  }
  for (std::uint32_t i = 0; i < request.count; ++i) {
    v4l2_buffer buffer{};
    buffer.type = kCapture;
    buffer.memory = V4L2_MEMORY_MMAP;
    buffer.index = i;
    if ((e = device_->QueryBuffer(&buffer)) != 0) {
      return fail("buffers: VIDIOC_QUERYBUF " + std::to_string(i) + " failed: " + ErrnoText(e));
    }
    void* address = nullptr;
    if ((e = device_->Map(buffer.length, buffer.m.offset, &address)) != 0) {
      return fail("buffers: mmap of buffer " + std::to_string(i) + " failed: " + ErrnoText(e));
    }
    mappings_.push_back({address, buffer.length});
  }
  for (std::uint32_t i = 0; i < request.count; ++i) {
    v4l2_buffer buffer{};
    buffer.type = kCapture;
    buffer.memory = V4L2_MEMORY_MMAP;
    buffer.index = i;
    if ((e = device_->QueueBuffer(&buffer)) != 0) {
      return fail("buffers: VIDIOC_QBUF " + std::to_string(i) + " failed: " + ErrnoText(e));
    }
  }
  if ((e = device_->StreamOn(kCapture)) != 0) {
    return fail("device: VIDIOC_STREAMON failed: " + ErrnoText(e));
  }
  have_sequence_ = false;
  streaming_.store(true, std::memory_order_relaxed);
  return true;
}

void V4l2Source::Shutdown() {
  if (!open_) return;
  if (streaming_.load(std::memory_order_relaxed)) device_->StreamOff(kCapture);
  streaming_.store(false, std::memory_order_relaxed);
  for (const Mapping& m : mappings_) device_->Unmap(m.address, m.length);
  mappings_.clear();
  if (buffers_requested_) {
    // Frees the driver's buffers now rather than at close (fails harmlessly
    // on a vanished camera).
    v4l2_requestbuffers release{};
    release.count = 0;
    release.type = kCapture;
    release.memory = V4L2_MEMORY_MMAP;
    device_->RequestBuffers(&release);
    buffers_requested_ = false;
  }
  device_->Close();
  open_ = false;
}

void V4l2Source::Lose(const char* why) {
  disconnects_.fetch_add(1, std::memory_order_relaxed);
  log::Warn("v4l2[{}]: camera lost ({}): reopening, after {} ms and then up to every {} ms",
            options_.device, why, kFirstRetry.count(), kMaxRetry.count());
  Shutdown();
  backoff_ = kFirstRetry;
  retry_at_ = std::chrono::steady_clock::now() + backoff_;
  backoff_ = std::min(2 * backoff_, kMaxRetry);
  reopen_error_.clear();
}

bool V4l2Source::Next(Frame* frame, std::chrono::milliseconds timeout) {
  using Clock = std::chrono::steady_clock;
  const Clock::time_point give_up = Clock::now() + timeout;
  for (;;) {
    if (stopped_.load()) return false;
    Clock::time_point now = Clock::now();
    if (!streaming_.load(std::memory_order_relaxed)) {
      // Lost: reopen when the backoff allows, else wait for that (or give up).
      if (now >= retry_at_) {
        std::string error;
        int call_error = 0;
        if (Start(&error, &call_error)) {
          reconnects_.fetch_add(1, std::memory_order_relaxed);
          log::Info("v4l2[{}]: reopened, streaming again", options_.device);
          backoff_ = kFirstRetry;
          continue;
        }
        // Why it cannot come back (another size, another format, busy, gone):
        // said when it changes, and again every kRepeatLog while it lasts.
        if (error != reopen_error_ || now - reopen_error_logged_ >= kRepeatLog) {
          log::Warn("v4l2[{}]: cannot reopen (retrying up to every {} ms): {}", options_.device,
                    kMaxRetry.count(), error);
          reopen_error_ = error;
          reopen_error_logged_ = now;
        }
        retry_at_ = now + backoff_;
        backoff_ = std::min(2 * backoff_, kMaxRetry);
      }
      if (now >= give_up) return false;
      std::this_thread::sleep_until(std::min({retry_at_, give_up, now + kSlice}));
      continue;
    }

    const auto wait = std::clamp(std::chrono::ceil<std::chrono::milliseconds>(give_up - now),
                                 std::chrono::milliseconds(0), kSlice);
    short revents = 0;
    const int poll_error = device_->Poll(wait, &revents);
    if (poll_error != 0 && poll_error != EINTR) {
      Lose("poll failed");
      return false;
    }
    if ((revents & (POLLERR | POLLHUP | POLLNVAL)) != 0) {
      Lose("poll: error or hang-up");
      return false;
    }
    if ((revents & POLLIN) == 0) {
      if (Clock::now() >= give_up) return false;
      continue;
    }

    v4l2_buffer buffer{};
    buffer.type = kCapture;
    buffer.memory = V4L2_MEMORY_MMAP;
    const int dequeue_error = device_->DequeueBuffer(&buffer);
    if (dequeue_error == EAGAIN || dequeue_error == EINTR) {
      if (Clock::now() >= give_up) return false;
      continue;
    }
    if (dequeue_error != 0) {  // ENODEV, EIO (queue error) or worse: start over.
      Lose("VIDIOC_DQBUF failed");
      return false;
    }
    const bool ok = Convert(buffer, frame);
    v4l2_buffer requeue{};
    requeue.type = kCapture;
    requeue.memory = V4L2_MEMORY_MMAP;
    requeue.index = buffer.index;
    if (device_->QueueBuffer(&requeue) != 0) {
      Lose("VIDIOC_QBUF failed");
      if (ok) completed_.fetch_add(1, std::memory_order_relaxed);
      return ok;  // The frame itself is complete.
    }
    if (ok) {
      completed_.fetch_add(1, std::memory_order_relaxed);
      return true;
    }
    if (Clock::now() >= give_up) return false;
  }
}

bool V4l2Source::Convert(const v4l2_buffer& buffer, Frame* frame) {
  // Sequence numbers first: a corrupt frame is not a dropped one.
  std::uint32_t gap = 0;
  if (have_sequence_) {
    gap = buffer.sequence - last_sequence_ - 1;  // Modulo 2^32.
    if (gap >= (1u << 31)) gap = 0;              // Backwards: the driver restarted counting.
  }
  have_sequence_ = true;
  last_sequence_ = buffer.sequence;
  dropped_.fetch_add(gap, std::memory_order_relaxed);
  const std::uint64_t index = index_ + gap;
  index_ = index + 1;

  auto corrupt = [&] {
    corrupt_.fetch_add(1, std::memory_order_relaxed);
    return false;
  };
  if (buffer.index >= mappings_.size() || (buffer.flags & V4L2_BUF_FLAG_ERROR) != 0) {
    return corrupt();
  }
  const auto* data = static_cast<const std::uint8_t*>(mappings_[buffer.index].address);
  const std::size_t size = std::min<std::size_t>(buffer.bytesused, mappings_[buffer.index].length);
  const int w = options_.width;
  const int h = options_.height;

  if (pixel_format_ == V4L2_PIX_FMT_MJPEG) {
    // A transfer cut short leaves a JPEG without its end marker (UVC pads the
    // payload with zeros), which libjpeg would decode into a half grey image.
    if (size < 4 || data[0] != 0xFF || data[1] != 0xD8 ||
        !common::IsCompleteImage(std::string_view(reinterpret_cast<const char*>(data), size))) {
      return corrupt();
    }
    // imdecode reports a failure only by an empty result: into a Mat that
    // held the previous frame it would fail silently and leave that frame
    // there, to be delivered again with a new stamp. So each frame decodes
    // into a fresh Mat (one image-sized allocation, beside libjpeg's own).
    cv::Mat bgr;
    try {
      const cv::Mat bytes(1, static_cast<int>(size), CV_8UC1, const_cast<std::uint8_t*>(data));
      bgr = cv::imdecode(bytes, cv::IMREAD_COLOR | cv::IMREAD_IGNORE_ORIENTATION);
    } catch (const cv::Exception&) {
      return corrupt();
    }
    if (bgr.empty() || bgr.type() != CV_8UC3 || bgr.cols != w || bgr.rows != h) return corrupt();
    frame->kind = FrameKind::kRgb;
    frame->rgb.width = w;
    frame->rgb.height = h;
    frame->rgb.pixels.resize(static_cast<std::size_t>(w) * h * 3);
    cv::Mat rgb(h, w, CV_8UC3, frame->rgb.pixels.data());
    cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
  } else {
    const std::size_t pixel_bytes = pixel_format_ == V4L2_PIX_FMT_YUYV ? 2 : 1;
    const std::size_t needed =
        static_cast<std::size_t>(bytes_per_line_) * (h - 1) + pixel_bytes * w;
    if (size < needed) return corrupt();  // Truncated.
    if (pixel_format_ == V4L2_PIX_FMT_GREY) {
      frame->kind = FrameKind::kMono;
      frame->grey.width = w;
      frame->grey.height = h;
      frame->grey.pixels.resize(static_cast<std::size_t>(w) * h);
      for (int v = 0; v < h; ++v) {
        std::copy_n(data + static_cast<std::size_t>(v) * bytes_per_line_, w,
                    frame->grey.pixels.data() + static_cast<std::size_t>(v) * w);
      }
    } else {
      frame->kind = FrameKind::kRgb;
      frame->rgb.width = w;
      frame->rgb.height = h;
      frame->rgb.pixels.resize(static_cast<std::size_t>(w) * h * 3);
      const cv::Mat yuyv(h, w, CV_8UC2, const_cast<std::uint8_t*>(data), bytes_per_line_);
      cv::Mat rgb(h, w, CV_8UC3, frame->rgb.pixels.data());
      cv::cvtColor(yuyv, rgb, cv::COLOR_YUV2RGB_YUYV);
    }
  }

  if ((buffer.flags & V4L2_BUF_FLAG_TIMESTAMP_MASK) == V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC) {
    const std::int64_t monotonic_ns =
        static_cast<std::int64_t>(buffer.timestamp.tv_sec) * 1'000'000'000 +
        static_cast<std::int64_t>(buffer.timestamp.tv_usec) * 1000;
    frame->stamp_ns = monotonic_ns + RealtimeMinusMonotonicNs();
  } else {
    frame->stamp_ns = RealtimeNs() - frame_period_.count();
  }
  frame->index = index;
  return true;
}

}  // namespace hg::capture
