#include "session.hpp"

#include <algorithm>
#include <atomic>
#include <boost/asio/dispatch.hpp>
#include <boost/asio/post.hpp>
#include <cassert>

namespace vts {
inline namespace server {
namespace http_detail {
namespace {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
using tcp = asio::ip::tcp;
using error_code = boost::system::error_code;
using Clock = std::chrono::steady_clock;  // latencies

HttpMethod to_method(http::verb v) {
  switch (v) {
    case http::verb::get:
      return HttpMethod::get;
    case http::verb::head:
      return HttpMethod::head;
    case http::verb::options:
      return HttpMethod::options;
    default:
      return HttpMethod::other;
  }
}

// The header fields the router reads, in one pass (the first of repeated fields wins).
void read_fields(const RequestParser::value_type& req, HttpRequest& hr) {
  for (const auto& f : req) {
    std::string_view* slot = nullptr;
    switch (f.name()) {
      case http::field::host:
        slot = &hr.host;
        break;
      case http::field::if_none_match:
        slot = &hr.if_none_match;
        break;
      case http::field::range:
        slot = &hr.range;
        break;
      case http::field::if_range:
        slot = &hr.if_range;
        break;
      case http::field::origin:
        slot = &hr.origin;
        break;
      case http::field::authorization:
        slot = &hr.authorization;
        break;
      case http::field::access_control_request_method:
        slot = &hr.access_control_request_method;
        break;
      case http::field::accept:
        slot = &hr.accept;
        break;
      default:
        continue;
    }
    if (slot->data() != nullptr) continue;
    const auto v = f.value();
    *slot = v.empty() ? std::string_view("", 0) : std::string_view(v.data(), v.size());
  }
}

// Why a parsed request cannot be answered, decided before routing: how it is framed (RFC 9112
// §6.3: a transfer coding other than chunked last leaves the body's length unknown) and its Host
// fields (§3.2: exactly one on HTTP/1.1, at most one before). nullptr when it can.
const char* framing_problem(const RequestParser& parser) {
  const auto& req = parser.get();
  if (req.count(http::field::transfer_encoding) > 0 && !parser.chunked())
    return "Transfer-Encoding must end with chunked; the body's length is unknown";
  const std::size_t hosts = req.count(http::field::host);
  if (hosts > 1) return "more than one Host header field";
  // Two credentials: which one applies would depend on which a proxy or we read first.
  if (req.count(http::field::authorization) > 1) return "more than one Authorization header field";
  if (hosts == 0 && req.version() >= 11) return "an HTTP/1.1 request needs a Host header field";
  return nullptr;
}

std::uint64_t next_connection_id() {
  static std::atomic<std::uint64_t> next{1};
  return next.fetch_add(1, std::memory_order_relaxed);
}

}  // namespace

Session::Session(SessionHost& server, Sweeper& sweeper, tcp::socket socket, bool admin)
    : server_(server),
      socket_(std::move(socket)),
      admin_(admin),
      sweeper_(sweeper),
      id_(next_connection_id()) {
  sweeper_.add(this);
  server_.metrics().open_connections.fetch_add(1, std::memory_order_relaxed);
  error_code ec;
  socket_.set_option(tcp::no_delay(true), ec);
  socket_.native_non_blocking(true, ec);  // write_some() sends with plain syscalls
  if (server_.access_log().enabled()) {
    const auto ep = socket_.remote_endpoint(ec);
    if (!ec) remote_ = ep.address().to_string() + ":" + std::to_string(ep.port());
  }
}

Session::~Session() {
  sweeper_.remove(this);
  server_.metrics().open_connections.fetch_sub(1, std::memory_order_relaxed);
  server_.remove_session(this);
}

void Session::start() {
  asio::dispatch(socket_.get_executor(), [self = shared_from_this()] {
    if (self->server_.stopping()) return self->close();
    self->wait_for_request();
  });
}

void Session::on_server_stop() {
  asio::post(socket_.get_executor(), [self = shared_from_this()] {
    self->read_done_ = true;
    if (!self->queue_.empty()) return;  // the writer closes after the last queued response
    // Idle: close at once — unless input is waiting (pipelined requests we will not answer),
    // where a plain close would reset the connection and could destroy the last response still
    // in the socket buffer.
    error_code ec;
    if (self->buffer_.size() == 0 && self->socket_.available(ec) == 0 && !ec)
      self->close();
    else
      self->linger_close();
  });
}

// Hard close (timeouts, errors, idle connections): pending operations complete with an error.
void Session::close() {
  abandon_.request_stop();
  closed_ = true;
  read_done_ = true;
  error_code ec;
  socket_.close(ec);
  clear_read_deadline();
  write_deadline_ = DeadlineClock::time_point::max();
}

// Close after the last response: send FIN, then read and discard whatever the client still sends
// (pipelined requests we will not answer, a refused body) until it closes or kLinger passes.
// Closing a socket with unread input makes the kernel send RST, which can destroy the response
// bytes the client has not read yet (the "lingering close" of RFC 9112 §9.6).
void Session::linger_close() {
  constexpr std::chrono::milliseconds kLinger{2000};
  if (closed_) return;
  closed_ = true;
  read_done_ = true;
  write_deadline_ = DeadlineClock::time_point::max();
  error_code ec;
  socket_.shutdown(tcp::socket::shutdown_send, ec);
  if (ec) return close();
  socket_.cancel(ec);  // a read still waiting for a request we will not serve
  set_read_deadline(kLinger);
  drain_input();
}

void Session::drain_input() {
  static thread_local char scratch[4096];
  socket_.async_read_some(asio::buffer(scratch),
                          [self = shared_from_this()](error_code ec, std::size_t) {
                            if (ec == asio::error::operation_aborted && self->socket_.is_open())
                              return;  // the cancelled earlier read; this chain continues
                            if (ec) return self->close();
                            self->drain_input();
                          });
}

// The client closed its end (or reset it): nothing more will be read. Idle, the connection
// closes; with responses still owed, nobody waits for them any more (as nginx does): the
// provider's fetches and the web encodes only this connection waited for are abandoned, and
// what is ready is still written until the socket refuses it.
void Session::client_gone() {
  read_done_ = true;
  if (queue_.empty()) return close();
  if (!abandon_.stop_requested())
    server_.metrics().abandoned_connections.fetch_add(1, std::memory_order_relaxed);
  abandon_.request_stop();
}

// Waits (idle timeout) for the first byte of the next request; the header then has its own
// deadline, so a client that trickles a header cannot hold the connection for idle_timeout.
void Session::wait_for_request() {
  if (closed_ || read_done_) return;
  if (queue_.size() >= server_.options().limits.max_pipeline) {
    read_paused_ = true;
    return read_ahead();
  }
  if (buffer_.size() > 0) return read_request();
  if (reading_) {
    // The read-ahead of a full pipeline is still outstanding: it goes on from here when bytes
    // come, and meanwhile the connection is idle.
    idle_wait_ = true;
    set_read_deadline(server_.options().limits.idle_timeout);
    return;
  }
  reading_ = true;
  idle_wait_ = true;
  set_read_deadline(server_.options().limits.idle_timeout);
  socket_.async_read_some(buffer_.prepare(4096),
                          [self = shared_from_this()](error_code ec, std::size_t n) {
                            self->reading_ = false;
                            self->idle_wait_ = false;
                            if (self->closed_) return;
                            self->clear_read_deadline();
                            if (ec || n == 0) return self->client_gone();
                            self->buffer_.commit(n);
                            if (self->server_.stopping()) {
                              // Unread input may follow: a plain close would reset the connection
                              // and could destroy responses still in the socket buffer.
                              self->read_done_ = true;
                              if (self->queue_.empty()) self->linger_close();
                              return;
                            }
                            self->read_request();
                          });
}

// While the pipeline is full, reads on without parsing, up to max_header_bytes buffered: a client
// that goes away (closes after pipelining, as a flood does) is noticed while its responses are
// still owed, and the work done only for it (provider fetches, web encodes) is abandoned, as
// nginx does. Once the pipeline has room, wait_for_request() parses what was read.
void Session::read_ahead() {
  if (reading_ || buffer_.size() >= server_.options().limits.max_header_bytes) return;
  reading_ = true;
  socket_.async_read_some(buffer_.prepare(4096),
                          [self = shared_from_this()](error_code ec, std::size_t n) {
                            self->reading_ = false;
                            if (self->closed_) return;
                            if (self->idle_wait_) {
                              self->idle_wait_ = false;
                              self->clear_read_deadline();
                            }
                            if (ec || n == 0) return self->client_gone();
                            self->buffer_.commit(n);
                            self->wait_for_request();  // still full: reads ahead again
                          });
}

// Parses the next request from what is buffered, synchronously; reads more only when the header is
// incomplete. (http::async_read would post its completion even when the whole request is already
// buffered, sending every request once around the scheduler queue: a pipelined or busy connection
// would wait behind every other ready connection for each request.)
void Session::read_request() {
  const auto& limits = server_.options().limits;
  if (!parser_) {
    parser_.emplace(std::piecewise_construct, std::make_tuple(),
                    std::make_tuple(FieldAllocator(&fields_)));
    parser_->header_limit(std::uint32_t(limits.max_header_bytes));
    parser_->body_limit(0);
    parser_->eager(true);
    set_read_deadline(limits.header_timeout);
  }
  error_code ec;
  while (buffer_.size() > 0 && !parser_->is_done()) {
    const std::size_t n = parser_->put(buffer_.data(), ec);
    buffer_.consume(n);
    if (ec || n == 0) break;
  }
  if (ec == http::error::need_more) ec = {};
  if (ec || parser_->is_done()) {
    clear_read_deadline();
    return on_read(ec);
  }
  if (buffer_.size() >= limits.max_header_bytes + 4096) {  // never: the parser stops first
    clear_read_deadline();
    return on_read(http::error::header_limit);
  }
  reading_ = true;
  socket_.async_read_some(buffer_.prepare(4096),
                          [self = shared_from_this()](error_code e, std::size_t n) {
                            self->reading_ = false;
                            if (self->closed_) return;
                            if (e || n == 0) {
                              self->clear_read_deadline();
                              return self->on_read(e ? e : http::error::end_of_stream);
                            }
                            self->buffer_.commit(n);
                            self->read_request();
                          });
}

void Session::fail_parse(int status, const char* message) {
  auto out = new_outgoing();
  out->response =
      unparsed_request_error(status, message, admin_ ? nullptr : &server_.options().router);
  out->start = Clock::now();
  out->close = true;
  read_done_ = true;
  enqueue(std::move(out));
}

// A request that could not be parsed: answered 400/413/414/431 and the connection closed, or
// (end of stream, reset, timeout) closed without an answer.
void Session::on_parse_error(error_code ec) {
  const auto& limits = server_.options().limits;
  if (ec == http::error::header_limit) {
    // A request line longer than the target limit is a long URI (414), not big headers (431).
    const auto data = buffer_.cdata();
    const std::string_view head(static_cast<const char*>(data.data()), data.size());
    const auto eol = head.find('\n');
    const std::size_t line = eol == std::string_view::npos ? head.size() : eol;
    // Beast consumes the request line once parsed; then the target is in the message.
    const auto parsed_target = parser_->get().target();
    if (parsed_target.size() > limits.max_target_bytes ||
        (parsed_target.empty() && line > limits.max_target_bytes + 16))
      return fail_parse(414, "request target too long");
    return fail_parse(431, "request header fields too large");
  }
  if (ec == http::error::body_limit) return fail_parse(413, "request body not allowed");
  read_done_ = true;
  if (ec == http::error::end_of_stream || ec == asio::error::operation_aborted ||
      ec == asio::error::connection_reset || ec == asio::error::eof || !socket_.is_open())
    return client_gone();
  fail_parse(400, "bad request");
}

// Routes a parsed request (the router checks its target) into a queued response.
std::unique_ptr<Outgoing> Session::answer(RequestParser::value_type& req) {
  auto out = new_outgoing();
  out->start = Clock::now();
  const auto target = req.target();
  HttpRequest hr;
  hr.method = to_method(req.method());
  const auto mt = req.method_string();
  hr.method_text = {mt.data(), mt.size()};
  hr.target = {target.data(), target.size()};
  hr.connection = id_;
  read_fields(req, hr);
  if (admin_) {
    out->response = server_.admin_route(hr);
  } else {
    out->response = route(hr, server_.registry(), server_.options().router, server_.provider());
    if (out->response.archive_changed) server_.request_reload(false);
  }
  if (!req.keep_alive() || server_.stopping()) out->close = true;
  // HTTP/1.0 keeps a connection open only when both sides say so.
  out->keep_alive_header = req.version() < 11 && !out->close;
  if (server_.access_log().enabled()) {
    out->method = std::string(hr.method_text);
    out->target = std::string(hr.target);
    if (out->response.hold) out->tileset = out->response.hold->name;
    if (out->response.pending && out->response.pending->provided)
      out->tileset = out->response.pending->provided->name;
  }
  return out;
}

void Session::on_read(error_code ec) {
  if (closed_) return;
  if (ec) return on_parse_error(ec);
  // Answered 400 and closed: the request's end (hence the next one's start) is unknown, or the
  // request is ambiguous about whom it addresses.
  if (const char* problem = framing_problem(*parser_)) return fail_parse(400, problem);
  auto out = answer(parser_->get());
  if (out->close) read_done_ = true;
  // Done with the request (its views end here): writing may parse the next one (see write_next).
  parser_.reset();
  fields_.release();
  enqueue(std::move(out));
  wait_for_request();
}

void Session::enqueue(std::unique_ptr<Outgoing> out) {
  out->seq = next_seq_++;
  Outgoing& o = *out;
  const bool pending = o.response.pending != nullptr;
  if (pending)
    o.ready = false;
  else
    prepare(o);
  queue_.push_back(std::move(out));
  if (pending)
    start_pending(o);  // may finish it at once (a cache hit)
  else if (!writing_ && !in_write_)
    write_next();
}

// Hands a pending answer to the answer pipeline (finish_pending). Its final response comes back
// through finish_pending_answer(): at once when the pipeline answers inside the call (a RAM hit:
// no scheduler round trip), else posted to this connection's thread from the thread that ended
// the work (the provider's, an encoder's); no thread ever blocks waiting. `state` tells the two
// apart without a lock: whoever moves it from kCalling first decides. The connection's stop
// token marks its interest: once the client has gone, a fetch or an encode only it waited for is
// abandoned.
void Session::start_pending(const Outgoing& o) {
  struct Call {
    enum : int { kCalling, kReturned, kAnsweredInside };
    std::atomic<int> state{kCalling};
    HttpResponse answer;  // written by `done` before it sets kAnsweredInside
  };
  auto call = std::make_shared<Call>();
  const std::uint64_t seq = o.seq;
  finish_pending(
      o.response, server_.provider(), abandon_.get_token(),
      [self = shared_from_this(), call, seq,
       executor = socket_.get_executor()](HttpResponse answer) mutable {
        auto keep_alive = std::move(self);  // released here or on the connection's thread
        call->answer = std::move(answer);
        int expected = Call::kCalling;
        if (call->state.compare_exchange_strong(expected, Call::kAnsweredInside,
                                                std::memory_order_acq_rel))
          return;  // start_pending() picks the answer up when finish_pending() returns
        asio::post(executor, [session = std::move(keep_alive), call = std::move(call), seq] {
          session->finish_pending_answer(seq, std::move(call->answer));
        });
      });
  int expected = Call::kCalling;
  if (!call->state.compare_exchange_strong(expected, Call::kReturned, std::memory_order_acq_rel))
    finish_pending_answer(seq, std::move(call->answer));
}

// On the connection's thread: the final answer of response `seq`. Dropped when the connection
// has closed meanwhile (its queue is gone or going).
void Session::finish_pending_answer(std::uint64_t seq, HttpResponse answer) {
  if (closed_) return;
  auto it = std::find_if(queue_.begin(), queue_.end(),
                         [seq](const std::unique_ptr<Outgoing>& o) { return o->seq == seq; });
  if (it == queue_.end() || (*it)->ready) return;
  Outgoing& o = **it;
  o.response = std::move(answer);
  o.ready = true;
  prepare(o);
  // Inside write_next() (the answer came at once, while completing a response resumed reading),
  // that loop writes it.
  if (!writing_ && !in_write_) write_next();
}

void Session::prepare(Outgoing& o) {
  prepare_response(o);
}

// Writes queued responses in order until the queue is empty or the socket is full; then waits for
// it to drain. Each response must be completely written by its deadline: `write_timeout` plus its
// size at `min_send_rate`, so a client reading a trickle cannot hold a connection for ever.
void Session::write_next() {
  // Completing a response can resume reading, which can parse and enqueue the next response:
  // that one is written by this loop, never by a nested call.
  if (in_write_) return;
  in_write_ = true;
  struct Reset {
    bool& flag;
    ~Reset() { flag = false; }
  } reset{in_write_};
  const auto& limits = server_.options().limits;
  while (!closed_ && !queue_.empty()) {
    Outgoing& o = *queue_.front();
    if (!o.ready) return;  // an answer still pending: finish_pending_answer() resumes
    if (o.deadline == DeadlineClock::time_point{}) {
      o.deadline = DeadlineClock::now() + limits.write_timeout;
      if (limits.min_send_rate > 0)
        o.deadline += std::chrono::milliseconds(o.total() * 1000 / limits.min_send_rate);
    }
    error_code ec;
    const std::size_t n = o.total() > o.sent ? write_some(socket_.native_handle(), o, ec) : 0;
    if (ec == asio::error::would_block) {
      write_deadline_ = o.deadline;
      return wait_writable();
    }
    if (ec == asio::error::interrupted) continue;
    if (ec) {
      close();
      queue_.clear();
      return;
    }
    server_.metrics().response_bytes.fetch_add(n, std::memory_order_relaxed);
    o.sent += n;
    if (o.sent < o.total()) continue;
    if (!complete_front()) return;
  }
  // Nothing more will be answered (stop, EOF, Connection: close): a read still pending is only
  // waiting for a request we will not serve.
  if (!closed_ && read_done_ && queue_.empty()) linger_close();
}

// Resumes write_next() when the socket accepts more (or closes on error).
void Session::wait_writable() {
  writing_ = true;
  socket_.async_wait(tcp::socket::wait_write, [self = shared_from_this()](error_code e) {
    self->writing_ = false;
    self->write_deadline_ = DeadlineClock::time_point::max();
    if (e || self->closed_) {
      self->close();
      self->queue_.clear();
      return;
    }
    self->write_next();
  });
}

// The front response is completely written: account for it, then either close (it asked to) or
// resume reading if the pipeline had filled. Returns false when the connection is closing.
bool Session::complete_front() {
  Outgoing& out = *queue_.front();
  const auto elapsed = Clock::now() - out.start;
  server_.metrics().record(out.response.route, out.response.status, 0, elapsed);
  if (server_.access_log().enabled()) log(out, elapsed);
  const bool close_after = out.close;
  recycle(std::move(queue_.front()));
  queue_.pop_front();
  if (close_after) {
    queue_.clear();
    linger_close();
    return false;
  }
  // Idle time counts from the last response owed (check_deadlines).
  if (idle_wait_ && queue_.empty()) set_read_deadline(server_.options().limits.idle_timeout);
  if (read_paused_ && queue_.size() < server_.options().limits.max_pipeline) {
    read_paused_ = false;
    wait_for_request();
  }
  return true;
}

void Session::log(const Outgoing& out, std::chrono::nanoseconds elapsed) {
  AccessLogEntry e;
  e.remote = remote_;
  e.method = out.method;
  e.target = out.target;
  e.route = route_name(out.response.route);
  e.tileset = out.tileset;
  e.status = out.response.status;
  e.bytes = out.response.head_only ? 0 : out.response.content_length;
  e.duration = elapsed;
  server_.access_log().write(e);
}

std::unique_ptr<Outgoing> Session::new_outgoing() {
  return spare_ ? std::move(spare_) : std::make_unique<Outgoing>();
}

void Session::recycle(std::unique_ptr<Outgoing> o) {
  std::string head = std::move(o->head);
  head.clear();
  *o = Outgoing{};  // releases what the response held (tile bytes, tileset)
  o->head = std::move(head);
  spare_ = std::move(o);
}

void Session::check_deadlines(DeadlineClock::time_point now) {
  if (!socket_.is_open()) return;
  const bool owed = idle_wait_ && !queue_.empty();
  if ((now >= read_deadline_ && !owed) || now >= write_deadline_) close();
}

}  // namespace http_detail
}  // namespace server
}  // namespace vts
