// Time in tests: a clock the test moves by hand for timing logic, and a bounded wait on a
// condition instead of a sleep.
#pragma once

#include <atomic>
#include <chrono>
#include <functional>
#include <thread>

namespace vts::test {

// A steady clock that only moves when advance() is called. now() is thread-safe; `fn()` gives a
// std::function<time_point()> to inject where the code under test takes one.
class FakeClock {
 public:
  using duration = std::chrono::steady_clock::duration;
  using time_point = std::chrono::steady_clock::time_point;

  explicit FakeClock(time_point start = time_point{} + std::chrono::hours(1)) : now_(start) {}
  time_point now() const { return now_.load(); }
  void advance(duration d) { now_.store(now_.load() + d); }
  std::function<time_point()> fn() const {
    return [this] { return now(); };
  }

 private:
  std::atomic<time_point> now_;
};

// Polls `done` until it returns true or `deadline` passes; returns its last answer. The deadline
// is generous on purpose: it bounds a hung test, it is not a timing assertion.
template <class Predicate>
bool wait_until(Predicate&& done, std::chrono::milliseconds deadline = std::chrono::seconds(20)) {
  const auto end = std::chrono::steady_clock::now() + deadline;
  while (!done()) {
    if (std::chrono::steady_clock::now() >= end) return done();
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return true;
}

}  // namespace vts::test
