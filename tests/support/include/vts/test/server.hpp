// The real `vts serve` (HttpServer + TilesetRegistry) in process on 127.0.0.1, port 0, running on
// its own thread from construction until stop() or destruction.
#pragma once

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "vts/server/http_server.hpp"
#include "vts/server/tileset_registry.hpp"

namespace vts::test {

class RunningServer {
 public:
  // Loads `archives` (files or folders; none is allowed, e.g. with a provider) into a new
  // registry and starts the server with `options`, except that signals are never handled and
  // listen_port is forced to 0 unless `keep_port` (to restart on a port a client already knows).
  // Throws std::runtime_error when loading or binding fails.
  explicit RunningServer(std::vector<std::filesystem::path> archives,
                         HttpServerOptions options = quiet_options(), bool keep_port = false);
  ~RunningServer();
  RunningServer(const RunningServer&) = delete;
  RunningServer& operator=(const RunningServer&) = delete;

  // No admin listener, two threads, no periodic reload.
  static HttpServerOptions quiet_options();

  // Stops the server and waits for run() to return (idempotent); returns how long that took.
  std::chrono::steady_clock::duration stop();

  std::uint16_t port() const { return port_; }
  // "http://127.0.0.1:<port>"
  std::string base_url() const { return "http://127.0.0.1:" + std::to_string(port_); }
  HttpServer& server() { return *server_; }
  TilesetRegistry& registry() { return *registry_; }

 private:
  std::shared_ptr<TilesetRegistry> registry_;
  std::unique_ptr<HttpServer> server_;
  std::uint16_t port_ = 0;
  std::thread thread_;
};

}  // namespace vts::test
