#include "common/worker_pool.h"

#include "common/check.h"

namespace hg::common {

WorkerPool::WorkerPool(int num_threads) {
  HG_CHECK(num_threads >= 1);
  threads_.reserve(num_threads - 1);
  try {
    for (int w = 1; w < num_threads; ++w) threads_.emplace_back([this, w] { WorkerLoop(w); });
  } catch (...) {
    // No more threads to be had (std::system_error): the ones started are
    // ended and joined, or their destruction would terminate the process.
    StopAndJoin();
    throw;
  }
}

WorkerPool::~WorkerPool() { StopAndJoin(); }

void WorkerPool::StopAndJoin() {
  stop_.store(true, std::memory_order_release);
  generation_.fetch_add(1, std::memory_order_acq_rel);
  generation_.notify_all();
  for (auto& t : threads_) {
    if (t.joinable()) t.join();
  }
}

void WorkerPool::Drain(int worker) {
  for (;;) {
    const int task = next_task_.fetch_add(1, std::memory_order_relaxed);
    if (task >= num_tasks_) return;
    fn_(ctx_, task, worker);
  }
}

void WorkerPool::RunImpl(int num_tasks, TaskFn fn, void* ctx) {
  if (num_tasks <= 0) return;
  fn_ = fn;
  ctx_ = ctx;
  num_tasks_ = num_tasks;
  next_task_.store(0, std::memory_order_relaxed);
  busy_.store(static_cast<int>(threads_.size()), std::memory_order_relaxed);
  // The release on generation_ publishes fn_, ctx_ and num_tasks_ to the workers.
  generation_.fetch_add(1, std::memory_order_release);
  generation_.notify_all();
  Drain(0);
  for (int b = busy_.load(std::memory_order_acquire); b != 0;
       b = busy_.load(std::memory_order_acquire)) {
    busy_.wait(b, std::memory_order_acquire);
  }
}

void WorkerPool::WorkerLoop(int worker) {
  std::uint64_t seen = 0;
  for (;;) {
    generation_.wait(seen, std::memory_order_acquire);
    seen = generation_.load(std::memory_order_acquire);
    if (stop_.load(std::memory_order_acquire)) return;
    Drain(worker);
    if (busy_.fetch_sub(1, std::memory_order_acq_rel) == 1) busy_.notify_one();
  }
}

}  // namespace hg::common
