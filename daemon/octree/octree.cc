#include "octree/octree.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "common/check.h"

namespace hg::octree {
namespace {

using Clock = std::chrono::steady_clock;
constexpr int kNumRoots = Octree::kNumRoots;

// The order passes take the roots in: columns of eight (z fastest), the
// columns in Morton order of (x, y).
constexpr std::array<std::uint16_t, kNumRoots> kRootOrder = [] {
  std::array<std::uint16_t, kNumRoots> order{};
  for (int i = 0; i < kNumRoots; ++i) {
    const int z = i & 7, m = i >> 3;
    const int x = (m & 1) | ((m >> 1) & 2) | ((m >> 2) & 4);
    const int y = ((m >> 1) & 1) | ((m >> 2) & 2) | ((m >> 3) & 4);
    order[i] = static_cast<std::uint16_t>(x + 8 * y + 64 * z);
  }
  return order;
}();
// Every bit: a camera set that no real one (at most 16 cameras) fills.
constexpr std::uint32_t kAllCameras = ~0u;

inline Verdict GetVerdict(std::uint32_t verdicts, int camera) {
  return static_cast<Verdict>((verdicts >> (2 * camera)) & 3u);
}
inline std::uint32_t SetVerdict(std::uint32_t verdicts, int camera, Verdict v) {
  const std::uint32_t shift = 2 * camera;
  return (verdicts & ~(3u << shift)) | (static_cast<std::uint32_t>(v) << shift);
}

}  // namespace

const char* ToString(PointState s) {
  switch (s) {
    case PointState::kFree:
      return "free";
    case PointState::kOccupied:
      return "occupied";
    case PointState::kOccluded:
      return "occluded";
    case PointState::kOutside:
      return "outside";
  }
  return "?";
}

common::Box3 CellBox(const common::Box3& bounds, const Cell& cell) {
  const double scale = std::ldexp(1.0, -cell.level);  // Exact power of two.
  const Eigen::Vector3d extent = bounds.max - bounds.min;
  auto at = [&](int axis, std::uint32_t i) {
    // The last cell ends exactly at the bound, whatever the rounding.
    if (static_cast<std::uint64_t>(i) == (1ULL << cell.level)) return bounds.max[axis];
    return bounds.min[axis] + extent[axis] * (static_cast<double>(i) * scale);
  };
  common::Box3 b;
  b.min = {at(0, cell.x), at(1, cell.y), at(2, cell.z)};
  b.max = {at(0, cell.x + 1), at(1, cell.y + 1), at(2, cell.z + 1)};
  return b;
}

/// A node a coarse-first pass stopped at, with what its children take over
/// from it (Visit()'s child_* values): the next pass goes on from here.
struct Octree::CappedEntry {
  std::uint64_t cell;       // PackCell().
  std::uint32_t index;      // The node.
  std::uint32_t since;      // Its stamp: 0 when its subtree is recomputed whole.
  std::uint32_t unchanged;  // Cameras without a change in its footprint.
  std::uint16_t inherit;    // Cameras full or hidden for it.
  std::uint16_t clear;      // Cameras that see it in front of every obstacle.
};

namespace {
static_assert(Octree::kMaxDepth <= 19 && Octree::kMaxCameras <= 16);
std::uint64_t PackCell(const Cell& c) {
  return static_cast<std::uint64_t>(c.level) | (static_cast<std::uint64_t>(c.x) << 5) |
         (static_cast<std::uint64_t>(c.y) << 24) | (static_cast<std::uint64_t>(c.z) << 43);
}
Cell UnpackCell(std::uint64_t key) {
  constexpr std::uint64_t kCoord = (std::uint64_t{1} << 19) - 1;
  return {static_cast<int>(key & 31u), static_cast<std::uint32_t>((key >> 5) & kCoord),
          static_cast<std::uint32_t>((key >> 24) & kCoord),
          static_cast<std::uint32_t>((key >> 43) & kCoord)};
}
}  // namespace

/// Per-worker counters and scratch, reused from update to update.
struct alignas(64) Octree::WorkerScratch {
  std::int64_t visited = 0;
  std::int64_t verdicts = 0;
  std::int64_t pending = 0;
  int clock_countdown = 0;
  // Footprints per tree level, so that a node visit initialises nothing.
  geometry::Footprint footprints[Octree::kMaxDepth + 1][Octree::kMaxCameras];
  // Per tree level: the 3x3x3 corner grid of the eight children of the node
  // being split there, projected per camera when a child first needs it.
  // A camera with a margin m gets a 4x4x4 grid instead: per axis the lower
  // face of each child less m and its upper face plus m (x0 - m, x1 + m,
  // x1 - m, x2 + m), so that its corners are those of the grown children.
  struct ChildGrid {
    double xs[3], ys[3], zs[3];
    std::uint32_t projected = 0;                         // Cameras whose u, v, z are filled in.
    alignas(16) double uv[Octree::kMaxCameras][2 * 64];  // u, v interleaved.
    double z[Octree::kMaxCameras][64];
  };
  ChildGrid grids[Octree::kMaxDepth + 1];
  // Free blocks of eight nodes, and the nodes the coarse passes stopped at
  // this update: reserved at construction for every block of the store.
  std::vector<std::uint32_t> free_blocks;
  // `capped`: the nodes this pass stops at; `capped_before`: those the
  // previous pass stopped at, which this one goes on from.
  std::vector<CappedEntry> capped;
  std::vector<CappedEntry> capped_before;
  std::int64_t unsplit = 0;  // Nodes left pending for want of free blocks.
  // Per tree level: the camera that freed the last node freed there (a hint).
  int last_free[Octree::kMaxDepth + 1] = {};
  int root = 0;  // The root this worker is in.
};

/// One update pass: the per-worker traversal of roots.
class Octree::Updater {
 public:
  /// A pass does not split nodes at `split_limit` (the finest level: no
  /// limit): a node there that needs finer work is left kCoarse (its subtree
  /// as of the last update, to be brought up to date) or, when its subtree is
  /// stale, pending. A kRefine pass then works only below such nodes
  /// (RefineRoot()): everything above them is up to date.
  enum class Pass { kFull, kRefine };

  Updater(Octree& tree, std::span<const silhouette::SilhouetteQuadtree* const> masks,
          const UpdateControl& control, Pass pass, int split_limit,
          std::atomic<std::int64_t>& spent)
      : tree_(tree),
        masks_(masks),
        now_(tree.update_count_),
        control_(control),
        boundary_depth_(tree.config_.depth - tree.config_.boundary_coarsening),
        split_limit_(split_limit),
        spent_(spent) {
    const int n = static_cast<int>(tree.cameras_.size());
    // Insertion sort, stable (std::stable_sort may allocate; this is per update).
    for (int c = 0; c < n; ++c) {
      int at = c;
      while (at > 0 && tree.margin_[order_[at - 1]] > tree.margin_[c]) {
        order_[at] = order_[at - 1];
        --at;
      }
      order_[at] = c;
    }
  }

  /// Per-worker counters, summed after the pass.
  using Counters = WorkerScratch;

  /// A full pass over root r: from the root down.
  void UpdateRoot(int r, Counters& counters) {
    counters.root = r;
    RootPool& pool = tree_.roots_[r];
    const Cell cell{kRootLevel, static_cast<std::uint32_t>(r & 7),
                    static_cast<std::uint32_t>((r >> 3) & 7), static_cast<std::uint32_t>(r >> 6)};
    Visit(pool, static_cast<std::uint32_t>(r), cell, false, 0, 0, 0, 0, now_ - 1, nullptr, 0,
          counters);
  }

  bool aborted() const { return aborted_.load(std::memory_order_relaxed); }

 private:
  Node& N(std::uint32_t index) const { return tree_.nodes_.get()[index]; }

  bool CheckAbort(Counters& k) {
    if (aborted_.load(std::memory_order_relaxed)) return true;
    bool stop = control_.abort != nullptr && control_.abort->load(std::memory_order_relaxed);
    if (!stop && control_.node_budget >= 0) {
      stop = spent_.fetch_add(1, std::memory_order_relaxed) >= control_.node_budget;
    }
    if (!stop && control_.deadline && --k.clock_countdown <= 0) {
      k.clock_countdown = 32;
      stop = Clock::now() >= *control_.deadline;
    }
    if (stop) aborted_.store(true, std::memory_order_relaxed);
    return stop;
  }

  // Footprint of the box grown by camera c's margin.
  geometry::Footprint FootprintOf(int c, const common::Box3& box) const {
    const double m = tree_.margin_[c];
    if (m == 0.0) return tree_.cameras_[c].projector().Project(box.min, box.max);
    const Eigen::Vector3d grow = Eigen::Vector3d::Constant(m);
    return tree_.cameras_[c].projector().Project(box.min - grow, box.max + grow);
  }

  // Starts the corner grid of the children of the node with `box`.
  void BeginChildGrid(WorkerScratch::ChildGrid& g, const Cell& cell,
                      const common::Box3& box) const {
    const common::Box3 upper = CellBox(tree_.config_.bounds, cell.Child(7));
    g.xs[0] = box.min.x(), g.xs[1] = upper.min.x(), g.xs[2] = box.max.x();
    g.ys[0] = box.min.y(), g.ys[1] = upper.min.y(), g.ys[2] = box.max.y();
    g.zs[0] = box.min.z(), g.zs[1] = upper.min.z(), g.zs[2] = box.max.z();
    g.projected = 0;
  }

  void Project(WorkerScratch::ChildGrid& g, int c) const {
    if (((g.projected >> c) & 1u) != 0) return;
    const double m = tree_.margin_[c];
    if (m == 0.0) {
      tree_.cameras_[c].projector().ProjectGrid<3>(g.xs, g.ys, g.zs, g.uv[c], g.z[c]);
    } else {
      // The same subtractions and additions as FootprintOf() of a child.
      const double xs[4] = {g.xs[0] - m, g.xs[1] + m, g.xs[1] - m, g.xs[2] + m};
      const double ys[4] = {g.ys[0] - m, g.ys[1] + m, g.ys[1] - m, g.ys[2] + m};
      const double zs[4] = {g.zs[0] - m, g.zs[1] + m, g.zs[1] - m, g.zs[2] + m};
      tree_.cameras_[c].projector().ProjectGrid<4>(xs, ys, zs, g.uv[c], g.z[c]);
    }
    g.projected |= 1u << c;
  }

  // True iff camera c sees foreground at the projection of the centre of the
  // grid's node, which is a corner of all eight children: that pixel lies in
  // every child's footprint, so the camera frees none of them, and, as the
  // node lies in front of the camera and of every obstacle it overlaps
  // (`clear`), each child's verdict in it is full or mixed in the silhouette.
  // With a margin, the centre lies inside every grown child, at least the
  // margin (kMinMargin or more) from its faces: its pixel, projected on its
  // own, is inside every grown child's footprint.
  bool CentreBlocks(WorkerScratch::ChildGrid& g, int c, std::uint32_t clear) const {
    const silhouette::SilhouetteQuadtree* mask = masks_[c];
    if (mask == nullptr || ((clear >> c) & 1u) == 0) return false;
    Project(g, c);
    const bool grown = tree_.margin_[c] != 0.0;
    const int points = grown ? 64 : 27;
    if (*std::min_element(g.z[c], g.z[c] + points) <= geometry::kMinFrontDepth) return false;
    double cu, cv;
    if (grown) {
      const Eigen::Vector2d p =
          tree_.cameras_[c].projector().ProjectPoint({g.xs[1], g.ys[1], g.zs[1]});
      cu = p.x();
      cv = p.y();
    } else {
      cu = g.uv[c][2 * 13];
      cv = g.uv[c][2 * 13 + 1];
    }
    const int u = geometry::PixelOf(cu);
    const int v = geometry::PixelOf(cv);
    return u >= 0 && v >= 0 && u < mask->width() && v < mask->height() && mask->IsForeground(u, v);
  }

  // With a margin m, whether camera c frees no box inside `box`, and sees
  // foreground in every one: each such box grown by m holds the core
  // [box.max - m, box.min + m] (a box when box is at most 2 m wide), so its
  // footprint holds the core's, and a foreground pixel there. A mixed verdict
  // then counts as full: the band of width 2 m that the margin lays along a
  // silhouette's edge is not split down to the finest cells, none of which
  // the camera could free.
  bool CoreSeesForeground(int c, const common::Box3& box) const {
    const double m = tree_.margin_[c];
    if (m == 0.0) return false;
    const Eigen::Vector3d lo = box.max.array() - m;
    const Eigen::Vector3d hi = box.min.array() + m;
    if ((lo.array() > hi.array()).any()) return false;
    const CameraView& view = tree_.cameras_[c];
    const geometry::Footprint fp = view.projector().Project(lo, hi);
    if (fp.side != geometry::Footprint::Side::kInFront) return false;
    const geometry::PixelRect clip = geometry::ClipToImage(fp.rect, view.width(), view.height());
    return !clip.Empty() && masks_[c]->Query(clip) != silhouette::Cover::kBackground;
  }

  // Camera c's relation to the obstacles of the box with footprint fp, from
  // `bits` (2 bits per camera), computed and stored there when unknown.
  ObstacleRelation RelationOf(int c, const geometry::Footprint& fp, std::uint32_t* bits) const {
    auto r = static_cast<ObstacleRelation>((*bits >> (2 * c)) & 3u);
    if (r == ObstacleRelation::kUnknown) {
      r = tree_.cameras_[c].has_obstacles() ? RelateToObstacles(tree_.cameras_[c], fp)
                                            : ObstacleRelation::kClear;
      *bits |= static_cast<std::uint32_t>(r) << (2 * c);
    }
    return r;
  }

  // Footprint of child i in camera c from the shared corner grid: bit-identical
  // to FootprintOf() of the child's own box (BoxProjector::ProjectGrid).
  // Written in place (*out) rather than returned: a returned footprint went
  // through a stack slot whose field-wise stores the caller's wider copy
  // could not forward from, which cost more than the projection.
  void ChildFootprint(WorkerScratch::ChildGrid& g, int c, int i, geometry::Footprint* out) const {
    Project(g, c);
    if (tree_.margin_[c] != 0.0) {
      *out = geometry::BoxProjector::FromCorners<4>(g.uv[c], g.z[c], 2 * (i & 1),
                                                    2 * ((i >> 1) & 1), 2 * ((i >> 2) & 1));
    } else {
      *out = geometry::BoxProjector::FromCorners<3>(g.uv[c], g.z[c], i & 1, (i >> 1) & 1,
                                                    (i >> 2) & 1);
    }
  }

  // Whether camera c's verdict on the box with footprint fp may have changed
  // since the last update. Cameras in `unchanged` are known to be unchanged
  // in an enclosing box; *settled tells that no box inside this one can have
  // a change in camera c either (its footprint lies inside this one's).
  // Changes are those since update `since`; `forced` = ForcedSince(since).
  bool ChangedIn(int c, const geometry::Footprint& fp, std::uint32_t unchanged, std::uint32_t since,
                 std::uint32_t forced, bool* settled) const {
    *settled = true;
    if (((unchanged >> c) & 1u) != 0) return false;
    if ((forced >> c) & 1u) {
      *settled = false;
      return true;
    }
    const silhouette::SilhouetteQuadtree* m = masks_[c];
    if (m == nullptr) return false;  // Still lost: its verdict (hidden) cannot change.
    if (fp.side == geometry::Footprint::Side::kBehind) return false;  // So is every sub-box.
    if (fp.side == geometry::Footprint::Side::kStraddling) {
      // The verdict is geometric and cannot change, but a sub-box may lie in
      // front of the camera and see a change: the caller must look below.
      *settled = false;
      return false;
    }
    const CameraView& view = tree_.cameras_[c];
    const geometry::PixelRect clip = geometry::ClipToImage(fp.rect, view.width(), view.height());
    // Exact pixels for the changes of one build; tiles for several.
    const std::uint64_t base = tree_.VersionAt(since, c);
    const bool changed = !clip.Empty() && (m->version() == base + 1 ? m->AnyChanged(clip)
                                                                    : m->ChangedSince(clip, base));
    *settled = !changed;
    return changed;
  }

  // The free list has room for every block of the store: never reallocates.
  void FreeChildren(Counters& k, std::uint32_t first) {
    for (std::uint32_t i = 0; i < 8; ++i) {
      const Node& child = N(first + i);
      if (child.state == kInner) FreeChildren(k, child.children);
    }
    k.free_blocks.push_back(first / 8);
  }

  // Eight fresh nodes, or kNoChildren when the store is used up.
  std::uint32_t AllocateChildren(Counters& k) {
    std::uint32_t block;
    if (!k.free_blocks.empty()) {
      block = k.free_blocks.back();
      k.free_blocks.pop_back();
    } else {
      // Checked first, so that a full store stops counting up.
      if (tree_.next_block_.load(std::memory_order_relaxed) >= tree_.num_blocks_) {
        return Node::kNoChildren;
      }
      block = tree_.next_block_.fetch_add(1, std::memory_order_relaxed);
      if (block >= tree_.num_blocks_) return Node::kNoChildren;
    }
    const std::uint32_t first = 8 * block;
    for (std::uint32_t i = 0; i < 8; ++i) N(first + i) = Node{};
    return first;
  }

  static std::uint32_t WitnessOf(const Node& n) {
    return static_cast<std::uint32_t>(n.flags) >> kWitnessShift;
  }

  // Returns whether the leaf reads occupied.
  bool MakeLeaf(Counters& k, std::uint32_t index, NodeState state) {
    Node& n = N(index);
    const bool had_block = n.state == kInner;
    const std::uint32_t first = n.children;
    n.children = Node::kNoChildren;
    n.state = state;
    n.flags = 0;
    if (had_block) FreeChildren(k, first);
    return state == kOccupiedLeaf;
  }

  // Whether some leaf of the node's subtree reads occupied (as ForEachLeaf
  // reports it); for an inner node, as its last refinement found.
  static bool ReadsOccupied(const Node& n) {
    if ((n.flags & kPending) != 0) return true;
    switch (n.state) {
      case kOccupiedLeaf:
        return true;
      case kPackedInner:
        for (std::uint32_t i = 0; i < 8; ++i) {
          if (PackedChild(n.children, i) == LeafState::kOccupied) return true;
        }
        return false;
      case kInner:
        return (n.flags & kHoldsOccupied) != 0;
      default:
        return false;
    }
  }

  // The eight children of a node one level above the finest, evaluated in bulk
  // and returned packed (2 bits each, LeafState). They share a 3x3x3 grid of
  // projected points per camera; the cameras in `inherit` are full or hidden
  // for the parent and therefore for every child.
  std::uint32_t FinestChildren(RootPool& pool, const Cell& cell, const common::Box3& box,
                               std::uint32_t inherit, std::uint32_t verdicts, std::uint32_t clear,
                               std::uint32_t* witness, Counters& k) {
    const int num_cameras = static_cast<int>(tree_.cameras_.size());
    // The children's cached obstacle relations: eight consecutive entries.
    std::uint32_t* child_relations = cell.level + 1 <= tree_.relation_level_
                                         ? &pool.relations[tree_.RelationIndex(cell.Child(0))]
                                         : nullptr;
    WorkerScratch::ChildGrid& g = k.grids[cell.level];
    BeginChildGrid(g, cell, box);
    bool inherited_full = false;
    int mixed[kMaxCameras];
    int num_mixed = 0;
    for (int c = 0; c < num_cameras; ++c) {
      if (((inherit >> c) & 1u) != 0) {
        inherited_full = inherited_full || GetVerdict(verdicts, c) == Verdict::kFull;
      } else if (CentreBlocks(g, c, clear)) {
        // Sees foreground in every child and frees none: nothing to evaluate.
        inherited_full = true;
      } else {
        mixed[num_mixed++] = c;
      }
    }
    static_assert(static_cast<int>(LeafState::kOccupied) == 1);
    if (num_mixed == 0 && inherited_full) return 0x5555u;  // Eight occupied leaves.
    // Inside a cell of the settle level, once one child reads occupied the
    // others are left occupied too (OctreeConfig::settle_level): recomputed
    // with the node when a camera sees a change in it.
    const bool settles = tree_.config_.settle_level > 0 && cell.level >= tree_.config_.settle_level;
    std::uint32_t packed = 0;
    // The child that read occupied last goes first: while it still does, the
    // others need no look-up.
    const std::uint32_t first = settles ? *witness : 0u;
    for (std::uint32_t order = 0; order < 8; ++order) {
      const int i = static_cast<int>(order ^ first);
      if (settles && (packed & 0x5555u) != 0) {
        packed |= static_cast<std::uint32_t>(LeafState::kOccupied) << (2 * i);
        continue;
      }
      bool any_free = false;
      bool sees_foreground = inherited_full;  // Some camera full or mixed in its silhouette.
      for (int m = 0; m < num_mixed && !any_free; ++m) {
        const int c = mixed[m];
        geometry::Footprint fp;
        ChildFootprint(g, c, i, &fp);
        const ObstacleRelation relation = ((clear >> c) & 1u) != 0 ? ObstacleRelation::kClear
                                          : child_relations != nullptr
                                              ? RelationOf(c, fp, &child_relations[i])
                                              : ObstacleRelation::kUnknown;
        ++k.verdicts;
        if (sees_foreground) {
          // The label is settled: only whether this camera frees the child counts.
          any_free = CertifiesFree(tree_.cameras_[c], masks_[c], fp, relation);
        } else {
          bool geometric = false;
          const Verdict v = Classify(tree_.cameras_[c], masks_[c], fp, relation, &geometric);
          any_free = v == Verdict::kFree;
          sees_foreground = v == Verdict::kFull || (v == Verdict::kMixed && !geometric);
        }
        // Neighbouring children tend to be freed by the same camera: try it first.
        if (any_free) std::swap(mixed[0], mixed[m]);
      }
      // At the finest level every cell that is not free is a leaf: occupied when
      // some camera sees foreground in it, occluded otherwise (hidden, or mixed
      // only through geometry), as in Visit().
      const LeafState s = any_free          ? LeafState::kFree
                          : sees_foreground ? LeafState::kOccupied
                                            : LeafState::kOccluded;
      if (s == LeafState::kOccupied && (packed & 0x5555u) == 0) *witness = i;
      packed |= static_cast<std::uint32_t>(s) << (2 * i);
    }
    k.visited += 8;
    return packed;
  }

  // `inherit` holds the cameras whose verdict on the parent is full or hidden,
  // with those verdicts in `parent_verdicts`. Both are monotone (a sub-box has
  // a sub-footprint and a depth range inside the parent's), so the child takes
  // them over without a footprint or a quadtree query; so is `clear`, the
  // cameras for which the parent lies in front of every obstacle it overlaps.
  // `grid` is the parent's child grid, null for a root.
  // Returns whether some leaf of the node's subtree reads occupied, as far as
  // known (false may also mean unknown): what settle_level prunes by.
  bool Visit(RootPool& pool, std::uint32_t index, const Cell& cell, bool force,
             std::uint32_t inherit, std::uint32_t parent_verdicts, std::uint32_t clear,
             std::uint32_t unchanged, std::uint32_t since, WorkerScratch::ChildGrid* grid,
             int child_index, Counters& k) {
    const int num_cameras = static_cast<int>(tree_.cameras_.size());
    // A child's box is read off its parent's grid: the same values as
    // CellBox() (which computes every face the same way at every level).
    common::Box3 box;
    if (grid != nullptr) {
      const int ix = child_index & 1, iy = (child_index >> 1) & 1, iz = (child_index >> 2) & 1;
      box.min = {grid->xs[ix], grid->ys[iy], grid->zs[iz]};
      box.max = {grid->xs[ix + 1], grid->ys[iy + 1], grid->zs[iz + 1]};
    } else {
      box = CellBox(tree_.config_.bounds, cell);
    }
    auto footprint_into = [&](int c, geometry::Footprint* out) {
      if (grid != nullptr) {
        ChildFootprint(*grid, c, child_index, out);
      } else {
        *out = FootprintOf(c, box);
      }
    };
    ++k.visited;
    Node node = N(index);  // Copy: worked on here, written back below.
    // Never a node a pass stopped at (kCoarse, kCapped): the next pass goes
    // on from its list with the node's children (RefineRoot), and
    // FinishCoarse() makes what is left pending.
    const bool pending = (node.flags & kPending) != 0;
    // A pending node's cache and subtree are exact as of its stamp only. Its
    // subtree takes every change from then on, even when the stamp is this
    // pass's own (a pass that found no room to list it left it pending at its
    // `since`).
    if (pending) unchanged = 0;
    if (pending && node.stamp < since) {
      since = node.stamp;
      unchanged = 0;
    }
    const std::uint32_t forced = tree_.ForcedSince(since);
    const bool recompute_all = force || forced == kAllCameras;
    // Inherited verdicts are stored but never marked valid: when the parent
    // stops passing a camera down, the child computes its own verdict.
    bool inherited_news = false;  // An inherited verdict differs from the stored one.
    for (int c = 0; c < num_cameras; ++c) {
      if (((inherit >> c) & 1u) == 0) continue;
      const Verdict v = GetVerdict(parent_verdicts, c);
      inherited_news =
          inherited_news || ((node.valid >> c) & 1u) != 0 || GetVerdict(node.verdicts, c) != v;
      node.verdicts = SetVerdict(node.verdicts, c, v);
      node.valid &= static_cast<std::uint16_t>(~(1u << c));
      node.geometric &= static_cast<std::uint16_t>(~(1u << c));
    }

    // Fast path: a free leaf stays free while one camera that certified it sees
    // no change in its footprint.
    if (!recompute_all && node.state == kFreeLeaf && (node.flags & kHasPending) == 0) {
      for (int c = 0; c < num_cameras; ++c) {
        if (((node.valid >> c) & 1u) == 0 || GetVerdict(node.verdicts, c) != Verdict::kFree) {
          continue;
        }
        bool settled = false;
        geometry::Footprint fp;
        footprint_into(c, &fp);
        if (!ChangedIn(c, fp, unchanged, since, forced, &settled)) {
          // Other cameras were not checked for changes: their caches may be stale.
          N(index).valid = static_cast<std::uint16_t>(1u << c);
          N(index).flags = 0;  // Up to date, if it was pending.
          return false;
        }
      }
    }

    geometry::Footprint* fps = k.footprints[cell.level];
    std::uint32_t recompute = 0;
    std::uint32_t child_unchanged = unchanged;
    // Cameras whose verdict on this box cannot change (it straddles their
    // camera plane) while a sub-box's may: the children must be visited.
    std::uint32_t unsettled = 0;
    for (int c = 0; c < num_cameras; ++c) {
      if (((inherit >> c) & 1u) != 0) continue;
      footprint_into(c, &fps[c]);
      if (recompute_all || ((node.valid >> c) & 1u) == 0) {
        recompute |= 1u << c;
        continue;
      }
      bool settled = false;
      const bool changed = ChangedIn(c, fps[c], unchanged, since, forced, &settled);
      if (changed) recompute |= 1u << c;
      if (settled) {
        child_unchanged |= 1u << c;
      } else if (!changed) {
        unsettled |= 1u << c;
      }
    }
    const bool has_children = node.state == kInner || node.state == kPackedInner;
    if (!recompute_all && recompute == 0 && !inherited_news && (unsettled == 0 || !has_children) &&
        (node.flags & kHasPending) == 0) {
      if (pending) N(index).flags &= kHoldsOccupied | kWitnessBits;
      return ReadsOccupied(N(index));  // Subtree still exact.
    }
    if (CheckAbort(k)) {
      // Stale from here down.
      ++k.pending;
      Node& n = N(index);
      n.flags |= kPending;
      n.stamp = recompute_all ? 0 : since;
      return true;
    }

    // The node's static relation to the obstacles per camera: passed down
    // (`clear`), kept in the node, or computed once in its lifetime.
    std::uint32_t obstacle = node.obstacle;
    std::uint32_t* cached =
        cell.level <= tree_.relation_level_ ? &pool.relations[tree_.RelationIndex(cell)] : nullptr;
    if (cached != nullptr) obstacle |= *cached;
    auto relation = [&](int c) {
      if (((clear >> c) & 1u) != 0) return ObstacleRelation::kClear;
      const ObstacleRelation r = RelationOf(c, fps[c], &obstacle);
      if (cached != nullptr) *cached = obstacle;
      return r;
    };

    // Evaluate the cameras to recompute; one free verdict settles the node.
    bool any_free = false;
    for (int c = 0; c < num_cameras && !any_free; ++c) {
      any_free = ((node.valid >> c) & 1u) != 0 && ((recompute >> c) & 1u) == 0 &&
                 GetVerdict(node.verdicts, c) == Verdict::kFree;
    }
    // The camera that freed the last node freed at this level first (a free
    // verdict is the common end of a visit, and neighbours share it), then
    // the others by margin, smallest first (a grown box is freed less often).
    int& last_free = k.last_free[cell.level];
    for (int o = -1; o < num_cameras && !any_free; ++o) {
      const int c = o < 0 ? last_free : order_[o];
      if (o >= 0 && c == last_free) continue;
      if (((recompute >> c) & 1u) == 0) continue;
      bool geometric = false;
      Verdict v = Classify(tree_.cameras_[c], masks_[c], fps[c], relation(c), &geometric);
      // Only for a grown box in front of the camera: across its plane the
      // verdict counts as unchangeable (ChangedIn), while the core's
      // foreground can leave.
      if (v == Verdict::kMixed && fps[c].side == geometry::Footprint::Side::kInFront &&
          CoreSeesForeground(c, box)) {
        v = Verdict::kFull;
        geometric = false;
      }
      ++k.verdicts;
      node.verdicts = SetVerdict(node.verdicts, c, v);
      node.valid |= static_cast<std::uint16_t>(1u << c);
      node.geometric = static_cast<std::uint16_t>(geometric ? (node.geometric | (1u << c))
                                                            : (node.geometric & ~(1u << c)));
      recompute &= ~(1u << c);
      any_free = v == Verdict::kFree;
      if (any_free) last_free = c;
    }
    // Cameras left unevaluated (a free verdict came first) are stale now.
    node.valid &= static_cast<std::uint16_t>(~recompute);

    bool all_hidden = true;
    bool any_full = false;
    bool mask_mixed = false;       // Some camera's silhouette is mixed here.
    bool geometric_mixed = false;  // Some camera is mixed through geometry only.
    for (int c = 0; c < num_cameras && !any_free; ++c) {
      const Verdict v = GetVerdict(node.verdicts, c);
      all_hidden = all_hidden && v == Verdict::kHidden;
      any_full = any_full || v == Verdict::kFull;
      if (v == Verdict::kMixed) {
        (((node.geometric >> c) & 1u) != 0 ? geometric_mixed : mask_mixed) = true;
      }
    }
    {
      Node& n = N(index);
      n.verdicts = node.verdicts;
      n.valid = node.valid;
      n.geometric = node.geometric;
      n.obstacle = obstacle;
    }
    if (any_free) return MakeLeaf(k, index, kFreeLeaf);
    if (num_cameras == 0 || all_hidden) return MakeLeaf(k, index, kOccludedLeaf);
    if (!mask_mixed && !geometric_mixed) return MakeLeaf(k, index, kOccupiedLeaf);
    // Mixed only through geometry: where it stops, an occluded leaf unless some
    // camera sees foreground in it (then it may hold a person in view).
    if (!mask_mixed && (cell.level >= boundary_depth_ || cell.level >= tree_.config_.depth)) {
      return MakeLeaf(k, index, any_full ? kOccupiedLeaf : kOccludedLeaf);
    }
    if (cell.level >= tree_.config_.depth) return MakeLeaf(k, index, kOccupiedLeaf);

    std::uint32_t child_inherit = 0;
    for (int c = 0; c < num_cameras; ++c) {
      const Verdict v = GetVerdict(node.verdicts, c);
      if (v == Verdict::kFull || v == Verdict::kHidden) child_inherit |= 1u << c;
    }
    // Cameras whose children will be classified and that see this node in
    // front of every obstacle: no descendant looks up obstacle depths for them.
    std::uint32_t child_clear = clear;
    for (int c = 0; c < num_cameras; ++c) {
      if ((((clear | child_inherit) >> c) & 1u) == 0 && relation(c) == ObstacleRelation::kClear) {
        child_clear |= 1u << c;
      }
    }
    N(index).obstacle = obstacle;
    if (cell.level >= split_limit_) {
      // Coarse pass: refined by the next pass, its subtree kept, exact as of
      // `since` (kCoarse), or not at all (pending).
      Node& n = N(index);
      n.stamp = recompute_all ? 0 : since;
      if (k.capped.size() < k.capped.capacity()) {
        n.flags = kCapped | (recompute_all ? kPending : kCoarse) |
                  (n.flags & (kHasPending | kWitnessBits));
        // What the next pass needs to go on with its children at once.
        k.capped.push_back({PackCell(cell), index, n.stamp, child_unchanged,
                            static_cast<std::uint16_t>(child_inherit),
                            static_cast<std::uint16_t>(child_clear)});
      } else {
        // No room to list it (the list holds as many entries as the store
        // has blocks, which a store nearly full falls short of): pending at
        // once, as FinishCoarse() would leave it if no later pass got to it.
        n.flags = kPending | (n.flags & kHasPending);
        n.valid = 0;
        ++k.pending;
      }
      return false;  // Unknown until refined.
    }
    return Split(pool, index, cell, box, recompute_all, child_inherit, child_clear, child_unchanged,
                 since, k);
  }

 public:
  /// A refinement pass over root r: goes on below the nodes the previous
  /// pass stopped at, from the list that pass made, without walking down to
  /// them again (everything above them is up to date).
  void RefineRoot(int r, const CappedRange& range, Counters& k) {
    k.root = r;
    RootPool& pool = tree_.roots_[r];
    const std::vector<CappedEntry>& list = tree_.scratch_[range.worker].capped_before;
    for (std::uint32_t e = range.begin; e < range.end; ++e) {
      const CappedEntry& entry = list[e];
      // Left capped on an abort: FinishCoarse() makes it pending.
      if (CheckAbort(k)) return;
      Node& n = N(entry.index);
      n.flags &= static_cast<std::uint8_t>(~(kCapped | kCoarse | kPending));
      const Cell cell = UnpackCell(entry.cell);
      Split(pool, entry.index, cell, CellBox(tree_.config_.bounds, cell), entry.since == 0,
            entry.inherit, entry.clear, entry.unchanged, entry.since, k);
    }
  }

 private:
  // The node's children (a node that is mixed and above the finest level):
  // split it, or go on with its children. `child_*` as Visit() passes them down.
  bool Split(RootPool& pool, std::uint32_t index, const Cell& cell, const common::Box3& box,
             bool recompute_all, std::uint32_t child_inherit, std::uint32_t child_clear,
             std::uint32_t child_unchanged, std::uint32_t since, Counters& k) {
    const Node node = N(index);
    if (cell.level + 1 == tree_.config_.depth) {
      // Children at the finest level: evaluated together, stored in the node.
      std::uint32_t witness = WitnessOf(node);
      const std::uint32_t packed =
          FinestChildren(pool, cell, box, child_inherit, node.verdicts, child_clear, &witness, k);
      MakeLeaf(k, index, kPackedInner);
      Node& n = N(index);
      n.children = packed;
      n.flags = static_cast<std::uint8_t>(witness << kWitnessShift);
      return ReadsOccupied(n);
    }

    // Mixed: split. Children of a pending node, or new children, are stale.
    bool child_force = recompute_all;
    std::uint32_t first = node.children;
    if (node.state != kInner) {
      first = AllocateChildren(k);
      if (first == Node::kNoChildren) {
        // The store is used up: the node stays an occupied leaf, pending
        // (recomputed whole by the next update), until blocks come free.
        MakeLeaf(k, index, kOccupiedLeaf);
        Node& n = N(index);
        n.flags = kPending;
        n.stamp = 0;
        ++k.unsplit;
        // The root is exact down to this level only (one worker per root).
        std::uint8_t& unsplit_level = tree_.unsplit_level_[k.root];
        unsplit_level = std::min(unsplit_level, static_cast<std::uint8_t>(cell.level));
        return true;
      }
      child_force = true;
    }
    {
      Node& n = N(index);
      n.children = first;
      n.state = kInner;
      n.flags = 0;
    }
    WorkerScratch::ChildGrid& g = k.grids[cell.level];
    BeginChildGrid(g, cell, box);
    std::uint8_t below = 0;
    bool holds = false;
    const bool settles = tree_.config_.settle_level > 0 && cell.level >= tree_.config_.settle_level;
    // The child that read occupied last goes first: while it still does, the
    // others are left pending without a look.
    const std::uint32_t witness = settles ? WitnessOf(node) : 0u;
    std::uint32_t found = 0;
    for (std::uint32_t order = 0; order < 8; ++order) {
      const std::uint32_t i = order ^ witness;
      if (holds && settles) {
        // A leaf of this settle-level cell reads occupied already: the rest
        // is left unrefined, pending (occupied), recomputed whole when it is
        // next visited.
        Node& rest = N(first + i);
        rest.flags = kPending | (rest.flags & kHasPending);
        rest.stamp = 0;
        below |= kPending;
        continue;
      }
      const Cell child = cell.Child(i);
      const bool child_holds =
          Visit(pool, first + i, child, child_force, child_inherit, node.verdicts, child_clear,
                child_unchanged, since, &g, static_cast<int>(i), k);
      if (child_holds && !holds) found = i;
      holds = holds || child_holds;
      below |= N(first + i).flags & (kPending | kHasPending | kCoarse | kCapped);
    }
    N(index).flags = static_cast<std::uint8_t>(
        (below != 0 ? kHasPending : 0) | (holds ? kHoldsOccupied : 0) | (found << kWitnessShift));
    return holds;
  }

  Octree& tree_;
  std::span<const silhouette::SilhouetteQuadtree* const> masks_;
  const std::uint32_t now_;  // This update's number.
  const UpdateControl& control_;
  const int boundary_depth_;
  const int split_limit_;  // Nodes at this level or deeper are not split.
  std::atomic<bool> aborted_{false};
  std::atomic<std::int64_t>& spent_;  // Nodes recomputed, over the passes of an update.
  // The cameras by margin, smallest first: the order verdicts are computed in.
  std::array<int, kMaxCameras> order_{};
};

Octree::Octree(const OctreeConfig& config, std::vector<CameraView> cameras)
    : config_(config), cameras_(std::move(cameras)) {
  HG_CHECK(config_.bounds.IsValid());
  HG_CHECK(config_.depth >= kRootLevel && config_.depth <= kMaxDepth);
  HG_CHECK(config_.num_threads >= 1);
  HG_CHECK(config_.boundary_coarsening >= 0);
  HG_CHECK(config_.coarse_first_depth >= 0);
  HG_CHECK(static_cast<int>(cameras_.size()) <= kMaxCameras);
  roots_.resize(kNumRoots);
  bool any_obstacles = false;
  for (const CameraView& view : cameras_) any_obstacles = any_obstacles || view.has_obstacles();
  if (any_obstacles) {
    constexpr int kDeepestRelationLevel = 7;
    relation_level_ = std::min(config_.depth, kDeepestRelationLevel);
    const int d = relation_level_ - kRootLevel;
    const std::size_t cells = ((std::size_t{1} << (3 * (d + 1))) - 1) / 7;
    for (RootPool& pool : roots_) pool.relations.assign(cells, 0u);
  }
  // The store: the roots, then blocks of eight, as many as max_nodes allows
  // (by default the full tree, capped), and at least one block per root.
  std::int64_t max_nodes = config_.max_nodes;
  if (max_nodes <= 0) {
    max_nodes = OctreeConfig::kDefaultMaxNodes;
    // The full tree under the roots: 512 * (8^(d + 1) - 1) / 7, d levels below them.
    const int below = config_.depth - kRootLevel;
    if (3 * (below + 1) < 40) {
      max_nodes =
          std::min(max_nodes, kNumRoots * (((std::int64_t{1} << (3 * (below + 1))) - 1) / 7));
    }
  }
  const std::int64_t blocks = std::clamp<std::int64_t>(
      (max_nodes + 7) / 8, 2 * kNumRoots / 8, std::numeric_limits<std::uint32_t>::max() / 8);
  num_blocks_ = static_cast<std::uint32_t>(blocks);
  nodes_.reset(
      static_cast<Node*>(::operator new(sizeof(Node) * 8 * static_cast<std::size_t>(blocks))));
  pool_ = std::make_unique<common::WorkerPool>(config_.num_threads);
  scratch_ = std::make_unique<WorkerScratch[]>(config_.num_threads);
  for (int w = 0; w < config_.num_threads; ++w) {
    scratch_[w].free_blocks.reserve(num_blocks_);
    scratch_[w].capped.reserve(num_blocks_);
    scratch_[w].capped_before.reserve(num_blocks_);
  }
  Reset();
  last_version_.assign(cameras_.size(), 0);
  last_id_.assign(cameras_.size(), 0);
  discontinuity_.assign(cameras_.size(), 0u);
  margin_.assign(cameras_.size(), 0.0);
  version_ring_.assign(static_cast<std::size_t>(kVersionRing) * kMaxCameras, 0);
}

Octree::~Octree() = default;

std::uint32_t Octree::ForcedSince(std::uint32_t since) const {
  if (since == 0 || update_count_ - since >= kVersionRing) return kAllCameras;
  if (since + 1 == update_count_) return forced_now_;
  std::uint32_t forced = 0;
  for (std::size_t c = 0; c < discontinuity_.size(); ++c) {
    if (discontinuity_[c] > since) forced |= 1u << c;
  }
  return forced;
}

std::size_t Octree::RelationIndex(const Cell& cell) const {
  // Level by level; within a level, Morton order of the cell's place in its
  // root, so that the eight children of a cell are consecutive, in Child() order.
  const int d = cell.level - kRootLevel;
  std::size_t morton = 0;
  for (int b = 0; b < d; ++b) {
    morton |= static_cast<std::size_t>((cell.x >> b) & 1u) << (3 * b);
    morton |= static_cast<std::size_t>((cell.y >> b) & 1u) << (3 * b + 1);
    morton |= static_cast<std::size_t>((cell.z >> b) & 1u) << (3 * b + 2);
  }
  const std::size_t level_offset = ((std::size_t{1} << (3 * d)) - 1) / 7;
  return level_offset + morton;
}

std::int64_t Octree::FinishCoarse() {
  // Nodes the refinement did not reach missed this update's changes below
  // them: pending from now on. Their ancestors have kHasPending already.
  std::int64_t left = 0;
  // An aborted pass leaves some of the previous pass's list unrefined too.
  for (int w = 0; w < pool_->num_threads(); ++w) {
    for (const auto* list : {&scratch_[w].capped_before, &scratch_[w].capped}) {
      for (const CappedEntry& entry : *list) {
        Node& n = nodes_.get()[entry.index];
        if ((n.flags & kCapped) == 0) continue;  // Refined.
        n.flags = kPending | (n.flags & kHasPending);
        // Its verdicts are newer than its subtree, whose inherited verdicts
        // came from the ones of its stamp: recompute them all first.
        n.valid = 0;
        ++left;
      }
    }
  }
  return left;
}

void Octree::Reset() {
  for (int r = 0; r < kNumRoots; ++r) {
    Node root;
    root.state = kOccupiedLeaf;
    root.flags = kPending;
    nodes_.get()[r] = root;
  }
  next_block_.store(kNumRoots / 8, std::memory_order_relaxed);  // After the roots.
  root_level_.fill(0);
  for (int w = 0; w < pool_->num_threads(); ++w) {
    scratch_[w].free_blocks.clear();
    scratch_[w].capped.clear();
    scratch_[w].capped_before.clear();
  }
}

void Octree::BalanceFreeBlocks() {
  const int workers = pool_->num_threads();
  std::size_t total = 0;
  for (int w = 0; w < workers; ++w) total += scratch_[w].free_blocks.size();
  const std::size_t share = total / static_cast<std::size_t>(workers);
  // Move blocks from lists above the share to lists below it (capacity is
  // reserved for every block: no list reallocates).
  int poor = 0;
  for (int rich = 0; rich < workers; ++rich) {
    std::vector<std::uint32_t>& from = scratch_[rich].free_blocks;
    while (from.size() > share + 1) {
      while (poor < workers && scratch_[poor].free_blocks.size() >= share) ++poor;
      if (poor == workers) return;
      std::vector<std::uint32_t>& to = scratch_[poor].free_blocks;
      const std::size_t n = std::min(from.size() - share, share - to.size());
      to.insert(to.end(), from.end() - static_cast<std::ptrdiff_t>(n), from.end());
      from.resize(from.size() - n);
    }
  }
}

void Octree::ForgetRelations(std::uint32_t cameras) {
  std::uint32_t keep = ~0u;
  for (std::size_t c = 0; c < cameras_.size(); ++c) {
    if (((cameras >> c) & 1u) != 0) keep &= ~(3u << (2 * c));
  }
  for (RootPool& pool : roots_) {
    for (std::uint32_t& bits : pool.relations) bits &= keep;
  }
  // Every node handed out since Reset(), free ones included (harmless).
  const std::size_t used = 8 * static_cast<std::size_t>(std::min(
                                   next_block_.load(std::memory_order_relaxed), num_blocks_));
  for (std::size_t i = 0; i < used; ++i) nodes_.get()[i].obstacle &= keep;
}

UpdateStats Octree::Update(std::span<const silhouette::SilhouetteQuadtree* const> masks,
                           const UpdateControl& control, std::span<const double> margins_m) {
  HG_CHECK(masks.size() == cameras_.size());
  HG_CHECK(margins_m.empty() || margins_m.size() == cameras_.size());
  const auto start = Clock::now();
  // Update numbers are 32 bits: after four billion updates, start over.
  if (update_count_ == std::numeric_limits<std::uint32_t>::max()) {
    Reset();
    update_count_ = 1;
    std::fill(discontinuity_.begin(), discontinuity_.end(), 0u);
  }
  const std::uint32_t now = ++update_count_;
  std::uint64_t* versions = &version_ring_[(now % kVersionRing) * kMaxCameras];
  forced_now_ = 0;
  for (std::size_t c = 0; c < masks.size(); ++c) {
    const silhouette::SilhouetteQuadtree* m = masks[c];
    if (m != nullptr) {
      HG_CHECK(m->width() == cameras_[c].width() && m->height() == cameras_[c].height());
    }
    // The same quadtree, built again zero or more times (ChangedSince() finds
    // what changed meanwhile), or still none.
    const std::uint64_t id = m == nullptr ? 0 : m->id();
    const bool continuous = id == last_id_[c] && (m == nullptr || m->version() >= last_version_[c]);
    if (!continuous) {
      discontinuity_[c] = now;
      forced_now_ |= 1u << c;
    }
    last_id_[c] = id;
    last_version_[c] = m == nullptr ? 0 : m->version();
    versions[c] = last_version_[c];
  }
  // A new margin changes the camera's verdict on every box, and its relation
  // to the obstacles.
  std::uint32_t new_margins = 0;
  for (std::size_t c = 0; c < cameras_.size(); ++c) {
    const double m = margins_m.empty() ? 0.0 : margins_m[c];
    HG_CHECK(std::isfinite(m) && (m == 0.0 || m >= kMinMargin));
    if (m == margin_[c]) continue;
    margin_[c] = m;
    discontinuity_[c] = now;
    forced_now_ |= 1u << c;
    new_margins |= 1u << c;
  }
  if (new_margins != 0) ForgetRelations(new_margins);

  for (int w = 0; w < pool_->num_threads(); ++w) {
    WorkerScratch& k = scratch_[w];
    k.visited = k.verdicts = k.pending = k.unsplit = 0;
    k.clock_countdown = 0;
  }
  // Roots are independent: whichever worker takes a root owns its pool for the pass.
  std::atomic<std::int64_t> spent{0};
  UpdateStats stats;
  root_level_.fill(0);
  unsplit_level_.fill(std::numeric_limits<std::uint8_t>::max());
  int aborted_level = 0;                      // The pass that was aborted, if one was.
  std::array<CappedRange, kNumRoots> ranges;  // Of the pass running.
  auto run_pass = [&](Updater::Pass pass, int split_limit) {
    if (pass == Updater::Pass::kRefine) {
      for (int w = 0; w < pool_->num_threads(); ++w) {
        std::swap(scratch_[w].capped, scratch_[w].capped_before);
        scratch_[w].capped.clear();
      }
    }
    Updater shared(*this, masks, control, pass, split_limit, spent);
    auto run = [&](int i, int worker) {
      const int r = kRootOrder[(i + root_start_) % kNumRoots];
      WorkerScratch& k = scratch_[worker];
      const auto begin = static_cast<std::uint32_t>(k.capped.size());
      if (pass == Updater::Pass::kRefine) {
        shared.RefineRoot(r, capped_ranges_[r], k);
      } else {
        shared.UpdateRoot(r, k);
      }
      ranges[r] = {worker, begin, static_cast<std::uint32_t>(k.capped.size())};
      // Finished before any abort: exact to this pass's level. (An abort
      // raised by another worker just after still counts it unfinished.)
      if (!shared.aborted()) root_level_[r] = static_cast<std::uint8_t>(split_limit);
    };
    pool_->Run(kNumRoots, run);
    capped_ranges_ = ranges;
    if (!shared.aborted()) {
      stats.level_done_ms[split_limit] =
          std::chrono::duration<double, std::milli>(Clock::now() - start).count();
    } else {
      aborted_level = split_limit;
    }
    return shared.aborted();
  };
  const bool coarse_first =
      config_.coarse_first_depth > 0 && config_.coarse_first_depth < config_.depth;
  if (coarse_first) {
    for (int w = 0; w < pool_->num_threads(); ++w) {
      scratch_[w].capped.clear();
      scratch_[w].capped_before.clear();
    }
    // Coarse to fine: an abort leaves every part of the cell as fine as the
    // last pass that completed, or finer.
    bool aborted = run_pass(Updater::Pass::kFull, config_.coarse_first_depth);
    if (!aborted) stats.refined_level = config_.coarse_first_depth;
    // Up to the key level, which the update should reach first, every level:
    // the coarse passes are cheap, and a deadline that falls short of the key
    // level then still leaves the level above it. Beyond it every second
    // level: each pass revisits the nodes the previous one stopped at, and
    // stopping one level above the finest would revisit most nodes.
    for (int level = config_.coarse_first_depth; !aborted && level < config_.depth;) {
      // Below the settle level a cell needs only one occupied leaf found: the
      // passes there are cheap, and a single one finishes the update.
      const int step = level < config_.key_level                                   ? 1
                       : config_.settle_level > 0 && level >= config_.settle_level ? config_.depth
                                                                                   : 2;
      const int next = std::min(level + step, config_.depth);
      aborted = run_pass(Updater::Pass::kRefine, next);
      if (!aborted) stats.refined_level = next;
      level = next;
    }
    stats.aborted = aborted;
    stats.nodes_pending += FinishCoarse();
  } else {
    stats.aborted = run_pass(Updater::Pass::kFull, config_.depth);
    if (!stats.aborted) stats.refined_level = config_.depth;
  }
  if (aborted_level > 0) {
    // The next update's passes begin with the first root this one's aborted
    // pass did not finish.
    int done = 0;
    while (done < kNumRoots &&
           root_level_[kRootOrder[(done + root_start_) % kNumRoots]] >= aborted_level) {
      ++done;
    }
    root_start_ = (root_start_ + done) % kNumRoots;
  }
  // A node the full store could not split is an occupied leaf at its level:
  // its root, and the tree, are exact down to that level only.
  for (int r = 0; r < kNumRoots; ++r) {
    if (unsplit_level_[r] < root_level_[r]) {
      root_level_[r] = unsplit_level_[r];
      stats.refined_level = std::min<int>(stats.refined_level, unsplit_level_[r]);
    }
  }
  for (int w = 0; w < pool_->num_threads(); ++w) {
    const WorkerScratch& k = scratch_[w];
    stats.nodes_visited += k.visited;
    stats.verdicts_computed += k.verdicts;
    stats.nodes_pending += k.pending;
    stats.nodes_unsplit += k.unsplit;
  }
  BalanceFreeBlocks();
  stats.update_ms = std::chrono::duration<double, std::milli>(Clock::now() - start).count();
  return stats;
}

PointState Octree::StateAt(const Eigen::Vector3d& p_W) const {
  const auto leaf = LeafAt(p_W);
  if (!leaf) return PointState::kOutside;
  switch (leaf->second) {
    case LeafState::kFree:
      return PointState::kFree;
    case LeafState::kOccluded:
      return PointState::kOccluded;
    case LeafState::kOccupied:
      break;
  }
  return PointState::kOccupied;
}

std::optional<std::pair<Cell, LeafState>> Octree::LeafAt(const Eigen::Vector3d& p_W) const {
  const common::Box3& b = config_.bounds;
  if (!b.Contains(p_W)) return std::nullopt;
  const Eigen::Vector3d rel = (p_W - b.min).cwiseQuotient(b.max - b.min);
  auto root_index = [](double t) {
    return static_cast<std::uint32_t>(std::clamp(std::floor(t * 8.0), 0.0, 7.0));
  };
  Cell cell{kRootLevel, root_index(rel.x()), root_index(rel.y()), root_index(rel.z())};
  // Rounding may put a point on a root face into the neighbour: fix by the box.
  for (int axis = 0; axis < 3; ++axis) {
    std::uint32_t& i = axis == 0 ? cell.x : axis == 1 ? cell.y : cell.z;
    const common::Box3 box = CellBox(b, cell);
    if (p_W[axis] < box.min[axis] && i > 0)
      --i;
    else if (p_W[axis] > box.max[axis] && i < 7)
      ++i;
  }
  // Down to a leaf, by the child whose box holds the point (the same
  // arithmetic as CellBox).
  return Descend(cell, config_.depth, [&](const Cell& parent) {
    const common::Box3 upper = CellBox(b, parent.Child(7));
    return static_cast<std::uint32_t>((p_W.x() >= upper.min.x() ? 1 : 0) |
                                      (p_W.y() >= upper.min.y() ? 2 : 0) |
                                      (p_W.z() >= upper.min.z() ? 4 : 0));
  });
}

std::optional<std::pair<Cell, LeafState>> Octree::LeafContaining(const Cell& target) const {
  if (target.level < kRootLevel || target.level > kMaxDepth) return std::nullopt;
  const std::uint64_t side = std::uint64_t{1} << target.level;
  if (target.x >= side || target.y >= side || target.z >= side) return std::nullopt;
  const int shift = target.level - kRootLevel;
  const Cell root{kRootLevel, target.x >> shift, target.y >> shift, target.z >> shift};
  // Down by the target's coordinate bits, stopping at its level.
  return Descend(root, target.level, [&](const Cell& parent) {
    const int s = target.level - parent.level - 1;
    return ((target.x >> s) & 1u) | (((target.y >> s) & 1u) << 1) | (((target.z >> s) & 1u) << 2);
  });
}

template <class PickChild>
std::optional<std::pair<Cell, LeafState>> Octree::Descend(Cell cell, int stop_level,
                                                          PickChild pick_child) const {
  std::uint32_t index = cell.x + 8 * cell.y + 64 * cell.z;  // The root's node.
  for (;;) {
    const Node& n = nodes_.get()[index];
    if ((n.flags & kPending) != 0) return std::make_pair(cell, LeafState::kOccupied);
    const bool inner = n.state == kInner || n.state == kPackedInner;
    if (!inner) return std::make_pair(cell, static_cast<LeafState>(n.state));
    if (cell.level == stop_level) return std::make_pair(cell, SummaryOf(index));
    const std::uint32_t i = pick_child(cell);
    if (n.state == kPackedInner) return std::make_pair(cell.Child(i), PackedChild(n.children, i));
    cell = cell.Child(i);
    index = n.children + i;
  }
}

LeafState Octree::SummaryOf(std::uint32_t index) const {
  const Node& n = nodes_.get()[index];
  if ((n.flags & kPending) != 0) return LeafState::kOccupied;
  if (n.state == kPackedInner) {
    // Two bits per child: kOccupied sets the low one, kOccluded the high one.
    static_assert(static_cast<int>(LeafState::kOccupied) == 1 &&
                  static_cast<int>(LeafState::kOccluded) == 2);
    if ((n.children & 0x5555u) != 0) return LeafState::kOccupied;
    return (n.children & 0xAAAAu) != 0 ? LeafState::kOccluded : LeafState::kFree;
  }
  if (n.state != kInner) return static_cast<LeafState>(n.state);
  LeafState summary = LeafState::kFree;
  for (std::uint32_t i = 0; i < 8; ++i) {
    const LeafState s = SummaryOf(n.children + i);
    if (s == LeafState::kOccupied) return s;
    if (s == LeafState::kOccluded) summary = s;
  }
  return summary;
}

double Octree::Volume(LeafState state) const {
  double volume = 0.0;
  ForEachLeaf([&](const Cell& cell, LeafState s) {
    if (s == state) volume += CellBox(config_.bounds, cell).Volume();
  });
  return volume;
}

std::int64_t Octree::NumNodes() const {
  // Blocks handed out, less those free again, and the roots.
  std::int64_t blocks = std::min(next_block_.load(std::memory_order_relaxed), num_blocks_);
  for (int w = 0; w < pool_->num_threads(); ++w) {
    blocks -= static_cast<std::int64_t>(scratch_[w].free_blocks.size());
  }
  return 8 * blocks - 8 * (kNumRoots / 8) + kNumRoots;
}

std::int64_t Octree::NumLeaves() const {
  std::int64_t n = 0;
  ForEachLeaf([&](const Cell&, LeafState) { ++n; });
  return n;
}

}  // namespace hg::octree
