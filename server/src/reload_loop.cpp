#include "reload_loop.hpp"

#include <cstdio>

namespace vts::http_detail {

void ReloadLoop::start() {
  thread_ = std::thread([this] { run(); });
}

void ReloadLoop::request(bool force) {
  {
    std::lock_guard lock(mutex_);
    pending_ = true;
    force_ = force_ || force;
  }
  cv_.notify_all();
}

void ReloadLoop::quit() {
  {
    std::lock_guard lock(mutex_);
    quit_ = true;
  }
  cv_.notify_all();
}

void ReloadLoop::stop() {
  quit();
  if (thread_.joinable()) thread_.join();
}

void ReloadLoop::run() {
  std::unique_lock lock(mutex_);
  while (!quit_) {
    if (interval_.count() > 0)
      cv_.wait_for(lock, interval_, [this] { return quit_ || pending_; });
    else
      cv_.wait(lock, [this] { return quit_ || pending_; });
    if (quit_) break;
    if (!force_) cv_.wait_until(lock, last_ + kMinGap, [this] { return quit_ || force_; });
    if (quit_) break;
    const bool force = force_;
    pending_ = force_ = false;
    lock.unlock();
    reload(force);
    lock.lock();
    last_ = std::chrono::steady_clock::now();
  }
}

void ReloadLoop::reload(bool force) {
  auto result = registry_.reload(force, settle_);
  if (result.swapped > 0) {
    metrics_.reloads_swapped.fetch_add(std::uint64_t(result.swapped));
    std::fprintf(stderr, "vts serve: reloaded %d tileset(s)\n", result.swapped);
  }
  if (result.added > 0) std::fprintf(stderr, "vts serve: added %d new tileset(s)\n", result.added);
  if (result.removed > 0)
    std::fprintf(stderr, "vts serve: removed %d tileset(s) whose archive left its folder\n",
                 result.removed);
  for (const auto& e : result.failures) {
    metrics_.reloads_refused.fetch_add(1);
    std::fprintf(stderr, "vts serve: reload refused: %s\n", e.to_string().c_str());
  }
}

}  // namespace vts::http_detail
