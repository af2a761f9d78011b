#pragma once
/// @file
/// Where a camera's frames come from. Each source runs on its camera's capture
/// thread; the pipeline never calls it from anywhere else.

#include <chrono>
#include <cstdint>

#include "common/image.h"

namespace hg::capture {

/// What a frame holds: a silhouette already (simulated cameras, mask
/// recordings) or an image for the background model.
enum class FrameKind : std::uint8_t {
  kMask,  ///< `grey` is a silhouette: foreground iff > 127.
  kMono,  ///< `grey` is a Mono8 image.
  kRgb,   ///< `rgb` is an RGB image.
};

/// A frame as a source delivers it (lens-distorted, camera-sized). Sources
/// refill the same Frame, so its buffers are reused from frame to frame.
struct Frame {
  FrameKind kind = FrameKind::kMask;
  common::ImageU8 grey;       ///< kMask and kMono.
  common::ImageRgb8 rgb;      ///< kRgb.
  std::int64_t stamp_ns = 0;  ///< Capture time, CLOCK_REALTIME.
  /// The camera's own timestamp (GigE Vision: the device clock, ns since its
  /// reset); -1 when the source has none. Kept in recordings, not used by the
  /// pipeline, whose time base is stamp_ns.
  std::int64_t device_stamp_ns = -1;
  std::uint64_t index = 0;  ///< Frame counter of the source.
};

/// Counters of a source's own transport (GigE Vision streams); all zero for
/// sources without one. Totals since the source was made, over reconnections.
struct TransportStats {
  std::uint64_t completed = 0;  ///< Complete frames delivered.
  std::uint64_t failed = 0;     ///< Failed, incomplete or unusable frames.
  std::uint64_t underruns = 0;  ///< Frames lost for lack of a free buffer (host too slow).
  std::uint64_t resends = 0;    ///< Packets the camera resent on request (lost on the way).
};

/// A camera source. Thread-compatible: one capture thread calls Next(); Stop()
/// may be called from any thread and makes a blocked Next() return soon.
class CameraSource {
 public:
  virtual ~CameraSource() = default;
  /// Waits for the next frame up to `timeout` and fills *frame, reusing its
  /// buffers. False on timeout, after Stop(), or when the camera fails.
  virtual bool Next(Frame* frame, std::chrono::milliseconds timeout) = 0;
  virtual void Stop() = 0;
  /// Frames the source received but could not use (unreadable, truncated).
  [[nodiscard]] virtual std::uint64_t corrupt_frames() const { return 0; }
  /// Transport counters; may be called from any thread while Next() runs.
  [[nodiscard]] virtual TransportStats transport_stats() const { return {}; }
  /// The source has lost its camera, or could not open it, and is retrying:
  /// no frames until it is back (the camera's status says `failed`). Any
  /// thread.
  [[nodiscard]] virtual bool failing() const { return false; }
  /// The pipeline's background model of this camera holds a learned
  /// background (learning ended, or a saved one was taken up). Called by the
  /// pipeline's silhouette worker after each frame once that holds; any
  /// thread. A staged scene (the simulator) keeps its people out until then.
  virtual void BackgroundLearned() {}
};

}  // namespace hg::capture
