#pragma once
/// @file
/// The `aravis` camera source: a GigE Vision (or USB3 Vision) camera through
/// the Aravis 0.8 library. Built only when Aravis is installed (HG_WITH_ARAVIS).

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include "capture/camera_source.h"

namespace hg::capture {

/// How to open and configure an Aravis camera. Unset optionals keep the
/// camera's own setting.
struct AravisOptions {
  /// Serial number, model name, Aravis device id ("<vendor>-<serial>") or IP
  /// address of the camera; "" takes the first camera found. An IPv4 address
  /// is opened directly (no broadcast discovery needed).
  std::string device;
  /// Pixel formats requested from the camera. Mono8 is delivered as
  /// FrameKind::kMono, RGB8 as FrameKind::kRgb, Bayer formats as the raw
  /// mosaic (FrameKind::kMono) or, with `debayer`, converted to kRgb.
  enum class Pixel { kMono8, kBayerRG8, kBayerGB8, kBayerGR8, kBayerBG8, kRGB8 };
  Pixel pixel_format = Pixel::kMono8;
  bool debayer = false;
  std::optional<double> exposure_us;  ///< Fixed exposure time (us); turns auto exposure off.
  std::optional<double> gain_db;      ///< Fixed analog gain (dB); turns auto gain off.
  /// Free run: the camera's AcquisitionFrameRate. Software trigger: the rate
  /// at which the source triggers (unset: the camera's frame rate, else 30 Hz).
  /// Hardware trigger: unused (the external pulse sets the rate).
  std::optional<double> frame_rate_hz;
  /// kFreeRun: the camera paces itself. kSoftware: the source triggers each
  /// frame (TriggerSource=Software). kHardware: each frame waits for a rising
  /// edge on Line0.
  enum class Trigger { kFreeRun, kSoftware, kHardware };
  Trigger trigger = Trigger::kFreeRun;
  std::optional<int> packet_size;          ///< GigE stream packet size (bytes); unset: negotiated.
  std::optional<int> socket_buffer_bytes;  ///< GigE receive socket buffer; unset: Aravis' auto.
  /// Expected image size (the camera's calibration); 0 = any. The region is
  /// always the full sensor; a camera whose sensor has another size is refused
  /// and frames of another size are counted as corrupt.
  int width = 0;
  int height = 0;
  int buffers = 8;  ///< Stream buffers, allocated once per connection.
  /// No complete frame for this long: the connection counts as lost, the
  /// camera is released and reopened (Aravis notices a dead camera only after
  /// seconds of missed heartbeats).
  std::chrono::milliseconds frame_timeout{200};
};

/// A GigE Vision camera as a CameraSource.
///
/// All blocking control-channel work (discovery, opening, configuring,
/// starting acquisition) runs on the source's own control thread, software
/// triggers on a trigger thread, and releasing a camera on a release thread,
/// so Next() never blocks
/// longer than its timeout even while a camera takes seconds to time out, and
/// a camera that comes back is reopened while the dead connection is still
/// being torn down. The constructor does not throw when the camera is absent:
/// the control thread keeps trying with exponential backoff (100 ms doubling
/// to 2 s, back to 100 ms once a connection delivers a frame). A connection
/// that is lost before it delivered anything (a hardware trigger without
/// pulses) doubles the backoff too, and is logged at most every 30 s.
///
/// Next() pops the newest completed stream buffer (older ones waiting are
/// skipped, so a late reader gets the freshest image), converts it (Mono8 ->
/// kMono, Bayer -> kRgb by OpenCV demosaicing, RGB8 -> kRgb) into the frame's
/// reused buffers and stamps it with the host's CLOCK_REALTIME time of the
/// frame's arrival (Aravis' system timestamp) minus the exposure time, an
/// instant no later than the end of the exposure: a late stamp would make the
/// capture-skew margin too small. Failed or incomplete buffers are counted
/// in corrupt_frames() and skipped. When no complete frame arrives for
/// frame_timeout, Next() declares the connection lost, hands the camera to the
/// control thread for release and returns false; a new connection is picked
/// up by a later Next().
///
/// A camera given by IPv4 address is first asked whether it is there (one
/// GigE Vision discovery command, unicast, answered within milliseconds by a
/// live camera) before Aravis opens it: Aravis waits 2.5 s for an absent
/// camera, under a process-wide lock and deaf to Stop().
///
/// Thread-compatible like every CameraSource: one capture thread calls Next();
/// Stop(), stats(), transport_stats() and corrupt_frames() may be called from
/// any thread. The destructor must not run concurrently with Next(). It is
/// bounded for systemd's stop timeout: a camera that answers is released at
/// once, but releasing a dead one takes Aravis 7.5 s of command timeouts
/// (12.5 s with stop-acquisition, which a camera known lost is not sent). The
/// destructor waits for releases (and a trigger in progress) until
/// kReleaseGrace after Stop() and then leaves the rest to the release (and
/// trigger) thread, which finishes on its own or ends with the process. No allocation per frame
/// after the first frame of each image size.
class AravisSource : public CameraSource {
 public:
  /// Starts the control thread, which opens the camera in the background.
  explicit AravisSource(AravisOptions options);
  ~AravisSource() override;
  AravisSource(const AravisSource&) = delete;
  AravisSource& operator=(const AravisSource&) = delete;

  /// How long after Stop() the destructor waits for camera releases at most.
  static constexpr std::chrono::milliseconds kReleaseGrace{1000};

  bool Next(Frame* frame, std::chrono::milliseconds timeout) override;
  void Stop() override;
  /// Failed or incomplete stream buffers, and complete ones of the wrong size
  /// or pixel format, since construction.
  [[nodiscard]] std::uint64_t corrupt_frames() const override {
    return failed_.load(std::memory_order_relaxed);
  }

  /// Counters since construction (over all connections). Thread-safe.
  struct Stats {
    std::uint64_t completed = 0;   ///< Frames delivered by Next().
    std::uint64_t failed = 0;      ///< Failed, incomplete or unusable buffers.
    std::uint64_t underruns = 0;   ///< Frames Aravis dropped for lack of a free buffer.
    std::uint64_t resends = 0;     ///< Packets the camera resent on request (GigE).
    std::uint64_t reconnects = 0;  ///< Connections opened after the first.
    bool connected = false;        ///< A camera is open and streaming.
  };
  [[nodiscard]] Stats stats() const;
  /// The counters of stats() that go into the camera's status. Thread-safe.
  [[nodiscard]] TransportStats transport_stats() const override;
  /// The last attempt to open the camera failed, or its connection was lost,
  /// and no connection has delivered a frame since.
  [[nodiscard]] bool failing() const override { return failing_.load(std::memory_order_relaxed); }

 private:
  struct Session;
  // The release thread's queue. Shared with that thread, which may outlive the
  // source when a dead camera's release is left to finish on its own.
  struct Releaser;
  // The software trigger thread's camera and period. Shared with that thread,
  // which may outlive the source while a trigger command to a dead camera
  // waits for its timeouts.
  struct Triggerer;

  void ControlLoop();
  // Opens, configures and starts the camera; `announce`: log the connection.
  Session* Connect(std::string* error, bool announce);
  // Hands a session to the release thread.
  void Retire(Session* session);
  static void Release(Session* session);
  static void ReleaseLoop(const std::shared_ptr<Releaser>& releaser);
  static void TriggerLoop(const std::shared_ptr<Triggerer>& triggerer);
  // The session whose camera the trigger thread triggers, at its period
  // (nullptr: none). The thread takes its own reference to the camera.
  void TriggerSession(const Session* session);
  void SampleStreamStats(Session* session);

  const AravisOptions options_;

  // Handoff of sessions between the control thread (which opens and releases
  // them) and the capture thread (which streams from them): a new session is
  // offered through `offered_`; a lost one comes back through `returned_`.
  std::atomic<Session*> offered_{nullptr};
  std::atomic<Session*> returned_{nullptr};
  Session* active_ = nullptr;                        // Capture thread only.
  std::chrono::steady_clock::time_point last_good_;  // Capture thread only.
  std::uint64_t index_ = 0;                          // Capture thread only.

  std::atomic<bool> stopped_{false};
  // steady_clock ticks of the first Stop(); the destructor's release deadline
  // counts from there, so sources stopped together wait together.
  std::atomic<std::chrono::steady_clock::rep> stop_ticks_{0};
  std::mutex control_mutex_;  // Guards the wake-up of the control thread only.
  std::condition_variable control_wake_;
  std::thread control_;

  // Releasing a dead camera takes Aravis seconds of command timeouts; its
  // own thread does it so that reopening need not wait.
  std::shared_ptr<Releaser> releaser_;
  std::thread release_thread_;

  // Software triggers go out on their own thread: a trigger command to a
  // camera that stopped answering blocks for Aravis' command timeouts (five
  // tries of 500 ms), which must hold up neither the reopening nor the
  // destructor. Started only for Trigger::kSoftware.
  std::shared_ptr<Triggerer> triggerer_;
  std::thread trigger_thread_;

  std::atomic<std::uint64_t> completed_{0};
  std::atomic<std::uint64_t> failed_{0};
  std::atomic<std::uint64_t> underruns_{0};
  std::atomic<std::uint64_t> resends_{0};
  std::atomic<std::uint64_t> connections_{0};
  std::atomic<bool> connected_{false};
  std::atomic<bool> failing_{false};  // failing().
};

}  // namespace hg::capture
