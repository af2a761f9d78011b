#include "octree/leaf_diff.h"

#include <algorithm>

namespace hg::octree {

std::vector<std::uint64_t> LeafKeys(const Octree& tree) {
  std::vector<std::uint64_t> keys;
  keys.reserve(static_cast<std::size_t>(tree.NumLeaves()));
  // Level 5 bits, x, y, z 19 bits each (kMaxDepth), state 2 bits.
  static_assert(Octree::kMaxDepth <= 19);
  tree.ForEachLeaf([&](const Cell& c, LeafState state) {
    keys.push_back((static_cast<std::uint64_t>(c.level) << 59) |
                   (static_cast<std::uint64_t>(c.x) << 40) |
                   (static_cast<std::uint64_t>(c.y) << 21) |
                   (static_cast<std::uint64_t>(c.z) << 2) | static_cast<std::uint64_t>(state));
  });
  std::sort(keys.begin(), keys.end());
  return keys;
}

std::int64_t CountNewLeaves(const std::vector<std::uint64_t>& before,
                            const std::vector<std::uint64_t>& after) {
  std::int64_t count = 0;
  auto b = before.begin();
  for (const std::uint64_t key : after) {
    while (b != before.end() && *b < key) ++b;
    if (b == before.end() || *b != key) ++count;
  }
  return count;
}

}  // namespace hg::octree
