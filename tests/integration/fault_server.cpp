#include "fault_server.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>
#include <xxhash.h>

#include <atomic>
#include <cerrno>
#include <charconv>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <list>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <span>
#include <stdexcept>
#include <thread>
#include <vector>

#include "vts/archive/pmtiles.hpp"

namespace vts::test {

namespace {

constexpr std::size_t kMaxHead = 64 * 1024;
constexpr auto kSlowByteInterval = std::chrono::milliseconds(200);

struct Request {
  std::string method;
  std::string target;                          // as received: path and query
  std::string path;                            // target without the query
  std::map<std::string, std::string> headers;  // lower-case names
  bool keep_alive = true;
};

struct Response {
  int status = 200;
  std::vector<std::string> headers;    // "Name: value"
  std::span<const std::uint8_t> view;  // the body, when it lives elsewhere (the archive)
  std::string owned;                   // the body, when non-empty (text answers, tiles)

  std::span<const std::uint8_t> body() const {
    if (owned.empty()) return view;
    return {reinterpret_cast<const std::uint8_t*>(owned.data()), owned.size()};
  }
};

struct Spec {
  enum Mode { drop, reset, stall, slow, truncate, corrupt, respond } mode = respond;
  int status = 0;
  int retry_after = -1;
  long count = -1;  // faulty attempts; -1: all of them
};

std::string lower(std::string_view s) {
  std::string r(s);
  for (char& c : r) c = (c >= 'A' && c <= 'Z') ? char(c - 'A' + 'a') : c;
  return r;
}

std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) s.remove_suffix(1);
  return s;
}

template <typename T>
bool parse_number(std::string_view s, T& out) {
  if (s.empty()) return false;
  auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
  return ec == std::errc() && p == s.data() + s.size();
}

std::optional<Spec> parse_spec(std::string_view text) {
  Spec spec;
  if (const auto star = text.find('*'); star != std::string_view::npos) {
    if (!parse_number(text.substr(star + 1), spec.count) || spec.count < 0) return std::nullopt;
    text = text.substr(0, star);
  }
  static const std::pair<std::string_view, Spec::Mode> kModes[] = {
      {"drop", Spec::drop}, {"reset", Spec::reset},       {"stall", Spec::stall},
      {"slow", Spec::slow}, {"truncate", Spec::truncate}, {"corrupt", Spec::corrupt}};
  for (const auto& [name, mode] : kModes) {
    if (text == name) {
      spec.mode = mode;
      return spec;
    }
  }
  // NNN or NNNraS
  if (text.size() < 3 || !parse_number(text.substr(0, 3), spec.status) || spec.status < 100 ||
      spec.status > 599) {
    return std::nullopt;
  }
  text.remove_prefix(3);
  if (!text.empty()) {
    if (text.substr(0, 2) != "ra" || !parse_number(text.substr(2), spec.retry_after)) {
      return std::nullopt;
    }
  }
  spec.mode = Spec::respond;
  return spec;
}

const char* reason_phrase(int status) {
  switch (status) {
    case 200:
      return "OK";
    case 206:
      return "Partial Content";
    case 304:
      return "Not Modified";
    case 400:
      return "Bad Request";
    case 404:
      return "Not Found";
    case 405:
      return "Method Not Allowed";
    case 416:
      return "Range Not Satisfiable";
    case 429:
      return "Too Many Requests";
    case 500:
      return "Internal Server Error";
    case 502:
      return "Bad Gateway";
    case 503:
      return "Service Unavailable";
    default:
      return "Status";
  }
}

bool send_all(int fd, const void* data, std::size_t n) {
  const auto* p = static_cast<const char*>(data);
  while (n > 0) {
    const ssize_t w = ::send(fd, p, n, MSG_NOSIGNAL);
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) return false;
    p += w;
    n -= std::size_t(w);
  }
  return true;
}

std::string etag_of(std::span<const std::uint8_t> bytes) {
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016llx",
                static_cast<unsigned long long>(XXH3_64bits(bytes.data(), bytes.size())));
  return std::string("\"") + hex + "\"";
}

// RFC 9110 weak comparison against a list of tags, or "*".
bool etag_matches(std::string_view header, std::string_view etag) {
  while (!header.empty()) {
    const auto comma = header.find(',');
    std::string_view tag = trim(header.substr(0, comma));
    if (tag == "*") return true;
    if (tag.substr(0, 2) == "W/") tag.remove_prefix(2);
    if (tag == etag) return true;
    if (comma == std::string_view::npos) break;
    header.remove_prefix(comma + 1);
  }
  return false;
}

std::vector<std::uint8_t> whole_archive(const archive::Reader& reader) {
  std::vector<std::uint8_t> bytes(reader.size());
  if (Status s = reader.read(0, bytes); !s) throw std::runtime_error(s.error().to_string());
  return bytes;
}

}  // namespace

class FaultServer::Impl {
 public:
  Impl(std::shared_ptr<archive::Reader> reader, std::string name)
      : reader_(std::move(reader)),
        archive_bytes_(whole_archive(*reader_)),
        name_(std::move(name)) {}

  ~Impl() { stop(); }

  Status listen(std::uint16_t port) {
    if (::pipe2(wake_, O_CLOEXEC) != 0) {
      return make_error(ErrorCode::io, std::string("pipe: ") + std::strerror(errno));
    }
    listen_fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (listen_fd_ < 0) return make_error(ErrorCode::io, std::string("socket: ") + strerror(errno));
    const int one = 1;
    ::setsockopt(listen_fd_, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    addr.sin_port = htons(port);
    if (::bind(listen_fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0 ||
        ::listen(listen_fd_, 256) != 0) {
      return make_error(ErrorCode::io, "bind/listen on 127.0.0.1:" + std::to_string(port) + ": " +
                                           std::strerror(errno));
    }
    socklen_t len = sizeof addr;
    ::getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&addr), &len);
    port_ = ntohs(addr.sin_port);
    accept_thread_ = std::thread([this] { accept_loop(); });
    return {};
  }

  std::uint16_t port() const { return port_; }

  int attempts(std::string_view target) const {
    std::lock_guard lock(counters_mutex_);
    auto it = counters_.find(std::string(target));
    return it == counters_.end() ? 0 : it->second;
  }

  void reset() {
    std::lock_guard lock(counters_mutex_);
    counters_.clear();
  }

 private:
  struct Connection {
    int fd = -1;  // guarded by conns_mutex_; -1 once closed
    std::thread thread;
    bool done = false;  // guarded by conns_mutex_
  };

  void stop() {
    if (accept_thread_.joinable()) {
      stopping_ = true;
      const char c = 'x';
      [[maybe_unused]] const ssize_t w = ::write(wake_[1], &c, 1);
      accept_thread_.join();
    }
    std::list<std::unique_ptr<Connection>> conns;
    {
      std::lock_guard lock(conns_mutex_);
      stopping_ = true;
      for (auto& c : conns_) {
        if (c->fd >= 0) ::shutdown(c->fd, SHUT_RDWR);  // wakes recv() in stalled connections
      }
      conns.swap(conns_);
    }
    { std::lock_guard lock(sleep_mutex_); }
    sleep_cv_.notify_all();
    for (auto& c : conns) c->thread.join();
    if (listen_fd_ >= 0) ::close(listen_fd_);
    listen_fd_ = -1;
    for (int& fd : wake_) {
      if (fd >= 0) ::close(fd);
      fd = -1;
    }
  }

  void accept_loop() {
    while (!stopping_) {
      pollfd fds[2] = {{listen_fd_, POLLIN, 0}, {wake_[0], POLLIN, 0}};
      if (::poll(fds, 2, 1000) < 0 && errno != EINTR) break;
      reap_finished();
      if (fds[1].revents != 0 || stopping_) break;
      if ((fds[0].revents & POLLIN) == 0) continue;
      const int fd = ::accept4(listen_fd_, nullptr, nullptr, SOCK_CLOEXEC);
      if (fd < 0) continue;
      const int one = 1;
      ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
      std::lock_guard lock(conns_mutex_);
      auto conn = std::make_unique<Connection>();
      conn->fd = fd;
      Connection* raw = conn.get();
      conns_.push_back(std::move(conn));
      raw->thread = std::thread([this, raw, fd] { serve_connection(raw, fd); });
    }
  }

  void reap_finished() {
    std::list<std::unique_ptr<Connection>> finished;
    {
      std::lock_guard lock(conns_mutex_);
      for (auto it = conns_.begin(); it != conns_.end();) {
        if ((*it)->done) {
          finished.push_back(std::move(*it));
          it = conns_.erase(it);
        } else {
          ++it;
        }
      }
    }
    for (auto& c : finished) c->thread.join();
  }

  // Closes the connection; with rst, aborts it with a TCP RST instead of a FIN.
  void close_connection(Connection* conn, bool rst) {
    std::lock_guard lock(conns_mutex_);
    if (conn->fd >= 0) {
      if (rst) {
        const linger lg{1, 0};
        ::setsockopt(conn->fd, SOL_SOCKET, SO_LINGER, &lg, sizeof lg);
      }
      ::close(conn->fd);
      conn->fd = -1;
    }
    conn->done = true;
  }

  void serve_connection(Connection* conn, int fd) {
    std::string buffer;
    bool rst = false;
    while (!stopping_) {
      std::optional<Request> req = read_request(fd, buffer);
      if (!req) break;
      const Outcome outcome = handle(fd, *req);
      if (outcome == Outcome::reset) rst = true;
      if (outcome != Outcome::keep_alive || !req->keep_alive) break;
    }
    close_connection(conn, rst);
  }

  std::optional<Request> read_request(int fd, std::string& buffer) {
    std::size_t end;
    while ((end = buffer.find("\r\n\r\n")) == std::string::npos) {
      if (buffer.size() > kMaxHead) return std::nullopt;
      char chunk[4096];
      const ssize_t n = ::recv(fd, chunk, sizeof chunk, 0);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) return std::nullopt;
      buffer.append(chunk, std::size_t(n));
    }
    const std::string head = buffer.substr(0, end);
    buffer.erase(0, end + 4);

    Request req;
    std::size_t line_end = head.find("\r\n");
    const std::string_view request_line = std::string_view(head).substr(0, line_end);
    const auto sp1 = request_line.find(' ');
    const auto sp2 = request_line.rfind(' ');
    if (sp1 == std::string_view::npos || sp2 == sp1) return std::nullopt;
    req.method = std::string(request_line.substr(0, sp1));
    req.target = std::string(request_line.substr(sp1 + 1, sp2 - sp1 - 1));
    req.path = req.target.substr(0, req.target.find('?'));
    const std::string_view version = request_line.substr(sp2 + 1);
    req.keep_alive = version == "HTTP/1.1";
    while (line_end != std::string::npos) {
      const std::size_t start = line_end + 2;
      line_end = head.find("\r\n", start);
      const std::string_view line = std::string_view(head).substr(
          start, line_end == std::string::npos ? std::string::npos : line_end - start);
      const auto colon = line.find(':');
      if (colon == std::string_view::npos) continue;
      req.headers[lower(trim(line.substr(0, colon)))] = std::string(trim(line.substr(colon + 1)));
    }
    if (auto it = req.headers.find("connection"); it != req.headers.end()) {
      const std::string v = lower(it->second);
      if (v == "close") req.keep_alive = false;
      if (v == "keep-alive") req.keep_alive = true;
    }
    // Discard a request body (POST /_reset may carry one).
    if (auto it = req.headers.find("content-length"); it != req.headers.end()) {
      std::size_t length = 0;
      if (!parse_number(std::string_view(it->second), length) || length > kMaxHead) {
        return std::nullopt;
      }
      while (buffer.size() < length) {
        char chunk[4096];
        const ssize_t n = ::recv(fd, chunk, sizeof chunk, 0);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) return std::nullopt;
        buffer.append(chunk, std::size_t(n));
      }
      buffer.erase(0, length);
    }
    return req;
  }

  enum class Outcome { keep_alive, close, reset };

  static std::string head_of(const Response& r, std::size_t content_length) {
    std::string h = "HTTP/1.1 " + std::to_string(r.status) + " " + reason_phrase(r.status) + "\r\n";
    for (const std::string& line : r.headers) h += line + "\r\n";
    h += "Content-Length: " + std::to_string(content_length) + "\r\n\r\n";
    return h;
  }

  static Response text(int status, std::string body) {
    Response r;
    r.status = status;
    r.headers.push_back("Content-Type: text/plain");
    r.owned = std::move(body);
    return r;
  }

  Outcome send_response(int fd, const Request& req, const Response& r) {
    const std::span<const std::uint8_t> body = r.body();
    std::string head = head_of(r, body.size());
    if (req.method == "HEAD")
      return send_all(fd, head.data(), head.size()) ? Outcome::keep_alive : Outcome::close;
    // Small bodies go out with the head in one write.
    if (body.size() <= 64 * 1024) {
      head.append(reinterpret_cast<const char*>(body.data()), body.size());
      return send_all(fd, head.data(), head.size()) ? Outcome::keep_alive : Outcome::close;
    }
    return send_all(fd, head.data(), head.size()) && send_all(fd, body.data(), body.size())
               ? Outcome::keep_alive
               : Outcome::close;
  }

  Outcome handle(int fd, const Request& req) {
    if (req.path == "/_stats" || req.path == "/_reset") {
      if (req.method != "GET" && req.method != "POST") {
        Response r = text(405, "method not allowed\n");
        return send_response(fd, req, r);
      }
      Response r;
      if (req.path == "/_reset") {
        reset();
        r = text(200, "reset\n");
      } else {
        nlohmann::json j = nlohmann::json::object();
        {
          std::lock_guard lock(counters_mutex_);
          for (const auto& [target, n] : counters_) j[target] = n;
        }
        r = text(200, j.dump() + "\n");
        r.headers = {"Content-Type: application/json"};
      }
      return send_response(fd, req, r);
    }

    int attempt = 0;
    {
      std::lock_guard lock(counters_mutex_);
      attempt = ++counters_[req.target];
    }
    if (req.method != "GET" && req.method != "HEAD") {
      Response r = text(405, "method not allowed\n");
      r.headers.push_back("Allow: GET, HEAD");
      return send_response(fd, req, r);
    }

    std::string_view rest = req.path;
    std::optional<Spec> fault;
    if (rest.substr(0, 7) == "/fault/") {
      rest.remove_prefix(7);
      const auto slash = rest.find('/');
      std::optional<Spec> spec =
          slash == std::string_view::npos ? std::nullopt : parse_spec(rest.substr(0, slash));
      if (!spec) {
        Response r = text(400, "bad fault spec in " + req.path + "\n");
        return send_response(fd, req, r);
      }
      rest.remove_prefix(slash);
      if (spec->count < 0 || attempt <= spec->count) fault = spec;
    }

    if (fault) {
      switch (fault->mode) {
        case Spec::drop:
          return Outcome::close;
        case Spec::reset:
          return Outcome::reset;
        case Spec::stall:
          stall(fd);
          return Outcome::close;
        case Spec::respond: {
          Response r = text(fault->status, "injected " + std::to_string(fault->status) + "\n");
          if (fault->retry_after >= 0) {
            r.headers.push_back("Retry-After: " + std::to_string(fault->retry_after));
          }
          return send_response(fd, req, r);
        }
        default:
          break;  // the modes below damage a normal answer
      }
    }

    const Response r = serve(rest, req);
    const std::span<const std::uint8_t> body = r.body();
    if (!fault || body.empty() || (r.status != 200 && r.status != 206) || req.method == "HEAD") {
      return send_response(fd, req, r);
    }
    const std::string head = head_of(r, body.size());
    switch (fault->mode) {
      case Spec::truncate:
        send_all(fd, head.data(), head.size());
        send_all(fd, body.data(), body.size() / 2);
        return Outcome::close;
      case Spec::corrupt: {
        std::vector<std::uint8_t> damaged(body.begin(), body.end());
        damaged[damaged.size() / 2] ^= 0xFF;
        if (!send_all(fd, head.data(), head.size()) ||
            !send_all(fd, damaged.data(), damaged.size())) {
          return Outcome::close;
        }
        return Outcome::keep_alive;
      }
      case Spec::slow: {
        if (!send_all(fd, head.data(), head.size())) return Outcome::close;
        for (std::uint8_t byte : body) {
          std::unique_lock lock(sleep_mutex_);
          if (sleep_cv_.wait_for(lock, kSlowByteInterval, [this] { return stopping_.load(); })) {
            return Outcome::close;
          }
          lock.unlock();
          if (!send_all(fd, &byte, 1)) return Outcome::close;
        }
        return Outcome::keep_alive;
      }
      default:
        return send_response(fd, req, r);
    }
  }

  // Holds the request unanswered until the peer closes or the server stops (stop() shuts the
  // socket down, which ends recv()).
  void stall(int fd) {
    char chunk[4096];
    for (;;) {
      const ssize_t n = ::recv(fd, chunk, sizeof chunk, 0);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0 || stopping_) return;
    }
  }

  Response serve(std::string_view path, const Request& req) const {
    const std::string archive_path = "/" + name_ + ".pmtiles";
    if (path == archive_path) return serve_archive(req);
    // "/NAME/z/x/y", or "/NAME@VERSION/z/x/y" as in the versioned URLs vts serve hands out.
    std::string_view rest;
    if (const std::string prefix = "/" + name_ + "/"; path.substr(0, prefix.size()) == prefix) {
      rest = path.substr(prefix.size());
    } else if (const std::string versioned = "/" + name_ + "@";
               path.substr(0, versioned.size()) == versioned) {
      const auto slash = path.find('/', versioned.size());
      if (slash != std::string_view::npos) rest = path.substr(slash + 1);
    }
    if (!rest.empty()) {
      auto id = parse_tile_id(rest);
      if (id && id->z <= 31 && (id->x >> id->z) == 0 && (id->y >> id->z) == 0) {
        auto tile = reader_->get(*id);
        if (tile) {
          Response r;
          const std::string etag = etag_of(*tile);
          r.headers.push_back("ETag: " + etag);
          r.headers.push_back("Content-Type: application/vnd.vtstream.tile");
          if (auto it = req.headers.find("if-none-match");
              it != req.headers.end() && etag_matches(it->second, etag)) {
            r.status = 304;
            return r;
          }
          r.owned.assign(tile->begin(), tile->end());  // a copy the reader made: keep it
          return r;
        }
      }
    }
    return text(404, "not found: " + std::string(path) + "\n");
  }

  Response serve_archive(const Request& req) const {
    const std::span<const std::uint8_t> bytes = archive_bytes_;
    const std::uint64_t size = bytes.size();
    Response r;
    r.headers.push_back("Content-Type: application/vnd.pmtiles");
    r.headers.push_back("Accept-Ranges: bytes");
    r.view = bytes;
    auto it = req.headers.find("range");
    if (it == req.headers.end()) return r;
    std::string_view spec = trim(it->second);
    if (lower(spec.substr(0, 6)) != "bytes=" || spec.find(',') != std::string_view::npos) return r;
    spec.remove_prefix(6);
    const auto dash = spec.find('-');
    if (dash == std::string_view::npos) return r;
    const std::string_view a = trim(spec.substr(0, dash)), b = trim(spec.substr(dash + 1));
    std::uint64_t first = 0, last = 0;
    if (a.empty()) {  // suffix: the last n bytes
      std::uint64_t n = 0;
      if (!parse_number(b, n)) return r;
      if (n == 0 || size == 0) {
        Response u = text(416, "range not satisfiable\n");
        u.headers.push_back("Content-Range: bytes */" + std::to_string(size));
        return u;
      }
      first = n >= size ? 0 : size - n;
      last = size - 1;
    } else {
      if (!parse_number(a, first)) return r;
      if (b.empty()) {
        last = size == 0 ? 0 : size - 1;
      } else if (!parse_number(b, last) || last < first) {
        return r;  // invalid range-spec: ignored
      }
      if (first >= size) {
        Response u = text(416, "range not satisfiable\n");
        u.headers.push_back("Content-Range: bytes */" + std::to_string(size));
        return u;
      }
      last = std::min(last, size - 1);
    }
    r.status = 206;
    r.headers.push_back("Content-Range: bytes " + std::to_string(first) + "-" +
                        std::to_string(last) + "/" + std::to_string(size));
    r.view = bytes.subspan(first, last - first + 1);
    return r;
  }

  std::shared_ptr<archive::Reader> reader_;
  const std::vector<std::uint8_t> archive_bytes_;  // the whole file, served for range requests
  std::string name_;
  int listen_fd_ = -1;
  int wake_[2] = {-1, -1};
  std::uint16_t port_ = 0;
  std::atomic<bool> stopping_{false};
  std::thread accept_thread_;

  std::mutex conns_mutex_;
  std::list<std::unique_ptr<Connection>> conns_;

  std::mutex sleep_mutex_;
  std::condition_variable sleep_cv_;

  mutable std::mutex counters_mutex_;
  std::map<std::string, int> counters_;
};

Result<std::unique_ptr<FaultServer>> FaultServer::start(const std::filesystem::path& archive,
                                                        std::string name, std::uint16_t port) {
  auto reader = archive::Reader::open(archive);
  if (!reader) return reader.error();
  auto impl = std::make_unique<Impl>(std::move(*reader), std::move(name));
  if (Status st = impl->listen(port); !st.ok()) return st.error();
  return std::unique_ptr<FaultServer>(new FaultServer(std::move(impl)));
}

FaultServer::FaultServer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
FaultServer::~FaultServer() = default;

std::uint16_t FaultServer::port() const {
  return impl_->port();
}
std::string FaultServer::base_url() const {
  return "http://127.0.0.1:" + std::to_string(port());
}
int FaultServer::attempts(std::string_view target) const {
  return impl_->attempts(target);
}
void FaultServer::reset() {
  impl_->reset();
}

}  // namespace vts::test
