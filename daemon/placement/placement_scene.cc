#include "placement/placement_scene.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Geometry>

#include "common/config_error.h"
#include "sim/solids.h"

namespace hg::placement {
namespace {

using common::ConfigError;
using Eigen::Vector3d;

/// Relative slack of the triangle-box overlap test: it only ever adds voxels
/// to the obstacles (space never counts as watched because of rounding).
constexpr double kOverlapSlack = 1e-9;

/// True when the triangle may overlap the axis-aligned box (centre, half):
/// separating-axis test over the box axes, the triangle normal and the nine
/// edge-axis cross products, with a small slack towards "overlaps".
bool TriangleOverlapsBox(const Vector3d& centre, const Vector3d& half, const Vector3d& p0,
                         const Vector3d& p1, const Vector3d& p2) {
  const std::array<Vector3d, 3> v = {p0 - centre, p1 - centre, p2 - centre};
  const double scale = 1.0 + half.maxCoeff() +
                       std::max({v[0].lpNorm<Eigen::Infinity>(), v[1].lpNorm<Eigen::Infinity>(),
                                 v[2].lpNorm<Eigen::Infinity>()});
  auto separated = [&](const Vector3d& axis) {
    const double a_norm = axis.lpNorm<1>();
    if (a_norm == 0.0) return false;  // Parallel edge and box axis: no information.
    const double d0 = axis.dot(v[0]);
    const double d1 = axis.dot(v[1]);
    const double d2 = axis.dot(v[2]);
    const double lo = std::min({d0, d1, d2});
    const double hi = std::max({d0, d1, d2});
    const double r = half.cwiseProduct(axis.cwiseAbs()).sum();
    const double slack = kOverlapSlack * a_norm * scale;
    return lo > r + slack || hi < -r - slack;
  };
  for (int i = 0; i < 3; ++i) {
    if (separated(Vector3d::Unit(i))) return false;
  }
  const std::array<Vector3d, 3> edges = {v[1] - v[0], v[2] - v[1], v[0] - v[2]};
  if (separated(edges[0].cross(edges[1]))) return false;
  for (int i = 0; i < 3; ++i) {
    for (const Vector3d& e : edges) {
      if (separated(Vector3d::Unit(i).cross(e))) return false;
    }
  }
  return true;
}

/// Inclusive voxel index range along one axis covering [lo, hi].
void AxisRange(double lo, double hi, double origin, double cell, int n, int* first, int* last) {
  *first = std::max(0, static_cast<int>(std::floor((lo - origin) / cell)) - 1);
  *last = std::min(n - 1, static_cast<int>(std::floor((hi - origin) / cell)) + 1);
}

/// Marks the voxels touched by `mesh`: those a triangle overlaps, then those
/// inside the closed surface (tested at the voxel centre).
void MarkMesh(const VoxelGrid& grid, const geometry::TriangleMesh& mesh,
              std::vector<std::uint8_t>* obstacle) {
  if (mesh.triangles.empty()) return;
  const Vector3d half = 0.5 * grid.cell_m;
  Vector3d mesh_min = mesh.vertices.front();
  Vector3d mesh_max = mesh_min;
  for (const Vector3d& p : mesh.vertices) {
    mesh_min = mesh_min.cwiseMin(p);
    mesh_max = mesh_max.cwiseMax(p);
  }
  std::vector<std::uint8_t> touched(obstacle->size(), 0);
  for (const auto& tri : mesh.triangles) {
    const Vector3d& a = mesh.vertices[tri[0]];
    const Vector3d& b = mesh.vertices[tri[1]];
    const Vector3d& c = mesh.vertices[tri[2]];
    const Vector3d lo = a.cwiseMin(b).cwiseMin(c);
    const Vector3d hi = a.cwiseMax(b).cwiseMax(c);
    int i0, i1, j0, j1, k0, k1;
    AxisRange(lo.x(), hi.x(), grid.bounds.min.x(), grid.cell_m.x(), grid.nx, &i0, &i1);
    AxisRange(lo.y(), hi.y(), grid.bounds.min.y(), grid.cell_m.y(), grid.ny, &j0, &j1);
    AxisRange(lo.z(), hi.z(), grid.bounds.min.z(), grid.cell_m.z(), grid.nz, &k0, &k1);
    for (int k = k0; k <= k1; ++k) {
      for (int j = j0; j <= j1; ++j) {
        for (int i = i0; i <= i1; ++i) {
          const int index = grid.Index(i, j, k);
          if (touched[index] != 0) continue;
          const common::Box3 box = grid.VoxelBox(i, j, k);
          if (TriangleOverlapsBox(0.5 * (box.min + box.max), half, a, b, c)) touched[index] = 1;
        }
      }
    }
  }
  // A voxel no triangle touches lies wholly inside or wholly outside.
  const sim::SolidGeometry solid = sim::MeshSolid{mesh};
  int i0, i1, j0, j1, k0, k1;
  AxisRange(mesh_min.x(), mesh_max.x(), grid.bounds.min.x(), grid.cell_m.x(), grid.nx, &i0, &i1);
  AxisRange(mesh_min.y(), mesh_max.y(), grid.bounds.min.y(), grid.cell_m.y(), grid.ny, &j0, &j1);
  AxisRange(mesh_min.z(), mesh_max.z(), grid.bounds.min.z(), grid.cell_m.z(), grid.nz, &k0, &k1);
  for (int k = k0; k <= k1; ++k) {
    for (int j = j0; j <= j1; ++j) {
      for (int i = i0; i <= i1; ++i) {
        const int index = grid.Index(i, j, k);
        if (touched[index] != 0) {
          (*obstacle)[index] = 1;
          continue;
        }
        const common::Box3 box = grid.VoxelBox(i, j, k);
        if (sim::Contains(solid, 0.5 * (box.min + box.max))) (*obstacle)[index] = 1;
      }
    }
  }
}

/// True when a capsule of `radius` around the vertical segment at `xy` from
/// z_lo to z_hi keeps clear of every obstacle voxel (tested against the
/// voxel boxes, so it errs towards "blocked").
bool CapsuleClear(const VoxelGrid& grid, const std::vector<std::uint8_t>& obstacle,
                  const Eigen::Vector2d& xy, double z_lo, double z_hi, double radius) {
  int i0, i1, j0, j1, k0, k1;
  AxisRange(xy.x() - radius, xy.x() + radius, grid.bounds.min.x(), grid.cell_m.x(), grid.nx, &i0,
            &i1);
  AxisRange(xy.y() - radius, xy.y() + radius, grid.bounds.min.y(), grid.cell_m.y(), grid.ny, &j0,
            &j1);
  AxisRange(z_lo - radius, z_hi + radius, grid.bounds.min.z(), grid.cell_m.z(), grid.nz, &k0, &k1);
  for (int k = k0; k <= k1; ++k) {
    for (int j = j0; j <= j1; ++j) {
      for (int i = i0; i <= i1; ++i) {
        if (obstacle[grid.Index(i, j, k)] == 0) continue;
        const common::Box3 box = grid.VoxelBox(i, j, k);
        // Distance from the voxel box to the capsule's axis segment, bounded
        // below by the horizontal and vertical gaps.
        const double dx = std::max({box.min.x() - xy.x(), 0.0, xy.x() - box.max.x()});
        const double dy = std::max({box.min.y() - xy.y(), 0.0, xy.y() - box.max.y()});
        const double dz = std::max({box.min.z() - z_hi, 0.0, z_lo - box.max.z()});
        if (dx * dx + dy * dy + dz * dz < radius * radius) return false;
      }
    }
  }
  return true;
}

/// The occluder of a mesh: closed when every directed edge appears once and
/// its reverse once; then turned so that its signed volume is positive.
Occluder MakeOccluder(const geometry::TriangleMesh& mesh) {
  Occluder o;
  o.mesh = mesh;
  if (!mesh.vertices.empty()) {
    o.bounds.min = o.bounds.max = mesh.vertices.front();
    for (const Vector3d& p : mesh.vertices) {
      o.bounds.min = o.bounds.min.cwiseMin(p);
      o.bounds.max = o.bounds.max.cwiseMax(p);
    }
  }
  std::map<std::pair<int, int>, int> edges;
  double volume = 0.0;
  for (const auto& t : mesh.triangles) {
    for (int i = 0; i < 3; ++i) ++edges[{t[i], t[(i + 1) % 3]}];
    volume += mesh.vertices[t[0]].dot(mesh.vertices[t[1]].cross(mesh.vertices[t[2]]));
  }
  o.closed = !mesh.triangles.empty();
  for (const auto& [edge, count] : edges) {
    const auto reverse = edges.find({edge.second, edge.first});
    if (count != 1 || reverse == edges.end() || reverse->second != 1) {
      o.closed = false;
      break;
    }
  }
  if (o.closed && volume < 0.0) {
    for (auto& t : o.mesh.triangles) std::swap(t[1], t[2]);
  }
  if (o.closed && volume == 0.0) o.closed = false;
  o.solid = sim::MeshSolid{o.mesh};
  return o;
}

}  // namespace

// Limits of the model's size: beyond them a run takes hours.
constexpr double kMaxVoxels = 2.0e7;
constexpr double kMaxPersonSamples = 1.0e4;

PlacementScene BuildPlacementScene(const sim::Scene& scene, const PlacementIntrinsics& intrinsics,
                                   const ModelOptions& options) {
  const std::string file = scene.source_file.empty() ? scene.name : scene.source_file;
  if (!(options.voxel_m > 0.0)) throw ConfigError::At(file, 0, "voxel: must be > 0");
  if (options.render_width_px < 8) {
    throw ConfigError::At(file, 0, "render width: must be >= 8 pixels");
  }
  if (!(options.person_radius_m > 0.0) ||
      !(options.person_height_m > 2.0 * options.person_radius_m)) {
    throw ConfigError::At(file, 0, "person: needs radius > 0 and height > 2 * radius");
  }
  if (!(options.person_spacing_m > 0.0)) {
    throw ConfigError::At(file, 0, "person spacing: must be > 0");
  }
  if (intrinsics.width < 1 || intrinsics.height < 1 || !(intrinsics.K(0, 0) > 0) ||
      !(intrinsics.K(1, 1) > 0)) {
    throw ConfigError::At(file, 0, "intrinsics: need width, height >= 1 and fx, fy > 0");
  }

  PlacementScene out;
  out.name = scene.name;
  out.source_file = scene.source_file;
  out.intrinsics = intrinsics;
  out.options = options;
  out.surfaces = MountingSurfacesOf(scene);

  VoxelGrid& grid = out.grid;
  grid.bounds = scene.bounds;
  const Vector3d size = scene.bounds.Size();
  // Counted in doubles first: a tiny voxel overflows an int (and became a
  // single voxel).
  std::array<double, 3> counts{};
  for (int a = 0; a < 3; ++a)
    counts[a] = std::max(1.0, std::ceil(size[a] / options.voxel_m - 1e-9));
  if (counts[0] * counts[1] * counts[2] > kMaxVoxels) {
    throw ConfigError::At(file, 0, "voxel: too small for this cell (more than 2e7 voxels)");
  }
  std::array<int, 3> n{};
  for (int a = 0; a < 3; ++a) n[a] = static_cast<int>(counts[a]);
  grid.nx = n[0];
  grid.ny = n[1];
  grid.nz = n[2];
  grid.cell_m = Vector3d(size.x() / n[0], size.y() / n[1], size.z() / n[2]);
  const double sample_columns = std::max(1.0, std::round(size.x() / options.person_spacing_m)) *
                                std::max(1.0, std::round(size.y() / options.person_spacing_m));
  if (sample_columns > kMaxPersonSamples) {
    throw ConfigError::At(file, 0,
                          "person spacing: too small for this cell (more than 10000 sample "
                          "people; each is tested against every camera at every evaluation)");
  }

  out.obstacle.assign(grid.Count(), 0);
  for (const sim::Solid& solid : scene.obstacles) {
    out.obstacle_meshes.push_back(sim::Tessellate(solid.geometry, kObstacleSegments));
  }
  for (const geometry::TriangleMesh& mesh : out.obstacle_meshes) {
    MarkMesh(grid, mesh, &out.obstacle);
    out.occluders.push_back(MakeOccluder(mesh));
  }
  out.target_voxels =
      static_cast<int>(std::count(out.obstacle.begin(), out.obstacle.end(), std::uint8_t{0}));

  // Sample people: one per cell of a spacing grid over the floor, at the cell
  // centre or, where that is blocked, at the nearest free candidate of a 7 x 7
  // pattern inside the cell.
  const double r = options.person_radius_m;
  const double z_lo = scene.bounds.min.z() + r;
  const double z_hi = scene.bounds.min.z() + options.person_height_m - r;
  const int sx = std::max(1, static_cast<int>(std::lround(size.x() / options.person_spacing_m)));
  const int sy = std::max(1, static_cast<int>(std::lround(size.y() / options.person_spacing_m)));
  const double cx = size.x() / sx;
  const double cy = size.y() / sy;
  for (int j = 0; j < sy; ++j) {
    for (int i = 0; i < sx; ++i) {
      const Eigen::Vector2d centre(scene.bounds.min.x() + (i + 0.5) * cx,
                                   scene.bounds.min.y() + (j + 0.5) * cy);
      bool found = false;
      Eigen::Vector2d best = centre;
      double best_d2 = 0.0;
      for (int b = -3; b <= 3; ++b) {
        for (int a = -3; a <= 3; ++a) {
          const Eigen::Vector2d p = centre + Eigen::Vector2d(a * cx / 7.0, b * cy / 7.0);
          // Keep the whole capsule inside the cell.
          if (p.x() - r < scene.bounds.min.x() || p.x() + r > scene.bounds.max.x() ||
              p.y() - r < scene.bounds.min.y() || p.y() + r > scene.bounds.max.y()) {
            continue;
          }
          const double d2 = (p - centre).squaredNorm();
          if (found && d2 >= best_d2) continue;
          if (!CapsuleClear(grid, out.obstacle, p, z_lo, z_hi, r)) continue;
          found = true;
          best = p;
          best_d2 = d2;
        }
      }
      if (!found) continue;
      PersonSample sample;
      sample.feet_W = Vector3d(best.x(), best.y(), scene.bounds.min.z());
      sample.a_W = Vector3d(best.x(), best.y(), z_lo);
      sample.b_W = Vector3d(best.x(), best.y(), z_hi);
      sample.radius_m = r;
      out.samples.push_back(sample);
    }
  }
  if (out.samples.empty()) {
    throw ConfigError::At(file, 0,
                          "no floor position where a sample person (capsule) keeps clear of the "
                          "obstacles");
  }
  return out;
}

}  // namespace hg::placement
