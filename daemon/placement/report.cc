#include "placement/report.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <limits>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "common/config_error.h"
#include "common/json.h"
#include "placement/fov_volume.h"

namespace hg::placement {
namespace {

using common::ConfigError;

std::string Fixed(double value, int digits) {
  std::ostringstream out;
  out << std::fixed << std::setprecision(digits) << value;
  return out.str();
}

std::string Percent(double fraction) { return Fixed(100.0 * fraction, 1) + " %"; }

std::string Vec(const Eigen::Vector3d& v, int digits) {
  std::ostringstream out;
  out << std::fixed << std::setprecision(digits) << "[" << v.x() << ", " << v.y() << ", " << v.z()
      << "]";
  return out.str();
}

/// JSON string literal (the texts here are names, paths and commands).
std::string Quote(const std::string& text) { return common::JsonString(text); }

/// A finite number for JSON (null otherwise).
std::string Number(double value, int digits = 6) {
  if (!std::isfinite(value)) return "null";
  std::ostringstream out;
  out << std::setprecision(digits) << value;
  return out.str();
}

const char* KindName(sim::MountingSurface::Kind kind) {
  switch (kind) {
    case sim::MountingSurface::Kind::kWall:
      return "wall";
    case sim::MountingSurface::Kind::kCeiling:
      return "ceiling";
    case sim::MountingSurface::Kind::kPole:
      return "pole";
  }
  return "?";
}

/// Everything the report says about one layout.
struct LayoutData {
  const LayoutReport* layout;
  std::vector<geometry::CameraModel> cameras;
  CoverageMetrics metrics;
  std::vector<std::uint8_t> counts;
  std::vector<int> seen_voxels;
  std::vector<double> fov_m3;  ///< Exact seen volume per camera (NaN when unavailable).
  int free_sample = 0;
  std::vector<std::uint8_t> free;
};

// ---------------------------------------------------------------------------
// Pictures

/// World x-y to picture pixels, north (+y) up.
class TopView {
 public:
  explicit TopView(const common::Box3& bounds) : bounds_(bounds) {
    const Eigen::Vector3d size = bounds.Size();
    ppm_ = std::min(110.0, 520.0 / std::max(size.x(), size.y()));
    width_ = static_cast<int>(std::ceil(size.x() * ppm_)) + 2 * kMargin;
    height_ = static_cast<int>(std::ceil(size.y() * ppm_)) + 2 * kMargin + kTitle;
  }
  static constexpr int kMargin = 34;
  static constexpr int kTitle = 22;
  [[nodiscard]] int width() const { return width_; }
  [[nodiscard]] int height() const { return height_; }
  [[nodiscard]] double ppm() const { return ppm_; }
  [[nodiscard]] cv::Point2d Pixel(double x, double y) const {
    return {kMargin + (x - bounds_.min.x()) * ppm_,
            kTitle + kMargin + (bounds_.max.y() - y) * ppm_};
  }
  [[nodiscard]] cv::Point Px(double x, double y) const {
    const cv::Point2d p = Pixel(x, y);
    return {static_cast<int>(std::lround(p.x)), static_cast<int>(std::lround(p.y))};
  }
  /// Fills the voxel column (i, j) of `grid`.
  void FillColumn(cv::Mat* image, const VoxelGrid& grid, int i, int j,
                  const cv::Scalar& colour) const {
    const common::Box3 box = grid.VoxelBox(i, j, 0);
    cv::rectangle(*image, Px(box.min.x(), box.max.y()), Px(box.max.x(), box.min.y()), colour,
                  cv::FILLED);
  }

 private:
  common::Box3 bounds_;
  double ppm_ = 100.0;
  int width_ = 0;
  int height_ = 0;
};

constexpr int kFont = cv::FONT_HERSHEY_SIMPLEX;

void Text(cv::Mat* image, const std::string& text, cv::Point at, double scale = 0.45,
          const cv::Scalar& colour = cv::Scalar(20, 20, 20)) {
  cv::putText(*image, text, at, kFont, scale, colour, 1, cv::LINE_AA);
}

/// Viridis colours for 0..255.
const std::array<cv::Vec3b, 256>& Viridis() {
  static const std::array<cv::Vec3b, 256> lut = [] {
    cv::Mat grey(1, 256, CV_8UC1);
    for (int i = 0; i < 256; ++i) grey.at<std::uint8_t>(0, i) = static_cast<std::uint8_t>(i);
    cv::Mat colour;
    cv::applyColorMap(grey, colour, cv::COLORMAP_VIRIDIS);
    std::array<cv::Vec3b, 256> out;
    for (int i = 0; i < 256; ++i) out[i] = colour.at<cv::Vec3b>(0, i);
    return out;
  }();
  return lut;
}

const cv::Scalar kUnseen(60, 60, 200);      // Red: no camera.
const cv::Scalar kObstacle(120, 120, 120);  // Grey.
const cv::Scalar kFree(90, 185, 90);        // Green.
const cv::Scalar kPerson(230, 120, 20);     // Blue.

/// Colour of a coverage count (0..max, fractional for means).
cv::Scalar CountColour(double count, int max_count) {
  if (count <= 0.0) return kUnseen;
  const double f = std::clamp(count / std::max(1, max_count), 0.0, 1.0);
  const cv::Vec3b c = Viridis()[static_cast<int>(std::lround(f * 255.0))];
  return {static_cast<double>(c[0]), static_cast<double>(c[1]), static_cast<double>(c[2])};
}

void Legend(cv::Mat* image, int x, int y, int max_count) {
  const int w = 160;
  for (int i = 0; i < w; ++i) {
    const double count = static_cast<double>(i) / (w - 1) * max_count;
    cv::line(*image, {x + i, y}, {x + i, y + 10}, CountColour(std::max(count, 1e-6), max_count));
  }
  cv::rectangle(*image, {x - 14, y}, {x - 4, y + 10}, kUnseen, cv::FILLED);
  Text(image, "0", {x - 14, y + 24}, 0.4);
  Text(image, ">0", {x, y + 24}, 0.4);
  Text(image, std::to_string(max_count) + " cameras", {x + w - 50, y + 24}, 0.4);
}

void Outline(cv::Mat* image, const TopView& view, const common::Box3& b) {
  cv::rectangle(*image, view.Px(b.min.x(), b.max.y()), view.Px(b.max.x(), b.min.y()),
                cv::Scalar(30, 30, 30), 1);
}

void DrawCameras(cv::Mat* image, const TopView& view,
                 const std::vector<geometry::CameraModel>& cams) {
  for (const geometry::CameraModel& cam : cams) {
    const Eigen::Vector3d c = cam.CentreW();
    const cv::Point p = view.Px(c.x(), c.y());
    cv::circle(*image, p, 5, cv::Scalar(0, 0, 0), cv::FILLED, cv::LINE_AA);
    cv::circle(*image, p, 3, cv::Scalar(255, 255, 255), cv::FILLED, cv::LINE_AA);
    Text(image, cam.name.substr(3), p + cv::Point(6, -6), 0.4);
  }
}

/// The picture canvas with a title.
cv::Mat Canvas(int width, int height, const std::string& title) {
  cv::Mat image(height, width, CV_8UC3, cv::Scalar(255, 255, 255));
  Text(&image, title, {8, 17}, 0.5);
  return image;
}

void Save(const std::filesystem::path& path, const cv::Mat& image) {
  if (!cv::imwrite(path.string(), image)) {
    throw ConfigError::At(path.string(), 0, "cannot write the picture");
  }
}

/// Layer index of height z above the floor, or -1 outside the cell.
int LayerAt(const VoxelGrid& grid, double z) {
  const double f = z / grid.cell_m.z();
  const int k = static_cast<int>(std::floor(f));
  return k >= 0 && k < grid.nz ? k : -1;
}

void CoverageTop(const std::filesystem::path& path, const PlacementScene& scene,
                 const LayoutData& data) {
  const VoxelGrid& g = scene.grid;
  const TopView view(g.bounds);
  const int n = static_cast<int>(data.cameras.size());
  cv::Mat image = Canvas(view.width(), view.height() + 30,
                         data.layout->title + ": cameras seeing each voxel, mean over height");
  for (int j = 0; j < g.ny; ++j) {
    for (int i = 0; i < g.nx; ++i) {
      long long sum = 0;
      int voxels = 0;
      for (int k = 0; k < g.nz; ++k) {
        const int index = g.Index(i, j, k);
        if (scene.obstacle[index] != 0) continue;
        sum += data.counts[index];
        ++voxels;
      }
      view.FillColumn(&image, g, i, j,
                      voxels == 0 ? kObstacle : CountColour(static_cast<double>(sum) / voxels, n));
    }
  }
  Outline(&image, view, g.bounds);
  DrawCameras(&image, view, data.cameras);
  Legend(&image, 30, view.height(), n);
  Save(path, image);
}

/// Side-by-side panels, one per slice height; `colour(index)` colours a voxel.
template <class ColourFn, class DecorateFn>
void Slices(const std::filesystem::path& path, const PlacementScene& scene,
            const std::string& title, const ColourFn& colour, const DecorateFn& decorate,
            int legend_max) {
  const VoxelGrid& g = scene.grid;
  const TopView view(g.bounds);
  std::vector<std::pair<double, int>> layers;
  for (const double z : kSliceHeightsM) {
    const int k = LayerAt(g, z);
    if (k >= 0) layers.emplace_back(z, k);
  }
  if (layers.empty()) layers.emplace_back(0.5 * g.bounds.Size().z(), g.nz / 2);
  const int panel = view.width();
  cv::Mat image = Canvas(panel * static_cast<int>(layers.size()),
                         view.height() + (legend_max > 0 ? 30 : 0), title);
  for (std::size_t p = 0; p < layers.size(); ++p) {
    cv::Mat roi = image(cv::Rect(static_cast<int>(p) * panel, TopView::kTitle, panel,
                                 view.height() - TopView::kTitle));
    cv::Mat part(view.height(), panel, CV_8UC3, cv::Scalar(255, 255, 255));
    const int k = layers[p].second;
    for (int j = 0; j < g.ny; ++j) {
      for (int i = 0; i < g.nx; ++i) view.FillColumn(&part, g, i, j, colour(g.Index(i, j, k)));
    }
    Outline(&part, view, g.bounds);
    decorate(&part, view, layers[p].first);
    Text(&part, "z = " + Fixed(layers[p].first, 2) + " m",
         {TopView::kMargin, TopView::kTitle + 14});
    part(cv::Rect(0, TopView::kTitle, panel, view.height() - TopView::kTitle)).copyTo(roi);
  }
  if (legend_max > 0) Legend(&image, 30, view.height(), legend_max);
  Save(path, image);
}

/// The part of the horizontal rectangle `rect` (at height z) inside the
/// camera's viewing pyramid: the rectangle clipped by the four side planes.
std::vector<Eigen::Vector2d> FrustumSection(const geometry::CameraModel& cam,
                                            const common::Box3& rect, double z) {
  std::vector<Eigen::Vector3d> poly = {{rect.min.x(), rect.min.y(), z},
                                       {rect.max.x(), rect.min.y(), z},
                                       {rect.max.x(), rect.max.y(), z},
                                       {rect.min.x(), rect.max.y(), z}};
  const Eigen::Vector3d c = cam.CentreW();
  const Eigen::Matrix3d K_inv = cam.K.inverse();
  const std::array<Eigen::Vector2d, 4> corners = {
      Eigen::Vector2d(-0.5, -0.5), Eigen::Vector2d(cam.width - 0.5, -0.5),
      Eigen::Vector2d(cam.width - 0.5, cam.height - 0.5), Eigen::Vector2d(-0.5, cam.height - 0.5)};
  std::array<Eigen::Vector3d, 4> rays;
  for (int i = 0; i < 4; ++i) {
    rays[i] = cam.R_CW.transpose() * (K_inv * Eigen::Vector3d(corners[i].x(), corners[i].y(), 1.0));
  }
  const Eigen::Vector3d forward = cam.R_CW.row(2).transpose();
  for (int i = 0; i < 4 && !poly.empty(); ++i) {
    Eigen::Vector3d n = rays[i].cross(rays[(i + 1) % 4]);
    if (n.dot(forward) < 0) n = -n;
    std::vector<Eigen::Vector3d> out;
    for (std::size_t k = 0; k < poly.size(); ++k) {
      const Eigen::Vector3d& a = poly[k];
      const Eigen::Vector3d& b = poly[(k + 1) % poly.size()];
      const double da = n.dot(a - c);
      const double db = n.dot(b - c);
      if (da >= 0) out.push_back(a);
      if ((da >= 0) != (db >= 0)) out.push_back(a + (b - a) * (da / (da - db)));
    }
    poly = std::move(out);
  }
  std::vector<Eigen::Vector2d> section;
  for (const Eigen::Vector3d& p : poly) section.emplace_back(p.x(), p.y());
  return section;
}

void Frusta(const std::filesystem::path& path, const PlacementScene& scene,
            const LayoutData& data) {
  const VoxelGrid& g = scene.grid;
  const TopView view(g.bounds);
  const double z = g.bounds.min.z();
  cv::Mat image = Canvas(view.width(), view.height(),
                         data.layout->title + ": where each camera sees the floor");
  for (int j = 0; j < g.ny; ++j) {
    for (int i = 0; i < g.nx; ++i) {
      bool any = false;
      for (int k = 0; k < g.nz && !any; ++k) any = scene.obstacle[g.Index(i, j, k)] != 0;
      if (any) view.FillColumn(&image, g, i, j, cv::Scalar(185, 185, 185));
    }
  }
  for (const sim::MountingSurface& s : scene.surfaces) {
    const Eigen::Vector3d a = s.origin_W;
    if (s.kind == sim::MountingSurface::Kind::kWall) {
      const Eigen::Vector3d b = a + s.u_W;
      cv::line(image, view.Px(a.x(), a.y()), view.Px(b.x(), b.y()), cv::Scalar(150, 200, 240), 6);
    } else if (s.kind == sim::MountingSurface::Kind::kCeiling) {
      const Eigen::Vector3d b = a + s.u_W + s.v_W;
      cv::rectangle(image, view.Px(a.x(), b.y()), view.Px(b.x(), a.y()), cv::Scalar(150, 200, 240),
                    2);
    } else {
      cv::drawMarker(image, view.Px(a.x(), a.y()), cv::Scalar(40, 150, 230), cv::MARKER_SQUARE, 9,
                     2);
    }
  }
  Outline(&image, view, g.bounds);
  static const std::array<cv::Scalar, 8> kPalette = {
      cv::Scalar(200, 60, 40),  cv::Scalar(40, 140, 40),  cv::Scalar(30, 30, 200),
      cv::Scalar(160, 40, 160), cv::Scalar(20, 130, 200), cv::Scalar(120, 120, 0),
      cv::Scalar(90, 60, 20),   cv::Scalar(0, 90, 160)};
  for (std::size_t c = 0; c < data.cameras.size(); ++c) {
    const geometry::CameraModel& cam = data.cameras[c];
    const cv::Scalar colour = kPalette[c % kPalette.size()];
    const std::vector<Eigen::Vector2d> section = FrustumSection(cam, g.bounds, z);
    std::vector<cv::Point> polygon;
    for (const Eigen::Vector2d& p : section) polygon.push_back(view.Px(p.x(), p.y()));
    if (polygon.size() >= 3) {
      cv::Mat layer = image.clone();
      cv::fillConvexPoly(layer, polygon, colour, cv::LINE_AA);
      cv::addWeighted(layer, 0.12, image, 0.88, 0.0, image);
      cv::polylines(image, polygon, true, colour, 2, cv::LINE_AA);
    }
    const Eigen::Vector3d centre = cam.CentreW();
    const Eigen::Vector3d look = data.layout->placements[c].look_at_W;
    cv::line(image, view.Px(centre.x(), centre.y()), view.Px(look.x(), look.y()), colour, 1,
             cv::LINE_AA);
    cv::circle(image, view.Px(look.x(), look.y()), 3, colour, cv::FILLED, cv::LINE_AA);
  }
  DrawCameras(&image, view, data.cameras);
  Save(path, image);
}

// ---------------------------------------------------------------------------
// Figures

std::string MetricsJson(const LayoutData& d, const PlacementScene& scene, int indent) {
  const std::string pad(indent, ' ');
  const CoverageMetrics& m = d.metrics;
  std::ostringstream out;
  out << "{\n";
  out << pad << "  \"score\": " << Number(m.score, 8) << ",\n";
  out << pad << "  \"mean_free_m3\": " << Number(m.mean_free_m3) << ",\n";
  out << pad << "  \"mean_free_fraction\": " << Number(m.mean_free_fraction) << ",\n";
  out << pad << "  \"min_free_fraction\": " << Number(m.min_free_fraction) << ",\n";
  out << pad << "  \"free_fraction_per_sample\": [";
  for (std::size_t s = 0; s < m.free_fraction.size(); ++s) {
    out << (s ? ", " : "") << Number(m.free_fraction[s]);
  }
  out << "],\n";
  out << pad << "  \"seen_fraction\": " << Number(m.seen_fraction) << ",\n";
  out << pad << "  \"k_coverage\": " << Number(m.k_coverage) << ",\n";
  out << pad << "  \"cameras\": [\n";
  for (std::size_t c = 0; c < d.cameras.size(); ++c) {
    const CameraPlacement& p = d.layout->placements[c];
    out << pad << "    {\"name\": " << Quote(d.cameras[c].name)
        << ", \"surface\": " << Quote(scene.surfaces[p.surface].name)
        << ", \"position\": " << Vec(p.position_W, 4) << ", \"look_at\": " << Vec(p.look_at_W, 4)
        << ", \"seen_m3\": " << Number(d.seen_voxels[c] * scene.grid.VoxelVolume())
        << ", \"exact_fov_m3\": " << Number(d.fov_m3[c]) << "}"
        << (c + 1 < d.cameras.size() ? "," : "") << "\n";
  }
  out << pad << "  ]\n" << pad << "}";
  return out.str();
}

}  // namespace

void WriteReport(const std::string& dir, const PlacementScene& scene, Evaluator* evaluator,
                 const RunInfo& run, const std::vector<LayoutReport>& layouts) {
  const std::filesystem::path root(dir);
  std::error_code ec;
  std::filesystem::create_directories(root, ec);
  if (ec || !std::filesystem::is_directory(root)) {
    throw ConfigError::At(dir, 0, "cannot create the report directory");
  }
  const VoxelGrid& g = scene.grid;

  // The exact field-of-view volume of single cameras, as a cross-check of
  // the voxel counts (the voxel figure can only be smaller).
  geometry::TriangleMesh obstacles;
  for (const geometry::TriangleMesh& mesh : scene.obstacle_meshes) obstacles.Append(mesh);
  std::optional<FovScene> fov_scene;
  try {
    fov_scene.emplace(g.bounds, obstacles);
  } catch (const ConfigError&) {
    fov_scene.reset();
  }

  // The sample person nearest to the middle of the floor.
  const Eigen::Vector3d centre = 0.5 * (g.bounds.min + g.bounds.max);
  int free_sample = 0;
  for (std::size_t s = 1; s < scene.samples.size(); ++s) {
    const auto d2 = [&](std::size_t i) {
      return (scene.samples[i].feet_W - centre).head<2>().squaredNorm();
    };
    if (d2(s) < d2(free_sample) - 1e-12) free_sample = static_cast<int>(s);
  }

  std::vector<LayoutData> data;
  for (const LayoutReport& layout : layouts) {
    LayoutData d;
    d.layout = &layout;
    d.cameras = CamerasOf(scene, layout.placements);
    d.metrics = evaluator->Evaluate(d.cameras);
    d.counts = evaluator->counts();
    d.seen_voxels = evaluator->SeenVoxelsPerCamera();
    d.free_sample = free_sample;
    evaluator->CertifiedFree(free_sample, &d.free);
    for (const geometry::CameraModel& cam : d.cameras) {
      double volume = std::numeric_limits<double>::quiet_NaN();
      if (fov_scene) volume = FovVolume(*fov_scene, cam.Pinhole());
      d.fov_m3.push_back(volume);
    }
    data.push_back(std::move(d));
  }

  // Pictures.
  for (const LayoutData& d : data) {
    const std::string key = d.layout->key;
    const int n = static_cast<int>(d.cameras.size());
    CoverageTop(root / (key + "_coverage_top.png"), scene, d);
    Slices(
        root / (key + "_slices.png"), scene, d.layout->title + ": cameras seeing each voxel",
        [&](int index) {
          return scene.obstacle[index] != 0 ? kObstacle : CountColour(d.counts[index], n);
        },
        [&](cv::Mat* image, const TopView& view, double) { DrawCameras(image, view, d.cameras); },
        n);
    const PersonSample& person = scene.samples[d.free_sample];
    Slices(
        root / (key + "_free.png"), scene,
        d.layout->title + ": certified free (green) with a person at (" +
            Fixed(person.feet_W.x(), 2) + ", " + Fixed(person.feet_W.y(), 2) +
            "): " + Percent(d.metrics.free_fraction[d.free_sample]) + " of the cell",
        [&](int index) {
          if (scene.obstacle[index] != 0) return kObstacle;
          return d.free[index] != 0 ? kFree : kUnseen;
        },
        [&](cv::Mat* image, const TopView& view, double z) {
          const double floor_z = g.bounds.min.z() + z;
          if (floor_z <= person.b_W.z() + person.radius_m) {
            cv::circle(*image, view.Px(person.feet_W.x(), person.feet_W.y()),
                       static_cast<int>(std::lround(person.radius_m * view.ppm())), kPerson, 2,
                       cv::LINE_AA);
          }
          DrawCameras(image, view, d.cameras);
        },
        0);
    Frusta(root / (key + "_frusta.png"), scene, d);
  }

  // report.json
  {
    std::ofstream out(root / "report.json");
    out << "{\n";
    out << "  \"scene\": " << Quote(scene.name) << ",\n";
    out << "  \"scene_file\": " << Quote(scene.source_file) << ",\n";
    out << "  \"command\": " << Quote(run.command) << ",\n";
    out << "  \"cameras_file\": " << Quote(run.cameras_file) << ",\n";
    out << "  \"cameras\": " << run.cameras << ",\n";
    out << "  \"min_views\": " << run.objective.min_views << ",\n";
    out << "  \"coverage_weight\": " << Number(run.objective.coverage_weight) << ",\n";
    out << "  \"seed\": " << run.seed << ",\n";
    out << "  \"score\": \"mean_free_fraction + coverage_weight * k_coverage\",\n";
    out << "  \"grid\": {\"voxels\": [" << g.nx << ", " << g.ny << ", " << g.nz
        << "], \"voxel_m\": " << Vec(g.cell_m, 4)
        << ", \"render_width_px\": " << scene.options.render_width_px << "},\n";
    out << "  \"cell_volume_m3\": " << Number(g.bounds.Volume()) << ",\n";
    out << "  \"target_volume_m3\": " << Number(scene.TargetVolume()) << ",\n";
    out << "  \"person\": {\"radius_m\": " << Number(scene.options.person_radius_m)
        << ", \"height_m\": " << Number(scene.options.person_height_m) << ", \"samples\": [";
    for (std::size_t s = 0; s < scene.samples.size(); ++s) {
      out << (s ? ", " : "") << "[" << Fixed(scene.samples[s].feet_W.x(), 3) << ", "
          << Fixed(scene.samples[s].feet_W.y(), 3) << "]";
    }
    out << "]},\n";
    out << "  \"surfaces\": [";
    for (std::size_t s = 0; s < scene.surfaces.size(); ++s) {
      out << (s ? ", " : "") << "{\"name\": " << Quote(scene.surfaces[s].name)
          << ", \"kind\": " << Quote(KindName(scene.surfaces[s].kind)) << "}";
    }
    out << "],\n";
    out << "  \"run\": {\"threads\": " << run.threads
        << ", \"global_evaluations\": " << run.global_evaluations
        << ", \"local_evaluations\": " << run.local_evaluations
        << ", \"global_s\": " << Number(run.global_seconds, 4)
        << ", \"local_s\": " << Number(run.local_seconds, 4)
        << ", \"total_s\": " << Number(run.total_seconds, 4) << "},\n";
    out << "  \"layouts\": {\n";
    for (std::size_t i = 0; i < data.size(); ++i) {
      out << "    " << Quote(data[i].layout->key) << ": " << MetricsJson(data[i], scene, 4)
          << (i + 1 < data.size() ? "," : "") << "\n";
    }
    out << "  }\n}\n";
    if (!out) throw ConfigError::At((root / "report.json").string(), 0, "cannot write");
  }

  // report.md
  {
    std::ofstream out(root / "report.md");
    const int k = run.objective.min_views;
    out << "# Camera placement: " << scene.name << ", " << run.cameras << " cameras\n\n";
    out << "```\n" << run.command << "\n```\n\n";
    out << "- Cell " << Vec(g.bounds.min, 2) << " .. " << Vec(g.bounds.max, 2) << ", "
        << Fixed(g.bounds.Volume(), 2) << " m³; " << g.nx << " x " << g.ny << " x " << g.nz
        << " voxels of " << Fixed(g.cell_m.x(), 3) << " x " << Fixed(g.cell_m.y(), 3) << " x "
        << Fixed(g.cell_m.z(), 3) << " m; surveillance volume without obstacle voxels "
        << Fixed(scene.TargetVolume(), 2) << " m³.\n";
    out << "- " << scene.samples.size()
        << " sample people (capsule r = " << Fixed(scene.options.person_radius_m, 2) << " m, "
        << Fixed(scene.options.person_height_m, 2) << " m tall) on a "
        << Fixed(scene.options.person_spacing_m, 2) << " m grid.\n";
    out << "- Score = mean share certified free with a person + "
        << Number(run.objective.coverage_weight) << " x share seen by >= " << k
        << " cameras (docs/placement.md).\n";
    out << "- Search: " << run.global_evaluations << " CMA-ES + " << run.local_evaluations
        << " BOBYQA evaluations, " << Fixed(run.global_seconds, 1) << " s + "
        << Fixed(run.local_seconds, 1) << " s on " << run.threads << " threads, seed " << run.seed
        << "; cameras written to `" << run.cameras_file << "`.\n\n";
    out << "| | ";
    for (const LayoutData& d : data) out << d.layout->title << " | ";
    out << "\n|---|";
    for (std::size_t i = 0; i < data.size(); ++i) out << "---|";
    out << "\n| score | ";
    for (const LayoutData& d : data) out << Fixed(d.metrics.score, 4) << " | ";
    out << "\n| certified free with a person, mean | ";
    for (const LayoutData& d : data) {
      out << Fixed(d.metrics.mean_free_m3, 2) << " m³ (" << Percent(d.metrics.mean_free_fraction)
          << ") | ";
    }
    out << "\n| certified free, worst sample | ";
    for (const LayoutData& d : data) out << Percent(d.metrics.min_free_fraction) << " | ";
    out << "\n| seen by >= 1 camera (empty cell) | ";
    for (const LayoutData& d : data) out << Percent(d.metrics.seen_fraction) << " | ";
    out << "\n| seen by >= " << k << " cameras (empty cell) | ";
    for (const LayoutData& d : data) out << Percent(d.metrics.k_coverage) << " | ";
    out << "\n\n";
    for (const LayoutData& d : data) {
      out << "## " << d.layout->title << "\n\n";
      out << "| camera | surface | position (m) | looks at (m) | seen, voxels (m³) | seen, exact "
             "(m³) |\n|---|---|---|---|---|---|\n";
      for (std::size_t c = 0; c < d.cameras.size(); ++c) {
        const CameraPlacement& p = d.layout->placements[c];
        out << "| " << d.cameras[c].name << " | " << scene.surfaces[p.surface].name << " | "
            << Vec(p.position_W, 2) << " | " << Vec(p.look_at_W, 2) << " | "
            << Fixed(d.seen_voxels[c] * g.VoxelVolume(), 2) << " | "
            << (std::isfinite(d.fov_m3[c]) ? Fixed(d.fov_m3[c], 2) : std::string("-")) << " |\n";
      }
      const std::string key = d.layout->key;
      out << "\n![coverage, top view](" << key << "_coverage_top.png)\n";
      out << "![coverage slices](" << key << "_slices.png)\n";
      out << "![free space around a sample person](" << key << "_free.png)\n";
      out << "![frusta](" << key << "_frusta.png)\n\n";
    }
    out << "\"seen, exact\" is the camera's exact field-of-view volume in the cell behind the "
           "obstacles (hg::placement_fov); the voxel figure counts only whole voxels seen "
           "in full, so it is smaller.\n";
    if (!out) throw ConfigError::At((root / "report.md").string(), 0, "cannot write");
  }
}

}  // namespace hg::placement
