#pragma once
/// @file
/// The `sim` camera source: one camera of a simulated scene, rendered live.

#include <atomic>
#include <chrono>
#include <memory>
#include <vector>

#include "capture/camera_source.h"
#include "sim/mask_renderer.h"
#include "sim/scene.h"

namespace hg::capture {

/// The simulated scene's clock: scene time 0 is the steady instant `start`,
/// which was `epoch_ns` on the system clock. A frame's stamp minus epoch_ns is
/// the scene time it shows, so ground truth can be evaluated for any stamp.
struct SimClock {
  std::chrono::steady_clock::time_point start;
  std::int64_t epoch_ns = 0;
  /// Scene time 0 = now.
  static SimClock Now();
};

/// Renders ground-truth masks of camera `camera_index` of a scene in real time.
/// The camera captures at scene times offset + k / rate_hz (offset: the
/// camera's capture offset in the scene, modulo the period, as free-running
/// cameras do); each frame shows the scene at its capture time and is stamped
/// with it. Paced by sleeping in Next() (capture thread only); frames that fall
/// due while the thread is busy are skipped, as a camera's would be.
class SimSource : public CameraSource {
 public:
  SimSource(std::shared_ptr<const sim::Scene> scene, int camera_index, double rate_hz,
            SimClock clock);

  bool Next(Frame* frame, std::chrono::milliseconds timeout) override;
  void Stop() override { stopped_.store(true); }

  /// While paused the camera delivers nothing, as a camera whose cable was
  /// pulled (tests and demos of a lost camera).
  void SetPaused(bool paused) { paused_.store(paused); }

  /// Fault injection: no frame is captured after this many seconds of scene
  /// time (set before the capture thread starts).
  void SetStopAfter(double seconds) { stop_after_ = std::chrono::duration<double>(seconds); }

  /// Colour frames instead of masks, so that the silhouette pipeline runs its
  /// background model on them (call before the capture thread starts). Made
  /// cheaply enough for 8 Full HD cameras at 30 Hz: the empty cell is rendered
  /// once (sim::ColourRenderer, noise-free), and each frame is a copy of it in
  /// which the people's pixels (the ground-truth mask) are painted 100 grey
  /// levels off the background in every channel, plus sensor noise from a
  /// precomputed table. No light changes, no shadows: for the pipeline's load
  /// and conservativeness, not for the background model's realism (which
  /// `hullguard synth --colour` recordings test). People are left out for the
  /// first `empty_s` seconds: the cell is empty while the model learns it.
  /// With `bayer`, each frame is the raw BayerRG8 mosaic of that image
  /// (FrameKind::kMono), as a GigE colour camera delivers it.
  void EnableColour(double empty_s, bool bayer = false);

  /// Holds the people of a group of colour sources out of their frames until
  /// the background model of every camera of the group has learned the empty
  /// cell (each calls BackgroundLearned()), however late or slowly that is:
  /// after `empty_s` alone, a start-up slower than it (a loaded machine) had
  /// the models learn the people in, and report them free. Thread-safe.
  class PeopleGate {
   public:
    explicit PeopleGate(int cameras) : waiting_(cameras) {}
    void Learned() { waiting_.fetch_sub(1); }
    [[nodiscard]] bool open() const { return waiting_.load() <= 0; }

   private:
    std::atomic<int> waiting_;
  };
  /// Colour mode: people also wait for `gate` (set before the capture thread starts).
  void HoldPeopleUntilLearned(std::shared_ptr<PeopleGate> gate) { gate_ = std::move(gate); }
  void BackgroundLearned() override {
    if (gate_ && !learned_.load(std::memory_order_relaxed) && !learned_.exchange(true)) {
      gate_->Learned();
    }
  }
  /// Colour mode: the capture stamp of the first frame that showed the
  /// people (CLOCK_REALTIME ns); 0 before.
  [[nodiscard]] std::int64_t people_shown_from_ns() const { return people_from_ns_.load(); }

 private:
  std::shared_ptr<const sim::Scene> scene_;
  int camera_index_;
  std::chrono::nanoseconds period_;
  SimClock clock_;
  std::chrono::steady_clock::time_point next_;
  sim::MaskRenderer renderer_;
  std::vector<sim::BodyState> people_;
  std::uint64_t index_ = 0;
  std::atomic<bool> stopped_{false};
  std::atomic<bool> paused_{false};
  std::chrono::duration<double> stop_after_{std::chrono::duration<double>::max()};
  // Colour mode (EnableColour): the empty cell, the noise table, scratch.
  bool colour_ = false;
  bool bayer_ = false;
  double empty_s_ = 0.0;
  std::shared_ptr<PeopleGate> gate_;
  std::atomic<bool> learned_{false};  // This camera counted in gate_.
  std::atomic<std::int64_t> people_from_ns_{0};
  std::vector<std::uint8_t> empty_;     // RGB, or the mosaic.
  std::vector<std::uint8_t> painted_;   // The empty cell 100 grey levels off: the people's colour.
  std::vector<std::uint8_t> noise_up_;  // The noise where positive, 0 elsewhere.
  std::vector<std::uint8_t> noise_down_;  // Minus the noise where negative, 0 elsewhere.
  common::ImageU8 mask_;
};

}  // namespace hg::capture
