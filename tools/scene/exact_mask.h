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
///
/// A pixel is background only when GJK certifies a plane separating the shape
/// from the pixel's viewing pyramid (apex at the camera centre, through the
/// closed pixel square, truncated beyond the shape) with a gap above 1e-9 of
/// the problem's size; touching, near-touching and any numerical doubt give
/// foreground. Pixels of a shape whose bounding box reaches behind the camera
/// plane are all examined; otherwise only the projected bounding box is.
/// Precondition: K(2, :) == (0, 0, 1). Thread-compatible (pure function).
[[nodiscard]] common::ImageU8 RenderExactMask(const geometry::CameraModel& pinhole,
                                              const std::vector<Shape>& shapes);

/// Same through the lens: a pixel of the distorted image is foreground iff some
/// shape point projects (with distortion) inside it. Used to test conservative
/// undistortion. Slower; for small images.
///
/// The rays of a distorted pixel are the undistorted image of its square. That
/// set is replaced by a convex quadrilateral of normalised coordinates that
/// contains it: 16 boundary samples per edge are undistorted by Newton's method
/// to a residual of 1e-12; each side of the quad is the line through two
/// undistorted corners, pushed out past every sample and then by the largest
/// gap between consecutive samples (which bounds how far the boundary curve
/// between two samples can bulge for any lens whose inverse map is smooth at
/// the scale of 1/16 pixel). The mask is therefore a superset of the exact
/// one: it may gain pixels whose square the shapes miss by a small fraction of
/// a pixel, never lose one. Where the lens model cannot be inverted (Newton
/// fails, or lands where the distortion's Jacobian is not positive, i.e. past a
/// fold of the polynomial model) or the quad degenerates, the pixel is
/// foreground. Assumes the distortion is one-to-one over the rays that reach
/// the image, as for a real lens; rays that the polynomial model folds back
/// into the image from outside the field of view are not seen. With all
/// distortion coefficients zero this is exactly RenderExactMask(camera,
/// shapes). Thread-compatible (pure function).
[[nodiscard]] common::ImageU8 RenderExactDistortedMask(const geometry::CameraModel& camera,
                                                       const std::vector<Shape>& shapes);

}  // namespace hg::scene
