#pragma once
/// @file
/// Hand-built bodies of 13 capsules for renderer tests and benchmarks: they do
/// not depend on the body model, so a renderer test fails only for the renderer.

#include <cstdint>
#include <initializer_list>
#include <vector>

#include <Eigen/Core>

#include "sim/body.h"
#include "sim/scene.h"

namespace hg::testing {

/// A walking person: feet at `base`, facing `heading` (radians from +x), gait
/// phase `phase` (radians; 0 = legs together).
[[nodiscard]] sim::BodyState WalkingBody(const Eigen::Vector3d& base, double heading, double phase);

/// A person standing at `base` facing +x with the arms slightly away from the body.
[[nodiscard]] sim::BodyState StandingBody(const Eigen::Vector3d& base);

/// `per_part` random points inside every body part of every person of the
/// scene at scene time t_s (seeded, uniform in each capsule).
[[nodiscard]] std::vector<Eigen::Vector3d> PointsInPeople(const sim::Scene& scene, double t_s,
                                                          int per_part, std::uint64_t seed);

/// The cells of a 2^depth grid (x fastest) that some run of `listed` holds
/// (runs of cells x .. x + length - 1 at y, z): 1 there, 0 elsewhere.
template <class Cell>
std::vector<std::uint8_t> ListedCells(int depth,
                                      std::initializer_list<const std::vector<Cell>*> listed) {
  const int n = 1 << depth;
  std::vector<std::uint8_t> in(static_cast<std::size_t>(n) * n * n, 0);
  for (const auto* cells : listed) {
    for (const Cell& c : *cells) {
      for (int i = 0; i < c.length; ++i) {
        in[c.x + i + n * (c.y + static_cast<std::size_t>(n) * c.z)] = 1;
      }
    }
  }
  return in;
}

/// Of `points`, how many fall in a grid cell (2^depth per axis over `bounds`)
/// that is not in `listed` (ListedCells); points outside the bounds are not
/// counted.
template <class Cell>
int PointsInUnlistedCells(const std::vector<Eigen::Vector3d>& points, const Eigen::Vector3d& lo,
                          const Eigen::Vector3d& hi, int depth,
                          std::initializer_list<const std::vector<Cell>*> listed) {
  const int n = 1 << depth;
  const std::vector<std::uint8_t> in = ListedCells(depth, listed);
  int free = 0;
  for (const Eigen::Vector3d& p : points) {
    const Eigen::Vector3d rel = (p - lo).cwiseQuotient(hi - lo) * n;
    if ((rel.array() < 0).any() || (rel.array() >= n).any()) continue;
    const auto x = static_cast<std::size_t>(rel.x()), y = static_cast<std::size_t>(rel.y()),
               z = static_cast<std::size_t>(rel.z());
    free += in[x + n * (y + n * z)] == 0;
  }
  return free;
}

}  // namespace hg::testing
