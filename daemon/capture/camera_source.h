#pragma once
/// @file
/// Where a camera's frames come from. Each source runs on its camera's capture
/// thread; the pipeline never calls it from anywhere else.

#include <chrono>
#include <cstdint>

#include "common/image.h"

namespace hg::capture {

/// A silhouette frame as a source delivers it (lens-distorted, camera-sized).
struct MaskFrame {
  common::ImageU8 mask;       ///< Foreground iff > 127.
  std::int64_t stamp_ns = 0;  ///< Capture time, CLOCK_REALTIME.
  std::uint64_t index = 0;    ///< Frame counter of the source.
};

/// A camera source. Thread-compatible: one capture thread calls Next(); Stop()
/// may be called from any thread and makes a blocked Next() return soon.
class CameraSource {
 public:
  virtual ~CameraSource() = default;
  /// Waits for the next frame up to `timeout` and fills *frame, reusing its
  /// buffers. False on timeout, after Stop(), or when the camera fails.
  virtual bool Next(MaskFrame* frame, std::chrono::milliseconds timeout) = 0;
  virtual void Stop() = 0;
};

}  // namespace hg::capture
