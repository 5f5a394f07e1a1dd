#include "deadline_sweeper.hpp"

#include <boost/asio/post.hpp>
#include <boost/system/error_code.hpp>

namespace vts {
inline namespace server {
namespace http_detail {

void Sweeper::start() {
  boost::asio::post(ioc_, [this] { schedule(); });
}

void Sweeper::stop() {
  boost::asio::post(ioc_, [this] {
    stopped_ = true;
    timer_->cancel();
  });
}

void Sweeper::release() {
  stopped_ = true;
  timer_.reset();
}

void Sweeper::schedule() {
  if (stopped_) return;
  timer_->expires_after(period_);
  timer_->async_wait([this](boost::system::error_code ec) {
    if (ec || stopped_) return;
    sweep();
    schedule();
  });
}

void Sweeper::add(Swept* s) {
  std::lock_guard lock(mutex_);
  s->sweep_slot = swept_.size();
  swept_.push_back(s);
}

void Sweeper::remove(Swept* s) {
  std::lock_guard lock(mutex_);
  const std::size_t i = s->sweep_slot;
  if (i >= swept_.size() || swept_[i] != s) return;
  swept_[i] = swept_.back();
  swept_[i]->sweep_slot = i;
  swept_.pop_back();
}

void Sweeper::sweep() {
  const auto now = DeadlineClock::now();
  std::lock_guard lock(mutex_);
  // check_deadlines() only closes sockets; nothing is destroyed (or removed) during the loop.
  for (Swept* s : swept_) s->check_deadlines(now);
}

}  // namespace http_detail
}  // namespace server
}  // namespace vts
