#include "response_writer.hpp"

#include <sys/sendfile.h>
#include <sys/socket.h>
#include <sys/uio.h>

#include <algorithm>
#include <boost/asio/error.hpp>
#include <boost/beast/http/status.hpp>
#include <cassert>
#include <cerrno>
#include <ctime>

#include "vts/protocol/pmtiles.hpp"
#include "vts/server/tileset_registry.hpp"

namespace vts::http_detail {
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

// Points the body at the archive's file (sendfile) or at memory.
void point_body(Outgoing& o, std::size_t sendfile_min_bytes) {
  const HttpResponse& r = o.response;
  if (r.view.empty()) {
    o.body = {r.owned.data(), r.owned.size()};
    return;
  }
  o.body = {reinterpret_cast<const char*>(r.view.data()), r.view.size()};
  const pmtiles::Reader* reader = r.hold ? r.hold->reader.get() : nullptr;
  const auto whole = reader ? reader->bytes() : std::span<const std::uint8_t>{};
  if (reader && reader->file_descriptor() >= 0 && r.view.data() >= whole.data() &&
      r.view.data() + r.view.size() <= whole.data() + whole.size() &&
      r.view.size() >= sendfile_min_bytes) {
    o.file_fd = reader->file_descriptor();
    o.file_offset = off_t(r.view.data() - whole.data());
  }
}

}  // namespace

void prepare_response(Outgoing& o, std::size_t sendfile_min_bytes) {
  const HttpResponse& r = o.response;
  const bool no_body = r.status == 304 || r.status == 204 || (r.status >= 100 && r.status < 200);
  serialise_head(o, no_body, o.head);
  if (!r.head_only && !no_body) {
    point_body(o, sendfile_min_bytes);
    assert(o.body.size() == r.content_length);
  }
}

std::size_t write_some(int sock, Outgoing& o, boost::system::error_code& ec) {
  namespace aerr = boost::asio::error;
  ssize_t n = 0;
  if (o.sent < o.head.size()) {
    const char* p = o.head.data() + o.sent;
    const std::size_t len = o.head.size() - o.sent;
    if (o.file_fd >= 0) {
      // The body follows from the file: MSG_MORE holds this partial segment for it.
      n = ::send(sock, p, len, MSG_NOSIGNAL | MSG_MORE);
    } else {
      iovec iov[2] = {{const_cast<char*>(p), len},
                      {const_cast<char*>(o.body.data()), o.body.size()}};
      msghdr msg{};
      msg.msg_iov = iov;
      msg.msg_iovlen = o.body.empty() ? 1 : 2;
      n = ::sendmsg(sock, &msg, MSG_NOSIGNAL);
    }
  } else {
    const std::size_t done = o.sent - o.head.size();
    const std::size_t len = o.body.size() - done;
    if (o.file_fd >= 0) {
      off_t off = o.file_offset + off_t(done);
      n = ::sendfile(sock, o.file_fd, &off, std::min<std::size_t>(len, std::size_t(1) << 30));
    } else {
      n = ::send(sock, o.body.data() + done, len, MSG_NOSIGNAL);
    }
  }
  if (n < 0) {
    const int err = errno;
    ec = (err == EAGAIN || err == EWOULDBLOCK)
             ? boost::system::error_code(aerr::would_block)
             : boost::system::error_code(err, boost::system::system_category());
    return 0;
  }
  if (n == 0) ec = aerr::eof;  // a file shorter than its mapping: never for a valid reader
  return std::size_t(n);
}

}  // namespace vts::http_detail
