#include "pipeline/black_box.h"

#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <filesystem>

#include "capture/recording.h"
#include "common/config_error.h"

namespace hg::pipeline {
namespace {

namespace fs = std::filesystem;

constexpr double kMiB = 1024.0 * 1024.0;

std::int64_t RealtimeNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

std::size_t Words(std::size_t bytes) { return (bytes + 7) / 8; }

}  // namespace

std::size_t BlackBoxSlots(double seconds, double rate_hz) {
  return static_cast<std::size_t>(std::ceil(std::max(0.0, seconds * rate_hz))) + 1;
}

std::size_t BlackBoxSlotBytes(int width, int height, capture::FrameKind kind) {
  return Words(static_cast<std::size_t>(std::max(width, 0)) * std::max(height, 0) *
               capture::BytesPerPixel(kind)) *
         8;
}

std::size_t BlackBoxBytes(const std::vector<BlackBoxCamera>& cameras, double seconds) {
  std::size_t total = 0;
  for (const BlackBoxCamera& c : cameras) {
    total += BlackBoxSlots(seconds, c.rate_hz) *
             BlackBoxSlotBytes(c.model.width, c.model.height, c.kind);
  }
  return total;
}

std::string BlackBoxFolderName(std::int64_t realtime_ns) {
  const std::time_t seconds = static_cast<std::time_t>(realtime_ns / 1'000'000'000);
  const int millis = static_cast<int>((realtime_ns / 1'000'000) % 1000);
  std::tm utc{};
  gmtime_r(&seconds, &utc);
  char text[32];
  const std::size_t n = std::strftime(text, sizeof(text), "%Y%m%dT%H%M%S", &utc);
  std::snprintf(text + n, sizeof(text) - n, ".%03dZ", millis);
  return text;
}

BlackBox::BlackBox(BlackBoxOptions options, std::vector<BlackBoxCamera> cameras)
    : options_(std::move(options)) {
  if (!(options_.seconds > 0.0)) {
    throw common::ConfigError("blackbox.seconds: must be > 0 for a black box");
  }
  const std::size_t ring_bytes = BlackBoxBytes(cameras, options_.seconds);
  if (options_.max_memory_mb > 0.0 &&
      kBlackBoxMemoryFactor * static_cast<double>(ring_bytes) > options_.max_memory_mb * kMiB) {
    std::string detail;
    for (const BlackBoxCamera& c : cameras) {
      char line[160];
      std::snprintf(line, sizeof(line), "%s%s %zu x %dx%d %s", detail.empty() ? "" : ", ",
                    c.model.name.c_str(), BlackBoxSlots(options_.seconds, c.rate_hz), c.model.width,
                    c.model.height, capture::ToString(c.kind));
      detail += line;
    }
    char message[256];
    std::snprintf(message, sizeof(message),
                  "blackbox: %.3g s of frames need %.0f MiB of rings, three times that with two "
                  "dumps' copies, more than max_memory_mb = %.0f (",
                  options_.seconds, static_cast<double>(ring_bytes) / kMiB, options_.max_memory_mb);
    throw common::ConfigError(message + detail + ")");
  }
  for (BlackBoxCamera& c : cameras) {
    auto ring = std::make_unique<Ring>();
    ring->capacity = BlackBoxSlots(options_.seconds, c.rate_hz);
    ring->slot_words = BlackBoxSlotBytes(c.model.width, c.model.height, c.kind) / 8;
    ring->camera = std::move(c);
    // Value-initialised: zeroed, so the pages are resident before capture.
    ring->pixels = std::make_unique<std::uint64_t[]>(ring->capacity * ring->slot_words);
    ring->slots = std::make_unique<Slot[]>(ring->capacity);
    for (std::size_t i = 0; i < ring->capacity; ++i) {
      ring->slots[i].words = ring->pixels.get() + i * ring->slot_words;
    }
    bytes_ += ring->capacity * ring->slot_words * 8;
    rings_.push_back(std::move(ring));
  }
  copier_ = std::thread([this] { CopierLoop(); });
  encoder_ = std::thread([this] { EncoderLoop(); });
}

BlackBox::~BlackBox() {
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  if (copier_.joinable()) copier_.join();
  if (encoder_.joinable()) encoder_.join();
}

void BlackBox::Push(int camera, const capture::Frame& frame) {
  Ring& r = *rings_[static_cast<std::size_t>(camera)];
  const bool rgb = frame.kind == capture::FrameKind::kRgb;
  const std::vector<std::uint8_t>& pixels = rgb ? frame.rgb.pixels : frame.grey.pixels;
  const int width = rgb ? frame.rgb.width : frame.grey.width;
  const int height = rgb ? frame.rgb.height : frame.grey.height;
  const std::size_t bytes = pixels.size();
  if (width < 1 || height < 1 ||
      bytes != static_cast<std::size_t>(width) * height * (rgb ? 3 : 1) ||
      Words(bytes) > r.slot_words) {
    r.oversized.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  const std::uint64_t number = r.head.load(std::memory_order_relaxed);
  Slot& s = r.slots[number % r.capacity];
  // Seqlock write: odd while the slot changes; the release fence keeps the
  // odd number ahead of every store of the frame.
  const std::uint64_t sequence = s.sequence.load(std::memory_order_relaxed);
  s.sequence.store(sequence + 1, std::memory_order_relaxed);
  std::atomic_thread_fence(std::memory_order_release);
  s.number.store(number, std::memory_order_relaxed);
  s.stamp_ns.store(frame.stamp_ns, std::memory_order_relaxed);
  s.device_stamp_ns.store(frame.device_stamp_ns, std::memory_order_relaxed);
  s.index.store(frame.index, std::memory_order_relaxed);
  s.kind.store(static_cast<std::uint32_t>(frame.kind), std::memory_order_relaxed);
  s.width.store(width, std::memory_order_relaxed);
  s.height.store(height, std::memory_order_relaxed);
  const std::uint8_t* src = pixels.data();
  const std::size_t full = bytes / 8;
  for (std::size_t i = 0; i < full; ++i) {
    std::uint64_t word;
    std::memcpy(&word, src + i * 8, 8);
    std::atomic_ref<std::uint64_t>(s.words[i]).store(word, std::memory_order_relaxed);
  }
  if (const std::size_t tail = bytes % 8; tail != 0) {
    std::uint64_t word = 0;
    std::memcpy(&word, src + full * 8, tail);
    std::atomic_ref<std::uint64_t>(s.words[full]).store(word, std::memory_order_relaxed);
  }
  s.sequence.store(sequence + 2, std::memory_order_release);
  r.head.store(number + 1, std::memory_order_release);
}

bool BlackBox::ReadSlot(const Ring& ring, std::uint64_t number, Copied* out) const {
  const Slot& s = ring.slots[number % ring.capacity];
  const std::uint64_t before = s.sequence.load(std::memory_order_acquire);
  if ((before & 1) != 0) return false;  // Being written.
  if (s.number.load(std::memory_order_relaxed) != number) return false;
  const auto kind = static_cast<capture::FrameKind>(s.kind.load(std::memory_order_relaxed));
  const int width = s.width.load(std::memory_order_relaxed);
  const int height = s.height.load(std::memory_order_relaxed);
  out->frame.stamp_ns = s.stamp_ns.load(std::memory_order_relaxed);
  out->frame.device_stamp_ns = s.device_stamp_ns.load(std::memory_order_relaxed);
  out->frame.index = s.index.load(std::memory_order_relaxed);
  // The fields may mix two frames if the slot changed meanwhile; they are
  // only trusted once the sequence is found unchanged below, but must not
  // lead the copy out of the slot before that.
  if (kind > capture::FrameKind::kRgb || width < 1 || height < 1) return false;
  const bool rgb = kind == capture::FrameKind::kRgb;
  const std::size_t bytes = static_cast<std::size_t>(width) * height * (rgb ? 3 : 1);
  if (Words(bytes) > ring.slot_words) return false;
  out->frame.kind = kind;
  common::ImageU8& grey = out->frame.grey;
  common::ImageRgb8& colour = out->frame.rgb;
  std::vector<std::uint8_t>& pixels = rgb ? colour.pixels : grey.pixels;
  (rgb ? colour.width : grey.width) = width;
  (rgb ? colour.height : grey.height) = height;
  pixels.resize(bytes);
  const std::size_t full = bytes / 8;
  for (std::size_t i = 0; i < full; ++i) {
    const std::uint64_t word =
        std::atomic_ref<std::uint64_t>(s.words[i]).load(std::memory_order_relaxed);
    std::memcpy(pixels.data() + i * 8, &word, 8);
  }
  if (const std::size_t tail = bytes % 8; tail != 0) {
    const std::uint64_t word =
        std::atomic_ref<std::uint64_t>(s.words[full]).load(std::memory_order_relaxed);
    std::memcpy(pixels.data() + full * 8, &word, tail);
  }
  std::atomic_thread_fence(std::memory_order_acquire);
  return s.sequence.load(std::memory_order_relaxed) == before;
}

std::vector<BlackBox::Copied> BlackBox::CopyRings(std::vector<std::uint64_t>* torn) const {
  std::vector<Copied> copied;
  torn->assign(rings_.size(), 0);
  // Oldest first: the capture thread overwrites the oldest slot next, and the
  // copy, at memory speed, soon leaves it behind.
  for (std::size_t c = 0; c < rings_.size(); ++c) {
    const Ring& r = *rings_[c];
    const std::uint64_t head = r.head.load(std::memory_order_acquire);
    const std::uint64_t first = head > r.capacity ? head - r.capacity : 0;
    for (std::uint64_t n = first; n < head; ++n) {
      Copied item;
      item.camera = static_cast<int>(c);
      item.number = n;
      if (ReadSlot(r, n, &item)) {
        copied.push_back(std::move(item));
      } else {
        ++(*torn)[c];
      }
    }
  }
  // Written in capture order across the cameras, not camera after camera: a
  // dump cut short (systemd's stop timeout) then holds every camera over the
  // span it got to, which replays, instead of whole cameras and none of the
  // others, which does not.
  std::stable_sort(copied.begin(), copied.end(), [](const Copied& a, const Copied& b) {
    return a.frame.stamp_ns < b.frame.stamp_ns;
  });
  return copied;
}

BlackBoxDump BlackBox::DumpTo(const std::string& directory, const std::string& reason) {
  Job job;
  job.directory = directory;
  job.reason = reason;
  job.frames = CopyRings(&job.torn);
  return Write(&job);
}

BlackBoxDump BlackBox::Write(Job* job_in) {
  Job& job = *job_in;
  BlackBoxDump dump;
  dump.reason = job.reason;
  for (std::uint64_t t : job.torn) dump.torn += t;
  std::vector<geometry::CameraModel> models;
  for (const auto& r : rings_) models.push_back(r->camera.model);
  try {
    capture::RecordingWriter writer(job.directory, std::move(models), "hullguardd black box",
                                    job.reason);
    dump.directory = job.directory;
    for (std::size_t c = 0; c < job.torn.size(); ++c) {
      if (job.torn[c] > 0) {
        writer.CountLost(static_cast<int>(c), capture::FrameLoss::kOverwritten, job.torn[c]);
      }
    }
    for (Copied& item : job.frames) {
      const bool written = writer.Write(item.camera, item.number, item.frame);
      // Each frame's pixels go once written: a dump copied meanwhile needs
      // the memory (BlackBoxOptions::max_memory_mb).
      std::vector<std::uint8_t>().swap(item.frame.grey.pixels);
      std::vector<std::uint8_t>().swap(item.frame.rgb.pixels);
      if (written) {
        ++dump.frames;
        const std::int64_t stamp = item.frame.stamp_ns;
        if (dump.frames == 1 || stamp < dump.first_ns) dump.first_ns = stamp;
        if (dump.frames == 1 || stamp > dump.last_ns) dump.last_ns = stamp;
      } else {
        ++dump.failed;
        dump.error = writer.stats(item.camera).last_error;
      }
    }
    std::string error;
    if (!writer.Finish(&error)) dump.error = error;
  } catch (const common::ConfigError& e) {
    dump.error = e.what();
    dump.failed = job.frames.size();
  }
  dumps_.fetch_add(1, std::memory_order_relaxed);
  return dump;
}

bool BlackBox::RequestDump(const std::string& reason) {
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    if (!AcceptingLocked()) {
      refused_.fetch_add(1, std::memory_order_relaxed);
      return false;
    }
    request_ = reason;
  }
  wake_.notify_one();
  return true;
}

bool BlackBox::AcceptingLocked() const { return !stop_ && !request_ && !copying_ && !job_; }

bool BlackBox::accepting() const {
  const std::lock_guard<std::mutex> lock(mutex_);
  return AcceptingLocked();
}

bool BlackBox::busy() const {
  const std::lock_guard<std::mutex> lock(mutex_);
  return BusyLocked();
}

bool BlackBox::BusyLocked() const { return request_ || copying_ || job_ || encoding_; }

void BlackBox::WaitIdle() {
  std::unique_lock<std::mutex> lock(mutex_);
  idle_.wait(lock, [this] { return !BusyLocked(); });
}

std::optional<BlackBoxDump> BlackBox::LastDump() const {
  const std::lock_guard<std::mutex> lock(mutex_);
  return last_;
}

void BlackBox::CopierLoop() {
  std::unique_lock<std::mutex> lock(mutex_);
  for (;;) {
    wake_.wait(lock, [this] { return stop_ || request_.has_value(); });
    // A request made before the stop is still served: the rings keep their
    // frames after capture has ended.
    if (!request_) break;
    Job job;
    job.reason = std::move(*request_);
    request_.reset();
    copying_ = true;
    lock.unlock();
    const std::int64_t now = RealtimeNs();
    fs::path folder = fs::path(options_.directory) / BlackBoxFolderName(now);
    std::error_code ec;
    for (int i = 1; fs::exists(folder, ec); ++i) {
      folder = fs::path(options_.directory) / (BlackBoxFolderName(now) + "-" + std::to_string(i));
    }
    job.directory = folder.string();
    job.frames = CopyRings(&job.torn);
    lock.lock();
    // A request is only taken while no copied dump waits (AcceptingLocked),
    // so the slot is free: at most one dump written and one waiting.
    job_ = std::move(job);
    copying_ = false;
    copies_.fetch_add(1, std::memory_order_relaxed);
    encode_.notify_one();
  }
  copier_done_ = true;
  encode_.notify_one();
}

void BlackBox::EncoderLoop() {
  if (options_.low_priority) {
    // Encoding a dump takes seconds of CPU; the capture, silhouette and
    // fusion threads come first. Linux applies nice to the calling thread.
    (void)setpriority(PRIO_PROCESS, static_cast<id_t>(syscall(SYS_gettid)), 19);
  }
  std::unique_lock<std::mutex> lock(mutex_);
  for (;;) {
    encode_.wait(lock, [this] { return job_.has_value() || copier_done_; });
    if (!job_) break;
    Job job = std::move(*job_);
    job_.reset();
    encoding_ = true;
    lock.unlock();
    BlackBoxDump dump = Write(&job);
    if (options_.on_dump) options_.on_dump(dump);
    lock.lock();
    last_ = std::move(dump);
    encoding_ = false;
    idle_.notify_all();
  }
}

}  // namespace hg::pipeline
