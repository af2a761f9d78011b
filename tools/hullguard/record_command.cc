// `hullguard record`: every camera of a daemon config recorded losslessly, with
// capture stamps, into a recording folder (format: docs/cameras.md,
// "Recording and replaying").
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "app/config.h"
#include "app/pipeline_setup.h"
#include "capture/recording.h"
#include "common/cli_checks.h"
#include "common/config_error.h"
#include "hullguard/commands.h"

namespace hg::tools {
namespace {

namespace fs = std::filesystem;

struct RecordFlags {
  std::string config;
  std::string out;
  double seconds = 0.0;  // 0: until SIGINT or SIGTERM.
  int queue = 64;
  int writers = 0;  // 0: one per camera, at most the hardware threads.
  std::string format = "auto";
};

std::atomic<bool> g_stop{false};

void OnSignal(int /*signal*/) { g_stop.store(true); }

/// Frames of one camera on their way from its capture thread to a writer: a
/// bounded ring of frames whose buffers are reused, so that after each slot's
/// first frame nothing is allocated. Thread-safe for one producer and one
/// consumer.
class FrameQueue {
 public:
  struct Item {
    capture::Frame frame;
    std::uint64_t number = 0;  // The recorder's count of frames the camera delivered.
  };

  explicit FrameQueue(std::size_t capacity) : items_(capacity) {}

  /// The slot to fill next, or nullptr when the queue is full. Producer only.
  Item* Back() {
    const std::uint64_t tail = tail_.load(std::memory_order_relaxed);
    if (tail - head_.load(std::memory_order_acquire) == items_.size()) return nullptr;
    return &items_[tail % items_.size()];
  }
  void Push() { tail_.store(tail_.load(std::memory_order_relaxed) + 1, std::memory_order_release); }

  /// The oldest filled slot, or nullptr when empty. Consumer only.
  Item* Front() {
    const std::uint64_t head = head_.load(std::memory_order_relaxed);
    if (head == tail_.load(std::memory_order_acquire)) return nullptr;
    return &items_[head % items_.size()];
  }
  void Pop() { head_.store(head_.load(std::memory_order_relaxed) + 1, std::memory_order_release); }

 private:
  std::vector<Item> items_;
  std::atomic<std::uint64_t> head_{0};
  std::atomic<std::uint64_t> tail_{0};
};

int RunRecord(const RecordFlags& f) {
  const app::Config config = app::LoadConfig(f.config);
  if (fs::exists(fs::path(f.out) / "manifest.yaml")) {
    throw common::ConfigError(f.out + ": already holds a recording (manifest.yaml)");
  }
  std::vector<pipeline::PipelineCamera> cameras =
      app::MakeCameras(config, capture::SimClock::Now());
  // No background model learns here: the simulated colour cameras show their
  // people after their empty period alone (a replay's models learn from the
  // recording's first frames, which hold the empty cell).
  for (pipeline::PipelineCamera& c : cameras) c.source->BackgroundLearned();
  std::vector<geometry::CameraModel> models;
  for (const pipeline::PipelineCamera& c : cameras) models.push_back(c.model);
  const capture::ImageFormat format = f.format == "png"   ? capture::ImageFormat::kPng
                                      : f.format == "pnm" ? capture::ImageFormat::kPnm
                                                          : capture::ImageFormat::kAuto;
  capture::RecordingWriter writer(f.out, models, "hullguard record",
                                  "config " + fs::absolute(f.config).string(), format);
  // The config it was recorded with, for reference (its relative paths point
  // next to the original).
  std::error_code ec;
  fs::copy_file(f.config, fs::path(f.out) / "config.yaml", fs::copy_options::overwrite_existing,
                ec);

  const int n = static_cast<int>(cameras.size());
  std::vector<std::unique_ptr<FrameQueue>> queues;
  for (int c = 0; c < n; ++c) {
    queues.push_back(std::make_unique<FrameQueue>(static_cast<std::size_t>(f.queue)));
  }
  std::vector<std::atomic<std::uint64_t>> queue_full(static_cast<std::size_t>(n));
  std::vector<std::atomic<std::uint64_t>> delivered(static_cast<std::size_t>(n));
  std::atomic<bool> capture_stop{false};
  std::atomic<bool> capture_done{false};

  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  const auto start = std::chrono::steady_clock::now();

  // A capture thread per camera: the source fills a queue slot directly; with
  // the queue full it fills a scratch frame, which is counted and dropped (the
  // camera delivers its frames whether the writer keeps up or not).
  std::vector<std::thread> capture_threads;
  for (int c = 0; c < n; ++c) {
    capture_threads.emplace_back([&, c] {
      capture::CameraSource& source = *cameras[c].source;
      FrameQueue& queue = *queues[c];
      capture::Frame scratch;
      while (!capture_stop.load(std::memory_order_relaxed)) {
        FrameQueue::Item* slot = queue.Back();
        if (!source.Next(slot != nullptr ? &slot->frame : &scratch,
                         std::chrono::milliseconds(100))) {
          continue;
        }
        const std::uint64_t number = delivered[c].fetch_add(1, std::memory_order_relaxed);
        if (slot == nullptr) {
          queue_full[c].fetch_add(1, std::memory_order_relaxed);
          continue;
        }
        slot->number = number;
        queue.Push();
      }
    });
  }

  // Writers: camera c goes to writer c % writers, so that each camera's frames
  // are written in order by one thread.
  const int hardware = std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  const int writers = std::max(1, f.writers > 0 ? std::min(f.writers, n) : std::min(n, hardware));
  std::vector<std::thread> writer_threads;
  for (int w = 0; w < writers; ++w) {
    writer_threads.emplace_back([&, w] {
      for (;;) {
        // Read before draining: frames pushed before the capture threads
        // ended are then drained by this pass at the latest.
        const bool last_pass = capture_done.load(std::memory_order_acquire);
        bool any = false;
        for (int c = w; c < n; c += writers) {
          while (FrameQueue::Item* item = queues[c]->Front()) {
            writer.Write(c, item->number, item->frame);
            queues[c]->Pop();
            any = true;
          }
        }
        if (last_pass) break;
        if (!any) std::this_thread::sleep_for(std::chrono::milliseconds(2));
      }
    });
  }

  const std::string until =
      f.seconds > 0 ? std::to_string(f.seconds) + " s" : "until SIGINT or SIGTERM";
  std::fprintf(stderr, "hullguard record: %d cameras -> %s (%s)\n", n, f.out.c_str(),
               until.c_str());
  while (!g_stop.load()) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    if (f.seconds > 0 &&
        std::chrono::steady_clock::now() - start >= std::chrono::duration<double>(f.seconds)) {
      break;
    }
  }
  const double recorded_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  capture_stop.store(true);
  for (pipeline::PipelineCamera& c : cameras) c.source->Stop();
  for (std::thread& t : capture_threads) t.join();
  capture_done.store(true, std::memory_order_release);
  for (std::thread& t : writer_threads) t.join();
  for (int c = 0; c < n; ++c) {
    const std::uint64_t full = queue_full[c].load();
    if (full > 0) writer.CountLost(c, capture::FrameLoss::kQueueFull, full);
  }
  std::string finish_error;
  const bool finished = writer.Finish(&finish_error);

  std::printf("hullguard record: %d cameras, %.2f s -> %s\n", n, recorded_s, f.out.c_str());
  std::uint64_t lost = 0;
  bool empty_camera = false;
  for (int c = 0; c < n; ++c) {
    const capture::RecordingCameraStats& s = writer.stats(c);
    std::printf("  %s: %llu frames kept, %llu lost (queue full %llu, write errors %llu)",
                models[c].name.c_str(), static_cast<unsigned long long>(s.kept),
                static_cast<unsigned long long>(s.lost()),
                static_cast<unsigned long long>(s.queue_full),
                static_cast<unsigned long long>(s.write_errors));
    if (const std::uint64_t corrupt = cameras[c].source->corrupt_frames(); corrupt > 0) {
      std::printf(", %llu corrupt at the source", static_cast<unsigned long long>(corrupt));
    }
    std::printf("\n");
    if (!s.last_error.empty()) std::printf("    last write error: %s\n", s.last_error.c_str());
    lost += s.lost();
    empty_camera = empty_camera || s.kept == 0;
  }
  if (!finished) {
    std::fprintf(stderr, "hullguard record: %s\n", finish_error.c_str());
    return kExitFailure;
  }
  if (lost > 0 || empty_camera) {
    std::fprintf(stderr, "hullguard record: %llu frames could not be kept%s\n",
                 static_cast<unsigned long long>(lost),
                 empty_camera ? "; a camera delivered no frame" : "");
    return kExitFailure;
  }
  return kExitOk;
}

}  // namespace

void RegisterRecord(CLI::App& app, int* exit_code) {
  auto flags = std::make_shared<RecordFlags>();
  CLI::App* cmd = app.add_subcommand(
      "record", "Record every camera of a config losslessly, with capture stamps");
  cmd->add_option("--config", flags->config, "Daemon config (its cameras and their sources)")
      ->required()
      ->check(CLI::ExistingFile);
  cmd->add_option("--out", flags->out, "Recording folder to create (docs/cameras.md)")->required();
  cmd->add_option("--seconds", flags->seconds, "Stop after this long (0: at SIGINT or SIGTERM)")
      ->check(hg::cli::kNonNegative)
      ->check(hg::cli::kFinite);
  cmd->add_option("--queue", flags->queue,
                  "Frames buffered per camera between capture and writing; a frame arriving "
                  "with the queue full is lost and counted")
      ->check(hg::cli::Range(1, 100000));
  cmd->add_option("--format", flags->format,
                  "Frame files: png (small, slow for camera images), pnm (PGM/PPM, disk speed) "
                  "or auto (png for masks, pnm for camera images)")
      ->check(CLI::IsMember({"auto", "png", "pnm"}));
  cmd->add_option("--writers", flags->writers,
                  "Writer (PNG encoding) threads; 0: one per camera, at most one per core")
      ->check(hg::cli::Range(0, 256));
  cmd->callback([flags, exit_code] {
    try {
      *exit_code = RunRecord(*flags);
    } catch (const common::ConfigError& e) {
      std::fprintf(stderr, "hullguard record: %s\n", e.what());
      *exit_code = kExitBadInput;
    }
  });
}

}  // namespace hg::tools
