#pragma once
/// @file
/// Articulated people: bodies of capsules (head, torso, pelvis, arms, legs,
/// feet) driven by a time script of actions (stand, walk, crouch, crawl, reach).

#include <array>
#include <limits>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "common/box.h"
#include "sim/solids.h"

namespace hg::sim {

enum class BodyPart {
  kHead,
  kTorso,
  kPelvis,
  kUpperArmLeft,
  kForearmLeft,
  kUpperArmRight,
  kForearmRight,
  kThighLeft,
  kShinLeft,
  kThighRight,
  kShinRight,
  kFootLeft,
  kFootRight,
};
inline constexpr int kNumBodyParts = 13;

/// Stable lower-case name of a part ("head", "upper_arm_left", ...), used in files.
[[nodiscard]] const char* BodyPartName(BodyPart part);
/// Inverse of BodyPartName; false when `name` is not a part name.
[[nodiscard]] bool BodyPartFromName(const std::string& name, BodyPart* part);

enum class ActionKind { kStand, kWalk, kCrouch, kCrawl, kReach };

/// Stable lower-case name ("stand", "walk", ...), as in scene files.
[[nodiscard]] const char* ActionName(ActionKind kind);

/// One scripted action. Actions of a person run one after the other; an action
/// starts at `start_s` (the person holds the previous pose until then). The
/// loader fills start_s and duration_s so that they are always set here.
struct Action {
  ActionKind kind = ActionKind::kStand;
  double start_s = 0.0;
  double duration_s = 0.0;
  /// walk, crawl: waypoints (x, y, ground height) followed at `speed_mps`,
  /// starting from where the person is when the action starts.
  std::vector<Eigen::Vector3d> path_W;
  double speed_mps = 1.2;
  /// reach: the point the hand moves to (clamped to arm's length); the person
  /// turns towards it.
  Eigen::Vector3d target_W = Eigen::Vector3d::Zero();
  bool left_hand = false;
  /// stand, crouch: heading to turn to (radians from +x, counter-clockwise);
  /// NaN keeps the current heading.
  double heading_rad = std::numeric_limits<double>::quiet_NaN();
};

struct Person {
  std::string name;
  double height_m = 1.75;  ///< Body size scales with height (1.0 .. 2.2 m).
  Rgb shirt = Rgb(0.2F, 0.3F, 0.7F);
  Rgb trousers = Rgb(0.15F, 0.15F, 0.2F);
  Rgb skin = Rgb(0.85F, 0.65F, 0.5F);
  Eigen::Vector3d start_W = Eigen::Vector3d::Zero();  ///< Feet position (x, y, ground z).
  double start_heading_rad = 0.0;
  std::vector<Action> actions;  ///< In time order, not overlapping.
};

struct BodyCapsule {
  BodyPart part = BodyPart::kHead;
  Eigen::Vector3d a_W = Eigen::Vector3d::Zero();
  Eigen::Vector3d b_W = Eigen::Vector3d::Zero();
  double radius_m = 0.0;
};

/// Pose of one person at one instant.
struct BodyState {
  std::array<BodyCapsule, kNumBodyParts> parts;  ///< Indexed by BodyPart.
  /// Centre of the axis-aligned bounding box of all parts.
  Eigen::Vector3d centre_W = Eigen::Vector3d::Zero();
  /// Half-axes of an axis-aligned ellipsoid centred at centre_W that contains
  /// every part entirely.
  Eigen::Vector3d ellipsoid_half_axes_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d velocity_W = Eigen::Vector3d::Zero();  ///< Of the feet position (m/s).
  double heading_rad = 0.0;
  ActionKind action = ActionKind::kStand;  ///< Action in progress (kStand when idle).
};

/// The person's pose at time t_s (any t; before the first action the start
/// pose, after the last action its final pose). Transitions between actions
/// are blended over a short time. Pure function of (person, t_s).
[[nodiscard]] BodyState EvaluatePerson(const Person& person, double t_s);

/// Colour of a part's surface for `person` (shirt, trousers, skin, shoes).
[[nodiscard]] Rgb PartColour(const Person& person, BodyPart part);

/// The axis-aligned bounding box of every part (the body box; centre_W is its centre).
[[nodiscard]] common::Box3 BodyBox(const BodyState& state);

/// Scene time (s) at which the person's last action ends.
[[nodiscard]] double ScriptEndS(const Person& person);

/// The fastest any point of the person moves (m/s) over [t0_s, t1_s],
/// measured per `step_s`: a point inside a capsule at t + dt lies within the
/// larger of its ends' displacements of the capsule at t (the segment moves
/// by no more anywhere, and the radius stays), so the largest end
/// displacement per step bounds every point's. What a pipeline's
/// max_speed_mps must cover for these people.
[[nodiscard]] double FastestPartSpeed(const Person& person, double t0_s, double t1_s,
                                      double step_s = 0.002);

/// Fills centre_W and ellipsoid_half_axes_m from the parts.
void ComputeBoundingEllipsoid(BodyState* state);

}  // namespace hg::sim
