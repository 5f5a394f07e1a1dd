// The builder's thread pool (builder/src/work_queue.hpp): a thread the system refuses to start is
// an error value, and the threads already started are joined (no std::terminate).
#include <gtest/gtest.h>
#include <sys/resource.h>

#include <atomic>
#include <fstream>
#include <string>

#include "work_queue.hpp"

namespace vts::detail {
namespace {

// The process's virtual memory size in bytes (VmSize of /proc/self/status), 0 if unknown.
std::uint64_t virtual_memory_bytes() {
  std::ifstream in("/proc/self/status");
  std::string key;
  while (in >> key) {
    if (key == "VmSize:") {
      std::uint64_t kib = 0;
      in >> kib;
      return kib * 1024;
    }
    in.ignore(1 << 20, '\n');
  }
  return 0;
}

// Lowers RLIMIT_AS to what the process maps now plus `room` (thread stacks are 8 MiB of it each)
// for its lifetime: the way `ulimit -v` makes std::thread fail, for root too.
class AddressSpaceLimit {
 public:
  explicit AddressSpaceLimit(std::uint64_t room) {
    getrlimit(RLIMIT_AS, &old_);
    rlimit limited = old_;
    limited.rlim_cur = virtual_memory_bytes() + room;
    ok_ = virtual_memory_bytes() > 0 && setrlimit(RLIMIT_AS, &limited) == 0;
  }
  ~AddressSpaceLimit() { setrlimit(RLIMIT_AS, &old_); }
  bool ok() const { return ok_; }

 private:
  rlimit old_{};
  bool ok_ = false;
};

bool sanitized() {
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  return true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
  return true;
#endif
#endif
  return false;
}

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
