#include "vts/test/server.hpp"

#include <cstdio>
#include <stdexcept>

namespace vts::test {

HttpServerOptions RunningServer::quiet_options() {
  HttpServerOptions o;
  o.admin_enabled = false;
  o.threads = 2;
  o.reload_interval = std::chrono::milliseconds(0);
  return o;
}

RunningServer::RunningServer(std::vector<std::filesystem::path> archives, HttpServerOptions options,
                             bool keep_port) {
  if (!keep_port) options.listen_port = 0;
  options.handle_signals = false;
  registry_ = std::make_shared<TilesetRegistry>();
  if (!archives.empty()) {
    auto st = registry_->load(archives);
    if (!st.ok()) throw std::runtime_error(st.error().to_string());
  }
  auto s = HttpServer::create(std::move(options), registry_);
  if (!s) throw std::runtime_error(s.error().to_string());
  server_ = std::move(*s);
  port_ = server_->port();
  thread_ = std::thread([this] {
    if (const Status ran = server_->run(); !ran.ok())
      std::fprintf(stderr, "RunningServer: %s\n", ran.error().to_string().c_str());
  });
}

RunningServer::~RunningServer() {
  stop();
}

std::chrono::steady_clock::duration RunningServer::stop() {
  const auto start = std::chrono::steady_clock::now();
  if (thread_.joinable()) {
    server_->stop();
    thread_.join();
  }
  return std::chrono::steady_clock::now() - start;
}

}  // namespace vts::test
