// The queue of the web-image encode workers (docs/PROTOCOL.md §12): bounded, fair between
// connections, and cancellable. A planet offers unlimited distinct cold images, so encodes are
// admitted up to two caps (per connection and in all: beyond, the request is answered 503 with
// Retry-After instead of queued), served round-robin between the connections that have work
// queued (one connection's 500 pipelined images wait their turn behind one image of every other
// connection, not in front of them), and a job is asked whether anybody still wants it just
// before it runs (a connection that closed leaves its queued encodes to be dropped, not run).
// The threads are the project's one pool (vts::WorkerPool): this queue keeps only the policy —
// each job it admits hands the pool one turn, and a turn runs whichever job is next round-robin.
// Thread-safe.
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <unordered_map>

#include "vts/base/worker_pool.hpp"

namespace vts {
inline namespace server {
namespace http_detail {

struct EncodeLimits {
  std::size_t max_queued = 1024;         // encodes waiting for a worker, in all
  std::size_t max_queued_per_owner = 8;  // of them, from one connection
};

class EncodeQueue {
 public:
  struct Job {
    std::uint64_t owner = 0;  // the connection that asked (fairness and its cap)
    // On a worker, right before the job would run: false = nobody waits for it any more, then
    // `dropped` runs instead of `run`.
    std::function<bool()> wanted;
    std::function<void()> run;
    std::function<void()> dropped;
  };
  enum class Admit : std::uint8_t { queued, owner_full, full };

  // Starts a pool of `threads` (>= 1) workers named "vts-web-encode". When the system refuses a
  // thread, the workers already started are joined and std::system_error is thrown.
  EncodeQueue(int threads, EncodeLimits limits);
  // stop().
  ~EncodeQueue();
  EncodeQueue(const EncodeQueue&) = delete;
  EncodeQueue& operator=(const EncodeQueue&) = delete;

  // Queues `job`, unless its owner already has max_queued_per_owner jobs waiting (owner_full) or
  // the queue holds max_queued (full): then nothing is queued and nothing of `job` runs. After
  // stop(), runs the job on the caller's thread (nobody else would).
  Admit push(Job job);
  // Runs (or drops) the jobs still queued, then joins the workers. Idempotent.
  void stop();

  int threads() const noexcept { return pool_ ? int(pool_->threads()) : 0; }
  std::size_t queued() const;

  const EncodeLimits& limits() const noexcept { return limits_; }

 private:
  // One turn on the pool: runs (or drops) the next job, round-robin between owners.
  void turn();
  // Under m_: the next job, round-robin between owners; false when none.
  bool pop(Job& out);
  static void execute(Job& job);

  EncodeLimits limits_;
  mutable std::mutex m_;
  std::unordered_map<std::uint64_t, std::deque<Job>> by_owner_;
  std::deque<std::uint64_t> turn_;  // owners with jobs queued, in the order they are served
  std::size_t queued_ = 0;
  bool stopping_ = false;
  std::unique_ptr<WorkerPool> pool_;  // last: joined (stop()) before the queue goes
};

}  // namespace http_detail
}  // namespace server
}  // namespace vts
