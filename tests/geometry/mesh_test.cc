#include "geometry/mesh.h"

#include <bit>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <string>
#include <system_error>

#include <unistd.h>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include "common/config_error.h"

namespace hg::geometry {
namespace {

// The process id keeps concurrent runs of the suite (parallel ctest, several
// build trees) from writing each other's files.
std::string TempPath(const std::string& name) {
  return (std::filesystem::path(::testing::TempDir()) /
          ("hg_mesh_test_" + std::to_string(::getpid()) + "_" + name))
      .string();
}

/// A file under the test temp directory, removed when the test is done.
struct ScopedFile {
  std::string path;
  ~ScopedFile() {
    std::error_code ignored;
    std::filesystem::remove(path, ignored);
  }
};

ScopedFile WriteFile(const std::string& name, const std::string& text) {
  ScopedFile file{TempPath(name)};
  std::ofstream out(file.path);
  out << text;
  return file;
}

/// Loads `text` and returns the ConfigError message ("" when it loads).
std::string LoadError(const std::string& name, const std::string& text) {
  const ScopedFile file = WriteFile(name, text);
  try {
    (void)LoadObj(file.path);
  } catch (const common::ConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(LoadObjTest, ParsesTrianglesAndIgnoresOtherRecords) {
  const ScopedFile obj = WriteFile("tri.obj",
                                   "# a comment\n"
                                   "o thing\n"
                                   "mtllib x.mtl\n"
                                   "v 0 0 0\n"
                                   "v 1.5 -2 3e-1  # trailing comment\n"
                                   "vn 0 0 1\n"
                                   "vt 0.5 0.5\n"
                                   "v\t0 1 0 1.0\r\n"
                                   "s off\n"
                                   "\n"
                                   "f 1 2 3\n");
  const TriangleMesh mesh = LoadObj(obj.path);
  ASSERT_EQ(mesh.vertices.size(), 3u);
  EXPECT_EQ(mesh.vertices[1], Eigen::Vector3d(1.5, -2, 0.3));
  EXPECT_EQ(mesh.vertices[2], Eigen::Vector3d(0, 1, 0));
  ASSERT_EQ(mesh.triangles.size(), 1u);
  EXPECT_EQ(mesh.triangles[0], (std::array<int, 3>{0, 1, 2}));
}

// Twice the signed area of triangle t seen from +z (its winding: > 0 counter-clockwise).
double TwiceAreaZ(const TriangleMesh& mesh, const std::array<int, 3>& t) {
  const Eigen::Vector3d a = mesh.vertices[t[0]], b = mesh.vertices[t[1]], c = mesh.vertices[t[2]];
  return (b - a).cross(c - a).z();
}

// Polygons become triangles that cover exactly the polygon, with its winding:
// a quad, a convex pentagon, and an L-shaped hexagon listed from a corner that
// cannot see the whole of it (a fan from there crossed the notch).
TEST(LoadObjTest, CutsQuadsAndPolygonsConcaveOnesToo) {
  const ScopedFile obj = WriteFile("poly.obj",
                                   "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0.5 1.5 0\n"
                                   "v 2 0 1\nv 2 1 1\nv 1 1 1\nv 1 2 1\nv 0 2 1\nv 0 0 1\n"
                                   "f 1 2 3 4\n"
                                   "f 1 2 3 5 4\n"
                                   "f 6 7 8 9 10 11\n");
  const TriangleMesh mesh = LoadObj(obj.path);
  ASSERT_EQ(mesh.triangles.size(), 2u + 3u + 4u);
  double areas[3] = {0, 0, 0};
  for (std::size_t i = 0; i < mesh.triangles.size(); ++i) {
    const double twice = TwiceAreaZ(mesh, mesh.triangles[i]);
    EXPECT_GT(twice, 0.0) << "triangle " << i << " turned over";
    areas[i < 2 ? 0 : i < 5 ? 1 : 2] += 0.5 * twice;
    // Every triangle lies inside its polygon: its centroid, for the L, off the notch.
    const Eigen::Vector3d centroid =
        (mesh.vertices[mesh.triangles[i][0]] + mesh.vertices[mesh.triangles[i][1]] +
         mesh.vertices[mesh.triangles[i][2]]) /
        3.0;
    if (i >= 5) {
      EXPECT_FALSE(centroid.x() > 1.0 && centroid.y() > 1.0) << "triangle " << i;
    }
  }
  EXPECT_NEAR(areas[0], 1.0, 1e-12);
  EXPECT_NEAR(areas[1], 1.25, 1e-12);
  EXPECT_NEAR(areas[2], 3.0, 1e-12);  // A fan from (2, 0) covers 3.5, part of it twice.
  // Each polygon's triangles use its own corners only.
  for (std::size_t i = 0; i < mesh.triangles.size(); ++i) {
    for (const int corner : mesh.triangles[i]) {
      EXPECT_TRUE(i < 2 ? corner <= 3 : i < 5 ? corner <= 4 : corner >= 5) << i << " " << corner;
    }
  }
}

TEST(LoadObjTest, NegativeIndicesCountBackFromLastVertexSoFar) {
  const ScopedFile obj = WriteFile("neg.obj",
                                   "v 0 0 0\nv 1 0 0\nv 0 1 0\n"
                                   "f -3 -2 -1\n"
                                   "v 5 5 5\n"
                                   "f -1 -2 1\n");
  const TriangleMesh mesh = LoadObj(obj.path);
  ASSERT_EQ(mesh.triangles.size(), 2u);
  EXPECT_EQ(mesh.triangles[0], (std::array<int, 3>{0, 1, 2}));
  EXPECT_EQ(mesh.triangles[1], (std::array<int, 3>{3, 2, 0}));
}

TEST(LoadObjTest, AcceptsTextureAndNormalIndexForms) {
  const ScopedFile obj = WriteFile("vtvn.obj",
                                   "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n"
                                   "vt 0 0\nvn 0 0 1\n"
                                   "f 1/1 2/1 3/1\n"
                                   "f 2//1 4//1 3//1\n"
                                   "f 1/1/1 2/1/1 4/1/1\n"
                                   "f -4/-1/-1 -3/1/1 -1//1\n");
  const TriangleMesh mesh = LoadObj(obj.path);
  ASSERT_EQ(mesh.triangles.size(), 4u);
  EXPECT_EQ(mesh.triangles[0], (std::array<int, 3>{0, 1, 2}));
  EXPECT_EQ(mesh.triangles[1], (std::array<int, 3>{1, 3, 2}));
  EXPECT_EQ(mesh.triangles[2], (std::array<int, 3>{0, 1, 3}));
  EXPECT_EQ(mesh.triangles[3], (std::array<int, 3>{0, 1, 3}));
}

TEST(LoadObjTest, MissingFileNamesTheFile) {
  const std::string path = TempPath("does_not_exist.obj");
  try {
    (void)LoadObj(path);
    FAIL() << "expected ConfigError";
  } catch (const common::ConfigError& e) {
    EXPECT_EQ(std::string(e.what()), path + ": cannot open: no such file");
  }
}

/// Three vertices and a face of `corners` corners going round them.
std::string HugeFace(int corners) {
  std::string text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf";
  for (int i = 0; i < corners; ++i) {
    text += ' ';
    text += static_cast<char>('1' + i % 3);
  }
  text += '\n';
  return text;
}

// A byte order mark before the first record (some Windows exporters) is
// skipped: it made the first vertex an unknown record, and every face's
// corners one vertex off. A face of 1000 corners loads.
TEST(LoadObjTest, ByteOrderMarkIsSkippedAndLargeFacesLoad) {
  const std::string text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\n";
  const ScopedFile plain = WriteFile("plain.obj", text);
  const ScopedFile bom = WriteFile("bom.obj", "\xEF\xBB\xBF" + text);
  const TriangleMesh a = LoadObj(plain.path), b = LoadObj(bom.path);
  ASSERT_EQ(b.vertices.size(), 4U);
  EXPECT_EQ(a.vertices, b.vertices);
  EXPECT_EQ(a.triangles, b.triangles);
  const ScopedFile large = WriteFile("large.obj", HugeFace(1000));
  EXPECT_FALSE(LoadObj(large.path).triangles.empty());
}

TEST(LoadObjTest, ErrorsNameFileAndLine) {
  struct Case {
    const char* name;
    std::string text;
    int line;
    const char* fragment;
  };
  const Case cases[] = {
      {"bad_number.obj", "v 0 0 0\nv 1 x 0\n", 2, "bad number"},
      {"nan.obj", "v 0 0 0\nv 1 0 nan\n", 2, "bad number"},
      {"few_numbers.obj", "# c\nv 1 2\n", 2, "3 numbers"},
      {"bad_index.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 1 2 3.5\n", 5, "bad index"},
      {"empty_index.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 /2 3\n", 4, "bad index"},
      {"bad_texture.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/x/1 2/1/1 3/1/1\n", 4, "bad index"},
      {"bad_normal.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1//1 2//1 3//n\n", 4, "bad index"},
      {"empty_texture.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/ 2/ 3/\n", 4, "bad index"},
      {"four_parts.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1/1/1 2 3\n", 4, "bad index"},
      {"too_large.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", 4, "out of range"},
      {"zero.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", 4, "out of range"},
      {"too_negative.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -4\n", 4, "out of range"},
      // Forward references are rejected: the index is checked against the
      // vertices read so far.
      {"forward.obj", "v 0 0 0\nv 1 0 0\nf 1 2 3\nv 0 1 0\n", 3, "out of range"},
      {"two_vertices.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", 4, "at least 3"},
      // A NUL before a record would make a damaged record an unknown one,
      // skipped: every later face's corners shifted.
      {"nul.obj", std::string("v 0 0 0\n\0v 1 0 0\nv 0 1 0\n", 24), 2, "control character"},
      // Ear clipping takes time quadratic in the corners and more.
      {"huge_face.obj", HugeFace(1001), 4, "more than 1000 vertices in one face"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const std::string message = LoadError(c.name, c.text);
    const std::string prefix = TempPath(c.name) + ":" + std::to_string(c.line) + ": ";
    EXPECT_EQ(message.rfind(prefix, 0), 0u) << message;
    EXPECT_NE(message.find(c.fragment), std::string::npos) << message;
  }
}

/// Little-endian bytes of a binary STL file holding `mesh`'s triangles; the
/// header starts with "solid" as some exporters write it.
std::string BinaryStl(const TriangleMesh& mesh) {
  std::string data = "solid written by a binary exporter";
  data.resize(80, ' ');
  auto put32 = [&data](std::uint32_t v) {
    for (int i = 0; i < 4; ++i) data.push_back(static_cast<char>((v >> (8 * i)) & 0xFF));
  };
  auto put_float = [&](float f) { put32(std::bit_cast<std::uint32_t>(f)); };
  put32(static_cast<std::uint32_t>(mesh.triangles.size()));
  for (const auto& t : mesh.triangles) {
    for (int i = 0; i < 3; ++i) put_float(0.0F);  // Normal, ignored.
    for (int corner = 0; corner < 3; ++corner) {
      for (int axis = 0; axis < 3; ++axis) {
        put_float(static_cast<float>(mesh.vertices[t[corner]][axis]));
      }
    }
    data.append(2, '\0');  // Attribute byte count.
  }
  return data;
}

/// Loads `text` as STL and returns the ConfigError message ("" when it loads).
std::string StlError(const std::string& name, const std::string& text) {
  const ScopedFile file = WriteFile(name, text);
  try {
    (void)LoadStl(file.path);
  } catch (const common::ConfigError& e) {
    return e.what();
  }
  return "";
}

/// Expects the corners of every triangle of `a` and `b` to be the same points, in order.
void ExpectSameTriangles(const TriangleMesh& a, const TriangleMesh& b) {
  ASSERT_EQ(a.triangles.size(), b.triangles.size());
  for (std::size_t i = 0; i < a.triangles.size(); ++i) {
    for (int k = 0; k < 3; ++k) {
      EXPECT_EQ(a.vertices[a.triangles[i][k]], b.vertices[b.triangles[i][k]]) << i << " " << k;
    }
  }
}

TEST(LoadStlTest, AsciiSolidsQuadsAndSharedCorners) {
  const ScopedFile stl = WriteFile("two.stl",
                                   "solid first\n"
                                   "  facet normal 0 0 1\n"
                                   "    outer loop\n"
                                   "      vertex 0 0 0\n"
                                   "      vertex 1.5 0 0\n"
                                   "      vertex 0 1 -2.5e-1\n"
                                   "    endloop\n"
                                   "  endfacet\n"
                                   "  facet normal 0 0 1\n"
                                   "    outer loop\n"
                                   "      vertex 1.5 0 0\n"
                                   "      vertex 1.5 1 0\n"
                                   "      vertex 0 1 -0.25\n"
                                   "    endloop\n"
                                   "  endfacet\n"
                                   "endsolid first\n"
                                   "\n"
                                   "SOLID second\r\n"
                                   "FACET NORMAL 0 0 0\r\n"
                                   "OUTER LOOP\r\n"
                                   "VERTEX 5 5 5\r\n"
                                   "VERTEX 6 5 5\r\n"
                                   "VERTEX 6 6 5\r\n"
                                   "VERTEX 5 6 5\r\n"
                                   "ENDLOOP\r\n"
                                   "ENDFACET\r\n"
                                   "ENDSOLID\r\n");
  const TriangleMesh mesh = LoadStl(stl.path);
  ASSERT_EQ(mesh.vertices.size(), 8u);  // 4 + 4: the first solid's triangles share 2 corners.
  ASSERT_EQ(mesh.triangles.size(), 4u);
  EXPECT_EQ(mesh.triangles[0], (std::array<int, 3>{0, 1, 2}));
  EXPECT_EQ(mesh.triangles[1], (std::array<int, 3>{1, 3, 2}));
  EXPECT_EQ(mesh.vertices[2], Eigen::Vector3d(0, 1, -0.25));
  // The quad is cut in two along a diagonal, with its winding.
  EXPECT_EQ(mesh.triangles[2], (std::array<int, 3>{7, 4, 5}));
  EXPECT_EQ(mesh.triangles[3], (std::array<int, 3>{5, 6, 7}));
  EXPECT_EQ(mesh.vertices[7], Eigen::Vector3d(5, 6, 5));
}

TEST(LoadStlTest, BinaryBoxWithSolidHeader) {
  // Coordinates exact in float, so the mesh reads back unchanged.
  const TriangleMesh box = TriangleMesh::Box({-1.5, 0.25, 2}, {3, 1.125, 2.5});
  const ScopedFile stl = WriteFile("box.stl", BinaryStl(box));
  const TriangleMesh mesh = LoadStl(stl.path);
  EXPECT_EQ(mesh.vertices.size(), 8u);
  ExpectSameTriangles(mesh, box);
}

TEST(LoadStlTest, BinaryRandomTrianglesRoundToFloat) {
  std::mt19937_64 rng(99);
  std::uniform_real_distribution<double> coord(-10, 10);
  TriangleMesh mesh;
  for (int i = 0; i < 60; ++i) {
    mesh.vertices.emplace_back(coord(rng), coord(rng), coord(rng));
  }
  std::uniform_int_distribution<int> index(0, 59);
  for (int i = 0; i < 100; ++i) {
    mesh.triangles.push_back({index(rng), index(rng), index(rng)});
  }
  const ScopedFile stl = WriteFile("random.stl", BinaryStl(mesh));
  const TriangleMesh loaded = LoadStl(stl.path);
  ASSERT_EQ(loaded.triangles.size(), mesh.triangles.size());
  for (std::size_t i = 0; i < mesh.triangles.size(); ++i) {
    for (int k = 0; k < 3; ++k) {
      for (int axis = 0; axis < 3; ++axis) {
        const float as_float = static_cast<float>(mesh.vertices[mesh.triangles[i][k]][axis]);
        EXPECT_EQ(loaded.vertices[loaded.triangles[i][k]][axis], static_cast<double>(as_float));
      }
    }
  }
}

TEST(LoadStlTest, BinaryErrors) {
  const std::string box = BinaryStl(TriangleMesh::Box({0, 0, 0}, {1, 1, 1}));
  // 80 + 4 + 12 * 50 = 684 bytes; one missing byte makes the count disagree
  // with the size, and the header ("solid ...") does not parse as ASCII.
  std::string truncated = box.substr(0, box.size() - 1);
  truncated.replace(0, 5, "bin  ");
  const std::string message = StlError("truncated.stl", truncated);
  EXPECT_EQ(message, TempPath("truncated.stl") +
                         ": binary STL: 12 triangles need 684 bytes, the file has 683");

  std::string nan = box;
  const float not_a_number = std::numeric_limits<float>::quiet_NaN();
  const std::uint32_t bits = std::bit_cast<std::uint32_t>(not_a_number);
  const std::size_t at = 80 + 4 + 3 * 50 + 12 + 4;  // Triangle 3, corner 0, y.
  for (int i = 0; i < 4; ++i) nan[at + i] = static_cast<char>((bits >> (8 * i)) & 0xFF);
  EXPECT_NE(StlError("nan.stl", nan).find("nan.stl: binary STL: triangle 3 has a non-finite"),
            std::string::npos)
      << StlError("nan.stl", nan);

  EXPECT_NE(StlError("short.stl", "abc").find("short.stl: not an STL file: 3 bytes"),
            std::string::npos);
  EXPECT_NE(StlError("empty.stl", "").find("empty.stl: not an STL file"), std::string::npos);
}

TEST(LoadStlTest, AsciiErrorsNameFileAndLine) {
  const std::string facet_start = "solid s\nfacet normal 0 0 1\nouter loop\n";
  struct Case {
    const char* name;
    std::string text;
    int line;
    const char* fragment;
  };
  const Case cases[] = {
      {"bad_number.stl", facet_start + "vertex 0 0 0\nvertex 1 x 0\n", 5, "vertex: bad number 'x'"},
      {"inf.stl", facet_start + "vertex 0 0 inf\n", 4, "vertex: bad number 'inf'"},
      {"two_numbers.stl", facet_start + "vertex 0 0\n", 4, "vertex: needs 3 numbers"},
      {"two_corners.stl", facet_start + "vertex 0 0 0\nvertex 1 0 0\nendloop\n", 6,
       "a facet needs at least 3 vertices, got 2"},
      {"no_loop.stl", "solid s\nfacet normal 0 0 1\nvertex 0 0 0\n", 3, "expected 'outer loop'"},
      {"no_endfacet.stl",
       facet_start + "vertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nfacet\n", 8,
       "expected 'endfacet'"},
      {"stray.stl", "solid s\n\nvertex 0 0 0\n", 3, "expected 'facet' or 'endsolid'"},
      {"no_endsolid.stl", "solid s\nfacet normal 0 0 1\nouter loop\n", 3,
       "unexpected end of file (missing 'endsolid')"},
      {"after_end.stl", "solid s\nendsolid s\nfacet\n", 3, "expected 'solid'"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const std::string message = StlError(c.name, c.text);
    const std::string prefix = TempPath(c.name) + ":" + std::to_string(c.line) + ": ";
    EXPECT_EQ(message.rfind(prefix, 0), 0u) << message;
    EXPECT_NE(message.find(c.fragment), std::string::npos) << message;
  }
}

TEST(LoadMeshTest, ChoosesFormatByExtension) {
  const TriangleMesh box = TriangleMesh::Box({0, 0, 0}, {1, 2, 3});
  const ScopedFile obj{TempPath("upper.OBJ")};
  WriteObj(obj.path, box);
  ExpectSameTriangles(LoadMesh(obj.path), box);
  const ScopedFile stl = WriteFile("mixed.Stl", BinaryStl(box));
  ExpectSameTriangles(LoadMesh(stl.path), box);

  // The extension decides, not the content: OBJ skips the STL records it does not know.
  const ScopedFile wrong = WriteFile("wrong.obj",
                                     "solid s\nfacet normal 0 0 1\nouter loop\n"
                                     "vertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\n"
                                     "endloop\nendfacet\nendsolid\n");
  EXPECT_EQ(LoadMesh(wrong.path).triangles.size(), 0u);  // OBJ ignores unknown records.

  for (const char* name : {"mesh.ply", "mesh"}) {
    const ScopedFile other = WriteFile(name, "v 0 0 0\n");
    try {
      (void)LoadMesh(other.path);
      ADD_FAILURE() << name;
    } catch (const common::ConfigError& e) {
      EXPECT_EQ(std::string(e.what()).rfind(other.path + ": ", 0), 0u) << e.what();
      EXPECT_NE(std::string(e.what()).find("(expected .obj or .stl)"), std::string::npos);
    }
  }
  EXPECT_THROW((void)LoadMesh(TempPath("missing.stl")), common::ConfigError);
}

TEST(TriangleMeshTest, BoxHasTwelveOutwardTrianglesAndExactBounds) {
  const Eigen::Vector3d min(-1, 0.5, 2);
  const Eigen::Vector3d max(3, 1.5, 2.25);
  const TriangleMesh box = TriangleMesh::Box(min, max);
  ASSERT_EQ(box.triangles.size(), 12u);
  ASSERT_EQ(box.vertices.size(), 8u);
  Eigen::Vector3d lo = box.vertices[0];
  Eigen::Vector3d hi = box.vertices[0];
  for (const auto& p : box.vertices) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  EXPECT_EQ(lo, min);
  EXPECT_EQ(hi, max);

  const Eigen::Vector3d centre = 0.5 * (min + max);
  double total_area = 0;
  for (const auto& t : box.triangles) {
    const Eigen::Vector3d& a = box.vertices[t[0]];
    const Eigen::Vector3d& b = box.vertices[t[1]];
    const Eigen::Vector3d& c = box.vertices[t[2]];
    const Eigen::Vector3d n = (b - a).cross(c - a);
    total_area += 0.5 * n.norm();
    // Non-degenerate, and facing away from the centre.
    EXPECT_GT(n.norm(), 0);
    EXPECT_GT(n.dot((a + b + c) / 3 - centre), 0);
  }
  const Eigen::Vector3d s = max - min;
  EXPECT_NEAR(total_area, 2 * (s.x() * s.y() + s.y() * s.z() + s.z() * s.x()), 1e-12);
}

TEST(TriangleMeshTest, AppendOffsetsIndices) {
  TriangleMesh a = TriangleMesh::Box({0, 0, 0}, {1, 1, 1});
  const TriangleMesh b = TriangleMesh::Box({2, 0, 0}, {3, 1, 1});
  a.Append(b);
  ASSERT_EQ(a.vertices.size(), 16u);
  ASSERT_EQ(a.triangles.size(), 24u);
  for (int i = 0; i < 12; ++i) {
    for (int k = 0; k < 3; ++k) {
      EXPECT_EQ(a.triangles[12 + i][k], b.triangles[i][k] + 8);
      EXPECT_EQ(a.vertices[a.triangles[12 + i][k]], b.vertices[b.triangles[i][k]]);
    }
  }
}

TEST(ObjRoundTripTest, WriteThenLoadIsExact) {
  std::mt19937_64 rng(20240611);
  std::uniform_real_distribution<double> coord(-1e3, 1e3);
  TriangleMesh mesh;
  for (int i = 0; i < 200; ++i) {
    mesh.vertices.emplace_back(coord(rng), coord(rng) * 1e-7, coord(rng) * 1e5);
  }
  std::uniform_int_distribution<int> index(0, 199);
  for (int i = 0; i < 300; ++i) {
    mesh.triangles.push_back({index(rng), index(rng), index(rng)});
  }
  mesh.Append(TriangleMesh::Box({-0.1, 0.2, 0.3}, {1.0 / 3, 2.0 / 3, 1e-20}));
  const ScopedFile obj{TempPath("roundtrip.obj")};
  WriteObj(obj.path, mesh);
  const TriangleMesh loaded = LoadObj(obj.path);
  ASSERT_EQ(loaded.vertices.size(), mesh.vertices.size());
  ASSERT_EQ(loaded.triangles.size(), mesh.triangles.size());
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    EXPECT_EQ(loaded.vertices[i], mesh.vertices[i]) << i;
  }
  for (size_t i = 0; i < mesh.triangles.size(); ++i) {
    EXPECT_EQ(loaded.triangles[i], mesh.triangles[i]) << i;
  }
}

}  // namespace
}  // namespace hg::geometry
