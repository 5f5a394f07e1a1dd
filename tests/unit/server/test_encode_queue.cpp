// The web-image encode workers' queue (encode_queue.hpp): fair between connections, bounded in all
// and per connection, and dropping a job nobody wants any more instead of running it.
#include <gtest/gtest.h>

#include <chrono>
#include <condition_variable>
#include <mutex>
#include <system_error>
#include <thread>
#include <vector>

#include "encode_queue.hpp"
#include "vts/test/address_space.hpp"

namespace {

using vts::http_detail::EncodeLimits;
using vts::http_detail::EncodeQueue;

// Holds the queue's only worker inside a job until open(), so that what is queued meanwhile is
// served in the queue's own order afterwards.
class Gate {
 public:
  EncodeQueue::Job job() {
    EncodeQueue::Job j;
    j.owner = 999;
    j.run = [this] {
      std::unique_lock lock(m_);
      entered_ = true;
      cv_.notify_all();
      cv_.wait(lock, [this] { return open_; });
    };
    return j;
  }
  void wait_entered() {
    std::unique_lock lock(m_);
    ASSERT_TRUE(cv_.wait_for(lock, std::chrono::seconds(30), [this] { return entered_; }));
  }
  void open() {
    std::lock_guard lock(m_);
    open_ = true;
    cv_.notify_all();
  }

 private:
  std::mutex m_;
  std::condition_variable cv_;
  bool entered_ = false, open_ = false;
};

// Records the order jobs ran in.
struct Log {
  std::mutex m;
  std::vector<int> ran;
  EncodeQueue::Job job(std::uint64_t owner, int tag) {
    EncodeQueue::Job j;
    j.owner = owner;
    j.run = [this, tag] {
      std::lock_guard lock(m);
      ran.push_back(tag);
    };
    return j;
  }
};

TEST(EncodeQueue, ServesConnectionsRoundRobinSoOneConnectionsBacklogDoesNotDelayAnother) {
  Gate gate;
  Log log;
  {
    EncodeQueue q(1, EncodeLimits{100, 100});
    ASSERT_EQ(q.push(gate.job()), EncodeQueue::Admit::queued);
    gate.wait_entered();
    for (int i = 0; i < 10; ++i) ASSERT_EQ(q.push(log.job(1, 100 + i)), EncodeQueue::Admit::queued);
    ASSERT_EQ(q.push(log.job(2, 200)), EncodeQueue::Admit::queued);  // another user, after them
    ASSERT_EQ(q.push(log.job(3, 300)), EncodeQueue::Admit::queued);
    EXPECT_EQ(q.queued(), 12u);
    gate.open();
  }  // the destructor runs what is queued, then joins
  ASSERT_EQ(log.ran.size(), 12u);
  // One job of each connection in turn: the late users' images come second and third, not after
  // the first connection's ten.
  EXPECT_EQ(log.ran[0], 100);
  EXPECT_EQ(log.ran[1], 200);
  EXPECT_EQ(log.ran[2], 300);
  for (int i = 1; i < 10; ++i) EXPECT_EQ(log.ran[std::size_t(2 + i)], 100 + i);
}

TEST(EncodeQueue, RefusesAJobBeyondItsConnectionsCapOrTheWholeCapAndRunsNothingOfIt) {
  Gate gate;
  Log log;
  {
    EncodeQueue q(1, EncodeLimits{5, 3});
    ASSERT_EQ(q.push(gate.job()), EncodeQueue::Admit::queued);
    gate.wait_entered();
    for (int i = 0; i < 3; ++i) ASSERT_EQ(q.push(log.job(1, i)), EncodeQueue::Admit::queued);
    EXPECT_EQ(q.push(log.job(1, 3)), EncodeQueue::Admit::owner_full);
    ASSERT_EQ(q.push(log.job(2, 10)), EncodeQueue::Admit::queued);
    ASSERT_EQ(q.push(log.job(3, 20)), EncodeQueue::Admit::queued);
    EXPECT_EQ(q.push(log.job(4, 30)), EncodeQueue::Admit::full);  // 5 waiting in all
    EXPECT_EQ(q.queued(), 5u);
    gate.open();
  }
  EXPECT_EQ(log.ran, (std::vector<int>{0, 10, 20, 1, 2}));
}

TEST(EncodeQueue, AJobNobodyWantsAnyMoreIsDroppedBeforeItRuns) {
  Gate gate;
  int ran = 0, dropped = 0;
  bool wanted = true;
  {
    EncodeQueue q(1, EncodeLimits{});
    ASSERT_EQ(q.push(gate.job()), EncodeQueue::Admit::queued);
    gate.wait_entered();
    for (int i = 0; i < 4; ++i) {
      EncodeQueue::Job j;
      j.owner = 1;
      j.wanted = [&wanted, i] { return wanted || i == 3; };
      j.run = [&ran] { ++ran; };
      j.dropped = [&dropped] { ++dropped; };
      ASSERT_EQ(q.push(std::move(j)), EncodeQueue::Admit::queued);
    }
    wanted = false;  // the client went away, but job 3 is still wanted by someone else
    gate.open();
  }
  EXPECT_EQ(ran, 1);
  EXPECT_EQ(dropped, 3);
}

TEST(EncodeQueue, AfterStopAJobRunsOnTheCallersThread) {
  EncodeQueue q(2, EncodeLimits{});
  q.stop();
  EXPECT_EQ(q.threads(), 0);
  const auto caller = std::this_thread::get_id();
  std::thread::id ran_on;
  EncodeQueue::Job j;
  j.run = [&ran_on] { ran_on = std::this_thread::get_id(); };
  EXPECT_EQ(q.push(std::move(j)), EncodeQueue::Admit::queued);
  EXPECT_EQ(ran_on, caller);
}

}  // namespace

namespace {

TEST(EncodeQueue, AWorkerTheSystemRefusesIsAnExceptionAfterTheStartedOnesAreJoined) {
  if (vts::test::sanitized()) GTEST_SKIP() << "sanitizers reserve the address space";
  bool refused = false;
  {
    // Room for a few 8 MiB stacks, not for 512: some start, then one is refused.
    vts::test::AddressSpaceLimit limit(48u << 20);
    ASSERT_TRUE(limit.ok());
    try {
      EncodeQueue q(512, EncodeLimits{});
    } catch (const std::system_error&) {
      refused = true;  // and no std::terminate: the started workers were joined
    }
  }
  EXPECT_TRUE(refused);
}

}  // namespace
