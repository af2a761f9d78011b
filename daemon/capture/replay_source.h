#pragma once
/// @file
/// The `replay` camera source: one camera of a recording folder (`hullguard
/// record`, the black box or `hullguard synth`) played back, in real time or
/// as fast as it is consumed.

#include <atomic>
#include <chrono>
#include <string>
#include <vector>

#include "capture/camera_source.h"
#include "capture/recording.h"
#include "capture/sim_source.h"

namespace hg::capture {

/// How a ReplaySource paces its frames.
enum class ReplayPacing : std::uint8_t {
  /// Each frame at its recorded capture time after the clock's start,
  /// stamped with that instant; frames that fell due while the capture thread
  /// was busy are skipped, as a camera's would be.
  kRealtime,
  /// Every frame, in order, as soon as Next() is called, stamped with the
  /// host time of delivery (CLOCK_REALTIME). For load tests: cameras are not
  /// kept in step with each other, so the occupancy is not the recorded
  /// scene's; `hullguard replay` is the faithful fast replay.
  kFast,
};

/// Plays one camera of a recording: masks (FrameKind::kMask), Mono8 or RGB
/// frames as recorded (synth recordings with masks play their masks, else
/// their colour frames). After the last frame it delivers nothing more, as a
/// camera that stopped. An unreadable frame is counted in corrupt_frames()
/// and skipped. Paced by sleeping in Next() (capture thread only).
class ReplaySource : public CameraSource {
 public:
  ReplaySource(RecordingCamera recording, SimClock clock,
               ReplayPacing pacing = ReplayPacing::kRealtime);

  bool Next(Frame* frame, std::chrono::milliseconds timeout) override;
  void Stop() override { stopped_.store(true); }
  [[nodiscard]] std::uint64_t corrupt_frames() const override {
    return corrupt_.load(std::memory_order_relaxed);
  }

  /// Lock-step use (`hullguard replay`): reads frame `index` into *frame
  /// without pacing, stamped with the clock's epoch plus its recording time.
  /// False when the file is missing or unreadable.
  bool ReadFrame(int index, Frame* frame);
  [[nodiscard]] const RecordingCamera& recording() const { return recording_; }
  /// Number of frames in the recording.
  [[nodiscard]] int frames() const { return static_cast<int>(recording_.frames.size()); }

 private:
  [[nodiscard]] std::chrono::steady_clock::time_point Due(int index) const;
  [[nodiscard]] std::int64_t StampOf(int index) const;

  RecordingCamera recording_;
  SimClock clock_;
  ReplayPacing pacing_;
  int next_index_ = 0;
  std::vector<unsigned char> file_bytes_;  // Reused read buffer.
  std::string path_;                       // Reused path buffer.
  std::atomic<bool> stopped_{false};
  std::atomic<std::uint64_t> corrupt_{0};
};

}  // namespace hg::capture
