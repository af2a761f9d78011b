// `hullguard bench`: the engine on a simulated scene, frame by frame, with
// per-stage timings, and optionally a dense per-voxel carve as the baseline.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <functional>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "common/cli_checks.h"
#include "common/config_error.h"
#include "common/json.h"
#include "hullguard/commands.h"
#include "hullguard/dense_baseline.h"
#include "hullguard/frame_stats.h"
#ifdef HG_WITH_OPEN3D
#include "hullguard/open3d_baseline.h"
#endif
#include "hullguard/scene_engine.h"
#include "octree/leaf_diff.h"
#include "pipeline/snapshot.h"
#include "sim/scene.h"

namespace hg::tools {
namespace {

struct BenchFlags {
  std::string scene;
  int frames = 60;
  double start_s = 0.0;
  int threads = 2;
  int depth = 10;
  int boundary_coarsening = octree::OctreeConfig{}.boundary_coarsening;
  int coarse_first_depth = 0;
  int key_level = 0;
  int settle_level = 0;
  double max_speed_mps = 0.0;
  bool stamp_at_median = false;
  double deadline_ms = 0.0;
  std::string baseline;
  int truth_points = 2000;
  int cameras = 0;
  bool leaf_changes = false;
  bool json = false;
};

std::string JsonSummary(const FrameStats& s) {
  char buf[128];
  std::snprintf(buf, sizeof(buf), "{\"median_ms\": %.3f, \"p99_ms\": %.3f, \"max_ms\": %.3f}",
                s.median, s.p99, s.max);
  return buf;
}

struct BaselineSpec {
  std::string kind;  ///< "dense" or "open3d"; empty: none.
  int resolution = 0;
};

BaselineSpec ParseBaseline(const std::string& spec) {
  if (spec.empty()) return {};
  const auto colon = spec.find(':');
  BaselineSpec out;
  out.kind = spec.substr(0, colon);
  if (colon == std::string::npos || (out.kind != "dense" && out.kind != "open3d")) {
    throw common::ConfigError("--baseline: expected dense:R or open3d:R (e.g. dense:256), got '" +
                              spec + "'");
  }
  try {
    std::size_t used = 0;
    out.resolution = std::stoi(spec.substr(colon + 1), &used);
    if (used != spec.size() - colon - 1) out.resolution = 0;
  } catch (const std::exception&) {
    out.resolution = 0;
  }
  if (out.resolution < 8 || out.resolution > 1024) {
    throw common::ConfigError("--baseline: R must be an integer in 8..1024, got '" + spec + "'");
  }
#ifndef HG_WITH_OPEN3D
  if (out.kind == "open3d") {
    throw common::ConfigError(
        "--baseline open3d:R: this hullguard was built without Open3D (configure with "
        "-DHG_WITH_OPEN3D=ON, needs libopen3d-dev)");
  }
#endif
  return out;
}

int RunBench(const BenchFlags& f) {
  const BaselineSpec baseline = ParseBaseline(f.baseline);
  const int dense_res = baseline.resolution;
  sim::Scene scene = sim::LoadScene(f.scene);
  if (f.cameras > static_cast<int>(scene.cameras.size())) {
    throw common::ConfigError("--cameras " + std::to_string(f.cameras) + ": scene " + f.scene +
                              " has only " + std::to_string(scene.cameras.size()) + " cameras");
  }
  if (f.cameras > 0) scene.cameras.resize(static_cast<std::size_t>(f.cameras));
  if (scene.cameras.empty()) {
    throw common::ConfigError(f.scene + ": the scene has no cameras: nothing to benchmark");
  }
  const double dt = 1.0 / scene.rate_hz;
  SceneEngine engine(std::move(scene),
                     {f.depth, f.threads, f.boundary_coarsening, f.coarse_first_depth, f.key_level,
                      f.settle_level, f.max_speed_mps, f.stamp_at_median});
  const sim::Scene& s = engine.scene();

  // The baseline carves the same undistorted masks and answers point queries.
  std::optional<DenseCarver> dense_carver;
  std::optional<common::WorkerPool> dense_pool;
  std::function<void(const std::vector<const common::ImageU8*>&)> baseline_carve;
  std::function<bool(const Eigen::Vector3d&)> baseline_occupied;
  if (baseline.kind == "dense") {
    dense_carver.emplace(s.bounds, dense_res, engine.pinholes());
    dense_pool.emplace(f.threads);
    baseline_carve = [&](const auto& masks) { dense_carver->Carve(masks, *dense_pool); };
    baseline_occupied = [&](const Eigen::Vector3d& p) { return dense_carver->Occupied(p); };
  }
#ifdef HG_WITH_OPEN3D
  std::optional<Open3dCarver> open3d_carver;
  if (baseline.kind == "open3d") {
    open3d_carver.emplace(s.bounds, dense_res, engine.pinholes());
    baseline_carve = [&](const auto& masks) { open3d_carver->Carve(masks); };
    baseline_occupied = [&](const Eigen::Vector3d& p) { return open3d_carver->Occupied(p); };
  }
#endif
  const bool has_baseline = static_cast<bool>(baseline_carve);

  std::vector<double> render_ms, quadtree_ms, octree_ms, dense_ms, visited, verdicts;
  // With --leaf-changes: per incremental frame, the leaves the update wrote.
  std::vector<double> written;
  std::vector<std::uint64_t> leaf_keys;
  std::vector<double> occupied_m3;    // With a deadline: what an abort leaves occupied.
  std::vector<double> key_roots;      // With a deadline and a key level: roots refined to it.
  std::vector<double> refined_level;  // With a deadline: how far each update refined.
  // Per level: when the incremental updates that got there were complete to it.
  std::vector<double> level_done_ms[octree::UpdateStats::kLevels];
  double first_octree_ms = 0.0;
  int aborts = 0;
  std::int64_t unsplit = 0;  // Nodes left occupied for want of node storage, all frames.
  TruthCheck truth;
  std::int64_t dense_carved = 0, dense_points = 0;
  std::vector<const common::ImageU8*> pinhole_masks(s.cameras.size());
  for (int frame = 0; frame < f.frames; ++frame) {
    const double t = f.start_s + frame * dt;
    // The deadline counts from the start of the octree update, not of the
    // frame (rendering and quadtrees are not the octree's budget).
    const FrameTimes times = engine.Step(t, {}, f.deadline_ms);
    if (f.leaf_changes) {
      std::vector<std::uint64_t> keys = octree::LeafKeys(engine.tree());
      if (frame > 0) {
        written.push_back(static_cast<double>(octree::CountNewLeaves(leaf_keys, keys)));
      }
      leaf_keys = std::move(keys);
    }
    render_ms.push_back(times.render_ms);
    quadtree_ms.push_back(times.quadtree_ms);
    aborts += times.octree.aborted;
    unsplit += times.octree.nodes_unsplit;
    // Frame 0 builds the tree from nothing; the others are incremental.
    if (frame == 0) {
      first_octree_ms = times.octree.update_ms;
    } else {
      octree_ms.push_back(times.octree.update_ms);
      visited.push_back(static_cast<double>(times.octree.nodes_visited));
      verdicts.push_back(static_cast<double>(times.octree.verdicts_computed));
      for (int level = 0; level < octree::UpdateStats::kLevels; ++level) {
        if (times.octree.level_done_ms[level] >= 0.0) {
          level_done_ms[level].push_back(times.octree.level_done_ms[level]);
        }
      }
      if (f.deadline_ms > 0) {
        occupied_m3.push_back(engine.tree().Volume(octree::LeafState::kOccupied));
        refined_level.push_back(times.octree.refined_level);
        if (f.key_level > 0) {
          const auto levels = engine.tree().RootLevels();
          key_roots.push_back(static_cast<double>(std::count_if(
              levels.begin(), levels.end(), [&](std::uint8_t l) { return l >= f.key_level; })));
        }
      }
    }
    const std::vector<Eigen::Vector3d> points = SampleTruthPoints(
        s, t, f.truth_points, 1000 + static_cast<std::uint64_t>(frame),
        f.max_speed_mps > 0.0 ? std::optional(StampOffset(s, f.stamp_at_median)) : std::nullopt);
    const TruthCheck check = CheckTruth(engine.tree(), points);
    truth.points += check.points;
    truth.reported_free += check.reported_free;
    if (has_baseline) {
      for (std::size_t c = 0; c < s.cameras.size(); ++c) {
        pinhole_masks[c] = &engine.PinholeMask(static_cast<int>(c));
      }
      const auto t0 = std::chrono::steady_clock::now();
      baseline_carve(pinhole_masks);
      dense_ms.push_back(
          std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
      for (const Eigen::Vector3d& p : points) {
        if (!s.bounds.Contains(p)) continue;
        ++dense_points;
        dense_carved += !baseline_occupied(p);
      }
    }
  }

  // The levels the coarse-first passes completed at: frames, and when.
  struct PassSummary {
    int level;
    std::size_t frames;
    FrameStats done;
  };
  std::vector<PassSummary> passes;
  for (int level = 0; level < octree::UpdateStats::kLevels; ++level) {
    if (!level_done_ms[level].empty()) {
      passes.push_back({level, level_done_ms[level].size(), Summarise(level_done_ms[level])});
    }
  }
  const FrameStats render = Summarise(render_ms), quad = Summarise(quadtree_ms),
                   oct = Summarise(octree_ms), dense_sum = Summarise(dense_ms);
  const octree::Octree& tree = engine.tree();
  const auto& cam0 = s.cameras.front().model;
  const double ratio = oct.median > 0 ? dense_sum.median / oct.median : 0.0;
  if (f.json) {
    std::printf(
        "{\"scene\": %s, \"cameras\": %zu, \"width\": %d, \"height\": %d, \"frames\": %d, "
        "\"depth\": %d, \"threads\": %d, \"deadline_ms\": %.3f,\n \"stages\": {\"render\": %s, "
        "\"quadtree\": %s, \"octree\": %s},\n \"octree_first_frame_ms\": %.3f, \"nodes\": %lld, "
        "\"leaves\": %lld, \"visited_per_frame_median\": %.0f, "
        "\"verdicts_per_frame_median\": %.0f, \"aborts\": %d, "
        "\"unsplit_nodes\": %lld, \"truth_points\": %lld, \"truth_points_free\": %lld",
        common::JsonString(s.name).c_str(), s.cameras.size(), cam0.width, cam0.height, f.frames,
        f.depth, f.threads, f.deadline_ms, JsonSummary(render).c_str(), JsonSummary(quad).c_str(),
        JsonSummary(oct).c_str(), first_octree_ms, static_cast<long long>(tree.NumNodes()),
        static_cast<long long>(tree.NumLeaves()), Summarise(visited).median,
        Summarise(verdicts).median, aborts, static_cast<long long>(unsplit),
        static_cast<long long>(truth.points), static_cast<long long>(truth.reported_free));
    if (!occupied_m3.empty()) {
      const FrameStats v = Summarise(occupied_m3);
      std::printf(", \"occupied_m3\": {\"median\": %.4f, \"p99\": %.4f, \"max\": %.4f}", v.median,
                  v.p99, v.max);
      // Lowest first: the worst refinement is what a controller must live with.
      const FrameStats r = Summarise(refined_level);
      std::printf(", \"refined_level\": {\"median\": %.0f, \"min\": %.0f}", r.median,
                  *std::min_element(refined_level.begin(), refined_level.end()));
      if (!key_roots.empty()) {
        std::printf(", \"roots_at_key_level\": {\"median\": %.0f, \"min\": %.0f}",
                    Summarise(key_roots).median,
                    *std::min_element(key_roots.begin(), key_roots.end()));
      }
    }
    if (!written.empty()) {
      std::printf(", \"leaves_written_per_frame_median\": %.0f", Summarise(written).median);
    }
    if (f.coarse_first_depth > 0) {
      std::printf(",\n \"passes\": [");
      const char* sep = "";
      for (const PassSummary& pass : passes) {
        std::printf("%s{\"level\": %d, \"frames\": %zu, \"median_ms\": %.3f, \"p99_ms\": %.3f}",
                    sep, pass.level, pass.frames, pass.done.median, pass.done.p99);
        sep = ", ";
      }
      std::printf("]");
    }
    if (has_baseline) {
      std::printf(
          ",\n \"baseline\": {\"kind\": \"%s\", \"resolution\": %d, \"time\": %s, "
          "\"ratio_to_octree_median\": %.3f, \"truth_points\": %lld, "
          "\"truth_points_carved\": %lld}",
          baseline.kind.c_str(), dense_res, JsonSummary(dense_sum).c_str(), ratio,
          static_cast<long long>(dense_points), static_cast<long long>(dense_carved));
    }
    std::printf("}\n");
  } else {
    std::printf(
        "hullguard bench: scene %s, %zu cameras %dx%d, %d frames at %.1f Hz, depth %d (%d^3), "
        "%d threads\n",
        s.name.c_str(), s.cameras.size(), cam0.width, cam0.height, f.frames, s.rate_hz, f.depth,
        1 << f.depth, f.threads);
    std::printf("  %-34s %9s %9s %9s\n", "stage (ms per frame)", "median", "p99", "max");
    auto row = [](const char* name, const FrameStats& x) {
      std::printf("  %-34s %9.2f %9.2f %9.2f\n", name, x.median, x.p99, x.max);
    };
    row("render masks (simulator)", render);
    row("mask -> quadtree (all cameras)", quad);
    row("octree update (incremental)", oct);
    std::printf("  octree first frame (from scratch): %.2f ms\n", first_octree_ms);
    std::printf(
        "  nodes %lld, leaves %lld (last frame); visited per frame (median) %.0f; "
        "aborts %d of %d frames\n",
        static_cast<long long>(tree.NumNodes()), static_cast<long long>(tree.NumLeaves()),
        Summarise(visited).median, aborts, f.frames);
    if (!written.empty()) {
      // The floor of any incremental update: what it had to write.
      const double median_written = Summarise(written).median;
      std::printf(
          "  leaves written per frame (new cell or state; median) %.0f; visited per leaf "
          "written %.2f\n",
          median_written, median_written > 0 ? Summarise(visited).median / median_written : 0.0);
    }
    if (unsplit > 0) {
      std::printf("  node store full: %lld nodes left unsplit (occupied) over the run\n",
                  static_cast<long long>(unsplit));
    }
    if (!occupied_m3.empty()) {
      const FrameStats v = Summarise(occupied_m3);
      std::printf("  occupied volume after the deadline (m^3): median %.3f, p99 %.3f, max %.3f\n",
                  v.median, v.p99, v.max);
      const FrameStats r = Summarise(refined_level);
      const double worst = *std::min_element(refined_level.begin(), refined_level.end());
      std::printf(
          "  refined to level (%d: complete): median %.0f (%.1f cm cells), worst %.0f (%.1f cm)\n",
          f.depth, r.median,
          100.0 * pipeline::RefinedCellSize(s.bounds, static_cast<int>(r.median)), worst,
          100.0 * pipeline::RefinedCellSize(s.bounds, static_cast<int>(worst)));
      if (!key_roots.empty()) {
        // Octree::RootLevels: an aborted pass finishes some roots.
        std::printf("  roots refined to the key level %d: median %.0f of %d, fewest %.0f\n",
                    f.key_level, Summarise(key_roots).median, octree::Octree::kNumRoots,
                    *std::min_element(key_roots.begin(), key_roots.end()));
      }
    }
    if (f.coarse_first_depth > 0) {
      // What a deadline must allow for each level: the passes' completion times.
      std::printf("  coarse-first passes (incremental frames complete to a level, when):\n");
      for (const PassSummary& pass : passes) {
        std::printf(
            "    level %2d (%5.1f cm cells): %zu of %zu frames, at median %.2f ms, p99 %.2f ms\n",
            pass.level, 100.0 * pipeline::RefinedCellSize(s.bounds, pass.level), pass.frames,
            octree_ms.size(), pass.done.median, pass.done.p99);
      }
    }
    std::printf("  ground truth: %lld points inside people, %lld reported free\n",
                static_cast<long long>(truth.points), static_cast<long long>(truth.reported_free));
    if (has_baseline) {
      row((baseline.kind + " " + std::to_string(dense_res) + "^3 carve").c_str(), dense_sum);
      std::printf(
          "  %s/octree median ratio %.2f; the %s carve wrongly frees %lld of %lld "
          "ground-truth points\n",
          baseline.kind.c_str(), ratio, baseline.kind.c_str(), static_cast<long long>(dense_carved),
          static_cast<long long>(dense_points));
    }
  }
  return truth.reported_free == 0 ? kExitOk : kExitFailure;
}

}  // namespace

void RegisterBench(CLI::App& app, int* exit_code) {
  auto flags = std::make_shared<BenchFlags>();
  CLI::App* cmd =
      app.add_subcommand("bench", "Time the engine on a simulated scene, frame by frame");
  cmd->add_option("--scene", flags->scene, "Scene YAML (docs/scenes.md)")->required();
  cmd->add_option("--frames", flags->frames, "Frames to run")->check(hg::cli::Range(2, 100000));
  cmd->add_option("--start", flags->start_s, "Scene time of the first frame (s)")
      ->check(hg::cli::kFinite);
  cmd->add_option("--cameras", flags->cameras, "Use only the scene's first N cameras")
      ->check(hg::cli::Range(1, 16));
  cmd->add_option("--threads", flags->threads, "Worker threads")->check(hg::cli::Range(1, 64));
  cmd->add_option("--depth", flags->depth, "Octree depth")->check(hg::cli::Range(3, 16));
  cmd->add_option("--boundary-coarsening", flags->boundary_coarsening,
                  "Levels above --depth at which static view and obstacle edges stop")
      ->check(hg::cli::Range(0, 16));
  cmd->add_option("--settle-level", flags->settle_level,
                  "Stop refining a cell of this level once a leaf in it reads occupied (the "
                  "daemon's publish_depth; 0: off; see octree::OctreeConfig::settle_level)")
      ->check(hg::cli::Range(0, 19));
  cmd->add_option("--max-speed", flags->max_speed_mps,
                  "Compensate the scene's capture offsets as the daemon does for people up to "
                  "this fast (m/s; motion.max_speed_mps): the tree then holds the people as "
                  "they were at the latest capture, and is checked against that. 0: off")
      ->check(hg::cli::Range(0.0, 100.0));
  cmd->add_flag("--stamp-at-median", flags->stamp_at_median,
                "With --max-speed: hold the people as they were at the median capture offset "
                "instead of the latest (motion.stamp_at_median)");
  cmd->add_option("--key-level", flags->key_level,
                  "With --coarse-first: a pass also stops at this level (the daemon uses its "
                  "tracking voxel's level; docs/reconstruction.md)")
      ->check(hg::cli::Range(0, 16));
  cmd->add_option("--coarse-first", flags->coarse_first_depth,
                  "Bring each update up to date down to this level first, then refine "
                  "(0: off; see octree.coarse_first_depth in docs/configuration.md)")
      ->check(hg::cli::Range(0, 16));
  cmd->add_option("--deadline-ms", flags->deadline_ms,
                  "Abort each octree update this long after it starts (0: no deadline)")
      ->check(hg::cli::kNonNegative)
      ->check(hg::cli::kFinite);
  cmd->add_option("--baseline", flags->baseline,
                  "dense:R also times a dense per-voxel carve at R^3 on the same frames; "
                  "open3d:R Open3D's VoxelGrid::CarveSilhouette (builds with HG_WITH_OPEN3D)");
  cmd->add_option("--truth-points", flags->truth_points,
                  "Points sampled inside each person per frame for the ground-truth check")
      ->check(hg::cli::Range(0, 1000000));
  cmd->add_flag("--leaf-changes", flags->leaf_changes,
                "Also count the leaves each incremental update wrote (a new cell or state: "
                "the least any incremental update must do); slow, outside the timings");
  cmd->add_flag("--json", flags->json, "Print one JSON object");
  cmd->callback([flags, exit_code] { *exit_code = RunBench(*flags); });
}

}  // namespace hg::tools
