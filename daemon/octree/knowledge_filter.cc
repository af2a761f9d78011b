#include "octree/knowledge_filter.h"

#include <numeric>
#include <optional>
#include <unordered_map>
#include <utility>
#include <vector>

namespace hg::octree {

PointState KnowledgeFilterResult::StateAt(const Octree& tree, const Eigen::Vector3d& p_W) const {
  const auto leaf = tree.LeafAt(p_W);
  if (!leaf) return PointState::kOutside;
  if (leaf->second == LeafState::kOccupied && IsDropped(leaf->first)) return PointState::kFree;
  return tree.StateAt(p_W);
}

KnowledgeFilterResult FilterSmallComponents(const Octree& tree, double min_volume_m3) {
  const common::Box3& bounds = tree.config().bounds;
  std::vector<Cell> cells;
  std::vector<Cell> occluded;
  tree.ForEachLeaf([&](const Cell& c, LeafState s) {
    if (s == LeafState::kOccupied) cells.push_back(c);
    if (s == LeafState::kOccluded) occluded.push_back(c);
  });
  std::unordered_map<std::uint64_t, int> index;
  index.reserve(cells.size() * 2);
  for (int i = 0; i < static_cast<int>(cells.size()); ++i) {
    index.emplace(KnowledgeFilterResult::Key(cells[i]), i);
  }
  // Whether the leaf touches occluded space or a face of the bounds.
  std::vector<char> anchored(cells.size(), 0);
  std::vector<int> parent(cells.size());
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
  };
  // Probe the 26 neighbour directions just outside a leaf, at the middle of
  // the face, edge or corner: the finest cell there, by integer coordinates
  // (exact wherever the bounds lie; a probe by world coordinates just outside
  // the leaf falls back inside it where the coordinates are large). A
  // touching leaf of the same or a coarser level always holds that probe
  // (octree cells are aligned), and a finer touching leaf finds this one from
  // its own side: occupied leaves probe to join occupied neighbours and to
  // find occluded ones or the bounds' faces, and occluded leaves probe to
  // find the occupied leaves they touch, so that a coarse occupied leaf
  // beside finer occluded ones is anchored too.
  const int depth = tree.config().depth;
  const std::int64_t side = std::int64_t{1} << depth;
  auto for_each_neighbour = [&](const Cell& cell, auto&& visit) {
    const std::int64_t size = std::int64_t{1} << (depth - cell.level);
    const std::int64_t lo[3] = {cell.x * size, cell.y * size, cell.z * size};
    for (int d = 0; d < 27; ++d) {
      const int dir[3] = {d % 3 - 1, (d / 3) % 3 - 1, d / 9 - 1};
      if (dir[0] == 0 && dir[1] == 0 && dir[2] == 0) continue;
      std::int64_t q[3];
      bool inside = true;
      for (int a = 0; a < 3; ++a) {
        q[a] = dir[a] < 0 ? lo[a] - 1 : dir[a] > 0 ? lo[a] + size : lo[a] + size / 2;
        inside = inside && q[a] >= 0 && q[a] < side;
      }
      visit(inside ? tree.LeafContaining({depth, static_cast<std::uint32_t>(q[0]),
                                          static_cast<std::uint32_t>(q[1]),
                                          static_cast<std::uint32_t>(q[2])})
                   : std::nullopt);
    }
  };
  auto occupied_index = [&](const std::optional<std::pair<Cell, LeafState>>& leaf) {
    if (!leaf || leaf->second != LeafState::kOccupied) return -1;
    const auto it = index.find(KnowledgeFilterResult::Key(leaf->first));
    return it == index.end() ? -1 : it->second;
  };
  for (int i = 0; i < static_cast<int>(cells.size()); ++i) {
    for_each_neighbour(cells[i], [&](const auto& leaf) {
      if (!leaf || leaf->second == LeafState::kOccluded) {
        anchored[i] = 1;  // Outside the bounds, or beside space no camera sees.
        return;
      }
      if (const int j = occupied_index(leaf); j >= 0) parent[find(i)] = find(j);
    });
  }
  for (const Cell& cell : occluded) {
    for_each_neighbour(cell, [&](const auto& leaf) {
      if (const int j = occupied_index(leaf); j >= 0) anchored[j] = 1;
    });
  }
  std::vector<double> volume(cells.size(), 0.0);
  std::vector<char> kept(cells.size(), 0);  // Per component root: anchored somewhere.
  for (int i = 0; i < static_cast<int>(cells.size()); ++i) {
    volume[find(i)] += CellBox(bounds, cells[i]).Volume();
    if (anchored[i] != 0) kept[find(i)] = 1;
  }
  auto dropped = [&](int root) { return kept[root] == 0 && volume[root] < min_volume_m3; };
  KnowledgeFilterResult result;
  for (int i = 0; i < static_cast<int>(cells.size()); ++i) {
    if (find(i) != i) continue;
    ++result.components;
    if (dropped(i)) {
      ++result.dropped_components;
      result.dropped_volume_m3 += volume[i];
    }
  }
  for (int i = 0; i < static_cast<int>(cells.size()); ++i) {
    if (dropped(find(i))) {
      result.dropped_.insert(KnowledgeFilterResult::Key(cells[i]));
    }
  }
  return result;
}

}  // namespace hg::octree
