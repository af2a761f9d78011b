#pragma once
/// @file
/// Triangle meshes of static obstacles.

#include <array>
#include <cstddef>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace hg::geometry {

/// Indexed triangle mesh in world coordinates (metres). Value type, thread-compatible.
struct TriangleMesh {
  std::vector<Eigen::Vector3d> vertices;
  std::vector<std::array<int, 3>> triangles;

  /// Axis-aligned box mesh (12 triangles).
  static TriangleMesh Box(const Eigen::Vector3d& min, const Eigen::Vector3d& max);
  /// Appends another mesh.
  void Append(const TriangleMesh& other);
};

/// Most corners of one polygon (an OBJ face, an STL loop): cutting it into
/// triangles takes time quadratic in its corners and more (1000: under a
/// second at worst).
inline constexpr std::size_t kMaxPolygonCorners = 1000;

/// Appends to `mesh` triangles covering the planar polygon whose corners are
/// mesh vertices `polygon` (in order, at least 3), with its winding: ear
/// clipping in the polygon's plane, so that a concave face (an L-shaped
/// cap) gets no triangle outside it, as a fan from its first corner would. A
/// polygon that is degenerate or not simple, where no ear is left, is fanned
/// from there on.
void TriangulatePolygon(const std::vector<int>& polygon, TriangleMesh* mesh);

/// Loads a Wavefront OBJ file: `v` and `f` records (polygons are cut into
/// triangles by TriangulatePolygon(), concave ones too; `f` indices may be
/// negative or carry /vt/vn parts); other records are ignored. A UTF-8 byte
/// order mark is skipped.
/// @throws common::ConfigError naming the file and line on a missing file, a
/// malformed number, an index out of range, a face of more than
/// kMaxPolygonCorners corners or a control character (a NUL) in a line.
[[nodiscard]] TriangleMesh LoadObj(const std::string& path);

/// Loads an STL file, ASCII (`solid` ... `facet` / `outer loop` / `vertex x y z` ...
/// `endsolid`, several solids allowed, loops of more than 3 vertices are fanned)
/// or binary (80-byte header, little-endian triangle count and records). A file
/// whose size matches its binary triangle count is read as binary even when its
/// header starts with "solid", as some exporters write. Facet normals are
/// ignored; bit-identical corners share one vertex.
/// @throws common::ConfigError naming the file (and the line for ASCII) on a
/// missing file, a truncated or malformed file or a non-finite coordinate.
[[nodiscard]] TriangleMesh LoadStl(const std::string& path);

/// Loads an OBJ or STL mesh, chosen by the extension (`.obj` or `.stl`, any case).
/// @throws common::ConfigError on another extension or any load error.
[[nodiscard]] TriangleMesh LoadMesh(const std::string& path);

/// Writes a mesh as OBJ.
void WriteObj(const std::string& path, const TriangleMesh& mesh);

}  // namespace hg::geometry
