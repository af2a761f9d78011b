#pragma once
/// @file
/// Voxel states for tracking: static KNOWN / OCCLUDED labels computed once,
/// the UNKNOWN set rebuilt every cycle, and prefix counts along x rows and
/// along z columns that let the likelihood sum an ellipsoid with one lookup
/// pair per row or per column, whichever it spans fewer of.

#include <cstdint>
#include <span>
#include <vector>

#include "pipeline/snapshot.h"
#include "tracking/voxel_grid.h"

namespace hg::tracking {

/// Prefix counts along one row (or column): entry i counts the voxels [0, i) of it in
/// each state (free voxels are the rest), packed into one 64-bit word of three
/// 21-bit fields. Entries are non-decreasing in every field, so the
/// difference of two entries is the packed count of the voxels between them
/// (no borrow crosses a field), and up to kMaxSummedRows such differences
/// can be added before a field could overflow. One lookup is one 8-byte load.
struct RowCounts {
  static constexpr int kBits = 21;
  static constexpr std::uint64_t kMask = (std::uint64_t{1} << kBits) - 1;
  static constexpr std::uint64_t kUnknownOne = 1;
  static constexpr std::uint64_t kOccludedOne = std::uint64_t{1} << kBits;
  static constexpr std::uint64_t kKnownOne = std::uint64_t{1} << (2 * kBits);
  /// Rows of at most VoxelGrid::kMaxRowLength voxels whose differences can be
  /// summed in one word: 32 * 65535 < 2^21.
  static constexpr int kMaxSummedRows = 32;

  std::uint64_t packed = 0;

  [[nodiscard]] static int Unknown(std::uint64_t packed) {
    return static_cast<int>(packed & kMask);
  }
  [[nodiscard]] static int Occluded(std::uint64_t packed) {
    return static_cast<int>((packed >> kBits) & kMask);
  }
  [[nodiscard]] static int Known(std::uint64_t packed) {
    return static_cast<int>((packed >> (2 * kBits)) & kMask);
  }
  [[nodiscard]] int unknown() const { return Unknown(packed); }
  [[nodiscard]] int occluded() const { return Occluded(packed); }
  [[nodiscard]] int known() const { return Known(packed); }
};
static_assert(static_cast<std::uint64_t>(RowCounts::kMaxSummedRows) * VoxelGrid::kMaxRowLength <=
              RowCounts::kMask);

/// The voxel states of the cell.
///
/// Static labels (KNOWN, OCCLUDED) are given at construction. The UNKNOWN set
/// is replaced each cycle by SetUnknown() or SetUnknownFromSnapshot(): only
/// the voxels set in the previous cycle are cleared (no pass over the grid),
/// and only the rows and columns whose UNKNOWN voxels changed get their prefix
/// counts rebuilt. Cost per cycle: O(|previous set| + |new set| + changed
/// rows * nx + changed columns * nz); at 4 cm voxels one moving person changes
/// a few hundred rows of ~125 voxels and columns of ~75, tens of microseconds.
/// Memory: 3 bytes per voxel for the states and support layers, 16 for the prefix
/// counts, 8 bytes per voxel reserved for the UNKNOWN lists (so no cycle
/// allocates, even with the whole cell occupied).
///
/// Thread-compatible: const methods may run concurrently; updates need
/// exclusive access.
class VoxelMap {
 public:
  /// `static_states` holds one state per voxel of `grid` (index order), each
  /// kFree, kOccluded or kKnown. `out_of_view` (empty, or one entry per voxel)
  /// marks with 1 the voxels no camera has in view: they stay kFree whatever
  /// the reconstruction says (see SetUnknown).
  /// @throws common::ConfigError when a size does not match or a state is kUnknown.
  VoxelMap(const VoxelGrid& grid, std::vector<VoxelState> static_states,
           std::span<const std::uint8_t> out_of_view = {});

  [[nodiscard]] const VoxelGrid& grid() const { return grid_; }

  /// The state of a voxel. Only FREE voxels become UNKNOWN: KNOWN and
  /// OCCLUDED are static (precedence KNOWN > OCCLUDED > UNKNOWN > FREE).
  [[nodiscard]] VoxelState State(std::uint32_t index) const {
    const std::uint8_t f = flags_[index];
    const auto s = static_cast<VoxelState>(f & kStaticMask);
    if (s != VoxelState::kKnown && (f & kUnknownBit) != 0) return VoxelState::kUnknown;
    return s;
  }
  [[nodiscard]] VoxelState State(int x, int y, int z) const { return State(grid_.Index(x, y, z)); }
  /// The static label alone (kFree, kOccluded or kKnown).
  [[nodiscard]] VoxelState StaticState(std::uint32_t index) const {
    return static_cast<VoxelState>(flags_[index] & kStaticMask);
  }

  /// Replaces the UNKNOWN set by the given voxel indices (duplicates, KNOWN and
  /// OCCLUDED voxels allowed; those stay as they are: occupancy where no
  /// camera sees the voxel's centre is what the reconstruction could not
  /// certify free, not a camera's evidence of a person, and scores as the
  /// space a person may hide in). Voxels out of every camera's view (with
  /// OutOfView's margin) stay kFree for the same reason: the reconstruction
  /// cannot carve them, and as UNKNOWN they would draw the ellipsoid of a
  /// person whose head nears the top of the views up into them. Precondition: every index <
  /// grid().size().
  void SetUnknown(std::span<const std::uint32_t> indices);

  /// Replaces the UNKNOWN set by every voxel that overlaps (with positive
  /// volume) an occupied cell of the snapshot; the snapshot's grid may differ
  /// from this one in bounds and resolution. Cells outside this grid are ignored.
  void SetUnknownFromSnapshot(const pipeline::OccupancySnapshot& snapshot);

  /// The surface under p_W: one above the highest KNOWN voxel below p_W's
  /// voxel in its (x, y) column, when that voxel's top lies at most
  /// max_top_z_m high; else 0 (the grid's bottom). Also 0 when p_W lies
  /// outside the grid in x or y, below it, or in a KNOWN voxel. Above the
  /// grid the column's top voxel stands for p_W's. CountVoxels' floor_layer
  /// for an ellipsoid that stands on an obstacle (a person on a table).
  [[nodiscard]] int SupportLayer(const Eigen::Vector3d& p_W, double max_top_z_m) const;

  /// The UNKNOWN voxels of the current cycle, each once (KNOWN and OCCLUDED
  /// ones left out).
  [[nodiscard]] std::span<const std::uint32_t> unknown_voxels() const { return current_; }

  /// Prefix counts of row (y, z): nx() + 1 entries.
  [[nodiscard]] const RowCounts* RowPrefix(int y, int z) const {
    return prefix_.data() + static_cast<std::size_t>(grid_.Row(y, z)) * (grid_.nx() + 1);
  }

  /// Prefix counts of column (x, y) along z: nz() + 1 entries.
  [[nodiscard]] const RowCounts* ColumnPrefix(int x, int y) const {
    return column_prefix_.data() +
           (static_cast<std::size_t>(y) * grid_.nx() + static_cast<std::size_t>(x)) *
               column_stride_;
  }

  /// Rows whose prefix counts the last update rebuilt (for tests and profiling).
  [[nodiscard]] int rows_rebuilt_last_update() const { return rows_rebuilt_; }
  /// Columns whose prefix counts the last update rebuilt.
  [[nodiscard]] int columns_rebuilt_last_update() const { return columns_rebuilt_; }

 private:
  static constexpr std::uint8_t kStaticMask = 0x3;
  static constexpr std::uint8_t kUnknownBit = 0x4;     // UNKNOWN in the current cycle.
  static constexpr std::uint8_t kStagedBit = 0x8;      // UNKNOWN in the cycle being built.
  static constexpr std::uint8_t kOutOfViewBit = 0x10;  // No camera has it in view.

  void Stage(std::uint32_t index) {
    const std::uint8_t f = flags_[index];
    if ((f & (kStagedBit | kOutOfViewBit | kStaticMask)) ==
        static_cast<std::uint8_t>(VoxelState::kFree)) {
      flags_[index] = f | kStagedBit;
      staged_.push_back(index);
    }
  }
  /// The packed count of one voxel with these flags (precedence KNOWN >
  /// UNKNOWN > OCCLUDED; FREE counts nothing).
  static std::uint64_t CountOf(std::uint8_t flags) {
    const auto s = static_cast<VoxelState>(flags & kStaticMask);
    if (s == VoxelState::kKnown) return RowCounts::kKnownOne;
    if ((flags & kUnknownBit) != 0) return RowCounts::kUnknownOne;
    if (s == VoxelState::kOccluded) return RowCounts::kOccludedOne;
    return 0;
  }
  void Commit();
  void MarkRow(std::uint32_t index);  // And its column.
  void RebuildRow(int row);
  void RebuildColumn(int column);  // column = y * nx + x.

  VoxelGrid grid_;
  // Per voxel: 1 + the highest KNOWN layer below it in its column (0: none,
  // or the voxel is KNOWN).
  std::vector<std::uint16_t> support_;
  std::vector<std::uint8_t> flags_;      // Static state | kUnknownBit | kStagedBit | kOutOfViewBit.
  std::vector<RowCounts> prefix_;        // (nx + 1) per row.
  std::vector<std::uint32_t> current_;   // UNKNOWN voxels now.
  std::vector<std::uint32_t> staged_;    // UNKNOWN voxels of the cycle being built.
  std::vector<std::uint8_t> row_dirty_;  // Per row.
  std::vector<int> dirty_rows_;          // Rows to rebuild.
  /// Entries from one column's prefix counts to the next: nz + 1 rounded up
  /// to an odd number of cache lines. The likelihood reads neighbouring
  /// columns at the same heights; with a stride of a power-of-two number of
  /// lines (nz = 63 gives 512 bytes) those reads would share a few cache sets
  /// and evict each other.
  std::size_t column_stride_ = 0;
  std::vector<RowCounts> column_prefix_;    // column_stride_ per column (x, y).
  std::vector<std::uint8_t> column_dirty_;  // Per column.
  std::vector<int> dirty_columns_;          // Columns to rebuild.
  // Snapshot cell -> voxel index ranges per axis (first, last), reused.
  std::vector<Eigen::Vector2i> cell_range_[3];
  int rows_rebuilt_ = 0;
  int columns_rebuilt_ = 0;
};

}  // namespace hg::tracking
