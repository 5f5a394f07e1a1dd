// Connection deadlines, checked by one periodic timer per I/O thread.
#pragma once

#include <boost/asio/io_context.hpp>
#include <boost/asio/steady_timer.hpp>
#include <chrono>
#include <ctime>
#include <mutex>
#include <optional>
#include <vector>

namespace vts {
inline namespace server {
namespace http_detail {

// Deadlines (seconds long, enforced by a sweep every 10-250 ms) need no nanoseconds: the coarse
// monotonic clock is read from the vDSO without touching the TSC, and a request reads it ~4 times.
struct DeadlineClock {
  using duration = std::chrono::nanoseconds;
  using rep = duration::rep;
  using period = duration::period;
  using time_point = std::chrono::time_point<DeadlineClock>;
  static constexpr bool is_steady = true;
  static time_point now() noexcept {
    timespec ts{};
    ::clock_gettime(CLOCK_MONOTONIC_COARSE, &ts);
    return time_point(std::chrono::seconds(ts.tv_sec) + std::chrono::nanoseconds(ts.tv_nsec));
  }
};

// What a Sweeper checks: called on the connection's own thread (the sweeper's io_context).
class Swept {
 public:
  virtual void check_deadlines(DeadlineClock::time_point now) = 0;
  std::size_t sweep_slot = 0;  // position in the Sweeper's list

 protected:
  ~Swept() = default;
};

// The deadlines of one thread's connections, checked by one periodic timer on that thread. A
// timer per connection would be armed and cancelled several times per request, each time a
// scheduler round trip and often a timerfd update; a sweep costs a compare per connection.
class Sweeper {
 public:
  // Sweepers outlive their io_context (connections destroyed with it still remove themselves);
  // their timer does not: the server drops it with release() before the io_context goes.
  Sweeper(boost::asio::io_context& ioc, std::chrono::milliseconds period)
      : ioc_(ioc), timer_(std::in_place, ioc), period_(period) {}
  boost::asio::io_context& context() { return ioc_; }
  void start();
  // Stops sweeping (from any thread); the timer then no longer keeps the io_context busy.
  void stop();
  void release();
  // add() on the connection's thread; remove() from its destructor, wherever that runs. O(1).
  void add(Swept* s);
  void remove(Swept* s);

 private:
  void schedule();
  void sweep();

  boost::asio::io_context& ioc_;
  std::optional<boost::asio::steady_timer> timer_;
  std::chrono::milliseconds period_;
  bool stopped_ = false;
  std::mutex mutex_;
  std::vector<Swept*> swept_;
};

}  // namespace http_detail
}  // namespace server
}  // namespace vts
