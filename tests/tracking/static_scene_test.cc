#include "tracking/static_scene.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <set>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include "scene/demo_cell.h"

namespace hg::tracking {
namespace {

using Eigen::Vector3d;

// 8 voxels of 0.125 m per metre: voxel boundaries are exact binary fractions.
VoxelGrid UnitGrid() { return VoxelGrid({Vector3d::Zero(), Vector3d::Ones()}, 0.125); }

std::set<std::uint32_t> Marked(const std::vector<std::uint8_t>& mask) {
  std::set<std::uint32_t> s;
  for (std::uint32_t i = 0; i < mask.size(); ++i) {
    if (mask[i] != 0) s.insert(i);
  }
  return s;
}

std::set<std::uint32_t> Block(const VoxelGrid& g, Eigen::Vector3i lo, Eigen::Vector3i hi) {
  std::set<std::uint32_t> s;
  for (int z = lo.z(); z <= hi.z(); ++z) {
    for (int y = lo.y(); y <= hi.y(); ++y) {
      for (int x = lo.x(); x <= hi.x(); ++x) s.insert(g.Index(x, y, z));
    }
  }
  return s;
}

TEST(VoxelizeMeshTest, ClosedBoxFillsSurfaceAndInterior) {
  const VoxelGrid g = UnitGrid();
  std::vector<std::uint8_t> mask(g.size(), 0);
  VoxelizeMesh(g, geometry::TriangleMesh::Box({0.2, 0.3, 0.1}, {0.6, 0.7, 0.45}), &mask);
  // Faces inside voxels: exactly the voxels the box overlaps.
  EXPECT_EQ(Marked(mask), Block(g, {1, 2, 0}, {4, 5, 3}));
}

TEST(VoxelizeMeshTest, FacesOnVoxelBoundariesTakeBothNeighbours) {
  const VoxelGrid g = UnitGrid();
  std::vector<std::uint8_t> mask(g.size(), 0);
  VoxelizeMesh(g, geometry::TriangleMesh::Box({0.25, 0.25, 0.25}, {0.5, 0.5, 0.5}), &mask);
  // The box covers voxels 2..3; the voxels whose faces it touches (1 and 4) are
  // taken too: conservative.
  EXPECT_EQ(Marked(mask), Block(g, {1, 1, 1}, {4, 4, 4}));
}

TEST(VoxelizeMeshTest, OpenSurfaceMarksOnlyItself) {
  const VoxelGrid g = UnitGrid();
  std::vector<std::uint8_t> mask(g.size(), 0);
  geometry::TriangleMesh sheet;
  sheet.vertices = {{0.05, 0.05, 0.3}, {0.95, 0.05, 0.3}, {0.05, 0.95, 0.3}};
  sheet.triangles = {{0, 1, 2}};
  VoxelizeMesh(g, sheet, &mask);
  const std::set<std::uint32_t> marked = Marked(mask);
  EXPECT_GT(marked.size(), 20u);
  for (const std::uint32_t i : marked) EXPECT_EQ(g.Coords(i).z(), 2);  // 0.3 lies in [0.25, 0.375).
}

TEST(VoxelizeMeshTest, MeshCutByTheGridStaysSolid) {
  const VoxelGrid g = UnitGrid();
  std::vector<std::uint8_t> mask(g.size(), 0);
  // A thick wall reaching far beyond the grid in x and z.
  VoxelizeMesh(g, geometry::TriangleMesh::Box({-1.0, 0.3, -1.0}, {2.0, 0.8, 2.0}), &mask);
  EXPECT_EQ(Marked(mask), Block(g, {0, 2, 0}, {7, 6, 7}));
}

// Points sampled inside a solid must fall in marked voxels; marked voxels must
// lie near the solid.
void ExpectCovers(const VoxelGrid& g, const sim::SolidGeometry& solid,
                  const std::vector<std::uint8_t>& mask, std::mt19937_64* rng) {
  const common::Box3 b = sim::Bounds(solid);
  std::uniform_real_distribution<double> ux(b.min.x(), b.max.x()), uy(b.min.y(), b.max.y()),
      uz(b.min.z(), b.max.z());
  int inside = 0;
  for (int k = 0; k < 60000; ++k) {
    const Vector3d p(ux(*rng), uy(*rng), uz(*rng));
    if (!sim::Contains(solid, p) || !g.covered().Contains(p)) continue;
    ++inside;
    const Eigen::Vector3i v =
        g.VoxelOf(p).cwiseMin(Eigen::Vector3i(g.nx(), g.ny(), g.nz()) - Eigen::Vector3i::Ones());
    ASSERT_NE(mask[g.Index(v.x(), v.y(), v.z())], 0) << p.transpose();
  }
  EXPECT_GT(inside, 1000);  // The thin capsule gets about 2300.
  // Every marked voxel's box reaches within a voxel diagonal of a solid point:
  // its centre is within a diagonal of the solid's bounds at least.
  const double diag = std::sqrt(3.0) * g.voxel_m();
  for (const std::uint32_t i : Marked(mask)) {
    const Eigen::Vector3i c = g.Coords(i);
    const Vector3d p = g.Centre(c.x(), c.y(), c.z());
    EXPECT_TRUE((p.array() >= b.min.array() - diag).all() &&
                (p.array() <= b.max.array() + diag).all());
  }
}

TEST(VoxelizeSolidTest, AnalyticSolidsAreCovered) {
  const VoxelGrid g({Vector3d::Zero(), Vector3d(2, 2, 2)}, 0.05);
  std::mt19937_64 rng(6);
  sim::BoxSolid box;
  box.centre_W = {0.7, 1.1, 0.6};
  box.half_extents_m = {0.4, 0.1, 0.3};
  box.R_WB = (Eigen::AngleAxisd(0.5, Vector3d::UnitZ()) * Eigen::AngleAxisd(0.3, Vector3d::UnitX()))
                 .toRotationMatrix();
  const std::vector<sim::SolidGeometry> solids = {
      box, sim::CapsuleSolid{{0.3, 0.3, 0.3}, {1.5, 1.2, 1.4}, 0.12},
      sim::CylinderSolid{{1.5, 0.4, 0.0}, {1.3, 0.6, 1.1}, 0.2}};
  for (const sim::SolidGeometry& solid : solids) {
    std::vector<std::uint8_t> mask(g.size(), 0);
    VoxelizeSolid(g, solid, &mask);
    ExpectCovers(g, solid, mask, &rng);
  }
  // A box solid marks the same voxels as its own (closed) mesh.
  sim::BoxSolid aligned;
  aligned.centre_W = {1.013, 0.987, 0.52};
  aligned.half_extents_m = {0.31, 0.22, 0.18};
  std::vector<std::uint8_t> a(g.size(), 0), b(g.size(), 0);
  VoxelizeSolid(g, aligned, &a);
  VoxelizeMesh(g,
               geometry::TriangleMesh::Box(aligned.centre_W - aligned.half_extents_m,
                                           aligned.centre_W + aligned.half_extents_m),
               &b);
  EXPECT_EQ(Marked(a), Marked(b));
}

TEST(MergeIntoBoxesTest, BoxesCoverExactlyTheMarkedVoxels) {
  const VoxelGrid g({Vector3d::Zero(), Vector3d(1.0, 0.75, 0.5)}, 0.0625);
  std::mt19937_64 rng(3);
  std::vector<std::uint8_t> mask(g.size(), 0);
  for (auto& m : mask) m = (rng() % 3 == 0) ? 1 : 0;
  // A solid block merges into few boxes.
  for (const std::uint32_t i : Block(g, {2, 2, 2}, {9, 7, 5})) mask[i] = 1;
  const std::vector<common::Box3> boxes = MergeIntoBoxes(g, mask);
  std::vector<int> cover(g.size(), 0);
  for (const common::Box3& b : boxes) {
    for (int z = 0; z < g.nz(); ++z) {
      for (int y = 0; y < g.ny(); ++y) {
        for (int x = 0; x < g.nx(); ++x) {
          if (b.Contains(g.Centre(x, y, z))) ++cover[g.Index(x, y, z)];
        }
      }
    }
  }
  for (std::uint32_t i = 0; i < g.size(); ++i) ASSERT_EQ(cover[i], mask[i] != 0 ? 1 : 0) << i;
  EXPECT_LT(boxes.size(), Marked(mask).size());
}

// A table (top and four legs in one mesh) seen by a camera from above.
struct TableCell {
  VoxelGrid grid{{Vector3d::Zero(), Vector3d(4, 4, 2)}, 0.0625};
  StaticScene scene;
  TableCell() {
    geometry::TriangleMesh table = geometry::TriangleMesh::Box({1.5, 1.5, 0.9}, {2.5, 2.5, 0.95});
    for (const double x : {1.5, 2.44}) {
      for (const double y : {1.5, 2.44}) {
        table.Append(geometry::TriangleMesh::Box({x, y, 0.0}, {x + 0.06, y + 0.06, 0.9}));
      }
    }
    scene.meshes.push_back(table);
    scene.cameras.push_back(scene::LookAtCamera({2, 2.01, 3.5}, {2, 2, 0}, 640, 480, 300));
  }
  VoxelState At(const StaticVoxels& v, const Vector3d& p) const {
    const Eigen::Vector3i c = grid.VoxelOf(p);
    return v.states[grid.Index(c.x(), c.y(), c.z())];
  }
};

TEST(StaticVoxelsTest, KnownOccludedAndFree) {
  TableCell cell;
  const StaticVoxels v = BuildStaticVoxels(cell.grid, cell.scene);
  EXPECT_EQ(cell.At(v, {2.0, 2.0, 0.92}), VoxelState::kKnown);    // Table top.
  EXPECT_EQ(cell.At(v, {1.53, 1.53, 0.4}), VoxelState::kKnown);   // A leg.
  EXPECT_EQ(cell.At(v, {2.0, 2.0, 0.4}), VoxelState::kOccluded);  // Under the top.
  EXPECT_EQ(cell.At(v, {2.0, 2.0, 1.5}), VoxelState::kFree);      // Above it.
  EXPECT_EQ(cell.At(v, {0.5, 0.5, 0.4}), VoxelState::kFree);      // Beside it.
  // Out of the camera's view (59 degrees off its axis, the image reaches 47):
  // not hidden by an obstacle, so not OCCLUDED either.
  EXPECT_EQ(cell.At(v, {0.1, 0.1, 1.9}), VoxelState::kFree);
  std::vector<VoxelState> marked(cell.grid.size(), VoxelState::kFree);
  MarkOccluded(cell.grid, cell.scene.cameras, cell.scene.meshes, &marked);
  const Eigen::Vector3i out_of_view = cell.grid.VoxelOf({0.1, 0.1, 1.9});
  const Eigen::Vector3i under = cell.grid.VoxelOf({2.0, 2.0, 0.4});
  EXPECT_EQ(marked[cell.grid.Index(out_of_view.x(), out_of_view.y(), out_of_view.z())],
            VoxelState::kFree);
  EXPECT_EQ(marked[cell.grid.Index(under.x(), under.y(), under.z())], VoxelState::kOccluded);
  // Out of view is recorded.
  auto index = [&](const Vector3d& p) {
    const Eigen::Vector3i c = cell.grid.VoxelOf(p);
    return cell.grid.Index(c.x(), c.y(), c.z());
  };
  ASSERT_EQ(v.out_of_view.size(), cell.grid.size());
  EXPECT_EQ(v.out_of_view[index({0.1, 0.1, 1.9})], 1);
  EXPECT_EQ(v.out_of_view[index({2.0, 2.0, 1.5})], 0);
  EXPECT_EQ(v.out_of_view[index({2.0, 2.0, 0.4})], 0);  // In view, behind the top.
  // Every voxel whose centre is in view is out of view for OutOfView only
  // near the image's border: within the image of a ball of one voxel diagonal
  // around it (f r (1 + |x / z|) / (z - r) pixels along u, likewise along v).
  const geometry::CameraModel cam = cell.scene.cameras[0].Pinhole();
  const double r = std::sqrt(3.0) * cell.grid.voxel_m();
  int near_border = 0, inside = 0;
  for (std::uint32_t i = 0; i < cell.grid.size(); ++i) {
    const Eigen::Vector3i c = cell.grid.Coords(i);
    const Vector3d p_C = cam.ToCamera(cell.grid.Centre(c.x(), c.y(), c.z()));
    if (p_C.z() <= 0.0) continue;
    const Eigen::Vector2d uv = cam.ProjectPinholeC(p_C);
    const double border_u = std::min(uv.x() + 0.5, cam.width - 0.5 - uv.x());
    const double border_v = std::min(uv.y() + 0.5, cam.height - 0.5 - uv.y());
    const double a = 1.01 * r / (p_C.z() - r);
    if (border_u < 0.0 || border_v < 0.0) {
      EXPECT_EQ(v.out_of_view[i], 1) << i;  // The only camera: out of its view.
    } else if (p_C.z() > 2.0 * r &&
               border_u > cam.K(0, 0) * a * (1.0 + std::abs(p_C.x() / p_C.z())) &&
               border_v > cam.K(1, 1) * a * (1.0 + std::abs(p_C.y() / p_C.z()))) {
      EXPECT_EQ(v.out_of_view[i], 0) << i;
      ++inside;
    } else {
      near_border += v.out_of_view[i];
    }
  }
  EXPECT_GT(inside, 1000);
  EXPECT_GT(near_border, 100);  // The margin is applied.
  // A low camera looking under the table sees that space.
  cell.scene.cameras.push_back(scene::LookAtCamera({2, -0.5, 0.45}, {2, 2, 0.45}, 640, 480, 300));
  const StaticVoxels w = BuildStaticVoxels(cell.grid, cell.scene);
  EXPECT_EQ(cell.At(w, {2.0, 2.0, 0.4}), VoxelState::kFree);
  // Without cameras, everything that is not an obstacle is occluded.
  cell.scene.cameras.clear();
  const StaticVoxels none = BuildStaticVoxels(cell.grid, cell.scene);
  EXPECT_EQ(cell.At(none, {0.5, 0.5, 0.4}), VoxelState::kOccluded);
  EXPECT_EQ(cell.At(none, {2.0, 2.0, 0.92}), VoxelState::kKnown);
}

// A camera inside an obstacle mesh (its housing modelled into the meshes) is
// blocked and sees nothing, as the pipeline reports it: what only it has in
// view is occluded, what no camera has in view stays free.
TEST(StaticVoxelsTest, ABlockedCameraSeesNothing) {
  TableCell cell;
  const Vector3d centre(2, 2.01, 3.5);  // TableCell's camera.
  const Vector3d half(0.0005, 0.0005, 0.0005);
  cell.scene.meshes.push_back(geometry::TriangleMesh::Box(centre - half, centre + half));
  const StaticVoxels v = BuildStaticVoxels(cell.grid, cell.scene);
  EXPECT_EQ(cell.At(v, {0.5, 0.5, 0.4}), VoxelState::kOccluded);
  EXPECT_EQ(cell.At(v, {2.0, 2.0, 1.5}), VoxelState::kOccluded);
  EXPECT_EQ(cell.At(v, {0.1, 0.1, 1.9}), VoxelState::kFree);  // Out of its view.
  EXPECT_EQ(cell.At(v, {2.0, 2.0, 0.92}), VoxelState::kKnown);
}

TEST(StaticVoxelsTest, MeshCollisionBoxesLeaveSpaceUnderATable) {
  TableCell cell;
  const StaticVoxels v = BuildStaticVoxels(cell.grid, cell.scene);
  EXPECT_LE(v.mesh_boxes.size(), 12u);  // Top and legs, a few boxes each at most.
  const CollisionWorld world(CollisionShapes(cell.scene, v));
  // Crawling under the top between the legs, 0.2 m capsule.
  EXPECT_FALSE(world.CapsuleHits({1.0, 2.0, 0.35}, {3.0, 2.0, 0.35}, 0.2));
  // Walking into the top, or into a leg.
  EXPECT_TRUE(world.CapsuleHits({1.0, 2.0, 0.9}, {2.0, 2.0, 0.9}, 0.2));
  EXPECT_TRUE(world.CapsuleHits({1.2, 1.53, 0.5}, {1.4, 1.53, 0.5}, 0.2));
}

TEST(StaticVoxelsTest, AnalyticSolidsKeepTheirShapeForCollisions) {
  const VoxelGrid grid({Vector3d::Zero(), Vector3d(2, 2, 2)}, 0.0625);
  StaticScene scene;
  sim::BoxSolid box;
  box.centre_W = {1, 1, 0.5};
  box.half_extents_m = {0.3, 0.3, 0.5};
  scene.solids = {box, sim::CylinderSolid{{0.3, 0.3, 0}, {0.3, 0.3, 1}, 0.1},
                  sim::MeshSolid{geometry::TriangleMesh::Box({1.6, 0.2, 0}, {1.8, 0.4, 0.5})}};
  const StaticVoxels v = BuildStaticVoxels(grid, scene);
  const std::vector<CollisionShape> shapes = CollisionShapes(scene, v);
  ASSERT_GE(shapes.size(), 3u);
  EXPECT_TRUE(std::holds_alternative<sim::BoxSolid>(shapes[0]));
  EXPECT_TRUE(std::holds_alternative<sim::CylinderSolid>(shapes[1]));
  const Eigen::Vector3i c = grid.VoxelOf({1, 1, 0.5});
  EXPECT_EQ(v.states[grid.Index(c.x(), c.y(), c.z())], VoxelState::kKnown);
  const Eigen::Vector3i m = grid.VoxelOf({1.7, 0.3, 0.25});
  EXPECT_EQ(v.states[grid.Index(m.x(), m.y(), m.z())], VoxelState::kKnown);
  const CollisionWorld world(shapes);
  EXPECT_TRUE(world.CapsuleHits({1.7, 0.0, 0.25}, {1.7, 0.1, 0.25}, 0.2));  // The mesh box.
  EXPECT_FALSE(world.CapsuleHits({0.3, 0.3, 1.5}, {1.0, 0.3, 1.5}, 0.2));   // Above all.
}

}  // namespace
}  // namespace hg::tracking
