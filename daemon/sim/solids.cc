#include "sim/solids.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <type_traits>
#include <vector>

#include <Eigen/Geometry>

namespace hg::sim {
namespace {

using Eigen::Vector3d;

/// Axis lengths below this (metres) make cylinders and capsules spheres: the
/// axis direction is then numerically meaningless.
constexpr double kDegenerateAxisM = 1e-12;

/// A point this close to the surface (relative to the solid's size, at least
/// 1 m) counts as on it: points computed on a surface are inside despite rounding.
constexpr double kOnSurfaceRelTol = 1e-9;

/// Unit vectors e1, e2 completing `axis` (unit) to a right-handed frame.
void OrthonormalBasis(const Vector3d& axis, Vector3d* e1, Vector3d* e2) {
  const Vector3d helper = std::abs(axis.x()) < 0.6 ? Vector3d::UnitX() : Vector3d::UnitY();
  *e1 = axis.cross(helper).normalized();
  *e2 = axis.cross(*e1);
}

/// Squared distance from p to segment a-b.
double SegmentDistanceSquared(const Vector3d& a, const Vector3d& b, const Vector3d& p) {
  const Vector3d e = b - a;
  const double len2 = e.squaredNorm();
  double s = 0.0;
  if (len2 > 0.0) {
    s = std::clamp((p - a).dot(e) / len2, 0.0, 1.0);
  }
  return (a + s * e - p).squaredNorm();
}

/// Squared distance from p to triangle (a, b, c) (closest-point by regions).
double TriangleDistanceSquared(const Vector3d& p, const Vector3d& a, const Vector3d& b,
                               const Vector3d& c) {
  const Vector3d ab = b - a;
  const Vector3d ac = c - a;
  const Vector3d n = ab.cross(ac);
  const double n2 = n.squaredNorm();
  if (n2 > 0.0) {
    // Inside the prism over the triangle: distance to the plane.
    const Vector3d ap = p - a;
    const bool in_ab = n.dot(ab.cross(ap)) >= 0.0;
    const bool in_bc = n.dot((c - b).cross(p - b)) >= 0.0;
    const bool in_ca = n.dot((a - c).cross(p - c)) >= 0.0;
    if (in_ab && in_bc && in_ca) {
      const double d = n.dot(ap);
      return d * d / n2;
    }
  }
  return std::min({SegmentDistanceSquared(a, b, p), SegmentDistanceSquared(b, c, p),
                   SegmentDistanceSquared(c, a, p)});
}

/// Ray-triangle intersection (Moller-Trumbore) for t > 0.
bool RayHitsTriangle(const Vector3d& origin, const Vector3d& dir, const Vector3d& a,
                     const Vector3d& b, const Vector3d& c) {
  const Vector3d e1 = b - a;
  const Vector3d e2 = c - a;
  const Vector3d pv = dir.cross(e2);
  const double det = e1.dot(pv);
  if (det == 0.0) {
    return false;
  }
  const double inv = 1.0 / det;
  const Vector3d tv = origin - a;
  const double u = tv.dot(pv) * inv;
  if (u < 0.0 || u > 1.0) {
    return false;
  }
  const Vector3d qv = tv.cross(e1);
  const double v = dir.dot(qv) * inv;
  if (v < 0.0 || u + v > 1.0) {
    return false;
  }
  return e2.dot(qv) * inv > 0.0;
}

bool MeshContains(const geometry::TriangleMesh& mesh, const Vector3d& p) {
  if (mesh.triangles.empty()) {
    return false;
  }
  common::Box3 box{Vector3d::Constant(std::numeric_limits<double>::infinity()),
                   Vector3d::Constant(-std::numeric_limits<double>::infinity())};
  for (const Vector3d& v : mesh.vertices) {
    box.min = box.min.cwiseMin(v);
    box.max = box.max.cwiseMax(v);
  }
  const double scale = std::max(1.0, (box.max - box.min).maxCoeff());
  const double tol = kOnSurfaceRelTol * scale;
  if (((p.array() < box.min.array() - tol) || (p.array() > box.max.array() + tol)).any()) {
    return false;
  }
  // Points on the surface are inside ("inside or on"); parity is unreliable there.
  for (const auto& t : mesh.triangles) {
    if (TriangleDistanceSquared(p, mesh.vertices[t[0]], mesh.vertices[t[1]], mesh.vertices[t[2]]) <=
        tol * tol) {
      return true;
    }
  }
  // Parity along three fixed directions with irrational-looking components,
  // majority vote: a ray that grazes an edge or a vertex (measure zero for one
  // direction) can flip one count, not two.
  static const std::array<Vector3d, 3> kDirections = {
      Vector3d(0.5773672, 0.3141593, 0.7539212).normalized(),
      Vector3d(-0.2718282, 0.8660261, 0.4192058).normalized(),
      Vector3d(0.6931472, -0.4142136, -0.5887302).normalized()};
  int inside_votes = 0;
  for (const Vector3d& dir : kDirections) {
    int crossings = 0;
    for (const auto& t : mesh.triangles) {
      if (RayHitsTriangle(p, dir, mesh.vertices[t[0]], mesh.vertices[t[1]], mesh.vertices[t[2]])) {
        ++crossings;
      }
    }
    inside_votes += crossings % 2;
  }
  return inside_votes >= 2;
}

/// Adds the quad (i0, i1, i2, i3), counter-clockwise seen from outside, as two triangles.
void AddQuad(geometry::TriangleMesh* mesh, int i0, int i1, int i2, int i3) {
  mesh->triangles.push_back({i0, i1, i2});
  mesh->triangles.push_back({i0, i2, i3});
}

// Capsule and sphere tessellation, and why it circumscribes.
//
// Frame: axis unit vector w from a to b, L = |b - a|, and e1, e2 completing it.
// The mesh is a stack of rings; every ring is a regular n-gon (n = segments)
// perpendicular to w, centred on the axis, vertex k at angle 2 pi k / n, so
// corresponding vertices of consecutive rings lie in the same half-plane
// through the axis. Between two rings the side faces are planar isosceles
// trapezoids (two parallel edges), so the horizontal cross-section of the
// mesh at any height h between the rings is again a regular n-gon whose vertex
// radius interpolates linearly: the solid's cross-section at height h is the
// n-gon of vertex radius V(h), whose inscribed circle has radius
// V(h) cos(pi / n).
//
// Cylinder part (0 <= h <= L): V = rho / cos(pi / n) with rho = r / cos(d / 2)
// below, so the inscribed circle has radius rho >= r: it contains the disk of
// radius r that is the capsule's cross-section there.
//
// Hemisphere at b (h = L + z, 0 <= z <= r): the meridian profile is the
// polygon with vertices rho (cos phi_j, sin phi_j), phi_j = j d, d = pi / (2 m),
// j = 0..m (m latitude bands). Each profile edge spans the angle d, so its
// line lies at distance rho cos(d / 2) = r from the centre. The convex polygon
// Q with these vertices and the centre is bounded by those edges and by the two
// axes, all of whose half-planes contain the quarter disk of radius r; hence Q
// contains it, and at each height z the profile radius g(z) (Q's width there)
// is at least sqrt(r^2 - z^2), the ball's cross-section radius. The ring at
// phi_j has vertex radius rho cos(phi_j) / cos(pi / n), so with the linear
// interpolation above, the mesh's cross-section at height z has inscribed
// radius g(z) >= sqrt(r^2 - z^2). The top ring (phi = pi / 2) is the pole
// point at height rho >= r. The hemisphere at a is the mirror image.
//
// Together every cross-section of the capsule perpendicular to its axis lies
// in the mesh's cross-section at the same height, so the capsule lies inside
// the closed mesh: vertex radius scale 1 / (cos(pi / n) cos(pi / (4 m))).
geometry::TriangleMesh TessellateCapsule(const Vector3d& a, const Vector3d& b, double r, int n) {
  const int m = std::max(2, n / 4);  // Latitude bands per hemisphere.
  const double d = M_PI / (2.0 * m);
  const double rho = r / std::cos(0.5 * d);
  const double polygon_scale = 1.0 / std::cos(M_PI / n);

  Vector3d w = b - a;
  const double length = w.norm();
  if (length > kDegenerateAxisM) {
    w /= length;
  } else {
    w = Vector3d::UnitZ();
  }
  Vector3d e1;
  Vector3d e2;
  OrthonormalBasis(w, &e1, &e2);

  geometry::TriangleMesh mesh;
  // Rings from the south pole (at a) to the north pole (at b). Pole rings are
  // single vertices; the equator rings of both hemispheres are shared by the
  // cylinder part (dropped at b when the capsule is a sphere).
  struct Ring {
    Vector3d centre;
    double radius;  // Vertex radius; 0 for a pole.
  };
  std::vector<Ring> rings;
  for (int j = m; j >= 0; --j) {
    const double phi = j * d;
    rings.push_back({a - rho * std::sin(phi) * w, rho * std::cos(phi) * polygon_scale});
  }
  const bool sphere = length <= kDegenerateAxisM;
  for (int j = sphere ? 1 : 0; j <= m; ++j) {
    const double phi = j * d;
    rings.push_back({b + rho * std::sin(phi) * w, rho * std::cos(phi) * polygon_scale});
  }
  // The poles (j = m) have cos(phi) ~ 6e-17: make them exact single points.
  std::vector<int> first_index;
  for (std::size_t i = 0; i < rings.size(); ++i) {
    first_index.push_back(static_cast<int>(mesh.vertices.size()));
    const bool pole = i == 0 || i + 1 == rings.size();
    if (pole) {
      mesh.vertices.push_back(rings[i].centre);
      continue;
    }
    for (int k = 0; k < n; ++k) {
      const double angle = 2.0 * M_PI * k / n;
      mesh.vertices.push_back(rings[i].centre +
                              rings[i].radius * (std::cos(angle) * e1 + std::sin(angle) * e2));
    }
  }
  // Vertex k of ring i at angle theta_k = 2 pi k / n about w (e1 -> e2 is
  // counter-clockwise seen from the +w side).
  const int last = static_cast<int>(rings.size()) - 1;
  for (int i = 0; i < last; ++i) {
    for (int k = 0; k < n; ++k) {
      const int k1 = (k + 1) % n;
      if (i == 0) {
        // South pole fan: outward normal points along -w.
        mesh.triangles.push_back({first_index[0], first_index[1] + k1, first_index[1] + k});
      } else if (i + 1 == last) {
        // North pole fan.
        mesh.triangles.push_back({first_index[i] + k, first_index[i] + k1, first_index[last]});
      } else {
        AddQuad(&mesh, first_index[i] + k, first_index[i] + k1, first_index[i + 1] + k1,
                first_index[i + 1] + k);
      }
    }
  }
  return mesh;
}

// Cylinder: the prism over the regular n-gon of vertex radius r / cos(pi / n),
// whose inscribed circle has radius r, closed by the two flat caps; it
// contains every cross-section (disk of radius r) between the caps.
geometry::TriangleMesh TessellateCylinder(const CylinderSolid& c, int n) {
  const Vector3d w = (c.b_W - c.a_W).normalized();
  Vector3d e1;
  Vector3d e2;
  OrthonormalBasis(w, &e1, &e2);
  const double radius = c.radius_m / std::cos(M_PI / n);
  geometry::TriangleMesh mesh;
  const int centre_a = 0;
  const int centre_b = 1;
  mesh.vertices.push_back(c.a_W);
  mesh.vertices.push_back(c.b_W);
  for (int k = 0; k < n; ++k) {
    const double angle = 2.0 * M_PI * k / n;
    const Vector3d offset = radius * (std::cos(angle) * e1 + std::sin(angle) * e2);
    mesh.vertices.push_back(c.a_W + offset);  // 2 + 2k
    mesh.vertices.push_back(c.b_W + offset);  // 3 + 2k
  }
  for (int k = 0; k < n; ++k) {
    const int k1 = (k + 1) % n;
    const int a0 = 2 + 2 * k;
    const int a1 = 2 + 2 * k1;
    mesh.triangles.push_back({centre_a, a1, a0});
    mesh.triangles.push_back({centre_b, a0 + 1, a1 + 1});
    AddQuad(&mesh, a0, a1, a1 + 1, a0 + 1);
  }
  return mesh;
}

}  // namespace

common::Box3 Bounds(const SolidGeometry& solid) {
  return std::visit(
      [](const auto& s) -> common::Box3 {
        using T = std::decay_t<decltype(s)>;
        common::Box3 box;
        if constexpr (std::is_same_v<T, BoxSolid>) {
          const Vector3d extent = s.R_WB.cwiseAbs() * s.half_extents_m;
          box.min = s.centre_W - extent;
          box.max = s.centre_W + extent;
        } else if constexpr (std::is_same_v<T, CylinderSolid>) {
          const Vector3d axis = s.b_W - s.a_W;
          const double len = axis.norm();
          Vector3d extent = Vector3d::Constant(s.radius_m);
          if (len > kDegenerateAxisM) {
            // A disk of radius r with unit normal w extends r sqrt(1 - w_i^2) along axis i.
            const Vector3d w = axis / len;
            for (int i = 0; i < 3; ++i) {
              extent[i] = s.radius_m * std::sqrt(std::max(0.0, 1.0 - w[i] * w[i]));
            }
          }
          box.min = s.a_W.cwiseMin(s.b_W) - extent;
          box.max = s.a_W.cwiseMax(s.b_W) + extent;
        } else if constexpr (std::is_same_v<T, CapsuleSolid>) {
          box.min = s.a_W.cwiseMin(s.b_W) - Vector3d::Constant(s.radius_m);
          box.max = s.a_W.cwiseMax(s.b_W) + Vector3d::Constant(s.radius_m);
        } else {
          if (s.mesh.vertices.empty()) {
            return box;
          }
          box.min = box.max = s.mesh.vertices.front();
          for (const Vector3d& v : s.mesh.vertices) {
            box.min = box.min.cwiseMin(v);
            box.max = box.max.cwiseMax(v);
          }
        }
        return box;
      },
      solid);
}

bool Contains(const SolidGeometry& solid, const Vector3d& p_W) {
  return std::visit(
      [&p_W](const auto& s) -> bool {
        using T = std::decay_t<decltype(s)>;
        if constexpr (std::is_same_v<T, BoxSolid>) {
          const Vector3d local = s.R_WB.transpose() * (p_W - s.centre_W);
          const double tol = kOnSurfaceRelTol * std::max(1.0, s.half_extents_m.maxCoeff());
          return (local.cwiseAbs().array() <= s.half_extents_m.array() + tol).all();
        } else if constexpr (std::is_same_v<T, CylinderSolid>) {
          const Vector3d axis = s.b_W - s.a_W;
          const double len2 = axis.squaredNorm();
          if (len2 <= kDegenerateAxisM * kDegenerateAxisM) {
            // Degenerate: treated as the sphere around it, as by Tessellate.
            return (p_W - s.a_W).norm() <= s.radius_m * (1.0 + kOnSurfaceRelTol);
          }
          const double tol = kOnSurfaceRelTol * std::max({1.0, s.radius_m, std::sqrt(len2)});
          const double along = (p_W - s.a_W).dot(axis) / std::sqrt(len2);
          if (along < -tol || along > std::sqrt(len2) + tol) {
            return false;
          }
          const Vector3d radial = (p_W - s.a_W) - (along / std::sqrt(len2)) * axis;
          return radial.norm() <= s.radius_m + tol;
        } else if constexpr (std::is_same_v<T, CapsuleSolid>) {
          const double tol = kOnSurfaceRelTol * std::max(1.0, s.radius_m);
          return std::sqrt(SegmentDistanceSquared(s.a_W, s.b_W, p_W)) <= s.radius_m + tol;
        } else {
          return MeshContains(s.mesh, p_W);
        }
      },
      solid);
}

geometry::TriangleMesh Tessellate(const SolidGeometry& solid, int segments) {
  const int n = std::max(8, segments);
  return std::visit(
      [n](const auto& s) -> geometry::TriangleMesh {
        using T = std::decay_t<decltype(s)>;
        if constexpr (std::is_same_v<T, BoxSolid>) {
          geometry::TriangleMesh mesh =
              geometry::TriangleMesh::Box(-s.half_extents_m, s.half_extents_m);
          for (Vector3d& v : mesh.vertices) {
            v = s.centre_W + s.R_WB * v;
          }
          return mesh;
        } else if constexpr (std::is_same_v<T, CylinderSolid>) {
          if ((s.b_W - s.a_W).norm() <= kDegenerateAxisM) {
            return TessellateCapsule(s.a_W, s.a_W, s.radius_m, n);
          }
          return TessellateCylinder(s, n);
        } else if constexpr (std::is_same_v<T, CapsuleSolid>) {
          return TessellateCapsule(s.a_W, s.b_W, s.radius_m, n);
        } else {
          return s.mesh;
        }
      },
      solid);
}

}  // namespace hg::sim
