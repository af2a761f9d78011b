// End-to-end tests of `hullguard carve`: real files, real process, exit codes.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "geometry/camera_yaml.h"
#include "geometry/mesh.h"
#include "scene/demo_cell.h"
#include "scene/exact_mask.h"
#include "silhouette/mask_io.h"
#include "support/dense_carve.h"
#include "support/handmade_images.h"
#include "support/random_scene.h"
#include "support/run_tool.h"

namespace hg {
namespace {

namespace fs = std::filesystem;

using testing::BigEndian;
using testing::PaletteBmp;
using testing::PalettePng;
using testing::PngCrc;
using testing::ProcessResult;

ProcessResult Hullguard(const std::string& args) {
  return testing::RunTool(HG_HULLGUARD_BIN, args);
}

std::vector<std::string> Lines(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

// Parses the one flat JSON object `--json` prints: {"key": number, ...} and a
// newline, numbers in JSON's grammar (no nan, no inf). Fails the test otherwise.
std::map<std::string, double> ParseFlatJson(const std::string& text) {
  std::map<std::string, double> out;
  std::size_t i = 0;
  auto skip_space = [&] {
    while (i < text.size() && (text[i] == ' ' || text[i] == '\n')) ++i;
  };
  auto expect = [&](char c) {
    skip_space();
    if (i < text.size() && text[i] == c) {
      ++i;
      return true;
    }
    ADD_FAILURE() << "expected '" << c << "' at " << i << " in " << text;
    return false;
  };
  if (text.empty() || text.front() != '{' || text.back() != '\n') {
    ADD_FAILURE() << "not one JSON object and a newline: " << text;
    return out;
  }
  if (!expect('{')) return out;
  while (true) {
    if (!expect('"')) return out;
    const std::size_t end = text.find('"', i);
    if (end == std::string::npos) {
      ADD_FAILURE() << "unterminated key in " << text;
      return out;
    }
    const std::string key = text.substr(i, end - i);
    i = end + 1;
    if (!expect(':')) return out;
    skip_space();
    const char* start = text.c_str() + i;
    char* stop = nullptr;
    const double value = std::strtod(start, &stop);
    const std::string number(start, static_cast<std::size_t>(stop - start));
    // JSON numbers: optional '-', a digit first, finite.
    const std::size_t digit = !number.empty() && number[0] == '-' ? 1 : 0;
    if (stop == start || number.size() <= digit || !std::isdigit(number[digit]) ||
        !std::isfinite(value) || number.find_first_of("xXnNiI") != std::string::npos) {
      ADD_FAILURE() << key << ": not a JSON number in " << text;
      return out;
    }
    EXPECT_EQ(out.count(key), 0u) << "duplicate key " << key;
    out[key] = value;
    i += number.size();
    skip_space();
    if (i < text.size() && text[i] == ',') {
      ++i;
      continue;
    }
    if (!expect('}')) return out;
    skip_space();
    EXPECT_EQ(i, text.size()) << "trailing text in " << text;
    return out;
  }
}

// A camera K/position/look_at entry of a cameras file.
std::string LookAtCameraYaml(const std::string& name, int width, int height,
                             const std::string& position, const std::string& look_at) {
  const double f = 0.9 * width;
  std::ostringstream s;
  s << "  - name: " << name << "\n    width: " << width << "\n    height: " << height
    << "\n    K: [" << f << ", 0, " << (width - 1) / 2.0 << ", 0, " << f << ", "
    << (height - 1) / 2.0 << ", 0, 0, 1]\n    position: " << position
    << "\n    look_at: " << look_at << "\n";
  return s.str();
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
  // `hullguard carve` of one mask of a 64 x 48 camera looking down at the
  // cell's centre, queried there: "1 1 1 STATE".
  ProcessResult CarveLookingDown(const std::string& mask) const {
    std::ofstream(Path("down.yaml")) << "cameras:\n"
                                     << LookAtCameraYaml("down", 64, 48, "[1, 1, 5]", "[1, 1, 1]");
    std::ofstream(Path("q.txt")) << "1 1 1\n";
    return Hullguard("carve --cameras " + Path("down.yaml") + " --masks " + Path(mask) +
                     " --bounds 0 0 0 2 2 2 --depth 4 --query " + Path("q.txt"));
  }
  fs::path dir_;
  testing::RandomScene scene_;
};

TEST_F(CarveCliTest, QueryClassifiesPointsInOrder) {
  const Eigen::Vector3d inside = std::visit(
      [](const auto& s) -> Eigen::Vector3d {
        using T = std::decay_t<decltype(s)>;
        if constexpr (std::is_same_v<T, scene::Capsule>)
          return s.a_W;
        else
          return s.centre_W;
      },
      scene_.objects[0]);
  std::ofstream q(Path("q.txt"));
  q.precision(17);
  q << inside.x() << " " << inside.y() << " " << inside.z() << "\n";
  // Coordinates are echoed as written: 1.0000000001 must not come back as 1.
  q << "# a comment\n5 5 5  # outside\n\n0.001 0.001 1.999#corner\n"
    << "  1.0000000001\t0.5   0.5e0 \n";
  q.close();
  // With exact boundaries the octree equals the brute-force oracle cell by cell.
  const ProcessResult r = Hullguard(Base() + " --boundary-coarsening 0 --query " + Path("q.txt"));
  ASSERT_EQ(r.code, 0) << r.err;
  const std::vector<std::string> lines = Lines(r.out);
  ASSERT_EQ(lines.size(), 4u) << r.out;

  const std::vector<common::ImageU8> masks = testing::RenderMasks(scene_.cameras, scene_.objects);
  std::vector<const common::ImageU8*> mask_ptrs;
  for (const auto& m : masks) mask_ptrs.push_back(&m);
  const common::Box3 bounds{Eigen::Vector3d::Zero(), Eigen::Vector3d::Constant(2.0)};
  const testing::DenseGrid oracle = testing::DenseCarve(bounds, 6, scene_.cameras, mask_ptrs, {});
  auto expected_state = [&](const Eigen::Vector3d& p_W) -> std::string {
    const Eigen::Vector3d cell = (p_W - bounds.min).cwiseQuotient(bounds.Size()) * 64.0;
    const std::uint8_t state = oracle.states[oracle.Index(static_cast<std::uint32_t>(cell.x()),
                                                          static_cast<std::uint32_t>(cell.y()),
                                                          static_cast<std::uint32_t>(cell.z()))];
    switch (static_cast<octree::LeafState>(state)) {
      case octree::LeafState::kFree:
        return "free";
      case octree::LeafState::kOccupied:
        return "occupied";
      case octree::LeafState::kOccluded:
        return "occluded";
    }
    return "?";
  };
  EXPECT_EQ(expected_state(inside), "occupied");  // An object is never free.
  EXPECT_NE(lines[0].find(" occupied"), std::string::npos) << lines[0];
  EXPECT_EQ(lines[1], "5 5 5 outside");
  EXPECT_EQ(lines[2], "0.001 0.001 1.999 " + expected_state({0.001, 0.001, 1.999}));
  EXPECT_EQ(lines[3], "1.0000000001 0.5 0.5e0 " + expected_state({1.0000000001, 0.5, 0.5}));
}

TEST_F(CarveCliTest, QueryFileWithoutPointsPrintsNothing) {
  std::ofstream(Path("q.txt")) << "# only a comment\n\n   \n";
  const ProcessResult r = Hullguard(Base() + " --query " + Path("q.txt"));
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(r.out, "");
  EXPECT_EQ(r.err, "");
}

// A query line that is not three finite numbers is an error naming the file
// and line, exit 2, nothing printed: a NUL inside a number too (it ended
// the number's read, so "1 1\0 5" was the point 1 1 5, echoed as "1 1").
TEST_F(CarveCliTest, BadQueryLinesNameTheFileAndLine) {
  const std::string bad[] = {"1 2",   "1 2 3 4",   "nan 1 2",
                             "1 2 x", "1e999 0 0", std::string("1 1\0 5", 6)};
  for (const std::string& line : bad) {
    SCOPED_TRACE(line);
    std::ofstream(Path("q.txt"), std::ios::binary) << "# points\n1 1 1\n" << line << "\n";
    const ProcessResult r = Hullguard(Base() + " --query " + Path("q.txt"));
    EXPECT_EQ(r.code, 2) << r.out;
    EXPECT_EQ(r.out, "");
    EXPECT_NE(r.err.find(Path("q.txt") + ":3: expected 'x y z' (finite numbers)"),
              std::string::npos)
        << r.err;
  }
}

TEST_F(CarveCliTest, ThresholdChoosesForeground) {
  // One camera looking down at the middle of the cell, a mask of grey 100
  // everywhere: background at the default threshold (127), foreground above 50.
  std::ofstream(Path("down.yaml")) << "cameras:\n"
                                   << LookAtCameraYaml("down", 64, 48, "[1, 1, 5]", "[1, 1, 1]");
  silhouette::WriteGreyImage(Path("grey100.png"), common::ImageU8(64, 48, 100));
  std::ofstream(Path("q.txt")) << "1 1 1\n";
  const std::string base = "carve --cameras " + Path("down.yaml") + " --masks " +
                           Path("grey100.png") + " --bounds 0 0 0 2 2 2 --depth 4 --query " +
                           Path("q.txt");
  const ProcessResult background = Hullguard(base);
  ASSERT_EQ(background.code, 0) << background.err;
  EXPECT_EQ(background.out, "1 1 1 free\n");
  const ProcessResult foreground = Hullguard(base + " --threshold 50");
  ASSERT_EQ(foreground.code, 0) << foreground.err;
  EXPECT_EQ(foreground.out, "1 1 1 occupied\n");
  const ProcessResult at_value = Hullguard(base + " --threshold 100");  // Strictly greater.
  ASSERT_EQ(at_value.code, 0) << at_value.err;
  EXPECT_EQ(at_value.out, "1 1 1 free\n");
}

TEST_F(CarveCliTest, ColourMasksCountTheirBrightestChannel) {
  // A pure red foreground is dark in grey (76): read by grey value it would
  // be background and the point free. Its brightest channel makes it foreground.
  std::ofstream(Path("down.yaml")) << "cameras:\n"
                                   << LookAtCameraYaml("down", 64, 48, "[1, 1, 5]", "[1, 1, 1]");
  ASSERT_TRUE(cv::imwrite(Path("red.png"), cv::Mat(48, 64, CV_8UC3, cv::Scalar(0, 0, 255))));
  ASSERT_TRUE(cv::imwrite(Path("black.png"), cv::Mat(48, 64, CV_8UC3, cv::Scalar(0, 0, 0))));
  // Opaque foreground on a transparent background: refused, whatever its colours.
  cv::Mat rgba(48, 64, CV_8UC4, cv::Scalar(0, 0, 0, 0));
  rgba(cv::Rect(16, 12, 32, 24)).setTo(cv::Scalar(0, 0, 0, 255));
  ASSERT_TRUE(cv::imwrite(Path("alpha.png"), rgba));
  // Opaque everywhere: the alpha channel changes nothing.
  ASSERT_TRUE(
      cv::imwrite(Path("opaque.png"), cv::Mat(48, 64, CV_8UC4, cv::Scalar(0, 255, 0, 255))));
  std::ofstream(Path("q.txt")) << "1 1 1\n";
  auto carve = [&](const std::string& mask) {
    return Hullguard("carve --cameras " + Path("down.yaml") + " --masks " + Path(mask) +
                     " --bounds 0 0 0 2 2 2 --depth 4 --query " + Path("q.txt"));
  };
  const ProcessResult red = carve("red.png");
  ASSERT_EQ(red.code, 0) << red.err;
  EXPECT_EQ(red.out, "1 1 1 occupied\n");
  const ProcessResult black = carve("black.png");
  ASSERT_EQ(black.code, 0) << black.err;
  EXPECT_EQ(black.out, "1 1 1 free\n");
  const ProcessResult opaque = carve("opaque.png");
  ASSERT_EQ(opaque.code, 0) << opaque.err;
  EXPECT_EQ(opaque.out, "1 1 1 occupied\n");
  const ProcessResult alpha = carve("alpha.png");
  EXPECT_EQ(alpha.code, 2);
  EXPECT_NE(alpha.err.find("alpha.png: mask has transparent pixels"), std::string::npos)
      << alpha.err;
  EXPECT_EQ(alpha.out, "");
}

// What decoders drop from a mask's own header: a binary PGM's maxval (a 0/1
// mask with maxval 1 read as raw 0/1 was all background, the person free) and
// a PNG's transparency key (a keyed-out background dropped, the mask read as
// drawn: refused like an alpha channel).
TEST_F(CarveCliTest, PgmMaxvalIsScaledAndPngColourKeysAreRefused) {
  auto carve = [&](const std::string& mask) { return CarveLookingDown(mask); };
  for (const int maxval : {1, 15, 255}) {
    SCOPED_TRACE(maxval);
    const std::string name = "max" + std::to_string(maxval) + ".pgm";
    std::ofstream(Path(name), std::ios::binary) << "P5\n64 48\n"
                                                << maxval << "\n"
                                                << std::string(64 * 48, static_cast<char>(maxval));
    const ProcessResult r = carve(name);
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(r.out, "1 1 1 occupied\n");
  }
  std::ofstream(Path("zero.pgm"), std::ios::binary) << "P5\n64 48\n1\n"
                                                    << std::string(64 * 48, '\0');
  EXPECT_EQ(carve("zero.pgm").out, "1 1 1 free\n");

  // A grey PNG (all foreground) with a tRNS chunk keying grey level 0 out.
  ASSERT_TRUE(cv::imwrite(Path("plain.png"), cv::Mat(48, 64, CV_8UC1, cv::Scalar(255))));
  std::string png;
  {
    std::ifstream in(Path("plain.png"), std::ios::binary);
    png.assign((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  }
  const std::size_t idat = png.find("IDAT");
  ASSERT_NE(idat, std::string::npos);
  const std::string body = std::string("tRNS") + std::string("\0\0", 2);
  png.insert(idat - 4, BigEndian(2) + body + BigEndian(PngCrc(body)));
  std::ofstream(Path("keyed.png"), std::ios::binary) << png;
  EXPECT_EQ(carve("plain.png").out, "1 1 1 occupied\n");
  const ProcessResult keyed = carve("keyed.png");
  EXPECT_EQ(keyed.code, 2) << keyed.out;
  EXPECT_NE(keyed.err.find("keyed.png: mask has transparent pixels (a PNG transparency key"),
            std::string::npos)
      << keyed.err;

  // OpenCV writes and decodes Sun raster, but decodes an 8-bit grey one as
  // all zeros: the person read as background, free. Refused by its format.
  ASSERT_TRUE(cv::imwrite(Path("plain.ras"), cv::Mat(48, 64, CV_8UC1, cv::Scalar(255))));
  const ProcessResult ras = carve("plain.ras");
  EXPECT_EQ(ras.code, 2) << ras.out;
  EXPECT_EQ(ras.out, "");
  EXPECT_NE(ras.err.find("plain.ras: not a mask format read reliably (use PNG, "),
            std::string::npos)
      << ras.err;
}

// A palette mask whose pixels index past its palette is damaged: decoders
// read those pixels as black, background, and the person in them free. It
// is refused; a palette mask within its palette reads as drawn.
TEST_F(CarveCliTest, PaletteMasksIndexingPastThePaletteAreRefused) {
  auto carve = [&](const std::string& mask) { return CarveLookingDown(mask); };
  const std::pair<const char*, std::string (*)(int, int, unsigned char)> formats[] = {
      {"png", PalettePng}, {"bmp", PaletteBmp}};
  for (const auto& [extension, make] : formats) {
    SCOPED_TRACE(extension);
    const std::string white = std::string("white.") + extension;
    const std::string black = std::string("black.") + extension;
    const std::string past = std::string("past.") + extension;
    std::ofstream(Path(white), std::ios::binary) << make(64, 48, 1);
    std::ofstream(Path(black), std::ios::binary) << make(64, 48, 0);
    std::ofstream(Path(past), std::ios::binary) << make(64, 48, 255);
    const ProcessResult w = carve(white);
    EXPECT_EQ(w.code, 0) << w.err;
    EXPECT_EQ(w.out, "1 1 1 occupied\n");
    EXPECT_EQ(carve(black).out, "1 1 1 free\n");
    const ProcessResult r = carve(past);
    EXPECT_EQ(r.code, 2) << r.out;
    EXPECT_EQ(r.out, "");
    EXPECT_NE(r.err.find(past + ": damaged: pixels index colours its palette does not have"),
              std::string::npos)
        << r.err;
  }
}

TEST_F(CarveCliTest, BytesAfterThePngEndAreIgnored) {
  // Some tools append bytes after a PNG's IEND chunk: the image is whole.
  {
    std::ifstream in(Path("m0.png"), std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    std::ofstream(Path("tail.png"), std::ios::binary) << bytes << std::string("\n\0trailer", 9);
  }
  std::ofstream(Path("q.txt")) << "1 1 1\n0.5 0.5 0.5\n1.5 1 0.5\n";
  const std::string rest = Masks().substr(Masks().find(' ', 1)) +
                           " --bounds 0 0 0 2 2 2 --depth 6 --query " + Path("q.txt");
  const ProcessResult whole = Hullguard(Base() + " --query " + Path("q.txt"));
  const ProcessResult tail =
      Hullguard("carve --cameras " + Path("cams.yaml") + " --masks " + Path("tail.png") + rest);
  ASSERT_EQ(whole.code, 0) << whole.err;
  ASSERT_EQ(tail.code, 0) << tail.err;
  EXPECT_EQ(tail.out, whole.out);
}

TEST_F(CarveCliTest, ProjectionMatrixCameraCarvesLikeKRt) {
  // The same cameras as P = s K [R | t], each with its own scale.
  std::ofstream p(Path("p.yaml"));
  p.precision(17);
  p << "cameras:\n";
  for (std::size_t c = 0; c < scene_.cameras.size(); ++c) {
    const geometry::CameraModel& cam = scene_.cameras[c];
    Eigen::Matrix<double, 3, 4> Rt;
    Rt << cam.R_CW, cam.t_CW;
    const Eigen::Matrix<double, 3, 4> P = (0.5 + static_cast<double>(c)) * cam.K * Rt;
    p << "  - name: " << cam.name << "\n    width: " << cam.width << "\n    height: " << cam.height
      << "\n    P: [";
    for (int i = 0; i < 12; ++i) p << (i ? ", " : "") << P(i / 4, i % 4);
    p << "]\n";
  }
  p.close();
  std::ofstream q(Path("q.txt"));
  for (double x = 0.05; x < 2; x += 0.3) {
    for (double y = 0.05; y < 2; y += 0.3) {
      for (double z = 0.05; z < 2; z += 0.3) q << x << " " << y << " " << z << "\n";
    }
  }
  q.close();
  const std::string rest = " --masks" + Masks() + " --bounds 0 0 0 2 2 2 --depth 6";
  const ProcessResult krt = Hullguard("carve --cameras " + Path("cams.yaml") + rest + " --json");
  const ProcessResult proj = Hullguard("carve --cameras " + Path("p.yaml") + rest + " --json");
  ASSERT_EQ(krt.code, 0) << krt.err;
  ASSERT_EQ(proj.code, 0) << proj.err;
  const auto a = ParseFlatJson(krt.out);
  const auto b = ParseFlatJson(proj.out);
  for (const char* key : {"occupied_volume_m3", "occluded_volume_m3", "free_volume_m3"}) {
    ASSERT_EQ(a.count(key), 1u) << key;
    ASSERT_EQ(b.count(key), 1u) << key;
    EXPECT_NEAR(a.at(key), b.at(key), 1e-9) << key;
  }
  EXPECT_EQ(a.at("leaves"), b.at("leaves"));
  const ProcessResult krt_q =
      Hullguard("carve --cameras " + Path("cams.yaml") + rest + " --query " + Path("q.txt"));
  const ProcessResult proj_q =
      Hullguard("carve --cameras " + Path("p.yaml") + rest + " --query " + Path("q.txt"));
  ASSERT_EQ(krt_q.code, 0) << krt_q.err;
  EXPECT_EQ(Lines(krt_q.out).size(), 7u * 7u * 7u);
  EXPECT_EQ(krt_q.out, proj_q.out);
}

// A cell a million metres from the origin: the PLY's boxes are its cells to
// the bit (they were floats of 9 digits: a 1.6 cm cell at 1e6 m became a box
// of 0 or 6.25 cm, and half the boxes did not hold their cells).
TEST_F(CarveCliTest, PlyBoxesAreTheirCellsFarFromTheOrigin) {
  std::ofstream(Path("far.yaml")) << "cameras:\n"
                                  << LookAtCameraYaml("top", 64, 48, "[999992, 2, 10]",
                                                      "[999992, 2, 0]");
  common::ImageU8 mask(64, 48);
  for (int v = 18; v < 30; ++v) {
    for (int u = 26; u < 38; ++u) mask.At(u, v) = 255;
  }
  silhouette::WriteGreyImage(Path("far.png"), mask);
  const ProcessResult r =
      Hullguard("carve --cameras " + Path("far.yaml") + " --masks " + Path("far.png") +
                " --bounds 999990 0 0 999994 4 4 --depth 8 --out " + Path("far.ply"));
  ASSERT_EQ(r.code, 0) << r.err;
  std::ifstream ply(Path("far.ply"));
  std::string line;
  long long vertices = -1;
  bool doubles = false;
  while (std::getline(ply, line) && line != "end_header") {
    if (line.rfind("element vertex ", 0) == 0) vertices = std::stoll(line.substr(15));
    doubles = doubles || line == "property double x";
  }
  EXPECT_TRUE(doubles);
  ASSERT_GT(vertices, 0);
  const double cell = 4.0 / 256.0;
  long long wrong = 0;
  for (long long box = 0; box < vertices / 8; ++box) {
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = -lo;
    for (int v = 0; v < 8; ++v) {
      ASSERT_TRUE(std::getline(ply, line));
      std::istringstream ss(line);
      Eigen::Vector3d p;
      ASSERT_TRUE(ss >> p.x() >> p.y() >> p.z()) << line;
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
    // Whole cells (or unions of them): faces on the grid, edges of whole cells.
    const double ix = (lo.x() - 999990.0) / cell, ex = (hi.x() - lo.x()) / cell;
    wrong +=
        std::abs(ix - std::round(ix)) > 1e-6 || std::abs(ex - std::round(ex)) > 1e-6 || ex < 0.5
            ? 1
            : 0;
  }
  EXPECT_EQ(wrong, 0) << "of " << vertices / 8 << " boxes";
}

TEST_F(CarveCliTest, JsonAndPly) {
  // A solid obstacle: no camera sees inside it, so the result has occluded leaves.
  geometry::WriteObj(
      Path("block.obj"),
      geometry::TriangleMesh::Box(Eigen::Vector3d::Constant(0.2), Eigen::Vector3d::Constant(0.6)));
  const ProcessResult r =
      Hullguard(Base() + " --threads 2 --json --obstacles " + Path("block.obj") + " --out " +
                Path("hull.ply") + " --snapshot " + Path("view.png"));
  ASSERT_EQ(r.code, 0) << r.err;
  const std::map<std::string, double> json = ParseFlatJson(r.out);
  for (const char* key : {"occupied_volume_m3", "occluded_volume_m3", "free_volume_m3", "leaves",
                          "nodes", "update_ms"}) {
    EXPECT_EQ(json.count(key), 1u) << key << " in " << r.out;
  }
  for (const char* key : {"occupied_volume_m3", "occluded_volume_m3", "free_volume_m3"}) {
    ASSERT_EQ(json.count(key), 1u) << key;
  }
  EXPECT_NEAR(
      json.at("occupied_volume_m3") + json.at("occluded_volume_m3") + json.at("free_volume_m3"),
      8.0, 1e-6);  // %.9g

  // PLY: the header's counts match the body; every leaf is 8 vertices of one
  // colour (occupied red, occluded grey) and 6 quadrilaterals; the boxes' volumes
  // add up to the JSON's occupied and occluded volumes.
  std::ifstream ply(Path("hull.ply"));
  std::string line;
  std::getline(ply, line);
  EXPECT_EQ(line, "ply");
  long long vertices = -1, faces = -1;
  bool end_header = false;
  while (!end_header && std::getline(ply, line)) {
    std::istringstream ss(line);
    std::string word, element;
    long long count = 0;
    ss >> word;
    if (word == "element" && ss >> element >> count)
      (element == "vertex" ? vertices : faces) = count;
    end_header = word == "end_header";
  }
  ASSERT_TRUE(end_header);
  ASSERT_GT(vertices, 0);
  EXPECT_EQ(vertices % 8, 0);
  EXPECT_EQ(faces, vertices / 8 * 6);
  std::vector<std::string> body;
  while (std::getline(ply, line)) body.push_back(line);
  ASSERT_EQ(static_cast<long long>(body.size()), vertices + faces);
  std::map<std::string, double> volume;  // By colour.
  for (long long box = 0; box < vertices / 8; ++box) {
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e9), hi = -lo;
    std::string colour;
    for (long long v = 8 * box; v < 8 * box + 8; ++v) {
      std::istringstream ss(body[v]);
      Eigen::Vector3d p;
      int red = 0, green = 0, blue = 0;
      ASSERT_TRUE(ss >> p.x() >> p.y() >> p.z() >> red >> green >> blue) << body[v];
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
      const std::string c =
          std::to_string(red) + " " + std::to_string(green) + " " + std::to_string(blue);
      if (v == 8 * box) colour = c;
      EXPECT_EQ(c, colour) << "vertex " << v;
    }
    volume[colour] += (hi - lo).prod();
  }
  for (long long f = vertices; f < vertices + faces; ++f) {
    std::istringstream ss(body[f]);
    int n = 0;
    long long index[4] = {};
    ASSERT_TRUE(ss >> n >> index[0] >> index[1] >> index[2] >> index[3]) << body[f];
    EXPECT_EQ(n, 4);
    for (long long i : index) EXPECT_EQ(i / 8, (f - vertices) / 6) << body[f];
  }
  EXPECT_EQ(volume.size(), 2u);  // Both states are present in this scene.
  EXPECT_NEAR(volume["200 40 40"], json.at("occupied_volume_m3"), 1e-6);
  EXPECT_NEAR(volume["128 128 128"], json.at("occluded_volume_m3"), 1e-6);

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

// A node store too small for the hull (--max-nodes): the run still succeeds,
// only grows the occupied volume, and says so on stderr and in the JSON.
TEST_F(CarveCliTest, TooFewNodesLeaveCellsOccupiedAndSaySo) {
  const ProcessResult full = Hullguard(Base() + " --json");
  ASSERT_EQ(full.code, 0) << full.err;
  EXPECT_EQ(JsonNumber(full.out, "unsplit_nodes"), 0.0) << full.out;
  const ProcessResult small = Hullguard(Base() + " --json --max-nodes 2000");
  ASSERT_EQ(small.code, 0) << small.err;
  EXPECT_GT(JsonNumber(small.out, "unsplit_nodes"), 0.0) << small.out;
  EXPECT_NE(small.err.find("node store was too small"), std::string::npos) << small.err;
  EXPECT_GT(JsonNumber(small.out, "occupied_volume_m3"),
            JsonNumber(full.out, "occupied_volume_m3"));
  EXPECT_LT(JsonNumber(small.out, "free_volume_m3"), JsonNumber(full.out, "free_volume_m3"));
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
  std::ofstream(Path("nan.txt")) << "1 nan 2\n";
  // Obstacles that would read as "no obstacle": an empty OBJ, one with only
  // comments, and files that are no OBJ or STL mesh.
  std::ofstream(Path("empty.obj")) << "";
  std::ofstream(Path("comments.obj")) << "# nothing\nv 0 0 0\n";
  std::ofstream(Path("mesh.ply")) << "ply\nformat ascii 1.0\nend_header\n";
  std::ofstream(Path("noise.stl")) << "not a mesh\n";
  // A PNG cut in half.
  {
    std::ifstream in(Path("m0.png"), std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    std::ofstream(Path("cut.png"), std::ios::binary) << bytes.substr(0, bytes.size() / 2);
  }
  // A JPEG mask without its end-of-image marker, which libjpeg would decode,
  // with a warning on stderr, as though it were whole.
  {
    silhouette::WriteGreyImage(Path("whole.jpg"), silhouette::ReadGreyImage(Path("m0.png")));
    std::ifstream in(Path("whole.jpg"), std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    std::ofstream(Path("cut.jpg"), std::ios::binary) << bytes.substr(0, bytes.size() - 2);
  }
  // A 16-bit mask, all 255 (foreground): a plain 8-bit decode would scale it
  // to 0, background, and certify the space free.
  {
    std::ofstream pgm(Path("deep.pgm"), std::ios::binary);
    pgm << "P5\n8 6\n65535\n";
    for (int i = 0; i < 8 * 6; ++i) pgm << '\0' << '\xff';
  }
  // 17 tiny cameras (the octree supports 16), each with its mask.
  std::string seventeen_masks;
  {
    std::ofstream yaml(Path("cams17.yaml"));
    yaml << "cameras:\n";
    for (int c = 0; c < 17; ++c) {
      yaml << LookAtCameraYaml("c" + std::to_string(c), 8, 6,
                               "[1, 1, " + std::to_string(3 + c) + "]", "[1, 1, 1]");
      const std::string mask = Path("tiny" + std::to_string(c) + ".png");
      silhouette::WriteGreyImage(mask, common::ImageU8(8, 6));
      seventeen_masks += " " + mask;
    }
  }
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
      {"carve" + cams + " --masks" + Masks() + " --bounds 0 0 0 inf 2 2 --depth 6", "finite"},
      {"carve" + cams + " --masks" + Masks() + " --bounds 0 0 nan 2 2 2 --depth 6", "finite"},
      {"carve" + cams + " --masks" + Masks() + " --bounds -inf 0 0 2 2 2 --depth 6", "finite"},
      {Base() + " --query " + Path("nan.txt"), "nan.txt:1"},
      {Base() + " --obstacles " + Path("empty.obj"), "empty.obj: no triangles"},
      {Base() + " --obstacles " + Path("comments.obj"), "comments.obj: no triangles"},
      {Base() + " --obstacles " + Path("mesh.ply"), "mesh.ply"},
      {Base() + " --obstacles " + Path("noise.stl"), "noise.stl"},
      {"carve" + cams + " --masks " + Path("gone.png") + Masks().substr(Masks().find(' ', 1)) +
           " --bounds 0 0 0 2 2 2 --depth 6",
       "gone.png"},
      {"carve" + cams + " --masks " + Path("cut.png") + Masks().substr(Masks().find(' ', 1)) +
           " --bounds 0 0 0 2 2 2 --depth 6",
       "cut.png"},
      {"carve" + cams + " --masks " + Path("cut.jpg") + Masks().substr(Masks().find(' ', 1)) +
           " --bounds 0 0 0 2 2 2 --depth 6",
       "cut.jpg: not a readable 8-bit image"},
      {"carve --cameras " + Path("cams17.yaml") + " --masks" + seventeen_masks +
           " --bounds 0 0 0 2 2 2 --depth 4",
       "cams17.yaml: 17 cameras, at most 16"},
      {"carve --cameras " + Path("") + " --masks" + Masks() + " --bounds 0 0 0 2 2 2 --depth 6",
       "is a folder, not a file"},
      {"carve" + cams + " --masks " + Path("deep.pgm") + Masks().substr(Masks().find(' ', 1)) +
           " --bounds 0 0 0 2 2 2 --depth 6",
       "deep.pgm: not a readable 8-bit image"},
      {"carve" + cams + " --masks " + Path("") + Masks().substr(Masks().find(' ', 1)) +
           " --bounds 0 0 0 2 2 2 --depth 6",
       "cannot open mask: is a folder"},
      {Base() + " --query " + Path(""), "cannot open query file: is a folder"},
      {Base() + " --min-component-m3 nan", "not a finite number"},
      {"carve" + cams + " --masks" + Masks() + " --bounds 0 0 0 2 2 2 --depth abc",
       "--depth: 'abc' is not an integer"},
      {"carve" + cams + " --masks" + Masks() + " --bounds 0 0 0 2 2 2 --depth 6.5",
       "--depth: '6.5' is not an integer"},
      {"carve" + cams + " --masks" + Masks() + " --bounds 0 0 0 2 2 2 --depth 17",
       "--depth: '17' is not in 3..16"},
      {Base() + " --min-component-m3 -1", "--min-component-m3: '-1' must be 0 or more"},
      {"carve" + cams + " --masks" + Masks() + " --bounds 0 0 0 1e300 2 2 --depth 6", "1e6 m"},
  };
  for (const Case& c : cases) {
    const ProcessResult r = Hullguard(c.args);
    EXPECT_EQ(r.code, 2) << c.args << "\n" << r.err;
    EXPECT_NE(r.err.find(c.expect), std::string::npos) << "stderr: " << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_EQ(r.out, "") << c.args;
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
