#include "geometry/mesh.h"

#include <filesystem>
#include <fstream>
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

TEST(LoadObjTest, FansQuadsAndPolygons) {
  const ScopedFile obj = WriteFile("quad.obj",
                                   "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0.5 1.5 0\n"
                                   "f 1 2 3 4\n"
                                   "f 1 2 3 5 4\n");
  const TriangleMesh mesh = LoadObj(obj.path);
  ASSERT_EQ(mesh.triangles.size(), 5u);
  EXPECT_EQ(mesh.triangles[0], (std::array<int, 3>{0, 1, 2}));
  EXPECT_EQ(mesh.triangles[1], (std::array<int, 3>{0, 2, 3}));
  EXPECT_EQ(mesh.triangles[2], (std::array<int, 3>{0, 1, 2}));
  EXPECT_EQ(mesh.triangles[3], (std::array<int, 3>{0, 2, 4}));
  EXPECT_EQ(mesh.triangles[4], (std::array<int, 3>{0, 4, 3}));
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
    EXPECT_EQ(std::string(e.what()), path + ": cannot open");
  }
}

TEST(LoadObjTest, ErrorsNameFileAndLine) {
  struct Case {
    const char* name;
    const char* text;
    int line;
    const char* fragment;
  };
  const Case cases[] = {
      {"bad_number.obj", "v 0 0 0\nv 1 x 0\n", 2, "bad number"},
      {"nan.obj", "v 0 0 0\nv 1 0 nan\n", 2, "bad number"},
      {"few_numbers.obj", "# c\nv 1 2\n", 2, "3 numbers"},
      {"bad_index.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 1 2 3.5\n", 5, "bad index"},
      {"empty_index.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 /2 3\n", 4, "bad index"},
      {"too_large.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", 4, "out of range"},
      {"zero.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", 4, "out of range"},
      {"too_negative.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -4\n", 4, "out of range"},
      // Forward references are rejected: the index is checked against the
      // vertices read so far.
      {"forward.obj", "v 0 0 0\nv 1 0 0\nf 1 2 3\nv 0 1 0\n", 3, "out of range"},
      {"two_vertices.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", 4, "at least 3"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const std::string message = LoadError(c.name, c.text);
    const std::string prefix = TempPath(c.name) + ":" + std::to_string(c.line) + ": ";
    EXPECT_EQ(message.rfind(prefix, 0), 0u) << message;
    EXPECT_NE(message.find(c.fragment), std::string::npos) << message;
  }
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
