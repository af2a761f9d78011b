#include "tracking/clear_mot.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>
#include <stdexcept>
#include <vector>

#include <gtest/gtest.h>

#include "common/config_error.h"

namespace hg::tracking {
namespace {

using Eigen::Vector3d;

MotPoint At(std::uint32_t id, double x, double y = 0.0) { return {id, Vector3d(x, y, 0.9)}; }

TEST(MinCostAssignmentTest, MatchesBruteForceOnRandomMatrices) {
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> u(0.0, 10.0);
  for (int trial = 0; trial < 300; ++trial) {
    const int rows = 1 + static_cast<int>(rng() % 5);
    const int cols = rows + static_cast<int>(rng() % 3);
    std::vector<double> cost(rows * cols);
    for (double& c : cost) c = std::round(u(rng) * 4.0) / 4.0;  // Ties too.
    const std::vector<int> a = MinCostAssignment(cost, rows, cols);
    ASSERT_EQ(a.size(), static_cast<std::size_t>(rows));
    double got = 0.0;
    std::vector<int> seen;
    for (int r = 0; r < rows; ++r) {
      ASSERT_GE(a[r], 0);
      ASSERT_LT(a[r], cols);
      seen.push_back(a[r]);
      got += cost[r * cols + a[r]];
    }
    std::sort(seen.begin(), seen.end());
    EXPECT_EQ(std::adjacent_find(seen.begin(), seen.end()), seen.end()) << "column used twice";
    // Brute force over every injection rows -> cols.
    std::vector<int> perm(cols);
    std::iota(perm.begin(), perm.end(), 0);
    double best = std::numeric_limits<double>::infinity();
    do {
      double s = 0.0;
      for (int r = 0; r < rows; ++r) s += cost[r * cols + perm[r]];
      best = std::min(best, s);
    } while (std::next_permutation(perm.begin(), perm.end()));
    EXPECT_NEAR(got, best, 1e-9) << "trial " << trial;
  }
}

TEST(MinCostAssignmentTest, RejectsMoreRowsThanColumns) {
  const std::vector<double> cost(6, 1.0);
  EXPECT_THROW((void)MinCostAssignment(cost, 3, 2), std::invalid_argument);
  EXPECT_THROW((void)MinCostAssignment(cost, 2, 4), std::invalid_argument);
}

TEST(ClearMotTest, PerfectTrackingWithAConstantOffset) {
  ClearMot mot;
  for (int t = 0; t < 10; ++t) {
    const std::vector<MotPoint> objects{At(1, 0.1 * t), At(2, 3.0 - 0.1 * t, 1.0)};
    const std::vector<MotPoint> tracks{At(7, 0.1 * t + 0.03), At(9, 3.0 - 0.1 * t, 1.04)};
    const MotFrame& f = mot.AddFrame(objects, tracks);
    ASSERT_EQ(f.matches.size(), 2u);
    EXPECT_EQ(f.matches[0].hypothesis_id, 7u);
    EXPECT_EQ(f.matches[1].hypothesis_id, 9u);
  }
  const MotTotals& s = mot.totals();
  EXPECT_EQ(s.frames, 10);
  EXPECT_EQ(s.objects, 20);
  EXPECT_EQ(s.matches, 20);
  EXPECT_EQ(s.misses + s.false_positives + s.mismatches, 0);
  EXPECT_DOUBLE_EQ(s.Mota(), 1.0);
  EXPECT_NEAR(s.Motp(), 0.035, 1e-12);
}

// A track is lost and a new one (new id) takes the person over: one switch.
TEST(ClearMotTest, ReplacedTrackIsOneSwitch) {
  ClearMot mot;
  for (int t = 0; t < 4; ++t) mot.AddFrame(std::vector{At(1, 0.0)}, std::vector{At(5, 0.05)});
  const MotFrame& f = mot.AddFrame(std::vector{At(1, 0.0)}, std::vector{At(6, 0.05)});
  ASSERT_EQ(f.matches.size(), 1u);
  EXPECT_TRUE(f.matches[0].mismatch);
  EXPECT_EQ(f.mismatches, 1);
  mot.AddFrame(std::vector{At(1, 0.0)}, std::vector{At(6, 0.05)});  // Stays with 6: no new switch.
  EXPECT_EQ(mot.totals().mismatches, 1);
  EXPECT_EQ(mot.totals().matches, 6);
  EXPECT_NEAR(mot.totals().Mota(), 1.0 - 1.0 / 6.0, 1e-12);
}

// Two tracks exchange their people (ids swap between two people far apart):
// each person changes hypothesis, so the swap is two switches, one per person.
TEST(ClearMotTest, SwapOfTwoTracksIsOneSwitchPerPerson) {
  ClearMot mot;
  for (int t = 0; t < 3; ++t) {
    mot.AddFrame(std::vector{At(1, 0.0), At(2, 2.0)}, std::vector{At(10, 0.0), At(20, 2.0)});
  }
  const MotFrame& f =
      mot.AddFrame(std::vector{At(1, 0.0), At(2, 2.0)}, std::vector{At(10, 2.0), At(20, 0.0)});
  EXPECT_EQ(f.mismatches, 2);
  EXPECT_EQ(f.misses, 0);
  EXPECT_EQ(f.false_positives, 0);
  EXPECT_EQ(mot.totals().mismatches, 2);
  EXPECT_NEAR(mot.totals().Mota(), 1.0 - 2.0 / 8.0, 1e-12);
}

// Two people pass each other; the tracks follow them but for one frame the
// other track is nearer. The old correspondence is still within the
// threshold, so it is kept: no switch (a nearest-neighbour match would swap).
TEST(ClearMotTest, KeepsACorrespondenceWhileItHolds) {
  ClearMot mot;
  mot.AddFrame(std::vector{At(1, 0.0), At(2, 1.0)}, std::vector{At(10, 0.0), At(20, 1.0)});
  const MotFrame& f =
      mot.AddFrame(std::vector{At(1, 0.5), At(2, 0.6)}, std::vector{At(10, 0.62), At(20, 0.48)});
  ASSERT_EQ(f.matches.size(), 2u);
  EXPECT_EQ(f.matches[0].hypothesis_id, 10u);
  EXPECT_EQ(f.matches[1].hypothesis_id, 20u);
  EXPECT_EQ(f.mismatches, 0);
  EXPECT_NEAR(f.distance_sum_m, 0.12 + 0.12, 1e-12);
}

TEST(ClearMotTest, MissesAndFalsePositives) {
  ClearMot mot;
  // Frame 0: both tracked. Frames 1-3: person 2 has no track (3 misses);
  // a track far from everybody appears in frames 2-3 (2 false positives).
  mot.AddFrame(std::vector{At(1, 0.0), At(2, 2.0)}, std::vector{At(10, 0.0), At(20, 2.1)});
  mot.AddFrame(std::vector{At(1, 0.0), At(2, 2.0)}, std::vector{At(10, 0.0)});
  for (int t = 0; t < 2; ++t) {
    const MotFrame& f =
        mot.AddFrame(std::vector{At(1, 0.0), At(2, 2.0)}, std::vector{At(10, 0.0), At(30, 3.5)});
    EXPECT_EQ(f.misses, 1);
    EXPECT_EQ(f.false_positives, 1);
  }
  const MotTotals& s = mot.totals();
  EXPECT_EQ(s.objects, 8);
  EXPECT_EQ(s.matches, 5);
  EXPECT_EQ(s.misses, 3);
  EXPECT_EQ(s.false_positives, 2);
  EXPECT_EQ(s.mismatches, 0);
  EXPECT_NEAR(s.Mota(), 1.0 - 5.0 / 8.0, 1e-12);
  EXPECT_NEAR(s.Motp(), 0.1 / 5.0, 1e-12);
}

// A hypothesis beyond the threshold is no match: a miss and a false positive.
TEST(ClearMotTest, ThresholdSeparatesMatchFromMissPlusFalsePositive) {
  ClearMot mot(ClearMotOptions{0.5});
  EXPECT_EQ(mot.AddFrame(std::vector{At(1, 0.0)}, std::vector{At(10, 0.49)}).matches.size(), 1u);
  const MotFrame& f = mot.AddFrame(std::vector{At(1, 0.0)}, std::vector{At(10, 0.51)});
  EXPECT_TRUE(f.matches.empty());
  EXPECT_EQ(f.misses, 1);
  EXPECT_EQ(f.false_positives, 1);
}

// A person disappears (under a table) and comes back: the same track id
// again is no switch; a different one is.
TEST(ClearMotTest, RematchAfterAGap) {
  ClearMot same;
  ClearMot other;
  for (ClearMot* mot : {&same, &other}) {
    for (int t = 0; t < 3; ++t)
      mot->AddFrame(std::vector{At(1, 0.1 * t)}, std::vector{At(4, 0.1 * t)});
    for (int t = 3; t < 6; ++t) mot->AddFrame(std::vector{At(1, 0.1 * t)}, {});
  }
  for (int t = 6; t < 8; ++t) {
    same.AddFrame(std::vector{At(1, 0.1 * t)}, std::vector{At(4, 0.1 * t)});
    other.AddFrame(std::vector{At(1, 0.1 * t)}, std::vector{At(8, 0.1 * t)});
  }
  EXPECT_EQ(same.totals().mismatches, 0);
  EXPECT_EQ(same.totals().misses, 3);
  EXPECT_NEAR(same.totals().Mota(), 1.0 - 3.0 / 8.0, 1e-12);
  EXPECT_EQ(other.totals().mismatches, 1);
  EXPECT_EQ(other.totals().misses, 3);
  EXPECT_NEAR(other.totals().Mota(), 1.0 - 4.0 / 8.0, 1e-12);
}

// Greedy nearest-first would pair person 2 with track 10 (0.25 m) and leave
// person 1 without a track; the optimal assignment matches both.
TEST(ClearMotTest, AssignmentIsOptimalNotGreedy) {
  ClearMot mot;
  const MotFrame& f =
      mot.AddFrame(std::vector{At(1, 0.0), At(2, 0.6)}, std::vector{At(10, 0.35), At(20, 0.95)});
  ASSERT_EQ(f.matches.size(), 2u);
  EXPECT_EQ(f.matches[0].hypothesis_id, 10u);
  EXPECT_EQ(f.matches[1].hypothesis_id, 20u);
  EXPECT_EQ(f.misses + f.false_positives, 0);
  EXPECT_NEAR(f.distance_sum_m, 0.7, 1e-12);
}

// Two people both last matched to one track (it jumped from the first to the
// second while the first was missed): the more recent correspondence keeps it.
TEST(ClearMotTest, MoreRecentCorrespondenceWinsAClaim) {
  ClearMot mot;
  mot.AddFrame(std::vector{At(1, 0.0)}, std::vector{At(10, 0.0)});
  mot.AddFrame(std::vector{At(1, 0.0), At(2, 0.3)}, std::vector{At(10, 0.3)});  // 10 -> 2.
  EXPECT_EQ(mot.last_frame().matches.size(), 1u);
  EXPECT_EQ(mot.last_frame().matches[0].object_id, 1u);  // Kept: 1 still within reach.
  mot.AddFrame(std::vector{At(1, 0.0), At(2, 0.6)}, std::vector{At(10, 0.6)});  // Only 2 reaches.
  EXPECT_EQ(mot.last_frame().matches[0].object_id, 2u);
  EXPECT_EQ(mot.totals().mismatches, 0);  // First match of person 2.
  const MotFrame& f = mot.AddFrame(std::vector{At(1, 0.3), At(2, 0.3)}, std::vector{At(10, 0.3)});
  ASSERT_EQ(f.matches.size(), 1u);
  EXPECT_EQ(f.matches[0].object_id, 2u);
  EXPECT_FALSE(f.matches[0].mismatch);
  EXPECT_EQ(f.misses, 1);
}

TEST(ClearMotTest, HypothesesNearADistractorAreIgnored) {
  ClearMot mot;
  const std::vector<Vector3d> crate{Vector3d(3.0, 0.0, 0.7)};
  const MotFrame& f = mot.AddFrame(std::vector{At(1, 0.0)},
                                   std::vector{At(10, 0.0), At(11, 3.1), At(12, 5.0)}, crate);
  EXPECT_EQ(f.matches.size(), 1u);
  EXPECT_EQ(f.ignored, 1);
  EXPECT_EQ(f.false_positives, 1);
  EXPECT_EQ(mot.totals().ignored, 1);
  EXPECT_NEAR(mot.totals().Mota(), 0.0, 1e-12);
}

TEST(ClearMotTest, EmptyAndBadInput) {
  ClearMot mot;
  mot.AddFrame({}, {});
  EXPECT_TRUE(std::isnan(mot.totals().Mota()));
  EXPECT_TRUE(std::isnan(mot.totals().Motp()));
  EXPECT_THROW(mot.AddFrame(std::vector{At(1, 0.0), At(1, 1.0)}, {}), std::invalid_argument);
  EXPECT_THROW(ClearMot(ClearMotOptions{0.0}), common::ConfigError);
  EXPECT_THROW(ClearMot(ClearMotOptions{std::numeric_limits<double>::quiet_NaN()}),
               common::ConfigError);
}

}  // namespace
}  // namespace hg::tracking
