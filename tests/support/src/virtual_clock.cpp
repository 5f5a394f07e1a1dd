#include "vts/test/virtual_clock.hpp"

#include <algorithm>
#include <condition_variable>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <mutex>
#include <optional>
#include <set>
#include <utility>
#include <vector>

namespace vts::test {

struct VirtualClock::State {
  std::mutex mutex;
  std::condition_variable cv;
  time_point now;
  unsigned declared = 0, joined = 0, ended = 0, waiting = 0;
  std::uint64_t next_seq = 0;
  std::set<std::pair<time_point, std::uint64_t>> sleepers;  // (deadline, order of arrival)
  std::optional<std::uint64_t> released;                    // the sleeper whose turn it is

  // Lock held. When every thread taking part waits, the earliest deadline's turn comes.
  void advance() {
    const unsigned alive = std::max(declared, joined) - ended;
    if (released || waiting < alive || sleepers.empty()) return;
    const auto first = *sleepers.begin();
    sleepers.erase(sleepers.begin());
    now = std::max(now, first.first);
    released = first.second;
    --waiting;
    cv.notify_all();
  }

  void leave() {
    std::lock_guard lock(mutex);
    ++ended;
    advance();
  }
};

namespace {

// The clocks the calling thread takes part in; it leaves them when it ends.
struct Parts {
  std::vector<std::shared_ptr<VirtualClock::State>> states;
  ~Parts() {
    for (auto& s : states) s->leave();
  }
};

thread_local Parts t_parts;

}  // namespace

VirtualClock::VirtualClock(unsigned threads, time_point start) : state_(std::make_shared<State>()) {
  state_->now = start;
  state_->declared = threads;
}

VirtualClock::~VirtualClock() = default;

VirtualClock::time_point VirtualClock::now() const {
  std::lock_guard lock(state_->mutex);
  return state_->now;
}

void VirtualClock::sleep_until(time_point t) {
  State& s = *state_;
  if (std::find(t_parts.states.begin(), t_parts.states.end(), state_) == t_parts.states.end()) {
    t_parts.states.push_back(state_);
    std::lock_guard lock(s.mutex);
    ++s.joined;
  }
  std::unique_lock lock(s.mutex);
  if (t <= s.now) return;
  const std::uint64_t seq = s.next_seq++;
  s.sleepers.emplace(t, seq);
  ++s.waiting;
  s.advance();
  if (!s.cv.wait_for(lock, std::chrono::minutes(1), [&] { return s.released == seq; })) {
    std::fprintf(stderr,
                 "VirtualClock: no thread ran for a minute of real time (%u threads declared, %u "
                 "joined, %u ended, %u waiting): a thread that never came or blocks elsewhere\n",
                 s.declared, s.joined, s.ended, s.waiting);
    std::abort();
  }
  s.released.reset();
}

void VirtualClock::spend(duration d) {
  std::lock_guard lock(state_->mutex);
  state_->now += d;
}

std::function<VirtualClock::time_point()> VirtualClock::now_fn() const {
  return [s = state_] {
    std::lock_guard lock(s->mutex);
    return s->now;
  };
}

std::function<void(VirtualClock::time_point)> VirtualClock::sleep_fn() {
  return [this](time_point t) { sleep_until(t); };
}

}  // namespace vts::test
