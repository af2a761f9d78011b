#include "pipeline/published_grid.h"

#include <algorithm>
#include <bit>
#include <cstdint>

#include "common/check.h"

namespace hg::pipeline {

PublishedGrid::PublishedGrid(int depth) : depth_(depth) {
  HG_CHECK(depth >= 1 && depth <= 10);
  const std::size_t cells = std::size_t{1} << (3 * depth);
  occupied_bits_.assign((cells + 63) / 64, 0);
  occluded_bits_.assign((cells + 63) / 64, 0);
}

void PublishedGrid::Fill(const octree::Octree& tree, OccupancySnapshot* snapshot) {
  std::fill(occupied_bits_.begin(), occupied_bits_.end(), 0);
  std::fill(occluded_bits_.begin(), occluded_bits_.end(), 0);
  const int p = depth_;
  const std::uint32_t n = 1U << p;
  auto mark = [&](std::vector<std::uint64_t>& bits, std::uint32_t x, std::uint32_t y,
                  std::uint32_t z) {
    const std::size_t i = x + static_cast<std::size_t>(n) * (y + static_cast<std::size_t>(n) * z);
    bits[i >> 6] |= std::uint64_t{1} << (i & 63);
  };
  // Cells of the published level come summarised (occupied over occluded);
  // coarser leaves cover blocks of them.
  tree.ForEachCellUpTo(p, [&](const octree::Cell& cell, octree::LeafState state) {
    if (state == octree::LeafState::kFree) return;
    std::vector<std::uint64_t>& bits =
        state == octree::LeafState::kOccupied ? occupied_bits_ : occluded_bits_;
    if (cell.level >= p) {  // Finer only where p is above the roots' level.
      const int shift = cell.level - p;
      mark(bits, cell.x >> shift, cell.y >> shift, cell.z >> shift);
      return;
    }
    // A coarse leaf covers a block of published cells.
    const std::uint32_t span = 1U << (p - cell.level);
    for (std::uint32_t z = cell.z * span; z < (cell.z + 1) * span; ++z) {
      for (std::uint32_t y = cell.y * span; y < (cell.y + 1) * span; ++y) {
        for (std::uint32_t x = cell.x * span; x < (cell.x + 1) * span; ++x) mark(bits, x, y, z);
      }
    }
  });
  snapshot->occupied.clear();
  snapshot->occluded.clear();
  // Runs along x: consecutive set bits of a row (rows are n bits long and
  // start at multiples of n, so runs split only at row ends).
  struct Emitter {
    std::vector<GridRun>* out;
    std::size_t end = SIZE_MAX;  // Index after the last cell of the open run.
  };
  auto emit = [n](std::uint64_t word, std::size_t base, Emitter* e) {
    while (word != 0) {
      const int s = std::countr_zero(word);
      const int len = std::countr_one(word >> s);
      word = s + len >= 64 ? 0 : word & ~(((std::uint64_t{1} << len) - 1) << s);
      std::size_t i = base + static_cast<std::size_t>(s);
      std::size_t left = static_cast<std::size_t>(len);
      while (left > 0) {
        const std::size_t x = i % n;
        const std::size_t take = std::min<std::size_t>(left, n - x);
        if (e->end == i && x != 0) {
          e->out->back().length = static_cast<std::uint16_t>(e->out->back().length + take);
        } else {
          const std::size_t row = i / n;
          e->out->push_back({static_cast<std::uint16_t>(x), static_cast<std::uint16_t>(row % n),
                             static_cast<std::uint16_t>(row / n),
                             static_cast<std::uint16_t>(take)});
        }
        i += take;
        left -= take;
        e->end = i;
      }
    }
  };
  Emitter occupied{&snapshot->occupied};
  Emitter occluded{&snapshot->occluded};
  for (std::size_t w = 0; w < occupied_bits_.size(); ++w) {
    // Occupied wins over occluded where a published cell holds both.
    const std::uint64_t occ = occupied_bits_[w];
    emit(occ, w * 64, &occupied);
    emit(occluded_bits_[w] & ~occ, w * 64, &occluded);
  }
}

}  // namespace hg::pipeline
