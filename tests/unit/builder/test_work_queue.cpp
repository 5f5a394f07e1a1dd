// The builder's thread pool (builder/src/work_queue.hpp): a thread the system refuses to start is
// an error value, and the threads already started are joined (no std::terminate).
#include <gtest/gtest.h>

#include <atomic>
#include <string>

#include "vts/test/address_space.hpp"
#include "work_queue.hpp"

namespace vts::detail {
namespace {

using test::AddressSpaceLimit;
using test::sanitized;

TEST(WorkQueue, RunsEverySubmittedJobBeforeItsThreadsAreJoined) {
  auto q = WorkQueue::start(4, 2);
  ASSERT_TRUE(q) << q.error().message;
  std::atomic<int> done{0};
  for (int i = 0; i < 100; ++i) (*q)->submit([&] { ++done; });
  (*q)->close_and_join();
  EXPECT_EQ(done.load(), 100);
}

TEST(WorkQueue, ThreadsTheSystemRefusesAreAnIoErrorNotAnAbort) {
  if (sanitized()) GTEST_SKIP() << "sanitizers reserve terabytes of address space";
  Result<std::unique_ptr<WorkQueue>> q = make_error(ErrorCode::internal, "not run");
  {
    // Room for a few 8 MiB stacks, not for 512: some start, then one fails.
    AddressSpaceLimit limit(48u << 20);
    ASSERT_TRUE(limit.ok());
    q = WorkQueue::start(512, 16);
  }
  ASSERT_FALSE(q);
  EXPECT_EQ(q.error().code, ErrorCode::io);
  EXPECT_NE(q.error().message.find("cannot start a thread"), std::string::npos)
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
