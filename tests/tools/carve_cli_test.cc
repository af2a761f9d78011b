// End-to-end tests of `hullguard carve`: real files, real process, exit codes.
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "geometry/camera_yaml.h"
#include "geometry/mesh.h"
#include "scene/demo_cell.h"
#include "scene/exact_mask.h"
#include "silhouette/mask_io.h"
#include "support/random_scene.h"
#include "support/run_tool.h"

namespace hg {
namespace {

namespace fs = std::filesystem;

using testing::ProcessResult;

ProcessResult Hullguard(const std::string& args) {
  return testing::RunTool(HG_HULLGUARD_BIN, args);
}

class CarveCliTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("hg_carve_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
    testing::RandomSceneOptions opt;
    opt.num_cameras = 4;
    opt.num_objects = 2;
    scene_ = testing::MakeRandomScene(99, opt);
    geometry::WriteCamerasFile(Path("cams.yaml"), scene_.cameras);
    const auto masks = testing::RenderMasks(scene_.cameras, scene_.objects);
    for (std::size_t i = 0; i < masks.size(); ++i) {
      silhouette::WriteGreyImage(Path(MaskName(i)), masks[i]);
    }
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Path(const std::string& name) const { return (dir_ / name).string(); }
  static std::string MaskName(std::size_t i) {
    return std::string("m").append(std::to_string(i)).append(".png");
  }
  std::string Masks() const {
    std::string s;
    for (std::size_t i = 0; i < scene_.cameras.size(); ++i) {
      s.append(" ");
      s.append(Path(MaskName(i)));
    }
    return s;
  }
  std::string Base() const {
    return "carve --cameras " + Path("cams.yaml") + " --masks" + Masks() +
           " --bounds 0 0 0 2 2 2 --depth 6";
  }
  fs::path dir_;
  testing::RandomScene scene_;
};

TEST_F(CarveCliTest, QueryClassifiesPointsInOrder) {
  std::ofstream q(Path("q.txt"));
  const auto* sphere_or_other = &scene_.objects[0];
  Eigen::Vector3d inside = std::visit(
      [](const auto& s) -> Eigen::Vector3d {
        using T = std::decay_t<decltype(s)>;
        if constexpr (std::is_same_v<T, scene::Capsule>)
          return s.a_W;
        else
          return s.centre_W;
      },
      *sphere_or_other);
  q << inside.x() << " " << inside.y() << " " << inside.z() << "\n";
  q << "# a comment\n5 5 5\n0.001 0.001 1.999\n";
  q.close();
  const ProcessResult r = Hullguard(Base() + " --query " + Path("q.txt"));
  ASSERT_EQ(r.code, 0) << r.err;
  std::istringstream lines(r.out);
  std::string l1, l2, l3;
  std::getline(lines, l1);
  std::getline(lines, l2);
  std::getline(lines, l3);
  EXPECT_NE(l1.find("occupied"), std::string::npos) << l1;
  EXPECT_EQ(l2, "5 5 5 outside");
  EXPECT_TRUE(l3.find(" free") != std::string::npos || l3.find(" occupied") != std::string::npos ||
              l3.find(" occluded") != std::string::npos)
      << l3;
}

TEST_F(CarveCliTest, JsonAndPly) {
  const ProcessResult r = Hullguard(Base() + " --threads 2 --json --out " + Path("hull.ply") +
                                    " --snapshot " + Path("view.png"));
  ASSERT_EQ(r.code, 0) << r.err;
  for (const char* key : {"\"occupied_volume_m3\"", "\"leaves\"", "\"nodes\"", "\"update_ms\""}) {
    EXPECT_NE(r.out.find(key), std::string::npos) << key << " in " << r.out;
  }
  std::ifstream ply(Path("hull.ply"));
  std::string magic;
  ply >> magic;
  EXPECT_EQ(magic, "ply");
  EXPECT_GT(fs::file_size(Path("hull.ply")), 100u);
  const common::ImageU8 picture = silhouette::ReadGreyImage(Path("view.png"));
  EXPECT_GT(picture.width, 600);
}

double JsonNumber(const std::string& json, const std::string& key) {
  const auto at = json.find("\"" + key + "\": ");
  EXPECT_NE(at, std::string::npos) << key << " in " << json;
  return at == std::string::npos ? 0.0 : std::stod(json.substr(at + key.size() + 4));
}

TEST_F(CarveCliTest, ExactBoundariesOnlyAddFreeSpace) {
  // One camera: much of the cell lies outside its view, so the edge of the view
  // is a large static boundary.
  geometry::WriteCamerasFile(Path("one.yaml"), {scene_.cameras[0]});
  const std::string base = "carve --cameras " + Path("one.yaml") + " --masks " + Path(MaskName(0)) +
                           " --bounds 0 0 0 2 2 2 --depth 6 --json";
  const ProcessResult coarse = Hullguard(base);
  const ProcessResult exact = Hullguard(base + " --boundary-coarsening 0");
  ASSERT_EQ(coarse.code, 0) << coarse.err;
  ASSERT_EQ(exact.code, 0) << exact.err;
  EXPECT_GT(JsonNumber(coarse.out, "occluded_volume_m3"), 0.5) << coarse.out;
  EXPECT_GT(JsonNumber(exact.out, "free_volume_m3"), JsonNumber(coarse.out, "free_volume_m3"))
      << coarse.out << "\n"
      << exact.out;
  EXPECT_GT(JsonNumber(exact.out, "leaves"), JsonNumber(coarse.out, "leaves"));
}

TEST_F(CarveCliTest, KnowledgeFilterIsOffUnlessAskedFor) {
  const Eigen::Vector3d inside = std::visit(
      [](const auto& s) -> Eigen::Vector3d {
        if constexpr (std::is_same_v<std::decay_t<decltype(s)>, scene::Capsule>) {
          return s.a_W;
        } else {
          return s.centre_W;
        }
      },
      scene_.objects[0]);
  std::ofstream(Path("q.txt")) << inside.x() << " " << inside.y() << " " << inside.z() << "\n";
  const ProcessResult plain = Hullguard(Base() + " --query " + Path("q.txt"));
  ASSERT_EQ(plain.code, 0) << plain.err;
  EXPECT_NE(plain.out.find(" occupied"), std::string::npos) << plain.out;
  // Every component is smaller than 100 m^3: the filter drops the object.
  const ProcessResult filtered =
      Hullguard(Base() + " --query " + Path("q.txt") + " --min-component-m3 100");
  ASSERT_EQ(filtered.code, 0) << filtered.err;
  EXPECT_NE(filtered.out.find(" free"), std::string::npos) << filtered.out;
  const ProcessResult json = Hullguard(Base() + " --json --min-component-m3 100");
  EXPECT_NE(json.out.find("\"dropped_components\": "), std::string::npos) << json.out;
  EXPECT_EQ(json.out.find("\"dropped_components\": 0,"), std::string::npos) << json.out;
}

TEST_F(CarveCliTest, BadInputGetsOneLineAndExitTwo) {
  struct Case {
    std::string args;
    std::string expect;  // Must appear in stderr.
  };
  std::ofstream(Path("bad.yaml"))
      << "cameras:\n  - name: a\n    width: 10\n    height: 10\n"
         "    K: [1, 0, 0, 0, 1, 0, 0, 0, 1]\n    R: [1,0,0,0,1,0,0,0,1]\n"
         "    t: [0, 0, 0]\n    colour: red\n";
  std::ofstream(Path("broken.yaml")) << "cameras: [ {name: a, width: 3\n";
  std::ofstream(Path("rank.yaml")) << "cameras:\n  - name: a\n    width: 160\n    height: 120\n"
                                      "    P: [1, 0, 0, 0, 2, 0, 0, 0, 0, 0, 0, 1]\n";
  silhouette::WriteGreyImage(Path("small.png"), common::ImageU8(10, 10));
  std::ofstream(Path("q.txt")) << "1 2\n";
  const std::string cams = " --cameras " + Path("cams.yaml");
  const std::vector<Case> cases = {
      {"carve --cameras " + Path("missing.yaml") + " --masks" + Masks() +
           " --bounds 0 0 0 2 2 2 --depth 6",
       "missing.yaml"},
      {"carve" + cams + " --masks " + Path("small.png") + Masks().substr(Masks().find(' ', 1)) +
           " --bounds 0 0 0 2 2 2 --depth 6",
       "small.png"},
      {"carve --cameras " + Path("bad.yaml") + " --masks " + Path("m0.png") +
           " --bounds 0 0 0 2 2 2 --depth 6",
       "colour"},
      {"carve --cameras " + Path("broken.yaml") + " --masks " + Path("m0.png") +
           " --bounds 0 0 0 2 2 2 --depth 6",
       "broken.yaml"},
      {"carve --cameras " + Path("rank.yaml") + " --masks " + Path("m0.png") +
           " --bounds 0 0 0 2 2 2 --depth 6",
       "rank"},
      {Base() + " --query " + Path("q.txt"), "q.txt:1"},
      {Base() + " --obstacles " + Path("none.obj"), "none.obj"},
      {"carve" + cams + " --masks " + Path("m0.png") + " --bounds 0 0 0 2 2 2 --depth 6", "masks"},
      {"carve" + cams + " --masks" + Masks() + " --bounds 0 0 0 2 2 --depth 6", "bounds"},
      {"carve" + cams + " --masks" + Masks() + " --bounds 0 0 0 -2 2 2 --depth 6", "bounds"},
  };
  for (const Case& c : cases) {
    const ProcessResult r = Hullguard(c.args);
    EXPECT_EQ(r.code, 2) << c.args << "\n" << r.err;
    EXPECT_NE(r.err.find(c.expect), std::string::npos) << "stderr: " << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  }
}

}  // namespace
}  // namespace hg

namespace hg {
namespace {

// The shipped demo cell files are what the built-in cell generates.
TEST(DemoCellConfigTest, ShippedFilesMatchTheBuiltInCell) {
  scene::DemoCellOptions opt;
  opt.num_cameras = 8;
  const scene::DemoCell cell = scene::MakeDemoCell(opt);
  const auto cams =
      geometry::LoadCamerasFile(std::string(HG_SOURCE_DIR) + "/config/demo_cell/cameras.yaml");
  ASSERT_EQ(cams.size(), cell.cameras.size());
  for (std::size_t i = 0; i < cams.size(); ++i) {
    EXPECT_EQ(cams[i].name, cell.cameras[i].name);
    EXPECT_TRUE(cams[i].K.isApprox(cell.cameras[i].K, 1e-12));
    EXPECT_TRUE(cams[i].R_CW.isApprox(cell.cameras[i].R_CW, 1e-12));
    EXPECT_TRUE(cams[i].t_CW.isApprox(cell.cameras[i].t_CW, 1e-12));
  }
  const geometry::TriangleMesh mesh =
      geometry::LoadObj(std::string(HG_SOURCE_DIR) + "/config/demo_cell/obstacles.obj");
  std::size_t triangles = 0;
  for (const auto& m : cell.obstacles) triangles += m.triangles.size();
  EXPECT_EQ(mesh.triangles.size(), triangles);
}

}  // namespace
}  // namespace hg
