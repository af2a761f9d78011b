// The background model at Full HD: the paper cell's 8 cameras, rendered and
// run through the pipeline lock-step, with the points inside the people that
// each setting publishes free. One of its people (bob) wears trousers within
// 10 to 20 grey levels of the dark floor in every channel: a camouflage that
// no threshold tells apart everywhere, and what docs/cameras.md ("Contrast
// below the threshold") reports from these runs.
#include <gtest/gtest.h>

#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "common/image.h"
#include "pipeline/pipeline.h"
#include "sim/colour_renderer.h"
#include "sim/scene.h"
#include "support/luma_image.h"
#include "support/sim_bodies.h"

namespace hg::pipeline {
namespace {

constexpr int kLearn = 12;   // Frames of the empty cell (the models learn 10).
constexpr int kChecked = 6;  // Frames with the people, from 4.4 s.

struct Setting {
  const char* name;
  bool grey;
  int threshold;
  int texture_threshold;
  bool fill_holes;
};

// Points (200 per body part) inside the people that each setting's pipeline
// published free over the checked frames; the settings run side by side on
// the same rendered frames.
std::vector<int> FreePoints(const std::vector<Setting>& settings) {
  const sim::Scene loaded =
      sim::LoadScene(std::string(HG_SOURCE_DIR) + "/config/scenes/paper_cell.yaml");
  sim::Scene empty = loaded;
  empty.people.clear();
  std::vector<std::unique_ptr<Pipeline>> pipelines;
  for (const Setting& s : settings) {
    PipelineOptions options;
    options.bounds = loaded.bounds;
    options.depth = 8;
    options.publish_depth = 8;
    options.background.learn_frames = 10;
    options.background.min_threshold = s.threshold;
    options.background.texture_threshold = s.texture_threshold;
    options.background_fill_holes = s.fill_holes;
    std::vector<PipelineCamera> cameras;
    for (const sim::SceneCamera& c : loaded.cameras) cameras.push_back({c.model, nullptr, 150});
    pipelines.push_back(
        std::make_unique<Pipeline>(options, std::move(cameras), loaded.ObstacleMeshes(), nullptr));
  }
  std::vector<sim::ColourRenderer> with, without;
  for (int c = 0; c < static_cast<int>(loaded.cameras.size()); ++c) {
    with.emplace_back(loaded, c);
    without.emplace_back(empty, c);
  }
  std::vector<int> free(settings.size(), 0);
  capture::Frame rgb, grey;
  rgb.kind = capture::FrameKind::kRgb;
  grey.kind = capture::FrameKind::kMono;
  for (int i = 0; i < kLearn + kChecked; ++i) {
    const bool present = i >= kLearn;
    const double t = 4.0 + i / 30.0;
    std::vector<sim::BodyState> people;
    if (present) {
      for (const sim::Person& p : loaded.people) people.push_back(sim::EvaluatePerson(p, t));
    }
    rgb.stamp_ns = grey.stamp_ns = 1'000'000'000LL + i * 1'000'000'000LL / 30;
    rgb.index = grey.index = static_cast<std::uint64_t>(i);
    for (int c = 0; c < static_cast<int>(loaded.cameras.size()); ++c) {
      (present ? with : without)[c].Render(people, t, rgb.index, &rgb.rgb);
      testing::LumaOf(rgb.rgb, &grey.grey);  // A grey camera's frame.
      for (std::size_t k = 0; k < settings.size(); ++k) {
        pipelines[k]->Feed(c, settings[k].grey ? grey : rgb);
      }
    }
    const auto points = testing::PointsInPeople(loaded, t, 200, static_cast<std::uint64_t>(i));
    for (std::size_t k = 0; k < settings.size(); ++k) {
      const auto s = pipelines[k]->Step(rgb.stamp_ns);
      EXPECT_FALSE(s->health.degraded) << settings[k].name << " frame " << i;
      if (!present) continue;
      free[k] += testing::PointsInUnlistedCells(points, s->bounds.min, s->bounds.max, s->depth,
                                                {&s->occupied, &s->occluded});
    }
  }
  for (std::size_t k = 0; k < settings.size(); ++k) {
    std::printf("%s: %d points inside the people free over %d frames\n", settings[k].name, free[k],
                kChecked);
  }
  return free;
}

// Colour frames: brightness alone at threshold 25 against the texture test
// at 25, and against hullguardd's defaults (threshold 15, texture test): each
// frees a tenth as many points or fewer (about 7 000 sampled per frame).
TEST(PipelineFullHdTest, TheTextureAndTheDefaultThresholdFindMostOfALowContrastPersonInColour) {
  const std::vector<int> free =
      FreePoints({{"RGB, brightness alone, threshold 25", false, 25, 0, true},
                  {"RGB, texture, threshold 25", false, 25, 14, true},
                  {"RGB, texture, threshold 15", false, 15, 14, true}});
  EXPECT_GT(free[0], 100) << "the camouflage no longer shows: the test shows nothing";
  EXPECT_LE(free[1] * 10, free[0]);
  EXPECT_LE(free[2] * 10, free[0]);
}

// Grey frames: the texture test and the filling against brightness alone,
// at threshold 25.
TEST(PipelineFullHdTest, TheTextureAndTheFillingFindMostOfALowContrastPersonInGrey) {
  const std::vector<int> free =
      FreePoints({{"Mono8, brightness alone, threshold 25", true, 25, 0, false},
                  {"Mono8, texture and filling, threshold 25", true, 25, 14, true}});
  EXPECT_GT(free[0], 1000) << "the camouflage no longer shows: the test shows nothing";
  EXPECT_LE(free[1] * 10, free[0]);
}

}  // namespace
}  // namespace hg::pipeline
