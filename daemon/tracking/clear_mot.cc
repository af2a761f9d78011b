#include "tracking/clear_mot.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "common/config_error.h"

namespace hg::tracking {
namespace {

void RequireUniqueIds(std::span<const MotPoint> points, const char* what) {
  for (std::size_t i = 0; i < points.size(); ++i) {
    for (std::size_t j = i + 1; j < points.size(); ++j) {
      if (points[i].id == points[j].id) {
        throw std::invalid_argument(std::string("ClearMot: duplicate ") + what + " id " +
                                    std::to_string(points[i].id));
      }
    }
  }
}

}  // namespace

double MotTotals::Mota() const {
  if (objects == 0) return std::numeric_limits<double>::quiet_NaN();
  return 1.0 -
         static_cast<double>(misses + false_positives + mismatches) / static_cast<double>(objects);
}

double MotTotals::Motp() const {
  if (matches == 0) return std::numeric_limits<double>::quiet_NaN();
  return distance_sum_m / static_cast<double>(matches);
}

std::vector<int> MinCostAssignment(std::span<const double> cost, int rows, int cols) {
  if (rows < 0 || cols < 0 || rows > cols ||
      cost.size() != static_cast<std::size_t>(rows) * static_cast<std::size_t>(cols)) {
    throw std::invalid_argument("MinCostAssignment: needs rows <= cols and rows * cols costs");
  }
  // Shortest augmenting paths with row potentials u and column potentials v
  // (1-based; column 0 is the virtual start of each path).
  const double inf = std::numeric_limits<double>::infinity();
  std::vector<double> u(rows + 1, 0.0), v(cols + 1, 0.0), min_slack(cols + 1);
  std::vector<int> row_of(cols + 1, 0), previous(cols + 1, 0);
  std::vector<char> used(cols + 1);
  for (int i = 1; i <= rows; ++i) {
    row_of[0] = i;
    int j0 = 0;
    std::fill(min_slack.begin(), min_slack.end(), inf);
    std::fill(used.begin(), used.end(), 0);
    do {
      used[j0] = 1;
      const int i0 = row_of[j0];
      double delta = inf;
      int j1 = 0;
      for (int j = 1; j <= cols; ++j) {
        if (used[j] != 0) continue;
        const double slack = cost[static_cast<std::size_t>(i0 - 1) * cols + (j - 1)] - u[i0] - v[j];
        if (slack < min_slack[j]) {
          min_slack[j] = slack;
          previous[j] = j0;
        }
        if (min_slack[j] < delta) {
          delta = min_slack[j];
          j1 = j;
        }
      }
      for (int j = 0; j <= cols; ++j) {
        if (used[j] != 0) {
          u[row_of[j]] += delta;
          v[j] -= delta;
        } else {
          min_slack[j] -= delta;
        }
      }
      j0 = j1;
    } while (row_of[j0] != 0);
    // Flip the path back to its start.
    do {
      const int j1 = previous[j0];
      row_of[j0] = row_of[j1];
      j0 = j1;
    } while (j0 != 0);
  }
  std::vector<int> assignment(rows, -1);
  for (int j = 1; j <= cols; ++j) {
    if (row_of[j] != 0) assignment[row_of[j] - 1] = j - 1;
  }
  return assignment;
}

ClearMot::ClearMot(const ClearMotOptions& options) : options_(options) {
  if (!(options_.match_threshold_m > 0.0) || !std::isfinite(options_.match_threshold_m)) {
    throw common::ConfigError("clear_mot: match_threshold_m: must be a number > 0");
  }
}

ClearMot::History* ClearMot::Find(std::uint32_t object_id) {
  for (History& h : history_) {
    if (h.object_id == object_id) return &h;
  }
  return nullptr;
}

const MotFrame& ClearMot::AddFrame(std::span<const MotPoint> objects,
                                   std::span<const MotPoint> hypotheses,
                                   std::span<const Eigen::Vector3d> distractors_W) {
  RequireUniqueIds(objects, "object");
  RequireUniqueIds(hypotheses, "hypothesis");
  const std::int64_t t = totals_.frames;
  const double threshold = options_.match_threshold_m;
  const int n_obj = static_cast<int>(objects.size());
  const int n_hyp = static_cast<int>(hypotheses.size());
  auto distance = [&](int o, int h) {
    return (objects[o].position_W - hypotheses[h].position_W).norm();
  };
  object_match_.assign(n_obj, -1);
  hypothesis_match_.assign(n_hyp, -1);
  mismatch_.assign(n_obj, 0);

  // 1. Keep earlier correspondences that still hold.
  struct Claim {
    int object;
    int hypothesis;
    std::int64_t frame;
    double distance;
  };
  std::vector<Claim> claims;
  for (int o = 0; o < n_obj; ++o) {
    const History* past = Find(objects[o].id);
    if (past == nullptr) continue;
    for (int h = 0; h < n_hyp; ++h) {
      if (hypotheses[h].id != past->hypothesis_id) continue;
      const double d = distance(o, h);
      if (d <= threshold) claims.push_back({o, h, past->frame, d});
    }
  }
  std::sort(claims.begin(), claims.end(), [](const Claim& a, const Claim& b) {
    if (a.frame != b.frame) return a.frame > b.frame;
    if (a.distance != b.distance) return a.distance < b.distance;
    return a.object < b.object;
  });
  for (const Claim& c : claims) {
    if (hypothesis_match_[c.hypothesis] >= 0) continue;
    object_match_[c.object] = c.hypothesis;
    hypothesis_match_[c.hypothesis] = c.object;
  }

  // 2. Optimal assignment of the rest: a pair beyond the threshold costs more
  // than any set of pairs within it, so the assignment first has the most
  // pairs within the threshold and then the least total distance.
  rows_.clear();
  cols_.clear();
  for (int o = 0; o < n_obj; ++o) {
    if (object_match_[o] < 0) rows_.push_back(o);
  }
  for (int h = 0; h < n_hyp; ++h) {
    if (hypothesis_match_[h] < 0) cols_.push_back(h);
  }
  if (!rows_.empty() && !cols_.empty()) {
    const bool transpose = rows_.size() > cols_.size();
    const std::vector<int>& r = transpose ? cols_ : rows_;
    const std::vector<int>& c = transpose ? rows_ : cols_;
    const int nr = static_cast<int>(r.size());
    const int nc = static_cast<int>(c.size());
    const double beyond = (nr + 1) * threshold + 1.0;
    cost_.resize(static_cast<std::size_t>(nr) * nc);
    for (int i = 0; i < nr; ++i) {
      for (int j = 0; j < nc; ++j) {
        const double d = transpose ? distance(c[j], r[i]) : distance(r[i], c[j]);
        cost_[static_cast<std::size_t>(i) * nc + j] = d <= threshold ? d : beyond;
      }
    }
    const std::vector<int> assignment = MinCostAssignment(cost_, nr, nc);
    for (int i = 0; i < nr; ++i) {
      const int j = assignment[i];
      if (j < 0) continue;
      const int o = transpose ? c[j] : r[i];
      const int h = transpose ? r[i] : c[j];
      if (distance(o, h) > threshold) continue;
      object_match_[o] = h;
      hypothesis_match_[h] = o;
      const History* past = Find(objects[o].id);
      // 3. A new hypothesis for an object that had another one.
      if (past != nullptr && past->hypothesis_id != hypotheses[h].id) mismatch_[o] = 1;
    }
  }

  // Book-keeping.
  frame_.objects = n_obj;
  frame_.hypotheses = n_hyp;
  frame_.misses = 0;
  frame_.false_positives = 0;
  frame_.ignored = 0;
  frame_.mismatches = 0;
  frame_.distance_sum_m = 0.0;
  frame_.matches.clear();
  for (int o = 0; o < n_obj; ++o) {
    const int h = object_match_[o];
    if (h < 0) {
      ++frame_.misses;
      continue;
    }
    const double d = distance(o, h);
    frame_.matches.push_back({objects[o].id, hypotheses[h].id, d, mismatch_[o] != 0});
    frame_.distance_sum_m += d;
    frame_.mismatches += mismatch_[o];
    History* past = Find(objects[o].id);
    if (past == nullptr) {
      history_.push_back({objects[o].id, hypotheses[h].id, t});
    } else {
      past->hypothesis_id = hypotheses[h].id;
      past->frame = t;
    }
  }
  // 4. Hypotheses without an object.
  for (int h = 0; h < n_hyp; ++h) {
    if (hypothesis_match_[h] >= 0) continue;
    const bool near_distractor =
        std::any_of(distractors_W.begin(), distractors_W.end(), [&](const Eigen::Vector3d& p) {
          return (p - hypotheses[h].position_W).norm() <= threshold;
        });
    ++(near_distractor ? frame_.ignored : frame_.false_positives);
  }

  ++totals_.frames;
  totals_.objects += n_obj;
  totals_.matches += static_cast<std::int64_t>(frame_.matches.size());
  totals_.misses += frame_.misses;
  totals_.false_positives += frame_.false_positives;
  totals_.ignored += frame_.ignored;
  totals_.mismatches += frame_.mismatches;
  totals_.distance_sum_m += frame_.distance_sum_m;
  return frame_;
}

}  // namespace hg::tracking
