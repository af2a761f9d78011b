#pragma once
/// @file
/// A fixed pool of worker threads running one parallel-for at a time.

#include <atomic>
#include <cstdint>
#include <thread>
#include <vector>

namespace hg::common {

/// Runs `fn(task, worker)` for task in [0, num_tasks) on `num_threads` threads
/// (the caller's thread is worker 0), handing out tasks through an atomic
/// counter. Dispatch and completion use atomic wait/notify: no mutex, no
/// allocation per Run(). A small pool of our own rather than oneTBB because the
/// octree needs a stable worker index (for per-worker scratch) and a run that is
/// allocation-free, both awkward to guarantee with a work-stealing scheduler.
///
/// Thread-compatible: Run() must be called from one thread at a time.
class WorkerPool {
 public:
  /// @throws std::system_error when a thread cannot be started (those started
  /// are ended and joined first).
  explicit WorkerPool(int num_threads);
  ~WorkerPool();
  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;

  [[nodiscard]] int num_threads() const { return static_cast<int>(threads_.size()) + 1; }

  /// Runs the tasks and returns when all have finished.
  template <class Fn>
  void Run(int num_tasks, Fn& fn) {
    RunImpl(num_tasks, &Invoke<Fn>, &fn);
  }

 private:
  using TaskFn = void (*)(void* ctx, int task, int worker);
  void StopAndJoin();
  template <class Fn>
  static void Invoke(void* ctx, int task, int worker) {
    (*static_cast<Fn*>(ctx))(task, worker);
  }
  void RunImpl(int num_tasks, TaskFn fn, void* ctx);
  void WorkerLoop(int worker);
  void Drain(int worker);

  std::vector<std::thread> threads_;
  TaskFn fn_ = nullptr;
  void* ctx_ = nullptr;
  int num_tasks_ = 0;
  std::atomic<int> next_task_{0};
  std::atomic<std::uint64_t> generation_{0};
  std::atomic<int> busy_{0};
  std::atomic<bool> stop_{false};
};

}  // namespace hg::common
