// The builder's threads: a ThreadGroup that always joins what it started, and a fixed pool of
// worker threads fed through a bounded queue (WorkQueue): submit() blocks while the queue is
// full, which is what bounds the builder's memory (back-pressure from encoding to cutting).
//
// A thread the system refuses to start (a tasks limit, `ulimit -v` leaving no room for its
// stack) is an error value, io "cannot start a thread ...", never an abort: std::thread throws
// std::system_error, and a std::thread destroyed while joinable calls std::terminate.
#pragma once

#include <condition_variable>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <system_error>
#include <thread>
#include <vector>

#include "vts/base/result.hpp"

namespace vts {
inline namespace builder {
namespace detail {

// Threads joined by join() or, at the latest, by the destructor. Not thread-safe: one thread
// starts and joins them.
class ThreadGroup {
 public:
  ThreadGroup() = default;
  ~ThreadGroup() { join(); }
  ThreadGroup(const ThreadGroup&) = delete;
  ThreadGroup& operator=(const ThreadGroup&) = delete;

  // Runs `f` on a new thread. io, naming `what` and the system's reason, when the system refuses
  // one; the threads already started keep running (the caller stops them, then joins).
  Status start(std::function<void()> f, const std::string& what) {
    try {
      threads_.emplace_back(std::move(f));
    } catch (const std::exception& e) {  // std::system_error; bad_alloc for its state
      return make_error(ErrorCode::io, "cannot start a thread (" + what + "): " + e.what() +
                                           " (a limit on tasks or virtual memory? fewer "
                                           "--threads may do)");
    }
    return {};
  }
  void join() {
    for (auto& t : threads_)
      if (t.joinable()) t.join();
    threads_.clear();
  }
  std::size_t size() const { return threads_.size(); }

 private:
  std::vector<std::thread> threads_;
};

class WorkQueue {
 public:
  // Starts `threads` (>= 1) workers; the error of ThreadGroup::start when one cannot start (those
  // started are stopped and joined first).
  static Result<std::unique_ptr<WorkQueue>> start(unsigned threads, std::size_t capacity) {
    std::unique_ptr<WorkQueue> q(new WorkQueue(capacity));
    for (unsigned i = 0; i < threads; ++i)
      if (Status s = q->workers_.start([p = q.get()] { p->run(); }, "encoder"); !s) {
        q->close_and_join();
        return s.error();
      }
    return q;
  }
  ~WorkQueue() { close_and_join(); }
  WorkQueue(const WorkQueue&) = delete;
  WorkQueue& operator=(const WorkQueue&) = delete;

  void submit(std::function<void()> job) {
    std::unique_lock lock(mutex_);
    not_full_.wait(lock, [&] { return jobs_.size() < capacity_; });
    jobs_.push_back(std::move(job));
    not_empty_.notify_one();
  }

  // Runs every job already submitted, then stops the workers.
  void close_and_join() {
    {
      std::lock_guard lock(mutex_);
      closed_ = true;
    }
    not_empty_.notify_all();
    workers_.join();
  }

 private:
  explicit WorkQueue(std::size_t capacity) : capacity_(capacity) {}

  void run() {
    for (;;) {
      std::function<void()> job;
      {
        std::unique_lock lock(mutex_);
        not_empty_.wait(lock, [&] { return closed_ || !jobs_.empty(); });
        if (jobs_.empty()) return;
        job = std::move(jobs_.front());
        jobs_.pop_front();
        not_full_.notify_one();
      }
      job();
    }
  }

  std::size_t capacity_;
  std::mutex mutex_;
  std::condition_variable not_empty_, not_full_;
  std::deque<std::function<void()>> jobs_;
  bool closed_ = false;
  ThreadGroup workers_;  // last: joined before the members its workers use go away
};

}  // namespace detail
}  // namespace builder
}  // namespace vts
