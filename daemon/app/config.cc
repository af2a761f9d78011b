#include "app/config.h"

#include <unistd.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <set>
#include <span>
#include <sstream>
#include <system_error>
#include <tuple>
#include <type_traits>
#include <utility>
#include <variant>

#include <yaml-cpp/yaml.h>

#include "app/config_doc.h"
#include "app/pipeline_setup.h"
#include "app/tracking_stage.h"
#include "capture/recording.h"
#include "capture/replay_source.h"
#include "common/config_error.h"
#include "common/input_file.h"
#include "common/limits.h"
#include "common/yaml_file.h"
#include "geometry/camera_yaml.h"
#include "geometry/mesh.h"
#include "geometry/obstacle_depth.h"
#include "octree/octree.h"
#include "sim/body.h"
#include "sim/scene.h"

namespace hg::app {
namespace {

/// Volume of a small child (m^3): a knowledge filter dropping blobs larger than
/// this could drop a person (a notice says so).
constexpr double kSmallestPersonM3 = 0.02;

namespace fs = std::filesystem;
using common::ConfigError;

constexpr double kInf = std::numeric_limits<double>::infinity();

// ---------------------------------------------------------------------------
// Enum spellings.

template <typename E>
using NameTable = std::span<const std::pair<E, const char*>>;

constexpr std::pair<SourceType, const char*> kSourceTypeNames[] = {{SourceType::kSim, "sim"},
                                                                   {SourceType::kReplay, "replay"},
                                                                   {SourceType::kAravis, "aravis"},
                                                                   {SourceType::kV4l2, "v4l2"}};
constexpr std::pair<PixelFormat, const char*> kPixelFormatNames[] = {
    {PixelFormat::kMono8, "Mono8"},       {PixelFormat::kBayerRG8, "BayerRG8"},
    {PixelFormat::kBayerGB8, "BayerGB8"}, {PixelFormat::kBayerGR8, "BayerGR8"},
    {PixelFormat::kBayerBG8, "BayerBG8"}, {PixelFormat::kRGB8, "RGB8"}};
constexpr std::pair<Trigger, const char*> kTriggerNames[] = {{Trigger::kFreeRun, "free_run"},
                                                             {Trigger::kSoftware, "software"},
                                                             {Trigger::kHardware, "hardware"}};
constexpr std::pair<V4l2Format, const char*> kV4l2FormatNames[] = {
    {V4l2Format::kGrey, "GREY"}, {V4l2Format::kYuyv, "YUYV"}, {V4l2Format::kMjpeg, "MJPEG"}};
constexpr std::pair<LogLevel, const char*> kLogLevelNames[] = {{LogLevel::kTrace, "trace"},
                                                               {LogLevel::kDebug, "debug"},
                                                               {LogLevel::kInfo, "info"},
                                                               {LogLevel::kWarn, "warn"},
                                                               {LogLevel::kError, "error"}};

NameTable<SourceType> Names(SourceType) { return kSourceTypeNames; }
NameTable<PixelFormat> Names(PixelFormat) { return kPixelFormatNames; }
NameTable<Trigger> Names(Trigger) { return kTriggerNames; }
NameTable<V4l2Format> Names(V4l2Format) { return kV4l2FormatNames; }
NameTable<LogLevel> Names(LogLevel) { return kLogLevelNames; }

template <typename E>
const char* NameOf(E value) {
  for (const auto& [v, name] : Names(value)) {
    if (v == value) return name;
  }
  return "?";
}

/// "a, b or c".
std::string OrList(const std::vector<std::string>& words, const char* last = " or ") {
  std::string out;
  for (std::size_t i = 0; i < words.size(); ++i) {
    if (i > 0) out += i + 1 == words.size() ? last : ", ";
    out += words[i];
  }
  return out;
}

template <typename E>
std::vector<std::string> NameList() {
  std::vector<std::string> out;
  for (const auto& [v, name] : Names(E{})) out.emplace_back(name);
  return out;
}

std::string FormatNumber(double value) {
  std::ostringstream out;
  out << value;
  return out.str();
}

// ---------------------------------------------------------------------------
// Field tables: the one description of every scalar key. The loader reads
// through them (type, range, required) and the reference prints them; defaults
// are those of the structs' in-line initializers.

/// Allowed numeric range; integers are checked against it too.
struct Limits {
  double lo = -kInf;
  double hi = kInf;
  bool lo_open = false;  ///< lo itself excluded ("> 0").
};

/// What a path-valued string must name once resolved against the config's folder.
enum class PathCheck { kNone, kFile, kDirectory };

template <typename S>
using Member = std::variant<int S::*, double S::*, bool S::*, std::string S::*,
                            std::optional<int> S::*, std::optional<double> S::*, common::Box3 S::*,
                            PixelFormat S::*, Trigger S::*, V4l2Format S::*, LogLevel S::*>;

template <typename S>
struct Field {
  const char* key;
  Member<S> member;
  const char* meaning;
  Limits limits = {};
  bool required = false;
  PathCheck path = PathCheck::kNone;
  const char* default_doc = nullptr;  ///< Printed instead of the struct's default.
};

const Field<CellConfig> kCellFields[] = {
    {.key = "bounds",
     .member = &CellConfig::bounds,
     .meaning = "Surveillance volume in the world frame (m): `{min: [x, y, z], max: [x, y, z]}`, "
                "max > min on every axis.",
     .required = true},
};

const Field<OctreeSettings> kOctreeFields[] = {
    {.key = "depth",
     .member = &OctreeSettings::depth,
     .meaning =
         "Levels of the octree; the finest cells are bounds / 2^depth (3 = the 8x8x8 roots).",
     .limits = {3, 16}},
    {.key = "boundary_coarsening",
     .member = &OctreeSettings::boundary_coarsening,
     .meaning = "Boxes mixed only through static geometry (view edges, obstacle depth) stop this "
                "many levels above depth, as occupied-when-seen leaves; at most depth - 3 (the "
                "roots). 0 resolves them exactly.",
     .limits = {0, 16}},
    {.key = "knowledge_filter_m3",
     .member = &OctreeSettings::knowledge_filter_m3,
     .meaning = "Knowledge filter on the published grid: a 26-connected blob of occupied cells "
                "smaller than this volume (m^3) is dropped (reported free) unless it touches "
                "occluded space or a face of the bounds, where it may be part of something "
                "larger. 0 turns it off; it frees space the cameras did not certify, so set it "
                "only where such blobs are known noise. Above 0.02 m^3 (a small child) hullguardd "
                "warns at start and --check-config.",
     .limits = {0, kInf}},
    {.key = "publish_depth",
     .member = &OctreeSettings::publish_depth,
     .meaning = "Resolution of the published occupancy grid: 2^publish_depth cells per axis, at "
                "most depth. A published cell is occupied when any leaf inside it is.",
     .limits = {1, 10}},
    {.key = "coarse_first_depth",
     .member = &OctreeSettings::coarse_first_depth,
     .meaning = "0: off. Otherwise a level below depth (a default at or above a shallow depth "
                "turns off): each cycle first brings the octree up to "
                "date down to this level, then refines one level per pass down to the tracking "
                "voxel's level and two per pass below it, so a cycle that hits "
                "its deadline still publishes a result as fine as its last completed pass "
                "everywhere (unrefined cells read occupied) instead of whole unvisited regions. "
                "A complete cycle gives the same result.",
     .limits = {0, 16}},
    {.key = "max_nodes",
     .member = &OctreeSettings::max_nodes,
     .meaning = "Octree nodes reserved at start, 24 bytes each (memory is committed as nodes are "
                "used), so that no cycle allocates. 0: the full tree of this depth, at most 8 Mi "
                "(192 MiB; the paper cell at depth 10 uses about 1.5 Mi). A cycle that needs more "
                "leaves the nodes it cannot split occupied and the status degraded (`node store "
                "full` in the health line) until people leave space.",
     .limits = {0, 500'000'000},
     .default_doc = "from the depth"},
};

const Field<MotionConfig> kMotionFields[] = {
    {.key = "max_speed_mps",
     .member = &MotionConfig::max_speed_mps,
     .meaning = "Fastest any part of a person moves (m/s): not the walking speed (ISO 13855's "
                "2 m/s) but that of the swinging feet (up to three times the walking speed) and "
                "of quick hands. Cameras capture at different instants; a camera whose frame is "
                "older (or newer) than the instant that stamps the occupancy certifies a box free "
                "only where it saw background, in its view and in front of the obstacles, "
                "everywhere within the distance covered meanwhile. A part faster than this may "
                "reach out of the occupancy by the excess times the skew. 0 assumes synchronised "
                "cameras. With `sim` cameras, hullguardd warns at start (and --check-config) when "
                "a person of the scene moves a part faster.",
     .limits = {0, 20}},
    {.key = "min_camera_distance_m",
     .member = &MotionConfig::min_camera_distance_m,
     .meaning = "Ignored; accepted so that older configs still load. The skew compensation "
                "used to assume people this far from every camera; it now holds at any "
                "distance.",
     .limits = {0.05, 100}},
    {.key = "stamp_at_median",
     .member = &MotionConfig::stamp_at_median,
     .meaning = "Stamp the occupancy with the median of the cameras' capture times instead of "
                "the newest. The cameras that captured at that instant then need no growth, only "
                "the others do: less occupied space when most cameras capture together and a few "
                "drift, at the cost of up to half the skew in the occupancy's age (latency)."},
};

const Field<TimingConfig> kTimingFields[] = {
    {.key = "rate_hz",
     .member = &TimingConfig::rate_hz,
     .meaning = "Fusion rate: octree updates per second.",
     .limits = {1, 1000}},
    {.key = "deadline_ms",
     .member = &TimingConfig::deadline_ms,
     .meaning = "Anytime deadline of one octree update; must be < 1000 / rate_hz. Branches not "
                "updated in time are reported not free.",
     .limits = {0, kInf, true}},
    {.key = "camera_timeout_ms",
     .member = &TimingConfig::camera_timeout_ms,
     .meaning = "A camera without a frame for this long counts as seeing nothing.",
     .limits = {1, kInf}},
    {.key = "align_to_frames",
     .member = &TimingConfig::align_to_frames,
     .meaning = "Phase-lock the cycle to the cameras' frames: the period stays 1000 / rate_hz, "
                "but its phase moves (at most 2 ms per cycle) until each cycle starts just after "
                "the last frame of a capture instant is ready, instead of at the phase the daemon "
                "happened to start with, which can cost up to a period of latency and skew. "
                "Cameras at another rate than the cycle leave it as it is."},
    {.key = "align_margin_ms",
     .member = &TimingConfig::align_margin_ms,
     .meaning = "With align_to_frames: the cycle aims to start this long plus twice the measured "
                "jitter after the last frame of a capture instant is usually ready.",
     .limits = {0, kInf}},
};

const Field<ThreadsConfig> kThreadsFields[] = {
    {.key = "octree",
     .member = &ThreadsConfig::octree,
     .meaning = "Threads of the octree update (the fusion thread included).",
     .limits = {1, 64}},
    {.key = "silhouette_workers",
     .member = &ThreadsConfig::silhouette_workers,
     .meaning = "Threads that turn frames into silhouettes (background model, undistortion); "
                "0 = one per camera. N > 0 shares N threads among all cameras, each taking the "
                "cameras' newest frames in turn; a camera whose frames come faster than they are "
                "processed skips to its newest (counted as drops).",
     .limits = {0, 64}},
    {.key = "realtime_priority",
     .member = &ThreadsConfig::realtime_priority,
     .meaning = "SCHED_FIFO priority of the fusion thread, so that other work cannot delay its "
                "cycle; 0 keeps normal scheduling. The unit allows up to 20 (LimitRTPRIO); where "
                "the system refuses it, the daemon logs a warning and runs unprioritised.",
     .limits = {0, 99}},
};

/// The camera block, read by geometry::ParseCamera; listed here for the split
/// of a camera entry and for the reference.
struct CameraBlockKey {
  const char* key;
  const char* type;
  const char* default_value;
  const char* meaning;
};
const CameraBlockKey kCameraBlockKeys[] = {
    {"name", "string", "required", "Unique camera name."},
    {"width", "integer", "1920", "Image width (pixels), 1 .. 65535."},
    {"height", "integer", "1080", "Image height (pixels), 1 .. 65535."},
    {"K", "9 numbers", "required (unless P)",
     "Intrinsics, row-major, last row 0 0 1; focal lengths 1 .. 1e6 px, at most 10 times apart; "
     "skew at most fx; principal point within an image size of the image, and the image at most "
     "100 focal lengths from it."},
    {"distortion", "5 numbers", "0 0 0 0 0", "OpenCV k1 k2 p1 p2 k3."},
    {"R", "9 numbers", "-", "World-to-camera rotation, row-major; with t."},
    {"t", "3 numbers", "-", "World-to-camera translation (m); with R."},
    {"position", "3 numbers", "-", "Camera centre in the world (m); with look_at instead of R, t."},
    {"look_at", "3 numbers", "-", "A world point on the optical axis (m); with position."},
    {"up", "3 numbers", "+z", "World direction shown upwards in the image; with position."},
    {"P", "12 numbers", "-", "3x4 projection, row-major, any scale; instead of K, R, t."},
};

const Field<CameraConfig> kCameraFields[] = {
    {.key = "timeout_ms",
     .member = &CameraConfig::timeout_ms,
     .meaning = "Overrides timing.camera_timeout_ms for this camera.",
     .limits = {1, kInf},
     .default_doc = "timing.camera_timeout_ms"},
};

const Field<SimSourceConfig> kSimFields[] = {
    {.key = "scene",
     .member = &SimSourceConfig::scene,
     .meaning = "Scene file (docs/scenes.md), relative to the config file. It must load and "
                "define the camera, and the camera block must be that camera's: the same width "
                "and height, and K, distortion and pose to 1e-9 relative.",
     .required = true,
     .path = PathCheck::kFile},
    {.key = "camera",
     .member = &SimSourceConfig::camera,
     .meaning = "Camera of the scene whose frames are rendered.",
     .default_doc = "the camera's name"},
    {.key = "stop_after_s",
     .member = &SimSourceConfig::stop_after_s,
     .meaning = "Fault injection: the camera stops delivering frames this many seconds after "
                "start, as one whose cable is pulled.",
     .limits = {0, kInf},
     .default_doc = "never"},
    {.key = "colour",
     .member = &SimSourceConfig::colour,
     .meaning = "Deliver colour frames, which go through the background model, instead of "
                "ground-truth masks: the empty cell rendered once, the people painted into it "
                "from their masks with sensor noise (no light changes or shadows; cheap enough "
                "for 8 Full HD cameras at 30 Hz). The people appear only after 2 * "
                "background.learn_frames frames plus 1 s of scene time, and not before every "
                "colour camera's background model has learned the cell empty (a slow start-up "
                "would otherwise have the models learn the people in)."},
    {.key = "bayer",
     .member = &SimSourceConfig::bayer,
     .meaning = "Colour frames (implies `colour`) delivered as the raw BayerRG8 mosaic, one byte "
                "per pixel, as a GigE colour camera sends them and the `aravis` source passes "
                "them on (its `debayer: false`): the background model works per photosite."},
};

const Field<ReplaySourceConfig> kReplayFields[] = {
    {.key = "directory",
     .member = &ReplaySourceConfig::directory,
     .meaning = "Recording folder (`hullguard record`, black box or `hullguard synth`), relative "
                "to the config file. Opened at validation: its manifest must read, hold the "
                "camera, and the camera's first frame must load at the camera block's size.",
     .required = true,
     .path = PathCheck::kDirectory},
    {.key = "camera",
     .member = &ReplaySourceConfig::camera,
     .meaning = "Camera of the recording whose frames are played.",
     .default_doc = "the camera's name"},
    {.key = "realtime",
     .member = &ReplaySourceConfig::realtime,
     .meaning = "Play frames at their recorded capture times; false delivers every frame as soon "
                "as the capture thread asks, stamped on delivery (load tests; `hullguard replay` "
                "is the deterministic fast replay)."},
    {.key = "preload",
     .member = &ReplaySourceConfig::preload,
     .meaning = "Read and decode every frame of the camera into memory at start-up (width x "
                "height bytes per frame, three times that for RGB; the log states the total); "
                "frames are then delivered by a copy, without disk or decoder; refused at load "
                "when they need more than half of the machine's memory. For soak runs and for "
                "load tests of the daemon's own cost."},
    {.key = "loop",
     .member = &ReplaySourceConfig::loop,
     .meaning = "After the last frame play again from the frame at `loop_start_s`, for ever; "
                "capture times go on increasing (each repetition one loop length later, the "
                "loop length being from that frame to one frame interval after the last; "
                "looping cameras share the longest, so they stay in step). For load and soak "
                "tests: at each repetition's start the scene jumps."},
    {.key = "loop_start_s",
     .member = &ReplaySourceConfig::loop_start_s,
     .meaning = "With `loop`: recording time (s) at which each repetition after the first "
                "starts, so that a stretch of empty cell at the beginning, which the background "
                "model learns from, is played once. At least two frames must follow it.",
     .limits = {0, 2592000}},
};

const Field<AravisSourceConfig> kAravisFields[] = {
    {.key = "device",
     .member = &AravisSourceConfig::device,
     .meaning = "Serial number, device name or IP address of the camera.",
     .required = true},
    {.key = "pixel_format",
     .member = &AravisSourceConfig::pixel_format,
     .meaning = "Pixel format requested from the camera."},
    {.key = "debayer",
     .member = &AravisSourceConfig::debayer,
     .meaning = "Bayer formats only: convert the mosaic to RGB before the background model. "
                "By default the raw mosaic goes to the model, which then works per photosite: "
                "a third of the bytes of RGB and no interpolation, each photosite compared in "
                "its own colour (the foreground dilation, `background.dilate_px` >= 1, fills "
                "the sites of the other colours)."},
    {.key = "exposure_us",
     .member = &AravisSourceConfig::exposure_us,
     .meaning = "Exposure time (us); unset keeps the camera's setting.",
     .limits = {0, 10'000'000, true},
     .default_doc = "camera's"},
    {.key = "gain_db",
     .member = &AravisSourceConfig::gain_db,
     .meaning = "Analog gain (dB); unset keeps the camera's setting.",
     .limits = {0, 60},
     .default_doc = "camera's"},
    {.key = "frame_rate_hz",
     .member = &AravisSourceConfig::frame_rate_hz,
     .meaning = "Acquisition frame rate; unset keeps the camera's setting.",
     .limits = {0, 1000, true},
     .default_doc = "camera's"},
    {.key = "trigger",
     .member = &AravisSourceConfig::trigger,
     .meaning = "Acquisition trigger: free running, software or hardware (line) trigger."},
    {.key = "packet_size",
     .member = &AravisSourceConfig::packet_size,
     .meaning = "GigE Vision stream packet size (bytes); unset negotiates it.",
     .limits = {576, 16384},
     .default_doc = "negotiated"},
    {.key = "socket_buffer_bytes",
     .member = &AravisSourceConfig::socket_buffer_bytes,
     .meaning = "Receive socket buffer of the stream (bytes); unset keeps the system default.",
     .limits = {4096, 1 << 30},
     .default_doc = "system's"},
};

const Field<V4l2SourceConfig> kV4l2Fields[] = {
    {.key = "device",
     .member = &V4l2SourceConfig::device,
     .meaning = "Device node, /dev/videoN.",
     .required = true},
    {.key = "format",
     .member = &V4l2SourceConfig::format,
     .meaning = "Capture format requested from the driver."},
    {.key = "frame_rate_hz",
     .member = &V4l2SourceConfig::frame_rate_hz,
     .meaning = "Frame rate; unset keeps the driver's setting.",
     .limits = {0, 1000, true},
     .default_doc = "driver's"},
    {.key = "exposure",
     .member = &V4l2SourceConfig::exposure,
     .meaning = "exposure_time_absolute (units of 100 us); unset keeps auto exposure.",
     .limits = {1, 100'000},
     .default_doc = "auto"},
};

const Field<BackgroundConfig> kBackgroundFields[] = {
    {.key = "learn_frames",
     .member = &BackgroundConfig::learn_frames,
     .meaning = "Frames averaged into the background model before the first mask.",
     .limits = {1, 10'000}},
    {.key = "threshold",
     .member = &BackgroundConfig::threshold,
     .meaning = "A pixel differing from the model by at least this (grey levels, in some "
                "channel; and by at least noise_sigmas times its learned noise) is foreground. "
                "Each level more lets more of a person whose colour is near the background's "
                "through (docs/cameras.md: what the background model cannot see).",
     .limits = {1, 255}},
    {.key = "adapt_rate",
     .member = &BackgroundConfig::adapt_rate,
     .meaning = "Per-frame weight with which background pixels update the model; 0 freezes it.",
     .limits = {0, 0.25}},
    {.key = "shadows_are_foreground",
     .member = &BackgroundConfig::shadows_are_foreground,
     .meaning = "Count shadows as foreground (conservative: a shadow may hide a person's edge). "
                "false takes a pixel darker than the background by a shadow's ratio, with its "
                "colour, for a shadow and background: a person's dark clothes too (any colour on "
                "grey or raw Bayer cameras); hullguardd warns at start and --check-config."},
    {.key = "noise_sigmas",
     .member = &BackgroundConfig::noise_sigmas,
     .meaning = "A pixel's threshold is at least this many times its noise (sigma) learned at "
                "start-up.",
     .limits = {0, 100}},
    {.key = "max_threshold",
     .member = &BackgroundConfig::max_threshold,
     .meaning = "Pixels whose threshold would exceed this (flicker, a monitor in view) are always "
                "foreground: nothing can be certified free there.",
     .limits = {1, 255}},
    {.key = "texture_threshold",
     .member = &BackgroundConfig::texture_threshold,
     .meaning = "A pixel is also foreground where its texture differs from the background's, "
                "that is where the difference of its two neighbours along the row or the column "
                "(in some channel, for colour frames) differs from the background's by at least "
                "this (grey levels, scaled like brightness differences in dim light), and by at "
                "least noise_sigmas times their learned noise. A person whose colour or grey "
                "matches the background behind them still hides its texture. 0: off (brightness "
                "alone). Raw Bayer mosaics (their photosites' colours tell) are not tested so.",
     .limits = {0, 255}},
    {.key = "guard_px",
     .member = &BackgroundConfig::guard_px,
     .meaning = "The model adapts only this far (pixels) or farther from any foreground pixel, so "
                "a person it has seen, standing still, is never absorbed (docs/cameras.md: what "
                "the background model cannot see).",
     .limits = {0, 1000}},
    {.key = "compensate_gain",
     .member = &BackgroundConfig::compensate_gain,
     .meaning = "Follow global light changes: one gain per frame, estimated from background "
                "pixels, scales the model before comparing."},
    {.key = "dilate_px",
     .member = &BackgroundConfig::dilate_px,
     .meaning = "The foreground is grown by this many pixels, so that a person's pixel whose "
                "colour matches the background is covered by its neighbours. Half of it (at "
                "least 1 px) is the shift of a camera's view tolerated before its frames stop "
                "being used (docs/cameras.md, a camera that moved).",
     .limits = {0, 50}},
    {.key = "fill_holes",
     .member = &BackgroundConfig::fill_holes,
     .meaning = "After the dilation, background that the foreground encloses (no path of "
                "background pixels leads from it to the image border) becomes foreground: the "
                "inside of a person whose clothes match the background over more than the "
                "dilation. Only adds foreground."},
    {.key = "keep_dir",
     .member = &BackgroundConfig::keep_dir,
     .meaning = "Folder (relative to the config file) where each camera's learned background is "
                "kept across restarts, as background-<camera>.bin; empty: every start learns. A "
                "camera whose file is there and fits takes it up instead of learning, so a person "
                "in the cell when the daemon restarts stays foreground; one that learns writes its "
                "file when learning ends (making the folder if missing). The cell must be empty "
                "when a camera learns. To learn "
                "again, remove the files while the daemon is stopped, or teach with "
                "`hullguardd --config FILE --learn-background`."},
    {.key = "learn_at_start",
     .member = &BackgroundConfig::learn_at_start,
     .meaning = "A camera that has no kept background to take up (keep_dir) learns the cell from "
                "its first frames. false (needs keep_dir): it learns nothing and sees nothing "
                "(status `failed (unlearned)`, degraded) until a background is taught with the "
                "cell empty, `hullguardd --config FILE --learn-background`; a restart then never "
                "learns whoever stands in the cell. The safe setting for a service."},
};

const Field<ObstacleConfig> kObstacleFields[] = {
    {.key = "file",
     .member = &ObstacleConfig::file,
     .meaning = "Static obstacle mesh (.obj or .stl, world frame, m), relative to the config "
                "file; loaded at validation and must have triangles.",
     .required = true,
     .path = PathCheck::kFile},
};

const Field<DdsConfig> kDdsFields[] = {
    {.key = "domain_id",
     .member = &DdsConfig::domain_id,
     .meaning = "DDS domain.",
     .limits = {0, 232}},
    {.key = "topic_prefix",
     .member = &DdsConfig::topic_prefix,
     .meaning = "Prefix of every topic name (`<prefix>/occupancy`, ...): letters, digits and "
                "`_`, names joined by `/`, not starting with a digit."},
    {.key = "enabled",
     .member = &DdsConfig::enabled,
     .meaning = "Publish on DDS; false runs with the null publisher."},
};

const Field<LoggingConfig> kLoggingFields[] = {
    {.key = "level",
     .member = &LoggingConfig::level,
     .meaning = "Least severe level logged. The health line comes once a second, at info while "
                "all is well and at warn while degraded; stalls and failed black-box dumps are "
                "errors."},
    {.key = "journald",
     .member = &LoggingConfig::journald,
     .meaning = "Log to the systemd journal (entries with their priority, "
                "SYSLOG_IDENTIFIER=hullguardd) instead of stderr. Under systemd stderr reaches "
                "the journal too, as plain lines at one priority."},
};

const Field<TrackingConfig> kTrackingFields[] = {
    {.key = "enabled",
     .member = &TrackingConfig::enabled,
     .meaning = "Track people on the occupancy and publish `<prefix>/tracks`. Tracking runs in "
                "its own thread on the newest snapshot and never delays the occupancy."},
    {.key = "voxel_m",
     .member = &TrackingConfig::voxel_m,
     .meaning = "Edge of the tracking voxels (m) over cell.bounds: 24 bytes per voxel, at most "
                "50 million voxels. Above about 0.25 m a person is a handful of voxels and no "
                "track starts (measured on the shipped scenes: 0.3 m already loses people).",
     .limits = {0.01, 0.25}},
    {.key = "particles",
     .member = &TrackingConfig::particles,
     .meaning = "Particles per track (each an ellipsoid); the cost of a cycle grows with it. "
                "Fewer than 10 lose people (1 gave ghost tracks and id switches).",
     .limits = {10, 100'000}},
    {.key = "max_tracks",
     .member = &TrackingConfig::max_tracks,
     .meaning = "Tracks held at most (their filters are allocated at start-up); more people get "
                "no track, their space stays occupied.",
     .limits = {1, 1024}},
    {.key = "rho_unknown",
     .member = &TrackingConfig::rho_unknown,
     .meaning = "Likelihood score (rho) of an occupied voxel inside a particle's ellipsoid: the "
                "evidence of a person.",
     .limits = {0, kInf, true}},
    {.key = "sigma_occluded",
     .member = &TrackingConfig::sigma_occluded,
     .meaning = "Score (sigma) of a voxel no camera sees past the obstacles: a person may hide "
                "there."},
    {.key = "tau_known",
     .member = &TrackingConfig::tau_known,
     .meaning = "Score (tau) of a voxel inside an obstacle."},
    {.key = "epsilon_free",
     .member = &TrackingConfig::epsilon_free,
     .meaning = "Score (epsilon) of a voxel seen empty."},
    {.key = "below_floor_weight",
     .member = &TrackingConfig::below_floor_weight,
     .meaning = "Score of lattice positions below cell.bounds (taken as the floor); 0 when the "
                "bounds start above the floor."},
    {.key = "support_reach_m",
     .member = &TrackingConfig::support_reach_m,
     .meaning = "An obstacle top under a particle's centre is that particle's floor (below it "
                "everything scores as below_floor_weight, the obstacle too) when it lies at most "
                "this far above the ellipsoid's bottom: a person standing on a table is tracked "
                "at her height, not pushed up by the table top. 0: the cell's floor only.",
     .limits = {0, kInf}},
    {.key = "posture_noise_m_per_sqrt_s",
     .member = &TrackingConfig::posture_noise_m_per_sqrt_s,
     .meaning = "Diffusion of a particle's top with its bottom fixed (m per square root of a "
                "second): how fast the filter follows a person crouching, lying down or getting "
                "up. 0: the centre and the vertical half-axis diffuse independently only.",
     .limits = {0, kInf}},
    {.key = "collision_radius_m",
     .member = &TrackingConfig::collision_radius_m,
     .meaning = "Radius of the capsule a particle sweeps from its previous centre; particles "
                "whose capsule touches an obstacle are replaced. At most 0.2 (the smallest "
                "horizontal half-axis of a person).",
     .limits = {0, kInf}},
    {.key = "birth_min_volume_m3",
     .member = &TrackingConfig::birth_min_volume_m3,
     .meaning = "A connected occupied component outside every track starts a track when at least "
                "this large.",
     .limits = {0, kInf, true}},
    {.key = "birth_min_height_m",
     .member = &TrackingConfig::birth_min_height_m,
     .meaning = "People come in standing: a new track is a person's when its evidence has a "
                "head's cross-section at this height above the floor; otherwise it is an object "
                "track (a parcel), followed but not published. 0: every track is a person's.",
     .limits = {0, kInf}},
    {.key = "birth_max_skew_ms",
     .member = &TrackingConfig::birth_max_skew_ms,
     .meaning = "Tracks start only from a whole cycle: every camera ok, the update refined to "
                "the tracking voxel, and frames captured at most this far apart, with no "
                "margin still held from a wider gap (the cameras of other instants certify less "
                "free, by the motion meanwhile, which leaves person-sized blobs where nobody "
                "is). Tracks follow their people through every cycle.",
     .limits = {0, kInf}},
    {.key = "death_timeout_s",
     .member = &TrackingConfig::death_timeout_s,
     .meaning = "A visible track dies after this long without occupied voxels in its ellipsoid.",
     .limits = {0, kInf, true}},
    {.key = "occluded_death_timeout_s",
     .member = &TrackingConfig::occluded_death_timeout_s,
     .meaning = "The same for a track mostly where no camera sees (a person under a table).",
     .limits = {0, kInf, true}},
    {.key = "reacquire_radius_m",
     .member = &TrackingConfig::reacquire_radius_m,
     .meaning = "A new component this near a track without support (plus reacquire_speed_mps "
                "times its time without support) is taken as that person back: it keeps the id.",
     .limits = {0, kInf}},
    {.key = "reacquire_speed_mps",
     .member = &TrackingConfig::reacquire_speed_mps,
     .meaning = "Speed at which the re-acquisition radius grows while a track has no support, "
                "for at most death_timeout_s: a track hidden longer is not handed to someone who "
                "appears farther away (with the defaults, 2 m).",
     .limits = {0, kInf}},
};

const Field<BlackBoxConfig> kBlackBoxFields[] = {
    {.key = "seconds",
     .member = &BlackBoxConfig::seconds,
     .meaning = "Seconds of every camera's frames kept in memory (a ring per camera, allocated "
                "at start-up); 0 turns the black box off.",
     .limits = {0, 3600}},
    {.key = "dir",
     .member = &BlackBoxConfig::dir,
     .meaning = "Each dump is a recording (docs/cameras.md) in dir/<UTC time>/; relative to the "
                "config file, created when missing."},
    {.key = "on_degraded",
     .member = &BlackBoxConfig::on_degraded,
     .meaning = "Dump when the status turns from ok to degraded; SIGUSR1 always dumps."},
    {.key = "max_memory_mb",
     .member = &BlackBoxConfig::max_memory_mb,
     .meaning = "Memory allowed (MiB) for the rings and the copies of them of two dumps in "
                "flight (one written, the next copied meanwhile): three times the rings; a "
                "longer history is refused at load.",
     .limits = {1, 100000}},
    {.key = "camera_rate_hz",
     .member = &BlackBoxConfig::camera_rate_hz,
     .meaning = "Frame rate the rings are sized for where the config does not fix it (aravis and "
                "v4l2 without frame_rate_hz; sim and replay use their scene's or recording's); a "
                "faster camera keeps a shorter history.",
     .limits = {0, 1000, true}},
};

/// Top-level keys.
struct Section {
  const char* key;
  const char* type;
  bool required;
  const char* meaning;
};
const Section kSections[] = {
    {"cell", "map", true, "The surveillance volume."},
    {"octree", "map", false, "Octree resolution and filtering."},
    {"timing", "map", false, "Fusion rate, deadline and camera timeout."},
    {"threads", "map", false, "Thread counts."},
    {"motion", "map", false, "How fast people move (capture-skew compensation)."},
    {"cameras", "list", true, "The cameras: calibration and source of each."},
    {"background", "map", false, "Background model of the silhouette stage."},
    {"obstacles", "list", false, "Static obstacle meshes."},
    {"dds", "map", false, "DDS publishing."},
    {"logging", "map", false, "Log level and destination."},
    {"blackbox", "map", false, "Black-box recorder: the last seconds of every camera."},
    {"tracking", "map", false, "Human tracking and its DDS topic."},
};

template <typename S>
std::vector<std::string> KeysOf(std::span<const Field<S>> fields) {
  std::vector<std::string> keys;
  for (const Field<S>& f : fields) keys.emplace_back(f.key);
  return keys;
}

// ---------------------------------------------------------------------------
// The reader.

/// One value of the file with its key path and the line reported for it (the
/// key's line for a map entry, the element's line for a list element).
struct Item {
  YAML::Node key;  ///< The key node for a map entry; undefined for a list element.
  YAML::Node value;
  std::string path;
  int line = 0;
};

using Entries = std::map<std::string, Item>;

std::string Join(const std::string& prefix, const std::string& key) {
  return prefix.empty() ? key : prefix + "." + key;
}

/// Reads a config tree, recording every problem instead of stopping at the first.
/// Single-thread.
class Reader {
 public:
  Reader(std::string file, fs::path base_dir)
      : file_(std::move(file)), base_dir_(std::move(base_dir)) {}

  [[nodiscard]] const std::string& file() const { return file_; }
  [[nodiscard]] std::size_t error_count() const { return errors_.size(); }
  [[nodiscard]] const fs::path& base_dir() const { return base_dir_; }

  void Error(int line, const std::string& path, const std::string& problem) {
    errors_.emplace_back(
        line, ConfigError::At(file_, line, path.empty() ? problem : path + ": " + problem).what());
  }

  /// Throws one ConfigError listing every recorded problem, ordered by line.
  void ThrowIfErrors() {
    if (errors_.empty()) return;
    std::stable_sort(errors_.begin(), errors_.end(),
                     [](const auto& a, const auto& b) { return a.first < b.first; });
    std::string message;
    for (const auto& [line, text] : errors_) {
      message += (message.empty() ? "" : "\n") + text;
    }
    throw ConfigError(message);
  }

  /// The entries of a map; records a non-map, non-string keys, duplicates and
  /// keys outside `known`. An absent (undefined) node gives no entries.
  Entries Map(const Item& item, const std::vector<std::string>& known) {
    Entries out;
    if (!item.value.IsDefined()) return out;
    if (!item.value.IsMap()) {
      Error(item.line, item.path, "expected a map");
      return out;
    }
    for (const auto& kv : item.value) {
      const int line = common::YamlLine(kv.first);
      if (!kv.first.IsScalar()) {
        Error(line, item.path, "keys must be strings");
        continue;
      }
      const std::string& key = kv.first.Scalar();
      const std::string path = Join(item.path, key);
      if (key == "<<") {
        Error(line, item.path, common::kMergeKeyText);
        continue;
      }
      if (std::find(known.begin(), known.end(), key) == known.end()) {
        Error(line, item.path,
              "unknown key '" + key + "'" +
                  (known.empty() ? "" : " (expected " + OrList(known) + ")"));
        continue;
      }
      const auto [it, inserted] = out.emplace(key, Item{kv.first, kv.second, path, line});
      if (!inserted) {
        Error(line, path, "duplicate key (first at line " + std::to_string(it->second.line) + ")");
      }
    }
    return out;
  }

  /// The elements of a list; records a non-list.
  std::vector<Item> List(const Item& item) {
    std::vector<Item> out;
    if (!item.value.IsSequence()) {
      Error(item.line, item.path, "expected a list");
      return out;
    }
    for (std::size_t i = 0; i < item.value.size(); ++i) {
      const YAML::Node element = item.value[i];
      const int line = common::YamlLine(element);
      out.push_back(Item{YAML::Node(), element, item.path + "[" + std::to_string(i) + "]",
                         line >= 1 ? line : item.line});
    }
    return out;
  }

  /// Reads the fields present in `entries` into `out` and records missing
  /// required ones (`parent` is the map holding them).
  template <typename S>
  void Fields(std::span<const Field<S>> fields, const Entries& entries, const Item& parent,
              S* out) {
    for (const Field<S>& f : fields) {
      const auto it = entries.find(f.key);
      if (it == entries.end()) {
        if (f.required) Error(parent.line, parent.path, std::string("missing key '") + f.key + "'");
        continue;
      }
      ReadField(f, it->second, out);
    }
  }

  // A quoted scalar ("7") is a string in YAML, whatever it spells.
  static bool Plain(const Item& item) { return item.value.IsScalar() && item.value.Tag() != "!"; }

  std::optional<double> Number(const Item& item, const Limits& limits) {
    double value = 0.0;
    bool ok = Plain(item);
    if (ok) {
      try {
        value = item.value.as<double>();
      } catch (const YAML::Exception&) {
        ok = false;
      }
    }
    if (!ok || !std::isfinite(value)) {
      Error(item.line, item.path, "expected a number" + Got(item));
      return std::nullopt;
    }
    return CheckRange(item, value, limits) ? std::optional<double>(value) : std::nullopt;
  }

  std::optional<int> Integer(const Item& item, const Limits& limits) {
    long long value = 0;
    bool ok = Plain(item);
    if (ok) {
      const std::string& text = item.value.Scalar();
      const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
      ok = !text.empty() && ec == std::errc() && end == text.data() + text.size() &&
           value >= std::numeric_limits<int>::min() && value <= std::numeric_limits<int>::max();
    }
    if (!ok) {
      Error(item.line, item.path, "expected an integer" + Got(item));
      return std::nullopt;
    }
    return CheckRange(item, static_cast<double>(value), limits)
               ? std::optional<int>(static_cast<int>(value))
               : std::nullopt;
  }

  std::optional<bool> Bool(const Item& item) {
    // YAML 1.2's spellings only: yes, on, y and friends (YAML 1.1) are
    // strings there, and a typo's reading should not depend on the version.
    bool value = false;
    bool ok = Plain(item);
    if (ok) {
      const std::string& text = item.value.Scalar();
      value = text == "true" || text == "True" || text == "TRUE";
      ok = value || text == "false" || text == "False" || text == "FALSE";
    }
    if (!ok) {
      Error(item.line, item.path, "expected true or false" + Got(item));
      return std::nullopt;
    }
    return value;
  }

  std::optional<std::string> String(const Item& item) {
    if (!item.value.IsScalar() || item.value.Scalar().empty()) {
      Error(item.line, item.path, "expected a non-empty string");
      return std::nullopt;
    }
    return item.value.Scalar();
  }

  template <typename E>
  std::optional<E> Enum(const Item& item, const std::string& noun) {
    const std::optional<std::string> text = String(item);
    if (!text) return std::nullopt;
    for (const auto& [v, name] : Names(E{})) {
      if (*text == name) return v;
    }
    Error(item.line, item.path,
          "unknown " + noun + " '" + *text + "' (expected " + OrList(NameList<E>()) + ")");
    return std::nullopt;
  }

  /// A path relative to the config's folder, resolved; records a missing file or folder.
  std::optional<std::string> Path(const Item& item, PathCheck check) {
    const std::optional<std::string> text = String(item);
    if (!text) return std::nullopt;
    const fs::path resolved = (base_dir_ / *text).lexically_normal();
    std::error_code ec;
    if (check == PathCheck::kFile && !fs::is_regular_file(resolved, ec)) {
      const char* what = fs::is_directory(resolved, ec) ? "a folder, not a file: '"
                         : fs::exists(resolved, ec)
                             ? "not a regular file (a pipe, socket or device): '"
                             : "no such file '";
      Error(item.line, item.path, what + resolved.string() + "'");
      return std::nullopt;
    }
    if (check == PathCheck::kDirectory && !fs::is_directory(resolved, ec)) {
      Error(item.line, item.path, "no such directory '" + resolved.string() + "'");
      return std::nullopt;
    }
    return resolved.string();
  }

  std::optional<Eigen::Vector3d> Vector3(const Item& item) {
    if (!item.value.IsSequence() || item.value.size() != 3) {
      Error(item.line, item.path, "expected a list of 3 numbers");
      return std::nullopt;
    }
    Eigen::Vector3d v;
    bool ok = true;
    const std::vector<Item> elements = List(item);
    for (int i = 0; i < 3; ++i) {
      const std::optional<double> x = Number(elements[i], {});
      ok = ok && x.has_value();
      if (x) v[i] = *x;
    }
    return ok ? std::optional<Eigen::Vector3d>(v) : std::nullopt;
  }

  std::optional<common::Box3> Box(const Item& item) {
    const Entries e = Map(item, {"min", "max"});
    if (!item.value.IsMap()) return std::nullopt;
    common::Box3 box;
    bool ok = true;
    for (const char* key : {"min", "max"}) {
      const auto it = e.find(key);
      if (it == e.end()) {
        Error(item.line, item.path, std::string("missing key '") + key + "'");
        ok = false;
        continue;
      }
      const std::optional<Eigen::Vector3d> v = Vector3(it->second);
      if (!v) {
        ok = false;
      } else {
        (std::string(key) == "min" ? box.min : box.max) = *v;
      }
    }
    if (!ok) return std::nullopt;
    if (!box.IsValid()) {
      Error(e.at("max").line, e.at("max").path, "must exceed min on every axis");
      return std::nullopt;
    }
    if (!box.IsPlausibleCell()) {
      // The corner that lies out there is named.
      const char* key = box.min.cwiseAbs().maxCoeff() > common::kMaxCoordinateM ? "min" : "max";
      Error(e.at(key).line, e.at(key).path, "coordinates must be within +-1e6 m");
      return std::nullopt;
    }
    return box;
  }

 private:
  template <typename S>
  void ReadField(const Field<S>& f, const Item& item, S* out) {
    std::visit(
        [&](auto member) {
          if (member == nullptr) return;  // Never; keeps GCC's flow analysis quiet.
          auto& dst = out->*member;
          using T = std::remove_reference_t<decltype(dst)>;
          if constexpr (sizeof(T) > sizeof(S)) {
            // No S has such a member; not instantiating the read keeps GCC from
            // warning about a write past the end of S.
          } else if constexpr (std::is_same_v<T, int>) {
            if (const auto v = Integer(item, f.limits)) dst = *v;
          } else if constexpr (std::is_same_v<T, double>) {
            if (const auto v = Number(item, f.limits)) dst = *v;
          } else if constexpr (std::is_same_v<T, std::optional<int>>) {
            if (const auto v = Integer(item, f.limits)) dst = *v;
          } else if constexpr (std::is_same_v<T, std::optional<double>>) {
            if (const auto v = Number(item, f.limits)) dst = *v;
          } else if constexpr (std::is_same_v<T, bool>) {
            if (const auto v = Bool(item)) dst = *v;
          } else if constexpr (std::is_same_v<T, std::string>) {
            const auto v = f.path == PathCheck::kNone ? String(item) : Path(item, f.path);
            if (v) dst = *v;
          } else if constexpr (std::is_same_v<T, common::Box3>) {
            if (const auto v = Box(item)) dst = *v;
          } else {
            if (const auto v = Enum<T>(item, "value")) dst = *v;
          }
        },
        f.member);
  }

  bool CheckRange(const Item& item, double value, const Limits& limits) {
    const bool low_ok = limits.lo_open ? value > limits.lo : value >= limits.lo;
    if (low_ok && value <= limits.hi) return true;
    const bool two_sided = std::isfinite(limits.lo) && std::isfinite(limits.hi) && !limits.lo_open;
    Error(item.line, item.path,
          std::string(two_sided ? "must be in " : "must be ") + RangeText(limits) + Got(item));
    return false;
  }

  static std::string Got(const Item& item) {
    if (!item.value.IsScalar()) return "";
    return item.value.Tag() == "!" ? " (got the quoted string \"" + item.value.Scalar() + "\")"
                                   : " (got '" + item.value.Scalar() + "')";
  }

 public:
  /// "3 .. 16", ">= 0", "> 0".
  static std::string RangeText(const Limits& limits) {
    const bool has_lo = std::isfinite(limits.lo);
    const bool has_hi = std::isfinite(limits.hi);
    if (has_lo && has_hi && !limits.lo_open) {
      return FormatNumber(limits.lo) + " .. " + FormatNumber(limits.hi);
    }
    std::string out;
    if (has_lo) out = (limits.lo_open ? "> " : ">= ") + FormatNumber(limits.lo);
    if (has_hi) out += (out.empty() ? "<= " : ", <= ") + FormatNumber(limits.hi);
    return out;
  }

 private:
  std::string file_;
  fs::path base_dir_;
  std::vector<std::pair<int, std::string>> errors_;
};

// ---------------------------------------------------------------------------
// Sections.

template <typename S>
void ReadSection(Reader& r, const Entries& root, const char* key, std::span<const Field<S>> fields,
                 S* out) {
  const auto it = root.find(key);
  if (it == root.end()) return;
  const Entries e = r.Map(it->second, KeysOf(fields));
  r.Fields(fields, e, it->second, out);
}

/// Keys of the `tracking` section by the tracking::TrackerOptions path they set.
constexpr std::pair<const char*, const char*> kTrackerOptionKeys[] = {
    {"voxel_m", "voxel_m"},
    {"filter.num_particles", "particles"},
    {"max_tracks", "max_tracks"},
    {"likelihood.unknown", "rho_unknown"},
    {"likelihood.occluded", "sigma_occluded"},
    {"likelihood.known", "tau_known"},
    {"likelihood.free", "epsilon_free"},
    {"likelihood.below_floor", "below_floor_weight"},
    {"filter.support_reach_m", "support_reach_m"},
    {"filter.posture_noise_m_per_sqrt_s", "posture_noise_m_per_sqrt_s"},
    {"filter.collision_radius_m", "collision_radius_m"},
    {"birth_min_volume_m3", "birth_min_volume_m3"},
    {"birth_min_height_m", "birth_min_height_m"},
    {"birth_max_skew_ms", "birth_max_skew_ms"},
    {"death_timeout_s", "death_timeout_s"},
    {"occluded_death_timeout_s", "occluded_death_timeout_s"},
    {"reacquire_radius_m", "reacquire_radius_m"},
    {"reacquire_speed_mps", "reacquire_speed_mps"},
};

/// Most voxels of the tracking grid (24 bytes each: about 1.2 GB).
constexpr double kMaxTrackingVoxels = 50e6;

/// Checks of the `tracking` section that involve more than one key, on values
/// that were read: the tracker's own option checks (tracking::CheckOptions,
/// each problem at the line of the key it names) and, when tracking is on, the
/// size of its grid over the cell.
void CheckTracking(Reader& r, const Entries& sections, const Config& config) {
  int section_line = 0;
  std::map<std::string, int> lines;  // Key -> line of the key.
  if (const auto it = sections.find("tracking"); it != sections.end()) {
    section_line = it->second.line;
    if (it->second.value.IsMap()) {
      for (const auto& kv : it->second.value) {
        if (kv.first.IsScalar()) lines[kv.first.Scalar()] = common::YamlLine(kv.first);
      }
    }
  }
  auto line_of = [&](const std::string& key) {
    const auto at = lines.find(key);
    return at != lines.end() ? at->second : section_line;
  };
  const TrackingConfig& t = config.tracking;
  for (const tracking::OptionProblem& p :
       tracking::CheckOptions(MakeTrackerOptions(t, config.timing.rate_hz))) {
    const char* key = nullptr;
    for (const auto& [option, config_key] : kTrackerOptionKeys) {
      if (p.key == option) key = config_key;
    }
    if (key != nullptr) {
      r.Error(line_of(key), std::string("tracking.") + key, p.problem);
    } else {
      r.Error(section_line, "tracking", p.key + ": " + p.problem);
    }
  }
  if (t.enabled && config.cell.bounds.IsValid()) {
    const Eigen::Vector3d cells = (config.cell.bounds.Size() / t.voxel_m).array().ceil();
    if (cells.prod() > kMaxTrackingVoxels) {
      r.Error(line_of("voxel_m"), "tracking.voxel_m",
              FormatNumber(t.voxel_m) + " m gives " + FormatNumber(cells.prod()) +
                  " tracking voxels over cell.bounds; at most " + FormatNumber(kMaxTrackingVoxels) +
                  " (a larger voxel_m, or enabled: false)");
    }
  }
}

/// The black box's memory: its rings, sized from every camera's frame size,
/// kind and rate, plus two dumps' copies of them must fit max_memory_mb.
void CheckBlackBox(Reader& r, const Entries& sections, const Config& config) {
  int line = 0;
  if (const auto it = sections.find("blackbox"); it != sections.end()) {
    line = it->second.line;
    if (it->second.value.IsMap()) {
      for (const auto& kv : it->second.value) {
        if (kv.first.IsScalar() && kv.first.Scalar() == "seconds") {
          line = common::YamlLine(kv.first);
        }
      }
    }
  }
  const double seconds = config.blackbox.seconds;
  auto mib = [seconds](const std::vector<pipeline::BlackBoxCamera>& cameras) {
    return static_cast<double>(pipeline::BlackBoxBytes(cameras, seconds)) / (1024.0 * 1024.0);
  };
  try {
    const std::vector<pipeline::BlackBoxCamera> cameras = BlackBoxCameras(config);
    const double total = mib(cameras);
    if (pipeline::kBlackBoxMemoryFactor * total <= config.blackbox.max_memory_mb) return;
    const pipeline::BlackBoxCamera* largest = &cameras.front();
    for (const pipeline::BlackBoxCamera& c : cameras) {
      if (mib({c}) > mib({*largest})) largest = &c;
    }
    const geometry::CameraModel& m = largest->model;
    r.Error(line, "blackbox.seconds",
            FormatNumber(seconds) + " s of every camera need " + FormatNumber(std::round(total)) +
                " MiB of rings, three times that while two dumps copy them, more than "
                "blackbox.max_memory_mb = " +
                std::to_string(config.blackbox.max_memory_mb) + " (largest: " + m.name + " " +
                std::to_string(m.width) + "x" + std::to_string(m.height) + " " +
                capture::ToString(largest->kind) + " at " + FormatNumber(largest->rate_hz) +
                " Hz, " + FormatNumber(std::round(mib({*largest}))) + " MiB)");
  } catch (const ConfigError& e) {
    r.Error(line, "blackbox", std::string("cannot size the rings: ") + e.what());
  } catch (const YAML::Exception& e) {  // A recording's manifest read by yaml-cpp.
    r.Error(line, "blackbox", std::string("cannot size the rings: ") + e.what());
  }
}

/// Largest image side capture::V4l2Source accepts.
constexpr int kMaxV4l2Side = 16384;

/// Scenes of `sim` sources by resolved path, each loaded once; nullopt for
/// one that could not be loaded (its error is recorded once).
using SceneCache = std::map<std::string, std::optional<sim::Scene>>;

/// The whole scene at `scene_path` (sim::LoadScene: every key, its meshes),
/// loaded once per path; nullptr when it cannot be, its error (with the
/// scene's own file and line) recorded at the `scene` key that names it first.
const sim::Scene* LoadSceneOnce(Reader& r, SceneCache* scenes, const Item& scene_item,
                                const std::string& scene_path) {
  const auto [it, inserted] = scenes->try_emplace(scene_path);
  if (inserted) {
    try {
      it->second = sim::LoadScene(scene_path);
    } catch (const ConfigError& e) {
      r.Error(scene_item.line, scene_item.path, std::string("bad scene: ") + e.what());
    } catch (const YAML::Exception& e) {  // LoadScene reports ConfigError; this is defence.
      r.Error(scene_item.line, scene_item.path,
              "bad scene: " + scene_path + ": " + std::string(e.what()));
    }
  }
  return it->second ? &*it->second : nullptr;
}

/// The shortest text that reads back as `value`: a difference far beyond the
/// sixth digit still shows.
std::string ExactNumber(double value) {
  char buf[32];
  const auto [end, ec] = std::to_chars(buf, buf + sizeof(buf), value);
  return ec == std::errc() ? std::string(buf, end) : FormatNumber(value);
}

/// Relative tolerance of the comparison of a camera block with the camera of
/// a scene or a recording (both written to round-trip exactly): of the
/// largest entry of the matrix (at least 1), so that zeros compare absolutely.
constexpr double kSceneCameraTolerance = 1e-9;

/// "name[i] a here, b <there>" for the first entry of `a` and `b` that
/// differ by more than the tolerance; empty when none does.
std::string FirstDifference(const std::string& name, std::span<const double> a,
                            std::span<const double> b, const std::string& there) {
  double scale = 1.0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    scale = std::max({scale, std::abs(a[i]), std::abs(b[i])});
  }
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (std::abs(a[i] - b[i]) <= kSceneCameraTolerance * scale) continue;
    return name + "[" + std::to_string(i) + "] " + ExactNumber(a[i]) + " here, " +
           ExactNumber(b[i]) + " " + there;
  }
  return "";
}

/// A sim source renders the scene's camera (a replay source plays what a
/// recording's camera saw) while the pipeline projects with the config's
/// camera block: they must be the same camera, or every frame is the wrong
/// size (corrupt) or the silhouettes land in the wrong place (unsafe: a
/// person seen by one camera is carved with another's pose). Records each
/// difference at the config key that sets it. `of_scene` names the other
/// camera ("camera 'cam0' of scene 'x.yaml'"), `there` is where it is ("in
/// the scene").
void CheckSameCamera(Reader& r, const Item& entry, const Entries& e,
                     const geometry::CameraModel& config_camera,
                     const geometry::CameraModel& scene_camera, const std::string& of_scene,
                     const std::string& there) {
  auto error_at = [&](std::initializer_list<const char*> keys, const std::string& problem) {
    for (const char* key : keys) {
      if (const auto it = e.find(key); it != e.end()) {
        r.Error(it->second.line, it->second.path, problem);
        return;
      }
    }
    r.Error(entry.line, Join(entry.path, *keys.begin()), problem);
  };
  for (const auto& [key, mine, theirs] :
       {std::tuple{"width", config_camera.width, scene_camera.width},
        std::tuple{"height", config_camera.height, scene_camera.height}}) {
    if (mine != theirs) {
      error_at({key}, "is " + std::to_string(mine) + " but " + of_scene + " has " +
                          std::to_string(theirs) + ": every frame would be the wrong size");
    }
  }
  // Entries row-major, as the camera block writes them.
  auto values = [](const auto& m) {
    std::vector<double> out;
    for (int i = 0; i < m.rows(); ++i) {
      for (int j = 0; j < m.cols(); ++j) out.push_back(m(i, j));
    }
    return out;
  };
  const std::string k =
      FirstDifference("K", values(config_camera.K), values(scene_camera.K), there);
  const std::string d =
      FirstDifference("distortion", config_camera.distortion, scene_camera.distortion, there);
  const std::string rot =
      FirstDifference("R", values(config_camera.R_CW), values(scene_camera.R_CW), there);
  const std::string t =
      FirstDifference("t", values(config_camera.t_CW), values(scene_camera.t_CW), there);
  // Each difference at the key that sets it: K, R and t come from P in that
  // form, and the pose from position and look_at in that one.
  const std::string differs = "differs from " + of_scene + ": ";
  if (!k.empty()) error_at({"K", "P"}, differs + k);
  if (!d.empty()) error_at({"distortion"}, differs + d);
  if (e.count("R") != 0 || e.count("t") != 0) {
    if (!rot.empty()) error_at({"R"}, differs + rot);
    if (!t.empty()) error_at({"t"}, differs + t);
  } else if (!rot.empty() || !t.empty()) {
    error_at({"position", "P"}, "the pose " + differs +
                                    (rot.empty() ? t
                                     : t.empty() ? rot
                                                 : rot + "; " + t));
  }
}

}  // namespace

std::string RecordedCameraName(const CameraConfig& camera) {
  if (const auto* replay = std::get_if<ReplaySourceConfig>(&camera.source)) return replay->camera;
  return camera.model.name;
}

void CheckRecordingForConfig(const Config& config, const std::string& recording) {
  const std::string cameras_file = (std::filesystem::path(recording) / "cameras.yaml").string();
  if (!std::filesystem::is_regular_file(cameras_file)) {
    throw ConfigError("recording '" + recording +
                      "' has no cameras.yaml: the calibration its frames were taken with cannot "
                      "be checked against the config's cameras (hullguard synth and record "
                      "write one)");
  }
  const std::vector<geometry::CameraModel> recorded = geometry::LoadCamerasFile(cameras_file);
  std::vector<std::string> problems;
  for (std::size_t i = 0; i < config.cameras.size(); ++i) {
    const geometry::CameraModel& mine = config.cameras[i].model;
    const std::string name = RecordedCameraName(config.cameras[i]);
    const std::string which =
        "cameras[" + std::to_string(i) + "] '" + mine.name + "' (recorded '" + name + "'): ";
    const auto it = std::find_if(recorded.begin(), recorded.end(),
                                 [&](const auto& c) { return c.name == name; });
    if (it == recorded.end()) {
      problems.push_back(which + "not in the recording");
      continue;
    }
    if (mine.width != it->width || mine.height != it->height) {
      problems.push_back(which + "size " + std::to_string(mine.width) + "x" +
                         std::to_string(mine.height) + " in the config, " +
                         std::to_string(it->width) + "x" + std::to_string(it->height) +
                         " in the recording");
    }
    auto values = [](const auto& m) {
      std::vector<double> out;
      for (int r = 0; r < m.rows(); ++r) {
        for (int c = 0; c < m.cols(); ++c) out.push_back(m(r, c));
      }
      return out;
    };
    for (const std::string& d :
         {FirstDifference("K", values(mine.K), values(it->K), "in the recording"),
          FirstDifference("distortion", mine.distortion, it->distortion, "in the recording"),
          FirstDifference("R", values(mine.R_CW), values(it->R_CW), "in the recording"),
          FirstDifference("t", values(mine.t_CW), values(it->t_CW), "in the recording")}) {
      if (d.empty()) continue;
      std::string problem = d;
      if (const auto at = problem.find(" here, "); at != std::string::npos) {
        problem.replace(at, 7, " in the config, ");
      }
      problems.push_back(which + problem);
    }
  }
  if (problems.empty()) return;
  std::string message = cameras_file + ": the recording does not match the config's cameras: ";
  for (std::size_t i = 0; i < problems.size(); ++i) message += (i ? "; " : "") + problems[i];
  throw ConfigError(message);
}

namespace {

/// The frames part of CheckRecording: the first frame reads and has the
/// camera block's size, and a preload fits the machine's memory. False when
/// an error was recorded or the camera block has errors of its own (`model`
/// null).
bool CheckRecordedFrames(Reader& r, const Item& directory, const Entries& source,
                         const ReplaySourceConfig& replay, const capture::RecordingCamera& rec,
                         const geometry::CameraModel* model) {
  capture::Frame frame;
  std::vector<unsigned char> bytes;
  std::string path;
  if (!capture::LoadRecordedFrame(rec, 0, &frame, &bytes, &path)) {
    r.Error(directory.line, directory.path,
            "first frame of camera '" + replay.camera + "' cannot be read: " + path);
    return false;
  }
  const bool rgb = frame.kind == capture::FrameKind::kRgb;
  const int w = rgb ? frame.rgb.width : frame.grey.width;
  const int h = rgb ? frame.rgb.height : frame.grey.height;
  if (model == nullptr) return false;
  if (w != model->width || h != model->height) {
    r.Error(directory.line, directory.path,
            "camera '" + replay.camera + "' was recorded at " + std::to_string(w) + "x" +
                std::to_string(h) + ", the camera block is " + std::to_string(model->width) + "x" +
                std::to_string(model->height) + " (" + path + ")");
    return false;
  }
  if (replay.preload) {
    // Every frame decoded in memory: more than half the machine's memory
    // would end the daemon at start-up (or the machine's other work).
    const double mib =
        static_cast<double>(rec.frames.size()) * w * h * (rgb ? 3 : 1) / (1024.0 * 1024.0);
    const double memory_mib = static_cast<double>(sysconf(_SC_PHYS_PAGES)) *
                              static_cast<double>(sysconf(_SC_PAGE_SIZE)) / (1024.0 * 1024.0);
    if (memory_mib > 0.0 && mib > 0.5 * memory_mib) {
      const Item& preload = source.at("preload");  // Set, so given.
      r.Error(preload.line, preload.path,
              std::to_string(rec.frames.size()) + " frames of camera '" + replay.camera +
                  "' need " + FormatNumber(std::round(mib)) +
                  " MiB preloaded, more than half of this machine's memory (" +
                  FormatNumber(std::round(memory_mib)) +
                  " MiB); play them from disk (preload: false)");
      return false;
    }
  }
  return true;
}

/// A replay source's recording, opened as the replay will: its manifest (and
/// frames index) must read and hold the camera, the first frame, if any,
/// must decode to the camera block's size, and the recording's
/// calibration of the camera (its cameras.yaml) must be the camera block's
/// (CheckSameCamera), and a preload must fit the machine's memory. Errors
/// are recorded at the source's `directory` key (`source`: its entries), with
/// the recording's own file and line, at its `preload` key, or at the camera
/// block's key that differs. `model` is null when the camera block has errors
/// of its own.
void CheckRecording(Reader& r, const Item& entry, const Entries& e, const Entries& source,
                    const ReplaySourceConfig& replay, const geometry::CameraModel* model) {
  const Item& directory = source.at("directory");
  try {
    const capture::RecordingCamera rec =
        capture::ReadRecordingCamera(replay.directory, replay.camera);
    // A camera that delivered nothing while it was recorded (a black box
    // dump taken because it was lost) replays as one that never delivers:
    // it sees nothing, and the stream is degraded, as it was then.
    const bool empty = rec.frames.empty();
    if (empty && replay.loop) {
      r.Error(directory.line, directory.path,
              "recording '" + replay.directory + "' has no frames of camera '" + replay.camera +
                  "' to loop");
      return;
    }
    if (replay.loop) {
      const auto start_ns = static_cast<std::int64_t>(std::llround(replay.loop_start_s * 1e9));
      const auto looped = std::count_if(rec.frames.begin(), rec.frames.end(),
                                        [&](const auto& f) { return f.time_ns >= start_ns; });
      if (looped < 2) {
        r.Error(directory.line, directory.path,
                "loop_start_s " + ExactNumber(replay.loop_start_s) + " leaves " +
                    std::to_string(looped) + " frame(s) of camera '" + replay.camera +
                    "' to loop, at least 2 needed (its last frame is at " +
                    ExactNumber(static_cast<double>(rec.frames.back().time_ns) * 1e-9) + " s)");
        return;
      }
      try {
        (void)capture::LoopLengthNs(rec, replay.loop_start_s);
      } catch (const common::ConfigError& error) {
        r.Error(directory.line, directory.path, error.what());
        return;
      }
    }
    if (!empty && !CheckRecordedFrames(r, directory, source, replay, rec, model)) return;
    if (model == nullptr) return;
    const std::string cameras_file =
        (std::filesystem::path(replay.directory) / "cameras.yaml").string();
    if (!std::filesystem::is_regular_file(cameras_file)) {
      r.Error(directory.line, directory.path,
              "recording '" + replay.directory +
                  "' has no cameras.yaml: the calibration its frames were taken with cannot be "
                  "checked against this camera block (hullguard synth and record write one)");
      return;
    }
    const std::vector<geometry::CameraModel> recorded = geometry::LoadCamerasFile(cameras_file);
    const auto it = std::find_if(recorded.begin(), recorded.end(),
                                 [&](const auto& c) { return c.name == replay.camera; });
    if (it == recorded.end()) {
      r.Error(directory.line, directory.path,
              cameras_file + " has no camera '" + replay.camera + "'");
      return;
    }
    CheckSameCamera(r, entry, e, *model, *it,
                    "camera '" + replay.camera + "' of recording '" + replay.directory + "'",
                    "in the recording");
  } catch (const ConfigError& error) {
    r.Error(directory.line, directory.path, std::string("bad recording: ") + error.what());
  } catch (const YAML::Exception& error) {
    // The recording's own YAML, converted by yaml-cpp: its line, not the config's.
    r.Error(directory.line, directory.path,
            "bad recording '" + replay.directory + "': " + std::string(error.what()));
  }
}

/// Rewrites an error of geometry::ParseCamera ("file:line: key: problem", about
/// a stand-alone camera block) into the entry's path ("cameras[2].K: problem").
void RecordCameraError(Reader& r, const std::string& message, const Item& entry) {
  std::string body = message;
  int line = entry.line;
  const std::string head = r.file() + ":";
  if (body.rfind(head, 0) == 0) {
    body = body.substr(head.size());
    std::size_t digits = 0;
    while (digits < body.size() && std::isdigit(static_cast<unsigned char>(body[digits]))) {
      ++digits;
    }
    if (digits > 0) {
      line = std::stoi(body.substr(0, digits));
      body = body.substr(digits);
    }
    if (body.rfind(": ", 0) == 0) {
      body = body.substr(2);
    } else if (body.rfind(' ', 0) == 0) {  // "file: problem": no line.
      body = body.substr(1);
    }
  }
  // A leading "key: " or "key[i]: " names a camera-block key.
  const std::size_t colon = body.find(": ");
  if (colon != std::string::npos) {
    const std::string key = body.substr(0, colon);
    const std::string base = key.substr(0, key.find('['));
    for (const CameraBlockKey& k : kCameraBlockKeys) {
      if (base == k.key) {
        r.Error(line, entry.path + "." + key, body.substr(colon + 2));
        return;
      }
    }
  }
  r.Error(line, entry.path, body);
}

/// Reads the keys of one source type; `entries` receives the source's entries.
template <typename S>
S ReadSource(Reader& r, const Item& source, std::span<const Field<S>> fields, Entries* entries) {
  std::vector<std::string> known = {"type"};
  for (const std::string& k : KeysOf(fields)) known.push_back(k);
  *entries = r.Map(source, known);
  S out;
  r.Fields(fields, *entries, source, &out);
  return out;
}

/// Reads one `cameras:` entry; `name_item` receives the item of its `name` key.
/// The scenes of sim sources are loaded into `scenes`.
std::optional<CameraConfig> ReadCamera(Reader& r, const Item& entry, SceneCache* scenes,
                                       Item* name_item) {
  std::vector<std::string> known;
  for (const CameraBlockKey& k : kCameraBlockKeys) known.emplace_back(k.key);
  known.emplace_back("source");
  for (const std::string& k : KeysOf<CameraConfig>(kCameraFields)) known.push_back(k);
  if (!entry.value.IsMap()) {
    r.Error(entry.line, entry.path, "expected a map with the camera keys and 'source'");
    return std::nullopt;
  }
  const Entries e = r.Map(entry, known);

  // The camera block goes to geometry::ParseCamera with its original key and
  // value nodes, so its messages keep their lines.
  YAML::Node block(YAML::NodeType::Map);
  for (const auto& [key, item] : e) {
    for (const CameraBlockKey& k : kCameraBlockKeys) {
      if (key == k.key) block.force_insert(item.key, item.value);
    }
  }
  CameraConfig camera;
  std::vector<std::string> camera_errors;
  const std::optional<geometry::CameraModel> model =
      geometry::ParseCameraReportingAll(block, r.file(), &camera_errors);
  for (const std::string& error : camera_errors) RecordCameraError(r, error, entry);
  const bool ok = model.has_value();
  if (model) camera.model = *model;
  if (const auto it = e.find("name"); it != e.end()) {
    *name_item = it->second;
    // The name becomes part of file names (kept backgrounds, recordings,
    // black-box dumps).
    if (ok) {
      if (const std::string problem = geometry::FileNameProblem(camera.model.name);
          !problem.empty()) {
        r.Error(it->second.line, it->second.path, problem);
      }
    }
  }
  r.Fields<CameraConfig>(kCameraFields, e, entry, &camera);

  const auto src = e.find("source");
  if (src == e.end()) {
    r.Error(entry.line, entry.path, "missing key 'source'");
    return std::nullopt;
  }
  const Item& source = src->second;
  if (!source.value.IsMap()) {
    r.Error(source.line, source.path, "expected a map with 'type' and its keys");
    return std::nullopt;
  }
  // The type decides which keys are known, so it is looked up first.
  std::optional<Item> type_item;
  for (const auto& kv : source.value) {
    if (kv.first.IsScalar() && kv.first.Scalar() == "type") {
      type_item = Item{kv.first, kv.second, source.path + ".type", common::YamlLine(kv.first)};
    }
  }
  if (!type_item) {
    r.Error(source.line, source.path,
            "missing key 'type' (" + OrList(NameList<SourceType>()) + ")");
    return std::nullopt;
  }
  const std::optional<SourceType> type = r.Enum<SourceType>(*type_item, "source type");
  if (!type) return std::nullopt;
  switch (*type) {
    case SourceType::kSim: {
      Entries e_src;
      SimSourceConfig sim = ReadSource<SimSourceConfig>(r, source, kSimFields, &e_src);
      if (sim.camera.empty()) sim.camera = camera.model.name;
      const auto scene_it = e_src.find("scene");
      if (!sim.scene.empty() && !sim.camera.empty() && scene_it != e_src.end()) {
        if (const sim::Scene* scene = LoadSceneOnce(r, scenes, scene_it->second, sim.scene)) {
          const std::string& scene_text = scene_it->second.value.Scalar();
          const sim::SceneCamera* scene_camera = nullptr;
          std::vector<std::string> names;
          for (const sim::SceneCamera& c : scene->cameras) {
            if (c.model.name == sim.camera) scene_camera = &c;
            names.push_back(c.model.name);
          }
          if (scene_camera == nullptr) {
            const auto cam_it = e_src.find("camera");
            const Item& at = cam_it != e_src.end()
                                 ? cam_it->second
                                 : Item{{}, {}, source.path + ".camera", source.line};
            r.Error(at.line, at.path,
                    "scene '" + scene_text + "' has no camera '" + sim.camera + "' (it has " +
                        OrList(names, " and ") + ")");
          } else if (ok) {
            CheckSameCamera(
                r, entry, e, camera.model, scene_camera->model,
                "camera '" + scene_camera->model.name + "' of scene '" + scene_text + "'",
                "in the scene");
          }
        }
      }
      camera.source = sim;
      break;
    }
    case SourceType::kReplay: {
      Entries e_src;
      ReplaySourceConfig replay = ReadSource<ReplaySourceConfig>(r, source, kReplayFields, &e_src);
      if (replay.camera.empty()) replay.camera = camera.model.name;
      const auto dir_it = e_src.find("directory");
      // Without a camera name (the camera block's own errors left none) there
      // is no camera to look for in the recording.
      if (!replay.directory.empty() && !replay.camera.empty() && dir_it != e_src.end() &&
          std::filesystem::is_directory(replay.directory)) {
        CheckRecording(r, entry, e, e_src, replay, ok ? &camera.model : nullptr);
      }
      camera.source = replay;
      break;
    }
    case SourceType::kAravis: {
      Entries e_src;
      camera.source = ReadSource<AravisSourceConfig>(r, source, kAravisFields, &e_src);
      break;
    }
    case SourceType::kV4l2: {
      Entries e_src;
      V4l2SourceConfig v4l2 = ReadSource<V4l2SourceConfig>(r, source, kV4l2Fields, &e_src);
      if (!v4l2.device.empty() && v4l2.device.rfind("/dev/", 0) != 0) {
        r.Error(e_src.at("device").line, e_src.at("device").path,
                "expected a device node such as /dev/video0");
      }
      // What capture::V4l2Source refuses, refused here, before any camera is opened.
      if (ok) {
        for (const auto& [key, side] :
             {std::pair{"width", camera.model.width}, std::pair{"height", camera.model.height}}) {
          if (side > kMaxV4l2Side) {
            r.Error(e.at(key).line, e.at(key).path,
                    "at most " + std::to_string(kMaxV4l2Side) + " for a v4l2 camera (got " +
                        std::to_string(side) + ")");
          }
        }
        if (v4l2.format == V4l2Format::kYuyv && camera.model.width % 2 != 0) {
          r.Error(e.at("width").line, e.at("width").path,
                  "YUYV needs an even width (got " + std::to_string(camera.model.width) + ")");
        }
      }
      camera.source = v4l2;
      break;
    }
  }
  return ok ? std::optional<CameraConfig>(camera) : std::nullopt;
}

/// Doc rows of a field table, defaults read from a default-constructed struct.
template <typename S>
std::vector<DocRow> Rows(std::span<const Field<S>> fields) {
  static const S defaults{};
  std::vector<DocRow> rows;
  for (const Field<S>& f : fields) {
    DocRow row;
    row.key = f.key;
    row.meaning = f.meaning;
    row.allowed = Reader::RangeText(f.limits);
    std::visit(
        [&](auto member) {
          if (member == nullptr) return;  // Never; keeps GCC's flow analysis quiet.
          const auto& value = defaults.*member;
          using T = std::remove_cvref_t<decltype(value)>;
          if constexpr (std::is_same_v<T, int> || std::is_same_v<T, std::optional<int>>) {
            row.type = "integer";
          } else if constexpr (std::is_same_v<T, double> ||
                               std::is_same_v<T, std::optional<double>>) {
            row.type = "number";
          } else if constexpr (std::is_same_v<T, bool>) {
            row.type = "bool";
          } else if constexpr (std::is_same_v<T, std::string>) {
            row.type = f.path == PathCheck::kNone ? "string" : "path";
          } else if constexpr (std::is_same_v<T, common::Box3>) {
            row.type = "box";
          } else {
            row.type = "enum";
            row.allowed = OrList(NameList<T>());
          }
          if constexpr (std::is_same_v<T, int> || std::is_same_v<T, double>) {
            row.default_value = FormatNumber(value);
          } else if constexpr (std::is_same_v<T, bool>) {
            row.default_value = value ? "true" : "false";
          } else if constexpr (std::is_same_v<T, std::string>) {
            row.default_value = value;
          } else if constexpr (std::is_enum_v<T>) {
            row.default_value = NameOf(value);
          }
        },
        f.member);
    if (f.default_doc != nullptr) row.default_value = f.default_doc;
    if (f.required) row.default_value = "required";
    rows.push_back(std::move(row));
  }
  return rows;
}

}  // namespace

const char* ToString(SourceType v) { return NameOf(v); }
const char* ToString(PixelFormat v) { return NameOf(v); }
const char* ToString(Trigger v) { return NameOf(v); }
const char* ToString(V4l2Format v) { return NameOf(v); }
const char* ToString(LogLevel v) { return NameOf(v); }

SourceType TypeOf(const SourceConfig& source) { return static_cast<SourceType>(source.index()); }

Config ParseConfig(const std::string& text, const std::string& file, const std::string& base_dir) {
  const YAML::Node root = common::ParseYaml(text, file);
  Reader r(file, base_dir.empty() ? fs::path(".") : fs::path(base_dir));
  Config config;
  config.source_file = file;
  if (!root.IsMap()) {
    r.Error(root.IsDefined() ? common::YamlLine(root) : 0, "",
            "expected a map with the config sections (cell, cameras, ...)");
    r.ThrowIfErrors();
  }
  std::vector<std::string> known;
  for (const Section& s : kSections) known.emplace_back(s.key);
  const Item root_item{YAML::Node(), root, "", common::YamlLine(root)};
  const Entries sections = r.Map(root_item, known);
  for (const Section& s : kSections) {
    if (s.required && sections.count(s.key) == 0) {
      // Said at the top of the file, where it would go.
      r.Error(common::YamlLine(root), "", std::string("missing section '") + s.key + "'");
    }
  }

  ReadSection<CellConfig>(r, sections, "cell", kCellFields, &config.cell);
  const std::size_t errors_before_octree = r.error_count();
  ReadSection<OctreeSettings>(r, sections, "octree", kOctreeFields, &config.octree);
  // The line of a key of a section; 0 when the key is not given.
  auto key_line = [&](const std::string& section, const std::string& key) {
    int line = 0;
    if (const auto it = sections.find(section); it != sections.end() && it->second.value.IsMap()) {
      for (const auto& kv : it->second.value) {
        if (kv.first.IsScalar() && kv.first.Scalar() == key) line = common::YamlLine(kv.first);
      }
    }
    return line;
  };
  if (r.error_count() == errors_before_octree) {
    OctreeSettings& o = config.octree;
    // Defaults beyond a shallow octree's depth are turned off; given ones are errors.
    if (o.coarse_first_depth != 0 && o.coarse_first_depth >= o.depth) {
      if (const int line = key_line("octree", "coarse_first_depth"); line == 0) {
        o.coarse_first_depth = 0;
      } else {
        r.Error(line, "octree.coarse_first_depth",
                "must be 0 (off) or a level below octree.depth = " + std::to_string(o.depth) +
                    " (got " + std::to_string(o.coarse_first_depth) + ")");
      }
    }
    if (o.depth - o.boundary_coarsening < octree::Octree::kRootLevel) {
      if (const int line = key_line("octree", "boundary_coarsening"); line == 0) {
        o.boundary_coarsening = o.depth - octree::Octree::kRootLevel;
      } else {
        r.Error(line, "octree.boundary_coarsening",
                "must be <= octree.depth - 3 = " +
                    std::to_string(o.depth - octree::Octree::kRootLevel) +
                    " (the roots' level; got " + std::to_string(o.boundary_coarsening) + ")");
      }
    }
  }
  if (r.error_count() == errors_before_octree &&
      config.octree.publish_depth > config.octree.depth) {
    const int line = key_line("octree", "publish_depth");
    if (line == 0) {
      config.octree.publish_depth = config.octree.depth;  // The default, for a shallow octree.
    } else {
      r.Error(line, "octree.publish_depth",
              "must be <= octree.depth = " + std::to_string(config.octree.depth) + " (got " +
                  std::to_string(config.octree.publish_depth) + ")");
    }
  }
  const std::size_t errors_before_timing = r.error_count();
  ReadSection<TimingConfig>(r, sections, "timing", kTimingFields, &config.timing);
  const bool timing_read = r.error_count() == errors_before_timing;
  ReadSection<ThreadsConfig>(r, sections, "threads", kThreadsFields, &config.threads);
  ReadSection<MotionConfig>(r, sections, "motion", kMotionFields, &config.motion);
  config.max_speed_line = key_line("motion", "max_speed_mps");
  if (config.octree.knowledge_filter_m3 > kSmallestPersonM3) {
    char notice[320];
    std::snprintf(notice, sizeof(notice),
                  "octree.knowledge_filter_m3: %g m^3 is more than a small child's volume (about "
                  "%g m^3): a child the cameras see whole, away from occluded space, would be "
                  "dropped and reported free; keep it below",
                  config.octree.knowledge_filter_m3, kSmallestPersonM3);
    config.notices.emplace_back(
        ConfigError::At(r.file(), key_line("octree", "knowledge_filter_m3"), notice).what());
  }
  if (const int line = key_line("motion", "min_camera_distance_m"); line != 0) {
    config.notices.emplace_back(
        ConfigError::At(r.file(), line,
                        "motion.min_camera_distance_m: ignored (the skew compensation now holds "
                        "at any distance from the cameras); remove it")
            .what());
  }
  const std::size_t errors_before_background = r.error_count();
  ReadSection<BackgroundConfig>(r, sections, "background", kBackgroundFields, &config.background);
  if (!config.background.shadows_are_foreground) {
    config.notices.emplace_back(
        ConfigError::At(r.file(), key_line("background", "shadows_are_foreground"),
                        "background.shadows_are_foreground: false: a part of a person that is "
                        "darker than the background by a shadow's ratio (dark trousers on a grey "
                        "floor; with grey or raw Bayer cameras any colour) is taken for a shadow "
                        "and reported background")
            .what());
  }
  if (r.error_count() == errors_before_background &&
      config.background.max_threshold < config.background.threshold) {
    r.Error(key_line("background", "max_threshold"), "background.max_threshold",
            "must be >= background.threshold = " + std::to_string(config.background.threshold));
  }
  if (r.error_count() == errors_before_background &&
      config.background.texture_threshold > config.background.max_threshold) {
    // Every pixel's texture threshold would exceed max_threshold: untested.
    r.Error(key_line("background", "texture_threshold"), "background.texture_threshold",
            "must be <= background.max_threshold = " +
                std::to_string(config.background.max_threshold) + " (0 turns the test off)");
  }
  const std::size_t errors_before_dds = r.error_count();
  ReadSection<DdsConfig>(r, sections, "dds", kDdsFields, &config.dds);
  if (r.error_count() == errors_before_dds) {
    // DDS topic names: letters, digits and '_', not starting with a digit; the
    // prefix may hold '/' between such names ("plant/cell_3").
    const std::string& prefix = config.dds.topic_prefix;
    bool valid = !prefix.empty() && prefix.front() != '/' && prefix.back() != '/' &&
                 prefix.find("//") == std::string::npos &&
                 !(prefix.front() >= '0' && prefix.front() <= '9');
    for (const char ch : prefix) {
      valid = valid && ((ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z') ||
                        (ch >= '0' && ch <= '9') || ch == '_' || ch == '/');
    }
    if (!valid) {
      r.Error(key_line("dds", "topic_prefix"), "dds.topic_prefix",
              "'" + prefix +
                  "' is not a DDS topic name prefix: letters, digits and '_', names joined by "
                  "'/', not starting with a digit");
    }
  }
  ReadSection<LoggingConfig>(r, sections, "logging", kLoggingFields, &config.logging);
  ReadSection<BlackBoxConfig>(r, sections, "blackbox", kBlackBoxFields, &config.blackbox);
  if (!config.background.learn_at_start && config.background.keep_dir.empty()) {
    const int line = key_line("background", "learn_at_start");
    r.Error(line, "background.learn_at_start",
            "false needs background.keep_dir: the taught background is kept there");
  }
  if (!config.background.keep_dir.empty() && fs::path(config.background.keep_dir).is_relative()) {
    config.background.keep_dir =
        (r.base_dir() / config.background.keep_dir).lexically_normal().string();
  }
  if (fs::path(config.blackbox.dir).is_relative()) {
    config.blackbox.dir = (r.base_dir() / config.blackbox.dir).lexically_normal().string();
  }
  const std::size_t errors_before_tracking = r.error_count();
  ReadSection<TrackingConfig>(r, sections, "tracking", kTrackingFields, &config.tracking);
  if (r.error_count() == errors_before_tracking) CheckTracking(r, sections, config);

  // Cross-field: the deadline must leave room within one period (checked on
  // values that were read, not on a default standing in for a bad one).
  const TimingConfig& timing = config.timing;
  if (timing_read && timing.deadline_ms >= 1000.0 / timing.rate_hz) {
    Entries t;
    if (const auto it = sections.find("timing"); it != sections.end() && it->second.value.IsMap()) {
      for (const auto& kv : it->second.value) {
        const std::string key = kv.first.IsScalar() ? kv.first.Scalar() : "";
        t.emplace(key, Item{kv.first, kv.second, "timing." + key, common::YamlLine(kv.first)});
      }
    }
    const int line = t.count("deadline_ms") ? t.at("deadline_ms").line
                     : t.count("rate_hz")   ? t.at("rate_hz").line
                                            : 0;
    r.Error(line, "timing.deadline_ms",
            "must be < 1000 / rate_hz = " + FormatNumber(1000.0 / timing.rate_hz) + " ms (got " +
                FormatNumber(timing.deadline_ms) + ")");
  }

  if (const auto it = sections.find("cameras"); it != sections.end()) {
    const Item& list = it->second;
    if (!list.value.IsSequence() || list.value.size() == 0) {
      r.Error(list.line, list.path, "expected a non-empty list of cameras");
    } else if (list.value.size() > static_cast<std::size_t>(common::kMaxCameras)) {
      r.Error(list.line, list.path,
              std::to_string(list.value.size()) + " cameras, at most " +
                  std::to_string(common::kMaxCameras) + " (one octree fuses at most that many)");
    } else {
      std::map<std::string, int> first_line;  // Camera name -> line of its name.
      SceneCache scenes;
      for (const Item& entry : r.List(list)) {
        Item name_item;
        std::optional<CameraConfig> camera = ReadCamera(r, entry, &scenes, &name_item);
        // Checked on the raw name, so that a duplicate is reported even when
        // the camera block has other problems.
        if (name_item.value.IsScalar() && !name_item.value.Scalar().empty()) {
          const std::string& name = name_item.value.Scalar();
          const auto [at, inserted] = first_line.emplace(name, name_item.line);
          if (!inserted) {
            r.Error(name_item.line, name_item.path,
                    "duplicate camera name '" + name + "' (first at line " +
                        std::to_string(at->second) + ")");
          }
        }
        if (!camera) continue;
        if (camera->timeout_ms == 0) camera->timeout_ms = timing.camera_timeout_ms;
        camera->line = entry.line;
        config.cameras.push_back(std::move(*camera));
      }
    }
  }

  if (const auto it = sections.find("obstacles"); it != sections.end()) {
    for (const Item& entry : r.List(it->second)) {
      const Entries e = r.Map(entry, KeysOf<ObstacleConfig>(kObstacleFields));
      if (!entry.value.IsMap()) continue;
      ObstacleConfig obstacle;
      r.Fields<ObstacleConfig>(kObstacleFields, e, entry, &obstacle);
      if (obstacle.file.empty()) continue;
      std::string ext = fs::path(obstacle.file).extension().string();
      std::transform(ext.begin(), ext.end(), ext.begin(),
                     [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
      const Item& file_item = e.at("file");
      if (ext != ".obj" && ext != ".stl") {
        r.Error(file_item.line, file_item.path, "expected an .obj or .stl mesh");
        continue;
      }
      // Loaded as the daemon will (LoadObstacles), so that a bad mesh fails here.
      try {
        if (geometry::LoadMesh(obstacle.file).triangles.empty()) {
          r.Error(file_item.line, file_item.path,
                  "mesh '" + obstacle.file + "' has no triangles (not an " +
                      (ext == ".obj" ? std::string("OBJ") : std::string("STL")) + " mesh?)");
          continue;
        }
      } catch (const ConfigError& error) {
        r.Error(file_item.line, file_item.path, std::string("bad mesh: ") + error.what());
        continue;
      }
      config.obstacles.push_back(std::move(obstacle));
    }
  }
  // The black box's rings are sized from the cameras: checked once they all read well.
  if (config.blackbox.seconds > 0.0 && r.error_count() == 0) CheckBlackBox(r, sections, config);

  r.ThrowIfErrors();
  return config;
}

std::vector<std::string> SimSpeedNotices(const Config& config) {
  std::set<std::string> scenes;
  for (const CameraConfig& camera : config.cameras) {
    if (const auto* sim = std::get_if<SimSourceConfig>(&camera.source)) scenes.insert(sim->scene);
  }
  std::vector<std::string> notices;
  for (const std::string& path : scenes) {
    const sim::Scene scene = sim::LoadScene(path);
    double fastest = 0.0;
    for (const sim::Person& person : scene.people) {
      // Every 2 ms (the default), but at most 200 000 samples per person, and
      // fewer for a script of many actions (each sample looks through them):
      // a script hours long, or of hundreds of laps, does not hold the
      // start-up back.
      const double end_s = sim::ScriptEndS(person) + 1.0;
      const double samples = std::min(
          200'000.0, 4e6 / static_cast<double>(std::max<std::size_t>(1, person.actions.size())));
      const double step_s = std::max(0.002, end_s / samples);
      fastest = std::max(fastest, sim::FastestPartSpeed(person, 0.0, end_s, step_s));
    }
    if (fastest <= config.motion.max_speed_mps) continue;
    char text[256];
    std::snprintf(text, sizeof(text),
                  "motion.max_speed_mps: %.2f m/s, but a person of scene '%s' moves a part at up "
                  "to %.2f m/s: a camera's frame of another instant may certify free what that "
                  "part reached meanwhile; raise it",
                  config.motion.max_speed_mps, path.c_str(), fastest);
    notices.emplace_back(ConfigError::At(config.source_file, config.max_speed_line, text).what());
  }
  return notices;
}

std::vector<std::string> BlockedCameraNotices(const Config& config) {
  std::vector<std::string> notices;
  if (config.obstacles.empty()) return notices;
  std::vector<geometry::TriangleMesh> meshes;
  for (const ObstacleConfig& o : config.obstacles) meshes.push_back(geometry::LoadMesh(o.file));
  for (std::size_t c = 0; c < config.cameras.size(); ++c) {
    const geometry::CameraModel& model = config.cameras[c].model;
    if (!geometry::RenderObstacleDepth(model.Pinhole(), meshes).blocked) continue;
    notices.emplace_back(ConfigError::At(config.source_file, config.cameras[c].line,
                                         "cameras[" + std::to_string(c) + "]: camera '" +
                                             model.name + "' " +
                                             geometry::ObstacleDepthMap::kBlockedText)
                             .what());
  }
  return notices;
}

Config LoadConfig(const std::string& path) {
  return ParseConfig(common::ReadInputFile(path, "config"), path,
                     fs::path(path).parent_path().string());
}

std::string Summary(const Config& config) {
  std::map<SourceType, int> counts;
  for (const CameraConfig& c : config.cameras) ++counts[TypeOf(c.source)];
  std::string types;
  for (const auto& [type, n] : counts) {
    types += (types.empty() ? "" : ", ") + std::to_string(n) + " " + ToString(type);
  }
  return std::to_string(config.cameras.size()) +
         (config.cameras.size() == 1 ? " camera (" : " cameras (") + types + "), depth " +
         std::to_string(config.octree.depth) + ", " + FormatNumber(config.timing.rate_hz) + " Hz";
}

std::vector<DocSection> ConfigDocSections() {
  std::vector<DocSection> out;
  {
    DocSection top{
        "Top level", "", "The file is a map of these sections; unknown keys are errors.", {}};
    for (const Section& s : kSections) {
      top.rows.push_back({s.key, s.type, s.required ? "required" : "see below", "", s.meaning});
    }
    out.push_back(std::move(top));
  }
  out.push_back({"cell", "cell", "The surveillance volume.", Rows<CellConfig>(kCellFields)});
  out.push_back({"octree", "octree", "Resolution of the reconstruction and its optional filter.",
                 Rows<OctreeSettings>(kOctreeFields)});
  out.push_back(
      {"timing", "timing", "Fusion rate and deadlines.", Rows<TimingConfig>(kTimingFields)});
  out.push_back({"threads", "threads", "Thread counts.", Rows<ThreadsConfig>(kThreadsFields)});
  out.push_back({"motion", "motion", "How fast people move: the capture-skew compensation.",
                 Rows<MotionConfig>(kMotionFields)});
  {
    DocSection cams{"cameras",
                    "cameras[]",
                    "A non-empty list; each entry is a camera block (the format of `hullguard "
                    "carve --cameras`: K with R and t, K with position and look_at, or P) plus its "
                    "source. Names must be unique.",
                    {}};
    for (const CameraBlockKey& k : kCameraBlockKeys) {
      cams.rows.push_back({k.key, k.type, k.default_value, "", k.meaning});
    }
    cams.rows.push_back({"source", "map", "required", "",
                         "Where the frames come from; `type` selects the keys below."});
    for (DocRow& row : Rows<CameraConfig>(kCameraFields)) cams.rows.push_back(std::move(row));
    out.push_back(std::move(cams));
  }
  out.push_back(
      {"cameras[].source",
       "cameras[].source",
       "`type` selects the kind of source; each kind has its own keys (next tables).",
       {{"type", "enum", "required", OrList(NameList<SourceType>()), "Kind of source."}}});
  out.push_back({"source type: sim", "cameras[].source",
                 "Frames rendered by the work-cell simulator.", Rows<SimSourceConfig>(kSimFields)});
  out.push_back({"source type: replay", "cameras[].source", "Frames played back from a recording.",
                 Rows<ReplaySourceConfig>(kReplayFields)});
  out.push_back({"source type: aravis", "cameras[].source",
                 "A GigE Vision or USB3 Vision camera through Aravis.",
                 Rows<AravisSourceConfig>(kAravisFields)});
  out.push_back({"source type: v4l2", "cameras[].source", "A USB camera through Video4Linux2.",
                 Rows<V4l2SourceConfig>(kV4l2Fields)});
  out.push_back({"background", "background", "Background model of the silhouette stage.",
                 Rows<BackgroundConfig>(kBackgroundFields)});
  out.push_back({"obstacles", "obstacles[]",
                 "A list (may be empty) of static obstacle meshes; the cameras cannot see "
                 "through them.",
                 Rows<ObstacleConfig>(kObstacleFields)});
  out.push_back({"dds", "dds", "DDS publishing.", Rows<DdsConfig>(kDdsFields)});
  out.push_back({"logging", "logging", "Logging.", Rows<LoggingConfig>(kLoggingFields)});
  out.push_back({"blackbox", "blackbox",
                 "The black box keeps the last `seconds` of every camera's frames in memory and "
                 "writes them out as a recording on SIGUSR1 or when the status turns degraded "
                 "(docs/cameras.md, \"Recording and replaying\").",
                 Rows<BlackBoxConfig>(kBlackBoxFields)});
  out.push_back({"tracking", "tracking",
                 "Human tracking (Ober-Gecks et al.): one particle filter per person over the "
                 "occupied voxels, births from occupied space no track explains, deaths after a "
                 "time without support. Published as `<prefix>/tracks` (docs/dds.md); not a "
                 "safety output, the occupancy is.",
                 Rows<TrackingConfig>(kTrackingFields)});
  return out;
}

}  // namespace hg::app
