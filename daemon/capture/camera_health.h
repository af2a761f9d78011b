#pragma once
/// @file
/// Image-level camera faults: frozen frames, black or saturated images, and a
/// camera that moved (bumped) since its reference view was taken.

#include <array>
#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

#include "capture/camera_source.h"
#include "capture/view_registration.h"

namespace hg::capture {

/// What is wrong with a camera's images (0: nothing).
enum class CameraFault : std::uint8_t {
  kNone = 0,
  kFrozen = 1,     ///< The same image again and again (a hung driver or camera).
  kBlack = 2,      ///< Lens covered, lights off, iris closed.
  kSaturated = 3,  ///< Blinded by a lamp, exposure run away.
  kMoved = 4,      ///< The view of the static background no longer matches the reference.
  /// No background to tell people from (none kept, and learning at start is
  /// off: background.learn_at_start): set by the pipeline, not the monitor.
  kUnlearned = 5,
  /// An obstacle mesh reaches within 1 mm in front of the camera centre, or
  /// covers its whole view within 10 cm (the camera modelled inside a housing
  /// or a robot; geometry::ObstacleDepthMap::blocked): every ray is taken as
  /// blocked, so the camera certifies nothing. Set by the pipeline at
  /// start, for good: a config to mend, not a state that passes.
  kBlocked = 6,
};

/// Stable lower-case name ("none", "frozen", "black", "saturated", "moved", "unlearned",
/// "blocked").
[[nodiscard]] const char* ToString(CameraFault fault);

struct CameraHealthOptions {
  /// Images are checked on a grid of this pitch (frozen, dark, saturated;
  /// the reference edges); a view that shifts by about a step or more (8 px:
  /// about 0.4 degrees at Full HD with a 1.45 rad lens) loses its edges.
  int sample_step_px = 8;
  int frozen_frames = 15;     ///< Repeated frames in a row before "frozen".
  int dark_level = 12;        ///< Mean grey below this: black.
  int saturated_level = 243;  ///< Mean grey above this: saturated.
  int reference_frames = 10;  ///< Frames averaged into the reference view at start-up.
  int edge_threshold = 24;    ///< Gradient (grey levels per sample step) that makes an edge.
  /// Share of reference edges still present below which the view is
  /// registered at once, and taken as shifted if it cannot be found.
  double min_edges_kept = 0.45;
  /// A view registered (ViewRegistration) as shifted by more than this
  /// many pixels somewhere, check after check, counts as moved. The pipeline
  /// sets it to half the foreground dilation (at least 1 px), so that a shift
  /// that goes unnoticed stays within what the dilation covers.
  double max_shift_px = 1.0;
  int shift_check_every = 3;  ///< Frames between two registrations of the view.
  int moved_checks = 5;       ///< Registrations in a row over max_shift_px before "moved".
};

/// Watches one camera's images (kMono and kRgb frames; masks are not checked):
/// a sparse grid every frame, a registration of the view every few, cheap
/// enough for every camera (about 0.5 ms a Full HD frame, on average).
///
/// A moved camera is found by registration (ViewRegistration) against its
/// reference view: the first frame, or, once the camera's view is found to
/// match it, the view its kept background was taught in (SetTaughtView()).
/// Textured patches of the reference are found again to a fraction of a
/// pixel every `shift_check_every` frames, and at once when a glance at a
/// few of them (kGlancePatches, in turn, on the frames between) finds some
/// moved; a shift, roll or zoom of more than `max_shift_px` anywhere in the
/// view makes the camera shifted() (its frames are not to be used) at once,
/// and `moved_checks` such registrations in a row make it moved. People in front of patches leave
/// them out; when too few are found, the registration tells nothing.
///
/// The strong edges of the reference view (the first `reference_frames`
/// averaged), sampled on a grid, back it up: a view that lost most of them,
/// or clearly more than while it was last found in place, is registered at
/// once. Found in place, it was dimmed or covered (no
/// fault); found nowhere (a move beyond the kSearchPx registration looks
/// for), it is shifted until a registration finds it in place again.
/// A camera whose calibration no longer holds must not certify anything
/// free, so "moved" stays until Reset() (after recalibration).
///
/// Thread-compatible; buffers are sized on the first frame, Check() does not
/// allocate afterwards.
class CameraHealthMonitor {
 public:
  explicit CameraHealthMonitor(CameraHealthOptions options = {});

  /// Checks one frame and returns the camera's fault now.
  CameraFault Check(const Frame& frame);
  [[nodiscard]] CameraFault fault() const { return fault_; }
  /// The last frame checked repeats one of the kRecentFrames before it,
  /// sample for sample: it brings nothing new (a real sensor's noise differs
  /// from frame to frame), so it must not count as a fresh view of the cell.
  /// Frozen follows after `frozen_frames` of these in a row.
  [[nodiscard]] bool repeated() const { return identical_run_ > 0; }
  /// Share of the reference edges found in the last frame (1 before the
  /// reference exists).
  [[nodiscard]] double edges_kept() const { return edges_kept_; }
  /// Whether the reference view has been taken (after reference_frames).
  [[nodiscard]] bool has_reference() const { return reference_count_ >= options_.reference_frames; }
  /// Edges of the reference view: a view with few (a blank wall, a view
  /// covered while the reference was taken) cannot be found moved.
  [[nodiscard]] std::size_t reference_edges() const { return reference_edges_.size(); }
  /// Textured patches of the reference view that registration finds again
  /// (fewer than ViewRegistration::kFewPatches: the view cannot be registered).
  [[nodiscard]] int reference_patches() const { return active().patches(); }
  /// The view's misalignment against the reference at the last registration,
  /// pixels; negative when it could not be told (or before the reference).
  [[nodiscard]] double misalignment_px() const { return misalignment_px_; }
  /// The last conclusive registration found the view shifted by more than
  /// max_shift_px: until one finds it back in place (or it turns moved), the
  /// camera's frames must not be used, as its calibration may no longer hold.
  /// Also while the view has yet to be found to match its taught view.
  [[nodiscard]] bool shifted() const { return shifted_ || taught_pending_; }
  /// The view the camera's kept background was taught in (its means, as a
  /// frame of the camera's kind and size), normally right after the camera
  /// was calibrated: a camera moved while the daemon was stopped no longer
  /// matches it. From now on every frame is registered against it until
  /// conclusive registrations in a row agree: kTaughtMatches within
  /// max_shift_px, and the check is passed; `moved_checks` beyond, and the
  /// camera is moved.
  /// Meanwhile shifted() holds. Without texture enough to register by, no
  /// check. Allocates (start-up).
  void SetTaughtView(const Frame& taught);
  /// The taught view is set and not yet matched (nor the camera found moved).
  [[nodiscard]] bool awaiting_taught_view() const { return taught_pending_; }
  /// Frames in a row the camera has been shifted() (0 once moved).
  [[nodiscard]] int shifted_frames() const { return shifted_frames_; }
  /// Whether the camera was found moved against its taught view.
  [[nodiscard]] bool moved_since_taught() const { return moved_since_taught_; }
  /// Frames a repeat is looked for among: a driver may cycle through its
  /// buffers, stale ones again and again (the GigE source holds 8, a V4L2
  /// source up to 32: `buffers`, which a driver may raise). A replayed
  /// recording looping over fewer frames looks the same, and is dropped so.
  static constexpr int kRecentFrames = 32;
  /// Registrations within max_shift_px of the taught view, in a row, that
  /// pass the camera (SetTaughtView()).
  static constexpr int kTaughtMatches = 2;
  /// Edges kept this much below their share while the view was last found
  /// in place count as lost: a move just beyond registration's reach keeps
  /// about half of them, more than min_edges_kept.
  static constexpr double kEdgesDrop = 0.15;
  /// Patches glanced at in each frame between two registrations.
  static constexpr int kGlancePatches = 8;
  /// Fewer reference edges than this: the camera cannot be checked for a move.
  static constexpr std::size_t kFewEdges = 16;
  /// Forgets the reference and every fault (after the camera was re-aimed).
  void Reset();

 private:
  void Sample(const Frame& frame);
  [[nodiscard]] bool EdgeAt(const std::vector<std::uint8_t>& img, int x, int y) const;

  CameraHealthOptions options_;
  int cols_ = 0, rows_ = 0;
  std::vector<std::uint8_t> current_, previous_;
  std::vector<std::uint32_t> reference_sum_;
  std::vector<std::uint8_t> reference_;
  std::vector<std::uint32_t> reference_edges_;  // Sample indices of reference edges.
  int reference_count_ = 0;
  std::array<std::uint64_t, kRecentFrames> recent_{};  // Sample hashes, a ring.
  int recent_count_ = 0;
  int recent_next_ = 0;
  int identical_run_ = 0;  // Repeated frames in a row.
  // Registration's references: the first frame (until the edge reference is
  // averaged, so that a move meanwhile is found), the average of the
  // reference frames, and the view the kept background was taught in.
  enum class Reference : std::uint8_t { kFirstFrame, kAveraged, kTaught };
  [[nodiscard]] const ViewRegistration& active() const {
    return active_ == Reference::kFirstFrame ? first_frame_
           : active_ == Reference::kAveraged ? averaged_
                                             : taught_;
  }
  [[nodiscard]] ViewRegistration& active() {
    return const_cast<ViewRegistration&>(std::as_const(*this).active());
  }
  ViewRegistration first_frame_, averaged_;
  Reference active_ = Reference::kFirstFrame;
  bool shift_while_averaging_ = false;  // The first frame's reference stays.
  int frames_since_check_ = 0;
  int shift_run_ = 0;  // Registrations in a row over max_shift_px.
  double misalignment_px_ = -1.0;
  bool shifted_ = false;
  ViewRegistration taught_;  // The kept background's view (SetTaughtView()).
  bool taught_pending_ = false;
  int taught_agree_ = 0, taught_differ_ = 0;  // Registrations in a row.
  bool moved_since_taught_ = false;
  bool has_registration_reference_ = false;
  int shifted_frames_ = 0;
  double edges_in_place_ = -1.0;  // Edges kept while found in place; -1: not yet.
  int glance_next_ = 0;           // First patch of the next glance.
  bool moved_ = false;
  double edges_kept_ = 1.0;
  CameraFault fault_ = CameraFault::kNone;
};

}  // namespace hg::capture
