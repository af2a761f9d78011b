#pragma once
/// @file
/// The seam between the `v4l2` camera source and the kernel: the few
/// Video4Linux2 calls that mmap streaming capture needs, one virtual function
/// each, so that the source can be tested against a scripted fake driver on
/// machines without a camera. The real implementation is a thin wrapper over
/// open(2), ioctl(2), mmap(2) and poll(2).

#include <linux/videodev2.h>

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

namespace hg::capture {

/// One V4L2 video node. Every call mirrors one system call: it returns 0 on
/// success or the errno value of the failure (never -1), and the structs are
/// the kernel's own, filled in and adjusted by the driver exactly as the
/// ioctl would. A device starts closed; Open() may be called again after
/// Close() (a camera that was unplugged and came back).
///
/// Thread-compatible: one thread (the camera's capture thread) owns it.
class V4l2Device {
 public:
  virtual ~V4l2Device() = default;

  /// Opens the node, non-blocking (DQBUF answers EAGAIN when no buffer is
  /// done). ENOENT while the camera is unplugged.
  virtual int Open() = 0;
  /// Closes the node; the driver forgets the formats and buffers of this
  /// file handle. Harmless when closed.
  virtual void Close() = 0;

  virtual int QueryCap(v4l2_capability* cap) = 0;                ///< VIDIOC_QUERYCAP
  virtual int SetFormat(v4l2_format* format) = 0;                ///< VIDIOC_S_FMT
  virtual int GetFormat(v4l2_format* format) = 0;                ///< VIDIOC_G_FMT
  virtual int SetParm(v4l2_streamparm* parm) = 0;                ///< VIDIOC_S_PARM
  virtual int SetControl(v4l2_control* control) = 0;             ///< VIDIOC_S_CTRL
  virtual int RequestBuffers(v4l2_requestbuffers* request) = 0;  ///< VIDIOC_REQBUFS
  virtual int QueryBuffer(v4l2_buffer* buffer) = 0;              ///< VIDIOC_QUERYBUF
  /// mmap(2) of `length` bytes at the buffer's `offset` (v4l2_buffer::m.offset),
  /// read-only and shared; *address is the mapping on success.
  virtual int Map(std::size_t length, std::uint32_t offset, void** address) = 0;
  virtual int Unmap(void* address, std::size_t length) = 0;  ///< munmap(2)
  virtual int QueueBuffer(v4l2_buffer* buffer) = 0;          ///< VIDIOC_QBUF
  virtual int DequeueBuffer(v4l2_buffer* buffer) = 0;        ///< VIDIOC_DQBUF
  virtual int StreamOn(v4l2_buf_type type) = 0;              ///< VIDIOC_STREAMON
  virtual int StreamOff(v4l2_buf_type type) = 0;             ///< VIDIOC_STREAMOFF
  /// poll(2) for readability (POLLIN) up to `timeout`; *revents gets the
  /// returned events (0 on timeout). A driver reports a vanished device or a
  /// stopped queue as POLLERR (or POLLHUP).
  virtual int Poll(std::chrono::milliseconds timeout, short* revents) = 0;
};

/// The video node at `path` (/dev/videoN) through the real system calls; not
/// opened until Open(). Defined in v4l2_source.cc.
[[nodiscard]] std::unique_ptr<V4l2Device> OpenSystemV4l2Device(const std::string& path);

}  // namespace hg::capture
