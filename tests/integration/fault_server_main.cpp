// fault_server ARCHIVE NAME [--port N]: the FaultServer of fault_server.hpp as a process, for shell
// tests. Prints "listening on PORT" on stdout once it accepts connections, then serves until
// SIGTERM or SIGINT and exits 0. Exit 2 on bad arguments, 1 when the archive or port is unusable.
#include <signal.h>

#include <charconv>
#include <cstdio>
#include <memory>
#include <string>
#include <string_view>

#include "fault_server.hpp"

namespace {

int usage() {
  std::fprintf(stderr, "usage: fault_server ARCHIVE NAME [--port N]\n");
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 3 && argc != 5) return usage();
  std::uint16_t port = 0;
  if (argc == 5) {
    const std::string_view flag = argv[3], value = argv[4];
    auto [p, ec] = std::from_chars(value.data(), value.data() + value.size(), port);
    if (flag != "--port" || ec != std::errc() || p != value.data() + value.size()) return usage();
  }

  // Block the signals before any thread starts, so every thread inherits the mask and sigwait()
  // below is the only receiver.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGINT);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  auto server = vts::test::FaultServer::start(argv[1], argv[2], port);
  if (!server) {
    std::fprintf(stderr, "fault_server: %s\n", server.error().to_string().c_str());
    return 1;
  }
  std::unique_ptr<vts::test::FaultServer> running = std::move(*server);
  std::printf("listening on %u\n", unsigned(running->port()));
  std::fflush(stdout);

  int sig = 0;
  sigwait(&signals, &sig);
  running.reset();  // closes every connection and joins before exit
  return 0;
}
