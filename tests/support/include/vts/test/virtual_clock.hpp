// Virtual time for code that waits on several threads of its own (the load tester's drivers, its
// open-loop dispatcher, the thread that reports and drains): a run of seconds takes none, and the
// times it measures are exact.
//
// The threads taking part call sleep_until(); time stands still while any of them runs. When all
// of them wait, time moves to the earliest deadline and that one thread alone runs on (of equal
// deadlines, the one that began waiting first), until it waits again or ends. So after the start
// the threads run one at a time, in the order of their deadlines, and a run is the same every
// time. Only the first waits race: threads that start together and wait for the same instant run
// in the order they got there.
//
// The constructor's `threads` is how many threads will take part, so that time does not move
// before the last of them has started. A thread takes part from its first sleep_until() until it
// ends (a thread_local tells the clock), so a thread that outlives its loop (a pool thread kept
// for more work) holds time still. A thread that calls spend() inside its turn moves time on by
// that much (work that takes time, not a wait). A wait that no thread can end (a thread that
// never came, or blocks on something else) aborts the test after a minute, naming the clock.
#pragma once

#include <chrono>
#include <functional>
#include <memory>

namespace vts::test {

class VirtualClock {
 public:
  using duration = std::chrono::steady_clock::duration;
  using time_point = std::chrono::steady_clock::time_point;

  explicit VirtualClock(unsigned threads, time_point start = time_point{} + std::chrono::hours(1));
  ~VirtualClock();
  VirtualClock(const VirtualClock&) = delete;
  VirtualClock& operator=(const VirtualClock&) = delete;

  time_point now() const;
  // Blocks the calling thread (which takes part from now on) until time reaches `t`; returns at
  // once when it already has.
  void sleep_until(time_point t);
  // Moves time on by `d` from inside the calling thread's turn.
  void spend(duration d);

  // For options that take the clock as functions (LoadTestOptions::now / sleep_until).
  std::function<time_point()> now_fn() const;
  std::function<void(time_point)> sleep_fn();

  struct State;

 private:
  std::shared_ptr<State> state_;
};

}  // namespace vts::test
