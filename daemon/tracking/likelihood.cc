#include "tracking/likelihood.h"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace hg::tracking {
namespace {

/// Closed-form x extent of one row of a region: voxels [lo, hi].
struct Span {
  int lo = 0;
  int hi = -1;
};

/// Narrows `span` to the voxels of the row (centres (CentreX(x), py, pz))
/// inside half-space h. The predicate is monotone in x even in floating point
/// (normal.x * x is monotone, adding s rounds monotonically), so the closed-form
/// boundary is corrected by testing the voxels next to it: exact, two or three
/// predicate evaluations per row.
void ClipToHalfSpace(const VoxelGrid& g, const HalfSpace& h, double py, double pz, Span* span) {
  const double nx = h.normal.x();
  const double s = h.normal.y() * py + h.normal.z() * pz;
  auto inside = [&](int x) { return nx * g.CentreX(x) + s <= h.offset; };
  if (nx == 0.0) {
    if (!(s <= h.offset)) span->hi = span->lo - 1;
    return;
  }
  // Index where the centre reaches the plane (may be far outside or not finite).
  const double t = ((h.offset - s) / nx - g.origin().x()) / g.voxel_m() - 0.5;
  const double clamped = std::clamp(t, span->lo - 1.0, span->hi + 1.0);
  if (nx > 0.0) {  // Inside for small x: find the last inside voxel.
    int a = static_cast<int>(std::clamp(std::floor(clamped), span->lo - 1.0, static_cast<double>(span->hi)));
    while (a >= span->lo && !inside(a)) --a;
    while (a + 1 <= span->hi && inside(a + 1)) ++a;
    span->hi = a;
  } else {  // Inside for large x: find the first inside voxel.
    int a = static_cast<int>(std::clamp(std::ceil(clamped), static_cast<double>(span->lo), span->hi + 1.0));
    while (a <= span->hi && !inside(a)) ++a;
    while (a - 1 >= span->lo && inside(a - 1)) --a;
    span->lo = a;
  }
}

/// Voxels x (unclamped) of one row whose centres satisfy dx^2 + q <= 1, with
/// dx = (CentreX(x) - cx) / k: the closed-form ends, re-tested with that
/// predicate where they fall within `tol` of a voxel centre. Precondition: q <= 1.
Span RowSpan(const VoxelGrid& g, double cx, double k, double q, double tol) {
  auto inside = [&](int x) {
    const double dx = (g.CentreX(x) - cx) / k;
    return dx * dx + q <= 1.0;
  };
  const double w = std::sqrt(1.0 - q) * k;
  // Clamped far outside any grid so the casts stay in range.
  const double t_lo = std::clamp((cx - w - g.origin().x()) / g.voxel_m() - 0.5, -1e9, 1e9);
  const double t_hi = std::clamp((cx + w - g.origin().x()) / g.voxel_m() - 0.5, -1e9, 1e9);
  Span span{static_cast<int>(std::ceil(t_lo)), static_cast<int>(std::floor(t_hi))};
  const double j_lo = std::nearbyint(t_lo);
  if (std::abs(t_lo - j_lo) < tol) {
    const int j = static_cast<int>(j_lo);
    span.lo = inside(j) ? j : j + 1;
  }
  const double j_hi = std::nearbyint(t_hi);
  if (std::abs(t_hi - j_hi) < tol) {
    const int j = static_cast<int>(j_hi);
    span.hi = inside(j) ? j : j - 1;
  }
  return span;
}

}  // namespace

double Ellipsoid::Volume() const {
  return 4.0 / 3.0 * std::numbers::pi * half_axes_m.prod();
}

HalfSpace HalfSpace::NearerTo(const Eigen::Vector3d& own, const Eigen::Vector3d& other) {
  // |p - own|^2 <= |p - other|^2  <=>  2 (other - own) . p <= |other|^2 - |own|^2.
  HalfSpace h;
  h.normal = 2.0 * (other - own);
  h.offset = other.squaredNorm() - own.squaredNorm();
  return h;
}

EllipsoidCounts CountVoxels(const VoxelMap& map, const Ellipsoid& e,
                            std::span<const HalfSpace> own_region) {
  const VoxelGrid& g = map.grid();
  const double v = g.voxel_m();
  const Eigen::Vector3d& o = g.origin();
  const Eigen::Vector3d& c = e.centre_W;
  const Eigen::Vector3d& h = e.half_axes_m;
  EllipsoidCounts out;
  if (!(h.array() > 0.0).all() || !c.allFinite() || !h.allFinite()) return out;

  // Index range [lo, hi] of the centres within c +- half along an axis, with one
  // voxel of slack (rows outside the ellipsoid are skipped by the predicate),
  // unclamped but kept far from integer overflow.
  auto range = [&](int axis, double half, int* lo, int* hi) {
    *lo = static_cast<int>(std::clamp(std::floor((c[axis] - half - o[axis]) / v - 0.5), -1e9, 1e9));
    *hi = static_cast<int>(std::clamp(std::ceil((c[axis] + half - o[axis]) / v - 0.5), -1e9, 1e9));
  };
  // The closed-form row ends are trusted unless they fall within this many
  // voxels of a voxel centre; the predicate's rounding moves the boundary by at
  // most ~1.5e-8 * k / voxel there (at the tangent rows), far inside it.
  const double tol = 1e-6 * (1.0 + h.x() / v);
  const int nx = g.nx();
  int z_lo, z_hi;
  range(2, h.z(), &z_lo, &z_hi);
  int foreign = 0;
  for (int z = z_lo; z <= std::min(z_hi, g.nz() - 1); ++z) {
    const double pz = g.CentreZ(z);
    const double dz = (pz - c.z()) / h.z();
    const double dz2 = dz * dz;
    if (dz2 > 1.0) continue;
    int y_lo, y_hi;
    range(1, h.y() * std::sqrt(1.0 - dz2), &y_lo, &y_hi);
    if (z < 0) {  // Below the grid: every lattice position counts, any x and y.
      for (int y = y_lo; y <= y_hi; ++y) {
        const double dy = (g.CentreY(y) - c.y()) / h.y();
        const double q = dy * dy + dz2;
        if (q > 1.0) continue;
        const Span span = RowSpan(g, c.x(), h.x(), q, tol);
        if (span.hi >= span.lo) out.below_floor += span.hi - span.lo + 1;
      }
      continue;
    }
    for (int y = std::max(y_lo, 0); y <= std::min(y_hi, g.ny() - 1); ++y) {
      const double py = g.CentreY(y);
      const double dy = (py - c.y()) / h.y();
      const double q = dy * dy + dz2;
      if (q > 1.0) continue;  // dx^2 + q >= q > 1 also after rounding.
      Span span = RowSpan(g, c.x(), h.x(), q, tol);
      span.lo = std::max(span.lo, 0);
      span.hi = std::min(span.hi, nx - 1);
      if (span.lo > span.hi) continue;
      const RowCounts* p = map.RowPrefix(y, z);
      const RowCounts& a = p[span.lo];
      const RowCounts& b = p[span.hi + 1];
      const int unknown = b.unknown - a.unknown;
      const int occluded = b.occluded - a.occluded;
      const int known = b.known - a.known;
      out.unknown += unknown;
      out.occluded += occluded;
      out.known += known;
      out.free += (span.hi - span.lo + 1) - unknown - occluded - known;
      if (!own_region.empty() && unknown > 0) {
        Span own = span;
        for (const HalfSpace& hs : own_region) {
          ClipToHalfSpace(g, hs, py, pz, &own);
          if (own.lo > own.hi) break;
        }
        const int own_unknown =
            own.lo > own.hi ? 0 : p[own.hi + 1].unknown - p[own.lo].unknown;
        foreign += unknown - own_unknown;
      }
    }
  }
  out.unknown -= foreign;
  out.foreign_unknown = foreign;
  return out;
}

void AppendVoxelsInside(const VoxelGrid& g, const Ellipsoid& e, std::vector<std::uint32_t>* out) {
  const Eigen::Vector3i lo = g.VoxelOf(e.centre_W - e.half_axes_m).cwiseMax(0);
  const Eigen::Vector3i hi =
      g.VoxelOf(e.centre_W + e.half_axes_m).cwiseMin(Eigen::Vector3i(g.nx(), g.ny(), g.nz()) -
                                                     Eigen::Vector3i::Ones());
  for (int z = lo.z(); z <= hi.z(); ++z) {
    for (int y = lo.y(); y <= hi.y(); ++y) {
      for (int x = lo.x(); x <= hi.x(); ++x) {
        if (e.Contains(g.Centre(x, y, z))) out->push_back(g.Index(x, y, z));
      }
    }
  }
}

double Score(const EllipsoidCounts& n, const LikelihoodWeights& w) {
  return w.unknown * n.unknown + w.occluded * n.occluded + w.known * n.known +
         w.free * (n.free + n.foreign_unknown) + w.below_floor * n.below_floor;
}

}  // namespace hg::tracking
