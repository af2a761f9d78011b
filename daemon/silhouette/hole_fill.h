#pragma once
/// @file
/// Filling the background that a silhouette encloses.

#include <cstdint>
#include <vector>

#include "common/image.h"

namespace hg::silhouette {

/// What FillEnclosedBackground() works in: the background runs of the mask,
/// row by row, and their union-find forest. Reserved on the first call for a
/// mask of its size (runs_per_pixel), then kept: a per-frame call does not
/// allocate.
struct HoleFillScratch {
  /// Runs reserved per pixel of the mask (at least kMinRuns). A mask with
  /// more background runs than that is left as it is. A silhouette has a few
  /// runs per row; a mask of noise (every other pixel) has half a run per
  /// pixel. 1/16: 130 000 runs, 1.2 MB, for Full HD.
  double runs_per_pixel = 1.0 / 16.0;
  static constexpr std::size_t kMinRuns = 4096;
  std::vector<std::uint16_t> begin;      ///< First pixel of each run.
  std::vector<std::uint16_t> end;        ///< One past its last pixel.
  std::vector<std::uint32_t> parent;     ///< Union-find: the run's parent (a root: itself).
  std::vector<std::uint8_t> outside;     ///< Per root: the component reaches the image border.
  std::vector<std::uint32_t> row_first;  ///< Per row: its first run; one more at the end.
};

/// Makes foreground (255) every background (zero) pixel of `mask` from which
/// no 4-connected path of background pixels leads to the image border: the
/// holes that the foreground encloses. The mask only gains foreground.
/// Returns the number of pixels filled; -1 when the mask had more background
/// runs than the scratch holds (it is then left unchanged). Width at most
/// 65535.
///
/// Cost: one pass over the mask, eight bytes at a time where they are all
/// background or all foreground, and a union-find over the background runs.
int FillEnclosedBackground(common::ImageU8* mask, HoleFillScratch* scratch);

}  // namespace hg::silhouette
