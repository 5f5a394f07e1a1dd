#include "response_writer.hpp"

#include <sys/socket.h>
#include <sys/uio.h>

#include <algorithm>
#include <boost/asio/error.hpp>
#include <boost/beast/http/status.hpp>
#include <cassert>
#include <cerrno>
#include <ctime>

#include "vts/archive/pmtiles.hpp"
#include "vts/server/tileset_registry.hpp"

namespace vts {
inline namespace server {
namespace http_detail {
namespace {

// One pass with no calls (find_first_of calls memchr once per character of its set).
bool has_line_break(std::string_view s) {
  bool found = false;
  for (const char c : s) found |= (c == '\r') | (c == '\n');
  return found;
}

// RFC 9110 IMF-fixdate, cached per second per thread.
std::string_view http_date() {
  thread_local std::time_t cached = 0;
  thread_local char buf[40];
  const std::time_t now = std::time(nullptr);
  if (now != cached) {
    std::tm tm{};
    gmtime_r(&now, &tm);
    std::strftime(buf, sizeof buf, "%a, %d %b %Y %H:%M:%S GMT", &tm);
    cached = now;
  }
  return buf;
}

void serialise_head(const Outgoing& o, bool no_body, std::string& h) {
  const HttpResponse& r = o.response;
  h.reserve(512);
  h += "HTTP/1.1 ";
  h += std::to_string(r.status);
  h += ' ';
  const auto reason =
      boost::beast::http::obsolete_reason(static_cast<boost::beast::http::status>(r.status));
  h.append(reason.data(), reason.size());
  h += "\r\nServer: vtstream\r\nDate: ";
  h += http_date();
  h += "\r\n";
  for (const auto& [k, v] : r.headers) {
    if (has_line_break(v)) continue;  // header injection guard (a bad config value)
    h += k;
    h += ": ";
    h += v;
    h += "\r\n";
  }
  if (o.close)
    h += "Connection: close\r\n";
  else if (o.keep_alive_header)
    h += "Connection: keep-alive\r\n";
  if (!no_body) {
    h += "Content-Length: ";
    h += std::to_string(r.content_length);
    h += "\r\n";
  }
  h += "\r\n";
}

constexpr std::size_t kFileChunkBytes = 256 * 1024;

}  // namespace

void prepare_response(Outgoing& o) {
  const HttpResponse& r = o.response;
  const bool no_body = r.status == 304 || r.status == 204 || (r.status >= 100 && r.status < 200);
  serialise_head(o, no_body, o.head);
  if (r.head_only || no_body) return;
  o.body_size = r.content_length;
  if (r.file_body) {
    assert(r.hold && r.hold->reader);
    o.file = r.hold->reader.get();
    o.file_offset = r.file_offset;
    return;
  }
  o.body = r.view.empty()
               ? std::span<const char>(r.owned.data(), r.owned.size())
               : std::span<const char>(reinterpret_cast<const char*>(r.view.data()), r.view.size());
  assert(o.body.size() == r.content_length);
}

std::size_t write_some(int sock, Outgoing& o, boost::system::error_code& ec) {
  namespace aerr = boost::asio::error;
  ssize_t n = 0;
  if (o.sent < o.head.size()) {
    const char* p = o.head.data() + o.sent;
    const std::size_t len = o.head.size() - o.sent;
    if (o.file != nullptr) {
      // The body follows from the file: MSG_MORE holds this partial segment for it.
      n = ::send(sock, p, len, MSG_NOSIGNAL | (o.body_size > 0 ? MSG_MORE : 0));
    } else {
      iovec iov[2] = {{const_cast<char*>(p), len},
                      {const_cast<char*>(o.body.data()), o.body.size()}};
      msghdr msg{};
      msg.msg_iov = iov;
      msg.msg_iovlen = o.body.empty() ? 1 : 2;
      n = ::sendmsg(sock, &msg, MSG_NOSIGNAL);
    }
  } else if (o.file != nullptr) {
    const std::uint64_t done = o.sent - o.head.size();
    if (done >= o.chunk_start + o.chunk.size()) {
      const std::size_t len =
          std::size_t(std::min<std::uint64_t>(kFileChunkBytes, o.body_size - done));
      o.chunk.resize(len);
      const std::span<std::uint8_t> out(reinterpret_cast<std::uint8_t*>(o.chunk.data()), len);
      if (!o.file->read(o.file_offset + done, out)) {
        ec = aerr::operation_aborted;
        return 0;
      }
      o.chunk_start = done;
    }
    const std::size_t at = std::size_t(done - o.chunk_start);
    n = ::send(sock, o.chunk.data() + at, o.chunk.size() - at, MSG_NOSIGNAL);
  } else {
    const std::size_t done = o.sent - o.head.size();
    n = ::send(sock, o.body.data() + done, o.body.size() - done, MSG_NOSIGNAL);
  }
  if (n < 0) {
    const int err = errno;
    ec = (err == EAGAIN || err == EWOULDBLOCK)
             ? boost::system::error_code(aerr::would_block)
             : boost::system::error_code(err, boost::system::system_category());
    return 0;
  }
  return std::size_t(n);
}

}  // namespace http_detail
}  // namespace server
}  // namespace vts
