#include "sim/body.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#include <utility>

#include <Eigen/Geometry>

#include "common/check.h"

// Model of a person
// -----------------
// Thirteen capsules hang off a root at the pelvis (the midpoint of the hip
// joints). Lengths follow the usual anthropometric ratios of the height H
// (Drillis & Contini): hip joint at 0.53 H, shoulders 0.288 H above it, upper
// arm 0.186 H, forearm plus hand 0.254 H (one capsule to the fingertips),
// thigh 0.245 H, shin 0.246 H, ankle 0.039 H above the sole. Radii are those of
// a 1.75 m adult scaled by H / 1.75. Adjacent capsules overlap at every joint.
//
// A pose is a set of parameters: heading, pelvis offset, torso and head pitch,
// and per side hip, knee, ankle, shoulder (flexion, abduction), elbow and a
// reach weight with its target. Actions produce target poses; transitions
// interpolate the parameters (never the capsules), so bodies deform smoothly.
// Forward kinematics places the body so that its lowest point (arms only when
// they bear weight, as in crawling) rests on the ground of the person's
// location: feet never sink and never float while standing or walking.
//
// Timeline (EvaluatePerson)
// -------------------------
// Before the first action the person stands at start_W facing
// start_heading_rad. Each action starts at start_s from wherever the previous
// one left the person and blends into its pose over kBlendS; large motions take
// longer (joints average at most kJointRateRadps, turns kTurnRateRadps). Walk
// and crawl follow their path at speed_mps until the path ends or the action's
// time runs out (the heading turns smoothly around waypoints). After a walk the
// person settles into the standing pose (blended) and stays there; after a
// crawl the person stays on hands and knees with the limbs where they stopped;
// after stand, crouch and reach the final pose is held. Everything is a pure
// function of (person, t) and touches no heap memory.

namespace hg::sim {
namespace {

using Eigen::Vector3d;

constexpr double kPi = 3.14159265358979323846;
constexpr int kLeft = 0;
constexpr int kRight = 1;

/// Shortest transition time between poses (s).
constexpr double kBlendS = 0.4;
/// Fastest joint motion in a transition (rad/s): getting up from all fours
/// takes about a second, not kBlendS.
constexpr double kJointRateRadps = 2.0;
/// Angle (rad) that a change of 1 in a reach weight or in arm support counts
/// as when timing a transition.
constexpr double kReachSwingRad = 1.2;
/// Fastest turn on the spot (rad/s): large turns blend over |angle| / rate.
constexpr double kTurnRateRadps = 3.0;
/// Half the length of path over which a walker turns at a waypoint (m).
constexpr double kPathTurnHalfM = 0.3;
/// Arms that do not bear weight still lift the body once they would sink more
/// than this below the ground (only in transitions; keeps the function continuous).
constexpr double kArmGroundMarginM = 0.05;
/// Step of the difference for velocity_W (s): central, forward at the start of
/// the script.
constexpr double kVelocityStepS = 1e-3;
/// Stride (one full gait cycle) at 1.2 m/s, as a share of the height.
constexpr double kStrideShare = 0.75;
/// Height by which the ankle of a swinging leg rises (at mid swing) above the
/// arc of a straight leg, as a share of the height.
constexpr double kSwingLiftShare = 0.08;
/// Length of one crawling cycle as a share of the height.
constexpr double kCrawlCycleShare = 0.35;

constexpr double Deg(double deg) { return deg * kPi / 180.0; }

/// Angle in (-pi, pi].
double WrapAngle(double a) {
  a = std::remainder(a, 2.0 * kPi);
  return a <= -kPi ? a + 2.0 * kPi : a;
}

double SmoothStep(double x) {
  x = std::clamp(x, 0.0, 1.0);
  return x * x * (3.0 - 2.0 * x);
}

double Lerp(double a, double b, double s) { return a + s * (b - a); }

/// Segment lengths, attachment offsets and radii of one person (metres).
struct Dims {
  double height;
  double r_head, r_torso, r_pelvis, r_upper_arm, r_forearm, r_thigh, r_shin, r_foot;
  double thigh, shin, ankle_height, foot, upper_arm, forearm;
  /// Offsets from the root: hips sideways; the rest along the torso axis
  /// (pelvis, torso ends, shoulders, neck) or sideways (pelvis, shoulders).
  double hip_half_width, pelvis_up, pelvis_half_width, torso_low, torso_high, shoulder_up,
      shoulder_half_width, neck_up, head;
};

Dims MakeDims(double height_m) {
  const double h = height_m;
  const double s = h / 1.75;
  Dims d{};
  d.height = h;
  d.r_head = 0.11 * s;
  d.r_torso = 0.16 * s;
  d.r_pelvis = 0.15 * s;
  d.r_upper_arm = 0.05 * s;
  d.r_forearm = 0.04 * s;
  d.r_thigh = 0.075 * s;
  d.r_shin = 0.055 * s;
  d.r_foot = 0.04 * s;
  d.thigh = 0.245 * h;
  d.shin = 0.246 * h;
  d.ankle_height = 0.039 * h;
  d.foot = 0.152 * h - 2.0 * d.r_foot;  // Heel to toe 0.152 H.
  d.upper_arm = 0.186 * h;
  d.forearm = 0.254 * h - d.r_forearm;  // The fingertips end the capsule.
  d.hip_half_width = 0.05 * h;
  d.pelvis_up = 0.03 * h;
  d.pelvis_half_width = 0.02 * h;
  d.torso_low = 0.10 * h;
  d.torso_high = 0.27 * h;
  d.shoulder_up = 0.288 * h;
  d.shoulder_half_width = 0.105 * h;
  d.neck_up = 0.37 * h;
  d.head = 0.10 * h - d.r_head;  // Crown at 0.47 H above the root = H when standing.
  return d;
}

/// Joint-space pose. Angles in radians in the person's sagittal plane,
/// measured from the vertical, positive forward, unless noted. Index 0 is the
/// left side, 1 the right.
struct Pose {
  double heading = 0.0;          ///< Facing direction, from +x counter-clockwise.
  double pelvis_forward = 0.0;   ///< Root ahead of the location (m).
  double torso_pitch = 0.0;      ///< Forward lean of the torso axis.
  double head_pitch = 0.0;       ///< Forward tilt of the head axis.
  std::array<double, 2> hip{};   ///< Thigh direction.
  std::array<double, 2> knee{};  ///< Flexion; the shin points at hip - knee.
  /// Foot direction relative to the shin (rotation in the sagittal plane,
  /// towards the front): pi/2 puts a foot flat under a vertical shin.
  std::array<double, 2> ankle{kPi / 2.0, kPi / 2.0};
  std::array<double, 2> shoulder_flex{};  ///< Upper arm swing forward.
  std::array<double, 2> shoulder_abd{};   ///< Upper arm away from the body.
  std::array<double, 2> elbow{};          ///< Forearm swing forward beyond the upper arm.
  std::array<double, 2> reach_weight{};   ///< 1: the arm points at reach_target_W.
  std::array<Vector3d, 2> reach_target_W{Vector3d::Zero(), Vector3d::Zero()};
  double arm_support = 0.0;  ///< 1: the hands bear weight (crawling).
};

/// `turn`: b's heading less a's, unwrapped (b.heading may move during a blend).
Pose Blend(const Pose& a, const Pose& b, double s, double s_heading, double turn) {
  Pose r;
  r.heading = WrapAngle(a.heading + s_heading * turn);
  r.pelvis_forward = Lerp(a.pelvis_forward, b.pelvis_forward, s);
  r.torso_pitch = Lerp(a.torso_pitch, b.torso_pitch, s);
  r.head_pitch = Lerp(a.head_pitch, b.head_pitch, s);
  r.arm_support = Lerp(a.arm_support, b.arm_support, s);
  for (int i = 0; i < 2; ++i) {
    r.hip[i] = Lerp(a.hip[i], b.hip[i], s);
    r.knee[i] = Lerp(a.knee[i], b.knee[i], s);
    r.ankle[i] = Lerp(a.ankle[i], b.ankle[i], s);
    r.shoulder_flex[i] = Lerp(a.shoulder_flex[i], b.shoulder_flex[i], s);
    r.shoulder_abd[i] = Lerp(a.shoulder_abd[i], b.shoulder_abd[i], s);
    r.elbow[i] = Lerp(a.elbow[i], b.elbow[i], s);
    r.reach_weight[i] = Lerp(a.reach_weight[i], b.reach_weight[i], s);
    // A target only matters with a weight: a pose without one adopts the
    // other's, so the hand does not sweep in from a meaningless point.
    const Vector3d& ta = a.reach_weight[i] > 0.0 ? a.reach_target_W[i] : b.reach_target_W[i];
    const Vector3d& tb = b.reach_weight[i] > 0.0 ? b.reach_target_W[i] : ta;
    r.reach_target_W[i] = ta + s * (tb - ta);
  }
  return r;
}

/// Ankle angle that keeps the foot flat on the floor for a leg with these angles.
double FlatFootAnkle(double hip, double knee) { return kPi / 2.0 - (hip - knee); }

Pose StandPose(double heading) {
  Pose p;
  p.heading = heading;
  for (int i = 0; i < 2; ++i) {
    p.ankle[i] = FlatFootAnkle(0.0, 0.0);
    p.shoulder_abd[i] = Deg(8.0);
    p.elbow[i] = Deg(10.0);
  }
  return p;
}

/// Foot (or hand) position in a gait cycle u in [0, 1): the first half is
/// stance, moving linearly from +1 (ahead) to -1 (behind) so the contact stays
/// put while the body advances; the second half swings back to +1 with `lift`
/// rising and falling. The swing starts and ends at the stance velocity, so a
/// foot leaves and meets the floor without sliding.
struct GaitSample {
  double x;
  double lift;
};

GaitSample Gait(double u) {
  u -= std::floor(u);
  if (u < 0.5) {
    return {1.0 - 4.0 * u, 0.0};
  }
  // Cubic Hermite from -1 to +1 with slope -2 (per swing fraction) at both ends.
  const double s = 2.0 * (u - 0.5);
  // The lift starts and ends with zero slope: a knee bending to reach it
  // would otherwise start at infinite speed.
  const double lift = std::sin(kPi * s);
  return {((-8.0 * s + 12.0) * s - 2.0) * s - 1.0, lift * lift};
}

/// Hip and knee angles that put the ankle `forward` ahead of and `depth`
/// below the hip joint, knee bending forward (straight leg when out of reach).
void LegToAnkle(const Dims& d, double forward, double depth, double* hip, double* knee) {
  const double l1 = d.thigh;
  const double l2 = d.shin;
  const double dist = std::clamp(std::hypot(forward, depth), std::abs(l1 - l2) + 1e-9, l1 + l2);
  const double towards = std::atan2(forward, depth);
  const double cos_knee = (dist * dist - l1 * l1 - l2 * l2) / (2.0 * l1 * l2);
  const double cos_hip = (l1 * l1 + dist * dist - l2 * l2) / (2.0 * l1 * dist);
  *knee = std::acos(std::clamp(cos_knee, -1.0, 1.0));
  *hip = towards + std::acos(std::clamp(cos_hip, -1.0, 1.0));
}

/// Stride length relative to the one at 1.2 m/s: people lengthen their steps
/// when they walk faster (and step faster too).
double StrideFactor(double speed_mps) {
  return std::clamp(std::sqrt(std::max(speed_mps, 0.0) / 1.2), 0.4, 1.3);
}

/// Walking pose after `distance_m` along the path. The cycle starts at mid
/// stance of the left leg, close to standing, so setting off looks natural.
Pose WalkPose(const Dims& d, double distance_m, double speed_mps, double heading) {
  Pose p;
  p.heading = heading;
  const double factor = StrideFactor(speed_mps);
  const double stride = kStrideShare * d.height * factor;
  const double half_step = stride / 4.0;  // Stance covers half a cycle.
  const double leg = d.thigh + d.shin;
  const double clearance = kSwingLiftShare * d.height;
  const double u = distance_m / stride + 0.25;
  std::array<GaitSample, 2> g{Gait(u), Gait(u + 0.5)};
  for (int i = 0; i < 2; ++i) {
    // The ankle moves on the arc of the straight leg (stance) or above it by
    // the lift (swing); the knee bends as needed to get there.
    const double x = std::clamp(g[i].x * half_step, -0.9 * leg, 0.9 * leg);
    const double depth = std::sqrt(leg * leg - x * x) - clearance * g[i].lift;
    LegToAnkle(d, x, depth, &p.hip[i], &p.knee[i]);
    p.ankle[i] = FlatFootAnkle(p.hip[i], p.knee[i]);
    // Arms swing with the opposite leg.
    p.shoulder_flex[i] = Deg(18.0) * factor * g[1 - i].x;
    p.shoulder_abd[i] = Deg(6.0);
    p.elbow[i] = Deg(15.0) + Deg(10.0) * std::max(0.0, g[1 - i].x);
  }
  p.torso_pitch = Deg(4.0);
  return p;
}

/// Deep squat: knees ~120 deg, torso leaning forward, feet where they stood.
Pose CrouchPose(const Dims& d, double heading) {
  Pose p;
  p.heading = heading;
  const double hip = Deg(85.0);
  const double knee = Deg(120.0);
  for (int i = 0; i < 2; ++i) {
    p.hip[i] = hip;
    p.knee[i] = knee;
    p.ankle[i] = FlatFootAnkle(hip, knee);
    p.shoulder_flex[i] = Deg(30.0);
    p.shoulder_abd[i] = Deg(12.0);
    p.elbow[i] = Deg(40.0);
  }
  // The ankles stay under the location: the pelvis moves back.
  p.pelvis_forward = -(d.thigh * std::sin(hip) + d.shin * std::sin(hip - knee));
  p.torso_pitch = Deg(45.0);
  p.head_pitch = Deg(20.0);
  return p;
}

/// Hands and knees after `distance_m`: torso horizontal, thighs about vertical,
/// shins and feet on the floor, diagonal limbs moving together. The hand
/// capsule runs to the fingertips, so with the back low enough for a 0.70 m
/// clearance the upper arms hang down and the forearms rest forward on the floor.
Pose CrawlPose(const Dims& d, double distance_m, double heading) {
  Pose p;
  p.heading = heading;
  const double cycle = kCrawlCycleShare * d.height;
  const double half_step = cycle / 4.0;
  const double u = distance_m / cycle + 0.25;
  std::array<GaitSample, 2> g{Gait(u), Gait(u + 0.5)};
  double max_cos = 0.0;
  const double shin_tilt = std::asin(std::max(d.r_thigh - d.r_shin, 0.0) / d.shin);
  for (int i = 0; i < 2; ++i) {
    p.hip[i] = std::asin(std::clamp(g[i].x * half_step / d.thigh, -0.9, 0.9));
    // Shin on the floor, pointing back (tilted down just enough for the
    // thinner shin to touch the floor behind the knee).
    p.knee[i] = p.hip[i] + kPi / 2.0 - shin_tilt;
    p.ankle[i] = 0.0;  // Foot along the shin, instep down.
    max_cos = std::max(max_cos, std::cos(p.hip[i]));
  }
  // Root height with the knees on the floor (shoulders are level with it).
  const double root_height = d.thigh * max_cos + std::max(d.r_thigh, d.r_shin);
  const double abd = Deg(5.0);
  const double reach = d.upper_arm + 0.5 * d.forearm;
  for (int i = 0; i < 2; ++i) {
    const GaitSample& arm = g[1 - i];
    const double flex = std::asin(std::clamp(arm.x * half_step / reach, -0.9, 0.9));
    // Forearm angle that puts the fingertips on the floor; lifting in swing.
    const double c = (root_height - d.r_forearm - d.upper_arm * std::cos(flex) * std::cos(abd)) /
                     (d.forearm * std::cos(abd));
    const double forearm = std::acos(std::clamp(c, -1.0, 1.0)) + Deg(15.0) * arm.lift;
    p.shoulder_flex[i] = flex;
    p.shoulder_abd[i] = abd;
    p.elbow[i] = forearm - flex;
  }
  p.torso_pitch = kPi / 2.0;
  p.head_pitch = Deg(55.0);
  p.arm_support = 1.0;
  return p;
}

/// Rotates unit vector `a` towards unit vector `b` by the fraction w of the angle.
Vector3d RotateToward(const Vector3d& a, const Vector3d& b, double w) {
  if (w <= 0.0) {
    return a;
  }
  if (w >= 1.0) {
    return b;
  }
  Vector3d axis = a.cross(b);
  const double sin_angle = axis.norm();
  const double cos_angle = a.dot(b);
  if (sin_angle < 1e-12) {
    if (cos_angle > 0.0) {
      return a;
    }
    // Opposite: any axis perpendicular to a.
    axis = a.cross(std::abs(a.x()) < 0.6 ? Vector3d::UnitX() : Vector3d::UnitY());
  }
  axis.normalize();
  const double angle = w * std::atan2(sin_angle, cos_angle);
  return Eigen::AngleAxisd(angle, axis) * a;
}

/// Upper-arm and forearm directions that put the hand (end of the forearm
/// segment) at `target` from `shoulder`, clamped to the arm's reach; the elbow
/// bends downwards (outwards for targets straight above or below).
void ReachArm(const Dims& d, const Vector3d& shoulder, const Vector3d& target, double side_sign,
              Vector3d* upper, Vector3d* fore) {
  const double l1 = d.upper_arm;
  const double l2 = d.forearm;
  Vector3d delta = target - shoulder;
  double dist = delta.norm();
  const Vector3d dir = dist > 1e-9 ? Vector3d(delta / dist) : Vector3d::UnitX();
  dist = std::clamp(dist, std::abs(l1 - l2) + 1e-3, l1 + l2);
  if (dist >= l1 + l2) {
    *upper = dir;
    *fore = dir;
    return;
  }
  Vector3d bend = -Vector3d::UnitZ() + dir.z() * dir;
  if (bend.norm() < 1e-6) {
    bend = side_sign * Vector3d::UnitY() - dir.y() * side_sign * dir;
  }
  bend.normalize();
  const double cos_a = std::clamp((l1 * l1 + dist * dist - l2 * l2) / (2.0 * l1 * dist), -1.0, 1.0);
  const double a = std::acos(cos_a);
  *upper = std::cos(a) * dir + std::sin(a) * bend;
  const Vector3d elbow = shoulder + l1 * *upper;
  *fore = (shoulder + dist * dir - elbow).normalized();
}

/// Arm direction from flexion (forward) and abduction (sideways) angles.
Vector3d ArmDirection(double flex, double abd, double side_sign) {
  return {std::sin(flex) * std::cos(abd), side_sign * std::sin(abd),
          -std::cos(flex) * std::cos(abd)};
}

/// Rotation by `angle` towards the front in the sagittal (x, z) plane.
Vector3d RotateSagittal(const Vector3d& v, double angle) {
  const double c = std::cos(angle);
  const double s = std::sin(angle);
  return {v.x() * c - v.z() * s, v.y(), v.x() * s + v.z() * c};
}

double PartRadius(const Dims& d, BodyPart part) {
  switch (part) {
    case BodyPart::kHead:
      return d.r_head;
    case BodyPart::kTorso:
      return d.r_torso;
    case BodyPart::kPelvis:
      return d.r_pelvis;
    case BodyPart::kUpperArmLeft:
    case BodyPart::kUpperArmRight:
      return d.r_upper_arm;
    case BodyPart::kForearmLeft:
    case BodyPart::kForearmRight:
      return d.r_forearm;
    case BodyPart::kThighLeft:
    case BodyPart::kThighRight:
      return d.r_thigh;
    case BodyPart::kShinLeft:
    case BodyPart::kShinRight:
      return d.r_shin;
    case BodyPart::kFootLeft:
    case BodyPart::kFootRight:
      return d.r_foot;
  }
  return 0.0;
}

bool IsArm(BodyPart part) {
  return part == BodyPart::kUpperArmLeft || part == BodyPart::kForearmLeft ||
         part == BodyPart::kUpperArmRight || part == BodyPart::kForearmRight;
}

/// Capsules of `pose` at location `loc_W` (feet position on the ground).
void ForwardKinematics(const Dims& d, const Pose& pose, const Vector3d& loc_W, BodyState* out) {
  std::array<Vector3d, kNumBodyParts> a;
  std::array<Vector3d, kNumBodyParts> b;
  auto set = [&](BodyPart part, const Vector3d& pa, const Vector3d& pb) {
    a[static_cast<int>(part)] = pa;
    b[static_cast<int>(part)] = pb;
  };
  // Local frame: origin at the location, x forward, y left, z up; the root
  // starts at height 0 and is lifted onto the ground below.
  const Vector3d up(std::sin(pose.torso_pitch), 0.0, std::cos(pose.torso_pitch));
  const Vector3d y = Vector3d::UnitY();
  const Vector3d root(pose.pelvis_forward, 0.0, 0.0);
  set(BodyPart::kPelvis, root + d.pelvis_up * up - d.pelvis_half_width * y,
      root + d.pelvis_up * up + d.pelvis_half_width * y);
  set(BodyPart::kTorso, root + d.torso_low * up, root + d.torso_high * up);
  const Vector3d neck = root + d.neck_up * up;
  const Vector3d head_dir(std::sin(pose.head_pitch), 0.0, std::cos(pose.head_pitch));
  set(BodyPart::kHead, neck, neck + d.head * head_dir);

  constexpr std::array<BodyPart, 2> kThigh{BodyPart::kThighLeft, BodyPart::kThighRight};
  constexpr std::array<BodyPart, 2> kShin{BodyPart::kShinLeft, BodyPart::kShinRight};
  constexpr std::array<BodyPart, 2> kFoot{BodyPart::kFootLeft, BodyPart::kFootRight};
  constexpr std::array<BodyPart, 2> kUpper{BodyPart::kUpperArmLeft, BodyPart::kUpperArmRight};
  constexpr std::array<BodyPart, 2> kFore{BodyPart::kForearmLeft, BodyPart::kForearmRight};
  std::array<Vector3d, 2> shoulder;
  for (int i = 0; i < 2; ++i) {
    const double side = i == kLeft ? 1.0 : -1.0;
    const Vector3d hip = root + side * d.hip_half_width * y;
    const Vector3d thigh_dir(std::sin(pose.hip[i]), 0.0, -std::cos(pose.hip[i]));
    const Vector3d knee = hip + d.thigh * thigh_dir;
    const double shin_angle = pose.hip[i] - pose.knee[i];
    const Vector3d shin_dir(std::sin(shin_angle), 0.0, -std::cos(shin_angle));
    const Vector3d ankle = knee + d.shin * shin_dir;
    const Vector3d foot_dir = RotateSagittal(shin_dir, pose.ankle[i]);
    const Vector3d foot_up = RotateSagittal(foot_dir, kPi / 2.0);
    const Vector3d heel = ankle - (d.ankle_height - d.r_foot) * foot_up;
    set(kThigh[i], hip, knee);
    set(kShin[i], knee, ankle);
    set(kFoot[i], heel, heel + d.foot * foot_dir);

    shoulder[i] = root + d.shoulder_up * up + side * d.shoulder_half_width * y;
    const Vector3d upper = ArmDirection(pose.shoulder_flex[i], pose.shoulder_abd[i], side);
    const Vector3d fore =
        ArmDirection(pose.shoulder_flex[i] + pose.elbow[i], pose.shoulder_abd[i], side);
    const Vector3d elbow = shoulder[i] + d.upper_arm * upper;
    set(kUpper[i], shoulder[i], elbow);
    set(kFore[i], elbow, elbow + d.forearm * fore);
  }

  // Put the lowest point on the ground. Arms count when they bear weight.
  double body_low = std::numeric_limits<double>::infinity();
  double arm_low = std::numeric_limits<double>::infinity();
  for (int k = 0; k < kNumBodyParts; ++k) {
    const BodyPart part = static_cast<BodyPart>(k);
    const double low = std::min(a[k].z(), b[k].z()) - PartRadius(d, part);
    double& bucket = IsArm(part) ? arm_low : body_low;
    bucket = std::min(bucket, low);
  }
  const double support = std::clamp(pose.arm_support, 0.0, 1.0);
  const double lowest = std::min(body_low, arm_low + (1.0 - support) * kArmGroundMarginM);
  const Vector3d lift(0.0, 0.0, -lowest);
  for (int k = 0; k < kNumBodyParts; ++k) {
    a[k] += lift;
    b[k] += lift;
  }

  const Eigen::Matrix3d R_WL =
      Eigen::AngleAxisd(pose.heading, Vector3d::UnitZ()).toRotationMatrix();
  for (int i = 0; i < 2; ++i) {
    const double w = std::clamp(pose.reach_weight[i], 0.0, 1.0);
    if (w <= 0.0) {
      continue;
    }
    const double side = i == kLeft ? 1.0 : -1.0;
    Vector3d target = R_WL.transpose() * (pose.reach_target_W[i] - loc_W);
    target.z() = std::max(target.z(), d.r_forearm);  // Not into the floor.
    const Vector3d s = shoulder[i] + lift;
    Vector3d upper_reach;
    Vector3d fore_reach;
    ReachArm(d, s, target, side, &upper_reach, &fore_reach);
    const int ku = static_cast<int>(kUpper[i]);
    const int kf = static_cast<int>(kFore[i]);
    const Vector3d upper = RotateToward((b[ku] - a[ku]).normalized(), upper_reach, w);
    const Vector3d fore = RotateToward((b[kf] - a[kf]).normalized(), fore_reach, w);
    const Vector3d elbow = s + d.upper_arm * upper;
    set(kUpper[i], s, elbow);
    set(kFore[i], elbow, elbow + d.forearm * fore);
  }

  for (int k = 0; k < kNumBodyParts; ++k) {
    const BodyPart part = static_cast<BodyPart>(k);
    out->parts[k] =
        BodyCapsule{part, R_WL * a[k] + loc_W, R_WL * b[k] + loc_W, PartRadius(d, part)};
  }
}

/// Point and facing direction at `distance_m` along the polyline from `start`
/// through `path`; the heading turns linearly over up to kPathTurnHalfM either
/// side of each waypoint. Segments without horizontal extent keep the heading
/// (`heading0` before any other).
struct PathSample {
  Vector3d point;
  double heading;
};

double SegmentHeading(const Vector3d& from, const Vector3d& to, double fallback) {
  const Eigen::Vector2d delta = (to - from).head<2>();
  return delta.norm() > 1e-9 ? std::atan2(delta.y(), delta.x()) : fallback;
}

constexpr double kZeroSegmentM = 1e-12;

double PathLength(const Vector3d& start, const std::vector<Vector3d>& path) {
  double length = 0.0;
  Vector3d prev = start;
  for (const Vector3d& p : path) {
    length += (p - prev).norm();
    prev = p;
  }
  return length;
}

PathSample PathAt(const Vector3d& start, const std::vector<Vector3d>& path, double distance_m,
                  double heading0) {
  const int n = static_cast<int>(path.size());
  auto point = [&](int k) -> const Vector3d& { return k == 0 ? start : path[k - 1]; };
  distance_m = std::max(distance_m, 0.0);
  double walked = 0.0;
  double prev_heading = heading0;
  double prev_length = 0.0;
  bool has_prev = false;
  for (int k = 0; k < n; ++k) {
    const Vector3d delta = point(k + 1) - point(k);
    const double length = delta.norm();
    if (length <= kZeroSegmentM) {
      continue;
    }
    const double heading = SegmentHeading(point(k), point(k + 1), prev_heading);
    if (distance_m < walked + length) {
      const double x = distance_m - walked;
      PathSample out{point(k) + delta * (x / length), heading};
      if (has_prev) {
        const double half = std::min({kPathTurnHalfM, prev_length / 2.0, length / 2.0});
        if (x < half) {
          out.heading =
              prev_heading + WrapAngle(heading - prev_heading) * (x + half) / (2.0 * half);
        }
      }
      for (int m = k + 1; m < n; ++m) {
        const double next_length = (point(m + 1) - point(m)).norm();
        if (next_length <= kZeroSegmentM) {
          continue;
        }
        const double next_heading = SegmentHeading(point(m), point(m + 1), heading);
        const double half = std::min({kPathTurnHalfM, length / 2.0, next_length / 2.0});
        if (x > length - half) {
          out.heading =
              heading + WrapAngle(next_heading - heading) * (x - (length - half)) / (2.0 * half);
        }
        break;
      }
      out.heading = WrapAngle(out.heading);
      return out;
    }
    walked += length;
    prev_heading = heading;
    prev_length = length;
    has_prev = true;
  }
  return {point(n), WrapAngle(prev_heading)};
}

/// One stretch of the timeline: from `from` (the pose when it began) the body
/// blends into a target pose that may move along a path.
enum class PhaseKind { kHold, kWalk, kCrawl };

struct Phase {
  PhaseKind kind = PhaseKind::kHold;
  double t0 = -std::numeric_limits<double>::infinity();
  Pose from;
  Pose target;                     ///< kHold only.
  const Action* action = nullptr;  ///< kWalk, kCrawl: path and speed.
  Vector3d loc0 = Vector3d::Zero();
  double move_s = 0.0;  ///< kWalk, kCrawl: time spent moving.
  double blend_s = kBlendS;
  double heading_blend_s = kBlendS;
  /// kWalk, kCrawl: the target's heading at the start, and the turn from
  /// `from` to it. The turn to the moving target is this turn plus how far
  /// the target has turned since, so it stays continuous when the target
  /// passes the heading opposite `from` during the blend.
  double target_heading0 = 0.0;
  double turn0 = 0.0;
};

struct Sample {
  Pose pose;
  Vector3d loc;
};

Pose MovingTarget(const Dims& d, const Phase& phase, double tau, Vector3d* loc) {
  const Action& act = *phase.action;
  const double speed = std::max(act.speed_mps, 0.0);
  const double distance = speed * std::clamp(tau, 0.0, phase.move_s);
  const PathSample at = PathAt(phase.loc0, act.path_W, distance, phase.from.heading);
  *loc = at.point;
  return phase.kind == PhaseKind::kWalk ? WalkPose(d, distance, speed, at.heading)
                                        : CrawlPose(d, distance, at.heading);
}

Sample EvaluatePhase(const Dims& d, const Phase& phase, double t) {
  if (phase.kind == PhaseKind::kHold && !std::isfinite(phase.t0)) {
    return {phase.target, phase.loc0};
  }
  const double tau = t - phase.t0;
  Sample out;
  out.loc = phase.loc0;
  const Pose target =
      phase.kind == PhaseKind::kHold ? phase.target : MovingTarget(d, phase, tau, &out.loc);
  const double turn = phase.kind == PhaseKind::kHold
                          ? WrapAngle(target.heading - phase.from.heading)
                          : phase.turn0 + WrapAngle(target.heading - phase.target_heading0);
  out.pose = Blend(phase.from, target, SmoothStep(tau / phase.blend_s),
                   SmoothStep(tau / phase.heading_blend_s), turn);
  return out;
}

double HeadingBlendTime(double from, double to) {
  return std::max(kBlendS, std::abs(WrapAngle(to - from)) / kTurnRateRadps);
}

/// Transition time from pose a to pose b: kBlendS, longer for large motions.
double BlendTime(const Pose& a, const Pose& b) {
  double largest =
      std::max({std::abs(b.torso_pitch - a.torso_pitch), std::abs(b.head_pitch - a.head_pitch),
                kReachSwingRad * std::abs(b.arm_support - a.arm_support)});
  for (int i = 0; i < 2; ++i) {
    largest = std::max(
        {largest, std::abs(b.hip[i] - a.hip[i]), std::abs(b.knee[i] - a.knee[i]),
         std::abs(b.ankle[i] - a.ankle[i]), std::abs(b.shoulder_flex[i] - a.shoulder_flex[i]),
         std::abs(b.shoulder_abd[i] - a.shoulder_abd[i]), std::abs(b.elbow[i] - a.elbow[i]),
         kReachSwingRad * std::abs(b.reach_weight[i] - a.reach_weight[i])});
  }
  return std::max(kBlendS, largest / kJointRateRadps);
}

Phase HoldPhase(double t0, const Sample& start, const Pose& target) {
  Phase phase;
  phase.kind = PhaseKind::kHold;
  phase.t0 = t0;
  phase.from = start.pose;
  phase.target = target;
  phase.loc0 = start.loc;
  phase.blend_s = BlendTime(start.pose, target);
  phase.heading_blend_s = HeadingBlendTime(start.pose.heading, target.heading);
  return phase;
}

/// Pose and location at t_s, and the action in progress.
Sample EvaluateTimeline(const Person& person, const Dims& d, double t_s, ActionKind* action) {
  Phase phase;
  phase.target = StandPose(WrapAngle(person.start_heading_rad));
  phase.loc0 = person.start_W;
  *action = ActionKind::kStand;
  const std::size_t n = person.actions.size();
  for (std::size_t i = 0; i < n; ++i) {
    const Action& act = person.actions[i];
    if (!(t_s >= act.start_s)) {
      break;
    }
    const double next_start =
        i + 1 < n ? person.actions[i + 1].start_s : std::numeric_limits<double>::infinity();
    const double end_s = std::min(act.start_s + std::max(act.duration_s, 0.0), next_start);
    const Sample start = EvaluatePhase(d, phase, act.start_s);
    const double current = start.pose.heading;
    switch (act.kind) {
      case ActionKind::kStand:
      case ActionKind::kCrouch: {
        const double heading =
            std::isfinite(act.heading_rad) ? WrapAngle(act.heading_rad) : current;
        phase =
            HoldPhase(act.start_s, start,
                      act.kind == ActionKind::kStand ? StandPose(heading) : CrouchPose(d, heading));
        break;
      }
      case ActionKind::kReach: {
        const Eigen::Vector2d to = (act.target_W - start.loc).head<2>();
        const double heading = to.norm() > 1e-6 ? std::atan2(to.y(), to.x()) : current;
        Pose target = StandPose(heading);
        const int side = act.left_hand ? kLeft : kRight;
        target.reach_weight[side] = 1.0;
        target.reach_target_W[side] = act.target_W;
        target.elbow[side] = 0.0;
        phase = HoldPhase(act.start_s, start, target);
        break;
      }
      case ActionKind::kWalk:
      case ActionKind::kCrawl: {
        phase = Phase();
        phase.kind = act.kind == ActionKind::kWalk ? PhaseKind::kWalk : PhaseKind::kCrawl;
        phase.t0 = act.start_s;
        phase.from = start.pose;
        phase.action = &act;
        phase.loc0 = start.loc;
        const double speed = act.speed_mps;
        const double length = PathLength(start.loc, act.path_W);
        const double path_s = speed > 0.0 ? length / speed : 0.0;
        phase.move_s = std::max(0.0, std::min(end_s - act.start_s, path_s));
        const PathSample first = PathAt(start.loc, act.path_W, 0.0, current);
        phase.heading_blend_s = HeadingBlendTime(current, first.heading);
        Vector3d unused_loc;
        const Pose target0 = MovingTarget(d, phase, 0.0, &unused_loc);
        phase.blend_s = BlendTime(start.pose, target0);
        phase.target_heading0 = target0.heading;
        phase.turn0 = WrapAngle(target0.heading - start.pose.heading);
        const double stop_s = act.start_s + phase.move_s;
        // A walker who stops settles into standing, unless the next action
        // begins right away.
        if (act.kind == ActionKind::kWalk && t_s >= stop_s && stop_s < next_start) {
          const Sample stopped = EvaluatePhase(d, phase, stop_s);
          phase = HoldPhase(stop_s, stopped, StandPose(stopped.pose.heading));
        }
        break;
      }
    }
    *action = t_s < act.start_s + act.duration_s ? act.kind : ActionKind::kStand;
  }
  return EvaluatePhase(d, phase, t_s);
}

}  // namespace

double ScriptEndS(const Person& person) {
  double end_s = 0.0;
  for (const Action& a : person.actions) end_s = std::max(end_s, a.start_s + a.duration_s);
  return end_s;
}

double FastestPartSpeed(const Person& person, double t0_s, double t1_s, double step_s) {
  double fastest = 0.0;
  BodyState before = EvaluatePerson(person, t0_s);
  for (int k = 1; t0_s + k * step_s <= t1_s; ++k) {
    const BodyState after = EvaluatePerson(person, t0_s + k * step_s);
    for (int i = 0; i < kNumBodyParts; ++i) {
      const double moved = std::max((after.parts[i].a_W - before.parts[i].a_W).norm(),
                                    (after.parts[i].b_W - before.parts[i].b_W).norm());
      fastest = std::max(fastest, moved / step_s);
    }
    before = after;
  }
  return fastest;
}

const char* BodyPartName(BodyPart part) {
  switch (part) {
    case BodyPart::kHead:
      return "head";
    case BodyPart::kTorso:
      return "torso";
    case BodyPart::kPelvis:
      return "pelvis";
    case BodyPart::kUpperArmLeft:
      return "upper_arm_left";
    case BodyPart::kForearmLeft:
      return "forearm_left";
    case BodyPart::kUpperArmRight:
      return "upper_arm_right";
    case BodyPart::kForearmRight:
      return "forearm_right";
    case BodyPart::kThighLeft:
      return "thigh_left";
    case BodyPart::kShinLeft:
      return "shin_left";
    case BodyPart::kThighRight:
      return "thigh_right";
    case BodyPart::kShinRight:
      return "shin_right";
    case BodyPart::kFootLeft:
      return "foot_left";
    case BodyPart::kFootRight:
      return "foot_right";
  }
  return "unknown";
}

bool BodyPartFromName(const std::string& name, BodyPart* part) {
  for (int k = 0; k < kNumBodyParts; ++k) {
    const BodyPart candidate = static_cast<BodyPart>(k);
    if (name == BodyPartName(candidate)) {
      *part = candidate;
      return true;
    }
  }
  return false;
}

const char* ActionName(ActionKind kind) {
  switch (kind) {
    case ActionKind::kStand:
      return "stand";
    case ActionKind::kWalk:
      return "walk";
    case ActionKind::kCrouch:
      return "crouch";
    case ActionKind::kCrawl:
      return "crawl";
    case ActionKind::kReach:
      return "reach";
  }
  return "unknown";
}

Rgb PartColour(const Person& person, BodyPart part) {
  switch (part) {
    case BodyPart::kHead:
    case BodyPart::kForearmLeft:
    case BodyPart::kForearmRight:
      return person.skin;
    case BodyPart::kTorso:
    case BodyPart::kUpperArmLeft:
    case BodyPart::kUpperArmRight:
      return person.shirt;
    case BodyPart::kPelvis:
    case BodyPart::kThighLeft:
    case BodyPart::kThighRight:
    case BodyPart::kShinLeft:
    case BodyPart::kShinRight:
      return person.trousers;
    case BodyPart::kFootLeft:
    case BodyPart::kFootRight:
      return Rgb(0.22F, 0.22F, 0.22F);  // Shoes.
  }
  return person.shirt;
}

BodyState EvaluatePerson(const Person& person, double t_s) {
  HG_CHECK(std::isfinite(person.height_m) && person.height_m > 0.0);
  const Dims d = MakeDims(person.height_m);
  BodyState state;
  ActionKind action = ActionKind::kStand;
  const Sample now = EvaluateTimeline(person, d, t_s, &action);
  ForwardKinematics(d, now.pose, now.loc, &state);
  state.heading_rad = now.pose.heading;
  state.action = action;
  ActionKind ignored = ActionKind::kStand;
  // Central difference, but forward at the start of the script (t = 0): before
  // it nobody has started moving, so a sample there would halve the speed of
  // someone who walks from t = 0.
  const bool forward = t_s - kVelocityStepS < 0.0;
  const double t_before = forward ? t_s : t_s - kVelocityStepS;
  const double t_after = t_s + kVelocityStepS;
  const Vector3d before = forward ? now.loc : EvaluateTimeline(person, d, t_before, &ignored).loc;
  const Vector3d after = EvaluateTimeline(person, d, t_after, &ignored).loc;
  state.velocity_W = (after - before) / (t_after - t_before);
  ComputeBoundingEllipsoid(&state);
  return state;
}

common::Box3 BodyBox(const BodyState& state) {
  common::Box3 box;
  box.min = Vector3d::Constant(std::numeric_limits<double>::infinity());
  box.max = -box.min;
  for (const BodyCapsule& c : state.parts) {
    const Vector3d r = Vector3d::Constant(c.radius_m);
    box.min = box.min.cwiseMin(c.a_W.cwiseMin(c.b_W) - r);
    box.max = box.max.cwiseMax(c.a_W.cwiseMax(c.b_W) + r);
  }
  return box;
}

void ComputeBoundingEllipsoid(BodyState* state) {
  const common::Box3 body_box = BodyBox(*state);
  const Vector3d centre = 0.5 * (body_box.min + body_box.max);
  const Vector3d e = (0.5 * (body_box.max - body_box.min)).cwiseMax(1e-9);
  const double e_min = e.minCoeff();
  // A capsule is the convex hull of its two end balls and the normalised
  // distance |(p - c) ./ e| is convex, so its maximum over the capsule is its
  // maximum over the end balls. Each ball (centre q, radius r, d = q - c) gets
  // the least of three upper bounds on max |(d + r n) ./ e| over |n| <= 1:
  //   triangle:  |d ./ e| + r / e_min
  //   expansion: sqrt(|d ./ e|^2 + 2 r |d ./ e.^2| + r^2 / e_min^2)
  //   box:       |(|d| + r) ./ e| (the ball lies in its bounding box)
  double scale = 1.0;
  for (const BodyCapsule& c : state->parts) {
    const double r = c.radius_m;
    for (const Vector3d* q : {&c.a_W, &c.b_W}) {
      const Vector3d d = *q - centre;
      const Vector3d dn = d.cwiseQuotient(e);
      const double triangle = dn.norm() + r / e_min;
      const double expansion = std::sqrt(dn.squaredNorm() + 2.0 * r * dn.cwiseQuotient(e).norm() +
                                         (r / e_min) * (r / e_min));
      const double box = (d.cwiseAbs() + Vector3d::Constant(r)).cwiseQuotient(e).norm();
      scale = std::max(scale, std::min({triangle, expansion, box}));
    }
  }
  // Every capsule lies in the box, and the box in the ellipsoid scaled by sqrt(3).
  scale = std::min(scale, std::sqrt(3.0));
  // Headroom for rounding in this computation and in containment tests.
  scale *= 1.0 + 1e-9;
  state->centre_W = centre;
  state->ellipsoid_half_axes_m = scale * e;
}

}  // namespace hg::sim
