// A deliberately misbehaving HTTP/1.1 upstream for the client's tests: it serves one PMTiles
// archive like `vts serve` does (a small subset) and injects faults chosen by the URL, so a test
// states the failure it wants in the URL it fetches.
//
//   GET /{name}/{z}/{x}/{y}   the tile's stored bytes; 404 when absent. ETag "<16 hex of XXH3-64
//                             of the bytes>"; If-None-Match with that tag (or *) -> 304.
//   GET /{name}.pmtiles       the archive; "Range: bytes=a-b" / "bytes=a-" / "bytes=-n" -> 206,
//                             unsatisfiable -> 416, no or other Range -> 200 full.
//   GET /fault/{spec}/{rest}  {rest} served as above, but the first N attempts at this exact
//                             target get the fault MODE, where spec is "MODE*N" (or "MODE": every
//                             attempt). Modes:
//                               drop      close the connection without a reply
//                               reset     close with an RST (SO_LINGER 0)
//                               stall     read the request, never answer (until the client or
//                                         the server's shutdown closes the connection)
//                               slow      normal headers, then the body 1 byte per 200 ms
//                               truncate  full Content-Length, half the body, close
//                               corrupt   200, correct length, one body byte flipped
//                               NNN       that HTTP status with a short text body (404, 500, 503)
//                               NNNraS    status NNN with "Retry-After: S" (503ra1, 429ra1)
//   GET /_stats               JSON object {"target": attempts, ...}
//   GET|POST /_reset          clears the counters
//
// Attempts are counted per request target (path and query, exactly as received) for every target
// except /_stats and /_reset; a query string is otherwise ignored, so tests can make a target
// unique with "?n=1". Connections are keep-alive, one thread each.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>

#include "vts/base/result.hpp"

namespace vts::test {

class FaultServer {
 public:
  // Opens the archive with archive::Reader and listens on 127.0.0.1:port (0: any free port).
  static Result<std::unique_ptr<FaultServer>> start(const std::filesystem::path& archive,
                                                    std::string name, std::uint16_t port = 0);
  ~FaultServer();  // closes every connection (stalled ones included) and joins all threads

  FaultServer(const FaultServer&) = delete;
  FaultServer& operator=(const FaultServer&) = delete;

  std::uint16_t port() const;
  std::string base_url() const;  // "http://127.0.0.1:PORT"
  // Requests received for a target ("/fault/drop*2/a/0/0/0"); 0 when never requested.
  // Thread-safe.
  int attempts(std::string_view target) const;
  void reset();  // thread-safe

 private:
  class Impl;
  explicit FaultServer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace vts::test
