#pragma once
/// @file
/// Occupied runs of a published occupancy grid from a predicate (tests that
/// hand the tracker snapshots of simple shapes).

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "pipeline/snapshot.h"

namespace hg::test {

/// The cells of a 2^depth grid over [0, edge_m]^3 whose centres satisfy
/// inside(centre), as runs along x.
template <typename Inside>
std::vector<pipeline::GridRun> RunsInside(int depth, double edge_m, Inside inside) {
  std::vector<pipeline::GridRun> runs;
  const int n = 1 << depth;
  const double cell = edge_m / n;
  for (int z = 0; z < n; ++z) {
    for (int y = 0; y < n; ++y) {
      int start = -1;
      for (int x = 0; x <= n; ++x) {
        const bool in =
            x < n && inside(Eigen::Vector3d((x + 0.5) * cell, (y + 0.5) * cell, (z + 0.5) * cell));
        if (in && start < 0) start = x;
        if (!in && start >= 0) {
          runs.push_back({static_cast<std::uint16_t>(start), static_cast<std::uint16_t>(y),
                          static_cast<std::uint16_t>(z), static_cast<std::uint16_t>(x - start)});
          start = -1;
        }
      }
    }
  }
  return runs;
}

}  // namespace hg::test
