#pragma once
/// @file
/// The hullguardd configuration: plain structs with their defaults in line, and
/// the loader that validates a whole YAML file before anything is opened.
///
/// Every key, its type, default, range and meaning is described once, in the
/// field tables of config.cc; the loader reads through them and
/// ConfigReferenceMarkdown() prints them as docs/configuration.md.

#include <optional>
#include <string>
#include <variant>
#include <vector>

#include "common/box.h"
#include "common/log.h"
#include "geometry/camera.h"

namespace hg::app {

/// The surveillance volume. Plain struct, thread-compatible.
struct CellConfig {
  common::Box3 bounds;  ///< World-frame box watched by the cameras (m); required.
};

/// Octree settings (mirrors octree::OctreeConfig without depending on it).
struct OctreeSettings {
  int depth = 10;                    ///< Finest cells are bounds / 2^depth.
  int boundary_coarsening = 3;       ///< Geometry-only boundaries stop this many levels early.
  double knowledge_filter_m3 = 0.0;  ///< Drop occupied components below this volume; 0 = off.
  int publish_depth = 7;             ///< Published grid: 2^publish_depth cells per axis (<= depth).
  int coarse_first_depth = 4;        ///< Update down to this level first; 0 = off.
  int max_nodes = 0;  ///< Octree nodes reserved at start (0: from the depth, at most 8 Mi).
};

/// How far people can move: the capture-skew compensation grows the boxes an
/// older frame certifies free by the distance a person covers until the
/// newest frame.
struct MotionConfig {
  double max_speed_mps = 5.0;          ///< Fastest any part of a person moves (feet, hands).
  double min_camera_distance_m = 1.0;  ///< Ignored (older configs carry it).
  bool stamp_at_median = false;        ///< pipeline::PipelineOptions::stamp_at_median.
};

/// Fusion timing.
struct TimingConfig {
  double rate_hz = 30.0;         ///< Fusion rate.
  double deadline_ms = 25.0;     ///< Anytime deadline of one octree update; < 1000 / rate_hz.
  int camera_timeout_ms = 200;   ///< A camera silent this long is treated as seeing nothing.
  bool align_to_frames = true;   ///< Phase-lock the cycle to the cameras' frames.
  double align_margin_ms = 2.0;  ///< The cycle starts this long after a frame set is ready.
};

/// Thread counts.
struct ThreadsConfig {
  int octree = 2;              ///< Octree worker threads (the fusion thread included).
  int silhouette_workers = 0;  ///< 0 = one per camera.
  int realtime_priority = 0;   ///< SCHED_FIFO priority of the fusion thread (0: normal).
};

/// Kind of camera source.
enum class SourceType { kSim, kReplay, kAravis, kV4l2 };
/// Aravis (GigE Vision / USB3 Vision) pixel formats.
enum class PixelFormat { kMono8, kBayerRG8, kBayerGB8, kBayerGR8, kBayerBG8, kRGB8 };
/// Aravis acquisition trigger.
enum class Trigger { kFreeRun, kSoftware, kHardware };
/// V4L2 capture formats.
enum class V4l2Format { kGrey, kYuyv, kMjpeg };
/// Log levels.
/// Log severity: the logging facade's own (common/log.h).
using LogLevel = log::Level;

/// The YAML spelling of each enum value ("sim", "BayerRG8", "free_run", "GREY", "info").
[[nodiscard]] const char* ToString(SourceType v);
[[nodiscard]] const char* ToString(PixelFormat v);
[[nodiscard]] const char* ToString(Trigger v);
[[nodiscard]] const char* ToString(V4l2Format v);
[[nodiscard]] const char* ToString(LogLevel v);

/// Frames rendered by the work-cell simulator from a scene file.
struct SimSourceConfig {
  std::string scene;   ///< Scene file, resolved against the config file's folder.
  std::string camera;  ///< Camera of that scene; the loader fills in the camera's own name.
  /// Fault injection for demos and tests: the camera stops delivering frames
  /// this many seconds after start, as a camera whose cable is pulled.
  std::optional<double> stop_after_s;
  /// Colour frames through the background model instead of masks (SimSource::EnableColour).
  bool colour = false;
  /// Colour frames as the raw BayerRG8 mosaic (implies `colour`).
  bool bayer = false;
};

/// Frames played back from a recording.
struct ReplaySourceConfig {
  std::string directory;      ///< Recording folder, resolved against the config file's folder.
  std::string camera;         ///< Camera in the recording; the loader fills in the camera's name.
  bool realtime = true;       ///< Pace frames by their timestamps (false: as fast as consumed).
  bool preload = false;       ///< capture::ReplayOptions::preload.
  bool loop = false;          ///< capture::ReplayOptions::loop.
  double loop_start_s = 0.0;  ///< capture::ReplayOptions::loop_start_s.
};

/// A GigE Vision / USB3 Vision camera through Aravis. Unset optionals keep the
/// camera's own setting.
struct AravisSourceConfig {
  std::string device;  ///< Serial number, device name or IP address.
  PixelFormat pixel_format = PixelFormat::kMono8;
  bool debayer = false;  ///< Bayer formats: RGB to the background model instead of the mosaic.
  std::optional<double> exposure_us;
  std::optional<double> gain_db;
  std::optional<double> frame_rate_hz;
  Trigger trigger = Trigger::kFreeRun;
  std::optional<int> packet_size;          ///< GigE packet size (bytes).
  std::optional<int> socket_buffer_bytes;  ///< Receive socket buffer (bytes).
};

/// A USB camera through Video4Linux2. Unset optionals keep the driver's setting.
struct V4l2SourceConfig {
  std::string device;  ///< Device node, /dev/videoN.
  V4l2Format format = V4l2Format::kYuyv;
  std::optional<double> frame_rate_hz;
  std::optional<int> exposure;  ///< V4L2 exposure_time_absolute (units of 100 us).
};

/// Where a camera's frames come from.
using SourceConfig =
    std::variant<SimSourceConfig, ReplaySourceConfig, AravisSourceConfig, V4l2SourceConfig>;

/// Type of a source (the variant's alternative).
[[nodiscard]] SourceType TypeOf(const SourceConfig& source);

/// One camera: its calibration (the camera block) and its source.
struct CameraConfig {
  geometry::CameraModel model;
  SourceConfig source;
  /// Silence after which the camera counts as seeing nothing (ms); the loader
  /// fills in timing.camera_timeout_ms when the entry does not override it.
  int timeout_ms = 0;
  /// Line of the camera's entry in Config::source_file (0: not read from a file).
  int line = 0;
};

/// Background model of the silhouette stage.
struct BackgroundConfig {
  int learn_frames = 30;               ///< Frames averaged before the first mask.
  int threshold = 15;                  ///< Foreground above this difference (grey levels).
  double adapt_rate = 0.01;            ///< Per-frame blend of background pixels into the model.
  bool shadows_are_foreground = true;  ///< Conservative: a shadow may hide a person's edge.
  double noise_sigmas = 4.0;    ///< Per-pixel threshold: at least this many learned noise sigmas.
  int max_threshold = 64;       ///< Pixels noisier than this are always foreground.
  int texture_threshold = 14;   ///< Foreground also where the texture differs this much.
  bool fill_holes = true;       ///< Background the foreground encloses becomes foreground.
  int guard_px = 8;             ///< No adaptation this close to foreground.
  bool compensate_gain = true;  ///< Follow global light changes with one gain per frame.
  int dilate_px = 2;            ///< Foreground grown by this many pixels.
  /// Folder keeping each camera's learned background across restarts ("": none).
  std::string keep_dir;
  /// Learn at start when no kept background is taken up (false: that camera
  /// sees nothing until `hullguardd --learn-background` taught it; needs keep_dir).
  bool learn_at_start = true;
};

/// A static obstacle mesh (OBJ or STL).
struct ObstacleConfig {
  std::string file;  ///< Resolved against the config file's folder.
};

/// DDS publishing.
struct DdsConfig {
  int domain_id = 0;
  std::string topic_prefix = "hullguard";
  bool enabled = true;
};

/// Logging.
struct LoggingConfig {
  LogLevel level = LogLevel::kInfo;
  bool journald = false;  ///< Log to the systemd journal instead of stderr.
};

/// Human tracking on the occupancy (particle filters, tracking/tracker.h).
/// The keys are a subset of tracking::TrackerOptions, with its defaults; the
/// weights are the paper's rho, sigma, tau and epsilon.
struct TrackingConfig {
  bool enabled = true;
  double voxel_m = 0.05;             ///< Edge of the tracking voxels.
  int particles = 300;               ///< Particles per track.
  int max_tracks = 16;               ///< Tracks held at most (preallocated).
  double rho_unknown = 1.0;          ///< Likelihood score of an occupied voxel.
  double sigma_occluded = 0.1;       ///< Of a voxel no camera sees.
  double tau_known = -5.0;           ///< Of a voxel inside an obstacle.
  double epsilon_free = -0.1;        ///< Of a voxel seen empty.
  double below_floor_weight = -0.1;  ///< Of lattice positions below the cell's floor.
  double support_reach_m = 0.25;     ///< An obstacle top this near the bottom is the floor.
  double collision_radius_m = 0.2;   ///< Capsule swept by a particle's move.
  /// Diffusion of a particle's top with its bottom fixed (m / sqrt(s)).
  double posture_noise_m_per_sqrt_s = 0.3;
  double birth_min_volume_m3 = 0.06;
  double birth_min_height_m = 1.0;
  double birth_max_skew_ms = 20.0;
  double death_timeout_s = 1.0;
  double occluded_death_timeout_s = 30.0;
  double reacquire_radius_m = 0.5;
  double reacquire_speed_mps = 1.5;
};

/// The black box: the last seconds of every camera kept in memory and written
/// out as a recording when the status turns degraded or on SIGUSR1
/// (docs/cameras.md, "Recording and replaying").
struct BlackBoxConfig {
  double seconds = 0.0;                             ///< History per camera; 0 = off.
  std::string dir = "/var/lib/hullguard/blackbox";  ///< Dumps go to dir/<UTC time>/.
  bool on_degraded = true;                          ///< Dump when the status turns degraded.
  int max_memory_mb = 1024;      ///< The rings and a dump's copy of them must fit.
  double camera_rate_hz = 30.0;  ///< Rate assumed where the config does not fix it.
};

/// The whole daemon configuration. Plain struct, thread-compatible.
struct Config {
  std::string source_file;  ///< The file it was read from (for messages).
  CellConfig cell;
  OctreeSettings octree;
  TimingConfig timing;
  ThreadsConfig threads;
  MotionConfig motion;
  std::vector<CameraConfig> cameras;
  BackgroundConfig background;
  std::vector<ObstacleConfig> obstacles;
  DdsConfig dds;
  LoggingConfig logging;
  BlackBoxConfig blackbox;
  TrackingConfig tracking;
  /// Keys the file sets that are accepted but have no effect any more, one
  /// "file:line: key: note" each: hullguardd prints them on stderr before it
  /// starts (or checks) the config.
  std::vector<std::string> notices;
  /// Line of motion.max_speed_mps in source_file; 0 when not given.
  int max_speed_line = 0;
};

/// Reads and validates a config file. Relative paths in it are resolved against
/// the file's folder.
/// @throws common::ConfigError listing every problem found, one per line, each
/// "file:line: key.path: problem".
[[nodiscard]] Config LoadConfig(const std::string& path);

/// Validates config text. `file` names it in messages; relative paths in it are
/// resolved against `base_dir`.
/// @throws common::ConfigError as LoadConfig.
[[nodiscard]] Config ParseConfig(const std::string& text, const std::string& file,
                                 const std::string& base_dir);

/// For every scene of the config's `sim` cameras whose people move faster
/// anywhere (a foot in swing, a hand in a reach; sampled every 2 ms over the
/// scene's script) than motion.max_speed_mps: a notice "file:line:
/// motion.max_speed_mps: ...". Frames of other instants then certify free
/// space a limb can reach meanwhile. Loads the scenes and samples their
/// scripts (about a second for the paper cell): hullguardd calls it, once,
/// not LoadConfig.
[[nodiscard]] std::vector<std::string> SimSpeedNotices(const Config& config);

/// One notice "file:line: cameras[i]: camera 'name' is blocked: ..." per
/// camera the obstacle meshes block (geometry::ObstacleDepthMap::blocked: a
/// mesh through its centre, or around it within 10 cm): it would run failed
/// (blocked), seeing nothing. Renders every camera's obstacle depth (about
/// 0.2 s per Full HD camera): hullguardd --check-config calls it, not
/// LoadConfig; a running daemon logs the same as an error.
[[nodiscard]] std::vector<std::string> BlockedCameraNotices(const Config& config);

/// The recording's camera that config camera `camera` plays in `hullguard
/// replay`: its replay source's `camera` where it has one, else its own name.
[[nodiscard]] std::string RecordedCameraName(const CameraConfig& camera);

/// Checks that `recording` (a folder of `hullguard synth` or `record`) can be
/// replayed with `config`'s cameras: its cameras.yaml holds each config
/// camera's recorded camera (RecordedCameraName) with the same size,
/// intrinsics, distortion and pose (a recording of another rig, or cameras
/// swapped, would carve each silhouette with another camera's pose). A
/// camera without frames (one the black box dumped because it was lost)
/// replays as a camera that never delivers.
/// @throws common::ConfigError naming the recording's file and every problem.
void CheckRecordingForConfig(const Config& config, const std::string& recording);

/// "4 cameras (4 sim), depth 9, 30 Hz": a one-line summary for --check-config.
[[nodiscard]] std::string Summary(const Config& config);

/// The full text of docs/configuration.md, generated from the field tables.
[[nodiscard]] std::string ConfigReferenceMarkdown();

}  // namespace hg::app
