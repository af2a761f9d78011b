#include "capture/aravis_source.h"

#include <arpa/inet.h>
#include <arv.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <memory>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "common/log.h"

namespace hg::capture {
namespace {

using Clock = std::chrono::steady_clock;
using std::chrono::milliseconds;

constexpr milliseconds kMinBackoff{100};
constexpr milliseconds kMaxBackoff{2000};
// Next() polls the stream in slices this long so Stop() takes effect soon.
constexpr milliseconds kPollSlice{20};
// A failure message is repeated at most this often while it does not change.
constexpr std::chrono::seconds kRepeatLog{30};
// Broadcast discovery answers within about a second; sources opening together
// share one discovery run instead of each waiting for its own.
constexpr milliseconds kDiscoveryReuse{1500};
// A live camera answers a discovery command within milliseconds; the probe
// asks twice (a lost datagram) and gives up after this long.
constexpr milliseconds kProbeTimeout{500};
// The destructor waits at least this long for releases of cameras that
// answer (a few commands each), even when Stop() was called long before.
constexpr milliseconds kMinReleaseWait{250};

// Aravis' device list and interface objects are process globals without
// locking of their own: every source discovers and opens cameras under this.
std::mutex& AravisSystemMutex() {
  static std::mutex mutex;
  return mutex;
}

void Log(log::Level level, const std::string& device, const char* format, ...)
    __attribute__((format(printf, 3, 4)));
void Log(log::Level level, const std::string& device, const char* format, ...) {
  if (!log::Enabled(level)) return;
  char text[512];
  va_list args;
  va_start(args, format);
  std::vsnprintf(text, sizeof(text), format, args);
  va_end(args);
  log::Write(level, std::string("aravis[")
                        .append(device.empty() ? "first camera" : device)
                        .append("]: ")
                        .append(text));
}

// Takes the message out of a GError and frees it. True if there was one.
bool TakeError(GError** error, std::string* message, const char* what) {
  if (*error == nullptr) return false;
  if (message != nullptr) *message = std::string(what) + ": " + (*error)->message;
  g_clear_error(error);
  return true;
}

ArvPixelFormat ToArv(AravisOptions::Pixel pixel) {
  switch (pixel) {
    case AravisOptions::Pixel::kMono8:
      return ARV_PIXEL_FORMAT_MONO_8;
    case AravisOptions::Pixel::kBayerRG8:
      return ARV_PIXEL_FORMAT_BAYER_RG_8;
    case AravisOptions::Pixel::kBayerGB8:
      return ARV_PIXEL_FORMAT_BAYER_GB_8;
    case AravisOptions::Pixel::kBayerGR8:
      return ARV_PIXEL_FORMAT_BAYER_GR_8;
    case AravisOptions::Pixel::kBayerBG8:
      return ARV_PIXEL_FORMAT_BAYER_BG_8;
    case AravisOptions::Pixel::kRGB8:
      return ARV_PIXEL_FORMAT_RGB_8_PACKED;
  }
  return ARV_PIXEL_FORMAT_MONO_8;
}

// OpenCV names a Bayer pattern by the 2x2 block that starts at the second row
// and column, GenICam by the one at the origin: GenICam BayerRG is OpenCV's
// BayerBG (checked against known mosaics in the tests).
int OpenCvBayerCode(AravisOptions::Pixel pixel) {
  switch (pixel) {
    case AravisOptions::Pixel::kBayerRG8:
      return cv::COLOR_BayerBG2RGB;
    case AravisOptions::Pixel::kBayerGB8:
      return cv::COLOR_BayerGR2RGB;
    case AravisOptions::Pixel::kBayerGR8:
      return cv::COLOR_BayerGB2RGB;
    case AravisOptions::Pixel::kBayerBG8:
      return cv::COLOR_BayerRG2RGB;
    default:
      return -1;
  }
}

bool IsIpv4Address(const std::string& text) {
  in_addr address{};
  return inet_pton(AF_INET, text.c_str(), &address) == 1;
}

// Closes a socket when it goes out of scope.
class SocketFd {
 public:
  explicit SocketFd(int fd) : fd_(fd) {}
  ~SocketFd() {
    if (fd_ >= 0) close(fd_);
  }
  SocketFd(const SocketFd&) = delete;
  SocketFd& operator=(const SocketFd&) = delete;
  [[nodiscard]] int get() const { return fd_; }

 private:
  int fd_;
};

// Whether a GigE Vision device answers at `address` (dotted IPv4): one
// DISCOVERY_CMD to its control port, unicast, sent again halfway through
// kProbeTimeout. Aravis' own opening of an absent camera blocks 2.5 s, holding
// the process-wide lock and ignoring Stop(); this returns within the timeout,
// at once when the host reports the port unreachable, and within a poll slice
// of `stopped` being set. False with *error set when nothing answered.
bool ProbeGvcp(const std::string& address, const std::atomic<bool>& stopped, std::string* error) {
  constexpr std::uint16_t kGvcpPort = 3956;
  constexpr std::uint16_t kDiscoveryCmd = 0x0002;
  constexpr std::uint16_t kDiscoveryAck = 0x0003;
  SocketFd fd(socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0));
  if (fd.get() < 0) {
    *error = std::string("probe: socket: ") + std::strerror(errno);
    return false;
  }
  sockaddr_in peer{};
  peer.sin_family = AF_INET;
  peer.sin_port = htons(kGvcpPort);
  inet_pton(AF_INET, address.c_str(), &peer.sin_addr);
  // Connected: only the camera's answers arrive, and an ICMP "port
  // unreachable" shows as ECONNREFUSED.
  if (connect(fd.get(), reinterpret_cast<const sockaddr*>(&peer), sizeof(peer)) != 0) {
    *error = std::string("probe: ") + std::strerror(errno);
    return false;
  }
  static std::atomic<std::uint16_t> next_id{1};
  const std::uint16_t id = static_cast<std::uint16_t>(next_id.fetch_add(1) | 0x8000);
  // GVCP command header, big-endian: key 0x42, flags (0x01: acknowledge),
  // command, payload length 0, request id.
  const std::uint8_t command[8] = {0x42,
                                   0x01,
                                   static_cast<std::uint8_t>(kDiscoveryCmd >> 8),
                                   static_cast<std::uint8_t>(kDiscoveryCmd & 0xff),
                                   0x00,
                                   0x00,
                                   static_cast<std::uint8_t>(id >> 8),
                                   static_cast<std::uint8_t>(id & 0xff)};
  const Clock::time_point start = Clock::now();
  int sent = 0;
  std::uint8_t answer[600];
  for (;;) {
    const Clock::time_point now = Clock::now();
    if (stopped.load()) {
      *error = "stopped";
      return false;
    }
    if (now - start >= kProbeTimeout) break;
    if (sent == 0 || (sent == 1 && now - start >= kProbeTimeout / 2)) {
      if (send(fd.get(), command, sizeof(command), 0) < 0 && errno == ECONNREFUSED) break;
      ++sent;
    }
    pollfd p{fd.get(), POLLIN, 0};
    if (poll(&p, 1, static_cast<int>(kPollSlice.count())) <= 0) continue;
    const ssize_t n = recv(fd.get(), answer, sizeof(answer), 0);
    if (n < 0 && errno == ECONNREFUSED) break;
    if (n >= 8 && ((answer[2] << 8) | answer[3]) == kDiscoveryAck &&
        ((answer[6] << 8) | answer[7]) == id) {
      return true;
    }
  }
  *error = "no GigE Vision device answers at " + address;
  return false;
}

// The Aravis device id to open for `device`: an IPv4 address is opened as it
// is (unicast, no broadcast discovery needed); otherwise the discovered
// devices are matched by id, serial number, model, address or MAC.
bool ResolveDeviceId(const std::string& device, std::string* id, std::string* error) {
  if (IsIpv4Address(device)) {
    *id = device;
    return true;
  }
  static Clock::time_point last_discovery;
  static bool discovered = false;
  const Clock::time_point now = Clock::now();
  if (!discovered || now - last_discovery > kDiscoveryReuse) {
    arv_update_device_list();
    last_discovery = Clock::now();
    discovered = true;
  }
  const unsigned n = arv_get_n_devices();
  if (device.empty()) {
    if (n == 0) {
      *error = "no camera discovered";
      return false;
    }
    *id = arv_get_device_id(0);
    return true;
  }
  auto is = [&](const char* s) { return s != nullptr && device == s; };
  for (unsigned i = 0; i < n; ++i) {
    if (is(arv_get_device_id(i)) || is(arv_get_device_serial_nbr(i)) ||
        is(arv_get_device_model(i)) || is(arv_get_device_address(i)) ||
        is(arv_get_device_physical_id(i))) {
      *id = arv_get_device_id(i);
      return true;
    }
  }
  *error =
      "no camera with this serial, name or address among the " + std::to_string(n) + " discovered";
  return false;
}

// Copies rows of `row_bytes` bytes `stride` apart into a packed image.
void CopyRows(const std::uint8_t* src, std::size_t stride, std::size_t row_bytes, int rows,
              std::uint8_t* dst) {
  if (stride == row_bytes) {
    std::memcpy(dst, src, row_bytes * static_cast<std::size_t>(rows));
    return;
  }
  for (int r = 0; r < rows; ++r) {
    std::memcpy(dst + r * row_bytes, src + r * stride, row_bytes);
  }
}

// Fills *frame from a complete buffer. False (the frame unusable) for a
// payload that is no image, another pixel format than requested, another size
// than expected, or too little data.
bool ConvertBuffer(ArvBuffer* buffer, const AravisOptions& options, Frame* frame) {
  const ArvBufferPayloadType payload = arv_buffer_get_payload_type(buffer);
  if (payload != ARV_BUFFER_PAYLOAD_TYPE_IMAGE &&
      payload != ARV_BUFFER_PAYLOAD_TYPE_EXTENDED_CHUNK_DATA) {
    return false;
  }
  const int w = arv_buffer_get_image_width(buffer);
  const int h = arv_buffer_get_image_height(buffer);
  if (w <= 0 || h <= 0) return false;
  if ((options.width > 0 && w != options.width) || (options.height > 0 && h != options.height)) {
    return false;
  }
  if (arv_buffer_get_image_pixel_format(buffer) != ToArv(options.pixel_format)) return false;
  size_t size = 0;
  const auto* data = static_cast<const std::uint8_t*>(arv_buffer_get_image_data(buffer, &size));
  gint x_padding = 0;
  gint y_padding = 0;
  arv_buffer_get_image_padding(buffer, &x_padding, &y_padding);
  const std::size_t bytes_per_pixel = options.pixel_format == AravisOptions::Pixel::kRGB8 ? 3 : 1;
  const std::size_t row_bytes = static_cast<std::size_t>(w) * bytes_per_pixel;
  const std::size_t stride = row_bytes + static_cast<std::size_t>(std::max(x_padding, 0));
  if (data == nullptr || size < stride * static_cast<std::size_t>(h - 1) + row_bytes) return false;

  const std::size_t pixels = static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
  const bool raw_mosaic = options.pixel_format != AravisOptions::Pixel::kRGB8 && !options.debayer;
  switch (raw_mosaic ? AravisOptions::Pixel::kMono8 : options.pixel_format) {
    case AravisOptions::Pixel::kMono8:  // Or a Bayer mosaic passed on raw.
      frame->kind = FrameKind::kMono;
      frame->grey.width = w;
      frame->grey.height = h;
      frame->grey.pixels.resize(pixels);  // Allocates only when the size grows.
      CopyRows(data, stride, row_bytes, h, frame->grey.pixels.data());
      return true;
    case AravisOptions::Pixel::kRGB8:
      frame->kind = FrameKind::kRgb;
      frame->rgb.width = w;
      frame->rgb.height = h;
      frame->rgb.pixels.resize(pixels * 3);
      CopyRows(data, stride, row_bytes, h, frame->rgb.pixels.data());
      return true;
    default: {
      frame->kind = FrameKind::kRgb;
      frame->rgb.width = w;
      frame->rgb.height = h;
      frame->rgb.pixels.resize(pixels * 3);
      // Both Mats wrap existing memory: cvtColor writes into the frame's
      // buffer, which has the right size and type, without reallocating.
      const cv::Mat mosaic(h, w, CV_8UC1, const_cast<std::uint8_t*>(data), stride);
      cv::Mat rgb(h, w, CV_8UC3, frame->rgb.pixels.data());
      cv::cvtColor(mosaic, rgb, OpenCvBayerCode(options.pixel_format));
      return true;
    }
  }
}

std::int64_t RealtimeNowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

}  // namespace

// One open camera with its stream and buffers. Opened and released on the
// control thread; streamed from by the capture thread in between.
struct AravisSource::Session {
  ArvCamera* camera = nullptr;
  ArvStream* stream = nullptr;
  int width = 0;
  int height = 0;
  std::int64_t exposure_ns = 0;   // Read back at connection; 0 when unknown.
  double trigger_period_s = 0.0;  // Software trigger only.
  // Capture thread only: Aravis' own counters, last seen.
  guint64 underruns_seen = 0;
  guint64 resends_seen = 0;
  bool first_frame_logged = false;
  // Declared dead (no frame for the frame timeout): releasing it sends no
  // stop-acquisition command, which would only wait for its timeout.
  bool lost = false;
  // Set by the capture thread when the session delivered a frame: the control
  // thread then resets its backoff.
  std::atomic<bool> delivered{false};
};

struct AravisSource::Releaser {
  std::mutex mutex;
  std::condition_variable wake;  // Work arrived, or done.
  std::condition_variable idle;  // Nothing queued or being released.
  std::vector<Session*> queue;   // Guarded by mutex.
  bool busy = false;             // Guarded by mutex.
  bool done = false;             // Guarded by mutex.
};

struct AravisSource::Triggerer {
  std::mutex mutex;
  std::condition_variable wake;      // Another camera, or done.
  std::condition_variable finished;  // The thread has ended.
  ArvCamera* camera = nullptr;       // A reference of the thread's own; guarded by mutex.
  Clock::duration period{};          // Guarded by mutex.
  std::uint64_t generation = 0;      // +1 per camera handed over; guarded by mutex.
  bool done = false;                 // Guarded by mutex.
  bool ended = false;                // Guarded by mutex.
};

AravisSource::AravisSource(AravisOptions options)
    : options_(std::move(options)), releaser_(std::make_shared<Releaser>()) {
  if (options_.frame_rate_hz && *options_.frame_rate_hz > 0.0 &&
      options_.frame_timeout.count() < 2000.0 / *options_.frame_rate_hz) {
    Log(log::Level::kWarn, options_.device,
        "frame_timeout %lld ms is less than two frame periods at %.1f Hz: "
        "the connection will be reopened again and again",
        static_cast<long long>(options_.frame_timeout.count()), *options_.frame_rate_hz);
  }
  releaser_->queue.reserve(4);
  // The thread holds its own reference: it may outlive the source.
  release_thread_ = std::thread([releaser = releaser_] { ReleaseLoop(releaser); });
  if (options_.trigger == AravisOptions::Trigger::kSoftware) {
    triggerer_ = std::make_shared<Triggerer>();
    trigger_thread_ = std::thread([triggerer = triggerer_] { TriggerLoop(triggerer); });
  }
  control_ = std::thread([this] { ControlLoop(); });
}

AravisSource::~AravisSource() {
  Stop();
  if (control_.joinable()) control_.join();
  if (triggerer_) {
    std::lock_guard<std::mutex> lock(triggerer_->mutex);
    triggerer_->done = true;
    triggerer_->wake.notify_all();
  }
  // The control thread has ended and Next() is not running: whichever of the
  // handoff places holds the session, it is released now. The streamed one
  // counts as lost when its frames had stopped.
  if (active_ != nullptr && Clock::now() - last_good_ >= options_.frame_timeout) {
    active_->lost = true;
  }
  Session* back = returned_.exchange(nullptr);
  if (back != nullptr) back->lost = true;
  Session* sessions[] = {active_, offered_.exchange(nullptr), back};
  active_ = nullptr;
  for (Session* s : sessions) {
    if (s != nullptr) Retire(s);
  }
  const Clock::time_point stopped_at{Clock::duration(stop_ticks_.load())};
  const Clock::time_point deadline =
      std::max(stopped_at + kReleaseGrace, Clock::now() + kMinReleaseWait);
  std::unique_lock<std::mutex> lock(releaser_->mutex);
  releaser_->done = true;
  releaser_->wake.notify_all();
  const bool drained = releaser_->idle.wait_until(
      lock, deadline, [this] { return releaser_->queue.empty() && !releaser_->busy; });
  const std::size_t pending = releaser_->queue.size() + (releaser_->busy ? 1 : 0);
  lock.unlock();
  if (drained) {
    release_thread_.join();
  } else {
    // systemd stops the daemon after a few seconds: the release thread finishes
    // on its own (it needs nothing of this object) or ends with the process.
    Log(log::Level::kWarn, options_.device,
        "leaving %zu unanswered camera release(s) to finish in the background", pending);
    release_thread_.detach();
  }
  if (triggerer_) {
    // A trigger command to a dead camera may still be waiting for its
    // timeouts: the thread needs nothing of this object and ends on its own.
    std::unique_lock<std::mutex> trigger_lock(triggerer_->mutex);
    if (triggerer_->finished.wait_until(trigger_lock, deadline,
                                        [this] { return triggerer_->ended; })) {
      trigger_lock.unlock();
      trigger_thread_.join();
    } else {
      trigger_thread_.detach();
    }
  }
}

void AravisSource::TriggerSession(const Session* session) {
  ArvCamera* camera = nullptr;
  if (session != nullptr && session->camera != nullptr) {
    camera = session->camera;
    g_object_ref(camera);
  }
  ArvCamera* old = nullptr;
  {
    std::lock_guard<std::mutex> lock(triggerer_->mutex);
    old = std::exchange(triggerer_->camera, camera);
    if (session != nullptr) {
      triggerer_->period = std::chrono::duration_cast<Clock::duration>(
          std::chrono::duration<double>(session->trigger_period_s));
    }
    ++triggerer_->generation;
  }
  triggerer_->wake.notify_all();
  // The release thread drops the session's own references; this one was only
  // the trigger thread's, which a trigger in progress holds another of.
  if (old != nullptr) g_object_unref(old);
}

void AravisSource::TriggerLoop(const std::shared_ptr<Triggerer>& triggerer) {
  Triggerer& t = *triggerer;
  std::unique_lock<std::mutex> lock(t.mutex);
  std::uint64_t generation = t.generation;
  Clock::time_point next = Clock::now();
  while (!t.done) {
    if (t.generation != generation) {
      generation = t.generation;
      next = Clock::now();  // A new camera is triggered at once.
    }
    if (t.camera == nullptr) {
      t.wake.wait(lock);
      continue;
    }
    if (Clock::now() < next) {
      t.wake.wait_until(lock, next);
      continue;
    }
    ArvCamera* camera = t.camera;
    g_object_ref(camera);
    const Clock::duration period = t.period;
    lock.unlock();
    GError* e = nullptr;
    arv_camera_software_trigger(camera, &e);
    g_clear_error(&e);  // A dead camera shows as missing frames.
    g_object_unref(camera);
    lock.lock();
    next += period;
    const Clock::time_point now = Clock::now();
    if (next <= now) next = now + period;
  }
  if (t.camera != nullptr) g_object_unref(std::exchange(t.camera, nullptr));
  t.ended = true;
  t.finished.notify_all();
}

void AravisSource::Retire(Session* session) {
  {
    std::lock_guard<std::mutex> lock(releaser_->mutex);
    releaser_->queue.push_back(session);
  }
  releaser_->wake.notify_all();
}

void AravisSource::ReleaseLoop(const std::shared_ptr<Releaser>& releaser) {
  Releaser& r = *releaser;
  std::unique_lock<std::mutex> lock(r.mutex);
  for (;;) {
    r.wake.wait(lock, [&r] { return !r.queue.empty() || r.done; });
    if (r.queue.empty()) return;
    Session* session = r.queue.back();
    r.queue.pop_back();
    r.busy = true;
    lock.unlock();
    Release(session);
    lock.lock();
    r.busy = false;
    if (r.queue.empty()) r.idle.notify_all();
  }
}

void AravisSource::Stop() {
  Clock::rep expected = 0;
  stop_ticks_.compare_exchange_strong(expected, Clock::now().time_since_epoch().count());
  stopped_.store(true);
  std::lock_guard<std::mutex> lock(control_mutex_);
  control_wake_.notify_all();
}

AravisSource::Stats AravisSource::stats() const {
  Stats s;
  s.completed = completed_.load(std::memory_order_relaxed);
  s.failed = failed_.load(std::memory_order_relaxed);
  s.underruns = underruns_.load(std::memory_order_relaxed);
  s.resends = resends_.load(std::memory_order_relaxed);
  const std::uint64_t connections = connections_.load(std::memory_order_relaxed);
  s.reconnects = connections > 0 ? connections - 1 : 0;
  s.connected = connected_.load(std::memory_order_relaxed);
  return s;
}

TransportStats AravisSource::transport_stats() const {
  TransportStats s;
  s.completed = completed_.load(std::memory_order_relaxed);
  s.failed = failed_.load(std::memory_order_relaxed);
  s.underruns = underruns_.load(std::memory_order_relaxed);
  s.resends = resends_.load(std::memory_order_relaxed);
  return s;
}

AravisSource::Session* AravisSource::Connect(std::string* error, bool announce) {
  GError* e = nullptr;
  auto session = std::make_unique<Session>();
  if (IsIpv4Address(options_.device) && !ProbeGvcp(options_.device, stopped_, error)) {
    return nullptr;
  }
  {
    std::lock_guard<std::mutex> lock(AravisSystemMutex());
    // Another source may have held the lock for seconds.
    if (stopped_.load()) {
      *error = "stopped";
      return nullptr;
    }
    std::string id;
    if (!ResolveDeviceId(options_.device, &id, error)) return nullptr;
    session->camera = arv_camera_new(id.c_str(), &e);
    if (session->camera == nullptr) {
      if (!TakeError(&e, error, "open")) *error = "open: no camera";
      return nullptr;
    }
  }
  ArvCamera* camera = session->camera;
  // From here on a failure releases what was opened.
  auto fail = [&](const char* what) {
    TakeError(&e, error, what);
    Retire(session.release());
    return nullptr;
  };
  const bool gv = arv_camera_is_gv_device(camera);

  if (gv) {
    if (options_.packet_size) {
      arv_camera_gv_set_packet_size(camera, *options_.packet_size, &e);
      if (e != nullptr) return fail("packet size");
    } else {
      // Negotiation finds the largest packet the path carries (jumbo frames
      // where the network allows them); a camera that cannot test packets
      // keeps its own size, which works, only slower.
      arv_camera_gv_auto_packet_size(camera, &e);
      g_clear_error(&e);
    }
  }
  arv_camera_set_pixel_format(camera, ToArv(options_.pixel_format), &e);
  if (e != nullptr) return fail("pixel format");
  // Full sensor: the calibration holds for the whole image, so no binning,
  // region of interest or offset may be left over from another application.
  if (arv_camera_is_binning_available(camera, nullptr)) {
    arv_camera_set_binning(camera, 1, 1, &e);
    if (e != nullptr) return fail("binning");
  }
  gint sensor_w = 0;
  gint sensor_h = 0;
  arv_camera_get_sensor_size(camera, &sensor_w, &sensor_h, &e);
  if (e != nullptr) return fail("sensor size");
  arv_camera_set_region(camera, 0, 0, sensor_w, sensor_h, &e);
  if (e != nullptr) return fail("region");
  gint x = 0;
  gint y = 0;
  arv_camera_get_region(camera, &x, &y, &session->width, &session->height, &e);
  if (e != nullptr) return fail("region");
  if ((options_.width > 0 && session->width != options_.width) ||
      (options_.height > 0 && session->height != options_.height)) {
    *error = "the camera's image is " + std::to_string(session->width) + "x" +
             std::to_string(session->height) + ", the calibration's " +
             std::to_string(options_.width) + "x" + std::to_string(options_.height);
    Retire(session.release());
    return nullptr;
  }
  if (options_.exposure_us) {
    if (arv_camera_is_exposure_auto_available(camera, nullptr)) {
      arv_camera_set_exposure_time_auto(camera, ARV_AUTO_OFF, &e);
      if (e != nullptr) return fail("exposure auto off");
    }
    arv_camera_set_exposure_time(camera, *options_.exposure_us, &e);
    if (e != nullptr) return fail("exposure");
  }
  if (options_.gain_db) {
    if (arv_camera_is_gain_auto_available(camera, nullptr)) {
      arv_camera_set_gain_auto(camera, ARV_AUTO_OFF, &e);
      if (e != nullptr) return fail("gain auto off");
    }
    arv_camera_set_gain(camera, *options_.gain_db, &e);
    if (e != nullptr) return fail("gain");
  }
  const double exposure_us = arv_camera_get_exposure_time(camera, &e);
  g_clear_error(&e);
  if (exposure_us > 0.0) session->exposure_ns = static_cast<std::int64_t>(exposure_us * 1e3);

  switch (options_.trigger) {
    case AravisOptions::Trigger::kFreeRun:
      // A camera without trigger features free-runs anyway.
      arv_camera_clear_triggers(camera, &e);
      g_clear_error(&e);
      if (options_.frame_rate_hz) {
        arv_camera_set_frame_rate(camera, *options_.frame_rate_hz, &e);
        if (e != nullptr) return fail("frame rate");
      }
      break;
    case AravisOptions::Trigger::kSoftware: {
      double rate = options_.frame_rate_hz.value_or(0.0);
      if (!(rate > 0.0)) {
        rate = arv_camera_get_frame_rate(camera, &e);
        g_clear_error(&e);
      }
      session->trigger_period_s = 1.0 / (rate > 0.0 ? rate : 30.0);
      arv_camera_set_trigger(camera, "Software", &e);
      if (e != nullptr) return fail("software trigger");
      break;
    }
    case AravisOptions::Trigger::kHardware:
      arv_camera_set_trigger(camera, "Line0", &e);
      if (e != nullptr) return fail("hardware trigger (Line0)");
      break;
  }
  arv_camera_set_acquisition_mode(camera, ARV_ACQUISITION_MODE_CONTINUOUS, &e);
  if (e != nullptr) return fail("acquisition mode");

  const guint payload = arv_camera_get_payload(camera, &e);
  if (e != nullptr) return fail("payload size");
  session->stream = arv_camera_create_stream(camera, nullptr, nullptr, &e);
  if (session->stream == nullptr) {
    if (e == nullptr) *error = "stream: not created";
    return fail("stream");
  }
  if (ARV_IS_GV_STREAM(session->stream) && options_.socket_buffer_bytes) {
    g_object_set(session->stream, "socket-buffer", ARV_GV_STREAM_SOCKET_BUFFER_FIXED,
                 "socket-buffer-size", static_cast<gint>(*options_.socket_buffer_bytes), nullptr);
  }
  for (int i = 0; i < std::max(options_.buffers, 1); ++i) {
    arv_stream_push_buffer(session->stream, arv_buffer_new_allocate(payload));
  }
  arv_camera_start_acquisition(camera, &e);
  if (e != nullptr) return fail("start acquisition");

  const char* model = arv_camera_get_model_name(camera, nullptr);
  const char* serial = arv_camera_get_device_serial_number(camera, nullptr);
  if (!announce) return session.release();
  Log(log::Level::kInfo, options_.device,
      "streaming from %s %s: %dx%d, exposure %.0f us, payload %u bytes%s",
      model != nullptr ? model : "?", serial != nullptr ? serial : "?", session->width,
      session->height, exposure_us, payload, gv ? "" : " (not GigE)");
  return session.release();
}

void AravisSource::Release(Session* session) {
  if (session->camera != nullptr && session->stream != nullptr && !session->lost) {
    // A camera that died unnoticed answers nothing; the command times out and
    // the release goes on regardless.
    GError* e = nullptr;
    arv_camera_stop_acquisition(session->camera, &e);
    g_clear_error(&e);
  }
  if (session->stream != nullptr) g_object_unref(session->stream);
  if (session->camera != nullptr) g_object_unref(session->camera);
  delete session;
}

void AravisSource::ControlLoop() {
  Session* current = nullptr;  // Offered, streamed from, or being returned.
  milliseconds backoff = kMinBackoff;
  Clock::time_point next_attempt = Clock::now();
  std::string last_error;
  Clock::time_point last_error_log;
  bool was_lost = false;
  // A connection that delivers nothing (a hardware trigger without pulses, a
  // camera that opens but does not stream) is reopened with a growing
  // backoff, and said again only every kRepeatLog while it lasts.
  Clock::time_point last_silent_log;
  bool announce = true;  // Log the next connection (not after a silent one).

  while (!stopped_.load()) {
    Clock::time_point now = Clock::now();
    if (Session* back = returned_.exchange(nullptr)) {
      const bool delivered = back->delivered.load();
      announce = delivered;
      if (delivered) {
        Log(log::Level::kWarn, options_.device,
            "no complete frame for %lld ms: connection lost, reopening",
            static_cast<long long>(options_.frame_timeout.count()));
        last_silent_log = Clock::time_point{};
      } else if (last_silent_log == Clock::time_point{} || now - last_silent_log >= kRepeatLog) {
        Log(log::Level::kWarn, options_.device,
            "no frame within %lld ms of opening%s: reopening, backoff up to %lld ms "
            "(said again every %lld s while it lasts)",
            static_cast<long long>(options_.frame_timeout.count()),
            options_.trigger == AravisOptions::Trigger::kHardware
                ? " (hardware trigger: no pulses on Line0?)"
                : "",
            static_cast<long long>(kMaxBackoff.count()),
            static_cast<long long>(std::chrono::seconds(kRepeatLog).count()));
        last_silent_log = now;
      }
      back->lost = true;
      if (triggerer_) TriggerSession(nullptr);
      Retire(back);
      current = nullptr;
      was_lost = true;
      now = Clock::now();
      next_attempt = now + backoff;
      if (!delivered) backoff = std::min(backoff * 2, kMaxBackoff);
    }
    if (current != nullptr && current->delivered.load()) backoff = kMinBackoff;

    if (current == nullptr && now >= next_attempt) {
      std::string error;
      current = Connect(&error, announce);
      if (current == nullptr && stopped_.load()) break;
      now = Clock::now();
      if (current != nullptr) {
        if ((connections_.fetch_add(1) > 0 || was_lost) && announce) {
          Log(log::Level::kInfo, options_.device, "reconnected");
        }
        last_error.clear();
        connected_.store(true);
        // failing() stays as it was until the connection delivers a frame
        // (Next()): one that opens but sends nothing is no better than none.
        if (triggerer_) TriggerSession(current);
        offered_.store(current, std::memory_order_release);
      } else {
        if (error != last_error || now - last_error_log >= kRepeatLog) {
          Log(log::Level::kWarn, options_.device,
              "cannot open (retrying, backoff up to %lld ms): %s",
              static_cast<long long>(kMaxBackoff.count()), error.c_str());
          last_error = error;
          last_error_log = now;
        }
        failing_.store(true);
        next_attempt = now + backoff;
        backoff = std::min(backoff * 2, kMaxBackoff);
      }
    }

    Clock::time_point wake = now + std::chrono::seconds(1);
    if (current == nullptr) wake = next_attempt;
    std::unique_lock<std::mutex> lock(control_mutex_);
    control_wake_.wait_until(lock, wake, [this] {
      return stopped_.load() || returned_.load(std::memory_order_relaxed) != nullptr;
    });
  }
}

void AravisSource::SampleStreamStats(Session* session) {
  guint64 completed = 0;
  guint64 failures = 0;
  guint64 underruns = 0;
  arv_stream_get_statistics(session->stream, &completed, &failures, &underruns);
  if (underruns > session->underruns_seen) {
    underruns_.fetch_add(underruns - session->underruns_seen, std::memory_order_relaxed);
    session->underruns_seen = underruns;
  }
  if (ARV_IS_GV_STREAM(session->stream)) {
    guint64 resent = 0;
    guint64 missing = 0;
    arv_gv_stream_get_statistics(ARV_GV_STREAM(session->stream), &resent, &missing);
    if (resent > session->resends_seen) {
      resends_.fetch_add(resent - session->resends_seen, std::memory_order_relaxed);
      session->resends_seen = resent;
    }
  }
}

bool AravisSource::Next(Frame* frame, milliseconds timeout) {
  const Clock::time_point give_up = Clock::now() + timeout;
  bool popped = false;  // A zero timeout still takes a frame that is waiting.
  for (;;) {
    if (stopped_.load()) return false;
    Clock::time_point now = Clock::now();
    if (active_ == nullptr) {
      active_ = offered_.exchange(nullptr, std::memory_order_acquire);
      if (active_ == nullptr) {
        if (now >= give_up) return false;
        std::this_thread::sleep_until(std::min(give_up, now + milliseconds(10)));
        continue;
      }
      last_good_ = now;
    }
    const Clock::time_point lost_at = last_good_ + options_.frame_timeout;
    ArvBuffer* buffer = nullptr;
    if (now >= lost_at) {
      // A caller that was itself held up past the timeout first takes the
      // buffers that arrived meanwhile (each stamped with its arrival, so an
      // old one ages as it should downstream).
      buffer = arv_stream_try_pop_buffer(active_->stream);
      if (buffer == nullptr) {
        // The watchdog: hand the camera to the control thread for release and
        // reopening. The lock only orders the wake-up; it is taken once per loss.
        connected_.store(false);
        failing_.store(true);
        returned_.store(active_, std::memory_order_release);
        active_ = nullptr;
        {
          std::lock_guard<std::mutex> lock(control_mutex_);
          control_wake_.notify_all();
        }
        return false;
      }
    } else {
      if (popped && now >= give_up) return false;
      const Clock::time_point wake = std::min({give_up, lost_at, now + kPollSlice});
      const auto wait_us =
          std::chrono::duration_cast<std::chrono::microseconds>(wake - now).count();
      popped = true;
      buffer = wait_us > 0
                   ? arv_stream_timeout_pop_buffer(active_->stream, static_cast<guint64>(wait_us))
                   : arv_stream_try_pop_buffer(active_->stream);
      if (buffer == nullptr) continue;
    }

    // The newest complete buffer wins; older ones waiting behind a slow
    // reader would only add latency.
    ArvBuffer* newest = nullptr;
    for (ArvBuffer* b = buffer; b != nullptr; b = arv_stream_try_pop_buffer(active_->stream)) {
      if (arv_buffer_get_status(b) == ARV_BUFFER_STATUS_SUCCESS) {
        if (newest != nullptr) arv_stream_push_buffer(active_->stream, newest);
        newest = b;
      } else {
        failed_.fetch_add(1, std::memory_order_relaxed);
        arv_stream_push_buffer(active_->stream, b);
      }
    }
    SampleStreamStats(active_);
    if (newest == nullptr) continue;

    const bool ok = ConvertBuffer(newest, options_, frame);
    if (ok) {
      const guint64 system_ns = arv_buffer_get_system_timestamp(newest);
      const std::int64_t arrival_ns =
          system_ns != 0 ? static_cast<std::int64_t>(system_ns) : RealtimeNowNs();
      // The image shows the scene during the exposure, which ended before
      // the frame arrived: stamping no later than that keeps the pipeline's
      // capture-skew margin large enough.
      frame->stamp_ns = arrival_ns - active_->exposure_ns;
      const guint64 device_ns = arv_buffer_get_timestamp(newest);
      frame->device_stamp_ns = device_ns != 0 ? static_cast<std::int64_t>(device_ns) : -1;
      frame->index = index_++;
      if (!active_->first_frame_logged) {
        active_->first_frame_logged = true;
        Log(log::Level::kInfo, options_.device,
            "first frame: device timestamp %llu ns, host %lld ns",
            static_cast<unsigned long long>(arv_buffer_get_timestamp(newest)),
            static_cast<long long>(arrival_ns));
      }
    }
    arv_stream_push_buffer(active_->stream, newest);
    if (!ok) {
      failed_.fetch_add(1, std::memory_order_relaxed);
      continue;
    }
    completed_.fetch_add(1, std::memory_order_relaxed);
    last_good_ = Clock::now();
    if (!active_->delivered.load(std::memory_order_relaxed)) {
      active_->delivered.store(true);
      failing_.store(false);
    }
    return true;
  }
}

}  // namespace hg::capture
