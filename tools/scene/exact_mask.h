#pragma once
/// @file
/// Exact ground-truth silhouettes: a pixel is foreground iff some point of some
/// shape in front of the camera projects inside the pixel square
/// [u-0.5, u+0.5) x [v-0.5, v+0.5) (up to a tolerance that only adds pixels).

#include <vector>

#include "common/image.h"
#include "geometry/camera.h"
#include "scene/shapes.h"

namespace hg::scene {

/// Renders the exact mask (255 foreground, 0 background) of `shapes` in the
/// pinhole camera (distortion ignored), at camera.width x camera.height.
/// Parts of shapes behind the camera (z <= 0) do not contribute.
[[nodiscard]] common::ImageU8 RenderExactMask(const geometry::CameraModel& pinhole,
                                              const std::vector<Shape>& shapes);

/// Same through the lens: a pixel of the distorted image is foreground iff some
/// shape point projects (with distortion) inside it. Used to test conservative
/// undistortion. Slower; for small images.
[[nodiscard]] common::ImageU8 RenderExactDistortedMask(const geometry::CameraModel& camera,
                                                       const std::vector<Shape>& shapes);

}  // namespace hg::scene
