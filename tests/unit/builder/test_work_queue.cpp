// The builder's threads (builder/src/work_queue.hpp): the encoder pool and the readers'
// ThreadGroup. A thread the system refuses to start is an error value, and the threads already
// started are joined (no std::terminate).
#include <gtest/gtest.h>

#include <atomic>
#include <future>
#include <string>
#include <thread>

#include "vts/test/address_space.hpp"
#include "work_queue.hpp"

namespace vts::detail {
namespace {

using test::AddressSpaceLimit;
using test::sanitized;

TEST(Encoders, RunEverySubmittedJobBeforeTheirThreadsAreJoined) {
  auto q = start_encoders(4);
  ASSERT_TRUE(q) << q.error().message;
  EXPECT_EQ((*q)->threads(), 4u);
  std::atomic<int> done{0};
  for (int i = 0; i < 100; ++i) ASSERT_TRUE((*q)->submit([&] { ++done; }));
  (*q)->join();
  EXPECT_EQ(done.load(), 100);
}

// What bounds the builder's memory: 4 tiles per encoder wait, then submit() blocks.
TEST(Encoders, QueueFourJobsPerThreadWhileTheyAreBusy) {
  auto q = start_encoders(2);
  ASSERT_TRUE(q) << q.error().message;
  std::promise<void> release;
  std::shared_future<void> released = release.get_future().share();
  std::atomic<int> running{0};
  for (int i = 0; i < 2; ++i)
    ASSERT_TRUE((*q)->submit([&running, released] {
      ++running;
      released.wait();
    }));
  while (running.load() < 2) std::this_thread::yield();  // both encoders hold a job
  int queued = 0;
  while (queued < 100 && (*q)->try_submit([] {})) ++queued;
  EXPECT_EQ(queued, 8);
  release.set_value();
  (*q)->join();
}

// The integration tests (stops_and_thread_limits.sh) grep "cannot start a thread" from
// `vts build` and `vts export`; the pool's own tests cover the joining of those started.
TEST(Encoders, ThreadsTheSystemRefusesAreAnIoErrorNamingThePool) {
  if (sanitized()) GTEST_SKIP() << "sanitizers reserve terabytes of address space";
  Result<std::unique_ptr<WorkerPool>> q = make_error(ErrorCode::internal, "not run");
  {
    // Room for a few 8 MiB stacks, not for 512: some start, then one fails.
    AddressSpaceLimit limit(48u << 20);
    ASSERT_TRUE(limit.ok());
    q = start_encoders(512);
  }
  ASSERT_FALSE(q);
  EXPECT_EQ(q.error().code, ErrorCode::io);
  EXPECT_NE(q.error().message.find("cannot start a thread (vts-encode)"), std::string::npos)
      << q.error().message;
}

TEST(ThreadGroup, JoinsTheThreadsItStartedWhenALaterOneFailsToStart) {
  if (sanitized()) GTEST_SKIP() << "sanitizers reserve terabytes of address space";
  std::atomic<bool> release{false};
  std::atomic<int> finished{0};
  Status failed;
  std::size_t started = 0;
  {
    ThreadGroup group;
    {
      AddressSpaceLimit limit(48u << 20);
      ASSERT_TRUE(limit.ok());
      for (int i = 0; i < 512 && failed; ++i)
        failed = group.start(
            [&] {
              while (!release.load()) std::this_thread::yield();
              ++finished;
            },
            "test");
    }
    started = group.size();
    release = true;
  }  // joins: a joinable std::thread left behind would have called std::terminate
  ASSERT_FALSE(failed);
  EXPECT_EQ(failed.error().code, ErrorCode::io);
  EXPECT_GT(started, 0u);
  EXPECT_EQ(finished.load(), static_cast<int>(started));
}

}  // namespace
}  // namespace vts::detail
