#include "tracking/static_scene.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <type_traits>

#include <Eigen/Geometry>

#include "common/check.h"
#include "geometry/obstacle_depth.h"

namespace hg::tracking {
namespace {

using Eigen::Vector3d;
using Eigen::Vector3i;

/// Relative growth of every voxel box in the overlap tests: rounding can only
/// add voxels to an obstacle, never drop one that it touches.
constexpr double kGrowVoxels = 1e-9;

/// True when the projections of the triangle (vertices relative to the box
/// centre) and of the centred box of half extents h overlap on `axis`.
bool OverlapOnAxis(const Vector3d& axis, const Vector3d& v0, const Vector3d& v1, const Vector3d& v2,
                   const Vector3d& h) {
  const double p0 = axis.dot(v0);
  const double p1 = axis.dot(v1);
  const double p2 = axis.dot(v2);
  const double r =
      h.x() * std::abs(axis.x()) + h.y() * std::abs(axis.y()) + h.z() * std::abs(axis.z());
  const double lo = std::min({p0, p1, p2});
  const double hi = std::max({p0, p1, p2});
  const double tol = 1e-12 * (std::abs(lo) + std::abs(hi) + r);
  return !(lo > r + tol || hi < -r - tol);
}

/// Separating-axis test of a triangle against the centred box of half extents
/// h (vertices relative to the box centre): 3 box normals, the triangle
/// normal, 9 edge cross products. Degenerate axes are skipped (they cannot
/// separate anything the others do not, and skipping only keeps voxels).
bool TriangleTouchesBox(const Vector3d& v0, const Vector3d& v1, const Vector3d& v2,
                        const Vector3d& h) {
  for (int a = 0; a < 3; ++a) {
    if (!OverlapOnAxis(Vector3d::Unit(a), v0, v1, v2, h)) return false;
  }
  const std::array<Vector3d, 3> edges = {v1 - v0, v2 - v1, v0 - v2};
  const Vector3d n = edges[0].cross(edges[1]);
  if (n.squaredNorm() > 0.0 && !OverlapOnAxis(n, v0, v1, v2, h)) return false;
  for (int a = 0; a < 3; ++a) {
    for (const Vector3d& e : edges) {
      const Vector3d axis = Vector3d::Unit(a).cross(e);
      if (axis.squaredNorm() > 0.0 && !OverlapOnAxis(axis, v0, v1, v2, h)) return false;
    }
  }
  return true;
}

/// Oriented box against an axis-aligned voxel box (centre c, half extent h):
/// 15 separating axes; near-parallel edge pairs are skipped (conservative).
bool BoxTouchesVoxel(const sim::BoxSolid& b, const Vector3d& c, double h) {
  const Vector3d d = c - b.centre_W;
  const Vector3d he = b.half_extents_m.cwiseAbs();
  auto separated = [&](const Vector3d& axis) {
    const double ra = h * axis.cwiseAbs().sum();
    const double rb = he.x() * std::abs(axis.dot(b.R_WB.col(0))) +
                      he.y() * std::abs(axis.dot(b.R_WB.col(1))) +
                      he.z() * std::abs(axis.dot(b.R_WB.col(2)));
    const double dist = std::abs(axis.dot(d));
    return dist > (ra + rb) * (1.0 + 1e-12) + 1e-15;
  };
  for (int a = 0; a < 3; ++a) {
    if (separated(Vector3d::Unit(a)) || separated(b.R_WB.col(a))) return false;
  }
  for (int a = 0; a < 3; ++a) {
    for (int k = 0; k < 3; ++k) {
      const Vector3d axis = Vector3d::Unit(a).cross(b.R_WB.col(k));
      if (axis.squaredNorm() > 1e-12 && separated(axis)) return false;
    }
  }
  return true;
}

/// Voxel index range [lo, hi] per axis covering the box [min, max] (closed),
/// with `pad` extra voxels each side, clipped to the grid.
bool GridRange(const VoxelGrid& g, const common::Box3& box, int pad, Vector3i* lo, Vector3i* hi) {
  const Vector3i n(g.nx(), g.ny(), g.nz());
  for (int a = 0; a < 3; ++a) {
    const double l = std::floor((box.min[a] - g.origin()[a]) / g.voxel_m()) - pad;
    const double u = std::floor((box.max[a] - g.origin()[a]) / g.voxel_m()) + pad;
    if (!(u >= 0.0) || !(l <= n[a] - 1.0)) return false;
    (*lo)[a] = static_cast<int>(std::max(l, 0.0));
    (*hi)[a] = static_cast<int>(std::min(u, n[a] - 1.0));
  }
  return true;
}

}  // namespace

void VoxelizeMesh(const VoxelGrid& g, const geometry::TriangleMesh& mesh,
                  std::vector<std::uint8_t>* mask) {
  HG_CHECK(mask->size() == g.size());
  if (mesh.triangles.empty()) return;
  common::Box3 box{Vector3d::Constant(std::numeric_limits<double>::infinity()),
                   Vector3d::Constant(-std::numeric_limits<double>::infinity())};
  for (const auto& t : mesh.triangles) {
    for (const int i : t) {
      box.min = box.min.cwiseMin(mesh.vertices[i]);
      box.max = box.max.cwiseMax(mesh.vertices[i]);
    }
  }
  if (!box.min.allFinite() || !box.max.allFinite()) return;
  const double v = g.voxel_m();
  const Vector3i n(g.nx(), g.ny(), g.nz());
  // Local grid: the mesh's voxels plus one voxel each side, clipped to two
  // voxels beyond the grid. A clipped side does not seed the outside search.
  Vector3i lo, hi;
  std::array<bool, 6> seeds{};  // -x, +x, -y, +y, -z, +z.
  for (int a = 0; a < 3; ++a) {
    const double l = std::floor((box.min[a] - g.origin()[a]) / v) - 1.0;
    const double u = std::floor((box.max[a] - g.origin()[a]) / v) + 1.0;
    if (u < -2.0 || l > n[a] + 1.0) return;
    seeds[2 * a] = l >= -2.0;
    seeds[2 * a + 1] = u <= n[a] + 1.0;
    lo[a] = static_cast<int>(std::max(l, -2.0));
    hi[a] = static_cast<int>(std::min(u, n[a] + 1.0));
  }
  const Vector3i dims = hi - lo + Vector3i::Ones();
  const std::size_t local_size = static_cast<std::size_t>(dims.x()) * dims.y() * dims.z();
  auto local = [&](int x, int y, int z) {
    return (static_cast<std::size_t>(z - lo.z()) * dims.y() + (y - lo.y())) * dims.x() +
           (x - lo.x());
  };
  enum : std::uint8_t { kEmpty = 0, kSurface = 1, kOutside = 2 };
  std::vector<std::uint8_t> cells(local_size, kEmpty);
  const Vector3d half = Vector3d::Constant(0.5 * v * (1.0 + kGrowVoxels));
  for (const auto& t : mesh.triangles) {
    const Vector3d& a = mesh.vertices[t[0]];
    const Vector3d& b = mesh.vertices[t[1]];
    const Vector3d& c = mesh.vertices[t[2]];
    const Vector3d tmin = a.cwiseMin(b).cwiseMin(c);
    const Vector3d tmax = a.cwiseMax(b).cwiseMax(c);
    Vector3i r0, r1;
    bool empty = false;
    for (int k = 0; k < 3; ++k) {
      r0[k] = std::max(lo[k],
                       static_cast<int>(std::floor((tmin[k] - g.origin()[k]) / v - kGrowVoxels)));
      r1[k] = std::min(hi[k],
                       static_cast<int>(std::floor((tmax[k] - g.origin()[k]) / v + kGrowVoxels)));
      empty = empty || r0[k] > r1[k];
    }
    if (empty) continue;
    for (int z = r0.z(); z <= r1.z(); ++z) {
      for (int y = r0.y(); y <= r1.y(); ++y) {
        for (int x = r0.x(); x <= r1.x(); ++x) {
          std::uint8_t& cell = cells[local(x, y, z)];
          if (cell == kSurface) continue;
          const Vector3d centre = g.Centre(x, y, z);
          if (TriangleTouchesBox(a - centre, b - centre, c - centre, half)) cell = kSurface;
        }
      }
    }
  }
  // Outside: 6-connected search from the unclipped sides of the local grid.
  std::vector<Vector3i> stack;
  auto push = [&](int x, int y, int z) {
    std::uint8_t& cell = cells[local(x, y, z)];
    if (cell == kEmpty) {
      cell = kOutside;
      stack.emplace_back(x, y, z);
    }
  };
  for (int z = lo.z(); z <= hi.z(); ++z) {
    for (int y = lo.y(); y <= hi.y(); ++y) {
      for (int x = lo.x(); x <= hi.x(); ++x) {
        const bool seed = (x == lo.x() && seeds[0]) || (x == hi.x() && seeds[1]) ||
                          (y == lo.y() && seeds[2]) || (y == hi.y() && seeds[3]) ||
                          (z == lo.z() && seeds[4]) || (z == hi.z() && seeds[5]);
        if (seed) push(x, y, z);
      }
    }
  }
  while (!stack.empty()) {
    const Vector3i p = stack.back();
    stack.pop_back();
    for (int a = 0; a < 3; ++a) {
      for (const int s : {-1, 1}) {
        Vector3i q = p;
        q[a] += s;
        if (q[a] >= lo[a] && q[a] <= hi[a]) push(q.x(), q.y(), q.z());
      }
    }
  }
  for (int z = std::max(lo.z(), 0); z <= std::min(hi.z(), n.z() - 1); ++z) {
    for (int y = std::max(lo.y(), 0); y <= std::min(hi.y(), n.y() - 1); ++y) {
      for (int x = std::max(lo.x(), 0); x <= std::min(hi.x(), n.x() - 1); ++x) {
        if (cells[local(x, y, z)] != kOutside) (*mask)[g.Index(x, y, z)] = 1;
      }
    }
  }
}

void VoxelizeSolid(const VoxelGrid& g, const sim::SolidGeometry& solid,
                   std::vector<std::uint8_t>* mask) {
  HG_CHECK(mask->size() == g.size());
  if (const auto* m = std::get_if<sim::MeshSolid>(&solid)) {
    VoxelizeMesh(g, m->mesh, mask);
    return;
  }
  Vector3i lo, hi;
  if (!GridRange(g, sim::Bounds(solid), 1, &lo, &hi)) return;
  const double h = 0.5 * g.voxel_m() * (1.0 + kGrowVoxels);
  const double half_diagonal = std::sqrt(3.0) * h;
  for (int z = lo.z(); z <= hi.z(); ++z) {
    for (int y = lo.y(); y <= hi.y(); ++y) {
      for (int x = lo.x(); x <= hi.x(); ++x) {
        const Vector3d c = g.Centre(x, y, z);
        const bool hit = std::visit(
            [&](const auto& s) {
              using T = std::decay_t<decltype(s)>;
              if constexpr (std::is_same_v<T, sim::BoxSolid>) {
                return BoxTouchesVoxel(s, c, h);
              } else if constexpr (std::is_same_v<T, sim::CapsuleSolid>) {
                sim::BoxSolid voxel;
                voxel.centre_W = c;
                voxel.half_extents_m = Vector3d::Constant(h);
                return SegmentBoxDistanceSquared(s.a_W, s.b_W, voxel) <= s.radius_m * s.radius_m;
              } else if constexpr (std::is_same_v<T, sim::CylinderSolid>) {
                return PointCylinderDistance(c, s) <= half_diagonal;
              } else {
                return false;
              }
            },
            solid);
        if (hit) (*mask)[g.Index(x, y, z)] = 1;
      }
    }
  }
}

std::vector<common::Box3> MergeIntoBoxes(const VoxelGrid& g,
                                         const std::vector<std::uint8_t>& mask) {
  HG_CHECK(mask.size() == g.size());
  std::vector<std::uint8_t> used(g.size(), 0);
  auto free_marked = [&](int x, int y, int z) {
    const std::uint32_t i = g.Index(x, y, z);
    return mask[i] != 0 && used[i] == 0;
  };
  std::vector<common::Box3> boxes;
  const double v = g.voxel_m();
  for (int z = 0; z < g.nz(); ++z) {
    for (int y = 0; y < g.ny(); ++y) {
      for (int x = 0; x < g.nx(); ++x) {
        if (!free_marked(x, y, z)) continue;
        int x1 = x;
        while (x1 + 1 < g.nx() && free_marked(x1 + 1, y, z)) ++x1;
        auto row_free = [&](int yy, int zz) {
          for (int xx = x; xx <= x1; ++xx) {
            if (!free_marked(xx, yy, zz)) return false;
          }
          return true;
        };
        int y1 = y;
        while (y1 + 1 < g.ny() && row_free(y1 + 1, z)) ++y1;
        int z1 = z;
        auto layer_free = [&](int zz) {
          for (int yy = y; yy <= y1; ++yy) {
            if (!row_free(yy, zz)) return false;
          }
          return true;
        };
        while (z1 + 1 < g.nz() && layer_free(z1 + 1)) ++z1;
        for (int zz = z; zz <= z1; ++zz) {
          for (int yy = y; yy <= y1; ++yy) {
            for (int xx = x; xx <= x1; ++xx) used[g.Index(xx, yy, zz)] = 1;
          }
        }
        const Vector3d lo_corner = g.origin() + v * Vector3d(x, y, z);
        const Vector3d hi_corner = g.origin() + v * Vector3d(x1 + 1, y1 + 1, z1 + 1);
        boxes.push_back({lo_corner, hi_corner});
      }
    }
  }
  return boxes;
}

namespace {

/// Calls fn(i, p_C) for every voxel i of the grid with p_C its centre in the
/// frame of the pinhole camera.
template <typename Fn>
void ForEachVoxelCentre(const VoxelGrid& g, const geometry::CameraModel& pinhole, Fn fn) {
  const Vector3d step = pinhole.R_CW.col(0) * g.voxel_m();
  for (int z = 0; z < g.nz(); ++z) {
    for (int y = 0; y < g.ny(); ++y) {
      Vector3d p_C = pinhole.ToCamera(g.Centre(0, y, z));
      for (int x = 0; x < g.nx(); ++x, p_C += step) fn(g.Index(x, y, z), p_C);
    }
  }
}

/// Calls in_view(i) for every voxel i whose centre lies in the camera's view
/// (in front of it, projecting into the image), and then seen(i) when the
/// camera also sees it: not behind the obstacle surface seen through that
/// pixel. skip(i) true: the voxel is not tested.
template <typename Skip, typename InView, typename Seen>
void ForEachSeenVoxel(const VoxelGrid& g, const geometry::CameraModel& camera,
                      const std::vector<geometry::TriangleMesh>& occluders, Skip skip,
                      InView in_view, Seen seen) {
  const geometry::CameraModel pinhole = camera.Pinhole();
  const geometry::ObstacleDepthMap depth = geometry::RenderObstacleDepth(pinhole, occluders);
  ForEachVoxelCentre(g, pinhole, [&](std::uint32_t i, const Vector3d& p_C) {
    if (skip(i) || p_C.z() <= 0.0) return;
    const Eigen::Vector2d uv = pinhole.ProjectPinholeC(p_C);
    const double u = std::floor(uv.x() + 0.5);
    const double w = std::floor(uv.y() + 0.5);
    if (!(u >= 0.0 && w >= 0.0 && u < depth.width && w < depth.height)) return;
    in_view(i);
    const std::size_t pixel =
        static_cast<std::size_t>(w) * depth.width + static_cast<std::size_t>(u);
    // A camera inside an obstacle (ObstacleDepthMap::blocked) sees nothing,
    // as the pipeline reports it (failed, blocked).
    if (!depth.blocked && p_C.z() <= depth.centre_depth[pixel]) seen(i);
  });
}

}  // namespace

void MarkOccluded(const VoxelGrid& g, const std::vector<geometry::CameraModel>& cameras,
                  const std::vector<geometry::TriangleMesh>& occluders,
                  std::vector<VoxelState>* states) {
  HG_CHECK(states->size() == g.size());
  // 1: in some camera's view; 2: seen by some camera.
  std::vector<std::uint8_t> seen(g.size(), 0);
  for (const geometry::CameraModel& camera : cameras) {
    ForEachSeenVoxel(
        g, camera, occluders, [&](std::uint32_t i) { return seen[i] == 2; },
        [&](std::uint32_t i) { seen[i] = 1; }, [&](std::uint32_t i) { seen[i] = 2; });
  }
  for (std::size_t i = 0; i < g.size(); ++i) {
    const bool hidden = cameras.empty() || seen[i] == 1;
    if ((*states)[i] != VoxelState::kKnown && hidden) (*states)[i] = VoxelState::kOccluded;
  }
}

std::vector<std::uint8_t> OutOfView(const VoxelGrid& g,
                                    const std::vector<geometry::CameraModel>& cameras) {
  std::vector<std::uint8_t> out(g.size(), 1);
  const double r = std::sqrt(3.0) * g.voxel_m();
  for (const geometry::CameraModel& camera : cameras) {
    const geometry::CameraModel pinhole = camera.Pinhole();
    ForEachVoxelCentre(g, pinhole, [&](std::uint32_t i, const Vector3d& p_C) {
      if (out[i] == 0 || p_C.z() <= 2.0 * r) return;
      // A point p_C + d, |d| <= r, projects within f r (1 + |x / z|) / (z - r)
      // pixels of p_C's image along u (from the derivative of f x / z), and
      // likewise along v.
      const double a = r / (p_C.z() - r);
      const double margin_u = pinhole.K(0, 0) * a * (1.0 + std::abs(p_C.x() / p_C.z()));
      const double margin_v = pinhole.K(1, 1) * a * (1.0 + std::abs(p_C.y() / p_C.z()));
      const Eigen::Vector2d uv = pinhole.ProjectPinholeC(p_C);
      if (uv.x() - margin_u >= -0.5 && uv.y() - margin_v >= -0.5 &&
          uv.x() + margin_u <= camera.width - 0.5 && uv.y() + margin_v <= camera.height - 0.5) {
        out[i] = 0;
      }
    });
  }
  return out;
}

std::vector<std::uint16_t> CameraViews(const VoxelGrid& g,
                                       const std::vector<geometry::CameraModel>& cameras,
                                       const std::vector<geometry::TriangleMesh>& occluders,
                                       std::vector<std::uint8_t>* in_view) {
  std::vector<std::uint16_t> views(g.size(), 0);
  if (in_view != nullptr) in_view->assign(g.size(), 0);
  const int n = std::min(static_cast<int>(cameras.size()), kMaxViewCameras);
  for (int c = 0; c < n; ++c) {
    const auto bit = static_cast<std::uint16_t>(1U << c);
    ForEachSeenVoxel(
        g, cameras[c], occluders, [](std::uint32_t) { return false; },
        [&](std::uint32_t i) {
          if (in_view != nullptr) (*in_view)[i] = 1;
        },
        [&](std::uint32_t i) { views[i] |= bit; });
  }
  return views;
}

StaticVoxels BuildStaticVoxels(const VoxelGrid& g, const StaticScene& scene) {
  std::vector<std::uint8_t> known(g.size(), 0);
  std::vector<std::uint8_t> mesh_known(g.size(), 0);
  std::vector<geometry::TriangleMesh> occluders = scene.meshes;
  for (const geometry::TriangleMesh& mesh : scene.meshes) VoxelizeMesh(g, mesh, &mesh_known);
  for (const sim::SolidGeometry& solid : scene.solids) {
    if (std::holds_alternative<sim::MeshSolid>(solid)) {
      VoxelizeSolid(g, solid, &mesh_known);
      occluders.push_back(std::get<sim::MeshSolid>(solid).mesh);
    } else {
      VoxelizeSolid(g, solid, &known);
      occluders.push_back(sim::Tessellate(solid));
    }
  }
  StaticVoxels out;
  out.states.assign(g.size(), VoxelState::kFree);
  for (std::size_t i = 0; i < g.size(); ++i) {
    if (known[i] != 0 || mesh_known[i] != 0) out.states[i] = VoxelState::kKnown;
  }
  std::vector<std::uint8_t> in_view;
  if (!scene.cameras.empty()) out.views = CameraViews(g, scene.cameras, occluders, &in_view);
  if (scene.cameras.size() <= static_cast<std::size_t>(kMaxViewCameras) && !scene.cameras.empty()) {
    // The views already say which voxels some camera sees.
    for (std::size_t i = 0; i < g.size(); ++i) {
      if (out.states[i] != VoxelState::kKnown && out.views[i] == 0 && in_view[i] != 0) {
        out.states[i] = VoxelState::kOccluded;
      }
    }
  } else {
    MarkOccluded(g, scene.cameras, occluders, &out.states);
  }
  if (!scene.cameras.empty()) out.out_of_view = OutOfView(g, scene.cameras);
  out.mesh_boxes = MergeIntoBoxes(g, mesh_known);
  return out;
}

std::vector<CollisionShape> CollisionShapes(const StaticScene& scene, const StaticVoxels& voxels) {
  std::vector<CollisionShape> shapes;
  for (const sim::SolidGeometry& solid : scene.solids) {
    std::visit(
        [&](const auto& s) {
          using T = std::decay_t<decltype(s)>;
          if constexpr (!std::is_same_v<T, sim::MeshSolid>) shapes.emplace_back(s);
        },
        solid);
  }
  for (const common::Box3& b : voxels.mesh_boxes) {
    sim::BoxSolid box;
    box.centre_W = 0.5 * (b.min + b.max);
    box.half_extents_m = 0.5 * b.Size();
    shapes.emplace_back(box);
  }
  return shapes;
}

}  // namespace hg::tracking
