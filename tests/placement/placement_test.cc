// Camera placement: mounting surfaces, the voxel objective against brute-force
// oracles, incremental == batch evaluation, and the optimiser.
#include <unistd.h>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/LU>

#include "common/config_error.h"
#include "geometry/camera_yaml.h"
#include "placement/coverage.h"
#include "placement/fov_volume.h"
#include "placement/mounting.h"
#include "placement/optimiser.h"
#include "placement/placement_scene.h"
#include "sim/scene.h"

namespace hg::placement {
namespace {

namespace fs = std::filesystem;
using Eigen::Vector3d;

PlacementIntrinsics SmallIntrinsics() {
  PlacementIntrinsics k;
  k.width = 320;
  k.height = 240;
  k.K << 200, 0, 159.5, 0, 200, 119.5, 0, 0, 1;
  return k;
}

sim::Scene SceneFromText(const std::string& text) { return sim::ParseScene(text, "test.yaml", ""); }

std::string Message(const std::function<void()>& fn) {
  try {
    fn();
  } catch (const common::ConfigError& e) {
    return e.what();
  }
  return "(no error)";
}

/// True when the full-resolution camera sees p in its image (pinhole).
bool InImage(const geometry::CameraModel& cam, const Vector3d& p_W) {
  const Vector3d p = cam.ToCamera(p_W);
  if (!(p.z() > 0.01)) return false;
  const Eigen::Vector2d uv = cam.ProjectPinholeC(p);
  return uv.x() >= -0.5 && uv.x() <= cam.width - 0.5 && uv.y() >= -0.5 &&
         uv.y() <= cam.height - 0.5;
}

/// 27 points of a voxel: corners, edge and face midpoints, centre.
std::vector<Vector3d> VoxelPoints(const common::Box3& box) {
  std::vector<Vector3d> out;
  for (int a = 0; a < 3; ++a) {
    for (int b = 0; b < 3; ++b) {
      for (int c = 0; c < 3; ++c) {
        out.push_back(box.min + Vector3d(a, b, c).cwiseProduct(box.Size()) / 2.0);
      }
    }
  }
  return out;
}

/// True when the segment p-q meets the box (slab test).
bool SegmentHitsBox(const Vector3d& p, const Vector3d& q, const common::Box3& box) {
  double t0 = 0.0;
  double t1 = 1.0;
  const Vector3d d = q - p;
  for (int a = 0; a < 3; ++a) {
    if (std::abs(d[a]) < 1e-15) {
      if (p[a] < box.min[a] || p[a] > box.max[a]) return false;
      continue;
    }
    double ta = (box.min[a] - p[a]) / d[a];
    double tb = (box.max[a] - p[a]) / d[a];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
    if (t0 > t1) return false;
  }
  return true;
}

/// Smallest distance between the half-line from c through p and segment a-b:
/// the distance of a point of the segment to the half-line is convex along
/// the segment, so a golden-section search finds its minimum.
double RayToSegment(const Vector3d& c, const Vector3d& p, const Vector3d& a, const Vector3d& b) {
  const Vector3d d = (p - c).normalized();
  auto dist = [&](double s) {
    const Vector3d q = a + (b - a) * s - c;
    const double t = std::max(0.0, q.dot(d));
    return (q - t * d).norm();
  };
  const double g = (std::sqrt(5.0) - 1.0) / 2.0;
  double lo = 0.0;
  double hi = 1.0;
  while (hi - lo > 1e-10) {
    const double m1 = hi - g * (hi - lo);
    const double m2 = lo + g * (hi - lo);
    if (dist(m1) < dist(m2)) {
      hi = m2;
    } else {
      lo = m1;
    }
  }
  return std::min({dist(0.0), dist(1.0), dist(0.5 * (lo + hi))});
}

// ---------------------------------------------------------------------------
// Mounting surfaces and cameras

TEST(MountingTest, SceneSectionGivesWallsCeilingsAndPoles) {
  const sim::Scene scene =
      SceneFromText(R"(scene: {name: m, bounds: {min: [0, 0, 0], max: [4, 3, 3]}}
mounting:
  - {name: north, wall: {from: [0, 3], to: [4, 3], z: [2.5, 3]}}
  - {name: roof, ceiling: {min: [1, 1], max: [3, 2], z: 2.9}}
  - {name: pole, pole: {at: [2, 1.5], z: [1, 2.5]}}
)");
  ASSERT_TRUE(scene.mounting.has_value());
  const std::vector<sim::MountingSurface> s = MountingSurfacesOf(scene);
  ASSERT_EQ(s.size(), 3u);
  EXPECT_EQ(s[0].kind, sim::MountingSurface::Kind::kWall);
  EXPECT_TRUE(s[0].PointAt(1, 1).isApprox(Vector3d(4, 3, 3)));
  EXPECT_TRUE(s[0].PointAt(0, 0).isApprox(Vector3d(0, 3, 2.5)));
  EXPECT_EQ(s[1].kind, sim::MountingSurface::Kind::kCeiling);
  EXPECT_TRUE(s[1].PointAt(0.5, 0.5).isApprox(Vector3d(2, 1.5, 2.9)));
  EXPECT_EQ(s[2].Dimensions(), 1);
  EXPECT_TRUE(s[2].PointAt(1, 0.7).isApprox(Vector3d(2, 1.5, 2.5)));
  double u = 0, v = 0;
  EXPECT_TRUE(ClosestMountPoint(s[0], Vector3d(-1, 5, 9), &u, &v).isApprox(Vector3d(0, 3, 3)));
  EXPECT_EQ(u, 0.0);
  EXPECT_EQ(v, 1.0);
}

TEST(MountingTest, DefaultIsTheTopBandOfTheWallsAndTheCeiling) {
  const sim::Scene scene =
      SceneFromText("scene: {name: d, bounds: {min: [0, 0, 0], max: [4, 3, 3]}}\n");
  EXPECT_FALSE(scene.mounting.has_value());
  const std::vector<sim::MountingSurface> s = MountingSurfacesOf(scene);
  ASSERT_EQ(s.size(), 5u);
  for (int i = 0; i < 4; ++i) {
    EXPECT_EQ(s[i].kind, sim::MountingSurface::Kind::kWall);
    EXPECT_DOUBLE_EQ(s[i].origin_W.z(), 3.0 - kDefaultWallBandM);
    EXPECT_DOUBLE_EQ(s[i].v_W.z(), kDefaultWallBandM);
  }
  EXPECT_EQ(s[4].name, "ceiling");
  EXPECT_TRUE(s[4].PointAt(1, 1).isApprox(Vector3d(4, 3, 3)));
}

TEST(MountingTest, EmptySectionAndBadEntriesAreErrors) {
  const sim::Scene empty =
      SceneFromText("scene: {name: e, bounds: {min: [0, 0, 0], max: [4, 3, 3]}}\nmounting: []\n");
  EXPECT_EQ(Message([&] { (void)MountingSurfacesOf(empty); }),
            "e: mounting: scene has no mounting surface");  // Named by the scene: no file.
  const std::string head =
      "scene: {name: e, bounds: {min: [0, 0, 0], max: [4, 3, 3]}}\nmounting:\n";
  EXPECT_EQ(Message([&] {
              (void)SceneFromText(head + "  - {name: a, pole: {at: [1, 1], z: [2, 1]}}\n");
            }),
            "test.yaml:3: mounting[0].pole.z: expected [low, high] with high > low");
  EXPECT_EQ(
      Message([&] {
        (void)SceneFromText(head + "  - {name: a, wall: {from: [1, 1], to: [1, 1], z: [1, 2]}}\n");
      }),
      "test.yaml:3: mounting[0].wall.to: must differ from 'from'");
  EXPECT_NE(Message([&] {
              (void)SceneFromText(head + "  - {name: a, shelf: {at: [1, 1]}}\n");
            }).find("unknown key 'shelf'"),
            std::string::npos);
  EXPECT_NE(Message([&] {
              (void)SceneFromText(head +
                                  "  - {name: a, pole: {at: [1, 1], z: [1, 2]}}\n"
                                  "  - {name: a, pole: {at: [2, 1], z: [1, 2]}}\n");
            }).find("duplicate mounting surface name 'a'"),
            std::string::npos);
}

TEST(MountingTest, CamerasLookAtTheirTargetWithoutRollAndRoundTrip) {
  const PlacementIntrinsics k = SmallIntrinsics();
  const fs::path file =
      fs::temp_directory_path() / ("hg_place_cams_" + std::to_string(::getpid()) + ".yaml");
  std::vector<geometry::CameraModel> cameras;
  const std::vector<std::pair<Vector3d, Vector3d>> poses = {
      {{0, 0, 3}, {2, 2, 1}}, {{4, 1, 2.5}, {1, 1.5, 0.3}}, {{2, 2, 3}, {2, 2, 0}}};
  for (std::size_t i = 0; i < poses.size(); ++i) {
    const geometry::CameraModel cam =
        MakeCamera(k, std::string(1, static_cast<char>('a' + i)), poses[i].first, poses[i].second);
    EXPECT_TRUE(cam.CentreW().isApprox(poses[i].first, 1e-12));
    const auto uv = cam.Project(poses[i].second);
    ASSERT_TRUE(uv.has_value());
    EXPECT_NEAR(uv->x(), 159.5, 1e-9);
    EXPECT_NEAR(uv->y(), 119.5, 1e-9);
    EXPECT_NEAR(cam.R_CW(0, 2), 0.0, 1e-12) << "image x must stay horizontal";
    EXPECT_NEAR((cam.R_CW * cam.R_CW.transpose() - Eigen::Matrix3d::Identity()).norm(), 0, 1e-12);
    EXPECT_NEAR(cam.R_CW.determinant(), 1.0, 1e-12);
    // Up in the world is up in the image (unless looking straight down).
    if (i < 2) {
      EXPECT_LT(cam.R_CW(1, 2), 0.0);
    }
    cameras.push_back(cam);
  }
  geometry::WriteCamerasFile(file.string(), cameras);
  const std::vector<geometry::CameraModel> loaded = geometry::LoadCamerasFile(file.string());
  fs::remove(file);
  ASSERT_EQ(loaded.size(), cameras.size());
  for (std::size_t i = 0; i < cameras.size(); ++i) {
    EXPECT_TRUE(loaded[i].R_CW.isApprox(cameras[i].R_CW, 1e-12));
    EXPECT_TRUE(loaded[i].t_CW.isApprox(cameras[i].t_CW, 1e-12));
  }
}

TEST(MountingTest, IntrinsicsFromAFileInBothForms) {
  const fs::path dir = fs::temp_directory_path() / ("hg_place_k_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  std::ofstream(dir / "k.yaml")
      << "width: 640\nheight: 480\nK: [500, 0, 319.5, 0, 500, 239.5, 0, 0, 1]\n"
         "distortion: [-0.1, 0.01, 0, 0, 0]\n";
  const PlacementIntrinsics a = LoadIntrinsics((dir / "k.yaml").string());
  EXPECT_EQ(a.width, 640);
  EXPECT_EQ(a.K(0, 0), 500);
  EXPECT_EQ(a.distortion[0], -0.1);
  std::ofstream(dir / "c.yaml")
      << "cameras:\n  - {name: x, width: 64, height: 48, K: [50, 0, 31.5, 0, 50, 23.5, 0, 0, 1],"
         " position: [0, 0, 2], look_at: [1, 1, 0]}\n";
  const PlacementIntrinsics b = LoadIntrinsics((dir / "c.yaml").string());
  EXPECT_EQ(b.width, 64);
  EXPECT_EQ(b.K(1, 2), 23.5);
  std::ofstream(dir / "bad.yaml") << "width: 640\nheight: 480\nK: [500, 0, 319.5]\n";
  EXPECT_EQ(Message([&] { (void)LoadIntrinsics((dir / "bad.yaml").string()); }),
            (dir / "bad.yaml").string() + ":3: K: expected 9 numbers");
  // Intrinsics the camera loader refuses would give a cameras file that
  // hullguardd and hullguard carve cannot load: refused here, at their line.
  std::ofstream(dir / "huge.yaml")
      << "width: 10000\nheight: 8000\nK: [5000, 0, 4999.5, 0, 5000, 3999.5, 0, 0, 1]\n";
  const std::string huge = Message([&] { (void)LoadIntrinsics((dir / "huge.yaml").string()); });
  EXPECT_NE(huge.find((dir / "huge.yaml").string() + ":"), std::string::npos) << huge;
  EXPECT_NE(huge.find("too large"), std::string::npos) << huge;
  std::ofstream(dir / "ratio.yaml")
      << "width: 640\nheight: 480\nK: [5000, 0, 319.5, 0, 400, 239.5, 0, 0, 1]\n";
  const std::string ratio = Message([&] { (void)LoadIntrinsics((dir / "ratio.yaml").string()); });
  EXPECT_NE(ratio.find("focal lengths more than 10 times apart"), std::string::npos) << ratio;
  fs::remove_all(dir);
  const sim::Scene none =
      SceneFromText("scene: {name: n, bounds: {min: [0, 0, 0], max: [4, 3, 3]}}\n");
  EXPECT_NE(Message([&] { (void)IntrinsicsFromScene(none); }).find("give --intrinsics"),
            std::string::npos);
}

TEST(MountingTest, RequestsAreChecked) {
  EXPECT_EQ(Message([] { CheckRequest(0, 1, "place"); }),
            "place: --cameras: must be at least 1 (got 0)");
  EXPECT_EQ(Message([] { CheckRequest(3, 4, "place"); }),
            "place: --min-views: must be between 1 and --cameras (3), got 4");
  EXPECT_EQ(Message([] { CheckRequest(3, 3, "place"); }), "(no error)");
}

// A voxel or a person spacing too small for the cell is refused by name: a
// voxel of 1e-9 m overflowed the count to a single voxel (a run with score 0
// and exit 0), a spacing of 1e-12 m ran for ever.
TEST(PlacementSceneTest, TooFineAModelIsRefused) {
  const sim::Scene scene =
      SceneFromText("scene: {name: box, bounds: {min: [0, 0, 0], max: [4, 4, 3]}}\n");
  for (const double voxel : {1e-9, 1e-300, 0.001}) {
    ModelOptions options;
    options.voxel_m = voxel;
    EXPECT_EQ(Message([&] { (void)BuildPlacementScene(scene, SmallIntrinsics(), options); }),
              "box: voxel: too small for this cell (more than 2e7 voxels)")
        << voxel;
  }
  for (const double spacing : {1e-12, 0.01}) {
    ModelOptions options;
    options.person_spacing_m = spacing;
    EXPECT_NE(Message([&] {
                (void)BuildPlacementScene(scene, SmallIntrinsics(), options);
              }).find("person spacing: too small for this cell"),
              std::string::npos)
        << spacing;
  }
  ModelOptions fine;
  fine.person_spacing_m = 0.05;  // 80 x 80 cells, allowed (those at the walls hold no person).
  const std::size_t samples = BuildPlacementScene(scene, SmallIntrinsics(), fine).samples.size();
  EXPECT_GT(samples, 4000u);
  EXPECT_LE(samples, 6400u);
}

// ---------------------------------------------------------------------------
// The voxel objective against oracles

TEST(CoverageTest, OneCameraInAnEmptyBoxSeesTheFrustumWithinOneVoxelLayer) {
  const sim::Scene scene =
      SceneFromText("scene: {name: box, bounds: {min: [0, 0, 0], max: [2, 2, 2]}}\n");
  ModelOptions options;
  options.render_width_px = 64;
  const PlacementScene ps = BuildPlacementScene(scene, SmallIntrinsics(), options);
  ASSERT_EQ(ps.target_voxels, 20 * 20 * 20);
  const geometry::CameraModel cam =
      MakeCamera(ps.intrinsics, "c", Vector3d(1.0, -0.8, 1.6), Vector3d(1.2, 1.3, 0.7));
  CameraView view;
  ViewScratch scratch;
  ComputeView(ps, cam, &view, &scratch);

  // Oracle: voxels with all corners in the image (inside) and with some.
  const VoxelGrid& g = ps.grid;
  int inside = 0;
  int touching = 0;
  std::vector<std::uint8_t> is_inside(g.Count(), 0);
  for (int k = 0; k < g.nz; ++k) {
    for (int j = 0; j < g.ny; ++j) {
      for (int i = 0; i < g.nx; ++i) {
        const common::Box3 box = g.VoxelBox(i, j, k);
        int in = 0;
        for (int c = 0; c < 8; ++c) in += InImage(cam, box.Corner(c)) ? 1 : 0;
        if (in == 8) {
          ++inside;
          is_inside[g.Index(i, j, k)] = 1;
        }
        if (in > 0) ++touching;
      }
    }
  }
  for (const std::int32_t v : view.voxels) EXPECT_EQ(is_inside[v], 1) << v;
  const int seen = static_cast<int>(view.voxels.size());
  EXPECT_GE(seen, inside - inside / 200) << "only corners within a rounding margin may differ";
  EXPECT_GT(seen, 1000);

  // The frustum-box volume, by a dense lattice and by the exact formula.
  const double dv = g.VoxelVolume();
  long long hits = 0;
  constexpr int kN = 200;
  for (int k = 0; k < kN; ++k) {
    for (int j = 0; j < kN; ++j) {
      for (int i = 0; i < kN; ++i) {
        hits += InImage(cam, Vector3d(i + 0.5, j + 0.5, k + 0.5) * (2.0 / kN)) ? 1 : 0;
      }
    }
  }
  const double lattice = hits * 8.0 / (static_cast<double>(kN) * kN * kN);
  EXPECT_LE(seen * dv, lattice + 0.01);
  EXPECT_LE(lattice, touching * dv + 0.01);
  const FovScene fov_scene(g.bounds, geometry::TriangleMesh{});
  const double exact = FovVolume(fov_scene, cam);
  EXPECT_NEAR(exact, lattice, 0.01);
  EXPECT_LE(seen * dv, exact + 1e-9);
  EXPECT_LE(exact, touching * dv + 1e-9);
}

TEST(CoverageTest, AnObstacleHidesItsShadowAndItself) {
  const sim::Scene scene =
      SceneFromText(R"(scene: {name: s, bounds: {min: [0, 0, 0], max: [3, 3, 2]}}
obstacles:
  - {name: pillar, box: {min: [1.2, 1.2, 0], max: [1.8, 1.8, 1.2]}}
)");
  ModelOptions options;
  options.render_width_px = 80;
  const PlacementScene ps = BuildPlacementScene(scene, SmallIntrinsics(), options);
  const common::Box3 pillar{Vector3d(1.2, 1.2, 0), Vector3d(1.8, 1.8, 1.2)};
  const geometry::CameraModel cam =
      MakeCamera(ps.intrinsics, "c", Vector3d(0.2, 0.2, 1.0), Vector3d(2.5, 2.5, 0.6));
  CameraView view;
  ViewScratch scratch;
  ComputeView(ps, cam, &view, &scratch);
  std::vector<std::uint8_t> seen(ps.grid.Count(), 0);
  for (const std::int32_t v : view.voxels) seen[v] = 1;
  const VoxelGrid& g = ps.grid;
  int hidden_in_frustum = 0;
  for (int k = 0; k < g.nz; ++k) {
    for (int j = 0; j < g.ny; ++j) {
      for (int i = 0; i < g.nx; ++i) {
        const int index = g.Index(i, j, k);
        const common::Box3 box = g.VoxelBox(i, j, k);
        if (seen[index] != 0) {
          EXPECT_EQ(ps.obstacle[index], 0);
          for (const Vector3d& p : VoxelPoints(box)) {
            ASSERT_FALSE(SegmentHitsBox(cam.CentreW(), p, pillar))
                << "voxel " << i << " " << j << " " << k << " is seen through the pillar";
          }
        }
        bool all_in = true;
        for (int c = 0; c < 8; ++c) all_in = all_in && InImage(cam, box.Corner(c));
        const Vector3d centre = 0.5 * (box.min + box.max);
        if (all_in && ps.obstacle[index] == 0 && SegmentHitsBox(cam.CentreW(), centre, pillar)) {
          ++hidden_in_frustum;
          EXPECT_EQ(seen[index], 0);
        }
      }
    }
  }
  EXPECT_GT(hidden_in_frustum, 100) << "the test needs a real shadow";
  // A camera inside the pillar certifies nothing.
  ComputeView(ps, MakeCamera(ps.intrinsics, "in", Vector3d(1.5, 1.5, 0.6), Vector3d(0.5, 0.5, 0.6)),
              &view, &scratch);
  EXPECT_TRUE(view.voxels.empty());
  // The pillar's voxels are not part of the surveillance volume.
  EXPECT_EQ(ps.obstacle[g.Index(15, 15, 5)], 1);
  EXPECT_EQ(ps.obstacle[g.Index(5, 5, 5)], 0);
  EXPECT_EQ(ps.target_voxels, g.Count() - 8 * 8 * 13);  // 0.6 x 0.6 x 1.2 m, one layer around.
}

TEST(CoverageTest, APersonsViewingConeIsNotFree) {
  const sim::Scene scene =
      SceneFromText("scene: {name: p, bounds: {min: [0, 0, 0], max: [2, 2, 2.2]}}\n");
  ModelOptions options;
  options.render_width_px = 96;
  options.person_spacing_m = 2.0;
  const PlacementScene ps = BuildPlacementScene(scene, SmallIntrinsics(), options);
  ASSERT_EQ(ps.samples.size(), 1u);
  const PersonSample& person = ps.samples[0];
  EXPECT_TRUE(person.feet_W.isApprox(Vector3d(1, 1, 0)));
  const geometry::CameraModel cam =
      MakeCamera(ps.intrinsics, "c", Vector3d(0.1, 0.1, 2.1), Vector3d(1.5, 1.5, 0.5));
  ObjectiveOptions objective;
  objective.min_views = 1;
  Evaluator evaluator(ps, objective, 1);
  const CoverageMetrics m = evaluator.Evaluate({cam});
  std::vector<std::uint8_t> free;
  evaluator.CertifiedFree(0, &free);
  const VoxelGrid& g = ps.grid;
  int blocked = 0;
  for (int k = 0; k < g.nz; ++k) {
    for (int j = 0; j < g.ny; ++j) {
      for (int i = 0; i < g.nx; ++i) {
        const int index = g.Index(i, j, k);
        if (free[index] != 0) {
          ASSERT_EQ(evaluator.counts()[index], 1);
          for (const Vector3d& p : VoxelPoints(g.VoxelBox(i, j, k))) {
            ASSERT_GT(RayToSegment(cam.CentreW(), p, person.a_W, person.b_W), person.radius_m)
                << "voxel " << i << " " << j << " " << k << " is free inside the person's cone";
          }
        } else if (evaluator.counts()[index] != 0) {
          ++blocked;
        }
      }
    }
  }
  EXPECT_GT(blocked, 200);
  auto voxel_at = [&](const Vector3d& p) {
    const Vector3d f = (p - g.bounds.min).cwiseQuotient(g.cell_m);
    return g.Index(static_cast<int>(f.x()), static_cast<int>(f.y()), static_cast<int>(f.z()));
  };
  // The person's own space, and its shadow behind it, are seen when the cell
  // is empty but not free with the person in it.
  const Vector3d chest(1.0, 1.0, 1.2);
  const Vector3d behind = cam.CentreW() + 1.35 * (chest - cam.CentreW());
  ASSERT_TRUE(g.bounds.Contains(behind));
  for (const Vector3d& p : {chest, behind}) {
    EXPECT_EQ(evaluator.counts()[voxel_at(p)], 1);
    EXPECT_EQ(free[voxel_at(p)], 0);
  }
  EXPECT_LT(m.free_fraction[0], m.seen_fraction);
  EXPECT_DOUBLE_EQ(m.mean_free_fraction, m.free_fraction[0]);
  EXPECT_DOUBLE_EQ(m.score, m.mean_free_fraction + objective.coverage_weight * m.k_coverage);
}

PlacementScene PaperCell(double voxel_m, int render_width) {
  const sim::Scene scene =
      sim::LoadScene(std::string(HG_SOURCE_DIR) + "/config/scenes/paper_cell.yaml");
  ModelOptions options;
  options.voxel_m = voxel_m;
  options.render_width_px = render_width;
  return BuildPlacementScene(scene, IntrinsicsFromScene(scene), options);
}

std::vector<CameraPlacement> RandomLayout(const PlacementScene& ps, int n, std::mt19937_64* rng) {
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::vector<CameraPlacement> out;
  for (int c = 0; c < n; ++c) {
    double genes[kGenesPerCamera];
    for (double& x : genes) x = unit(*rng);
    out.push_back(DecodePlacement(ps, genes));
  }
  return out;
}

void ExpectSameMetrics(const CoverageMetrics& a, const CoverageMetrics& b) {
  EXPECT_EQ(a.score, b.score);
  EXPECT_EQ(a.seen_fraction, b.seen_fraction);
  EXPECT_EQ(a.k_coverage, b.k_coverage);
  EXPECT_EQ(a.free_fraction, b.free_fraction);
}

TEST(CoverageTest, OneCameraAtATimeEqualsTheWholeLayoutForAnyThreadCount) {
  const PlacementScene ps = PaperCell(0.2, 96);
  EXPECT_GE(ps.samples.size(), 10u);
  ObjectiveOptions objective;
  objective.min_views = 2;
  Evaluator one(ps, objective, 1);
  Evaluator three(ps, objective, 3);
  std::mt19937_64 rng(42);
  for (int round = 0; round < 3; ++round) {
    std::vector<CameraPlacement> layout = RandomLayout(ps, 4, &rng);
    const std::vector<geometry::CameraModel> cams = CamerasOf(ps, layout);
    const CoverageMetrics batch = one.Evaluate(cams);
    ExpectSameMetrics(batch, three.Evaluate(cams));
    EXPECT_GT(batch.seen_fraction, 0.0);
    for (int c = 0; c < 4; ++c) {
      three.Freeze(cams, c);
      // The frozen layout itself, then with camera c moved.
      ExpectSameMetrics(three.EvaluateVarying(cams[c]), batch);
      std::vector<geometry::CameraModel> moved = cams;
      moved[c] = CamerasOf(ps, RandomLayout(ps, 1, &rng)).front();
      const CoverageMetrics incremental = three.EvaluateVarying(moved[c]);
      ExpectSameMetrics(incremental, one.Evaluate(moved));
    }
  }
}

// ---------------------------------------------------------------------------
// Corner heuristic and optimiser

TEST(OptimiserTest, CornerHeuristicUsesTheTopCornersThenTheEdges) {
  const PlacementScene ps = PaperCell(0.25, 64);
  const std::vector<CameraPlacement> four = CornerHeuristic(ps, 4);
  ASSERT_EQ(four.size(), 4u);
  EXPECT_TRUE(four[0].position_W.isApprox(Vector3d(0, 0, 3)));
  EXPECT_TRUE(four[1].position_W.isApprox(Vector3d(4, 4, 3)));
  EXPECT_TRUE(four[2].position_W.isApprox(Vector3d(4, 0, 3)));
  EXPECT_TRUE(four[3].position_W.isApprox(Vector3d(0, 4, 3)));
  for (const CameraPlacement& p : four) EXPECT_TRUE(p.look_at_W.isApprox(Vector3d(2, 2, 1.5)));
  const std::vector<CameraPlacement> six = CornerHeuristic(ps, 6);
  ASSERT_EQ(six.size(), 6u);
  EXPECT_TRUE(six[4].position_W.isApprox(Vector3d(2, 0, 3)));
  EXPECT_TRUE(six[5].position_W.isApprox(Vector3d(2, 4, 3)));
  // Encoding and decoding keep the placement.
  for (const CameraPlacement& p : six) {
    double genes[kGenesPerCamera];
    EncodePlacement(ps, p, genes);
    const CameraPlacement q = DecodePlacement(ps, genes);
    EXPECT_EQ(q.surface, p.surface);
    EXPECT_TRUE(q.position_W.isApprox(p.position_W, 1e-12));
    EXPECT_TRUE(q.look_at_W.isApprox(p.look_at_W, 1e-12));
  }
}

PlacementResult SmallRun(const PlacementScene& ps, std::uint64_t seed, int threads) {
  ObjectiveOptions objective;
  objective.min_views = 2;
  OptimiserOptions options;
  options.cameras = 3;
  options.seed = seed;
  options.global_evaluations = 300;
  options.local_evaluations = 60;
  options.threads = threads;
  return OptimisePlacement(ps, objective, options);
}

TEST(OptimiserTest, ImprovesOnTheCornerHeuristicAndStaysOnTheSurfaces) {
  const PlacementScene ps = PaperCell(0.2, 96);
  ObjectiveOptions objective;
  objective.min_views = 2;
  Evaluator evaluator(ps, objective, 2);
  const CoverageMetrics start = evaluator.Evaluate(CamerasOf(ps, CornerHeuristic(ps, 3)));
  int progress_calls = 0;
  OptimiserOptions options;
  options.cameras = 3;
  options.seed = 3;
  options.global_evaluations = 300;
  options.local_evaluations = 60;
  const PlacementResult r =
      OptimisePlacement(ps, objective, options, [&](const Progress&) { ++progress_calls; });
  EXPECT_GT(r.metrics.score, start.score + 1e-3);
  EXPECT_GT(progress_calls, 3);
  EXPECT_LE(r.global_evaluations, 300);
  EXPECT_GT(r.global_evaluations, 250);
  EXPECT_LE(r.local_evaluations, 60);
  ASSERT_EQ(r.placements.size(), 3u);
  for (const CameraPlacement& p : r.placements) {
    ASSERT_GE(p.surface, 0);
    ASSERT_LT(p.surface, static_cast<int>(ps.surfaces.size()));
    EXPECT_TRUE(p.position_W.isApprox(ps.surfaces[p.surface].PointAt(p.s, p.t), 1e-12));
    EXPECT_TRUE(ps.grid.bounds.Contains(p.look_at_W));
  }
  ExpectSameMetrics(r.metrics, evaluator.Evaluate(r.cameras));
}

TEST(OptimiserTest, SameSeedSameResultWhateverTheThreads) {
  const PlacementScene ps = PaperCell(0.25, 64);
  const PlacementResult a = SmallRun(ps, 11, 1);
  const PlacementResult b = SmallRun(ps, 11, 2);
  ASSERT_EQ(a.placements.size(), b.placements.size());
  for (std::size_t c = 0; c < a.placements.size(); ++c) {
    EXPECT_EQ(a.placements[c].surface, b.placements[c].surface);
    EXPECT_EQ(a.placements[c].position_W, b.placements[c].position_W);
    EXPECT_EQ(a.placements[c].look_at_W, b.placements[c].look_at_W);
  }
  ExpectSameMetrics(a.metrics, b.metrics);
  EXPECT_EQ(a.global_evaluations, b.global_evaluations);
  EXPECT_EQ(a.local_evaluations, b.local_evaluations);
  const PlacementResult c = SmallRun(ps, 12, 2);
  bool differs = false;
  for (std::size_t i = 0; i < c.placements.size(); ++i) {
    differs = differs || c.placements[i].position_W != a.placements[i].position_W;
  }
  EXPECT_TRUE(differs) << "another seed should search elsewhere";
}

}  // namespace
}  // namespace hg::placement
