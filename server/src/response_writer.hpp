// How a response goes on the wire: its serialised header plus its body, without copying the
// body. A body from an archive goes out with sendfile(2) from the archive's file (the kernel hands
// page-cache pages to the socket), the header just before it with MSG_MORE so both leave in one
// segment; any other body (`response.owned`, a provided tile) goes out with the header in one
// gathered write.
#pragma once

#include <sys/types.h>

#include <boost/system/error_code.hpp>
#include <chrono>
#include <cstdint>
#include <span>
#include <string>

#include "deadline_sweeper.hpp"
#include "vts/server/router.hpp"

namespace vts::http_detail {

// One queued response of a connection.
struct Outgoing {
  HttpResponse response;
  std::uint64_t seq = 0;  // position in the connection's request order
  bool ready = true;      // false while a provided tile is awaited (head and body not built yet)
  std::string head;       // status line and header fields, CRLF CRLF
  std::span<const char> body;  // empty for HEAD, 204 and 304
  int file_fd = -1;            // >= 0: send `body` with sendfile from this file ...
  off_t file_offset = 0;       // ... at this offset (where `body` lies in the mapping)
  std::size_t sent = 0;        // bytes of head + body written so far
  std::chrono::steady_clock::time_point start;
  DeadlineClock::time_point deadline{};  // set when writing starts: all out by then
  bool close = false;
  bool keep_alive_header = false;  // HTTP/1.0 client that asked for keep-alive
  // For the access log (only filled when it is on).
  std::string method, target, tileset;

  std::size_t total() const { return head.size() + body.size(); }
};

// Serialises the status line and header fields of `o.response` into `o.head` (a header value
// with CR or LF is dropped, never sent), and points `o.body` at the bytes to send: the archive's
// file for sendfile when the body is a view of its mapping of at least `sendfile_min_bytes`,
// else memory.
void prepare_response(Outgoing& o, std::size_t sendfile_min_bytes);

// One non-blocking send of what is left of `o` on socket `sock` (one syscall); returns the bytes
// written. Sets `ec` to would_block when the socket buffer is full, to eof when a file ends early.
std::size_t write_some(int sock, Outgoing& o, boost::system::error_code& ec);

}  // namespace vts::http_detail
