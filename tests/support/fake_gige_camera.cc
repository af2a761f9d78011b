#include "support/fake_gige_camera.h"

#include <arv.h>
#include <spawn.h>
#include <sys/wait.h>

#include <algorithm>
#include <atomic>
#include <cstdlib>
#include <cstring>
#include <vector>

extern char** environ;

namespace hg::testing {
namespace {

// The fake camera's sensor is 2048 x 2048 unless told otherwise.
void SetSensorSize(ArvFakeCamera* fake, int width, int height) {
  const auto w = static_cast<guint32>(width);
  const auto h = static_cast<guint32>(height);
  arv_fake_camera_write_register(fake, ARV_FAKE_CAMERA_REGISTER_SENSOR_WIDTH, w);
  arv_fake_camera_write_register(fake, ARV_FAKE_CAMERA_REGISTER_SENSOR_HEIGHT, h);
  arv_fake_camera_write_register(fake, ARV_FAKE_CAMERA_REGISTER_WIDTH, w);
  arv_fake_camera_write_register(fake, ARV_FAKE_CAMERA_REGISTER_HEIGHT, h);
}

// RGB channel (0 R, 1 G, 2 B) of the Bayer site at (u, v): GenICam names a
// mosaic by its first row's first two sites.
int BayerChannel(ArvPixelFormat format, int u, int v) {
  const int site = (v % 2) * 2 + (u % 2);
  static constexpr int kRg[4] = {0, 1, 1, 2};
  static constexpr int kGb[4] = {1, 2, 0, 1};
  static constexpr int kGr[4] = {1, 0, 2, 1};
  static constexpr int kBg[4] = {2, 1, 1, 0};
  switch (format) {
    case ARV_PIXEL_FORMAT_BAYER_RG_8:
      return kRg[site];
    case ARV_PIXEL_FORMAT_BAYER_GB_8:
      return kGb[site];
    case ARV_PIXEL_FORMAT_BAYER_GR_8:
      return kGr[site];
    case ARV_PIXEL_FORMAT_BAYER_BG_8:
      return kBg[site];
    default:
      return -1;
  }
}

}  // namespace

struct FakeGigeCamera::State {
  FrameFn frame;
  std::atomic<std::uint64_t> frames{0};

  // Runs on the fake camera's thread for every frame it sends. The buffer
  // holds the full payload of the image size and format the client set.
  static void Fill(ArvBuffer* buffer, void* self, guint32 /*exposure_us*/, guint32 /*gain*/,
                   ArvPixelFormat format) {
    auto* state = static_cast<State*>(self);
    const common::ImageRgb8& image = state->frame(state->frames.fetch_add(1));
    const int w = arv_buffer_get_image_width(buffer);
    const int h = arv_buffer_get_image_height(buffer);
    // The fake camera allocated the buffer for the image it announces; the
    // data size Aravis reports is not set yet while the buffer is filled.
    auto* data =
        static_cast<std::uint8_t*>(const_cast<void*>(arv_buffer_get_data(buffer, nullptr)));
    const bool rgb = format == ARV_PIXEL_FORMAT_RGB_8_PACKED;
    const std::size_t bytes = static_cast<std::size_t>(w) * h * (rgb ? 3 : 1);
    if (data == nullptr) return;
    std::memset(data, 0, bytes);
    // A client that has not set the region yet may get another size: the
    // overlap is filled, the rest stays black.
    const int cw = std::min(w, image.width);
    const int ch = std::min(h, image.height);
    for (int v = 0; v < ch; ++v) {
      for (int u = 0; u < cw; ++u) {
        const std::uint8_t* p = image.Pixel(u, v);
        const std::size_t i = static_cast<std::size_t>(v) * w + u;
        if (rgb) {
          std::memcpy(data + 3 * i, p, 3);
        } else if (format == ARV_PIXEL_FORMAT_MONO_8) {
          // ITU-R BT.601 luma, rounded.
          data[i] = static_cast<std::uint8_t>((299 * p[0] + 587 * p[1] + 114 * p[2] + 500) / 1000);
        } else if (const int c = BayerChannel(format, u, v); c >= 0) {
          data[i] = p[c];
        }
      }
    }
  }
};

FakeGigeCamera::FakeGigeCamera(const std::string& address, const std::string& serial, int width,
                               int height, FrameFn frame)
    : state_(std::make_unique<State>()) {
  state_->frame = std::move(frame);
  ArvGvFakeCamera* camera = arv_gv_fake_camera_new(address.c_str(), serial.c_str());
  camera_ = camera;
  ArvFakeCamera* fake = arv_gv_fake_camera_get_fake_camera(camera);
  // A client connecting before this sees a 2048 x 2048 sensor, refuses it
  // (not the calibrated size) and tries again.
  SetSensorSize(fake, width, height);
  arv_fake_camera_set_fill_pattern(fake, &State::Fill, state_.get());
}

FakeGigeCamera::~FakeGigeCamera() {
  // Stops the camera's thread (joined) and closes its sockets.
  g_object_unref(static_cast<ArvGvFakeCamera*>(camera_));
}

bool FakeGigeCamera::running() const {
  return arv_gv_fake_camera_is_running(static_cast<ArvGvFakeCamera*>(camera_));
}

std::uint64_t FakeGigeCamera::frames_served() const { return state_->frames.load(); }

bool AddLoopbackAddress(const std::string& address, std::string* error) {
  const char* in_netns = std::getenv("HG_IN_NETNS");
  if (in_netns == nullptr || std::strcmp(in_netns, "1") != 0) {
    *error = "not inside tests/publish/in_netns.sh: the host's loopback is left alone";
    return false;
  }
  // "replace" adds the address or keeps it: adding twice is no error.
  std::vector<std::string> args = {"ip", "addr", "replace", address + "/8", "dev", "lo"};
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  pid_t pid = -1;
  if (posix_spawnp(&pid, "ip", nullptr, nullptr, argv.data(), environ) != 0) {
    *error = "cannot run ip";
    return false;
  }
  int status = 0;
  if (waitpid(pid, &status, 0) != pid || !WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    *error = "ip addr replace " + address + "/8 dev lo failed";
    return false;
  }
  return true;
}

}  // namespace hg::testing
