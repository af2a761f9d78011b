#pragma once
/// @file
/// Hand-built bodies of 13 capsules for renderer tests and benchmarks: they do
/// not depend on the body model, so a renderer test fails only for the renderer.

#include <Eigen/Core>

#include "sim/body.h"

namespace hg::testing {

/// A walking person: feet at `base`, facing `heading` (radians from +x), gait
/// phase `phase` (radians; 0 = legs together).
[[nodiscard]] sim::BodyState WalkingBody(const Eigen::Vector3d& base, double heading, double phase);

/// A person standing at `base` facing +x with the arms slightly away from the body.
[[nodiscard]] sim::BodyState StandingBody(const Eigen::Vector3d& base);

}  // namespace hg::testing
