#include "tracking/tracker.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <numbers>

#include "common/config_error.h"

namespace hg::tracking {
namespace {

using Eigen::Vector3d;

void Require(bool ok, const char* key, const char* problem, std::vector<OptionProblem>* out) {
  if (!ok) out->push_back({key, problem});
}

bool Finite(double x) { return std::isfinite(x); }

void ThrowIfBad(const TrackerOptions& options) {
  const std::vector<OptionProblem> problems = CheckOptions(options);
  if (problems.empty()) return;
  std::string message = "tracking:";
  for (std::size_t i = 0; i < problems.size(); ++i) {
    message += (i == 0 ? " " : "; ") + problems[i].key + ": " + problems[i].problem;
  }
  throw common::ConfigError(message);
}

}  // namespace

struct Tracker::Built {
  VoxelMap map;
  CollisionWorld world;
  std::vector<std::uint16_t> views;
  std::vector<Vector3d> camera_centres_W;
};

Tracker::Built Tracker::BuildStatic(const TrackerOptions& options, const common::Box3& bounds,
                                    const StaticScene& scene) {
  ThrowIfBad(options);
  const VoxelGrid grid(bounds, options.voxel_m);
  StaticVoxels voxels = BuildStaticVoxels(grid, scene);
  std::vector<CollisionShape> shapes = CollisionShapes(scene, voxels);
  std::vector<Vector3d> centres;
  for (std::size_t c = 0; c < scene.cameras.size() && c < kMaxViewCameras; ++c) {
    centres.push_back(scene.cameras[c].CentreW());
  }
  return {VoxelMap(grid, std::move(voxels.states), voxels.out_of_view),
          CollisionWorld(std::move(shapes)), std::move(voxels.views), std::move(centres)};
}

namespace {

/// Distinct seeds per track from one option (splitmix64 finaliser).
std::uint64_t MixSeed(std::uint64_t seed, std::uint32_t id) {
  std::uint64_t z = seed + 0x9E3779B97F4A7C15ULL * (static_cast<std::uint64_t>(id) + 1);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
  return z ^ (z >> 31);
}

// Marks of this cycle's UNKNOWN voxels during the birth search: inside a
// gate or not, reached by the component search, and whether the column below
// stands on something (kGroundedMark valid once kResolvedMark is set).
constexpr std::uint8_t kExplainedMark = 1;
constexpr std::uint8_t kUnexplainedMark = 2;
constexpr std::uint8_t kVisitedMark = 4;
constexpr std::uint8_t kResolvedMark = 8;
constexpr std::uint8_t kGroundedMark = 16;
constexpr std::uint8_t kEvidenceMark = 32;  // Evidence of the component being examined.

bool Overlap(const common::Box3& a, const common::Box3& b, double margin) {
  return (a.min.array() - margin <= b.max.array()).all() &&
         (b.min.array() - margin <= a.max.array()).all();
}

}  // namespace

std::vector<OptionProblem> CheckOptions(const TrackerOptions& o) {
  std::vector<OptionProblem> p;
  const ParticleFilterOptions& f = o.filter;
  Require(o.voxel_m > 0.0 && Finite(o.voxel_m), "voxel_m", "must be > 0", &p);
  Require(Finite(o.likelihood.unknown), "likelihood.unknown", "must be finite", &p);
  Require(Finite(o.likelihood.occluded), "likelihood.occluded", "must be finite", &p);
  Require(Finite(o.likelihood.known), "likelihood.known", "must be finite", &p);
  Require(Finite(o.likelihood.free), "likelihood.free", "must be finite", &p);
  Require(f.num_particles >= 1 && f.num_particles <= 1000000, "filter.num_particles",
          "must be in [1, 1000000]", &p);
  Require(o.object_particles >= 1, "object_particles", "must be >= 1", &p);
  Require(f.position_noise_m_per_sqrt_s >= 0.0 && Finite(f.position_noise_m_per_sqrt_s),
          "filter.position_noise_m_per_sqrt_s", "must be >= 0", &p);
  Require(f.vertical_noise_m_per_sqrt_s >= 0.0 && Finite(f.vertical_noise_m_per_sqrt_s),
          "filter.vertical_noise_m_per_sqrt_s", "must be >= 0", &p);
  Require(f.axis_noise_m_per_sqrt_s >= 0.0 && Finite(f.axis_noise_m_per_sqrt_s),
          "filter.axis_noise_m_per_sqrt_s", "must be >= 0", &p);
  Require(f.posture_noise_m_per_sqrt_s >= 0.0 && Finite(f.posture_noise_m_per_sqrt_s),
          "filter.posture_noise_m_per_sqrt_s", "must be >= 0", &p);
  Require(f.min_half_axis_xy_m > 0.0 && f.min_half_axis_xy_m <= f.max_half_axis_xy_m &&
              Finite(f.max_half_axis_xy_m),
          "filter.min_half_axis_xy_m", "must be > 0 and <= filter.max_half_axis_xy_m", &p);
  Require(f.min_half_axis_z_m > 0.0 && f.min_half_axis_z_m <= f.max_half_axis_z_m &&
              Finite(f.max_half_axis_z_m),
          "filter.min_half_axis_z_m", "must be > 0 and <= filter.max_half_axis_z_m", &p);
  const double min_volume = 4.0 / 3.0 * std::numbers::pi * f.min_half_axis_xy_m *
                            f.min_half_axis_xy_m * f.min_half_axis_z_m;
  Require(f.max_volume_m3 >= min_volume && Finite(f.max_volume_m3), "filter.max_volume_m3",
          "must hold the smallest ellipsoid of the half-axis ranges", &p);
  Require(f.support_reach_m >= 0.0 && Finite(f.support_reach_m), "filter.support_reach_m",
          "must be >= 0", &p);
  Require(f.velocity_gain >= 0.0 && f.velocity_gain <= 1.0, "filter.velocity_gain",
          "must be in [0, 1]", &p);
  Require(f.weight_exponent >= 1.0 && f.weight_exponent <= 64.0, "filter.weight_exponent",
          "must be in [1, 64]", &p);
  Require(f.max_speed_mps > 0.0 && Finite(f.max_speed_mps), "filter.max_speed_mps", "must be > 0",
          &p);
  Require(f.collision_radius_m >= 0.0 &&
              f.collision_radius_m <= std::min(f.min_half_axis_xy_m, f.min_half_axis_z_m),
          "filter.collision_radius_m", "must be >= 0 and not larger than any half-axis", &p);
  Require(f.init_position_spread_m >= 0.0 && Finite(f.init_position_spread_m),
          "filter.init_position_spread_m", "must be >= 0", &p);
  Require(f.init_axis_spread_m >= 0.0 && Finite(f.init_axis_spread_m), "filter.init_axis_spread_m",
          "must be >= 0", &p);
  Require(o.max_tracks >= 1 && o.max_tracks <= 1024, "max_tracks", "must be in [1, 1024]", &p);
  Require(o.birth_min_volume_m3 > 0.0 && Finite(o.birth_min_volume_m3), "birth_min_volume_m3",
          "must be > 0", &p);
  Require(o.birth_gate_margin_m >= 0.0 && Finite(o.birth_gate_margin_m), "birth_gate_margin_m",
          "must be >= 0", &p);
  Require(Finite(o.birth_max_floating_m), "birth_max_floating_m", "must be finite", &p);
  Require(o.birth_min_height_m >= 0.0 && Finite(o.birth_min_height_m), "birth_min_height_m",
          "must be >= 0", &p);
  Require(o.birth_max_skew_ms >= 0.0 && Finite(o.birth_max_skew_ms), "birth_max_skew_ms",
          "must be >= 0", &p);
  Require(Finite(o.promote_min_top_m), "promote_min_top_m", "must be finite", &p);
  Require(Finite(o.explain_margin_m), "explain_margin_m", "must be finite", &p);
  Require(o.birth_min_views >= 0 && o.birth_min_views <= kMaxViewCameras, "birth_min_views",
          "must be in [0, 16]", &p);
  Require(o.reacquire_radius_m >= 0.0 && Finite(o.reacquire_radius_m), "reacquire_radius_m",
          "must be >= 0", &p);
  Require(o.reacquire_speed_mps >= 0.0 && Finite(o.reacquire_speed_mps), "reacquire_speed_mps",
          "must be >= 0", &p);
  Require(o.support_min_volume_m3 >= 0.0 && Finite(o.support_min_volume_m3),
          "support_min_volume_m3", "must be >= 0", &p);
  Require(o.death_timeout_s > 0.0, "death_timeout_s", "must be > 0", &p);
  Require(o.occluded_death_timeout_s > 0.0, "occluded_death_timeout_s", "must be > 0", &p);
  Require(o.tentative_age_s >= 0.0 && Finite(o.tentative_age_s), "tentative_age_s", "must be >= 0",
          &p);
  Require(o.tentative_death_timeout_s > 0.0, "tentative_death_timeout_s", "must be > 0", &p);
  Require(o.occluded_min_share > 0.0 && o.occluded_min_share <= 1.0, "occluded_min_share",
          "must be in (0, 1]", &p);
  Require(o.overlap_margin_m >= 0.0 && Finite(o.overlap_margin_m), "overlap_margin_m",
          "must be >= 0", &p);
  Require(o.birth_view_margin_voxels >= 0 && o.birth_view_margin_voxels <= 8,
          "birth_view_margin_voxels", "must be in [0, 8]", &p);
  Require(o.first_dt_s > 0.0 && Finite(o.first_dt_s), "first_dt_s", "must be > 0", &p);
  Require(o.max_dt_s >= 1e-3 && Finite(o.max_dt_s), "max_dt_s", "must be >= 0.001", &p);
  return p;
}

Tracker::Tracker(const TrackerOptions& options, const common::Box3& bounds,
                 const StaticScene& scene)
    : Tracker(options, BuildStatic(options, bounds, scene)) {}

Tracker::Tracker(const TrackerOptions& options, Built&& built)
    : Tracker(options, std::move(built.map), std::move(built.world)) {
  views_ = std::move(built.views);
  ErodeViews();
  camera_centres_W_ = std::move(built.camera_centres_W);
  sight_tests_.resize(camera_centres_W_.size() * static_cast<std::size_t>(options_.max_tracks));
}

Tracker::Tracker(const TrackerOptions& options, VoxelMap map, CollisionWorld world)
    : options_(options), map_(std::move(map)), world_(std::move(world)) {
  ThrowIfBad(options_);
  Init();
}

void Tracker::ErodeViews() {
  const int r = options_.birth_view_margin_voxels;
  if (views_.empty() || r <= 0) return;
  const VoxelGrid& g = map_.grid();
  // A box erosion of every camera's bit at once, separable: along x, y, z.
  // Outside the grid counts as seen (the grid's faces are the cell's).
  std::vector<std::uint16_t> line;
  auto erode = [&](int n, auto index_of, int lines_a, int lines_b) {
    line.resize(static_cast<std::size_t>(n));
    for (int b = 0; b < lines_b; ++b) {
      for (int a = 0; a < lines_a; ++a) {
        for (int k = 0; k < n; ++k) line[k] = views_[index_of(k, a, b)];
        for (int k = 0; k < n; ++k) {
          std::uint16_t v = 0xFFFF;
          for (int j = std::max(0, k - r); j <= std::min(n - 1, k + r); ++j) v &= line[j];
          views_[index_of(k, a, b)] = v;
        }
      }
    }
  };
  erode(
      g.nx(), [&](int k, int a, int b) { return g.Index(k, a, b); }, g.ny(), g.nz());
  erode(
      g.ny(), [&](int k, int a, int b) { return g.Index(a, k, b); }, g.nx(), g.nz());
  erode(
      g.nz(), [&](int k, int a, int b) { return g.Index(a, b, k); }, g.nx(), g.ny());
}

void Tracker::Init() {
  slots_.resize(options_.max_tracks);
  for (Slot& s : slots_) {
    s.filter = std::make_unique<ParticleFilter>(options_.filter);
    s.filter->set_abort(&abort_);
    s.region.reserve(options_.max_tracks);
  }
  gates_.reserve(options_.max_tracks);
  tracks_.reserve(options_.max_tracks);
  marks_.assign(map_.grid().size(), 0);
  queue_.reserve(map_.grid().size());
  path_.reserve(map_.grid().nz());
  layer_evidence_.assign(map_.grid().nz(), 0);
  const std::size_t floor_columns =
      static_cast<std::size_t>(map_.grid().nx()) * static_cast<std::size_t>(map_.grid().ny());
  column_labels_.assign(floor_columns, 0);
  columns_.reserve(floor_columns);
  column_stack_.reserve(floor_columns);
  heads_.reserve(static_cast<std::size_t>(options_.max_tracks));
  for (int dz = -1; dz <= 1; ++dz) {
    for (int dy = -1; dy <= 1; ++dy) {
      for (int dx = -1; dx <= 1; ++dx) {
        const int manhattan = std::abs(dx) + std::abs(dy) + std::abs(dz);
        if (manhattan == 0 || (!options_.connect_26 && manhattan > 1)) continue;
        neighbours_.emplace_back(dx, dy, dz);
      }
    }
  }
}

bool Tracker::SideBySide(const Ellipsoid& a, const Ellipsoid& b) {
  const double bottom =
      std::max(a.centre_W.z() - a.half_axes_m.z(), b.centre_W.z() - b.half_axes_m.z());
  const double top =
      std::min(a.centre_W.z() + a.half_axes_m.z(), b.centre_W.z() + b.half_axes_m.z());
  const double shorter = 2.0 * std::min(a.half_axes_m.z(), b.half_axes_m.z());
  const Eigen::Vector2d apart = (a.centre_W - b.centre_W).head<2>();
  return top - bottom >= kSideBySideShare * shorter && apart.squaredNorm() > 1e-6;
}

void Tracker::Update(const pipeline::OccupancySnapshot& snapshot) {
  map_.SetUnknownFromSnapshot(snapshot);
  const bool whole =
      pipeline::WholeForBirths(snapshot, options_.voxel_m, options_.birth_max_skew_ms);
  births_by_root_ =
      !whole && pipeline::RootsWholeForBirths(snapshot, options_.voxel_m,
                                              options_.birth_max_skew_ms, &birth_roots_);
  root_bounds_ = snapshot.bounds;
  stats_.cycles_with_births_by_root += births_by_root_ ? 1 : 0;
  Step(snapshot.stamp_ns, whole || births_by_root_);
  births_by_root_ = false;
}

bool Tracker::InBirthRoots() const {
  const VoxelGrid& g = map_.grid();
  const Vector3d extent = root_bounds_.max - root_bounds_.min;
  const double half = 0.5 * g.voxel_m();
  // Root index along one axis of a coordinate, clamped to the bounds.
  auto root = [&](double v, int axis) {
    const double t = (v - root_bounds_.min[axis]) / extent[axis] * pipeline::kRootsPerAxis;
    return std::clamp(static_cast<int>(std::floor(t)), 0, pipeline::kRootsPerAxis - 1);
  };
  for (const std::uint32_t i : queue_) {
    const Eigen::Vector3i c = g.Coords(i);
    const Vector3d p = g.Centre(c.x(), c.y(), c.z());
    // Every root the voxel's box overlaps (a voxel is smaller than a root).
    int lo[3], hi[3];
    for (int a = 0; a < 3; ++a) {
      lo[a] = root(p[a] - half, a);
      hi[a] = root(p[a] + half, a);
    }
    for (int z = lo[2]; z <= hi[2]; ++z) {
      for (int y = lo[1]; y <= hi[1]; ++y) {
        for (int x = lo[0]; x <= hi[0]; ++x) {
          const int r = x + pipeline::kRootsPerAxis * (y + pipeline::kRootsPerAxis * z);
          if (!birth_roots_[static_cast<std::size_t>(r)]) return false;
        }
      }
    }
  }
  return true;
}

void Tracker::Step(std::int64_t stamp_ns, bool births) {
  // Time since the previous cycle: ages and times without support count all of
  // it (a track that lost its person during a long gap dies, and a birth near
  // it re-acquires its id, instead of a stale track lingering beside a new
  // one); the filters' motion model only max_dt_s of it.
  double elapsed = options_.first_dt_s;
  if (has_stamp_) elapsed = std::max(static_cast<double>(stamp_ns - last_stamp_ns_) * 1e-9, 1e-3);
  const double dt = std::min(elapsed, options_.max_dt_s);
  last_stamp_ns_ = stamp_ns;
  has_stamp_ = true;
  ++stats_.cycles;

  // 1. Voronoi regions of tracks whose clouds overlap (previous estimates).
  for (Slot& s : slots_) s.region.clear();
  for (std::size_t i = 0; i < slots_.size(); ++i) {
    if (!slots_[i].alive) continue;
    const FilterEstimate& ei = slots_[i].filter->estimate();
    for (std::size_t j = i + 1; j < slots_.size(); ++j) {
      if (!slots_[j].alive) continue;
      const FilterEstimate& ej = slots_[j].filter->estimate();
      if (!Overlap(ei.cloud_bounds, ej.cloud_bounds, options_.overlap_margin_m)) continue;
      Vector3d ci = ei.ellipsoid.centre_W;
      Vector3d cj = ej.ellipsoid.centre_W;
      if (SideBySide(ei.ellipsoid, ej.ellipsoid)) {
        // A vertical plane: bisecting the 3-D centres of two people who cross
        // close by tilted towards horizontal once their estimates drifted apart
        // in height, and then each filter fed on the upper or the lower halves
        // of both bodies, stacked between them. One above the other (on and
        // under a table) keeps the 3-D bisector.
        cj.z() = ci.z();
      }
      slots_[i].region.push_back(HalfSpace::NearerTo(ci, cj));
      slots_[j].region.push_back(HalfSpace::NearerTo(cj, ci));
    }
  }

  // 2. Filters, support, occlusion. 3. Deaths.
  const common::Box3 covered = map_.grid().covered();
  for (Slot& s : slots_) {
    if (!s.alive) continue;
    s.filter->Step(dt, map_, options_.likelihood, world_, s.region);
    if (aborted()) return;
    Assess(&s, elapsed);
    const double timeout =
        s.age_s < options_.tentative_age_s
            ? options_.tentative_death_timeout_s
            : (s.occluded ? options_.occluded_death_timeout_s : options_.death_timeout_s);
    const Ellipsoid& e = s.filter->estimate().ellipsoid;
    const bool left = ((e.centre_W + e.half_axes_m).array() < covered.min.array()).any() ||
                      ((e.centre_W - e.half_axes_m).array() > covered.max.array()).any();
    if (left) {
      s.alive = false;
      if (s.person) ++stats_.deaths;
    } else if (s.time_since_support_s > timeout) {
      s.dying = true;  // Unless a birth re-acquires it below.
    } else if (!s.person &&
               e.centre_W.z() + e.half_axes_m.z() - covered.min.z() >= options_.promote_min_top_m) {
      s.person = true;  // Stood up.
      s.filter->SetParticleCount(options_.filter.num_particles);
      ++stats_.births;
      ++stats_.promotions;
    }
  }

  // 4. Births (which may re-acquire a dying track), then the deaths.
  if (births) Births();
  for (Slot& s : slots_) {
    if (!s.dying) continue;
    s.dying = false;
    s.alive = false;
    if (s.person) ++stats_.deaths;
  }
  Publish();
}

void Tracker::Assess(Slot* s, double dt_s) {
  const Ellipsoid& e = s->filter->estimate().ellipsoid;
  const EllipsoidCounts n =
      CountVoxels(map_, e, s->region, SumAxis::kAuto,
                  FloorLayerOf(map_, e, s->filter->options().support_reach_m));
  const bool supported =
      n.unknown * map_.grid().voxel_volume_m3() >= options_.support_min_volume_m3 && n.unknown > 0;
  const int total = n.Total();
  s->occluded_fraction = total > 0 ? static_cast<double>(n.occluded) / total : 0.0;
  s->occluded = s->occluded_fraction >= options_.occluded_min_share;
  s->age_s += dt_s;
  s->time_since_support_s = supported ? 0.0 : s->time_since_support_s + dt_s;
}

void Tracker::Births() {
  gates_.clear();
  for (const Slot& s : slots_) {
    if (!s.alive || s.dying) continue;
    const FilterEstimate& e = s.filter->estimate();
    const Vector3d sd = e.centre_covariance_m2.diagonal().cwiseMax(0.0).cwiseSqrt();
    const Vector3d half =
        e.ellipsoid.half_axes_m + Vector3d::Constant(options_.birth_gate_margin_m) + 2.0 * sd;
    gates_.push_back({e.ellipsoid.centre_W, half.cwiseInverse()});
  }
  const VoxelGrid& g = map_.grid();
  const double vv = g.voxel_volume_m3();
  const std::span<const std::uint32_t> unknown = map_.unknown_voxels();
  // Every UNKNOWN voxel once against the gates, a run of the UNKNOWN list
  // (consecutive voxels of one x row) at a time: each gate covers an interval
  // of the row. When the unexplained voxels together are less than a person
  // (the common case: everybody is tracked), no component can start a track
  // and the search is skipped.
  int unexplained_total = 0;
  const int nx = g.nx();
  for (std::size_t k = 0; k < unknown.size();) {
    const std::uint32_t first = unknown[k];
    const Eigen::Vector3i c = g.Coords(first);
    std::size_t end = k + 1;
    while (end < unknown.size() && unknown[end] == first + (end - k) &&
           c.x() + static_cast<int>(end - k) < nx) {
      ++end;
    }
    const int x_last = c.x() + static_cast<int>(end - k) - 1;
    for (std::size_t j = k; j < end; ++j) marks_[unknown[j]] = kUnexplainedMark;
    for (const Gate& gate : gates_) {
      const double dy = (g.CentreY(c.y()) - gate.centre_W.y()) * gate.inv_half_axes.y();
      const double dz = (g.CentreZ(c.z()) - gate.centre_W.z()) * gate.inv_half_axes.z();
      const double r = 1.0 - (dy * dy + dz * dz);
      if (r < 0.0) continue;
      // Voxel centres within the gate's x extent on this row.
      const double half = std::sqrt(r) / gate.inv_half_axes.x();
      const double lo = (gate.centre_W.x() - half - g.origin().x()) / g.voxel_m() - 0.5;
      const double hi = (gate.centre_W.x() + half - g.origin().x()) / g.voxel_m() - 0.5;
      const int a = std::max(c.x(), static_cast<int>(std::ceil(std::clamp(lo, -1.0, 1.0 * nx))));
      const int b = std::min(x_last, static_cast<int>(std::floor(std::clamp(hi, -1.0, 1.0 * nx))));
      for (int x = a; x <= b; ++x) {
        marks_[first + static_cast<std::uint32_t>(x - c.x())] = kExplainedMark;
      }
    }
    for (std::size_t j = k; j < end; ++j) {
      unexplained_total += marks_[unknown[j]] == kUnexplainedMark ? 1 : 0;
    }
    k = end;
  }
  if (unexplained_total * vv >= options_.birth_min_volume_m3) {
    PrepareSightTests();
    for (const std::uint32_t seed : unknown) {
      // Explained, or visited already.
      if ((marks_[seed] & (kUnexplainedMark | kVisitedMark)) != kUnexplainedMark) continue;
      // One component: breadth-first from the seed through unexplained
      // UNKNOWN neighbours. A tracked person's voxels do not join it: the
      // fringes of a hull that stick out of a gate stay separate pieces, and
      // the search never walks a whole tracked body.
      queue_.clear();
      queue_.push_back(seed);
      marks_[seed] |= kVisitedMark;
      for (std::size_t head = 0; head < queue_.size(); ++head) {
        const std::uint32_t i = queue_[head];
        const Eigen::Vector3i c = g.Coords(i);
        for (const Eigen::Vector3i& d : neighbours_) {
          const Eigen::Vector3i q = c + d;
          if (!g.InGrid(q.x(), q.y(), q.z())) continue;
          const std::uint32_t qi = g.Index(q.x(), q.y(), q.z());
          // Unexplained and not visited: an UNKNOWN voxel of this cycle outside every gate.
          if ((marks_[qi] & (kUnexplainedMark | kVisitedMark)) == kUnexplainedMark) {
            marks_[qi] |= kVisitedMark;
            queue_.push_back(qi);
          }
        }
      }
      if (static_cast<double>(queue_.size()) * vv < options_.birth_min_volume_m3) continue;
      // An aborted snapshot: only from what the update finished to the voxel.
      if (births_by_root_ && !InBirthRoots()) continue;
      // The component's evidence of a new person: unexplained voxels that the
      // cameras see past every track; some of them must stand on something.
      int evidence = 0;
      bool grounded = false;
      int z_min = g.nz();
      int z_max = -1;  // Layers of layer_evidence_ to read and clear.
      Vector3d sum = Vector3d::Zero();
      Vector3d sum_sq = Vector3d::Zero();
      for (const std::uint32_t i : queue_) {
        const Eigen::Vector3i c = g.Coords(i);
        const Vector3d p = g.Centre(c.x(), c.y(), c.z());
        if (!SeenPastTracks(i, p)) continue;
        ++evidence;
        sum += p;
        sum_sq += p.cwiseProduct(p);
        z_min = std::min(z_min, c.z());
        z_max = std::max(z_max, c.z());
        marks_[i] |= kEvidenceMark;
        grounded = grounded || Grounded(i);
      }
      // Tall: a layer at birth_min_height_m or higher holds a head's
      // cross-section of evidence; the thin tip that silhouette cones leave
      // above a low object does not. Counted are the interior voxels of a
      // layer's evidence (its four horizontal neighbours are evidence too):
      // a voxel that merely overlaps an occupied cell makes the evidence up
      // to one voxel wider all round, which at coarse voxels would pass a
      // tip of a few square centimetres for a head.
      const int z_tall =
          std::max(0, static_cast<int>(std::ceil(options_.birth_min_height_m / g.voxel_m() - 0.5)));
      if (z_max >= z_tall) {
        for (const std::uint32_t i : queue_) {
          const int z = g.Coords(i).z();
          if (z >= z_tall && InteriorEvidence(i)) ++layer_evidence_[z];
        }
      }
      bool tall = options_.birth_min_height_m <= 0.0;
      const double voxel_area = g.voxel_m() * g.voxel_m();
      for (int z = std::max(z_min, z_tall); z <= z_max; ++z) {
        if (layer_evidence_[z] * voxel_area >= kHeadAreaM2) tall = true;
        layer_evidence_[z] = 0;
      }
      // Several people in one component (standing one behind the other, their
      // hulls joined below): one track each, from the evidence nearest each
      // one's upper body. A piece counts as a person only when its share would
      // start a person's track on its own. Something held out at arm's length
      // is a piece of its own (an arm is too thin to hold interior evidence),
      // and the component stands on the holder's legs, but the thing itself
      // floats: its share goes to the people around it, and when fewer than
      // two pieces are people, the component is one person's.
      int heads = grounded && tall && z_max >= z_tall ? FindHeads(z_tall) : 0;
      if (heads >= 2) {
        SplitEvidence(heads);
        heads = KeepStandingHeads(heads);
        if (heads >= 2) SplitEvidence(heads);
      }
      for (const std::uint32_t i : queue_) marks_[i] &= static_cast<std::uint8_t>(~kEvidenceMark);
      if (grounded) {
        const std::uint64_t before = stats_.births + stats_.object_births + stats_.reacquisitions;
        if (heads >= 2) {
          for (int h = 0; h < heads; ++h) {
            const Head& head = heads_[static_cast<std::size_t>(h)];
            StartOrReacquire(head.evidence, head.sum, head.sum_sq, true);
          }
        } else {
          StartOrReacquire(evidence, sum, sum_sq, tall);
        }
        if (births_by_root_) {
          stats_.births_by_root +=
              stats_.births + stats_.object_births + stats_.reacquisitions - before;
        }
      }
    }
  }
  for (const std::uint32_t i : unknown) marks_[i] = 0;
}

bool Tracker::Grounded(std::uint32_t index) {
  if (options_.birth_max_floating_m < 0.0) return true;
  if ((marks_[index] & kResolvedMark) != 0) return (marks_[index] & kGroundedMark) != 0;
  const VoxelGrid& g = map_.grid();
  const std::uint32_t layer =
      static_cast<std::uint32_t>(g.nx()) * static_cast<std::uint32_t>(g.ny());
  const int max_free = static_cast<int>(std::floor(options_.birth_max_floating_m / g.voxel_m()));
  // Down the column until the answer is known; every unexplained voxel passed
  // on the way shares it.
  path_.clear();
  path_.push_back(index);
  bool grounded = true;  // Reaching the bottom: the floor.
  int free = 0;          // FREE voxels in the current gap.
  std::uint32_t i = index;
  for (int z = g.Coords(index).z() - 1; z >= 0; --z) {
    i -= layer;
    const std::uint8_t m = marks_[i];
    if (m != 0) {  // UNKNOWN this cycle.
      if ((m & kUnexplainedMark) == 0) {
        grounded = false;  // On a tracked person: not standing.
        break;
      }
      if ((m & kResolvedMark) != 0) {
        grounded = (m & kGroundedMark) != 0;
        break;
      }
      path_.push_back(i);
      free = 0;
      continue;
    }
    const VoxelState state = map_.StaticState(i);
    if (state == VoxelState::kKnown) break;  // On an obstacle.
    if (state == VoxelState::kOccluded) {    // Legs may be where no camera sees.
      free = 0;
      continue;
    }
    if (++free > max_free) {
      grounded = false;
      break;
    }
  }
  const std::uint8_t bits = kResolvedMark | (grounded ? kGroundedMark : 0);
  for (const std::uint32_t p : path_) marks_[p] |= bits;
  return grounded;
}

void Tracker::PrepareSightTests() {
  sight_tracks_ = 0;
  if (views_.empty() || options_.explain_margin_m < 0.0) return;
  const int cameras = static_cast<int>(camera_centres_W_.size());
  int n = 0;
  for (const Slot& s : slots_) {
    if (!s.alive || s.time_since_support_s > 0.0) continue;
    const Ellipsoid& e = s.filter->estimate().ellipsoid;
    const Vector3d inv_half =
        (e.half_axes_m + Vector3d::Constant(options_.explain_margin_m)).cwiseInverse();
    for (int c = 0; c < cameras; ++c) {
      SightTest& t = sight_tests_[static_cast<std::size_t>(c) * options_.max_tracks + n];
      t.centre_W = e.centre_W;
      t.inv_half_axes = inv_half;
      t.camera_S = (camera_centres_W_[c] - e.centre_W).cwiseProduct(inv_half);
      t.camera_norm2_minus_1 = t.camera_S.squaredNorm() - 1.0;
    }
    ++n;
  }
  sight_tracks_ = n;
}

bool Tracker::SeenPastTracks(std::uint32_t index, const Vector3d& p_W) const {
  if (views_.empty() || options_.explain_margin_m < 0.0) return true;
  std::uint32_t mask = views_[index];
  if (std::popcount(mask) < std::max(options_.birth_min_views, 1)) return false;
  while (mask != 0) {
    const int c = std::countr_zero(mask);
    mask &= mask - 1;
    const SightTest* t = sight_tests_.data() + static_cast<std::size_t>(c) * options_.max_tracks;
    for (int k = 0; k < sight_tracks_; ++k, ++t) {
      // The half-line from the camera through p, in the frame where the
      // grown ellipsoid is the unit sphere: camera + s d, s >= 0, meets the
      // sphere iff |camera + s d|^2 = 1 has a root s >= 0.
      const Vector3d d = (p_W - t->centre_W).cwiseProduct(t->inv_half_axes) - t->camera_S;
      const double a = d.squaredNorm();
      const double b = t->camera_S.dot(d);
      const double c0 = t->camera_norm2_minus_1;
      if (b * b >= a * c0 && (b <= 0.0 || c0 <= 0.0)) return false;
    }
  }
  return true;
}

bool Tracker::InteriorEvidence(std::uint32_t index) const {
  const VoxelGrid& g = map_.grid();
  if ((marks_[index] & kEvidenceMark) == 0) return false;
  const Eigen::Vector3i c = g.Coords(index);
  // Beyond the cell's sides counts as evidence: someone entering continues there.
  auto evidence_at = [&](int dx, int dy) {
    const int x = c.x() + dx;
    const int y = c.y() + dy;
    if (x < 0 || x >= g.nx() || y < 0 || y >= g.ny()) return true;
    return (marks_[index + dx + static_cast<std::int64_t>(dy) * g.nx()] & kEvidenceMark) != 0;
  };
  return evidence_at(-1, 0) && evidence_at(1, 0) && evidence_at(0, -1) && evidence_at(0, 1);
}

int Tracker::FindHeads(int z_tall) {
  const VoxelGrid& g = map_.grid();
  const int nx = g.nx();
  const int ny = g.ny();
  // Floor plan of the interior evidence at or above z_tall: one column per
  // (x, y) holding some.
  columns_.clear();
  for (const std::uint32_t i : queue_) {
    if (g.Coords(i).z() < z_tall || !InteriorEvidence(i)) continue;
    const std::uint32_t column = i % static_cast<std::uint32_t>(nx * ny);
    if (column_labels_[column] != 0) continue;
    column_labels_[column] = kUnlabelledColumn;
    columns_.push_back(column);
  }
  // Its 8-connected pieces, largest first kept up to max_tracks.
  heads_.clear();
  std::size_t pieces = 0;
  for (const std::uint32_t seed : columns_) {
    if (column_labels_[seed] != kUnlabelledColumn) continue;
    ++pieces;
    const auto label =
        static_cast<std::uint16_t>(std::min<std::size_t>(pieces, kUnlabelledColumn - 1));
    column_stack_.clear();
    column_stack_.push_back(seed);
    column_labels_[seed] = label;
    int count = 0;
    double sx = 0.0, sy = 0.0;
    while (!column_stack_.empty()) {
      const std::uint32_t c = column_stack_.back();
      column_stack_.pop_back();
      const int x = static_cast<int>(c % static_cast<std::uint32_t>(nx));
      const int y = static_cast<int>(c / static_cast<std::uint32_t>(nx));
      ++count;
      sx += g.CentreX(x);
      sy += g.CentreY(y);
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
          const int qx = x + dx;
          const int qy = y + dy;
          if (qx < 0 || qx >= nx || qy < 0 || qy >= ny) continue;
          const auto q = static_cast<std::uint32_t>(qx + qy * nx);
          if (column_labels_[q] != kUnlabelledColumn) continue;
          column_labels_[q] = label;
          column_stack_.push_back(q);
        }
      }
    }
    if (heads_.size() < static_cast<std::size_t>(options_.max_tracks)) {
      heads_.push_back({label, count, sx / count, sy / count});
    } else {
      // Full: the smallest piece makes way for a larger one.
      auto smallest =
          std::min_element(heads_.begin(), heads_.end(),
                           [](const Head& a, const Head& b) { return a.columns < b.columns; });
      if (smallest->columns < count) *smallest = {label, count, sx / count, sy / count};
    }
  }
  // A piece is a head when one of its layers alone holds a head's cross-section.
  const double voxel_area = g.voxel_m() * g.voxel_m();
  int heads = 0;
  for (std::size_t h = 0; h < heads_.size(); ++h) {
    Head head = heads_[h];
    if (head.columns * voxel_area < kHeadAreaM2) continue;
    int z_lo = g.nz();
    int z_hi = -1;
    for (const std::uint32_t i : queue_) {
      const int z = g.Coords(i).z();
      if (z < z_tall || column_labels_[i % static_cast<std::uint32_t>(nx * ny)] != head.label ||
          !InteriorEvidence(i)) {
        continue;
      }
      ++layer_evidence_[z];
      z_lo = std::min(z_lo, z);
      z_hi = std::max(z_hi, z);
    }
    bool tall = false;
    for (int z = z_lo; z <= z_hi; ++z) {
      if (layer_evidence_[z] * voxel_area >= kHeadAreaM2) tall = true;
      layer_evidence_[z] = 0;
    }
    if (tall) heads_[static_cast<std::size_t>(heads++)] = head;
  }
  heads_.resize(static_cast<std::size_t>(heads));
  for (const std::uint32_t c : columns_) column_labels_[c] = 0;
  return heads;
}

void Tracker::SplitEvidence(int heads) {
  const VoxelGrid& g = map_.grid();
  for (Head& head : heads_) {
    head.evidence = 0;
    head.sum.setZero();
    head.sum_sq.setZero();
    head.grounded = false;
  }
  // Each evidence voxel goes to the head nearest in the floor plan.
  for (const std::uint32_t i : queue_) {
    if ((marks_[i] & kEvidenceMark) == 0) continue;
    const Eigen::Vector3i c = g.Coords(i);
    const Vector3d p = g.Centre(c.x(), c.y(), c.z());
    Head* nearest = nullptr;
    double nearest_d2 = std::numeric_limits<double>::infinity();
    for (int h = 0; h < heads; ++h) {
      Head& head = heads_[static_cast<std::size_t>(h)];
      const double dx = p.x() - head.x;
      const double dy = p.y() - head.y;
      if (dx * dx + dy * dy < nearest_d2) {
        nearest_d2 = dx * dx + dy * dy;
        nearest = &head;
      }
    }
    ++nearest->evidence;
    nearest->sum += p;
    nearest->sum_sq += p.cwiseProduct(p);
    nearest->grounded = nearest->grounded || Grounded(i);
  }
}

int Tracker::KeepStandingHeads(int heads) {
  const double vv = map_.grid().voxel_volume_m3();
  int kept = 0;
  for (int h = 0; h < heads; ++h) {
    const Head& head = heads_[static_cast<std::size_t>(h)];
    // What a component needs to start a track, asked of the head's share:
    // standing on something and a person's volume. Its height it has: a
    // layer at birth_min_height_m or higher holds a head's cross-section.
    if (!head.grounded || head.evidence * vv < options_.birth_min_volume_m3) continue;
    heads_[static_cast<std::size_t>(kept++)] = head;
  }
  heads_.resize(static_cast<std::size_t>(kept));
  return kept;
}

void Tracker::StartOrReacquire(int unexplained, const Vector3d& sum, const Vector3d& sum_sq,
                               bool tall) {
  if (unexplained * map_.grid().voxel_volume_m3() < options_.birth_min_volume_m3) return;
  // Uniform solid ellipsoid: variance along an axis = half-axis^2 / 5.
  const Vector3d mean = sum / unexplained;
  const Vector3d var = (sum_sq / unexplained - mean.cwiseProduct(mean)).cwiseMax(0.0);
  const Ellipsoid initial{mean, (5.0 * var).cwiseSqrt()};
  Slot* lost = nullptr;
  double lost_distance = std::numeric_limits<double>::infinity();
  for (Slot& s : slots_) {
    if (!s.alive || s.time_since_support_s <= 0.0) continue;
    const double d = (s.filter->estimate().ellipsoid.centre_W - mean).norm();
    // The reach grows with the time without support up to the (visible)
    // death timeout, no further: a track hidden for long (an occluded pocket)
    // is not handed to someone who appears metres away, across walls.
    const double reach =
        options_.reacquire_radius_m +
        options_.reacquire_speed_mps * std::min(s.time_since_support_s, options_.death_timeout_s);
    if (d <= reach && d < lost_distance) {
      lost = &s;
      lost_distance = d;
    }
  }
  if (lost != nullptr) {
    lost->filter->Reset(initial, Vector3d::Zero(),
                        MixSeed(options_.seed ^ stats_.cycles, lost->id));
    Assess(lost, 0.0);
    lost->time_since_support_s = 0.0;
    lost->dying = false;
    ++stats_.reacquisitions;
    return;
  }
  Slot* free_slot = nullptr;
  for (Slot& s : slots_) {
    if (!s.alive) {
      free_slot = &s;
      break;
    }
  }
  if (free_slot == nullptr) {
    ++stats_.births_dropped;
    return;
  }
  Slot& s = *free_slot;
  s.alive = true;
  s.person = tall;
  s.id = next_id_++;
  s.age_s = 0.0;
  s.time_since_support_s = 0.0;
  s.region.clear();
  s.filter->SetParticleCount(
      tall ? options_.filter.num_particles
           : std::min(options_.object_particles, options_.filter.num_particles));
  s.filter->Reset(initial, Vector3d::Zero(), MixSeed(options_.seed, s.id));
  Assess(&s, 0.0);
  s.time_since_support_s = 0.0;
  ++(tall ? stats_.births : stats_.object_births);
}

void Tracker::Publish() {
  tracks_.clear();
  for (const Slot& s : slots_) {
    if (!s.alive || !s.person) continue;
    const FilterEstimate& e = s.filter->estimate();
    Track t;
    t.id = s.id;
    t.centre_W = e.ellipsoid.centre_W;
    t.half_axes_m = e.ellipsoid.half_axes_m;
    t.velocity_W_mps = e.velocity_W_mps;
    t.centre_covariance_m2 = e.centre_covariance_m2;
    t.occluded_fraction = s.occluded_fraction;
    t.occluded = s.occluded;
    t.age_s = s.age_s;
    t.time_since_support_s = s.time_since_support_s;
    tracks_.push_back(t);
  }
  std::sort(tracks_.begin(), tracks_.end(),
            [](const Track& a, const Track& b) { return a.id < b.id; });
}

const ParticleFilter* Tracker::filter(std::uint32_t id) const {
  for (const Slot& s : slots_) {
    if (s.alive && s.id == id) return s.filter.get();
  }
  return nullptr;
}

}  // namespace hg::tracking
