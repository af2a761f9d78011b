#include "hullguard/carve.h"

#include <algorithm>
#include <chrono>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "common/config_error.h"
#include "silhouette/undistort.h"

namespace hg::tools {
namespace {

using Clock = std::chrono::steady_clock;
double MsSince(Clock::time_point t) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

}  // namespace

CarveResult Carve(const CarveJob& job) {
  CarveResult out;
  // Undistort where the lens distorts; from here on every camera is a pinhole.
  std::vector<geometry::CameraModel> pinholes;
  // Masks of distorting cameras are replaced by their undistorted copies; the
  // others are used as they are.
  std::vector<common::ImageU8> undistorted(job.cameras.size());
  auto t0 = Clock::now();
  for (std::size_t c = 0; c < job.cameras.size(); ++c) {
    const geometry::CameraModel& cam = job.cameras[c];
    pinholes.push_back(cam.Pinhole());
    if (cam.HasDistortion()) {
      const silhouette::ConservativeUndistorter undistort(cam);
      undistort.Apply(job.masks[c].View(), job.threshold, &undistorted[c]);
    }
  }
  out.undistort_ms = MsSince(t0);

  t0 = Clock::now();
  std::vector<octree::CameraView> views;
  views.reserve(pinholes.size());
  for (const auto& cam : pinholes) views.emplace_back(cam, job.obstacles);
  out.tree = std::make_unique<octree::Octree>(
      octree::OctreeConfig{job.bounds, job.depth, job.threads, job.boundary_coarsening},
      std::move(views));
  out.setup_ms = MsSince(t0);

  t0 = Clock::now();
  out.quadtrees.reserve(pinholes.size());
  std::vector<const silhouette::SilhouetteQuadtree*> ptrs;
  for (std::size_t c = 0; c < pinholes.size(); ++c) {
    out.quadtrees.emplace_back(pinholes[c].width, pinholes[c].height);
    // Undistorted masks are 0/255; raw ones use the user's threshold.
    const std::uint8_t threshold = job.cameras[c].HasDistortion() ? 127 : job.threshold;
    const common::ImageU8& mask = job.cameras[c].HasDistortion() ? undistorted[c] : job.masks[c];
    out.quadtrees.back().Build(mask.View(), threshold);
  }
  for (const auto& q : out.quadtrees) ptrs.push_back(&q);
  out.quadtree_ms = MsSince(t0);
  out.stats = out.tree->Update(ptrs);
  return out;
}

void WriteSnapshot(const octree::Octree& tree, const std::vector<geometry::CameraModel>& cameras,
                   const std::vector<geometry::TriangleMesh>& obstacles, const std::string& path) {
  const common::Box3& b = tree.config().bounds;
  const Eigen::Vector3d size = b.Size();
  const double px_per_m = 600.0 / std::max(size.x(), size.y());
  const int margin = 40;
  const int top_w = static_cast<int>(size.x() * px_per_m),
            top_h = static_cast<int>(size.y() * px_per_m);
  const int side_h = static_cast<int>(size.z() * px_per_m);
  cv::Mat img(std::max(top_h, side_h) + 2 * margin + 30, 2 * top_w + 3 * margin, CV_8UC3,
              cv::Scalar(255, 255, 255));
  // Views: top (x, y) on the left; side (x, z) on the right.
  auto top = [&](double x, double y) {
    return cv::Point(margin + static_cast<int>((x - b.min.x()) * px_per_m),
                     margin + 30 + top_h - static_cast<int>((y - b.min.y()) * px_per_m));
  };
  auto side = [&](double x, double z) {
    return cv::Point(2 * margin + top_w + static_cast<int>((x - b.min.x()) * px_per_m),
                     margin + 30 + side_h - static_cast<int>((z - b.min.z()) * px_per_m));
  };
  // Paint leaves far to near so that the nearest (highest / front-most) wins.
  struct Leaf {
    common::Box3 box;
    octree::LeafState state;
  };
  std::vector<Leaf> leaves;
  tree.ForEachLeaf([&](const octree::Cell& c, octree::LeafState s) {
    if (s != octree::LeafState::kFree) leaves.push_back({octree::CellBox(b, c), s});
  });
  // Occluded space first, light, as background; occupied leaves over it,
  // painted far to near so that the nearest (highest / front-most) wins.
  auto colour = [](double height01) {
    const double t = std::clamp(height01, 0.0, 1.0);
    return cv::Scalar(40 + 60 * (1 - t), 40 + 80 * t, 140 + 115 * t);
  };
  const cv::Scalar occluded(215, 215, 215);
  for (const Leaf& l : leaves) {
    if (l.state != octree::LeafState::kOccluded) continue;
    cv::rectangle(img, top(l.box.min.x(), l.box.max.y()), top(l.box.max.x(), l.box.min.y()),
                  occluded, cv::FILLED);
    cv::rectangle(img, side(l.box.min.x(), l.box.max.z()), side(l.box.max.x(), l.box.min.z()),
                  occluded, cv::FILLED);
  }
  std::erase_if(leaves, [](const Leaf& l) { return l.state == octree::LeafState::kOccluded; });
  std::sort(leaves.begin(), leaves.end(),
            [](const Leaf& a, const Leaf& l) { return a.box.max.z() < l.box.max.z(); });
  for (const Leaf& l : leaves) {
    cv::rectangle(img, top(l.box.min.x(), l.box.max.y()), top(l.box.max.x(), l.box.min.y()),
                  colour((l.box.max.z() - b.min.z()) / size.z()), cv::FILLED);
  }
  std::sort(leaves.begin(), leaves.end(),
            [](const Leaf& a, const Leaf& l) { return a.box.min.y() > l.box.min.y(); });
  for (const Leaf& l : leaves) {
    cv::rectangle(img, side(l.box.min.x(), l.box.max.z()), side(l.box.max.x(), l.box.min.z()),
                  colour((b.max.y() - l.box.min.y()) / size.y()), cv::FILLED);
  }
  for (const auto& mesh : obstacles) {
    for (const auto& t : mesh.triangles) {
      for (int k = 0; k < 3; ++k) {
        const Eigen::Vector3d& p = mesh.vertices[t[k]];
        const Eigen::Vector3d& q = mesh.vertices[t[(k + 1) % 3]];
        cv::line(img, top(p.x(), p.y()), top(q.x(), q.y()), cv::Scalar(0, 120, 0), 1);
        cv::line(img, side(p.x(), p.z()), side(q.x(), q.z()), cv::Scalar(0, 120, 0), 1);
      }
    }
  }
  cv::rectangle(img, top(b.min.x(), b.max.y()), top(b.max.x(), b.min.y()), cv::Scalar(0, 0, 0), 1);
  cv::rectangle(img, side(b.min.x(), b.max.z()), side(b.max.x(), b.min.z()), cv::Scalar(0, 0, 0),
                1);
  for (const auto& cam : cameras) {
    const Eigen::Vector3d c = cam.CentreW();
    cv::circle(img, top(c.x(), c.y()), 6, cv::Scalar(200, 80, 0), cv::FILLED);
    cv::circle(img, side(c.x(), c.z()), 6, cv::Scalar(200, 80, 0), cv::FILLED);
  }
  cv::putText(img, "top view (x right, y up); red: occupied, grey: occluded, blue: cameras",
              cv::Point(margin, img.rows - 12), cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 0, 0),
              1);
  cv::putText(img, "side view (x right, z up)", cv::Point(2 * margin + top_w, img.rows - 12),
              cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 0, 0), 1);
  bool ok = false;
  try {
    ok = cv::imwrite(path, img);
  } catch (const cv::Exception&) {
    ok = false;
  }
  if (!ok) throw common::ConfigError(path + ": cannot write image");
}

}  // namespace hg::tools
