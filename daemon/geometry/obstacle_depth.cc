#include "geometry/obstacle_depth.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <utility>

#include <Eigen/Geometry>

#include "common/check.h"
#include "geometry/footprint.h"

namespace hg::geometry {
namespace {

/// Near clipping plane (camera z, metres). Obstacle parts closer than this to the
/// camera centre would sit inside the lens housing, which no real cell can have;
/// clipping them keeps every projected coordinate finite.
constexpr double kNearPlaneM = 1e-3;

/// Relative error budget of the double arithmetic below. Each bound needs only a
/// handful of operations (a few machine epsilons, ~1e-16 each); 1e-12 leaves
/// orders of magnitude of headroom while costing nothing measurable in depth.
constexpr double kTol = 1e-12;

/// Extra relative shrink of every near-depth bound. It absorbs the rounding of
/// the world -> camera transform (computed relative to the camera centre, here
/// and in the octree's footprints, so its error is a few ulps of the distance
/// from the camera, not of the scene coordinates) and stays far below the
/// 1e-5 m scale at which depth comparisons matter.
constexpr double kDepthMargin = 1e-9;

/// Relative tolerance of the pixel coverage tests; it only ever adds pixels.
constexpr double kCoverTol = 1e-9;

/// Converts to float rounding towards -infinity so the stored value is never
/// above the double lower bound it came from.
float FloatDown(double d) {
  float f = static_cast<float>(d);
  if (static_cast<double>(f) > d) f = std::nextafter(f, -std::numeric_limits<float>::infinity());
  return f;
}

/// Pinhole intrinsics read straight from K (K(2,2) == 1, K(1,0) == K(2,0) == K(2,1) == 0).
struct Intrinsics {
  double fx, fy, skew, cx, cy;

  explicit Intrinsics(const Eigen::Matrix3d& K)
      : fx(K(0, 0)), fy(K(1, 1)), skew(K(0, 1)), cx(K(0, 2)), cy(K(1, 2)) {}

  /// Precondition: p_C.z() > 0.
  [[nodiscard]] Eigen::Vector2d Project(const Eigen::Vector3d& p_C) const {
    const double x = p_C.x() / p_C.z();
    const double y = p_C.y() / p_C.z();
    return {fx * x + skew * y + cx, fy * y + cy};
  }
};

/// Plane of one obstacle triangle in the camera frame, n . p_C = d with d >= 0,
/// plus the magnitudes needed to bound the rounding error of 1/z evaluated on it.
///
/// Why 1/z: a camera ray through pixel point (u, v) is p_C = z * (xn, yn, 1) with
/// (xn, yn) = K^-1 (u, v, 1) affine in (u, v). On the plane n . p_C = d this gives
/// 1/z = (n0 xn + n1 yn + n2) / d, an affine function of (u, v).
struct InvDepthPlane {
  Eigen::Vector3d n;
  double d = 0;
  double n_mag = 0;  // |e1| |e2|: bounds |n| and the scale of its rounding error.
  double d_mag = 0;  // Scale of the rounding error of d.
  bool valid = false;

  InvDepthPlane(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Eigen::Vector3d& p2) {
    const Eigen::Vector3d e1 = p1 - p0;
    const Eigen::Vector3d e2 = p2 - p0;
    n = e1.cross(e2);
    d = n.dot(p0);
    n_mag = e1.norm() * e2.norm();
    d_mag = n_mag * p0.lpNorm<1>();
    if (d < 0) {
      n = -n;
      d = -d;
    }
    // A plane through the camera centre (triangle seen edge-on) gives no 1/z bound.
    valid = d > 0 && std::isfinite(d);
  }

  /// Upper bound of 1/z on the plane along the ray through pixel point (u, v).
  [[nodiscard]] double InvDepthUpper(const Intrinsics& k, double u, double v) const {
    const double yn = (v - k.cy) / k.fy;
    const double xn = (u - k.cx - k.skew * yn) / k.fx;
    // Magnitudes of the terms that were summed, to scale their rounding error.
    const double yn_abs = (std::abs(v) + std::abs(k.cy)) / std::abs(k.fy);
    const double xn_abs =
        (std::abs(u) + std::abs(k.cx) + std::abs(k.skew) * yn_abs) / std::abs(k.fx);
    const double inv = (n.x() * xn + n.y() * yn + n.z()) / d;
    const double err = kTol *
                       ((std::abs(n.x()) + n_mag) * xn_abs + (std::abs(n.y()) + n_mag) * yn_abs +
                        std::abs(n.z()) + n_mag + std::abs(inv) * d_mag) /
                       d;
    return inv + err;
  }
};

/// Clips a triangle (camera frame) against z >= kNearPlaneM (Sutherland-Hodgman
/// for one plane). Returns the number of polygon vertices written (0, 3 or 4).
int ClipNear(const std::array<Eigen::Vector3d, 3>& tri, std::array<Eigen::Vector3d, 4>* out) {
  int count = 0;
  for (int i = 0; i < 3; ++i) {
    const Eigen::Vector3d& a = tri[i];
    const Eigen::Vector3d& b = tri[(i + 1) % 3];
    const bool a_in = a.z() >= kNearPlaneM;
    const bool b_in = b.z() >= kNearPlaneM;
    if (a_in) (*out)[count++] = a;
    if (a_in != b_in) {
      const double t = (kNearPlaneM - a.z()) / (b.z() - a.z());
      Eigen::Vector3d p = a + t * (b - a);
      p.z() = kNearPlaneM;  // Exactly on the plane despite rounding.
      (*out)[count++] = p;
    }
  }
  return count;
}

/// The point of triangle abc nearest to the origin (Ericson, Real-Time
/// Collision Detection, 5.1.5: by the Voronoi region of the origin).
Eigen::Vector3d NearestToOrigin(const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = -a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Eigen::Vector3d bp = -b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + d1 / (d1 - d3) * ab;
  const Eigen::Vector3d cp = -c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + d2 / (d2 - d6) * ac;
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    return b + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (c - b);
  }
  const double denom = va + vb + vc;
  if (!(denom > 0)) {  // Degenerate (a segment or a point): the nearest corner.
    const Eigen::Vector3d* best = &a;
    if (b.squaredNorm() < best->squaredNorm()) best = &b;
    if (c.squaredNorm() < best->squaredNorm()) best = &c;
    return *best;
  }
  return a + ab * (vb / denom) + ac * (vc / denom);
}

/// Inclusive pixel index range [lo, hi] of the pixels whose squares may touch
/// the coordinate interval [min, max]; empty (lo > hi) when outside [0, size).
std::pair<int, int> PixelRange(double min, double max, double slack, int size) {
  const double lo = std::ceil(min - 0.5 - slack);
  const double hi = std::floor(max + 0.5 + slack);
  if (hi < 0 || lo > size - 1) return {1, 0};
  return {static_cast<int>(std::max(lo, 0.0)),
          static_cast<int>(std::min(hi, static_cast<double>(size - 1)))};
}

/// The part of a camera's view within the near plane: a ball around the
/// camera centre whose radius is the near plane's distance along the longest
/// ray through a corner of the image (one pixel beyond it). A triangle in
/// front of the camera that reaches into it blocks the view.
class NearBall {
 public:
  explicit NearBall(const CameraModel& camera) {
    const Eigen::Matrix3d k_inv = camera.K.inverse();
    double longest = 1.0;
    for (const double u : {-1.5, camera.width + 0.5}) {
      for (const double v : {-1.5, camera.height + 0.5}) {
        const Eigen::Vector3d ray = k_inv * Eigen::Vector3d(u, v, 1.0);
        longest = std::max(longest, ray.norm() / ray.z());
      }
    }
    radius_ = kNearPlaneM * longest * (1.0 + 1e-6);
  }

  [[nodiscard]] bool Blocks(const std::array<Eigen::Vector3d, 3>& tri_C) const {
    return std::max({tri_C[0].z(), tri_C[1].z(), tri_C[2].z()}) > 0.0 &&
           NearestToOrigin(tri_C[0], tri_C[1], tri_C[2]).norm() < radius_;
  }

 private:
  double radius_ = 0.0;
};

/// The meshes' vertices in the camera frame, one mesh at a time, computed
/// relative to the camera centre (as the octree's footprints are): R p + t
/// directly cancels terms of the size of the coordinates, an error of 1e-10 m
/// a million metres out, above the depth margin of an obstacle a few
/// centimetres from the lens.
class ToCamera {
 public:
  explicit ToCamera(const CameraModel& camera) : rigid_(Rigid(camera)) {}

  /// Calls triangle({a_C, b_C, c_C}) for every triangle of the meshes.
  template <typename F>
  void ForEachTriangle(const std::vector<TriangleMesh>& meshes, F&& triangle) {
    for (const TriangleMesh& mesh : meshes) {
      vertices_C_.clear();
      vertices_C_.reserve(mesh.vertices.size());
      for (const Eigen::Vector3d& p_W : mesh.vertices) {
        vertices_C_.push_back(rigid_.Homogeneous(p_W));
      }
      const int vertex_count = static_cast<int>(vertices_C_.size());
      for (const auto& t : mesh.triangles) {
        HG_CHECK(t[0] >= 0 && t[0] < vertex_count && t[1] >= 0 && t[1] < vertex_count &&
                 t[2] >= 0 && t[2] < vertex_count);
        triangle(std::array<Eigen::Vector3d, 3>{vertices_C_[t[0]], vertices_C_[t[1]],
                                                vertices_C_[t[2]]});
      }
    }
  }

 private:
  static BoxProjector Rigid(const CameraModel& camera) {
    Eigen::Matrix<double, 3, 4> rigid;
    rigid.leftCols<3>() = camera.R_CW;
    rigid.col(3) = camera.t_CW;
    return BoxProjector(rigid);
  }

  BoxProjector rigid_;
  std::vector<Eigen::Vector3d> vertices_C_;
};

class Rasteriser {
 public:
  Rasteriser(const CameraModel& camera, ObstacleDepthMap* map)
      : k_(camera.K), width_(camera.width), height_(camera.height), map_(map), near_(camera) {}

  /// Whether a triangle came so close in front of the camera that the part of
  /// it clipped at the near plane may be in view (an obstacle inside the lens
  /// housing, or a mesh through the camera centre).
  [[nodiscard]] bool blocked() const { return blocked_; }

  void Triangle(const std::array<Eigen::Vector3d, 3>& tri_C) {
    if (!blocked_ && near_.Blocks(tri_C)) blocked_ = true;
    std::array<Eigen::Vector3d, 4> poly;
    const int count = ClipNear(tri_C, &poly);
    if (count < 3) return;
    const InvDepthPlane plane(tri_C[0], tri_C[1], tri_C[2]);
    for (int i = 1; i + 1 < count; ++i) {
      const std::array<Eigen::Vector3d, 3> part = {poly[0], poly[i], poly[i + 1]};
      const std::array<Eigen::Vector2d, 3> uv = {k_.Project(part[0]), k_.Project(part[1]),
                                                 k_.Project(part[2])};
      Conservative(part, uv, plane);
      Centres(part, uv);
    }
  }

 private:
  /// near_depth: every pixel whose square touches the projected triangle gets a
  /// lower bound of the triangle's camera z over that square.
  ///
  /// Why the bound holds: every triangle point seen through the square lies on the
  /// triangle's plane, where 1/z is affine in (u, v) (see InvDepthPlane). An affine
  /// function on a square is largest at a corner, so 1/z <= max over the corners,
  /// i.e. z >= 1 / max_corner_inv_z whenever that maximum is positive. Independently,
  /// z is affine along the (clipped) triangle in 3D, so z >= its smallest vertex z.
  /// Both are lower bounds; the larger one is kept. Rounding is covered by the
  /// error terms of InvDepthUpper, kDepthMargin and rounding down to float.
  void Conservative(const std::array<Eigen::Vector3d, 3>& p,
                    const std::array<Eigen::Vector2d, 3>& uv, const InvDepthPlane& plane) {
    const double min_z = std::min({p[0].z(), p[1].z(), p[2].z()});
    const double min_u = std::min({uv[0].x(), uv[1].x(), uv[2].x()});
    const double max_u = std::max({uv[0].x(), uv[1].x(), uv[2].x()});
    const double min_v = std::min({uv[0].y(), uv[1].y(), uv[2].y()});
    const double max_v = std::max({uv[0].y(), uv[1].y(), uv[2].y()});
    const double scale =
        1.0 + std::max({std::abs(min_u), std::abs(max_u), std::abs(min_v), std::abs(max_v),
                        static_cast<double>(width_), static_cast<double>(height_)});
    const double slack = kCoverTol * scale;
    const auto [u0, u1] = PixelRange(min_u, max_u, slack, width_);
    const auto [v0, v1] = PixelRange(min_v, max_v, slack, height_);
    if (u0 > u1 || v0 > v1) return;

    // Separating-axis test, triangle edge normals (the two image axes are the
    // pixel range above). For each edge normal the triangle covers the interval
    // [lo, hi]; the pixel square covers centre +- radius. Disjoint by more than
    // the slack means the square misses the triangle.
    struct Axis {
      Eigen::Vector2d n;
      double lo, hi, radius, slack;
    };
    std::array<Axis, 3> axes;
    for (int i = 0; i < 3; ++i) {
      const Eigen::Vector2d& a = uv[i];
      const Eigen::Vector2d& b = uv[(i + 1) % 3];
      const Eigen::Vector2d& c = uv[(i + 2) % 3];
      Axis& axis = axes[i];
      axis.n = Eigen::Vector2d(a.y() - b.y(), b.x() - a.x());
      const double on_edge = axis.n.dot(a);
      const double opposite = axis.n.dot(c);
      axis.lo = std::min(on_edge, opposite);
      axis.hi = std::max(on_edge, opposite);
      const double n_abs = axis.n.lpNorm<1>();
      axis.radius = 0.5 * n_abs;
      axis.slack = kCoverTol * n_abs * scale;
    }

    for (int v = v0; v <= v1; ++v) {
      for (int u = u0; u <= u1; ++u) {
        const Eigen::Vector2d centre(u, v);
        bool separated = false;
        for (const Axis& axis : axes) {
          const double c = axis.n.dot(centre);
          if (c + axis.radius < axis.lo - axis.slack || c - axis.radius > axis.hi + axis.slack) {
            separated = true;
            break;
          }
        }
        if (separated) continue;

        double bound = min_z;
        if (plane.valid) {
          double max_inv = -std::numeric_limits<double>::infinity();
          for (const double du : {-0.5, 0.5}) {
            for (const double dv : {-0.5, 0.5}) {
              max_inv = std::max(max_inv, plane.InvDepthUpper(k_, u + du, v + dv));
            }
          }
          if (max_inv > 0) bound = std::max(bound, 1.0 / max_inv);
        }
        const float depth = FloatDown(bound * (1.0 - kDepthMargin));
        float& cell = map_->near_depth[static_cast<size_t>(v) * width_ + u];
        cell = std::min(cell, depth);
      }
    }
  }

  /// centre_depth: ordinary rasterisation at pixel centres with perspective-correct
  /// depth (1/z interpolated linearly in the image); nearest surface wins.
  void Centres(const std::array<Eigen::Vector3d, 3>& p, const std::array<Eigen::Vector2d, 3>& uv) {
    const Eigen::Vector2d e1 = uv[1] - uv[0];
    const Eigen::Vector2d e2 = uv[2] - uv[0];
    const double area = e1.x() * e2.y() - e1.y() * e2.x();
    if (area == 0 || !std::isfinite(area)) return;
    const double min_u = std::min({uv[0].x(), uv[1].x(), uv[2].x()});
    const double max_u = std::max({uv[0].x(), uv[1].x(), uv[2].x()});
    const double min_v = std::min({uv[0].y(), uv[1].y(), uv[2].y()});
    const double max_v = std::max({uv[0].y(), uv[1].y(), uv[2].y()});
    // Pixel centres (integers) inside [min, max]: reuse PixelRange without the half pixel.
    const auto [u0, u1] = PixelRange(min_u + 0.5, max_u - 0.5, 0.0, width_);
    const auto [v0, v1] = PixelRange(min_v + 0.5, max_v - 0.5, 0.0, height_);
    const std::array<double, 3> inv_z = {1.0 / p[0].z(), 1.0 / p[1].z(), 1.0 / p[2].z()};
    for (int v = v0; v <= v1; ++v) {
      for (int u = u0; u <= u1; ++u) {
        // Barycentric weights from signed sub-areas, normalised by the full area
        // so that the sign convention of the triangle does not matter.
        std::array<double, 3> w;
        bool inside = true;
        for (int i = 0; i < 3; ++i) {
          const Eigen::Vector2d& a = uv[(i + 1) % 3];
          const Eigen::Vector2d& b = uv[(i + 2) % 3];
          w[i] = ((b.x() - a.x()) * (v - a.y()) - (b.y() - a.y()) * (u - a.x())) / area;
          if (w[i] < 0) {
            inside = false;
            break;
          }
        }
        if (!inside) continue;
        const double inv = w[0] * inv_z[0] + w[1] * inv_z[1] + w[2] * inv_z[2];
        if (!(inv > 0)) continue;
        float& cell = map_->centre_depth[static_cast<size_t>(v) * width_ + u];
        cell = std::min(cell, static_cast<float>(1.0 / inv));
      }
    }
  }

  Intrinsics k_;
  int width_;
  int height_;
  ObstacleDepthMap* map_;
  NearBall near_;
  bool blocked_ = false;
};

}  // namespace

ObstacleDepthMap RenderObstacleDepth(const CameraModel& pinhole,
                                     const std::vector<TriangleMesh>& meshes) {
  HG_CHECK(pinhole.width > 0 && pinhole.height > 0);
  HG_CHECK(pinhole.K(0, 0) > 0 && pinhole.K(1, 1) > 0);
  ObstacleDepthMap map;
  map.width = pinhole.width;
  map.height = pinhole.height;
  const size_t pixels = static_cast<size_t>(map.width) * map.height;
  map.near_depth.assign(pixels, ObstacleDepthMap::kNone);
  map.centre_depth.assign(pixels, ObstacleDepthMap::kNone);

  Rasteriser rasteriser(pinhole, &map);
  ToCamera(pinhole).ForEachTriangle(
      meshes, [&](const std::array<Eigen::Vector3d, 3>& tri_C) { rasteriser.Triangle(tri_C); });
  // A camera enclosed by a mesh (its housing or mount modelled with the
  // obstacles) sees an obstacle within a hand's breadth at every pixel: it
  // could certify at most that shell around its lens free, and is as useless
  // as one with the mesh through its centre.
  const bool enclosed = *std::max_element(map.centre_depth.begin(), map.centre_depth.end()) <
                        ObstacleDepthMap::kEnclosedDepthM;
  if (rasteriser.blocked() || enclosed) {
    // What the near plane cut off could cover any pixel, at a depth down to
    // zero: nothing is certainly in front of it. Enclosed: certifying nothing
    // is as conservative as the shell.
    map.blocked = true;
    std::fill(map.near_depth.begin(), map.near_depth.end(), 0.0F);
  }
  return map;
}

DepthPyramid::DepthPyramid(const std::vector<float>& values, int width, int height, Kind kind)
    : kind_(kind) {
  HG_CHECK(width > 0 && height > 0);
  HG_CHECK(values.size() == static_cast<size_t>(width) * height);
  levels_.push_back(Level{width, height, values});
  const bool is_min = kind == Kind::kMin;
  while (levels_.back().width > 1 || levels_.back().height > 1) {
    const Level& child = levels_.back();
    Level parent;
    parent.width = (child.width + 1) / 2;
    parent.height = (child.height + 1) / 2;
    parent.values.resize(static_cast<size_t>(parent.width) * parent.height);
    for (int y = 0; y < parent.height; ++y) {
      const int cy0 = 2 * y;
      const int cy1 = std::min(2 * y + 1, child.height - 1);
      for (int x = 0; x < parent.width; ++x) {
        const int cx0 = 2 * x;
        const int cx1 = std::min(2 * x + 1, child.width - 1);
        const size_t row0 = static_cast<size_t>(cy0) * child.width;
        const size_t row1 = static_cast<size_t>(cy1) * child.width;
        const float a = child.values[row0 + cx0];
        const float b = child.values[row0 + cx1];
        const float c = child.values[row1 + cx0];
        const float d = child.values[row1 + cx1];
        parent.values[static_cast<size_t>(y) * parent.width + x] =
            is_min ? std::min({a, b, c, d}) : std::max({a, b, c, d});
      }
    }
    levels_.push_back(std::move(parent));
  }
}

namespace {

/// Decides "every pixel of rect satisfies the predicate" on a pyramid whose
/// aggregate respects it: all_ok(aggregate) holds iff every pixel below does
/// (min > z for a min pyramid, max < z for a max pyramid). Depth-first over the
/// levels with a fixed stack, so a query never allocates.
template <typename Levels, typename AllOk>
bool AllInRect(const Levels& levels, const PixelRect& rect, AllOk all_ok) {
  struct Entry {
    int level;
    int x;
    int y;
  };
  // Each pop pushes at most 4 children, a net growth of 3 per level descended;
  // int image sizes give at most 32 levels.
  constexpr int kStackSize = 3 * 32 + 2;
  std::array<Entry, kStackSize> stack;
  // Small rectangles (footprints of fine octree cells) are read pixel by pixel.
  if (static_cast<long long>(rect.u1 - rect.u0 + 1) * (rect.v1 - rect.v0 + 1) <= 16) {
    const auto& base = levels[0];
    for (int v = rect.v0; v <= rect.v1; ++v) {
      const float* row = base.values.data() + static_cast<size_t>(v) * base.width;
      for (int u = rect.u0; u <= rect.u1; ++u) {
        if (!all_ok(row[u])) return false;
      }
    }
    return true;
  }
  // One pixel that fails settles the answer: probing a corner first turns the
  // common negative answer into a single look-up.
  if (!all_ok(levels[0].values[static_cast<size_t>(rect.v0) * levels[0].width + rect.u0])) {
    return false;
  }
  int top = 0;
  const int top_level = static_cast<int>(levels.size()) - 1;
  HG_CHECK(top_level < 32);
  // Start at the finest level where the rect spans at most 2x2 elements rather
  // than at the root: the same answer, without the descent through coarse
  // elements whose aggregate mixes in far-away pixels.
  int start = 0;
  while (start < top_level && (((rect.u1 >> start) - (rect.u0 >> start)) > 1 ||
                               ((rect.v1 >> start) - (rect.v0 >> start)) > 1)) {
    ++start;
  }
  for (int y = rect.v1 >> start; y >= (rect.v0 >> start); --y) {
    for (int x = rect.u1 >> start; x >= (rect.u0 >> start); --x) stack[top++] = {start, x, y};
  }
  while (top > 0) {
    const Entry e = stack[--top];
    const auto& level = levels[e.level];
    if (all_ok(level.values[static_cast<size_t>(e.y) * level.width + e.x])) continue;
    // Pixels of this element, clipped to the image (int64: (x + 1) << level may
    // exceed int). Elements on the right and bottom borders have fewer pixels.
    const int64_t px0 = static_cast<int64_t>(e.x) << e.level;
    const int64_t py0 = static_cast<int64_t>(e.y) << e.level;
    const int64_t px1 =
        std::min<int64_t>((static_cast<int64_t>(e.x + 1) << e.level) - 1, levels[0].width - 1);
    const int64_t py1 =
        std::min<int64_t>((static_cast<int64_t>(e.y + 1) << e.level) - 1, levels[0].height - 1);
    // Every pixel of the element is in the rect and one of them fails: the answer
    // is known. Only elements that overlap the rect are ever pushed, so a pixel
    // (level 0) always ends here or in the accept branch above.
    if (px0 >= rect.u0 && px1 <= rect.u1 && py0 >= rect.v0 && py1 <= rect.v1) return false;
    const int child_level = e.level - 1;
    const auto& child = levels[child_level];
    for (int cy = 2 * e.y; cy <= 2 * e.y + 1 && cy < child.height; ++cy) {
      const int64_t cy0 = static_cast<int64_t>(cy) << child_level;
      const int64_t cy1 = (static_cast<int64_t>(cy + 1) << child_level) - 1;
      if (cy1 < rect.v0 || cy0 > rect.v1) continue;
      for (int cx = 2 * e.x; cx <= 2 * e.x + 1 && cx < child.width; ++cx) {
        const int64_t cx0 = static_cast<int64_t>(cx) << child_level;
        const int64_t cx1 = (static_cast<int64_t>(cx + 1) << child_level) - 1;
        if (cx1 < rect.u0 || cx0 > rect.u1) continue;
        stack[top++] = {child_level, cx, cy};
      }
    }
  }
  return true;
}

}  // namespace

bool DepthPyramid::AllGreater(const PixelRect& rect, double z) const {
  HG_CHECK(kind_ == Kind::kMin && !levels_.empty());
  HG_CHECK(!rect.Empty() && rect.u0 >= 0 && rect.v0 >= 0 && rect.u1 < levels_[0].width &&
           rect.v1 < levels_[0].height);
  return AllInRect(levels_, rect, [z](float min) { return min > z; });
}

bool DepthPyramid::AllLess(const PixelRect& rect, double z) const {
  HG_CHECK(kind_ == Kind::kMax && !levels_.empty());
  HG_CHECK(!rect.Empty() && rect.u0 >= 0 && rect.v0 >= 0 && rect.u1 < levels_[0].width &&
           rect.v1 < levels_[0].height);
  return AllInRect(levels_, rect, [z](float max) { return max < z; });
}

float DepthPyramid::Global() const {
  HG_CHECK(!levels_.empty());
  return levels_.back().values[0];
}

}  // namespace hg::geometry
