// End-to-end tests of `hullguard place`: the real binary on a shipped scene,
// the camera block it writes read back by the daemon's loaders, the report,
// determinism and the errors.
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include "app/config.h"
#include "geometry/camera_yaml.h"
#include "support/run_tool.h"

namespace hg {
namespace {

namespace fs = std::filesystem;

std::string ReadFile(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

class PlaceCliTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           std::string("hg_place_")
               .append(std::to_string(::getpid()))
               .append("_")
               .append(::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Path(const std::string& name) const { return (dir_ / name).string(); }
  static std::string PaperCell() {
    return std::string(HG_SOURCE_DIR) + "/config/scenes/paper_cell.yaml";
  }
  /// A quick run: coarse voxels, a small budget.
  testing::ProcessResult Place(const std::string& scene, const std::string& args,
                               const std::string& name) const {
    return testing::RunTool(HG_HULLGUARD_BIN, "place --scene " + scene +
                                                  " --voxel 0.25 --render-width 64 "
                                                  "--budget 150 --local-budget 24 --out " +
                                                  Path(name + ".yaml") + " --report " + Path(name) +
                                                  " " + args);
  }
  fs::path dir_;
};

TEST_F(PlaceCliTest, WritesACameraBlockTheDaemonLoadsAndAReport) {
  const auto r = Place(PaperCell(), "--cameras 3 --min-views 2 --seed 5", "a");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("hullguard place: paper_cell, 3 cameras, K = 2: score"), std::string::npos)
      << r.out;
  EXPECT_NE(r.err.find("place: global"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("place: local"), std::string::npos) << r.err;

  // The cameras file, through the cameras-file loader.
  const auto cameras = geometry::LoadCamerasFile(Path("a.yaml"));
  ASSERT_EQ(cameras.size(), 3u);
  EXPECT_EQ(cameras[0].name, "cam0");
  EXPECT_EQ(cameras[0].width, 1920);

  // The same blocks as the `cameras:` section of a daemon config.
  YAML::Node file = YAML::LoadFile(Path("a.yaml"));
  YAML::Node config;
  config["cell"]["bounds"]["min"] = std::vector<double>{0, 0, 0};
  config["cell"]["bounds"]["max"] = std::vector<double>{4, 4, 3};
  int i = 0;
  for (YAML::Node camera : file["cameras"]) {
    camera["source"]["type"] = "aravis";
    camera["source"]["device"] = "cam-" + std::to_string(i++);
    config["cameras"].push_back(camera);
  }
  YAML::Emitter out;
  out << config;
  const app::Config loaded = app::ParseConfig(out.c_str(), Path("daemon.yaml"), dir_.string());
  ASSERT_EQ(loaded.cameras.size(), 3u);
  EXPECT_TRUE(loaded.cameras[1].model.R_CW.isApprox(cameras[1].R_CW, 1e-12));

  for (const char* f :
       {"report.md", "report.json", "optimised_coverage_top.png", "optimised_slices.png",
        "optimised_free.png", "optimised_frusta.png", "corner_coverage_top.png",
        "corner_slices.png", "corner_free.png", "corner_frusta.png"}) {
    EXPECT_GT(fs::exists(dir_ / "a" / f) ? fs::file_size(dir_ / "a" / f) : 0u, 100u) << f;
  }
  const YAML::Node report = YAML::LoadFile(Path("a/report.json"));  // JSON is YAML.
  EXPECT_EQ(report["cameras"].as<int>(), 3);
  EXPECT_EQ(report["min_views"].as<int>(), 2);
  const double optimised = report["layouts"]["optimised"]["score"].as<double>();
  const double corner = report["layouts"]["corner"]["score"].as<double>();
  EXPECT_GE(optimised, corner);
  EXPECT_EQ(report["layouts"]["optimised"]["cameras"].size(), 3u);
  const std::string md = ReadFile(dir_ / "a" / "report.md");
  EXPECT_NE(md.find("| corner heuristic |"), std::string::npos);
  EXPECT_NE(md.find("seen by >= 2 cameras"), std::string::npos);
}

TEST_F(PlaceCliTest, SameSeedSameCamerasFile) {
  const auto a = Place(PaperCell(), "--cameras 2 --seed 9 --threads 1 --quiet", "a");
  const auto b = Place(PaperCell(), "--cameras 2 --seed 9 --threads 2 --quiet", "b");
  ASSERT_EQ(a.code, 0) << a.err;
  ASSERT_EQ(b.code, 0) << b.err;
  EXPECT_EQ(a.err, "");
  EXPECT_EQ(ReadFile(dir_ / "a.yaml"), ReadFile(dir_ / "b.yaml"));
  EXPECT_FALSE(ReadFile(dir_ / "a.yaml").empty());
}

TEST_F(PlaceCliTest, BadRequestsExitWithTwoAndSayWhy) {
  const auto none = Place(PaperCell(), "--cameras 0", "x");
  EXPECT_EQ(none.code, 2);
  EXPECT_NE(none.err.find("place: --cameras: must be at least 1 (got 0)"), std::string::npos)
      << none.err;
  // The cameras file must load in hullguardd and hullguard carve.
  const auto seventeen = Place(PaperCell(), "--cameras 17", "x");
  EXPECT_EQ(seventeen.code, 2);
  EXPECT_NE(seventeen.err.find("place: --cameras: at most 16 cameras, as hullguardd and hullguard "
                               "carve take (got 17)"),
            std::string::npos)
      << seventeen.err;
  const auto too_many = Place(PaperCell(), "--cameras 3 --min-views 4", "x");
  EXPECT_EQ(too_many.code, 2);
  EXPECT_NE(too_many.err.find("--min-views: must be between 1 and --cameras (3), got 4"),
            std::string::npos)
      << too_many.err;
  std::ofstream(Path("bare.yaml"))
      << "scene: {name: bare, bounds: {min: [0, 0, 0], max: [3, 3, 2.5]}}\n"
         "cameras:\n  - {name: a, width: 320, height: 240, K: [240, 0, 159.5, 0, 240, 119.5, 0, "
         "0, 1], position: [0, 0, 2.4], look_at: [1.5, 1.5, 0.8]}\n"
         "mounting: []\n";
  const auto bare = Place(Path("bare.yaml"), "--cameras 2", "x");
  EXPECT_EQ(bare.code, 2);
  EXPECT_NE(bare.err.find(Path("bare.yaml") + ": mounting: scene has no mounting surface"),
            std::string::npos)
      << bare.err;
  EXPECT_FALSE(fs::exists(dir_ / "x.yaml"));

  // Output paths that cannot be written are named before the search (which
  // may take minutes), and nothing is left behind.
  const auto unwritable = testing::RunTool(
      HG_HULLGUARD_BIN, "place --scene " + PaperCell() + " --cameras 2 --out " +
                            Path("missing/dir/cams.yaml") + " --report " + Path("r"));
  EXPECT_EQ(unwritable.code, 2);
  EXPECT_NE(unwritable.err.find("place: --out: cannot write " + Path("missing/dir/cams.yaml")),
            std::string::npos)
      << unwritable.err;
  EXPECT_EQ(unwritable.err.find("evaluations"), std::string::npos) << "searched first";
  std::ofstream(Path("file")) << "a file\n";
  const auto report_on_file = Place(PaperCell(), "--cameras 2", "file");
  EXPECT_EQ(report_on_file.code, 2);
  EXPECT_NE(report_on_file.err.find("--report: " + Path("file") + " exists and is not a directory"),
            std::string::npos)
      << report_on_file.err;
  EXPECT_FALSE(fs::exists(dir_ / "file.yaml"));
  // Thread counts and budgets out of range: one line and exit 2 (100000
  // threads aborted the process).
  for (const std::string& bad : {std::string("--threads 100000"), std::string("--threads 0"),
                                 std::string("--budget -5"), std::string("--coverage-weight -1")}) {
    const auto r = Place(PaperCell(), "--cameras 2 " + bad, "x");
    EXPECT_EQ(r.code, 2) << bad << ": " << r.err;
    EXPECT_NE(r.err.find(bad.substr(0, bad.find(' '))), std::string::npos) << r.err;
  }
}

}  // namespace
}  // namespace hg
