#include "pipeline/cycle_phase.h"

#include <chrono>
#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>

namespace hg::pipeline {
namespace {

using std::chrono::microseconds;
using std::chrono::milliseconds;
using std::chrono::nanoseconds;
using Duration = CyclePhase::Duration;

constexpr nanoseconds kPeriod{33'333'333};  // 30 Hz.

double Ms(Duration d) { return std::chrono::duration<double, std::milli>(d).count(); }

TEST(CyclePhaseTest, NoCamerasNoCorrection) {
  CyclePhase phase(kPeriod, {});
  EXPECT_EQ(phase.Error({}).count(), 0);
  EXPECT_EQ(phase.Update({}).count(), 0);
}

TEST(CyclePhaseTest, OneCameraAimsMarginAfterItsFrame) {
  CyclePhase phase(kPeriod, {});  // Margin 2 ms, gain 0.25, step 2 ms.
  // Ready 5 ms before the start: the start should have been 3 ms earlier.
  const std::vector<Duration> early{milliseconds(5)};
  EXPECT_NEAR(Ms(phase.Error(early)), -3.0, 1e-6);
  EXPECT_NEAR(Ms(phase.Update(early)), -0.75, 1e-6);  // No jitter seen yet.
  EXPECT_TRUE(phase.locked());
  // Ready 1 ms after the start: 3 ms later.
  const std::vector<Duration> late{milliseconds(-1)};
  EXPECT_NEAR(Ms(phase.Error(late)), 3.0, 1e-6);
  // A frame several periods old says the same as a fresh one of that phase.
  const std::vector<Duration> old{milliseconds(5) + 3 * kPeriod};
  EXPECT_NEAR(Ms(phase.Error(old)), -3.0, 1e-6);
}

TEST(CyclePhaseTest, TheFrameBeforeTheWidestGapCompletesTheSet) {
  const CyclePhase phase(kPeriod, {});
  // Four cameras at capture offsets of 0, 4, 8 and 12.5 ms: ready 20, 16, 12
  // and 7.5 ms before the start. The set completes with the last one.
  const std::vector<Duration> set{milliseconds(16), milliseconds(20), microseconds(7500),
                                  milliseconds(12)};
  EXPECT_NEAR(Ms(phase.Error(set)), -5.5, 1e-6);
  // A set that straddles the start: ready 2.3 ms before, 1 ms and 3 ms after.
  const std::vector<Duration> straddling{microseconds(2300), milliseconds(-1), milliseconds(-3)};
  EXPECT_NEAR(Ms(phase.Error(straddling)), 5.0, 1e-6);
}

TEST(CyclePhaseTest, CorrectionIsLimitedPerCycle) {
  const CyclePhaseOptions options{
      .margin = milliseconds(2), .gain = 1.0, .max_step = milliseconds(1)};
  CyclePhase later(kPeriod, options);
  const std::vector<Duration> late{milliseconds(-10)};
  EXPECT_NEAR(Ms(later.Update(late)), 1.0, 1e-6);
  CyclePhase earlier(kPeriod, options);
  const std::vector<Duration> early{milliseconds(10)};
  EXPECT_NEAR(Ms(earlier.Update(early)), -1.0, 1e-6);
}

// A fixed-rate cycle with the corrections applied, against cameras that
// capture at `camera_period` at fixed offsets and are ready after a jittered
// processing time. Returns the cycle starts.
std::vector<double> Simulate(nanoseconds camera_period, double first_start_ms, int cycles,
                             std::vector<double>* last_ready_lag_ms, bool* locked = nullptr) {
  CyclePhase phase(kPeriod, {});
  const double offsets_ms[] = {0.0, 0.0, 0.0, 0.0, 0.0, 4.0, 8.0, 12.5};
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> processing_ms(1.5, 4.5);
  const double cam_ms = std::chrono::duration<double, std::milli>(camera_period).count();
  // Ready times of every camera's frames, by frame number.
  const int frames = static_cast<int>(cycles * Ms(kPeriod) / cam_ms) + 10;
  std::vector<std::vector<double>> ready(8, std::vector<double>(frames));
  for (int c = 0; c < 8; ++c) {
    for (int f = 0; f < frames; ++f) ready[c][f] = f * cam_ms + offsets_ms[c] + processing_ms(rng);
  }
  std::vector<double> starts;
  double next_ms = first_start_ms;
  for (int k = 0; k < cycles; ++k) {
    const double start = next_ms;
    starts.push_back(start);
    std::vector<Duration> ages;
    double newest_of_set = -1e9;
    for (int c = 0; c < 8; ++c) {
      double newest = -1e9;
      for (int f = 0; f < frames && ready[c][f] <= start; ++f) newest = ready[c][f];
      if (newest < -1e8) continue;
      ages.push_back(nanoseconds(static_cast<std::int64_t>((start - newest) * 1e6)));
      if (c == 7) newest_of_set = newest;
    }
    if (last_ready_lag_ms != nullptr) last_ready_lag_ms->push_back(start - newest_of_set);
    next_ms = start + Ms(kPeriod) + Ms(phase.Update(ages));
  }
  if (locked != nullptr) *locked = phase.locked();
  return starts;
}

TEST(CyclePhaseTest, LocksOntoCamerasAtTheSameRate) {
  // Whatever phase the cycle starts at, within two seconds it starts at most
  // 7 ms after the last camera of a set is ready (margin 2 ms, twice the
  // jitter, and the processing time's spread of 3 ms: 1.5 to 4.5 ms), and
  // never so early that this camera's frame slips to the next cycle.
  for (double first : {1.0, 9.0, 17.0, 25.0, 33.0}) {
    std::vector<double> lag;
    bool locked = false;
    const std::vector<double> starts = Simulate(kPeriod, first, 600, &lag, &locked);
    EXPECT_TRUE(locked);
    for (std::size_t k = 60; k < lag.size(); ++k) {
      EXPECT_GE(lag[k], 0.0) << "first start " << first << " ms, cycle " << k;
      EXPECT_LE(lag[k], 7.0) << "first start " << first << " ms, cycle " << k;
    }
    // The rate is the configured one: once locked, a period per cycle.
    const double mean_period = (starts.back() - starts[60]) / (starts.size() - 1 - 60);
    EXPECT_NEAR(mean_period, Ms(kPeriod), 0.05);
  }
}

TEST(CyclePhaseTest, CamerasAtAnotherRateDoNotChangeTheRate) {
  // Cameras at 25 Hz against a 30 Hz cycle: the phase error goes round and
  // round; the corrections must cancel out, not drag the cycle along.
  bool locked = true;
  const std::vector<double> starts = Simulate(nanoseconds(40'000'000), 3.0, 900, nullptr, &locked);
  EXPECT_FALSE(locked);
  const double mean_period = (starts.back() - starts.front()) / (starts.size() - 1);
  EXPECT_NEAR(mean_period, Ms(kPeriod), 0.02 * Ms(kPeriod));
  for (std::size_t k = 1; k < starts.size(); ++k) {
    EXPECT_NEAR(starts[k] - starts[k - 1], Ms(kPeriod), 2.0 + 1e-6);
  }
}

}  // namespace
}  // namespace hg::pipeline
