// Fetcher: one thread owns a libcurl multi handle and every piece of state below; other threads
// only post commands to the inbox and wake the multi (curl_multi_wakeup). Transfers move through
//
//   queued (in queue_) -> in flight (an easy handle in the multi) -> done
//                 ^                           |
//                 +--- waiting (in waiting_) <+  (a retryable failure: backoff, no slot held)
//
// Our queue, not libcurl's, decides what starts next, so libcurl never holds a backlog and
// priorities can change until the last moment.
#include "vts/client/fetcher.hpp"

#include <curl/curl.h>
#include <pthread.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cassert>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <map>
#include <mutex>
#include <random>
#include <system_error>
#include <thread>
#include <tuple>
#include <unordered_map>

#include "vts/base/file_io.hpp"

namespace vts::client {

namespace {

using Clock = std::chrono::steady_clock;

// libcurl's global state is set up once per process and never torn down (other code in the
// process may be using libcurl too).
Status init_curl_once() {
  static const CURLcode rc = curl_global_init(CURL_GLOBAL_DEFAULT);
  if (rc != CURLE_OK) {
    return make_error(ErrorCode::internal,
                      std::string("curl_global_init failed: ") + curl_easy_strerror(rc));
  }
  return {};
}

// "bytes first-last/total" (total may be "*"); false when malformed.
bool parse_content_range(std::string_view v, std::uint64_t& first, std::uint64_t& last) {
  v = trim(v);
  if (!istarts_with(v, "bytes ")) return false;
  v.remove_prefix(6);
  v = trim(v);
  const auto dash = v.find('-');
  const auto slash = v.find('/');
  if (dash == std::string_view::npos || slash == std::string_view::npos || slash < dash) {
    return false;
  }
  auto num = [](std::string_view s, std::uint64_t& out) {
    s = trim(s);
    auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
    return ec == std::errc() && p == s.data() + s.size() && !s.empty();
  };
  return num(v.substr(0, dash), first) && num(v.substr(dash + 1, slash - dash - 1), last) &&
         first <= last;
}

}  // namespace

class Fetcher::Impl {
 public:
  explicit Impl(FetcherOptions options)
      : options_(std::move(options)), rng_(std::random_device{}()) {}

  ~Impl() {
    stop();
    for (CURL* e : idle_) curl_easy_cleanup(e);
    if (multi_ != nullptr) curl_multi_cleanup(multi_);
  }

  // Cancels everything and joins the thread. The Impl stays fully usable meanwhile, so the
  // cancellation callbacks this runs may still call submit() and cancel().
  void stop() {
    if (!thread_.joinable()) return;
    {
      std::lock_guard lock(inbox_mutex_);
      stopping_ = true;
    }
    curl_multi_wakeup(multi_);
    thread_.join();
  }

  Status start() {
    multi_ = curl_multi_init();
    if (multi_ == nullptr) return make_error(ErrorCode::internal, "curl_multi_init failed");
    if (options_.max_host_connections > 0) {
      curl_multi_setopt(multi_, CURLMOPT_MAX_HOST_CONNECTIONS,
                        long(std::min<std::size_t>(options_.max_host_connections, 1u << 20)));
    }
    curl_multi_setopt(multi_, CURLMOPT_PIPELINING, long(CURLPIPE_MULTIPLEX));
    try {
      thread_ = std::thread([this] {
        pthread_setname_np(pthread_self(), "vts-fetch");  // profiles, `top -H`
        run();
      });
    } catch (const std::system_error& e) {
      return make_error(ErrorCode::io, std::string("cannot start fetcher thread: ") + e.what());
    }
    return {};
  }

  Handle submit(FetchRequest request, FetchCallback callback) {
    const Handle h = next_handle_.fetch_add(1, std::memory_order_relaxed);
    stats_.submitted.fetch_add(1, std::memory_order_relaxed);
    post(Command{Command::kSubmit, h, std::move(request), std::move(callback), 0, 0, Clock::now()});
    return h;
  }
  void cancel(Handle h) { post(Command{Command::kCancel, h, {}, {}, 0, 0}); }
  void reprioritize(Handle h, int level, double urgency) {
    post(Command{Command::kReprioritize, h, {}, {}, level, urgency});
  }

  Stats stats() const {
    Stats s;
    s.submitted = stats_.submitted.load();
    s.merged = stats_.merged.load();
    s.started = stats_.started.load();
    s.retried = stats_.retried.load();
    s.succeeded = stats_.succeeded.load();
    s.failed = stats_.failed.load();
    s.cancelled = stats_.cancelled.load();
    s.expired = stats_.expired.load();
    s.in_flight = stats_.in_flight.load();
    s.queued = stats_.queued.load();
    s.bytes = stats_.bytes.load();
    return s;
  }

 private:
  struct Command {
    enum Kind { kSubmit, kCancel, kReprioritize } kind;
    Handle handle;
    FetchRequest request;
    FetchCallback callback;
    int level;
    double urgency;
    Clock::time_point submitted{};
  };

  struct Waiter {
    Handle handle;
    FetchCallback callback;
    int level;
    double urgency;
    Clock::time_point submitted{};
  };

  enum class State { queued, waiting, in_flight };

  // Ordering key of the queue: (level, -urgency, seq). seq is fixed at creation, so a transfer
  // that comes back from a retry keeps its place among its peers.
  using QueueKey = std::tuple<int, double, std::uint64_t>;

  struct Transfer {
    Impl* owner = nullptr;
    std::string key;
    std::string url;
    std::optional<std::pair<std::uint64_t, std::uint64_t>> range;
    bool whole_if_range_ignored = false;
    std::uint64_t max_body = 0;  // this transfer's body limit
    std::string if_none_match;
    std::string group;
    std::vector<Waiter> waiters;
    int level = 0;
    double urgency = 0;
    std::uint64_t seq = 0;
    State state = State::queued;
    Clock::time_point due;
    Clock::time_point deadline = Clock::time_point::max();  // max: none
    int attempts = 0;
    // Timing: the first attempt's and the current attempt's start, and the current attempt's
    // first response byte (from libcurl's STARTTRANSFER time; unset when none arrived).
    Clock::time_point first_start{}, attempt_start{};
    std::optional<Clock::time_point> first_byte;
    curl_slist* headers = nullptr;
    CURL* easy = nullptr;
    // The current attempt's response.
    std::vector<std::uint8_t> body;
    std::string etag;
    std::string vts_error;
    std::string content_range;
    std::string cache_control;
    std::int64_t content_length = -1;  // the current response's Content-Length header
    bool too_large = false;
    bool sized = false;  // body capacity reserved from Content-Length
    char errbuf[CURL_ERROR_SIZE] = {};

    ~Transfer() { curl_slist_free_all(headers); }
    QueueKey queue_key() const { return {level, -urgency, seq}; }
  };

  struct Counters {
    std::atomic<std::uint64_t> submitted{0}, merged{0}, started{0}, retried{0}, succeeded{0},
        failed{0}, cancelled{0}, expired{0}, in_flight{0}, queued{0}, bytes{0};
  };

  void post(Command c) {
    {
      std::lock_guard lock(inbox_mutex_);
      inbox_.push_back(std::move(c));
    }
    curl_multi_wakeup(multi_);
  }

  // ---- the fetcher thread ------------------------------------------------------------------

  void run() {
    for (;;) {
      std::vector<Command> commands;
      bool stop = false;
      {
        std::lock_guard lock(inbox_mutex_);
        commands.swap(inbox_);
        stop = stopping_;
      }
      if (stop) {
        // Commands posted before the destructor are cancelled by shutdown() like the rest.
        std::lock_guard lock(inbox_mutex_);
        inbox_.insert(inbox_.begin(), std::make_move_iterator(commands.begin()),
                      std::make_move_iterator(commands.end()));
        break;
      }
      for (Command& c : commands) apply(c);
      expire(Clock::now());
      promote_due(Clock::now());
      start_queued();
      int running = 0;
      curl_multi_perform(multi_, &running);
      const bool progressed = collect_done();
      if (progressed) start_queued();
      publish_gauges();
      curl_multi_poll(multi_, nullptr, 0, progressed ? 0 : poll_timeout_ms(), nullptr);
    }
    shutdown();
  }

  void apply(Command& c) {
    // A NaN would break the queue's ordering; it means "no particular urgency".
    if (std::isnan(c.request.urgency)) c.request.urgency = 0;
    if (std::isnan(c.urgency)) c.urgency = 0;
    switch (c.kind) {
      case Command::kSubmit:
        add(c.handle, std::move(c.request), std::move(c.callback), c.submitted);
        break;
      case Command::kCancel:
        cancel_handle(c.handle);
        break;
      case Command::kReprioritize:
        set_priority(c.handle, c.level, c.urgency);
        break;
    }
  }

  void add(Handle h, FetchRequest req, FetchCallback cb, Clock::time_point submitted) {
    std::string key = req.merge_key;
    if (key.empty()) {
      key = req.url;
      key += '\n';
      if (req.range)
        key += std::to_string(req.range->first) + "-" + std::to_string(req.range->second);
      key += '\n';
      key += req.if_none_match;
      if (req.whole_if_range_ignored) key += "\nwhole";
    }
    if (auto it = by_key_.find(key); it != by_key_.end()) {
      Transfer* t = it->second.get();
      stats_.merged.fetch_add(1, std::memory_order_relaxed);
      t->waiters.push_back(Waiter{h, std::move(cb), req.level, req.urgency, submitted});
      by_handle_.emplace(h, t);
      update_priority(t);
      return;
    }
    auto owned = std::make_unique<Transfer>();
    Transfer* t = owned.get();
    t->owner = this;
    t->key = key;
    t->url = std::move(req.url);
    t->range = req.range;
    t->whole_if_range_ignored = req.whole_if_range_ignored;
    t->max_body = req.max_body_bytes != 0 ? req.max_body_bytes : options_.max_body_bytes;
    t->if_none_match = std::move(req.if_none_match);
    t->group = std::move(req.group);
    t->waiters.push_back(Waiter{h, std::move(cb), req.level, req.urgency, submitted});
    t->level = req.level;
    t->urgency = req.urgency;
    t->seq = next_seq_++;
    by_key_.emplace(key, std::move(owned));
    by_handle_.emplace(h, t);

    if (t->range && t->range->first > t->range->second) {
      finish_error(
          t, make_error(ErrorCode::invalid_argument, "GET " + t->url + ": empty range " +
                                                         std::to_string(t->range->first) + "-" +
                                                         std::to_string(t->range->second)));
      return;
    }
    for (const std::string& header : options_.headers) {
      t->headers = curl_slist_append(t->headers, header.c_str());
    }
    if (!t->if_none_match.empty()) {
      t->headers = curl_slist_append(t->headers, ("If-None-Match: " + t->if_none_match).c_str());
    }
    t->state = State::queued;
    queue_.emplace(t->queue_key(), t);
    if (options_.deadline.count() > 0) {
      t->deadline = submitted + options_.deadline;
      by_deadline_.emplace(std::make_pair(t->deadline, t->seq), t);
    }
  }

  // A merged transfer runs at the most urgent priority of its handles.
  void update_priority(Transfer* t) {
    assert(!t->waiters.empty());
    int level = t->waiters.front().level;
    double urgency = t->waiters.front().urgency;
    for (const Waiter& w : t->waiters) {
      if (w.level < level || (w.level == level && w.urgency > urgency)) {
        level = w.level;
        urgency = w.urgency;
      }
    }
    if (level == t->level && urgency == t->urgency) return;
    if (t->state == State::queued) {
      queue_.erase(t->queue_key());
      t->level = level;
      t->urgency = urgency;
      queue_.emplace(t->queue_key(), t);
    } else {
      t->level = level;
      t->urgency = urgency;
    }
  }

  void set_priority(Handle h, int level, double urgency) {
    auto it = by_handle_.find(h);
    if (it == by_handle_.end()) return;
    Transfer* t = it->second;
    for (Waiter& w : t->waiters) {
      if (w.handle == h) {
        w.level = level;
        w.urgency = urgency;
      }
    }
    update_priority(t);
  }

  void cancel_handle(Handle h) {
    auto it = by_handle_.find(h);
    if (it == by_handle_.end()) return;  // unknown, or its callback already ran
    Transfer* t = it->second;
    by_handle_.erase(it);
    auto w = std::find_if(t->waiters.begin(), t->waiters.end(),
                          [&](const Waiter& x) { return x.handle == h; });
    assert(w != t->waiters.end());
    FetchCallback cb = std::move(w->callback);
    t->waiters.erase(w);
    const int attempts = t->attempts;
    const std::string url = t->url;
    if (t->waiters.empty()) {
      drop(t);
    } else {
      update_priority(t);
    }
    deliver_cancelled(cb, url, attempts);
  }

  void deliver_cancelled(FetchCallback& cb, const std::string& url, int attempts) {
    FetchResult r;
    r.cancelled = true;
    r.attempts = attempts;
    r.error = make_error(ErrorCode::cancelled, "GET " + url + ": cancelled");
    stats_.cancelled.fetch_add(1, std::memory_order_relaxed);
    publish_gauges();
    if (cb) cb(std::move(r));
  }

  // Removes a transfer that no handle waits for any more, aborting its attempt if one runs.
  void drop(Transfer* t) {
    assert(t->waiters.empty());
    switch (t->state) {
      case State::queued:
        queue_.erase(t->queue_key());
        break;
      case State::waiting:
        waiting_.erase({t->due, t->seq});
        break;
      case State::in_flight:
        release_easy(t);
        break;
    }
    forget_deadline(t);
    const std::string key = std::move(t->key);
    by_key_.erase(key);  // destroys t
  }

  void release_easy(Transfer* t) {
    if (t->easy == nullptr) return;
    curl_multi_remove_handle(multi_, t->easy);
    idle_.push_back(t->easy);
    t->easy = nullptr;
    --in_flight_;
    if (!t->group.empty())
      if (auto g = group_in_flight_.find(t->group); g != group_in_flight_.end() && --g->second == 0)
        group_in_flight_.erase(g);
  }

  void forget_deadline(Transfer* t) {
    if (t->deadline != Clock::time_point::max()) by_deadline_.erase({t->deadline, t->seq});
  }

  // Fails every transfer whose deadline has passed, aborting its attempt in flight.
  void expire(Clock::time_point now) {
    while (!by_deadline_.empty() && by_deadline_.begin()->first.first <= now) {
      Transfer* t = by_deadline_.begin()->second;
      release_easy(t);
      stats_.expired.fetch_add(1, std::memory_order_relaxed);
      finish_error(t, make_error(ErrorCode::io,
                                 describe(t,
                                          "no answer within the deadline of " +
                                              std::to_string(options_.deadline.count()) + " ms",
                                          false)));
    }
  }

  bool group_full(const Transfer* t) const {
    if (options_.max_in_flight_per_group == 0 || t->group.empty()) return false;
    const auto g = group_in_flight_.find(t->group);
    return g != group_in_flight_.end() && g->second >= options_.max_in_flight_per_group;
  }

  void promote_due(Clock::time_point now) {
    while (!waiting_.empty() && waiting_.begin()->first.first <= now) {
      Transfer* t = waiting_.begin()->second;
      waiting_.erase(waiting_.begin());
      t->state = State::queued;
      queue_.emplace(t->queue_key(), t);
    }
  }

  // In queue order, skipping transfers whose group is at its cap.
  void start_queued() {
    for (auto it = queue_.begin(); in_flight_ < options_.max_in_flight && it != queue_.end();) {
      Transfer* t = it->second;
      if (group_full(t)) {
        ++it;
        continue;
      }
      it = queue_.erase(it);
      start_attempt(t);
    }
  }

  static std::size_t on_body(char* data, std::size_t size, std::size_t n, void* user) {
    auto* t = static_cast<Transfer*>(user);
    const std::size_t bytes = size * n;
    const std::uint64_t limit = t->max_body;
    if (!t->sized) {
      t->sized = true;
      curl_off_t length = -1;
      if (curl_easy_getinfo(t->easy, CURLINFO_CONTENT_LENGTH_DOWNLOAD_T, &length) == CURLE_OK &&
          length > 0 && std::uint64_t(length) <= limit) {
        t->body.reserve(std::size_t(length));
      }
    }
    if (t->body.size() + bytes > limit) {
      t->too_large = true;
      return 0;  // aborts the transfer with CURLE_WRITE_ERROR
    }
    // As bytes: inserting the char range into a vector of uint8_t converts byte by byte (a
    // one-byte loop, 5-11% of `vts warm`'s CPU); the same type copies with memmove.
    const auto* first = reinterpret_cast<const std::uint8_t*>(data);
    t->body.insert(t->body.end(), first, first + bytes);
    t->owner->stats_.bytes.fetch_add(bytes, std::memory_order_relaxed);
    return bytes;
  }

  static std::size_t on_header(char* data, std::size_t size, std::size_t n, void* user) {
    auto* t = static_cast<Transfer*>(user);
    const std::string_view line(data, size * n);
    if (istarts_with(line, "http/")) {
      // A new response (after a redirect or a 100 Continue): forget the previous one's headers.
      t->etag.clear();
      t->vts_error.clear();
      t->content_range.clear();
      t->cache_control.clear();
      t->content_length = -1;
    } else if (istarts_with(line, "content-length:")) {
      const std::string_view v = trim(line.substr(15));
      std::int64_t length = 0;
      const auto [end, ec] = std::from_chars(v.data(), v.data() + v.size(), length);
      t->content_length =
          ec == std::errc() && end == v.data() + v.size() && length >= 0 ? length : -1;
    } else if (istarts_with(line, "etag:")) {
      t->etag = std::string(trim(line.substr(5)));
    } else if (istarts_with(line, "vts-error:")) {
      t->vts_error = std::string(trim(line.substr(10)));
    } else if (istarts_with(line, "content-range:")) {
      t->content_range = std::string(trim(line.substr(14)));
    } else if (istarts_with(line, "cache-control:")) {
      if (!t->cache_control.empty()) t->cache_control += ", ";
      t->cache_control += std::string(trim(line.substr(14)));
    }
    return size * n;
  }

  void start_attempt(Transfer* t) {
    CURL* e = nullptr;
    if (!idle_.empty()) {
      e = idle_.back();
      idle_.pop_back();
      curl_easy_reset(e);  // keeps the easy handle's caches; connections live in the multi
    } else {
      e = curl_easy_init();
    }
    ++t->attempts;
    t->attempt_start = Clock::now();
    if (t->attempts == 1) t->first_start = t->attempt_start;
    t->first_byte.reset();
    stats_.started.fetch_add(1, std::memory_order_relaxed);
    if (t->attempts > 1) stats_.retried.fetch_add(1, std::memory_order_relaxed);
    if (e == nullptr) {
      finish_error(t, make_error(ErrorCode::internal, "GET " + t->url + ": curl_easy_init failed"));
      return;
    }
    t->body.clear();
    t->etag.clear();
    t->vts_error.clear();
    t->content_range.clear();
    t->cache_control.clear();
    t->content_length = -1;
    t->too_large = false;
    t->sized = false;
    t->errbuf[0] = '\0';

    const FetcherOptions& o = options_;
    curl_easy_setopt(e, CURLOPT_URL, t->url.c_str());
    curl_easy_setopt(e, CURLOPT_PRIVATE, t);
    curl_easy_setopt(e, CURLOPT_ERRORBUFFER, t->errbuf);
    curl_easy_setopt(e, CURLOPT_NOSIGNAL, 1L);
    curl_easy_setopt(e, CURLOPT_PROTOCOLS_STR, "http,https");
    curl_easy_setopt(e, CURLOPT_REDIR_PROTOCOLS_STR, "http,https");
    curl_easy_setopt(e, CURLOPT_FOLLOWLOCATION, 1L);
    curl_easy_setopt(e, CURLOPT_MAXREDIRS, 5L);
    curl_easy_setopt(e, CURLOPT_HTTP_VERSION, long(CURL_HTTP_VERSION_2TLS));
    if (!o.ca_file.empty()) curl_easy_setopt(e, CURLOPT_CAINFO, o.ca_file.c_str());
    // Prefer multiplexing on an HTTP/2 connection to opening another one. Only over TLS: that is
    // where HTTP/2 is negotiated (ALPN, known right after the handshake). Over plain http:// the
    // answer would only come with the first response, so one stalled request would hold back
    // every other request to its host.
    if (istarts_with(t->url, "https://")) curl_easy_setopt(e, CURLOPT_PIPEWAIT, 1L);
    // Tiles are already compressed: no Accept-Encoding, and no decoding of the stored bytes.
    curl_easy_setopt(e, CURLOPT_ACCEPT_ENCODING, static_cast<char*>(nullptr));
    curl_easy_setopt(e, CURLOPT_HTTP_CONTENT_DECODING, 0L);
    curl_easy_setopt(e, CURLOPT_CONNECTTIMEOUT_MS, long(o.connect_timeout.count()));
    curl_easy_setopt(e, CURLOPT_TIMEOUT_MS, long(o.request_timeout.count()));
    if (o.low_speed_bytes > 0 && o.low_speed_time.count() > 0) {
      curl_easy_setopt(e, CURLOPT_LOW_SPEED_LIMIT, o.low_speed_bytes);
      curl_easy_setopt(e, CURLOPT_LOW_SPEED_TIME, long(o.low_speed_time.count()));
    }
    curl_easy_setopt(e, CURLOPT_MAXFILESIZE_LARGE, curl_off_t(t->max_body));
    curl_easy_setopt(e, CURLOPT_USERAGENT, o.user_agent.c_str());
    if (t->headers != nullptr) curl_easy_setopt(e, CURLOPT_HTTPHEADER, t->headers);
    std::string range;
    if (t->range) {
      range = std::to_string(t->range->first) + "-" + std::to_string(t->range->second);
      curl_easy_setopt(e, CURLOPT_RANGE, range.c_str());  // libcurl copies the string
    }
    curl_easy_setopt(e, CURLOPT_WRITEFUNCTION, &Impl::on_body);
    curl_easy_setopt(e, CURLOPT_WRITEDATA, t);
    curl_easy_setopt(e, CURLOPT_HEADERFUNCTION, &Impl::on_header);
    curl_easy_setopt(e, CURLOPT_HEADERDATA, t);

    t->easy = e;  // on_body() reads it
    const CURLMcode mc = curl_multi_add_handle(multi_, e);
    if (mc != CURLM_OK) {
      t->easy = nullptr;
      idle_.push_back(e);
      finish_error(
          t, make_error(ErrorCode::internal,
                        "GET " + t->url + ": curl_multi_add_handle: " + curl_multi_strerror(mc)));
      return;
    }
    t->state = State::in_flight;
    ++in_flight_;
    if (!t->group.empty()) ++group_in_flight_[t->group];
  }

  // Returns true when at least one attempt ended.
  bool collect_done() {
    bool any = false;
    int left = 0;
    while (CURLMsg* msg = curl_multi_info_read(multi_, &left)) {
      if (msg->msg != CURLMSG_DONE) continue;
      CURL* e = msg->easy_handle;
      const CURLcode rc = msg->data.result;  // msg is invalid once the handle is removed
      char* priv = nullptr;
      curl_easy_getinfo(e, CURLINFO_PRIVATE, &priv);
      auto* t = reinterpret_cast<Transfer*>(priv);
      long status = 0;
      curl_easy_getinfo(e, CURLINFO_RESPONSE_CODE, &status);
      curl_off_t retry_after = 0;
      curl_easy_getinfo(e, CURLINFO_RETRY_AFTER, &retry_after);
      long os_errno = 0;
      curl_easy_getinfo(e, CURLINFO_OS_ERRNO, &os_errno);
      curl_off_t first_byte_us = 0;
      if (curl_easy_getinfo(e, CURLINFO_STARTTRANSFER_TIME_T, &first_byte_us) == CURLE_OK &&
          first_byte_us > 0)
        t->first_byte = t->attempt_start + std::chrono::microseconds(first_byte_us);
      release_easy(t);
      attempt_done(t, rc, int(status), std::int64_t(retry_after), int(os_errno));
      any = true;
    }
    return any;
  }

  std::string describe(const Transfer* t, const std::string& reason, bool with_detail) const {
    std::string m = "GET " + t->url + ": " + reason;
    if (t->attempts > 1) m += " after " + std::to_string(t->attempts) + " attempts";
    if (with_detail && t->errbuf[0] != '\0') m += std::string(" (") + t->errbuf + ")";
    return m;
  }

  void attempt_done(Transfer* t, CURLcode rc, int status, std::int64_t retry_after, int os_errno) {
    std::string reason;  // non-empty: this attempt failed in a way worth retrying
    ErrorCode code = ErrorCode::io;
    std::chrono::milliseconds min_delay{0};

    if (rc == CURLE_OK) {
      if (status == 429 || status >= 500) {
        reason = "HTTP " + std::to_string(status);
        if ((status == 429 || status == 503) && retry_after > 0) {
          if (retry_after > max_retry_after_s()) {
            FetchResult r = take_response(t, status);
            r.error =
                make_error(ErrorCode::io,
                           describe(t,
                                    reason + " with Retry-After " + std::to_string(retry_after) +
                                        " s, longer than the limit of " +
                                        std::to_string(max_retry_after_s()) + " s",
                                    false));
            finish(t, std::move(r));
            return;
          }
          min_delay = std::chrono::seconds(retry_after);
        }
      } else if (t->range && status == 206) {
        if (!range_answer_matches(t)) {
          reason = "206 answer (" + std::to_string(t->body.size()) + " bytes, Content-Range '" +
                   t->content_range + "') does not match the range " +
                   std::to_string(t->range->first) + "-" + std::to_string(t->range->second);
          code = ErrorCode::truncated;
        }
      } else if (t->range && status == 200) {
        // The server ignored Range and sent the whole resource: keep the requested slice, or
        // all of it when asked to.
        if (t->whole_if_range_ignored) {
          FetchResult r = take_response(t, status);
          r.range_ignored = true;
          finish(t, std::move(r));
          return;
        }
        const std::uint64_t first = t->range->first;
        if (first >= t->body.size()) {
          FetchResult r = take_response(t, status);
          r.body.clear();
          r.error = make_error(
              ErrorCode::invalid_argument,
              describe(t,
                       "range starts at " + std::to_string(first) + ", beyond the end of the " +
                           std::to_string(t->body.size()) + "-byte resource",
                       false));
          finish(t, std::move(r));
          return;
        }
        const std::uint64_t end = std::min<std::uint64_t>(t->range->second + 1, t->body.size());
        t->body.erase(t->body.begin() + std::ptrdiff_t(end), t->body.end());
        t->body.erase(t->body.begin(), t->body.begin() + std::ptrdiff_t(first));
      }
      if (reason.empty()) {
        finish(t, take_response(t, status));
        return;
      }
    } else {
      switch (rc) {
        case CURLE_OPERATION_TIMEDOUT:
          reason = "timed out";
          break;
        case CURLE_COULDNT_CONNECT:
          reason = os_errno == ECONNREFUSED ? "connection refused" : "could not connect";
          break;
        case CURLE_GOT_NOTHING:
          reason = "empty reply";
          break;
        case CURLE_PARTIAL_FILE:
          reason = "partial body";
          code = ErrorCode::truncated;
          break;
        case CURLE_RECV_ERROR:
          reason = os_errno == ECONNRESET ? "connection reset" : "receive error";
          break;
        case CURLE_SEND_ERROR:
          reason = "send error";
          break;
        case CURLE_HTTP2:
        case CURLE_HTTP2_STREAM:
          reason = "HTTP/2 error";
          break;
        case CURLE_WRITE_ERROR:
        case CURLE_FILESIZE_EXCEEDED:
          if (t->too_large || rc == CURLE_FILESIZE_EXCEEDED) {
            FetchResult r;
            r.status = status;
            r.attempts = t->attempts;
            r.content_length = t->content_length;
            r.error = make_error(ErrorCode::too_large, "GET " + t->url + ": body larger than " +
                                                           std::to_string(t->max_body) + " bytes");
            finish(t, std::move(r));
            return;
          }
          [[fallthrough]];
        default: {
          FetchResult r;
          r.status = status;
          r.attempts = t->attempts;
          const bool bad_url = rc == CURLE_URL_MALFORMAT || rc == CURLE_UNSUPPORTED_PROTOCOL;
          // The server's certificate or the handshake: not retried, said as TLS.
          const bool tls = rc == CURLE_PEER_FAILED_VERIFICATION || rc == CURLE_SSL_CONNECT_ERROR ||
                           rc == CURLE_SSL_CERTPROBLEM || rc == CURLE_SSL_CACERT_BADFILE ||
                           rc == CURLE_SSL_ISSUER_ERROR || rc == CURLE_SSL_PINNEDPUBKEYNOTMATCH;
          const std::string what = bad_url ? "bad URL"
                                   : tls   ? std::string("TLS: ") + curl_easy_strerror(rc)
                                           : curl_easy_strerror(rc);
          r.error = make_error(bad_url ? ErrorCode::invalid_argument : ErrorCode::io,
                               describe(t, what, true));
          finish(t, std::move(r));
          return;
        }
      }
    }

    // A retryable failure.
    if (t->attempts < options_.max_attempts) {
      schedule_retry(t, min_delay);
      return;
    }
    FetchResult r = take_response(t, rc == CURLE_OK ? status : 0);
    r.error = make_error(code, describe(t, reason, rc != CURLE_OK));
    finish(t, std::move(r));
  }

  std::int64_t max_retry_after_s() const { return options_.max_retry_after.count(); }

  bool range_answer_matches(const Transfer* t) const {
    const auto [first, last] = *t->range;
    const std::uint64_t size = t->body.size();
    std::uint64_t cr_first = 0, cr_last = 0;
    const bool has_cr = parse_content_range(t->content_range, cr_first, cr_last);
    if (has_cr && cr_first != first) return false;
    if (size == last - first + 1) return !has_cr || cr_last == last;
    // Shorter is fine only when the resource ends inside the range: "bytes first-e/total" with
    // e == total - 1 (we accept the unknown-total form "*" at face value).
    if (!has_cr || cr_last >= last || size != cr_last - cr_first + 1) return false;
    const std::string_view cr = t->content_range;
    const auto slash = cr.find('/');
    const std::string_view total = trim(cr.substr(slash + 1));
    if (total == "*") return true;
    std::uint64_t n = 0;
    auto [p, ec] = std::from_chars(total.data(), total.data() + total.size(), n);
    return ec == std::errc() && p == total.data() + total.size() && n == cr_last + 1;
  }

  void schedule_retry(Transfer* t, std::chrono::milliseconds min_delay) {
    // Full jitter: uniform in [0, min(max, base * 2^(attempts-1))].
    const int shift = std::min(t->attempts - 1, 30);
    const auto cap = std::min<std::int64_t>(options_.backoff_max.count(),
                                            options_.backoff_base.count() << shift);
    std::uniform_int_distribution<std::int64_t> dist(0, std::max<std::int64_t>(cap, 0));
    const std::chrono::milliseconds delay =
        std::max(std::chrono::milliseconds(dist(rng_)), min_delay);
    t->state = State::waiting;
    t->due = Clock::now() + delay;
    t->body.clear();
    t->body.shrink_to_fit();
    waiting_.emplace(std::make_pair(t->due, t->seq), t);
  }

  FetchResult take_response(Transfer* t, int status) {
    FetchResult r;
    r.status = status;
    r.content_length = t->content_length;
    r.body = std::move(t->body);
    r.etag = std::move(t->etag);
    r.vts_error = std::move(t->vts_error);
    r.cache_control = std::move(t->cache_control);
    r.attempts = t->attempts;
    return r;
  }

  void finish_error(Transfer* t, Error error) {
    FetchResult r;
    r.attempts = t->attempts;
    r.error = std::move(error);
    finish(t, std::move(r));
  }

  // Removes the transfer and runs every waiter's callback (copies for all but the last).
  void finish(Transfer* t, FetchResult result) {
    assert(t->easy == nullptr);
    if (t->state == State::queued) queue_.erase(t->queue_key());
    if (t->state == State::waiting) waiting_.erase({t->due, t->seq});
    forget_deadline(t);
    std::vector<Waiter> waiters = std::move(t->waiters);
    for (const Waiter& w : waiters) by_handle_.erase(w.handle);
    const bool t_started = t->attempts > 0;
    const Clock::time_point first_start = t->first_start;
    const std::optional<Clock::time_point> first_byte = t->first_byte;
    const std::string key = std::move(t->key);
    by_key_.erase(key);  // destroys t
    auto& counter = result.error ? stats_.failed : stats_.succeeded;
    counter.fetch_add(waiters.size(), std::memory_order_relaxed);
    publish_gauges();
    const Clock::time_point now = Clock::now();
    const auto since = [](Clock::time_point from, Clock::time_point to) {
      return std::max(std::chrono::nanoseconds(0), std::chrono::nanoseconds(to - from));
    };
    for (std::size_t i = 0; i < waiters.size(); ++i) {
      if (!waiters[i].callback) continue;
      const Clock::time_point sub = waiters[i].submitted;
      result.timing.queued = t_started ? since(sub, first_start) : since(sub, now);
      result.timing.first_byte = first_byte ? since(sub, *first_byte) : std::chrono::nanoseconds(0);
      result.timing.total = since(sub, now);
      if (i + 1 == waiters.size()) {
        waiters[i].callback(std::move(result));
      } else {
        FetchResult copy = result;
        waiters[i].callback(std::move(copy));
      }
    }
  }

  int poll_timeout_ms() const {
    Clock::time_point next = Clock::time_point::max();
    if (!waiting_.empty()) next = waiting_.begin()->first.first;
    if (!by_deadline_.empty()) next = std::min(next, by_deadline_.begin()->first.first);
    if (next == Clock::time_point::max()) return 1000;
    const auto until = next - Clock::now();
    const auto ms = std::chrono::ceil<std::chrono::milliseconds>(until).count();
    return int(std::clamp<std::int64_t>(ms, 0, 1000));
  }

  void publish_gauges() {
    stats_.in_flight.store(in_flight_, std::memory_order_relaxed);
    stats_.queued.store(queue_.size() + waiting_.size(), std::memory_order_relaxed);
  }

  // Cancels every transfer and every command still in the inbox, including those posted by the
  // callbacks this runs.
  void shutdown() {
    while (!by_key_.empty()) {
      Transfer* t = by_key_.begin()->second.get();
      std::vector<Waiter> waiters = std::move(t->waiters);
      const std::string url = t->url;
      const int attempts = t->attempts;
      for (const Waiter& w : waiters) by_handle_.erase(w.handle);
      t->waiters.clear();
      drop(t);
      for (Waiter& w : waiters) deliver_cancelled(w.callback, url, attempts);
    }
    for (;;) {
      std::vector<Command> commands;
      {
        std::lock_guard lock(inbox_mutex_);
        commands.swap(inbox_);
      }
      if (commands.empty()) break;
      for (Command& c : commands) {
        if (c.kind == Command::kSubmit) deliver_cancelled(c.callback, c.request.url, 0);
      }
    }
    publish_gauges();
  }

  const FetcherOptions options_;
  CURLM* multi_ = nullptr;
  std::thread thread_;

  std::mutex inbox_mutex_;
  std::vector<Command> inbox_;  // guarded by inbox_mutex_
  bool stopping_ = false;       // guarded by inbox_mutex_

  std::atomic<Handle> next_handle_{1};
  Counters stats_;

  // Owned by the fetcher thread.
  std::unordered_map<std::string, std::unique_ptr<Transfer>> by_key_;
  std::unordered_map<Handle, Transfer*> by_handle_;
  std::map<QueueKey, Transfer*> queue_;
  std::map<std::pair<Clock::time_point, std::uint64_t>, Transfer*> waiting_;
  std::map<std::pair<Clock::time_point, std::uint64_t>, Transfer*> by_deadline_;
  std::unordered_map<std::string, std::size_t> group_in_flight_;  // groups with transfers in flight
  std::vector<CURL*> idle_;
  std::size_t in_flight_ = 0;
  std::uint64_t next_seq_ = 0;
  std::mt19937_64 rng_;
};

Result<std::unique_ptr<Fetcher>> Fetcher::create(FetcherOptions options) {
  if (options.max_in_flight == 0) {
    return make_error(ErrorCode::invalid_argument, "fetcher: max_in_flight must be at least 1");
  }
  if (options.max_attempts < 1) {
    return make_error(ErrorCode::invalid_argument, "fetcher: max_attempts must be at least 1");
  }
  if (!options.ca_file.empty() && ::access(options.ca_file.c_str(), R_OK) != 0) {
    return make_error(ErrorCode::not_found,
                      "CA certificate file " + options.ca_file + " cannot be read");
  }
  if (Status st = init_curl_once(); !st.ok()) return st.error();
  auto impl = std::make_unique<Impl>(std::move(options));
  if (Status st = impl->start(); !st.ok()) return st.error();
  return std::unique_ptr<Fetcher>(new Fetcher(std::move(impl)));
}

Fetcher::Fetcher(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Fetcher::~Fetcher() {
  impl_->stop();
}

Fetcher::Handle Fetcher::submit(FetchRequest request, FetchCallback callback) {
  return impl_->submit(std::move(request), std::move(callback));
}
void Fetcher::cancel(Handle h) {
  impl_->cancel(h);
}
void Fetcher::reprioritize(Handle h, int level, double urgency) {
  impl_->reprioritize(h, level, urgency);
}
Fetcher::Stats Fetcher::stats() const {
  return impl_->stats();
}

}  // namespace vts::client
