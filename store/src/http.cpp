#include "http.hpp"

#include <curl/curl.h>

#include <algorithm>
#include <charconv>
#include <cstring>
#include <mutex>
#include <thread>

#include "s3_xml.hpp"
#include "vts/base/file_io.hpp"

namespace vts::store::detail {
namespace {

// SHA-256 of an empty body: what curl 7.88's SigV4 signer hashes for a GET or HEAD, sent as S3's
// x-amz-content-sha256 (S3 requires the header; curl < 8.x does not add it). UNSIGNED-PAYLOAD
// would not match the hash curl signs.
constexpr const char* kEmptyBodySha256 =
    "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855";
constexpr std::size_t kMaxErrorBody = 64 * 1024;
constexpr std::size_t kMaxIdleHandles = 32;

// Easy handles kept between requests: each keeps its connections alive, so a pooled handle
// reuses the connection its last request opened. curl_global_init runs once, before the first.
class HandlePool {
 public:
  HandlePool() { curl_global_init(CURL_GLOBAL_DEFAULT); }
  ~HandlePool() {
    for (CURL* h : idle_) curl_easy_cleanup(h);
  }
  HandlePool(const HandlePool&) = delete;
  HandlePool& operator=(const HandlePool&) = delete;

  CURL* take() {
    {
      std::lock_guard lock(mutex_);
      if (!idle_.empty()) {
        CURL* h = idle_.back();
        idle_.pop_back();
        curl_easy_reset(h);  // keeps the live connections and the DNS cache
        return h;
      }
    }
    return curl_easy_init();
  }
  void give(CURL* h) {
    std::lock_guard lock(mutex_);
    if (idle_.size() < kMaxIdleHandles) {
      idle_.push_back(h);
      return;
    }
    curl_easy_cleanup(h);
  }

 private:
  std::mutex mutex_;
  std::vector<CURL*> idle_;
};

HandlePool& handle_pool() {
  static HandlePool pool;
  return pool;
}

class HandleLease {
 public:
  HandleLease() : h_(handle_pool().take()) {}
  ~HandleLease() {
    if (h_ != nullptr) handle_pool().give(h_);
  }
  HandleLease(const HandleLease&) = delete;
  HandleLease& operator=(const HandleLease&) = delete;
  CURL* get() const { return h_; }

 private:
  CURL* h_;
};

struct CurlList {
  curl_slist* list = nullptr;
  ~CurlList() { curl_slist_free_all(list); }
  void add(const std::string& s) { list = curl_slist_append(list, s.c_str()); }
};

// One transfer's state, seen by the callbacks.
struct Transfer {
  const HttpRequest* request;
  HttpResponse response;
  std::size_t room() const { return request->use_into ? request->into.size() : request->max_body; }
  bool success() const { return response.status >= 200 && response.status < 300; }
};

std::optional<std::uint64_t> to_u64(std::string_view s) {
  std::uint64_t v = 0;
  const auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc{} || p != s.data() + s.size() || s.empty()) return std::nullopt;
  return v;
}

std::size_t on_header(char* data, std::size_t size, std::size_t n, void* user) {
  auto* t = static_cast<Transfer*>(user);
  const std::string_view line(data, size * n);
  if (line.starts_with("HTTP/")) {  // a new answer (after a redirect or a 100): start over
    t->response = HttpResponse{};
    const std::size_t sp = line.find(' ');
    if (sp != std::string_view::npos) {
      t->response.status = static_cast<long>(to_u64(line.substr(sp + 1, 3)).value_or(0));
    }
    return size * n;
  }
  const std::size_t colon = line.find(':');
  if (colon == std::string_view::npos) return size * n;
  const std::string_view name = trim(line.substr(0, colon));
  const std::string_view value = trim(line.substr(colon + 1));
  if (iequals(name, "etag")) t->response.etag = std::string(value);
  if (iequals(name, "last-modified")) t->response.last_modified = std::string(value);
  if (iequals(name, "content-range")) t->response.content_range = std::string(value);
  if (iequals(name, "content-length")) {
    t->response.content_length = to_u64(value);
    // A declared body that cannot fit stops the transfer before it is read (a 200 from a server
    // that ignores Range, an object over get_object()'s limit).
    if (t->success() && !t->request->head && t->response.content_length &&
        *t->response.content_length > t->room()) {
      t->response.overflow = true;
      return 0;
    }
  }
  return size * n;
}

std::size_t on_body(char* data, std::size_t size, std::size_t n, void* user) {
  auto* t = static_cast<Transfer*>(user);
  const std::size_t len = size * n;
  HttpResponse& r = t->response;
  if (!t->success()) {  // an error's body: kept for its message, the rest dropped
    r.body.append(data, std::min(len, kMaxErrorBody - std::min(kMaxErrorBody, r.body.size())));
    return len;
  }
  if (len > t->room() - r.received) {
    r.overflow = true;
    return 0;  // stops the transfer: CURLE_WRITE_ERROR
  }
  if (t->request->use_into) {
    std::memcpy(t->request->into.data() + r.received, data, len);
  } else {
    r.body.append(data, len);
  }
  r.received += len;
  return len;
}

bool retryable(CURLcode rc) {
  switch (rc) {
    case CURLE_COULDNT_CONNECT:
    case CURLE_COULDNT_RESOLVE_HOST:
    case CURLE_OPERATION_TIMEDOUT:
    case CURLE_SEND_ERROR:
    case CURLE_RECV_ERROR:
    case CURLE_GOT_NOTHING:
    case CURLE_PARTIAL_FILE:
    case CURLE_HTTP2:
    case CURLE_HTTP2_STREAM:
      return true;
    default:
      return false;
  }
}

void configure(CURL* e, const HttpRequest& req, const StoreOptions& o, Transfer& t,
               curl_slist* headers, char* errbuf) {
  curl_easy_setopt(e, CURLOPT_URL, req.url.c_str());
  curl_easy_setopt(e, CURLOPT_ERRORBUFFER, errbuf);
  curl_easy_setopt(e, CURLOPT_NOSIGNAL, 1L);
  curl_easy_setopt(e, CURLOPT_PROTOCOLS_STR, "http,https");
  curl_easy_setopt(e, CURLOPT_REDIR_PROTOCOLS_STR, "http,https");
  // The URL is already canonical: curl must not squash "." or ".." segments of a key.
  curl_easy_setopt(e, CURLOPT_PATH_AS_IS, 1L);
  curl_easy_setopt(e, CURLOPT_FOLLOWLOCATION, req.follow_redirects ? 1L : 0L);
  curl_easy_setopt(e, CURLOPT_MAXREDIRS, 5L);
  curl_easy_setopt(e, CURLOPT_NOBODY, req.head ? 1L : 0L);
  // Bytes exactly as stored: no Accept-Encoding, no decoding.
  curl_easy_setopt(e, CURLOPT_HTTP_CONTENT_DECODING, 0L);
  curl_easy_setopt(e, CURLOPT_CONNECTTIMEOUT_MS, static_cast<long>(o.connect_timeout.count()));
  curl_easy_setopt(e, CURLOPT_TIMEOUT_MS, static_cast<long>(o.timeout.count()));
  const long low_speed_s = std::clamp(static_cast<long>(o.timeout.count() / 1000), 1L, 10L);
  curl_easy_setopt(e, CURLOPT_LOW_SPEED_LIMIT, 1024L);
  curl_easy_setopt(e, CURLOPT_LOW_SPEED_TIME, low_speed_s);
  curl_easy_setopt(e, CURLOPT_USERAGENT, "vtstream-store/1");
  if (!o.ca_file.empty()) curl_easy_setopt(e, CURLOPT_CAINFO, o.ca_file.c_str());
  if (req.sign && o.credentials) {
    const std::string provider = "aws:amz:" + o.region + ":s3";
    curl_easy_setopt(e, CURLOPT_AWS_SIGV4, provider.c_str());  // libcurl copies strings
    curl_easy_setopt(e, CURLOPT_USERNAME, o.credentials->access_key_id.c_str());
    curl_easy_setopt(e, CURLOPT_PASSWORD, o.credentials->secret_access_key.c_str());
  }
  curl_easy_setopt(e, CURLOPT_HTTPHEADER, headers);
  curl_easy_setopt(e, CURLOPT_HEADERFUNCTION, &on_header);
  curl_easy_setopt(e, CURLOPT_HEADERDATA, &t);
  curl_easy_setopt(e, CURLOPT_WRITEFUNCTION, &on_body);
  curl_easy_setopt(e, CURLOPT_WRITEDATA, &t);
}

void count(const StoreOptions& o, std::atomic<std::uint64_t> Counters::*member, std::uint64_t n) {
  if (o.counters) (o.counters.get()->*member) += n;
}

}  // namespace

std::optional<ContentRange> parse_content_range(std::string_view v) {
  if (!v.starts_with("bytes ")) return std::nullopt;
  v.remove_prefix(6);
  const std::size_t slash = v.find('/');
  if (slash == std::string_view::npos) return std::nullopt;
  ContentRange r;
  if (v.substr(slash + 1) != "*") {
    r.total = to_u64(v.substr(slash + 1));
    if (!r.total) return std::nullopt;
  }
  const std::string_view span = v.substr(0, slash);
  if (span == "*") return r;
  const std::size_t dash = span.find('-');
  if (dash == std::string_view::npos) return std::nullopt;
  r.first = to_u64(span.substr(0, dash));
  r.last = to_u64(span.substr(dash + 1));
  if (!r.first || !r.last || *r.last < *r.first) return std::nullopt;
  return r;
}

Result<HttpResponse> perform(const HttpRequest& req, const StoreOptions& o,
                             const std::string& what) {
  CurlList headers;
  for (const std::string& h : req.headers) headers.add(h);
  if (req.sign && o.credentials) {
    headers.add(std::string("x-amz-content-sha256: ") + kEmptyBodySha256);
    if (!o.credentials->session_token.empty()) {
      headers.add("x-amz-security-token: " + o.credentials->session_token);
    }
  }
  // What messages name: the location, and the request URL when it is not the location itself.
  const std::string where = what == req.url ? what : what + " (" + req.url + ")";
  std::string last_cause;
  const int attempts = std::max(0, o.retries) + 1;
  for (int attempt = 0; attempt < attempts; ++attempt) {
    if (attempt > 0) {
      count(o, &Counters::retries, 1);
      const auto backoff = std::min<std::chrono::milliseconds>(
          o.retry_backoff * (std::int64_t{1} << std::min(attempt - 1, 10)),
          std::chrono::seconds(5));
      std::this_thread::sleep_for(backoff);
    }
    HandleLease handle;
    if (handle.get() == nullptr) return make_error(ErrorCode::internal, "curl_easy_init failed");
    Transfer t{&req, {}};
    char errbuf[CURL_ERROR_SIZE] = {};
    configure(handle.get(), req, o, t, headers.list, errbuf);
    count(o, &Counters::requests, 1);
    const CURLcode rc = curl_easy_perform(handle.get());
    if (t.success()) count(o, &Counters::bytes, t.response.received);
    if (rc == CURLE_OK || (rc == CURLE_WRITE_ERROR && t.response.overflow)) {
      const long status = t.response.status;
      if (status >= 500 || status == 429) {
        const std::string s3 = s3_error_text(t.response.body);  // SlowDown, InternalError...
        last_cause = "HTTP " + std::to_string(status) + (s3.empty() ? "" : ", " + s3);
        continue;
      }
      return std::move(t.response);
    }
    last_cause = errbuf[0] != '\0' ? std::string(errbuf) : curl_easy_strerror(rc);
    if (!retryable(rc)) {
      return make_error(ErrorCode::io, where + ": " + last_cause);
    }
  }
  return make_error(ErrorCode::unavailable,
                    where + " did not answer after " + std::to_string(attempts) +
                        (attempts == 1 ? " attempt: " : " attempts: ") + last_cause);
}

}  // namespace vts::store::detail
