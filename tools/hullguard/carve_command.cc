// `hullguard carve`: masks + calibrated cameras -> conservative octree.
#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iostream>
#include <iterator>
#include <sstream>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "common/cli_checks.h"
#include "common/config_error.h"
#include "common/input_file.h"
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
  std::int64_t max_nodes = 0;
  int threshold = 127;
  std::string obstacles;
  std::string query;
  std::string out;
  std::string snapshot;
  bool json = false;
  double min_component_m3 = 0.0;
};

// Sends file descriptor 2 to /dev/null while alive. Image decoders print their
// own diagnostics there (libpng's default error handler: "libpng error: ...",
// OpenCV's logger: several lines per failed read); the tool reports a failed
// read in its one error line instead. The redirect is process-wide, so this is
// single-thread: it is used only while reading input, before any worker exists.
class SilencedStderr {
 public:
  SilencedStderr() {
    std::cerr.flush();
    std::fflush(stderr);
    saved_ = ::dup(STDERR_FILENO);
    const int null = ::open("/dev/null", O_WRONLY | O_CLOEXEC);
    if (saved_ >= 0 && null >= 0) ::dup2(null, STDERR_FILENO);
    if (null >= 0) ::close(null);
  }
  ~SilencedStderr() {
    std::cerr.flush();
    std::fflush(stderr);
    if (saved_ >= 0) {
      ::dup2(saved_, STDERR_FILENO);
      ::close(saved_);
    }
  }
  SilencedStderr(const SilencedStderr&) = delete;
  SilencedStderr& operator=(const SilencedStderr&) = delete;

 private:
  int saved_ = -1;
};

// Reads a grey mask (colour is converted to grey). A missing, empty, truncated or
// damaged file is a ConfigError naming it, and nothing else reaches stderr.
// A file cut short is refused before decoding (libjpeg would fill the missing
// rows with grey and call the mask whole).
common::ImageU8 ReadMask(const std::string& path) {
  const std::string bytes = common::ReadInputFile(path, "mask", std::ios::binary);
  if (bytes.empty()) throw common::ConfigError(path + ": mask file is empty");
  if (!common::IsTrustedImageFormat(bytes)) {
    throw common::ConfigError(path + ": not a mask format read reliably (use " +
                              common::kTrustedImageFormats + ")");
  }
  cv::Mat m;
  if (common::IsCompleteImage(bytes)) {
    const SilencedStderr quiet;
    try {
      // UNCHANGED: a 16-bit mask stays 16-bit and is refused below (a plain
      // GRAYSCALE decode would scale 255 to 0, foreground to background), and
      // colour and alpha arrive as they are, to be read conservatively below.
      const cv::Mat encoded(1, static_cast<int>(bytes.size()), CV_8UC1,
                            const_cast<char*>(bytes.data()));
      m = cv::imdecode(encoded, cv::IMREAD_UNCHANGED);
    } catch (const cv::Exception&) {
      m = cv::Mat();
    }
  }
  if (m.empty() || m.depth() != CV_8U) {
    throw common::ConfigError(
        path + ": not a readable 8-bit image (16-bit, truncated, damaged or not an image)");
  }
  bool past_palette = false;
  {
    // A pixel whose index lies past the palette decodes as black, background:
    // a damaged mask would free the space of a person.
    const SilencedStderr quiet;
    past_palette = silhouette::IndexesPastItsPalette(bytes);
  }
  if (past_palette) {
    throw common::ConfigError(path + ": damaged: pixels index colours its palette does not have");
  }
  const int channels = m.channels();
  const common::ImageHeaderFacts facts = common::InspectImageHeader(bytes);
  if (facts.png_colour_key && channels != 2 && channels != 4) {
    // OpenCV drops a colour key from grey and RGB images: a foreground drawn
    // on a keyed-out background would read inverted.
    throw common::ConfigError(path +
                              ": mask has transparent pixels (a PNG transparency key, tRNS); "
                              "masks are read by their grey value, so save it without "
                              "transparency");
  }
  if (facts.pnm_maxval > 0 && facts.pnm_maxval < 255) {
    // Binary PGM/PPM samples are not scaled by OpenCV: a 0/1 mask (maxval 1)
    // would read as all background. Scaled, maxval is white (255).
    m.convertTo(m, -1, 255.0 / facts.pnm_maxval);
  }
  if (channels == 2 || channels == 4) {
    // Transparency would be dropped: a mask drawn as opaque foreground on a
    // transparent background would read as all background, the person free.
    std::vector<cv::Mat> planes;
    cv::split(m, planes);
    double lowest_alpha = 0.0;
    cv::minMaxLoc(planes.back(), &lowest_alpha);
    if (lowest_alpha < 255.0) {
      throw common::ConfigError(path +
                                ": mask has transparent pixels (an alpha channel); masks are read "
                                "by their grey value, so save it without transparency");
    }
  }
  // Colour: a pixel's value is its brightest channel, never less than its grey
  // value, so that a foreground drawn in any colour counts (a pure red one
  // would be dark in grey).
  cv::Mat value;
  if (channels == 1) {
    value = m;
  } else {
    std::vector<cv::Mat> planes;
    cv::split(m, planes);
    value = planes[0];
    const int colours = channels == 2 ? 1 : 3;
    for (int i = 1; i < colours; ++i) cv::max(value, planes[static_cast<std::size_t>(i)], value);
  }
  common::ImageU8 out(value.cols, value.rows);
  for (int v = 0; v < value.rows; ++v) {
    std::memcpy(&out.At(0, v), value.ptr<std::uint8_t>(v), static_cast<std::size_t>(value.cols));
  }
  return out;
}

// One point of a --query file, with its coordinates as the user wrote them: the
// output echoes the text, so that no rounding can make two points look alike.
struct QueryPoint {
  std::string text;  ///< The three tokens, joined by one space.
  Eigen::Vector3d p_W;
};

std::vector<QueryPoint> ReadQueryPoints(const std::string& path) {
  std::ifstream in = common::OpenInputFile(path, "query file");
  std::vector<QueryPoint> points;
  std::string line;
  int number = 0;
  while (std::getline(in, line)) {
    ++number;
    const auto first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') continue;
    // A comment may also follow the coordinates.
    std::istringstream ss(line.substr(0, line.find('#')));
    std::string token[3];
    std::string rest;
    QueryPoint q;
    bool ok = static_cast<bool>(ss >> token[0] >> token[1] >> token[2]) && !(ss >> rest);
    for (int axis = 0; ok && axis < 3; ++axis) {
      char* end = nullptr;
      q.p_W[axis] = std::strtod(token[axis].c_str(), &end);
      // The whole token: a NUL inside it ends strtod's read, not the token.
      ok = end == token[axis].c_str() + token[axis].size() && std::isfinite(q.p_W[axis]);
    }
    if (!ok) {
      if (!line.empty() && line.back() == '\r') line.pop_back();
      throw common::ConfigError::At(path, number,
                                    "expected 'x y z' (finite numbers), got '" + line + "'");
    }
    q.text = token[0] + " " + token[1] + " " + token[2];
    points.push_back(std::move(q));
  }
  return points;
}

int RunCarve(const CarveFlags& f) {
  CarveJob job;
  // Cheap flags first: a bad --bounds fails before any file is read.
  job.bounds.min = {f.bounds[0], f.bounds[1], f.bounds[2]};
  job.bounds.max = {f.bounds[3], f.bounds[4], f.bounds[5]};
  if (!job.bounds.IsPlausibleCell()) {
    throw common::ConfigError(
        "--bounds: need finite numbers within +-1e6 m with each max greater than its min (XMIN "
        "YMIN ZMIN XMAX YMAX ZMAX)");
  }
  job.cameras = geometry::LoadCamerasFile(f.cameras);
  if (job.cameras.size() > static_cast<std::size_t>(octree::Octree::kMaxCameras)) {
    throw common::ConfigError(f.cameras + ": " + std::to_string(job.cameras.size()) +
                              " cameras, at most " + std::to_string(octree::Octree::kMaxCameras) +
                              " are supported");
  }
  if (f.masks.size() != job.cameras.size()) {
    throw common::ConfigError(f.cameras + ": " + std::to_string(job.cameras.size()) +
                              " cameras but " + std::to_string(f.masks.size()) + " masks given");
  }
  for (std::size_t c = 0; c < f.masks.size(); ++c) {
    common::ImageU8 m = ReadMask(f.masks[c]);
    const auto& cam = job.cameras[c];
    if (m.width != cam.width || m.height != cam.height) {
      throw common::ConfigError(f.masks[c] + ": mask is " + std::to_string(m.width) + "x" +
                                std::to_string(m.height) + " but camera '" + cam.name + "' is " +
                                std::to_string(cam.width) + "x" + std::to_string(cam.height));
    }
    job.masks.push_back(std::move(m));
  }
  job.depth = f.depth;
  job.threads = f.threads;
  job.boundary_coarsening = std::min(f.boundary_coarsening, f.depth - octree::Octree::kRootLevel);
  job.max_nodes = f.max_nodes;
  job.threshold = static_cast<std::uint8_t>(f.threshold);
  if (!f.obstacles.empty()) {
    // An obstacle hides what lies behind it; a file read as no obstacle at all
    // (wrong format, empty mesh) would free that space, so both are errors.
    geometry::TriangleMesh mesh = geometry::LoadMesh(f.obstacles);
    if (mesh.triangles.empty()) throw common::ConfigError(f.obstacles + ": no triangles");
    job.obstacles.push_back(std::move(mesh));
  }
  const std::vector<QueryPoint> queries =
      f.query.empty() ? std::vector<QueryPoint>{} : ReadQueryPoints(f.query);

  const CarveResult r = Carve(job);
  const octree::Octree& tree = *r.tree;
  if (!f.out.empty()) octree::WriteOccupiedPly(tree, f.out);
  if (!f.snapshot.empty()) WriteSnapshot(tree, job.cameras, job.obstacles, f.snapshot);
  // The knowledge filter only changes what queries report; it is off unless asked for.
  const octree::KnowledgeFilterResult filter =
      f.min_component_m3 > 0 ? octree::FilterSmallComponents(tree, f.min_component_m3)
                             : octree::KnowledgeFilterResult{};
  for (const QueryPoint& q : queries) {
    std::printf("%s %s\n", q.text.c_str(), octree::ToString(filter.StateAt(tree, q.p_W)));
  }
  if (r.stats.nodes_unsplit > 0) {
    std::fprintf(stderr,
                 "hullguard carve: the octree's node store was too small: %lld nodes left "
                 "unsplit (reported occupied, coarser than depth %d); raise --max-nodes\n",
                 static_cast<long long>(r.stats.nodes_unsplit), f.depth);
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
        "\"dropped_volume_m3\": %.9g, \"unsplit_nodes\": %lld}\n",
        occupied, occluded, free_volume, static_cast<long long>(tree.NumLeaves()),
        static_cast<long long>(tree.NumNodes()), r.stats.update_ms, r.quadtree_ms, r.undistort_ms,
        job.cameras.size(), job.depth, job.threads,
        static_cast<long long>(r.stats.verdicts_computed), filter.components,
        filter.dropped_components, filter.dropped_volume_m3,
        static_cast<long long>(r.stats.nodes_unsplit));
  } else if (f.query.empty()) {  // A query file without points prints nothing.
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
  cmd->add_option("--masks", flags->masks,
                  "One grey mask image per camera, paired by position with the cameras file")
      ->required();
  cmd->add_option("--bounds", flags->bounds, "XMIN YMIN ZMIN XMAX YMAX ZMAX (m)")
      ->required()
      ->expected(6)
      ->check(hg::cli::kFinite);
  cmd->add_option("--depth", flags->depth, "Octree depth; finest cell = bounds / 2^depth")
      ->required()
      ->check(hg::cli::Range(3, 16));
  cmd->add_option("--threads", flags->threads, "Worker threads")->check(hg::cli::Range(1, 64));
  cmd->add_option("--boundary-coarsening", flags->boundary_coarsening,
                  "Levels above --depth at which the static edges of the cameras' views and of "
                  "obstacles stop (0: exact)")
      ->check(hg::cli::Range(0, 16));
  cmd->add_option("--max-nodes", flags->max_nodes,
                  "Octree nodes reserved (24 bytes each; 0: the full tree of the depth, at most "
                  "8 Mi). Where they run out, cells are left occupied, and a warning says so")
      ->check(hg::cli::Range(std::int64_t{0}, std::int64_t{500'000'000}));
  cmd->add_option("--threshold", flags->threshold, "Foreground iff grey value > T")
      ->check(hg::cli::Range(0, 254));
  cmd->add_option("--obstacles", flags->obstacles, "Static obstacles as an OBJ or STL mesh");
  cmd->add_option("--query", flags->query, "Text file of 'x y z' lines to classify");
  cmd->add_option(
      "--out", flags->out,
      "Write occupied and occluded leaves as PLY boxes (colour per vertex: red occupied, grey "
      "occluded)");
  cmd->add_option("--snapshot", flags->snapshot, "Write a PNG: top and side view of the result");
  cmd->add_flag("--json", flags->json, "Print a JSON summary");
  cmd->add_option("--min-component-m3", flags->min_component_m3,
                  "Knowledge filter: report occupied components below this volume as free "
                  "in --query (off: 0)")
      ->check(hg::cli::kNonNegative)
      ->check(hg::cli::kFinite);
  cmd->callback([flags, exit_code] { *exit_code = RunCarve(*flags); });
}

}  // namespace hg::tools
