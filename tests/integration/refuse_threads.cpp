// LD_PRELOAD shim for the tests of a thread the system refuses: the first VTS_THREADS_ALLOWED
// calls of pthread_create in the process succeed and every later one fails with EAGAIN, as under
// a task limit (ulimit -u, a cgroup's pids.max) or an address-space limit (ulimit -v). Without
// VTS_THREADS_ALLOWED every call goes through. std::thread reaches pthread_create through the
// dynamic linker, so this shim sees every thread a program starts.
#include <dlfcn.h>
#include <pthread.h>

#include <atomic>
#include <cerrno>
#include <cstdlib>

namespace {

using CreateFn = int (*)(pthread_t*, const pthread_attr_t*, void* (*)(void*), void*);

std::atomic<long> calls{0};

long allowed() {
  static const long n = [] {
    const char* v = std::getenv("VTS_THREADS_ALLOWED");
    return v ? std::atol(v) : -1;
  }();
  return n;
}

}  // namespace

extern "C" int pthread_create(pthread_t* thread, const pthread_attr_t* attr, void* (*start)(void*),
                              void* arg) {
  static const auto real = reinterpret_cast<CreateFn>(dlsym(RTLD_NEXT, "pthread_create"));
  const long n = allowed();
  if (n >= 0 && calls.fetch_add(1) >= n) return EAGAIN;
  return real(thread, attr, start, arg);
}
