#include "tracking/tracker.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "common/config_error.h"
#include "scene/demo_cell.h"
#include "support/grid_runs.h"

namespace hg::tracking {
namespace {

using Eigen::Vector3d;

constexpr double kDt = 1.0 / 30.0;

std::int64_t StampNs(int frame) { return static_cast<std::int64_t>(frame) * 33'333'333; }

VoxelGrid CellGrid(double voxel_m = 0.04) {
  return VoxelGrid({Vector3d::Zero(), Vector3d(4, 4, 2.2)}, voxel_m);
}

Ellipsoid Person(const Vector3d& centre) { return {centre, Vector3d(0.25, 0.2, 0.85)}; }

// UNKNOWN voxels of the blobs, leaving out voxels `hidden` says no camera sees.
template <typename Hidden>
void SetBlobs(Tracker* tracker, const std::vector<Ellipsoid>& blobs, Hidden hidden) {
  const VoxelGrid& g = tracker->voxel_map().grid();
  std::vector<std::uint32_t> all, visible;
  for (const Ellipsoid& b : blobs) AppendVoxelsInside(g, b, &all);
  for (const std::uint32_t i : all) {
    const Eigen::Vector3i c = g.Coords(i);
    if (!hidden(g.Centre(c.x(), c.y(), c.z()))) visible.push_back(i);
  }
  tracker->voxel_map().SetUnknown(visible);
}

void SetBlobs(Tracker* tracker, const std::vector<Ellipsoid>& blobs) {
  SetBlobs(tracker, blobs, [](const Vector3d&) { return false; });
}

Tracker OpenCellTracker(const TrackerOptions& options = {}, double voxel_m = 0.04) {
  const VoxelGrid g = CellGrid(voxel_m);
  return Tracker(options, VoxelMap(g, std::vector<VoxelState>(g.size(), VoxelState::kFree)),
                 CollisionWorld());
}

const Track* Nearest(const std::vector<Track>& tracks, const Vector3d& p) {
  const Track* best = nullptr;
  for (const Track& t : tracks) {
    if (best == nullptr || (t.centre_W - p).norm() < (best->centre_W - p).norm()) best = &t;
  }
  return best;
}

TEST(TrackerOptionsTest, EveryProblemIsReported) {
  TrackerOptions o;
  EXPECT_TRUE(CheckOptions(o).empty());
  o.voxel_m = 0.0;
  o.filter.collision_radius_m = 0.5;  // Not smaller than the half-axes.
  o.occluded_min_share = 1.5;
  o.object_particles = 0;
  const std::vector<OptionProblem> p = CheckOptions(o);
  ASSERT_EQ(p.size(), 4u);
  EXPECT_EQ(p[0].key, "voxel_m");
  EXPECT_EQ(p[1].key, "object_particles");
  EXPECT_EQ(p[2].key, "filter.collision_radius_m");
  EXPECT_EQ(p[3].key, "occluded_min_share");
  try {
    OpenCellTracker(o);
    FAIL() << "no exception";
  } catch (const common::ConfigError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("voxel_m: must be > 0"), std::string::npos) << m;
    EXPECT_NE(m.find("filter.collision_radius_m"), std::string::npos) << m;
    EXPECT_NE(m.find("occluded_min_share"), std::string::npos) << m;
  }
}

// A person walks in through one side of the cell and out through the other;
// later another enters and gets a new id.
TEST(TrackerTest, BirthOnEntryDeathOnExit) {
  Tracker tracker = OpenCellTracker();
  int frame = 0;
  const Vector3d velocity(1.2, 0.0, 0.0);
  for (int k = 0; k <= 120; ++k, ++frame) {
    const Vector3d c = Vector3d(-0.4, 2.0, 0.9) + velocity * (k * kDt);
    SetBlobs(&tracker, {Person(c)});
    tracker.Step(StampNs(frame));
    const auto& tracks = tracker.tracks();
    ASSERT_LE(tracks.size(), 1u) << "frame " << frame;
    if (c.x() > 0.5 && c.x() < 3.5) {
      ASSERT_EQ(tracks.size(), 1u) << "frame " << frame;
      EXPECT_EQ(tracks[0].id, 1u);
      EXPECT_LT((tracks[0].centre_W - c).norm(), 0.1) << "frame " << frame;
      EXPECT_FALSE(tracks[0].occluded);
      EXPECT_EQ(tracks[0].time_since_support_s, 0.0);
    }
    if (c.x() > 1.5 && c.x() < 3.0) {
      EXPECT_LT((tracks[0].velocity_W_mps - velocity).norm(), 0.4) << "frame " << frame;
    }
  }
  // Gone: the track dies within the death timeout.
  for (int k = 0; k < 40; ++k, ++frame) {
    SetBlobs(&tracker, {});
    tracker.Step(StampNs(frame));
  }
  EXPECT_TRUE(tracker.tracks().empty());
  EXPECT_EQ(tracker.stats().births, 1u);
  EXPECT_EQ(tracker.stats().deaths, 1u);
  // Someone else enters from the far side in y.
  for (int k = 0; k <= 30; ++k, ++frame) {
    SetBlobs(&tracker, {Person(Vector3d(2.0, 4.3 - 1.2 * k * kDt, 0.9))});
    tracker.Step(StampNs(frame));
  }
  ASSERT_EQ(tracker.tracks().size(), 1u);
  EXPECT_EQ(tracker.tracks()[0].id, 2u);
  EXPECT_EQ(tracker.stats().births, 2u);
}

// A parcel (0.6 m tall) appears and stays: it occupies a person's volume but
// gets an object track, never published. A person who comes in standing and
// then crouches to the parcel's height keeps the track. Someone crouching when
// tracking starts is an object until they stand up.
// Abort() cuts a cycle in progress short (a daemon's stop with many particles:
// a cycle of seconds held SIGTERM up), and every later one.
TEST(TrackerTest, AbortCutsACycleShort) {
  TrackerOptions options;
  options.filter.num_particles = 20000;
  Tracker tracker = OpenCellTracker(options);
  const std::vector<Ellipsoid> people = {Person(Vector3d(1.0, 1.0, 0.9)),
                                         Person(Vector3d(3.0, 3.0, 0.9))};
  int frame = 0;
  for (; frame < 2; ++frame) {
    SetBlobs(&tracker, people);
    tracker.Step(StampNs(frame));
  }
  ASSERT_EQ(tracker.tracks().size(), 2u);
  using Clock = std::chrono::steady_clock;
  SetBlobs(&tracker, people);
  Clock::time_point start = Clock::now();
  tracker.Step(StampNs(frame++));
  const Clock::duration whole = Clock::now() - start;
  ASSERT_EQ(tracker.tracks().size(), 2u);

  SetBlobs(&tracker, people);
  std::atomic<bool> started{false};
  Clock::time_point ended;
  std::thread cycle([&] {
    started.store(true);
    tracker.Step(StampNs(frame));
    ended = Clock::now();
  });
  while (!started.load()) std::this_thread::yield();
  std::this_thread::sleep_for(whole / 10);
  const Clock::time_point aborted_at = Clock::now();
  tracker.Abort();
  cycle.join();
  EXPECT_TRUE(tracker.aborted());
  const auto after_abort =
      std::chrono::duration_cast<std::chrono::milliseconds>(ended - aborted_at);
  const auto whole_ms = std::chrono::duration_cast<std::chrono::milliseconds>(whole);
  EXPECT_LT(after_abort, whole_ms / 3) << "a whole cycle takes " << whole_ms.count() << " ms";
  start = Clock::now();
  tracker.Step(StampNs(frame + 1));  // Later cycles return at once.
  EXPECT_LT(Clock::now() - start, whole / 3);
}

TEST(TrackerTest, OnlyStandingPeopleStartTracks) {
  Tracker tracker = OpenCellTracker();
  const Ellipsoid parcel{Vector3d(3.0, 3.0, 0.3), Vector3d(0.35, 0.35, 0.3)};
  ASSERT_GE(parcel.Volume(), TrackerOptions{}.birth_min_volume_m3);
  int frame = 0;
  for (int k = 0; k < 60; ++k, ++frame) {
    SetBlobs(&tracker, {parcel});
    tracker.Step(StampNs(frame));
    ASSERT_TRUE(tracker.tracks().empty()) << "frame " << frame;
  }
  const Vector3d c(1.2, 1.2, 0.9);
  for (int k = 0; k < 30; ++k, ++frame) {
    SetBlobs(&tracker, {parcel, Person(c)});
    tracker.Step(StampNs(frame));
  }
  ASSERT_EQ(tracker.tracks().size(), 1u);
  const std::uint32_t id = tracker.tracks()[0].id;
  // Crouching: as low as the parcel, for longer than the death timeout.
  const Ellipsoid crouched{Vector3d(1.2, 1.2, 0.3), Vector3d(0.3, 0.3, 0.3)};
  for (int k = 0; k < 60; ++k, ++frame) {
    SetBlobs(&tracker, {parcel, crouched});
    tracker.Step(StampNs(frame));
    ASSERT_EQ(tracker.tracks().size(), 1u) << "frame " << frame;
    EXPECT_EQ(tracker.tracks()[0].id, id);
  }
  EXPECT_LT((tracker.tracks()[0].centre_W - crouched.centre_W).norm(), 0.15);
  EXPECT_EQ(tracker.stats().births, 1u);
  EXPECT_EQ(tracker.stats().object_births, 1u);

  // Crouching from the start, then standing up where they are.
  Tracker later = OpenCellTracker();
  for (int k = 0; k < 30; ++k, ++frame) {
    SetBlobs(&later, {crouched});
    later.Step(StampNs(frame));
    ASSERT_TRUE(later.tracks().empty()) << "frame " << frame;
  }
  // An object track, with fewer particles (the first id).
  ASSERT_NE(later.filter(1), nullptr);
  EXPECT_EQ(later.filter(1)->particles().size(),
            static_cast<std::size_t>(TrackerOptions{}.object_particles));
  for (int k = 0; k < 30; ++k, ++frame) {
    SetBlobs(&later, {Person(c)});
    later.Step(StampNs(frame));
  }
  ASSERT_EQ(later.tracks().size(), 1u);
  EXPECT_LT((later.tracks()[0].centre_W - c).norm(), 0.15);
  EXPECT_EQ(later.stats().promotions, 1u);
  EXPECT_EQ(later.filter(later.tracks()[0].id)->particles().size(),
            static_cast<std::size_t>(TrackerOptions{}.filter.num_particles));
  EXPECT_EQ(later.stats().births, 1u);
}

// The tracker misses 2.5 s (a daemon whose updates were too coarse to track
// on) while the person walks on 2 m: afterwards there is one track, with the
// person's id, not a stale one beside a new one.
TEST(TrackerTest, LongGapLeavesNoStaleTrack) {
  Tracker tracker = OpenCellTracker();
  const Vector3d v(0.8, 0.0, 0.0);
  const Vector3d start(0.5, 2.0, 0.9);
  int frame = 0;
  for (; frame < 30; ++frame) {
    SetBlobs(&tracker, {Person(start + v * (frame * kDt))});
    tracker.Step(StampNs(frame));
  }
  ASSERT_EQ(tracker.tracks().size(), 1u);
  const std::uint32_t id = tracker.tracks()[0].id;
  frame += 75;  // 2.5 s without a cycle.
  for (int k = 0; k < 10; ++k, ++frame) {
    const Vector3d p = start + v * (frame * kDt);
    SetBlobs(&tracker, {Person(p)});
    tracker.Step(StampNs(frame));
    ASSERT_LE(tracker.tracks().size(), 1u) << "cycle " << k;
  }
  ASSERT_EQ(tracker.tracks().size(), 1u);
  EXPECT_EQ(tracker.tracks()[0].id, id);
  EXPECT_LT((tracker.tracks()[0].centre_W - (start + v * ((frame - 1) * kDt))).norm(), 0.2);
}

// The silhouette cones of a low object leave a thin tip of occupancy above
// it, which the occupancy's cells widen to a few voxels across: not a head. A
// parcel with a tip three voxels square reaching 1.3 m gets an object track.
TEST(TrackerTest, ThinTipAboveAParcelIsNoHead) {
  Tracker tracker = OpenCellTracker();
  const VoxelGrid& g = tracker.voxel_map().grid();
  std::vector<std::uint32_t> voxels;
  AppendVoxelsInside(g, {Vector3d(3.0, 3.0, 0.3), Vector3d(0.35, 0.35, 0.3)}, &voxels);
  const Eigen::Vector3i centre = g.VoxelOf(Vector3d(3.0, 3.0, 0.0));
  const int top = g.VoxelOf(Vector3d(0.0, 0.0, 1.3)).z();
  ASSERT_GE(9 * g.voxel_m() * g.voxel_m(), 0.01);  // Three voxels square would pass for a head.
  for (int z = g.VoxelOf(Vector3d(0.0, 0.0, 0.6)).z(); z <= top; ++z) {
    for (int y = centre.y() - 1; y <= centre.y() + 1; ++y) {
      for (int x = centre.x() - 1; x <= centre.x() + 1; ++x) voxels.push_back(g.Index(x, y, z));
    }
  }
  std::sort(voxels.begin(), voxels.end());
  voxels.erase(std::unique(voxels.begin(), voxels.end()), voxels.end());
  for (int frame = 0; frame < 30; ++frame) {
    tracker.voxel_map().SetUnknown(voxels);
    tracker.Step(StampNs(frame));
    ASSERT_TRUE(tracker.tracks().empty()) << "frame " << frame;
  }
  EXPECT_EQ(tracker.stats().object_births, 1u);
  EXPECT_EQ(tracker.stats().births, 0u);
}

// Two people walk past each other shoulder to shoulder (their blobs touch and
// form one component while they pass): neither id swaps nor merges.
TEST(TrackerTest, TwoPeoplePassingKeepTheirIds) {
  Tracker tracker = OpenCellTracker();
  const Vector3d a0(0.6, 1.8, 0.9), b0(3.4, 2.2, 0.9);
  const Vector3d va(1.2, 0.0, 0.0), vb(-1.2, 0.0, 0.0);
  std::uint32_t id_a = 0, id_b = 0;
  double worst = 0.0;
  for (int k = 0; k <= 70; ++k) {
    const Vector3d a = a0 + va * (k * kDt), b = b0 + vb * (k * kDt);
    SetBlobs(&tracker, {Person(a), Person(b)});
    tracker.Step(StampNs(k));
    const auto& tracks = tracker.tracks();
    ASSERT_EQ(tracks.size(), 2u) << "frame " << k;
    if (k == 0) {
      id_a = Nearest(tracks, a)->id;
      id_b = Nearest(tracks, b)->id;
      ASSERT_NE(id_a, id_b);
      continue;
    }
    ASSERT_EQ(Nearest(tracks, a)->id, id_a) << "frame " << k;
    ASSERT_EQ(Nearest(tracks, b)->id, id_b) << "frame " << k;
    for (const Track& t : tracks) {
      const Vector3d& truth = t.id == id_a ? a : b;
      if (k > 10) worst = std::max(worst, (t.centre_W - truth).norm());
    }
  }
  EXPECT_LT(worst, 0.1);
  EXPECT_EQ(tracker.stats().births, 2u);
  EXPECT_EQ(tracker.stats().deaths, 0u);
}

// The tests of people sharing one component run at the tests' voxel and at
// the default (TrackerOptions::voxel_m): which pieces of the floor plan hold
// interior evidence depends on it.
constexpr double kSplitVoxels[] = {0.04, 0.05};

// Radius of an arm (m): occupied voxels one or two wide across it at either
// voxel, so that none of them has evidence on all four horizontal sides.
double ArmRadius(double voxel_m) { return voxel_m < 0.045 ? 0.035 : 0.045; }

// A ball of 0.3 m held out along +x at arm's length by a person standing at
// `person` (Person()), and the arm. At 5 cm the arm is thicker (ArmRadius),
// so its ends taper away sooner, and it is longer to reach both the body and
// the ball.
std::vector<Ellipsoid> HeldOut(const Vector3d& person, double voxel_m) {
  const double r = ArmRadius(voxel_m);
  const bool fine = voxel_m < 0.045;
  const Ellipsoid arm{person + Vector3d(fine ? 0.4 : 0.5, 0.0, 0.45),
                      Vector3d(fine ? 0.5 : 0.65, r, r)};
  const Ellipsoid ball{person + Vector3d(1.1, 0.0, 0.4), Vector3d::Constant(0.3)};
  return {arm, ball};
}

// Two people stand one behind the other from the first frame, their hulls
// joined between their legs (a ghost of the visual hull): one component, but
// two tracks from the first cycle, each on its person, and they stay. So too
// when one of them holds something out at arm's length: that is a third
// head-sized piece of the floor plan, but no person.
// Two people whose paths cross, one passing a fraction of a second ahead of
// the other: the evidence of the two tracks was split by the plane bisecting
// their 3-D centres, which tilted towards horizontal once the estimates
// drifted apart in height; then one filter fed on the upper and the other on
// the lower halves of both bodies, and both tracks sat stacked between the
// people (a person without a track within 0.5 m for several frames, in every
// seed). Each person keeps a track near them, at a person's height.
TEST(TrackerTest, PeopleCrossingCloselyKeepATrackEach) {
  const VoxelGrid g({Vector3d::Zero(), Vector3d(4, 4, 2.5)}, 0.05);
  for (const double lead : {0.2, 0.3, 0.5}) {
    for (std::uint64_t seed = 1; seed <= 3; ++seed) {
      TrackerOptions options;
      options.seed = seed;
      Tracker tracker(options, VoxelMap(g, std::vector<VoxelState>(g.size(), VoxelState::kFree)),
                      CollisionWorld());
      int misses = 0;
      double max_dz = 0.0;
      for (int f = 0; f < 150; ++f) {
        const double t = f / 30.0;
        const Vector3d a(0.3 + 0.9 * t, 2.5, 0.9);            // Walks along +x.
        const Vector3d b(1.5, 3.7 - 0.9 * (t + lead), 0.88);  // Along -y, ahead.
        std::vector<std::uint32_t> voxels;
        AppendVoxelsInside(g, {a, Vector3d(0.25, 0.2, 0.88)}, &voxels);
        AppendVoxelsInside(g, {b, Vector3d(0.2, 0.25, 0.85)}, &voxels);
        tracker.voxel_map().SetUnknown(voxels);
        tracker.Step(StampNs(f));
        const std::vector<Track>& tracks = tracker.tracks();
        if (tracks.size() == 2) {
          max_dz = std::max(max_dz, std::abs(tracks[0].centre_W.z() - tracks[1].centre_W.z()));
        }
        for (const Vector3d& p : {a, b}) {
          if (p.y() < 0.4 || p.x() > 3.6 || f < 5) continue;  // Leaving; being born.
          const Track* near = Nearest(tracks, p);
          misses += near == nullptr || (near->centre_W - p).norm() > 0.5 ? 1 : 0;
        }
      }
      EXPECT_EQ(misses, 0) << "lead " << lead << " s, seed " << seed;
      EXPECT_LT(max_dz, 0.25) << "lead " << lead << " s, seed " << seed;
    }
  }
}

TEST(TrackerTest, PeopleOneBehindTheOtherInOneComponentGetATrackEach) {
  for (const double voxel_m : kSplitVoxels) {
    for (const bool holding : {false, true}) {
      SCOPED_TRACE(testing::Message() << "voxel " << voxel_m << (holding ? ", holding" : ""));
      Tracker tracker = OpenCellTracker({}, voxel_m);
      const Vector3d a(2.0, 1.65, 0.9), b(2.0, 2.25, 0.9);
      const Ellipsoid ghost{Vector3d(2.0, 1.95, 0.35), Vector3d(0.15, 0.3, 0.3)};
      std::vector<Ellipsoid> blobs = {Person(a), Person(b), ghost};
      if (holding) {
        const std::vector<Ellipsoid> held = HeldOut(b, voxel_m);
        blobs.insert(blobs.end(), held.begin(), held.end());
      }
      for (int k = 0; k <= 60; ++k) {
        SetBlobs(&tracker, blobs);
        tracker.Step(StampNs(k));
        const auto& tracks = tracker.tracks();
        ASSERT_EQ(tracks.size(), 2u) << "frame " << k;
        EXPECT_NE(Nearest(tracks, a)->id, Nearest(tracks, b)->id) << "frame " << k;
        EXPECT_LT((Nearest(tracks, a)->centre_W - a).norm(), 0.15) << "frame " << k;
        // The ball's share went to b's track at birth: it settles on b within
        // a few frames.
        if (!holding || k >= 20) {
          EXPECT_LT((Nearest(tracks, b)->centre_W - b).norm(), 0.15) << "frame " << k;
        }
      }
      EXPECT_EQ(tracker.stats().births, 2u);
      EXPECT_EQ(tracker.stats().object_births, 0u);
    }
  }
}

// A person holds a large object out at arm's length. The arm is too thin for
// interior evidence, so in the floor plan the object is a piece of its own
// with a head's cross-section, and the component stands on the person's legs;
// but the object floats, and would start no track on its own. One track from
// the first cycle, born on the whole component and nearer the person than the
// object, which settles on the person.
TEST(TrackerTest, APersonHoldingSomethingOutIsOneTrack) {
  for (const double voxel_m : kSplitVoxels) {
    SCOPED_TRACE(testing::Message() << "voxel " << voxel_m);
    Tracker tracker = OpenCellTracker({}, voxel_m);
    const Vector3d c(2.0, 2.0, 0.9);
    std::vector<Ellipsoid> blobs = HeldOut(c, voxel_m);
    const Vector3d held = blobs.back().centre_W;
    blobs.push_back(Person(c));
    for (int k = 0; k <= 60; ++k) {
      SetBlobs(&tracker, blobs);
      tracker.Step(StampNs(k));
      const auto& tracks = tracker.tracks();
      ASSERT_EQ(tracks.size(), 1u) << "frame " << k;
      const Vector3d& p = tracks[0].centre_W;
      EXPECT_LT((p - c).norm(), (p - held).norm()) << "frame " << k;
      if (k >= 20) {
        EXPECT_LT((p - c).norm(), 0.1) << "frame " << k;
      }
    }
    EXPECT_EQ(tracker.stats().births, 1u);
    EXPECT_EQ(tracker.stats().object_births, 0u);
  }
}

// A person with both arms out, thin, and something at each hand: a ball held
// out on one side, a standing lamp on the other, whose shade the hand rests
// on. Both are head-sized pieces of the floor plan apart from the person's;
// the ball floats, the lamp stands but is far less than a person. One track.
TEST(TrackerTest, APersonWithThingsAtBothHandsIsOneTrack) {
  for (const double voxel_m : kSplitVoxels) {
    SCOPED_TRACE(testing::Message() << "voxel " << voxel_m);
    Tracker tracker = OpenCellTracker({}, voxel_m);
    const Vector3d c(2.0, 2.0, 0.9);
    const double r = ArmRadius(voxel_m);
    // The arms reach into the body and into what the hands hold, so that
    // their tapered ends join both.
    const Ellipsoid left_arm{Vector3d(1.45, 2.0, 1.35), Vector3d(0.65, r, r)};
    const Ellipsoid ball{Vector3d(0.8, 2.0, 1.3), Vector3d::Constant(0.3)};
    const Ellipsoid right_arm{Vector3d(2.55, 2.0, 1.35), Vector3d(0.65, r, r)};
    // The pole's axis lies on voxel faces at both voxels: two by two voxels
    // across, down to the floor.
    const Ellipsoid pole{Vector3d(3.0, 2.0, 0.6), Vector3d(1.2 * voxel_m, 1.2 * voxel_m, 0.75)};
    const Ellipsoid shade{Vector3d(3.0, 2.0, 1.3), Vector3d::Constant(0.15)};
    ASSERT_LT(pole.Volume() + shade.Volume(), TrackerOptions{}.birth_min_volume_m3);
    for (int k = 0; k <= 60; ++k) {
      SetBlobs(&tracker, {Person(c), left_arm, ball, right_arm, pole, shade});
      tracker.Step(StampNs(k));
      const auto& tracks = tracker.tracks();
      ASSERT_EQ(tracks.size(), 1u) << "frame " << k;
      if (k >= 20) {
        EXPECT_LT((tracks[0].centre_W - c).norm(), 0.1) << "frame " << k;
      }
    }
    EXPECT_EQ(tracker.stats().births, 1u);
    EXPECT_EQ(tracker.stats().object_births, 0u);
  }
}

// A person crawls under a table: under the top nobody sees (OCCLUDED), so the
// UNKNOWN blob shrinks to nothing and grows again on the far side. The track
// stays alive (occluded) and keeps its id.
TEST(TrackerTest, CrawlUnderATableKeepsTheTrack) {
  const VoxelGrid g = CellGrid();
  const Vector3d table_min(1.4, 1.4, 0.0), table_max(2.6, 2.6, 0.95);
  auto under_table = [&](const Vector3d& p) {
    return p.x() >= table_min.x() && p.x() <= table_max.x() && p.y() >= table_min.y() &&
           p.y() <= table_max.y() && p.z() < 0.9;
  };
  std::vector<VoxelState> states(g.size(), VoxelState::kFree);
  for (int z = 0; z < g.nz(); ++z) {
    for (int y = 0; y < g.ny(); ++y) {
      for (int x = 0; x < g.nx(); ++x) {
        const Vector3d p = g.Centre(x, y, z);
        if (under_table(p)) states[g.Index(x, y, z)] = VoxelState::kOccluded;
        if (p.z() >= 0.9 && p.z() <= 0.95 && p.x() >= 1.4 && p.x() <= 2.6 && p.y() >= 1.4 &&
            p.y() <= 2.6) {
          states[g.Index(x, y, z)] = VoxelState::kKnown;
        }
      }
    }
  }
  std::vector<CollisionShape> shapes;
  sim::BoxSolid top;
  top.centre_W = {2.0, 2.0, 0.925};
  top.half_extents_m = {0.6, 0.6, 0.025};
  shapes.emplace_back(top);
  for (const double x : {1.43, 2.57}) {
    for (const double y : {1.43, 2.57}) {
      sim::BoxSolid leg;
      leg.centre_W = {x, y, 0.45};
      leg.half_extents_m = {0.03, 0.03, 0.45};
      shapes.emplace_back(leg);
    }
  }
  // The person is on all fours from the first frame: no height needed to be born.
  TrackerOptions options;
  options.birth_min_height_m = 0.0;
  Tracker tracker(options, VoxelMap(g, states), CollisionWorld(shapes));

  const Vector3d half(0.45, 0.25, 0.3);  // On all fours, along x.
  const double speed = 0.4;
  bool seen_occluded = false;
  std::uint32_t id = 0;
  int frame = 0;
  Vector3d c;
  for (; frame <= 255; ++frame) {
    const double x = std::min(0.5 + speed * frame * kDt, 3.5);  // Then waits at 3.5.
    c = Vector3d(x, 2.0, 0.32);
    SetBlobs(&tracker, {{c, half}}, under_table);
    tracker.Step(StampNs(frame));
    const auto& tracks = tracker.tracks();
    ASSERT_EQ(tracks.size(), 1u) << "frame " << frame;
    if (frame == 0) id = tracks[0].id;
    ASSERT_EQ(tracks[0].id, id) << "frame " << frame;
    const bool hidden = x - half.x() > 1.4 && x + half.x() < 2.6;
    if (hidden) seen_occluded = seen_occluded || tracks[0].occluded;
    if (!hidden && x < 1.0) {
      EXPECT_FALSE(tracks[0].occluded);
    }
  }
  EXPECT_TRUE(seen_occluded);
  EXPECT_EQ(tracker.stats().births, 1u);
  EXPECT_EQ(tracker.stats().deaths, 0u);
  EXPECT_LT((tracker.tracks()[0].centre_W - c).norm(), 0.05);
  EXPECT_FALSE(tracker.tracks()[0].occluded);
}

// A person hides in a pocket no camera sees into; long after, someone else
// appears 3 m away. The hidden track's re-acquisition reach grows with its
// time without support only up to the death timeout (2 m by default): the
// newcomer gets an id of their own, and the hidden person keeps theirs
// (before, the reach grew without bound and the track jumped to the newcomer).
TEST(TrackerTest, AHiddenTrackIsNotHandedToSomeoneFarAway) {
  const VoxelGrid g = CellGrid();
  auto in_pocket = [](const Vector3d& p) { return p.x() < 1.0 && p.y() < 1.0; };
  std::vector<VoxelState> states(g.size(), VoxelState::kFree);
  for (int z = 0; z < g.nz(); ++z) {
    for (int y = 0; y < g.ny(); ++y) {
      for (int x = 0; x < g.nx(); ++x) {
        if (in_pocket(g.Centre(x, y, z))) states[g.Index(x, y, z)] = VoxelState::kOccluded;
      }
    }
  }
  Tracker tracker(TrackerOptions{}, VoxelMap(g, states), CollisionWorld());
  int frame = 0;
  // Walks in from the open cell and stays in the pocket, hidden.
  for (; frame < 180; ++frame) {
    const double x = std::max(2.4 - 1.0 * frame * kDt, 0.5);
    SetBlobs(&tracker, {Person(Vector3d(x, 0.5, 0.9))}, in_pocket);
    tracker.Step(StampNs(frame));
  }
  ASSERT_EQ(tracker.tracks().size(), 1u);
  const std::uint32_t hidden_id = tracker.tracks()[0].id;
  EXPECT_TRUE(tracker.tracks()[0].occluded);
  EXPECT_GT(tracker.tracks()[0].time_since_support_s, 3.0);
  // Someone else appears 3 m away and stands.
  const Vector3d newcomer(3.2, 2.6, 0.9);
  for (int k = 0; k < 30; ++k, ++frame) {
    SetBlobs(&tracker, {Person(Vector3d(0.5, 0.5, 0.9)), Person(newcomer)}, in_pocket);
    tracker.Step(StampNs(frame));
  }
  EXPECT_EQ(tracker.stats().reacquisitions, 0u);
  EXPECT_EQ(tracker.stats().births, 2u);
  ASSERT_EQ(tracker.tracks().size(), 2u);
  const Track* near_newcomer = Nearest(tracker.tracks(), newcomer);
  EXPECT_NE(near_newcomer->id, hidden_id);
  EXPECT_LT((near_newcomer->centre_W - newcomer).norm(), 0.2);
  const Track* near_pocket = Nearest(tracker.tracks(), Vector3d(0.5, 0.5, 0.9));
  EXPECT_EQ(near_pocket->id, hidden_id);
}

// A person standing on a table is tracked at the height of one standing on
// the floor: the table top under the ellipsoid is its floor (scored like the
// space below the cell's floor), not an obstacle that pushes the ellipsoid up.
TEST(TrackerTest, StandingOnATableIsTrackedAtItsHeight) {
  const VoxelGrid g({Vector3d::Zero(), Vector3d(4, 4, 2.8)}, 0.04);
  std::vector<VoxelState> states(g.size(), VoxelState::kFree);
  sim::BoxSolid top;
  top.centre_W = {1.5, 2.0, 0.98};
  top.half_extents_m = {0.7, 0.7, 0.02};
  for (int z = 0; z < g.nz(); ++z) {
    for (int y = 0; y < g.ny(); ++y) {
      for (int x = 0; x < g.nx(); ++x) {
        const Vector3d d = (g.Centre(x, y, z) - top.centre_W).cwiseAbs();
        if ((d - top.half_extents_m).maxCoeff() <= 0.0) {
          states[g.Index(x, y, z)] = VoxelState::kKnown;
        }
      }
    }
  }
  // A body-shaped blob: a box 0.4 x 0.3 x 1.7 m (a visual hull is not an
  // ellipsoid), on the table top (z 1.0) and on the floor beside the table.
  auto body = [&](const Vector3d& feet) {
    std::vector<std::uint32_t> voxels;
    for (int z = 0; z < g.nz(); ++z) {
      for (int y = 0; y < g.ny(); ++y) {
        for (int x = 0; x < g.nx(); ++x) {
          const Vector3d d = g.Centre(x, y, z) - feet;
          if (std::abs(d.x()) <= 0.2 && std::abs(d.y()) <= 0.15 && d.z() >= 0.0 && d.z() <= 1.7) {
            voxels.push_back(g.Index(x, y, z));
          }
        }
      }
    }
    return voxels;
  };
  auto vertical_error = [&](double support_reach_m, const Vector3d& feet) {
    TrackerOptions options;
    options.filter.support_reach_m = support_reach_m;
    std::vector<CollisionShape> shapes;
    shapes.emplace_back(top);
    Tracker tracker(options, VoxelMap(g, states), CollisionWorld(shapes));
    const std::vector<std::uint32_t> voxels = body(feet);
    double sum = 0.0;
    int n = 0;
    for (int frame = 0; frame < 90; ++frame) {
      tracker.voxel_map().SetUnknown(voxels);
      tracker.Step(StampNs(frame));
      EXPECT_EQ(tracker.tracks().size(), 1u) << "frame " << frame;
      if (frame >= 30 && tracker.tracks().size() == 1) {
        sum += tracker.tracks()[0].centre_W.z() - (feet.z() + 0.85);
        ++n;
      }
    }
    return n > 0 ? sum / n : 1e9;
  };
  const double on_floor = vertical_error(0.25, Vector3d(3.2, 2.0, 0.0));
  const double on_table = vertical_error(0.25, Vector3d(1.5, 2.0, 1.0));
  EXPECT_LT(std::abs(on_floor), 0.04);
  EXPECT_LT(std::abs(on_table - on_floor), 0.03);
  // Without the support surface the table top pushes the ellipsoid up.
  EXPECT_GT(vertical_error(0.0, Vector3d(1.5, 2.0, 1.0)), on_table + 0.04);
}

// One person walks on a platform table while another crawls underneath, right
// below them: the two blobs are stacked, split only by the table top. Each
// keeps its own track and id the whole time; neither filter drifts through
// the top to the other level, none dies.
TEST(TrackerTest, OnAndUnderATableKeepTwoTracks) {
  const VoxelGrid g({Vector3d::Zero(), Vector3d(5, 4, 2.8)}, 0.04);
  const Vector3d top_min(1.7, 1.4, 0.95), top_max(3.3, 2.6, 1.0);
  auto below_top = [&](const Vector3d& p) {
    return p.x() >= top_min.x() && p.x() <= top_max.x() && p.y() >= top_min.y() &&
           p.y() <= top_max.y() && p.z() < top_min.z() - 0.02;
  };
  // The middle of the space below the top, which the low cameras cannot see.
  auto hidden = [&](const Vector3d& p) { return below_top(p) && std::abs(p.x() - 2.5) < 0.4; };
  std::vector<VoxelState> states(g.size(), VoxelState::kFree);
  for (int z = 0; z < g.nz(); ++z) {
    for (int y = 0; y < g.ny(); ++y) {
      for (int x = 0; x < g.nx(); ++x) {
        const Vector3d p = g.Centre(x, y, z);
        const bool in_xy = p.x() >= top_min.x() && p.x() <= top_max.x() && p.y() >= top_min.y() &&
                           p.y() <= top_max.y();
        if (in_xy && p.z() >= top_min.z() - 0.02 && p.z() <= top_max.z() + 0.02) {
          states[g.Index(x, y, z)] = VoxelState::kKnown;
        } else if (hidden(p)) {
          states[g.Index(x, y, z)] = VoxelState::kOccluded;
        }
      }
    }
  }
  std::vector<CollisionShape> shapes;
  sim::BoxSolid top;
  top.centre_W = 0.5 * (top_min + top_max);
  top.half_extents_m = 0.5 * (top_max - top_min);
  shapes.emplace_back(top);
  for (const double x : {1.73, 3.27}) {
    for (const double y : {1.43, 2.57}) {
      sim::BoxSolid leg;
      leg.centre_W = {x, y, 0.475};
      leg.half_extents_m = {0.03, 0.03, 0.475};
      shapes.emplace_back(leg);
    }
  }
  // One person is under the table from the first frame: no height needed to be born.
  TrackerOptions options;
  options.birth_min_height_m = 0.0;
  Tracker tracker(options, VoxelMap(g, states), CollisionWorld(shapes));

  const Vector3d standing_half(0.25, 0.2, 0.85), crawling_half(0.45, 0.25, 0.3);
  std::uint32_t id_on = 0, id_under = 0;
  double worst_on = 0.0, worst_under_visible = 0.0;
  for (int frame = 0; frame <= 330; ++frame) {
    // On top: back and forth along x at 0.5 m/s, feet on the top (z = 1.0).
    const double phase = std::fmod(0.5 * frame * kDt, 1.6);
    const double x_on = 2.1 + (phase < 0.8 ? phase : 1.6 - phase);
    const Vector3d on(x_on, 2.0, 1.0 + 0.85);
    // Below: crawls along the middle from x = 0.8 to 4.2 at 0.4 m/s, waits.
    const Vector3d under(std::min(0.8 + 0.4 * frame * kDt, 4.2), 2.0, 0.32);
    SetBlobs(&tracker, {{on, standing_half}, {under, crawling_half}}, hidden);
    tracker.Step(StampNs(frame));
    const auto& tracks = tracker.tracks();
    ASSERT_EQ(tracks.size(), 2u) << "frame " << frame;
    if (frame == 0) {
      id_on = Nearest(tracks, on)->id;
      id_under = Nearest(tracks, under)->id;
      ASSERT_NE(id_on, id_under);
    }
    for (const Track& t : tracks) {
      ASSERT_TRUE(t.id == id_on || t.id == id_under) << "frame " << frame;
      if (t.id == id_on) {
        // Never below the top: that would be the other person's level.
        ASSERT_GT(t.centre_W.z(), 1.3) << "frame " << frame;
        if (frame > 10) worst_on = std::max(worst_on, (t.centre_W - on).norm());
      } else {
        ASSERT_LT(t.centre_W.z(), 0.9) << "frame " << frame;
        ASSERT_LT((t.centre_W - under).norm(), 0.5) << "frame " << frame;
        // Wholly in view again for 0.4 s (0.16 m at 0.4 m/s): the filter has
        // caught up with what the occlusion hid.
        const bool visible = std::abs(under.x() - 2.5) > 0.4 + crawling_half.x() + 0.16;
        if (frame > 10 && visible) {
          worst_under_visible = std::max(worst_under_visible, (t.centre_W - under).norm());
        }
      }
    }
  }
  EXPECT_LT(worst_on, 0.1);
  EXPECT_LT(worst_under_visible, 0.1);
  EXPECT_EQ(tracker.stats().births, 2u);
  EXPECT_EQ(tracker.stats().deaths, 0u);
}

// The daemon's path: static states from cameras and obstacles, UNKNOWN from
// the snapshot's occupied runs.
// The occupied cells of a blob on a 128^3 grid over a 4 m cube, as runs along x.
std::vector<pipeline::GridRun> BlobRuns(const Ellipsoid& blob) {
  return test::RunsInside(7, 4.0, [&](const Vector3d& p) { return blob.Contains(p); });
}

// Births wait for a whole snapshot: a person-sized blob in a cycle with a
// stale camera, with a camera still learning its background, with frames
// captured too far apart (or margins still held from such frames), or from
// an update aborted above the tracking
// voxel starts nothing; the same blob in a whole
// cycle starts a track, which then follows its person through such cycles.
TEST(TrackerTest, BirthsWaitForAWholeCycle) {
  Tracker tracker = OpenCellTracker();
  pipeline::OccupancySnapshot snap;
  snap.bounds = {Vector3d::Zero(), Vector3d(4, 4, 4)};
  snap.depth = 7;
  snap.health.cameras.resize(2);
  for (pipeline::CameraHealth& c : snap.health.cameras) c.state = pipeline::CameraState::kOk;
  const Vector3d velocity(0.0, 0.8, 0.0);
  int frame = 0;
  auto step = [&](auto&& spoil) {
    const Vector3d c = Vector3d(1.5, 1.0, 0.9) + velocity * (frame * kDt);
    snap.occupied = BlobRuns(Person(c));
    snap.complete = true;
    snap.refined_cell_m = 4.0 / 128;
    snap.health.skew_ms = 0.0;
    snap.health.margin_skew_ms = 0.0;
    snap.health.cameras[1].state = pipeline::CameraState::kOk;
    snap.health.cameras[1].learning = false;
    spoil();
    snap.stamp_ns = 1'000'000'000 + StampNs(frame++);
    tracker.Update(snap);
    return c;
  };
  for (int k = 0; k < 10; ++k) {
    step([&] {
      switch (k % 5) {
        case 4:  // Frames of one instant, but margins still held from a late frame.
          snap.health.margin_skew_ms = 33.0;
          break;
        case 0:
          snap.health.cameras[1].state = pipeline::CameraState::kStale;
          break;
        case 2:
          snap.health.cameras[1].learning = true;
          break;
        case 1:
          snap.health.skew_ms = 33.0;
          break;
        default:  // Refined to 6.25 cm cells, enough to track on but not for births.
          snap.complete = false;
          snap.refined_cell_m = 4.0 / 64;
          break;
      }
    });
    ASSERT_TRUE(tracker.tracks().empty()) << "cycle " << k;
  }
  step([] {});
  ASSERT_EQ(tracker.tracks().size(), 1u);
  Vector3d c;
  for (int k = 0; k < 20; ++k) {
    c = step([&] { snap.health.skew_ms = 33.0; });
    ASSERT_EQ(tracker.tracks().size(), 1u) << "cycle " << k;
  }
  EXPECT_LT((tracker.tracks()[0].centre_W - c).norm(), 0.1);
  EXPECT_EQ(tracker.stats().births, 1u);
}

// From an update aborted short of the tracking voxel, a track starts where
// the update finished the octree roots to it (RootsWholeForBirths): the
// person's roots all finished starts a track; one of them not finished, a
// stale camera, a camera whose background model is still learning, or no
// root levels at all starts none.
TEST(TrackerTest, BirthsFromTheRootsAnAbortedUpdateFinished) {
  const Vector3d centre(1.5, 1.0, 0.9);
  const Ellipsoid person = Person(centre);
  // Roots of the 4 m cube are 0.5 m; those the blob (and a voxel around it) touches.
  const common::Box3 bounds{Vector3d::Zero(), Vector3d(4, 4, 4)};
  auto touches_person = [&](int r) {
    const Vector3d lo = Vector3d(r % 8, (r / 8) % 8, r / 64) * 0.5;
    const Vector3d hi = lo + Vector3d::Constant(0.5);
    const Vector3d margin = person.half_axes_m + Vector3d::Constant(0.1);
    return ((lo.array() <= (centre + margin).array()) && (hi.array() >= (centre - margin).array()))
        .all();
  };
  const int centre_root = 3 + 8 * 2 + 64 * 1;  // (1.5, 1.0, 0.9) lies in root (3, 2, 1).
  ASSERT_TRUE(touches_person(centre_root));
  enum class Case { kAllFinished, kOneUnfinished, kStaleCamera, kLearningCamera, kNoLevels };
  for (const Case which : {Case::kAllFinished, Case::kOneUnfinished, Case::kStaleCamera,
                           Case::kLearningCamera, Case::kNoLevels}) {
    SCOPED_TRACE(static_cast<int>(which));
    Tracker tracker = OpenCellTracker();
    pipeline::OccupancySnapshot snap;
    snap.bounds = bounds;
    snap.depth = 7;
    snap.health.cameras.resize(2);
    for (pipeline::CameraHealth& c : snap.health.cameras) c.state = pipeline::CameraState::kOk;
    if (which == Case::kStaleCamera) snap.health.cameras[1].state = pipeline::CameraState::kStale;
    if (which == Case::kLearningCamera) snap.health.cameras[1].learning = true;
    snap.complete = false;
    snap.refined_cell_m = 4.0 / 64;  // Level 6: 6.25 cm, coarser than the voxel.
    if (which != Case::kNoLevels) {
      snap.root_levels.assign(512, 6);
      for (int r = 0; r < 512; ++r) {
        if (touches_person(r)) snap.root_levels[static_cast<std::size_t>(r)] = 7;
      }
      if (which == Case::kOneUnfinished) snap.root_levels[centre_root] = 6;
    }
    snap.occupied = BlobRuns(person);
    for (int frame = 0; frame < 5; ++frame) {
      snap.stamp_ns = 1'000'000'000 + StampNs(frame);
      tracker.Update(snap);
    }
    const bool expected = which == Case::kAllFinished;
    EXPECT_EQ(tracker.tracks().size(), expected ? 1u : 0u);
    EXPECT_EQ(tracker.stats().births_by_root, expected ? 1u : 0u);
    EXPECT_EQ(tracker.stats().cycles_with_births_by_root,
              which == Case::kAllFinished || which == Case::kOneUnfinished ? 5u : 0u);
    if (expected) {
      EXPECT_LT((tracker.tracks()[0].centre_W - centre).norm(), 0.1);
    }
  }
}

TEST(TrackerTest, TracksFromSnapshots) {
  StaticScene scene;
  scene.cameras.push_back(scene::LookAtCamera({2, 2.01, 3.5}, {2, 2, 0}, 640, 480, 300));
  // Births need two cameras on a voxel (TrackerOptions::birth_min_views).
  scene.cameras.push_back(scene::LookAtCamera({-0.3, 2.0, 2.2}, {2, 2, 0.8}, 640, 480, 300));
  sim::BoxSolid rack;
  rack.centre_W = {3.5, 0.5, 1.0};
  rack.half_extents_m = {0.3, 0.3, 1.0};
  scene.solids.emplace_back(rack);
  const common::Box3 bounds{Vector3d::Zero(), Vector3d(4, 4, 2.2)};
  Tracker tracker(TrackerOptions{}, bounds, scene);
  EXPECT_EQ(tracker.collision_world().shapes().size(), 1u);

  pipeline::OccupancySnapshot snap;
  snap.bounds = {Vector3d::Zero(), Vector3d(4, 4, 4)};
  snap.depth = 7;
  const Vector3d velocity(0.0, 0.8, 0.0);
  Vector3d c;
  for (int frame = 0; frame < 45; ++frame) {
    c = Vector3d(1.5, 1.0, 0.9) + velocity * (frame * kDt);
    snap.occupied = BlobRuns(Person(c));
    snap.stamp_ns = 1'000'000'000 + StampNs(frame);
    tracker.Update(snap);
  }
  ASSERT_EQ(tracker.tracks().size(), 1u);
  const Track& t = tracker.tracks()[0];
  EXPECT_LT((t.centre_W - c).norm(), 0.05);
  EXPECT_LT((t.velocity_W_mps - velocity).norm(), 0.3);
  EXPECT_NEAR(t.age_s, 44 * kDt, 1e-6);
  EXPECT_FALSE(t.occluded);
}

}  // namespace
}  // namespace hg::tracking
