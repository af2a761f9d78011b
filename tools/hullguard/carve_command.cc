// `hullguard carve`: masks + calibrated cameras -> conservative octree.
#include <algorithm>
#include <cstdio>
#include <fstream>
#include <sstream>

#include "common/config_error.h"
#include "geometry/camera_yaml.h"
#include "hullguard/carve.h"
#include "hullguard/commands.h"
#include "octree/knowledge_filter.h"
#include "octree/ply.h"
#include "silhouette/mask_io.h"

namespace hg::tools {
namespace {

struct CarveFlags {
  std::string cameras;
  std::vector<std::string> masks;
  std::vector<double> bounds;
  int depth = 8;
  int threads = 1;
  int boundary_coarsening = octree::OctreeConfig{}.boundary_coarsening;
  int threshold = 127;
  std::string obstacles;
  std::string query;
  std::string out;
  std::string snapshot;
  bool json = false;
  double min_component_m3 = 0.0;
};

std::vector<Eigen::Vector3d> ReadQueryPoints(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw common::ConfigError(path + ": cannot open");
  std::vector<Eigen::Vector3d> points;
  std::string line;
  int number = 0;
  while (std::getline(in, line)) {
    ++number;
    const auto first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') continue;
    std::istringstream ss(line);
    Eigen::Vector3d p;
    std::string rest;
    if (!(ss >> p.x() >> p.y() >> p.z()) || (ss >> rest)) {
      throw common::ConfigError::At(path, number, "expected 'x y z', got '" + line + "'");
    }
    points.push_back(p);
  }
  return points;
}

int RunCarve(const CarveFlags& f) {
  CarveJob job;
  job.cameras = geometry::LoadCamerasFile(f.cameras);
  if (f.masks.size() != job.cameras.size()) {
    throw common::ConfigError(f.cameras + ": " + std::to_string(job.cameras.size()) +
                              " cameras but " + std::to_string(f.masks.size()) + " masks given");
  }
  for (std::size_t c = 0; c < f.masks.size(); ++c) {
    common::ImageU8 m = silhouette::ReadGreyImage(f.masks[c]);
    const auto& cam = job.cameras[c];
    if (m.width != cam.width || m.height != cam.height) {
      throw common::ConfigError(f.masks[c] + ": mask is " + std::to_string(m.width) + "x" +
                                std::to_string(m.height) + " but camera '" + cam.name + "' is " +
                                std::to_string(cam.width) + "x" + std::to_string(cam.height));
    }
    job.masks.push_back(std::move(m));
  }
  job.bounds.min = {f.bounds[0], f.bounds[1], f.bounds[2]};
  job.bounds.max = {f.bounds[3], f.bounds[4], f.bounds[5]};
  if (!job.bounds.IsValid()) {
    throw common::ConfigError("--bounds: each max must be greater than its min");
  }
  job.depth = f.depth;
  job.threads = f.threads;
  job.boundary_coarsening = std::min(f.boundary_coarsening, f.depth - octree::Octree::kRootLevel);
  job.threshold = static_cast<std::uint8_t>(f.threshold);
  if (!f.obstacles.empty()) job.obstacles.push_back(geometry::LoadObj(f.obstacles));
  const std::vector<Eigen::Vector3d> queries =
      f.query.empty() ? std::vector<Eigen::Vector3d>{} : ReadQueryPoints(f.query);

  const CarveResult r = Carve(job);
  const octree::Octree& tree = *r.tree;
  if (!f.out.empty()) octree::WriteOccupiedPly(tree, f.out);
  if (!f.snapshot.empty()) WriteSnapshot(tree, job.cameras, job.obstacles, f.snapshot);
  // The knowledge filter only changes what queries report; it is off unless asked for.
  const octree::KnowledgeFilterResult filter =
      f.min_component_m3 > 0 ? octree::FilterSmallComponents(tree, f.min_component_m3)
                             : octree::KnowledgeFilterResult{};
  for (const auto& p : queries) {
    std::printf("%.9g %.9g %.9g %s\n", p.x(), p.y(), p.z(),
                octree::ToString(filter.StateAt(tree, p)));
  }
  const double occupied = tree.Volume(octree::LeafState::kOccupied);
  const double occluded = tree.Volume(octree::LeafState::kOccluded);
  const double free_volume = tree.Volume(octree::LeafState::kFree);
  if (f.json) {
    std::printf(
        "{\"occupied_volume_m3\": %.9g, \"occluded_volume_m3\": %.9g, \"free_volume_m3\": %.9g, "
        "\"leaves\": %lld, \"nodes\": %lld, \"update_ms\": %.3f, \"quadtree_ms\": %.3f, "
        "\"undistort_ms\": %.3f, \"cameras\": %zu, \"depth\": %d, \"threads\": %d, "
        "\"verdicts\": %lld, \"components\": %d, \"dropped_components\": %d, "
        "\"dropped_volume_m3\": %.9g}\n",
        occupied, occluded, free_volume, static_cast<long long>(tree.NumLeaves()),
        static_cast<long long>(tree.NumNodes()), r.stats.update_ms, r.quadtree_ms, r.undistort_ms,
        job.cameras.size(), job.depth, job.threads,
        static_cast<long long>(r.stats.verdicts_computed), filter.components,
        filter.dropped_components, filter.dropped_volume_m3);
  } else if (queries.empty()) {
    std::printf(
        "occupied %.6f m^3, occluded %.6f m^3, free %.6f m^3; %lld leaves, %lld nodes; "
        "octree %.2f ms, quadtrees %.2f ms\n",
        occupied, occluded, free_volume, static_cast<long long>(tree.NumLeaves()),
        static_cast<long long>(tree.NumNodes()), r.stats.update_ms, r.quadtree_ms);
  }
  return kExitOk;
}

}  // namespace

void RegisterCarve(CLI::App& app, int* exit_code) {
  auto flags = std::make_shared<CarveFlags>();
  CLI::App* cmd = app.add_subcommand("carve", "Carve a conservative visual hull from masks");
  cmd->add_option("--cameras", flags->cameras, "YAML file with a top-level cameras: list")
      ->required();
  cmd->add_option("--masks", flags->masks, "One grey mask image per camera, in order")->required();
  cmd->add_option("--bounds", flags->bounds, "XMIN YMIN ZMIN XMAX YMAX ZMAX (m)")
      ->required()
      ->expected(6);
  cmd->add_option("--depth", flags->depth, "Octree depth; finest cell = bounds / 2^depth")
      ->required()
      ->check(CLI::Range(3, 16));
  cmd->add_option("--threads", flags->threads, "Worker threads")->check(CLI::Range(1, 64));
  cmd->add_option("--boundary-coarsening", flags->boundary_coarsening,
                  "Levels above --depth at which the static edges of the cameras' views and of "
                  "obstacles stop (0: exact)")
      ->check(CLI::Range(0, 16));
  cmd->add_option("--threshold", flags->threshold, "Foreground iff grey value > T")
      ->check(CLI::Range(0, 254));
  cmd->add_option("--obstacles", flags->obstacles, "Static obstacles as an OBJ mesh");
  cmd->add_option("--query", flags->query, "Text file of 'x y z' lines to classify");
  cmd->add_option("--out", flags->out, "Write occupied leaves as PLY boxes");
  cmd->add_option("--snapshot", flags->snapshot, "Write a PNG: top and side view of the result");
  cmd->add_flag("--json", flags->json, "Print a JSON summary");
  cmd->add_option("--min-component-m3", flags->min_component_m3,
                  "Knowledge filter: report occupied components below this volume as free "
                  "in --query (off: 0)")
      ->check(CLI::NonNegativeNumber);
  cmd->callback([flags, exit_code] { *exit_code = RunCarve(*flags); });
}

}  // namespace hg::tools
