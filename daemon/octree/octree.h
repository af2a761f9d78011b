#pragma once
/// @file
/// The incremental conservative octree over 8x8x8 parallel roots.

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <vector>

#include "common/box.h"
#include "common/limits.h"
#include "common/worker_pool.h"
#include "octree/camera_view.h"
#include "silhouette/quadtree.h"

namespace hg::octree {

/// Octree settings. Plain struct with defaults in line.
struct OctreeConfig {
  common::Box3 bounds;  ///< Surveillance volume (m).
  int depth = 10;       ///< Finest cells are bounds / 2^depth; 3 (the 8x8x8 roots) to 19.
  int num_threads = 1;  ///< Worker threads for the update (the caller's thread included).
  /// Boxes that are mixed only through geometry (the edge of a camera's view,
  /// the depth of an obstacle, but background everywhere in the silhouettes)
  /// are split down to depth - boundary_coarsening only; there they become
  /// occluded leaves (occupied when a camera sees foreground in them). These
  /// boundaries are static, and resolving them to the finest cell costs more
  /// than everything else. 0 resolves them exactly.
  int boundary_coarsening = 3;
  /// Coarse first (0: off; otherwise a level below `depth`): each update
  /// first brings the tree up to date down to this level only (a node there
  /// that needs finer work reads as occupied meanwhile), then refines it in
  /// passes: one level at a time up to `key_level`, then two at a time. An
  /// abort (a deadline) leaves a result as
  /// fine as the last completed pass everywhere, or finer, instead of whole
  /// roots left unvisited. A completed update gives the same leaves as without.
  int coarse_first_depth = 0;
  /// With coarse first: the passes go one level at a time down to this level
  /// (0: none), so that an update that aborts deeper down is still exact to
  /// it and one that aborts before is exact to the level above. The daemon
  /// sets the level of its tracking voxels.
  int key_level = 0;
  /// Nodes the tree may hold, all roots together (0: the full tree of this
  /// depth, at most kDefaultMaxNodes). Reserved once, at construction; pages
  /// are touched as nodes are used. An update that needs more leaves the
  /// nodes it cannot split pending (occupied) and counts them
  /// (UpdateStats::nodes_unsplit): never free, never an allocation.
  std::int64_t max_nodes = 0;
  static constexpr std::int64_t kDefaultMaxNodes = std::int64_t{8} << 20;
  /// 0: off. Otherwise a level (the resolution of a grid the tree is read
  /// into, such as the daemon's published grid): inside each cell of this
  /// level, once one leaf reads occupied, the node's remaining children are
  /// not refined but left pending (occupied). The grid cell is occupied
  /// either way, so a grid of this level (or coarser) read from the tree is
  /// the same as without; finer queries may read occupied where the full tree
  /// is free (never the reverse).
  int settle_level = 0;
};

/// State of a leaf.
enum class LeafState : std::uint8_t {
  kFree = 0,      ///< Certified free by some camera.
  kOccupied = 1,  ///< May hold an object (full or mixed at the finest level, or pending).
  kOccluded = 2,  ///< No camera sees it (occupied, but kept apart).
};

/// State of a point.
enum class PointState : std::uint8_t { kFree, kOccupied, kOccluded, kOutside };

[[nodiscard]] const char* ToString(PointState s);

/// A cell of the octree grid at `level` (2^level cells per axis over the bounds).
struct Cell {
  int level = 0;
  std::uint32_t x = 0, y = 0, z = 0;
  friend bool operator==(const Cell&, const Cell&) = default;
  /// Child i (bit 0: upper x half, bit 1: upper y, bit 2: upper z).
  [[nodiscard]] Cell Child(std::uint32_t i) const {
    return {level + 1, 2 * x + (i & 1), 2 * y + ((i >> 1) & 1), 2 * z + ((i >> 2) & 1)};
  }
};

/// The box of a cell. Adjacent cells share bit-identical faces, and a child's box
/// is computed the same way at every level, so a dense grid at the finest level
/// reproduces octree leaves exactly.
[[nodiscard]] common::Box3 CellBox(const common::Box3& bounds, const Cell& cell);

/// When to give up on an update.
struct UpdateControl {
  const std::atomic<bool>* abort = nullptr;  ///< Raised by another thread: stop now.
  std::optional<std::chrono::steady_clock::time_point> deadline;
  /// Abort once this many nodes were recomputed (negative: no limit). Lets tests
  /// abort at reproducible moments; with several threads the count is shared.
  std::int64_t node_budget = -1;
};

/// What an update did.
struct UpdateStats {
  bool aborted = false;
  /// The tree is exact down to this level everywhere (a node there that
  /// needs finer work reads as occupied): config.depth when the update
  /// completed; with coarse first, the level of its last completed pass; 0
  /// when an abort left whole regions unvisited; at most the coarsest level
  /// of a node the full store could not split (nodes_unsplit).
  int refined_level = 0;
  std::int64_t nodes_visited = 0;      ///< Nodes whose footprints were computed.
  std::int64_t verdicts_computed = 0;  ///< Camera verdicts evaluated (quadtree queries).
  /// Nodes this update left marked pending (abort, or coarse first not refined).
  std::int64_t nodes_pending = 0;
  /// Nodes left pending because the node storage (OctreeConfig::max_nodes)
  /// was used up: the tree is coarser than asked there until nodes free up.
  std::int64_t nodes_unsplit = 0;
  double update_ms = 0.0;
  /// When the tree was complete to each level (ms from the update's start),
  /// indexed by level; negative for levels no pass completed at. With coarse
  /// first, one entry per completed pass; without, config.depth alone when
  /// the update completed. What a deadline must allow to reach a level.
  static constexpr int kLevels = 20;
  std::array<double, kLevels> level_done_ms = [] {
    std::array<double, kLevels> none{};
    none.fill(-1.0);
    return none;
  }();
};

/// Conservative incremental octree (ARCHITECTURE.md, reconstruction rules).
///
/// The volume is split into 512 roots; during an update each root belongs to
/// exactly one worker, so the result is the same for any thread count. Nodes
/// live in one store reserved at construction: each worker takes blocks of
/// eight from its own free list, or, when that is empty, from the never-used
/// rest of the store (an atomic counter); the free lists are evened out after
/// each update. Nothing is allocated per update. A node keeps
/// its cached per-camera verdicts; an update revisits only nodes whose footprint
/// holds a changed quadtree element in some camera (or that are pending from an
/// aborted update). On abort, every node that needed an update and did not get
/// it is marked pending: it reads as occupied until a later update recomputes
/// it and its whole subtree.
///
/// Thread-compatible: Update() and the queries must not run concurrently.
class Octree {
 public:
  static constexpr int kMaxCameras = common::kMaxCameras;
  static constexpr int kRootLevel = 3;
  /// The 8 x 8 x 8 roots, numbered x + 8 y + 64 z.
  static constexpr int kNumRoots = 512;
  /// Deepest supported tree: cell coordinates of 19 bits each pack into one
  /// 64-bit key with the level (knowledge filter).
  static constexpr int kMaxDepth = 19;
  static_assert(UpdateStats::kLevels == kMaxDepth + 1);

  Octree(const OctreeConfig& config, std::vector<CameraView> cameras);
  ~Octree();
  Octree(const Octree&) = delete;
  Octree& operator=(const Octree&) = delete;

  /// Updates from the newest quadtree of every camera (same order as the views).
  /// nullptr marks a camera that delivers nothing (lost or stale): it sees nothing.
  /// A camera's quadtree may have been built several times since the last
  /// update (its changes since are found); another quadtree (another id())
  /// counts as changed everywhere.
  ///
  /// `margins_m` (empty: all 0) holds per camera a distance (m, 0 or at least
  /// kMinMargin): the camera certifies a box free only when it certifies free
  /// the box grown by that distance on every side. A camera whose frame is
  /// from another instant than the one the update stands for gets the
  /// distance a person can cover in between: whoever is in the box now was within that distance
  /// of it then, where the camera saw background, in its view and in front of
  /// every obstacle. A camera whose margin changes is recomputed everywhere.
  UpdateStats Update(std::span<const silhouette::SilhouetteQuadtree* const> masks,
                     const UpdateControl& control = {}, std::span<const double> margins_m = {});

  /// Smallest positive margin (m) Update() takes.
  static constexpr double kMinMargin = 1e-4;
  /// Lag margins are rounded up to whole multiples of this (m), so that a
  /// camera's margin changes seldom (each change recomputes it everywhere).
  static constexpr double kMarginStep = 0.005;
  /// `distance_m` (>= 0) rounded up to a whole kMarginStep (0 stays 0).
  [[nodiscard]] static double RoundMargin(double distance_m) {
    if (!(distance_m > 0.0)) return 0.0;
    double m = std::ceil(distance_m / kMarginStep) * kMarginStep;
    if (m < distance_m) m += kMarginStep;
    return m;
  }

  /// Drops every node: the next update builds from scratch.
  void Reset();

  [[nodiscard]] PointState StateAt(const Eigen::Vector3d& p_W) const;

  /// Per root, the level the last update left it exact down to, as
  /// UpdateStats::refined_level is for the whole tree: config.depth where the
  /// root was completed, the level of the last pass that completed it with
  /// coarse first, 0 where an abort left it unfinished, at most the level of
  /// a node in it the full store could not split. An aborted pass
  /// completes some roots; the next update's passes start where the last
  /// aborted one stopped, so that successive aborted updates refine the
  /// whole cell in turn. Roots go in columns (z fastest), the columns in
  /// Morton order of (x, y), so the roots a pass completes lie together.
  [[nodiscard]] std::span<const std::uint8_t> RootLevels() const { return root_level_; }

  /// The leaf holding p_W (a pending node counts as an occupied leaf); nullopt
  /// outside the bounds.
  [[nodiscard]] std::optional<std::pair<Cell, LeafState>> LeafAt(const Eigen::Vector3d& p_W) const;
  /// The leaf that holds cell `target` (any level from kRootLevel on; a leaf
  /// at or above its level), by integer coordinates alone: exact however far
  /// from the origin the bounds lie. nullopt when the coordinates are outside
  /// the grid of the target's level.
  [[nodiscard]] std::optional<std::pair<Cell, LeafState>> LeafContaining(const Cell& target) const;

  /// Calls fn(const Cell&, LeafState) for every leaf (pending nodes count as
  /// occupied leaves), roots in x-fastest order, children in index order.
  template <class Fn>
  void ForEachLeaf(Fn&& fn) const;

  /// The tree read into a grid of `level` (at most depth): calls fn(const
  /// Cell&, LeafState) for every leaf coarser than `level` and for every cell
  /// of `level`, with what its leaves hold: kOccupied when some leaf inside
  /// reads occupied (as ForEachLeaf reports it), else kOccluded when one is
  /// occluded, else kFree. A cell's leaves are read only until an occupied one.
  template <class Fn>
  void ForEachCellUpTo(int level, Fn&& fn) const;

  /// Volume (m^3) of the leaves in the given state.
  [[nodiscard]] double Volume(LeafState state) const;
  [[nodiscard]] std::int64_t NumNodes() const;
  [[nodiscard]] std::int64_t NumLeaves() const;

  [[nodiscard]] const OctreeConfig& config() const { return config_; }
  [[nodiscard]] int num_cameras() const { return static_cast<int>(cameras_.size()); }
  [[nodiscard]] const CameraView& camera(int i) const { return cameras_[i]; }

 private:
  struct Node {
    static constexpr std::uint32_t kNoChildren = 0xFFFFFFFFu;
    std::uint32_t children = kNoChildren;  // First of 8 consecutive nodes, or packed leaves.
    std::uint32_t verdicts = 0;            // 2 bits per camera.
    std::uint16_t valid = 0;               // Cameras whose cached verdict is current.
    std::uint16_t geometric = 0;           // Cameras whose kMixed verdict is geometric.
    std::uint8_t state = 0;                // NodeState.
    std::uint8_t flags = 0;                // kPending | kHasPending | kCoarse | kCapped.
    std::uint32_t obstacle = 0;            // 2 bits per camera: ObstacleRelation (static).
    // kPending or kCoarse: the node's cache and subtree are exact as of this
    // update (0: not at all), so only what changed since needs recomputing.
    std::uint32_t stamp = 0;
  };
  // kPackedInner: a node one level above the finest whose eight children are
  // leaves stored in `children`, 2 bits each (LeafState), not as nodes.
  enum NodeState : std::uint8_t {
    kFreeLeaf = 0,
    kOccupiedLeaf = 1,
    kOccludedLeaf = 2,
    kInner = 3,
    kPackedInner = 4
  };
  static LeafState PackedChild(std::uint32_t packed, std::uint32_t i) {
    return static_cast<LeafState>((packed >> (2 * i)) & 3u);
  }
  static constexpr std::uint8_t kPending = 1;
  static constexpr std::uint8_t kHasPending = 2;
  // Only during an update with coarse first (FinishCoarse() removes them):
  // kCoarse: stopped at by the coarse pass, subtree as of the last update;
  // kCapped: stopped at by a pass (kCoarse or pending), listed for the next.
  static constexpr std::uint8_t kCoarse = 4;
  static constexpr std::uint8_t kCapped = 8;
  // kInner only, with settle_level: some leaf below reads occupied.
  static constexpr std::uint8_t kHoldsOccupied = 16;
  // With settle_level, kInner and kPackedInner: bits 5-7 name the child that
  // read occupied last, the first one the next update looks at.
  static constexpr int kWitnessShift = 5;
  static constexpr std::uint8_t kWitnessBits = 0xE0;

  /// Nodes of one root: nodes[0] is the root, blocks of 8 children follow.
  struct RootPool {
    /// Per cell of levels kRootLevel .. relation_level_ under this root (level
    /// by level, x fastest): its ObstacleRelation per camera, 2 bits each,
    /// filled in when first needed. The relation is static, while nodes come
    /// and go as people move: without this, every newly split node near an
    /// obstacle looked the obstacle depths up again.
    std::vector<std::uint32_t> relations;
  };
  class Updater;
  struct WorkerScratch;
  struct CappedEntry;
  /// Where a pass listed the nodes it stopped at in one root: entries
  /// [begin, end) of worker `worker`'s list.
  struct CappedRange {
    int worker = 0;
    std::uint32_t begin = 0;
    std::uint32_t end = 0;
  };
  std::array<CappedRange, kNumRoots> capped_ranges_{};  // Of the last pass.

  /// Ends an update with coarse first; returns the nodes left pending.
  std::int64_t FinishCoarse();

  template <class Fn>
  void VisitLeaves(std::uint32_t index, const Cell& cell, Fn& fn) const;
  template <class Fn>
  void VisitCellsUpTo(std::uint32_t index, const Cell& cell, int level, Fn& fn) const;
  /// From root cell `cell` down to the leaf that pick_child(const Cell& parent)
  /// (the child index, 0..7) leads to, or to the node at `stop_level`, read
  /// as SummaryOf() (a pending node counts as an occupied leaf).
  template <class PickChild>
  [[nodiscard]] std::optional<std::pair<Cell, LeafState>> Descend(Cell cell, int stop_level,
                                                                  PickChild pick_child) const;
  /// What the subtree's leaves hold: occupied over occluded over free.
  [[nodiscard]] LeafState SummaryOf(std::uint32_t index) const;

  /// Evens out the workers' free lists (after an update).
  void BalanceFreeBlocks();

  struct FreeStore {
    void operator()(Node* p) const { ::operator delete(p); }
  };
  // The node store: roots at 0..511, then blocks of eight. Raw storage
  // (Node is an implicit-lifetime aggregate), written before it is read.
  std::unique_ptr<Node, FreeStore> nodes_;
  std::uint32_t num_blocks_ = 0;              // Blocks of eight in the store.
  std::atomic<std::uint32_t> next_block_{0};  // First block never handed out since Reset().

  /// Index of `cell` (level kRootLevel .. relation_level_) in its root's relations.
  [[nodiscard]] std::size_t RelationIndex(const Cell& cell) const;

  /// Updates remembered: a node stale for longer is recomputed whole.
  static constexpr std::uint32_t kVersionRing = 64;
  /// Cameras whose changes since update `since` are unknown (the quadtree was
  /// replaced, lost or came back since): every camera when `since` is 0 or
  /// older than the ring.
  [[nodiscard]] std::uint32_t ForcedSince(std::uint32_t since) const;
  /// Version of camera c's quadtree that update `since` used (within the ring).
  [[nodiscard]] std::uint64_t VersionAt(std::uint32_t since, int c) const {
    return version_ring_[(since % kVersionRing) * kMaxCameras + c];
  }

  OctreeConfig config_;
  std::vector<CameraView> cameras_;
  /// Deepest level whose cells' obstacle relations are kept per root (none
  /// without obstacles): up to level 7, 4681 cells and 18 KiB per root.
  int relation_level_ = kRootLevel - 1;
  std::vector<RootPool> roots_;  // 512, x fastest.
  std::unique_ptr<common::WorkerPool> pool_;
  std::unique_ptr<WorkerScratch[]> scratch_;  // One per worker, cache-line separate.
  // Per camera: version of the quadtree used last; 0 = none (lost or never seen).
  std::vector<std::uint64_t> last_version_;
  std::vector<std::uint64_t> last_id_;  // Per camera: id() of the quadtree used last; 0 = none.
  // Number of the current (or last) update; the first is 2, so that "as of
  // the previous update" is never 0, which means "not at all".
  std::uint32_t update_count_ = 1;
  std::uint32_t forced_now_ = 0;              // ForcedSince(update_count_ - 1).
  std::vector<std::uint32_t> discontinuity_;  // Per camera: last update that was not continuous.
  std::vector<double> margin_;                // Per camera: Update()'s margins_m, as last used.
  /// Forgets camera set `cameras`' obstacle relations (they were of boxes
  /// grown by another margin).
  void ForgetRelations(std::uint32_t cameras);
  std::vector<std::uint64_t> version_ring_;           // [update % kVersionRing][camera].
  std::array<std::uint8_t, kNumRoots> root_level_{};  // RootLevels().
  // Per root, the coarsest level of a node this update could not split.
  std::array<std::uint8_t, kNumRoots> unsplit_level_{};
  int root_start_ = 0;  // Position in the pass order where the passes begin.
};

template <class Fn>
void Octree::VisitLeaves(std::uint32_t index, const Cell& cell, Fn& fn) const {
  const Node& n = nodes_.get()[index];
  if ((n.flags & kPending) != 0) {
    fn(cell, LeafState::kOccupied);
    return;
  }
  if (n.state == kPackedInner) {
    for (std::uint32_t i = 0; i < 8; ++i) {
      fn(cell.Child(i), PackedChild(n.children, i));
    }
    return;
  }
  if (n.state != kInner) {
    fn(cell, static_cast<LeafState>(n.state));
    return;
  }
  for (std::uint32_t i = 0; i < 8; ++i) {
    const Cell child = cell.Child(i);
    VisitLeaves(n.children + i, child, fn);
  }
}

template <class Fn>
void Octree::VisitCellsUpTo(std::uint32_t index, const Cell& cell, int level, Fn& fn) const {
  if (cell.level == level) {
    fn(cell, SummaryOf(index));
    return;
  }
  const Node& n = nodes_.get()[index];
  if ((n.flags & kPending) != 0) {
    fn(cell, LeafState::kOccupied);
    return;
  }
  if (n.state == kPackedInner) {  // Its children are cells of `level`.
    for (std::uint32_t i = 0; i < 8; ++i) fn(cell.Child(i), PackedChild(n.children, i));
    return;
  }
  if (n.state != kInner) {
    fn(cell, static_cast<LeafState>(n.state));
    return;
  }
  for (std::uint32_t i = 0; i < 8; ++i) VisitCellsUpTo(n.children + i, cell.Child(i), level, fn);
}

template <class Fn>
void Octree::ForEachCellUpTo(int level, Fn&& fn) const {
  level = std::clamp(level, kRootLevel, config_.depth);
  for (std::uint32_t r = 0; r < roots_.size(); ++r) {
    const Cell root{kRootLevel, r & 7, (r >> 3) & 7, r >> 6};
    VisitCellsUpTo(r, root, level, fn);
  }
}

template <class Fn>
void Octree::ForEachLeaf(Fn&& fn) const {
  for (std::uint32_t r = 0; r < roots_.size(); ++r) {
    const Cell root{kRootLevel, r & 7, (r >> 3) & 7, r >> 6};
    VisitLeaves(r, root, fn);
  }
}

}  // namespace hg::octree
