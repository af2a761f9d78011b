#pragma once
/// @file
/// hullguardd configs for tests/data/small_cell.yaml: its three 320x180
/// cameras, depth 6, DDS off.

#include <string>

namespace hg::testing {

/// A daemon config with the camera blocks of tests/data/small_cell.yaml, each
/// with `source` as its source map, and `extra` (more sections) at the end.
inline std::string SmallCellConfig(const std::string& source, const std::string& extra = "") {
  std::string cameras;
  const char* blocks[] = {
      "{name: cam0, width: 320, height: 180, position: [-0.3, -0.3, 3.6], look_at: [2, 2, 1], "
      "K: &k [180.59645105620495, 0, 159.5, 0, 180.59645105620495, 89.5, 0, 0, 1], ",
      "{name: cam1, width: 320, height: 180, position: [4.3, 4.3, 3.6], look_at: [2, 2, 1], "
      "K: *k, ",
      "{name: cam2, width: 320, height: 180, position: [4.3, -0.3, 3.6], look_at: [2, 2, 1], "
      "K: *k, "};
  for (int c = 0; c < 3; ++c) {
    cameras += std::string("  - ") + blocks[c] + "source: " + source + "}\n";
  }
  return "cell: {bounds: {min: [0, 0, 0], max: [4, 4, 4]}}\n"
         "octree: {depth: 6, publish_depth: 6}\n"
         "timing: {rate_hz: 30, deadline_ms: 25, camera_timeout_ms: 200}\n"
         "dds: {enabled: false}\n"
         "cameras:\n" +
         cameras + extra;
}

}  // namespace hg::testing
