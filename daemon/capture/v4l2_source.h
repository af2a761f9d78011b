#pragma once
/// @file
/// The `v4l2` camera source: a USB camera (UVC) through Video4Linux2, mmap
/// streaming, GREY, YUYV or MJPEG frames.

#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "capture/camera_source.h"
#include "capture/v4l2_device.h"

namespace hg::capture {

/// What the source asks of the driver. width and height are the calibrated
/// camera's size: the driver must deliver exactly that size (no scaling, the
/// calibration would not hold).
struct V4l2Options {
  std::string device;  ///< Device node, /dev/videoN.
  enum class Format { kGrey, kYuyv, kMjpeg } format = Format::kYuyv;
  std::optional<double> frame_rate_hz;  ///< Unset keeps the driver's rate.
  std::optional<int> exposure;          ///< exposure_time_absolute (100 us units); unset: auto.
  int width = 0;
  int height = 0;
  int buffers = 4;  ///< mmap buffers requested (2 .. 32); the driver may grant more.
};

/// Creates the (unopened) device for a node path; tests pass a fake.
using V4l2DeviceFactory = std::function<std::unique_ptr<V4l2Device>(const std::string& path)>;

/// A USB camera through Video4Linux2 memory-mapped streaming.
///
/// Start-up, in the constructor, in the documented V4L2 streaming order:
/// Open, VIDIOC_QUERYCAP (a capture device that streams), VIDIOC_S_FMT (then
/// VIDIOC_G_FMT to read back what the driver holds), VIDIOC_S_PARM when a
/// frame rate is set, VIDIOC_S_CTRL exposure_auto = manual and
/// exposure_time_absolute when an exposure is set, VIDIOC_REQBUFS,
/// VIDIOC_QUERYBUF + mmap per buffer, VIDIOC_QBUF of every buffer,
/// VIDIOC_STREAMON. Next() polls, VIDIOC_DQBUFs the oldest filled buffer,
/// converts it into the frame and VIDIOC_QBUFs it again at once. Shutdown:
/// VIDIOC_STREAMOFF, munmap, VIDIOC_REQBUFS with 0 buffers, close.
///
/// Formats:
/// - GREY -> FrameKind::kMono.
/// - YUYV -> FrameKind::kRgb (OpenCV, BT.601 video range, the V4L2 default
///   for YUYV). Not grey from the Y channel, although that would be cheaper
///   and the background model takes grey frames too: a person whose clothes
///   are as bright as the background behind them but of another colour
///   differs from it only in chroma, and a grey frame would certify that
///   person's pixels as background. Colour can only add foreground.
/// - MJPEG -> FrameKind::kRgb, decoded with OpenCV (imdecode, then BGR to
///   RGB into the frame's reused buffer). The decoder allocates per frame
///   (libjpeg's working memory and the decoded image: imdecode signals a
///   failed decode only by an empty result, so it never decodes into a
///   buffer that still holds the previous frame). A JPEG without its start
///   or end marker, one that does not decode, or one of another size is
///   counted in corrupt_frames() and skipped.
/// A buffer the driver flags V4L2_BUF_FLAG_ERROR, or one too short for the
/// format, is counted in corrupt_frames() and skipped.
///
/// Timestamps: the driver's buffer timestamp (CLOCK_MONOTONIC for every
/// mainline driver, V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC; uvcvideo estimates the
/// start of exposure) moved to CLOCK_REALTIME by the current offset between the two
/// clocks. A driver without monotonic timestamps gets the dequeue time minus
/// one frame period (when frame_rate_hz is set), an estimate that the
/// transfer delay makes late.
///
/// Frame index: counts the driver's sequence numbers, so a gap in the
/// sequence (the driver had no free buffer and dropped frames) is counted in
/// dropped_frames() and skips as many indices.
///
/// A camera that vanishes (unplugged, USB reset: POLLERR/POLLHUP, or ENODEV,
/// EIO or any other error from VIDIOC_DQBUF/VIDIOC_QBUF) is closed, Next()
/// returns false, and later calls to Next() reopen and reconfigure it, trying
/// again after 100 ms, doubling to at most 2 s, until it is back; the frames
/// then flow again (the pipeline treats the silent camera as seeing nothing
/// meanwhile). Re-enumeration may give the camera another /dev/videoN: name
/// it by its stable /dev/v4l/by-id/ or by-path/ link.
///
/// After start-up GREY and YUYV frames allocate nothing; MJPEG frames
/// allocate inside the decoder. Thread-compatible: one capture thread calls Next(); Stop() and the
/// counters may be called from any thread.
class V4l2Source : public CameraSource {
 public:
  /// Opens and configures the camera and starts streaming.
  /// @throws common::ConfigError "<device>: <key>: <problem>" for bad options,
  /// a node that cannot be opened (permissions) or is not a streaming capture
  /// device, and a format, size, frame rate or exposure that the driver does
  /// not grant: a person has to change something.
  /// @throws std::runtime_error when the camera is absent (ENOENT, ENODEV,
  /// ENXIO: unplugged, not enumerated yet) or busy (EBUSY: another program
  /// streams from it): the daemon exits as unable to run and systemd starts
  /// it again.
  explicit V4l2Source(V4l2Options options, V4l2DeviceFactory factory = OpenSystemV4l2Device);
  ~V4l2Source() override;
  V4l2Source(const V4l2Source&) = delete;
  V4l2Source& operator=(const V4l2Source&) = delete;

  bool Next(Frame* frame, std::chrono::milliseconds timeout) override;
  void Stop() override { stopped_.store(true); }
  /// Lost and reopening (the constructor opened it; it throws when it cannot).
  [[nodiscard]] bool failing() const override { return !streaming(); }
  [[nodiscard]] std::uint64_t corrupt_frames() const override {
    return corrupt_.load(std::memory_order_relaxed);
  }
  /// The status's transport counters: frames delivered (`completed`),
  /// corrupt ones (`failed`) and the driver's drops (`underruns`: it had no
  /// free buffer, the host was too slow); no resends.
  [[nodiscard]] TransportStats transport_stats() const override {
    TransportStats s;
    s.completed = completed_.load(std::memory_order_relaxed);
    s.failed = corrupt_.load(std::memory_order_relaxed);
    s.underruns = dropped_.load(std::memory_order_relaxed);
    return s;
  }
  /// Frames the driver dropped (gaps in its sequence numbers).
  [[nodiscard]] std::uint64_t dropped_frames() const {
    return dropped_.load(std::memory_order_relaxed);
  }
  /// Times the camera was lost while streaming.
  [[nodiscard]] std::uint64_t disconnects() const {
    return disconnects_.load(std::memory_order_relaxed);
  }
  /// Times it was reopened and streams again after a loss.
  [[nodiscard]] std::uint64_t reconnects() const {
    return reconnects_.load(std::memory_order_relaxed);
  }
  /// Streaming now (false while the camera is lost).
  [[nodiscard]] bool streaming() const { return streaming_.load(std::memory_order_relaxed); }

 private:
  struct Mapping {
    void* address = nullptr;
    std::size_t length = 0;
  };

  /// Open to STREAMON. On failure everything is undone, *error says why
  /// ("<key>: <problem>") and *call_error is the errno of the call that failed
  /// (0 when the driver answered but did not grant the request).
  bool Start(std::string* error, int* call_error);
  /// STREAMOFF, munmap, REQBUFS 0, close; ignores errors (the camera may be gone).
  void Shutdown();
  /// The camera failed while streaming (`why`, logged): close it and
  /// schedule a reopen.
  void Lose(const char* why);
  /// Fills *frame from a dequeued buffer; false when the buffer is unusable.
  bool Convert(const v4l2_buffer& buffer, Frame* frame);

  V4l2Options options_;
  std::unique_ptr<V4l2Device> device_;
  std::uint32_t pixel_format_ = 0;
  std::uint32_t bytes_per_line_ = 0;
  std::chrono::nanoseconds frame_period_{0};  // As granted by S_PARM; 0 when not set.
  std::vector<Mapping> mappings_;             // Capacity for the most buffers, reserved once.
  bool open_ = false;                         // device_ opened (possibly half configured).
  bool buffers_requested_ = false;            // REQBUFS granted buffers (freed at shutdown).
  bool have_sequence_ = false;                // last_sequence_ is valid (since the last start).
  std::uint32_t last_sequence_ = 0;
  std::uint64_t index_ = 0;  // Index of the next frame without a gap.
  std::chrono::steady_clock::time_point retry_at_;
  std::chrono::milliseconds backoff_{0};
  std::atomic<bool> streaming_{false};
  std::atomic<bool> stopped_{false};
  std::string reopen_error_;  // The last reopen failure logged, and when.
  std::chrono::steady_clock::time_point reopen_error_logged_;
  std::atomic<std::uint64_t> completed_{0};
  std::atomic<std::uint64_t> corrupt_{0};
  std::atomic<std::uint64_t> dropped_{0};
  std::atomic<std::uint64_t> disconnects_{0};
  std::atomic<std::uint64_t> reconnects_{0};
};

}  // namespace hg::capture
