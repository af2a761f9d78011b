#include "pipeline/blob_filter.h"

#include "common/check.h"

namespace hg::pipeline {

BlobFilter::BlobFilter(int depth, std::size_t min_cells) : n_(1 << depth), min_cells_(min_cells) {
  HG_CHECK(depth >= 1 && depth <= 10);
  HG_CHECK(min_cells >= 1);
  const std::size_t rows = static_cast<std::size_t>(n_) * n_;
  occupied_rows_.assign(rows + 1, 0);
  occluded_rows_.assign(rows + 1, 0);
}

int BlobFilter::Find(int i) {
  while (parent_[i] != i) i = parent_[i] = parent_[parent_[i]];
  return i;
}

void BlobFilter::Union(int a, int b) {
  a = Find(a);
  b = Find(b);
  if (a != b) parent_[a < b ? b : a] = a < b ? a : b;
}

void BlobFilter::IndexRows(const std::vector<GridRun>& runs,
                           std::vector<std::uint32_t>* starts) const {
  std::vector<std::uint32_t>& s = *starts;
  std::size_t i = 0;
  const std::size_t rows = s.size() - 1;
  for (std::size_t row = 0; row < rows; ++row) {
    s[row] = static_cast<std::uint32_t>(i);
    while (i < runs.size() &&
           static_cast<std::size_t>(runs[i].y) + static_cast<std::size_t>(n_) * runs[i].z == row) {
      ++i;
    }
  }
  s[rows] = static_cast<std::uint32_t>(i);
  HG_CHECK(i == runs.size());  // Sorted by row.
}

BlobFilterStats BlobFilter::Apply(std::vector<GridRun>* occupied,
                                  const std::vector<GridRun>& occluded) {
  BlobFilterStats stats;
  const int num_occupied = static_cast<int>(occupied->size());
  const int total = num_occupied + static_cast<int>(occluded.size());
  if (num_occupied == 0) return stats;
  IndexRows(*occupied, &occupied_rows_);
  IndexRows(occluded, &occluded_rows_);
  parent_.resize(static_cast<std::size_t>(total));
  for (int i = 0; i < total; ++i) parent_[i] = i;
  auto run = [&](int i) -> const GridRun& {
    return i < num_occupied ? (*occupied)[i] : occluded[i - num_occupied];
  };

  // Each run meets the runs it touches in its own row, in the row before and
  // in the three rows of the layer before: every touching pair is met from
  // its later run at least.
  for (int i = 0; i < total; ++i) {
    const GridRun& r = run(i);
    const int x0 = r.x - 1;
    const int x1 = r.x + r.length;  // Inclusive reach: one beyond either end.
    auto join_row = [&](int y, int z) {
      if (y < 0 || y >= n_ || z < 0) return;
      const std::size_t row = static_cast<std::size_t>(y) + static_cast<std::size_t>(n_) * z;
      for (int list = 0; list < 2; ++list) {
        const std::vector<std::uint32_t>& starts = list == 0 ? occupied_rows_ : occluded_rows_;
        const int base = list == 0 ? 0 : num_occupied;
        for (std::uint32_t j = starts[row]; j < starts[row + 1]; ++j) {
          const GridRun& o = run(base + static_cast<int>(j));
          if (o.x > x1) break;
          if (o.x + o.length - 1 >= x0) Union(i, base + static_cast<int>(j));
        }
      }
    };
    join_row(r.y, r.z);
    join_row(r.y - 1, r.z);
    for (int dy = -1; dy <= 1; ++dy) join_row(r.y + dy, r.z - 1);
  }

  cells_.assign(static_cast<std::size_t>(total), 0);
  keep_.assign(static_cast<std::size_t>(total), 0);
  for (int i = 0; i < total; ++i) {
    const GridRun& r = run(i);
    const int root = Find(i);
    const bool face =
        r.x == 0 || r.x + r.length == n_ || r.y == 0 || r.y == n_ - 1 || r.z == 0 || r.z == n_ - 1;
    if (i >= num_occupied || face) keep_[root] = 1;
    if (i < num_occupied) cells_[root] += r.length;
  }
  for (int i = 0; i < total; ++i) {
    if (Find(i) == i && cells_[i] > 0) ++stats.components;
  }
  std::size_t out = 0;
  for (int i = 0; i < num_occupied; ++i) {
    const int root = Find(i);
    const bool drop = keep_[root] == 0 && cells_[root] < min_cells_;
    if (drop) {
      stats.dropped_cells += (*occupied)[i].length;
      if (root == i) ++stats.dropped_components;
    } else {
      (*occupied)[out++] = (*occupied)[i];
    }
  }
  occupied->resize(out);
  return stats;
}

}  // namespace hg::pipeline
