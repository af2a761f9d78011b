#pragma once
/// @file
/// A GigE Vision camera for tests: Aravis' fake camera (ArvGvFakeCamera) in
/// the test process, on a loopback address, with a sensor of the test's size,
/// serving the test's RGB images in whatever pixel format the client selects
/// (RGB8, Mono8 or one of the four 8-bit Bayer mosaics). It speaks real GVCP
/// and GVSP, so a client sees a camera on the network; destroying the object
/// makes the camera vanish without a goodbye, as a pulled cable does.
/// Built only with Aravis; run through tests/publish/in_netns.sh.

#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include "common/image.h"

namespace hg::testing {

/// Single-thread for construction and destruction; `frame` runs on the fake
/// camera's own thread.
class FakeGigeCamera {
 public:
  /// Returns the image of frame `index` (counting from 0 for this camera
  /// object), `width` x `height`. Called on the camera's thread for every
  /// frame it sends; the image must stay valid until the next call.
  using FrameFn = std::function<const common::ImageRgb8&(std::uint64_t index)>;

  /// Serves on `address` (an IPv4 address of an interface that is up, e.g.
  /// 127.0.0.2 after AddLoopbackAddress) at the GigE Vision control port.
  /// Check running(): another camera may already hold the address.
  FakeGigeCamera(const std::string& address, const std::string& serial, int width, int height,
                 FrameFn frame);
  ~FakeGigeCamera();
  FakeGigeCamera(const FakeGigeCamera&) = delete;
  FakeGigeCamera& operator=(const FakeGigeCamera&) = delete;

  /// Listening on the address.
  [[nodiscard]] bool running() const;
  /// Frames filled so far (sent, unless the client stopped listening).
  [[nodiscard]] std::uint64_t frames_served() const;

 private:
  struct State;  // What the fill callback uses, on the camera's thread.
  std::unique_ptr<State> state_;
  void* camera_ = nullptr;  // The ArvGvFakeCamera (a GObject).
};

/// Adds `address` (127.x.y.z) to the loopback interface, so that a fake camera
/// can listen on it. Refuses (false, *error set) outside the private network
/// namespace of tests/publish/in_netns.sh (HG_IN_NETNS=1): the host's
/// interfaces are never touched. Adding an address twice is no error.
bool AddLoopbackAddress(const std::string& address, std::string* error);

}  // namespace hg::testing
