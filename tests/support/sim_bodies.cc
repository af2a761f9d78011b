#include "support/sim_bodies.h"

#include <algorithm>
#include <cmath>
#include <random>

namespace hg::testing {

using Eigen::Vector3d;
using sim::BodyPart;
using sim::BodyState;

BodyState WalkingBody(const Vector3d& base, double heading, double phase) {
  const Vector3d fwd(std::cos(heading), std::sin(heading), 0.0);
  const Vector3d side(-fwd.y(), fwd.x(), 0.0);
  const Vector3d up = Vector3d::UnitZ();
  const double swing = 0.35 * std::sin(phase);
  BodyState body;
  auto set = [&body](BodyPart part, const Vector3d& a, const Vector3d& b, double r) {
    body.parts[static_cast<int>(part)] = {part, a, b, r};
  };
  const Vector3d hip = base + 0.95 * up;
  const Vector3d neck = base + 1.45 * up;
  set(BodyPart::kHead, base + 1.6 * up, base + 1.7 * up, 0.1);
  set(BodyPart::kTorso, base + 1.15 * up, neck, 0.16);
  set(BodyPart::kPelvis, hip - 0.08 * side, hip + 0.08 * side, 0.14);
  for (int s = -1; s <= 1; s += 2) {
    const bool left = s > 0;
    const Vector3d shoulder = neck - 0.05 * up + 0.2 * s * side;
    const Vector3d elbow = shoulder - 0.3 * up - 0.15 * s * swing * fwd;
    const Vector3d hand = elbow - 0.28 * up - 0.3 * s * swing * fwd + 0.05 * fwd;
    set(left ? BodyPart::kUpperArmLeft : BodyPart::kUpperArmRight, shoulder, elbow, 0.05);
    set(left ? BodyPart::kForearmLeft : BodyPart::kForearmRight, elbow, hand, 0.045);
    const Vector3d h = hip + 0.1 * s * side;
    const Vector3d knee = h - 0.45 * up + 0.2 * s * swing * fwd;
    const Vector3d ankle = base + 0.1 * s * side + 0.08 * up + 0.35 * s * swing * fwd;
    set(left ? BodyPart::kThighLeft : BodyPart::kThighRight, h, knee, 0.08);
    set(left ? BodyPart::kShinLeft : BodyPart::kShinRight, knee, ankle, 0.06);
    set(left ? BodyPart::kFootLeft : BodyPart::kFootRight, ankle - 0.04 * up,
        ankle - 0.04 * up + 0.18 * fwd, 0.045);
  }
  return body;
}

BodyState StandingBody(const Vector3d& base) {
  const Vector3d up = Vector3d::UnitZ();
  const Vector3d side = Vector3d::UnitY();
  const Vector3d fwd = Vector3d::UnitX();
  BodyState body;
  auto set = [&body](BodyPart part, const Vector3d& a, const Vector3d& b, double r) {
    body.parts[static_cast<int>(part)] = {part, a, b, r};
  };
  const Vector3d hip = base + 0.95 * up;
  const Vector3d neck = base + 1.45 * up;
  set(BodyPart::kHead, base + 1.6 * up, base + 1.7 * up, 0.1);
  set(BodyPart::kTorso, base + 1.15 * up, neck, 0.16);
  set(BodyPart::kPelvis, hip - 0.08 * side, hip + 0.08 * side, 0.14);
  for (int s = -1; s <= 1; s += 2) {
    const bool left = s > 0;
    const Vector3d shoulder = neck - 0.05 * up + 0.2 * s * side;
    const Vector3d elbow = shoulder - 0.3 * up + 0.08 * s * side;
    const Vector3d hand = elbow - 0.28 * up + 0.05 * fwd;
    set(left ? BodyPart::kUpperArmLeft : BodyPart::kUpperArmRight, shoulder, elbow, 0.05);
    set(left ? BodyPart::kForearmLeft : BodyPart::kForearmRight, elbow, hand, 0.045);
    const Vector3d h = hip + 0.1 * s * side;
    const Vector3d knee = h - 0.45 * up;
    const Vector3d ankle = base + 0.1 * s * side + 0.08 * up;
    set(left ? BodyPart::kThighLeft : BodyPart::kThighRight, h, knee, 0.08);
    set(left ? BodyPart::kShinLeft : BodyPart::kShinRight, knee, ankle, 0.06);
    set(left ? BodyPart::kFootLeft : BodyPart::kFootRight, ankle - 0.04 * up,
        ankle - 0.04 * up + 0.18 * fwd, 0.045);
  }
  return body;
}

std::vector<Vector3d> PointsInPeople(const sim::Scene& scene, double t_s, int per_part,
                                     std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::vector<Vector3d> points;
  for (const sim::Person& person : scene.people) {
    const BodyState body = sim::EvaluatePerson(person, t_s);
    for (const sim::BodyCapsule& c : body.parts) {
      for (int i = 0; i < per_part;) {
        // Rejection sampling in the capsule's bounding box.
        const Vector3d lo = c.a_W.cwiseMin(c.b_W).array() - c.radius_m;
        const Vector3d hi = c.a_W.cwiseMax(c.b_W).array() + c.radius_m;
        const Vector3d p = lo + Vector3d(u01(rng), u01(rng), u01(rng)).cwiseProduct(hi - lo);
        const Vector3d ab = c.b_W - c.a_W;
        const double s = ab.squaredNorm() > 0
                             ? std::clamp((p - c.a_W).dot(ab) / ab.squaredNorm(), 0.0, 1.0)
                             : 0.0;
        if ((c.a_W + s * ab - p).norm() > c.radius_m) continue;
        points.push_back(p);
        ++i;
      }
    }
  }
  return points;
}

}  // namespace hg::testing
