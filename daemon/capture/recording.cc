#include "capture/recording.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include <cerrno>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "common/config_error.h"
#include "common/input_file.h"
#include "common/limits.h"
#include "common/yaml_file.h"
#include "geometry/camera_yaml.h"
#include "silhouette/mask_io.h"

namespace hg::capture {
namespace {

namespace fs = std::filesystem;
using common::ConfigError;

constexpr int kRecordFormat = 1;
constexpr char kIndexHeader[] = "frame,stamp_ns,device_stamp_ns,source_index,file";
// Larger than any frame file (an RGB image of 16384 x 16384 is 768 MiB raw).
constexpr std::streamoff kMaxFrameFileBytes = std::streamoff{1} << 30;
/// Longest side of a frame a header may state (and common::ImageFits()).
constexpr long long kMaxFrameSide = 1LL << 16;
// Frame rates and spans a recording may claim.
constexpr double kMaxRateHz = 1000.0;
/// As a scene's rate_hz (docs/scenes.md): below it, frame times run into days.
constexpr double kMinRateHz = 0.1;
/// Frame sets a synth manifest may claim (9 hours at 30 Hz): each is listed
/// in memory before any is read.
constexpr int kMaxSynthFrames = 1'000'000;
constexpr std::int64_t kMaxSpanNs = std::int64_t{30} * 24 * 3600 * 1'000'000'000;  // 30 days.

std::string ManifestPath(const std::string& directory) {
  return (fs::path(directory) / "manifest.yaml").string();
}

std::string IndexPath(const std::string& directory, const std::string& camera) {
  return (fs::path(directory) / "frames" / camera / "index.csv").string();
}

[[noreturn]] void Fail(const std::string& file, const YAML::Node& at, const std::string& key,
                       const std::string& problem) {
  throw ConfigError::At(file, at.IsDefined() ? common::YamlLine(at) : 0, key + ": " + problem);
}

/// The manifest's head: `synth:` or `recording:`.
RecordingLayout LayoutOf(const YAML::Node& root, const std::string& manifest) {
  // A missing key of a const node is invalid: test it before asking its type.
  if (root.IsMap()) {
    if (const YAML::Node head = root["recording"]; head && head.IsMap()) {
      return RecordingLayout::kRecord;
    }
    if (const YAML::Node head = root["synth"]; head && head.IsMap()) return RecordingLayout::kSynth;
  }
  Fail(manifest, root, "synth", "missing map `synth` or `recording` (not a recording folder?)");
}

YAML::Node CameraEntry(const YAML::Node& root, const std::string& manifest,
                       const std::string& camera) {
  const YAML::Node cameras = root["cameras"];
  if (!cameras || !cameras.IsSequence()) Fail(manifest, root, "cameras", "missing list");
  for (const YAML::Node& c : cameras) {
    if (!c.IsMap() || !c["name"] || !c["name"].IsScalar()) {
      Fail(manifest, c, "cameras", "every entry needs a name");
    }
    if (c["name"].Scalar() == camera) return c;
  }
  Fail(manifest, cameras, "cameras", "the recording has no camera '" + camera + "'");
}

template <typename T>
bool ParseInt(std::string_view text, T* out) {
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), *out);
  return !text.empty() && ec == std::errc() && end == text.data() + text.size();
}

/// Reads frames/<camera>/index.csv: every complete line (a last line without
/// its newline was cut short by a crash and is left out).
std::vector<RecordedFrame> ReadIndex(const std::string& path) {
  const std::string text = common::ReadInputFile(path, "the frames index", std::ios::binary);
  std::vector<RecordedFrame> frames;
  std::size_t pos = 0;
  int line = 0;
  while (pos < text.size()) {
    const std::size_t end = text.find('\n', pos);
    if (end == std::string::npos) break;  // Cut short.
    const std::string_view row(text.data() + pos, end - pos);
    pos = end + 1;
    ++line;
    if (line == 1) {
      if (row != kIndexHeader) {
        throw ConfigError::At(path, line,
                              std::string("expected the header '") + kIndexHeader + "'");
      }
      continue;
    }
    std::string_view field[5];
    std::size_t start = 0;
    int n = 0;
    for (; n < 5; ++n) {
      const std::size_t comma = n < 4 ? row.find(',', start) : std::string_view::npos;
      if (n < 4 && comma == std::string_view::npos) break;
      field[n] = row.substr(start, comma == std::string_view::npos ? row.npos : comma - start);
      start = comma + 1;
    }
    RecordedFrame f;
    std::uint64_t number = 0;
    std::int64_t device = 0;
    const bool ok = n == 5 && ParseInt(field[0], &number) && ParseInt(field[1], &f.stamp_ns) &&
                    (field[2].empty() || ParseInt(field[2], &device)) &&
                    ParseInt(field[3], &f.source_index) && !field[4].empty() &&
                    field[4].find_first_of("/,") == std::string_view::npos && field[4] != "." &&
                    field[4] != "..";
    if (!ok) {
      throw ConfigError::At(path, line,
                            "expected frame,stamp_ns,device_stamp_ns,source_index,file (got '" +
                                std::string(row) + "')");
    }
    if (f.stamp_ns <= 0) throw ConfigError::At(path, line, "stamp_ns must be > 0");
    // Stamps may step back with the host clock, but never this far.
    if (!frames.empty() && std::abs(f.stamp_ns - frames.front().stamp_ns) > kMaxSpanNs) {
      throw ConfigError::At(path, line, "stamp_ns more than 30 days from the first frame's");
    }
    if (!field[2].empty()) f.device_stamp_ns = device;
    f.file = std::string(field[4]);
    frames.push_back(std::move(f));
  }
  return frames;
}

/// Stamp of the first indexed frame of a camera; nullopt when it has none.
std::optional<std::int64_t> FirstStamp(const std::string& path) {
  std::ifstream in = common::OpenInputFile(path, "the frames index", std::ios::binary);
  std::string header, row;
  if (!std::getline(in, header) || !std::getline(in, row) || in.eof()) return std::nullopt;
  const std::size_t a = row.find(',');
  const std::size_t b = a == std::string::npos ? a : row.find(',', a + 1);
  std::int64_t stamp = 0;
  if (b == std::string::npos || !ParseInt(std::string_view(row).substr(a + 1, b - a - 1), &stamp)) {
    throw ConfigError::At(path, 2, "bad frame line '" + row + "'");
  }
  return stamp;
}

RecordingCamera ReadSynth(const YAML::Node& root, const std::string& manifest,
                          const std::string& directory, const std::string& camera) {
  const YAML::Node head = root["synth"];
  RecordingCamera r;
  r.directory = directory;
  r.camera = camera;
  r.layout = RecordingLayout::kSynth;
  int frames = 0;
  bool masks = false, colour = false;
  try {
    r.rate_hz = head["rate_hz"].as<double>();
    frames = head["frames"].as<int>();
    masks = head["masks"].as<bool>();
    colour = head["colour"].as<bool>();
  } catch (const YAML::Exception& e) {
    Fail(manifest, head, "synth",
         std::string("expected rate_hz, frames, masks, colour: ") + e.what());
  }
  if (!(r.rate_hz >= kMinRateHz && r.rate_hz <= kMaxRateHz) || frames < 1 ||
      frames > kMaxSynthFrames || (!masks && !colour)) {
    Fail(manifest, head, "synth",
         "needs 0.1 <= rate_hz <= " + std::to_string(static_cast<int>(kMaxRateHz)) +
             ", 1 <= frames <= " + std::to_string(kMaxSynthFrames) + " and masks or colour");
  }
  const YAML::Node c = CameraEntry(root, manifest, camera);
  r.time_offset_s = 0.0;
  if (const YAML::Node offset = c["time_offset_s"]) {
    try {
      r.time_offset_s = offset.as<double>();
    } catch (const YAML::Exception&) {
      Fail(manifest, offset, "time_offset_s", "not a number");
    }
    // A capture offset is a fraction of a period; NaN or a huge one would put
    // the frames (and their ground truth) at times that mean nothing.
    if (!(std::abs(r.time_offset_s) <= 1.0)) {
      Fail(manifest, offset, "time_offset_s", "must be a number of seconds within [-1, 1]");
    }
  }
  // Masks are preferred: they are the ground truth the colour frames show.
  r.kind = masks ? FrameKind::kMask : FrameKind::kRgb;
  // Frame i shows the scene at i / rate_hz plus the camera's offset (the
  // simulator renders it then), and is stamped so: a negative offset is a
  // frame taken before the set's nominal time, never one a period later (its
  // stamp would claim a newer view than it holds). Frame 0 of such a camera
  // lies before recording time 0.
  const std::chrono::duration<double> offset_s(r.time_offset_s);
  const std::string folder = std::string(masks ? "masks/" : "colour/") + camera + "/";
  r.frames.resize(static_cast<std::size_t>(frames));
  for (int i = 0; i < frames; ++i) {
    RecordedFrame& f = r.frames[static_cast<std::size_t>(i)];
    f.time_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                    std::chrono::duration<double>(i / r.rate_hz) + offset_s)
                    .count();
    f.stamp_ns = f.time_ns;
    f.source_index = static_cast<std::uint64_t>(i);
    char name[32];
    std::snprintf(name, sizeof(name), "%06d.png", i);
    f.file = folder + name;
  }
  return r;
}

FrameKind ParseKind(const YAML::Node& node, const std::string& manifest) {
  const std::string text = node && node.IsScalar() ? node.Scalar() : "";
  for (FrameKind k : {FrameKind::kMask, FrameKind::kMono, FrameKind::kRgb}) {
    if (text == ToString(k)) return k;
  }
  Fail(manifest, node, "kind", "expected mask, mono or rgb (got '" + text + "')");
}

RecordingCamera ReadRecord(const YAML::Node& root, const std::string& manifest,
                           const std::string& directory, const std::string& camera) {
  const YAML::Node head = root["recording"];
  int format = 0;
  try {
    format = head["format"].as<int>();
  } catch (const YAML::Exception&) {
    Fail(manifest, head, "recording.format", "missing or not an integer");
  }
  if (format != kRecordFormat) {
    Fail(manifest, head, "recording.format",
         "this build reads format " + std::to_string(kRecordFormat) + " (got " +
             std::to_string(format) + ")");
  }
  const YAML::Node c = CameraEntry(root, manifest, camera);
  RecordingCamera r;
  r.directory = directory;
  r.camera = camera;
  r.layout = RecordingLayout::kRecord;
  r.kind = ParseKind(c["kind"], manifest);
  try {
    r.width = c["width"].as<int>();
    r.height = c["height"].as<int>();
    if (const YAML::Node lost = c["lost"]; lost && lost.IsMap()) {
      for (const auto& kv : lost) r.lost += kv.second.as<std::uint64_t>();
    }
  } catch (const YAML::Exception& e) {
    Fail(manifest, c, "cameras",
         std::string("expected width, height and lost counts: ") + e.what());
  }
  if (r.width < 1 || r.height < 1) Fail(manifest, c, "cameras", "width and height must be >= 1");
  r.frames = ReadIndex(IndexPath(directory, camera));
  for (RecordedFrame& f : r.frames) f.file = "frames/" + camera + "/" + f.file;
  // Recording time 0: the first frame of the camera that started first.
  std::optional<std::int64_t> start;
  for (const YAML::Node& other : root["cameras"]) {
    if (!other.IsMap() || !other["name"]) continue;
    const std::string name = other["name"].as<std::string>();
    const std::optional<std::int64_t> first =
        name == camera
            ? (r.frames.empty() ? std::nullopt : std::optional<std::int64_t>(r.frames[0].stamp_ns))
            : FirstStamp(IndexPath(directory, name));
    // Another camera's first stamp sets recording time 0 for all: one that
    // means nothing (not after the epoch, or far from this camera's) would
    // put this camera's frames at meaningless times.
    if (first && name != camera) {
      if (*first <= 0) throw ConfigError::At(IndexPath(directory, name), 2, "stamp_ns must be > 0");
      if (!r.frames.empty() && std::abs(*first - r.frames[0].stamp_ns) > kMaxSpanNs) {
        throw ConfigError::At(
            IndexPath(directory, name), 2,
            "stamp_ns more than 30 days from the first frame of camera '" + camera + "'");
      }
    }
    if (first && (!start || *first < *start)) start = first;
  }
  r.start_ns = start.value_or(0);
  for (RecordedFrame& f : r.frames) f.time_ns = f.stamp_ns - r.start_ns;
  r.rate_hz = 0.0;
  if (r.frames.size() >= 2) {
    const double span_s = (r.frames.back().stamp_ns - r.frames.front().stamp_ns) * 1e-9;
    if (span_s > 0.0) r.rate_hz = static_cast<double>(r.frames.size() - 1) / span_s;
  }
  return r;
}

std::int64_t RealtimeNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

}  // namespace

const char* ToString(FrameKind kind) {
  switch (kind) {
    case FrameKind::kMask:
      return "mask";
    case FrameKind::kMono:
      return "mono";
    case FrameKind::kRgb:
      return "rgb";
  }
  return "?";
}

int BytesPerPixel(FrameKind kind) { return kind == FrameKind::kRgb ? 3 : 1; }

const char* ToString(ImageFormat format) {
  switch (format) {
    case ImageFormat::kPng:
      return "png";
    case ImageFormat::kPnm:
      return "pnm";
    case ImageFormat::kAuto:
      return "auto";
  }
  return "?";
}

RecordingCamera ReadRecordingCamera(const std::string& directory, const std::string& camera) {
  const std::string manifest = ManifestPath(directory);
  const YAML::Node root = common::LoadYamlFile(manifest);
  if (LayoutOf(root, manifest) == RecordingLayout::kSynth) {
    return ReadSynth(root, manifest, directory, camera);
  }
  return ReadRecord(root, manifest, directory, camera);
}

std::vector<std::string> RecordingCameraNames(const std::string& directory) {
  const std::string manifest = ManifestPath(directory);
  const YAML::Node root = common::LoadYamlFile(manifest);
  (void)LayoutOf(root, manifest);
  const YAML::Node cameras = root["cameras"];
  if (!cameras || !cameras.IsSequence()) Fail(manifest, root, "cameras", "missing list");
  std::vector<std::string> names;
  for (const YAML::Node& c : cameras) {
    if (!c.IsMap() || !c["name"] || !c["name"].IsScalar()) {
      Fail(manifest, c, "cameras", "every entry needs a name");
    }
    names.push_back(c["name"].Scalar());
  }
  return names;
}

namespace {

/// Decodes an encoded frame whose header passed LoadRecordedFrame's checks.
bool DecodeRecordedFrame(const RecordingCamera& recording, std::size_t index,
                         const cv::Mat& encoded, const common::ImageHeaderFacts& facts,
                         Frame* frame);

}  // namespace

bool LoadRecordedFrame(const RecordingCamera& recording, std::size_t index, Frame* frame,
                       std::vector<unsigned char>* bytes, std::string* path) {
  if (index >= recording.frames.size()) return false;
  path->assign(recording.directory).append("/").append(recording.frames[index].file);
  // Only a regular file: a named pipe would block the read until someone
  // writes into it (and the capture thread with it), a device never ends.
  struct stat status {};
  if (::stat(path->c_str(), &status) != 0 || !S_ISREG(status.st_mode)) return false;
  std::ifstream in(*path, std::ios::binary | std::ios::ate);
  if (!in) return false;
  // An empty file, or one larger than any frame, is none.
  const std::streamoff size = in.tellg();
  if (size <= 0 || size > kMaxFrameFileBytes) return false;
  bytes->resize(static_cast<std::size_t>(size));
  in.seekg(0);
  if (!in.read(reinterpret_cast<char*>(bytes->data()),
               static_cast<std::streamsize>(bytes->size())) ||
      bytes->empty()) {
    return false;
  }
  const std::string_view encoded_bytes(reinterpret_cast<const char*>(bytes->data()), bytes->size());
  if (!common::IsTrustedImageFormat(encoded_bytes) || !common::IsCompleteImage(encoded_bytes)) {
    return false;
  }
  const cv::Mat encoded(1, static_cast<int>(bytes->size()), CV_8UC1, bytes->data());
  const common::ImageHeaderFacts facts = common::InspectImageHeader(encoded_bytes);
  // A decoder allocates what the header states, and a file of a few bytes
  // can state gigabytes: the size is checked before decoding (the recording's
  // where it states one, else a camera's largest), and a format whose header
  // size is not read here is not replayed.
  const bool sized = recording.width > 0;
  if (facts.width < 1 || facts.height < 1 || facts.width > kMaxFrameSide ||
      facts.height > kMaxFrameSide ||
      !common::ImageFits(static_cast<int>(facts.width), static_cast<int>(facts.height)) ||
      (sized && (facts.width != recording.width || facts.height != recording.height))) {
    return false;
  }
  try {
    return DecodeRecordedFrame(recording, index, encoded, facts, frame);
  } catch (const cv::Exception&) {  // The decoder's own refusal (damaged data, memory).
    return false;
  }
}

namespace {

bool DecodeRecordedFrame(const RecordingCamera& recording, std::size_t index,
                         const cv::Mat& encoded, const common::ImageHeaderFacts& facts,
                         Frame* frame) {
  // A keyed-out background (PNG tRNS) is dropped by the decoder: the frame
  // would read as drawn, not as meant. Unusable, as a damaged one.
  if (facts.png_colour_key) return false;
  // Pixels that index past a palette decode as black without a word: damage.
  if (silhouette::IndexesPastItsPalette(
          std::string_view(reinterpret_cast<const char*>(encoded.data), encoded.total()))) {
    return false;
  }
  if (facts.png_alpha) {
    // The same for transparent pixels of an alpha channel (opaque ones are
    // harmless): the decodes below drop it.
    const cv::Mat with_alpha = cv::imdecode(encoded, cv::IMREAD_UNCHANGED);
    if (with_alpha.empty() || with_alpha.depth() != CV_8U) return false;
    const int channels = with_alpha.channels();
    if (channels == 2 || channels == 4) {
      cv::Mat alpha;
      cv::extractChannel(with_alpha, alpha, channels - 1);
      double lowest = 0.0;
      cv::minMaxLoc(alpha, &lowest);
      if (lowest < 255.0) return false;
    }
  }
  const bool sized = recording.width > 0;
  frame->device_stamp_ns = recording.frames[index].device_stamp_ns.value_or(-1);
  if (recording.kind != FrameKind::kRgb) {
    // ANYDEPTH: a 16-bit image stays 16-bit and is refused below, where a plain
    // GRAYSCALE decode would scale 255 down to 0 (foreground read as background).
    // ANYCOLOR: a colour image stays colour and is refused below, where a
    // GRAYSCALE decode would make a grey mask of a camera image (a person
    // darker than the threshold read as background).
    cv::Mat img = cv::imdecode(encoded, cv::IMREAD_ANYCOLOR | cv::IMREAD_ANYDEPTH);
    if (img.empty() || img.type() != CV_8UC1 || !img.isContinuous()) return false;
    // Binary PGM samples are not scaled to 8 bits: a 0/1 mask (maxval 1)
    // would read as all background.
    if (facts.pnm_maxval > 0 && facts.pnm_maxval < 255) {
      img.convertTo(img, -1, 255.0 / facts.pnm_maxval);
    }
    if (sized && (img.cols != recording.width || img.rows != recording.height)) return false;
    frame->kind = recording.kind;
    frame->grey.width = img.cols;
    frame->grey.height = img.rows;
    frame->grey.pixels.assign(img.data, img.data + img.total());
  } else {
    // ANYCOLOR: a grey image is refused (the colours that tell a person from
    // the background are not in it), not spread over three channels.
    cv::Mat img = cv::imdecode(encoded, cv::IMREAD_ANYCOLOR | cv::IMREAD_ANYDEPTH);
    if (img.empty() || img.type() != CV_8UC3) return false;
    if (facts.pnm_maxval > 0 && facts.pnm_maxval < 255) {
      img.convertTo(img, -1, 255.0 / facts.pnm_maxval);
    }
    if (sized && (img.cols != recording.width || img.rows != recording.height)) return false;
    frame->kind = FrameKind::kRgb;
    frame->rgb.width = img.cols;
    frame->rgb.height = img.rows;
    frame->rgb.pixels.resize(img.total() * 3);
    cv::Mat rgb(img.rows, img.cols, CV_8UC3, frame->rgb.pixels.data());
    cv::cvtColor(img, rgb, cv::COLOR_BGR2RGB);
  }
  return true;
}

}  // namespace

// ---------------------------------------------------------------------------
// RecordingWriter.

RecordingWriter::RecordingWriter(std::string directory, std::vector<geometry::CameraModel> cameras,
                                 std::string writer, std::string note, ImageFormat format)
    : directory_(std::move(directory)),
      writer_(std::move(writer)),
      note_(std::move(note)),
      format_(format),
      created_ns_(RealtimeNs()),
      cameras_(cameras.size()) {
  std::error_code ec;
  if (fs::exists(ManifestPath(directory_), ec)) {
    throw ConfigError(directory_ + ": already holds a recording (manifest.yaml); choose another");
  }
  for (std::size_t c = 0; c < cameras.size(); ++c) {
    CameraState& s = cameras_[c];
    s.model = std::move(cameras[c]);
    const fs::path folder = fs::path(directory_) / "frames" / s.model.name;
    fs::create_directories(folder, ec);
    if (ec) throw ConfigError(folder.string() + ": cannot create: " + ec.message());
    const std::string index = (folder / "index.csv").string();
    s.index = ::open(index.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    const std::string header = std::string(kIndexHeader) + "\n";
    if (s.index < 0 || !AppendIndexLine(&s, header.data(), header.size())) {
      throw ConfigError(index + ": cannot write: " + std::strerror(errno));
    }
  }
  std::vector<geometry::CameraModel> models;
  for (const CameraState& s : cameras_) models.push_back(s.model);
  geometry::WriteCamerasFile((fs::path(directory_) / "cameras.yaml").string(), models);
  std::string error;
  const std::lock_guard<std::mutex> lock(manifest_mutex_);
  if (!WriteManifest(false, &error)) throw ConfigError(error);
}

RecordingWriter::~RecordingWriter() {
  Finish(nullptr);
  for (CameraState& c : cameras_) {
    if (c.index >= 0) ::close(c.index);
  }
}

bool RecordingWriter::Fail(CameraState* c, const std::string& what) {
  ++c->stats.write_errors;
  c->stats.last_error = what;
  return false;
}

bool RecordingWriter::Write(int camera, std::uint64_t number, const Frame& frame,
                            std::optional<std::int64_t> device_stamp_ns) {
  CameraState& c = cameras_[static_cast<std::size_t>(camera)];
  if (finished_ || c.index < 0) return Fail(&c, "the recording is closed");
  const bool rgb = frame.kind == FrameKind::kRgb;
  const int width = rgb ? frame.rgb.width : frame.grey.width;
  const int height = rgb ? frame.rgb.height : frame.grey.height;
  const std::size_t bytes = static_cast<std::size_t>(width) * height * (rgb ? 3 : 1);
  if (width < 1 || height < 1 ||
      (rgb ? frame.rgb.pixels.size() : frame.grey.pixels.size()) != bytes) {
    return Fail(&c, "frame " + std::to_string(number) + ": empty or inconsistent image");
  }
  {
    // The first frame fixes the camera's kind and size; later ones must match,
    // or the recording would not read back as one camera.
    const std::lock_guard<std::mutex> lock(manifest_mutex_);
    if (!c.kind_known) {
      c.kind = frame.kind;
      c.width = width;
      c.height = height;
      c.kind_known = true;
      std::string error;
      if (!WriteManifest(false, &error)) {
        c.kind_known = false;
        return Fail(&c, error);
      }
    } else if (c.kind != frame.kind || c.width != width || c.height != height) {
      return Fail(&c, "frame " + std::to_string(number) + ": " + ToString(frame.kind) + " " +
                          std::to_string(width) + "x" + std::to_string(height) + " after " +
                          ToString(c.kind) + " " + std::to_string(c.width) + "x" +
                          std::to_string(c.height));
    }
  }
  const std::uint8_t* pixels = rgb ? frame.rgb.pixels.data() : frame.grey.pixels.data();
  const unsigned char* data = pixels;
  std::size_t size = bytes;
  char header[48] = "";
  char name[32];
  const bool pnm = format_ == ImageFormat::kPnm ||
                   (format_ == ImageFormat::kAuto && frame.kind != FrameKind::kMask);
  if (pnm) {
    // Binary PGM / PPM: the pixels as they are behind a one-line header.
    std::snprintf(header, sizeof(header), "%s\n%d %d\n255\n", rgb ? "P6" : "P5", width, height);
    std::snprintf(name, sizeof(name), "%06llu.%s", static_cast<unsigned long long>(number),
                  rgb ? "ppm" : "pgm");
  } else {
    // Level 1: higher levels cost twice the time for a few per cent on noisy
    // camera images.
    const std::vector<int> params = {cv::IMWRITE_PNG_COMPRESSION, 1};
    bool encoded = false;
    try {
      if (rgb) {
        c.bgr.resize(bytes);
        const cv::Mat in(height, width, CV_8UC3, const_cast<std::uint8_t*>(pixels));
        cv::Mat bgr(height, width, CV_8UC3, c.bgr.data());
        cv::cvtColor(in, bgr, cv::COLOR_RGB2BGR);
        encoded = cv::imencode(".png", bgr, c.bytes, params);
      } else {
        const cv::Mat in(height, width, CV_8UC1, const_cast<std::uint8_t*>(pixels));
        encoded = cv::imencode(".png", in, c.bytes, params);
      }
    } catch (const cv::Exception& e) {
      return Fail(&c, std::string("encoding: ") + e.what());
    }
    if (!encoded) return Fail(&c, "frame " + std::to_string(number) + ": PNG encoding failed");
    data = c.bytes.data();
    size = c.bytes.size();
    std::snprintf(name, sizeof(name), "%06llu.png", static_cast<unsigned long long>(number));
  }
  c.path.assign(directory_).append("/frames/").append(c.model.name).append("/").append(name);
  std::FILE* file = std::fopen(c.path.c_str(), "wb");
  if (file == nullptr) return Fail(&c, c.path + ": " + std::strerror(errno));
  const std::size_t header_size = std::strlen(header);
  const bool written = std::fwrite(header, 1, header_size, file) == header_size &&
                       std::fwrite(data, 1, size, file) == size;
  const int write_errno = errno;
  if (std::fclose(file) != 0 || !written) {
    const std::string why = std::strerror(written ? errno : write_errno);
    std::remove(c.path.c_str());
    return Fail(&c, c.path + ": " + why);
  }
  char device[32] = "";
  if (!device_stamp_ns && frame.device_stamp_ns >= 0) device_stamp_ns = frame.device_stamp_ns;
  if (device_stamp_ns) {
    std::snprintf(device, sizeof(device), "%lld", static_cast<long long>(*device_stamp_ns));
  }
  char line[160];
  const int length =
      std::snprintf(line, sizeof(line), "%llu,%lld,%s,%llu,%s\n",
                    static_cast<unsigned long long>(number), static_cast<long long>(frame.stamp_ns),
                    device, static_cast<unsigned long long>(frame.index), name);
  if (length <= 0 || static_cast<std::size_t>(length) >= sizeof(line) ||
      !AppendIndexLine(&c, line, static_cast<std::size_t>(length))) {
    const std::string why = std::strerror(errno);
    // Without its index line the frame is not in the recording.
    std::remove(c.path.c_str());
    return Fail(&c, IndexPath(directory_, c.model.name) + ": " + why);
  }
  ++c.stats.kept;
  return true;
}

bool RecordingWriter::AppendIndexLine(CameraState* c, const char* line, std::size_t length) {
  // Straight to the descriptor, whole or not at all: a disk that fills in the
  // middle of a line left half of it, and the next line glued on, and the
  // reader refused the whole recording. A failed write is cut back to the
  // last whole line.
  const int fd = c->index;
  std::size_t done = 0;
  while (done < length) {
    const ssize_t n = ::write(fd, line + done, length - done);
    if (n > 0) {
      done += static_cast<std::size_t>(n);
      continue;
    }
    if (n < 0 && errno == EINTR) continue;
    const int error = n < 0 ? errno : ENOSPC;
    if (::ftruncate(fd, c->index_bytes) == 0) ::lseek(fd, c->index_bytes, SEEK_SET);
    errno = error;
    return false;
  }
  c->index_bytes += static_cast<std::int64_t>(length);
  return true;
}

void RecordingWriter::CountLost(int camera, FrameLoss reason, std::uint64_t count) {
  RecordingCameraStats& s = cameras_[static_cast<std::size_t>(camera)].stats;
  switch (reason) {
    case FrameLoss::kQueueFull:
      s.queue_full += count;
      break;
    case FrameLoss::kWriteError:
      s.write_errors += count;
      break;
    case FrameLoss::kOverwritten:
      s.overwritten += count;
      break;
  }
}

bool RecordingWriter::WriteManifest(bool complete, std::string* error) const {
  YAML::Emitter out;
  out << YAML::BeginMap << YAML::Key << "recording" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "format" << YAML::Value << kRecordFormat;
  out << YAML::Key << "writer" << YAML::Value << writer_;
  out << YAML::Key << "images" << YAML::Value << ToString(format_);
  if (!note_.empty()) out << YAML::Key << "note" << YAML::Value << note_;
  out << YAML::Key << "created_ns" << YAML::Value << created_ns_;
  out << YAML::Key << "complete" << YAML::Value << complete;
  out << YAML::EndMap;
  out << YAML::Key << "cameras" << YAML::Value << YAML::BeginSeq;
  for (const CameraState& c : cameras_) {
    out << YAML::Flow << YAML::BeginMap;
    out << YAML::Key << "name" << YAML::Value << c.model.name;
    // Until its first frame, a camera's kind is unknown; its calibrated size
    // stands in (the index is empty then).
    out << YAML::Key << "kind" << YAML::Value
        << (c.kind_known ? ToString(c.kind) : ToString(FrameKind::kMask));
    out << YAML::Key << "width" << YAML::Value << (c.kind_known ? c.width : c.model.width);
    out << YAML::Key << "height" << YAML::Value << (c.kind_known ? c.height : c.model.height);
    if (complete) {
      out << YAML::Key << "frames" << YAML::Value << c.stats.kept;
      out << YAML::Key << "lost" << YAML::Value << YAML::BeginMap;
      out << YAML::Key << "queue_full" << YAML::Value << c.stats.queue_full;
      out << YAML::Key << "write_error" << YAML::Value << c.stats.write_errors;
      out << YAML::Key << "overwritten" << YAML::Value << c.stats.overwritten;
      out << YAML::EndMap;
    }
    out << YAML::EndMap;
  }
  out << YAML::EndSeq << YAML::EndMap;
  // Written aside and renamed: a reader never sees half a manifest.
  const std::string path = ManifestPath(directory_);
  const std::string temp = path + ".tmp";
  try {
    common::WriteYamlFile(temp, out);
  } catch (const ConfigError& e) {
    if (error != nullptr) *error = e.what();
    return false;
  }
  std::error_code ec;
  fs::rename(temp, path, ec);
  if (ec) {
    if (error != nullptr) *error = path + ": " + ec.message();
    return false;
  }
  return true;
}

bool RecordingWriter::Finish(std::string* error) {
  if (finished_) return true;
  finished_ = true;
  bool ok = true;
  std::string why;
  for (CameraState& c : cameras_) {
    if (c.index >= 0 && ::close(c.index) != 0) {
      ok = false;
      why = IndexPath(directory_, c.model.name) + ": " + std::strerror(errno);
    }
    c.index = -1;
  }
  const std::lock_guard<std::mutex> lock(manifest_mutex_);
  if (!WriteManifest(true, &why)) ok = false;
  if (!ok && error != nullptr) *error = why;
  return ok;
}

}  // namespace hg::capture
