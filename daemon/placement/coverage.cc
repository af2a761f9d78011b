#include "placement/coverage.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <vector>

#include <Eigen/Geometry>

#include "common/check.h"
#include "geometry/obstacle_depth.h"
#include "sim/solids.h"

namespace hg::placement {
namespace {

using Eigen::Vector3d;

/// Corners closer to the camera plane than this (camera z, m) are not seen:
/// no lens focuses there, and it keeps every projection finite.
constexpr double kNearM = 0.01;

/// Pixel-coordinate margin of the reduced image: image bounds shrink and
/// footprints grow by it, which covers the float rounding of the projected
/// corners (|u| < 1e4 pixels, float epsilon 6e-8).
constexpr double kPixelMargin = 1e-3;

/// Squared distance between the half-line {t d : t >= 0} (unit d) and the
/// segment a-b, where points of the half-line beyond t_max do not matter
/// (t_max >= |a|, |b|). The distance between two segments is a convex
/// function of the pair of parameters; the minimiser below clamps the
/// unconstrained one and re-solves each side on the clamped boundary.
double RaySegmentDistance2(const Vector3d& d, double t_max, const Vector3d& a, const Vector3d& b) {
  const Vector3d e = b - a;
  const double ee = e.squaredNorm();
  const double de = d.dot(e);
  const double da = d.dot(a);
  const double ea = e.dot(a);
  double t = 0.0;
  double s = 0.0;
  if (ee <= 0.0) {
    t = std::clamp(da, 0.0, t_max);
  } else {
    const double denom = ee - de * de;  // |d|^2 |e|^2 - (d.e)^2 with |d| = 1.
    s = denom > 1e-12 * ee ? std::clamp((de * da - ea) / denom, 0.0, 1.0) : 0.0;
    t = da + s * de;
    if (t < 0.0) {
      t = 0.0;
      s = std::clamp(-ea / ee, 0.0, 1.0);
    } else if (t > t_max) {
      t = t_max;
      s = std::clamp((t_max * de - ea) / ee, 0.0, 1.0);
    }
  }
  return (t * d - (a + s * e)).squaredNorm();
}

/// Full-resolution pixels per reduced pixel.
double ReductionOf(const geometry::CameraModel& camera, int width_px) {
  return std::max(1.0, static_cast<double>(camera.width) / width_px);
}

/// Conservative silhouette of a capsule in the reduced camera `cam`
/// (world -> camera from `cam`): a pixel is set when some capsule point in
/// front of the camera projects into its square. Test: the ray through the
/// pixel centre passes within radius + D * h of the axis, where D bounds the
/// distance of capsule points from the camera and h the sine of the angle
/// between the centre ray and any ray through the square.
void RenderSilhouette(const geometry::CameraModel& cam, const PersonSample& person, Silhouette* sil,
                      std::vector<std::uint8_t>* mask) {
  const Vector3d a = cam.R_CW * person.a_W + cam.t_CW;
  const Vector3d b = cam.R_CW * person.b_W + cam.t_CW;
  const double r = person.radius_m;
  const double fx = cam.K(0, 0);
  const double sk = cam.K(0, 1);
  const double cx = cam.K(0, 2);
  const double fy = cam.K(1, 1);
  const double cy = cam.K(1, 2);

  sil->u0 = 0;
  sil->v0 = 0;
  sil->u1 = -1;
  sil->v1 = -1;

  // Image points lie within a cone of normalised radius rho around the axis,
  // so a person point that projects into the image with camera z < kNearM is
  // closer than kNearM * sqrt(1 + rho^2) to the camera centre. A person that
  // close fills the whole image (it blocks everything); otherwise the part
  // in front of the near plane holds every point that projects into the image.
  double rho2 = 0.0;
  for (const double u : {-0.5, cam.width - 0.5}) {
    for (const double v : {-0.5, cam.height - 0.5}) {
      const double yn = (v - cy) / fy;
      const double xn = (u - cx - sk * yn) / fx;
      rho2 = std::max(rho2, xn * xn + yn * yn);
    }
  }
  const double close = r + kNearM * std::sqrt(1.0 + rho2) + 1e-6;
  {
    const Vector3d e = b - a;
    const double ee = e.squaredNorm();
    const double s = ee > 0.0 ? std::clamp(-a.dot(e) / ee, 0.0, 1.0) : 0.0;
    if ((a + s * e).norm() <= close) {
      sil->u0 = 0;
      sil->v0 = 0;
      sil->u1 = cam.width - 1;
      sil->v1 = cam.height - 1;
      const int sw = cam.width;
      const int sh = cam.height;
      sil->sat.assign(static_cast<std::size_t>(sw + 1) * (sh + 1), 0);
      for (int y = 1; y <= sh; ++y) {
        for (int x = 1; x <= sw; ++x) sil->sat[static_cast<std::size_t>(y) * (sw + 1) + x] = x * y;
      }
      return;
    }
  }

  // Pixel range: the projection of the capsule's bounding box clipped to the
  // near plane (its corners in front and where its edges cross the plane).
  const Vector3d lo = person.a_W.cwiseMin(person.b_W).array() - r;
  const Vector3d hi = person.a_W.cwiseMax(person.b_W).array() + r;
  std::array<Vector3d, 8> corner;
  for (int i = 0; i < 8; ++i) {
    const Vector3d p_W((i & 1) ? hi.x() : lo.x(), (i & 2) ? hi.y() : lo.y(),
                       (i & 4) ? hi.z() : lo.z());
    corner[i] = cam.R_CW * p_W + cam.t_CW;
  }
  double umin = std::numeric_limits<double>::infinity();
  double umax = -umin;
  double vmin = umin;
  double vmax = -umin;
  auto extend = [&](const Vector3d& p) {
    const double u = (fx * p.x() + sk * p.y()) / p.z() + cx;
    const double v = fy * p.y() / p.z() + cy;
    umin = std::min(umin, u);
    umax = std::max(umax, u);
    vmin = std::min(vmin, v);
    vmax = std::max(vmax, v);
  };
  for (int i = 0; i < 8; ++i) {
    if (corner[i].z() >= kNearM) extend(corner[i]);
    for (int bit = 1; bit < 8; bit <<= 1) {
      const int j = i | bit;
      if (j == i) continue;
      const double zi = corner[i].z() - kNearM;
      const double zj = corner[j].z() - kNearM;
      if ((zi >= 0.0) == (zj >= 0.0)) continue;
      Vector3d p = corner[i] + (corner[j] - corner[i]) * (zi / (zi - zj));
      p.z() = kNearM;
      extend(p);
    }
  }
  if (!(umin <= umax)) return;  // Wholly behind the near plane.
  // One pixel more on each side for the dilation of the test below; the
  // clamping keeps the casts in range.
  const double big = 1e6;
  const int u0 = std::max(0, static_cast<int>(std::floor(std::max(umin, -big) + 0.5)) - 1);
  const int u1 =
      std::min(cam.width - 1, static_cast<int>(std::floor(std::min(umax, big) + 0.5)) + 1);
  const int v0 = std::max(0, static_cast<int>(std::floor(std::max(vmin, -big) + 0.5)) - 1);
  const int v1 =
      std::min(cam.height - 1, static_cast<int>(std::floor(std::min(vmax, big) + 0.5)) + 1);
  if (u1 < u0 || v1 < v0) return;

  // Largest offset from a pixel centre to its corners, in normalised image
  // coordinates; sin(angle between the rays) <= that offset.
  double h = 0.0;
  for (const double du : {-0.5, 0.5}) {
    for (const double dv : {-0.5, 0.5}) {
      const double yn = dv / fy;
      const double xn = (du - sk * yn) / fx;
      h = std::max(h, std::hypot(xn, yn));
    }
  }
  const double reach = std::max(a.norm(), b.norm()) + r;
  const double grown = (r + reach * h) * (1.0 + 1e-9) + 1e-9;
  const double grown2 = grown * grown;

  const int w = u1 - u0 + 1;
  const int hgt = v1 - v0 + 1;
  mask->assign(static_cast<std::size_t>(w) * hgt, 0);
  int bu0 = u1 + 1;
  int bu1 = u0 - 1;
  int bv0 = v1 + 1;
  int bv1 = v0 - 1;
  // The pixels whose centre ray meets the grown capsule form a convex set
  // (the image of the capsule's viewing cone), so each row is one run. The
  // run is found from a guess (the middle of the previous row's run) by
  // searching outwards, then followed to both ends.
  int guess = (u0 + u1) / 2;
  for (int v = v0; v <= v1; ++v) {
    const double yn = (v - cy) / fy;
    auto hit = [&](int u) {
      const double xn = (u - cx - sk * yn) / fx;
      return RaySegmentDistance2(Vector3d(xn, yn, 1.0).normalized(), reach, a, b) <= grown2;
    };
    int found = -1;
    for (int step = 0; found < 0 && (guess - step >= u0 || guess + step <= u1); ++step) {
      if (guess - step >= u0 && hit(guess - step)) {
        found = guess - step;
      } else if (step > 0 && guess + step <= u1 && hit(guess + step)) {
        found = guess + step;
      }
    }
    if (found < 0) continue;
    int left = found;
    while (left > u0 && hit(left - 1)) --left;
    int right = found;
    while (right < u1 && hit(right + 1)) ++right;
    guess = (left + right) / 2;
    std::fill_n(mask->begin() + static_cast<std::ptrdiff_t>(v - v0) * w + (left - u0),
                right - left + 1, std::uint8_t{1});
    bu0 = std::min(bu0, left);
    bu1 = std::max(bu1, right);
    bv0 = std::min(bv0, v);
    bv1 = std::max(bv1, v);
  }
  if (bu1 < bu0) return;
  sil->u0 = bu0;
  sil->u1 = bu1;
  sil->v0 = bv0;
  sil->v1 = bv1;
  const int sw = bu1 - bu0 + 1;
  const int sh = bv1 - bv0 + 1;
  sil->sat.assign(static_cast<std::size_t>(sw + 1) * (sh + 1), 0);
  for (int y = 0; y < sh; ++y) {
    std::int32_t row = 0;
    for (int x = 0; x < sw; ++x) {
      row += (*mask)[static_cast<std::size_t>(y + bv0 - v0) * w + (x + bu0 - u0)];
      sil->sat[static_cast<std::size_t>(y + 1) * (sw + 1) + (x + 1)] =
          sil->sat[static_cast<std::size_t>(y) * (sw + 1) + (x + 1)] + row;
    }
  }
}

}  // namespace

bool Silhouette::Touches(const Footprint& rect) const {
  const int x0 = std::max<int>(rect.u0, u0);
  const int x1 = std::min<int>(rect.u1, u1);
  const int y0 = std::max<int>(rect.v0, v0);
  const int y1 = std::min<int>(rect.v1, v1);
  if (x1 < x0 || y1 < y0) return false;
  const int stride = u1 - u0 + 2;
  const auto at = [&](int x, int y) {
    return sat[static_cast<std::size_t>(y - v0) * stride + (x - u0)];
  };
  return at(x1 + 1, y1 + 1) - at(x0, y1 + 1) - at(x1 + 1, y0) + at(x0, y0) > 0;
}

geometry::CameraModel ReducedCamera(const geometry::CameraModel& camera, int width_px) {
  const double s = ReductionOf(camera, width_px);
  geometry::CameraModel reduced = camera;
  reduced.distortion = {0, 0, 0, 0, 0};
  reduced.width = static_cast<int>(std::ceil(camera.width / s - 1e-9));
  reduced.height = static_cast<int>(std::ceil(camera.height / s - 1e-9));
  // Full-resolution coordinate x maps to (x + 0.5) / s - 0.5.
  reduced.K(0, 0) = camera.K(0, 0) / s;
  reduced.K(0, 1) = camera.K(0, 1) / s;
  reduced.K(0, 2) = (camera.K(0, 2) + 0.5) / s - 0.5;
  reduced.K(1, 1) = camera.K(1, 1) / s;
  reduced.K(1, 2) = (camera.K(1, 2) + 0.5) / s - 0.5;
  return reduced;
}

void ComputeView(const PlacementScene& scene, const geometry::CameraModel& camera, CameraView* view,
                 ViewScratch* scratch) {
  const VoxelGrid& g = scene.grid;
  const geometry::CameraModel cam = ReducedCamera(camera, scene.options.render_width_px);
  const double s = ReductionOf(camera, scene.options.render_width_px);
  // The real image extent in reduced coordinates (the last reduced column may
  // be partly outside the full-resolution image).
  const double u_lo = -0.5 + kPixelMargin;
  const double v_lo = -0.5 + kPixelMargin;
  const double u_hi = camera.width / s - 0.5 - kPixelMargin;
  const double v_hi = camera.height / s - 0.5 - kPixelMargin;

  // Project every grid corner once.
  const int nc = g.CornerCount();
  scratch->u.resize(nc);
  scratch->v.resize(nc);
  scratch->z.resize(nc);
  scratch->ok.resize(nc);
  const double fx = cam.K(0, 0);
  const double sk = cam.K(0, 1);
  const double cx = cam.K(0, 2);
  const double fy = cam.K(1, 1);
  const double cy = cam.K(1, 2);
  int c = 0;
  for (int k = 0; k <= g.nz; ++k) {
    for (int j = 0; j <= g.ny; ++j) {
      const Vector3d row_W = g.bounds.min + Vector3d(0.0, j * g.cell_m.y(), k * g.cell_m.z());
      const Vector3d row_C = cam.R_CW * row_W + cam.t_CW;
      const Vector3d step_C = cam.R_CW.col(0) * g.cell_m.x();
      for (int i = 0; i <= g.nx; ++i, ++c) {
        const Vector3d p = row_C + static_cast<double>(i) * step_C;
        scratch->z[c] = p.z();
        scratch->ok[c] = 0;
        scratch->u[c] = 0.0F;
        scratch->v[c] = 0.0F;
        if (p.z() > kNearM) {
          const double iz = 1.0 / p.z();
          const double u = (fx * p.x() + sk * p.y()) * iz + cx;
          const double v = fy * p.y() * iz + cy;
          scratch->u[c] = static_cast<float>(u);
          scratch->v[c] = static_cast<float>(v);
          scratch->ok[c] = u >= u_lo && u <= u_hi && v >= v_lo && v <= v_hi ? 1 : 0;
        }
      }
    }
  }

  view->voxels.clear();
  view->footprints.clear();
  view->silhouettes.resize(scene.samples.size());

  view->tiles_x = 0;
  view->tiles_y = 0;
  view->tile_start.assign(1, 0);
  view->tile_entries.clear();
  view->large_entries.clear();

  // Obstacle faces that can be nearest along a ray: of closed meshes, those
  // facing the camera; a camera inside a closed obstacle sees nothing.
  const Vector3d centre_W = camera.CentreW();
  scratch->facing.resize(scene.occluders.size());
  for (std::size_t o = 0; o < scene.occluders.size(); ++o) {
    const Occluder& occluder = scene.occluders[o];
    geometry::TriangleMesh& facing = scratch->facing[o];
    facing.vertices = occluder.mesh.vertices;
    facing.triangles.clear();
    if (!occluder.closed) {
      facing.triangles = occluder.mesh.triangles;
      continue;
    }
    if (occluder.bounds.Contains(centre_W) && sim::Contains(occluder.solid, centre_W)) {
      for (Silhouette& sil : view->silhouettes) sil.u1 = -1;
      return;
    }
    for (const auto& t : occluder.mesh.triangles) {
      const Vector3d& a = occluder.mesh.vertices[t[0]];
      const Vector3d n = (occluder.mesh.vertices[t[1]] - a).cross(occluder.mesh.vertices[t[2]] - a);
      if (n.dot(centre_W - a) >= 0.0) facing.triangles.push_back(t);
    }
  }
  const geometry::ObstacleDepthMap depth = geometry::RenderObstacleDepth(cam, scratch->facing);
  const geometry::DepthPyramid pyramid(depth.near_depth, depth.width, depth.height,
                                       geometry::DepthPyramid::Kind::kMin);
  const int width = cam.width;
  const int height = cam.height;
  // Prefix counts of the pixels that show an obstacle: most footprints hold
  // none, and then need no depth comparison.
  std::vector<std::int32_t>& any = scratch->obstacle_sat;
  any.assign(static_cast<std::size_t>(width + 1) * (height + 1), 0);
  for (int v = 0; v < height; ++v) {
    std::int32_t row = 0;
    for (int u = 0; u < width; ++u) {
      row += depth.near_depth[static_cast<std::size_t>(v) * width + u] <
                     geometry::ObstacleDepthMap::kNone
                 ? 1
                 : 0;
      any[static_cast<std::size_t>(v + 1) * (width + 1) + u + 1] =
          any[static_cast<std::size_t>(v) * (width + 1) + u + 1] + row;
    }
  }
  auto obstacle_pixels = [&](int u0, int v0, int u1, int v1) {
    const std::size_t w = width + 1;
    return any[(v1 + 1) * w + u1 + 1] - any[v0 * w + u1 + 1] - any[(v1 + 1) * w + u0] +
           any[v0 * w + u0];
  };

  const int sy = g.nx + 1;
  const int sz = (g.nx + 1) * (g.ny + 1);
  const std::array<int, 8> offsets = {0, 1, sy, sy + 1, sz, sz + 1, sz + sy, sz + sy + 1};
  const float* us = scratch->u.data();
  const float* vs = scratch->v.data();
  const double* zs = scratch->z.data();
  const std::uint8_t* oks = scratch->ok.data();
  for (int k = 0; k < g.nz; ++k) {
    for (int j = 0; j < g.ny; ++j) {
      int index = g.Index(0, j, k);
      int c0 = (k * (g.ny + 1) + j) * (g.nx + 1);
      for (int i = 0; i < g.nx; ++i, ++index, ++c0) {
        if (scene.obstacle[index] != 0) continue;
        bool all_ok = true;
        for (const int o : offsets) all_ok = all_ok && oks[c0 + o] != 0;
        if (!all_ok) continue;
        double zmin = zs[c0];
        double zmax = zmin;
        for (int o = 1; o < 8; ++o) {
          const double z = zs[c0 + offsets[o]];
          zmin = std::min(zmin, z);
          zmax = std::max(zmax, z);
        }
        if (!(zmin > kNearM)) continue;
        float umin = us[c0];
        float umax = umin;
        float vmin = vs[c0];
        float vmax = vmin;
        for (int o = 1; o < 8; ++o) {
          umin = std::min(umin, us[c0 + offsets[o]]);
          umax = std::max(umax, us[c0 + offsets[o]]);
          vmin = std::min(vmin, vs[c0 + offsets[o]]);
          vmax = std::max(vmax, vs[c0 + offsets[o]]);
        }
        if (umin < u_lo || umax > u_hi || vmin < v_lo || vmax > v_hi) continue;
        const int fu0 = std::max(0, static_cast<int>(std::floor(umin + 0.5 - kPixelMargin)));
        const int fu1 =
            std::min(width - 1, static_cast<int>(std::floor(umax + 0.5 + kPixelMargin)));
        const int fv0 = std::max(0, static_cast<int>(std::floor(vmin + 0.5 - kPixelMargin)));
        const int fv1 =
            std::min(height - 1, static_cast<int>(std::floor(vmax + 0.5 + kPixelMargin)));
        // Seen only when every footprint pixel shows obstacles behind the
        // voxel's farthest corner.
        if (obstacle_pixels(fu0, fv0, fu1, fv1) != 0) {
          // Small footprints read the pixels directly, larger ones the pyramid.
          bool clear = true;
          if ((fu1 - fu0 + 1) * (fv1 - fv0 + 1) <= 16) {
            for (int v = fv0; v <= fv1 && clear; ++v) {
              const float* row = depth.near_depth.data() + static_cast<std::size_t>(v) * width;
              for (int u = fu0; u <= fu1; ++u) clear = clear && static_cast<double>(row[u]) > zmax;
            }
          } else {
            clear = pyramid.AllGreater(geometry::PixelRect{fu0, fv0, fu1, fv1}, zmax);
          }
          if (!clear) continue;
        }
        view->voxels.push_back(index);
        view->footprints.push_back(
            Footprint{static_cast<std::int16_t>(fu0), static_cast<std::int16_t>(fv0),
                      static_cast<std::int16_t>(fu1), static_cast<std::int16_t>(fv1)});
      }
    }
  }

  for (std::size_t p = 0; p < scene.samples.size(); ++p) {
    RenderSilhouette(cam, scene.samples[p], &view->silhouettes[p], &scratch->mask);
  }

  // Tile index of the small footprints (counting sort by tile).
  const int t = CameraView::kFootprintTile;
  view->tiles_x = (width + t - 1) / t;
  view->tiles_y = (height + t - 1) / t;
  const int tiles = view->tiles_x * view->tiles_y;
  view->tile_start.assign(tiles + 1, 0);
  view->large_entries.clear();
  auto tile_of = [&](const Footprint& fp) { return (fp.v0 / t) * view->tiles_x + fp.u0 / t; };
  auto small = [&](const Footprint& fp) { return fp.u1 - fp.u0 < t && fp.v1 - fp.v0 < t; };
  const int entries = static_cast<int>(view->voxels.size());
  for (int e = 0; e < entries; ++e) {
    const Footprint& fp = view->footprints[e];
    if (small(fp)) {
      ++view->tile_start[tile_of(fp) + 1];
    } else {
      view->large_entries.push_back(e);
    }
  }
  for (int i = 0; i < tiles; ++i) view->tile_start[i + 1] += view->tile_start[i];
  view->tile_entries.resize(view->tile_start[tiles]);
  std::vector<std::int32_t>& fill = scratch->tile_fill;
  fill.assign(view->tile_start.begin(), view->tile_start.end() - 1);
  for (int e = 0; e < entries; ++e) {
    const Footprint& fp = view->footprints[e];
    if (small(fp)) view->tile_entries[fill[tile_of(fp)]++] = e;
  }
}

// ---------------------------------------------------------------------------
// Evaluator

struct Evaluator::WorkerScratch {
  ViewScratch view;
  std::vector<std::uint8_t> blocked;
  std::vector<std::int32_t> touched;
};

Evaluator::Evaluator(const PlacementScene& scene, const ObjectiveOptions& objective, int threads)
    : scene_(&scene),
      objective_(objective),
      pool_(std::make_unique<common::WorkerPool>(std::max(1, threads))) {
  workers_.resize(pool_->num_threads());
  for (WorkerScratch& w : workers_) w.blocked.assign(scene.grid.Count(), 0);
  counts_.assign(scene.grid.Count(), 0);
  certified_.assign(scene.samples.size(), 0);
  others_free_.resize(scene.samples.size());
  others_free_count_.assign(scene.samples.size(), 0);
}

Evaluator::~Evaluator() = default;

void Evaluator::ComputeViews(const std::vector<geometry::CameraModel>& cameras, int skip) {
  HG_CHECK(cameras.size() < 255);
  cameras_ = cameras;
  views_.resize(cameras.size());
  auto task = [&](int c, int worker) {
    if (c == skip) {
      views_[c].voxels.clear();
      views_[c].footprints.clear();
      views_[c].silhouettes.clear();
      return;
    }
    ComputeView(*scene_, cameras[c], &views_[c], &workers_[worker].view);
  };
  pool_->Run(static_cast<int>(cameras.size()), task);
  std::fill(counts_.begin(), counts_.end(), 0);
  for (const CameraView& view : views_) {
    for (const std::int32_t v : view.voxels) ++counts_[v];
  }
}

long long Evaluator::LostVoxels(int sample, int skip, WorkerScratch* scratch) {
  scratch->touched.clear();
  std::uint8_t* blocked = scratch->blocked.data();
  for (std::size_t c = 0; c < views_.size(); ++c) {
    if (static_cast<int>(c) == skip) continue;
    const CameraView& view = views_[c];
    const Silhouette& sil = view.silhouettes[sample];
    if (sil.Empty()) continue;
    view.ForEachNear(sil.u0, sil.v0, sil.u1, sil.v1, [&](std::int32_t i) {
      const Footprint& fp = view.footprints[i];
      if (fp.u1 < sil.u0 || fp.u0 > sil.u1 || fp.v1 < sil.v0 || fp.v0 > sil.v1) return;
      if (!sil.Touches(fp)) return;
      const std::int32_t v = view.voxels[i];
      if (blocked[v]++ == 0) scratch->touched.push_back(v);
    });
  }
  long long lost = 0;
  for (const std::int32_t v : scratch->touched) {
    if (blocked[v] == counts_[v]) ++lost;
  }
  return lost;
}

CoverageMetrics Evaluator::Finish(long long seen1, long long seen_k,
                                  const std::vector<long long>& certified) const {
  CoverageMetrics m;
  const double target = std::max(1, scene_->target_voxels);
  m.min_views = objective_.min_views;
  m.target_volume_m3 = scene_->TargetVolume();
  m.seen_fraction = seen1 / target;
  m.k_coverage = seen_k / target;
  m.free_fraction.resize(certified.size());
  double sum = 0.0;
  m.min_free_fraction = certified.empty() ? 0.0 : 1.0;
  for (std::size_t s = 0; s < certified.size(); ++s) {
    m.free_fraction[s] = certified[s] / target;
    sum += m.free_fraction[s];
    m.min_free_fraction = std::min(m.min_free_fraction, m.free_fraction[s]);
  }
  m.mean_free_fraction = certified.empty() ? 0.0 : sum / certified.size();
  m.mean_free_m3 = m.mean_free_fraction * m.target_volume_m3;
  m.score = m.mean_free_fraction + objective_.coverage_weight * m.k_coverage;
  return m;
}

CoverageMetrics Evaluator::Evaluate(const std::vector<geometry::CameraModel>& cameras) {
  varying_ = -1;
  ComputeViews(cameras, -1);
  long long seen1 = 0;
  long long seen_k = 0;
  for (const std::uint8_t n : counts_) {
    seen1 += n >= 1 ? 1 : 0;
    seen_k += n >= objective_.min_views ? 1 : 0;
  }
  auto task = [&](int s, int worker) {
    WorkerScratch& w = workers_[worker];
    certified_[s] = seen1 - LostVoxels(s, -1, &w);
    for (const std::int32_t v : w.touched) w.blocked[v] = 0;
  };
  pool_->Run(static_cast<int>(scene_->samples.size()), task);
  return Finish(seen1, seen_k, certified_);
}

void Evaluator::CertifiedFree(int sample, std::vector<std::uint8_t>* free) {
  HG_CHECK(varying_ < 0 && sample >= 0 && sample < static_cast<int>(scene_->samples.size()));
  WorkerScratch& w = workers_[0];
  (void)LostVoxels(sample, -1, &w);
  free->assign(counts_.size(), 0);
  for (std::size_t v = 0; v < counts_.size(); ++v) {
    (*free)[v] = counts_[v] > w.blocked[v] ? 1 : 0;
  }
  for (const std::int32_t v : w.touched) w.blocked[v] = 0;
}

std::vector<int> Evaluator::SeenVoxelsPerCamera() const {
  std::vector<int> out;
  for (const CameraView& view : views_) out.push_back(static_cast<int>(view.voxels.size()));
  return out;
}

void Evaluator::Freeze(const std::vector<geometry::CameraModel>& cameras, int varying) {
  HG_CHECK(varying >= 0 && varying < static_cast<int>(cameras.size()));
  ComputeViews(cameras, varying);
  varying_ = varying;
  others_seen1_ = 0;
  others_seen_k_ = 0;
  for (const std::uint8_t n : counts_) {
    others_seen1_ += n >= 1 ? 1 : 0;
    others_seen_k_ += n >= objective_.min_views ? 1 : 0;
  }
  auto task = [&](int s, int worker) {
    WorkerScratch& w = workers_[worker];
    (void)LostVoxels(s, varying, &w);
    std::vector<std::uint8_t>& free = others_free_[s];
    free.assign(counts_.size(), 0);
    long long count = 0;
    for (std::size_t v = 0; v < counts_.size(); ++v) {
      free[v] = counts_[v] > w.blocked[v] ? 1 : 0;
      count += free[v];
    }
    others_free_count_[s] = count;
    for (const std::int32_t v : w.touched) w.blocked[v] = 0;
  };
  pool_->Run(static_cast<int>(scene_->samples.size()), task);
}

CoverageMetrics Evaluator::EvaluateVarying(const geometry::CameraModel& camera) {
  HG_CHECK(varying_ >= 0);
  ComputeView(*scene_, camera, &varying_view_, &workers_[0].view);
  long long seen1 = others_seen1_;
  long long seen_k = others_seen_k_;
  const int k = objective_.min_views;
  for (const std::int32_t v : varying_view_.voxels) {
    const int n = counts_[v];
    seen1 += n == 0 ? 1 : 0;
    seen_k += n + 1 == k ? 1 : 0;
  }
  auto task = [&](int s, int /*worker*/) {
    const Silhouette& sil = varying_view_.silhouettes[s];
    const std::vector<std::uint8_t>& free = others_free_[s];
    long long gain = 0;
    const std::size_t n = varying_view_.voxels.size();
    for (std::size_t i = 0; i < n; ++i) {
      const std::int32_t v = varying_view_.voxels[i];
      if (free[v] != 0) continue;
      if (sil.Empty() || !sil.Touches(varying_view_.footprints[i])) ++gain;
    }
    certified_[s] = others_free_count_[s] + gain;
  };
  pool_->Run(static_cast<int>(scene_->samples.size()), task);
  return Finish(seen1, seen_k, certified_);
}

}  // namespace hg::placement
