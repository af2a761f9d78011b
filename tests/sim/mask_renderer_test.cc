#include "sim/mask_renderer.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include "scene/demo_cell.h"
#include "scene/exact_mask.h"
#include "scene/shapes.h"
#include "support/random_scene.h"
#include "support/sim_bodies.h"

namespace hg::sim {
namespace {

using testing::StandingBody;
using testing::WalkingBody;

using Eigen::Vector3d;

/// A body of 13 random capsules around `centre` (one of them a sphere).
BodyState RandomBody(std::mt19937_64& rng, const Vector3d& centre, double spread) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::uniform_real_distribution<double> len(0.0, 0.5);
  std::uniform_real_distribution<double> rad(0.03, 0.15);
  BodyState body;
  for (int i = 0; i < kNumBodyParts; ++i) {
    BodyCapsule& c = body.parts[i];
    c.part = static_cast<BodyPart>(i);
    c.a_W = centre + spread * Vector3d(u(rng), u(rng), u(rng));
    c.b_W = i == 0 ? c.a_W : c.a_W + len(rng) * Vector3d(u(rng), u(rng), u(rng)).normalized();
    c.radius_m = rad(rng);
  }
  return body;
}

std::vector<scene::Shape> ToShapes(const std::vector<BodyState>& people) {
  std::vector<scene::Shape> shapes;
  for (const BodyState& body : people) {
    for (const BodyCapsule& c : body.parts) {
      shapes.push_back(scene::Capsule{c.a_W, c.b_W, c.radius_m});
    }
  }
  return shapes;
}

geometry::CameraModel WithRandomDistortion(std::mt19937_64& rng, geometry::CameraModel camera) {
  std::uniform_real_distribution<double> k1(-0.25, 0.1);
  std::uniform_real_distribution<double> k2(-0.04, 0.04);
  std::uniform_real_distribution<double> p(-0.003, 0.003);
  camera.distortion = {k1(rng), k2(rng), p(rng), p(rng), 0.0};
  return camera;
}

long long Count(const common::ImageU8& mask) {
  return std::count_if(mask.pixels.begin(), mask.pixels.end(), [](std::uint8_t p) { return p; });
}

common::ImageU8 Dilate(const common::ImageU8& mask, int radius) {
  common::ImageU8 out(mask.width, mask.height, 0);
  for (int v = 0; v < mask.height; ++v) {
    for (int u = 0; u < mask.width; ++u) {
      if (!mask.At(u, v)) continue;
      for (int dv = -radius; dv <= radius; ++dv) {
        for (int du = -radius; du <= radius; ++du) {
          const int x = u + du;
          const int y = v + dv;
          if (x >= 0 && y >= 0 && x < mask.width && y < mask.height) out.At(x, y) = 255;
        }
      }
    }
  }
  return out;
}

/// Pixel of a projected point (pixel (u, v) covers [u - 0.5, u + 0.5)); false outside.
bool PixelOf(const geometry::CameraModel& camera, const Vector3d& p_W, int* u, int* v) {
  const auto uv = camera.Project(p_W);
  if (!uv) return false;
  const double fu = std::floor(uv->x() + 0.5);
  const double fv = std::floor(uv->y() + 0.5);
  if (fu < 0 || fv < 0 || fu >= camera.width || fv >= camera.height) return false;
  *u = static_cast<int>(fu);
  *v = static_cast<int>(fv);
  return true;
}

/// Checks the fast mask against the exact one: a superset, and its extra
/// pixels are at most `max_ring_share` of the one-pixel ring around the exact
/// mask (the cone relaxation adds well under a pixel at the silhouette; a
/// renderer that grew masks by a whole pixel or more would fail).
void ExpectContainsExact(const common::ImageU8& fast, const common::ImageU8& exact,
                         double max_ring_share) {
  ASSERT_EQ(fast.width, exact.width);
  ASSERT_EQ(fast.height, exact.height);
  long long missing = 0;
  for (std::size_t i = 0; i < fast.pixels.size(); ++i) {
    if (exact.pixels[i] && !fast.pixels[i]) ++missing;
  }
  EXPECT_EQ(missing, 0);
  const long long exact_count = Count(exact);
  const long long ring = Count(Dilate(exact, 1)) - exact_count;
  EXPECT_LE(Count(fast) - exact_count, max_ring_share * ring + 10)
      << "exact " << exact_count << " ring " << ring;
}

TEST(MaskRendererTest, ContainsTheExactMaskPinhole) {
  long long total_exact = 0;
  for (std::uint64_t seed = 1; seed <= 8u * static_cast<unsigned>(testing::SoakFactor()); ++seed) {
    testing::RandomSceneOptions options;
    options.num_cameras = 3;
    options.width = 320;
    options.height = 240;
    options.num_objects = 0;
    const testing::RandomScene s = testing::MakeRandomScene(seed, options);
    std::mt19937_64 rng(seed * 7919);
    const std::vector<BodyState> people = {RandomBody(rng, Vector3d(0.7, 1.0, 1.0), 0.4),
                                           RandomBody(rng, Vector3d(1.3, 1.0, 0.8), 0.4)};
    const std::vector<scene::Shape> shapes = ToShapes(people);
    for (const geometry::CameraModel& camera : s.cameras) {
      const MaskRenderer renderer(camera, {}, {}, true);
      common::ImageU8 fast;
      renderer.Render(people, &fast);
      const common::ImageU8 exact = scene::RenderExactMask(camera, shapes);
      total_exact += Count(exact);
      SCOPED_TRACE(::testing::Message() << "seed " << seed << " camera " << camera.name);
      ExpectContainsExact(fast, exact, 0.35);
    }
  }
  EXPECT_GT(total_exact, 10000);
}

TEST(MaskRendererTest, ContainsTheExactMaskDistorted) {
  long long total_exact = 0;
  for (std::uint64_t seed = 11; seed <= 16; ++seed) {
    testing::RandomSceneOptions options;
    options.num_cameras = 2;
    options.width = 200;
    options.height = 150;
    options.num_objects = 0;
    const testing::RandomScene s = testing::MakeRandomScene(seed, options);
    std::mt19937_64 rng(seed * 104729);
    const std::vector<BodyState> people = {RandomBody(rng, Vector3d(0.8, 0.9, 1.0), 0.4),
                                           RandomBody(rng, Vector3d(1.2, 1.2, 1.0), 0.4)};
    const std::vector<scene::Shape> shapes = ToShapes(people);
    for (const geometry::CameraModel& pinhole : s.cameras) {
      const geometry::CameraModel camera = WithRandomDistortion(rng, pinhole);
      const MaskRenderer renderer(camera, {}, {}, false);
      common::ImageU8 fast;
      renderer.Render(people, &fast);
      const common::ImageU8 exact = scene::RenderExactDistortedMask(camera, shapes);
      total_exact += Count(exact);
      SCOPED_TRACE(::testing::Message() << "seed " << seed << " camera " << camera.name);
      ExpectContainsExact(fast, exact, 0.75);
    }
  }
  EXPECT_GT(total_exact, 5000);
}

/// Every sample point of every capsule projects onto a foreground pixel.
void ExpectSamplesCovered(const MaskRenderer& renderer, const std::vector<BodyState>& people,
                          std::mt19937_64& rng, int samples_per_capsule, int* landed) {
  common::ImageU8 mask;
  renderer.Render(people, &mask);
  const geometry::CameraModel& camera = renderer.camera();
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  auto uniform = [&] { return u01(rng); };
  for (const scene::Shape& shape : ToShapes(people)) {
    for (int i = 0; i < samples_per_capsule; ++i) {
      const Vector3d p = scene::SampleInside(shape, uniform);
      int u;
      int v;
      if (!PixelOf(camera, p, &u, &v)) continue;
      ++*landed;
      ASSERT_EQ(mask.At(u, v), 255) << "point " << p.transpose() << " pixel " << u << "," << v;
    }
  }
}

TEST(MaskRendererTest, SamplePointsLandOnForeground) {
  int landed = 0;
  for (std::uint64_t seed = 21; seed <= 26; ++seed) {
    testing::RandomSceneOptions options;
    options.num_cameras = 2;
    options.width = 320;
    options.height = 240;
    options.num_objects = 0;
    const testing::RandomScene s = testing::MakeRandomScene(seed, options);
    std::mt19937_64 rng(seed);
    const std::vector<BodyState> people = {RandomBody(rng, Vector3d(1.0, 1.0, 1.0), 0.6)};
    for (const geometry::CameraModel& pinhole : s.cameras) {
      for (const bool distorted : {false, true}) {
        const geometry::CameraModel camera =
            distorted ? WithRandomDistortion(rng, pinhole) : pinhole;
        const MaskRenderer renderer(camera, {}, {}, true);
        ExpectSamplesCovered(renderer, people, rng, 150, &landed);
      }
    }
  }
  EXPECT_GT(landed, 10000);
}

TEST(MaskRendererTest, SamplePointsLandOnForegroundFullHd) {
  scene::DemoCellOptions options;
  options.num_cameras = 1;
  const scene::DemoCell cell = scene::MakeDemoCell(options);
  std::mt19937_64 rng(31);
  const std::vector<BodyState> people = {WalkingBody(Vector3d(1.5, 2.0, 0.0), 0.3, 0.0),
                                         WalkingBody(Vector3d(2.6, 2.4, 0.0), 2.0, 1.5),
                                         WalkingBody(Vector3d(1.0, 1.0, 0.0), -1.0, 3.0)};
  geometry::CameraModel camera = cell.cameras[0];
  camera.distortion = {-0.12, 0.02, 0.0005, -0.0004, 0.0};
  const MaskRenderer renderer(camera, {}, {}, true);
  int landed = 0;
  ExpectSamplesCovered(renderer, people, rng, 400, &landed);
  EXPECT_GT(landed, 10000);
}

std::vector<geometry::TriangleMesh> ObstacleMeshes(const std::vector<Solid>& obstacles) {
  std::vector<geometry::TriangleMesh> meshes;
  for (const Solid& s : obstacles) meshes.push_back(Tessellate(s.geometry));
  return meshes;
}

TEST(MaskRendererTest, PersonBehindABoxIsHidden) {
  const geometry::CameraModel camera =
      scene::LookAtCamera(Vector3d(-2.0, 0.0, 1.2), Vector3d(2.0, 0.0, 1.0), 320, 240, 250.0);
  const std::vector<BodyState> people = {WalkingBody(Vector3d(2.0, 0.1, 0.0), 1.0, 0.5)};
  BoxSolid wall;
  wall.centre_W = Vector3d(0.25, 0.0, 1.5);
  wall.half_extents_m = Vector3d(0.25, 2.5, 1.5);
  const std::vector<std::pair<const char*, SolidGeometry>> cases = {
      {"box", wall},
      {"mesh", MeshSolid{Tessellate(wall)}},
      {"cylinder", CylinderSolid{Vector3d(0.0, 0.0, -0.5), Vector3d(0.0, 0.0, 3.5), 1.2}},
      {"capsule", CapsuleSolid{Vector3d(0.0, -1.0, 1.0), Vector3d(0.0, 1.0, 1.0), 1.3}},
  };
  common::ImageU8 open_mask;
  MaskRenderer(camera, {Solid{"wall", wall}}, {}, false).Render(people, &open_mask);
  ASSERT_GT(Count(open_mask), 2000);
  for (const auto& [name, geometry] : cases) {
    SCOPED_TRACE(name);
    const MaskRenderer renderer(camera, {Solid{name, geometry}}, {}, true);
    common::ImageU8 mask;
    renderer.Render(people, &mask);
    EXPECT_EQ(Count(mask), 0);
  }
}

TEST(MaskRendererTest, VisiblePointsStayForegroundWithObstacles) {
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  int landed = 0;
  int hidden = 0;
  long long with_occlusion = 0;
  long long without_occlusion = 0;
  for (std::uint64_t seed = 41; seed <= 48; ++seed) {
    std::mt19937_64 rng(seed);
    testing::RandomSceneOptions options;
    options.num_cameras = 2;
    options.width = 240;
    options.height = 180;
    options.num_objects = 0;
    options.num_obstacles = 2;
    const testing::RandomScene s = testing::MakeRandomScene(seed, options);
    // Obstacles of every kind between the cameras and the people.
    std::vector<Solid> obstacles;
    for (const auto& mesh : s.obstacles) obstacles.push_back({"mesh", MeshSolid{mesh}});
    BoxSolid box;
    box.centre_W = Vector3d(0.4 + 1.2 * u01(rng), 0.4 + 1.2 * u01(rng), 0.8);
    box.half_extents_m = Vector3d(0.3, 0.05, 0.4);
    box.R_WB = Eigen::AngleAxisd(u01(rng) * M_PI, Vector3d::UnitZ()).toRotationMatrix();
    obstacles.push_back({"box", box});
    obstacles.push_back({"cylinder", CylinderSolid{Vector3d(1.5 * u01(rng), 1.0, 0.0),
                                                   Vector3d(1.5 * u01(rng), 1.2, 1.5), 0.15}});
    obstacles.push_back({"capsule", CapsuleSolid{Vector3d(0.3, 0.3 + u01(rng), 1.2),
                                                 Vector3d(1.7, 1.5, 0.9), 0.12}});
    const std::vector<geometry::TriangleMesh> meshes = ObstacleMeshes(obstacles);
    const std::vector<BodyState> people = {RandomBody(rng, Vector3d(1.0, 1.0, 1.0), 0.6),
                                           RandomBody(rng, Vector3d(0.7, 1.3, 0.6), 0.5)};
    for (const geometry::CameraModel& pinhole : s.cameras) {
      for (const bool distorted : {false, true}) {
        const geometry::CameraModel camera =
            distorted ? WithRandomDistortion(rng, pinhole) : pinhole;
        const MaskRenderer renderer(camera, obstacles, {}, true);
        common::ImageU8 mask;
        renderer.Render(people, &mask);
        common::ImageU8 open_mask;
        MaskRenderer(camera, obstacles, {}, false).Render(people, &open_mask);
        with_occlusion += Count(mask);
        without_occlusion += Count(open_mask);
        for (std::size_t i = 0; i < mask.pixels.size(); ++i) {
          ASSERT_TRUE(!mask.pixels[i] || open_mask.pixels[i]);  // Occlusion only removes.
        }
        auto uniform = [&] { return u01(rng); };
        for (const scene::Shape& shape : ToShapes(people)) {
          for (int i = 0; i < 100; ++i) {
            const Vector3d p = scene::SampleInside(shape, uniform);
            int u;
            int v;
            if (!PixelOf(camera, p, &u, &v)) continue;
            if (!testing::VisibleFrom(camera, meshes, p)) {
              ++hidden;
              continue;
            }
            ++landed;
            ASSERT_EQ(mask.At(u, v), 255)
                << "seed " << seed << " point " << p.transpose() << " pixel " << u << "," << v;
          }
        }
      }
    }
  }
  EXPECT_GT(landed, 10000);
  EXPECT_GT(hidden, 500);
  // The obstacles do hide part of the people.
  EXPECT_LT(with_occlusion, without_occlusion);
}

TEST(MaskRendererTest, StaticForegroundAppears) {
  const geometry::CameraModel pinhole =
      scene::LookAtCamera(Vector3d(-1.5, -1.0, 2.5), Vector3d(1.0, 1.0, 0.3), 320, 240, 260.0);
  BoxSolid crate;
  crate.centre_W = Vector3d(1.0, 1.0, 0.25);
  crate.half_extents_m = Vector3d(0.3, 0.2, 0.25);
  crate.R_WB = Eigen::AngleAxisd(0.4, Vector3d::UnitZ()).toRotationMatrix();
  const std::vector<Solid> statics = {
      {"crate", crate},
      {"barrel", CylinderSolid{Vector3d(2.0, 0.0, 0.0), Vector3d(2.0, 0.0, 0.9), 0.3}},
      {"bollard", CapsuleSolid{Vector3d(0.0, 2.0, 0.2), Vector3d(0.0, 2.0, 1.0), 0.1}},
      {"mesh",
       MeshSolid{geometry::TriangleMesh::Box(Vector3d(2.0, 2.0, 0.0), Vector3d(2.4, 2.3, 0.5))}},
  };
  std::mt19937_64 rng(51);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  for (const bool distorted : {false, true}) {
    const geometry::CameraModel camera = distorted ? WithRandomDistortion(rng, pinhole) : pinhole;
    const MaskRenderer renderer(camera, {}, statics, true);
    common::ImageU8 mask;
    renderer.Render({}, &mask);
    for (const Solid& solid : statics) {
      const common::Box3 b = Bounds(solid.geometry);
      int landed = 0;
      for (int i = 0; i < 3000 && landed < 500; ++i) {
        const Vector3d p =
            b.min + (b.max - b.min).cwiseProduct(Vector3d(u01(rng), u01(rng), u01(rng)));
        if (!Contains(solid.geometry, p)) continue;
        int u;
        int v;
        if (!PixelOf(camera, p, &u, &v)) continue;
        ++landed;
        ASSERT_EQ(mask.At(u, v), 255) << solid.name;
      }
      EXPECT_GT(landed, 100) << solid.name;
    }
    // Not much more than the crate-like shapes: compare with the exact mask of
    // their bounding shapes (box, capsules and the mesh's box).
    if (!distorted) {
      scene::OrientedBox box{crate.centre_W, crate.half_extents_m, crate.R_WB};
      const std::vector<scene::Shape> shapes = {
          box, scene::Capsule{Vector3d(2.0, 0.0, 0.0), Vector3d(2.0, 0.0, 0.9), 0.3},
          scene::Capsule{Vector3d(0.0, 2.0, 0.2), Vector3d(0.0, 2.0, 1.0), 0.1},
          scene::OrientedBox{Vector3d(2.2, 2.15, 0.25), Vector3d(0.2, 0.15, 0.25),
                             Eigen::Matrix3d::Identity()}};
      const common::ImageU8 exact = scene::RenderExactMask(camera, shapes);
      ExpectContainsExact(mask, exact, 0.6);
    }
  }
}

// Long, thin parts (a cable 15 to 30 m long, 1 mm thick, seen by a
// telephoto camera): every point of the axis lands on foreground. The
// interior distance used to be computed as (A C - B^2) / A in float, whose
// cancellation (of the ends' distances, metres off the ray) left holes along
// 10 to 90 % of such cables.
TEST(MaskRendererTest, LongThinPartsHaveNoHoles) {
  std::mt19937_64 rng(71);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  int landed = 0;
  for (int trial = 0; trial < 40; ++trial) {
    geometry::CameraModel camera;
    camera.name = "tele";
    camera.width = 64;
    camera.height = 64;
    const double f = 2000.0 + 3000.0 * u01(rng);
    camera.K << f, 0, 31.5, 0, f, 31.5, 0, 0, 1;
    const double z = 5.0 + 5.0 * u01(rng);
    const double half = 7.5 + 7.5 * u01(rng);
    const double angle = 6.2831853 * u01(rng);
    const Vector3d dir(std::cos(angle), std::sin(angle), 0.3 * (u01(rng) - 0.5));
    const Vector3d centre(0.002 * (u01(rng) - 0.5) * z, 0.002 * (u01(rng) - 0.5) * z, z);
    const Vector3d a = centre - half * dir;
    const Vector3d b = centre + half * dir;
    const std::vector<Solid> statics = {{"cable", CapsuleSolid{a, b, 0.001}}};
    const MaskRenderer renderer(camera, {}, statics, true);
    common::ImageU8 mask;
    renderer.Render({}, &mask);
    for (int i = 0; i <= 20000; ++i) {
      const Vector3d p = a + (b - a) * (i / 20000.0);
      int u;
      int v;
      if (!PixelOf(camera, p, &u, &v)) continue;
      ++landed;
      ASSERT_EQ(mask.At(u, v), 255) << "trial " << trial << " point " << p.transpose();
    }
  }
  EXPECT_GT(landed, 5000);
}

// A strongly distorting lens whose image corners reach past the fold of its
// polynomial model (k1 = -0.4, k2 = 0.05, f = 60 px: fold at 46 degrees):
// every pixel that has a ray on the primary branch shows a 1 mm sphere on
// that ray. The inversion used to start each row at the image edge, past
// the fold, and keep to a root of another branch along the row, its pixels
// looking 20 degrees and more away from where they look (408 of 4668).
TEST(MaskRendererTest, PixelsOfALensFoldedAtItsCornersLookAlongTheirOwnRays) {
  geometry::CameraModel camera;
  camera.name = "wide";
  camera.width = 96;
  camera.height = 72;
  const double f = 60.0;
  const double cx = 47.5;
  const double cy = 35.5;
  camera.K << f, 0, cx, 0, f, cy, 0, 0, 1;
  camera.distortion = {-0.4, 0.05, 0.0, 0.0, 0.0};
  const auto radial = [&](double r) {
    const double r2 = r * r;
    return r * (1.0 + camera.distortion[0] * r2 + camera.distortion[1] * r2 * r2);
  };
  // The fold: where r (1 + k1 r^2 + k2 r^4) stops rising.
  double fold = 0.0;
  double highest = 0.0;
  for (double r = 1e-4; radial(r) > highest; r += 1e-4) {
    highest = radial(r);
    fold = r;
  }
  const MaskRenderer renderer(camera, {}, {}, false);
  std::vector<std::pair<int, int>> pixels;
  std::vector<BodyState> people(1);
  int tested = 0;
  const auto flush = [&] {
    common::ImageU8 mask;
    renderer.Render(people, &mask);
    for (const auto& [u, v] : pixels) {
      EXPECT_EQ(mask.At(u, v), 255) << "pixel " << u << ", " << v;
    }
    tested += static_cast<int>(pixels.size());
    pixels.clear();
  };
  for (int v = 0; v < camera.height; ++v) {
    for (int u = 0; u < camera.width; ++u) {
      const double xd = (u - cx) / f;
      const double yd = (v - cy) / f;
      const double rd = std::hypot(xd, yd);
      if (rd >= 0.999 * highest) continue;  // No primary ray, or at the fold.
      double lo = 0.0;
      double hi = fold;
      for (int i = 0; i < 100; ++i) (radial(0.5 * (lo + hi)) < rd ? lo : hi) = 0.5 * (lo + hi);
      const double scale = rd > 0.0 ? 0.5 * (lo + hi) / rd : 1.0;
      BodyCapsule& part = people[0].parts[pixels.size()];
      part.a_W = part.b_W = Vector3d(xd * scale, yd * scale, 1.0);
      part.radius_m = 0.001;
      pixels.emplace_back(u, v);
      if (pixels.size() == people[0].parts.size()) flush();
    }
  }
  if (!pixels.empty()) {
    for (std::size_t i = pixels.size(); i < people[0].parts.size(); ++i) {
      people[0].parts[i] = people[0].parts[0];
    }
    flush();
  }
  EXPECT_GT(tested, 4000);
}

TEST(MaskRendererTest, RenderReusesTheOutputImage) {
  const geometry::CameraModel camera =
      scene::LookAtCamera(Vector3d(-2.0, 0.0, 1.5), Vector3d(1.0, 0.0, 1.0), 160, 120, 120.0);
  const MaskRenderer renderer(camera, {}, {}, true);
  common::ImageU8 mask;
  renderer.Render({WalkingBody(Vector3d(1.0, 0.0, 0.0), 0.0, 0.0)}, &mask);
  ASSERT_EQ(mask.width, 160);
  ASSERT_EQ(mask.height, 120);
  const std::uint8_t* data = mask.pixels.data();
  const long long first = Count(mask);
  EXPECT_GT(first, 100);
  renderer.Render({WalkingBody(Vector3d(5.0, 0.0, 0.0), 0.0, 1.0)}, &mask);
  EXPECT_EQ(mask.pixels.data(), data);
  EXPECT_LT(Count(mask), first);  // Farther away: smaller, and the old pixels are gone.
  renderer.Render({}, &mask);
  EXPECT_EQ(Count(mask), 0);
  // People behind the camera do not show.
  renderer.Render({WalkingBody(Vector3d(-4.0, 0.0, 0.0), 0.0, 0.0)}, &mask);
  EXPECT_EQ(Count(mask), 0);
}

}  // namespace
}  // namespace hg::sim
