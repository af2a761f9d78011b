#pragma once
/// @file
/// The daemon's knowledge filter: small isolated blobs dropped from the
/// published grid.

#include <cstdint>
#include <vector>

#include "pipeline/snapshot.h"

namespace hg::pipeline {

/// What one Apply() did.
struct BlobFilterStats {
  /// Connected groups of not-free cells that hold an occupied cell (groups of
  /// occluded cells alone are not counted: the filter never drops them).
  int components = 0;
  int dropped_components = 0;  ///< Groups whose occupied cells were dropped.
  std::size_t dropped_cells = 0;
};

/// Drops occupied cells that are too small to be a person and cannot be part
/// of a larger object (octree.knowledge_filter_m3): noise in a silhouette
/// leaves such blobs where the cameras' cones happen to cross.
///
/// The cells that are not free (occupied and occluded runs together) are
/// split into 26-connected components (cells sharing a face, an edge or a
/// corner). A component's occupied cells are dropped only when all of these
/// hold: it holds fewer than `min_cells` occupied cells, it holds no occluded
/// cell (an object that reaches into unseen space may be larger than what is
/// seen of it), and it touches no face of the grid (it may be the visible
/// part of something outside the bounds). This deliberately reports space
/// free that the cameras did not certify: it is off unless configured.
///
/// Works on runs (GridRun, sorted by z, y, then x as the snapshot lists
/// them): union-find over runs with each run's neighbours in the row before
/// and the rows of the layer before. Buffers grow to the largest grid seen
/// and are reused: no allocation after warm-up.
class BlobFilter {
 public:
  /// `depth`: the grid has 2^depth cells per axis. `min_cells` >= 1.
  BlobFilter(int depth, std::size_t min_cells);

  /// Removes the dropped runs from *occupied, keeping the order.
  BlobFilterStats Apply(std::vector<GridRun>* occupied, const std::vector<GridRun>& occluded);

 private:
  /// Index of a run in the combined list: occupied first, then occluded.
  int Find(int i);
  void Union(int a, int b);
  /// First run of each row (y + n z) in `runs`, and one past the last row.
  void IndexRows(const std::vector<GridRun>& runs, std::vector<std::uint32_t>* starts) const;

  int n_;  // Cells per axis.
  std::size_t min_cells_;
  std::vector<std::uint32_t> occupied_rows_;
  std::vector<std::uint32_t> occluded_rows_;
  std::vector<int> parent_;
  std::vector<std::uint32_t> cells_;  // Per root: occupied cells.
  std::vector<std::uint8_t> keep_;    // Per root: holds an occluded cell or touches a face.
};

}  // namespace hg::pipeline
