// A remote source's delivery thread: answers known without the network (a remote source never
// runs a callback inside fetch()) run on it, one at a time and in the order they were posted. It
// is a one-thread WorkerPool (base/worker_pool.hpp) named "vts-deliver"; destroying it runs what
// is queued, then joins.
#pragma once

#include <memory>

#include "vts/base/worker_pool.hpp"

namespace vts::client {

// io "cannot start a thread (vts-deliver) ..." when the system refuses the thread.
inline Result<std::unique_ptr<WorkerPool>> start_deliverer() {
  return WorkerPool::start({.threads = 1, .capacity = 0, .name = "vts-deliver"});
}

}  // namespace vts::client
