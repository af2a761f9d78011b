#include "capture/replay_source.h"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <thread>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "common/config_error.h"
#include "common/yaml_file.h"

namespace hg::capture {

RecordingCamera ReadRecordingCamera(const std::string& directory, const std::string& camera) {
  const std::string manifest = (std::filesystem::path(directory) / "manifest.yaml").string();
  const YAML::Node root = common::LoadYamlFile(manifest);
  auto fail = [&](const YAML::Node& at, const std::string& key, const std::string& problem) {
    throw common::ConfigError(manifest + ":" + std::to_string(common::YamlLine(at)) + ": " + key +
                              ": " + problem);
  };
  const YAML::Node head = root["synth"];
  if (!head || !head.IsMap()) fail(root, "synth", "missing map (not a recording folder?)");
  RecordingCamera r;
  r.directory = directory;
  r.camera = camera;
  try {
    r.rate_hz = head["rate_hz"].as<double>();
    r.frames = head["frames"].as<int>();
    r.masks = head["masks"].as<bool>();
    r.colour = head["colour"].as<bool>();
  } catch (const YAML::Exception& e) {
    fail(head, "synth", std::string("expected rate_hz, frames, masks, colour: ") + e.what());
  }
  if (!(r.rate_hz > 0.0) || r.frames < 1 || (!r.masks && !r.colour)) {
    fail(head, "synth", "needs rate_hz > 0, frames >= 1 and masks or colour");
  }
  const YAML::Node cameras = root["cameras"];
  if (!cameras || !cameras.IsSequence()) fail(root, "cameras", "missing list");
  for (const YAML::Node& c : cameras) {
    if (c["name"] && c["name"].as<std::string>() == camera) {
      r.time_offset_s = c["time_offset_s"] ? c["time_offset_s"].as<double>() : 0.0;
      return r;
    }
  }
  fail(cameras, "cameras", "the recording has no camera '" + camera + "'");
  return r;
}

ReplaySource::ReplaySource(RecordingCamera recording, SimClock clock)
    : recording_(std::move(recording)), clock_(clock) {
  const double period = 1.0 / recording_.rate_hz;
  double offset = std::fmod(recording_.time_offset_s, period);
  if (offset < 0.0) offset += period;
  offset_ = std::chrono::duration<double>(offset);
}

std::chrono::steady_clock::time_point ReplaySource::Due(int index) const {
  return clock_.start + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                            std::chrono::duration<double>(index / recording_.rate_hz) + offset_);
}

bool ReplaySource::Load(int index, Frame* frame) {
  char name[32];
  std::snprintf(name, sizeof(name), "/%06d.png", index);
  path_.assign(recording_.directory)
      .append(recording_.masks ? "/masks/" : "/colour/")
      .append(recording_.camera)
      .append(name);
  std::ifstream in(path_, std::ios::binary | std::ios::ate);
  if (!in) return false;
  file_bytes_.resize(static_cast<std::size_t>(in.tellg()));
  in.seekg(0);
  if (!in.read(reinterpret_cast<char*>(file_bytes_.data()),
               static_cast<std::streamsize>(file_bytes_.size()))) {
    return false;
  }
  const cv::Mat bytes(1, static_cast<int>(file_bytes_.size()), CV_8UC1, file_bytes_.data());
  if (recording_.masks) {
    const cv::Mat img = cv::imdecode(bytes, cv::IMREAD_GRAYSCALE);
    if (img.empty() || !img.isContinuous()) return false;
    frame->kind = FrameKind::kMask;
    frame->grey.width = img.cols;
    frame->grey.height = img.rows;
    frame->grey.pixels.assign(img.data, img.data + img.total());
  } else {
    const cv::Mat img = cv::imdecode(bytes, cv::IMREAD_COLOR);
    if (img.empty()) return false;
    frame->kind = FrameKind::kRgb;
    frame->rgb.width = img.cols;
    frame->rgb.height = img.rows;
    frame->rgb.pixels.resize(img.total() * 3);
    cv::Mat rgb(img.rows, img.cols, CV_8UC3, frame->rgb.pixels.data());
    cv::cvtColor(img, rgb, cv::COLOR_BGR2RGB);
  }
  return true;
}

bool ReplaySource::ReadFrame(int index, Frame* frame) {
  if (index < 0 || index >= recording_.frames || !Load(index, frame)) return false;
  frame->stamp_ns =
      clock_.epoch_ns +
      std::chrono::duration_cast<std::chrono::nanoseconds>(Due(index) - clock_.start).count();
  frame->index = static_cast<std::uint64_t>(index);
  return true;
}

bool ReplaySource::Next(Frame* frame, std::chrono::milliseconds timeout) {
  using Clock = std::chrono::steady_clock;
  const Clock::time_point give_up = Clock::now() + timeout;
  for (;;) {
    if (stopped_.load()) return false;
    const Clock::time_point now = Clock::now();
    if (next_index_ >= recording_.frames) {
      // The recording ended: the camera falls silent.
      std::this_thread::sleep_until(std::min(give_up, now + std::chrono::milliseconds(20)));
      if (Clock::now() >= give_up) return false;
      continue;
    }
    if (now >= Due(next_index_)) break;
    if (now >= give_up) return false;
    std::this_thread::sleep_until(
        std::min({Due(next_index_), give_up, now + std::chrono::milliseconds(20)}));
  }
  // The newest frame that is due; earlier ones are skipped, as a camera's
  // would be when its reader falls behind.
  const Clock::time_point now = Clock::now();
  while (next_index_ + 1 < recording_.frames && Due(next_index_ + 1) <= now) ++next_index_;
  const int index = next_index_++;
  if (!Load(index, frame)) {
    corrupt_.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  frame->stamp_ns =
      clock_.epoch_ns +
      std::chrono::duration_cast<std::chrono::nanoseconds>(Due(index) - clock_.start).count();
  frame->index = static_cast<std::uint64_t>(index);
  return true;
}

}  // namespace hg::capture
