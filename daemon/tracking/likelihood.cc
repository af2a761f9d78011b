#include "tracking/likelihood.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numbers>

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#endif

namespace hg::tracking {
namespace {

/// Floor and ceiling of |x| < 2^31 without a libm call (x86-64 without
/// SSE4.1 has no rounding instruction).
inline int FloorInt(double x) {
  const int i = static_cast<int>(x);
  return i - (x < i ? 1 : 0);
}
inline int CeilInt(double x) {
  const int i = static_cast<int>(x);
  return i + (x > i ? 1 : 0);
}

/// Closed-form x extent of one row of a region: voxels [lo, hi].
struct Span {
  int lo = 0;
  int hi = -1;
};

/// Narrows `span` to the indices where the monotone predicate `inside` holds:
/// it holds for small indices when `inside_for_small`, else for large ones.
/// `t` estimates the index where it changes (may be far outside or not
/// finite); the voxels next to the estimate are tested until the boundary is
/// found, so the result is exact whatever the estimate's error.
template <typename Inside>
void ClipMonotone(double t, bool inside_for_small, Inside inside, Span* span) {
  const double clamped = std::clamp(t, span->lo - 1.0, span->hi + 1.0);
  if (inside_for_small) {  // Find the last inside voxel.
    int a = std::clamp(FloorInt(clamped), span->lo - 1, span->hi);
    while (a >= span->lo && !inside(a)) --a;
    while (a + 1 <= span->hi && inside(a + 1)) ++a;
    span->hi = a;
  } else {  // Find the first inside voxel.
    int a = std::clamp(CeilInt(clamped), span->lo, span->hi + 1);
    while (a <= span->hi && !inside(a)) ++a;
    while (a - 1 >= span->lo && inside(a - 1)) --a;
    span->lo = a;
  }
}

/// Narrows `span` to the voxels of the row (centres (CentreX(x), py, pz))
/// inside half-space h. The predicate is monotone in x even in floating point
/// (normal.x * x is monotone, adding s rounds monotonically), so the closed-form
/// boundary is corrected by testing the voxels next to it: exact, two or three
/// predicate evaluations per row.
void ClipToHalfSpace(const VoxelGrid& g, const HalfSpace& h, double py, double pz, Span* span) {
  const double nx = h.normal.x();
  const double s = h.normal.y() * py + h.normal.z() * pz;
  auto inside = [&](int x) { return nx * g.CentreX(x) + s <= h.offset; };
  if (span->lo > span->hi) return;
  // Monotone: both ends inside, all inside; both outside, none. Mostly one of
  // the two (the plane between two people stands nearly upright).
  const bool lo_in = inside(span->lo);
  if (lo_in == inside(span->hi)) {
    if (!lo_in) span->hi = span->lo - 1;
    return;
  }
  const double t = ((h.offset - s) / nx - g.origin().x()) / g.voxel_m() - 0.5;
  ClipMonotone(t, nx > 0.0, inside, span);
}

/// The same for the voxels of the column (centres (px, py, CentreZ(z))), with
/// HalfSpace::Contains' arithmetic: n.x px + (n.y py + n.z pz), monotone in z.
void ClipColumnToHalfSpace(const VoxelGrid& g, const HalfSpace& h, double px, double py,
                           Span* span) {
  const double nz = h.normal.z();
  const double a = h.normal.x() * px;
  const double b = h.normal.y() * py;
  auto inside = [&](int z) { return a + (b + nz * g.CentreZ(z)) <= h.offset; };
  if (span->lo > span->hi) return;
  // Monotone: both ends inside, all inside; both outside, none. Mostly one of
  // the two (the plane between two people stands nearly upright).
  const bool lo_in = inside(span->lo);
  if (lo_in == inside(span->hi)) {
    if (!lo_in) span->hi = span->lo - 1;
    return;
  }
  // One division: the estimate needs no exactness (ClipMonotone corrects it).
  const double t = (h.offset - a - b - nz * g.origin().z()) / (nz * g.voxel_m()) - 0.5;
  ClipMonotone(t, nz > 0.0, inside, span);
}

/// One ellipsoid prepared for the row loops: reciprocals and the centre and
/// x half-axis in voxel index units (voxel i's centre sits at index i).
struct Prepared {
  Eigen::Vector3d c;
  Eigen::Vector3d inv_h;  // 1 / half-axes: the same values Ellipsoid::Contains uses.
  Eigen::Vector3d c_idx;  // (c - origin) / voxel - 0.5.
  Eigen::Vector3d h_idx;  // half-axes / voxel.
  double tol = 0.0;
};

/// Floor of -2^30 < x < 2^30 with one conversion: exact, except that x within
/// 2^-22 below an integer may round up to it. Callers treat every x within
/// their tolerance (>= 1e-6) of an integer as ambiguous and re-test it.
inline int FastFloor(double x) {
  constexpr double kOffset = 1073741824.0;  // 2^30: 0 < x + kOffset < 2^31, truncation floors.
  return static_cast<int>(x + kOffset) - 1073741824;
}

/// Indices [lo, hi] between the closed-form ends t_lo <= t_hi of an interval
/// where `inside` (the exact predicate, true on an interval of indices) holds:
/// the ends are re-tested with `inside` where they fall within `tol` of an
/// index.
template <typename Inside>
inline Span ExactSpan(double t_lo, double t_hi, double tol, Inside inside) {
  // First centre at or after t_lo, last at or before t_hi.
  const int f_lo = FastFloor(t_lo);
  const double r_lo = t_lo - f_lo;
  Span span{f_lo + 1, 0};
  if (r_lo < tol || r_lo > 1.0 - tol) {
    const int j = r_lo < 0.5 ? f_lo : f_lo + 1;
    span.lo = inside(j) ? j : j + 1;
  }
  const int f_hi = FastFloor(t_hi);
  const double r_hi = t_hi - f_hi;
  span.hi = f_hi;
  if (r_hi < tol || r_hi > 1.0 - tol) {
    const int j = r_hi < 0.5 ? f_hi : f_hi + 1;
    span.hi = inside(j) ? j : j - 1;
  }
  return span;
}

/// Voxels x (unclamped) of one row whose centres satisfy dx^2 + q <= 1, with
/// dx = (CentreX(x) - cx) / k: the closed-form ends, re-tested with that
/// predicate where they fall within `tol` of a voxel centre. Precondition: q <= 1.
inline Span RowSpan(const VoxelGrid& g, const Prepared& e, double q) {
  const double w = std::sqrt(1.0 - q) * e.h_idx.x();
  auto inside = [&](int x) {
    const double dx = (g.CentreX(x) - e.c.x()) * e.inv_h.x();
    return dx * dx + q <= 1.0;
  };
  return ExactSpan(e.c_idx.x() - w, e.c_idx.x() + w, e.tol, inside);
}

/// UNKNOWN voxels of a line (row or column: prefix counts p, voxels `span`,
/// packed counts `line`) outside the own region, whose half-spaces `clip`
/// narrows the span to.
template <typename Clip>
int ForeignUnknown(const RowCounts* p, Span span, std::uint64_t line,
                   std::span<const HalfSpace> region, Clip clip) {
  for (const HalfSpace& hs : region) {
    clip(hs, &span);
    if (span.lo > span.hi) break;
  }
  const int own = span.lo > span.hi ? 0 : p[span.hi + 1].unknown() - p[span.lo].unknown();
  return RowCounts::Unknown(line) - own;
}

/// Packed row or column differences summed into counts (flushed before a
/// field could overflow).
struct CountAccumulator {
  std::uint64_t packed = 0;
  int packed_rows = 0;
  int length = 0;
  int unknown = 0, occluded = 0, known = 0, free = 0;
  void Add(std::uint64_t row, int row_length) {
    packed += row;
    length += row_length;
    if (++packed_rows == RowCounts::kMaxSummedRows) Flush();
  }
  /// Flushes and writes the state counts into *out; `foreign` of the UNKNOWN
  /// voxels lie outside the own region.
  void FillCounts(int foreign, EllipsoidCounts* out) {
    Flush();
    out->unknown = unknown - foreign;
    out->foreign_unknown = foreign;
    out->occluded = occluded;
    out->known = known;
    out->free = free;
  }
  void Flush() {
    const int u = RowCounts::Unknown(packed);
    const int o = RowCounts::Occluded(packed);
    const int k = RowCounts::Known(packed);
    unknown += u;
    occluded += o;
    known += k;
    free += length - u - o - k;
    packed = 0;
    packed_rows = 0;
    length = 0;
  }
};

/// The z spans of a batch of columns along y at one x, in closed form and not
/// yet clamped to the grid: kOutside where dx^2 + dy^2 > 1 (no centre of the
/// column can be inside), kExact where neither end falls within tol of a voxel
/// centre (the ends are exact), kAmbiguous where one does (re-tested).
constexpr int kBatch = 64;  // A multiple of four.
enum : std::uint8_t { kOutside = 0, kExact = 1, kAmbiguous = 2 };
struct ColumnBatch {
  int lo[kBatch];
  int hi[kBatch];
  double dy2[kBatch];
  std::uint8_t kind[kBatch];
};

/// What the batch fillers need of one x line of the footprint.
struct ColumnLine {
  double dx2 = 0.0;
  double origin_y = 0.0;
  double voxel = 0.0;
  double cy = 0.0;
  double inv_hy = 0.0;
  double cz_idx = 0.0;
  double hz_idx = 0.0;
  double tol = 0.0;
};

/// Fills batch entries [k0, n) for the columns y = y0 + k, with the arithmetic
/// of VoxelGrid::CentreY and Ellipsoid::Contains.
void FillColumnBatch(const ColumnLine& l, int y0, int k0, int n, ColumnBatch* b) {
  for (int k = k0; k < n; ++k) {
    const double dy = (l.origin_y + (y0 + k + 0.5) * l.voxel - l.cy) * l.inv_hy;
    const double dy2 = dy * dy;
    const double q = l.dx2 + dy2;
    b->dy2[k] = dy2;
    if (q > 1.0) {
      b->kind[k] = kOutside;
      continue;
    }
    const double w = std::sqrt(1.0 - q) * l.hz_idx;
    const double t_lo = l.cz_idx - w;
    const double t_hi = l.cz_idx + w;
    b->lo[k] = FastFloor(t_lo - l.tol) + 1;
    b->hi[k] = FastFloor(t_hi - l.tol);
    const bool exact =
        FastFloor(t_lo + l.tol) + 1 == b->lo[k] && FastFloor(t_hi + l.tol) == b->hi[k];
    b->kind[k] = exact ? kExact : kAmbiguous;
  }
}

#if defined(__x86_64__) && defined(__GNUC__)
/// FillColumnBatch four columns at a time (AVX2): the same operations in the
/// same order, no fused multiply-add, so the same values.
__attribute__((target("avx2"))) void FillColumnBatchAvx2(const ColumnLine& l, int y0, int k0, int n,
                                                         ColumnBatch* b) {
  const __m256d origin = _mm256_set1_pd(l.origin_y);
  const __m256d voxel = _mm256_set1_pd(l.voxel);
  const __m256d cy = _mm256_set1_pd(l.cy);
  const __m256d inv_hy = _mm256_set1_pd(l.inv_hy);
  const __m256d dx2 = _mm256_set1_pd(l.dx2);
  const __m256d one = _mm256_set1_pd(1.0);
  const __m256d zero = _mm256_setzero_pd();
  const __m256d cz = _mm256_set1_pd(l.cz_idx);
  const __m256d hz = _mm256_set1_pd(l.hz_idx);
  const __m256d tol = _mm256_set1_pd(l.tol);
  const __m256d offset = _mm256_set1_pd(1073741824.0);  // FastFloor's 2^30.
  const __m128i ioffset = _mm_set1_epi32(1073741824);
  const __m128i ione = _mm_set1_epi32(1);
  const __m256d halves = _mm256_set_pd(3.5, 2.5, 1.5, 0.5);
// FastFloor of four values.
#define HG_FLOOR4(x) _mm_sub_epi32(_mm256_cvttpd_epi32(_mm256_add_pd((x), offset)), ioffset)
  int k = k0;
  for (; k + 4 <= n; k += 4) {
    // y + 0.5 for the four columns, exact as in the scalar code.
    const __m256d y = _mm256_add_pd(_mm256_set1_pd(static_cast<double>(y0 + k)), halves);
    const __m256d centre = _mm256_add_pd(origin, _mm256_mul_pd(y, voxel));
    const __m256d dy = _mm256_mul_pd(_mm256_sub_pd(centre, cy), inv_hy);
    const __m256d dy2 = _mm256_mul_pd(dy, dy);
    const __m256d q = _mm256_add_pd(dx2, dy2);
    _mm256_storeu_pd(b->dy2 + k, dy2);
    const int outside = _mm256_movemask_pd(_mm256_cmp_pd(q, one, _CMP_GT_OQ));
    const __m256d w = _mm256_mul_pd(_mm256_sqrt_pd(_mm256_max_pd(_mm256_sub_pd(one, q), zero)), hz);
    const __m256d t_lo = _mm256_sub_pd(cz, w);
    const __m256d t_hi = _mm256_add_pd(cz, w);
    const __m128i lo = _mm_add_epi32(HG_FLOOR4(_mm256_sub_pd(t_lo, tol)), ione);
    const __m128i hi = HG_FLOOR4(_mm256_sub_pd(t_hi, tol));
    const __m128i lo2 = _mm_add_epi32(HG_FLOOR4(_mm256_add_pd(t_lo, tol)), ione);
    const __m128i hi2 = HG_FLOOR4(_mm256_add_pd(t_hi, tol));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(b->lo + k), lo);
    _mm_storeu_si128(reinterpret_cast<__m128i*>(b->hi + k), hi);
    const int same = _mm_movemask_ps(
        _mm_castsi128_ps(_mm_and_si128(_mm_cmpeq_epi32(lo, lo2), _mm_cmpeq_epi32(hi, hi2))));
    for (int j = 0; j < 4; ++j) {
      b->kind[k + j] = ((outside >> j) & 1) != 0 ? kOutside
                       : ((same >> j) & 1) != 0  ? kExact
                                                 : kAmbiguous;
    }
  }
#undef HG_FLOOR4
  FillColumnBatch(l, y0, k, n, b);
}
#endif

using FillColumnBatchFn = void (*)(const ColumnLine&, int, int, int, ColumnBatch*);

/// The batch filler for this processor, chosen once.
FillColumnBatchFn ColumnBatchFiller() {
#if defined(__x86_64__) && defined(__GNUC__)
  static const FillColumnBatchFn fill =
      __builtin_cpu_supports("avx2") ? FillColumnBatchAvx2 : FillColumnBatch;
  return fill;
#else
  return FillColumnBatch;
#endif
}

/// CountVoxels over z columns: one prefix lookup pair per (x, y) column of the
/// ellipsoid's footprint. Exact as the row version: the column's z extent is
/// the closed form of dz^2 <= 1 - (dx^2 + dy^2), its ends re-tested with
/// Ellipsoid::Contains' arithmetic dx^2 + (dy^2 + dz^2) <= 1 where they fall
/// within tol of a voxel centre (the predicate is monotone in |dz| in floating
/// point: every rounding step is monotone). The closed forms of a line of
/// columns are computed first, in a batch (four at a time where the processor
/// has AVX2), then the lookups.
EllipsoidCounts CountColumns(const VoxelMap& map, Prepared e, std::span<const HalfSpace> own_region,
                             FillColumnBatchFn fill, int floor_layer) {
  const VoxelGrid& g = map.grid();
  EllipsoidCounts out;
  e.tol = 1e-6 * (1.0 + e.h_idx.z());
  const int nx = g.nx();
  const int ny = g.ny();
  const int nz = g.nz();
  // Below the floor every lattice position counts, at any x and y; without
  // that, only columns in the grid matter.
  const bool reaches_floor = FloorInt(e.c_idx.z() - e.h_idx.z()) < floor_layer;
  int x_lo = FloorInt(e.c_idx.x() - e.h_idx.x());
  int x_hi = CeilInt(e.c_idx.x() + e.h_idx.x());
  if (!reaches_floor) {
    x_lo = std::max(x_lo, 0);
    x_hi = std::min(x_hi, nx - 1);
  }
  ColumnLine line;
  line.origin_y = g.origin().y();
  line.voxel = g.voxel_m();
  line.cy = e.c.y();
  line.inv_hy = e.inv_h.y();
  line.cz_idx = e.c_idx.z();
  line.hz_idx = e.h_idx.z();
  line.tol = e.tol;
  ColumnBatch batch;
  CountAccumulator acc;
  int foreign = 0;
  for (int x = x_lo; x <= x_hi; ++x) {
    const double dx = (g.CentreX(x) - e.c.x()) * e.inv_h.x();
    const double dx2 = dx * dx;
    if (dx2 > 1.0) continue;
    const bool x_in = x >= 0 && x < nx;
    const double wy = std::sqrt(1.0 - dx2) * e.h_idx.y();
    int y_lo = FloorInt(e.c_idx.y() - wy);
    int y_hi = CeilInt(e.c_idx.y() + wy);
    if (!reaches_floor) {
      y_lo = std::max(y_lo, 0);
      y_hi = std::min(y_hi, ny - 1);
    }
    line.dx2 = dx2;
    for (int y0 = y_lo; y0 <= y_hi; y0 += kBatch) {
      const int n = std::min(kBatch, y_hi - y0 + 1);
      // Whole groups of four (kBatch is a multiple of four): the columns past
      // n cost nothing in the vector filler and are not read.
      fill(line, y0, 0, (n + 3) & ~3, &batch);
      for (int k = 0; k < n; ++k) {
        if (batch.kind[k] == kOutside) continue;
        const int y = y0 + k;
        Span span{batch.lo[k], batch.hi[k]};
        if (batch.kind[k] == kAmbiguous) {
          const double dy2 = batch.dy2[k];
          const double w = std::sqrt(1.0 - (dx2 + dy2)) * e.h_idx.z();
          span = ExactSpan(e.c_idx.z() - w, e.c_idx.z() + w, e.tol, [&](int z) {
            const double dz = (g.CentreZ(z) - e.c.z()) * e.inv_h.z();
            return dx2 + (dy2 + dz * dz) <= 1.0;
          });
        }
        if (span.lo < floor_layer && span.hi >= span.lo) {
          out.below_floor += std::min(span.hi, floor_layer - 1) - span.lo + 1;
        }
        if (!x_in || y < 0 || y >= ny) continue;
        span.lo = std::max(span.lo, floor_layer);
        span.hi = std::min(span.hi, nz - 1);
        if (span.lo > span.hi) continue;
        const RowCounts* p = map.ColumnPrefix(x, y);
        const std::uint64_t column = p[span.hi + 1].packed - p[span.lo].packed;
        acc.Add(column, span.hi - span.lo + 1);
        if (!own_region.empty() && RowCounts::Unknown(column) > 0) {
          const double px = g.CentreX(x);
          const double py = g.CentreY(y);
          foreign += ForeignUnknown(p, span, column, own_region, [&](const HalfSpace& hs, Span* s) {
            ClipColumnToHalfSpace(g, hs, px, py, s);
          });
        }
      }
    }
  }
  acc.FillCounts(foreign, &out);
  return out;
}

}  // namespace

double Ellipsoid::Volume() const { return 4.0 / 3.0 * std::numbers::pi * half_axes_m.prod(); }

HalfSpace HalfSpace::NearerTo(const Eigen::Vector3d& own, const Eigen::Vector3d& other) {
  // |p - own|^2 <= |p - other|^2  <=>  2 (other - own) . p <= |other|^2 - |own|^2.
  HalfSpace h;
  h.normal = 2.0 * (other - own);
  h.offset = other.squaredNorm() - own.squaredNorm();
  return h;
}

EllipsoidCounts CountVoxels(const VoxelMap& map, const Ellipsoid& ellipsoid,
                            std::span<const HalfSpace> own_region, SumAxis axis, int floor_layer) {
  const VoxelGrid& g = map.grid();
  const Eigen::Vector3d& c = ellipsoid.centre_W;
  const Eigen::Vector3d& h = ellipsoid.half_axes_m;
  EllipsoidCounts out;
  if (!(h.array() > 0.0).all() || !c.allFinite() || !h.allFinite()) return out;
  floor_layer = std::clamp(floor_layer, 0, g.nz());
  const double inv_v = 1.0 / g.voxel_m();
  Prepared e;
  e.c = c;
  e.inv_h = Eigen::Vector3d(1.0 / h.x(), 1.0 / h.y(), 1.0 / h.z());
  e.c_idx = (c - g.origin()) * inv_v - Eigen::Vector3d::Constant(0.5);
  e.h_idx = h * inv_v;
  // Far away (or absurdly large): nothing of the grid or its floor is inside,
  // and the index arithmetic below stays far from integer overflow.
  if ((e.c_idx.cwiseAbs() + e.h_idx).maxCoeff() > 1e8) return out;
  // The closed-form row ends are trusted unless they fall within this many
  // voxels of a voxel centre; the predicate's rounding moves the boundary by at
  // most ~1.5e-8 * k / voxel there (at the tangent rows), far inside it.
  e.tol = 1e-6 * (1.0 + e.h_idx.x());
  // Fewer z columns than x rows (a standing person: about a third as many).
  const bool scalar = axis == SumAxis::kXScalar || axis == SumAxis::kZScalar;
  const FillColumnBatchFn fill = scalar ? FillColumnBatch : ColumnBatchFiller();
  if (axis == SumAxis::kZ || axis == SumAxis::kZScalar ||
      (axis == SumAxis::kAuto && e.h_idx.z() > e.h_idx.x())) {
    return CountColumns(map, e, own_region, fill, floor_layer);
  }

  // Layers within the bounding box, and per layer the rows within its
  // ellipse's bounding interval: floor/ceil of the closed-form bounds include
  // every row the predicate can accept, and the predicate skips the rest.
  const int nx = g.nx();
  const std::size_t stride = static_cast<std::size_t>(nx) + 1;
  const double cx_idx = e.c_idx.x();
  const double hx_idx = e.h_idx.x();
  const double tol = e.tol;
  const double cy = c.y();
  const double inv_hy = e.inv_h.y();
  const int z_lo = FloorInt(e.c_idx.z() - e.h_idx.z());
  const int z_hi = std::min(CeilInt(e.c_idx.z() + e.h_idx.z()), g.nz() - 1);
  // Row differences are summed packed and unpacked every kMaxSummedRows rows,
  // before a field could overflow.
  ColumnLine line;  // The batch filler's rows: y across, ends along x.
  line.origin_y = g.origin().y();
  line.voxel = g.voxel_m();
  line.cy = cy;
  line.inv_hy = inv_hy;
  line.cz_idx = cx_idx;
  line.hz_idx = hx_idx;
  line.tol = tol;
  ColumnBatch batch;
  CountAccumulator acc;
  int foreign = 0;
  for (int z = z_lo; z <= z_hi; ++z) {
    const double pz = g.CentreZ(z);
    const double dz = (pz - c.z()) * e.inv_h.z();
    const double dz2 = dz * dz;
    if (dz2 > 1.0) continue;
    const double wy = std::sqrt(1.0 - dz2) * e.h_idx.y();
    int y_lo = FloorInt(e.c_idx.y() - wy);
    int y_hi = CeilInt(e.c_idx.y() + wy);
    if (z < floor_layer) {  // Below the floor: every lattice position counts, any x and y.
      for (int y = y_lo; y <= y_hi; ++y) {
        const double dy = (g.CentreY(y) - cy) * inv_hy;
        const double q = dy * dy + dz2;
        if (q > 1.0) continue;
        const Span span = RowSpan(g, e, q);
        if (span.hi >= span.lo) out.below_floor += span.hi - span.lo + 1;
      }
      continue;
    }
    y_lo = std::max(y_lo, 0);
    y_hi = std::min(y_hi, g.ny() - 1);
    if (y_lo > y_hi) continue;
    // The closed-form row ends of the layer's rows, in batches (the column
    // filler with z and x swapped: q = dz^2 + dy^2, ends along x). Each end is
    // the floor of the closed form shifted by -tol and by +tol: equal results
    // mean no voxel centre within tol of the boundary, so the end is exact;
    // otherwise RowSpan re-tests with the predicate. (FastFloor may round an
    // argument within 2^-22 below an integer up, which can only make the two
    // differ.) q > 1: dx^2 + q >= q > 1 also after rounding, no centre is
    // inside.
    line.dx2 = dz2;
    for (int y0 = y_lo; y0 <= y_hi; y0 += kBatch) {
      const int n = std::min(kBatch, y_hi - y0 + 1);
      fill(line, y0, 0, (n + 3) & ~3, &batch);
      const RowCounts* p = map.RowPrefix(y0, z);
      for (int k = 0; k < n; ++k, p += stride) {
        if (batch.kind[k] == kOutside) continue;
        Span span{batch.lo[k], batch.hi[k]};
        if (batch.kind[k] == kAmbiguous) span = RowSpan(g, e, batch.dy2[k] + dz2);
        span.lo = std::max(span.lo, 0);
        span.hi = std::min(span.hi, nx - 1);
        if (span.lo > span.hi) continue;
        const std::uint64_t row = p[span.hi + 1].packed - p[span.lo].packed;
        acc.Add(row, span.hi - span.lo + 1);
        if (!own_region.empty() && RowCounts::Unknown(row) > 0) {
          const double py = g.CentreY(y0 + k);
          foreign += ForeignUnknown(p, span, row, own_region, [&](const HalfSpace& hs, Span* s) {
            ClipToHalfSpace(g, hs, py, pz, s);
          });
        }
      }
    }
  }
  acc.FillCounts(foreign, &out);
  return out;
}

int FloorLayerOf(const VoxelMap& map, const Ellipsoid& e, double reach_m) {
  if (!(reach_m > 0.0)) return 0;
  return map.SupportLayer(e.centre_W, e.centre_W.z() - e.half_axes_m.z() + reach_m);
}

void AppendVoxelsInside(const VoxelGrid& g, const Ellipsoid& e, std::vector<std::uint32_t>* out) {
  const Eigen::Vector3i lo = g.VoxelOf(e.centre_W - e.half_axes_m).cwiseMax(0);
  const Eigen::Vector3i hi =
      g.VoxelOf(e.centre_W + e.half_axes_m)
          .cwiseMin(Eigen::Vector3i(g.nx(), g.ny(), g.nz()) - Eigen::Vector3i::Ones());
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
