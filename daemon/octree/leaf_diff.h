#pragma once
/// @file
/// Which leaves one update wrote: the floor of any incremental update's work.

#include <cstdint>
#include <vector>

#include "octree/octree.h"

namespace hg::octree {

/// Every leaf of the tree as one key (its cell and its state), sorted. Two
/// trees hold the same leaf where they hold the same key. Allocates; meant
/// for measurements and tests, not the per-frame path.
[[nodiscard]] std::vector<std::uint64_t> LeafKeys(const Octree& tree);

/// How many leaves of `after` are not leaves of `before` with the same cell and
/// state: the leaves an update from `before` to `after` had to write, however
/// it found them. Both sorted, as LeafKeys() returns them.
[[nodiscard]] std::int64_t CountNewLeaves(const std::vector<std::uint64_t>& before,
                                          const std::vector<std::uint64_t>& after);

}  // namespace hg::octree
