// One client connection of HttpServer (the contract is in http_server.hpp). All of a session's
// handlers run on its io_context's one thread, in order; only on_server_stop() and remove() from
// the sweeper come from elsewhere.
#pragma once

#include <array>
#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core/flat_buffer.hpp>
#include <boost/beast/http.hpp>
#include <cstddef>
#include <deque>
#include <memory>
#include <memory_resource>
#include <optional>
#include <stop_token>
#include <string>

#include "access_log.hpp"
#include "deadline_sweeper.hpp"
#include "metrics.hpp"
#include "response_writer.hpp"
#include "vts/server/http_server.hpp"

namespace vts {
inline namespace server {
namespace http_detail {

class Session;

// What a session needs from its server.
class SessionHost {
 public:
  virtual const HttpServerOptions& options() const = 0;
  virtual const TilesetRegistry& registry() const = 0;
  virtual AsyncTileProvider* provider() const = 0;
  virtual Metrics& metrics() = 0;
  virtual AccessLog& access_log() = 0;
  virtual bool stopping() const = 0;
  virtual HttpResponse admin_route(const HttpRequest& request) = 0;
  // Asks for registry.reload(force) on the reload thread; returns at once.
  virtual void request_reload(bool force) = 0;
  // From the session's destructor, on whatever thread runs it.
  virtual void remove_session(Session* s) = 0;

 protected:
  ~SessionHost() = default;
};

// Request header fields live in a per-connection arena, reset after each request: Beast allocates
// every field separately, which would be a malloc and a free per field per request.
using FieldAllocator = std::pmr::polymorphic_allocator<char>;
using RequestParser =
    boost::beast::http::request_parser<boost::beast::http::empty_body, FieldAllocator>;

class Session final : public std::enable_shared_from_this<Session>, public Swept {
 public:
  using tcp = boost::asio::ip::tcp;
  using error_code = boost::system::error_code;

  Session(SessionHost& server, Sweeper& sweeper, tcp::socket socket, bool admin);
  ~Session();
  // Closes the connection when a deadline has passed. The idle deadline does not count while
  // responses are owed (the client waits for us, not idle).
  void check_deadlines(DeadlineClock::time_point now) override;
  void start();
  // When the server stops (any thread): close now if nothing is queued, else after the last
  // queued response.
  void on_server_stop();

 private:
  void wait_for_request();
  void read_request();
  void read_ahead();
  void client_gone();
  void on_read(error_code ec);
  void on_parse_error(error_code ec);
  std::unique_ptr<Outgoing> answer(RequestParser::value_type& req);
  void enqueue(std::unique_ptr<Outgoing> out);
  void prepare(Outgoing& o);
  void start_pending(const Outgoing& o);
  void finish_pending_answer(std::uint64_t seq, HttpResponse answer);
  void write_next();
  void wait_writable();
  bool complete_front();
  void log(const Outgoing& out, std::chrono::nanoseconds elapsed);
  void fail_parse(int status, const char* message);
  // Deadlines, enforced by the connection's thread's Sweeper (expiry closes the connection).
  void set_read_deadline(std::chrono::milliseconds d) { read_deadline_ = DeadlineClock::now() + d; }
  void clear_read_deadline() { read_deadline_ = DeadlineClock::time_point::max(); }
  void close();
  void linger_close();
  void drain_input();
  // Outgoing objects are reused (with their header buffer): a keep-alive connection allocates
  // neither for each request.
  std::unique_ptr<Outgoing> new_outgoing();
  void recycle(std::unique_ptr<Outgoing> o);

  SessionHost& server_;
  tcp::socket socket_;
  bool admin_;
  Sweeper& sweeper_;
  DeadlineClock::time_point read_deadline_ = DeadlineClock::time_point::max();
  DeadlineClock::time_point write_deadline_ = DeadlineClock::time_point::max();
  boost::beast::flat_buffer buffer_;
  std::array<std::byte, 2048> field_buffer_;
  std::pmr::monotonic_buffer_resource fields_{field_buffer_.data(), field_buffer_.size()};
  std::optional<RequestParser> parser_;
  std::deque<std::unique_ptr<Outgoing>> queue_;
  std::unique_ptr<Outgoing> spare_;
  bool reading_ = false;      // a read (wait or header) is outstanding
  bool read_paused_ = false;  // stopped reading because the pipeline is full
  bool read_done_ = false;    // no more requests will be read (close requested / error / EOF)
  bool writing_ = false;      // waiting for the socket to accept more
  bool in_write_ = false;     // inside write_next()
  bool closed_ = false;
  bool idle_wait_ = false;      // the outstanding read waits for the first byte of a request
  std::uint64_t next_seq_ = 0;  // of the next response queued
  // Requested when the client has gone (its end of the connection closed, or we closed it): the
  // provider's tiles still owed are abandoned (AsyncTileProvider::tile).
  std::stop_source abandon_;
  std::string remote_;
  const std::uint64_t id_;  // HttpRequest::connection: unique in this process
};

}  // namespace http_detail
}  // namespace server
}  // namespace vts
