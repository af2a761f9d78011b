#pragma once
/// @file
/// Knowledge filter: occupied components too small to be a person.

#include <cstdint>
#include <unordered_set>

#include "octree/octree.h"

namespace hg::octree {

/// Settings; the filter is off by default because it deliberately frees space
/// that the cameras could not certify (noise blobs, pseudo objects).
struct KnowledgeFilterConfig {
  bool enabled = false;
  double min_component_volume_m3 = 0.001;  ///< Components below this volume are dropped.
};

/// Connected components (26-connectivity: leaves sharing a face, an edge or a
/// corner) of the occupied leaves, computed on the octree leaves themselves.
/// Occluded leaves are never dropped. Value type; queries are thread-safe.
class KnowledgeFilterResult {
 public:
  [[nodiscard]] bool IsDropped(const Cell& cell) const { return dropped_.count(Key(cell)) != 0; }
  /// The tree's state of p_W with dropped leaves reported free.
  [[nodiscard]] PointState StateAt(const Octree& tree, const Eigen::Vector3d& p_W) const;

  int components = 0;
  int dropped_components = 0;
  double dropped_volume_m3 = 0.0;

  static std::uint64_t Key(const Cell& c) {
    return (static_cast<std::uint64_t>(c.level) << 57) | (static_cast<std::uint64_t>(c.x) << 38) |
           (static_cast<std::uint64_t>(c.y) << 19) | c.z;
  }

 private:
  friend KnowledgeFilterResult FilterSmallComponents(const Octree&, double);
  std::unordered_set<std::uint64_t> dropped_;
};

/// Finds the occupied components of the tree and marks those smaller than
/// `min_volume_m3` as dropped.
[[nodiscard]] KnowledgeFilterResult FilterSmallComponents(const Octree& tree, double min_volume_m3);

}  // namespace hg::octree
