#include "scene/demo_cell.h"

#include <cmath>

namespace hg::scene {
namespace {

// A standing person at `base` (floor point) facing `heading`, gait phase `phase`.
void AddPerson(const Eigen::Vector3d& base, double heading, double phase, std::vector<Shape>* out) {
  const Eigen::Vector3d fwd(std::cos(heading), std::sin(heading), 0);
  const Eigen::Vector3d side(-fwd.y(), fwd.x(), 0);
  const Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
  const double swing = 0.35 * std::sin(phase);
  const Eigen::Vector3d hip = base + 0.95 * up;
  const Eigen::Vector3d neck = base + 1.45 * up;
  out->push_back(Capsule{hip, neck, 0.16});        // Torso.
  out->push_back(Sphere{base + 1.65 * up, 0.11});  // Head.
  for (int s = -1; s <= 1; s += 2) {
    const Eigen::Vector3d h = hip + 0.1 * s * side;
    const Eigen::Vector3d foot = base + 0.1 * s * side + 0.45 * s * swing * fwd + 0.06 * up;
    out->push_back(Capsule{h, foot, 0.075});  // Leg.
    const Eigen::Vector3d shoulder = neck - 0.05 * up + 0.22 * s * side;
    const Eigen::Vector3d hand = shoulder - 0.6 * up - 0.35 * s * swing * fwd + 0.05 * s * side;
    out->push_back(Capsule{shoulder, hand, 0.05});  // Arm.
  }
}

}  // namespace

geometry::CameraModel LookAtCamera(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
                                   int width, int height, double fx) {
  const Eigen::Vector3d forward = (target - eye).normalized();
  Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
  if (std::abs(forward.dot(up)) > 0.99) up = Eigen::Vector3d::UnitY();
  const Eigen::Vector3d right = forward.cross(up).normalized();
  const Eigen::Vector3d down = forward.cross(right);
  geometry::CameraModel cam;
  cam.width = width;
  cam.height = height;
  cam.K << fx, 0, (width - 1) / 2.0, 0, fx, (height - 1) / 2.0, 0, 0, 1;
  cam.R_CW.row(0) = right.transpose();
  cam.R_CW.row(1) = down.transpose();
  cam.R_CW.row(2) = forward.transpose();
  cam.t_CW = -cam.R_CW * eye;
  return cam;
}

DemoCell MakeDemoCell(const DemoCellOptions& options) {
  DemoCell cell;
  cell.bounds.min = Eigen::Vector3d(0, 0, 0);
  cell.bounds.max = Eigen::Vector3d(4, 4, 4);
  const Eigen::Vector3d centre(2, 2, 1.0);
  // Upper corners first (the classic layout), then wall centres lower down.
  const std::vector<Eigen::Vector3d> eyes = {{-0.3, -0.3, 3.6}, {4.3, 4.3, 3.6},  {4.3, -0.3, 3.6},
                                             {-0.3, 4.3, 3.6},  {2.0, -0.4, 2.6}, {2.0, 4.4, 2.6},
                                             {-0.4, 2.0, 2.6},  {4.4, 2.0, 2.6}};
  for (int i = 0; i < options.num_cameras && i < static_cast<int>(eyes.size()); ++i) {
    const double hfov_rad = i < 4 ? 1.45 : 1.55;
    geometry::CameraModel cam = LookAtCamera(eyes[i], centre, options.width, options.height,
                                             0.5 * options.width / std::tan(0.5 * hfov_rad));
    cam.name = "cam" + std::to_string(i);
    cell.cameras.push_back(cam);
  }
  if (options.obstacles) {
    // A table (top and four legs) and a rack against the wall.
    geometry::TriangleMesh table = geometry::TriangleMesh::Box({2.6, 0.6, 0.72}, {3.6, 1.4, 0.78});
    for (const double x : {2.65, 3.5}) {
      for (const double y : {0.65, 1.3}) {
        table.Append(geometry::TriangleMesh::Box({x, y, 0.0}, {x + 0.05, y + 0.05, 0.72}));
      }
    }
    cell.obstacles.push_back(table);
    cell.obstacles.push_back(geometry::TriangleMesh::Box({0.2, 3.3, 0.0}, {1.4, 3.8, 1.9}));
  }
  return cell;
}

std::vector<Shape> DemoPeople(int num_people, double t_s) {
  std::vector<Shape> shapes;
  for (int p = 0; p < num_people; ++p) {
    // Each person walks an ellipse of its own at ~1.2 m/s.
    const double rx = 1.1 - 0.2 * p, ry = 0.8 + 0.15 * p;
    const Eigen::Vector2d c(2.0 + 0.2 * p, 2.1 - 0.1 * p);
    const double perimeter = 2 * M_PI * std::sqrt(0.5 * (rx * rx + ry * ry));
    const double angle = 2 * M_PI * 1.2 * t_s / perimeter * (p % 2 == 0 ? 1 : -1) + 2.1 * p;
    const Eigen::Vector3d base(c.x() + rx * std::cos(angle), c.y() + ry * std::sin(angle), 0.0);
    const double dir = p % 2 == 0 ? 1.0 : -1.0;
    const double heading = std::atan2(dir * ry * std::cos(angle), -dir * rx * std::sin(angle));
    AddPerson(base, heading, 2 * M_PI * 0.9 * t_s + p, &shapes);
  }
  return shapes;
}

}  // namespace hg::scene
