#pragma once
/// @file
/// The `replay` camera source: one camera of a recording folder played back in
/// real time.

#include <atomic>
#include <chrono>
#include <string>
#include <vector>

#include "capture/camera_source.h"
#include "capture/sim_source.h"

namespace hg::capture {

/// What a recording folder holds for one camera (read from manifest.yaml, the
/// layout `hullguard synth` writes; docs/synth.md).
struct RecordingCamera {
  std::string directory;
  std::string camera;
  double rate_hz = 30.0;
  double time_offset_s = 0.0;  ///< This camera's capture offset within a frame period.
  int frames = 0;
  bool masks = false;   ///< masks/<camera>/NNNNNN.png present (preferred).
  bool colour = false;  ///< colour/<camera>/NNNNNN.png present.
};

/// Reads the manifest of a recording folder for one camera.
/// @throws common::ConfigError naming the file when the manifest is missing or
/// bad, or does not list the camera.
[[nodiscard]] RecordingCamera ReadRecordingCamera(const std::string& directory,
                                                  const std::string& camera);

/// Plays frame i of the camera at i / rate_hz + its offset after the clock's
/// start, stamped with that instant, from its masks (FrameKind::kMask) or, when
/// the recording has none, its colour frames (FrameKind::kRgb, for the
/// background model). After the last frame it delivers nothing more, as a
/// camera that stopped. An unreadable frame is counted in corrupt_frames()
/// and skipped. Paced by sleeping in Next() (capture thread only).
class ReplaySource : public CameraSource {
 public:
  ReplaySource(RecordingCamera recording, SimClock clock);

  bool Next(Frame* frame, std::chrono::milliseconds timeout) override;
  void Stop() override { stopped_.store(true); }
  [[nodiscard]] std::uint64_t corrupt_frames() const override {
    return corrupt_.load(std::memory_order_relaxed);
  }

  /// Lock-step use (`hullguard replay`): reads frame `index` into *frame
  /// without pacing, stamped with the clock's epoch plus its capture time
  /// (index / rate_hz + the camera's offset). False when the file is missing
  /// or unreadable.
  bool ReadFrame(int index, Frame* frame);
  [[nodiscard]] const RecordingCamera& recording() const { return recording_; }

 private:
  [[nodiscard]] std::chrono::steady_clock::time_point Due(int index) const;
  bool Load(int index, Frame* frame);

  RecordingCamera recording_;
  SimClock clock_;
  std::chrono::duration<double> offset_;
  int next_index_ = 0;
  std::vector<unsigned char> file_bytes_;  // Reused read buffer.
  std::string path_;                       // Reused path buffer.
  std::atomic<bool> stopped_{false};
  std::atomic<std::uint64_t> corrupt_{0};
};

}  // namespace hg::capture
