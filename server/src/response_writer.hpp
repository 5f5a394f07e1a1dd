// How a response goes on the wire: its serialised header plus its body. A body in memory (a
// tile read from its archive, `response.owned`, a provided tile) goes out with the header in one
// gathered write. A region of an archive file (`/{ts}.pmtiles`) is read into a buffer a chunk at
// a time as the socket takes it, each chunk checked against the archive being modified in place
// before any of it is sent (archive::Reader::read): a changed archive ends the connection, so a
// client never receives a body that mixes two archives. (Never sendfile(2): the kernel may read
// the file after the check, or put pages on the wire that a writer modifies afterwards.)
#pragma once

#include <sys/types.h>

#include <boost/system/error_code.hpp>
#include <chrono>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "deadline_sweeper.hpp"
#include "vts/archive/pmtiles.hpp"
#include "vts/server/router.hpp"

namespace vts {
inline namespace server {
namespace http_detail {

// One queued response of a connection.
struct Outgoing {
  HttpResponse response;
  std::uint64_t seq = 0;  // position in the connection's request order
  bool ready = true;      // false while a provided tile is awaited (head and body not built yet)
  std::string head;       // status line and header fields, CRLF CRLF
  std::span<const char> body;  // in memory; empty for HEAD, 204 and 304, and for a file body
  // Non-null: the body is bytes [file_offset, file_offset + body_size) of this archive (held by
  // response.hold), read a chunk at a time into `chunk`, which starts at body byte chunk_start.
  const archive::Reader* file = nullptr;
  std::uint64_t file_offset = 0;
  std::uint64_t body_size = 0;  // bytes of body to send
  std::vector<char> chunk;
  std::uint64_t chunk_start = 0;
  std::size_t sent = 0;  // bytes of head + body written so far
  std::chrono::steady_clock::time_point start;
  DeadlineClock::time_point deadline{};  // set when writing starts: all out by then
  bool close = false;
  bool keep_alive_header = false;  // HTTP/1.0 client that asked for keep-alive
  // For the access log (only filled when it is on).
  std::string method, target, tileset;

  std::size_t total() const { return head.size() + body_size; }
};

// Serialises the status line and header fields of `o.response` into `o.head` (a header value
// with CR or LF is dropped, never sent), and points `o.body` at the bytes to send in memory, or
// `o.file` at the archive whose region the body is.
void prepare_response(Outgoing& o);

// One non-blocking send of what is left of `o` on socket `sock` (one send syscall, after a pread
// when the next chunk of a file body is needed); returns the bytes written. Sets `ec` to
// would_block when the socket buffer is full, to operation_aborted when a file body cannot be
// read as it was (the archive was modified in place, or a read error).
std::size_t write_some(int sock, Outgoing& o, boost::system::error_code& ec);

}  // namespace http_detail
}  // namespace server
}  // namespace vts
