#include "octree/ply.h"

#include <fstream>
#include <limits>
#include <vector>

#include "common/config_error.h"

namespace hg::octree {

void WriteOccupiedPly(const Octree& tree, const std::string& path) {
  struct Leaf {
    common::Box3 box;
    LeafState state;
  };
  std::vector<Leaf> leaves;
  tree.ForEachLeaf([&](const Cell& cell, LeafState s) {
    if (s != LeafState::kFree) leaves.push_back({CellBox(tree.config().bounds, cell), s});
  });
  std::ofstream out(path);
  if (!out) throw common::ConfigError(path + ": cannot open for writing");
  out << "ply\nformat ascii 1.0\ncomment hullguard occupied (red 200 40 40) and occluded (grey 128 "
         "128 128) leaves as boxes\n"
      << "element vertex " << 8 * leaves.size()
      << "\nproperty double x\nproperty double y\nproperty double z\n"
      << "property uchar red\nproperty uchar green\nproperty uchar blue\n"
      << "element face " << 6 * leaves.size() << "\nproperty list uchar int vertex_indices\n"
      << "end_header\n";
  // Doubles, every digit: a cell far from the origin (1.6 cm at a million
  // metres) is no float, and 9 digits rounded its faces inward.
  out.precision(std::numeric_limits<double>::max_digits10);
  for (const Leaf& l : leaves) {
    const char* colour = l.state == LeafState::kOccluded ? " 128 128 128\n" : " 200 40 40\n";
    for (int i = 0; i < 8; ++i) {
      const Eigen::Vector3d p = l.box.Corner(i);
      out << p.x() << ' ' << p.y() << ' ' << p.z() << colour;
    }
  }
  // Corner bits: 1 = x max, 2 = y max, 4 = z max; faces wound outward.
  static constexpr int kFaces[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                                       {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (std::size_t l = 0; l < leaves.size(); ++l) {
    const std::size_t base = 8 * l;
    for (const auto& f : kFaces) {
      out << "4 " << base + f[0] << ' ' << base + f[1] << ' ' << base + f[2] << ' ' << base + f[3]
          << '\n';
    }
  }
  if (!out) throw common::ConfigError(path + ": write failed");
}

}  // namespace hg::octree
