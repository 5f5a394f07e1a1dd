// Making std::thread fail on purpose: an address-space limit (what `ulimit -v` sets) with room for
// only a few more 8 MiB thread stacks, so a pool asked for hundreds of threads starts some and
// then is refused one. Works for root too (a task limit does not). Sanitizers reserve terabytes of
// address space up front, so under them the limit cannot be set: tests skip (sanitized()).
#pragma once

#include <sys/resource.h>

#include <cstdint>

namespace vts::test {

// True in an ASan or TSan build.
constexpr bool sanitized() {
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  return true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
  return true;
#else
  return false;
#endif
#else
  return false;
#endif
}

// The process's virtual memory size in bytes (VmSize of /proc/self/status), 0 if unknown.
std::uint64_t virtual_memory_bytes();

// For its lifetime, RLIMIT_AS is what the process maps now plus `room` bytes.
class AddressSpaceLimit {
 public:
  explicit AddressSpaceLimit(std::uint64_t room);
  ~AddressSpaceLimit();
  AddressSpaceLimit(const AddressSpaceLimit&) = delete;
  AddressSpaceLimit& operator=(const AddressSpaceLimit&) = delete;
  bool ok() const { return ok_; }  // the limit is in force

 private:
  rlimit old_{};
  bool ok_ = false;
};

}  // namespace vts::test
