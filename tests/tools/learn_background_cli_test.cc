// Teaching the background on purpose: `hullguardd --learn-background` keeps
// every image camera's background, and with background.learn_at_start: false
// a camera with none to take up learns nothing at start and sees nothing
// (failed, unlearned, degraded) instead of learning whoever stands in view.
// Simulated colour cameras of tests/data/small_cell.yaml, DDS off (no sockets).
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <regex>
#include <string>

#include <gtest/gtest.h>

#include "support/run_tool.h"
#include "support/small_cell_config.h"

namespace hg {
namespace {

namespace fs = std::filesystem;

const std::string kScene = std::string(HG_SOURCE_DIR) + "/tests/data/small_cell.yaml";

class LearnBackgroundCliTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("hg_learn_background_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Path(const std::string& name) const { return (dir_ / name).string(); }
  // A config of simulated colour cameras (`colour`) or mask cameras, with `background`.
  std::string Write(const std::string& name, bool colour, const std::string& background) {
    std::ofstream(Path(name)) << testing::SmallCellConfig(
        "{type: sim, scene: " + kScene + (colour ? ", colour: true}" : "}"),
        "background: " + background + "\n");
    return Path(name);
  }
  static testing::ProcessResult Daemon(const std::string& args) {
    return testing::RunTool(HG_HULLGUARDD_BIN, args);
  }
  fs::path dir_;
};

TEST_F(LearnBackgroundCliTest, TaughtOnPurposeAndNeverLearnedAtStart) {
  const std::string kept = Path("kept");
  const std::string taught = Write(
      "taught.yaml", true, "{learn_frames: 5, keep_dir: " + kept + ", learn_at_start: false}");
  auto file = [&](const std::string& camera) {
    return fs::path(kept) / ("background-" + camera + ".bin");
  };

  // Never taught: every camera sees nothing, and says why.
  const auto untaught = Daemon("--config " + taught + " --duration 1.5");
  EXPECT_EQ(untaught.code, 0) << untaught.err;
  EXPECT_TRUE(std::regex_search(
      untaught.err, std::regex("cycle [0-9]+ DEGRADED .* cam0 failed [0-9]+ fps "
                               "\\(unlearned\\) cam1 failed [0-9]+ fps \\(unlearned\\)")))
      << untaught.err;
  EXPECT_NE(untaught.err.find("--learn-background"), std::string::npos) << untaught.err;
  EXPECT_FALSE(fs::exists(file("cam0"))) << "learned at start although learn_at_start is false";

  // Teaching: every camera learns afresh and keeps its background.
  const auto teach = Daemon("--config " + taught + " --learn-background");
  EXPECT_EQ(teach.code, 0) << teach.out << teach.err;
  for (const std::string camera : {"cam0", "cam1", "cam2"}) {
    EXPECT_NE(teach.out.find(camera + ": background kept in " + file(camera).string()),
              std::string::npos)
        << teach.out;
    EXPECT_TRUE(fs::exists(file(camera))) << camera;
  }

  // The next start takes it up: every camera ok.
  const auto run = Daemon("--config " + taught + " --duration 1.5");
  EXPECT_EQ(run.code, 0) << run.err;
  EXPECT_TRUE(std::regex_search(
      run.err, std::regex("cam0 ok [0-9]+ fps( margin [0-9.]+ cm)? cam1 ok [0-9]+ fps( margin "
                          "[0-9.]+ cm)? cam2 ok")))
      << run.err;
  EXPECT_EQ(run.err.find("unlearned"), std::string::npos) << run.err;

  // A camera whose file is gone sees nothing again; the others are unaffected.
  fs::remove(file("cam1"));
  const auto one_gone = Daemon("--config " + taught + " --duration 1.5");
  EXPECT_EQ(one_gone.code, 0) << one_gone.err;
  EXPECT_TRUE(std::regex_search(
      one_gone.err,
      std::regex(
          "DEGRADED .* cam0 ok [0-9]+ fps.* cam1 failed [0-9]+ fps \\(unlearned\\) cam2 ok")))
      << one_gone.err;
  EXPECT_FALSE(fs::exists(file("cam1")));

  // A teaching that cannot finish in time names the cameras and fails.
  const std::string slow =
      Write("slow.yaml", true, "{learn_frames: 1000, keep_dir: " + Path("slow") + "}");
  const auto timeout = Daemon("--config " + slow + " --learn-background --duration 0.5");
  EXPECT_EQ(timeout.code, 1) << timeout.out << timeout.err;
  EXPECT_NE(timeout.out.find("cam2: did not finish learning"), std::string::npos) << timeout.out;

  // Nothing to teach: mask cameras, or nowhere to keep it.
  const std::string masks = Write("masks.yaml", false, "{keep_dir: " + Path("masks") + "}");
  const auto nothing = Daemon("--config " + masks + " --learn-background");
  EXPECT_EQ(nothing.code, 2) << nothing.out << nothing.err;
  EXPECT_NE(nothing.err.find("no camera of this config delivers images"), std::string::npos)
      << nothing.err;
  const std::string nowhere = Write("nowhere.yaml", true, "{learn_frames: 5}");
  const auto no_dir = Daemon("--config " + nowhere + " --learn-background");
  EXPECT_EQ(no_dir.code, 2) << no_dir.err;
  EXPECT_NE(no_dir.err.find("background.keep_dir is not set"), std::string::npos) << no_dir.err;

  // learn_at_start: false needs a keep_dir: a config error with file and line.
  const std::string bad = Write("bad.yaml", true, "{learn_frames: 5, learn_at_start: false}");
  const auto check = Daemon("--check-config " + bad);
  EXPECT_EQ(check.code, 2) << check.err;
  EXPECT_NE(check.err.find(bad + ":9: background.learn_at_start: false needs background.keep_dir"),
            std::string::npos)
      << check.err;
}

}  // namespace
}  // namespace hg
