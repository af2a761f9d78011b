#pragma once
/// @file
/// Triangle meshes of static obstacles.

#include <array>
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

/// Loads a Wavefront OBJ file: `v` and `f` records (polygons are fanned into
/// triangles; `f` indices may be negative or carry /vt/vn parts); other records
/// are ignored.
/// @throws common::ConfigError naming the file and line on a missing file, a
/// malformed number or an index out of range.
[[nodiscard]] TriangleMesh LoadObj(const std::string& path);

/// Writes a mesh as OBJ.
void WriteObj(const std::string& path, const TriangleMesh& mesh);

}  // namespace hg::geometry
