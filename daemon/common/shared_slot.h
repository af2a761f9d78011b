#pragma once
/// @file
/// A shared_ptr that threads store and load concurrently.

#include <atomic>
#include <memory>
#include <thread>
#include <utility>

namespace hg::common {

/// What std::atomic<std::shared_ptr<T>> offers (load and store from any
/// thread), held by a flag for the length of a pointer copy, with the flag
/// released in release order after every load and store. libstdc++ 12's
/// std::atomic<std::shared_ptr> releases its internal lock in relaxed order
/// after a load: on a weakly ordered CPU (ARM) a reader's read of the pointer
/// may then pass a writer's swap, pairing one snapshot's pointer with another
/// one's count (ThreadSanitizer reports it as a data race).
///
/// Neither side allocates; the value a store replaces is released after the
/// flag, so no destructor runs while it is held.
template <class T>
class SharedSlot {
 public:
  SharedSlot() = default;
  SharedSlot(const SharedSlot&) = delete;
  SharedSlot& operator=(const SharedSlot&) = delete;

  [[nodiscard]] std::shared_ptr<T> Load() const {
    Lock();
    std::shared_ptr<T> copy = value_;
    Unlock();
    return copy;
  }

  void Store(std::shared_ptr<T> value) {
    Lock();
    value_.swap(value);
    Unlock();
  }  // The replaced value is released here, after Unlock().

 private:
  void Lock() const {
    while (held_.exchange(true, std::memory_order_acquire)) {
      // Held for a pointer copy only: the holder was preempted; let it run.
      while (held_.load(std::memory_order_relaxed)) std::this_thread::yield();
    }
  }
  void Unlock() const { held_.store(false, std::memory_order_release); }

  mutable std::atomic<bool> held_{false};
  std::shared_ptr<T> value_;
};

}  // namespace hg::common
