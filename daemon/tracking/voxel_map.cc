#include "tracking/voxel_map.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include "common/check.h"
#include "common/config_error.h"

namespace hg::tracking {
namespace {

/// Largest snapshot depth whose per-axis tables are reserved up front (the
/// pipeline publishes at most depth 10).
constexpr int kReservedSnapshotDepth = 10;

/// Relative slack (in voxels) when mapping snapshot cells: a cell boundary that
/// rounds onto a voxel boundary takes the neighbouring voxel too, which only
/// grows the UNKNOWN set.
constexpr double kCellSlackVoxels = 1e-9;

}  // namespace

VoxelMap::VoxelMap(const VoxelGrid& grid, std::vector<VoxelState> static_states,
                   std::span<const std::uint8_t> out_of_view)
    : grid_(grid) {
  if (static_states.size() != grid_.size()) {
    throw common::ConfigError(
        "tracking: static voxel states: " + std::to_string(static_states.size()) +
        " given, the grid has " + std::to_string(grid_.size()));
  }
  if (!out_of_view.empty() && out_of_view.size() != grid_.size()) {
    throw common::ConfigError(
        "tracking: out-of-view voxels: " + std::to_string(out_of_view.size()) +
        " given, the grid has " + std::to_string(grid_.size()));
  }
  flags_.resize(grid_.size());
  for (std::size_t i = 0; i < flags_.size(); ++i) {
    if (static_states[i] == VoxelState::kUnknown) {
      throw common::ConfigError("tracking: static voxel states: UNKNOWN is not a static state");
    }
    flags_[i] = static_cast<std::uint8_t>(static_states[i]);
    if (!out_of_view.empty() && out_of_view[i] != 0) flags_[i] |= kOutOfViewBit;
  }
  support_.assign(grid_.size(), 0);
  for (int y = 0; y < grid_.ny(); ++y) {
    for (int x = 0; x < grid_.nx(); ++x) {
      int above_known = 0;  // 1 + the highest KNOWN layer so far.
      for (int z = 0; z < grid_.nz(); ++z) {
        const std::uint32_t i = grid_.Index(x, y, z);
        if (static_states[i] == VoxelState::kKnown) {
          above_known = z + 1;
        } else {
          support_[i] = static_cast<std::uint16_t>(above_known);
        }
      }
    }
  }
  prefix_.resize(static_cast<std::size_t>(grid_.num_rows()) * (grid_.nx() + 1));
  for (int row = 0; row < grid_.num_rows(); ++row) RebuildRow(row);
  const int columns = grid_.nx() * grid_.ny();
  constexpr std::size_t kLine = 64 / sizeof(RowCounts);  // Entries per cache line.
  const std::size_t lines = (static_cast<std::size_t>(grid_.nz()) + 1 + kLine - 1) / kLine;
  column_stride_ = (lines | 1) * kLine;
  column_prefix_.resize(static_cast<std::size_t>(columns) * column_stride_);
  for (int column = 0; column < columns; ++column) RebuildColumn(column);
  column_dirty_.assign(columns, 0);
  dirty_columns_.reserve(columns);
  current_.reserve(grid_.size());
  staged_.reserve(grid_.size());
  row_dirty_.assign(grid_.num_rows(), 0);
  dirty_rows_.reserve(grid_.num_rows());
  for (auto& r : cell_range_) r.reserve(std::size_t{1} << kReservedSnapshotDepth);
}

int VoxelMap::SupportLayer(const Eigen::Vector3d& p_W, double max_top_z_m) const {
  const Eigen::Vector3d f = (p_W - grid_.origin()) / grid_.voxel_m();
  if (!(f.x() >= 0.0 && f.y() >= 0.0 && f.z() >= 0.0 && f.x() < grid_.nx() && f.y() < grid_.ny())) {
    return 0;
  }
  const int z = f.z() < grid_.nz() ? static_cast<int>(f.z()) : grid_.nz() - 1;
  const int layer = support_[grid_.Index(static_cast<int>(f.x()), static_cast<int>(f.y()), z)];
  const double top_z = grid_.origin().z() + layer * grid_.voxel_m();
  return layer > 0 && top_z <= max_top_z_m ? layer : 0;
}

void VoxelMap::SetUnknown(std::span<const std::uint32_t> indices) {
  for (const std::uint32_t i : indices) {
    HG_CHECK(i < flags_.size());
    Stage(i);
  }
  Commit();
}

void VoxelMap::SetUnknownFromSnapshot(const pipeline::OccupancySnapshot& snapshot) {
  const int depth = std::clamp(snapshot.depth, 0, 15);
  const int n = 1 << depth;
  const Eigen::Vector3d cell = snapshot.bounds.Size() / n;
  const double v = grid_.voxel_m();
  const int grid_n[3] = {grid_.nx(), grid_.ny(), grid_.nz()};
  // Voxel range overlapping each cell coordinate, per axis: voxel i covers
  // [o + i v, o + (i+1) v] and overlaps the cell [lo, hi] with positive length iff
  // (lo - o)/v - 1 < i < (hi - o)/v. Empty ranges (first > last) are outside.
  for (int a = 0; a < 3; ++a) {
    cell_range_[a].resize(n);
    for (int c = 0; c < n; ++c) {
      const double lo = snapshot.bounds.min[a] + c * cell[a] - grid_.origin()[a];
      const double hi = snapshot.bounds.min[a] + (c + 1) * cell[a] - grid_.origin()[a];
      const double first = std::floor(lo / v - kCellSlackVoxels);
      const double last = std::ceil(hi / v + kCellSlackVoxels) - 1.0;
      const double n_a = grid_n[a];
      cell_range_[a][c] = {static_cast<int>(std::clamp(first, 0.0, n_a)),
                           static_cast<int>(std::clamp(last, -1.0, n_a - 1.0))};
    }
  }
  for (const pipeline::GridRun& r : snapshot.occupied) {
    if (r.length == 0 || r.x >= n || r.y >= n || r.z >= n) continue;
    const int last_cell = std::min(static_cast<int>(r.x) + r.length - 1, n - 1);
    // The run's cells are contiguous along x, so their voxels are one range.
    const int x0 = cell_range_[0][r.x][0];
    const int x1 = cell_range_[0][last_cell][1];
    const Eigen::Vector2i ry = cell_range_[1][r.y];
    const Eigen::Vector2i rz = cell_range_[2][r.z];
    for (int z = rz[0]; z <= rz[1]; ++z) {
      for (int y = ry[0]; y <= ry[1]; ++y) {
        const std::uint32_t base = grid_.Index(0, y, z);
        for (int x = x0; x <= x1; ++x) Stage(base + static_cast<std::uint32_t>(x));
      }
    }
  }
  Commit();
}

void VoxelMap::MarkRow(std::uint32_t index) {
  const int row = static_cast<int>(index / static_cast<std::uint32_t>(grid_.nx()));
  if (row_dirty_[row] == 0) {
    row_dirty_[row] = 1;
    dirty_rows_.push_back(row);
  }
  const int column = static_cast<int>(
      index % (static_cast<std::uint32_t>(grid_.nx()) * static_cast<std::uint32_t>(grid_.ny())));
  if (column_dirty_[column] == 0) {
    column_dirty_[column] = 1;
    dirty_columns_.push_back(column);
  }
}

void VoxelMap::Commit() {
  // Rows change where a voxel enters (staged, not flagged) or leaves (flagged,
  // not staged) the set; voxels in both keep their rows' counts.
  for (const std::uint32_t i : staged_) {
    if ((flags_[i] & kUnknownBit) == 0) MarkRow(i);
  }
  for (const std::uint32_t i : current_) {
    if ((flags_[i] & kStagedBit) == 0) MarkRow(i);
    flags_[i] &= static_cast<std::uint8_t>(~kUnknownBit);
  }
  for (const std::uint32_t i : staged_) {
    flags_[i] = static_cast<std::uint8_t>((flags_[i] & ~kStagedBit) | kUnknownBit);
  }
  std::swap(current_, staged_);
  staged_.clear();
  rows_rebuilt_ = static_cast<int>(dirty_rows_.size());
  for (const int row : dirty_rows_) {
    RebuildRow(row);
    row_dirty_[row] = 0;
  }
  dirty_rows_.clear();
  columns_rebuilt_ = static_cast<int>(dirty_columns_.size());
  for (const int column : dirty_columns_) {
    RebuildColumn(column);
    column_dirty_[column] = 0;
  }
  dirty_columns_.clear();
}

void VoxelMap::RebuildRow(int row) {
  const int nx = grid_.nx();
  const std::uint8_t* f = flags_.data() + static_cast<std::size_t>(row) * nx;
  RowCounts* p = prefix_.data() + static_cast<std::size_t>(row) * (nx + 1);
  RowCounts acc;
  p[0] = acc;
  for (int x = 0; x < nx; ++x) {
    acc.packed += CountOf(f[x]);
    p[x + 1] = acc;
  }
}

void VoxelMap::RebuildColumn(int column) {
  const int nz = grid_.nz();
  const std::size_t layer = static_cast<std::size_t>(grid_.nx()) * grid_.ny();
  const std::uint8_t* f = flags_.data() + column;
  RowCounts* p = column_prefix_.data() + static_cast<std::size_t>(column) * column_stride_;
  RowCounts acc;
  p[0] = acc;
  for (int z = 0; z < nz; ++z, f += layer) {
    acc.packed += CountOf(*f);
    p[z + 1] = acc;
  }
}

}  // namespace hg::tracking
