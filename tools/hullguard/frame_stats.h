#pragma once
/// @file
/// Median, 99th percentile and maximum of per-frame times, as the tools report them.

#include <algorithm>
#include <vector>

namespace hg::tools {

struct FrameStats {
  double median = 0.0;
  double p99 = 0.0;
  double max = 0.0;
};

/// Nearest-rank statistics of `v` (all zero when empty).
[[nodiscard]] inline FrameStats Summarise(std::vector<double> v) {
  if (v.empty()) return {};
  std::sort(v.begin(), v.end());
  auto at = [&](double q) {
    return v[std::min(v.size() - 1, static_cast<std::size_t>(q * (v.size() - 1) + 0.5))];
  };
  return {at(0.5), at(0.99), v.back()};
}

}  // namespace hg::tools
