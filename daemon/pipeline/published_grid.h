#pragma once
/// @file
/// The octree read into the published grid of an occupancy snapshot.

#include <cstdint>
#include <vector>

#include "octree/octree.h"
#include "pipeline/snapshot.h"

namespace hg::pipeline {

/// Fills a snapshot's occupied and occluded runs (along x) on the grid of
/// 2^depth cells per axis over the tree's bounds: a cell is occupied when a
/// leaf overlapping it reads occupied, else occluded when one reads occluded
/// (Octree::ForEachCellUpTo). Keeps the grid's bit sets between calls: no
/// allocation once the snapshot's run vectors have grown.
class PublishedGrid {
 public:
  /// depth: 1 .. 10 (the runs' 16-bit coordinates).
  explicit PublishedGrid(int depth);

  /// Sets snapshot->occupied and ->occluded; nothing else.
  void Fill(const octree::Octree& tree, OccupancySnapshot* snapshot);

  [[nodiscard]] int depth() const { return depth_; }

 private:
  int depth_;
  std::vector<std::uint64_t> occupied_bits_, occluded_bits_;
};

}  // namespace hg::pipeline
