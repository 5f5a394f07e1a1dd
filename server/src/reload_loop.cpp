#include "reload_loop.hpp"

#include <cstdio>
#include <system_error>

#include "vts/base/file_io.hpp"

namespace vts {
inline namespace server {
namespace http_detail {

Status ReloadLoop::start() {
  try {
    thread_ = std::thread([this] { run(); });
  } catch (const std::system_error& e) {
    return make_error(ErrorCode::io, std::string("cannot start the reload thread: ") + e.what());
  }
  return {};
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

void ReloadLoop::drop_stale_tiles() {
  std::vector<std::uint64_t> live;
  for (const auto& t : registry_.all())
    if (!t->modified.load(std::memory_order_relaxed)) live.push_back(t->generation);
  tiles_->retain(live);
}

void ReloadLoop::reload(bool force) {
  auto result = registry_.reload(force, settle_);
  if (tiles_ &&
      (result.swapped > 0 || result.removed > 0 || result.settling > 0 || !result.failures.empty()))
    drop_stale_tiles();
  if (result.swapped > 0) {
    metrics_.reloads_swapped.fetch_add(std::uint64_t(result.swapped));
    std::fprintf(stderr, "vts serve: reloaded %d tileset(s)\n", result.swapped);
  }
  if (result.added > 0) std::fprintf(stderr, "vts serve: added %d new tileset(s)\n", result.added);
  if (result.removed > 0)
    std::fprintf(stderr, "vts serve: removed %d tileset(s) whose archive left its folder\n",
                 result.removed);
  const auto now = std::chrono::steady_clock::now();
  std::map<std::string, Logged> refusals;
  for (const auto& e : result.failures) {
    metrics_.reloads_refused.fetch_add(1);
    // The message names a file found in a served folder: one line, whatever it is named.
    const std::string line = escape_controls(e.to_string());
    Logged logged;
    if (auto it = refusals_.find(line); it != refusals_.end()) logged = it->second;
    if (logged.at == std::chrono::steady_clock::time_point{} ||
        now - logged.at >= kRepeatInterval) {
      if (logged.held_back > 0)
        std::fprintf(stderr, "vts serve: reload refused: %s (again; %llu more times since)\n",
                     line.c_str(), static_cast<unsigned long long>(logged.held_back));
      else
        std::fprintf(stderr, "vts serve: reload refused: %s\n", line.c_str());
      logged = Logged{now, 0};
    } else {
      ++logged.held_back;
    }
    refusals[line] = logged;
  }
  // A refusal the last reload did not repeat is logged at once if it comes back.
  refusals_ = std::move(refusals);
}

}  // namespace http_detail
}  // namespace server
}  // namespace vts
