#include "sim/colour_renderer.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include "scene/demo_cell.h"
#include "sim/mask_renderer.h"
#include "support/sim_bodies.h"

namespace hg::sim {
namespace {

using testing::StandingBody;
using testing::WalkingBody;

using Eigen::Vector3d;

/// A 4 m x 4 m x 3 m cell with a table, a crate, one person description and
/// one camera in a corner (pinhole, or with a barrel lens).
Scene TestScene(bool distorted) {
  Scene scene;
  scene.name = "test";
  scene.bounds.min = Vector3d(0, 0, 0);
  scene.bounds.max = Vector3d(4, 4, 3);
  geometry::CameraModel camera =
      scene::LookAtCamera(Vector3d(-0.3, -0.3, 2.8), Vector3d(2.0, 2.0, 0.6), 320, 240, 230.0);
  camera.name = "cam0";
  if (distorted) camera.distortion = {-0.15, 0.02, 0.001, -0.0005, 0.0};
  scene.cameras.push_back({camera, 0.0});
  BoxSolid table;
  table.centre_W = Vector3d(3.0, 1.0, 0.75);
  table.half_extents_m = Vector3d(0.5, 0.4, 0.03);
  scene.obstacles.push_back({"table", table, Rgb(0.5F, 0.35F, 0.2F)});
  BoxSolid crate;
  crate.centre_W = Vector3d(1.0, 3.0, 0.25);
  crate.half_extents_m = Vector3d(0.3, 0.25, 0.25);
  crate.R_WB = Eigen::AngleAxisd(0.3, Vector3d::UnitZ()).toRotationMatrix();
  scene.foreground_objects.push_back({"crate", crate, Rgb(0.7F, 0.55F, 0.2F)});
  Person person;
  person.name = "alice";
  person.shirt = Rgb(0.8F, 0.1F, 0.1F);
  person.trousers = Rgb(0.1F, 0.1F, 0.5F);
  scene.people.push_back(person);
  scene.imaging.noise_sigma = 2.0;
  scene.imaging.seed = 7;
  return scene;
}

double MeanBrightness(const common::ImageRgb8& image) {
  double sum = 0.0;
  for (const std::uint8_t p : image.pixels) sum += p;
  return sum / static_cast<double>(image.pixels.size());
}

int Luma(const common::ImageRgb8& image, std::size_t pixel) {
  const std::uint8_t* p = image.pixels.data() + 3 * pixel;
  return p[0] + p[1] + p[2];
}

TEST(ColourRendererTest, DeterministicAndNoisyPerFrame) {
  const Scene scene = TestScene(false);
  const ColourRenderer renderer(scene, 0);
  const std::vector<BodyState> people = {StandingBody(Vector3d(2.0, 2.0, 0.0))};
  common::ImageRgb8 a;
  common::ImageRgb8 b;
  common::ImageRgb8 c;
  renderer.Render(people, 1.0, 5, &a);
  renderer.Render(people, 1.0, 5, &b);
  renderer.Render(people, 1.0, 6, &c);
  ASSERT_EQ(a.width, 320);
  ASSERT_EQ(a.height, 240);
  EXPECT_EQ(a.pixels, b.pixels);
  // Another frame: other noise, same scene.
  long long differing = 0;
  double sum_sq = 0.0;
  for (std::size_t i = 0; i < a.pixels.size(); ++i) {
    const int d = static_cast<int>(a.pixels[i]) - c.pixels[i];
    differing += d != 0 ? 1 : 0;
    sum_sq += d * d;
  }
  EXPECT_GT(differing, static_cast<long long>(a.pixels.size() / 2));
  // The difference of two independent noises has variance 2 sigma^2 (plus
  // rounding); clamping at 0 / 255 only lowers it.
  const double sigma_diff = std::sqrt(sum_sq / static_cast<double>(a.pixels.size()));
  EXPECT_GT(sigma_diff, 2.0 * std::sqrt(2.0) * 0.8);
  EXPECT_LT(sigma_diff, 2.0 * std::sqrt(2.0) * 1.2);
  // Another renderer of the same camera gives the same frames.
  common::ImageRgb8 d;
  ColourRenderer(scene, 0).Render(people, 1.0, 5, &d);
  EXPECT_EQ(a.pixels, d.pixels);
}

TEST(ColourRendererTest, EmptyRenderMatchesRenderWithoutPeopleOrNoise) {
  for (const bool distorted : {false, true}) {
    Scene scene = TestScene(distorted);
    scene.imaging.noise_sigma = 0.0;
    const ColourRenderer renderer(scene, 0);
    common::ImageRgb8 empty;
    common::ImageRgb8 frame;
    renderer.RenderEmpty(&empty);
    renderer.Render({}, 3.0, 9, &frame);
    EXPECT_EQ(empty.pixels, frame.pixels);
    // The image shows structure (floor tiles, walls, objects), not a flat colour.
    int min_luma = 1000;
    int max_luma = 0;
    for (std::size_t i = 0; i < static_cast<std::size_t>(empty.width) * empty.height; ++i) {
      min_luma = std::min(min_luma, Luma(empty, i));
      max_luma = std::max(max_luma, Luma(empty, i));
    }
    EXPECT_GT(max_luma - min_luma, 150);
  }
}

TEST(ColourRendererTest, PeopleShowWhereTheMaskSaysPerson) {
  for (const bool distorted : {false, true}) {
    SCOPED_TRACE(distorted ? "distorted" : "pinhole");
    Scene scene = TestScene(distorted);
    scene.imaging.noise_sigma = 0.0;
    const ColourRenderer renderer(scene, 0);
    const std::vector<BodyState> people = {StandingBody(Vector3d(2.0, 2.0, 0.0))};
    common::ImageRgb8 empty;
    common::ImageRgb8 frame;
    renderer.RenderEmpty(&empty);
    renderer.Render(people, 0.0, 1, &frame);
    const MaskRenderer masks(scene.cameras[0].model, scene.obstacles, {}, true);
    common::ImageU8 mask;
    masks.Render(people, &mask);
    long long person = 0;
    long long changed = 0;
    long long brighter_outside = 0;
    for (std::size_t i = 0; i < mask.pixels.size(); ++i) {
      const bool differs = std::memcmp(&frame.pixels[3 * i], &empty.pixels[3 * i], 3) != 0;
      if (mask.pixels[i]) {
        ++person;
        changed += differs ? 1 : 0;
      } else if (differs && Luma(frame, i) > Luma(empty, i)) {
        ++brighter_outside;  // Outside the person only shadows may change pixels.
      }
    }
    EXPECT_GT(person, 1000);
    EXPECT_GT(static_cast<double>(changed), 0.85 * static_cast<double>(person));
    EXPECT_EQ(brighter_outside, 0);
  }
}

TEST(ColourRendererTest, ShadowDarkensTheFloorNearThePerson) {
  Scene scene = TestScene(false);
  scene.imaging.noise_sigma = 0.0;
  // Lamp above and beside the person: the shadow falls on the visible floor.
  scene.imaging.light_W = Vector3d(3.0, 2.5, 2.9);
  const std::vector<BodyState> people = {StandingBody(Vector3d(2.0, 2.0, 0.0))};
  const MaskRenderer masks(scene.cameras[0].model, {}, {}, false);
  common::ImageU8 mask;
  masks.Render(people, &mask);
  auto darker_floor_pixels = [&](bool shadows) {
    scene.imaging.shadows = shadows;
    const ColourRenderer renderer(scene, 0);
    common::ImageRgb8 empty;
    common::ImageRgb8 frame;
    renderer.RenderEmpty(&empty);
    renderer.Render(people, 0.0, 1, &frame);
    long long darker = 0;
    for (std::size_t i = 0; i < mask.pixels.size(); ++i) {
      if (!mask.pixels[i] && Luma(frame, i) + 6 < Luma(empty, i)) ++darker;
    }
    return darker;
  };
  EXPECT_GT(darker_floor_pixels(true), 300);
  EXPECT_EQ(darker_floor_pixels(false), 0);
}

TEST(ColourRendererTest, LightChangeScalesBrightness) {
  Scene scene = TestScene(false);
  scene.imaging.light_change_amplitude = 0.2;
  scene.imaging.light_change_period_s = 20.0;
  const ColourRenderer renderer(scene, 0);
  const std::vector<BodyState> people = {StandingBody(Vector3d(2.0, 2.0, 0.0))};
  common::ImageRgb8 base;
  common::ImageRgb8 bright;
  common::ImageRgb8 dark;
  renderer.Render(people, 0.0, 1, &base);    // gain 1
  renderer.Render(people, 5.0, 1, &bright);  // gain 1.2
  renderer.Render(people, 15.0, 1, &dark);   // gain 0.8
  const double mean = MeanBrightness(base);
  EXPECT_NEAR(MeanBrightness(bright) / mean, 1.2, 0.03);
  EXPECT_NEAR(MeanBrightness(dark) / mean, 0.8, 0.03);
}

}  // namespace
}  // namespace hg::sim
