#pragma once
/// @file
/// The exact field-of-view volume of one camera in a polyhedral cell with
/// polyhedral obstacles, its gradient with respect to the camera pose, and the
/// definitely-object-free volume when an object (a person as capsules) stands
/// in the cell: the camera-placement objective of Ober-Gecks et al., "Fast
/// multi-camera reconstruction and surveillance with human tracking and
/// optimized camera configurations".
///
/// What is measured. The camera sees a point p of the cell when p lies inside
/// its frustum (the four side planes through the image borders, unbounded in
/// depth) and the segment from the camera centre x to p crosses no obstacle
/// surface. The cell boundary is transparent: it only says which space counts
/// (an opaque wall is an obstacle), and x may lie inside the cell, outside it
/// (as the paper cell's cameras do) or on its boundary. With x inside a convex
/// cell the seen set is the paper's star-shaped polyhedron, whose volume is
///   sum over the seen parts P of the faces F: (1/3) d(x, plane(F)) area(P).
///
/// How it is computed exactly (no sampling, no rasterisation). Every triangle
/// is moved into the camera frame, clipped in 3D by the four frustum planes and
/// projected to normalised image coordinates w = (u, v, 1) = p_C / z. A plane
/// not through x has an inverse depth that is affine in the image,
/// 1/z = m . w, so (i) "G is in front of F" is a half-plane of the image, the
/// side of the line (m_G - m_F) . w = 0, and (ii) the cone from x over a convex
/// image polygon w_0..w_{n-1} up to the plane m has the closed-form volume
///   (1/3) sum_i t_0 t_i t_{i+1} area(w_0, w_i, w_{i+1}),  t = 1 / (m . w).
/// In image coordinates dV = z^2 dz du dv, so a viewing ray w adds the
/// integral of z^2 over its seen part of the cell: s z^3 / 3 for each crossing
/// of the cell boundary in front of the first obstacle hit F (s = +1 where the
/// ray leaves the cell, -1 where it enters), and z_F^3 / 3 if F's point is in
/// the cell, which is the sum of s over the crossings behind F (the ray ends
/// outside). Summed over triangles:
///   V = sum_T s_T cone_T(footprint T)                       (the empty cell)
///     + sum_F sum_T s_T [cone_F(R_FT) - cone_T(R_FT)],
///   R_FT = seen(F) n footprint(T) n {T not in front of F},
/// over cell triangles T and obstacle triangles F: the cell crossings hidden
/// by F are taken back and F's own depth comes in with their signs. seen(F)
/// is F's footprint minus, for every other triangle G, the convex polygon
/// footprint(G) n {G in front of F}: a set of disjoint convex pieces, cut by
/// half-plane clipping in double precision (a convex piece minus a convex
/// polygon is at most one convex piece per polygon edge). Every polygon edge
/// keeps the line it came from (a triangle edge's plane through x, a frustum
/// side, a depth cut), so clipping never derives a line from two nearby
/// vertices. No depth order is needed: intersecting and cyclically
/// overlapping obstacles are handled; faces on one plane are ordered by index
/// so that exactly one of them counts. The result is exact up to rounding:
/// pieces below 1e-14 of the image area are dropped (far below a pixel,
/// ~1e-12 m^3 in a 4 m cell); planes that agree to 1e-10 are one plane.
///
/// Speed-ups that do not change the result: back faces of closed obstacle
/// components are culled (the faces that face the camera hide them), faces of
/// one convex component never hide each other, occluder candidates are found
/// per component (and through an image grid in large components) and rejected
/// by bounding boxes and depth ranges.
///
/// Gradient. The same computation runs on Eigen's forward-mode AutoDiff
/// scalars with six derivatives: every decision (clipping sides, what hides
/// what) is taken on the values, so the derivative is that of the volume with
/// the visibility combinatorics held fixed, which is the volume's gradient at
/// generic poses. The volume is not differentiable everywhere: where the
/// camera crosses the plane of a face, or a projected vertex crosses a
/// projected edge, the slope may jump. At exact coincidences (a mesh vertex on
/// a frustum plane, two projected edges on one line: symmetric set-ups) the
/// held-fixed derivative can differ from the volume's even where that exists;
/// moving the pose by ~1e-9 restores the generic case.
///
/// Object-free volume. An object in the cell (a person) hides its own space and
/// its shadow: the free volume is the seen volume with the object as one more
/// obstacle. Capsules enter as circumscribing polyhedra (CapsuleHullMesh), which
/// contain them, so the object and its shadow are only ever grown and the free
/// volume is never overestimated.

#include <memory>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "common/box.h"
#include "geometry/camera.h"
#include "geometry/mesh.h"

namespace hg::placement {

/// Camera pose: centre and orientation. The camera frame is OpenCV's, x right,
/// y down, z forward; columns of R_WC are the camera axes in the world. Value
/// type, thread-compatible.
struct CameraPose {
  Eigen::Vector3d position_W = Eigen::Vector3d::Zero();  ///< Camera centre (m).
  Eigen::Matrix3d R_WC = Eigen::Matrix3d::Identity();    ///< Camera -> world rotation.

  /// The pose of a calibrated camera (x_C = R_CW p_W + t_CW).
  [[nodiscard]] static CameraPose FromModel(const geometry::CameraModel& camera);
  /// Looks from `position_W` at `target_W`; `up_W` points upwards in the image
  /// (the convention of the cameras' `look_at` form). Precondition: the viewing
  /// direction is not parallel to `up_W`.
  [[nodiscard]] static CameraPose LookAt(const Eigen::Vector3d& position_W,
                                         const Eigen::Vector3d& target_W,
                                         const Eigen::Vector3d& up_W = Eigen::Vector3d::UnitZ());
};

/// Pinhole frustum: the image rectangle [-0.5, width - 0.5] x [-0.5, height - 0.5]
/// (pixel borders) seen through K. Distortion is not part of it (use the
/// pinhole part of a calibrated camera). Value type, thread-compatible.
struct Intrinsics {
  int width = 0;
  int height = 0;
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();

  [[nodiscard]] static Intrinsics FromModel(const geometry::CameraModel& camera);
};

/// A triangle mesh prepared for visibility: connected components (through
/// shared vertex indices), whether each is closed (every edge used once in each
/// direction) and convex, and closed components turned to outward normals.
/// Faces of closed components are one-sided (back faces culled), others are
/// seen from both sides. Immutable after construction; thread-safe to read.
class OccluderMesh {
 public:
  OccluderMesh() = default;
  /// @throws common::ConfigError when a triangle indexes a missing vertex or a
  /// vertex is not finite.
  explicit OccluderMesh(const geometry::TriangleMesh& mesh);

  /// Triangles with closed components oriented outwards.
  [[nodiscard]] const geometry::TriangleMesh& mesh() const { return mesh_; }
  [[nodiscard]] int NumComponents() const { return static_cast<int>(components_.size()); }
  /// Component of triangle i.
  [[nodiscard]] int ComponentOf(int triangle) const { return triangle_component_[triangle]; }

  /// One connected component: triangles [first_triangle, first_triangle +
  /// num_triangles) of mesh().
  struct Component {
    bool closed = false;
    bool convex = false;
    int first_triangle = 0;
    int num_triangles = 0;
    common::Box3 bounds;
  };
  [[nodiscard]] const Component& component(int c) const { return components_[c]; }

 private:
  geometry::TriangleMesh mesh_;
  std::vector<int> triangle_component_;
  std::vector<Component> components_;
};

/// The cell and its static obstacles. Immutable after construction;
/// thread-safe to read.
class FovScene {
 public:
  /// `cell`: a closed triangle mesh whose inside is the cell (need not be
  /// convex; every connected component is turned outwards here, so a cavity
  /// inside the cell belongs in `obstacles`). `obstacles`: any triangle
  /// meshes; closed components are solids, open ones thin sheets.
  /// @throws common::ConfigError when the cell mesh is not closed or has no
  /// volume, or on bad indices or non-finite vertices.
  FovScene(const geometry::TriangleMesh& cell, const geometry::TriangleMesh& obstacles);
  /// An axis-aligned box cell.
  /// @throws common::ConfigError when the box is not valid (max > min).
  FovScene(const common::Box3& cell, const geometry::TriangleMesh& obstacles);

  /// Cell boundary, outward normals.
  [[nodiscard]] const geometry::TriangleMesh& cell() const { return cell_; }
  [[nodiscard]] const OccluderMesh& obstacles() const { return obstacles_; }
  /// Volume of the cell (m^3).
  [[nodiscard]] double CellVolume() const { return cell_volume_m3_; }
  /// Axis-aligned bounds of the cell.
  [[nodiscard]] const common::Box3& CellBounds() const { return cell_bounds_; }

 private:
  geometry::TriangleMesh cell_;
  OccluderMesh obstacles_;
  double cell_volume_m3_ = 0.0;
  common::Box3 cell_bounds_;
};

/// Volume and its gradient with respect to the pose. gradient(0..2): d/d
/// position_W (m^2). gradient(3..5): d/d delta (m^3/rad) for the rotation
/// R_WC * Exp(delta), delta a rotation vector in the camera frame (delta.z()
/// rolls about the optical axis). Chain to other parameterisations with
/// RotationParameterDerivative.
struct VolumeGradient {
  double volume_m3 = 0.0;
  Eigen::Matrix<double, 6, 1> gradient = Eigen::Matrix<double, 6, 1>::Zero();
};

/// Counters of the last evaluation (for benchmarks and tests).
struct FovStats {
  int cell_faces = 0;      ///< Cell triangles inside the frustum.
  int obstacle_faces = 0;  ///< Obstacle triangles facing the camera, inside the frustum.
  int subtractions = 0;    ///< Convex occluder polygons subtracted.
  int max_pieces = 0;      ///< Largest piece set of one face.
};

/// Evaluates seen volumes. Holds scratch buffers that grow to the largest scene
/// seen and are reused (no allocation after warm-up). Thread-compatible: one
/// evaluator per thread; the scenes may be shared.
class FovEvaluator {
 public:
  FovEvaluator();
  ~FovEvaluator();
  FovEvaluator(FovEvaluator&&) noexcept;
  FovEvaluator& operator=(FovEvaluator&&) noexcept;
  FovEvaluator(const FovEvaluator&) = delete;
  FovEvaluator& operator=(const FovEvaluator&) = delete;

  /// Seen volume (m^3) of the cell. `object`, when given, is one more occluder
  /// (its own space is not seen either): the result is then the volume that the
  /// camera certifies free of the object. Precondition: intrinsics with
  /// positive size and an invertible upper-triangular K with K(2,2) == 1.
  [[nodiscard]] double Volume(const FovScene& scene, const CameraPose& pose,
                              const Intrinsics& intrinsics, const OccluderMesh* object = nullptr);

  /// Volume and gradient (see VolumeGradient); same volume as Volume().
  [[nodiscard]] VolumeGradient VolumeAndGradient(const FovScene& scene, const CameraPose& pose,
                                                 const Intrinsics& intrinsics,
                                                 const OccluderMesh* object = nullptr);

  [[nodiscard]] const FovStats& stats() const { return stats_; }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  FovStats stats_;
};

/// Seen volume of a calibrated camera (its pinhole part), with a fresh evaluator.
[[nodiscard]] double FovVolume(const FovScene& scene, const geometry::CameraModel& camera);

/// Segment a_W-b_W swept by a ball of radius_m.
struct Capsule {
  Eigen::Vector3d a_W = Eigen::Vector3d::Zero();
  Eigen::Vector3d b_W = Eigen::Vector3d::UnitZ();
  double radius_m = 0.1;
};

/// A closed convex triangle mesh (outward normals) that contains the capsule:
/// the convex hull of two copies, at a and b, of a latitude-longitude
/// polyhedron (`segments` >= 4 facets around, segments / 4 rings per
/// hemisphere) scaled so that its every face plane is at least radius_m (plus
/// a relative 1e-9 against rounding) from its centre. Its vertices lie that
/// much farther out: +7% of the radius with 12 segments, +4% with 16.
/// @throws common::ConfigError when radius_m <= 0, a point is not finite or
/// segments < 4.
[[nodiscard]] geometry::TriangleMesh CapsuleHullMesh(const Capsule& capsule, int segments = 12);

/// An object made of capsules (a person), as one occluder: the union of their
/// hulls, which contains the object.
[[nodiscard]] OccluderMesh CapsulesOccluder(std::span<const Capsule> capsules, int segments = 12);

/// Volume that one camera certifies free of the object: neither inside it nor
/// in its shadow (Volume with the object as an occluder).
[[nodiscard]] double ObjectFreeVolume(const FovScene& scene, const geometry::CameraModel& camera,
                                      const OccluderMesh& object);

/// Chains the rotation part of VolumeGradient to another parameter theta of
/// the orientation: given R_WC and dR_WC = d R_WC / d theta, returns
/// d V / d theta = grad_delta . vee(R_WC^T dR_WC).
[[nodiscard]] double RotationParameterDerivative(const Eigen::Matrix3d& R_WC,
                                                 const Eigen::Matrix3d& dR_WC,
                                                 const Eigen::Vector3d& grad_delta);

}  // namespace hg::placement
