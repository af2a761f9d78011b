#pragma once
/// @file
/// Knowledge filter: occupied components too small to be a person.

#include <cstdint>
#include <unordered_set>

#include "octree/octree.h"

namespace hg::octree {

/// Connected components (26-connectivity: leaves sharing a face, an edge or a
/// corner) of the occupied leaves, computed on the octree leaves themselves.
/// Occluded leaves are never dropped, nor is a component that touches an
/// occluded leaf or a face of the bounds: it may be the visible part of
/// something larger (a person partly hidden, or reaching in from outside).
/// The filter is opt-in because it frees space the cameras could not certify.
/// Value type; queries are thread-safe.
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

/// Finds the occupied components of the tree and marks as dropped those
/// smaller than `min_volume_m3` that touch neither occluded space nor a face of
/// the bounds.
[[nodiscard]] KnowledgeFilterResult FilterSmallComponents(const Octree& tree, double min_volume_m3);

}  // namespace hg::octree
