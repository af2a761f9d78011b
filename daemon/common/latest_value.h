#pragma once
/// @file
/// Lock-free latest-value handoff between one writer and one reader.

#include <array>
#include <atomic>
#include <cstdint>

namespace hg::common {

/// Triple buffer: the writer fills a back buffer and publishes it; the reader
/// takes the newest published buffer. Neither side ever blocks or allocates;
/// a value published before the reader took the previous one is overwritten
/// (latest wins) and counted as a drop. T's buffers are constructed once, so a
/// T that owns memory (an image) is reused frame after frame.
///
/// Thread-safe for exactly one writer thread and one reader thread.
template <class T>
class LatestValue {
 public:
  /// The buffer to fill next; valid until Publish().
  T& BeginWrite() { return buffers_[back_]; }

  /// Makes the buffer from BeginWrite() the newest value.
  void Publish() {
    const std::uint8_t previous =
        middle_.exchange(static_cast<std::uint8_t>(back_ | kFresh), std::memory_order_acq_rel);
    if ((previous & kFresh) != 0) drops_.fetch_add(1, std::memory_order_relaxed);
    back_ = previous & kIndex;
  }

  /// The newest value not taken yet, or nullptr when nothing new was
  /// published. The pointer stays valid until the next TakeNewest().
  T* TakeNewest() {
    if ((middle_.load(std::memory_order_acquire) & kFresh) == 0) return nullptr;
    front_ = middle_.exchange(front_, std::memory_order_acq_rel) & kIndex;
    return &buffers_[front_];
  }

  /// Values overwritten before the reader took them.
  [[nodiscard]] std::uint64_t drops() const { return drops_.load(std::memory_order_relaxed); }

 private:
  static constexpr std::uint8_t kFresh = 0x4;
  static constexpr std::uint8_t kIndex = 0x3;
  std::array<T, 3> buffers_{};
  std::uint8_t back_ = 0;                // Writer's buffer.
  std::atomic<std::uint8_t> middle_{1};  // Last published (index | fresh bit).
  std::uint8_t front_ = 2;               // Reader's buffer.
  std::atomic<std::uint64_t> drops_{0};
};

}  // namespace hg::common
