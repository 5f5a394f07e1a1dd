// The one thread pool (base/include/vts/base/worker_pool.hpp): FIFO order on one thread, a bounded
// queue that blocks submit() and refuses try_submit(), close() that still runs what was queued,
// named threads, and a thread the system refuses to start as an error value.
#include "vts/base/worker_pool.hpp"

#include <gtest/gtest.h>
#include <pthread.h>

#include <atomic>
#include <future>
#include <string>
#include <vector>

#include "vts/test/address_space.hpp"

namespace vts {
namespace {

std::unique_ptr<WorkerPool> started(WorkerPoolOptions options) {
  auto pool = WorkerPool::start(std::move(options));
  EXPECT_TRUE(pool) << pool.error().message;
  return pool ? std::move(*pool) : nullptr;
}

TEST(WorkerPool, OneThreadRunsJobsOneAtATimeInTheOrderTheyWereQueued) {
  auto pool = started({.threads = 1, .capacity = 0, .name = "serial"});
  ASSERT_TRUE(pool);
  std::vector<int> order;  // only the pool's one thread writes it
  for (int i = 0; i < 200; ++i) ASSERT_TRUE(pool->submit([&order, i] { order.push_back(i); }));
  pool->join();
  ASSERT_EQ(order.size(), 200u);
  for (int i = 0; i < 200; ++i) EXPECT_EQ(order[std::size_t(i)], i);
}

TEST(WorkerPool, RunsEveryQueuedJobWhenClosedAndRefusesLaterOnes) {
  auto pool = started({.threads = 3, .capacity = 4, .name = "drain"});
  ASSERT_TRUE(pool);
  std::atomic<int> done{0};
  for (int i = 0; i < 100; ++i) ASSERT_TRUE(pool->submit([&] { ++done; }));
  pool->close();
  EXPECT_FALSE(pool->submit([&] { done += 1000; }));
  EXPECT_FALSE(pool->try_submit([&] { done += 1000; }));
  pool->join();
  EXPECT_EQ(done.load(), 100);
  pool->join();  // idempotent
}

TEST(WorkerPool, AFullQueueBlocksSubmitAndRefusesTrySubmit) {
  auto pool = started({.threads = 1, .capacity = 1, .name = "bounded"});
  ASSERT_TRUE(pool);
  std::promise<void> release;
  std::shared_future<void> released = release.get_future().share();
  std::promise<void> running;
  ASSERT_TRUE(pool->submit([&running, released] {
    running.set_value();
    released.wait();
  }));
  running.get_future().wait();            // the worker holds the first job
  ASSERT_TRUE(pool->try_submit([] {}));   // the one place in the queue
  EXPECT_FALSE(pool->try_submit([] {}));  // full
  EXPECT_EQ(pool->queued(), 1u);
  std::atomic<bool> third_ran{false};
  auto blocked =
      std::async(std::launch::async, [&] { return pool->submit([&] { third_ran = true; }); });
  // submit() waits for room: it cannot have returned while the worker is held.
  EXPECT_EQ(blocked.wait_for(std::chrono::milliseconds(0)), std::future_status::timeout);
  release.set_value();
  EXPECT_TRUE(blocked.get());
  pool->join();
  EXPECT_TRUE(third_ran.load());
}

TEST(WorkerPool, ClosingWakesASubmitWaitingForRoom) {
  auto pool = started({.threads = 1, .capacity = 1, .name = "wake"});
  ASSERT_TRUE(pool);
  std::promise<void> release, running;
  std::shared_future<void> released = release.get_future().share();
  ASSERT_TRUE(pool->submit([&running, released] {
    running.set_value();
    released.wait();
  }));
  running.get_future().wait();
  ASSERT_TRUE(pool->submit([] {}));
  auto blocked = std::async(std::launch::async, [&] { return pool->submit([] {}); });
  pool->close();
  EXPECT_FALSE(blocked.get());  // woken by close(), not by room
  release.set_value();
  pool->join();
}

TEST(WorkerPool, ItsThreadsCarryItsNameAndKnowTheyAreItsOwn) {
  auto pool = started({.threads = 2, .capacity = 0, .name = "vts-encode-web-images"});
  ASSERT_TRUE(pool);
  EXPECT_FALSE(pool->on_worker_thread());
  std::promise<std::pair<std::string, bool>> seen;
  ASSERT_TRUE(pool->submit([&] {
    char name[16] = {};
    pthread_getname_np(pthread_self(), name, sizeof name);
    seen.set_value({name, pool->on_worker_thread()});
  }));
  auto [name, own] = seen.get_future().get();
  EXPECT_EQ(name, "vts-encode-web-");  // 15 characters kept
  EXPECT_TRUE(own);
}

TEST(WorkerPool, ThreadsTheSystemRefusesAreAnIoErrorNotAnAbort) {
  if (test::sanitized()) GTEST_SKIP() << "sanitizers reserve terabytes of address space";
  Result<std::unique_ptr<WorkerPool>> pool = make_error(ErrorCode::internal, "not run");
  {
    // Room for a few 8 MiB stacks, not for 512: some start, then one fails and those are joined.
    test::AddressSpaceLimit limit(48u << 20);
    ASSERT_TRUE(limit.ok());
    pool = WorkerPool::start({.threads = 512, .capacity = 16, .name = "many"});
  }
  ASSERT_FALSE(pool);
  EXPECT_EQ(pool.error().code, ErrorCode::io);
  EXPECT_NE(pool.error().message.find("cannot start a thread (many)"), std::string::npos)
      << pool.error().message;
}

}  // namespace
}  // namespace vts
