#pragma once
/// @file
/// The brute-force oracle: every finest cell classified on its own, by loops
/// over the pixels of plain masks and depth maps (no quadtree, no pyramid).

#include <cstdint>
#include <string>
#include <vector>

#include "common/box.h"
#include "common/image.h"
#include "geometry/camera.h"
#include "geometry/obstacle_depth.h"
#include "octree/octree.h"

namespace hg::testing {

/// LeafState per finest cell, index x + n (y + n z), n = 2^depth.
struct DenseGrid {
  int depth = 0;
  std::vector<std::uint8_t> states;
  [[nodiscard]] std::size_t Index(std::uint32_t x, std::uint32_t y, std::uint32_t z) const {
    const std::size_t n = std::size_t{1} << depth;
    return x + n * (y + n * z);
  }
};

/// Classifies every finest cell. masks[c] == nullptr: camera c sees nothing.
/// depth_maps may be empty (no obstacles) or hold one map per camera.
/// margins (empty: none) grows each cell by margins[c] for camera c, as
/// octree::Octree::Update()'s margins do.
DenseGrid DenseCarve(const common::Box3& bounds, int depth,
                     const std::vector<geometry::CameraModel>& cameras,
                     const std::vector<const common::ImageU8*>& masks,
                     const std::vector<geometry::ObstacleDepthMap>& depth_maps,
                     const std::vector<double>& margins = {});

/// The octree's leaves painted onto the finest grid.
DenseGrid Rasterize(const octree::Octree& tree);

/// Leaves of a tree in visiting order, for exact structural comparisons.
std::vector<std::pair<octree::Cell, octree::LeafState>> Leaves(const octree::Octree& tree);

/// Empty when the two trees have the same leaves; otherwise the leaf counts and
/// the first leaves that differ, readable in a test failure.
std::string LeafDifference(const octree::Octree& a, const octree::Octree& b);

}  // namespace hg::testing
