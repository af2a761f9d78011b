#include "scene/exact_mask.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <limits>
#include <optional>

#include <Eigen/Geometry>
#include <Eigen/LU>

#include "common/check.h"

namespace hg::scene {
namespace {

using Eigen::Matrix2d;
using Eigen::Matrix3d;
using Eigen::Vector2d;
using Eigen::Vector3d;

// Gap, relative to the size of the scene seen by one pixel, that a separating
// plane must clear before a pixel is called background. Anything closer counts
// as touching, so the tolerance only ever adds foreground.
constexpr double kRelativeTolerance = 1e-9;
// GJK stops refining once its upper and lower distance bounds agree this well.
constexpr double kGjkRelativeConvergence = 1e-6;
// GJK gives up (and reports "touching", the conservative answer) after this.
constexpr int kGjkMaxIterations = 96;
// A barycentric weight this far below zero still counts as inside a face; it
// only affects how fast GJK converges, never what it certifies.
constexpr double kBarycentricSlack = 1e-12;
// Boundary samples per pixel edge when undistorting a pixel square.
constexpr int kSamplesPerEdge = 16;
// Slack added to the polygon margin for the Newton residual: a residual of
// 1e-12 in distorted coordinates moves the solution by 1e-12 * |J^-1|, far
// below this for any lens whose Jacobian is not nearly singular.
constexpr double kUndistortSlack = 1e-9;

/// A shape seen from the camera frame C.
class ShapeInCamera {
 public:
  ShapeInCamera(const Shape& shape, const geometry::CameraModel& camera)
      : shape_(shape), R_CW_(camera.R_CW), t_CW_(camera.t_CW) {}

  [[nodiscard]] Vector3d Support(const Vector3d& d_C) const {
    return R_CW_ * scene::Support(shape_, R_CW_.transpose() * d_C) + t_CW_;
  }
  [[nodiscard]] Vector3d ToCamera(const Vector3d& p_W) const { return R_CW_ * p_W + t_CW_; }
  [[nodiscard]] bool ContainsC(const Vector3d& p_C) const {
    return Contains(shape_, R_CW_.transpose() * (p_C - t_CW_));
  }

 private:
  const Shape& shape_;
  Matrix3d R_CW_;
  Vector3d t_CW_;
};

/// Truncated viewing pyramid: the camera centre (origin of C) and the far
/// cross-section far * (x_i, y_i, 1) over a convex polygon of normalised
/// image coordinates. Support is the best of its vertices.
class Pyramid {
 public:
  void Set(const std::vector<Vector2d>& polygon_xy, double far) {
    polygon_ = &polygon_xy;
    far_ = far;
  }

  [[nodiscard]] Vector3d Support(const Vector3d& d) const {
    double best = 0.0;  // The apex, at the origin.
    const Vector2d* best_xy = nullptr;
    for (const Vector2d& xy : *polygon_) {
      const double s = d.x() * xy.x() + d.y() * xy.y() + d.z();
      if (s * far_ > best) {
        best = s * far_;
        best_xy = &xy;
      }
    }
    if (best_xy == nullptr) return Vector3d::Zero();
    return far_ * Vector3d(best_xy->x(), best_xy->y(), 1.0);
  }

 private:
  const std::vector<Vector2d>* polygon_ = nullptr;
  double far_ = 1.0;
};

/// Up to four points of the Minkowski difference A - B.
struct Simplex {
  std::array<Vector3d, 4> p;
  int n = 0;
};

// Closest point to the origin on the affine hull of q[0..M] when it lies in the
// face (all barycentric weights >= 0); false otherwise or for a flat face.
template <int M>
bool AffineClosestPoint(const std::array<const Vector3d*, 4>& q, Vector3d* v) {
  Eigen::Matrix<double, 3, M> e;
  for (int j = 0; j < M; ++j) e.col(j) = *q[j + 1] - *q[0];
  const Eigen::Matrix<double, M, M> gram = e.transpose() * e;
  const double det = gram.determinant();
  // A face is usable when its Gram determinant is not negligible next to the
  // product of its squared edge lengths (the Hadamard bound); flatter faces
  // are covered by their sub-faces.
  if (!(det > 1e-14 * gram.diagonal().prod())) return false;
  const Eigen::Matrix<double, M, 1> mu = -(gram.inverse() * (e.transpose() * *q[0]));
  if ((mu.array() < -kBarycentricSlack).any() || 1.0 - mu.sum() < -kBarycentricSlack) {
    return false;
  }
  *v = *q[0] + e * mu;
  return true;
}

// Closest point to the origin of the convex hull of the simplex. Tries every
// face (vertex, edge, triangle, tetrahedron): the closest point lies in the
// relative interior of one of them, where its affine projection has
// non-negative weights, and every such candidate lies in the hull, so the
// shortest valid candidate is the answer. The simplex shrinks to that face.
Vector3d ClosestPointAndReduce(Simplex* simplex) {
  const int n = simplex->n;
  double best_norm2 = std::numeric_limits<double>::infinity();
  Vector3d best_v = simplex->p[0];
  unsigned best_mask = 1;
  for (unsigned mask = 1; mask < (1u << n); ++mask) {
    std::array<const Vector3d*, 4> q{};
    int k = 0;
    for (int i = 0; i < n; ++i) {
      if (mask & (1u << i)) q[k++] = &simplex->p[i];
    }
    Vector3d v = *q[0];
    bool valid = true;
    switch (k) {
      case 2:
        valid = AffineClosestPoint<1>(q, &v);
        break;
      case 3:
        valid = AffineClosestPoint<2>(q, &v);
        break;
      case 4:
        valid = AffineClosestPoint<3>(q, &v);
        break;
      default:
        break;
    }
    if (!valid) continue;
    const double norm2 = v.squaredNorm();
    // Ties go to the face with fewer points, which is better conditioned.
    if (norm2 < best_norm2 ||
        (norm2 == best_norm2 && std::popcount(mask) < std::popcount(best_mask))) {
      best_norm2 = norm2;
      best_v = v;
      best_mask = mask;
    }
  }
  int kept = 0;
  for (int i = 0; i < n; ++i) {
    if (best_mask & (1u << i)) simplex->p[kept++] = simplex->p[i];
  }
  simplex->n = kept;
  return best_v;
}

// True only when a plane provably separates convex sets A and B with a gap
// larger than `tol`: for the final direction v and w = support of A - B
// towards -v, every point x of A - B has v.x >= v.w > tol |v|. Every other
// outcome (touching, convergence near tol, iteration cap, degeneracy) returns
// false, so numerical trouble can only add foreground. `hint` carries the last
// separating direction between neighbouring pixels, which usually certifies
// the next pixel at the cost of one support call.
template <class SetA, class SetB>
bool CertifiedSeparated(const SetA& a, const SetB& b, double tol, Vector3d* hint) {
  const auto support = [&](const Vector3d& v) -> Vector3d { return a.Support(-v) - b.Support(v); };
  Vector3d w = support(*hint);
  if (hint->squaredNorm() > 0.0 && hint->dot(w) > tol * hint->norm()) return true;

  Simplex simplex;
  simplex.p[0] = w;
  simplex.n = 1;
  Vector3d v = w;
  for (int iter = 0; iter < kGjkMaxIterations; ++iter) {
    const double vv = v.squaredNorm();
    if (vv <= tol * tol) return false;
    w = support(v);
    const double vw = v.dot(w);
    if (vw > tol * std::sqrt(vv)) {
      *hint = v;
      return true;
    }
    if (vv - vw <= kGjkRelativeConvergence * vv) return false;
    for (int i = 0; i < simplex.n; ++i) {
      if (simplex.p[i] == w) return false;  // No progress possible.
    }
    simplex.p[simplex.n++] = w;
    v = ClosestPointAndReduce(&simplex);
    if (simplex.n == 4) return false;  // The origin lies inside the tetrahedron.
    // No progress: the simplex is numerically flat around a point next to the
    // origin, which happens when the sets touch or overlap.
    if (!(v.squaredNorm() < vv)) return false;
  }
  return false;
}

// Convex quadrilateral that contains every sample of an undistorted pixel
// boundary grown by `margin`. samples[i * kSamplesPerEdge] is the image of
// corner i, in counter-clockwise order (K and a lens with positive Jacobian
// keep the square's orientation). Side i is the line through the images of
// corners i and i+1, pushed outward until no sample lies beyond it, then by
// the margin; the quad is the intersection of the four half-planes, so it
// holds hull(samples) + disk(margin). False when the sides do not form a
// proper convex quadrilateral (nearly parallel neighbours, inverted order):
// the caller then cannot certify the pixel.
bool EnclosingQuad(const std::vector<Vector2d>& samples, double margin,
                   std::vector<Vector2d>* quad) {
  std::array<Vector2d, 4> normal;
  std::array<double, 4> offset{};
  for (int i = 0; i < 4; ++i) {
    const Vector2d d = samples[((i + 1) % 4) * kSamplesPerEdge] - samples[i * kSamplesPerEdge];
    const double length = d.norm();
    if (!(length > 0.0)) return false;
    normal[i] = Vector2d(d.y(), -d.x()) / length;
    double h = -std::numeric_limits<double>::infinity();
    for (const Vector2d& p : samples) h = std::max(h, normal[i].dot(p));
    offset[i] = h + margin;
  }
  quad->resize(4);
  for (int i = 0; i < 4; ++i) {
    const int prev = (i + 3) % 4;
    // Normals must turn left by a clear angle (here more than ~5 degrees).
    const double det = normal[prev].x() * normal[i].y() - normal[prev].y() * normal[i].x();
    if (!(det > 0.09)) return false;
    // Solve normal[prev] . x = offset[prev], normal[i] . x = offset[i].
    (*quad)[i] = Vector2d(offset[prev] * normal[i].y() - offset[i] * normal[prev].y(),
                          normal[prev].x() * offset[i] - normal[i].x() * offset[prev]) /
                 det;
  }
  // Vertex i lies on sides i-1 and i, so edge i runs from vertex i to i+1 on
  // side i; it must run counter-clockwise for the polygon to be the
  // intersection of the half-planes.
  for (int i = 0; i < 4; ++i) {
    const Vector2d tangent(-normal[i].y(), normal[i].x());
    if (!(((*quad)[(i + 1) % 4] - (*quad)[i]).dot(tangent) > 0.0)) return false;
  }
  return true;
}

/// Inclusive pixel range examined for one shape.
struct PixelRange {
  int u0 = 0;
  int v0 = 0;
  int u1 = -1;
  int v1 = -1;
};

// Normalised-coordinate box holding the projection of every point of the
// shape's bounding box; nullopt when some corner is not clearly in front of the
// camera (then the projection is unbounded). The bounding box is convex and in
// front, so its projection is the convex hull of its corners' projections.
std::optional<Eigen::AlignedBox2d> NormalisedBounds(const ShapeInCamera& shape_C,
                                                    const common::Box3& bounds_W) {
  Eigen::AlignedBox2d box;
  for (int i = 0; i < 8; ++i) {
    const Vector3d p_C = shape_C.ToCamera(bounds_W.Corner(i));
    if (!(p_C.z() > 1e-9 * p_C.norm())) return std::nullopt;
    box.extend(Vector2d(p_C.x() / p_C.z(), p_C.y() / p_C.z()));
  }
  return box;
}

// Pixels whose closed square may meet the projection of the shape's bounding
// box, grown by one pixel against rounding; the whole image when the box
// reaches behind the camera.
PixelRange CandidatePixels(const ShapeInCamera& shape_C, const common::Box3& bounds_W,
                           const Matrix3d& K, int width, int height) {
  PixelRange all{0, 0, width - 1, height - 1};
  const std::optional<Eigen::AlignedBox2d> box = NormalisedBounds(shape_C, bounds_W);
  if (!box) return all;
  double u_min = std::numeric_limits<double>::infinity();
  double v_min = u_min;
  double u_max = -u_min;
  double v_max = -u_min;
  for (int i = 0; i < 4; ++i) {
    const Vector2d xy = box->corner(static_cast<Eigen::AlignedBox2d::CornerType>(i));
    const Vector3d uvw = K * Vector3d(xy.x(), xy.y(), 1.0);
    const double u = uvw.x() / uvw.z();
    const double v = uvw.y() / uvw.z();
    u_min = std::min(u_min, u);
    u_max = std::max(u_max, u);
    v_min = std::min(v_min, v);
    v_max = std::max(v_max, v);
  }
  if (!std::isfinite(u_min + u_max + v_min + v_max)) return all;
  // Pixel u's closed square [u-0.5, u+0.5] meets [u_min, u_max] iff
  // ceil(u_min-0.5) <= u <= floor(u_max+0.5).
  const auto clamp_to = [](double x, int hi) {
    return static_cast<int>(std::clamp(x, -1.0, static_cast<double>(hi) + 1.0));
  };
  PixelRange range;
  range.u0 = std::max(0, clamp_to(std::ceil(u_min - 0.5) - 1.0, width));
  range.u1 = std::min(width - 1, clamp_to(std::floor(u_max + 0.5) + 1.0, width));
  range.v0 = std::max(0, clamp_to(std::ceil(v_min - 0.5) - 1.0, height));
  range.v1 = std::min(height - 1, clamp_to(std::floor(v_max + 0.5) + 1.0, height));
  return range;
}

// Per-shape data shared by both renderers.
struct ShapeView {
  ShapeInCamera in_camera;
  common::Box3 bounds_W;
  double far = 0.0;       // Beyond every point of the shape, > 0.
  double extent = 0.0;    // Size scale of the shape as seen from C (m).
  bool in_front = false;  // Some point has z > 0.
  // Depth at which a pixel's inner ray is probed before running GJK: the
  // middle of the shape's depth range, where a convex shape's cross-section
  // tends to be widest; 0 disables the probe.
  double probe_depth = 0.0;
};

ShapeView MakeShapeView(const Shape& shape, const geometry::CameraModel& camera) {
  ShapeView view{ShapeInCamera(shape, camera), Bounds(shape), 0.0, 0.0, false, 0.0};
  const double z_max = view.in_camera.Support(Vector3d::UnitZ()).z();
  const double z_min = view.in_camera.Support(-Vector3d::UnitZ()).z();
  view.in_front = z_max > 0.0;
  view.far = 1.25 * z_max;
  view.probe_depth = std::max(0.0, 0.5 * (z_min + z_max));
  const Vector3d centre_C = view.in_camera.ToCamera(0.5 * (view.bounds_W.min + view.bounds_W.max));
  view.extent = centre_C.norm() + view.bounds_W.Size().norm();
  return view;
}

// A point of the pixel's pyramid (on the ray through normalised xy, which lies
// in the pixel's polygon) inside the shape proves they intersect. Most pixels
// inside a silhouette are settled by this one Contains call instead of a full
// GJK run that has to enclose the origin.
bool ProbeHits(const ShapeView& view, const Vector2d& xy) {
  return view.probe_depth > 0.0 &&
         view.in_camera.ContainsC(view.probe_depth * Vector3d(xy.x(), xy.y(), 1.0));
}

// Separation tolerance for a pyramid whose far polygon reaches normalised
// radius `max_xy`: relative to the largest coordinates in the GJK problem.
double Tolerance(const ShapeView& view, double max_xy) {
  return kRelativeTolerance * (view.far * (1.0 + max_xy) + view.extent);
}

double MaxAbsCoordinate(const std::vector<Vector2d>& polygon) {
  double m = 0.0;
  for (const Vector2d& xy : polygon) m = std::max(m, xy.cwiseAbs().maxCoeff());
  return m;
}

Vector2d Normalised(const Matrix3d& K_inv, double u, double v) {
  const Vector3d ray = K_inv * Vector3d(u, v, 1.0);
  return {ray.x() / ray.z(), ray.y() / ray.z()};
}

bool AllZero(const std::array<double, 5>& k) {
  return std::all_of(k.begin(), k.end(), [](double c) { return c == 0.0; });
}

}  // namespace

common::ImageU8 RenderExactMask(const geometry::CameraModel& pinhole,
                                const std::vector<Shape>& shapes) {
  HG_CHECK(pinhole.width >= 0 && pinhole.height >= 0);
  common::ImageU8 mask(pinhole.width, pinhole.height, 0);
  const Matrix3d K_inv = pinhole.K.inverse();
  std::vector<Vector2d> square(4);
  Pyramid pyramid;
  for (const Shape& shape : shapes) {
    const ShapeView view = MakeShapeView(shape, pinhole);
    if (!view.in_front) continue;  // Nothing of it lies in front of the camera.
    const PixelRange range =
        CandidatePixels(view.in_camera, view.bounds_W, pinhole.K, pinhole.width, pinhole.height);
    Vector3d row_hint = Vector3d::Zero();
    for (int v = range.v0; v <= range.v1; ++v) {
      Vector3d hint = row_hint;
      for (int u = range.u0; u <= range.u1; ++u) {
        if (mask.At(u, v) != 0) continue;
        if (ProbeHits(view, Normalised(K_inv, u, v))) {
          mask.At(u, v) = 255;
          continue;
        }
        // Pixel corners in normalised coordinates (a parallelogram for any K).
        square[0] = Normalised(K_inv, u - 0.5, v - 0.5);
        square[1] = Normalised(K_inv, u + 0.5, v - 0.5);
        square[2] = Normalised(K_inv, u + 0.5, v + 0.5);
        square[3] = Normalised(K_inv, u - 0.5, v + 0.5);
        pyramid.Set(square, view.far);
        const double tol = Tolerance(view, MaxAbsCoordinate(square));
        if (!CertifiedSeparated(pyramid, view.in_camera, tol, &hint)) mask.At(u, v) = 255;
        if (u == range.u0) row_hint = hint;
      }
    }
  }
  return mask;
}

common::ImageU8 RenderExactDistortedMask(const geometry::CameraModel& camera,
                                         const std::vector<Shape>& shapes) {
  if (AllZero(camera.distortion)) return RenderExactMask(camera, shapes);
  HG_CHECK(camera.width >= 0 && camera.height >= 0);
  common::ImageU8 mask(camera.width, camera.height, 0);
  const Matrix3d K_inv = camera.K.inverse();
  const std::array<double, 5>& k = camera.distortion;

  std::vector<ShapeView> views;
  std::vector<std::optional<Eigen::AlignedBox2d>> normalised_bounds;
  for (const Shape& shape : shapes) {
    ShapeView view = MakeShapeView(shape, camera);
    if (!view.in_front) continue;
    normalised_bounds.push_back(NormalisedBounds(view.in_camera, view.bounds_W));
    views.push_back(std::move(view));
  }
  if (views.empty()) return mask;
  std::vector<Vector3d> hints(views.size(), Vector3d::Zero());

  // The rays through a distorted pixel are the undistorted image U(S) of its
  // square S. U(S) is bounded by the curve U(boundary of S); we sample that
  // curve and enclose the samples, grown by a margin that covers the curve
  // between samples. Between consecutive samples p, q (chord c) the curve has
  // some length L; every point x on it has |x-p| + |x-q| <= L, so it lies
  // within sqrt(L^2 - c^2) / 2 of the chord. At 16 samples per edge a sub-arc
  // spans 1/16 pixel, over which a lens's inverse map is near affine (L ~ c);
  // even L <= 2c gives a deviation below (sqrt(3)/2) c, so a margin of the
  // largest chord over-covers. The enclosing quad holds U(S), so the mask can
  // only gain pixels.
  std::vector<Vector2d> samples;
  std::vector<Vector2d> polygon;
  samples.reserve(4 * kSamplesPerEdge);
  Pyramid pyramid;
  for (int v = 0; v < camera.height; ++v) {
    for (int u = 0; u < camera.width; ++u) {
      const std::array<Vector2d, 4> corners{Vector2d(u - 0.5, v - 0.5), Vector2d(u + 0.5, v - 0.5),
                                            Vector2d(u + 0.5, v + 0.5), Vector2d(u - 0.5, v + 0.5)};
      samples.clear();
      bool inverted = true;
      Vector2d x = Normalised(K_inv, corners[0].x(), corners[0].y());
      for (int edge = 0; edge < 4 && inverted; ++edge) {
        const Vector2d& from = corners[edge];
        const Vector2d& to = corners[(edge + 1) % 4];
        for (int j = 0; j < kSamplesPerEdge && inverted; ++j) {
          const Vector2d uv = from + (to - from) * (static_cast<double>(j) / kSamplesPerEdge);
          inverted = geometry::InvertDistortion(k, Normalised(K_inv, uv.x(), uv.y()), &x);
          samples.push_back(x);
        }
      }
      double margin = 0.0;
      for (std::size_t i = 0; inverted && i < samples.size(); ++i) {
        margin = std::max(margin, (samples[(i + 1) % samples.size()] - samples[i]).norm());
      }
      if (!inverted || !EnclosingQuad(samples, margin + kUndistortSlack, &polygon)) {
        // The lens model cannot be inverted here, or its image of the pixel is
        // too distorted to enclose: the camera cannot certify this pixel.
        mask.At(u, v) = 255;
        continue;
      }
      Eigen::AlignedBox2d polygon_box;
      for (const Vector2d& p : polygon) polygon_box.extend(p);
      const double max_xy = MaxAbsCoordinate(polygon);
      Vector2d inner = Vector2d::Zero();  // Vertex mean: inside the convex polygon.
      for (const Vector2d& p : polygon) inner += p;
      inner /= static_cast<double>(polygon.size());

      for (std::size_t s = 0; s < views.size(); ++s) {
        if (normalised_bounds[s] && !normalised_bounds[s]->intersects(polygon_box)) continue;
        if (ProbeHits(views[s], inner)) {
          mask.At(u, v) = 255;
          break;
        }
        pyramid.Set(polygon, views[s].far);
        const double tol = Tolerance(views[s], max_xy);
        if (!CertifiedSeparated(pyramid, views[s].in_camera, tol, &hints[s])) {
          mask.At(u, v) = 255;
          break;
        }
      }
    }
  }
  return mask;
}

}  // namespace hg::scene
