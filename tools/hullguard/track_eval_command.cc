// `hullguard track-eval`: a simulated scene rendered, reconstructed by the
// engine, published as occupancy snapshots and tracked frame by frame, with
// the CLEAR MOT metrics against the simulator's ground truth.
#include <time.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "common/cli_checks.h"
#include "common/config_error.h"
#include "common/json.h"
#include "hullguard/commands.h"
#include "hullguard/frame_stats.h"
#include "hullguard/scene_engine.h"
#include "pipeline/published_grid.h"
#include "pipeline/snapshot.h"
#include "sim/scene.h"
#include "tracking/clear_mot.h"
#include "tracking/tracker.h"

namespace hg::tools {
namespace {

using Eigen::Vector3d;

struct TrackEvalFlags {
  std::string scene;
  int frames = 0;  // 0: until every script has ended, plus one second.
  double start_s = 0.0;
  int depth = 8;
  int publish_depth = 7;
  int threads = 2;
  double threshold_m = 0.5;
  int particles = tracking::ParticleFilterOptions{}.num_particles;
  double voxel_m = tracking::TrackerOptions{}.voxel_m;
  double deadline_ms = 0.0;  // 0: no deadline.
  int coarse_first_depth = 0;
  bool json = false;
  std::string plot;
  std::string trace;
};

/// Time of the calling thread on its core (ms): the tracker's own work,
/// whatever else runs on the machine.
double ThreadCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) * 1e3 + static_cast<double>(ts.tv_nsec) * 1e-6;
}

double Mean(const std::vector<double>& v) {
  if (v.empty()) return 0.0;
  double s = 0.0;
  for (const double x : v) s += x;
  return s / static_cast<double>(v.size());
}

/// Scene time when the last person's script ends.
double ScriptEnd(const sim::Scene& scene) {
  double end = 0.0;
  for (const sim::Person& person : scene.people) end = std::max(end, sim::ScriptEndS(person));
  return end;
}

/// What the plot needs of one frame.
struct FrameRecord {
  double t_s = 0.0;
  std::vector<std::pair<int, Vector3d>> people;  // Person index, centre (in the bounds).
  std::vector<int> missed;                       // Person indices without a track.
  std::vector<std::pair<std::uint32_t, Vector3d>> tracks;
  std::vector<std::uint32_t> false_positives;  // Track ids.
  std::vector<int> switched;                   // Person indices with an identity switch.
};

/// Per ground-truth person.
struct PersonStats {
  std::int64_t frames = 0;
  std::int64_t misses = 0;
  std::int64_t switches = 0;
  std::int64_t matches = 0;
  double distance_sum_m = 0.0;
};

cv::Scalar TrackColour(std::uint32_t id) {
  static constexpr std::array<std::array<int, 3>, 10> kPalette = {{{31, 119, 180},
                                                                   {255, 127, 14},
                                                                   {44, 160, 44},
                                                                   {214, 39, 40},
                                                                   {148, 103, 189},
                                                                   {140, 86, 75},
                                                                   {227, 119, 194},
                                                                   {188, 189, 34},
                                                                   {23, 190, 207},
                                                                   {127, 127, 127}}};
  const auto& c = kPalette[(id - 1) % kPalette.size()];
  return {static_cast<double>(c[2]), static_cast<double>(c[1]), static_cast<double>(c[0])};
}

/// Top view (x, y) of the ground-truth paths (grey) and the tracks (a colour
/// per id) over the whole run, and the heights of both over time.
void WritePlot(const sim::Scene& scene, const std::vector<FrameRecord>& frames,
               const std::string& title, const std::string& path) {
  const common::Box3& b = scene.bounds;
  const Vector3d size = b.Size();
  const int margin = 50;
  const double scale = 640.0 / std::max(size.x(), size.y());  // px per m.
  const int top_w = static_cast<int>(std::lround(size.x() * scale));
  const int top_h = static_cast<int>(std::lround(size.y() * scale));
  const int z_w = 640;
  const int z_h = top_h;
  const int width = margin + top_w + margin + 20 + z_w + margin;
  const int height = margin + 30 + top_h + margin;
  cv::Mat img(height, width, CV_8UC3, cv::Scalar(255, 255, 255));
  const cv::Point2d top_origin(margin, margin + 30);
  auto top = [&](const Vector3d& p) {
    return cv::Point(static_cast<int>(std::lround(top_origin.x + (p.x() - b.min.x()) * scale)),
                     static_cast<int>(std::lround(top_origin.y + (b.max.y() - p.y()) * scale)));
  };
  const double t0 = frames.empty() ? 0.0 : frames.front().t_s;
  const double t1 = frames.empty() ? 1.0 : std::max(frames.back().t_s, t0 + 1e-3);
  const double z_max = std::min(b.max.z(), 2.2);
  const cv::Point2d z_origin(margin + top_w + margin + 20, margin + 30);
  auto zt = [&](double t, double z) {
    return cv::Point(static_cast<int>(std::lround(z_origin.x + (t - t0) / (t1 - t0) * z_w)),
                     static_cast<int>(std::lround(
                         z_origin.y + (1.0 - (z - b.min.z()) / (z_max - b.min.z())) * z_h)));
  };
  const cv::Scalar grid(225, 225, 225), axis(90, 90, 90), text(30, 30, 30);
  const auto font = cv::FONT_HERSHEY_SIMPLEX;

  // Frames: top view with a 1 m grid, obstacles and foreground objects.
  for (double x = std::ceil(b.min.x()); x <= b.max.x() + 1e-9; x += 1.0) {
    cv::line(img, top({x, b.min.y(), 0}), top({x, b.max.y(), 0}), grid, 1);
    cv::putText(img, std::to_string(static_cast<int>(x)),
                top({x, b.min.y(), 0}) + cv::Point(-4, 18), font, 0.45, text, 1, cv::LINE_AA);
  }
  for (double y = std::ceil(b.min.y()); y <= b.max.y() + 1e-9; y += 1.0) {
    cv::line(img, top({b.min.x(), y, 0}), top({b.max.x(), y, 0}), grid, 1);
    cv::putText(img, std::to_string(static_cast<int>(y)),
                top({b.min.x(), y, 0}) + cv::Point(-18, 5), font, 0.45, text, 1, cv::LINE_AA);
  }
  auto footprint = [&](const sim::Solid& s, const cv::Scalar& fill) {
    const common::Box3 box = sim::Bounds(s.geometry);
    const cv::Point a = top({box.min.x(), box.max.y(), 0}), c = top({box.max.x(), box.min.y(), 0});
    cv::rectangle(img, a, c, fill, cv::FILLED);
    cv::rectangle(img, a, c, axis, 1);
  };
  for (const sim::Solid& s : scene.obstacles) footprint(s, cv::Scalar(200, 200, 200));
  for (const sim::Solid& s : scene.foreground_objects) footprint(s, cv::Scalar(150, 190, 215));
  cv::rectangle(img, top({b.min.x(), b.max.y(), 0}), top({b.max.x(), b.min.y(), 0}), axis, 1);
  cv::putText(img, "top view (x right, y up, m)", cv::Point(margin, margin + 18), font, 0.5, text,
              1, cv::LINE_AA);
  // z over time.
  for (double z = 0.0; z <= z_max + 1e-9; z += 0.5) {
    cv::line(img, zt(t0, z), zt(t1, z), grid, 1);
    char label[16];
    std::snprintf(label, sizeof(label), "%.1f", z);
    cv::putText(img, label, zt(t0, z) + cv::Point(-32, 5), font, 0.45, text, 1, cv::LINE_AA);
  }
  const double t_step = (t1 - t0) > 40 ? 10.0 : (t1 - t0) > 8 ? 2.0 : 0.5;
  for (double t = std::ceil(t0 / t_step) * t_step; t <= t1 + 1e-9; t += t_step) {
    cv::line(img, zt(t, b.min.z()), zt(t, z_max), grid, 1);
    char label[16];
    std::snprintf(label, sizeof(label), "%g", t);
    cv::putText(img, label, zt(t, b.min.z()) + cv::Point(-6, 18), font, 0.45, text, 1, cv::LINE_AA);
  }
  cv::rectangle(img, zt(t0, z_max), zt(t1, b.min.z()), axis, 1);
  cv::putText(img, "centre height z (m) over time (s)", cv::Point(z_origin.x, margin + 18), font,
              0.5, text, 1, cv::LINE_AA);

  // Ground truth: thick grey paths, names at the start.
  const cv::Scalar truth(170, 170, 170);
  for (std::size_t person = 0; person < scene.people.size(); ++person) {
    const FrameRecord* previous = nullptr;
    Vector3d last = Vector3d::Zero();
    bool labelled = false;
    for (const FrameRecord& f : frames) {
      const Vector3d* p = nullptr;
      for (const auto& [index, c] : f.people) {
        if (index == static_cast<int>(person)) p = &c;
      }
      if (p == nullptr) {
        previous = nullptr;
        continue;
      }
      if (previous != nullptr) {
        cv::line(img, top(last), top(*p), truth, 7, cv::LINE_AA);
        cv::line(img, zt(previous->t_s, last.z()), zt(f.t_s, p->z()), truth, 7, cv::LINE_AA);
      }
      if (!labelled) {
        cv::putText(img, scene.people[person].name, top(*p) + cv::Point(8, -8), font, 0.5, text, 1,
                    cv::LINE_AA);
        labelled = true;
      }
      previous = &f;
      last = *p;
    }
  }
  // Tracks: thin lines, one colour per id, the id at the start.
  std::map<std::uint32_t, std::pair<double, Vector3d>> last_seen;
  for (const FrameRecord& f : frames) {
    std::map<std::uint32_t, std::pair<double, Vector3d>> now;
    for (const auto& [id, c] : f.tracks) {
      const cv::Scalar colour = TrackColour(id);
      const auto it = last_seen.find(id);
      if (it != last_seen.end()) {
        cv::line(img, top(it->second.second), top(c), colour, 2, cv::LINE_AA);
        cv::line(img, zt(it->second.first, it->second.second.z()), zt(f.t_s, c.z()), colour, 2,
                 cv::LINE_AA);
      } else {
        cv::circle(img, top(c), 4, colour, cv::FILLED, cv::LINE_AA);
        cv::putText(img, "#" + std::to_string(id), top(c) + cv::Point(6, 16), font, 0.5, colour, 1,
                    cv::LINE_AA);
      }
      now[id] = {f.t_s, c};
    }
    last_seen = std::move(now);
  }
  // Errors: misses as red crosses on the truth, false positives as black
  // squares, switches as red circles.
  for (const FrameRecord& f : frames) {
    for (const int person : f.missed) {
      for (const auto& [index, c] : f.people) {
        if (index != person) continue;
        cv::drawMarker(img, top(c), cv::Scalar(0, 0, 220), cv::MARKER_TILTED_CROSS, 8, 1);
        cv::drawMarker(img, zt(f.t_s, c.z()), cv::Scalar(0, 0, 220), cv::MARKER_TILTED_CROSS, 8, 1);
      }
    }
    for (const std::uint32_t id : f.false_positives) {
      for (const auto& [tid, c] : f.tracks) {
        if (tid != id) continue;
        cv::drawMarker(img, top(c), cv::Scalar(0, 0, 0), cv::MARKER_SQUARE, 6, 1);
        cv::drawMarker(img, zt(f.t_s, c.z()), cv::Scalar(0, 0, 0), cv::MARKER_SQUARE, 6, 1);
      }
    }
    for (const int person : f.switched) {
      for (const auto& [index, c] : f.people) {
        if (index == person) cv::circle(img, top(c), 12, cv::Scalar(0, 0, 220), 2, cv::LINE_AA);
      }
    }
  }
  cv::putText(img, title, cv::Point(margin, 30), font, 0.6, text, 1, cv::LINE_AA);
  cv::putText(img,
              "grey: ground truth (body box centre); colour: tracks by id; red x: miss; "
              "black square: false positive; red ring: id switch",
              cv::Point(margin, height - 18), font, 0.45, text, 1, cv::LINE_AA);
  if (!cv::imwrite(path, img)) throw common::ConfigError(path + ": cannot write the plot");
}

/// The match of ground-truth object `object_id` in frame `m`; null when missed.
const tracking::MotMatch* MatchOf(const tracking::MotFrame& m, std::uint32_t object_id) {
  const auto it =
      std::find_if(m.matches.begin(), m.matches.end(),
                   [&](const tracking::MotMatch& x) { return x.object_id == object_id; });
  return it == m.matches.end() ? nullptr : &*it;
}

/// One frame of the --trace CSV: each person in the cell (truth: body-box
/// centre and half-extents, the matched track and its distance, empty when
/// missed), then each scored track (centre and half-axes).
void WriteTraceFrame(int frame, double t, const sim::Scene& scene,
                     const std::vector<tracking::MotPoint>& objects,
                     const std::vector<int>& object_person,
                     const std::vector<Vector3d>& object_half, const tracking::MotFrame& m,
                     const tracking::Tracker& tracker, std::FILE* out) {
  for (std::size_t k = 0; k < objects.size(); ++k) {
    const Vector3d& p = objects[k].position_W;
    const Vector3d& h = object_half[k];
    std::fprintf(out, "%d,%.4f,truth,%u,%s,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,", frame, t, objects[k].id,
                 scene.people[object_person[k]].name.c_str(), p.x(), p.y(), p.z(), h.x(), h.y(),
                 h.z());
    if (const tracking::MotMatch* match = MatchOf(m, objects[k].id)) {
      std::fprintf(out, "%u,%.4f\n", match->hypothesis_id, match->distance_m);
    } else {
      std::fputs(",\n", out);
    }
  }
  for (const tracking::Track& tr : tracker.tracks()) {
    if (!scene.bounds.Contains(tr.centre_W)) continue;  // Not scored.
    const Vector3d& c = tr.centre_W;
    const Vector3d& h = tr.half_axes_m;
    std::fprintf(out, "%d,%.4f,track,%u,,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,,\n", frame, t, tr.id, c.x(),
                 c.y(), c.z(), h.x(), h.y(), h.z());
  }
}

int RunTrackEval(const TrackEvalFlags& f) {
  if (f.publish_depth > f.depth) {
    throw common::ConfigError("--publish-depth " + std::to_string(f.publish_depth) +
                              ": must not exceed --depth " + std::to_string(f.depth));
  }
  sim::Scene loaded = sim::LoadScene(f.scene);
  const double dt = 1.0 / loaded.rate_hz;
  const int frames =
      f.frames > 0
          ? f.frames
          : std::max(2, static_cast<int>(std::ceil((ScriptEnd(loaded) + 1.0 - f.start_s) / dt)));

  tracking::StaticScene static_scene;
  for (const sim::SceneCamera& c : loaded.cameras) static_scene.cameras.push_back(c.model);
  for (const sim::Solid& s : loaded.obstacles) static_scene.solids.push_back(s.geometry);
  tracking::TrackerOptions options;
  options.voxel_m = f.voxel_m;
  options.filter.num_particles = f.particles;
  const auto build_start = std::chrono::steady_clock::now();
  tracking::Tracker tracker(options, loaded.bounds, static_scene);
  const double build_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - build_start)
          .count();

  // As the daemon: a coarse pass stops at the tracking voxel's level.
  const int key_level = pipeline::TrackingKeyLevel(loaded.bounds, f.depth, f.voxel_m);
  SceneEngine engine(std::move(loaded), {.depth = f.depth,
                                         .threads = f.threads,
                                         .coarse_first_depth = f.coarse_first_depth,
                                         .key_level = key_level});
  const sim::Scene& s = engine.scene();
  std::vector<Vector3d> distractors;
  for (const sim::Solid& o : s.foreground_objects) {
    const common::Box3 box = sim::Bounds(o.geometry);
    distractors.push_back(0.5 * (box.min + box.max));
  }
  const std::size_t num_foreground = distractors.size();

  tracking::ClearMot mot(tracking::ClearMotOptions{f.threshold_m});
  pipeline::OccupancySnapshot snapshot;
  pipeline::PublishedGrid grid(f.publish_depth);
  std::vector<double> track_ms, track_cpu_ms, per_person_ms, per_person_cpu_ms, octree_ms,
      unknown_voxels;
  std::vector<PersonStats> people(s.people.size());
  std::vector<FrameRecord> records;
  std::vector<tracking::MotPoint> objects, hypotheses;
  std::vector<int> object_person;
  std::vector<Vector3d> object_half;  // Body-box half-extents, for the trace.
  int max_tracks = 0;
  int aborted = 0, untracked = 0;
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> trace(nullptr, &std::fclose);
  if (!f.trace.empty()) {
    trace.reset(std::fopen(f.trace.c_str(), "w"));
    if (!trace) throw common::ConfigError(f.trace + ": cannot write the trace");
    std::fputs("frame,time_s,kind,id,name,x,y,z,half_x,half_y,half_z,matched_id,distance_m\n",
               trace.get());
  }
  for (int frame = 0; frame < frames; ++frame) {
    const double t = f.start_s + frame * dt;
    const FrameTimes times = engine.Step(t, {}, f.deadline_ms);
    if (frame > 0) octree_ms.push_back(times.octree.update_ms);
    aborted += times.octree.aborted;
    // As the pipeline publishes it.
    grid.Fill(engine.tree(), &snapshot);
    snapshot.bounds = s.bounds;
    snapshot.depth = f.publish_depth;
    snapshot.sequence = static_cast<std::uint64_t>(frame);
    snapshot.stamp_ns = static_cast<std::int64_t>(std::llround(t * 1e9));
    snapshot.complete = !times.octree.aborted;
    snapshot.refined_cell_m = pipeline::RefinedCellSize(s.bounds, times.octree.refined_level);
    const auto root_levels = engine.tree().RootLevels();
    snapshot.root_levels.assign(root_levels.begin(), root_levels.end());

    const double cpu0 = ThreadCpuMs();
    const auto wall0 = std::chrono::steady_clock::now();
    // As the daemon does: an update that left regions unrefined is not tracked
    // (the tracks stay as they were, and are scored so).
    const bool tracked = pipeline::RefinedForTracking(snapshot, f.voxel_m);
    if (tracked) {
      tracker.Update(snapshot);
    } else {
      ++untracked;
    }
    const double wall =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - wall0).count();
    const double cpu = ThreadCpuMs() - cpu0;
    if (tracked) {  // Times of tracker cycles only.
      track_ms.push_back(wall);
      track_cpu_ms.push_back(cpu);
    }

    FrameRecord record;
    record.t_s = t;
    objects.clear();
    object_person.clear();
    object_half.clear();
    // People whose centre is outside the cell (entering, leaving) are not
    // scored: a track on them is neither a match nor a false positive.
    distractors.resize(num_foreground);
    for (std::size_t i = 0; i < s.people.size(); ++i) {
      const sim::BodyState body = sim::EvaluatePerson(s.people[i], t);
      if (!s.bounds.Contains(body.centre_W)) {
        distractors.push_back(body.centre_W);
        continue;
      }
      objects.push_back({static_cast<std::uint32_t>(i + 1), body.centre_W});
      object_person.push_back(static_cast<int>(i));
      if (trace) {
        const common::Box3 box = sim::BodyBox(body);
        object_half.push_back(0.5 * (box.max - box.min));
      }
      record.people.emplace_back(static_cast<int>(i), body.centre_W);
      ++people[i].frames;
    }
    if (tracked && !objects.empty()) {
      per_person_ms.push_back(wall / static_cast<double>(objects.size()));
      per_person_cpu_ms.push_back(cpu / static_cast<double>(objects.size()));
    }
    unknown_voxels.push_back(static_cast<double>(tracker.voxel_map().unknown_voxels().size()));
    hypotheses.clear();
    for (const tracking::Track& tr : tracker.tracks()) {
      if (!s.bounds.Contains(tr.centre_W)) continue;  // Scored inside the cell only.
      hypotheses.push_back({tr.id, tr.centre_W});
      record.tracks.emplace_back(tr.id, tr.centre_W);
    }
    max_tracks = std::max(max_tracks, static_cast<int>(hypotheses.size()));
    const tracking::MotFrame& m = mot.AddFrame(objects, hypotheses, distractors);
    if (trace)
      WriteTraceFrame(frame, t, s, objects, object_person, object_half, m, tracker, trace.get());
    for (std::size_t k = 0; k < objects.size(); ++k) {
      const int person = object_person[k];
      const tracking::MotMatch* match = MatchOf(m, objects[k].id);
      if (match == nullptr) {
        ++people[person].misses;
        record.missed.push_back(person);
        continue;
      }
      ++people[person].matches;
      people[person].distance_sum_m += match->distance_m;
      if (match->mismatch) {
        ++people[person].switches;
        record.switched.push_back(person);
      }
    }
    for (const tracking::MotPoint& h : hypotheses) {
      const bool matched = std::any_of(m.matches.begin(), m.matches.end(),
                                       [&](const auto& x) { return x.hypothesis_id == h.id; });
      const bool ignored = std::any_of(distractors.begin(), distractors.end(), [&](const auto& d) {
        return (d - h.position_W).norm() <= f.threshold_m;
      });
      if (!matched && !ignored) record.false_positives.push_back(h.id);
    }
    if (!f.plot.empty()) records.push_back(std::move(record));
  }

  const tracking::MotTotals& tot = mot.totals();
  const tracking::TrackerStats& ts = tracker.stats();
  const FrameStats wall = Summarise(track_ms), cpu = Summarise(track_cpu_ms),
                   person = Summarise(per_person_ms), person_cpu = Summarise(per_person_cpu_ms),
                   oct = Summarise(octree_ms);
  const double mota = tot.Mota(), motp = tot.Motp();
  auto number = [](double x, const char* format) {
    if (!std::isfinite(x)) return std::string("null");
    char buf[32];
    std::snprintf(buf, sizeof(buf), format, x);
    return std::string(buf);
  };
  if (f.json) {
    std::printf(
        "{\"scene\": %s, \"frames\": %d, \"rate_hz\": %.3f, \"start_s\": %.3f, \"depth\": %d, "
        "\"publish_depth\": %d, \"voxel_m\": %.3f, \"particles\": %d, \"threshold_m\": %.3f,\n"
        " \"mota\": %s, \"motp_m\": %s, \"id_switches\": %lld, \"misses\": %lld, "
        "\"false_positives\": %lld, \"ignored\": %lld, \"objects\": %lld, \"matches\": %lld,\n"
        " \"births\": %llu, \"deaths\": %llu, \"reacquisitions\": %llu, \"object_tracks\": %llu, "
        "\"max_tracks\": %d, \"aborted_updates\": %d, \"untracked_frames\": %d,\n"
        " \"tracking_ms\": {\"mean\": %.4f, \"median\": %.4f, \"p99\": %.4f, \"max\": %.4f},\n"
        " \"tracking_cpu_ms\": {\"mean\": %.4f, \"p99\": %.4f},\n"
        " \"tracking_ms_per_person\": {\"mean\": %.4f, \"p99\": %.4f},\n"
        " \"tracking_cpu_ms_per_person\": {\"mean\": %.4f, \"p99\": %.4f},\n"
        " \"unknown_voxels_mean\": %.0f,\n"
        " \"tracker_build_ms\": %.1f, \"octree_ms\": {\"median\": %.3f, \"p99\": %.3f},\n"
        " \"people\": [",
        common::JsonString(s.name).c_str(), frames, s.rate_hz, f.start_s, f.depth, f.publish_depth,
        tracker.voxel_map().grid().voxel_m(), f.particles, f.threshold_m,
        number(mota, "%.5f").c_str(), number(motp, "%.5f").c_str(),
        static_cast<long long>(tot.mismatches), static_cast<long long>(tot.misses),
        static_cast<long long>(tot.false_positives), static_cast<long long>(tot.ignored),
        static_cast<long long>(tot.objects), static_cast<long long>(tot.matches),
        static_cast<unsigned long long>(ts.births), static_cast<unsigned long long>(ts.deaths),
        static_cast<unsigned long long>(ts.reacquisitions),
        static_cast<unsigned long long>(ts.object_births), max_tracks, aborted, untracked,
        Mean(track_ms), wall.median, wall.p99, wall.max, Mean(track_cpu_ms), cpu.p99,
        Mean(per_person_ms), person.p99, Mean(per_person_cpu_ms), person_cpu.p99,
        Mean(unknown_voxels), build_ms, oct.median, oct.p99);
    for (std::size_t i = 0; i < people.size(); ++i) {
      const PersonStats& p = people[i];
      std::printf(
          "%s{\"name\": %s, \"frames\": %lld, \"misses\": %lld, \"id_switches\": %lld, "
          "\"mean_distance_m\": %s}",
          i == 0 ? "" : ", ", common::JsonString(s.people[i].name).c_str(),
          static_cast<long long>(p.frames), static_cast<long long>(p.misses),
          static_cast<long long>(p.switches),
          number(p.matches > 0 ? p.distance_sum_m / static_cast<double>(p.matches) : NAN, "%.4f")
              .c_str());
    }
    std::printf("]}\n");
  } else {
    std::printf(
        "hullguard track-eval: scene %s, %d frames at %.1f Hz from %.2f s, octree depth %d "
        "(published at %d), tracking voxels %.3f m, %d particles per person\n",
        s.name.c_str(), frames, s.rate_hz, f.start_s, f.depth, f.publish_depth,
        tracker.voxel_map().grid().voxel_m(), f.particles);
    std::printf(
        "  MOTA %s  MOTP %s m  ID switches %lld  misses %lld  false positives %lld  "
        "(ground-truth objects %lld, match threshold %.2f m)\n",
        number(mota, "%.4f").c_str(), number(motp, "%.4f").c_str(),
        static_cast<long long>(tot.mismatches), static_cast<long long>(tot.misses),
        static_cast<long long>(tot.false_positives), static_cast<long long>(tot.objects),
        f.threshold_m);
    if (aborted > 0) {
      std::printf("  octree updates aborted by the deadline: %d; frames not tracked: %d\n", aborted,
                  untracked);
    }
    if (tot.ignored > 0) {
      std::printf("  tracks on foreground objects or people outside the cell (not scored): %lld\n",
                  static_cast<long long>(tot.ignored));
    }
    std::printf(
        "  tracks: %llu born, %llu died, %llu re-acquired, at most %d at once; %llu object "
        "tracks (not people, not published)\n",
        static_cast<unsigned long long>(ts.births), static_cast<unsigned long long>(ts.deaths),
        static_cast<unsigned long long>(ts.reacquisitions), max_tracks,
        static_cast<unsigned long long>(ts.object_births));
    std::printf(
        "  tracking time per frame (one thread): wall mean %.3f ms, p99 %.3f ms, max %.3f ms; "
        "CPU mean %.3f ms, p99 %.3f ms\n",
        Mean(track_ms), wall.p99, wall.max, Mean(track_cpu_ms), cpu.p99);
    std::printf(
        "  per person: wall mean %.3f ms, p99 %.3f ms; CPU mean %.3f ms, p99 %.3f ms "
        "(%.0f UNKNOWN voxels per frame)\n",
        Mean(per_person_ms), person.p99, Mean(per_person_cpu_ms), person_cpu.p99,
        Mean(unknown_voxels));
    std::printf("  octree update median %.2f ms, p99 %.2f ms; tracker start-up %.0f ms\n",
                oct.median, oct.p99, build_ms);
    for (std::size_t i = 0; i < people.size(); ++i) {
      const PersonStats& p = people[i];
      std::printf(
          "  %-12s %5lld frames, %4lld missed, %2lld switches, mean distance %s m\n",
          s.people[i].name.c_str(), static_cast<long long>(p.frames),
          static_cast<long long>(p.misses), static_cast<long long>(p.switches),
          number(p.matches > 0 ? p.distance_sum_m / static_cast<double>(p.matches) : NAN, "%.3f")
              .c_str());
    }
  }
  if (!f.plot.empty()) {
    char title[256];
    std::snprintf(title, sizeof(title),
                  "%s: MOTA %s, MOTP %s m, %lld id switches, %lld misses, %lld false positives",
                  s.name.c_str(), number(mota, "%.3f").c_str(), number(motp, "%.3f").c_str(),
                  static_cast<long long>(tot.mismatches), static_cast<long long>(tot.misses),
                  static_cast<long long>(tot.false_positives));
    WritePlot(s, records, title, f.plot);
  }
  return kExitOk;
}

}  // namespace

void RegisterTrackEval(CLI::App& app, int* exit_code) {
  auto flags = std::make_shared<TrackEvalFlags>();
  CLI::App* cmd = app.add_subcommand(
      "track-eval",
      "Track the people of a simulated scene on its reconstruction; CLEAR MOT metrics");
  cmd->add_option("--scene", flags->scene, "Scene YAML (docs/scenes.md)")->required();
  cmd->add_option("--frames", flags->frames,
                  "Frames to run (default: until every script has ended, plus 1 s)")
      ->check(hg::cli::Range(2, 1000000));
  cmd->add_option("--start", flags->start_s, "Scene time of the first frame (s)")
      ->check(hg::cli::kNonNegative)
      ->check(hg::cli::kFinite);
  cmd->add_option("--depth", flags->depth, "Octree depth")->check(hg::cli::Range(3, 12));
  cmd->add_option("--publish-depth", flags->publish_depth,
                  "Depth of the published occupancy grid the tracker reads")
      ->check(hg::cli::Range(3, 10));
  cmd->add_option("--threads", flags->threads, "Octree worker threads (the tracker uses one)")
      ->check(hg::cli::Range(1, 64));
  cmd->add_option("--threshold", flags->threshold_m,
                  "CLEAR MOT match threshold between track and body centre (m)")
      ->check(hg::cli::kPositive)
      ->check(hg::cli::kFinite);
  cmd->add_option("--deadline-ms", flags->deadline_ms,
                  "Abort each octree update this long after it starts, as the daemon does "
                  "(0: none); updates left unrefined are not tracked")
      ->check(hg::cli::kNonNegative)
      ->check(hg::cli::kFinite);
  cmd->add_option("--coarse-first", flags->coarse_first_depth,
                  "octree.coarse_first_depth (0: off; docs/reconstruction.md)")
      ->check(hg::cli::Range(0, 16));
  cmd->add_option("--particles", flags->particles, "Particles per person")
      ->check(hg::cli::Range(1, 100000));
  cmd->add_option("--voxel", flags->voxel_m, "Tracking voxel edge (m)")
      ->check(hg::cli::Range(0.01, 0.5))
      ->check(hg::cli::kFinite);
  cmd->add_flag("--json", flags->json, "Print one JSON object");
  cmd->add_option("--plot", flags->plot,
                  "Write a PNG: top view of truth and tracks over the run, heights over time");
  cmd->add_option("--trace", flags->trace,
                  "Write a CSV: per frame each person's true centre, matched track and distance, "
                  "and each track's centre and half-axes");
  cmd->callback([flags, exit_code] { *exit_code = RunTrackEval(*flags); });
}

}  // namespace hg::tools
