#include "geometry/camera_yaml.h"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include "common/config_error.h"

namespace hg::geometry {
namespace {

using common::ConfigError;

/// A temp file path unique to the running test, so parallel test processes do not collide.
std::string TempPath(const std::string& suffix) {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  return ::testing::TempDir() + "hg_camera_yaml_" + info->test_suite_name() + "_" + info->name() +
         "_" + suffix + ".yaml";
}

std::string WriteTemp(const std::string& text, const std::string& suffix = "in") {
  std::string path = TempPath(suffix);
  std::ofstream(path) << text;
  return path;
}

// Two valid cameras; the comments give the 1-based line numbers the tests rely on.
const char* const kCam0 =
    "cameras:\n"                                    // 1
    "  - name: cam0\n"                              // 2
    "    width: 640\n"                              // 3
    "    height: 480\n"                             // 4
    "    K: [500, 0, 320, 0, 500, 240, 0, 0, 1]\n"  // 5
    "    distortion: [0.1, -0.01, 0, 0, 0]\n"       // 6
    "    R: [1, 0, 0, 0, 1, 0, 0, 0, 1]\n"          // 7
    "    t: [0, 0, 2]\n";                           // 8
const char* const kCam1 =
    "  - name: cam1\n"                              // 9
    "    width: 320\n"                              // 10
    "    height: 240\n"                             // 11
    "    K: [250, 0, 160, 0, 250, 120, 0, 0, 1]\n"  // 12
    "    R: [0, -1, 0, 1, 0, 0, 0, 0, 1]\n"         // 13
    "    t: [1, 2, 3]\n";                           // 14

/// Replaces the one occurrence of `from` in `text`.
std::string Replace(std::string text, const std::string& from, const std::string& to) {
  const std::size_t at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  EXPECT_EQ(text.find(from, at + 1), std::string::npos) << from;
  return at == std::string::npos ? text : text.replace(at, from.size(), to);
}

/// Loads `text` and expects a ConfigError "FILE:LINE: ..." containing every fragment.
void ExpectError(const std::string& text, int line, const std::vector<std::string>& fragments) {
  const std::string path = WriteTemp(text);
  try {
    (void)LoadCamerasFile(path);
    ADD_FAILURE() << "no error for:\n" << text;
  } catch (const ConfigError& e) {
    const std::string message = e.what();
    const std::string prefix = path + ":" + (line > 0 ? std::to_string(line) + ":" : "") + " ";
    EXPECT_EQ(message.rfind(prefix, 0), 0u) << "expected prefix '" << prefix << "' in: " << message;
    for (const std::string& f : fragments) {
      EXPECT_NE(message.find(f), std::string::npos) << "expected '" << f << "' in: " << message;
    }
  }
}

Eigen::Matrix3d RandomRotation(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  return Eigen::Quaterniond(unit(rng), unit(rng), unit(rng), unit(rng))
      .normalized()
      .toRotationMatrix();
}

TEST(CameraYamlTest, LoadsBothCameras) {
  const std::vector<CameraModel> cams = LoadCamerasFile(WriteTemp(std::string(kCam0) + kCam1));
  ASSERT_EQ(cams.size(), 2u);
  EXPECT_EQ(cams[0].name, "cam0");
  EXPECT_EQ(cams[0].width, 640);
  EXPECT_EQ(cams[0].height, 480);
  EXPECT_EQ(cams[0].K(0, 2), 320.0);
  EXPECT_EQ(cams[0].distortion[0], 0.1);
  EXPECT_EQ(cams[0].t_CW.z(), 2.0);
  EXPECT_EQ(cams[1].name, "cam1");
  EXPECT_FALSE(cams[1].HasDistortion());  // `distortion` is optional.
  EXPECT_EQ(cams[1].R_CW(0, 1), -1.0);
  EXPECT_EQ(cams[1].t_CW, Eigen::Vector3d(1, 2, 3));
}

// Width and height default to Full HD.
TEST(CameraYamlTest, SizeDefaultsToFullHd) {
  const std::vector<CameraModel> cams =
      LoadCamerasFile(WriteTemp(std::string(kCam0) + Replace(Replace(kCam1, "    width: 320\n", ""),
                                                             "    height: 240\n", "")));
  ASSERT_EQ(cams.size(), 2u);
  EXPECT_EQ(cams[1].width, 1920);
  EXPECT_EQ(cams[1].height, 1080);
  EXPECT_EQ(cams[0].width, 640);  // Given: kept.
}

TEST(CameraYamlTest, WriteThenLoadIsExact) {
  std::mt19937_64 rng(42);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  std::vector<CameraModel> cams;
  for (const char* name : {"left", "cam #2", "3", "yes"}) {
    CameraModel c;
    c.name = name;
    c.width = 1920;
    c.height = 1080;
    c.K << 1000 + 100 * unit(rng), 0.01 * unit(rng), 960 + unit(rng), 0, 1000 + 100 * unit(rng),
        540 + unit(rng), 0, 0, 1;
    for (double& d : c.distortion) {
      d = 0.1 * unit(rng);
    }
    c.distortion[3] = -0.0;
    c.R_CW = RandomRotation(rng);
    c.t_CW = Eigen::Vector3d(unit(rng), unit(rng), 1e-17 * unit(rng));
    cams.push_back(c);
  }
  const std::string path = TempPath("out");
  WriteCamerasFile(path, cams);
  const std::vector<CameraModel> back = LoadCamerasFile(path);
  ASSERT_EQ(back.size(), cams.size());
  for (std::size_t i = 0; i < cams.size(); ++i) {
    EXPECT_EQ(back[i].name, cams[i].name);
    EXPECT_EQ(back[i].width, cams[i].width);
    EXPECT_EQ(back[i].height, cams[i].height);
    EXPECT_EQ(back[i].K, cams[i].K) << i;  // Bit-exact, not approximately equal.
    EXPECT_EQ(back[i].R_CW, cams[i].R_CW) << i;
    EXPECT_EQ(back[i].t_CW, cams[i].t_CW) << i;
    for (int k = 0; k < 5; ++k) {
      EXPECT_EQ(back[i].distortion[k], cams[i].distortion[k]) << i;
    }
  }
  EXPECT_TRUE(std::signbit(back[0].distortion[3]));
}

TEST(CameraYamlTest, ProjectionMatrixFormIsDecomposed) {
  std::mt19937_64 rng(3);
  CameraModel c;
  c.K << 812.5, 0.25, 330.5, 0, 805.0, 241.0, 0, 0, 1;
  c.R_CW = RandomRotation(rng);
  c.t_CW = Eigen::Vector3d(0.3, -0.4, 2.5);
  const Eigen::Matrix<double, 3, 4> P = -2.5 * c.ProjectionMatrix();
  std::string p_list;
  for (int r = 0; r < 3; ++r) {
    for (int k = 0; k < 4; ++k) {
      char buf[40];
      std::snprintf(buf, sizeof(buf), "%s%.17g", p_list.empty() ? "" : ", ", P(r, k));
      p_list += buf;
    }
  }
  const std::string text =
      "cameras:\n"
      "  - name: p_cam\n"
      "    width: 640\n"
      "    height: 480\n"
      "    distortion: [-0.2, 0.05, 0, 0, 0]\n"
      "    P: [" +
      p_list + "]\n";
  const std::vector<CameraModel> cams = LoadCamerasFile(WriteTemp(text));
  ASSERT_EQ(cams.size(), 1u);
  EXPECT_LT((cams[0].K - c.K).norm(), 1e-9);
  EXPECT_LT((cams[0].R_CW - c.R_CW).norm(), 1e-12);
  EXPECT_LT((cams[0].t_CW - c.t_CW).norm(), 1e-12);
  EXPECT_EQ(cams[0].distortion[0], -0.2);
}

TEST(CameraYamlTest, ParseCameraAloneNamesKeyWithoutListPrefix) {
  const YAML::Node node = YAML::Load(
      "name: solo\n"
      "width: 64\n"
      "height: 48\n"
      "K: [50, 0, 32, 0, 50, 24, 0, 0]\n"
      "R: [1, 0, 0, 0, 1, 0, 0, 0, 1]\n"
      "t: [0, 0, 1]\n");
  try {
    (void)ParseCamera(node, "inline.yaml");
    ADD_FAILURE() << "no error";
  } catch (const ConfigError& e) {
    EXPECT_STREQ(e.what(), "inline.yaml:4: K: expected 9 numbers, got 8");
  }
}

/// A camera entry in the position + look_at form (lines 2..7 of the file).
std::string LookAtCamera(const Eigen::Vector3d& position, const Eigen::Vector3d& look_at,
                         const std::string& up = "") {
  char buf[512];
  std::snprintf(buf, sizeof(buf),
                "cameras:\n"
                "  - name: la\n"
                "    width: 640\n"
                "    height: 480\n"
                "    K: [500, 0, 330.5, 0, 510, 235.25, 0, 0, 1]\n"
                "    position: [%.17g, %.17g, %.17g]\n"
                "    look_at: [%.17g, %.17g, %.17g]\n",
                position.x(), position.y(), position.z(), look_at.x(), look_at.y(), look_at.z());
  return std::string(buf) + (up.empty() ? "" : "    up: " + up + "\n");
}

TEST(CameraYamlLookAtTest, TargetProjectsToPrincipalPointAndUpIsUp) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> unit(-3.0, 3.0);
  for (int trial = 0; trial < 50; ++trial) {
    const Eigen::Vector3d position(unit(rng), unit(rng), unit(rng));
    const Eigen::Vector3d look_at(unit(rng), unit(rng), 0.2 * unit(rng));
    if ((look_at - position).normalized().z() > 0.95 ||
        (look_at - position).normalized().z() < -0.95) {
      continue;  // Near-vertical views are covered below.
    }
    SCOPED_TRACE(trial);
    const std::vector<CameraModel> cams =
        LoadCamerasFile(WriteTemp(LookAtCamera(position, look_at)));
    ASSERT_EQ(cams.size(), 1u);
    const CameraModel& c = cams[0];
    EXPECT_LT((c.R_CW.transpose() * c.R_CW - Eigen::Matrix3d::Identity()).norm(), 1e-12);
    EXPECT_NEAR(c.R_CW.determinant(), 1.0, 1e-12);
    EXPECT_LT((c.CentreW() - position).norm(), 1e-9);
    const std::optional<Eigen::Vector2d> target = c.Project(look_at);
    ASSERT_TRUE(target.has_value());
    EXPECT_NEAR(target->x(), 330.5, 1e-6);
    EXPECT_NEAR(target->y(), 235.25, 1e-6);
    // A point above the target appears above it (smaller v) and not sideways:
    // the image x axis is horizontal.
    const std::optional<Eigen::Vector2d> above = c.Project(look_at + Eigen::Vector3d(0, 0, 0.1));
    ASSERT_TRUE(above.has_value());
    EXPECT_LT(above->y(), target->y());
    EXPECT_NEAR(c.R_CW.row(0).z(), 0.0, 1e-12);
  }
}

TEST(CameraYamlLookAtTest, ExplicitUpAndVerticalView) {
  // Looking along +x with up = +y: world +y is up in the image, +z points right.
  const std::vector<CameraModel> side =
      LoadCamerasFile(WriteTemp(LookAtCamera({0, 0, 0}, {2, 0, 0}, "[0, 2, 0]")));
  const Eigen::Matrix3d expected_side =
      (Eigen::Matrix3d() << 0, 0, 1, 0, -1, 0, 1, 0, 0).finished();
  EXPECT_LT((side[0].R_CW - expected_side).norm(), 1e-12);

  // Straight down without `up`: +y is used as up, so world +x points right.
  const std::vector<CameraModel> down =
      LoadCamerasFile(WriteTemp(LookAtCamera({1, 2, 3}, {1, 2, 0}), "down"));
  const Eigen::Matrix3d expected_down =
      (Eigen::Matrix3d() << 1, 0, 0, 0, -1, 0, 0, 0, -1).finished();
  EXPECT_LT((down[0].R_CW - expected_down).norm(), 1e-12);
  const std::optional<Eigen::Vector2d> p = down[0].Project({1, 2, 0});
  ASSERT_TRUE(p.has_value());
  EXPECT_NEAR(p->x(), 330.5, 1e-9);
  EXPECT_NEAR(p->y(), 235.25, 1e-9);
}

TEST(CameraYamlLookAtTest, WrittenAsRotationAndTranslation) {
  const std::vector<CameraModel> cams =
      LoadCamerasFile(WriteTemp(LookAtCamera({-0.3, -0.3, 3.6}, {2, 2, 1})));
  const std::string path = TempPath("out");
  WriteCamerasFile(path, cams);
  std::ifstream in(path);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("R: ["), std::string::npos) << text;
  EXPECT_NE(text.find("t: ["), std::string::npos) << text;
  EXPECT_EQ(text.find("position"), std::string::npos) << text;
  const std::vector<CameraModel> back = LoadCamerasFile(path);
  ASSERT_EQ(back.size(), 1u);
  EXPECT_EQ(back[0].R_CW, cams[0].R_CW);
  EXPECT_EQ(back[0].t_CW, cams[0].t_CW);
}

TEST(CameraYamlLookAtTest, Errors) {
  const std::string base = LookAtCamera({0, 0, 2}, {1, 1, 0});
  ExpectError(base + "    R: [1, 0, 0, 0, 1, 0, 0, 0, 1]\n", 8,
              {"cameras[0]: give either R+t or position+look_at (+up), not both"});
  ExpectError(base + "    t: [0, 0, 1]\n", 8,
              {"cameras[0]: give either R+t or position+look_at (+up), not both"});
  ExpectError(Replace(std::string(kCam0), "    t: [0, 0, 2]\n", "    up: [0, 0, 1]\n"), 7,
              {"cameras[0]: give either R+t or position+look_at"});
  ExpectError(base + "    P: [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0]\n", 8,
              {"cameras[0]: give either K+R+t or P, not both"});
  ExpectError(Replace(Replace(base, "    K: [500, 0, 330.5, 0, 510, 235.25, 0, 0, 1]\n", ""),
                      "    look_at:", "    P: [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0]\n    look_at:"),
              6, {"cameras[0]: give either K+position+look_at or P, not both"});
  ExpectError(Replace(base, "    look_at: [1, 1, 0]\n", ""), 2,
              {"cameras[0]: missing key 'look_at'"});
  ExpectError(Replace(base, "    position: [0, 0, 2]\n", ""), 2,
              {"cameras[0]: missing key 'position'"});
  ExpectError(Replace(base, "    K: [500, 0, 330.5, 0, 510, 235.25, 0, 0, 1]\n", ""), 2,
              {"cameras[0]: missing key 'K'"});
  ExpectError(Replace(base, "look_at: [1, 1, 0]", "look_at: [0, 0, 2]"), 7,
              {"cameras[0].look_at: must differ from position"});
  ExpectError(Replace(base, "look_at: [1, 1, 0]", "look_at: [1, 1]"), 7,
              {"cameras[0].look_at: expected 3 numbers, got 2"});
  ExpectError(Replace(base, "position: [0, 0, 2]", "position: [0, .inf, 2]"), 6,
              {"cameras[0].position[1]: not finite"});
  ExpectError(base + "    up: [0, 0, 0]\n", 8, {"cameras[0].up: must not be zero"});
  // Beyond 1e6 m the norms overflow and the pose came out as R = 0, t = 0.
  ExpectError(Replace(base, "position: [0, 0, 2]", "position: [1e200, 0, 2]"), 6,
              {"cameras[0].position: more than 1e6 m from the origin"});
  ExpectError(Replace(base, "look_at: [1, 1, 0]", "look_at: [1, 1e200, 0]"), 7,
              {"cameras[0].look_at: more than 1e6 m from the origin"});
  ExpectError(base + "    up: [-1, -1, 2]\n", 8,
              {"cameras[0].up: (nearly) parallel to the viewing direction"});
  ExpectError(Replace(base, "K: [500,", "K: [-500,"), 5, {"cameras[0].K: focal lengths"});
  ExpectError(Replace(base, "K: [500,", "K: [5101,"), 5,
              {"cameras[0].K: focal lengths more than 10 times apart (got 5101, 510)"});
  ExpectError(Replace(Replace(base, "width: 640", "width: 9000"), "height: 480", "height: 8000"), 3,
              {"cameras[0].width: an image of 9000 x 8000 pixels is too large"});
  ExpectError(Replace(base, "K: [500,", "K: [50,"), 5,
              {"cameras[0].K: focal lengths more than 10 times apart (got 50, 510)"});
  ExpectError(Replace(Replace(base, "K: [500,", "K: [3,"), "510,", "6,"), 5,
              {"cameras[0].K: the image reaches 110.167 focal lengths"});
}

TEST(CameraYamlErrorTest, WrongCount) {
  ExpectError(std::string(kCam0) + Replace(kCam1, "120, 0, 0, 1]", "120, 0, 1]"), 12,
              {"cameras[1].K: expected 9 numbers, got 8"});
  ExpectError(Replace(kCam0, "[0.1, -0.01, 0, 0, 0]", "[0.1, -0.01, 0, 0]"), 6,
              {"cameras[0].distortion: expected 5 numbers, got 4"});
  ExpectError(Replace(kCam0, "t: [0, 0, 2]", "t: 2"), 8,
              {"cameras[0].t: expected a list of 3 numbers"});
}

TEST(CameraYamlErrorTest, NotANumber) {
  ExpectError(Replace(kCam0, "K: [500, 0, 320,", "K: [500, 0, abc,"), 5,
              {"cameras[0].K[2]: not a number"});
  ExpectError(Replace(kCam0, "t: [0, 0, 2]", "t: [0, .nan, 2]"), 8,
              {"cameras[0].t[1]: not finite"});
  // Elements of a block sequence report their own line.
  ExpectError(Replace(kCam0, "t: [0, 0, 2]", "t:\n      - 0\n      - [1]\n      - 2"), 10,
              {"cameras[0].t[1]: not a number"});
}

TEST(CameraYamlErrorTest, UnknownDuplicateAndMissingKeys) {
  ExpectError(std::string(kCam0) + "    foo: 1\n" + kCam1, 9, {"cameras[0]: unknown key 'foo'"});
  ExpectError(std::string(kCam0) + "    width: 640\n", 9, {"cameras[0]: duplicate key 'width'"});
  ExpectError(Replace(kCam0, "    t: [0, 0, 2]\n", ""), 2, {"cameras[0]: missing key 't'"});
  ExpectError(Replace(kCam0, "  - name: cam0\n", "  - width: 1\n"), 3,
              {"cameras[0]: duplicate key 'width'"});
  ExpectError(Replace(kCam0, "  - name: cam0\n    width: 640\n", "  - width: 640\n"), 2,
              {"cameras[0]: missing key 'name'"});
}

// Where names become file and folder names (a scene's cameras: synth's
// masks/<camera>/; the daemon's: kept backgrounds, recordings), nothing that
// could leave the folder or spell a path two ways; a cameras file for carve
// takes any name.
TEST(CameraYamlErrorTest, NamesThatCannotNameAFile) {
  for (const char* name : {"../x", "a/b", "/abs", ".hidden", "cam #2", "caf\xc3\xa9"}) {
    SCOPED_TRACE(name);
    const std::string text =
        Replace(kCam0, "  - name: cam0\n", std::string("  - name: \"") + name + "\"\n");
    EXPECT_EQ(LoadCamerasFile(WriteTemp(text)).at(0).name, name);
    try {
      (void)ParseCameraList(YAML::Load(text)["cameras"], "f.yaml", /*file_names=*/true);
      ADD_FAILURE() << "accepted";
    } catch (const ConfigError& e) {
      EXPECT_EQ(std::string(e.what()),
                "f.yaml:2: cameras[0].name: '" + std::string(name) +
                    "' cannot name the camera's files and folders: letters, digits, '_', '-' and "
                    "'.', not starting with '.'");
    }
  }
  EXPECT_EQ(FileNameProblem("cam.2-b_X"), "");
}

TEST(CameraYamlErrorTest, KRtAndPTogether) {
  ExpectError(std::string(kCam0) + "    P: [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0]\n", 9,
              {"cameras[0]: give either K+R+t or P, not both"});
}

TEST(CameraYamlErrorTest, RankDeficientP) {
  ExpectError(
      "cameras:\n"
      "  - name: p\n"
      "    width: 10\n"
      "    height: 10\n"
      "    P: [1, 0, 0, 0, 0, 1, 0, 0, 1, 1, 0, 0]\n",
      5, {"cameras[0].P: P has rank < 3"});
  // Rank 3, but no pinhole camera: its centre is at infinity.
  ExpectError(
      "cameras:\n"
      "  - name: p\n"
      "    width: 10\n"
      "    height: 10\n"
      "    P: [1, 0, 0, 0, 0, 1, 0, 0, 1, 1, 0, 1]\n",
      5, {"cameras[0].P: P's left 3x3 block is singular"});
}

TEST(CameraYamlErrorTest, BadRotationAndIntrinsics) {
  ExpectError(Replace(kCam0, "R: [1, 0, 0, 0, 1, 0, 0, 0, 1]", "R: [1, 0, 0, 0, 1, 0, 0, 0, 1.1]"),
              7, {"cameras[0].R: R is not a rotation (|R^T R - I| = "});
  // A reflection is orthogonal but not a rotation.
  ExpectError(Replace(kCam0, "R: [1, 0, 0, 0, 1, 0, 0, 0, 1]", "R: [1, 0, 0, 0, 1, 0, 0, 0, -1]"),
              7, {"cameras[0].R: R is not a rotation"});
  ExpectError(Replace(kCam0, "0, 500, 240, 0, 0, 1]", "0, 500, 240, 0, 0, 2]"), 5,
              {"cameras[0].K: must be upper triangular"});
  ExpectError(Replace(kCam0, "K: [500,", "K: [-500,"), 5, {"cameras[0].K: focal lengths"});
}

TEST(CameraYamlErrorTest, BadImageSize) {
  // Decimal digits only: yaml-cpp would read 01200 as octal (640), 0x280 as
  // hex, and a quoted "640" as a number.
  for (const char* bad :
       {"-640", "0", "640.5", "abc", "[640]", "100000", "01200", "0x280", "\"640\"", "+640"}) {
    ExpectError(Replace(kCam0, "width: 640", std::string("width: ") + bad), 3,
                {"cameras[0].width: expected a positive integer"});
  }
  ExpectError(Replace(kCam0, "height: 480", "height: -1"), 4,
              {"cameras[0].height: expected a positive integer"});
}

TEST(CameraYamlErrorTest, BadName) {
  ExpectError(std::string(kCam0) + Replace(kCam1, "name: cam1", "name: cam0"), 9,
              {"cameras[1].name: duplicate camera name 'cam0' (first at line 2)"});
  ExpectError(Replace(kCam0, "name: cam0", "name: [a]"), 2,
              {"cameras[0].name: expected a non-empty string"});
  ExpectError(Replace(kCam0, "name: cam0", "name: ''"), 2,
              {"cameras[0].name: expected a non-empty string"});
}

TEST(CameraYamlErrorTest, FileStructure) {
  ExpectError(std::string(kCam0) + "extra: 1\n", 9, {"unknown key 'extra'"});
  ExpectError("cams:\n  - name: a\n", 1, {"unknown key 'cams'"});
  ExpectError("- 1\n- 2\n", 1, {"expected a map with the single key 'cameras'"});
  ExpectError("", 0, {"expected a map with the single key 'cameras'"});
  ExpectError("cameras: []\n", 1, {"cameras: expected a non-empty list"});
  ExpectError("cameras:\n  name: a\n", 2, {"cameras: expected a non-empty list"});
  ExpectError("cameras:\n  - 5\n", 2, {"cameras[0]: expected a map"});
  ExpectError(std::string(kCam0) + "cameras:\n" + kCam1, 9, {"duplicate key 'cameras'"});
}

TEST(CameraYamlErrorTest, MalformedYamlReportsParserLine) {
  ExpectError(Replace(kCam0, "width: 640", "width: 640: 3"), 3, {"malformed YAML"});
  ExpectError(Replace(kCam0, "t: [0, 0, 2]", "t: [0, 0, 2]]"), 8, {"malformed YAML"});
}

TEST(CameraYamlErrorTest, MissingFile) {
  const std::string path = TempPath("does_not_exist");
  std::remove(path.c_str());
  try {
    (void)LoadCamerasFile(path);
    ADD_FAILURE() << "no error";
  } catch (const ConfigError& e) {
    EXPECT_EQ(std::string(e.what()), path + ": cannot open: no such file");
  }
}

TEST(CameraYamlErrorTest, UnwritablePath) {
  EXPECT_THROW(WriteCamerasFile("/nonexistent_dir_hg/cams.yaml", {}), ConfigError);
}

}  // namespace
}  // namespace hg::geometry
