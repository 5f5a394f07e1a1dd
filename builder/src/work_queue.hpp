// The builder's threads: a ThreadGroup that always joins what it started (the readers of a
// pass), and the encoder pool, a WorkerPool (base/worker_pool.hpp) whose bounded queue blocks
// submit() while full, which is what bounds the builder's memory (back-pressure from encoding to
// cutting).
//
// A thread the system refuses to start (a tasks limit, `ulimit -v` leaving no room for its
// stack) is an error value, io "cannot start a thread ...", never an abort: std::thread throws
// std::system_error, and a std::thread destroyed while joinable calls std::terminate.
#pragma once

#include <algorithm>
#include <functional>
#include <memory>
#include <string>
#include <system_error>
#include <thread>
#include <vector>

#include "vts/base/result.hpp"
#include "vts/base/worker_pool.hpp"

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

// The encoder pool: `threads` (>= 1) workers named "vts-encode" on the one thread pool
// (base/worker_pool.hpp), its queue bounded to 4 tiles per thread so that cutting waits for
// encoding. io "cannot start a thread (vts-encode) ..." when one cannot start (those started are
// joined first).
inline Result<std::unique_ptr<WorkerPool>> start_encoders(unsigned threads) {
  threads = std::max(threads, 1u);  // capacity 0 would mean unbounded
  return WorkerPool::start(
      {.threads = threads, .capacity = std::size_t{threads} * 4, .name = "vts-encode"});
}

}  // namespace detail
}  // namespace builder
}  // namespace vts
