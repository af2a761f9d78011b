#pragma once
/// @file
/// The reconstruction pipeline: a capture thread per camera, a fusion thread
/// at a fixed rate, and immutable occupancy snapshots for the consumers.

#include <atomic>
#include <chrono>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "capture/camera_health.h"
#include "capture/camera_source.h"
#include "common/heartbeat.h"
#include "common/latest_value.h"
#include "common/shared_slot.h"
#include "geometry/camera.h"
#include "geometry/mesh.h"
#include "octree/octree.h"
#include "pipeline/blob_filter.h"
#include "pipeline/published_grid.h"
#include "pipeline/snapshot.h"
#include "silhouette/background_model.h"
#include "silhouette/hole_fill.h"
#include "silhouette/quadtree.h"
#include "silhouette/tile_dilation.h"
#include "silhouette/undistort.h"

namespace hg::pipeline {

class BlackBox;

struct PipelineOptions {
  common::Box3 bounds;
  int depth = 9;
  int boundary_coarsening = octree::OctreeConfig{}.boundary_coarsening;
  int coarse_first_depth = octree::OctreeConfig{}.coarse_first_depth;
  int key_level = 0;           ///< octree::OctreeConfig::key_level.
  std::int64_t max_nodes = 0;  ///< octree::OctreeConfig::max_nodes.
  int octree_threads = 2;
  double rate_hz = 30.0;
  double deadline_ms = 25.0;
  /// Phase-lock the fusion cycle to the cameras' frames (CyclePhase): each
  /// cycle starts about `align_margin_ms` after the last frame of a capture
  /// instant is ready. Off: the cycle keeps the phase it started with.
  bool align_to_frames = true;
  double align_margin_ms = 2.0;
  /// Silhouette worker threads (background model, undistortion): 0 gives
  /// every camera its own; N > 0 shares N among all cameras, each taking the
  /// cameras' newest frames in turn.
  int silhouette_workers = 0;
  /// Knowledge filter (BlobFilter) on the published grid: isolated occupied
  /// blobs below this volume (m^3) are dropped. 0: off. It frees space the
  /// cameras did not certify.
  double knowledge_filter_m3 = 0.0;
  /// Depth of the published grid (<= depth): each published cell is occupied
  /// when any leaf inside it is, so coarser publishing stays conservative.
  int publish_depth = 7;
  /// Capture skew: cameras' newest frames are taken at different instants. The
  /// snapshot is made valid for the newest capture time T: a camera whose
  /// frame is from t_i < T certifies a box free only when it saw background
  /// everywhere within max_speed_mps * (T - t_i) of it (octree margins).
  /// It must bound every part of a person: a walker's swinging foot moves at
  /// up to three times the walking speed, so ISO 13855's 2.0 m/s approach
  /// speed is too low for this.
  double max_speed_mps = 5.0;
  /// Stamp each snapshot with the median of the cameras' capture times
  /// instead of the newest: the cameras that captured together (most of a
  /// rig whose few free-running cameras drift) then need no margin, and only
  /// the others do, at the cost of up to half the skew in the snapshot's age.
  bool stamp_at_median = false;
  /// Turns image frames (colour or Mono8 sources) into silhouettes.
  silhouette::BackgroundModelOptions background;
  /// The background model's foreground is grown by this many pixels: a
  /// person's pixel whose colour happens to match the background is covered
  /// by its neighbours (holes and ragged edges of the silhouette).
  int background_dilate_px = 2;
  /// After the dilation, background pixels that the foreground encloses (no
  /// path of background pixels leads from them to the image border) become
  /// foreground (silhouette::FillEnclosedBackground): a person's inside
  /// whose colour matches the background over more than the dilation.
  bool background_fill_holes = true;
  /// Where each camera's learned background is kept across restarts
  /// (`background-<camera>.bin`; empty: nowhere, every start learns). A camera
  /// whose file is there and fits takes it up instead of learning: a person
  /// in the cell when the daemon restarts stays foreground. A camera that
  /// learns (no file, or one that does not fit) writes its file when learning
  /// ends (making the folder if it is missing). To learn again, remove the
  /// files while the daemon is stopped.
  std::string background_dir;
  /// What a camera with a background model does at start.
  enum class BackgroundStart {
    /// Takes up its kept background (background_dir), or else learns.
    kLearn,
    /// Takes up its kept background, or else learns nothing and sees nothing
    /// (capture::CameraFault::kUnlearned: failed, the status degraded) until
    /// one is taught: a restart never learns whoever stands in the cell.
    kKeptOnly,
    /// Learns afresh whatever is kept, and keeps what it learned (teaching
    /// the empty cell: `hullguardd --learn-background`).
    kRelearn,
  };
  BackgroundStart background_start = BackgroundStart::kLearn;
  /// SCHED_FIFO priority of the fusion thread (0: normal scheduling). Where
  /// the system refuses it, a warning is logged and the thread runs as is.
  int fusion_realtime_priority = 0;
};

struct PipelineCamera {
  geometry::CameraModel model;  ///< As calibrated (may distort).
  /// May be null in lock-step use (Feed() and Step(), no Start()).
  std::unique_ptr<capture::CameraSource> source;
  int timeout_ms = 200;  ///< Silent longer than this: the camera sees nothing.
  /// Its one-byte frames are raw Bayer mosaics, not grey: the background
  /// model compares each photosite in its own colour, and the texture test
  /// (BackgroundModelOptions::texture_threshold) is left off, the colours
  /// telling what it would (and it would cost 0.2-0.4 ms a Full HD frame).
  bool bayer_mosaic = false;
};

/// Capture thread per camera: source -> a latest-value handoff of raw frames
/// (newest frame wins, overwritten frames counted as drops) -> silhouette
/// worker (one per camera, or a shared few): background model, conservative
/// undistortion -> a latest-value slot of masks (again newest wins, drops
/// counted). A slow silhouette step never holds up the capture: it skips to
/// the newest frame. Fusion thread every 1 / rate_hz, phase-locked to the
/// frames (CyclePhase): takes each camera's newest mask and builds that
/// camera's quadtree itself (so the changed flags are always relative to what
/// the octree last saw), treats a camera silent for longer than its timeout
/// as seeing nothing, updates the octree under the deadline, and publishes a
/// snapshot, after the knowledge filter when one is configured. Snapshots
/// are reused from a small pool once no consumer holds them: after warm-up a
/// cycle allocates nothing.
///
/// The consumer runs on the fusion thread after each cycle; it must be quick
/// (hand the snapshot to another thread for slow work).
///
/// Capture skew: a camera's background certifies space free only at its own
/// capture time t_i. The snapshot is stamped with the newest capture time T of
/// the cameras used (or their median, stamp_at_median), and each camera
/// certifies a box free only when it saw background, in its view and in
/// front of its obstacles, everywhere within the distance a person can move
/// in |T - t_i| of the box (octree::Octree's
/// margins: the box grown in 3D, so the growth is as small in the image as
/// the distance makes it, and an obstacle hides only what lies behind it,
/// grown by that distance), so the published occupancy holds every person as
/// they were at T. Margins are rounded up (octree::Octree::RoundMargin) and lowered only
/// after kMarginHoldNs without need (each change makes the octree recompute
/// that camera everywhere), except while the running cycle is not yet
/// phase-locked to the frames (timing.align_to_frames): at start-up the
/// cameras' first frames arrive out of step, and holding the margins of that
/// moment would fatten the occupancy for the hold's length. Consumers add their own reaction time
/// to the stamp's age, as for any safety sensor.
class Pipeline {
 public:
  /// A margin is lowered only after this long (ns) without a lag needing it.
  static constexpr std::int64_t kMarginHoldNs = 2'000'000'000;
  /// Snapshots made at construction: the newest (Latest()), one being
  /// filled, and for each of the daemon's two consumers (the occupancy
  /// publisher and tracking) the three its handoff (common::LatestValue)
  /// holds and the one it works on, plus two for readers of Latest().
  static constexpr int kSnapshotPool = 1 + 1 + 2 * (3 + 1) + 2;

  using Consumer = std::function<void(const std::shared_ptr<const OccupancySnapshot>&)>;

  /// `heartbeats` (optional, must outlive the pipeline) gets one stage per
  /// capture thread ("capture <camera>"), one per silhouette worker
  /// ("silhouette <camera>", or "silhouette <n>" when shared) and one for
  /// fusion ("fusion"), each beaten every loop iteration.
  Pipeline(const PipelineOptions& options, std::vector<PipelineCamera> cameras,
           const std::vector<geometry::TriangleMesh>& obstacles, Consumer consumer,
           common::Heartbeats* heartbeats = nullptr);
  ~Pipeline();
  Pipeline(const Pipeline&) = delete;
  Pipeline& operator=(const Pipeline&) = delete;

  /// Before Start(): every captured frame is also pushed into `box` (a copy
  /// into a preallocated slot, after the frame was processed). `box` must
  /// outlive the pipeline's threads.
  void SetBlackBox(BlackBox* box) { black_box_ = box; }

  void Start();
  /// Stops every thread and returns when they have ended (within about 100 ms).
  void Stop();

  /// Lock-step use (replay, tests), without Start(): hands camera `camera` a
  /// frame as its capture thread would (background model, undistortion), and
  /// runs one fusion cycle at `now_ns` without a deadline. Deterministic: the
  /// same frames and times give the same snapshot whatever the thread count.
  void Feed(int camera, const capture::Frame& frame) { ProcessFrame(camera, frame); }
  std::shared_ptr<const OccupancySnapshot> Step(std::int64_t now_ns);

  /// The newest snapshot (nullptr before the first cycle). Thread-safe.
  [[nodiscard]] std::shared_ptr<const OccupancySnapshot> Latest() const { return latest_.Load(); }

  /// Whether camera `camera` kept the background it learned (background_dir):
  /// nullopt while it has not finished learning (or learns nothing: a mask
  /// source, or one that took up a kept background), else whether its file
  /// was written. Thread-safe.
  [[nodiscard]] std::optional<bool> BackgroundSaved(int camera) const;
  /// Whether camera `camera` turns images into silhouettes with a background
  /// model (its frames so far were images, not masks). Thread-safe.
  [[nodiscard]] bool HasBackgroundModel(int camera) const;

  /// At least this share of a camera's view foreground after its background
  /// model counts as mostly foreground (ForegroundHeavySince()).
  static constexpr double kHeavyForegroundShare = 1.0 / 3.0;
  /// Frames a camera's view may stay unmatched to its reference (or to the
  /// view its kept background was taught in), its frames unused, before a
  /// warning.
  static constexpr int kUnmatchedPatienceFrames = 150;
  /// Since when every frame camera `camera`'s background model classified
  /// (learning done) has been at least kHeavyForegroundShare foreground;
  /// nullopt while it is not, and for sources of masks. Long runs of it mean
  /// a person close to the lens, or a light change the single gain could not
  /// follow (part of the view changed, part not), whose changed part stays
  /// foreground, occupied, until the background is learned again.
  [[nodiscard]] std::optional<std::chrono::steady_clock::time_point> ForegroundHeavySince(
      int camera) const;
  /// The file camera `camera` keeps its background in (background_dir).
  [[nodiscard]] std::string BackgroundFile(int camera) const;

 private:
  struct Slot {
    common::ImageU8 mask;  // Pinhole (undistorted) mask.
    std::int64_t stamp_ns = 0;
    std::chrono::steady_clock::time_point ready;  // When it was published.
    bool learning = false;  // From the background model's learning: all foreground.
  };
  struct CameraRuntime {
    geometry::CameraModel model;
    std::unique_ptr<capture::CameraSource> source;
    std::unique_ptr<silhouette::ConservativeUndistorter> undistorter;
    int timeout_ms = 200;
    bool bayer_mosaic = false;                // PipelineCamera::bayer_mosaic.
    common::LatestValue<capture::Frame> raw;  // Capture thread -> silhouette worker.
    std::atomic<bool> busy{false};  // A silhouette worker is on this camera (shared workers).
    std::atomic<std::uint32_t>* signal = nullptr;  // Bumped by the capture thread every loop.
    common::LatestValue<Slot> slot;
    std::atomic<std::uint64_t> frames{0};
    std::atomic<std::uint64_t> corrupt{0};      // Frames of the wrong size.
    std::atomic<std::uint8_t> fault{0};         // capture::CameraFault.
    std::atomic<float> misalignment_px{-1.0F};  // CameraHealth::misalignment_px.
    std::atomic<bool> shifted{false};           // CameraHealth::shifted.
    /// An obstacle covers the lens (capture::CameraFault::kBlocked): failed,
    /// the status degraded, for as long as the daemon runs.
    bool blocked = false;
    bool unlearned = false;  // No background kept, and learning not allowed (kKeptOnly).
    std::atomic<bool> has_model{false};  // `background` exists (HasBackgroundModel()).
    // BackgroundSaved(): 0 not yet, 1 saved, 2 failed to save.
    std::atomic<std::uint8_t> background_saved{0};
    // ForegroundHeavySince() in steady-clock ns since its epoch; -1: not.
    std::atomic<std::int64_t> heavy_since_ns{-1};
    // Silhouette work (one worker at a time).
    capture::CameraHealthMonitor health_monitor;
    bool reference_logged = false;  // Whether a view without edges was reported.
    // The view is to be matched to its kept background's; its outcome untold.
    bool taught_pending_told = false;
    bool unmatched_told = false;  // The current spell of an unmatched view was told.
    common::ImageU8 foreground;
    silhouette::DilateScratch dilate_scratch;                 // DilateSquare of the foreground.
    silhouette::HoleFillScratch hole_scratch;                 // FillEnclosedBackground of it.
    std::unique_ptr<silhouette::BackgroundModel> background;  // Image sources only.
    int heartbeat = -1;                                       // Id in heartbeats_, if any.
    // Fusion thread only.
    silhouette::SilhouetteQuadtree quadtree;
    const Slot* current = nullptr;          // Newest frame taken; valid until the next take.
    bool fresh = false;                     // `current` not built into the quadtree yet.
    double margin_m = 0.0;                  // Lag margin (octree::Octree::Update()).
    std::int64_t margin_held_until_ns = 0;  // Not lowered before then.
    std::int64_t last_stamp_ns = 0;
    std::chrono::steady_clock::time_point last_ready;  // `ready` of the newest frame taken.
    bool seen = false;                                 // A frame has arrived since start.
    bool was_live = false;                             // Used in the previous cycle.
    std::uint64_t frames_at_last_second = 0;
    double fps = 0.0;
    bool fps_windowed = false;        // A whole one-second window has been counted.
    std::int64_t first_stamp_ns = 0;  // Capture stamp of the first frame taken.
    /// The camera and its calibration, in its kept background's file.
    std::uint64_t calibration_id = 0;
    CameraRuntime(geometry::CameraModel m, std::unique_ptr<capture::CameraSource> s, int timeout);
  };

  /// A silhouette worker and the cameras it serves.
  struct SilhouetteWorker {
    std::vector<int> cameras;
    std::atomic<std::uint32_t>* signal = nullptr;  // Waited on while nothing is new.
    int heartbeat = -1;
  };

  void CaptureLoop(int camera);
  void SilhouetteLoop(int worker);
  /// Processes camera `camera`'s newest raw frame unless another worker is on
  /// it; true when a frame was taken.
  bool TakeAndProcess(int camera);
  /// `spare`, when not null, is `frame`'s mask and may be taken (swapped with
  /// an older buffer of the same size) instead of copied.
  void ProcessFrame(int camera, const capture::Frame& frame, common::ImageU8* spare = nullptr);
  void FusionLoop();
  /// One fusion cycle; fps_window_s > 0 also updates the frame rates.
  /// `received_by`, in live use, is the cycle's start on the steady clock: a
  /// camera also counts as silent when its newest frame was handed over
  /// longer than its timeout before that (the frame age alone is measured on
  /// the stamps' clock, which a time step can move backwards).
  std::shared_ptr<OccupancySnapshot> RunCycle(
      std::int64_t now_ns, const octree::UpdateControl& control, double fps_window_s,
      std::optional<std::chrono::steady_clock::time_point> received_by = std::nullopt);
  std::shared_ptr<OccupancySnapshot> FreeSnapshot();

  PipelineOptions options_;
  std::vector<std::unique_ptr<CameraRuntime>> cameras_;
  std::unique_ptr<octree::Octree> tree_;
  Consumer consumer_;
  common::Heartbeats* heartbeats_ = nullptr;
  BlackBox* black_box_ = nullptr;
  int fusion_heartbeat_ = -1;
  std::vector<SilhouetteWorker> workers_;
  std::unique_ptr<std::atomic<std::uint32_t>[]> signals_;  // One per worker, or one shared.
  std::vector<const silhouette::SilhouetteQuadtree*> quadtree_ptrs_;
  std::vector<double> margins_;  // Per camera, for the octree update.
  std::vector<std::shared_ptr<OccupancySnapshot>> pool_;
  std::unique_ptr<PublishedGrid> grid_;      // The snapshots' cells from the tree.
  std::unique_ptr<BlobFilter> blob_filter_;  // With options_.knowledge_filter_m3 > 0.
  double published_cell_m3_ = 0.0;
  common::SharedSlot<const OccupancySnapshot> latest_;
  std::atomic<bool> stop_{false};
  // Fusion thread only: whether RunCycle holds raised margins (kMarginHoldNs).
  // FusionLoop clears it while the cycle is not phase-locked; Step() keeps it.
  bool hold_margins_ = true;
  std::vector<std::thread> threads_;
  std::uint64_t sequence_ = 0;
  std::uint64_t deadline_misses_ = 0;
  std::uint64_t missed_cycles_ = 0;  // Fusion thread only.
};

}  // namespace hg::pipeline
