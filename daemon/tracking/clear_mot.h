#pragma once
/// @file
/// CLEAR MOT metrics (Bernardin & Stiefelhagen, "Evaluating Multiple Object
/// Tracking Performance: The CLEAR MOT Metrics", EURASIP JIVP 2008) for
/// tracks against ground truth: MOTA (misses, false positives and identity
/// switches per ground-truth object) and MOTP (mean distance of the matches).

#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

namespace hg::tracking {

/// A ground-truth object or a tracker hypothesis in one frame: an id that is
/// stable over the sequence and a position. Which point of a person is the
/// position is the caller's choice, but both sides must mean the same point
/// (`hullguard track-eval`: the centre of the body's axis-aligned bounding box
/// against the centre of the track's ellipsoid).
struct MotPoint {
  std::uint32_t id = 0;
  Eigen::Vector3d position_W = Eigen::Vector3d::Zero();
};

struct ClearMotOptions {
  /// An object and a hypothesis correspond only while their distance is at
  /// most this (m), the paper's T.
  double match_threshold_m = 0.5;
};

/// One correspondence of a frame.
struct MotMatch {
  std::uint32_t object_id = 0;
  std::uint32_t hypothesis_id = 0;
  double distance_m = 0.0;
  /// The object was last matched (in this or an earlier frame) to another
  /// hypothesis: an identity switch (the paper's mismatch).
  bool mismatch = false;
};

/// What one frame added.
struct MotFrame {
  int objects = 0;          ///< Ground-truth objects in the frame.
  int hypotheses = 0;       ///< Hypotheses in the frame, ignored ones included.
  int misses = 0;           ///< Objects without a hypothesis.
  int false_positives = 0;  ///< Hypotheses matched to no object and to no distractor.
  int ignored = 0;          ///< Hypotheses matched to no object but near a distractor.
  int mismatches = 0;
  double distance_sum_m = 0.0;
  std::vector<MotMatch> matches;  ///< In the order of the objects given.
};

/// Sums over the frames so far.
struct MotTotals {
  std::int64_t frames = 0;
  std::int64_t objects = 0;  ///< The paper's sum of g_t.
  std::int64_t matches = 0;  ///< The paper's sum of c_t.
  std::int64_t misses = 0;
  std::int64_t false_positives = 0;
  std::int64_t ignored = 0;
  std::int64_t mismatches = 0;
  double distance_sum_m = 0.0;

  /// 1 - (misses + false positives + mismatches) / objects; may be negative.
  /// NaN when there were no objects.
  [[nodiscard]] double Mota() const;
  /// Mean distance of the matches (m); NaN when there were none.
  [[nodiscard]] double Motp() const;
};

/// The CLEAR MOT mapping, frame by frame:
/// 1. an object keeps the hypothesis it was last matched to (in the previous
///    frame, or in an earlier one when it was missed since) when that
///    hypothesis is present and within the threshold; when two objects claim
///    one hypothesis, the one matched more recently keeps it (then the nearer);
/// 2. the remaining objects and hypotheses are matched by an optimal
///    assignment: the most pairs within the threshold, and among those the
///    least total distance (Hungarian method);
/// 3. a match in step 2 of an object whose last hypothesis was a different one
///    is a mismatch (identity switch); the object's last hypothesis becomes
///    the new one. An object met again after frames without a match therefore
///    counts a switch only when its new hypothesis differs from its old one;
/// 4. objects left over are misses; hypotheses left over are false positives,
///    unless a distractor lies within the threshold: a static thing that is
///    not a person but that the tracker may rightly follow (a crate nobody
///    told the system about); those are counted apart as ignored.
/// Distances are Euclidean in 3-D (m). Memory grows with the number of
/// distinct object ids. Single-thread.
class ClearMot {
 public:
  /// @throws common::ConfigError when the threshold is not a positive number.
  explicit ClearMot(const ClearMotOptions& options = {});

  /// Adds one frame. Ids must be unique within `objects` and within
  /// `hypotheses` (checked; a duplicate throws std::invalid_argument).
  const MotFrame& AddFrame(std::span<const MotPoint> objects, std::span<const MotPoint> hypotheses,
                           std::span<const Eigen::Vector3d> distractors_W = {});

  [[nodiscard]] const MotTotals& totals() const { return totals_; }
  [[nodiscard]] const MotFrame& last_frame() const { return frame_; }
  [[nodiscard]] const ClearMotOptions& options() const { return options_; }

 private:
  struct History {
    std::uint32_t object_id = 0;
    std::uint32_t hypothesis_id = 0;
    std::int64_t frame = -1;  // Last frame with a match.
  };
  History* Find(std::uint32_t object_id);

  ClearMotOptions options_;
  MotTotals totals_;
  MotFrame frame_;
  std::vector<History> history_;
  // Scratch of one frame.
  std::vector<int> object_match_;      // Per object: hypothesis index or -1.
  std::vector<int> hypothesis_match_;  // Per hypothesis: object index or -1.
  std::vector<std::uint8_t> mismatch_;
  std::vector<int> rows_, cols_;
  std::vector<double> cost_;
};

/// Minimum-cost assignment of a rows x cols cost matrix (row-major, finite
/// entries), rows <= cols: assignment[r] = the column of row r, each column
/// used at most once, the sum of the chosen costs minimal (Hungarian method
/// with potentials, O(rows^2 cols)).
/// @throws std::invalid_argument when rows > cols or the sizes do not match.
[[nodiscard]] std::vector<int> MinCostAssignment(std::span<const double> cost, int rows, int cols);

}  // namespace hg::tracking
