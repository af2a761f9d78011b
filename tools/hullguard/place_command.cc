// `hullguard place`: where to mount N cameras so that the most space is
// certified free (docs/placement.md).
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "common/cli_checks.h"
#include "common/config_error.h"
#include "geometry/camera_yaml.h"
#include "hullguard/commands.h"
#include "placement/coverage.h"
#include "placement/mounting.h"
#include "placement/optimiser.h"
#include "placement/placement_scene.h"
#include "placement/report.h"
#include "sim/scene.h"

namespace hg::tools {
namespace {

struct PlaceFlags {
  std::string scene;
  int cameras = 0;
  int min_views = 0;
  bool min_views_given = false;  // Else min(2, cameras).
  std::uint64_t seed = 1;
  int budget = 0;
  int local_budget = 0;
  std::string intrinsics;
  double voxel_m = 0.10;
  int render_width = 192;
  double person_radius_m = 0.25;
  double person_height_m = 1.8;
  double person_spacing_m = 1.0;
  double coverage_weight = 0.5;
  double sigma = 0.25;
  int threads = 2;
  std::string out;
  std::string report;
  bool quiet = false;
};

/// The command as the user can repeat it (every setting spelled out).
std::string CommandLine(const PlaceFlags& f, int min_views) {
  std::ostringstream out;
  out << "hullguard place --scene " << f.scene << " --cameras " << f.cameras << " --min-views "
      << min_views << " --seed " << f.seed;
  if (f.budget > 0) out << " --budget " << f.budget;
  if (f.local_budget > 0) out << " --local-budget " << f.local_budget;
  if (!f.intrinsics.empty()) out << " --intrinsics " << f.intrinsics;
  if (f.voxel_m != 0.10) out << " --voxel " << f.voxel_m;
  if (f.render_width != 192) out << " --render-width " << f.render_width;
  if (f.person_radius_m != 0.25) out << " --person-radius " << f.person_radius_m;
  if (f.person_height_m != 1.8) out << " --person-height " << f.person_height_m;
  if (f.person_spacing_m != 1.0) out << " --person-spacing " << f.person_spacing_m;
  if (f.coverage_weight != 0.5) out << " --coverage-weight " << f.coverage_weight;
  if (f.sigma != 0.25) out << " --sigma " << f.sigma;
  out << " --threads " << f.threads << " --out " << f.out << " --report " << f.report;
  return out.str();
}

/// Progress on stderr: a bar redrawn in place on a terminal, else a line
/// every tenth of each stage.
class ProgressPrinter {
 public:
  explicit ProgressPrinter(bool enabled) : enabled_(enabled), tty_(isatty(STDERR_FILENO) != 0) {}
  ~ProgressPrinter() { Finish(); }

  void operator()(const placement::Progress& p) {
    if (!enabled_) return;
    if (p.stage != stage_) {
      Finish();
      stage_ = p.stage;
      last_tenth_ = -1;
    }
    const double f =
        p.budget > 0 ? std::min(1.0, static_cast<double>(p.evaluations) / p.budget) : 1.0;
    if (tty_) {
      constexpr int kWidth = 30;
      const int filled = static_cast<int>(f * kWidth);
      std::fprintf(stderr, "\rplace: %-6s [%s%s] %3d%% %lld/%lld evaluations, best score %.4f",
                   p.stage.c_str(), std::string(filled, '#').c_str(),
                   std::string(kWidth - filled, '.').c_str(), static_cast<int>(100 * f),
                   p.evaluations, p.budget, p.best_score);
      open_line_ = true;
    } else {
      const int tenth = static_cast<int>(10 * f);
      if (tenth == last_tenth_) return;
      last_tenth_ = tenth;
      std::fprintf(stderr, "place: %s %3d%% %lld/%lld evaluations, best score %.4f\n",
                   p.stage.c_str(), 10 * tenth, p.evaluations, p.budget, p.best_score);
    }
    std::fflush(stderr);
  }

 private:
  void Finish() {
    if (open_line_) std::fputc('\n', stderr);
    open_line_ = false;
  }

  bool enabled_;
  bool tty_;
  bool open_line_ = false;
  std::string stage_;
  int last_tenth_ = -1;
};

// A file that can be written at `path` (its folder exists and is writable;
// the path is no folder itself), checked without creating it.
void CheckCanWrite(const std::string& path, const char* flag) {
  namespace fs = std::filesystem;
  const fs::path p(path);
  std::error_code ec;
  if (fs::is_directory(p, ec)) {
    throw common::ConfigError(std::string("place: ") + flag + ": " + path + " is a directory");
  }
  const fs::path folder = p.has_parent_path() ? p.parent_path() : fs::path(".");
  if (!fs::is_directory(folder, ec) || access(folder.c_str(), W_OK) != 0) {
    throw common::ConfigError(std::string("place: ") + flag + ": cannot write " + path + " (" +
                              folder.string() + " is not a writable directory)");
  }
}

// A directory at `path` that exists and is writable, or whose nearest
// existing ancestor is a writable directory.
void CheckCanCreateDirectory(const std::string& path, const char* flag) {
  namespace fs = std::filesystem;
  std::error_code ec;
  fs::path p = fs::absolute(fs::path(path), ec);
  if (ec) p = fs::path(path);
  if (fs::exists(p, ec) && !fs::is_directory(p, ec)) {
    throw common::ConfigError(std::string("place: ") + flag + ": " + path +
                              " exists and is not a directory");
  }
  while (!fs::exists(p, ec) && p.has_parent_path() && p.parent_path() != p) p = p.parent_path();
  if (!fs::is_directory(p, ec) || access(p.c_str(), W_OK) != 0) {
    throw common::ConfigError(std::string("place: ") + flag + ": cannot create or write " + path +
                              " (" + p.string() + " is not a writable directory)");
  }
}

int RunPlace(const PlaceFlags& f) {
  const auto t_begin = std::chrono::steady_clock::now();
  const int min_views = f.min_views_given ? f.min_views : std::min(2, std::max(1, f.cameras));
  placement::CheckRequest(f.cameras, min_views, "place");
  if (f.threads < 1) throw common::ConfigError("place: --threads: must be at least 1");

  // The output paths before the search, which may take minutes.
  CheckCanWrite(f.out, "--out");
  CheckCanCreateDirectory(f.report, "--report");

  const sim::Scene scene = sim::LoadScene(f.scene);
  const placement::PlacementIntrinsics intrinsics = f.intrinsics.empty()
                                                        ? placement::IntrinsicsFromScene(scene)
                                                        : placement::LoadIntrinsics(f.intrinsics);
  placement::ModelOptions model;
  model.voxel_m = f.voxel_m;
  model.render_width_px = f.render_width;
  model.person_radius_m = f.person_radius_m;
  model.person_height_m = f.person_height_m;
  model.person_spacing_m = f.person_spacing_m;
  const placement::PlacementScene placement_scene =
      placement::BuildPlacementScene(scene, intrinsics, model);

  placement::ObjectiveOptions objective;
  objective.min_views = min_views;
  objective.coverage_weight = f.coverage_weight;
  placement::OptimiserOptions options;
  options.cameras = f.cameras;
  options.seed = f.seed;
  options.global_evaluations = f.budget;
  options.local_evaluations = f.local_budget;
  options.threads = f.threads;
  options.sigma0 = f.sigma;

  if (!f.quiet) {
    std::fprintf(stderr,
                 "place: %s, %d x %d x %d voxels, %zu sample people, %zu mounting surfaces, "
                 "%d cameras, K = %d, seed %llu\n",
                 placement_scene.name.c_str(), placement_scene.grid.nx, placement_scene.grid.ny,
                 placement_scene.grid.nz, placement_scene.samples.size(),
                 placement_scene.surfaces.size(), f.cameras, min_views,
                 static_cast<unsigned long long>(f.seed));
  }
  auto printer = std::make_shared<ProgressPrinter>(!f.quiet);
  const placement::PlacementResult result =
      placement::OptimisePlacement(placement_scene, objective, options,
                                   [printer](const placement::Progress& p) { (*printer)(p); });
  printer.reset();

  geometry::WriteCamerasFile(f.out, result.cameras);

  const double total_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t_begin).count();
  placement::RunInfo run;
  run.command = CommandLine(f, min_views);
  run.cameras_file = f.out;
  run.cameras = f.cameras;
  run.seed = f.seed;
  run.threads = f.threads;
  run.objective = objective;
  run.global_evaluations = result.global_evaluations;
  run.local_evaluations = result.local_evaluations;
  run.global_seconds = result.global_seconds;
  run.local_seconds = result.local_seconds;
  run.total_seconds = total_s;
  std::vector<placement::LayoutReport> layouts(2);
  layouts[0].key = "optimised";
  layouts[0].title = "optimised";
  layouts[0].placements = result.placements;
  layouts[1].key = "corner";
  layouts[1].title = "corner heuristic";
  layouts[1].placements = placement::CornerHeuristic(placement_scene, f.cameras);
  placement::Evaluator evaluator(placement_scene, objective, f.threads);
  const placement::CoverageMetrics corner =
      evaluator.Evaluate(placement::CamerasOf(placement_scene, layouts[1].placements));
  const auto t_report = std::chrono::steady_clock::now();
  placement::WriteReport(f.report, placement_scene, &evaluator, run, layouts);
  if (!f.quiet) {
    std::fprintf(
        stderr, "place: report written in %.1f s\n",
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t_report).count());
  }

  const placement::CoverageMetrics& m = result.metrics;
  std::printf(
      "hullguard place: %s, %d cameras, K = %d: score %.4f (corner heuristic %.4f)\n"
      "  certified free with a person %.1f %% (corner %.1f %%), seen by >= %d cameras %.1f %% "
      "(corner %.1f %%)\n"
      "  %lld + %lld evaluations, %.1f s -> %s, report in %s\n",
      placement_scene.name.c_str(), f.cameras, min_views, m.score, corner.score,
      100.0 * m.mean_free_fraction, 100.0 * corner.mean_free_fraction, min_views,
      100.0 * m.k_coverage, 100.0 * corner.k_coverage, result.global_evaluations,
      result.local_evaluations, total_s, f.out.c_str(), f.report.c_str());
  return kExitOk;
}

}  // namespace

void RegisterPlace(CLI::App& app, int* exit_code) {
  auto flags = std::make_shared<PlaceFlags>();
  CLI::App* cmd = app.add_subcommand(
      "place", "Optimise where to mount cameras so that the most space is certified free");
  cmd->add_option("--scene", flags->scene, "Scene YAML with optional `mounting:` (docs/scenes.md)")
      ->required();
  cmd->add_option("--cameras", flags->cameras, "Number of cameras to place")->required();
  CLI::Option* min_views =
      cmd->add_option("--min-views", flags->min_views,
                      "K of the K-coverage term (default: 2, or 1 for one camera)");
  cmd->add_option("--seed", flags->seed, "Seed of the search; same seed, same cameras file");
  cmd->add_option("--budget", flags->budget,
                  "Objective evaluations of the global search (default, or 0: 2000 + 1000 per "
                  "camera)")
      ->check(hg::cli::Range(0, 100'000'000));
  cmd->add_option("--local-budget", flags->local_budget,
                  "Objective evaluations of the local refinement (default, or 0: 150 per camera)")
      ->check(hg::cli::Range(0, 100'000'000));
  cmd->add_option("--intrinsics", flags->intrinsics,
                  "Camera intrinsics: a cameras file (first camera) or width/height/K; default: "
                  "the scene's first camera");
  cmd->add_option("--voxel", flags->voxel_m, "Voxel edge of the objective (m)")
      ->check(hg::cli::kFinite);
  cmd->add_option("--render-width", flags->render_width,
                  "Width of the reduced image on which visibility is decided (pixels)");
  cmd->add_option("--person-radius", flags->person_radius_m, "Sample person capsule radius (m)")
      ->check(hg::cli::kFinite);
  cmd->add_option("--person-height", flags->person_height_m, "Sample person height (m)")
      ->check(hg::cli::kFinite);
  cmd->add_option("--person-spacing", flags->person_spacing_m,
                  "Spacing of the sample person grid (m)")
      ->check(hg::cli::kFinite);
  cmd->add_option("--coverage-weight", flags->coverage_weight,
                  "Weight of the K-coverage share in the score")
      ->check(hg::cli::kNonNegative);
  cmd->add_option("--sigma", flags->sigma,
                  "Initial CMA-ES step, as a share of each variable's range")
      ->check(hg::cli::kFinite);
  cmd->add_option("--threads", flags->threads, "Evaluation threads (results do not depend on it)")
      ->check(hg::cli::Range(1, 64));
  cmd->add_option("--out", flags->out, "Camera block to write (daemon config format)")->required();
  cmd->add_option("--report", flags->report, "Report directory (report.md, report.json, PNGs)")
      ->required();
  cmd->add_flag("--quiet", flags->quiet, "No progress on stderr");
  cmd->callback([flags, exit_code, min_views] {
    flags->min_views_given = min_views->count() > 0;
    *exit_code = RunPlace(*flags);
  });
}

}  // namespace hg::tools
