#pragma once
/// @file
/// Silhouette quadtree: per element of every level, whether it holds background,
/// foreground or both, and whether any pixel flipped since the previous mask.

#include <cstdint>
#include <span>
#include <vector>

#include "common/image.h"
#include "geometry/camera.h"

namespace hg::silhouette {

/// What a set of pixels holds. Bit 0: some background pixel; bit 1: some foreground pixel.
enum class Cover : std::uint8_t { kNone = 0, kBackground = 1, kForeground = 2, kMixed = 3 };

/// Quadtree over a binary silhouette of one camera.
///
/// The finest level holds 8x8-pixel tiles as 64-bit words (bit r*8+c is pixel
/// (8tx+c, 8ty+r)); every coarser level halves the tile grid. Each element
/// stores its Cover and a changed flag (some pixel differs from the mask of the
/// previous Build()). Queries are exact at pixel level and stop as soon as the
/// answer is known: a rect of up to 2x2 tiles reads its tiles; a larger one
/// first asks a summed-area table over the tiles (four look-ups answer it
/// where the tiles it touches are all alike, or where those wholly inside it
/// already differ), then reads only its border tiles. The coarser levels
/// serve ChangedSince(), whose per-element versions do not sum.
///
/// Thread-compatible: Build() must not run concurrently with anything else;
/// const queries may run concurrently. Build() does not allocate.
class SilhouetteQuadtree {
 public:
  SilhouetteQuadtree(int width, int height);
  /// A copy is a new quadtree with the same content: it gets its own id().
  SilhouetteQuadtree(const SilhouetteQuadtree& other);
  SilhouetteQuadtree& operator=(const SilhouetteQuadtree& other);
  SilhouetteQuadtree(SilhouetteQuadtree&&) = default;
  SilhouetteQuadtree& operator=(SilhouetteQuadtree&&) = default;

  /// Rebuilds from a grey mask (foreground iff value > threshold). Changed flags
  /// are relative to the previously built mask; the first build marks every
  /// pixel changed. Precondition: mask size equals the tree's size.
  void Build(const common::ImageViewU8& mask, std::uint8_t threshold);

  /// Marks every element changed (for a consumer that missed a version).
  void MarkAllChanged();

  /// Cover of the pixels of `rect`. Precondition: rect is non-empty and inside the image.
  [[nodiscard]] Cover Query(const geometry::PixelRect& rect) const;

  /// True iff some pixel of `rect` changed in the last Build().
  /// Precondition: rect is non-empty and inside the image.
  [[nodiscard]] bool AnyChanged(const geometry::PixelRect& rect) const;

  /// True iff some pixel of `rect` may have changed in a Build() after the one
  /// that made `version` (every change since, exact at 8x8 tiles: a tile with a
  /// change counts wholly). ChangedSince(rect, version() - 1) covers AnyChanged(rect).
  /// Precondition: rect is non-empty and inside the image.
  [[nodiscard]] bool ChangedSince(const geometry::PixelRect& rect, std::uint64_t version) const;

  /// True iff pixel (u, v) is foreground.
  [[nodiscard]] bool IsForeground(int u, int v) const;

  /// Number of Build() calls so far.
  [[nodiscard]] std::uint64_t version() const { return version_; }
  /// Unique among the quadtrees of the process (never 0), kept by a move: a
  /// consumer holding (id, version) can tell a later build of the same
  /// quadtree, whose changes since that version it may ask for, from another
  /// quadtree that happens to sit at the same address.
  [[nodiscard]] std::uint64_t id() const { return id_; }
  [[nodiscard]] int width() const { return width_; }
  [[nodiscard]] int height() const { return height_; }
  [[nodiscard]] int num_levels() const { return static_cast<int>(levels_.size()); }

 private:
  struct Level {
    int width = 0;                    // Elements per row.
    int height = 0;                   // Element rows.
    int shift = 0;                    // Element side in pixels is 8 << shift.
    std::vector<std::uint8_t> cells;  // Cover bits | kChangedBit.
    /// Version of the last Build() that changed a pixel of the element.
    std::vector<std::uint64_t> changed_at;
  };
  static constexpr std::uint8_t kChangedBit = 4;

  /// An element on a descent's stack.
  struct Item {
    int level, x, y;
  };
  /// Each level pushes at most 4 siblings on top of what is pending.
  static constexpr int kStackSize = 4 * 32;
  /// Pushes the elements that cover `rect` at the finest level where it spans
  /// at most 2x2 of them; returns how many.
  int PushCover(const geometry::PixelRect& rect, Item* stack) const;
  void BuildCoarseLevels();
  /// Fills sums_ from the tile covers and changed bits.
  void BuildSums();
  /// Counts over tiles [tx0, tx1] x [ty0, ty1], packed as in sums_.
  [[nodiscard]] std::uint64_t TileSum(int tx0, int ty0, int tx1, int ty1) const;
  /// Query() and AnyChanged() of a rect spanning more than 2x2 tiles.
  template <bool kChanged>
  [[nodiscard]] std::uint8_t LargeRect(const geometry::PixelRect& rect) const;
  // Turns row ty's new words (assembled in changed_) into words, changed bits
  // and tile covers.
  void CommitTileRow(int ty, bool first);

  int width_;
  int height_;
  int tiles_w_;
  int tiles_h_;
  std::uint64_t version_ = 0;
  std::uint64_t id_;
  std::vector<std::uint64_t> words_;    // Foreground bits per tile.
  std::vector<std::uint64_t> changed_;  // Changed bits per tile.
  std::vector<std::uint64_t> valid_;    // Bits inside the image per tile.
  std::vector<Level> levels_;           // levels_[0]: tiles; last: 1x1.
  /// Summed-area table over the tiles, (tiles_w_ + 1) x (tiles_h_ + 1): per
  /// entry the number of tiles above and left of it holding background (bits
  /// 0-20), foreground (bits 21-41) and a changed pixel (bits 42-62). Answers
  /// a large rect's tiles in four look-ups.
  std::vector<std::uint64_t> sums_;
};

}  // namespace hg::silhouette
