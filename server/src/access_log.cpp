#include "access_log.hpp"

#include <ctime>

namespace vts {
inline namespace server {
namespace http_detail {
namespace {

// A JSON string's content: quote and backslash escaped; control bytes (newline, ESC, ...) and
// every byte outside printable ASCII as \u00XX, so a line is one line of ASCII whatever a client
// sent (a JSON log cannot use escape_controls' \xHH).
std::string json_escape(std::string_view s) {
  std::string out;
  out.reserve(s.size() + 2);
  for (const char c : s) {
    const auto u = static_cast<unsigned char>(c);
    if (c == '"' || c == '\\') {
      out += '\\';
      out += c;
    } else if (u < 0x20 || u >= 0x7f) {
      char b[8];
      std::snprintf(b, sizeof b, "\\u%04x", u);
      out += b;
    } else {
      out += c;
    }
  }
  return out;
}

}  // namespace

AccessLog::~AccessLog() {
  if (owns_) std::fclose(file_);
}

Status AccessLog::open(const std::string& where) {
  if (where.empty()) return {};
  if (where == "-") {
    file_ = stdout;
    return {};
  }
  file_ = std::fopen(where.c_str(), "a");
  owns_ = file_ != nullptr;
  if (!file_) return make_error(ErrorCode::io, "cannot open access log '" + where + "'");
  return {};
}

void AccessLog::write(const AccessLogEntry& e) {
  char tbuf[32];
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&now, &tm);
  std::strftime(tbuf, sizeof tbuf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  const auto us = std::chrono::duration_cast<std::chrono::microseconds>(e.duration).count();
  const std::string line =
      std::string("{\"time\":\"") + tbuf + "\",\"remote\":\"" + json_escape(e.remote) +
      "\",\"method\":\"" + json_escape(e.method) + "\",\"target\":\"" + json_escape(e.target) +
      "\",\"status\":" + std::to_string(e.status) + ",\"bytes\":" + std::to_string(e.bytes) +
      ",\"duration_us\":" + std::to_string(us) + ",\"route\":\"" + json_escape(e.route) +
      "\",\"tileset\":\"" + json_escape(e.tileset) + "\"}\n";
  std::lock_guard lock(mutex_);
  std::fwrite(line.data(), 1, line.size(), file_);
  std::fflush(file_);
}

}  // namespace http_detail
}  // namespace server
}  // namespace vts
