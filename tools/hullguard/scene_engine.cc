#include "hullguard/scene_engine.h"

#include <algorithm>
#include <chrono>
#include <random>

#include "octree/camera_view.h"

namespace hg::tools {
namespace {

using Clock = std::chrono::steady_clock;
double MsSince(Clock::time_point t) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

bool InsideCapsule(const sim::BodyCapsule& c, const Eigen::Vector3d& p) {
  return sim::Contains(sim::CapsuleSolid{c.a_W, c.b_W, c.radius_m}, p);
}

bool InsideBody(const sim::BodyState& body, const Eigen::Vector3d& p) {
  return std::any_of(body.parts.begin(), body.parts.end(),
                     [&](const sim::BodyCapsule& c) { return InsideCapsule(c, p); });
}

}  // namespace

SceneEngine::SceneEngine(sim::Scene scene, const SceneEngineOptions& options)
    : simulator_(std::move(scene), options.threads) {
  const sim::Scene& s = simulator_.scene();
  const std::vector<geometry::TriangleMesh> obstacles = s.ObstacleMeshes();
  std::vector<octree::CameraView> views;
  for (const sim::SceneCamera& camera : s.cameras) {
    pinholes_.push_back(camera.model.Pinhole());
    undistorters_.push_back(
        camera.model.HasDistortion()
            ? std::make_unique<silhouette::ConservativeUndistorter>(camera.model)
            : nullptr);
    views.emplace_back(pinholes_.back(), obstacles);
    quadtrees_.emplace_back(camera.model.width, camera.model.height);
  }
  for (const auto& q : quadtrees_) quadtree_ptrs_.push_back(&q);
  undistorted_.resize(s.cameras.size());
  octree::OctreeConfig config{s.bounds, options.depth, options.threads,
                              options.boundary_coarsening};
  config.coarse_first_depth = options.coarse_first_depth;
  config.key_level = options.key_level;
  config.settle_level = options.settle_level;
  tree_ = std::make_unique<octree::Octree>(config, std::move(views));
  if (options.max_speed_mps > 0.0) {
    const double stamp = StampOffset(s, options.stamp_at_median);
    for (const sim::SceneCamera& camera : s.cameras) {
      margins_.push_back(octree::Octree::RoundMargin(options.max_speed_mps *
                                                     std::abs(stamp - camera.time_offset_s)));
    }
  }
}

double StampOffset(const sim::Scene& scene, bool median) {
  std::vector<double> offsets;
  for (const sim::SceneCamera& camera : scene.cameras) offsets.push_back(camera.time_offset_s);
  if (offsets.empty()) return 0.0;
  std::sort(offsets.begin(), offsets.end());
  return median ? offsets[(offsets.size() - 1) / 2] : offsets.back();
}

const common::ImageU8& SceneEngine::PinholeMask(int camera) const {
  return undistorters_[camera] ? undistorted_[camera] : masks_[camera];
}

FrameTimes SceneEngine::Step(double t_s, const octree::UpdateControl& control,
                             double octree_budget_ms) {
  FrameTimes times;
  auto t0 = Clock::now();
  simulator_.RenderMasks(t_s, &masks_);
  times.render_ms = MsSince(t0);
  t0 = Clock::now();
  for (std::size_t c = 0; c < quadtrees_.size(); ++c) {
    if (undistorters_[c]) undistorters_[c]->Apply(masks_[c].View(), 127, &undistorted_[c]);
    quadtrees_[c].Build(PinholeMask(static_cast<int>(c)).View(), 127);
  }
  times.quadtree_ms = MsSince(t0);
  octree::UpdateControl budgeted = control;
  if (octree_budget_ms > 0.0) {
    budgeted.deadline = std::chrono::steady_clock::now() +
                        std::chrono::microseconds(std::llround(octree_budget_ms * 1e3));
  }
  times.octree = tree_->Update(quadtree_ptrs_, budgeted, margins_);
  return times;
}

std::vector<Eigen::Vector3d> SampleTruthPoints(const sim::Scene& scene, double t_s, int per_person,
                                               std::uint64_t seed,
                                               std::optional<double> stamp_offset_s) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::vector<Eigen::Vector3d> points;
  const bool compensated = stamp_offset_s.has_value();
  for (const sim::Person& person : scene.people) {
    const sim::BodyState body = sim::EvaluatePerson(person, t_s + stamp_offset_s.value_or(0.0));
    std::vector<sim::BodyState> seen;  // The body at each camera's capture time.
    for (const sim::SceneCamera& camera : scene.cameras) {
      if (!compensated && camera.time_offset_s != 0.0) {
        seen.push_back(sim::EvaluatePerson(person, t_s + camera.time_offset_s));
      }
    }
    for (int i = 0; i < per_person; ++i) {
      // A part chosen by volume share would be fairer; uniform over parts
      // samples small parts (hands, feet) more, where errors show first.
      const sim::BodyCapsule& c =
          body.parts[static_cast<std::size_t>(u01(rng) * sim::kNumBodyParts) % sim::kNumBodyParts];
      const Eigen::Vector3d lo = c.a_W.cwiseMin(c.b_W).array() - c.radius_m;
      const Eigen::Vector3d hi = c.a_W.cwiseMax(c.b_W).array() + c.radius_m;
      Eigen::Vector3d p;
      do {
        p = lo + Eigen::Vector3d(u01(rng), u01(rng), u01(rng)).cwiseProduct(hi - lo);
      } while (!InsideCapsule(c, p));
      if (std::all_of(seen.begin(), seen.end(),
                      [&](const sim::BodyState& b) { return InsideBody(b, p); })) {
        points.push_back(p);
      }
    }
  }
  return points;
}

TruthCheck CheckTruth(const octree::Octree& tree, const std::vector<Eigen::Vector3d>& points) {
  TruthCheck check;
  for (const Eigen::Vector3d& p : points) {
    const octree::PointState state = tree.StateAt(p);
    if (state == octree::PointState::kOutside) continue;
    ++check.points;
    check.reported_free += state == octree::PointState::kFree;
  }
  return check;
}

}  // namespace hg::tools
