#include "geometry/mesh.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "common/config_error.h"

namespace hg::geometry {

TriangleMesh TriangleMesh::Box(const Eigen::Vector3d& min, const Eigen::Vector3d& max) {
  TriangleMesh mesh;
  // Vertex i has coordinate bit 0 -> x, bit 1 -> y, bit 2 -> z (0 = min, 1 = max).
  mesh.vertices.reserve(8);
  for (int i = 0; i < 8; ++i) {
    mesh.vertices.emplace_back((i & 1) ? max.x() : min.x(), (i & 2) ? max.y() : min.y(),
                               (i & 4) ? max.z() : min.z());
  }
  // Two triangles per face, counter-clockwise seen from outside (outward normals).
  mesh.triangles = {
      {0, 2, 3}, {0, 3, 1},  // z = min
      {4, 5, 7}, {4, 7, 6},  // z = max
      {0, 1, 5}, {0, 5, 4},  // y = min
      {2, 6, 7}, {2, 7, 3},  // y = max
      {0, 4, 6}, {0, 6, 2},  // x = min
      {1, 3, 7}, {1, 7, 5},  // x = max
  };
  return mesh;
}

void TriangleMesh::Append(const TriangleMesh& other) {
  const int offset = static_cast<int>(vertices.size());
  vertices.insert(vertices.end(), other.vertices.begin(), other.vertices.end());
  triangles.reserve(triangles.size() + other.triangles.size());
  for (const auto& t : other.triangles) {
    triangles.push_back({t[0] + offset, t[1] + offset, t[2] + offset});
  }
}

namespace {

constexpr std::string_view kWhitespace = " \t\r\v\f";

// Splits off the next whitespace-separated token of `rest`; empty at the end.
std::string_view NextToken(std::string_view& rest) {
  const size_t begin = rest.find_first_not_of(kWhitespace);
  if (begin == std::string_view::npos) {
    rest = {};
    return {};
  }
  rest.remove_prefix(begin);
  const size_t end = std::min(rest.find_first_of(kWhitespace), rest.size());
  const std::string_view token = rest.substr(0, end);
  rest.remove_prefix(end);
  return token;
}

// Parses a whole token as a finite double; NaN and infinities are rejected
// because they would poison every depth bound computed from the mesh.
bool ParseDouble(std::string_view token, double* value) {
  if (!token.empty() && token.front() == '+') token.remove_prefix(1);
  const char* end = token.data() + token.size();
  const auto [ptr, ec] = std::from_chars(token.data(), end, *value);
  return ec == std::errc() && ptr == end && std::isfinite(*value);
}

bool ParseInt(std::string_view token, long long* value) {
  if (!token.empty() && token.front() == '+') token.remove_prefix(1);
  const char* end = token.data() + token.size();
  const auto [ptr, ec] = std::from_chars(token.data(), end, *value);
  return ec == std::errc() && ptr == end;
}

}  // namespace

TriangleMesh LoadObj(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw common::ConfigError::At(path, 0, "cannot open");

  TriangleMesh mesh;
  std::string line;
  std::vector<int> polygon;
  int line_number = 0;
  while (std::getline(in, line)) {
    ++line_number;
    std::string_view rest(line);
    if (const size_t hash = rest.find('#'); hash != std::string_view::npos) {
      rest = rest.substr(0, hash);
    }
    const std::string_view keyword = NextToken(rest);
    if (keyword == "v") {
      // A fourth (w) or colour components may follow; only x y z matter here.
      Eigen::Vector3d p;
      for (int axis = 0; axis < 3; ++axis) {
        const std::string_view token = NextToken(rest);
        if (token.empty()) {
          throw common::ConfigError::At(path, line_number, "v: needs 3 numbers");
        }
        if (!ParseDouble(token, &p[axis])) {
          throw common::ConfigError::At(path, line_number,
                                        "v: bad number '" + std::string(token) + "'");
        }
      }
      mesh.vertices.push_back(p);
    } else if (keyword == "f") {
      polygon.clear();
      const long long vertex_count = static_cast<long long>(mesh.vertices.size());
      for (std::string_view token = NextToken(rest); !token.empty(); token = NextToken(rest)) {
        // Only the position index (before the first '/') is used; vt/vn are ignored.
        const std::string_view position = token.substr(0, token.find('/'));
        long long index = 0;
        if (!ParseInt(position, &index)) {
          throw common::ConfigError::At(path, line_number,
                                        "f: bad index '" + std::string(token) + "'");
        }
        // OBJ indices are 1-based; negative ones count back from the last vertex read.
        const long long zero_based = index > 0 ? index - 1 : vertex_count + index;
        if (index == 0 || zero_based < 0 || zero_based >= vertex_count) {
          throw common::ConfigError::At(path, line_number,
                                        "f: index " + std::to_string(index) + " out of range (" +
                                            std::to_string(vertex_count) + " vertices so far)");
        }
        polygon.push_back(static_cast<int>(zero_based));
      }
      if (polygon.size() < 3) {
        throw common::ConfigError::At(path, line_number, "f: needs at least 3 vertices");
      }
      for (size_t i = 1; i + 1 < polygon.size(); ++i) {
        mesh.triangles.push_back({polygon[0], polygon[i], polygon[i + 1]});
      }
    }
  }
  if (in.bad()) throw common::ConfigError::At(path, line_number, "read error");
  return mesh;
}

void WriteObj(const std::string& path, const TriangleMesh& mesh) {
  std::ofstream out(path);
  if (!out) throw common::ConfigError::At(path, 0, "cannot open for writing");
  // Shortest round-trip formatting so that LoadObj(WriteObj(m)) == m exactly.
  char buffer[64];
  auto write_number = [&](double x) {
    const auto result = std::to_chars(buffer, buffer + sizeof(buffer), x);
    out.write(buffer, result.ptr - buffer);
  };
  for (const Eigen::Vector3d& p : mesh.vertices) {
    out << 'v';
    for (int axis = 0; axis < 3; ++axis) {
      out << ' ';
      write_number(p[axis]);
    }
    out << '\n';
  }
  for (const auto& t : mesh.triangles) {
    out << "f " << t[0] + 1 << ' ' << t[1] + 1 << ' ' << t[2] + 1 << '\n';
  }
  out.flush();
  if (!out) throw common::ConfigError::At(path, 0, "write failed");
}

}  // namespace hg::geometry
