// A test fixture for the web-image encode queue: occupies a WebTileCache's only encode worker
// until release() (or destruction), so that what is routed meanwhile waits in the queue and is
// then served, or dropped, in the queue's own order.
#pragma once

#include <gtest/gtest.h>
#include <chrono>
#include <condition_variable>
#include <mutex>

#include "web_tile_cache.hpp"

namespace vts::test {

// Occupies the cache's only encode worker until release(): what is routed meanwhile queues.
class BusyWorker {
 public:
  explicit BusyWorker(http_detail::WebTileCache& c) : c_(c) {
    auto lead = c.acquire("busy").lead;
    EXPECT_EQ(c.queue("busy", lead, 999,
                      [this, lead] {
                        std::unique_lock lock(m_);
                        busy_ = true;
                        cv_.notify_all();
                        cv_.wait(lock, [this] { return released_; });
                        c_.finish("busy", lead, nullptr, 500, "test");
                        left_ = true;
                        cv_.notify_all();
                      }),
              vts::http_detail::EncodeQueue::Admit::queued);
    std::unique_lock lock(m_);
    EXPECT_TRUE(cv_.wait_for(lock, std::chrono::seconds(30), [this] { return busy_; }));
  }
  void release() {
    std::lock_guard lock(m_);
    released_ = true;
    cv_.notify_all();
  }
  // Releases the worker and waits until it has left this object.
  ~BusyWorker() {
    release();
    std::unique_lock lock(m_);
    cv_.wait(lock, [this] { return left_; });
  }

 private:
  http_detail::WebTileCache& c_;
  std::mutex m_;
  std::condition_variable cv_;
  bool busy_ = false, released_ = false, left_ = false;
};

}  // namespace vts::test
