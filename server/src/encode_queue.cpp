#include "encode_queue.hpp"

#include <system_error>

namespace vts {
inline namespace server {
namespace http_detail {

EncodeQueue::EncodeQueue(int threads, EncodeLimits limits) : limits_(limits) {
  try {
    for (int i = 0; i < threads; ++i) workers_.emplace_back([this] { work(); });
  } catch (const std::system_error&) {
    stop();  // joins the ones that started
    throw;
  }
}

EncodeQueue::~EncodeQueue() {
  stop();
}

void EncodeQueue::stop() {
  {
    std::lock_guard lock(m_);
    stopping_ = true;
  }
  cv_.notify_all();
  for (auto& w : workers_) w.join();
  workers_.clear();
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
      lock.unlock();
      cv_.notify_one();
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

void EncodeQueue::work() {
  while (true) {
    Job job;
    {
      std::unique_lock lock(m_);
      cv_.wait(lock, [this] { return stopping_ || !turn_.empty(); });
      if (!pop(job)) return;  // stopping, and nothing left
    }
    execute(job);
  }
}

}  // namespace http_detail
}  // namespace server
}  // namespace vts
