#pragma once
/// @file
/// Sub-pixel registration of a camera's view against its reference view: how
/// far the static background has shifted in the image since start-up.

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "capture/camera_source.h"

namespace hg::capture {

/// Measures how far a camera's view has turned, rolled or zoomed since its
/// reference view, to a fraction of a pixel, for kMono and kRgb frames.
///
/// The reference view is the average of one or more frames (Accumulate(),
/// then TakeReference()). In it, up to kMaxPatches textured patches of 16 x
/// 16 pixels are chosen, the best corner (Shi-Tomasi: the structure tensor's
/// smaller eigenvalue) of each cell of a grid over the image, so that they
/// spread over the view. Measure() finds each patch again in a frame, within
/// kSearchPx pixels (normalised cross-correlation, coarse at half
/// resolution, refined at full, sub-pixel by a parabola through the scores).
/// Patches that do not match well are left out: a person in front of them,
/// or the background changed. Of the similarity transforms (shift, roll,
/// zoom) that pairs of the rest give, the one most patches agree with (those
/// that match nearly as well a few pixels away, a repetitive texture such as
/// a rack, a grating or tiles, count half) is refined by least squares over
/// them; at least a quarter of the patches (and kFewPatches) must agree. The
/// misalignment is the largest displacement it gives at any patch's place.
///
/// Normalised correlation ignores gain and offset, so a change of light does
/// not read as a move. Buffers are sized on the first frame; TakeReference()
/// and Measure() do not allocate. Thread-compatible.
class ViewRegistration {
 public:
  static constexpr int kPatchPx = 16;   ///< Patch side, pixels.
  static constexpr int kSearchPx = 12;  ///< Largest shift looked for, pixels.
  static constexpr int kMaxPatches = 48;
  /// Fewer patches than this (a view without texture): nothing is measured.
  static constexpr int kFewPatches = 8;
  /// Correlation below which a patch counts as not found.
  static constexpr double kMinCorrelation = 0.8;
  /// A second peak of the coarse search within this much of the best one
  /// makes a patch ambiguous (a repetitive texture): it counts half when
  /// patches vote on the shift.
  static constexpr double kAmbiguityMargin = 0.05;
  /// Displacements this close (pixels) agree; so do a patch and a fit.
  static constexpr double kAgreePx = 1.0;
  /// A roll or zoom is taken over a plain shift when this many times as many
  /// patches agree with it.
  static constexpr double kPreferShift = 1.25;
  /// Patches of a Glance() that must have moved.
  static constexpr int kGlanceAgree = 2;

  /// Adds a frame to the reference view (the first one after a
  /// TakeReference() allocates the sums, 2 bytes a pixel).
  void Accumulate(const Frame& frame);
  /// Averages the frames accumulated into the reference view and chooses its
  /// patches; the sums are released. Returns how many patches were chosen.
  int TakeReference();
  /// Patches of the reference view (0 before TakeReference()).
  [[nodiscard]] int patches() const { return static_cast<int>(patches_.size()); }
  /// The misalignment of `frame`'s view against the reference, in pixels, or
  /// a negative value when too few patches were found to tell (people in
  /// front of most of them, a view without texture, a shift beyond
  /// kSearchPx).
  [[nodiscard]] double Measure(const Frame& frame);
  /// A quick look between registrations: patches `first` .. `first + count`
  /// (round the list) are found again, and whether at least kGlanceAgree of
  /// them moved by more than `beyond_px` is returned (a registration is then
  /// due at once). Spoils matched() and inliers() until the next Measure().
  [[nodiscard]] bool Glance(const Frame& frame, int first, int count, double beyond_px);
  /// Patches found in the last Measure(), and those the fit kept.
  [[nodiscard]] int matched() const { return matched_; }
  [[nodiscard]] int inliers() const { return inliers_; }
  /// Forgets the reference view.
  void Reset();

 private:
  static constexpr int kMargin = kSearchPx + 2;             // Refinement and parabola.
  static constexpr int kRegionPx = kPatchPx + 2 * kMargin;  // Searched region's side.
  static constexpr int kHalfPatch = kPatchPx / 2;           // Half-resolution patch side.
  static constexpr int kHalfRegion = kRegionPx / 2;
  struct Patch {
    int x0 = 0, y0 = 0;                                 // Top left corner in the reference view.
    std::array<float, kPatchPx * kPatchPx> full{};      // Zero mean, unit norm.
    std::array<float, kHalfPatch * kHalfPatch> half{};  // The same, at half resolution.
  };
  struct Found {
    double x = 0, y = 0;    // Patch centre, pixels from the image centre.
    double dx = 0, dy = 0;  // Displacement.
    bool ok = false;
    bool ambiguous = false;  // A second peak nearly as high.
  };

  struct Candidate {
    double score = 0;
    int x0 = -1, y0 = -1;
  };
  static constexpr int kCandidatesPerCell = 4;

  void Size(int width, int height);
  [[nodiscard]] bool FitsFrame(const Frame& frame) const;
  /// Finds patch i in `frame` (found_[i]); whether it was found.
  bool Find(const Frame& frame, std::size_t i);
  void ReadRegion(const Frame& frame, int x0, int y0);
  /// The misalignment from the patches found; negative when too few agree.
  [[nodiscard]] double FitAndMeasure();

  int width_ = 0, height_ = 0;
  int frames_ = 0;
  std::vector<std::uint16_t> sum_;  // Reference frames, summed; full resolution.
  std::vector<Patch> patches_;
  std::array<float, kRegionPx * kRegionPx> region_{};
  std::array<float, kHalfRegion * kHalfRegion> region_half_{};
  std::array<Found, kMaxPatches> found_{};
  Patch scratch_patch_;
  std::array<float, (kSearchPx + 1) * (kSearchPx + 1)> coarse_{};  // Half-resolution scores.
  int matched_ = 0, inliers_ = 0;
};

}  // namespace hg::capture
