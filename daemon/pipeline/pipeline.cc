#include "pipeline/pipeline.h"

#include <pthread.h>
#include <sched.h>

#include <algorithm>
#include <array>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstring>
#include <exception>
#include <filesystem>
#include <string>
#include <thread>

#include "common/log.h"
#include "octree/camera_view.h"
#include "pipeline/black_box.h"
#include "pipeline/cycle_phase.h"

namespace hg::pipeline {
namespace {

using SteadyClock = std::chrono::steady_clock;

std::int64_t RealtimeNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

double MsSince(SteadyClock::time_point t) {
  return std::chrono::duration<double, std::milli>(SteadyClock::now() - t).count();
}

/// A kept background's camera: its name, size, intrinsics, distortion and
/// pose, rounded (1e-3 px, 1e-6 for the rest) so that the last bits of a
/// pose computed from a look-at point do not matter. FNV-1a.
std::uint64_t CalibrationId(const geometry::CameraModel& m) {
  std::uint64_t hash = 0xcbf29ce484222325ULL;
  const auto add = [&hash](const void* data, std::size_t size) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (std::size_t i = 0; i < size; ++i) hash = (hash ^ p[i]) * 0x100000001b3ULL;
  };
  const auto add_rounded = [&add](double v, double scale) {
    const long long q = std::llround(v * scale);
    add(&q, sizeof(q));
  };
  add(m.name.data(), m.name.size());
  add(&m.width, sizeof(m.width));
  add(&m.height, sizeof(m.height));
  for (int i = 0; i < 9; ++i) add_rounded(m.K(i / 3, i % 3), 1e3);
  for (const double d : m.distortion) add_rounded(d, 1e6);
  for (int i = 0; i < 9; ++i) add_rounded(m.R_CW(i / 3, i % 3), 1e6);
  for (int i = 0; i < 3; ++i) add_rounded(m.t_CW[i], 1e6);
  return hash;
}

// The means of a learned background model as a frame of `kind` (kRgb or
// kMono): the view it was taught in. Allocates.
capture::Frame BackgroundFrame(const silhouette::BackgroundModel& model, capture::FrameKind kind) {
  capture::Frame frame;
  frame.kind = kind;
  const int w = model.width(), h = model.height();
  const bool rgb = kind == capture::FrameKind::kRgb;
  if (rgb) {
    frame.rgb = common::ImageRgb8(w, h);
  } else {
    frame.grey = common::ImageU8(w, h);
  }
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      for (int k = 0; k < (rgb ? 3 : 1); ++k) {
        const auto mean = static_cast<std::uint8_t>(std::lround(model.MeanAt(u, v, k)));
        (rgb ? frame.rgb.Pixel(u, v)[k] : frame.grey.At(u, v)) = mean;
      }
    }
  }
  return frame;
}

}  // namespace

Pipeline::CameraRuntime::CameraRuntime(geometry::CameraModel m,
                                       std::unique_ptr<capture::CameraSource> s, int timeout)
    : model(std::move(m)),
      source(std::move(s)),
      timeout_ms(timeout),
      quadtree(model.width, model.height),
      calibration_id(CalibrationId(model)) {}

Pipeline::Pipeline(const PipelineOptions& options, std::vector<PipelineCamera> cameras,
                   const std::vector<geometry::TriangleMesh>& obstacles, Consumer consumer,
                   common::Heartbeats* heartbeats)
    : options_(options), consumer_(std::move(consumer)), heartbeats_(heartbeats) {
  options_.publish_depth = std::clamp(options_.publish_depth, 1, std::min(options_.depth, 10));
  // Background models are made on a camera's first image frame, on its capture
  // thread; bad options must fail here, at start-up, instead.
  silhouette::ValidateBackgroundModelOptions(options_.background);
  std::vector<octree::CameraView> views;
  for (PipelineCamera& c : cameras) {
    auto runtime = std::make_unique<CameraRuntime>(c.model, std::move(c.source), c.timeout_ms);
    runtime->bayer_mosaic = c.bayer_mosaic;
    // A shift of the view that is not found as a move stays within half of
    // what the foreground dilation covers; the other half is for colours.
    capture::CameraHealthOptions health;
    health.max_shift_px = std::max(1.0, 0.5 * options_.background_dilate_px);
    runtime->health_monitor = capture::CameraHealthMonitor(health);
    if (c.model.HasDistortion()) {
      runtime->undistorter = std::make_unique<silhouette::ConservativeUndistorter>(c.model);
    }
    views.emplace_back(c.model.Pinhole(), obstacles);
    if (views.back().depth_map().blocked) {
      // It could still show foreground (never free anything): seeing nothing
      // is as conservative, and the status says what is wrong.
      runtime->blocked = true;
      log::Error("camera '{}' {}", c.model.name, geometry::ObstacleDepthMap::kBlockedText);
    }
    if (heartbeats_ != nullptr) {
      runtime->heartbeat = heartbeats_->Register(std::string("capture ").append(c.model.name));
    }
    cameras_.push_back(std::move(runtime));
  }
  // Silhouette workers: one per camera, or N shared by all, waiting on one signal.
  const int num_cameras = static_cast<int>(cameras_.size());
  const bool shared = options_.silhouette_workers > 0;
  const int num_workers = shared ? options_.silhouette_workers : num_cameras;
  const int num_signals = shared ? 1 : num_cameras;
  signals_ = std::make_unique<std::atomic<std::uint32_t>[]>(static_cast<std::size_t>(num_signals));
  for (int c = 0; c < num_cameras; ++c) cameras_[c]->signal = &signals_[shared ? 0 : c];
  workers_.resize(static_cast<std::size_t>(num_workers));
  for (int w = 0; w < num_workers; ++w) {
    SilhouetteWorker& worker = workers_[w];
    worker.signal = &signals_[shared ? 0 : w];
    if (shared) {
      for (int c = 0; c < num_cameras; ++c) worker.cameras.push_back((w + c) % num_cameras);
    } else {
      worker.cameras.push_back(w);
    }
    if (heartbeats_ != nullptr) {
      worker.heartbeat = heartbeats_->Register(
          shared ? "silhouette " + std::to_string(w)
                 : std::string("silhouette ").append(cameras_[w]->model.name));
    }
  }
  if (heartbeats_ != nullptr) fusion_heartbeat_ = heartbeats_->Register("fusion");
  quadtree_ptrs_.resize(cameras_.size(), nullptr);
  margins_.resize(cameras_.size(), 0.0);
  octree::OctreeConfig tree_config{options_.bounds, options_.depth, options_.octree_threads,
                                   options_.boundary_coarsening};
  tree_config.coarse_first_depth = options_.coarse_first_depth;
  tree_config.key_level = options_.key_level;
  tree_config.max_nodes = options_.max_nodes;
  // Only the published grid is read from the tree (PublishedGrid): a cell of it
  // is settled once a leaf inside reads occupied.
  tree_config.settle_level = options_.publish_depth;
  tree_ = std::make_unique<octree::Octree>(tree_config, std::move(views));
  const std::size_t cells = std::size_t{1} << (3 * options_.publish_depth);
  grid_ = std::make_unique<PublishedGrid>(options_.publish_depth);
  published_cell_m3_ = options_.bounds.Size().prod() / static_cast<double>(cells);
  if (options_.knowledge_filter_m3 > 0.0) {
    const auto min_cells =
        static_cast<std::size_t>(std::ceil(options_.knowledge_filter_m3 / published_cell_m3_));
    blob_filter_ =
        std::make_unique<BlobFilter>(options_.publish_depth, std::max<std::size_t>(1, min_cells));
  }
  // The snapshots, made now with room for what a cycle writes into them, so
  // that cycles allocate nothing (FreeSnapshot). Runs along x: a row of n
  // published cells holds at most n / 2 runs of one kind; the reserve stops
  // at 2^20 runs (8 MiB, address space until the cells are there: publish
  // depths up to 7 never need more).
  const std::size_t n = std::size_t{1} << options_.publish_depth;
  const std::size_t runs = std::min<std::size_t>(n * n * ((n + 1) / 2), std::size_t{1} << 20);
  pool_.reserve(kSnapshotPool);
  for (int i = 0; i < kSnapshotPool; ++i) {
    auto snapshot = std::make_shared<OccupancySnapshot>();
    snapshot->health.cameras.resize(cameras_.size());
    for (std::size_t c = 0; c < cameras_.size(); ++c) {
      snapshot->health.cameras[c].name = cameras_[c]->model.name;
    }
    snapshot->root_levels.reserve(512);
    snapshot->occupied.reserve(runs);
    snapshot->occluded.reserve(runs);
    pool_.push_back(std::move(snapshot));
  }
}

Pipeline::~Pipeline() {
  Stop();
  // A source's destructor may wait up to its stop grace for its camera (a
  // dead GigE camera's release, capture::AravisSource::kReleaseGrace): the
  // sources go side by side, so that many dead cameras take as long as one.
  std::vector<std::thread> releases;
  releases.reserve(cameras_.size());
  for (auto& camera : cameras_) {
    if (camera->source) releases.emplace_back([&source = camera->source] { source.reset(); });
  }
  for (std::thread& t : releases) t.join();
}

void Pipeline::Start() {
  stop_.store(false);
  for (std::size_t c = 0; c < cameras_.size(); ++c) {
    threads_.emplace_back([this, c] { CaptureLoop(static_cast<int>(c)); });
  }
  for (std::size_t w = 0; w < workers_.size(); ++w) {
    threads_.emplace_back([this, w] { SilhouetteLoop(static_cast<int>(w)); });
  }
  threads_.emplace_back([this] { FusionLoop(); });
}

void Pipeline::Stop() {
  stop_.store(true);
  for (auto& camera : cameras_) {
    if (camera->source) camera->source->Stop();
  }
  // After stop_ (both sequentially consistent): a worker that read its
  // signal before this bump and stop_ as false waits on a stale value and
  // wakes (SilhouetteLoop).
  for (SilhouetteWorker& worker : workers_) {
    worker.signal->fetch_add(1);
    worker.signal->notify_all();
  }
  for (std::thread& t : threads_) {
    if (t.joinable()) t.join();
  }
  threads_.clear();
}

void Pipeline::CaptureLoop(int camera) {
  CameraRuntime& c = *cameras_[camera];
  bool told = false;  // That the source threw.
  while (!stop_.load(std::memory_order_relaxed)) {
    if (heartbeats_ != nullptr) heartbeats_->Beat(c.heartbeat);
    capture::Frame& frame = c.raw.BeginWrite();
    bool delivered = false;
    try {
      delivered = c.source->Next(&frame, std::chrono::milliseconds(50));
    } catch (const std::exception& e) {
      // A source is to count what it cannot read and go on; one that throws
      // (out of memory, a library's own error) loses that frame, not the
      // daemon: counted corrupt, said once, and the camera turns stale if it
      // goes on.
      c.corrupt.fetch_add(1, std::memory_order_relaxed);
      if (!told) {
        told = true;
        log::Error("{}: the camera source failed to deliver a frame: {}", c.model.name, e.what());
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    if (delivered) {
      if (black_box_ != nullptr) black_box_->Push(camera, frame);
      c.raw.Publish();
    }
    // Every loop, frame or not: a waiting worker wakes at least every 50 ms
    // to beat its heartbeat.
    c.signal->fetch_add(1, std::memory_order_release);
    c.signal->notify_all();
  }
}

bool Pipeline::TakeAndProcess(int camera) {
  CameraRuntime& c = *cameras_[camera];
  if (c.busy.exchange(true, std::memory_order_acquire)) return false;
  capture::Frame* frame = c.raw.TakeNewest();
  // The frame stays this worker's until its next take: a mask may be handed
  // over whole (the capture thread refills another buffer meanwhile).
  if (frame != nullptr) ProcessFrame(camera, *frame, &frame->grey);
  c.busy.store(false, std::memory_order_release);
  return frame != nullptr;
}

void Pipeline::SilhouetteLoop(int index) {
  const SilhouetteWorker& worker = workers_[index];
  while (!stop_.load(std::memory_order_relaxed)) {
    if (heartbeats_ != nullptr) heartbeats_->Beat(worker.heartbeat);
    // The signal before stop_, as Stop() writes them the other way round:
    // either this sees the stop, or the wait below sees Stop()'s bump.
    const std::uint32_t seen = worker.signal->load();
    if (stop_.load()) break;
    bool took = false;
    for (int camera : worker.cameras) took = TakeAndProcess(camera) || took;
    if (!took) worker.signal->wait(seen, std::memory_order_acquire);
  }
}

std::optional<bool> Pipeline::BackgroundSaved(int camera) const {
  const std::uint8_t saved = cameras_[camera]->background_saved.load(std::memory_order_acquire);
  if (saved == 0) return std::nullopt;
  return saved == 1;
}

bool Pipeline::HasBackgroundModel(int camera) const {
  return cameras_[camera]->has_model.load(std::memory_order_acquire);
}

std::optional<std::chrono::steady_clock::time_point> Pipeline::ForegroundHeavySince(
    int camera) const {
  const std::int64_t ns = cameras_[camera]->heavy_since_ns.load(std::memory_order_relaxed);
  if (ns < 0) return std::nullopt;
  return SteadyClock::time_point(
      std::chrono::duration_cast<SteadyClock::duration>(std::chrono::nanoseconds(ns)));
}

std::string Pipeline::BackgroundFile(int camera) const {
  return options_.background_dir + "/background-" + cameras_[camera]->model.name + ".bin";
}

void Pipeline::ProcessFrame(int camera, const capture::Frame& frame, common::ImageU8* spare) {
  CameraRuntime& c = *cameras_[camera];
  const common::ImageU8* mask = &frame.grey;
  // A buffer of ours holding the mask, which the slot may take over whole.
  common::ImageU8* swappable = spare;
  bool learning = false;  // The mask is the background model's learning one.
  if (frame.kind != capture::FrameKind::kMask) {
    if (c.unlearned) return;  // Stays failed: see below.
    const bool rgb = frame.kind == capture::FrameKind::kRgb;
    const int width = rgb ? frame.rgb.width : frame.grey.width;
    const int height = rgb ? frame.rgb.height : frame.grey.height;
    if (width != c.model.width || height != c.model.height) {
      c.corrupt.fetch_add(1, std::memory_order_relaxed);  // Not this camera's size.
      return;
    }
    // A frozen, black, saturated or moved camera certifies nothing: its
    // frames are dropped and fusion counts it as seeing nothing.
    const capture::CameraFault fault = c.health_monitor.Check(frame);
    c.fault.store(static_cast<std::uint8_t>(fault), std::memory_order_relaxed);
    c.misalignment_px.store(static_cast<float>(c.health_monitor.misalignment_px()),
                            std::memory_order_relaxed);
    c.shifted.store(c.health_monitor.shifted(), std::memory_order_relaxed);
    if (!c.reference_logged && c.health_monitor.has_reference()) {
      c.reference_logged = true;  // Once, when the reference view is taken.
      if (c.health_monitor.reference_edges() < capture::CameraHealthMonitor::kFewEdges) {
        log::Warn(
            "{}: its view has {} strong edges (a blank wall, or covered at start-up): a move of "
            "this camera cannot be found; aim it at some structure, or check its calibration "
            "by other means",
            c.model.name, c.health_monitor.reference_edges());
      } else if (c.health_monitor.reference_patches() < capture::ViewRegistration::kFewPatches) {
        log::Warn(
            "{}: its view has {} textured patches (a blank wall, or covered at start-up): a "
            "move of this camera by less than 8 pixels cannot be found; aim it at some "
            "structure, or check its calibration by other means",
            c.model.name, c.health_monitor.reference_patches());
      }
    }
    const capture::CameraHealthMonitor& m = c.health_monitor;
    if (c.taught_pending_told && !m.awaiting_taught_view()) {
      // What became of the registration against the taught view, told once.
      c.taught_pending_told = false;
      if (m.moved_since_taught()) {
        log::Error(
            "{}: its view is {:.1f} px off the view its kept background was taught in: the "
            "camera moved while hullguardd was stopped, so its calibration no longer holds; it "
            "sees nothing (failed, moved) until it is recalibrated and its background taught "
            "again",
            c.model.name, m.misalignment_px());
      } else {
        log::Info("{}: its view matches the view its background was taught in ({:.2f} px)",
                  c.model.name, m.misalignment_px());
      }
    }
    if (m.shifted_frames() == 0) {
      c.unmatched_told = false;
    } else if (!c.unmatched_told && m.shifted_frames() >= kUnmatchedPatienceFrames) {
      c.unmatched_told = true;  // Once per spell.
      if (m.awaiting_taught_view()) {
        log::Warn(
            "{}: after {} frames its view still cannot be matched to the view its kept "
            "background was taught in (too little of it found: people in front of the camera, "
            "the cell rearranged, or the camera moved further than 12 px); its frames are not "
            "used until it is. If the camera was moved, recalibrate it and teach its background "
            "again",
            c.model.name, m.shifted_frames());
      } else if (m.misalignment_px() >= 0.0) {
        log::Warn(
            "{}: for {} frames its view has been {:.1f} px off its reference view; its frames "
            "are not used until it is back in place",
            c.model.name, m.shifted_frames(), m.misalignment_px());
      } else {
        log::Warn(
            "{}: for {} frames its view has not been found where it was (moved by more than 12 "
            "px, or covered, or too dark to tell); its frames are not used until it is. If the "
            "camera was moved, recalibrate it",
            c.model.name, m.shifted_frames());
      }
    }
    if (fault != capture::CameraFault::kNone) return;
    // A repeat of the last frame is not a new view: dropped, so the camera's
    // age keeps growing (dilation, then stale at its timeout) until frozen.
    // So is a view found shifted, until it is found back in place or moved:
    // the frames from before the shift stay true to the calibration.
    if (c.health_monitor.repeated() || c.health_monitor.shifted()) return;
    using Start = PipelineOptions::BackgroundStart;
    if (!c.background) {
      // Warm-up, the camera's first frame: the model, and its saved background.
      silhouette::BackgroundModelOptions model_options = options_.background;
      if (c.bayer_mosaic) model_options.texture_threshold = 0;
      c.background = std::make_unique<silhouette::BackgroundModel>(c.model.width, c.model.height,
                                                                   model_options);
      c.has_model.store(true, std::memory_order_release);
      const std::string file = BackgroundFile(camera);
      std::string error;
      // Only a kept background of the frames' format (RGB or grey) is taken up.
      const int channels = frame.kind == capture::FrameKind::kRgb ? 3 : 1;
      const bool taken_up = options_.background_start != Start::kRelearn &&
                            !options_.background_dir.empty() &&
                            c.background->Load(file, &error, channels, c.calibration_id);
      if (options_.background_start == Start::kRelearn) {
        log::Info("{}: learning the background afresh, to be kept in {}", c.model.name, file);
      } else if (taken_up) {
        log::Info("{}: background taken up from {}", c.model.name, file);
        // The kept background is the view as taught (after calibration): a
        // camera moved while the daemon was stopped no longer matches it.
        c.health_monitor.SetTaughtView(BackgroundFrame(*c.background, frame.kind));
        c.taught_pending_told = c.health_monitor.awaiting_taught_view();
      } else if (options_.background_start == Start::kKeptOnly) {
        c.unlearned = true;
        log::Error(
            "{}: no background to take up ({}); background.learn_at_start is off, so this camera "
            "sees nothing until one is taught: stop the service, empty the cell, run "
            "`hullguardd --config FILE --learn-background`",
            c.model.name, error);
      } else {
        log::Info("{}: learning the background ({})", c.model.name,
                  options_.background_dir.empty() ? "no background.keep_dir" : error);
      }
    }
    // Frames wait until the view is found to match the taught one.
    if (c.health_monitor.awaiting_taught_view()) return;
    if (c.unlearned) {
      // Sees nothing (failed), as a faulty camera: nothing it shows was learned.
      c.fault.store(static_cast<std::uint8_t>(capture::CameraFault::kUnlearned),
                    std::memory_order_relaxed);
      return;
    }
    const bool was_learning = c.background->learning();
    learning = was_learning;
    if (frame.kind == capture::FrameKind::kRgb) {
      c.background->Apply(frame.rgb, &c.foreground);
    } else {
      c.background->Apply(frame.grey, &c.foreground);
    }
    if (c.source && !c.background->learning()) c.source->BackgroundLearned();
    if (!c.background->learning()) {
      if (c.background->foreground_fraction() < kHeavyForegroundShare) {
        c.heavy_since_ns.store(-1, std::memory_order_relaxed);
      } else if (c.heavy_since_ns.load(std::memory_order_relaxed) < 0) {
        c.heavy_since_ns.store(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                   SteadyClock::now().time_since_epoch())
                                   .count(),
                               std::memory_order_relaxed);
      }
    }
    if (was_learning && !c.background->learning() && !options_.background_dir.empty()) {
      // Once per learning, at the end of warm-up; the folder is made if missing.
      std::string error;
      std::error_code ec;
      std::filesystem::create_directories(options_.background_dir, ec);
      const std::string file = BackgroundFile(camera);
      const bool saved = c.background->Save(file, &error, c.calibration_id);
      if (saved) {
        log::Info("{}: background learned, saved to {}", c.model.name, file);
      } else {
        log::Warn("{}: background learned, not saved: {}", c.model.name, error);
      }
      c.background_saved.store(saved ? 1 : 2, std::memory_order_release);
    }
    // A (2 r + 1)^2 square, without allocating once the scratch has grown.
    silhouette::DilateSquare(&c.foreground, options_.background_dilate_px, &c.dilate_scratch,
                             c.background->foreground_tiles());
    // A learning mask is all foreground: nothing to fill.
    if (options_.background_fill_holes && !learning) {
      silhouette::FillEnclosedBackground(&c.foreground, &c.hole_scratch);
    }
    mask = &c.foreground;
    // Written whole by the next frame's Apply(): any buffer of its size will do.
    swappable = &c.foreground;
  }
  if (mask->width != c.model.width || mask->height != c.model.height) {
    c.corrupt.fetch_add(1, std::memory_order_relaxed);  // Not this camera's size.
    return;
  }
  Slot& slot = c.slot.BeginWrite();
  if (c.undistorter) {
    c.undistorter->Apply(mask->View(), 127, &slot.mask);
  } else if (mask == swappable) {
    // Swapped, not copied: the source, or the background model, refills the
    // slot's previous buffer.
    std::swap(slot.mask, *swappable);
  } else {
    slot.mask.width = mask->width;
    slot.mask.height = mask->height;
    slot.mask.pixels.assign(mask->pixels.begin(), mask->pixels.end());
  }
  slot.stamp_ns = frame.stamp_ns;
  slot.ready = SteadyClock::now();
  slot.learning = learning;
  c.slot.Publish();
  c.frames.fetch_add(1, std::memory_order_relaxed);
}

std::shared_ptr<OccupancySnapshot> Pipeline::FreeSnapshot() {
  // use_count() == 1: only the pool holds it (no consumer, not the latest).
  for (const auto& s : pool_) {
    if (s.use_count() == 1) {
      // use_count() is a relaxed load: the fence orders the consumers' last
      // reads (before their release of the reference) before our rewrite.
      std::atomic_thread_fence(std::memory_order_acquire);
      return s;
    }
  }
  // More holders than kSnapshotPool counts (readers of Latest() keeping
  // theirs): one more, which allocates.
  pool_.push_back(std::make_shared<OccupancySnapshot>());
  return pool_.back();
}

void Pipeline::FusionLoop() {
  if (options_.fusion_realtime_priority > 0) {
    sched_param param{};
    param.sched_priority = options_.fusion_realtime_priority;
    const int error = pthread_setschedparam(pthread_self(), SCHED_FIFO, &param);
    if (error != 0) {
      log::Warn("fusion thread: SCHED_FIFO priority {} refused ({}); running unprioritised",
                options_.fusion_realtime_priority, std::strerror(error));
    } else {
      log::Info("fusion thread: SCHED_FIFO priority {}", options_.fusion_realtime_priority);
    }
  }
  const auto period = std::chrono::nanoseconds(static_cast<std::int64_t>(1e9 / options_.rate_hz));
  SteadyClock::time_point next = SteadyClock::now();
  SteadyClock::time_point last_second = next;
  CyclePhaseOptions phase_options;
  phase_options.margin = std::chrono::nanoseconds(
      static_cast<std::int64_t>(std::max(0.0, options_.align_margin_ms) * 1e6));
  CyclePhase phase(period, phase_options);
  std::array<CyclePhase::Duration, CyclePhase::kMaxCameras> ready_before_start{};
  while (!stop_.load(std::memory_order_relaxed)) {
    if (heartbeats_ != nullptr) heartbeats_->Beat(fusion_heartbeat_);
    // In slices, so that Stop() ends the wait within one slice at any rate
    // (a period of a second would otherwise hold it up that long), and no
    // cycle runs after it (its cameras stopped, it would publish them stale).
    // The heartbeat beats every slice: at 1 Hz a beat per cycle is as slow as
    // the watchdog's checks, and jitter left some checks without one.
    constexpr auto kStopSlice = std::chrono::milliseconds(20);
    for (SteadyClock::time_point now = SteadyClock::now();
         now < next && !stop_.load(std::memory_order_relaxed); now = SteadyClock::now()) {
      std::this_thread::sleep_until(std::min(next, now + kStopSlice));
      if (heartbeats_ != nullptr) heartbeats_->Beat(fusion_heartbeat_);
    }
    if (stop_.load(std::memory_order_relaxed)) break;
    next += period;
    const SteadyClock::time_point cycle_start = SteadyClock::now();
    if (next < cycle_start) {
      // Fell behind: skip the periods already past, never burst.
      missed_cycles_ += static_cast<std::uint64_t>((cycle_start - next) / period) + 1;
      next = cycle_start + period;
    }
    const bool new_second = cycle_start - last_second >= std::chrono::seconds(1);
    const double elapsed_s = std::chrono::duration<double>(cycle_start - last_second).count();
    if (new_second) last_second = cycle_start;
    // Raised margins are held once the cycle is locked to the frames (or
    // when it is not asked to lock); before, they follow each cycle's need.
    hold_margins_ = !options_.align_to_frames || phase.locked();
    octree::UpdateControl control;
    control.deadline = cycle_start + std::chrono::microseconds(
                                         static_cast<std::int64_t>(options_.deadline_ms * 1e3));
    std::shared_ptr<OccupancySnapshot> snapshot =
        RunCycle(RealtimeNs(), control, new_second ? elapsed_s : 0.0, cycle_start);
    snapshot->health.cycle_ms = MsSince(cycle_start);
    snapshot->health.phase_lock = options_.align_to_frames;
    snapshot->health.phase_locked = options_.align_to_frames && phase.locked();
    latest_.Store(snapshot);
    if (consumer_) consumer_(snapshot);
    if (options_.align_to_frames) {
      std::size_t n = 0;
      for (std::size_t i = 0; i < cameras_.size() && n < ready_before_start.size(); ++i) {
        if (quadtree_ptrs_[i] == nullptr) continue;  // Delivers nothing this cycle.
        ready_before_start[n++] = cycle_start - cameras_[i]->last_ready;
      }
      next += phase.Update(std::span(ready_before_start.data(), n));
    }
  }
}

std::shared_ptr<const OccupancySnapshot> Pipeline::Step(std::int64_t now_ns) {
  std::shared_ptr<OccupancySnapshot> snapshot = RunCycle(now_ns, octree::UpdateControl{}, 0.0);
  latest_.Store(snapshot);
  return snapshot;
}

std::shared_ptr<OccupancySnapshot> Pipeline::RunCycle(
    std::int64_t now_ns, const octree::UpdateControl& control, double fps_window_s,
    std::optional<SteadyClock::time_point> received_by) {
  const bool new_second = fps_window_s > 0.0;
  std::shared_ptr<OccupancySnapshot> snapshot = FreeSnapshot();
  PipelineHealth& health = snapshot->health;
  health.cameras.resize(cameras_.size());
  health.degraded = false;
  health.silhouette_ms = 0.0;
  // Pass 1: newest frames, and which cameras are live.
  std::int64_t newest_stamp = 0;
  for (std::size_t i = 0; i < cameras_.size(); ++i) {
    CameraRuntime& c = *cameras_[i];
    if (const Slot* slot = c.slot.TakeNewest()) {
      c.current = slot;
      c.fresh = true;
      c.last_stamp_ns = slot->stamp_ns;
      c.last_ready = slot->ready;
      if (!c.seen) c.first_stamp_ns = slot->stamp_ns;
      c.seen = true;
    }
    const double age_ms = c.seen ? (now_ns - c.last_stamp_ns) * 1e-6 : 0.0;
    const std::uint8_t fault = c.blocked ? static_cast<std::uint8_t>(capture::CameraFault::kBlocked)
                                         : c.fault.load(std::memory_order_relaxed);
    const bool received_lately =
        !received_by || *received_by - c.last_ready <= std::chrono::milliseconds(c.timeout_ms);
    const bool live = c.seen && age_ms <= c.timeout_ms && received_lately && fault == 0;
    if (live) newest_stamp = std::max(newest_stamp, c.last_stamp_ns);
    quadtree_ptrs_[i] = live ? &c.quadtree : nullptr;
    const std::uint64_t frames = c.frames.load(std::memory_order_relaxed);
    if (new_second) {
      c.fps = static_cast<double>(frames - c.frames_at_last_second) / fps_window_s;
      c.frames_at_last_second = frames;
      c.fps_windowed = true;
    } else if (!c.fps_windowed && c.seen && frames > 1 && c.last_stamp_ns > c.first_stamp_ns) {
      // Before the first whole second (the first health lines, READY=1's
      // STATUS=): the rate over the frames so far, rather than 0.
      c.fps = static_cast<double>(frames - 1) /
              (static_cast<double>(c.last_stamp_ns - c.first_stamp_ns) * 1e-9);
    }
    // Nothing arrived within the last second: its rate over the last second is
    // 0 now, not at the end of the window (a camera that stopped showed its
    // old rate beside `stale` for up to a second).
    if (c.seen && received_by && *received_by - c.last_ready > std::chrono::seconds(1)) {
      c.fps = 0.0;
    }
    CameraHealth& h = health.cameras[i];
    if (h.name != c.model.name) h.name = c.model.name;
    const bool source_failing = c.source != nullptr && c.source->failing();
    h.state = live                           ? CameraState::kOk
              : fault != 0 || source_failing ? CameraState::kFailed
              : c.seen                       ? CameraState::kStale
                                             : CameraState::kStarting;
    h.fault = fault;
    h.misalignment_px = c.misalignment_px.load(std::memory_order_relaxed);
    h.shifted = fault == 0 && c.shifted.load(std::memory_order_relaxed);
    h.learning = c.current != nullptr && c.current->learning;
    h.fps = c.fps;
    h.frame_age_ms = age_ms;
    h.frames = frames;
    h.drops = c.raw.drops() + c.slot.drops();
    h.corrupt =
        c.corrupt.load(std::memory_order_relaxed) + (c.source ? c.source->corrupt_frames() : 0);
    const capture::TransportStats transport =
        c.source ? c.source->transport_stats() : capture::TransportStats{};
    h.completed = transport.completed;
    h.failed = transport.failed;
    h.underruns = transport.underruns;
    h.resends = transport.resends;
    health.degraded = health.degraded || !live;
  }
  // Pass 2: the instant the snapshot holds for (the newest capture time, or
  // the median of the live cameras', PipelineOptions::stamp_at_median), then
  // per camera its quadtree and its margin for the gap between its frame's
  // capture and that instant (PipelineOptions::max_speed_mps).
  std::int64_t stamp = newest_stamp;
  std::array<std::int64_t, common::kMaxCameras> stamps{};
  std::size_t num_live = 0;
  for (std::size_t i = 0; i < cameras_.size() && options_.stamp_at_median; ++i) {
    if (quadtree_ptrs_[i] != nullptr) stamps[num_live++] = cameras_[i]->last_stamp_ns;
  }
  if (num_live > 0) {
    const auto middle = stamps.begin() + static_cast<std::ptrdiff_t>((num_live - 1) / 2);
    std::nth_element(stamps.begin(), middle,
                     stamps.begin() + static_cast<std::ptrdiff_t>(num_live));
    stamp = *middle;
  }
  std::int64_t oldest_used = newest_stamp;
  health.margin_skew_ms = 0.0;
  for (std::size_t i = 0; i < cameras_.size(); ++i) {
    CameraRuntime& c = *cameras_[i];
    const bool live = quadtree_ptrs_[i] != nullptr;
    if (live) {
      const double needed =
          options_.max_speed_mps * static_cast<double>(std::llabs(stamp - c.last_stamp_ns)) * 1e-9;
      const double margin = octree::Octree::RoundMargin(needed);
      // Up at once; down only once the hold has passed (each change makes
      // the octree recompute the camera everywhere).
      if (margin >= c.margin_m || now_ns >= c.margin_held_until_ns || !hold_margins_) {
        c.margin_m = margin;
        c.margin_held_until_ns = now_ns + kMarginHoldNs;
      }
      // What the margin stands for (rounded up): the gap it covers.
      if (options_.max_speed_mps > 0.0) {
        health.margin_skew_ms =
            std::max(health.margin_skew_ms, c.margin_m / options_.max_speed_mps * 1e3);
      }
      if (c.fresh) {
        c.quadtree.Build(c.current->mask.View(), 127);
        health.silhouette_ms =
            std::max(health.silhouette_ms, (RealtimeNs() - c.last_stamp_ns) * 1e-6);
        c.fresh = false;
      }
      oldest_used = std::min(oldest_used, c.last_stamp_ns);
    }
    margins_[i] = c.margin_m;  // Kept while the camera is out: no recomputation for it.
    health.cameras[i].margin_m = live ? c.margin_m : 0.0;
    // A camera that comes back was absent from the octree's view: every
    // region is new to it.
    if (live && !c.was_live) c.quadtree.MarkAllChanged();
    c.was_live = live;
  }
  health.skew_ms = (newest_stamp - oldest_used) * 1e-6;

  const octree::UpdateStats stats = tree_->Update(quadtree_ptrs_, control, margins_);
  deadline_misses_ += stats.aborted;
  grid_->Fill(*tree_, snapshot.get());
  health.knowledge_filter = blob_filter_ != nullptr;
  health.filtered_blobs = 0;
  health.filtered_m3 = 0.0;
  if (blob_filter_) {
    const BlobFilterStats dropped = blob_filter_->Apply(&snapshot->occupied, snapshot->occluded);
    health.filtered_blobs = dropped.dropped_components;
    health.filtered_m3 = static_cast<double>(dropped.dropped_cells) * published_cell_m3_;
  }
  snapshot->sequence = ++sequence_;
  snapshot->stamp_ns = stamp != 0 ? stamp : now_ns;
  // Complete: refined to the finest cell everywhere, which a full node store
  // (nodes left unsplit, occupied) also prevents.
  snapshot->complete = !stats.aborted && stats.nodes_unsplit == 0;
  snapshot->aborted = stats.aborted;
  snapshot->refined_cell_m = RefinedCellSize(options_.bounds, stats.refined_level);
  static_assert(kRootsPerAxis * kRootsPerAxis * kRootsPerAxis == octree::Octree::kNumRoots);
  const std::span<const std::uint8_t> root_levels = tree_->RootLevels();
  snapshot->root_levels.assign(root_levels.begin(), root_levels.end());  // Capacity kept.
  snapshot->bounds = options_.bounds;
  snapshot->depth = options_.publish_depth;
  // Nodes the full store could not split read occupied: conservative, but
  // coarser than asked.
  health.unsplit_nodes = stats.nodes_unsplit;
  health.degraded = health.degraded || stats.aborted || stats.nodes_unsplit > 0;
  health.octree_ms = stats.update_ms;
  health.deadline_misses = deadline_misses_;
  health.cycles = sequence_;
  health.missed_cycles = missed_cycles_;
  return snapshot;
}

}  // namespace hg::pipeline
