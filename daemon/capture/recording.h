#pragma once
/// @file
/// Recording folders: the layout `hullguard record` and the daemon's black box
/// write, and a reader for it and for the layout `hullguard synth` writes.
/// Both layouts are described in docs/cameras.md ("Recording and replaying")
/// and docs/synth.md.

#include <cstdint>
#include <cstdio>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "capture/camera_source.h"
#include "geometry/camera.h"

namespace hg::capture {

/// Which program wrote a recording folder.
enum class RecordingLayout : std::uint8_t {
  kSynth,   ///< `hullguard synth`: frames on a fixed grid, i / rate_hz + the camera's offset.
  kRecord,  ///< `hullguard record` or the black box: a frames index with capture stamps.
};

/// "mask", "mono" or "rgb": the spelling in a recording's manifest.
[[nodiscard]] const char* ToString(FrameKind kind);

/// Bytes per pixel of a frame of this kind: 1, or 3 for kRgb.
[[nodiscard]] int BytesPerPixel(FrameKind kind);

/// One frame of a recorded camera.
struct RecordedFrame {
  /// Capture time since the recording's time 0 (ns). Replays are paced and
  /// stamped by it.
  std::int64_t time_ns = 0;
  /// Host capture stamp as the source gave it (CLOCK_REALTIME ns); in a synth
  /// recording the same as time_ns.
  std::int64_t stamp_ns = 0;
  /// The camera's own clock, when the source knew it.
  std::optional<std::int64_t> device_stamp_ns;
  std::uint64_t source_index = 0;  ///< The source's frame counter.
  std::string file;                ///< Image path, relative to the recording folder.
};

/// What a recording folder holds for one camera. Plain struct.
struct RecordingCamera {
  std::string directory;
  std::string camera;
  RecordingLayout layout = RecordingLayout::kSynth;
  FrameKind kind = FrameKind::kMask;
  int width = 0;   ///< 0 where the layout does not state it (synth).
  int height = 0;  ///< 0 where the layout does not state it (synth).
  /// Synth: the nominal rate. Record: the mean rate over the frames (0 with
  /// fewer than two frames).
  double rate_hz = 30.0;
  double time_offset_s = 0.0;  ///< Synth: the camera's capture offset (s), frame times include it.
  /// Record: the host stamp of recording time 0, the first frame of the
  /// camera that started first. Synth: 0.
  std::int64_t start_ns = 0;
  std::uint64_t lost = 0;  ///< Record: frames the writer could not keep (all reasons).
  std::vector<RecordedFrame> frames;
};

/// Reads what a recording folder (either layout) holds for one camera.
/// @throws common::ConfigError naming the file and line when the manifest or
/// the frames index is missing or bad, or the recording has no such camera.
[[nodiscard]] RecordingCamera ReadRecordingCamera(const std::string& directory,
                                                  const std::string& camera);

/// Names of the cameras of a recording folder, in manifest order.
/// @throws common::ConfigError as ReadRecordingCamera.
[[nodiscard]] std::vector<std::string> RecordingCameraNames(const std::string& directory);

/// Decodes a frame file of `recording` into *frame (kind, size, pixels and
/// the recorded device stamp; the capture stamp untouched), reusing its buffers and *bytes. False
/// when the file is missing, unreadable, of another size than the manifest states, or not an image.
bool LoadRecordedFrame(const RecordingCamera& recording, std::size_t index, Frame* frame,
                       std::vector<unsigned char>* bytes, std::string* path);

/// Why a frame did not make it into a recording.
enum class FrameLoss : std::uint8_t {
  kQueueFull,    ///< The writer was behind and the frame queue was full.
  kWriteError,   ///< Encoding or writing the file (or its index line) failed.
  kOverwritten,  ///< Black box: the frame was overwritten (or torn) while being copied.
};

/// How a RecordingWriter stores frames; both are lossless and 8-bit, and the
/// reader takes either (the index names each file).
enum class ImageFormat : std::uint8_t {
  /// PNG, deflate level 1: about half the size of the pixels on camera
  /// images, but tens of milliseconds of CPU per Full HD frame.
  kPng,
  /// Binary PGM (grey) / PPM (RGB): the pixels behind a one-line header,
  /// written at disk speed.
  kPnm,
  /// PNG for masks (mostly uniform: small and quick to compress), PGM/PPM for
  /// camera images (so that the writer keeps up with the cameras).
  kAuto,
};

/// "png", "pnm" or "auto".
[[nodiscard]] const char* ToString(ImageFormat format);

/// Per camera counts of a RecordingWriter.
struct RecordingCameraStats {
  std::uint64_t kept = 0;
  std::uint64_t queue_full = 0;
  std::uint64_t write_errors = 0;
  std::uint64_t overwritten = 0;
  std::string last_error;  ///< The most recent write error, for the report.
  [[nodiscard]] std::uint64_t lost() const { return queue_full + write_errors + overwritten; }
};

/// Writes a recording folder in the record layout: manifest.yaml, cameras.yaml
/// (the calibration, so that a recording replays on its own), and per camera
/// frames/<camera>/index.csv plus one lossless image per frame (8-bit grey for
/// masks and Mono8, 8-bit RGB for colour; PNG or PGM/PPM).
///
/// The index is appended and flushed frame by frame and the manifest is
/// written at start and again by Finish(), so a recording cut short (power
/// loss, SIGKILL) still reads back up to its last indexed frame.
///
/// Thread safety: Write() and CountLost() for different cameras may run
/// concurrently; calls for one camera must come from one thread at a time.
/// The constructor and Finish() must not overlap with any other call.
class RecordingWriter {
 public:
  /// Creates `directory` (and its parents) unless it exists, and refuses one
  /// that already holds a manifest.yaml. `writer` names the program in the
  /// manifest; `note` (may be empty) says why it was written.
  /// @throws common::ConfigError naming the path when the folder or its files
  /// cannot be created.
  RecordingWriter(std::string directory, std::vector<geometry::CameraModel> cameras,
                  std::string writer, std::string note = {},
                  ImageFormat format = ImageFormat::kAuto);
  ~RecordingWriter();
  RecordingWriter(const RecordingWriter&) = delete;
  RecordingWriter& operator=(const RecordingWriter&) = delete;

  /// Encodes and writes `frame` of camera `camera` (index in the constructor's
  /// list) as its frame `number`: the recorder's count of frames the camera
  /// delivered, so that gaps in the numbers show the frames lost. False, and
  /// counted as a write error, when it cannot be written; the recording goes
  /// on without it. The device stamp is `device_stamp_ns` when given, else
  /// the frame's own (none when it is negative).
  bool Write(int camera, std::uint64_t number, const Frame& frame,
             std::optional<std::int64_t> device_stamp_ns = std::nullopt);

  /// Counts `count` frames of `camera` lost before they reached the writer.
  void CountLost(int camera, FrameLoss reason, std::uint64_t count = 1);

  /// Closes the indexes and writes the final manifest with the counts. False
  /// (with the reason in *error) when that fails. Idempotent.
  bool Finish(std::string* error = nullptr);

  [[nodiscard]] const RecordingCameraStats& stats(int camera) const {
    return cameras_[camera].stats;
  }
  [[nodiscard]] const std::string& directory() const { return directory_; }
  [[nodiscard]] int num_cameras() const { return static_cast<int>(cameras_.size()); }

 private:
  struct CameraState {
    geometry::CameraModel model;
    int index = -1;                // File descriptor of frames/<camera>/index.csv.
    std::int64_t index_bytes = 0;  // Length of its whole lines.
    // Of the first frame written; guarded by manifest_mutex_.
    FrameKind kind = FrameKind::kMask;
    bool kind_known = false;
    int width = 0;
    int height = 0;
    RecordingCameraStats stats;
    std::string path;                  // Reused path buffer.
    std::vector<std::uint8_t> bgr;     // Reused RGB -> BGR buffer.
    std::vector<unsigned char> bytes;  // Reused PNG buffer.
  };
  // Caller holds manifest_mutex_.
  bool WriteManifest(bool complete, std::string* error) const;
  bool Fail(CameraState* c, const std::string& what);
  // Appends one index line, whole or not at all (errno set on failure).
  static bool AppendIndexLine(CameraState* c, const char* line, std::size_t length);

  std::string directory_;
  std::string writer_;
  std::string note_;
  ImageFormat format_ = ImageFormat::kAuto;
  std::int64_t created_ns_ = 0;
  std::vector<CameraState> cameras_;
  // The manifest is rewritten when a camera's first frame tells its kind.
  mutable std::mutex manifest_mutex_;
  bool finished_ = false;
};

}  // namespace hg::capture
