#include "sim/colour_renderer.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <Eigen/LU>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "common/check.h"

namespace hg::sim {
namespace {

using Eigen::Matrix2d;
using Eigen::Matrix3d;
using Eigen::Vector2d;
using Eigen::Vector3d;

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr float kInfF = std::numeric_limits<float>::infinity();

/// Near clipping plane of the rasteriser (camera z, metres).
constexpr double kNearM = 0.01;
/// Colour where no surface is seen (beyond the walls), linear 0..1.
Rgb Background() { return {0.08F, 0.08F, 0.1F}; }
/// Colour of people beyond scene.people (no person description).
Rgb UnknownPerson() { return {0.5F, 0.5F, 0.5F}; }
/// The pinhole canvas of a distorted camera grows at most this share of the
/// image size on each side (what a barrel lens shows beyond the pinhole view).
constexpr double kMaxCanvasPad = 0.75;

// -----------------------------------------------------------------------------
// Deterministic hashing, noise and textures.

std::uint64_t SplitMix64(std::uint64_t x) {
  x += 0x9E3779B97F4A7C15ULL;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ULL;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBULL;
  return x ^ (x >> 31);
}

double Hash01(std::int64_t ix, std::int64_t iy, std::uint64_t salt) {
  const std::uint64_t h =
      SplitMix64(static_cast<std::uint64_t>(ix) * 0x8CB92BA72F3D8DD7ULL ^
                 SplitMix64(static_cast<std::uint64_t>(iy) ^ (salt * 0xD6E8FEB86659FD93ULL)));
  return static_cast<double>(h >> 11) * 0x1.0p-53;
}

/// Smooth value noise in [0, 1] with features of size `cell` metres.
double ValueNoise(double x, double y, double cell, std::uint64_t salt) {
  const double fx = x / cell;
  const double fy = y / cell;
  const double x0 = std::floor(fx);
  const double y0 = std::floor(fy);
  const auto ix = static_cast<std::int64_t>(x0);
  const auto iy = static_cast<std::int64_t>(y0);
  auto smooth = [](double t) { return t * t * (3.0 - 2.0 * t); };
  const double sx = smooth(fx - x0);
  const double sy = smooth(fy - y0);
  const double a = Hash01(ix, iy, salt);
  const double b = Hash01(ix + 1, iy, salt);
  const double c = Hash01(ix, iy + 1, salt);
  const double d = Hash01(ix + 1, iy + 1, salt);
  return (a + (b - a) * sx) + ((c + (d - c) * sx) - (a + (b - a) * sx)) * sy;
}

/// Floor: 0.5 m tiles with grout joints, per-tile tint and low-frequency stains.
Rgb FloorTexture(const Vector3d& p_W) {
  constexpr double kTileM = 0.5;
  constexpr double kGroutM = 0.008;
  const double tx = std::floor(p_W.x() / kTileM);
  const double ty = std::floor(p_W.y() / kTileM);
  const double gx = p_W.x() - tx * kTileM;
  const double gy = p_W.y() - ty * kTileM;
  if (std::min({gx, gy, kTileM - gx, kTileM - gy}) < kGroutM) {
    return Rgb(0.3F, 0.3F, 0.28F);
  }
  const double tint =
      0.88 + 0.12 * Hash01(static_cast<std::int64_t>(tx), static_cast<std::int64_t>(ty), 11);
  const double stain = 0.8 + 0.2 * ValueNoise(p_W.x(), p_W.y(), 1.1, 12) +
                       0.1 * ValueNoise(p_W.x(), p_W.y(), 0.15, 13);
  const auto k = static_cast<float>(tint * stain);
  return Rgb(0.56F, 0.55F, 0.5F) * k;
}

/// Walls: painted, with low-frequency noise and a dark skirting board.
Rgb WallTexture(const Vector3d& p_W, double floor_z, int wall) {
  if (p_W.z() - floor_z < 0.1) {
    return Rgb(0.22F, 0.2F, 0.2F);
  }
  const double along = (wall < 2) ? p_W.y() : p_W.x();
  const double k = 0.85 + 0.2 * ValueNoise(along, p_W.z(), 0.9, 20 + wall) +
                   0.05 * ValueNoise(along, p_W.z(), 0.07, 30 + wall);
  const Rgb base = (wall % 2 == 0) ? Rgb(0.72F, 0.7F, 0.62F) : Rgb(0.62F, 0.68F, 0.7F);
  return base * static_cast<float>(k);
}

/// Standard normal quantiles at (i + 0.5) / 65536: 16 random bits give one
/// Gaussian sample by lookup.
const std::array<float, 65536>& GaussianTable() {
  static const std::array<float, 65536> table = [] {
    std::array<float, 65536> t{};
    for (int i = 0; i < 32768; ++i) {
      const double p = (i + 0.5) / 65536.0;
      // Start from the tail asymptote and polish with Newton on Phi(z) = p.
      double z = -std::sqrt(-2.0 * std::log(p));
      for (int iter = 0; iter < 12; ++iter) {
        const double cdf = 0.5 * std::erfc(-z / std::sqrt(2.0));
        const double pdf = std::exp(-0.5 * z * z) / std::sqrt(2.0 * M_PI);
        z -= (cdf - p) / pdf;
      }
      t[i] = static_cast<float>(z);
      t[65535 - i] = static_cast<float>(-z);
    }
    return t;
  }();
  return table;
}

// -----------------------------------------------------------------------------
// Geometry helpers.

/// Entry parameter t >= 0 of the ray t u (from the origin) into a sphere.
double SphereEntry(const Vector3d& u, const Vector3d& c, double r) {
  const double a = u.squaredNorm();
  const double b = -u.dot(c);
  const double cc = c.squaredNorm() - r * r;
  const double disc = b * b - a * cc;
  if (disc < 0.0) return kInf;
  const double root = std::sqrt(disc);
  if (-b + root < 0.0) return kInf;
  return std::max(0.0, (-b - root) / a);
}

/// Entry parameter of the ray t u into the capsule a-b of radius r.
double CapsuleEntry(const Vector3d& u, const Vector3d& a, const Vector3d& b, double r) {
  double best = std::min(SphereEntry(u, a, r), SphereEntry(u, b, r));
  const Vector3d axis = b - a;
  const double length = axis.norm();
  if (length > 0.0) {
    const Vector3d w = axis / length;
    // Inside the infinite cylinder |o + t m| <= r, between the end planes.
    const Vector3d o = -a + a.dot(w) * w;
    const Vector3d m = u - u.dot(w) * w;
    const double qa = m.squaredNorm();
    const double qb = o.dot(m);
    const double qc = o.squaredNorm() - r * r;
    const double disc = qb * qb - qa * qc;
    if (qa > 0.0 && disc >= 0.0) {
      const double t = std::max(0.0, (-qb - std::sqrt(disc)) / qa);
      const double s = (t * u - a).dot(w);
      if (s >= 0.0 && s <= length && (t * u - a - s * w).squaredNorm() <= r * r * (1 + 1e-9)) {
        best = std::min(best, t);
      }
    }
  }
  return best;
}

/// Normalised bounds (x/z, y/z) of a set of rays.
struct NormBox {
  double x0 = kInf;
  double x1 = -kInf;
  double y0 = kInf;
  double y1 = -kInf;
  bool unbounded = false;
  void Extend(double x, double y) {
    x0 = std::min(x0, x);
    x1 = std::max(x1, x);
    y0 = std::min(y0, y);
    y1 = std::max(y1, y);
  }
};

/// Bounds of the rays of a capsule (camera frame); the capsule is the convex
/// hull of its end balls, whose tangent planes x = t z give the extremes.
NormBox CapsuleNormBox(const Vector3d& a, const Vector3d& b, double r) {
  NormBox box;
  if (std::min(a.z(), b.z()) - r < kNearM) {
    box.unbounded = true;
    return box;
  }
  for (const Vector3d* c : {&a, &b}) {
    const double denom = c->z() * c->z() - r * r;
    const double rx = r * std::sqrt(std::max(0.0, c->x() * c->x() + denom));
    const double ry = r * std::sqrt(std::max(0.0, c->y() * c->y() + denom));
    box.Extend((c->x() * c->z() - rx) / denom, (c->y() * c->z() - ry) / denom);
    box.Extend((c->x() * c->z() + rx) / denom, (c->y() * c->z() + ry) / denom);
  }
  return box;
}

/// One triangle of the static scene.
struct StaticTriangle {
  std::array<Vector3d, 3> p_W;
  Vector3d normal_W;  // Unit; sign arbitrary (shading is two-sided).
  Rgb colour;
  int kind;  // kFloor, kWall + i (i = 0..3), kObject.
};
constexpr int kFloor = 0;
constexpr int kWall = 1;
constexpr int kObject = 5;

/// Axis-aligned box test of the segment p + s d, s in (s0, s1).
bool SegmentHitsBox(const Vector3d& p, const Vector3d& d, const common::Box3& box, double s0,
                    double s1) {
  for (int i = 0; i < 3; ++i) {
    if (d[i] == 0.0) {
      if (p[i] < box.min[i] || p[i] > box.max[i]) return false;
      continue;
    }
    double ta = (box.min[i] - p[i]) / d[i];
    double tb = (box.max[i] - p[i]) / d[i];
    if (ta > tb) std::swap(ta, tb);
    s0 = std::max(s0, ta);
    s1 = std::min(s1, tb);
    if (s0 > s1) return false;
  }
  return true;
}

bool SegmentHitsTriangle(const Vector3d& p, const Vector3d& d, const Vector3d& a, const Vector3d& b,
                         const Vector3d& c, double s0, double s1) {
  const Vector3d e1 = b - a;
  const Vector3d e2 = c - a;
  const Vector3d pv = d.cross(e2);
  const double det = e1.dot(pv);
  if (det == 0.0) return false;
  const double inv = 1.0 / det;
  const Vector3d tv = p - a;
  const double u = tv.dot(pv) * inv;
  if (u < 0.0 || u > 1.0) return false;
  const Vector3d qv = tv.cross(e1);
  const double v = d.dot(qv) * inv;
  if (v < 0.0 || u + v > 1.0) return false;
  const double s = e2.dot(qv) * inv;
  return s > s0 && s < s1;
}

/// A mesh that casts shadows, with its bounds for a quick reject.
struct Occluder {
  geometry::TriangleMesh mesh;
  common::Box3 bounds;
};

}  // namespace

// Everything but the per-frame scratch is immutable after construction; the
// scratch makes one renderer render one frame at a time (different renderers
// render concurrently, as the simulator does per camera).
struct ColourRenderer::Impl {
  geometry::CameraModel camera;
  int camera_index = 0;
  int width = 0;
  int height = 0;
  double floor_z = 0.0;
  ImagingSettings imaging;
  Vector3d light_C;  // Light in the camera frame.
  std::vector<std::array<Rgb, kNumBodyParts>> part_colours;

  bool pinhole = true;
  // Distorted cameras: pixel-centre rays (NaN where the lens cannot be inverted)
  // and the bounds of all valid rays.
  std::vector<float> ray_x;
  std::vector<float> ray_y;
  NormBox ray_bounds;

  std::vector<std::uint8_t> static_rgb;
  std::vector<float> static_depth;  // Camera z; +inf where no surface.
  /// Floor pixels lit by the lamp: 255 * (shadowed / lit brightness); 0 elsewhere.
  std::vector<std::uint8_t> floor_shadow_ratio;

  /// Floor point (x, y) of a ray (x/z, y/z, 1): (H0 . r, H1 . r) / (H2 . r).
  std::array<std::array<double, 3>, 3> floor_h{};
  /// Sensor noise per 16 random bits, in 1/16 grey levels.
  std::vector<std::int16_t> noise16;
  bool has_noise = false;

  // Per-frame scratch (one Render at a time per renderer).
  mutable std::vector<float> depth;
  mutable std::vector<std::uint8_t> shadow;
  mutable std::vector<std::uint8_t> row_flags;

  Impl(const Scene& scene, int index) {
    HG_CHECK(index >= 0 && index < static_cast<int>(scene.cameras.size()));
    camera = scene.cameras[index].model;
    camera_index = index;
    width = camera.width;
    height = camera.height;
    HG_CHECK(width > 0 && height > 0);
    floor_z = scene.bounds.min.z();
    imaging = scene.imaging;
    light_C = camera.ToCamera(imaging.light_W);
    for (const Person& person : scene.people) {
      std::array<Rgb, kNumBodyParts> colours;
      for (int p = 0; p < kNumBodyParts; ++p) {
        colours[p] = PartColour(person, static_cast<BodyPart>(p));
      }
      part_colours.push_back(colours);
    }
    pinhole = !camera.HasDistortion();
    const std::size_t n = static_cast<std::size_t>(width) * height;
    depth.assign(n, kInfF);
    shadow.assign(n, 0);
    row_flags.assign(width, 0);
    // The ray r = (x, y, 1) has world direction d = R_WC r and meets the floor
    // at C + t d with t = (floor_z - C_z) / d_z: projective in r.
    const Matrix3d R_WC = camera.R_CW.transpose();
    const Vector3d c = camera.CentreW();
    for (int k = 0; k < 3; ++k) {
      floor_h[0][k] = c.x() * R_WC(2, k) + (floor_z - c.z()) * R_WC(0, k);
      floor_h[1][k] = c.y() * R_WC(2, k) + (floor_z - c.z()) * R_WC(1, k);
      floor_h[2][k] = R_WC(2, k);
    }
    const double sigma = std::max(0.0, imaging.noise_sigma);
    has_noise = sigma > 0.0;
    if (has_noise) {
      const std::array<float, 65536>& gauss = GaussianTable();
      noise16.resize(gauss.size());
      for (std::size_t i = 0; i < gauss.size(); ++i) {
        noise16[i] = static_cast<std::int16_t>(
            std::clamp(std::lround(16.0 * sigma * gauss[i]), -32000L, 32000L));
      }
    }
    BuildStatic(scene);
  }

  /// Normalised pixel-centre ray; false where the lens cannot be inverted.
  [[nodiscard]] bool Ray(int u, int v, double* x, double* y) const {
    if (pinhole) {
      *y = (v - camera.K(1, 2)) / camera.K(1, 1);
      *x = (u - camera.K(0, 2) - camera.K(0, 1) * *y) / camera.K(0, 0);
      return true;
    }
    const std::size_t i = static_cast<std::size_t>(v) * width + u;
    *x = ray_x[i];
    *y = ray_y[i];
    return !std::isnan(ray_x[i]);
  }

  /// Pixel rectangle [u0, u1] x [v0, v1] holding every pixel whose centre ray
  /// lies in `box`; empty (u1 < u0) when none.
  void PixelRect(NormBox box, int* u0, int* u1, int* v0, int* v1) const {
    *u0 = 0;
    *v0 = 0;
    *u1 = width - 1;
    *v1 = height - 1;
    if (box.unbounded) return;
    if (!(box.x0 <= box.x1 && box.y0 <= box.y1)) {
      *u1 = -1;
      return;
    }
    const Matrix3d& K = camera.K;
    double lo_u;
    double hi_u;
    double lo_v;
    double hi_v;
    if (pinhole) {
      const double s0 = K(0, 1) * box.y0;
      const double s1 = K(0, 1) * box.y1;
      lo_u = K(0, 0) * box.x0 + std::min(s0, s1) + K(0, 2);
      hi_u = K(0, 0) * box.x1 + std::max(s0, s1) + K(0, 2);
      lo_v = K(1, 1) * box.y0 + K(1, 2);
      hi_v = K(1, 1) * box.y1 + K(1, 2);
    } else {
      // Rays outside the image's ray bounds hit no pixel; inside them the lens
      // is one-to-one, so the rectangle's image is bounded by the image of its
      // boundary (sampled densely, plus a margin for the bulge between samples).
      box.x0 = std::max(box.x0, ray_bounds.x0);
      box.x1 = std::min(box.x1, ray_bounds.x1);
      box.y0 = std::max(box.y0, ray_bounds.y0);
      box.y1 = std::min(box.y1, ray_bounds.y1);
      if (!(box.x0 <= box.x1 && box.y0 <= box.y1)) {
        *u1 = -1;
        return;
      }
      lo_u = lo_v = kInf;
      hi_u = hi_v = -kInf;
      constexpr int kSamples = 32;
      for (int i = 0; i <= kSamples; ++i) {
        const double s = static_cast<double>(i) / kSamples;
        const std::array<Vector2d, 4> points = {Vector2d(box.x0 + s * (box.x1 - box.x0), box.y0),
                                                Vector2d(box.x0 + s * (box.x1 - box.x0), box.y1),
                                                Vector2d(box.x0, box.y0 + s * (box.y1 - box.y0)),
                                                Vector2d(box.x1, box.y0 + s * (box.y1 - box.y0))};
        for (const Vector2d& p : points) {
          const Vector2d d = geometry::ApplyDistortion(camera.distortion, p);
          const double pu = K(0, 0) * d.x() + K(0, 1) * d.y() + K(0, 2);
          const double pv = K(1, 1) * d.y() + K(1, 2);
          lo_u = std::min(lo_u, pu);
          hi_u = std::max(hi_u, pu);
          lo_v = std::min(lo_v, pv);
          hi_v = std::max(hi_v, pv);
        }
      }
      lo_u -= 2.0;
      lo_v -= 2.0;
      hi_u += 2.0;
      hi_v += 2.0;
    }
    auto clamp = [](double value, int lo, int hi) {
      if (!(value > lo)) return lo;
      if (!(value < hi)) return hi;
      return static_cast<int>(value);
    };
    *u0 = clamp(std::floor(lo_u) - 1.0, 0, width);
    *u1 = clamp(std::ceil(hi_u) + 1.0, -1, width - 1);
    *v0 = clamp(std::floor(lo_v) - 1.0, 0, height);
    *v1 = clamp(std::ceil(hi_v) + 1.0, -1, height - 1);
  }

  void BuildStatic(const Scene& scene) {
    const std::size_t n = static_cast<std::size_t>(width) * height;
    // Pinhole canvas: the image itself, or for a distorted lens the pinhole
    // view of every distorted pixel (grown past the image as far as needed).
    int pad_l = 0;
    int pad_r = 0;
    int pad_t = 0;
    int pad_b = 0;
    cv::Mat map_x;
    cv::Mat map_y;
    const Matrix3d& K = camera.K;
    if (!pinhole) {
      const Matrix3d K_inv = K.inverse();
      ray_x.assign(n, std::numeric_limits<float>::quiet_NaN());
      ray_y.assign(n, std::numeric_limits<float>::quiet_NaN());
      map_x.create(height, width, CV_32FC1);
      map_y.create(height, width, CV_32FC1);
      double min_u = 0;
      double max_u = width - 1;
      double min_v = 0;
      double max_v = height - 1;
      for (int v = 0; v < height; ++v) {
        Vector2d guess(kInf, kInf);
        for (int u = 0; u < width; ++u) {
          const Vector2d xd(K_inv(0, 0) * u + K_inv(0, 1) * v + K_inv(0, 2),
                            K_inv(1, 1) * v + K_inv(1, 2));
          Vector2d x = std::isfinite(guess.x()) ? guess : xd;
          const std::size_t i = static_cast<std::size_t>(v) * width + u;
          if (!geometry::InvertDistortion(camera.distortion, xd, &x)) {
            guess = Vector2d(kInf, kInf);
            map_x.at<float>(v, u) = -1e6F;
            map_y.at<float>(v, u) = -1e6F;
            continue;
          }
          guess = x;
          ray_x[i] = static_cast<float>(x.x());
          ray_y[i] = static_cast<float>(x.y());
          ray_bounds.Extend(x.x(), x.y());
          const double pu = K(0, 0) * x.x() + K(0, 1) * x.y() + K(0, 2);
          const double pv = K(1, 1) * x.y() + K(1, 2);
          map_x.at<float>(v, u) = static_cast<float>(pu);
          map_y.at<float>(v, u) = static_cast<float>(pv);
          min_u = std::min(min_u, pu);
          max_u = std::max(max_u, pu);
          min_v = std::min(min_v, pv);
          max_v = std::max(max_v, pv);
        }
      }
      auto pad = [](double overshoot, int size) {
        return static_cast<int>(
            std::min(std::ceil(std::max(0.0, overshoot)) + 2.0, kMaxCanvasPad * size));
      };
      pad_l = pad(-min_u, width);
      pad_r = pad(max_u - (width - 1), width);
      pad_t = pad(-min_v, height);
      pad_b = pad(max_v - (height - 1), height);
      map_x += static_cast<float>(pad_l);
      map_y += static_cast<float>(pad_t);
    }
    const int cw = width + pad_l + pad_r;
    const int ch = height + pad_t + pad_b;
    Matrix3d K_canvas = K;
    K_canvas(0, 2) += pad_l;
    K_canvas(1, 2) += pad_t;

    std::vector<StaticTriangle> triangles = SceneTriangles(scene);
    std::vector<float> canvas_depth(static_cast<std::size_t>(cw) * ch, kInfF);
    std::vector<int> canvas_id(canvas_depth.size(), -1);
    for (int i = 0; i < static_cast<int>(triangles.size()); ++i) {
      Rasterise(triangles[i], i, K_canvas, cw, ch, &canvas_depth, &canvas_id);
    }

    std::vector<Occluder> occluders;
    if (imaging.shadows) {
      for (const auto* list : {&scene.obstacles, &scene.foreground_objects}) {
        for (const Solid& solid : *list) {
          Occluder o{Tessellate(solid.geometry), Bounds(solid.geometry)};
          o.bounds.min.array() -= 1e-6;
          o.bounds.max.array() += 1e-6;
          occluders.push_back(std::move(o));
        }
      }
    }

    // Shading of the canvas.
    cv::Mat canvas(ch, cw, CV_8UC3);
    cv::Mat canvas_ratio(ch, cw, CV_8UC1, cv::Scalar(0));
    const Matrix3d K_canvas_inv = K_canvas.inverse();
    const Matrix3d R_WC = camera.R_CW.transpose();
    const Vector3d centre_W = camera.CentreW();
    const double ambient = std::clamp(imaging.ambient, 0.0, 1.0);
    for (int v = 0; v < ch; ++v) {
      auto* row = canvas.ptr<std::uint8_t>(v);
      for (int u = 0; u < cw; ++u) {
        const std::size_t ci = static_cast<std::size_t>(v) * cw + u;
        Rgb colour = Background();
        if (canvas_id[ci] >= 0) {
          const StaticTriangle& tri = triangles[canvas_id[ci]];
          const Vector3d ray_C = K_canvas_inv * Vector3d(u, v, 1.0);
          const Vector3d p_W = R_WC * (canvas_depth[ci] * ray_C / ray_C.z()) + centre_W;
          Rgb albedo = tri.colour;
          if (tri.kind == kFloor) {
            albedo = FloorTexture(p_W);
          } else if (tri.kind < kObject) {
            albedo = WallTexture(p_W, floor_z, tri.kind - kWall);
          }
          Vector3d normal = tri.normal_W;
          if (normal.dot(centre_W - p_W) < 0.0) normal = -normal;
          const Vector3d to_light = imaging.light_W - p_W;
          double lambert = std::max(0.0, normal.dot(to_light.normalized()));
          if (lambert > 0.0 && Shadowed(occluders, p_W, to_light)) lambert = 0.0;
          const double lit = ambient + (1.0 - ambient) * lambert;
          colour = albedo * static_cast<float>(lit);
          if (tri.kind == kFloor && lambert > 0.0) {
            canvas_ratio.at<std::uint8_t>(v, u) =
                static_cast<std::uint8_t>(std::clamp(255.0 * ambient / lit, 1.0, 255.0));
          }
        }
        for (int c = 0; c < 3; ++c) {
          row[3 * u + c] =
              static_cast<std::uint8_t>(std::clamp(255.0F * colour[c] + 0.5F, 0.0F, 255.0F));
        }
      }
    }

    static_rgb.assign(3 * n, 0);
    static_depth.assign(n, kInfF);
    floor_shadow_ratio.assign(n, 0);
    if (pinhole) {
      std::copy(canvas.data, canvas.data + 3 * n, static_rgb.begin());
      std::copy(canvas_depth.begin(), canvas_depth.end(), static_depth.begin());
      std::copy(canvas_ratio.data, canvas_ratio.data + n, floor_shadow_ratio.begin());
      return;
    }
    // Through the lens: bilinear colour, nearest depth and floor ratio.
    cv::Mat out(height, width, CV_8UC3, static_rgb.data());
    const Rgb bg = Background();
    const cv::Scalar background(255.0 * bg[0], 255.0 * bg[1], 255.0 * bg[2]);
    cv::remap(canvas, out, map_x, map_y, cv::INTER_LINEAR, cv::BORDER_CONSTANT, background);
    for (int v = 0; v < height; ++v) {
      for (int u = 0; u < width; ++u) {
        const int su = static_cast<int>(std::lround(map_x.at<float>(v, u)));
        const int sv = static_cast<int>(std::lround(map_y.at<float>(v, u)));
        if (su < 0 || sv < 0 || su >= cw || sv >= ch) continue;
        const std::size_t i = static_cast<std::size_t>(v) * width + u;
        const std::size_t ci = static_cast<std::size_t>(sv) * cw + su;
        static_depth[i] = canvas_depth[ci];
        floor_shadow_ratio[i] = canvas_ratio.at<std::uint8_t>(sv, su);
      }
    }
  }

  /// Floor, the walls the camera sees from inside, obstacles and crates.
  [[nodiscard]] std::vector<StaticTriangle> SceneTriangles(const Scene& scene) const {
    std::vector<StaticTriangle> triangles;
    const common::Box3& b = scene.bounds;
    const Vector3d centre_W = camera.CentreW();
    auto add_quad = [&](const Vector3d& p0, const Vector3d& p1, const Vector3d& p2,
                        const Vector3d& p3, int kind) {
      const Vector3d normal = (p1 - p0).cross(p2 - p0).normalized();
      triangles.push_back({{p0, p1, p2}, normal, Rgb::Zero(), kind});
      triangles.push_back({{p0, p2, p3}, normal, Rgb::Zero(), kind});
    };
    const double x0 = b.min.x();
    const double x1 = b.max.x();
    const double y0 = b.min.y();
    const double y1 = b.max.y();
    const double z0 = b.min.z();
    const double z1 = b.max.z();
    if (centre_W.z() > z0) {
      add_quad({x0, y0, z0}, {x1, y0, z0}, {x1, y1, z0}, {x0, y1, z0}, kFloor);
    }
    // A wall is drawn when the camera is on its inner side (else it would hide the cell).
    if (centre_W.x() > x0) add_quad({x0, y0, z0}, {x0, y1, z0}, {x0, y1, z1}, {x0, y0, z1}, kWall);
    if (centre_W.x() < x1) {
      add_quad({x1, y0, z0}, {x1, y1, z0}, {x1, y1, z1}, {x1, y0, z1}, kWall + 1);
    }
    if (centre_W.y() > y0) {
      add_quad({x0, y0, z0}, {x1, y0, z0}, {x1, y0, z1}, {x0, y0, z1}, kWall + 2);
    }
    if (centre_W.y() < y1) {
      add_quad({x0, y1, z0}, {x1, y1, z0}, {x1, y1, z1}, {x0, y1, z1}, kWall + 3);
    }
    for (const auto* list : {&scene.obstacles, &scene.foreground_objects}) {
      for (const Solid& solid : *list) {
        const geometry::TriangleMesh mesh = Tessellate(solid.geometry);
        for (const auto& t : mesh.triangles) {
          const Vector3d& p0 = mesh.vertices[t[0]];
          const Vector3d& p1 = mesh.vertices[t[1]];
          const Vector3d& p2 = mesh.vertices[t[2]];
          const Vector3d normal = (p1 - p0).cross(p2 - p0);
          if (!(normal.norm() > 0.0)) continue;
          triangles.push_back({{p0, p1, p2}, normal.normalized(), solid.colour, kObject});
        }
      }
    }
    return triangles;
  }

  /// Z-buffer rasterisation of one triangle into the canvas, clipped at the
  /// near plane; depth is interpolated as 1/z, which is affine in the image.
  void Rasterise(const StaticTriangle& tri, int id, const Matrix3d& K_canvas, int cw, int ch,
                 std::vector<float>* zbuf, std::vector<int>* ids) const {
    std::array<Vector3d, 3> p_C;
    for (int k = 0; k < 3; ++k) p_C[k] = camera.ToCamera(tri.p_W[k]);
    // Sutherland-Hodgman against z >= kNearM.
    std::array<Vector3d, 4> poly;
    int count = 0;
    for (int k = 0; k < 3; ++k) {
      const Vector3d& cur = p_C[k];
      const Vector3d& next = p_C[(k + 1) % 3];
      const bool cur_in = cur.z() >= kNearM;
      const bool next_in = next.z() >= kNearM;
      if (cur_in) poly[count++] = cur;
      if (cur_in != next_in) {
        const double s = (kNearM - cur.z()) / (next.z() - cur.z());
        poly[count++] = cur + s * (next - cur);
      }
    }
    for (int k = 1; k + 1 < count; ++k) {
      RasteriseClipped({poly[0], poly[k], poly[k + 1]}, id, K_canvas, cw, ch, zbuf, ids);
    }
  }

  static void RasteriseClipped(const std::array<Vector3d, 3>& p_C, int id, const Matrix3d& K_canvas,
                               int cw, int ch, std::vector<float>* zbuf, std::vector<int>* ids) {
    std::array<Vector2d, 3> s;
    std::array<double, 3> inv_z;
    for (int k = 0; k < 3; ++k) {
      const Vector3d q = K_canvas * (p_C[k] / p_C[k].z());
      s[k] = q.head<2>();
      inv_z[k] = 1.0 / p_C[k].z();
    }
    const double area =
        (s[1] - s[0]).x() * (s[2] - s[0]).y() - (s[1] - s[0]).y() * (s[2] - s[0]).x();
    if (!(std::abs(area) > 1e-12)) return;
    const double min_x = std::min({s[0].x(), s[1].x(), s[2].x()});
    const double max_x = std::max({s[0].x(), s[1].x(), s[2].x()});
    const double min_y = std::min({s[0].y(), s[1].y(), s[2].y()});
    const double max_y = std::max({s[0].y(), s[1].y(), s[2].y()});
    const int u0 = std::max(0, static_cast<int>(std::ceil(std::max(min_x, -1.0))));
    const int u1 = std::min(cw - 1, static_cast<int>(std::floor(std::min(max_x, cw + 1.0))));
    const int v0 = std::max(0, static_cast<int>(std::ceil(std::max(min_y, -1.0))));
    const int v1 = std::min(ch - 1, static_cast<int>(std::floor(std::min(max_y, ch + 1.0))));
    const double inv_area = 1.0 / area;
    for (int v = v0; v <= v1; ++v) {
      for (int u = u0; u <= u1; ++u) {
        const Vector2d p(u, v);
        double w[3];
        for (int k = 0; k < 3; ++k) {
          const Vector2d& e0 = s[(k + 1) % 3];
          const Vector2d& e1 = s[(k + 2) % 3];
          w[k] = ((e1 - e0).x() * (p - e0).y() - (e1 - e0).y() * (p - e0).x()) * inv_area;
        }
        if (w[0] < 0.0 || w[1] < 0.0 || w[2] < 0.0) continue;
        const double iz = w[0] * inv_z[0] + w[1] * inv_z[1] + w[2] * inv_z[2];
        if (!(iz > 0.0)) continue;
        const auto z = static_cast<float>(1.0 / iz);
        const std::size_t i = static_cast<std::size_t>(v) * cw + u;
        if (z < (*zbuf)[i]) {
          (*zbuf)[i] = z;
          (*ids)[i] = id;
        }
      }
    }
  }

  static bool Shadowed(const std::vector<Occluder>& occluders, const Vector3d& p_W,
                       const Vector3d& to_light) {
    constexpr double kStart = 1e-4;  // Leaves the surface the point lies on.
    for (const Occluder& o : occluders) {
      if (!SegmentHitsBox(p_W, to_light, o.bounds, kStart, 1.0)) continue;
      for (const auto& t : o.mesh.triangles) {
        if (SegmentHitsTriangle(p_W, to_light, o.mesh.vertices[t[0]], o.mesh.vertices[t[1]],
                                o.mesh.vertices[t[2]], kStart, 1.0)) {
          return true;
        }
      }
    }
    return false;
  }

  /// Soft floor shadows of one capsule: the capsule's shadow on the floor
  /// plane, seen from the lamp, is the capsule of the projected end points
  /// with radius growing as the lamp's magnification; floor pixels within
  /// softness / 2 of its edge fade smoothly. Writes the largest shadow amount
  /// (0..255) into `shadow` and grows the touched rectangle.
  void CapsuleShadow(const Vector3d& a_W, const Vector3d& b_W, double r,
                     std::array<int, 4>* touched) const {
    const Vector3d& L = imaging.light_W;
    const double lamp_height = L.z() - floor_z;
    if (!(lamp_height > 0.0) || a_W.z() >= L.z() - 1e-3 || b_W.z() >= L.z() - 1e-3) return;
    const double ka = lamp_height / (L.z() - a_W.z());
    const double kb = lamp_height / (L.z() - b_W.z());
    const Vector2d sa = L.head<2>() + (a_W.head<2>() - L.head<2>()) * ka;
    const Vector2d sb = L.head<2>() + (b_W.head<2>() - L.head<2>()) * kb;
    const double ra = r * ka;
    const double rb = r * kb;
    const double soft = std::max(1e-3, imaging.shadow_softness_m);
    const double reach = std::max(ra, rb) + 0.5 * soft;
    const Vector2d lo = sa.cwiseMin(sb) - Vector2d::Constant(reach);
    const Vector2d hi = sa.cwiseMax(sb) + Vector2d::Constant(reach);
    NormBox box;
    for (int k = 0; k < 4 && !box.unbounded; ++k) {
      const Vector3d p_C =
          camera.ToCamera(Vector3d((k & 1) ? hi.x() : lo.x(), (k & 2) ? hi.y() : lo.y(), floor_z));
      if (p_C.z() < kNearM) {
        box.unbounded = true;
      } else {
        box.Extend(p_C.x() / p_C.z(), p_C.y() / p_C.z());
      }
    }
    int u0;
    int u1;
    int v0;
    int v1;
    PixelRect(box, &u0, &u1, &v0, &v1);
    if (u1 < u0 || v1 < v0) return;
    (*touched)[0] = std::min((*touched)[0], u0);
    (*touched)[1] = std::max((*touched)[1], u1);
    (*touched)[2] = std::min((*touched)[2], v0);
    (*touched)[3] = std::max((*touched)[3], v1);
    // Relative to the shadow's start point, in float.
    const auto ex = static_cast<float>(sb.x() - sa.x());
    const auto ey = static_cast<float>(sb.y() - sa.y());
    const float len2 = ex * ex + ey * ey;
    const float inv_len2 = len2 > 0.0F ? 1.0F / len2 : 0.0F;
    const auto ra_f = static_cast<float>(ra);
    const auto dr = static_cast<float>(rb - ra);
    const auto inv_soft = static_cast<float>(1.0 / soft);
    // Floor point of a ray relative to sa: (H0 . r, H1 . r) / (H2 . r).
    std::array<std::array<float, 3>, 3> h;
    for (int k = 0; k < 3; ++k) {
      h[0][k] = static_cast<float>(floor_h[0][k] - sa.x() * floor_h[2][k]);
      h[1][k] = static_cast<float>(floor_h[1][k] - sa.y() * floor_h[2][k]);
      h[2][k] = static_cast<float>(floor_h[2][k]);
    }
    const int n = u1 - u0 + 1;
    for (int v = v0; v <= v1; ++v) {
      const std::size_t row = static_cast<std::size_t>(v) * width + u0;
      const std::uint8_t* __restrict ratio = floor_shadow_ratio.data() + row;
      std::uint8_t* __restrict out = shadow.data() + row;
      const float* __restrict xs = pinhole ? nullptr : ray_x.data() + row;
      const float* __restrict ys = pinhole ? nullptr : ray_y.data() + row;
      const auto y_row = static_cast<float>((v - camera.K(1, 2)) / camera.K(1, 1));
      const auto x_row =
          static_cast<float>((u0 - camera.K(0, 2) - camera.K(0, 1) * y_row) / camera.K(0, 0));
      const auto dx = static_cast<float>(1.0 / camera.K(0, 0));
      for (int i = 0; i < n; ++i) {
        const float x = pinhole ? x_row + dx * static_cast<float>(i) : xs[i];
        const float y = pinhole ? y_row : ys[i];
        const float w = h[2][0] * x + h[2][1] * y + h[2][2];
        const float fx = (h[0][0] * x + h[0][1] * y + h[0][2]) / w;
        const float fy = (h[1][0] * x + h[1][1] * y + h[1][2]) / w;
        float s = (fx * ex + fy * ey) * inv_len2;
        s = s > 0.0F ? s : 0.0F;  // Also maps NaN (no ray) to 0.
        s = s < 1.0F ? s : 1.0F;
        const float gx = fx - s * ex;
        const float gy = fy - s * ey;
        const float d = std::sqrt(gx * gx + gy * gy) - (ra_f + s * dr);
        float amount = 0.5F - d * inv_soft;
        amount = amount > 0.0F ? amount : 0.0F;  // Also maps NaN to no shadow.
        amount = amount < 1.0F ? amount : 1.0F;
        const float smooth = amount * amount * (3.0F - 2.0F * amount);
        const auto q = static_cast<std::uint8_t>(255.0F * smooth + 0.5F);
        const std::uint8_t masked = ratio[i] != 0 ? q : 0;
        out[i] = std::max(out[i], masked);
      }
    }
  }

  /// Ray-casts one body capsule into the frame with a depth test.
  void DrawCapsule(const BodyCapsule& part, const Rgb& colour, std::uint8_t* rgb) const {
    const Vector3d a = camera.ToCamera(part.a_W);
    const Vector3d b = camera.ToCamera(part.b_W);
    const double r = part.radius_m;
    if (!(r > 0.0) || std::max(a.z(), b.z()) + r <= 0.0) return;
    int u0;
    int u1;
    int v0;
    int v1;
    PixelRect(CapsuleNormBox(a, b, r * 1.001 + 1e-4), &u0, &u1, &v0, &v1);
    if (u1 < u0) return;
    const double ambient = std::clamp(imaging.ambient, 0.0, 1.0);
    const Vector3d e = b - a;
    const double len2 = e.squaredNorm();
    // Cheap float prefilter before the exact entry: does the pixel's ray pass
    // within r of the segment (see the mask renderer for the algebra)?
    const auto r2 = static_cast<float>(r * r * 1.01 + 1e-8);
    const auto ax = static_cast<float>(a.x());
    const auto ay = static_cast<float>(a.y());
    const auto az = static_cast<float>(a.z());
    const auto bx = static_cast<float>(b.x());
    const auto by = static_cast<float>(b.y());
    const auto bz = static_cast<float>(b.z());
    const int n = u1 - u0 + 1;
    std::uint8_t* __restrict flags = row_flags.data();
    for (int v = v0; v <= v1; ++v) {
      const std::size_t row = static_cast<std::size_t>(v) * width + u0;
      const float* __restrict xs = pinhole ? nullptr : ray_x.data() + row;
      const float* __restrict ys = pinhole ? nullptr : ray_y.data() + row;
      const auto y_row = static_cast<float>((v - camera.K(1, 2)) / camera.K(1, 1));
      const auto x_row =
          static_cast<float>((u0 - camera.K(0, 2) - camera.K(0, 1) * y_row) / camera.K(0, 0));
      const auto dx = static_cast<float>(1.0 / camera.K(0, 0));
      for (int i = 0; i < n; ++i) {
        const float x = pinhole ? x_row + dx * static_cast<float>(i) : xs[i];
        const float y = pinhole ? y_row : ys[i];
        const float p0 = ay - az * y;
        const float p1 = az * x - ax;
        const float p2 = ax * y - ay * x;
        const float q0 = by - bz * y;
        const float q1 = bz * x - bx;
        const float q2 = bx * y - by * x;
        const float e0 = q0 - p0;
        const float e1 = q1 - p1;
        const float e2 = q2 - p2;
        const float t = r2 * (x * x + y * y + 1.0F);
        const float ca = p0 * p0 + p1 * p1 + p2 * p2;
        const float cb = q0 * q0 + q1 * q1 + q2 * q2;
        const float aa = e0 * e0 + e1 * e1 + e2 * e2;
        const float bb = p0 * e0 + p1 * e1 + p2 * e2;
        const bool hit =
            (ca <= t) | (cb <= t) | ((bb < 0.0F) & (-bb < aa) & (aa * ca - bb * bb <= t * aa));
        flags[i] = hit ? 1 : 0;
      }
      for (int i = 0; i < n; ++i) {
        if (!flags[i]) continue;
        const int u = u0 + i;
        double x;
        double y;
        if (!Ray(u, v, &x, &y)) continue;
        const Vector3d ray(x, y, 1.0);
        const double t = CapsuleEntry(ray, a, b, r);
        const std::size_t pi = row + i;
        if (!(t < depth[pi]) || !(t > 0.0)) continue;
        depth[pi] = static_cast<float>(t);
        const Vector3d p = t * ray;
        const double s = len2 > 0.0 ? std::clamp((p - a).dot(e) / len2, 0.0, 1.0) : 0.0;
        Vector3d normal = p - (a + s * e);
        const double nn = normal.norm();
        normal = nn > 0.0 ? Vector3d(normal / nn) : Vector3d(-ray.normalized());
        const double lambert = std::max(0.0, normal.dot((light_C - p).normalized()));
        const auto lit = static_cast<float>(ambient + (1.0 - ambient) * lambert);
        for (int c = 0; c < 3; ++c) {
          rgb[3 * pi + c] =
              static_cast<std::uint8_t>(std::clamp(255.0F * colour[c] * lit + 0.5F, 0.0F, 255.0F));
        }
      }
    }
  }

  void Render(const std::vector<BodyState>& people, double t_s, std::uint64_t frame_index,
              common::ImageRgb8* out) const {
    const std::size_t n = static_cast<std::size_t>(width) * height;
    if (out->width != width || out->height != height || out->pixels.size() != 3 * n) {
      *out = common::ImageRgb8(width, height);
    }
    std::uint8_t* rgb = out->pixels.data();
    std::copy(static_rgb.begin(), static_rgb.end(), rgb);
    std::copy(static_depth.begin(), static_depth.end(), depth.begin());

    if (imaging.shadows) {
      std::array<int, 4> touched = {width, -1, height, -1};  // u0, u1, v0, v1
      for (const BodyState& person : people) {
        for (const BodyCapsule& part : person.parts) {
          CapsuleShadow(part.a_W, part.b_W, part.radius_m, &touched);
        }
      }
      for (int v = touched[2]; v <= touched[3]; ++v) {
        for (int u = touched[0]; u <= touched[1]; ++u) {
          const std::size_t i = static_cast<std::size_t>(v) * width + u;
          if (shadow[i] == 0) continue;
          // Lit floor keeps `ratio` of its brightness in full shadow.
          const float s = shadow[i] * (1.0F / 255.0F);
          const float k = 1.0F - s * (1.0F - floor_shadow_ratio[i] * (1.0F / 255.0F));
          for (int c = 0; c < 3; ++c) {
            rgb[3 * i + c] = static_cast<std::uint8_t>(rgb[3 * i + c] * k + 0.5F);
          }
          shadow[i] = 0;
        }
      }
    }

    for (std::size_t p = 0; p < people.size(); ++p) {
      for (int k = 0; k < kNumBodyParts; ++k) {
        const Rgb colour = p < part_colours.size() ? part_colours[p][k] : UnknownPerson();
        DrawCapsule(people[p].parts[k], colour, rgb);
      }
    }

    // Global light change and sensor noise, in fixed point (1/16 grey level).
    // The noise of a sample is a pure function of (seed, frame, camera, sample
    // index): frames are reproducible and renders share no random state.
    double gain = 1.0;
    if (imaging.light_change_period_s > 0.0) {
      gain += imaging.light_change_amplitude *
              std::sin(2.0 * M_PI * t_s / imaging.light_change_period_s);
    }
    gain = std::max(0.0, gain);
    if (gain == 1.0 && !has_noise) return;
    std::array<std::int32_t, 256> scaled;
    for (int i = 0; i < 256; ++i) {
      scaled[i] = static_cast<std::int32_t>(std::lround(i * gain * 16.0)) + 8;
    }
    const std::size_t samples = 3 * n;
    if (!has_noise) {
      for (std::size_t j = 0; j < samples; ++j) {
        rgb[j] = static_cast<std::uint8_t>(std::min(scaled[rgb[j]] >> 4, 255));
      }
      return;
    }
    const std::int16_t* noise = noise16.data();
    const std::uint64_t key = SplitMix64(
        imaging.seed ^ SplitMix64(frame_index ^ SplitMix64(0xC0FFEE00ULL + camera_index)));
    std::size_t j = 0;
    auto apply = [&](std::size_t sample, std::uint64_t bits) {
      const int value = (scaled[rgb[sample]] + noise[bits & 0xFFFF]) >> 4;
      rgb[sample] = static_cast<std::uint8_t>(std::clamp(value, 0, 255));
    };
    for (; j + 4 <= samples; j += 4) {
      const std::uint64_t h = SplitMix64(key + j);
      apply(j, h);
      apply(j + 1, h >> 16);
      apply(j + 2, h >> 32);
      apply(j + 3, h >> 48);
    }
    const std::uint64_t h = SplitMix64(key + j);
    for (int k = 0; j < samples; ++j, ++k) apply(j, h >> (16 * k));
  }
};

ColourRenderer::ColourRenderer(const Scene& scene, int camera_index)
    : impl_(std::make_unique<Impl>(scene, camera_index)) {}
ColourRenderer::~ColourRenderer() = default;
ColourRenderer::ColourRenderer(ColourRenderer&&) noexcept = default;
ColourRenderer& ColourRenderer::operator=(ColourRenderer&&) noexcept = default;

void ColourRenderer::Render(const std::vector<BodyState>& people, double t_s,
                            std::uint64_t frame_index, common::ImageRgb8* out) const {
  impl_->Render(people, t_s, frame_index, out);
}

void ColourRenderer::RenderEmpty(common::ImageRgb8* out) const {
  const Impl& impl = *impl_;
  const std::size_t n = static_cast<std::size_t>(impl.width) * impl.height;
  if (out->width != impl.width || out->height != impl.height || out->pixels.size() != 3 * n) {
    *out = common::ImageRgb8(impl.width, impl.height);
  }
  std::copy(impl.static_rgb.begin(), impl.static_rgb.end(), out->pixels.begin());
}

}  // namespace hg::sim
