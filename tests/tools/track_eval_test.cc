// End-to-end test of `hullguard track-eval`: a small scene file, the real
// binary (render, reconstruct, publish, track, score), its JSON read back.
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "support/run_tool.h"

namespace hg {
namespace {

namespace fs = std::filesystem;

// Four small cameras in the upper corners of a 3 m cell with a table; one
// person walks past the table, another stands and then crouches.
constexpr char kScene[] =
    R"(scene: {name: tiny_tracking, bounds: {min: [0, 0, 0], max: [3, 3, 2.5]}, rate_hz: 15}
cameras:
  - {name: a, width: 480, height: 270, K: [270, 0, 239.5, 0, 270, 134.5, 0, 0, 1],
     position: [-0.3, -0.3, 2.4], look_at: [1.5, 1.5, 0.8]}
  - {name: b, width: 480, height: 270, K: [270, 0, 239.5, 0, 270, 134.5, 0, 0, 1],
     position: [3.3, 3.3, 2.4], look_at: [1.5, 1.5, 0.8]}
  - {name: c, width: 480, height: 270, K: [270, 0, 239.5, 0, 270, 134.5, 0, 0, 1],
     position: [3.3, -0.3, 2.4], look_at: [1.5, 1.5, 0.8]}
  - {name: d, width: 480, height: 270, K: [270, 0, 239.5, 0, 270, 134.5, 0, 0, 1],
     position: [-0.3, 3.3, 2.4], look_at: [1.5, 1.5, 0.8]}
obstacles:
  - {name: table, box: {min: [2.0, 0.3, 0.70], max: [2.8, 1.0, 0.75]}}
people:
  - name: walker
    start: [0.6, 0.6]
    script:
      - walk: {path: [[1.6, 1.4]], speed: 1.0}
  - name: croucher
    start: [0.8, 2.3]
    script:
      - stand: {duration: 0.6}
      - crouch: {duration: 3}
)";

class TrackEvalTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           std::string("hg_track_eval_")
               .append(std::to_string(::getpid()))
               .append("_")
               .append(::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
    std::ofstream(Path("tiny.yaml")) << kScene;
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Path(const std::string& name) const { return (dir_ / name).string(); }
  static testing::ProcessResult Hullguard(const std::string& args) {
    return testing::RunTool(HG_HULLGUARD_BIN, args);
  }
  fs::path dir_;
};

// The text after "key": up to the next comma or brace.
std::string JsonField(const std::string& json, const std::string& key) {
  const auto at = json.find("\"" + key + "\": ");
  EXPECT_NE(at, std::string::npos) << key << " in " << json;
  if (at == std::string::npos) return "";
  const auto start = at + key.size() + 4;
  return json.substr(start, json.find_first_of(",}", start) - start);
}

double JsonNumber(const std::string& json, const std::string& key) {
  const std::string field = JsonField(json, key);
  return field.empty() || field == "null" ? -1e9 : std::stod(field);
}

TEST_F(TrackEvalTest, TracksTwoPeopleAndReportsPlausibleMetrics) {
  const auto r = Hullguard("track-eval --scene " + Path("tiny.yaml") +
                           " --frames 30 --depth 7 --publish-depth 6 --threads 2 --json --plot " +
                           Path("plot.png") + " --trace " + Path("trace.csv"));
  ASSERT_EQ(r.code, 0) << r.err << r.out;
  const std::string& j = r.out;
  EXPECT_EQ(JsonField(j, "scene"), "\"tiny_tracking\"");
  EXPECT_EQ(JsonNumber(j, "frames"), 30);
  EXPECT_EQ(JsonNumber(j, "objects"), 60);  // Both people in the cell in every frame.
  // Each frame's ground-truth objects are matched, missed, or both counts hold.
  EXPECT_EQ(JsonNumber(j, "matches") + JsonNumber(j, "misses"), JsonNumber(j, "objects"));
  // Both people are found at once and kept: at most the first frames of a
  // birth are lost, nobody is followed by two tracks.
  EXPECT_GE(JsonNumber(j, "mota"), 0.9);
  EXPECT_LE(JsonNumber(j, "mota"), 1.0);
  EXPECT_EQ(JsonNumber(j, "id_switches"), 0);
  EXPECT_LE(JsonNumber(j, "false_positives"), 2);
  EXPECT_GE(JsonNumber(j, "motp_m"), 0.0);
  EXPECT_LE(JsonNumber(j, "motp_m"), 0.2);
  EXPECT_EQ(JsonNumber(j, "births"), 2);
  EXPECT_EQ(JsonNumber(j, "deaths"), 0);
  EXPECT_GT(JsonNumber(j, "mean"), 0.0);  // tracking_ms.mean, the first "mean".
  EXPECT_NE(j.find("\"tracking_ms_per_person\": {\"mean\": "), std::string::npos) << j;
  EXPECT_NE(j.find("\"name\": \"walker\""), std::string::npos) << j;
  EXPECT_NE(j.find("\"name\": \"croucher\""), std::string::npos) << j;
  // The plot is a PNG.
  std::ifstream png(Path("plot.png"), std::ios::binary);
  ASSERT_TRUE(png.good());
  std::string head(8, '\0');
  png.read(head.data(), 8);
  EXPECT_EQ(head, std::string("\x89PNG\r\n\x1a\n", 8));
  // The trace: a truth row per person and frame, matched to a track row of
  // the same frame; the matched distances average to the MOTP.
  std::ifstream csv(Path("trace.csv"));
  std::string line;
  ASSERT_TRUE(std::getline(csv, line));
  EXPECT_EQ(line, "frame,time_s,kind,id,name,x,y,z,half_x,half_y,half_z,matched_id,distance_m");
  int truths = 0, matched = 0;
  double distance_sum = 0.0;
  std::set<std::string> tracks_seen;  // "frame/id" of each track row.
  std::vector<std::string> matches_wanted;
  while (std::getline(csv, line)) {
    std::vector<std::string> cell;
    std::stringstream row(line);
    for (std::string c; std::getline(row, c, ',');) cell.push_back(c);
    if (!line.empty() && line.back() == ',') cell.emplace_back();
    ASSERT_EQ(cell.size(), 13u) << line;
    if (cell[2] == "track") {
      tracks_seen.insert(cell[0] + "/" + cell[3]);
      continue;
    }
    ASSERT_EQ(cell[2], "truth") << line;
    ++truths;
    EXPECT_TRUE(cell[4] == "walker" || cell[4] == "croucher") << line;
    // The body box's half-extents: a person's size.
    const double half_z = std::stod(cell[10]);
    EXPECT_GT(std::stod(cell[8]), 0.05) << line;
    EXPECT_GT(std::stod(cell[9]), 0.05) << line;
    EXPECT_TRUE(half_z > 0.3 && half_z < 1.0) << line;
    if (cell[11].empty()) continue;
    ++matched;
    distance_sum += std::stod(cell[12]);
    matches_wanted.push_back(cell[0] + "/" + cell[11]);
  }
  EXPECT_EQ(truths, JsonNumber(j, "objects"));
  EXPECT_EQ(matched, JsonNumber(j, "matches"));
  for (const std::string& m : matches_wanted) EXPECT_EQ(tracks_seen.count(m), 1u) << m;
  ASSERT_GT(matched, 0);
  EXPECT_NEAR(distance_sum / matched, JsonNumber(j, "motp_m"), 1e-3);
}

// As in the daemon, an update the deadline cut off before it was refined
// anywhere (here: at once) is not tracked, and the report says so.
TEST_F(TrackEvalTest, UpdatesCutOffByTheDeadlineAreNotTracked) {
  const auto r = Hullguard("track-eval --scene " + Path("tiny.yaml") +
                           " --frames 4 --depth 6 --publish-depth 6 --coarse-first 3"
                           " --deadline-ms 0.001 --json");
  ASSERT_EQ(r.code, 0) << r.err << r.out;
  EXPECT_EQ(JsonNumber(r.out, "aborted_updates"), 4);
  EXPECT_EQ(JsonNumber(r.out, "untracked_frames"), 4);
  EXPECT_EQ(JsonNumber(r.out, "births"), 0);
}

TEST_F(TrackEvalTest, TextReportNamesTheMetrics) {
  const auto r = Hullguard("track-eval --scene " + Path("tiny.yaml") +
                           " --frames 4 --depth 6 --publish-depth 6");
  ASSERT_EQ(r.code, 0) << r.err;
  for (const char* key : {"MOTA", "MOTP", "ID switches", "misses", "false positives",
                          "tracking time per frame", "per person"}) {
    EXPECT_NE(r.out.find(key), std::string::npos) << key << " in " << r.out;
  }
}

TEST_F(TrackEvalTest, BadInputIsExitCodeTwo) {
  EXPECT_EQ(Hullguard("track-eval --scene " + Path("missing.yaml")).code, 2);
  const auto deep = Hullguard("track-eval --scene " + Path("tiny.yaml") +
                              " --frames 3 --depth 6 --publish-depth 7");
  EXPECT_EQ(deep.code, 2);
  EXPECT_NE(deep.err.find("--publish-depth"), std::string::npos) << deep.err;
  EXPECT_EQ(Hullguard("track-eval --scene " + Path("tiny.yaml") + " --threshold -1").code, 2);
}

}  // namespace
}  // namespace hg
