#include "geometry/mesh.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "common/check.h"
#include "common/config_error.h"
#include "common/input_file.h"

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

// The parts of a face corner after its position index: none, "/vt",
// "//vn" or "/vt/vn", each present index an integer.
bool ValidTextureAndNormal(std::string_view corner) {
  const size_t first = corner.find('/');
  if (first == std::string_view::npos) return true;
  std::string_view rest = corner.substr(first + 1);
  const size_t second = rest.find('/');
  const std::string_view texture = rest.substr(0, second);
  long long unused = 0;
  if (!texture.empty() && !ParseInt(texture, &unused)) return false;
  if (second == std::string_view::npos) return !texture.empty();
  const std::string_view normal = rest.substr(second + 1);
  return ParseInt(normal, &unused);
}

}  // namespace

void TriangulatePolygon(const std::vector<int>& polygon, TriangleMesh* mesh) {
  HG_CHECK(polygon.size() >= 3);
  const std::vector<Eigen::Vector3d>& v = mesh->vertices;
  if (polygon.size() == 3) {
    mesh->triangles.push_back({polygon[0], polygon[1], polygon[2]});
    return;
  }
  // The plane's normal (Newell), and the two axes it is seen along best.
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < polygon.size(); ++i) {
    const Eigen::Vector3d& a = v[polygon[i]];
    const Eigen::Vector3d& b = v[polygon[(i + 1) % polygon.size()]];
    normal += Eigen::Vector3d((a.y() - b.y()) * (a.z() + b.z()), (a.z() - b.z()) * (a.x() + b.x()),
                              (a.x() - b.x()) * (a.y() + b.y()));
  }
  int drop = 0;
  normal.cwiseAbs().maxCoeff(&drop);
  const int ax = (drop + 1) % 3, ay = (drop + 2) % 3;
  // Counter-clockwise in (ax, ay) when the normal points along +drop.
  const double orientation = normal[drop] >= 0.0 ? 1.0 : -1.0;
  auto cross = [&](int a, int b, int c) {  // Twice the signed area, winding-corrected.
    const Eigen::Vector3d& p = v[a];
    const Eigen::Vector3d& q = v[b];
    const Eigen::Vector3d& r = v[c];
    return orientation * ((q[ax] - p[ax]) * (r[ay] - p[ay]) - (q[ay] - p[ay]) * (r[ax] - p[ax]));
  };
  std::vector<int> left = polygon;
  while (left.size() > 3) {
    const std::size_t n = left.size();
    bool clipped = false;
    for (std::size_t i = 0; i < n && !clipped; ++i) {
      const int a = left[(i + n - 1) % n], b = left[i], c = left[(i + 1) % n];
      if (cross(a, b, c) <= 0.0) continue;  // A reflex (or flat) corner is no ear.
      bool empty = true;
      for (std::size_t j = 0; j < n && empty; ++j) {
        const int p = left[j];
        if (p == a || p == b || p == c) continue;
        // Inside or on the triangle: it would cut through the polygon.
        empty = !(cross(a, b, p) >= 0.0 && cross(b, c, p) >= 0.0 && cross(c, a, p) >= 0.0);
      }
      if (!empty) continue;
      mesh->triangles.push_back({a, b, c});
      left.erase(left.begin() + static_cast<std::ptrdiff_t>(i));
      clipped = true;
    }
    if (!clipped) break;  // Degenerate or not simple: fanned below.
  }
  for (std::size_t i = 1; i + 1 < left.size(); ++i) {
    mesh->triangles.push_back({left[0], left[i], left[i + 1]});
  }
}

TriangleMesh LoadObj(const std::string& path) {
  std::ifstream in = common::OpenInputFile(path, "");

  TriangleMesh mesh;
  std::string line;
  std::vector<int> polygon;
  int line_number = 0;
  while (std::getline(in, line)) {
    ++line_number;
    std::string_view rest(line);
    if (line_number == 1 && rest.substr(0, 3) == "\xEF\xBB\xBF") rest.remove_prefix(3);  // BOM.
    // Unknown records are skipped, as OBJ readers do; a control character
    // (a NUL, say) would make a damaged `v` or `f` record look like one.
    if (std::any_of(rest.begin(), rest.end(), [](char ch) {
          const auto c = static_cast<unsigned char>(ch);
          return (c < 0x20 && kWhitespace.find(ch) == std::string_view::npos) || c == 0x7F;
        })) {
      throw common::ConfigError::At(path, line_number,
                                    "control character in the line (damaged or not an OBJ file)");
    }
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
        // v, v/vt, v//vn or v/vt/vn: only the position index is used, but
        // the texture and normal indices must still be integers (or empty),
        // so a damaged file is refused rather than half read.
        const std::string_view position = token.substr(0, token.find('/'));
        long long index = 0;
        if (!ParseInt(position, &index) || !ValidTextureAndNormal(token)) {
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
        if (polygon.size() > kMaxPolygonCorners) {
          throw common::ConfigError::At(path, line_number,
                                        "f: more than " + std::to_string(kMaxPolygonCorners) +
                                            " vertices in one face (split it)");
        }
      }
      if (polygon.size() < 3) {
        throw common::ConfigError::At(path, line_number, "f: needs at least 3 vertices");
      }
      TriangulatePolygon(polygon, &mesh);
    }
  }
  if (in.bad()) throw common::ConfigError::At(path, line_number, "read error");
  return mesh;
}

namespace {

/// Turns STL's triangle soup into an indexed mesh: corners with bit-identical
/// coordinates share one vertex.
class VertexIndex {
 public:
  explicit VertexIndex(TriangleMesh* mesh) : mesh_(mesh) {}

  int Add(const Eigen::Vector3d& p) {
    const auto [it, inserted] = index_.emplace(std::array<double, 3>{p.x(), p.y(), p.z()},
                                               static_cast<int>(mesh_->vertices.size()));
    if (inserted) mesh_->vertices.push_back(p);
    return it->second;
  }

 private:
  TriangleMesh* mesh_;
  std::map<std::array<double, 3>, int> index_;
};

constexpr std::size_t kStlHeaderBytes = 80;
constexpr std::size_t kStlRecordBytes = 50;  // Normal, 3 corners (12 floats), attribute.

std::uint32_t ReadLittleEndian32(const std::string& data, std::size_t at) {
  std::uint32_t value = 0;
  for (int i = 3; i >= 0; --i) {
    value = (value << 8) | static_cast<unsigned char>(data[at + i]);
  }
  return value;
}

TriangleMesh ParseBinaryStl(const std::string& path, const std::string& data, std::uint32_t count) {
  TriangleMesh mesh;
  VertexIndex index(&mesh);
  mesh.triangles.reserve(count);
  for (std::uint32_t t = 0; t < count; ++t) {
    // Skip the 12-byte facet normal; the corners follow.
    const std::size_t record = kStlHeaderBytes + 4 + t * kStlRecordBytes + 12;
    std::array<int, 3> triangle{};
    for (int corner = 0; corner < 3; ++corner) {
      Eigen::Vector3d p;
      for (int axis = 0; axis < 3; ++axis) {
        p[axis] = std::bit_cast<float>(ReadLittleEndian32(data, record + 12 * corner + 4 * axis));
        if (!std::isfinite(p[axis])) {
          throw common::ConfigError::At(
              path, 0,
              "binary STL: triangle " + std::to_string(t) + " has a non-finite coordinate");
        }
      }
      triangle[corner] = index.Add(p);
    }
    mesh.triangles.push_back(triangle);
  }
  return mesh;
}

std::string Lower(std::string_view text) {
  std::string out(text);
  std::transform(out.begin(), out.end(), out.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return out;
}

TriangleMesh ParseAsciiStl(const std::string& path, const std::string& data) {
  enum class State { kOutside, kSolid, kFacet, kLoop, kLoopDone };
  TriangleMesh mesh;
  VertexIndex index(&mesh);
  State state = State::kOutside;
  std::vector<int> loop;
  int solids = 0;
  int line_number = 0;
  std::size_t begin = 0;
  auto fail = [&](const std::string& message) {
    return common::ConfigError::At(path, line_number, message);
  };
  while (begin < data.size()) {
    std::size_t end = data.find('\n', begin);
    if (end == std::string::npos) end = data.size();
    std::string_view rest(data.data() + begin, end - begin);
    begin = end + 1;
    ++line_number;
    const std::string keyword = Lower(NextToken(rest));
    if (keyword.empty()) continue;
    auto unexpected = [&](const char* expected) {
      return fail("unexpected '" + keyword + "' (expected " + expected + ")");
    };
    switch (state) {
      case State::kOutside:
        if (keyword != "solid") throw unexpected("'solid'");
        ++solids;
        state = State::kSolid;
        break;
      case State::kSolid:
        if (keyword == "endsolid") {
          state = State::kOutside;
        } else if (keyword == "facet") {
          state = State::kFacet;
        } else {
          throw unexpected("'facet' or 'endsolid'");
        }
        break;
      case State::kFacet:
        if (keyword != "outer" || Lower(NextToken(rest)) != "loop") {
          throw unexpected("'outer loop'");
        }
        loop.clear();
        state = State::kLoop;
        break;
      case State::kLoop:
        if (keyword == "vertex") {
          Eigen::Vector3d p;
          for (int axis = 0; axis < 3; ++axis) {
            const std::string_view token = NextToken(rest);
            if (token.empty()) throw fail("vertex: needs 3 numbers");
            if (!ParseDouble(token, &p[axis])) {
              throw fail("vertex: bad number '" + std::string(token) + "'");
            }
          }
          loop.push_back(index.Add(p));
          if (loop.size() > kMaxPolygonCorners) {
            throw fail("vertex: more than " + std::to_string(kMaxPolygonCorners) +
                       " vertices in one loop (split it)");
          }
        } else if (keyword == "endloop") {
          if (loop.size() < 3) {
            throw fail("endloop: a facet needs at least 3 vertices, got " +
                       std::to_string(loop.size()));
          }
          TriangulatePolygon(loop, &mesh);
          state = State::kLoopDone;
        } else {
          throw unexpected("'vertex' or 'endloop'");
        }
        break;
      case State::kLoopDone:
        if (keyword != "endfacet") throw unexpected("'endfacet'");
        state = State::kSolid;
        break;
    }
  }
  if (state != State::kOutside) {
    throw common::ConfigError::At(path, line_number, "unexpected end of file (missing 'endsolid')");
  }
  if (solids == 0) throw common::ConfigError::At(path, 0, "empty file");
  return mesh;
}

}  // namespace

TriangleMesh LoadStl(const std::string& path) {
  const std::string data = common::ReadInputFile(path, "", std::ios::binary);

  if (data.size() >= kStlHeaderBytes + 4) {
    const std::uint32_t count = ReadLittleEndian32(data, kStlHeaderBytes);
    if (data.size() == kStlHeaderBytes + 4 + std::uint64_t{count} * kStlRecordBytes) {
      return ParseBinaryStl(path, data, count);
    }
  }
  const std::size_t first = data.find_first_not_of(" \t\r\n\v\f");
  if (first != std::string::npos && Lower(std::string_view(data).substr(first, 5)) == "solid") {
    return ParseAsciiStl(path, data);
  }
  if (data.size() < kStlHeaderBytes + 4) {
    throw common::ConfigError::At(path, 0,
                                  "not an STL file: " + std::to_string(data.size()) +
                                      " bytes, too short for binary and no 'solid' at the start");
  }
  const std::uint32_t count = ReadLittleEndian32(data, kStlHeaderBytes);
  throw common::ConfigError::At(
      path, 0,
      "binary STL: " + std::to_string(count) + " triangles need " +
          std::to_string(kStlHeaderBytes + 4 + std::uint64_t{count} * kStlRecordBytes) +
          " bytes, the file has " + std::to_string(data.size()));
}

TriangleMesh LoadMesh(const std::string& path) {
  const std::string extension = Lower(std::filesystem::path(path).extension().string());
  if (extension == ".obj") return LoadObj(path);
  if (extension == ".stl") return LoadStl(path);
  throw common::ConfigError::At(path, 0,
                                (extension.empty() ? std::string("no file extension")
                                                   : "unknown mesh format '" + extension + "'") +
                                    " (expected .obj or .stl)");
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
