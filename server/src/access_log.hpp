// The JSON-lines access log: one object per answered request, written whole under a lock and
// flushed, so lines from several threads never interleave.
#pragma once

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <mutex>
#include <string>
#include <string_view>

#include "vts/base/result.hpp"

namespace vts {
inline namespace server {
namespace http_detail {

struct AccessLogEntry {
  std::string_view remote, method, target, route, tileset;
  int status = 0;
  std::uint64_t bytes = 0;
  std::chrono::nanoseconds duration{0};
};

class AccessLog {
 public:
  AccessLog() = default;
  AccessLog(const AccessLog&) = delete;
  AccessLog& operator=(const AccessLog&) = delete;
  ~AccessLog();
  // "" = off, "-" = stdout, else a file opened for appending. Error io naming the file.
  Status open(const std::string& where);
  bool enabled() const { return file_ != nullptr; }
  // Thread-safe. {"time","remote","method","target","status","bytes","duration_us","route",
  // "tileset"}; every string is JSON-escaped (controls and non-ASCII bytes as \u00XX: one line,
  // whatever the request held), time is UTC to the second.
  void write(const AccessLogEntry& e);

 private:
  FILE* file_ = nullptr;
  bool owns_ = false;
  std::mutex mutex_;
};

}  // namespace http_detail
}  // namespace server
}  // namespace vts
