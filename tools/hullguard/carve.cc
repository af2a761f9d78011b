#include "hullguard/carve.h"

#include <algorithm>
#include <chrono>

#include "common/config_error.h"
#include "hullguard/snapshot_picture.h"
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
      silhouette::ConservativeUndistorter undistort(cam);
      undistort.Apply(job.masks[c].View(), job.threshold, &undistorted[c]);
    }
  }
  out.undistort_ms = MsSince(t0);

  t0 = Clock::now();
  std::vector<octree::CameraView> views;
  views.reserve(pinholes.size());
  for (const auto& cam : pinholes) views.emplace_back(cam, job.obstacles);
  octree::OctreeConfig config{job.bounds, job.depth, job.threads, job.boundary_coarsening};
  config.max_nodes = job.max_nodes;
  out.tree = std::make_unique<octree::Octree>(config, std::move(views));
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
  WriteSnapshotPicture(LeafBoxes(tree), tree.config().bounds, cameras, obstacles, "", path);
}

}  // namespace hg::tools
