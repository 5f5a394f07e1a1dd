// The one thread pool every library runs its background work on (the builder's encoders, the
// server's web-image encoders, the client's decoders and deliveries, the load tester's viewers):
// a fixed set of named threads fed from one FIFO queue, optionally bounded.
//
// - submit() blocks while the queue is full (back-pressure: what bounds the builder's memory);
//   try_submit() never blocks and says whether it queued.
// - With one thread, jobs run one at a time in the order they were queued (a serial executor).
// - close() stops taking jobs; the jobs already queued still run, and join() waits for them. The
//   destructor closes and joins. A job must not join its own pool.
// - A thread the system refuses to start (a tasks limit, `ulimit -v` leaving no room for its
//   stack) is an error value from start(), never an abort.
//
// Policies over the queue (fairness between connections, admission caps, priorities) stay with
// their owners: they keep their own bookkeeping and hand the pool one job per unit of work.
// Thread-safe.
#pragma once

#include <condition_variable>
#include <cstddef>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "vts/base/result.hpp"

namespace vts {
inline namespace base {

struct WorkerPoolOptions {
  unsigned threads = 1;      // >= 1
  std::size_t capacity = 0;  // jobs that may wait; 0 = unbounded
  std::string name = "vts";  // thread name (profiles, `top -H`); at most 15 characters are kept
};

class WorkerPool {
 public:
  // Starts the threads. io, naming the pool and the system's reason, when one cannot start (the
  // threads already started are joined first).
  static Result<std::unique_ptr<WorkerPool>> start(WorkerPoolOptions options);
  ~WorkerPool();
  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;

  // Queues `job`, waiting while the queue is full. false (and `job` not run) once closed.
  bool submit(std::function<void()> job);
  // Queues `job` unless the queue is full or the pool closed: false then, and `job` not run.
  bool try_submit(std::function<void()> job);

  // Takes no more jobs; those queued still run. Idempotent.
  void close();
  // close(), then waits for every queued job to have run and the threads to end. Idempotent; not
  // from one of the pool's own jobs.
  void join();

  unsigned threads() const noexcept { return unsigned(threads_.size()); }
  std::size_t queued() const;
  // The pool's own threads answer true (a job that must not block on its own pool can check).
  bool on_worker_thread() const noexcept;

 private:
  explicit WorkerPool(WorkerPoolOptions options);
  void run();

  WorkerPoolOptions options_;
  mutable std::mutex mutex_;
  std::condition_variable not_empty_, not_full_;
  std::deque<std::function<void()>> jobs_;
  bool closed_ = false;
  std::vector<std::thread> threads_;
};

}  // namespace base
}  // namespace vts
