#include "vts/base/worker_pool.hpp"

#include <pthread.h>

#include <algorithm>
#include <exception>

namespace vts {
inline namespace base {

namespace {
thread_local const WorkerPool* t_current_pool = nullptr;  // the pool whose job this thread runs
}  // namespace

WorkerPool::WorkerPool(WorkerPoolOptions options) : options_(std::move(options)) {}

Result<std::unique_ptr<WorkerPool>> WorkerPool::start(WorkerPoolOptions options) {
  options.threads = std::max(1u, options.threads);
  std::unique_ptr<WorkerPool> pool(new WorkerPool(std::move(options)));
  pool->threads_.reserve(pool->options_.threads);
  for (unsigned i = 0; i < pool->options_.threads; ++i) {
    try {
      pool->threads_.emplace_back([p = pool.get()] { p->run(); });
    } catch (const std::exception& e) {  // std::system_error; bad_alloc for its state
      pool->join();
      return make_error(ErrorCode::io, "cannot start a thread (" + pool->options_.name +
                                           "): " + e.what() +
                                           " (a limit on tasks or virtual memory? fewer threads "
                                           "may do)");
    }
    // Linux keeps 15 characters and a NUL; a name it refuses only costs the label.
    std::string label = pool->options_.name.substr(0, 15);
    pthread_setname_np(pool->threads_.back().native_handle(), label.c_str());
  }
  return pool;
}

WorkerPool::~WorkerPool() {
  join();
}

bool WorkerPool::submit(std::function<void()> job) {
  std::unique_lock lock(mutex_);
  not_full_.wait(
      lock, [&] { return closed_ || options_.capacity == 0 || jobs_.size() < options_.capacity; });
  if (closed_) return false;
  jobs_.push_back(std::move(job));
  not_empty_.notify_one();
  return true;
}

bool WorkerPool::try_submit(std::function<void()> job) {
  std::lock_guard lock(mutex_);
  if (closed_ || (options_.capacity != 0 && jobs_.size() >= options_.capacity)) return false;
  jobs_.push_back(std::move(job));
  not_empty_.notify_one();
  return true;
}

void WorkerPool::close() {
  {
    std::lock_guard lock(mutex_);
    closed_ = true;
  }
  not_empty_.notify_all();
  not_full_.notify_all();
}

void WorkerPool::join() {
  close();
  for (auto& t : threads_)
    if (t.joinable()) t.join();
  threads_.clear();
}

std::size_t WorkerPool::queued() const {
  std::lock_guard lock(mutex_);
  return jobs_.size();
}

bool WorkerPool::on_worker_thread() const noexcept {
  return t_current_pool == this;
}

void WorkerPool::run() {
  t_current_pool = this;
  for (;;) {
    std::function<void()> job;
    {
      std::unique_lock lock(mutex_);
      not_empty_.wait(lock, [&] { return closed_ || !jobs_.empty(); });
      if (jobs_.empty()) return;  // closed and drained
      job = std::move(jobs_.front());
      jobs_.pop_front();
    }
    not_full_.notify_one();
    job();
  }
}

}  // namespace base
}  // namespace vts
