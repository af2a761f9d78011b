#include "support/dense_carve.h"

#include <algorithm>
#include <sstream>

#include "geometry/footprint.h"

namespace hg::testing {
namespace {

using octree::Verdict;

// `*sees_foreground`: the camera is full, or mixed through its silhouette.
Verdict OracleVerdict(const geometry::CameraModel& cam, const geometry::BoxProjector& proj,
                      const common::ImageU8* mask, const geometry::ObstacleDepthMap* depth,
                      const common::Box3& box, bool* sees_foreground) {
  using Side = geometry::Footprint::Side;
  *sees_foreground = false;
  const geometry::Footprint fp = proj.Project(box.min, box.max);
  if (mask == nullptr || fp.side == Side::kBehind) return Verdict::kHidden;
  if (fp.side == Side::kStraddling) return Verdict::kMixed;
  const int u0 = std::max(fp.rect.u0, 0), u1 = std::min(fp.rect.u1, cam.width - 1);
  const int v0 = std::max(fp.rect.v0, 0), v1 = std::min(fp.rect.v1, cam.height - 1);
  if (u1 < u0 || v1 < v0) return Verdict::kHidden;
  const bool inside =
      fp.rect.u0 >= 0 && fp.rect.v0 >= 0 && fp.rect.u1 < cam.width && fp.rect.v1 < cam.height;
  bool has_fg = false, has_bg = false;
  float near_min = geometry::ObstacleDepthMap::kNone;
  float centre_max = -geometry::ObstacleDepthMap::kNone;
  for (int v = v0; v <= v1; ++v) {
    for (int u = u0; u <= u1; ++u) {
      (mask->At(u, v) > 127 ? has_fg : has_bg) = true;
      if (depth != nullptr) {
        const std::size_t i = static_cast<std::size_t>(v) * cam.width + u;
        near_min = std::min(near_min, depth->near_depth[i]);
        centre_max = std::max(centre_max, depth->centre_depth[i]);
      }
    }
  }
  if (inside && !has_fg && near_min > fp.z_far) return Verdict::kFree;
  if (depth != nullptr && centre_max < fp.z_near) return Verdict::kHidden;
  *sees_foreground = has_fg;
  return has_bg ? Verdict::kMixed : Verdict::kFull;
}

}  // namespace

DenseGrid DenseCarve(const common::Box3& bounds, int depth,
                     const std::vector<geometry::CameraModel>& cameras,
                     const std::vector<const common::ImageU8*>& masks,
                     const std::vector<geometry::ObstacleDepthMap>& depth_maps,
                     const std::vector<double>& margins) {
  DenseGrid grid;
  grid.depth = depth;
  const std::uint32_t n = 1u << depth;
  grid.states.assign(static_cast<std::size_t>(n) * n * n, 0);
  std::vector<geometry::BoxProjector> projectors;
  for (const auto& cam : cameras) projectors.emplace_back(cam.K, cam.R_CW, cam.t_CW);
  for (std::uint32_t z = 0; z < n; ++z) {
    for (std::uint32_t y = 0; y < n; ++y) {
      for (std::uint32_t x = 0; x < n; ++x) {
        const common::Box3 box = octree::CellBox(bounds, {depth, x, y, z});
        // Free when a camera certifies it; occupied when a camera sees foreground
        // in it; occluded otherwise (every camera hidden, or mixed only through
        // geometry: the edge of its view or an obstacle's depth).
        bool any_free = false, any_foreground = false;
        for (std::size_t c = 0; c < cameras.size() && !any_free; ++c) {
          bool foreground = false;
          common::Box3 grown = box;
          if (!margins.empty() && margins[c] != 0.0) {
            grown.min = box.min.array() - margins[c];
            grown.max = box.max.array() + margins[c];
          }
          const Verdict v =
              OracleVerdict(cameras[c], projectors[c], masks[c],
                            depth_maps.empty() ? nullptr : &depth_maps[c], grown, &foreground);
          any_free = v == Verdict::kFree;
          any_foreground = any_foreground || (foreground && v != Verdict::kHidden);
        }
        const octree::LeafState s = any_free         ? octree::LeafState::kFree
                                    : any_foreground ? octree::LeafState::kOccupied
                                                     : octree::LeafState::kOccluded;
        grid.states[grid.Index(x, y, z)] = static_cast<std::uint8_t>(s);
      }
    }
  }
  return grid;
}

DenseGrid Rasterize(const octree::Octree& tree) {
  DenseGrid grid;
  grid.depth = tree.config().depth;
  const std::uint32_t n = 1u << grid.depth;
  grid.states.assign(static_cast<std::size_t>(n) * n * n, 255);
  tree.ForEachLeaf([&](const octree::Cell& cell, octree::LeafState s) {
    const int shift = grid.depth - cell.level;
    const std::uint32_t size = 1u << shift;
    for (std::uint32_t z = cell.z << shift; z < (cell.z << shift) + size; ++z) {
      for (std::uint32_t y = cell.y << shift; y < (cell.y << shift) + size; ++y) {
        for (std::uint32_t x = cell.x << shift; x < (cell.x << shift) + size; ++x) {
          grid.states[grid.Index(x, y, z)] = static_cast<std::uint8_t>(s);
        }
      }
    }
  });
  return grid;
}

std::vector<std::pair<octree::Cell, octree::LeafState>> Leaves(const octree::Octree& tree) {
  std::vector<std::pair<octree::Cell, octree::LeafState>> out;
  tree.ForEachLeaf([&](const octree::Cell& c, octree::LeafState s) { out.emplace_back(c, s); });
  return out;
}

std::string LeafDifference(const octree::Octree& a, const octree::Octree& b) {
  const auto la = Leaves(a);
  const auto lb = Leaves(b);
  if (la == lb) return "";
  std::ostringstream out;
  out << la.size() << " leaves against " << lb.size();
  auto describe = [&](const std::pair<octree::Cell, octree::LeafState>& leaf) {
    const octree::Cell& c = leaf.first;
    out << "level " << c.level << " (" << c.x << ", " << c.y << ", " << c.z << ") "
        << (leaf.second == octree::LeafState::kFree       ? "free"
            : leaf.second == octree::LeafState::kOccupied ? "occupied"
                                                          : "occluded");
  };
  std::size_t i = 0;
  while (i < la.size() && i < lb.size() && la[i] == lb[i]) ++i;
  out << "; first difference at leaf " << i << ": ";
  if (i < la.size()) describe(la[i]);
  out << " against ";
  if (i < lb.size()) describe(lb[i]);
  return out.str();
}

}  // namespace hg::testing
