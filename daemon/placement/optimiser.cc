#include "placement/optimiser.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include <nlopt.h>
#include <pagmo/algorithms/cmaes.hpp>
#include <pagmo/population.hpp>
#include <pagmo/problem.hpp>
#include <pagmo/types.hpp>

#include "common/check.h"
#include "common/config_error.h"
#include "common/limits.h"
#include "placement/mounting.h"

namespace hg::placement {
namespace {

using Clock = std::chrono::steady_clock;

double Seconds(Clock::time_point since) {
  return std::chrono::duration<double>(Clock::now() - since).count();
}

/// The layout objective on gene vectors, shared by the copies pagmo makes
/// of the problem. Single-thread (pagmo's CMA-ES evaluates in its thread;
/// the evaluator parallelises inside one evaluation).
class LayoutObjective {
 public:
  LayoutObjective(const PlacementScene& scene, Evaluator* evaluator, int cameras,
                  const ProgressFn* progress, long long budget)
      : scene_(&scene),
        evaluator_(evaluator),
        cameras_(cameras),
        progress_(progress),
        budget_(budget) {}

  [[nodiscard]] int dimension() const { return cameras_ * kGenesPerCamera; }

  double Score(const std::vector<double>& genes) {
    std::vector<CameraPlacement> placements(cameras_);
    for (int c = 0; c < cameras_; ++c) {
      placements[c] = DecodePlacement(*scene_, genes.data() + c * kGenesPerCamera);
    }
    const double score = evaluator_->Evaluate(CamerasOf(*scene_, placements)).score;
    ++evaluations_;
    best_ = std::max(best_, score);
    return score;
  }

  /// Reports progress (once per generation).
  void Report() const {
    if (*progress_) (*progress_)(Progress{"global", evaluations_, budget_, best_});
  }

  [[nodiscard]] long long evaluations() const { return evaluations_; }

 private:
  const PlacementScene* scene_;
  Evaluator* evaluator_;
  int cameras_;
  const ProgressFn* progress_;
  long long budget_;
  long long evaluations_ = 0;
  double best_ = -std::numeric_limits<double>::infinity();
};

/// pagmo user-defined problem: minimise -score over [0, 1]^n.
class PagmoProblem {
 public:
  PagmoProblem() = default;
  explicit PagmoProblem(std::shared_ptr<LayoutObjective> objective)
      : objective_(std::move(objective)) {}

  [[nodiscard]] pagmo::vector_double fitness(const pagmo::vector_double& x) const {
    return {-objective_->Score(x)};
  }
  [[nodiscard]] std::pair<pagmo::vector_double, pagmo::vector_double> get_bounds() const {
    const std::size_t n = objective_ ? static_cast<std::size_t>(objective_->dimension()) : 1;
    return {pagmo::vector_double(n, 0.0), pagmo::vector_double(n, 1.0)};
  }
  [[nodiscard]] std::string get_name() const { return "hullguard camera placement"; }

 private:
  std::shared_ptr<LayoutObjective> objective_;
};

/// Context of the NLopt objective for one camera's block.
struct BlockContext {
  const PlacementScene* scene = nullptr;
  Evaluator* evaluator = nullptr;
  int surface = 0;
  long long evaluations = 0;
  long long limit = 0;
  double best_score = -std::numeric_limits<double>::infinity();
  std::vector<double> best_x;
};

/// The continuous variables of a placement: s, (t,) look-at x, y, z.
std::vector<double> BlockVariables(const PlacementScene& scene, const CameraPlacement& p) {
  std::array<double, kGenesPerCamera> genes{};
  EncodePlacement(scene, p, genes.data());
  std::vector<double> x = {genes[1]};
  if (scene.surfaces[p.surface].Dimensions() == 2) x.push_back(genes[2]);
  x.insert(x.end(), genes.begin() + 3, genes.end());
  return x;
}

CameraPlacement PlacementOfBlock(const PlacementScene& scene, int surface, const double* x) {
  const int n = static_cast<int>(scene.surfaces.size());
  std::array<double, kGenesPerCamera> genes{};
  genes[0] = (surface + 0.5) / n;
  int i = 0;
  genes[1] = x[i++];
  genes[2] = scene.surfaces[surface].Dimensions() == 2 ? x[i++] : 0.0;
  genes[3] = x[i++];
  genes[4] = x[i++];
  genes[5] = x[i++];
  return DecodePlacement(scene, genes.data());
}

double BlockObjective(unsigned n, const double* x, double* grad, void* data) {
  (void)grad;  // Derivative-free (BOBYQA).
  auto* ctx = static_cast<BlockContext*>(data);
  const CameraPlacement p = PlacementOfBlock(*ctx->scene, ctx->surface, x);
  const std::vector<geometry::CameraModel> camera = CamerasOf(*ctx->scene, {p});
  const double score = ctx->evaluator->EvaluateVarying(camera.front()).score;
  ++ctx->evaluations;
  if (score > ctx->best_score) {
    ctx->best_score = score;
    ctx->best_x.assign(x, x + n);
  }
  return score;
}

}  // namespace

CameraPlacement DecodePlacement(const PlacementScene& scene, const double* genes) {
  const int n = static_cast<int>(scene.surfaces.size());
  HG_CHECK(n > 0);
  CameraPlacement p;
  p.surface = std::clamp(static_cast<int>(std::floor(genes[0] * n)), 0, n - 1);
  p.s = std::clamp(genes[1], 0.0, 1.0);
  p.t = scene.surfaces[p.surface].Dimensions() == 2 ? std::clamp(genes[2], 0.0, 1.0) : 0.0;
  p.position_W = scene.surfaces[p.surface].PointAt(p.s, p.t);
  const Eigen::Vector3d f(std::clamp(genes[3], 0.0, 1.0), std::clamp(genes[4], 0.0, 1.0),
                          std::clamp(genes[5], 0.0, 1.0));
  p.look_at_W = scene.grid.bounds.min + f.cwiseProduct(scene.grid.bounds.Size());
  return p;
}

void EncodePlacement(const PlacementScene& scene, const CameraPlacement& placement, double* genes) {
  const int n = static_cast<int>(scene.surfaces.size());
  genes[0] = (placement.surface + 0.5) / n;
  genes[1] = placement.s;
  genes[2] = placement.t;
  const Eigen::Vector3d f = (placement.look_at_W - scene.grid.bounds.min)
                                .cwiseQuotient(scene.grid.bounds.Size())
                                .cwiseMax(0.0)
                                .cwiseMin(1.0);
  genes[3] = f.x();
  genes[4] = f.y();
  genes[5] = f.z();
}

std::vector<geometry::CameraModel> CamerasOf(const PlacementScene& scene,
                                             const std::vector<CameraPlacement>& placements) {
  std::vector<geometry::CameraModel> cameras;
  cameras.reserve(placements.size());
  for (std::size_t c = 0; c < placements.size(); ++c) {
    cameras.push_back(MakeCamera(scene.intrinsics, "cam" + std::to_string(c),
                                 placements[c].position_W, placements[c].look_at_W));
  }
  return cameras;
}

std::vector<CameraPlacement> CornerHeuristic(const PlacementScene& scene, int cameras) {
  const common::Box3& b = scene.grid.bounds;
  const double z = b.max.z();
  std::vector<Eigen::Vector3d> targets = {{b.min.x(), b.min.y(), z},
                                          {b.max.x(), b.max.y(), z},
                                          {b.max.x(), b.min.y(), z},
                                          {b.min.x(), b.max.y(), z}};
  targets.resize(std::min<std::size_t>(targets.size(), std::max(0, cameras)));
  const int extra = std::max(0, cameras - 4);
  // Top edges south, north, east, west; extra cameras go round them in turn.
  const std::array<std::pair<Eigen::Vector3d, Eigen::Vector3d>, 4> edges = {{
      {{b.min.x(), b.min.y(), z}, {b.max.x(), b.min.y(), z}},
      {{b.min.x(), b.max.y(), z}, {b.max.x(), b.max.y(), z}},
      {{b.max.x(), b.min.y(), z}, {b.max.x(), b.max.y(), z}},
      {{b.min.x(), b.min.y(), z}, {b.min.x(), b.max.y(), z}},
  }};
  for (int e = 0; e < 4; ++e) {
    const int on_edge = extra / 4 + (e < extra % 4 ? 1 : 0);
    for (int q = 0; q < on_edge; ++q) {
      const double f = (q + 1.0) / (on_edge + 1.0);
      targets.push_back(edges[e].first + f * (edges[e].second - edges[e].first));
    }
  }
  const Eigen::Vector3d centre = 0.5 * (b.min + b.max);
  std::vector<CameraPlacement> placements;
  for (const Eigen::Vector3d& target : targets) {
    CameraPlacement best;
    double best_d2 = std::numeric_limits<double>::infinity();
    for (std::size_t i = 0; i < scene.surfaces.size(); ++i) {
      double s = 0.0;
      double t = 0.0;
      const Eigen::Vector3d p = ClosestMountPoint(scene.surfaces[i], target, &s, &t);
      const double d2 = (p - target).squaredNorm();
      if (d2 < best_d2 - 1e-12) {
        best_d2 = d2;
        best.surface = static_cast<int>(i);
        best.s = s;
        best.t = t;
        best.position_W = p;
      }
    }
    best.look_at_W = centre;
    placements.push_back(best);
  }
  return placements;
}

void CheckRequest(int cameras, int min_views, const std::string& source) {
  if (cameras < 1) {
    throw common::ConfigError::At(
        source, 0, "--cameras: must be at least 1 (got " + std::to_string(cameras) + ")");
  }
  if (cameras > common::kMaxCameras) {
    // The cameras file is for hullguardd and hullguard carve, which take no more.
    throw common::ConfigError::At(source, 0,
                                  "--cameras: at most " + std::to_string(common::kMaxCameras) +
                                      " cameras, as hullguardd and hullguard carve take (got " +
                                      std::to_string(cameras) + ")");
  }
  if (min_views < 1 || min_views > cameras) {
    throw common::ConfigError::At(source, 0,
                                  "--min-views: must be between 1 and --cameras (" +
                                      std::to_string(cameras) + "), got " +
                                      std::to_string(min_views));
  }
}

PlacementResult OptimisePlacement(const PlacementScene& scene, const ObjectiveOptions& objective,
                                  const OptimiserOptions& options, const ProgressFn& progress) {
  const std::string source = scene.source_file.empty() ? scene.name : scene.source_file;
  CheckRequest(options.cameras, objective.min_views, source);
  if (!(options.sigma0 > 0.0 && options.sigma0 <= 1.0)) {
    throw common::ConfigError::At(source, 0, "--sigma: must be in (0, 1]");
  }
  const int n_cameras = options.cameras;
  const int dim = n_cameras * kGenesPerCamera;
  const long long global_budget =
      options.global_evaluations > 0 ? options.global_evaluations : 2000 + 1000LL * n_cameras;
  const long long local_budget =
      options.local_evaluations > 0 ? options.local_evaluations : 150LL * n_cameras;
  const int lambda =
      options.population > 0
          ? std::max(5, options.population)
          : 2 * (4 + static_cast<int>(std::floor(3.0 * std::log(static_cast<double>(dim)))));

  Evaluator evaluator(scene, objective, options.threads);
  PlacementResult result;

  // Global search.
  const Clock::time_point global_start = Clock::now();
  auto layout =
      std::make_shared<LayoutObjective>(scene, &evaluator, n_cameras, &progress, global_budget);
  pagmo::problem problem{PagmoProblem(layout)};
  pagmo::population population(problem, 0u);
  std::vector<double> genes(dim);
  const std::vector<CameraPlacement> start = CornerHeuristic(scene, n_cameras);
  for (int c = 0; c < n_cameras; ++c) {
    EncodePlacement(scene, start[c], genes.data() + c * kGenesPerCamera);
  }
  population.push_back(genes);
  std::mt19937_64 rng(options.seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (int i = 1; i < lambda; ++i) {
    for (double& g : genes) g = unit(rng);
    population.push_back(genes);
  }
  const auto cma_seed = static_cast<unsigned>(options.seed ^ (options.seed >> 32));
  pagmo::cmaes cmaes(1u, -1, -1, -1, -1, options.sigma0, /*ftol=*/1e-9, /*xtol=*/1e-6,
                     /*memory=*/true, /*force_bounds=*/true, cma_seed);
  layout->Report();
  while (layout->evaluations() + lambda <= global_budget) {
    const long long before = layout->evaluations();
    population = cmaes.evolve(population);
    if (layout->evaluations() == before) break;  // Converged: nothing left to sample.
    layout->Report();
  }
  result.global_evaluations = layout->evaluations();
  result.global_seconds = Seconds(global_start);
  const pagmo::vector_double champion = population.champion_x();
  std::vector<CameraPlacement> best(n_cameras);
  for (int c = 0; c < n_cameras; ++c) {
    best[c] = DecodePlacement(scene, champion.data() + c * kGenesPerCamera);
  }
  double best_score = -population.champion_f()[0];

  // Local refinement: one camera at a time, the others fixed; sweeps over the
  // cameras with shrinking first steps until the budget is spent or a whole
  // sweep improves nothing.
  const Clock::time_point local_start = Clock::now();
  const long long per_block = std::max<long long>(12, local_budget / (2LL * n_cameras));
  long long local_done = 0;
  double step = 0.06;  // Steps of a few voxels: smaller ones change no voxel count at first.
  for (bool improved = true; improved && local_done < local_budget;
       step = std::max(0.01, step / 2)) {
    improved = false;
    for (int c = 0; c < n_cameras && local_done < local_budget; ++c) {
      evaluator.Freeze(CamerasOf(scene, best), c);
      BlockContext ctx;
      ctx.scene = &scene;
      ctx.evaluator = &evaluator;
      ctx.surface = best[c].surface;
      std::vector<double> x = BlockVariables(scene, best[c]);
      const auto n = static_cast<unsigned>(x.size());
      nlopt_opt opt = nlopt_create(NLOPT_LN_BOBYQA, n);
      HG_CHECK(opt != nullptr);
      const std::vector<double> lower(n, 0.0);
      const std::vector<double> upper(n, 1.0);
      nlopt_set_lower_bounds(opt, lower.data());
      nlopt_set_upper_bounds(opt, upper.data());
      nlopt_set_max_objective(opt, &BlockObjective, &ctx);
      nlopt_set_maxeval(opt, static_cast<int>(std::min(per_block, local_budget - local_done)));
      nlopt_set_xtol_abs1(opt, 1e-4);
      nlopt_set_initial_step1(opt, step);
      double value = 0.0;
      (void)nlopt_optimize(opt, x.data(), &value);  // Any stop reason keeps the best seen.
      nlopt_destroy(opt);
      local_done += ctx.evaluations;
      if (ctx.best_score > best_score) {
        best_score = ctx.best_score;
        best[c] = PlacementOfBlock(scene, best[c].surface, ctx.best_x.data());
        improved = true;
      }
      if (progress) progress(Progress{"local", local_done, local_budget, best_score});
    }
  }
  result.local_evaluations = local_done;
  result.local_seconds = Seconds(local_start);

  result.placements = best;
  result.cameras = CamerasOf(scene, best);
  result.metrics = evaluator.Evaluate(result.cameras);
  return result;
}

}  // namespace hg::placement
