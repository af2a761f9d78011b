#include "silhouette/background_model.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <new>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "common/config_error.h"
#include "scene/demo_cell.h"
#include "sim/body.h"
#include "sim/colour_renderer.h"
#include "sim/mask_renderer.h"
#include "sim/scene.h"
#include "support/allocation_counter.h"
#include "support/luma_image.h"

namespace hg::silhouette {
namespace {

using Eigen::Vector3d;

constexpr double kRateHz = 30.0;
constexpr int kWidth = 320;
constexpr int kHeight = 180;

// -----------------------------------------------------------------------------
// Image helpers.

/// Pixels whose whole (2r+1)^2 neighbourhood is foreground (edge pixels of a
/// silhouette are partly background in the colour frame).
common::ImageU8 Erode(const common::ImageU8& mask, int r) {
  common::ImageU8 out(mask.width, mask.height, 0);
  for (int v = r; v < mask.height - r; ++v) {
    for (int u = r; u < mask.width - r; ++u) {
      bool all = true;
      for (int dv = -r; dv <= r && all; ++dv) {
        for (int du = -r; du <= r && all; ++du) all = mask.At(u + du, v + dv) != 0;
      }
      out.At(u, v) = all ? 255 : 0;
    }
  }
  return out;
}

/// Squared distance between the segments p0-p1 and q0-q1.
double SegmentDistance2(const Vector3d& p0, const Vector3d& p1, const Vector3d& q0,
                        const Vector3d& q1) {
  const Vector3d d1 = p1 - p0;
  const Vector3d d2 = q1 - q0;
  const Vector3d r = p0 - q0;
  const double a = d1.squaredNorm();
  const double e = d2.squaredNorm();
  const double f = d2.dot(r);
  double s = 0.0;
  double t = 0.0;
  if (a <= 1e-18 && e <= 1e-18) return r.squaredNorm();
  if (a <= 1e-18) {
    t = std::clamp(f / e, 0.0, 1.0);
  } else {
    const double c = d1.dot(r);
    if (e <= 1e-18) {
      s = std::clamp(-c / a, 0.0, 1.0);
    } else {
      const double b = d1.dot(d2);
      const double denom = a * e - b * b;
      s = denom > 1e-18 ? std::clamp((b * f - c * e) / denom, 0.0, 1.0) : 0.0;
      t = (b * s + f) / e;
      if (t < 0.0) {
        t = 0.0;
        s = std::clamp(-c / a, 0.0, 1.0);
      } else if (t > 1.0) {
        t = 1.0;
        s = std::clamp((b - c) / a, 0.0, 1.0);
      }
    }
  }
  return (p0 + s * d1 - (q0 + t * d2)).squaredNorm();
}

/// The pixels of `truth` whose centre ray meets a body capsule: the person's
/// visible surface. The ground-truth mask is conservative (it fills gaps of a
/// pixel or two between limbs), so its erosion alone keeps background pixels.
common::ImageU8 CentreSilhouette(const geometry::CameraModel& camera,
                                 const std::vector<sim::BodyState>& people,
                                 const common::ImageU8& truth) {
  common::ImageU8 out(truth.width, truth.height, 0);
  const Eigen::Matrix3d K_inv = camera.K.inverse();
  const Eigen::Matrix3d R_WC = camera.R_CW.transpose();
  const Vector3d centre = camera.CentreW();
  for (int v = 0; v < truth.height; ++v) {
    for (int u = 0; u < truth.width; ++u) {
      if (truth.At(u, v) == 0) continue;
      const Vector3d ray = (R_WC * (K_inv * Vector3d(u, v, 1.0))).normalized();
      const Vector3d far = centre + 100.0 * ray;
      bool hit = false;
      for (const sim::BodyState& body : people) {
        for (const sim::BodyCapsule& part : body.parts) {
          hit = hit ||
                SegmentDistance2(centre, far, part.a_W, part.b_W) <= part.radius_m * part.radius_m;
        }
      }
      out.At(u, v) = hit ? 255 : 0;
    }
  }
  return out;
}

/// Pixels within Chebyshev distance r of a foreground pixel.
common::ImageU8 Dilate(const common::ImageU8& mask, int r) {
  common::ImageU8 out(mask.width, mask.height, 0);
  for (int v = 0; v < mask.height; ++v) {
    for (int u = 0; u < mask.width; ++u) {
      if (mask.At(u, v) == 0) continue;
      for (int y = std::max(0, v - r); y <= std::min(mask.height - 1, v + r); ++y) {
        for (int x = std::max(0, u - r); x <= std::min(mask.width - 1, u + r); ++x) {
          out.At(x, y) = 255;
        }
      }
    }
  }
  return out;
}

/// Share of `region` pixels that `mask` reports foreground; -1 for an empty region.
double ShareForeground(const common::ImageU8& mask, const common::ImageU8& region,
                       long long* region_size = nullptr) {
  long long n = 0;
  long long fg = 0;
  for (std::size_t i = 0; i < mask.pixels.size(); ++i) {
    if (region.pixels[i] == 0) continue;
    ++n;
    fg += mask.pixels[i] != 0 ? 1 : 0;
  }
  if (region_size != nullptr) *region_size = n;
  return n == 0 ? -1.0 : static_cast<double>(fg) / static_cast<double>(n);
}

common::ImageU8 Invert(const common::ImageU8& mask) {
  common::ImageU8 out = mask;
  for (std::uint8_t& p : out.pixels) p = p != 0 ? 0 : 255;
  return out;
}

/// The model's background at every pixel and channel, for "did not adapt" checks.
std::vector<double> Means(const BackgroundModel& model, int channels) {
  std::vector<double> means;
  means.reserve(static_cast<std::size_t>(model.width()) * model.height() * channels);
  for (int v = 0; v < model.height(); ++v) {
    for (int u = 0; u < model.width(); ++u) {
      for (int c = 0; c < channels; ++c) means.push_back(model.MeanAt(u, v, c));
    }
  }
  return means;
}

/// Number of pixels of `region` whose background changed between two Means().
long long ChangedIn(const std::vector<double>& before, const std::vector<double>& after,
                    const common::ImageU8& region, int channels) {
  long long changed = 0;
  for (std::size_t p = 0; p < region.pixels.size(); ++p) {
    if (region.pixels[p] == 0) continue;
    bool any = false;
    for (int c = 0; c < channels; ++c)
      any = any || before[p * channels + c] != after[p * channels + c];
    changed += any ? 1 : 0;
  }
  return changed;
}

// -----------------------------------------------------------------------------
// Simulated cells.

/// The demo cell's first Full HD camera, scaled to kWidth x kHeight (the
/// pixel-centre convention moves the principal point by half a pixel).
geometry::CameraModel SmallCamera(const Vector3d& eye, const Vector3d& target) {
  constexpr double kFullHdFx = 1083.5787063372297;
  geometry::CameraModel camera = scene::LookAtCamera(eye, target, 1920, 1080, kFullHdFx);
  const double s = static_cast<double>(kWidth) / camera.width;
  camera.K(0, 0) *= s;
  camera.K(1, 1) *= s;
  camera.K(0, 2) = (camera.K(0, 2) + 0.5) * s - 0.5;
  camera.K(1, 2) = (camera.K(1, 2) + 0.5) * s - 0.5;
  camera.width = kWidth;
  camera.height = kHeight;
  camera.name = "cam0";
  return camera;
}

sim::Person Person(const Vector3d& start, double heading_rad) {
  sim::Person person;
  person.name = "alice";
  person.height_m = 1.75;
  person.shirt = sim::Rgb(0.75F, 0.15F, 0.15F);
  person.trousers = sim::Rgb(0.15F, 0.2F, 0.55F);
  person.start_W = start;
  person.start_heading_rad = heading_rad;
  return person;
}

/// A 4 m cell seen from an upper corner, one person standing still in the
/// middle for `seconds`, a global light change and sensor noise.
sim::Scene StandingCell(double seconds, double light_amplitude) {
  sim::Scene scene;
  scene.name = "standing";
  scene.bounds.min = Vector3d(0, 0, 0);
  scene.bounds.max = Vector3d(4, 4, 3);
  scene.cameras.push_back({SmallCamera(Vector3d(-0.3, -0.3, 2.8), Vector3d(2, 2, 1)), 0.0});
  sim::Person person = Person(Vector3d(2.0, 2.2, 0.0), 0.8);
  sim::Action stand;
  stand.kind = sim::ActionKind::kStand;
  stand.start_s = 0.0;
  stand.duration_s = seconds;
  person.actions.push_back(stand);
  scene.people.push_back(person);
  scene.imaging.noise_sigma = 2.0;
  scene.imaging.light_change_amplitude = light_amplitude;
  scene.imaging.light_change_period_s = 20.0;
  scene.imaging.seed = 11;
  return scene;
}

/// Renders a scene frame by frame: the colour frame, the ground-truth mask and
/// the region the people change in a clean frame (their pixels and shadows).
class Sequence {
 public:
  explicit Sequence(const sim::Scene& scene)
      : scene_(scene),
        colour_(scene, 0),
        clean_(CleanScene(scene), 0),
        masks_(scene.cameras[0].model, scene.obstacles, scene.foreground_objects,
               scene.mask_occlusion) {
    clean_.RenderEmpty(&empty_);
  }

  /// Frame `i` at t = i / 30 s. `present` false leaves the people out.
  void Render(int i, bool present = true) {
    t_s = i / kRateHz;
    people_.clear();
    if (present) {
      for (const sim::Person& p : scene_.people) people_.push_back(sim::EvaluatePerson(p, t_s));
    }
    colour_.Render(people_, t_s, static_cast<std::uint64_t>(i), &frame);
    masks_.Render(people_, &truth);
    surface = CentreSilhouette(scene_.cameras[0].model, people_, truth);
    interior = Erode(surface, 2);
    clean_.Render(people_, t_s, 0, &clean_frame_);
    changed = common::ImageU8(frame.width, frame.height, 0);
    for (std::size_t p = 0; p < changed.pixels.size(); ++p) {
      for (int c = 0; c < 3; ++c) {
        if (std::abs(clean_frame_.pixels[3 * p + c] - empty_.pixels[3 * p + c]) > 2) {
          changed.pixels[p] = 255;
        }
      }
      if (truth.pixels[p] != 0) changed.pixels[p] = 255;
    }
  }

  /// Pixels that the people leave unchanged, a margin away from any change.
  [[nodiscard]] common::ImageU8 Untouched() const { return Invert(Dilate(changed, 3)); }

  /// The people's floor shadow: pixels that a clean frame shows at most 80 % as
  /// bright as the empty cell, away from the people's silhouettes.
  [[nodiscard]] common::ImageU8 Shadow() const {
    common::ImageU8 out(frame.width, frame.height, 0);
    const common::ImageU8 near_people = Dilate(truth, 2);
    for (std::size_t p = 0; p < out.pixels.size(); ++p) {
      int lit = 0;
      int now = 0;
      for (int c = 0; c < 3; ++c) {
        lit += empty_.pixels[3 * p + c];
        now += clean_frame_.pixels[3 * p + c];
      }
      if (near_people.pixels[p] == 0 && lit > 60 && 5 * now <= 4 * lit) out.pixels[p] = 255;
    }
    return out;
  }

  /// The scene's light gain at the current frame.
  [[nodiscard]] double LightGain() const {
    return 1.0 + scene_.imaging.light_change_amplitude *
                     std::sin(2.0 * M_PI * t_s / scene_.imaging.light_change_period_s);
  }

  double t_s = 0.0;
  common::ImageRgb8 frame;
  common::ImageU8 truth;     ///< Ground-truth silhouette (conservative).
  common::ImageU8 surface;   ///< Pixels whose centre sees a person.
  common::ImageU8 interior;  ///< The surface eroded by 2 px: must be foreground.
  common::ImageU8 changed;   ///< Silhouette plus shadows (noise-free difference).

 private:
  static sim::Scene CleanScene(sim::Scene scene) {
    scene.imaging.noise_sigma = 0.0;
    scene.imaging.light_change_amplitude = 0.0;
    return scene;
  }

  sim::Scene scene_;
  sim::ColourRenderer colour_;
  sim::ColourRenderer clean_;
  sim::MaskRenderer masks_;
  common::ImageRgb8 empty_;
  common::ImageRgb8 clean_frame_;
  std::vector<sim::BodyState> people_;
};

// -----------------------------------------------------------------------------
// Options and learning.

TEST(BackgroundModelTest, RejectsBadOptions) {
  auto expect_error = [](BackgroundModelOptions o, const std::string& key) {
    try {
      BackgroundModel model(64, 48, o);
      ADD_FAILURE() << "no error for " << key;
    } catch (const common::ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find(key), std::string::npos) << e.what();
    }
  };
  BackgroundModelOptions o;
  o.learn_frames = 0;
  expect_error(o, "learn_frames");
  o = {};
  o.min_threshold = 0;
  expect_error(o, "min_threshold");
  o = {};
  o.max_threshold = o.min_threshold - 1;
  expect_error(o, "max_threshold");
  o = {};
  o.adapt_rate = -0.1;
  expect_error(o, "adapt_rate");
  o = {};
  o.noise_sigmas = std::nan("");
  expect_error(o, "noise_sigmas");
  o = {};
  o.shadow_min_ratio = 0.9;
  o.shadow_max_ratio = 0.8;
  expect_error(o, "shadow_max_ratio");
  o = {};
  o.guard_px = -1;
  expect_error(o, "guard_px");
  EXPECT_THROW(BackgroundModel(0, 10, BackgroundModelOptions{}), common::ConfigError);
}

// Every foreground pixel of `mask` lies in a tile the model flags
// (BackgroundModel::foreground_tiles, which DilateSquare relies on).
void ExpectTilesCoverTheMask(const BackgroundModel& model, const common::ImageU8& mask) {
  const std::uint8_t* tiles = model.foreground_tiles();
  ASSERT_NE(tiles, nullptr);
  const int tx_n = (mask.width + 7) / 8;
  for (int v = 0; v < mask.height; ++v) {
    for (int u = 0; u < mask.width; ++u) {
      if (mask.At(u, v) == 0) continue;
      ASSERT_NE(tiles[static_cast<std::size_t>(v / 8) * tx_n + u / 8], 0)
          << "(" << u << ", " << v << ")";
    }
  }
}

TEST(BackgroundModelTest, AllForegroundWhileLearningThenTheEmptyCellIsBackground) {
  const sim::Scene scene = StandingCell(60.0, 0.15);
  Sequence seq(scene);
  BackgroundModelOptions options;
  options.learn_frames = 20;
  BackgroundModel model(kWidth, kHeight, options);
  common::ImageU8 mask;
  for (int i = 0; i < options.learn_frames; ++i) {
    ASSERT_TRUE(model.learning());
    seq.Render(i, /*present=*/false);
    model.Apply(seq.frame, &mask);
    ASSERT_EQ(mask.width, kWidth);
    ASSERT_EQ(mask.height, kHeight);
    EXPECT_TRUE(std::all_of(mask.pixels.begin(), mask.pixels.end(),
                            [](std::uint8_t p) { return p == 255; }))
        << "frame " << i;
    EXPECT_EQ(model.foreground_fraction(), 1.0);
    // The all-foreground masks of learning have no tile map, the last one too.
    EXPECT_EQ(model.foreground_tiles(), nullptr);
  }
  EXPECT_FALSE(model.learning());
  // The noise is learned: 4 sigma of 2 grey levels stays under the minimum.
  EXPECT_EQ(model.ThresholdAt(kWidth / 2, kHeight / 2), options.min_threshold);
  seq.Render(options.learn_frames, /*present=*/false);
  model.Apply(seq.frame, &mask);
  EXPECT_LT(model.foreground_fraction(), 0.01);
  ExpectTilesCoverTheMask(model, mask);
  // Reset learns again, all foreground meanwhile.
  model.Reset();
  EXPECT_TRUE(model.learning());
  EXPECT_EQ(model.foreground_tiles(), nullptr);
  model.Apply(seq.frame, &mask);
  EXPECT_EQ(model.foreground_fraction(), 1.0);
  EXPECT_EQ(model.foreground_tiles(), nullptr);
}

// A saved background taken up by another model (a restart) classifies exactly
// as the model that learned it, with thresholds from the loader's options;
// files of another size or damaged ones are refused and leave it learning.
TEST(BackgroundModelTest, SavedBackgroundIsTakenUpAfterARestart) {
  const sim::Scene scene = StandingCell(60.0, 0.15);
  Sequence seq(scene);
  BackgroundModelOptions options;
  options.learn_frames = 10;
  BackgroundModel learned(kWidth, kHeight, options);
  common::ImageU8 mask;
  for (int i = 0; i < options.learn_frames; ++i) {
    seq.Render(i, /*present=*/false);
    learned.Apply(seq.frame, &mask);
  }
  ASSERT_FALSE(learned.learning());
  const std::string path = ::testing::TempDir() + "hg_background_saved.bin";
  std::string error;
  ASSERT_TRUE(learned.Save(path, &error)) << error;

  BackgroundModel restarted(kWidth, kHeight, options);
  ASSERT_TRUE(restarted.Load(path, &error)) << error;
  EXPECT_FALSE(restarted.learning());
  for (int v = 0; v < kHeight; v += 7) {
    for (int u = 0; u < kWidth; u += 5) {
      ASSERT_EQ(restarted.ThresholdAt(u, v), learned.ThresholdAt(u, v)) << u << "," << v;
      for (int c = 0; c < 3; ++c) ASSERT_EQ(restarted.MeanAt(u, v, c), learned.MeanAt(u, v, c));
    }
  }
  // The person is there from the restart's first frame on: foreground at once,
  // exactly as the model that learned the empty cell sees it.
  common::ImageU8 expected;
  for (int i = options.learn_frames; i < options.learn_frames + 5; ++i) {
    seq.Render(i, /*present=*/true);
    learned.Apply(seq.frame, &expected);
    restarted.Apply(seq.frame, &mask);
    ASSERT_EQ(mask.pixels, expected.pixels) << "frame " << i;
    EXPECT_GT(restarted.foreground_fraction(), 0.005);
  }

  // Thresholds come from the loader's own options.
  BackgroundModelOptions stricter = options;
  stricter.min_threshold = 40;
  BackgroundModel other_options(kWidth, kHeight, stricter);
  ASSERT_TRUE(other_options.Load(path, &error)) << error;
  EXPECT_EQ(other_options.ThresholdAt(kWidth / 2, kHeight / 2), 40);

  // Saved for one camera (and its calibration), taken up by that one only:
  // another camera's file, or one of this camera before it was calibrated
  // anew, is refused.
  const std::string own = path + ".cam";
  ASSERT_TRUE(learned.Save(own, &error, 7)) << error;
  BackgroundModel same_camera(kWidth, kHeight, options);
  EXPECT_TRUE(same_camera.Load(own, &error, 0, 7)) << error;
  BackgroundModel other_camera(kWidth, kHeight, options);
  EXPECT_FALSE(other_camera.Load(own, &error, 0, 8));
  EXPECT_NE(error.find("taught for another camera"), std::string::npos) << error;
  EXPECT_TRUE(other_camera.learning());
  std::remove(own.c_str());

  // Another size, a damaged file, no file: refused, still learning.
  BackgroundModel smaller(kWidth / 2, kHeight, options);
  EXPECT_FALSE(smaller.Load(path, &error));
  EXPECT_NE(error.find("the camera is 160x180"), std::string::npos) << error;
  EXPECT_TRUE(smaller.learning());
  {
    std::fstream file(path, std::ios::in | std::ios::out | std::ios::binary);
    file.seekp(1000);
    file.put('\x5a');
  }
  BackgroundModel damaged(kWidth, kHeight, options);
  EXPECT_FALSE(damaged.Load(path, &error));
  EXPECT_NE(error.find("damaged"), std::string::npos) << error;
  EXPECT_TRUE(damaged.learning());
  std::remove(path.c_str());
  EXPECT_FALSE(damaged.Load(path, &error));
  EXPECT_NE(error.find("cannot open"), std::string::npos) << error;
  EXPECT_TRUE(damaged.learning());
}

// -----------------------------------------------------------------------------
// The product requirements on simulated sequences.

// A person standing still for a minute while the light breathes by +-15 %:
// every frame keeps the person's interior foreground, the background under and
// around the person never moves, and the rest of the cell stays background.
TEST(BackgroundModelTest, PersonStandingStillForAMinuteIsNeverAbsorbed) {
  constexpr double kSeconds = 60.0;
  const sim::Scene scene = StandingCell(kSeconds + 1.0, 0.15);
  Sequence seq(scene);
  const BackgroundModelOptions options;
  BackgroundModel model(kWidth, kHeight, options);
  common::ImageU8 mask;
  // The cell is empty while the model learns; the person then walks in, as
  // far as the model can tell (appears between two frames).
  for (int i = 0; i < options.learn_frames; ++i) {
    seq.Render(i, /*present=*/false);
    model.Apply(seq.frame, &mask);
  }
  ASSERT_FALSE(model.learning());
  const std::vector<double> learned = Means(model, 3);
  double worst_recall = 1.0;
  double worst_false_positive = 0.0;
  double worst_gain_error = 0.0;
  common::ImageU8 guard;
  common::ImageU8 previous = mask;
  const int frames = static_cast<int>(kSeconds * kRateHz);
  for (int i = options.learn_frames; i < frames; ++i) {
    seq.Render(i);
    model.Apply(seq.frame, &mask);
    const common::ImageU8& interior = seq.interior;
    long long interior_size = 0;
    const double recall = ShareForeground(mask, interior, &interior_size);
    ASSERT_GT(interior_size, 500);
    worst_recall = std::min(worst_recall, recall);
    ASSERT_GE(recall, 0.98) << "frame " << i << " t " << seq.t_s;
    const double false_positive = ShareForeground(mask, seq.Untouched());
    worst_false_positive = std::max(worst_false_positive, false_positive);
    ASSERT_LE(false_positive, 0.03) << "frame " << i << " t " << seq.t_s;
    worst_gain_error = std::max(worst_gain_error, std::abs(model.gain() - seq.LightGain()));
    // The guard around what stayed foreground (the person, their shadow):
    // a pixel foreground in this frame and the one before. Noise can make a
    // single pixel foreground for a frame; the background around it adapts
    // again in the next.
    if (i % 150 == 0) {
      common::ImageU8 lasting = mask;
      for (std::size_t p = 0; p < lasting.pixels.size(); ++p) {
        lasting.pixels[p] = mask.pixels[p] != 0 && previous.pixels[p] != 0 ? 255 : 0;
      }
      guard = Dilate(lasting, options.guard_px);
    }
    previous = mask;
  }
  // The person's pixels, and the guard around whatever was foreground, kept the
  // empty cell's background through the whole minute.
  const std::vector<double> now = Means(model, 3);
  EXPECT_EQ(ChangedIn(learned, now, seq.truth, 3), 0);
  EXPECT_EQ(ChangedIn(learned, now, guard, 3), 0);
  // The light change is followed by the gain (the first frame is the reference).
  EXPECT_LT(worst_gain_error, 0.01);
  std::printf(
      "standing 60 s: worst interior recall %.4f, worst false positives %.4f, "
      "worst gain error %.4f\n",
      worst_recall, worst_false_positive, worst_gain_error);
}

/// A wide hall seen from one side: a person waits out of view (left) while the
/// model learns, walks across the view at 1.2 m/s and leaves it on the right.
sim::Scene WalkingCell() {
  sim::Scene scene;
  scene.name = "walking";
  scene.bounds.min = Vector3d(-4, -4, 0);
  scene.bounds.max = Vector3d(8, 8, 3);
  scene.cameras.push_back({SmallCamera(Vector3d(2, -0.3, 2.8), Vector3d(2, 3, 0.8)), 0.0});
  sim::Person person = Person(Vector3d(-2.2, 2.5, 0.0), 0.0);
  sim::Action wait;
  wait.kind = sim::ActionKind::kStand;
  wait.start_s = 0.0;
  wait.duration_s = 2.0;
  sim::Action walk;
  walk.kind = sim::ActionKind::kWalk;
  walk.start_s = 2.0;
  walk.speed_mps = 1.2;
  walk.path_W = {Vector3d(6.2, 2.5, 0.0)};
  walk.duration_s = 8.4 / 1.2;
  sim::Action stay;
  stay.kind = sim::ActionKind::kStand;
  stay.start_s = walk.start_s + walk.duration_s;
  stay.duration_s = 10.0;
  person.actions = {wait, walk, stay};
  scene.people.push_back(person);
  scene.imaging.noise_sigma = 2.0;
  scene.imaging.light_change_amplitude = 0.15;
  scene.imaging.light_change_period_s = 20.0;
  scene.imaging.seed = 23;
  return scene;
}

// A person walks through the view and leaves: every frame keeps the interior
// foreground, nothing under or near foreground adapts, and once the person is
// gone the background is as clean as before, also where the person walked.
TEST(BackgroundModelTest, PersonWalkingThroughLeavesNoTrace) {
  const sim::Scene scene = WalkingCell();
  Sequence seq(scene);
  const BackgroundModelOptions options;
  BackgroundModel model(kWidth, kHeight, options);
  common::ImageU8 mask;
  common::ImageU8 trail(kWidth, kHeight, 0);  // Every pixel the person covered.
  std::vector<double> before;
  double worst_recall = 1.0;
  double false_positive_before = 0.0;
  double false_positive_after = 0.0;
  double trail_after = 0.0;
  int frames_with_person = 0;
  int frames_after = 0;
  int left_at = -1;
  const int frames = static_cast<int>(12.5 * kRateHz);
  for (int i = 0; i < frames; ++i) {
    seq.Render(i);
    model.Apply(seq.frame, &mask);
    const bool in_view = std::any_of(seq.truth.pixels.begin(), seq.truth.pixels.end(),
                                     [](std::uint8_t p) { return p != 0; });
    if (i < options.learn_frames) {
      ASSERT_FALSE(in_view) << "the cell must be empty while the model learns";
      before = Means(model, 3);
      continue;
    }
    const std::vector<double> after = Means(model, 3);
    // Nothing adapts under the person or within the guard of any foreground.
    ASSERT_EQ(ChangedIn(before, after, seq.surface, 3), 0) << "frame " << i;
    ASSERT_EQ(ChangedIn(before, after, Dilate(mask, options.guard_px), 3), 0) << "frame " << i;
    before = after;
    long long interior_size = 0;
    const double recall = ShareForeground(mask, seq.interior, &interior_size);
    if (interior_size >= 50) {
      ++frames_with_person;
      worst_recall = std::min(worst_recall, recall);
      ASSERT_GE(recall, 0.98) << "frame " << i << " t " << seq.t_s;
    }
    for (std::size_t p = 0; p < trail.pixels.size(); ++p) trail.pixels[p] |= seq.truth.pixels[p];
    const double false_positive = ShareForeground(mask, seq.Untouched());
    if (seq.t_s < 2.0) {
      false_positive_before = std::max(false_positive_before, false_positive);
    }
    if (in_view) left_at = -1;
    if (!in_view && seq.t_s > 2.0 && left_at < 0) left_at = i;
    if (left_at >= 0 && i >= left_at + static_cast<int>(0.5 * kRateHz)) {
      ++frames_after;
      false_positive_after = std::max(false_positive_after, false_positive);
      // Where the person walked (and their shadow fell) the cell is empty again.
      const common::ImageU8 trail_now = [&] {
        common::ImageU8 t = Erode(trail, 2);
        const common::ImageU8 untouched = seq.Untouched();
        for (std::size_t p = 0; p < t.pixels.size(); ++p) t.pixels[p] &= untouched.pixels[p];
        return t;
      }();
      trail_after = std::max(trail_after, ShareForeground(mask, trail_now));
    }
  }
  EXPECT_GT(frames_with_person, 120);
  EXPECT_GT(frames_after, 60);
  EXPECT_LE(false_positive_before, 0.01);
  EXPECT_LE(false_positive_after, 0.01);
  EXPECT_LE(trail_after, 0.01);
  std::printf(
      "walking: %d frames with the person, worst interior recall %.4f; false positives "
      "before %.4f, after leaving %.4f, on the trail after leaving %.4f\n",
      frames_with_person, worst_recall, false_positive_before, false_positive_after, trail_after);
}

// The floor shadow of a standing person: foreground by default; with
// shadows_are_foreground off most of it turns background, the person does not.
TEST(BackgroundModelTest, ShadowsAreForegroundUnlessConfiguredOtherwise) {
  const sim::Scene scene = StandingCell(10.0, 0.15);
  Sequence seq(scene);
  BackgroundModelOptions with_shadows;
  BackgroundModelOptions without_shadows;
  without_shadows.shadows_are_foreground = false;
  // The scene's ambient share (0.35) leaves the umbra at about 0.35..0.4 of
  // the lit floor, darker than the default bound.
  without_shadows.shadow_min_ratio = 0.3;
  BackgroundModel model_with(kWidth, kHeight, with_shadows);
  BackgroundModel model_without(kWidth, kHeight, without_shadows);
  common::ImageU8 mask_with;
  common::ImageU8 mask_without;
  for (int i = 0; i < with_shadows.learn_frames; ++i) {
    seq.Render(i, /*present=*/false);
    model_with.Apply(seq.frame, &mask_with);
    model_without.Apply(seq.frame, &mask_without);
  }
  double share_with = 1.0;
  double share_without = 0.0;
  double recall_without = 1.0;
  for (int i = with_shadows.learn_frames; i < 10 * static_cast<int>(kRateHz); i += 3) {
    seq.Render(i);
    model_with.Apply(seq.frame, &mask_with);
    model_without.Apply(seq.frame, &mask_without);
    ExpectTilesCoverTheMask(model_with, mask_with);
    ExpectTilesCoverTheMask(model_without, mask_without);
    long long shadow_size = 0;
    const common::ImageU8 shadow = seq.Shadow();
    share_with = std::min(share_with, ShareForeground(mask_with, shadow, &shadow_size));
    ASSERT_GT(shadow_size, 100);
    share_without = std::max(share_without, ShareForeground(mask_without, shadow));
    recall_without = std::min(recall_without, ShareForeground(mask_without, seq.interior));
  }
  EXPECT_GE(share_with, 0.95);
  EXPECT_LE(share_without, 0.2);
  EXPECT_GE(recall_without, 0.98);
  std::printf(
      "shadow share reported foreground: %.3f by default, %.3f with shadows as "
      "background (person recall %.4f)\n",
      share_with, share_without, recall_without);
}

// Grey cameras: the same promise on Mono8 frames (the luma of the colour
// frames). In grey, parts of the person match the brightness of what is behind
// them (the shaded shirt against the skirting board), which no background model
// can see; what is seen at the start must stay seen.
TEST(BackgroundModelTest, Mono8PersonStandingStillIsNeverAbsorbed) {
  const sim::Scene scene = StandingCell(21.0, 0.15);
  Sequence seq(scene);
  const BackgroundModelOptions options;
  BackgroundModel model(kWidth, kHeight, options);
  common::ImageU8 mask;
  for (int i = 0; i < options.learn_frames; ++i) {
    seq.Render(i, /*present=*/false);
    model.Apply(testing::LumaOf(seq.frame), &mask);
  }
  const std::vector<double> learned = Means(model, 1);
  double first_recall = -1.0;
  double worst_recall = 1.0;
  double worst_false_positive = 0.0;
  for (int i = options.learn_frames; i < 20 * static_cast<int>(kRateHz); ++i) {
    seq.Render(i);
    model.Apply(testing::LumaOf(seq.frame), &mask);
    const double recall = ShareForeground(mask, seq.interior);
    if (first_recall < 0.0) first_recall = recall;
    worst_recall = std::min(worst_recall, recall);
    worst_false_positive = std::max(worst_false_positive, ShareForeground(mask, seq.Untouched()));
  }
  EXPECT_EQ(ChangedIn(learned, Means(model, 1), seq.truth, 1), 0);
  // Brightness alone found 0.906 (the person's grey matches the background
  // in places); the texture they hide finds 0.984.
  EXPECT_GE(first_recall, 0.96);
  EXPECT_GE(worst_recall, first_recall - 0.02);
  EXPECT_LE(worst_false_positive, 0.03);
  EXPECT_NEAR(model.gain(), seq.LightGain(), 0.01);
  std::printf(
      "mono8 standing 20 s: interior recall %.4f first, %.4f worst; worst false "
      "positives %.4f\n",
      first_recall, worst_recall, worst_false_positive);
}

// -----------------------------------------------------------------------------
// Synthetic frames: one mechanism at a time.

/// A textured frame, values 40..200, seeded.
common::ImageRgb8 Texture(int width, int height, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_int_distribution<int> level(40, 200);
  common::ImageRgb8 image(width, height);
  for (std::uint8_t& p : image.pixels) p = static_cast<std::uint8_t>(level(rng));
  return image;
}

/// base * gain plus Gaussian noise of `sigma`, rounded and clipped.
common::ImageRgb8 Observe(const common::ImageRgb8& base, double gain, double sigma,
                          std::mt19937_64* rng) {
  std::normal_distribution<double> noise(0.0, sigma);
  common::ImageRgb8 out = base;
  for (std::size_t i = 0; i < out.pixels.size(); ++i) {
    const double value = base.pixels[i] * gain + (sigma > 0.0 ? noise(*rng) : 0.0);
    out.pixels[i] = static_cast<std::uint8_t>(std::clamp(std::lround(value), 0L, 255L));
  }
  return out;
}

TEST(BackgroundModelTest, GainFollowsSuddenGlobalLightChanges) {
  const common::ImageRgb8 base = Texture(160, 120, 3);
  std::mt19937_64 rng(4);
  BackgroundModel model(160, 120, BackgroundModelOptions{});
  common::ImageU8 mask;
  for (int i = 0; i < 30; ++i) model.Apply(Observe(base, 1.0, 2.0, &rng), &mask);
  for (const double gain : {1.2, 0.8, 1.05, 0.6}) {
    model.Apply(Observe(base, gain, 2.0, &rng), &mask);
    EXPECT_NEAR(model.gain(), gain, 0.006) << gain;
    EXPECT_LT(model.foreground_fraction(), 0.002) << gain;
  }
  // Without compensation the same change is foreground nearly everywhere.
  BackgroundModelOptions fixed;
  fixed.compensate_gain = false;
  BackgroundModel uncompensated(160, 120, fixed);
  for (int i = 0; i < 30; ++i) uncompensated.Apply(Observe(base, 1.0, 2.0, &rng), &mask);
  uncompensated.Apply(Observe(base, 1.3, 2.0, &rng), &mask);
  EXPECT_EQ(uncompensated.gain(), 1.0);
  EXPECT_GT(uncompensated.foreground_fraction(), 0.5);
}

// A person covering most of the view at once (close to the lens, or after a
// frame gap) must not set the gain: their ratio to the background is not the
// light's. Here the person's shirt is the background's own texture at half
// its brightness, the worst case: the median of the ratios became theirs,
// and every pixel of theirs was background from then on.
TEST(BackgroundModelTest, APersonCoveringMostOfTheViewDoesNotSetTheGain) {
  constexpr int kW = 160;
  constexpr int kH = 120;
  const common::ImageRgb8 base = Texture(kW, kH, 5);
  const common::ImageRgb8 shirt = Observe(base, 0.5, 0.0, nullptr);
  std::mt19937_64 rng(6);
  BackgroundModel model(kW, kH, BackgroundModelOptions{});
  common::ImageU8 mask;
  for (int i = 0; i < 30; ++i) model.Apply(Observe(base, 1.0, 2.0, &rng), &mask);
  for (const double cover : {0.7, 0.9}) {
    long long visible = 0;
    long long missed = 0;
    for (int f = 0; f < 60; ++f) {
      common::ImageRgb8 frame = Observe(base, 1.0, 2.0, &rng);
      for (int v = 0; v < kH; ++v) {
        for (int u = 0; u < static_cast<int>(cover * kW); ++u) {
          for (int c = 0; c < 3; ++c) frame.Pixel(u, v)[c] = shirt.Pixel(u, v)[c];
        }
      }
      model.Apply(frame, &mask);
      for (int v = 0; v < kH; ++v) {
        for (int u = 0; u < static_cast<int>(cover * kW); ++u) {
          // Clearly visible: every channel at least twice the threshold off.
          bool clear = true;
          for (int c = 0; c < 3; ++c)
            clear = clear && base.Pixel(u, v)[c] - shirt.Pixel(u, v)[c] >= 50;
          if (!clear) continue;
          ++visible;
          missed += mask.At(u, v) == 0;
        }
      }
    }
    EXPECT_NEAR(model.gain(), 1.0, 0.03) << cover;
    EXPECT_GT(visible, 10000) << cover;
    EXPECT_EQ(missed, 0) << cover << ": of " << visible;
  }
}

constexpr int kStripesW = 160;
constexpr int kStripesH = 120;

/// The background's level at column u: stripes of +-40 around 128.
double Stripe(int u) { return 128.0 + 40.0 * std::sin(2.0 * M_PI * u / 16.0); }

/// Whether (u, v) lies in the flat patch.
bool InPatch(int u, int v) { return u >= 40 && u < 120 && v >= 30 && v < 90; }

/// Runs a model with and without the texture test on frames of
/// observe(gain, patch, rng) (kStripesW x kStripesH, the patch of
/// InPatch()): learning the empty cell, then under each light, the empty cell
/// (noise and the light add under 0.2 % foreground) and the patch (with the
/// texture every pixel inside its rim is foreground; without, more than a
/// sixth is missed). A rim pixel has one neighbour in the background, and
/// its texture differs by half as much (the pipeline's dilation covers the
/// rim from the pixels inside).
template <typename Observe>
void ExpectTheTextureFindsThePatch(const Observe& observe, std::uint64_t seed) {
  ASSERT_GT(BackgroundModelOptions{}.texture_threshold, 0) << "the default tests the texture";
  BackgroundModelOptions brightness_only;
  brightness_only.texture_threshold = 0;
  for (const BackgroundModelOptions& options : {BackgroundModelOptions{}, brightness_only}) {
    const bool texture = options.texture_threshold > 0;
    std::mt19937_64 rng(seed);
    BackgroundModel model(kStripesW, kStripesH, options);
    common::ImageU8 mask;
    for (int i = 0; i < options.learn_frames; ++i) model.Apply(observe(1.0, false, &rng), &mask);
    EXPECT_EQ(model.TextureThresholdAt(80, 60), texture ? options.texture_threshold : 0);
    // No neighbour beyond the border.
    EXPECT_EQ(model.TextureThresholdAt(0, 60), 0);
    EXPECT_EQ(model.TextureThresholdAt(kStripesW - 1, 60), 0);
    EXPECT_EQ(model.TextureThresholdAt(80, 0), 0);
    for (const double gain : {1.0, 0.8, 1.2}) {
      for (int i = 0; i < 3; ++i) {
        model.Apply(observe(gain, false, &rng), &mask);
        EXPECT_LT(model.foreground_fraction(), 0.002) << gain << " texture " << texture;
      }
      int missed = 0;
      for (int i = 0; i < 3; ++i) {
        model.Apply(observe(gain, true, &rng), &mask);
        for (int v = 31; v < 89; ++v) {
          for (int u = 41; u < 119; ++u) missed += mask.At(u, v) == 0 ? 1 : 0;
        }
      }
      if (texture) {
        EXPECT_EQ(missed, 0) << gain;
      } else {
        EXPECT_GT(missed, 3 * 78 * 58 / 6) << gain << ": the brightness test missed little";
      }
    }
  }
}

// A grey camera tells a person from the background by brightness alone: one
// whose grey matches the background behind them is background wherever it
// does. Before a textured background they still hide its texture: the
// difference of a pixel's neighbours changes. Here a flat patch before a
// background whose grey varies along the rows by +-40 levels (period 16 px),
// under three lights: brightness alone misses the patch where the
// background is within the threshold of it (a fifth to a third); with the texture
// every pixel inside its rim is foreground, while noise and the light add
// none.
TEST(BackgroundModelTest, AGreyMatchingTheBackgroundIsFoundByTheTextureItHides) {
  ExpectTheTextureFindsThePatch(
      [](double gain, bool patch, std::mt19937_64* rng) {
        std::normal_distribution<double> noise(0.0, 1.5);
        common::ImageU8 frame(kStripesW, kStripesH);
        for (int v = 0; v < kStripesH; ++v) {
          for (int u = 0; u < kStripesW; ++u) {
            const double value = (patch && InPatch(u, v) ? 128.0 : Stripe(u)) * gain + noise(*rng);
            frame.At(u, v) = static_cast<std::uint8_t>(std::clamp(std::lround(value), 0L, 255L));
          }
        }
        return frame;
      },
      12);
}

// The same for colour: a patch of the background's mean colour on
// stripes that only the red channel shows (green and blue are flat). Each
// channel's texture is tested.
TEST(BackgroundModelTest, AColourMatchingTheBackgroundIsFoundByTheTextureItHides) {
  ExpectTheTextureFindsThePatch(
      [](double gain, bool patch, std::mt19937_64* rng) {
        std::normal_distribution<double> noise(0.0, 1.5);
        common::ImageRgb8 frame(kStripesW, kStripesH);
        for (int v = 0; v < kStripesH; ++v) {
          for (int u = 0; u < kStripesW; ++u) {
            const std::array<double, 3> rgb{patch && InPatch(u, v) ? 128.0 : Stripe(u), 90.0,
                                            150.0};
            for (int c = 0; c < 3; ++c) {
              frame.Pixel(u, v)[c] = static_cast<std::uint8_t>(
                  std::clamp(std::lround(rgb[c] * gain + noise(*rng)), 0L, 255L));
            }
          }
        }
        return frame;
      },
      13);
}

// Grey frames too small to have a pixel with neighbours on every side are
// classified by brightness alone, the texture nowhere.
TEST(BackgroundModelTest, TinyGreyFramesAreClassified) {
  for (const auto& [w, h] : std::vector<std::pair<int, int>>{{1, 1}, {2, 5}, {5, 2}, {3, 3}}) {
    BackgroundModelOptions options;
    options.learn_frames = 2;
    BackgroundModel model(w, h, options);
    common::ImageU8 frame(w, h, 100);
    common::ImageU8 mask;
    for (int i = 0; i < 2; ++i) model.Apply(frame, &mask);
    model.Apply(frame, &mask);
    EXPECT_EQ(model.foreground_fraction(), 0.0) << w << " x " << h;
    frame.pixels.back() = 200;
    model.Apply(frame, &mask);
    EXPECT_EQ(mask.pixels.back(), 255) << w << " x " << h;
    EXPECT_EQ(model.TextureThresholdAt(w / 2, h / 2),
              w == 3 && h == 3 ? options.texture_threshold : 0);
  }
}

// A clipped pixel can certify nothing: a white vest before a wall that the
// light (or the exposure) brings near white is clipped like the wall, at 255,
// within the threshold of the wall's expected value, and was background.
TEST(BackgroundModelTest, ClippedPixelsAreForeground) {
  constexpr int kW = 64;
  constexpr int kH = 48;
  common::ImageRgb8 wall(kW, kH);
  std::mt19937_64 rng(8);
  std::uniform_int_distribution<int> level(236, 244);
  for (std::uint8_t& p : wall.pixels) p = static_cast<std::uint8_t>(level(rng));
  BackgroundModelOptions options;
  options.compensate_gain = false;
  BackgroundModel model(kW, kH, options);
  common::ImageU8 mask;
  for (int i = 0; i < 30; ++i) model.Apply(Observe(wall, 1.0, 1.0, &rng), &mask);
  model.Apply(Observe(wall, 1.0, 1.0, &rng), &mask);
  EXPECT_EQ(model.foreground_fraction(), 0.0);
  common::ImageRgb8 frame = Observe(wall, 1.0, 1.0, &rng);
  for (int v = 10; v < 30; ++v) {
    for (int u = 20; u < 40; ++u) {
      for (int c = 0; c < 3; ++c) frame.Pixel(u, v)[c] = 255;  // The vest, clipped.
    }
  }
  model.Apply(frame, &mask);
  for (int v = 10; v < 30; ++v) {
    for (int u = 20; u < 40; ++u) ASSERT_EQ(mask.At(u, v), 255) << u << "," << v;
  }
  EXPECT_EQ(mask.At(5, 5), 0);
}

// Adds `delta` to every channel of the square [20, 30) x [20, 30) of `frame`
// (something passing, or a person, there).
void PaintSquare(common::ImageRgb8* frame, int delta) {
  for (int v = 20; v < 30; ++v) {
    for (int u = 20; u < 30; ++u) {
      for (int c = 0; c < 3; ++c) {
        std::uint8_t& p = frame->Pixel(u, v)[c];
        p = static_cast<std::uint8_t>(std::clamp(p + delta, 0, 255));
      }
    }
  }
}

// Has `model` learn the view `base` (with noise), where learning frame i has
// `painted(i)` added in the square (0: nothing), then shows it a person of
// contrast `person` in the square: the square must be foreground and its
// pixels unreliable (threshold -1).
void LearnThenShowAPersonInTheSquare(BackgroundModel* model, const common::ImageRgb8& base,
                                     std::mt19937_64* rng, const std::function<int(int)>& painted,
                                     int person) {
  common::ImageU8 mask;
  for (int i = 0; model->learning() && i < 100000; ++i) {
    common::ImageRgb8 frame = Observe(base, 1.0, 2.0, rng);
    if (const int delta = painted(i); delta != 0) PaintSquare(&frame, delta);
    model->Apply(frame, &mask);
  }
  ASSERT_FALSE(model->learning());
  common::ImageRgb8 frame = Observe(base, 1.0, 2.0, rng);
  PaintSquare(&frame, person);
  model->Apply(frame, &mask);
  for (int v = 20; v < 30; ++v) {
    for (int u = 20; u < 30; ++u) {
      ASSERT_EQ(mask.At(u, v), 255) << u << "," << v;
      EXPECT_EQ(model->ThresholdAt(u, v), -1) << u << "," << v;
    }
  }
}

// Something passing through the view while the cell is learned (a robot arm)
// biases the mean and the noise where it passed, raising the threshold there
// above the one promised: a person of a contrast just over the threshold was
// then background. Those pixels are unreliable, always foreground, also after
// the background is saved and taken up again.
TEST(BackgroundModelTest, WhatPassedWhileLearningLeavesAlwaysForeground) {
  constexpr int kW = 64;
  constexpr int kH = 48;
  const common::ImageRgb8 base = Texture(kW, kH, 12);
  std::mt19937_64 rng(13);
  BackgroundModelOptions options;
  options.compensate_gain = false;
  BackgroundModel model(kW, kH, options);
  // The arm, for one frame; a person just over the threshold where it passed.
  LearnThenShowAPersonInTheSquare(
      &model, base, &rng, [](int i) { return i == 10 ? 100 : 0; }, options.min_threshold + 6);
  EXPECT_LT(model.foreground_fraction(), 0.05);  // Only there.
  // Saved and taken up: still unreliable there, and nowhere else.
  const std::string path = ::testing::TempDir() + "hg_bg_passed.bin";
  std::string error;
  ASSERT_TRUE(model.Save(path, &error)) << error;
  BackgroundModel restarted(kW, kH, options);
  ASSERT_TRUE(restarted.Load(path, &error)) << error;
  EXPECT_EQ(restarted.ThresholdAt(25, 25), -1);
  EXPECT_EQ(restarted.ThresholdAt(5, 5), model.ThresholdAt(5, 5));
  // Whatever the thresholds of the restart: with noise_sigmas 0 the pixels
  // were taken up at the least threshold, reliable.
  BackgroundModelOptions no_noise = options;
  no_noise.noise_sigmas = 0.0;
  BackgroundModel strict(kW, kH, no_noise);
  ASSERT_TRUE(strict.Load(path, &error)) << error;
  EXPECT_EQ(strict.ThresholdAt(25, 25), -1);
  EXPECT_EQ(strict.ThresholdAt(5, 5), options.min_threshold);
  // The header is checked too: a flipped bit of its frame count (which sets
  // every threshold) was taken up. Bytes 20..23: the frame count, here
  // within its range (the checksum tells) and out of it.
  for (const std::streamoff at : {std::streamoff{20}, std::streamoff{21}}) {
    SCOPED_TRACE(at);
    const std::string flipped = path + ".flipped";
    std::filesystem::copy_file(path, flipped, std::filesystem::copy_options::overwrite_existing);
    {
      std::fstream f(flipped, std::ios::in | std::ios::out | std::ios::binary);
      f.seekg(at);
      const char byte = static_cast<char>(f.get());
      f.seekp(at);
      f.put(static_cast<char>(byte ^ (at == 20 ? 0x01 : 0x40)));
    }
    BackgroundModel damaged(kW, kH, options);
    EXPECT_FALSE(damaged.Load(flipped, &error));
    EXPECT_NE(error.find("damaged"), std::string::npos) << error;
    std::remove(flipped.c_str());
  }
  std::remove(path.c_str());
}

// The same over a long learning (more frames than the noise is measured
// over): a person standing in view for the first 20 of 200 learning frames,
// then leaving, left the mean 10 levels dark there and the noise measured
// over the last frames inflated by that bias (the threshold at 57 where 25
// was promised); a later person of a contrast over the promised threshold
// was background there, free. Those pixels are unreliable now.
TEST(BackgroundModelTest, APersonLeavingEarlyInALongLearningLeavesAlwaysForeground) {
  constexpr int kW = 64;
  constexpr int kH = 48;
  const common::ImageRgb8 base = Texture(kW, kH, 14);
  std::mt19937_64 rng(15);
  BackgroundModelOptions options;
  options.compensate_gain = false;
  options.learn_frames = 200;
  BackgroundModel model(kW, kH, options);
  // Someone in dark clothes, then gone; later a person in the promised contrast.
  LearnThenShowAPersonInTheSquare(
      &model, base, &rng, [](int i) { return i < 20 ? -100 : 0; }, -(options.min_threshold + 6));
  // Elsewhere the promised threshold, and the empty cell background.
  EXPECT_EQ(model.ThresholdAt(5, 5), options.min_threshold);
  EXPECT_LT(model.foreground_fraction(), 0.05);
}

TEST(BackgroundModelTest, ThresholdsFollowTheLearnedNoise) {
  constexpr int kW = 64;
  constexpr int kH = 48;
  const common::ImageRgb8 base = Texture(kW, kH, 5);
  std::mt19937_64 rng(6);
  std::normal_distribution<double> noise(0.0, 1.0);
  BackgroundModelOptions options;
  options.compensate_gain = false;
  options.learn_frames = 60;
  BackgroundModel model(kW, kH, options);
  common::ImageU8 mask;
  // Columns 0..15 quiet (sigma 2), 16..31 noisy (sigma 8), 32..47 flickering
  // (sigma 30: unreliable), the rest quiet.
  auto sigma_at = [](int u) { return u < 16 ? 2.0 : u < 32 ? 8.0 : u < 48 ? 30.0 : 2.0; };
  for (int i = 0; i < options.learn_frames; ++i) {
    common::ImageRgb8 frame = base;
    for (int v = 0; v < kH; ++v) {
      for (int u = 0; u < kW; ++u) {
        for (int c = 0; c < 3; ++c) {
          const double value = base.Pixel(u, v)[c] + sigma_at(u) * noise(rng);
          frame.Pixel(u, v)[c] =
              static_cast<std::uint8_t>(std::clamp(std::lround(value), 0L, 255L));
        }
      }
    }
    model.Apply(frame, &mask);
  }
  ASSERT_FALSE(model.learning());
  double noisy_sum = 0.0;
  for (int v = 0; v < kH; ++v) {
    EXPECT_EQ(model.ThresholdAt(5, v), options.min_threshold);
    EXPECT_EQ(model.ThresholdAt(40, v), -1);  // Unreliable: always foreground.
    noisy_sum += model.ThresholdAt(20, v);
  }
  // 4 sigma of the largest of three channels of sigma 8: a little above 32.
  EXPECT_NEAR(noisy_sum / kH, 4.0 * 8.0 * 1.08, 4.0);
  model.Apply(base, &mask);
  for (int v = 0; v < kH; ++v) {
    EXPECT_EQ(mask.At(5, v), 0);
    EXPECT_EQ(mask.At(20, v), 0);
    EXPECT_EQ(mask.At(40, v), 255);
  }
}

/// Feeds frame_at(0 .. 899) (160 x 120: the object at x 100..129, y
/// 40..79; the left part brightening) to a learned model, checks that the
/// object is foreground in every frame, and returns the largest share of
/// foreground in columns 0..39 (well inside the lit part).
template <typename FrameAt>
double RunTheLocalBrightening(BackgroundModel* model, const FrameAt& frame_at) {
  common::ImageU8 mask;
  double worst = 0.0;
  for (int i = 0; i < 900; ++i) {
    model->Apply(frame_at(i), &mask);
    long long object = 0;
    for (int v = 40; v < 80; ++v) {
      for (int u = 100; u < 130; ++u) object += mask.At(u, v) != 0 ? 1 : 0;
    }
    EXPECT_EQ(object, 30 * 40) << "frame " << i;
    long long lit = 0;
    for (int v = 0; v < mask.height; ++v) {
      for (int u = 0; u < 40; ++u) lit += mask.At(u, v) != 0 ? 1 : 0;
    }
    worst = std::max(worst, static_cast<double>(lit) / (40.0 * mask.height));
  }
  return worst;
}

// A slow local light change far from foreground is followed; an object that
// stays put is never learned, and neither is anything within the guard.
TEST(BackgroundModelTest, AdaptsSlowLocalChangesOnlyFarFromForeground) {
  constexpr int kW = 160;
  constexpr int kH = 120;
  const common::ImageRgb8 base = Texture(kW, kH, 7);
  std::mt19937_64 rng(8);
  BackgroundModelOptions options;
  BackgroundModel model(kW, kH, options);
  common::ImageU8 mask;
  for (int i = 0; i < options.learn_frames; ++i) model.Apply(Observe(base, 1.0, 2.0, &rng), &mask);
  // An object at x 100..129, y 40..79 (constant colour), and the left third of
  // the image brightening by 40 grey levels over 20 s.
  auto frame_at = [&](int i) {
    common::ImageRgb8 f = Observe(base, 1.0, 2.0, &rng);
    const double lift = std::min(40.0, 40.0 * i / 600.0);
    for (int v = 0; v < kH; ++v) {
      for (int u = 0; u < kW; ++u) {
        std::uint8_t* p = f.Pixel(u, v);
        if (u >= 100 && u < 130 && v >= 40 && v < 80) {
          p[0] = 230;
          p[1] = 20;
          p[2] = 90;
        } else if (u < 50) {
          for (int c = 0; c < 3; ++c)
            p[c] = static_cast<std::uint8_t>(std::min(255.0, p[c] + lift));
        }
      }
    }
    return f;
  };
  const std::vector<double> learned = Means(model, 3);
  const double worst_lit_false_positive = RunTheLocalBrightening(&model, frame_at);
  // The brightening was followed (well inside the lit part) ...
  EXPECT_LE(worst_lit_false_positive, 0.01);
  EXPECT_NEAR(model.MeanAt(10, 60, 0), learned[(60 * kW + 10) * 3] + 40.0, 3.0);
  // ... the object and its guard band were not learned ...
  common::ImageU8 guard(kW, kH, 0);
  for (int v = 40 - options.guard_px; v < 80 + options.guard_px; ++v) {
    for (int u = 100 - options.guard_px; u < 130 + options.guard_px; ++u) guard.At(u, v) = 255;
  }
  EXPECT_EQ(ChangedIn(learned, Means(model, 3), guard, 3), 0);
  // ... and where the light did not change, the background did not drift.
  EXPECT_NEAR(model.MeanAt(80, 10, 1), learned[(10 * kW + 80) * 3 + 1], 1.5);
  EXPECT_NEAR(model.gain(), 1.0, 0.01);
}

// The same slow local brightening behind a sharp light edge, for a grey
// camera with the texture test: the background follows it, and the edge,
// where the lit side's background lags the frame by a few levels, does not
// start foreground that spreads. (At a texture threshold of 12, this
// background's noise bound, foreground spread tile by tile over the lit part:
// tiles near foreground may not adapt and fall behind their neighbours.)
TEST(BackgroundModelTest, AGreyCameraFollowsASlowLocalChangeBehindALightEdge) {
  constexpr int kW = 160;
  constexpr int kH = 120;
  std::mt19937_64 texture_rng(7);
  std::uniform_int_distribution<int> level(40, 200);
  common::ImageU8 base(kW, kH);
  for (std::uint8_t& p : base.pixels) p = static_cast<std::uint8_t>(level(texture_rng));
  std::mt19937_64 rng(8);
  std::normal_distribution<double> noise(0.0, 2.0);
  // Frame i; i < 0: the empty cell as learned.
  auto frame_at = [&](int i) {
    common::ImageU8 f(kW, kH);
    const double lift = std::clamp(40.0 * i / 600.0, 0.0, 40.0);
    for (int v = 0; v < kH; ++v) {
      for (int u = 0; u < kW; ++u) {
        double x = base.At(u, v) + noise(rng);
        if (i >= 0 && u >= 100 && u < 130 && v >= 40 && v < 80) {
          x = 230.0;  // An object that stays.
        } else if (u < 50) {
          x += lift;
        }
        f.At(u, v) = static_cast<std::uint8_t>(std::clamp(std::lround(x), 0L, 255L));
      }
    }
    return f;
  };
  const BackgroundModelOptions options;
  ASSERT_GT(options.texture_threshold, 0);
  BackgroundModel model(kW, kH, options);
  common::ImageU8 mask;
  for (int i = 0; i < options.learn_frames; ++i) model.Apply(frame_at(-1), &mask);
  ASSERT_FALSE(model.learning());
  const double worst_lit_false_positive = RunTheLocalBrightening(&model, frame_at);
  EXPECT_LE(worst_lit_false_positive, 0.01);
  EXPECT_NEAR(model.MeanAt(10, 60, 0), base.At(10, 60) + 40.0, 3.0);
}

TEST(BackgroundModelTest, AnotherPixelFormatRestartsLearning) {
  const common::ImageRgb8 base = Texture(64, 48, 9);
  BackgroundModelOptions options;
  options.learn_frames = 5;
  BackgroundModel model(64, 48, options);
  common::ImageU8 mask;
  for (int i = 0; i < 5; ++i) model.Apply(base, &mask);
  ASSERT_FALSE(model.learning());
  model.Apply(base, &mask);
  EXPECT_EQ(model.foreground_fraction(), 0.0);
  model.Apply(testing::LumaOf(base), &mask);
  EXPECT_TRUE(model.learning());
  EXPECT_EQ(model.foreground_fraction(), 1.0);
  for (int i = 0; i < 5; ++i) model.Apply(testing::LumaOf(base), &mask);
  EXPECT_FALSE(model.learning());
  EXPECT_EQ(model.foreground_fraction(), 0.0);
}

TEST(BackgroundModelTest, NoAllocationPerFrame) {
  const common::ImageRgb8 base = Texture(320, 180, 10);
  std::mt19937_64 rng(11);
  std::vector<common::ImageRgb8> frames;
  for (int i = 0; i < 8; ++i) frames.push_back(Observe(base, 1.0 + 0.02 * i, 2.0, &rng));
  // Foreground, shadows and adaptation all on the path.
  for (int i = 4; i < 8; ++i) {
    for (int v = 50; v < 120; ++v) {
      for (int u = 100 + 10 * i; u < 150 + 10 * i; ++u) {
        std::uint8_t* p = frames[i].Pixel(u, v);
        for (int c = 0; c < 3; ++c) p[c] = static_cast<std::uint8_t>(p[c] * (c == 0 ? 0.3 : 0.7));
      }
    }
  }
  std::vector<common::ImageU8> grey;
  for (const auto& f : frames) grey.push_back(testing::LumaOf(f));
  for (const bool shadows : {true, false}) {
    BackgroundModelOptions options;
    options.shadows_are_foreground = shadows;
    options.learn_frames = 4;
    BackgroundModel colour(320, 180, options);
    BackgroundModel mono(320, 180, options);
    common::ImageU8 mask;
    common::ImageU8 mono_mask;
    colour.Apply(frames[0], &mask);  // Sizes the masks.
    mono.Apply(grey[0], &mono_mask);
    long allocations = 0;
    {
      const hg::testing::AllocationCounter counter;
      for (int pass = 0; pass < 3; ++pass) {
        for (std::size_t i = 0; i < frames.size(); ++i) {
          colour.Apply(frames[i], &mask);
          mono.Apply(grey[i], &mono_mask);
        }
        colour.Reset();
        mono.Reset();
      }
      allocations = counter.count();
    }
    EXPECT_EQ(allocations, 0) << "shadows_are_foreground " << shadows;
  }
}
}  // namespace
}  // namespace hg::silhouette
