#pragma once
/// @file
/// The black box: the last seconds of every camera's frames kept in memory,
/// written out as a recording (docs/cameras.md, "Recording and replaying")
/// when the status turns degraded or on request (SIGUSR1).

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "capture/camera_source.h"
#include "geometry/camera.h"

namespace hg::pipeline {

/// What the black box keeps of one camera: its calibration (copied into every
/// dump), the largest frame kind it delivers and the rate its ring is sized for.
struct BlackBoxCamera {
  geometry::CameraModel model;
  capture::FrameKind kind = capture::FrameKind::kRgb;  ///< Slots hold frames this large.
  double rate_hz = 30.0;                               ///< Frames per second expected.
};

struct BlackBoxDump;

/// Memory of a black box per byte of its rings: the rings, the copy of the
/// dump being written and the copy of the next one, taken meanwhile.
inline constexpr double kBlackBoxMemoryFactor = 3.0;

struct BlackBoxOptions {
  double seconds = 10.0;  ///< History per camera (s); > 0.
  std::string directory;  ///< Requested dumps go to directory/<UTC time>/.
  /// Refuse more memory than this (MiB): the rings plus the copies of them
  /// of two dumps in flight, three times the rings
  /// (kBlackBoxMemoryFactor). 0 = no limit.
  double max_memory_mb = 0.0;
  bool low_priority = true;  ///< Encode requested dumps at nice 19.
  /// Called on the writer thread after each requested dump (logging).
  std::function<void(const BlackBoxDump&)> on_dump;
};

/// Slots of one camera's ring: enough for `seconds` at `rate_hz`, plus one
/// for the frame being written.
[[nodiscard]] std::size_t BlackBoxSlots(double seconds, double rate_hz);
/// Bytes of one slot's pixels for a camera (rounded up to whole 8-byte words).
[[nodiscard]] std::size_t BlackBoxSlotBytes(int width, int height, capture::FrameKind kind);
/// Bytes of all the rings for these cameras (pixels; the dump's copy is as
/// much again).
[[nodiscard]] std::size_t BlackBoxBytes(const std::vector<BlackBoxCamera>& cameras, double seconds);

/// What one dump wrote.
struct BlackBoxDump {
  std::string directory;      ///< The recording folder; empty when none was written.
  std::string reason;         ///< Why it was taken ("SIGUSR1", "degraded", ...).
  std::uint64_t frames = 0;   ///< Frames written, all cameras.
  std::uint64_t torn = 0;     ///< Slots overwritten while being copied, skipped.
  std::uint64_t failed = 0;   ///< Frames that could not be written.
  std::int64_t first_ns = 0;  ///< Stamp of the oldest frame written (CLOCK_REALTIME).
  std::int64_t last_ns = 0;   ///< Stamp of the newest frame written.
  std::string error;          ///< Why the folder could not be written, if so.
};

/// Per camera a ring of preallocated frame slots that the capture thread
/// fills; on request the rings are copied and written out as a recording.
///
/// Push() is the capture thread's only cost: a copy into the next slot and an
/// atomic publish, without lock, allocation or I/O. A dump first copies the
/// rings slot by slot while capture goes on; each slot carries a sequence
/// number (a seqlock: odd while being written), so a slot overwritten during
/// its copy is detected, skipped and counted as torn instead of being written
/// as a mixture of two frames. The copy runs on a thread of normal priority,
/// at memory speed, so that it outruns the capture threads and at most the
/// oldest frames are lost; the PNG encoding and the writing, seconds of CPU,
/// run afterwards on a second thread at nice 19, below the pipeline. While
/// one dump is written the next is still copied when asked for: a camera
/// lost during a long dump is kept at the moment it is lost, not after the
/// first dump is written and the ring has moved on. Two dumps are in flight
/// at most (one written, one copied and waiting).
///
/// When to dump on the status turning from ok to degraded: at most once per
/// `min_interval` (the ring's length: a flapping status would otherwise write
/// the same frames again and again). A turn sooner than that after the last
/// dump is dumped once the interval is over: that dump and the last one
/// together hold every frame from the last one's start on, the turn among
/// them. So one brief turn (a missed deadline) cannot hide a camera lost a
/// moment later. A turn while the black box takes no request (two dumps in
/// flight) waits for it.
/// Thread-compatible: one thread (the daemon's main loop) calls it.
class DegradedDumpTrigger {
 public:
  using Clock = std::chrono::steady_clock;
  explicit DegradedDumpTrigger(Clock::duration min_interval) : min_interval_(min_interval) {}

  /// A new cycle's status. The first cycles (cameras starting) are not turns.
  void Observe(bool degraded) {
    if (degraded && was_ok_) due_ = true;
    was_ok_ = !degraded;
  }
  /// Whether a dump is due now and allowed (the black box accepting a
  /// request, the interval past).
  [[nodiscard]] bool ShouldDump(Clock::time_point now, bool accepting) const {
    return due_ && accepting && (!dumped_ || now - last_ >= min_interval_);
  }
  /// A turn not dumped yet (at shutdown: the last chance, interval or not).
  [[nodiscard]] bool due() const { return due_; }
  /// The dump ShouldDump() asked for was started at `now`.
  void Dumped(Clock::time_point now) {
    due_ = false;
    dumped_ = true;
    last_ = now;
  }

 private:
  Clock::duration min_interval_;
  bool was_ok_ = false;
  bool due_ = false;
  bool dumped_ = false;
  Clock::time_point last_{};
};

/// Thread safety: Push(camera, ...) from one thread per camera (its capture
/// thread); RequestDump(), accepting(), busy(), LastDump(), WaitIdle() and the counters
/// from any thread; DumpTo() from one thread at a time (tests, tools).
class BlackBox {
 public:
  /// Allocates and touches every ring (the memory is resident before the
  /// first frame) and starts the copy and encoder threads.
  /// @throws common::ConfigError when the rings need more than max_memory_mb.
  BlackBox(BlackBoxOptions options, std::vector<BlackBoxCamera> cameras);
  /// Finishes a requested dump (one already asked for is still written),
  /// then stops the threads.
  ~BlackBox();
  BlackBox(const BlackBox&) = delete;
  BlackBox& operator=(const BlackBox&) = delete;

  /// Capture thread of `camera` only. Copies `frame` into the camera's next
  /// slot. A frame larger than the slot (another kind or size than the
  /// camera's) is not kept and is counted in oversized().
  void Push(int camera, const capture::Frame& frame);

  /// Asks for a dump into options.directory/<UTC time>/: the rings are
  /// copied at once, also while an earlier dump is still written. False (and
  /// counted in refused_requests()) while not accepting().
  bool RequestDump(const std::string& reason);

  /// Copies the rings and writes them into `directory` (created) on the
  /// calling thread. For tests and tools; the daemon uses RequestDump().
  BlackBoxDump DumpTo(const std::string& directory, const std::string& reason);

  /// True while RequestDump() would take a request: none is pending or
  /// being copied, and no copied dump waits for the one being written.
  [[nodiscard]] bool accepting() const;
  /// True while a requested dump is pending, copied or written.
  [[nodiscard]] bool busy() const;
  /// Blocks until no dump is requested or running.
  void WaitIdle();
  /// The last finished dump, if any.
  [[nodiscard]] std::optional<BlackBoxDump> LastDump() const;

  [[nodiscard]] std::size_t bytes() const { return bytes_; }
  [[nodiscard]] std::size_t slots(int camera) const { return rings_[camera]->capacity; }
  [[nodiscard]] std::uint64_t pushed(int camera) const {
    return rings_[camera]->head.load(std::memory_order_relaxed);
  }
  [[nodiscard]] std::uint64_t oversized(int camera) const {
    return rings_[camera]->oversized.load(std::memory_order_relaxed);
  }
  [[nodiscard]] std::uint64_t dumps() const { return dumps_.load(std::memory_order_relaxed); }
  /// Requested dumps whose rings have been copied (written or not yet).
  [[nodiscard]] std::uint64_t copies() const { return copies_.load(std::memory_order_relaxed); }
  [[nodiscard]] std::uint64_t refused_requests() const {
    return refused_.load(std::memory_order_relaxed);
  }

 private:
  /// One frame's slot. The metadata and the pixels are written with relaxed
  /// atomics between two updates of `sequence` (seqlock), which keeps the
  /// concurrent copy free of data races in the C++ memory model.
  struct Slot {
    std::atomic<std::uint64_t> sequence{0};  // Odd while being written.
    std::atomic<std::uint64_t> number{0};    // Push count of the frame held.
    std::atomic<std::int64_t> stamp_ns{0};
    std::atomic<std::int64_t> device_stamp_ns{-1};  // The camera's own clock; -1: none.
    std::atomic<std::uint64_t> index{0};
    std::atomic<std::uint32_t> kind{0};
    std::atomic<std::int32_t> width{0};
    std::atomic<std::int32_t> height{0};
    std::uint64_t* words = nullptr;  // slot_words of the ring's pixel block.
  };
  struct Ring {
    BlackBoxCamera camera;
    std::size_t capacity = 0;
    std::size_t slot_words = 0;
    std::unique_ptr<Slot[]> slots;
    std::unique_ptr<std::uint64_t[]> pixels;
    std::atomic<std::uint64_t> head{0};  // Frames pushed; written by the capture thread.
    std::atomic<std::uint64_t> oversized{0};
  };
  /// A frame copied out of a ring.
  struct Copied {
    int camera = 0;
    std::uint64_t number = 0;
    capture::Frame frame;
  };

  /// A dump between its copy and its writing.
  struct Job {
    std::string directory;
    std::string reason;
    std::vector<Copied> frames;
    std::vector<std::uint64_t> torn;  // Per camera.
  };

  void CopierLoop();
  void EncoderLoop();
  /// Copies every consistent slot of every ring; counts torn ones per camera.
  std::vector<Copied> CopyRings(std::vector<std::uint64_t>* torn) const;
  /// Writes a copied dump as a recording, freeing each frame once written.
  BlackBoxDump Write(Job* job);
  [[nodiscard]] bool AcceptingLocked() const;  // mutex_ held.
  [[nodiscard]] bool BusyLocked() const;       // mutex_ held.
  /// Reads one slot; false when it changed while being read or does not hold
  /// frame `number`.
  bool ReadSlot(const Ring& ring, std::uint64_t number, Copied* out) const;

  BlackBoxOptions options_;
  std::vector<std::unique_ptr<Ring>> rings_;
  std::size_t bytes_ = 0;

  mutable std::mutex mutex_;
  std::condition_variable wake_;    // The copier: a request or the stop.
  std::condition_variable encode_;  // The encoder: a job or the copier's end.
  std::condition_variable idle_;
  std::optional<std::string> request_;  // Reason of the pending request.
  bool copying_ = false;                // The copier copies the rings.
  std::optional<Job> job_;              // Copied, waiting for the encoder.
  bool encoding_ = false;               // The encoder writes a dump.
  bool stop_ = false;
  bool copier_done_ = false;
  std::optional<BlackBoxDump> last_;
  std::atomic<std::uint64_t> dumps_{0};
  std::atomic<std::uint64_t> copies_{0};
  std::atomic<std::uint64_t> refused_{0};
  std::thread copier_;
  std::thread encoder_;
};

/// "20240501T120304.123Z": a dump folder's name for a CLOCK_REALTIME instant.
[[nodiscard]] std::string BlackBoxFolderName(std::int64_t realtime_ns);

}  // namespace hg::pipeline
