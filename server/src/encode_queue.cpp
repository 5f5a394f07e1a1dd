#include "encode_queue.hpp"

#include <algorithm>
#include <system_error>

namespace vts {
inline namespace server {
namespace http_detail {

EncodeQueue::EncodeQueue(int threads, EncodeLimits limits) : limits_(limits) {
  auto pool =
      WorkerPool::start({.threads = unsigned(std::max(1, threads)), .name = "vts-web-encode"});
  if (!pool)
    throw std::system_error(std::make_error_code(std::errc::resource_unavailable_try_again),
                            pool.error().message);
  pool_ = std::move(*pool);
}

EncodeQueue::~EncodeQueue() {
  stop();
}

void EncodeQueue::stop() {
  {
    std::lock_guard lock(m_);
    stopping_ = true;
  }
  // Every job queued has its turn queued on the pool: joining runs (or drops) them all.
  if (pool_) pool_->join();
}

std::size_t EncodeQueue::queued() const {
  std::lock_guard lock(m_);
  return queued_;
}

EncodeQueue::Admit EncodeQueue::push(Job job) {
  {
    std::unique_lock lock(m_);
    if (!stopping_) {
      if (queued_ >= limits_.max_queued) return Admit::full;
      auto [it, fresh] = by_owner_.try_emplace(job.owner);
      if (it->second.size() >= limits_.max_queued_per_owner) return Admit::owner_full;
      if (it->second.empty()) turn_.push_back(job.owner);
      it->second.push_back(std::move(job));
      ++queued_;
      // Under m_, so stop() (which sets stopping_ under it before it closes the pool) cannot
      // come between: the turn is never refused. The pool's queue is unbounded (admission is
      // bounded above), so submit() does not wait.
      pool_->submit([this] { turn(); });
      return Admit::queued;
    }
  }
  execute(job);  // stopped: the workers are gone
  return Admit::queued;
}

bool EncodeQueue::pop(Job& out) {
  if (turn_.empty()) return false;
  const std::uint64_t owner = turn_.front();
  turn_.pop_front();
  auto it = by_owner_.find(owner);
  out = std::move(it->second.front());
  it->second.pop_front();
  --queued_;
  if (it->second.empty())
    by_owner_.erase(it);
  else
    turn_.push_back(owner);  // its next job after one of every other owner's
  return true;
}

void EncodeQueue::execute(Job& job) {
  if (job.wanted && !job.wanted()) {
    if (job.dropped) job.dropped();
  } else {
    job.run();
  }
}

void EncodeQueue::turn() {
  Job job;
  {
    std::lock_guard lock(m_);
    if (!pop(job)) return;
  }
  execute(job);
}

}  // namespace http_detail
}  // namespace server
}  // namespace vts
