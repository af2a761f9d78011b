#include "sim/body.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

namespace hg::sim {
namespace {

using Eigen::Vector3d;

constexpr double kPi = 3.14159265358979323846;
constexpr double kFrameS = 1.0 / 30.0;

const BodyCapsule& Part(const BodyState& s, BodyPart part) {
  return s.parts[static_cast<int>(part)];
}

double LowestZ(const BodyCapsule& c) { return std::min(c.a_W.z(), c.b_W.z()) - c.radius_m; }
double HighestZ(const BodyCapsule& c) { return std::max(c.a_W.z(), c.b_W.z()) + c.radius_m; }

double FeetLowestZ(const BodyState& s) {
  return std::min(LowestZ(Part(s, BodyPart::kFootLeft)), LowestZ(Part(s, BodyPart::kFootRight)));
}

double BodyTop(const BodyState& s) {
  double top = -std::numeric_limits<double>::infinity();
  for (const BodyCapsule& c : s.parts) {
    top = std::max(top, HighestZ(c));
  }
  return top;
}

double BodyBottom(const BodyState& s) {
  double bottom = std::numeric_limits<double>::infinity();
  for (const BodyCapsule& c : s.parts) {
    bottom = std::min(bottom, LowestZ(c));
  }
  return bottom;
}

/// Root position (midpoint of the hip joints, where the thighs start) on the
/// ground plane. Standing, walking and crawling it lies over the feet position.
Eigen::Vector2d RootXY(const BodyState& s) {
  return (0.5 * (Part(s, BodyPart::kThighLeft).a_W + Part(s, BodyPart::kThighRight).a_W)).head<2>();
}

/// Distance between segments p0-p1 and q0-q1 (closest points by clamped
/// parameters, refined once per side; exact for non-parallel segments and
/// an upper bound otherwise, which is what the connectivity test needs).
double SegmentDistance(const Vector3d& p0, const Vector3d& p1, const Vector3d& q0,
                       const Vector3d& q1) {
  const Vector3d d1 = p1 - p0;
  const Vector3d d2 = q1 - q0;
  const Vector3d r = p0 - q0;
  const double a = d1.squaredNorm();
  const double e = d2.squaredNorm();
  const double f = d2.dot(r);
  double s = 0.0;
  double t = 0.0;
  if (a <= 1e-18 && e <= 1e-18) {
    return r.norm();
  }
  if (a <= 1e-18) {
    t = std::clamp(f / e, 0.0, 1.0);
  } else {
    const double c = d1.dot(r);
    if (e <= 1e-18) {
      s = std::clamp(-c / a, 0.0, 1.0);
    } else {
      const double b = d1.dot(d2);
      const double denom = a * e - b * b;
      s = denom > 1e-18 ? std::clamp((b * f - c * e) / denom, 0.0, 1.0) : 0.0;
      t = (b * s + f) / e;
      if (t < 0.0) {
        t = 0.0;
        s = std::clamp(-c / a, 0.0, 1.0);
      } else if (t > 1.0) {
        t = 1.0;
        s = std::clamp((b - c) / a, 0.0, 1.0);
      }
    }
  }
  return ((p0 + s * d1) - (q0 + t * d2)).norm();
}

/// True when the two capsules overlap (no gap at the joint).
bool Overlap(const BodyCapsule& x, const BodyCapsule& y) {
  return SegmentDistance(x.a_W, x.b_W, y.a_W, y.b_W) < x.radius_m + y.radius_m;
}

const std::vector<std::pair<BodyPart, BodyPart>>& Joints() {
  static const std::vector<std::pair<BodyPart, BodyPart>> kJoints = {
      {BodyPart::kHead, BodyPart::kTorso},
      {BodyPart::kTorso, BodyPart::kPelvis},
      {BodyPart::kTorso, BodyPart::kUpperArmLeft},
      {BodyPart::kTorso, BodyPart::kUpperArmRight},
      {BodyPart::kUpperArmLeft, BodyPart::kForearmLeft},
      {BodyPart::kUpperArmRight, BodyPart::kForearmRight},
      {BodyPart::kPelvis, BodyPart::kThighLeft},
      {BodyPart::kPelvis, BodyPart::kThighRight},
      {BodyPart::kThighLeft, BodyPart::kShinLeft},
      {BodyPart::kThighRight, BodyPart::kShinRight},
      {BodyPart::kShinLeft, BodyPart::kFootLeft},
      {BodyPart::kShinRight, BodyPart::kFootRight},
  };
  return kJoints;
}

/// Checks finiteness, radii, part indexing and joints of one state.
void ExpectWellFormed(const BodyState& s, const std::string& where) {
  for (int k = 0; k < kNumBodyParts; ++k) {
    const BodyCapsule& c = s.parts[k];
    EXPECT_EQ(static_cast<int>(c.part), k) << where;
    EXPECT_TRUE(c.a_W.allFinite() && c.b_W.allFinite()) << where << " part " << k;
    EXPECT_GT(c.radius_m, 0.0) << where;
  }
  for (const auto& [x, y] : Joints()) {
    EXPECT_TRUE(Overlap(Part(s, x), Part(s, y)))
        << where << ": gap between " << BodyPartName(x) << " and " << BodyPartName(y);
  }
  // Elbows and knees are shared points.
  EXPECT_LT((Part(s, BodyPart::kUpperArmLeft).b_W - Part(s, BodyPart::kForearmLeft).a_W).norm(),
            1e-9)
      << where;
  EXPECT_LT((Part(s, BodyPart::kThighRight).b_W - Part(s, BodyPart::kShinRight).a_W).norm(), 1e-9)
      << where;
  EXPECT_TRUE(s.centre_W.allFinite() && s.velocity_W.allFinite() && std::isfinite(s.heading_rad))
      << where;
  EXPECT_TRUE((s.ellipsoid_half_axes_m.array() > 0.0).all()) << where;
}

Action MakeAction(ActionKind kind, double start_s, double duration_s) {
  Action a;
  a.kind = kind;
  a.start_s = start_s;
  a.duration_s = duration_s;
  return a;
}

/// A person who does everything: stand, walk (with turns), crouch, crawl,
/// reach, walk again, stand turning round.
Person Busybody() {
  Person p;
  p.name = "busy";
  p.height_m = 1.75;
  p.start_W = Vector3d(0.5, -0.5, 0.0);
  p.start_heading_rad = 0.3;
  p.actions.push_back(MakeAction(ActionKind::kStand, 0.5, 1.0));
  Action walk = MakeAction(ActionKind::kWalk, 1.5, 5.0);
  walk.path_W = {Vector3d(0.5, -0.5, 0.0), Vector3d(2.5, -0.5, 0.0), Vector3d(2.5, 1.5, 0.0),
                 Vector3d(1.0, 2.0, 0.0)};
  walk.speed_mps = 1.2;
  p.actions.push_back(walk);
  p.actions.push_back(MakeAction(ActionKind::kCrouch, 7.0, 2.0));
  Action crawl = MakeAction(ActionKind::kCrawl, 9.0, 4.0);
  crawl.path_W = {Vector3d(0.0, 2.0, 0.0), Vector3d(0.0, 1.0, 0.0)};
  crawl.speed_mps = 0.4;
  p.actions.push_back(crawl);
  Action reach = MakeAction(ActionKind::kReach, 14.0, 2.0);
  reach.target_W = Vector3d(0.6, 1.2, 1.1);
  p.actions.push_back(reach);
  Action walk2 = MakeAction(ActionKind::kWalk, 16.0, 3.0);
  walk2.path_W = {Vector3d(-1.0, 1.0, 0.0)};
  walk2.speed_mps = 0.8;
  p.actions.push_back(walk2);
  Action turn = MakeAction(ActionKind::kStand, 19.5, 2.0);
  turn.heading_rad = 0.0;
  p.actions.push_back(turn);
  Action reach_left = MakeAction(ActionKind::kReach, 22.0, 1.5);
  reach_left.left_hand = true;
  reach_left.target_W = Vector3d(-0.7, 1.2, 1.6);
  p.actions.push_back(reach_left);
  return p;
}

TEST(BodyNamesTest, PartNamesRoundTrip) {
  const char* const kExpected[kNumBodyParts] = {"head",           "torso",        "pelvis",
                                                "upper_arm_left", "forearm_left", "upper_arm_right",
                                                "forearm_right",  "thigh_left",   "shin_left",
                                                "thigh_right",    "shin_right",   "foot_left",
                                                "foot_right"};
  for (int k = 0; k < kNumBodyParts; ++k) {
    const BodyPart part = static_cast<BodyPart>(k);
    EXPECT_STREQ(BodyPartName(part), kExpected[k]);
    BodyPart back = BodyPart::kHead;
    ASSERT_TRUE(BodyPartFromName(kExpected[k], &back));
    EXPECT_EQ(back, part);
  }
  BodyPart unchanged = BodyPart::kTorso;
  EXPECT_FALSE(BodyPartFromName("tail", &unchanged));
  EXPECT_FALSE(BodyPartFromName("Head", &unchanged));
  EXPECT_FALSE(BodyPartFromName("", &unchanged));
  EXPECT_EQ(unchanged, BodyPart::kTorso);
}

TEST(BodyNamesTest, ActionNames) {
  EXPECT_STREQ(ActionName(ActionKind::kStand), "stand");
  EXPECT_STREQ(ActionName(ActionKind::kWalk), "walk");
  EXPECT_STREQ(ActionName(ActionKind::kCrouch), "crouch");
  EXPECT_STREQ(ActionName(ActionKind::kCrawl), "crawl");
  EXPECT_STREQ(ActionName(ActionKind::kReach), "reach");
}

TEST(BodyColourTest, ClothesAndSkin) {
  Person p;
  p.shirt = Rgb(1.0F, 0.0F, 0.0F);
  p.trousers = Rgb(0.0F, 1.0F, 0.0F);
  p.skin = Rgb(0.0F, 0.0F, 1.0F);
  for (BodyPart part : {BodyPart::kTorso, BodyPart::kUpperArmLeft, BodyPart::kUpperArmRight}) {
    EXPECT_EQ(PartColour(p, part), p.shirt) << BodyPartName(part);
  }
  for (BodyPart part : {BodyPart::kPelvis, BodyPart::kThighLeft, BodyPart::kThighRight,
                        BodyPart::kShinLeft, BodyPart::kShinRight}) {
    EXPECT_EQ(PartColour(p, part), p.trousers) << BodyPartName(part);
  }
  for (BodyPart part : {BodyPart::kHead, BodyPart::kForearmLeft, BodyPart::kForearmRight}) {
    EXPECT_EQ(PartColour(p, part), p.skin) << BodyPartName(part);
  }
  for (BodyPart part : {BodyPart::kFootLeft, BodyPart::kFootRight}) {
    const Rgb shoe = PartColour(p, part);
    EXPECT_NE(shoe, p.shirt);
    EXPECT_NE(shoe, p.trousers);
    EXPECT_NE(shoe, p.skin);
    EXPECT_LT(shoe.maxCoeff(), 0.4F);     // Dark.
    EXPECT_FLOAT_EQ(shoe.x(), shoe.z());  // Grey.
  }
}

TEST(BodyTest, StandingBodyHasHumanProportions) {
  for (double height : {1.0, 1.6, 1.75, 2.2}) {
    Person p;
    p.height_m = height;
    p.start_W = Vector3d(1.0, 2.0, 0.0);
    p.start_heading_rad = 1.0;
    const BodyState s = EvaluatePerson(p, 0.0);
    const std::string where = "H=" + std::to_string(height);
    ExpectWellFormed(s, where);
    EXPECT_NEAR(BodyTop(s), height, 0.01 * height) << where;
    EXPECT_NEAR(FeetLowestZ(s), 0.0, 1e-9) << where;
    EXPECT_GE(BodyBottom(s), -1e-9) << where;
    EXPECT_EQ(s.action, ActionKind::kStand);
    EXPECT_NEAR(s.heading_rad, 1.0, 1e-12);
    EXPECT_NEAR((RootXY(s) - Eigen::Vector2d(1.0, 2.0)).norm(), 0.0, 1e-9) << where;
    EXPECT_LT(s.velocity_W.norm(), 1e-9);
    // Arms hang down beside the torso, a little away from it.
    const double s_h = height / 1.75;
    const BodyCapsule& hand = Part(s, BodyPart::kForearmLeft);
    EXPECT_GT(hand.a_W.z(), hand.b_W.z()) << where;
    EXPECT_NEAR(Part(s, BodyPart::kHead).radius_m, 0.11 * s_h, 1e-12);
    EXPECT_NEAR(Part(s, BodyPart::kThighRight).radius_m, 0.075 * s_h, 1e-12);
    // Upper arm length follows the height.
    const BodyCapsule& upper = Part(s, BodyPart::kUpperArmRight);
    EXPECT_NEAR((upper.b_W - upper.a_W).norm(), 0.186 * height, 1e-9);
    // Shoulder height ~0.82 H, fingertips ~0.38 H.
    EXPECT_NEAR(upper.a_W.z(), 0.818 * height, 0.02 * height);
    EXPECT_NEAR(LowestZ(hand), 0.38 * height, 0.04 * height);
    // Facing +heading: the toes point along it.
    const BodyCapsule& foot = Part(s, BodyPart::kFootLeft);
    const Vector3d toe = (foot.b_W - foot.a_W).normalized();
    EXPECT_NEAR(std::atan2(toe.y(), toe.x()), 1.0, 1e-9) << where;
  }
}

TEST(BodyTest, EveryActionGivesAWellFormedBodyOnTheGround) {
  const Person p = Busybody();
  for (double t = -1.0; t < 25.0; t += 0.05) {
    const BodyState s = EvaluatePerson(p, t);
    const std::string where = "t=" + std::to_string(t);
    ExpectWellFormed(s, where);
    // Arms may only dip into the floor in a blend between supported and free
    // arms, and then by at most a few centimetres; the rest never does.
    EXPECT_GE(BodyBottom(s), -0.051) << where;
    for (const BodyCapsule& c : s.parts) {
      if (c.part != BodyPart::kForearmLeft && c.part != BodyPart::kForearmRight &&
          c.part != BodyPart::kUpperArmLeft && c.part != BodyPart::kUpperArmRight) {
        EXPECT_GE(LowestZ(c), -1e-9) << where << " " << BodyPartName(c.part);
      }
    }
  }
}

TEST(BodyTest, ActionInProgressIsReported) {
  const Person p = Busybody();
  EXPECT_EQ(EvaluatePerson(p, 0.2).action, ActionKind::kStand);
  EXPECT_EQ(EvaluatePerson(p, 2.0).action, ActionKind::kWalk);
  EXPECT_EQ(EvaluatePerson(p, 6.8).action, ActionKind::kStand);  // Gap after the walk.
  EXPECT_EQ(EvaluatePerson(p, 8.0).action, ActionKind::kCrouch);
  EXPECT_EQ(EvaluatePerson(p, 10.0).action, ActionKind::kCrawl);
  EXPECT_EQ(EvaluatePerson(p, 13.5).action, ActionKind::kStand);  // Gap: still on all fours.
  EXPECT_EQ(EvaluatePerson(p, 15.0).action, ActionKind::kReach);
  EXPECT_EQ(EvaluatePerson(p, 30.0).action, ActionKind::kStand);
}

TEST(BodyTest, FeetStayOnTheGroundWhileStandingAndWalking) {
  const Person p = Busybody();
  int samples = 0;
  // Standing (before and during the first stand) and walking (all of it,
  // including setting off, the turns, stopping and the settle).
  for (double t = -0.5; t < 7.0; t += 0.01) {
    const BodyState s = EvaluatePerson(p, t);
    const double low = FeetLowestZ(s);
    EXPECT_GE(low, -1e-3) << "t=" << t;
    EXPECT_LE(low, 0.01) << "t=" << t;
    ++samples;
  }
  for (double t = 16.0; t < 22.0; t += 0.01) {
    const double low = FeetLowestZ(EvaluatePerson(p, t));
    EXPECT_NEAR(low, 0.0, 1e-3) << "t=" << t;
  }
  EXPECT_GT(samples, 700);
}

TEST(BodyTest, StandingTopIsTheHeightAndWalkingBobsSlightly) {
  const Person p = Busybody();
  EXPECT_NEAR(BodyTop(EvaluatePerson(p, 1.4)), 1.75, 0.01);
  double lo = 10.0;
  double hi = 0.0;
  for (double t = 2.5; t < 3.5; t += 0.01) {
    const double top = BodyTop(EvaluatePerson(p, t));
    lo = std::min(lo, top);
    hi = std::max(hi, top);
  }
  EXPECT_GT(hi - lo, 0.01);  // The pelvis bobs ...
  EXPECT_LT(hi - lo, 0.10);  // ... but only a little.
  EXPECT_LT(hi, 1.75 + 1e-6);
  EXPECT_GT(lo, 1.6);
}

TEST(BodyTest, CrouchIsLowWithFeetOnTheGround) {
  for (double height : {1.2, 1.75, 2.1}) {
    Person p;
    p.height_m = height;
    p.start_W = Vector3d(0.0, 0.0, 0.3);
    p.actions.push_back(MakeAction(ActionKind::kCrouch, 1.0, 3.0));
    const BodyState before = EvaluatePerson(p, 0.9);
    for (double t = 2.1; t < 6.0; t += 0.1) {
      const BodyState s = EvaluatePerson(p, t);
      const std::string where = "H=" + std::to_string(height) + " t=" + std::to_string(t);
      ExpectWellFormed(s, where);
      const double top = BodyTop(s) - 0.3;
      EXPECT_LT(top, 0.7 * height) << where;
      EXPECT_GT(top, 0.5 * height) << where;
      EXPECT_NEAR(FeetLowestZ(s), 0.3, 1e-9) << where;
      EXPECT_GE(BodyBottom(s), 0.3 - 1e-9) << where;
      // The feet stay where they were standing.
      for (BodyPart foot : {BodyPart::kFootLeft, BodyPart::kFootRight}) {
        EXPECT_LT((Part(s, foot).a_W - Part(before, foot).a_W).norm(), 1e-6) << where;
      }
      // Knees bent by 110..130 degrees.
      const BodyCapsule& thigh = Part(s, BodyPart::kThighLeft);
      const BodyCapsule& shin = Part(s, BodyPart::kShinLeft);
      const double bend =
          std::acos((thigh.b_W - thigh.a_W).normalized().dot((shin.b_W - shin.a_W).normalized()));
      EXPECT_GT(bend, 110.0 * kPi / 180.0) << where;
      EXPECT_LT(bend, 130.0 * kPi / 180.0) << where;
    }
  }
}

TEST(BodyTest, CrawlerFitsUnderATable) {
  Person p;
  p.height_m = 1.75;
  Action crawl = MakeAction(ActionKind::kCrawl, 0.0, 8.0);
  crawl.path_W = {Vector3d(3.0, 0.0, 0.0)};
  crawl.speed_mps = 0.5;
  p.actions.push_back(crawl);
  double min_support = 1.0;
  for (double t = 1.0; t < 10.0; t += 0.02) {
    const BodyState s = EvaluatePerson(p, t);
    const std::string where = "t=" + std::to_string(t);
    ExpectWellFormed(s, where);
    EXPECT_LT(BodyTop(s), 0.70) << where;
    EXPECT_GE(BodyBottom(s), -1e-9) << where;
    const BodyCapsule& torso = Part(s, BodyPart::kTorso);
    EXPECT_LT(std::abs(torso.a_W.z() - torso.b_W.z()), 0.05) << where;  // Horizontal.
    EXPECT_GT(torso.a_W.z(), 0.4) << where;
    EXPECT_LT(torso.a_W.z(), 0.52) << where;
    // Thighs about vertical, shins flat on the floor.
    for (BodyPart thigh : {BodyPart::kThighLeft, BodyPart::kThighRight}) {
      const Vector3d dir = (Part(s, thigh).b_W - Part(s, thigh).a_W).normalized();
      EXPECT_LT(dir.z(), -0.9) << where;
    }
    for (BodyPart shin : {BodyPart::kShinLeft, BodyPart::kShinRight}) {
      EXPECT_LT(LowestZ(Part(s, shin)), 0.05) << where;  // The swinging one lifts a little.
    }
    EXPECT_LT(
        std::min(LowestZ(Part(s, BodyPart::kShinLeft)), LowestZ(Part(s, BodyPart::kShinRight))),
        0.005)
        << where;
    // The lowest hand touches the floor when the arms bear weight.
    min_support = std::min(min_support, std::min(LowestZ(Part(s, BodyPart::kForearmLeft)),
                                                 LowestZ(Part(s, BodyPart::kForearmRight))));
  }
  EXPECT_NEAR(min_support, 0.0, 1e-6);
  // Limbs move with distance: the left knee is not where it was half a cycle on.
  const double knee_early = Part(EvaluatePerson(p, 2.0), BodyPart::kThighLeft).b_W.x() -
                            RootXY(EvaluatePerson(p, 2.0)).x();
  const double knee_later = Part(EvaluatePerson(p, 2.6), BodyPart::kThighLeft).b_W.x() -
                            RootXY(EvaluatePerson(p, 2.6)).x();
  EXPECT_GT(std::abs(knee_early - knee_later), 0.05);
  // After the crawl the person stays on all fours where the path ended.
  const BodyState rest = EvaluatePerson(p, 20.0);
  EXPECT_LT(BodyTop(rest), 0.70);
  EXPECT_NEAR(RootXY(rest).x(), 3.0, 1e-9);
  EXPECT_EQ(rest.action, ActionKind::kStand);
  EXPECT_EQ(EvaluatePerson(p, 3.0).action, ActionKind::kCrawl);
}

TEST(BodyTest, WalkerFollowsThePathAtSpeed) {
  Person p;
  p.start_W = Vector3d(0.0, 0.0, 0.0);
  Action walk = MakeAction(ActionKind::kWalk, 1.0, 10.0);
  // Includes a waypoint equal to the start.
  walk.path_W = {Vector3d(0.0, 0.0, 0.0), Vector3d(4.0, 0.0, 0.0), Vector3d(4.0, 3.0, 0.0)};
  walk.speed_mps = 1.4;
  p.actions.push_back(walk);
  const double arrive_s = 1.0 + 7.0 / 1.4;

  // Straight stretch: pelvis moves at the speed, along +x, facing +x.
  const BodyState a = EvaluatePerson(p, 2.0);
  const BodyState b = EvaluatePerson(p, 3.0);
  EXPECT_NEAR((RootXY(b) - RootXY(a)).norm(), 1.4, 1e-6);
  EXPECT_NEAR(RootXY(a).y(), 0.0, 1e-9);
  EXPECT_NEAR(RootXY(a).x(), 1.4, 1e-9);
  EXPECT_NEAR(a.heading_rad, 0.0, 1e-9);
  EXPECT_NEAR((a.velocity_W - Vector3d(1.4, 0.0, 0.0)).norm(), 0.0, 1e-6);
  EXPECT_EQ(a.action, ActionKind::kWalk);

  // Second leg: along +y.
  const BodyState c = EvaluatePerson(p, 1.0 + 5.5 / 1.4);
  EXPECT_NEAR((RootXY(c) - Eigen::Vector2d(4.0, 1.5)).norm(), 0.0, 1e-6);
  EXPECT_NEAR(c.heading_rad, kPi / 2.0, 1e-9);
  EXPECT_NEAR((c.velocity_W - Vector3d(0.0, 1.4, 0.0)).norm(), 0.0, 1e-6);

  // Turning at the corner is gradual.
  const double corner_s = 1.0 + 4.0 / 1.4;
  const double h = EvaluatePerson(p, corner_s).heading_rad;
  EXPECT_GT(h, 0.1);
  EXPECT_LT(h, kPi / 2.0 - 0.1);

  // After arriving: at the last waypoint, standing still.
  for (double t : {arrive_s + 0.01, arrive_s + 1.0, 11.5, 30.0}) {
    const BodyState s = EvaluatePerson(p, t);
    EXPECT_NEAR((RootXY(s) - Eigen::Vector2d(4.0, 3.0)).norm(), 0.0, 1e-9) << t;
    EXPECT_LT(s.velocity_W.norm(), 1e-9) << t;
  }
  const BodyState settled = EvaluatePerson(p, arrive_s + 1.0);
  EXPECT_NEAR(BodyTop(settled), 1.75, 0.01);
  EXPECT_NEAR(settled.heading_rad, kPi / 2.0, 1e-9);
  EXPECT_EQ(settled.action, ActionKind::kWalk);  // Still within the action's time.
  EXPECT_EQ(EvaluatePerson(p, 11.5).action, ActionKind::kStand);
}

// Like demo_cell's alice: walking at 1.2 m/s from t = 0. The velocity at
// t = 0 is the walking speed, not half of it (nothing before the script).
TEST(BodyTest, WalkerFromTheStartReportsItsSpeedAtTimeZero) {
  Person p;
  p.height_m = 1.72;
  p.start_W = Vector3d(0.8, 0.9, 0.0);
  Action walk = MakeAction(ActionKind::kWalk, 0.0, 10.0);
  walk.path_W = {Vector3d(2.0, 0.9, 0.0), Vector3d(2.0, 2.6, 0.0)};
  walk.speed_mps = 1.2;
  p.actions.push_back(walk);
  for (double t : {0.0, 0.5 * kFrameS, kFrameS}) {
    const BodyState s = EvaluatePerson(p, t);
    EXPECT_NEAR(s.velocity_W.norm(), 1.2, 0.05) << t;
    EXPECT_GT(s.velocity_W.x(), 1.15) << t;
  }
}

TEST(BodyTest, WalkCutShortStopsOnThePath) {
  Person p;
  Action walk = MakeAction(ActionKind::kWalk, 0.0, 2.0);
  walk.path_W = {Vector3d(10.0, 0.0, 0.0)};
  walk.speed_mps = 1.0;
  p.actions.push_back(walk);
  const BodyState s = EvaluatePerson(p, 5.0);
  EXPECT_NEAR((RootXY(s) - Eigen::Vector2d(2.0, 0.0)).norm(), 0.0, 1e-9);
  EXPECT_NEAR(BodyTop(s), 1.75, 0.01);
}

TEST(BodyTest, PlantedFeetDoNotSkate) {
  for (double speed : {0.6, 1.2, 1.8}) {
    Person p;
    Action walk = MakeAction(ActionKind::kWalk, 0.0, 20.0);
    walk.path_W = {Vector3d(30.0, 0.0, 0.0)};
    walk.speed_mps = speed;
    p.actions.push_back(walk);
    const double dt = 1.0 / 240.0;
    double slide = 0.0;
    double contact_time = 0.0;
    for (double t = 1.0; t < 7.0; t += dt) {
      const BodyState s0 = EvaluatePerson(p, t);
      const BodyState s1 = EvaluatePerson(p, t + dt);
      for (BodyPart foot : {BodyPart::kFootLeft, BodyPart::kFootRight}) {
        if (LowestZ(Part(s0, foot)) < 1e-3 && LowestZ(Part(s1, foot)) < 1e-3) {
          slide += (Part(s1, foot).a_W - Part(s0, foot).a_W).norm();
          contact_time += dt;
        }
      }
    }
    // About one foot on the floor at any time.
    EXPECT_GT(contact_time, 5.5) << speed;
    EXPECT_LT(contact_time, 6.5) << speed;
    EXPECT_LT(slide / contact_time, 0.02 * speed) << speed;  // Mean sliding speed.
  }
}

TEST(BodyTest, WalkOntoRaisedGroundStandsOnIt) {
  Person p;
  Action walk = MakeAction(ActionKind::kWalk, 0.5, 6.0);
  walk.path_W = {Vector3d(1.0, 0.0, 0.0), Vector3d(2.0, 0.0, 0.75), Vector3d(3.0, 0.0, 0.75)};
  walk.speed_mps = 1.0;
  p.actions.push_back(walk);
  p.actions.push_back(MakeAction(ActionKind::kCrouch, 7.0, 2.0));
  const BodyState up = EvaluatePerson(p, 6.8);
  EXPECT_NEAR(FeetLowestZ(up), 0.75, 1e-9);
  EXPECT_NEAR(BodyTop(up), 0.75 + 1.75, 0.01);
  const BodyState low = EvaluatePerson(p, 8.5);
  EXPECT_NEAR(FeetLowestZ(low), 0.75, 1e-9);
  EXPECT_GE(BodyBottom(low), 0.75 - 1e-9);
  // Mid-ramp the feet follow the interpolated ground.
  const double ramp_s = 0.5 + (1.0 + 0.5 * std::hypot(1.0, 0.75)) / 1.0;
  EXPECT_NEAR(FeetLowestZ(EvaluatePerson(p, ramp_s)), 0.375, 1e-6);

  Person raised;
  raised.start_W = Vector3d(0.0, 0.0, 0.75);
  EXPECT_NEAR(FeetLowestZ(EvaluatePerson(raised, 0.0)), 0.75, 1e-9);
}

TEST(BodyTest, ReachPutsTheHandOnReachableTargets) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  int reached = 0;
  for (int trial = 0; trial < 60; ++trial) {
    Person p;
    p.start_W = Vector3d(unit(rng), unit(rng), 0.0);
    p.start_heading_rad = kPi * unit(rng);
    Action reach = MakeAction(ActionKind::kReach, 0.5, 3.0);
    reach.left_hand = trial % 2 == 0;
    // Targets around chest height, 0.3..0.9 m away in any direction.
    const double angle = kPi * unit(rng);
    const double dist = 0.6 + 0.3 * unit(rng);
    reach.target_W =
        p.start_W + Vector3d(dist * std::cos(angle), dist * std::sin(angle), 1.3 + 0.4 * unit(rng));
    p.actions.push_back(reach);
    const BodyState s = EvaluatePerson(p, 3.0);
    ExpectWellFormed(s, "trial " + std::to_string(trial));
    EXPECT_NEAR(FeetLowestZ(s), 0.0, 1e-9);
    EXPECT_EQ(s.action, ActionKind::kReach);
    const BodyPart upper_part =
        reach.left_hand ? BodyPart::kUpperArmLeft : BodyPart::kUpperArmRight;
    const BodyPart fore_part = reach.left_hand ? BodyPart::kForearmLeft : BodyPart::kForearmRight;
    const Vector3d shoulder = Part(s, upper_part).a_W;
    const Vector3d hand = Part(s, fore_part).b_W;
    const double arm = (Part(s, upper_part).b_W - shoulder).norm() +
                       (Part(s, fore_part).b_W - Part(s, fore_part).a_W).norm();
    const double to_target = (reach.target_W - shoulder).norm();
    if (to_target <= arm) {
      EXPECT_LT((hand - reach.target_W).norm(), 0.05) << "trial " << trial;
      ++reached;
    } else {
      // Out of reach: the straight arm points at the target.
      EXPECT_NEAR((hand - shoulder).norm(), arm, 1e-6) << "trial " << trial;
      EXPECT_GT((hand - shoulder).normalized().dot((reach.target_W - shoulder).normalized()), 0.999)
          << "trial " << trial;
    }
    // The person turned towards the target.
    const Vector3d to = reach.target_W - p.start_W;
    EXPECT_NEAR(std::remainder(s.heading_rad - std::atan2(to.y(), to.x()), 2.0 * kPi), 0.0, 1e-9);
    // The other arm still hangs.
    const BodyPart other = reach.left_hand ? BodyPart::kForearmRight : BodyPart::kForearmLeft;
    EXPECT_LT(Part(s, other).b_W.z(), 0.8);
  }
  EXPECT_GT(reached, 30);
}

TEST(BodyTest, StandAndCrouchTurnToTheirHeading) {
  Person p;
  p.start_heading_rad = 0.0;
  Action stand = MakeAction(ActionKind::kStand, 1.0, 2.0);
  stand.heading_rad = 3.0;
  p.actions.push_back(stand);
  Action crouch = MakeAction(ActionKind::kCrouch, 4.0, 2.0);
  crouch.heading_rad = -2.0;
  p.actions.push_back(crouch);
  p.actions.push_back(MakeAction(ActionKind::kStand, 7.0, 1.0));  // NaN heading: keeps it.
  EXPECT_NEAR(EvaluatePerson(p, 0.9).heading_rad, 0.0, 1e-12);
  const double mid = EvaluatePerson(p, 1.2).heading_rad;
  EXPECT_GT(mid, 0.0);
  EXPECT_LT(mid, 3.0);
  EXPECT_NEAR(EvaluatePerson(p, 3.5).heading_rad, 3.0, 1e-12);
  EXPECT_NEAR(EvaluatePerson(p, 6.0).heading_rad, -2.0, 1e-12);
  EXPECT_NEAR(EvaluatePerson(p, 9.0).heading_rad, -2.0, 1e-12);
  EXPECT_NEAR(BodyTop(EvaluatePerson(p, 9.0)), 1.75, 0.01);
}

TEST(BodyTest, MotionIsContinuousAcrossAllActions) {
  const Person p = Busybody();
  BodyState prev = EvaluatePerson(p, -0.5);
  double max_jump = 0.0;
  double max_turn = 0.0;
  for (int f = 1; f < 26 * 30; ++f) {
    const double t = -0.5 + f * kFrameS;
    const BodyState s = EvaluatePerson(p, t);
    for (int k = 0; k < kNumBodyParts; ++k) {
      max_jump = std::max({max_jump, (s.parts[k].a_W - prev.parts[k].a_W).norm(),
                           (s.parts[k].b_W - prev.parts[k].b_W).norm()});
    }
    max_turn =
        std::max(max_turn, std::abs(std::remainder(s.heading_rad - prev.heading_rad, 2 * kPi)));
    prev = s;
  }
  EXPECT_LT(max_jump, 0.25);
  EXPECT_LT(max_turn, 0.2);
  // Far finer sampling shrinks the jumps: no hidden discontinuity.
  double fine_jump = 0.0;
  BodyState fine_prev = EvaluatePerson(p, 0.0);
  for (int f = 1; f <= 25 * 1000; ++f) {
    const BodyState s = EvaluatePerson(p, f * 1e-3);
    for (int k = 0; k < kNumBodyParts; ++k) {
      fine_jump = std::max({fine_jump, (s.parts[k].a_W - fine_prev.parts[k].a_W).norm(),
                            (s.parts[k].b_W - fine_prev.parts[k].b_W).norm()});
    }
    fine_prev = s;
  }
  EXPECT_LT(fine_jump, 0.01);
}

TEST(BodyTest, EvaluationIsDeterministic) {
  const Person p = Busybody();
  for (double t : {0.0, 3.3, 8.1, 11.7, 15.2, 23.0}) {
    const BodyState a = EvaluatePerson(p, t);
    const BodyState b = EvaluatePerson(p, t);
    for (int k = 0; k < kNumBodyParts; ++k) {
      EXPECT_EQ(a.parts[k].a_W, b.parts[k].a_W);
      EXPECT_EQ(a.parts[k].b_W, b.parts[k].b_W);
    }
    EXPECT_EQ(a.ellipsoid_half_axes_m, b.ellipsoid_half_axes_m);
  }
}

/// Random point inside the capsule (not uniform; covers the whole volume).
Vector3d PointInCapsule(const BodyCapsule& c, std::mt19937_64* rng) {
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::normal_distribution<double> normal;
  Vector3d n(normal(*rng), normal(*rng), normal(*rng));
  n.normalize();
  return c.a_W + u01(*rng) * (c.b_W - c.a_W) + c.radius_m * std::cbrt(u01(*rng)) * n;
}

/// Random point on the capsule surface: one of the end spheres or the side.
Vector3d PointOnCapsule(const BodyCapsule& c, std::mt19937_64* rng) {
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::normal_distribution<double> normal;
  Vector3d n(normal(*rng), normal(*rng), normal(*rng));
  n.normalize();
  const Vector3d axis = c.b_W - c.a_W;
  const double pick = u01(*rng);
  if (pick < 0.4 || axis.norm() < 1e-12) {
    return c.a_W + c.radius_m * n;
  }
  if (pick < 0.8) {
    return c.b_W + c.radius_m * n;
  }
  const Vector3d dir = axis.normalized();
  Vector3d side = n - n.dot(dir) * dir;
  if (side.norm() < 1e-9) {
    side = dir.unitOrthogonal();
  }
  return c.a_W + u01(*rng) * axis + c.radius_m * side.normalized();
}

double EllipsoidNorm(const BodyState& s, const Vector3d& p) {
  return (p - s.centre_W).cwiseQuotient(s.ellipsoid_half_axes_m).norm();
}

TEST(BodyEllipsoidTest, ContainsEveryPartOfEveryPose) {
  const Person p = Busybody();
  std::mt19937_64 rng(42);
  for (double t : {0.0, 2.1, 4.4, 8.0, 11.0, 15.0, 17.0, 23.0}) {
    const BodyState s = EvaluatePerson(p, t);
    // Centre: middle of the bounding box of the parts.
    Vector3d lo = Vector3d::Constant(1e9);
    Vector3d hi = Vector3d::Constant(-1e9);
    for (const BodyCapsule& c : s.parts) {
      lo = lo.cwiseMin(c.a_W.cwiseMin(c.b_W) - Vector3d::Constant(c.radius_m));
      hi = hi.cwiseMax(c.a_W.cwiseMax(c.b_W) + Vector3d::Constant(c.radius_m));
    }
    EXPECT_LT((s.centre_W - 0.5 * (lo + hi)).norm(), 1e-12) << t;
    // Axes proportional to the box, scaled by a moderate factor.
    const Vector3d scale = s.ellipsoid_half_axes_m.cwiseQuotient(0.5 * (hi - lo));
    EXPECT_NEAR(scale.x(), scale.y(), 1e-9);
    EXPECT_NEAR(scale.x(), scale.z(), 1e-9);
    // Proportional axes need sqrt(2) for an upright cylinder and never more
    // than sqrt(3) (the box corners).
    EXPECT_GE(scale.x(), 1.0) << t;
    EXPECT_LE(scale.x(), std::sqrt(3.0) + 1e-6) << t;
    double worst = 0.0;
    for (int i = 0; i < 10000; ++i) {
      const BodyCapsule& c = s.parts[i % kNumBodyParts];
      worst = std::max(worst, EllipsoidNorm(s, PointInCapsule(c, &rng)));
    }
    for (int i = 0; i < 10000; ++i) {
      const BodyCapsule& c = s.parts[i % kNumBodyParts];
      worst = std::max(worst, EllipsoidNorm(s, PointOnCapsule(c, &rng)));
    }
    EXPECT_LE(worst, 1.0) << "t=" << t;
    EXPECT_GT(worst, 0.95) << "t=" << t;  // The smallest such scale, give or take.
  }
}

TEST(BodyEllipsoidTest, ContainsRandomCapsuleSets) {
  std::mt19937_64 rng(1234);
  std::uniform_real_distribution<double> coord(-2.0, 2.0);
  std::uniform_real_distribution<double> radius(0.001, 0.5);
  std::uniform_int_distribution<int> flat(0, 3);
  for (int trial = 0; trial < 200; ++trial) {
    BodyState s;
    const int squash = flat(rng);  // Sometimes very thin along one axis.
    for (int k = 0; k < kNumBodyParts; ++k) {
      BodyCapsule& c = s.parts[k];
      c.part = static_cast<BodyPart>(k);
      c.a_W = Vector3d(coord(rng), coord(rng), coord(rng));
      c.b_W = (k % 4 == 0) ? c.a_W : Vector3d(coord(rng), coord(rng), coord(rng));
      if (squash < 3) {
        c.a_W[squash] *= 0.01;
        c.b_W[squash] *= 0.01;
      }
      c.radius_m = radius(rng) * (squash < 3 ? 0.05 : 1.0);
    }
    ComputeBoundingEllipsoid(&s);
    double worst = 0.0;
    for (int i = 0; i < 2000; ++i) {
      const BodyCapsule& c = s.parts[i % kNumBodyParts];
      worst = std::max({worst, EllipsoidNorm(s, PointInCapsule(c, &rng)),
                        EllipsoidNorm(s, PointOnCapsule(c, &rng))});
    }
    // Extreme points: each end sphere in the six axis directions.
    for (const BodyCapsule& c : s.parts) {
      for (int axis = 0; axis < 3; ++axis) {
        for (double sign : {-1.0, 1.0}) {
          const Vector3d off = sign * c.radius_m * Vector3d::Unit(axis);
          worst = std::max({worst, EllipsoidNorm(s, c.a_W + off), EllipsoidNorm(s, c.b_W + off)});
        }
      }
    }
    EXPECT_LE(worst, 1.0) << "trial " << trial;
  }
}

}  // namespace
}  // namespace hg::sim
