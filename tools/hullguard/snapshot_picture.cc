#include "hullguard/snapshot_picture.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <string>

#include <Eigen/Geometry>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "common/config_error.h"

namespace hg::tools {
namespace {

cv::Scalar HeightColour(double t01) {
  const double t = std::clamp(t01, 0.0, 1.0);
  return {40 + 60 * (1 - t), 40 + 80 * t, 140 + 115 * t};  // BGR: dark red -> light orange.
}

// A virtual pinhole looking at the cell from above one corner.
struct ViewCamera {
  Eigen::Matrix3d R;  // World -> camera.
  Eigen::Vector3d centre;
  double f = 1.0;
  cv::Point2d offset;
  [[nodiscard]] Eigen::Vector3d ToCamera(const Eigen::Vector3d& p) const {
    return R * (p - centre);
  }
  [[nodiscard]] cv::Point Project(const Eigen::Vector3d& p) const {
    const Eigen::Vector3d c = ToCamera(p);
    return {static_cast<int>(std::lround(offset.x + f * c.x() / c.z())),
            static_cast<int>(std::lround(offset.y + f * c.y() / c.z()))};
  }
};

ViewCamera MakeViewCamera(const common::Box3& b, int size_px, cv::Point2d origin) {
  const Eigen::Vector3d size = b.Size();
  const Eigen::Vector3d target = b.min + Eigen::Vector3d(0.5, 0.5, 0.3).cwiseProduct(size);
  const Eigen::Vector3d eye =
      b.min + Eigen::Vector3d(-0.55, -0.85, 1.6).cwiseProduct(size.cwiseMax(1e-6));
  const Eigen::Vector3d z = (target - eye).normalized();
  const Eigen::Vector3d x = z.cross(Eigen::Vector3d::UnitZ()).normalized();
  const Eigen::Vector3d y = z.cross(x);
  ViewCamera cam;
  cam.R.row(0) = x.transpose();
  cam.R.row(1) = y.transpose();
  cam.R.row(2) = z.transpose();
  cam.centre = eye;
  // Fit the cell's corners into the panel.
  double extent = 1e-9;
  for (int i = 0; i < 8; ++i) {
    const Eigen::Vector3d p((i & 1) ? b.max.x() : b.min.x(), (i & 2) ? b.max.y() : b.min.y(),
                            (i & 4) ? b.max.z() : b.min.z());
    const Eigen::Vector3d c = cam.ToCamera(p);
    extent = std::max({extent, std::abs(c.x() / c.z()), std::abs(c.y() / c.z())});
  }
  cam.f = 0.46 * size_px / extent;
  cam.offset = origin + cv::Point2d(size_px / 2.0, size_px / 2.0);
  return cam;
}

/// Tracks over the three views: the ellipse of each track's ellipsoid in the
/// top and side views (it is axis-aligned), the convex outline of its
/// projected surface in the perspective view, the id next to each.
template <typename TopFn, typename SideFn>
void DrawTracks(const std::vector<SnapshotTrack>& tracks, TopFn top, SideFn side,
                const ViewCamera& view, double px_per_m, cv::Mat* img) {
  const cv::Scalar colour(200, 0, 200);
  for (const SnapshotTrack& t : tracks) {
    const int thickness = t.occluded ? 1 : 2;
    const Eigen::Vector3d& c = t.centre_W;
    const Eigen::Vector3d& h = t.half_axes_m;
    // Appended, not "#" + ...: GCC 12 warns (-Wrestrict) about the operator+ form.
    const std::string label = std::string("#").append(std::to_string(t.id));
    auto axes = [&](double a, double b) {
      return cv::Size(std::max(1, static_cast<int>(std::lround(a * px_per_m))),
                      std::max(1, static_cast<int>(std::lround(b * px_per_m))));
    };
    auto put_label = [&](cv::Point at) {
      cv::putText(*img, label, at, cv::FONT_HERSHEY_SIMPLEX, 0.5, colour, 1 + (thickness > 1));
    };
    cv::ellipse(*img, top(c.x(), c.y()), axes(h.x(), h.y()), 0, 0, 360, colour, thickness,
                cv::LINE_AA);
    const Eigen::Vector3d ahead = c + 0.5 * t.velocity_W_mps;
    if ((ahead - c).head<2>().norm() * px_per_m >= 3) {
      cv::arrowedLine(*img, top(c.x(), c.y()), top(ahead.x(), ahead.y()), colour, 1, cv::LINE_AA);
    }
    put_label(top(c.x() + h.x(), c.y() + h.y()));
    cv::ellipse(*img, side(c.x(), c.z()), axes(h.x(), h.z()), 0, 0, 360, colour, thickness,
                cv::LINE_AA);
    put_label(side(c.x() + h.x(), c.z() + h.z()));
    // Perspective: surface points in front of the view camera, then their hull.
    std::vector<cv::Point> projected;
    constexpr int kAround = 32, kUp = 16;
    for (int i = 0; i <= kUp; ++i) {
      const double polar = std::numbers::pi * i / kUp;
      for (int j = 0; j < kAround; ++j) {
        const double azimuth = 2 * std::numbers::pi * j / kAround;
        const Eigen::Vector3d p = c + h.cwiseProduct(Eigen::Vector3d(
                                          std::sin(polar) * std::cos(azimuth),
                                          std::sin(polar) * std::sin(azimuth), std::cos(polar)));
        if (view.ToCamera(p).z() > 0.05) projected.push_back(view.Project(p));
      }
    }
    if (projected.size() < 3) continue;
    std::vector<cv::Point> hull;
    cv::convexHull(projected, hull);
    cv::polylines(*img, hull, true, colour, thickness, cv::LINE_AA);
    if (view.ToCamera(c + Eigen::Vector3d(0, 0, h.z())).z() > 0.05) {
      put_label(view.Project(c + Eigen::Vector3d(0, 0, h.z())) + cv::Point(4, -4));
    }
  }
}

}  // namespace

std::vector<SnapshotBox> LeafBoxes(const octree::Octree& tree) {
  std::vector<SnapshotBox> boxes;
  const common::Box3& b = tree.config().bounds;
  tree.ForEachLeaf([&](const octree::Cell& c, octree::LeafState s) {
    if (s != octree::LeafState::kFree) {
      boxes.push_back({octree::CellBox(b, c), s == octree::LeafState::kOccupied});
    }
  });
  return boxes;
}

void WriteSnapshotPicture(const std::vector<SnapshotBox>& input, const common::Box3& b,
                          const std::vector<geometry::CameraModel>& cameras,
                          const std::vector<geometry::TriangleMesh>& obstacles,
                          const std::string& caption, const std::string& path,
                          const std::vector<SnapshotTrack>& tracks) {
  const Eigen::Vector3d size = b.Size();
  const double px_per_m = 520.0 / std::max(size.x(), size.y());
  const int margin = 40;
  const int top_w = static_cast<int>(size.x() * px_per_m),
            top_h = static_cast<int>(size.y() * px_per_m);
  const int side_h = static_cast<int>(size.z() * px_per_m);
  const int persp = std::max(top_h, side_h);
  cv::Mat img(persp + 2 * margin + 40, 2 * top_w + persp + 4 * margin, CV_8UC3,
              cv::Scalar(255, 255, 255));
  auto top = [&](double x, double y) {
    return cv::Point(margin + static_cast<int>((x - b.min.x()) * px_per_m),
                     margin + 30 + top_h - static_cast<int>((y - b.min.y()) * px_per_m));
  };
  auto side = [&](double x, double z) {
    return cv::Point(2 * margin + top_w + static_cast<int>((x - b.min.x()) * px_per_m),
                     margin + 30 + side_h - static_cast<int>((z - b.min.z()) * px_per_m));
  };
  const ViewCamera view =
      MakeViewCamera(b, persp, cv::Point2d(3 * margin + 2 * top_w, margin + 30));

  std::vector<SnapshotBox> boxes = input;
  const cv::Scalar occluded(215, 215, 215);
  // Occluded space in the top view only up to a person's height: the space
  // above the cameras is occluded too and would grey out the whole view.
  const double top_occluded_below = b.min.z() + std::min(2.0, size.z());
  for (const SnapshotBox& l : boxes) {
    if (l.occupied) continue;
    if (l.box.min.z() < top_occluded_below) {
      cv::rectangle(img, top(l.box.min.x(), l.box.max.y()), top(l.box.max.x(), l.box.min.y()),
                    occluded, cv::FILLED);
    }
    cv::rectangle(img, side(l.box.min.x(), l.box.max.z()), side(l.box.max.x(), l.box.min.z()),
                  occluded, cv::FILLED);
  }
  std::erase_if(boxes, [](const SnapshotBox& l) { return !l.occupied; });
  // Top and side: painted far to near so that the nearest wins.
  std::sort(boxes.begin(), boxes.end(), [](const SnapshotBox& a, const SnapshotBox& l) {
    return a.box.max.z() < l.box.max.z();
  });
  for (const SnapshotBox& l : boxes) {
    cv::rectangle(img, top(l.box.min.x(), l.box.max.y()), top(l.box.max.x(), l.box.min.y()),
                  HeightColour((l.box.max.z() - b.min.z()) / size.z()), cv::FILLED);
  }
  std::sort(boxes.begin(), boxes.end(), [](const SnapshotBox& a, const SnapshotBox& l) {
    return a.box.min.y() > l.box.min.y();
  });
  for (const SnapshotBox& l : boxes) {
    cv::rectangle(img, side(l.box.min.x(), l.box.max.z()), side(l.box.max.x(), l.box.min.z()),
                  HeightColour((b.max.y() - l.box.min.y()) / size.y()), cv::FILLED);
  }

  // Perspective: the floor, then cubes far to near, three visible faces each
  // shaded by their orientation and tinted by height.
  auto corner = [](const common::Box3& box, int i) {
    return Eigen::Vector3d((i & 1) ? box.max.x() : box.min.x(), (i & 2) ? box.max.y() : box.min.y(),
                           (i & 4) ? box.max.z() : box.min.z());
  };
  {
    std::array<cv::Point, 4> floor = {view.Project(corner(b, 0)), view.Project(corner(b, 1)),
                                      view.Project(corner(b, 3)), view.Project(corner(b, 2))};
    cv::fillConvexPoly(img, floor.data(), 4, cv::Scalar(240, 240, 240));
  }
  std::sort(boxes.begin(), boxes.end(), [&](const SnapshotBox& a, const SnapshotBox& l) {
    return (view.centre - 0.5 * (a.box.min + a.box.max)).squaredNorm() >
           (view.centre - 0.5 * (l.box.min + l.box.max)).squaredNorm();
  });
  // Faces as corner index quadruples with their outward normals.
  struct Face {
    std::array<int, 4> c;
    Eigen::Vector3d n;
  };
  const std::array<Face, 6> faces = {{{{0, 2, 6, 4}, -Eigen::Vector3d::UnitX()},
                                      {{1, 3, 7, 5}, Eigen::Vector3d::UnitX()},
                                      {{0, 1, 5, 4}, -Eigen::Vector3d::UnitY()},
                                      {{2, 3, 7, 6}, Eigen::Vector3d::UnitY()},
                                      {{0, 1, 3, 2}, -Eigen::Vector3d::UnitZ()},
                                      {{4, 5, 7, 6}, Eigen::Vector3d::UnitZ()}}};
  const Eigen::Vector3d light = Eigen::Vector3d(0.3, -0.5, 1.0).normalized();
  for (const SnapshotBox& l : boxes) {
    const cv::Scalar base = HeightColour((l.box.max.z() - b.min.z()) / size.z());
    for (const Face& face : faces) {
      const Eigen::Vector3d on_face = corner(l.box, face.c[0]);
      if (face.n.dot(view.centre - on_face) <= 0) continue;  // Back face.
      std::array<cv::Point, 4> q;
      for (int k = 0; k < 4; ++k) q[k] = view.Project(corner(l.box, face.c[k]));
      const double shade = 0.55 + 0.45 * std::max(0.0, face.n.dot(light));
      cv::fillConvexPoly(img, q.data(), 4, base * shade);
    }
  }
  auto draw_box_edges = [&](const common::Box3& box, const cv::Scalar& colour) {
    for (int i = 0; i < 8; ++i) {
      for (int axis = 0; axis < 3; ++axis) {
        const int j = i | (1 << axis);
        if (j != i)
          cv::line(img, view.Project(corner(box, i)), view.Project(corner(box, j)), colour);
      }
    }
  };
  draw_box_edges(b, cv::Scalar(0, 0, 0));

  for (const auto& mesh : obstacles) {
    for (const auto& t : mesh.triangles) {
      for (int k = 0; k < 3; ++k) {
        const Eigen::Vector3d& p = mesh.vertices[t[k]];
        const Eigen::Vector3d& q = mesh.vertices[t[(k + 1) % 3]];
        cv::line(img, top(p.x(), p.y()), top(q.x(), q.y()), cv::Scalar(0, 120, 0), 1);
        cv::line(img, side(p.x(), p.z()), side(q.x(), q.z()), cv::Scalar(0, 120, 0), 1);
        cv::line(img, view.Project(p), view.Project(q), cv::Scalar(0, 120, 0), 1);
      }
    }
  }
  cv::rectangle(img, top(b.min.x(), b.max.y()), top(b.max.x(), b.min.y()), cv::Scalar(0, 0, 0), 1);
  cv::rectangle(img, side(b.min.x(), b.max.z()), side(b.max.x(), b.min.z()), cv::Scalar(0, 0, 0),
                1);
  for (const auto& cam : cameras) {
    const Eigen::Vector3d c = cam.CentreW();
    cv::circle(img, top(c.x(), c.y()), 6, cv::Scalar(200, 80, 0), cv::FILLED);
    cv::circle(img, side(c.x(), c.z()), 6, cv::Scalar(200, 80, 0), cv::FILLED);
    if (view.ToCamera(c).z() > 0.1) {
      cv::circle(img, view.Project(c), 6, cv::Scalar(200, 80, 0), cv::FILLED);
    }
  }
  DrawTracks(tracks, top, side, view, px_per_m, &img);
  const cv::Scalar black(0, 0, 0);
  cv::putText(img, "top view (x right, y up)", cv::Point(margin, margin + 18),
              cv::FONT_HERSHEY_SIMPLEX, 0.5, black, 1);
  cv::putText(img, "side view (x right, z up)", cv::Point(2 * margin + top_w, margin + 18),
              cv::FONT_HERSHEY_SIMPLEX, 0.5, black, 1);
  cv::putText(img, "perspective", cv::Point(3 * margin + 2 * top_w, margin + 18),
              cv::FONT_HERSHEY_SIMPLEX, 0.5, black, 1);
  // The legend names only what this picture draws.
  std::string legend = "red to orange: occupied (by height), grey: occluded (top view: below 2 m)";
  if (!obstacles.empty()) legend += ", green: obstacles";
  if (!cameras.empty()) legend += ", blue: cameras";
  legend += tracks.empty() ? ". " : ", magenta: tracks (#id). ";
  cv::putText(img, legend + caption, cv::Point(margin, img.rows - 14), cv::FONT_HERSHEY_SIMPLEX,
              0.5, black, 1);
  bool ok = false;
  try {
    ok = cv::imwrite(path, img);
  } catch (const cv::Exception&) {
    ok = false;
  }
  if (!ok) throw common::ConfigError(path + ": cannot write image");
}

}  // namespace hg::tools
