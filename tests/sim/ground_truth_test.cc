#include "sim/ground_truth.h"

#include <bit>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <system_error>
#include <vector>

#include <unistd.h>

#include <gtest/gtest.h>

#include "common/config_error.h"

namespace hg::sim {
namespace {

using Eigen::Vector3d;

// The process id keeps concurrent runs (parallel ctest, several build trees)
// from writing each other's files.
std::string TempPath(const std::string& name) {
  return (std::filesystem::path(::testing::TempDir()) /
          ("hg_ground_truth_test_" + std::to_string(::getpid()) + "_" + name))
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

std::string ReadText(const std::string& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

void WriteText(const std::string& path, const std::string& text) { std::ofstream(path) << text; }

bool SameBits(double a, double b) {
  return std::bit_cast<std::uint64_t>(a) == std::bit_cast<std::uint64_t>(b);
}

bool SameBits(const Vector3d& a, const Vector3d& b) {
  return SameBits(a.x(), b.x()) && SameBits(a.y(), b.y()) && SameBits(a.z(), b.z());
}

Action Act(ActionKind kind, double start_s, double duration_s) {
  Action a;
  a.kind = kind;
  a.start_s = start_s;
  a.duration_s = duration_s;
  return a;
}

/// Ground truth of two people over a few frames, plus a frame with nobody and
/// awkward numbers (negative zero, tiny, huge, not representable in decimal).
GroundTruth SampleTruth() {
  Person alice;
  alice.name = "alice";
  Action walk = Act(ActionKind::kWalk, 0.0, 3.0);
  walk.path_W = {Vector3d(2.0, 1.0, 0.0)};
  alice.actions.push_back(walk);
  Person bob;
  bob.name = "bob smith: the \"second\"";
  bob.height_m = 1.9;
  bob.start_W = Vector3d(-1.0, 0.5, 0.1);
  bob.actions.push_back(Act(ActionKind::kCrouch, 0.0, 5.0));

  GroundTruth truth;
  truth.scene = "test cell";
  truth.rate_hz = 29.97;
  for (int f = 0; f < 5; ++f) {
    FrameTruth frame;
    frame.frame = f;
    frame.time_s = f / truth.rate_hz;
    frame.people.push_back({alice.name, EvaluatePerson(alice, frame.time_s)});
    frame.people.push_back({bob.name, EvaluatePerson(bob, frame.time_s)});
    truth.frames.push_back(frame);
  }
  FrameTruth empty;
  empty.frame = 5;
  empty.time_s = 0.1;
  truth.frames.push_back(empty);
  FrameTruth odd = truth.frames[0];
  odd.frame = 6;
  odd.time_s = -0.0;
  BodyState& s = odd.people[0].state;
  s.heading_rad = -3.141592653589793;
  s.velocity_W = Vector3d(-0.0, 1e-300, 1.0 / 3.0);
  s.centre_W = Vector3d(1e10, -2.5e-7, std::nextafter(1.0, 2.0));
  s.action = ActionKind::kReach;
  odd.people[1].state.action = ActionKind::kCrawl;
  truth.frames.push_back(odd);
  return truth;
}

void ExpectSame(const GroundTruth& a, const GroundTruth& b) {
  EXPECT_EQ(a.scene, b.scene);
  EXPECT_TRUE(SameBits(a.rate_hz, b.rate_hz));
  ASSERT_EQ(a.frames.size(), b.frames.size());
  for (std::size_t f = 0; f < a.frames.size(); ++f) {
    const FrameTruth& fa = a.frames[f];
    const FrameTruth& fb = b.frames[f];
    EXPECT_EQ(fa.frame, fb.frame);
    EXPECT_TRUE(SameBits(fa.time_s, fb.time_s)) << f;
    ASSERT_EQ(fa.people.size(), fb.people.size());
    for (std::size_t p = 0; p < fa.people.size(); ++p) {
      const BodyState& sa = fa.people[p].state;
      const BodyState& sb = fb.people[p].state;
      EXPECT_EQ(fa.people[p].name, fb.people[p].name);
      EXPECT_EQ(sa.action, sb.action);
      EXPECT_TRUE(SameBits(sa.heading_rad, sb.heading_rad));
      EXPECT_TRUE(SameBits(sa.centre_W, sb.centre_W));
      EXPECT_TRUE(SameBits(sa.ellipsoid_half_axes_m, sb.ellipsoid_half_axes_m));
      EXPECT_TRUE(SameBits(sa.velocity_W, sb.velocity_W));
      for (int k = 0; k < kNumBodyParts; ++k) {
        EXPECT_EQ(sa.parts[k].part, sb.parts[k].part);
        EXPECT_TRUE(SameBits(sa.parts[k].a_W, sb.parts[k].a_W)) << f << " " << p << " " << k;
        EXPECT_TRUE(SameBits(sa.parts[k].b_W, sb.parts[k].b_W));
        EXPECT_TRUE(SameBits(sa.parts[k].radius_m, sb.parts[k].radius_m));
      }
    }
  }
}

TEST(GroundTruthTest, RoundTripIsExact) {
  const GroundTruth truth = SampleTruth();
  const ScopedFile file{TempPath("round_trip.yaml")};
  WriteGroundTruth(file.path, truth);
  const GroundTruth back = ReadGroundTruth(file.path);
  ExpectSame(truth, back);
  // Writing what was read gives the same text.
  const ScopedFile again{TempPath("round_trip_again.yaml")};
  WriteGroundTruth(again.path, back);
  EXPECT_EQ(ReadText(file.path), ReadText(again.path));
}

TEST(GroundTruthTest, RandomNumbersRoundTripExactly) {
  std::mt19937_64 rng(99);
  std::uniform_int_distribution<std::uint64_t> bits;
  GroundTruth truth = SampleTruth();
  truth.frames.resize(2);
  // Arbitrary finite doubles, all exponents.
  auto random_double = [&]() {
    for (;;) {
      const double v = std::bit_cast<double>(bits(rng));
      if (std::isfinite(v)) {
        return v;
      }
    }
  };
  for (FrameTruth& frame : truth.frames) {
    for (PersonTruth& person : frame.people) {
      for (BodyCapsule& c : person.state.parts) {
        c.a_W = Vector3d(random_double(), random_double(), random_double());
        c.b_W = Vector3d(random_double(), random_double(), random_double());
        c.radius_m = std::abs(random_double()) + std::numeric_limits<double>::denorm_min();
      }
      person.state.heading_rad = random_double();
    }
  }
  const ScopedFile file{TempPath("random.yaml")};
  WriteGroundTruth(file.path, truth);
  ExpectSame(truth, ReadGroundTruth(file.path));
}

TEST(GroundTruthTest, EmptySequence) {
  GroundTruth truth;
  truth.scene = "empty";
  const ScopedFile file{TempPath("empty.yaml")};
  WriteGroundTruth(file.path, truth);
  const GroundTruth back = ReadGroundTruth(file.path);
  EXPECT_EQ(back.scene, "empty");
  EXPECT_EQ(back.rate_hz, 30.0);
  EXPECT_TRUE(back.frames.empty());
}

TEST(GroundTruthTest, FileStartsWithTheDocumentedHeader) {
  GroundTruth truth = SampleTruth();
  truth.scene = "cell";
  truth.rate_hz = 30.0;
  const ScopedFile file{TempPath("header.yaml")};
  WriteGroundTruth(file.path, truth);
  const std::string text = ReadText(file.path);
  EXPECT_EQ(text.rfind("ground_truth: {scene: cell, rate_hz: 30, frames: 7}\nframes:\n", 0), 0u)
      << text.substr(0, 200);
  EXPECT_NE(text.find("head: {a: ["), std::string::npos);
  EXPECT_NE(text.find("action: walk"), std::string::npos);
  EXPECT_NE(text.find("ellipsoid_half_axes: ["), std::string::npos);
}

TEST(GroundTruthTest, NonFiniteNumbersAreNotWritten) {
  GroundTruth truth = SampleTruth();
  truth.frames[2].people[1].state.parts[3].b_W.y() = std::numeric_limits<double>::quiet_NaN();
  const ScopedFile file{TempPath("nan.yaml")};
  try {
    WriteGroundTruth(file.path, truth);
    FAIL() << "expected ConfigError";
  } catch (const common::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("frames[2].people[1].parts.upper_arm_left.b: not finite"),
              std::string::npos)
        << e.what();
  }
}

/// A valid file's lines, to corrupt one at a time.
class MalformedGroundTruthTest : public ::testing::Test {
 protected:
  void SetUp() override {
    GroundTruth truth = SampleTruth();
    truth.frames.resize(2);
    const ScopedFile file{TempPath("valid.yaml")};
    WriteGroundTruth(file.path, truth);
    std::istringstream in(ReadText(file.path));
    for (std::string line; std::getline(in, line);) {
      lines_.push_back(line);
    }
  }

  /// 0-based index of the n-th (0-based) line containing `needle`.
  int Find(const std::string& needle, int n = 0) const {
    for (std::size_t i = 0; i < lines_.size(); ++i) {
      if (lines_[i].find(needle) != std::string::npos && n-- == 0) {
        return static_cast<int>(i);
      }
    }
    ADD_FAILURE() << "no line with " << needle;
    return 0;
  }

  /// Reads the corrupted lines; returns the ConfigError message ("" if none).
  std::string Error(const std::vector<std::string>& lines) const {
    const ScopedFile file{TempPath("bad.yaml")};
    std::string text;
    for (const std::string& line : lines) {
      text += line + "\n";
    }
    WriteText(file.path, text);
    try {
      (void)ReadGroundTruth(file.path);
    } catch (const common::ConfigError& e) {
      return e.what();
    }
    return "";
  }

  /// Expected message start: "file:line: " where `index` is 0-based.
  static std::string At(int index) {
    return TempPath("bad.yaml") + ":" + std::to_string(index + 1) + ": ";
  }

  std::vector<std::string> lines_;
};

TEST_F(MalformedGroundTruthTest, ValidFileReads) { EXPECT_EQ(Error(lines_), ""); }

TEST_F(MalformedGroundTruthTest, BadNumberNamesFileLineAndKey) {
  std::vector<std::string> lines = lines_;
  // Second frame, first person: its head radius becomes text.
  const int i = Find("head: {", 2);
  const std::size_t r = lines[i].find("radius: ");
  ASSERT_NE(r, std::string::npos);
  lines[i] = lines[i].substr(0, r) + "radius: oops}";
  EXPECT_EQ(Error(lines), At(i) + "frames[1].people[0].parts.head.radius: not a number");
}

TEST_F(MalformedGroundTruthTest, UnknownPartName) {
  std::vector<std::string> lines = lines_;
  const int i = Find("shin_left: {", 1);
  lines[i].replace(lines[i].find("shin_left"), 9, "tail");
  const std::string error = Error(lines);
  EXPECT_EQ(error.rfind(At(i) + "frames[0].people[1].parts: unknown body part 'tail'", 0), 0u)
      << error;
}

TEST_F(MalformedGroundTruthTest, MissingPart) {
  std::vector<std::string> lines = lines_;
  const int i = Find("foot_right: {");
  lines.erase(lines.begin() + i);
  const std::string error = Error(lines);
  EXPECT_NE(error.find("frames[0].people[0].parts: missing body part 'foot_right'"),
            std::string::npos)
      << error;
  EXPECT_EQ(error.rfind(TempPath("bad.yaml") + ":", 0), 0u) << error;
}

TEST_F(MalformedGroundTruthTest, MissingKey) {
  std::vector<std::string> lines = lines_;
  const int i = Find("velocity: [", 3);
  lines.erase(lines.begin() + i);
  const std::string error = Error(lines);
  EXPECT_NE(error.find("frames[1].people[1]: missing key 'velocity'"), std::string::npos) << error;
}

TEST_F(MalformedGroundTruthTest, UnknownKey) {
  std::vector<std::string> lines = lines_;
  const int i = Find("time_s:", 1);
  lines.insert(lines.begin() + i + 1, lines[i].substr(0, lines[i].find("time_s")) + "colour: red");
  EXPECT_EQ(Error(lines), At(i + 1) + "frames[1]: unknown key 'colour'");
}

TEST_F(MalformedGroundTruthTest, FrameCountMismatch) {
  std::vector<std::string> lines = lines_;
  const int i = Find("ground_truth:");
  lines[i].replace(lines[i].find("frames: 2"), 9, "frames: 3");
  const std::string error = Error(lines);
  EXPECT_NE(error.find("frames: holds 2 frames, but ground_truth.frames says 3"), std::string::npos)
      << error;
}

TEST_F(MalformedGroundTruthTest, UnknownAction) {
  std::vector<std::string> lines = lines_;
  const int i = Find("action: crouch");
  lines[i].replace(lines[i].find("crouch"), 6, "dance");
  const std::string error = Error(lines);
  EXPECT_EQ(error.rfind(At(i) + "frames[0].people[1].action: expected one of", 0), 0u) << error;
}

TEST_F(MalformedGroundTruthTest, ShortVectorAndBadRadius) {
  std::vector<std::string> lines = lines_;
  const int i = Find("centre: [");
  lines[i] = lines[i].substr(0, lines[i].find('[')) + "[1, 2]";
  EXPECT_EQ(Error(lines), At(i) + "frames[0].people[0].centre: expected a list of 3 numbers");

  lines = lines_;
  const int j = Find("torso: {");
  const std::size_t r = lines[j].find("radius: ");
  lines[j] = lines[j].substr(0, r) + "radius: -0.1}";
  EXPECT_EQ(Error(lines), At(j) + "frames[0].people[0].parts.torso.radius: must be positive");
}

TEST_F(MalformedGroundTruthTest, DuplicatePerson) {
  std::vector<std::string> lines = lines_;
  const int i = Find("name: \"bob");
  lines[i] = lines[i].substr(0, lines[i].find("name:")) + "name: alice";
  const std::string error = Error(lines);
  EXPECT_NE(error.find("frames[0].people[1].name: duplicate person 'alice'"), std::string::npos)
      << error;
}

TEST_F(MalformedGroundTruthTest, BrokenYamlAndMissingFile) {
  std::vector<std::string> lines = lines_;
  lines.push_back("  - frame: [unclosed");
  const std::string error = Error(lines);
  EXPECT_NE(error.find("malformed YAML"), std::string::npos) << error;
  EXPECT_EQ(error.rfind(TempPath("bad.yaml") + ":", 0), 0u) << error;

  try {
    (void)ReadGroundTruth(TempPath("does_not_exist.yaml"));
    FAIL() << "expected ConfigError";
  } catch (const common::ConfigError& e) {
    EXPECT_EQ(std::string(e.what()),
              TempPath("does_not_exist.yaml") + ": cannot open: no such file");
  }
}

}  // namespace
}  // namespace hg::sim
