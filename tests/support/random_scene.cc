#include "support/random_scene.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>

#include <Eigen/Geometry>

#include "scene/exact_mask.h"

namespace hg::testing {

int SoakFactor() {
  static const int factor = [] {
    const char* text = std::getenv("HG_SOAK");
    if (text == nullptr || *text == '\0') return 1;
    char* end = nullptr;
    const long value = std::strtol(text, &end, 10);
    if (*end != '\0' || value < 1 || value > 100000) {
      std::fprintf(stderr, "HG_SOAK must be a positive integer, not '%s'\n", text);
      std::exit(2);
    }
    return static_cast<int>(value);
  }();
  return factor;
}

int SoakSeeds(int seeds) { return seeds * SoakFactor(); }

scene::Shape RandomObject(std::mt19937_64& rng, const common::Box3& bounds) {
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  auto point = [&] {
    return Eigen::Vector3d(bounds.min.x() + (0.2 + 0.6 * u01(rng)) * bounds.Size().x(),
                           bounds.min.y() + (0.2 + 0.6 * u01(rng)) * bounds.Size().y(),
                           bounds.min.z() + (0.2 + 0.6 * u01(rng)) * bounds.Size().z());
  };
  const double scale = bounds.Size().minCoeff();
  switch (std::uniform_int_distribution<int>(0, 2)(rng)) {
    case 0:
      return scene::Sphere{point(), scale * (0.03 + 0.1 * u01(rng))};
    case 1: {
      scene::OrientedBox b;
      b.centre_W = point();
      b.half_extents_m = Eigen::Vector3d(u01(rng), u01(rng), u01(rng)) * scale * 0.1 +
                         Eigen::Vector3d::Constant(scale * 0.02);
      const Eigen::Vector3d axis =
          Eigen::Vector3d(u01(rng) - 0.5, u01(rng) - 0.5, u01(rng) - 0.5).normalized();
      b.R_WB = Eigen::AngleAxisd(u01(rng) * 2 * M_PI, axis).toRotationMatrix();
      return b;
    }
    default: {
      scene::Capsule c;
      c.a_W = point();
      c.b_W = c.a_W + Eigen::Vector3d(u01(rng) - 0.5, u01(rng) - 0.5, u01(rng) - 0.5) * scale * 0.4;
      c.radius_m = scale * (0.02 + 0.05 * u01(rng));
      return c;
    }
  }
}

RandomScene MakeRandomScene(std::uint64_t seed, const RandomSceneOptions& options) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  RandomScene s;
  s.bounds.min = Eigen::Vector3d::Zero();
  s.bounds.max = Eigen::Vector3d::Constant(2.0);
  const Eigen::Vector3d centre = s.bounds.min + 0.5 * s.bounds.Size();
  for (int c = 0; c < options.num_cameras; ++c) {
    // Direction on the upper part of the sphere, distance 1.5 .. 3.5 m from the middle.
    const double azimuth = u01(rng) * 2 * M_PI;
    const double elevation = (-0.2 + 0.9 * u01(rng)) * M_PI / 2;
    const double distance = 1.5 + 2.0 * u01(rng);
    const Eigen::Vector3d dir(std::cos(elevation) * std::cos(azimuth),
                              std::cos(elevation) * std::sin(azimuth), std::sin(elevation));
    const Eigen::Vector3d eye = centre + distance * dir;
    const Eigen::Vector3d target =
        centre + Eigen::Vector3d(u01(rng) - 0.5, u01(rng) - 0.5, u01(rng) - 0.5) * 0.8;
    const double fx = options.width * (0.5 + 0.6 * u01(rng));
    s.cameras.push_back(LookAtCamera(eye, target, options.width, options.height, fx));
    s.cameras.back().name = "cam" + std::to_string(c);
  }
  for (int i = 0; i < options.num_objects; ++i) s.objects.push_back(RandomObject(rng, s.bounds));
  for (int i = 0; i < options.num_obstacles; ++i) {
    if (i % 2 == 0) {
      const Eigen::Vector3d lo(u01(rng) * 1.6, u01(rng) * 1.6, u01(rng) * 1.6);
      const Eigen::Vector3d size(0.05 + 0.4 * u01(rng), 0.05 + 0.4 * u01(rng),
                                 0.05 + 0.4 * u01(rng));
      s.obstacles.push_back(geometry::TriangleMesh::Box(lo, lo + size));
    } else {
      geometry::TriangleMesh soup;
      const Eigen::Vector3d base(0.2 + 1.6 * u01(rng), 0.2 + 1.6 * u01(rng), 0.2 + 1.6 * u01(rng));
      for (int t = 0; t < 4; ++t) {
        const int first = static_cast<int>(soup.vertices.size());
        for (int k = 0; k < 3; ++k) {
          soup.vertices.push_back(
              base + Eigen::Vector3d(u01(rng) - 0.5, u01(rng) - 0.5, u01(rng) - 0.5) * 0.6);
        }
        soup.triangles.push_back({first, first + 1, first + 2});
      }
      s.obstacles.push_back(soup);
    }
  }
  return s;
}

std::vector<common::ImageU8> RenderMasks(const std::vector<geometry::CameraModel>& cameras,
                                         const std::vector<scene::Shape>& objects) {
  std::vector<common::ImageU8> masks;
  masks.reserve(cameras.size());
  for (const auto& cam : cameras) masks.push_back(scene::RenderExactMask(cam, objects));
  return masks;
}

std::vector<octree::CameraView> MakeViews(const std::vector<geometry::CameraModel>& cameras,
                                          const std::vector<geometry::TriangleMesh>& obstacles) {
  std::vector<octree::CameraView> views;
  views.reserve(cameras.size());
  for (const auto& cam : cameras) views.emplace_back(cam, obstacles);
  return views;
}

namespace {
// Segment-triangle intersection (Moller-Trumbore), closed triangle, segment o + s d, s in (0, 1).
bool SegmentHitsTriangle(const Eigen::Vector3d& o, const Eigen::Vector3d& d,
                         const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                         const Eigen::Vector3d& c) {
  const Eigen::Vector3d e1 = b - a, e2 = c - a;
  const Eigen::Vector3d p = d.cross(e2);
  const double det = e1.dot(p);
  if (std::abs(det) < 1e-15) return false;
  const double inv = 1.0 / det;
  const Eigen::Vector3d tv = o - a;
  const double u = tv.dot(p) * inv;
  if (u < -1e-9 || u > 1 + 1e-9) return false;
  const Eigen::Vector3d q = tv.cross(e1);
  const double v = d.dot(q) * inv;
  if (v < -1e-9 || u + v > 1 + 1e-9) return false;
  const double s = e2.dot(q) * inv;
  return s > 1e-12 && s < 1.0 - 1e-12;
}
}  // namespace

bool VisibleFrom(const geometry::CameraModel& camera,
                 const std::vector<geometry::TriangleMesh>& obstacles, const Eigen::Vector3d& p_W) {
  const Eigen::Vector3d o = camera.CentreW();
  const Eigen::Vector3d d = p_W - o;
  for (const auto& mesh : obstacles) {
    for (const auto& t : mesh.triangles) {
      if (SegmentHitsTriangle(o, d, mesh.vertices[t[0]], mesh.vertices[t[1]],
                              mesh.vertices[t[2]])) {
        return false;
      }
    }
  }
  return true;
}

}  // namespace hg::testing
