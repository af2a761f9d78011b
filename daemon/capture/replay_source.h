#pragma once
/// @file
/// The `replay` camera source: one camera of a recording folder (`hullguard
/// record`, the black box or `hullguard synth`) played back, in real time or
/// as fast as it is consumed.

#include <atomic>
#include <chrono>
#include <cstdint>
#include <string>
#include <utility>
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

/// How a ReplaySource plays its recording.
struct ReplayOptions {
  ReplayPacing pacing = ReplayPacing::kRealtime;
  /// Every frame is read and decoded at construction and kept in memory; a
  /// frame is then delivered by a copy, without disk or decoder (long soak
  /// runs, and load tests of the daemon's own cost).
  bool preload = false;
  /// After the last frame the recording plays again from its frame at
  /// `loop_start_s` (recording time), and on for ever: capture times go on
  /// increasing, each repetition one loop length (from that frame to one
  /// frame interval after the last) after the one before. A recording that
  /// begins with the empty cell for the background model to learn keeps that
  /// stretch out of the loop.
  bool loop = false;
  double loop_start_s = 0.0;
  /// With `loop`: how much later each repetition plays, at least the
  /// camera's own loop length (LoopLengthNs; 0: exactly that). Cameras played
  /// together must share one (the longest of theirs): each keeps its own
  /// frames' times, so their frames stay in step however many repetitions
  /// go by, where lengths one frame apart (a camera whose recording dropped
  /// its last frame) would drift a frame further apart every repetition.
  std::int64_t loop_period_ns = 0;
};

/// The length of one repetition of `recording`'s loop from `loop_start_s`
/// (ReplayOptions::loop): from the first frame at or after it to one frame
/// interval (the looped frames' mean) after the last frame.
/// @throws common::ConfigError when fewer than two frames lie at or after
/// loop_start_s, or when the last of them is not later than the first (the
/// recording's stamps stepped back).
[[nodiscard]] std::int64_t LoopLengthNs(const RecordingCamera& recording, double loop_start_s);

/// Plays one camera of a recording: masks (FrameKind::kMask), Mono8 or RGB
/// frames as recorded (synth recordings with masks play their masks, else
/// their colour frames). After the last frame it delivers nothing more, as a
/// camera that stopped (unless it loops, ReplayOptions). An unreadable frame
/// is counted in corrupt_frames() and skipped, each time it comes round. Paced
/// by sleeping in Next() (capture thread only).
class ReplaySource : public CameraSource {
 public:
  /// @throws common::ConfigError as LoopLengthNs() with `loop`.
  ReplaySource(RecordingCamera recording, SimClock clock, const ReplayOptions& options);
  ReplaySource(RecordingCamera recording, SimClock clock,
               ReplayPacing pacing = ReplayPacing::kRealtime)
      : ReplaySource(std::move(recording), clock, ReplayOptions{.pacing = pacing}) {}

  bool Next(Frame* frame, std::chrono::milliseconds timeout) override;
  void Stop() override { stopped_.store(true); }
  [[nodiscard]] std::uint64_t corrupt_frames() const override {
    return corrupt_.load(std::memory_order_relaxed);
  }
  /// A camera the recording holds no frame of (lost before the recording
  /// began) replays as one that never answers: `failed`.
  [[nodiscard]] bool failing() const override { return recording_.frames.empty(); }

  /// Bytes of the frames held in memory (ReplayOptions::preload), 0 without.
  [[nodiscard]] std::size_t preloaded_bytes() const { return preloaded_bytes_; }

  /// Lock-step use (`hullguard replay`): reads frame `index` into *frame
  /// without pacing, stamped with the clock's epoch plus its recording time,
  /// from its file (preloaded or not; no loop). False when the file is missing
  /// or unreadable.
  bool ReadFrame(int index, Frame* frame);
  [[nodiscard]] const RecordingCamera& recording() const { return recording_; }
  /// Number of frames in the recording.
  [[nodiscard]] int frames() const { return static_cast<int>(recording_.frames.size()); }

 private:
  // Frames are numbered in playing order, repetitions of a loop included:
  // frame n of the play is FrameAt(n) of the recording, OffsetNs(n) late.
  [[nodiscard]] bool Ended(std::int64_t n) const { return !loop_ && n >= frames(); }
  [[nodiscard]] int FrameAt(std::int64_t n) const;
  [[nodiscard]] std::int64_t OffsetNs(std::int64_t n) const;
  [[nodiscard]] std::chrono::steady_clock::time_point Due(std::int64_t n) const;
  [[nodiscard]] std::int64_t StampOf(std::int64_t n) const;
  /// Frame n of the play into *frame, all but its stamp; false (counted
  /// corrupt) when it cannot be read.
  bool Load(std::int64_t n, Frame* frame);

  RecordingCamera recording_;
  SimClock clock_;
  ReplayPacing pacing_;
  bool loop_ = false;
  int loop_first_ = 0;               // First frame of each repetition after the first.
  std::int64_t loop_period_ns_ = 0;  // How much later each repetition plays.
  std::uint64_t index_stride_ = 0;   // Frame counter added per repetition.
  std::vector<Frame> preloaded_;     // With preload: every frame (no pixels where unreadable).
  std::size_t preloaded_bytes_ = 0;
  std::int64_t next_ = 0;                  // Next frame of the play.
  std::vector<unsigned char> file_bytes_;  // Reused read buffer.
  std::string path_;                       // Reused path buffer.
  std::atomic<bool> stopped_{false};
  std::atomic<std::uint64_t> corrupt_{0};
};

}  // namespace hg::capture
