// `hullguard demo`: carve the built-in demo cell and write a picture and a summary.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>

#include "geometry/camera_yaml.h"
#include "hullguard/carve.h"
#include "hullguard/commands.h"
#include "octree/ply.h"
#include "scene/demo_cell.h"
#include "scene/exact_mask.h"
#include "silhouette/mask_io.h"

namespace hg::tools {
namespace {

struct DemoFlags {
  std::string out = "hullguard-demo";
  int cameras = 4;
  int people = 2;
  int depth = 9;
  int threads = 2;
  int width = 1920;
  int height = 1080;
  double time_s = 1.0;
};

int RunDemo(const DemoFlags& f) {
  namespace fs = std::filesystem;
  fs::create_directories(f.out);
  scene::DemoCellOptions opt;
  opt.num_cameras = f.cameras;
  opt.width = f.width;
  opt.height = f.height;
  opt.num_people = f.people;
  const scene::DemoCell cell = scene::MakeDemoCell(opt);
  const std::vector<scene::Shape> people = scene::DemoPeople(f.people, f.time_s);

  CarveJob job;
  job.cameras = cell.cameras;
  job.bounds = cell.bounds;
  job.depth = f.depth;
  job.threads = f.threads;
  job.obstacles = cell.obstacles;
  std::vector<std::string> mask_files;
  for (const auto& cam : cell.cameras) {
    job.masks.push_back(scene::RenderExactMask(cam, people));
    mask_files.push_back((fs::path(f.out) / ("mask_" + cam.name + ".png")).string());
    silhouette::WriteGreyImage(mask_files.back(), job.masks.back());
  }
  geometry::WriteCamerasFile((fs::path(f.out) / "cameras.yaml").string(), cell.cameras);
  geometry::TriangleMesh all_obstacles;
  for (const auto& m : cell.obstacles) all_obstacles.Append(m);
  geometry::WriteObj((fs::path(f.out) / "obstacles.obj").string(), all_obstacles);

  const CarveResult r = Carve(job);
  const octree::Octree& tree = *r.tree;
  octree::WriteOccupiedPly(tree, (fs::path(f.out) / "hull.ply").string());
  const std::string picture = (fs::path(f.out) / "snapshot.png").string();
  WriteSnapshot(tree, cell.cameras, cell.obstacles, picture);

  // Ground truth check: no point of any person may be reported free.
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  int sampled = 0, reported_free = 0;
  for (const auto& shape : people) {
    for (int i = 0; i < 2000; ++i, ++sampled) {
      const Eigen::Vector3d p = scene::SampleInside(shape, [&] { return u01(rng); });
      reported_free += tree.StateAt(p) == octree::PointState::kFree;
    }
  }
  double people_volume = 0.0;
  for (const auto& s : people) people_volume += scene::Volume(s);
  char summary[1024];
  std::snprintf(summary, sizeof(summary),
                "hullguard demo: %d cameras %dx%d, %d people, depth %d (%d^3 cells), %d threads\n"
                "  occupied %.4f m^3 (people %.4f m^3), occluded %.4f m^3, free %.4f m^3\n"
                "  %lld leaves, %lld nodes; quadtrees %.2f ms, octree %.2f ms\n"
                "  ground truth: %d points sampled inside people, %d reported free\n"
                "  wrote %s, hull.ply, masks and cameras.yaml in %s\n",
                f.cameras, f.width, f.height, f.people, f.depth, 1 << f.depth, f.threads,
                tree.Volume(octree::LeafState::kOccupied), people_volume,
                tree.Volume(octree::LeafState::kOccluded), tree.Volume(octree::LeafState::kFree),
                static_cast<long long>(tree.NumLeaves()), static_cast<long long>(tree.NumNodes()),
                r.quadtree_ms, r.stats.update_ms, sampled, reported_free, picture.c_str(),
                f.out.c_str());
  std::fputs(summary, stdout);
  std::ofstream((fs::path(f.out) / "summary.txt").string()) << summary;
  return reported_free == 0 ? kExitOk : kExitFailure;
}

}  // namespace

void RegisterDemo(CLI::App& app, int* exit_code) {
  auto flags = std::make_shared<DemoFlags>();
  CLI::App* cmd = app.add_subcommand("demo", "Carve the built-in demo cell; write a picture");
  cmd->add_option("--out", flags->out, "Output directory");
  cmd->add_option("--cameras", flags->cameras, "Cameras (1..8)")->check(CLI::Range(1, 8));
  cmd->add_option("--people", flags->people, "People (0..3)")->check(CLI::Range(0, 3));
  cmd->add_option("--depth", flags->depth, "Octree depth")->check(CLI::Range(3, 12));
  cmd->add_option("--threads", flags->threads, "Worker threads")->check(CLI::Range(1, 64));
  cmd->add_option("--width", flags->width, "Image width")->check(CLI::Range(16, 8192));
  cmd->add_option("--height", flags->height, "Image height")->check(CLI::Range(16, 8192));
  cmd->add_option("--time", flags->time_s, "Scene time (s): where the people are");
  cmd->callback([flags, exit_code] { *exit_code = RunDemo(*flags); });
}

}  // namespace hg::tools
