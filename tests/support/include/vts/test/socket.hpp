// Raw TCP on loopback for tests that speak HTTP by hand (pipelining, half-sent requests, abuse):
// what libcurl would hide. Blocking sockets; the caller closes what it gets (::close).
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

namespace vts::test {

// A connected socket to 127.0.0.1:port, or -1 when it cannot connect.
int connect_to(std::uint16_t port);

// Writes all of `s` (MSG_NOSIGNAL: a closed peer is false, not SIGPIPE); false when the peer went
// away first.
bool send_all(int fd, std::string_view s);

// Everything the peer sends until it closes (or resets, or a receive timeout set on `fd` passes).
std::string read_until_closed(int fd);

}  // namespace vts::test
