// `hullguard demo`: the simulator's demo cell, animated and carved frame by
// frame; writes pictures, the last frame's masks and a summary.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "common/cli_checks.h"
#include "geometry/camera_yaml.h"
#include "hullguard/carve.h"
#include "hullguard/commands.h"
#include "hullguard/frame_stats.h"
#include "hullguard/scene_engine.h"
#include "octree/ply.h"
#include "silhouette/mask_io.h"
#include "sim/scene.h"

#ifndef HG_DEFAULT_SCENE
#define HG_DEFAULT_SCENE "config/scenes/demo_cell.yaml"
#endif
#ifndef HG_BUILD_TOOLS_DIR
#define HG_BUILD_TOOLS_DIR ""
#endif
#ifndef HG_INSTALLED_SCENE
#define HG_INSTALLED_SCENE "/usr/share/hullguard/scenes/demo_cell.yaml"
#endif

namespace hg::tools {
namespace {

namespace fs = std::filesystem;

/// The demo cell: the source tree's for the tool in its build tree; for an
/// installed tool the one installed beside it (<prefix>/share/hullguard,
/// wherever the prefix was moved), else the one of the configured prefix;
/// the source tree's as the last resort.
std::string DefaultScene() {
  std::error_code ec;
  const fs::path exe = fs::canonical("/proc/self/exe", ec);
  const fs::path build_dir = fs::weakly_canonical(HG_BUILD_TOOLS_DIR, ec);
  const bool in_build_tree = !exe.empty() && exe.parent_path() == build_dir;
  if (!in_build_tree) {
    const fs::path beside =
        exe.parent_path().parent_path() / "share/hullguard/scenes/demo_cell.yaml";
    if (!exe.empty() && fs::is_regular_file(beside, ec)) return beside.string();
    if (fs::is_regular_file(HG_INSTALLED_SCENE, ec)) return HG_INSTALLED_SCENE;
  }
  return HG_DEFAULT_SCENE;
}

struct DemoFlags {
  std::string scene = DefaultScene();
  std::string out = "hullguard-demo";
  int frames = 90;
  int every = 15;
  double start_s = 0.0;
  int depth = 9;
  int threads = 2;
};

/// The cameras' colour frames, people outlined by their ground-truth masks, in a grid.
void WriteCameraMosaic(SceneEngine& engine, double t_s, std::uint64_t frame,
                       const std::string& path) {
  std::vector<common::ImageRgb8> colour;
  engine.simulator().RenderColour(t_s, frame, &colour);
  const int n = static_cast<int>(colour.size());
  const int cols = n <= 4 ? 2 : 4;
  const int rows = (n + cols - 1) / cols;
  const int tile_w = 480;
  const int tile_h = tile_w * colour[0].height / colour[0].width;
  cv::Mat mosaic(rows * tile_h, cols * tile_w, CV_8UC3, cv::Scalar(0, 0, 0));
  for (int c = 0; c < n; ++c) {
    const common::ImageRgb8& img = colour[c];
    cv::Mat rgb(img.height, img.width, CV_8UC3, const_cast<std::uint8_t*>(img.pixels.data()));
    cv::Mat bgr;
    cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
    const common::ImageU8& m = engine.masks()[c];
    cv::Mat mask(m.height, m.width, CV_8UC1, const_cast<std::uint8_t*>(m.pixels.data()));
    std::vector<std::vector<cv::Point>> contours;
    cv::findContours(mask.clone(), contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_SIMPLE);
    cv::drawContours(bgr, contours, -1, cv::Scalar(0, 0, 255), 3);
    cv::Mat tile;
    cv::resize(bgr, tile, cv::Size(tile_w, tile_h), 0, 0, cv::INTER_AREA);
    cv::putText(tile, engine.scene().cameras[c].model.name, cv::Point(8, 22),
                cv::FONT_HERSHEY_SIMPLEX, 0.6, cv::Scalar(255, 255, 255), 2);
    tile.copyTo(mosaic(cv::Rect((c % cols) * tile_w, (c / cols) * tile_h, tile_w, tile_h)));
  }
  cv::imwrite(path, mosaic);
}

int RunDemo(const DemoFlags& f) {
  sim::Scene scene = sim::LoadScene(f.scene);
  const fs::path out(f.out);
  fs::create_directories(out / "frames");
  const double dt = 1.0 / scene.rate_hz;
  SceneEngine engine(std::move(scene), {f.depth, f.threads});
  const sim::Scene& s = engine.scene();
  const std::vector<geometry::TriangleMesh> obstacles = s.ObstacleMeshes();

  std::vector<double> octree_ms, quadtree_ms, render_ms;
  TruthCheck truth;
  double t = f.start_s;
  for (int frame = 0; frame < f.frames; ++frame) {
    t = f.start_s + frame * dt;
    const FrameTimes times = engine.Step(t);
    render_ms.push_back(times.render_ms);
    quadtree_ms.push_back(times.quadtree_ms);
    octree_ms.push_back(times.octree.update_ms);
    const TruthCheck check =
        CheckTruth(engine.tree(), SampleTruthPoints(s, t, 1000, static_cast<std::uint64_t>(frame)));
    truth.points += check.points;
    truth.reported_free += check.reported_free;
    if (frame % f.every == 0 || frame + 1 == f.frames) {
      char name[64];
      std::snprintf(name, sizeof(name), "snapshot_%04d.png", frame);
      WriteSnapshot(engine.tree(), s.CameraModels(), obstacles, (out / "frames" / name).string());
    }
  }
  const octree::Octree& tree = engine.tree();
  const std::string picture = (out / "snapshot.png").string();
  WriteSnapshot(tree, s.CameraModels(), obstacles, picture);
  WriteCameraMosaic(engine, t, static_cast<std::uint64_t>(f.frames - 1),
                    (out / "cameras.png").string());
  octree::WriteOccupiedPly(tree, (out / "hull.ply").string());
  for (std::size_t c = 0; c < s.cameras.size(); ++c) {
    silhouette::WriteGreyImage((out / ("mask_" + s.cameras[c].model.name + ".png")).string(),
                               engine.masks()[c]);
  }
  geometry::WriteCamerasFile((out / "cameras.yaml").string(), s.CameraModels());
  geometry::TriangleMesh all_obstacles;
  for (const auto& m : obstacles) all_obstacles.Append(m);
  geometry::WriteObj((out / "obstacles.obj").string(), all_obstacles);

  auto median = [](const std::vector<double>& v) { return Summarise(v).median; };
  const double first_ms = octree_ms.front();
  octree_ms.erase(octree_ms.begin());
  const common::Box3& b = s.bounds;
  char summary[2048];
  std::snprintf(
      summary, sizeof(summary),
      "hullguard demo: scene %s, %zu cameras %dx%d, %zu people, %d frames (%.1f s), depth %d "
      "(%d^3 cells), %d threads\n"
      "  scene file %s\n"
      "  bounds %.2f %.2f %.2f .. %.2f %.2f %.2f\n"
      "  last frame: occupied %.4f m^3, occluded %.4f m^3, free %.4f m^3; %lld leaves, %lld "
      "nodes\n"
      "  median per frame: render %.1f ms, quadtrees %.1f ms, octree %.1f ms (first frame %.1f "
      "ms)\n"
      "  ground truth: %lld points sampled inside people, %lld reported free\n"
      "  wrote snapshot.png, cameras.png, frames/, hull.ply, masks, cameras.yaml, obstacles.obj "
      "in %s\n",
      s.name.c_str(), s.cameras.size(), s.cameras[0].model.width, s.cameras[0].model.height,
      s.people.size(), f.frames, f.frames * dt, f.depth, 1 << f.depth, f.threads, f.scene.c_str(),
      b.min.x(), b.min.y(), b.min.z(), b.max.x(), b.max.y(), b.max.z(),
      tree.Volume(octree::LeafState::kOccupied), tree.Volume(octree::LeafState::kOccluded),
      tree.Volume(octree::LeafState::kFree), static_cast<long long>(tree.NumLeaves()),
      static_cast<long long>(tree.NumNodes()), median(render_ms), median(quadtree_ms),
      octree_ms.empty() ? first_ms : median(octree_ms), first_ms,
      static_cast<long long>(truth.points), static_cast<long long>(truth.reported_free),
      f.out.c_str());
  std::fputs(summary, stdout);
  std::ofstream((out / "summary.txt").string()) << summary;
  return truth.reported_free == 0 ? kExitOk : kExitFailure;
}

}  // namespace

void RegisterDemo(CLI::App& app, int* exit_code) {
  auto flags = std::make_shared<DemoFlags>();
  CLI::App* cmd =
      app.add_subcommand("demo", "Animate a simulated cell, carve every frame, write pictures");
  cmd->add_option("--scene", flags->scene, "Scene YAML")->capture_default_str();
  cmd->add_option("--out", flags->out, "Output directory")->capture_default_str();
  cmd->add_option("--frames", flags->frames, "Frames to simulate")
      ->check(hg::cli::Range(1, 100000));
  cmd->add_option("--every", flags->every, "Write a snapshot every N frames")
      ->check(hg::cli::Range(1, 100000));
  cmd->add_option("--start", flags->start_s, "Scene time of the first frame (s)")
      ->check(hg::cli::kFinite);
  cmd->add_option("--depth", flags->depth, "Octree depth")->check(hg::cli::Range(3, 12));
  cmd->add_option("--threads", flags->threads, "Worker threads")->check(hg::cli::Range(1, 64));
  cmd->callback([flags, exit_code] { *exit_code = RunDemo(*flags); });
}

}  // namespace hg::tools
