#include "vts/store/store.hpp"

#include <algorithm>
#include <charconv>
#include <condition_variable>
#include <cstring>
#include <map>
#include <mutex>
#include <set>

#include "http.hpp"
#include "s3_xml.hpp"

namespace vts::store {
namespace {

using detail::HttpRequest;
using detail::HttpResponse;

// A location resolved for requests: what messages name, the URL requests go to, and whether
// they are signed and may follow redirects.
struct Target {
  Location location;
  std::string request_url;
  bool sign = false;
};

Result<Target> resolve(const std::string& location, const StoreOptions& o) {
  Result<Location> l = parse_location(location);
  if (!l) return std::move(l).error();
  Target t{std::move(*l), {}, false};
  if (t.location.scheme == Scheme::s3) {
    t.request_url = s3_request_url(t.location, o);
    t.sign = o.credentials.has_value();
  } else {
    t.request_url = t.location.url;
  }
  return t;
}

HttpRequest request_for(const Target& t) {
  HttpRequest r;
  r.url = t.request_url;
  r.sign = t.sign;
  r.follow_redirects = t.location.scheme != Scheme::s3;
  return r;
}

// The error for an answer that is not a success, naming the location.
Error status_error(const Target& t, const HttpResponse& r) {
  const std::string s3 = detail::s3_error_text(r.body);
  const std::string code = detail::s3_error_code(r.body);
  const std::string detail = s3.empty() ? "HTTP " + std::to_string(r.status)
                                        : "HTTP " + std::to_string(r.status) + ", " + s3;
  const std::string& what = t.location.url;
  if (r.status == 404) {
    if (code == "NoSuchBucket") {
      return make_error(ErrorCode::not_found, what + ": bucket \"" + t.location.bucket +
                                                  "\" does not exist (" + detail + ")");
    }
    return make_error(ErrorCode::not_found, what + ": not found (" + detail + ")");
  }
  if (r.status == 401 || r.status == 403) {
    const std::string how =
        !t.sign ? " (the request was not signed: no AWS credentials found)" : "";
    return make_error(ErrorCode::io, what + ": credentials refused by " + t.request_url + " (" +
                                         detail + ")" + how);
  }
  if (r.status >= 300 && r.status < 400 && t.location.scheme == Scheme::s3) {
    return make_error(ErrorCode::io, what + ": redirected by " + t.request_url + " (" + detail +
                                         "): is the region (AWS_REGION) or the endpoint wrong?");
  }
  return make_error(ErrorCode::io, what + ": " + t.request_url + " answered " + detail);
}

// Reads of one object by ranged GETs; see open_object() in store.hpp for the contract.
class RemoteObject final : public archive::ByteSource {
 public:
  RemoteObject(Target target, StoreOptions options, std::uint64_t size, std::string etag,
               std::string last_modified, std::vector<std::uint8_t> first_block)
      : target_(std::move(target)),
        options_(std::move(options)),
        size_(size),
        etag_(std::move(etag)),
        last_modified_(std::move(last_modified)),
        first_block_(std::move(first_block)) {}

  std::uint64_t size() const override { return size_; }
  std::string name() const override { return target_.location.url; }

  Status check_unchanged() const override {
    if (changed_.load()) return changed_error("");
    return {};
  }

  Status read(std::uint64_t offset, std::span<std::uint8_t> out) const override {
    if (changed_.load()) return changed_error("");
    if (out.empty()) return {};
    if (offset > size_ || out.size() > size_ - offset) {
      return make_error(ErrorCode::invalid_argument, name() + ": bytes " + std::to_string(offset) +
                                                         "+" + std::to_string(out.size()) +
                                                         " lie beyond its " +
                                                         std::to_string(size_));
    }
    if (offset + out.size() <= first_block_.size()) {
      std::memcpy(out.data(), first_block_.data() + offset, out.size());
      if (options_.counters) ++options_.counters->first_block_hits;
      return {};
    }
    return coalesced_read(offset, out);
  }

 private:
  // One GET in flight for a byte range, and the threads waiting for it.
  struct Flight {
    bool done = false;
    Status status;
    std::vector<std::uint8_t> bytes;  // filled only when someone waits
    int waiters = 0;
  };
  using Range = std::pair<std::uint64_t, std::size_t>;

  Status coalesced_read(std::uint64_t offset, std::span<std::uint8_t> out) const {
    const Range key{offset, out.size()};
    std::unique_lock lock(flights_mutex_);
    if (const auto it = flights_.find(key); it != flights_.end()) {
      const std::shared_ptr<Flight> flight = it->second;
      ++flight->waiters;
      if (options_.counters) ++options_.counters->coalesced;
      flights_done_.wait(lock, [&] { return flight->done; });
      if (!flight->status) return flight->status;
      std::memcpy(out.data(), flight->bytes.data(), out.size());
      return {};
    }
    const auto flight = std::make_shared<Flight>();
    flights_.emplace(key, flight);
    lock.unlock();
    Status s = fetch(offset, out);
    lock.lock();
    flights_.erase(key);  // later readers start a GET of their own
    flight->status = s;
    if (flight->waiters > 0 && s) flight->bytes.assign(out.begin(), out.end());
    flight->done = true;
    lock.unlock();
    flights_done_.notify_all();
    return s;
  }

  Error changed_error(const std::string& why) const {
    if (!why.empty()) changed_.store(true);
    return make_error(ErrorCode::changed, name() + " changed after it was opened" +
                                              (why.empty() ? std::string{} : " (" + why + ")") +
                                              "; reopen it");
  }

  // One ranged GET into `out`, verified to be exactly those bytes of the object opened.
  Status fetch(std::uint64_t offset, std::span<std::uint8_t> out) const {
    const std::uint64_t last = offset + out.size() - 1;
    HttpRequest req = request_for(target_);
    req.headers.push_back("Range: bytes=" + std::to_string(offset) + "-" + std::to_string(last));
    if (!etag_.empty()) {
      req.headers.push_back("If-Match: " + etag_);
    } else if (!last_modified_.empty()) {
      req.headers.push_back("If-Unmodified-Since: " + last_modified_);
    }
    req.use_into = true;
    req.into = out;
    Result<HttpResponse> r = detail::perform(req, options_, name());
    if (!r) return std::move(r).error();
    if (r->status == 412) return changed_error("412 Precondition Failed");
    if (r->status == 404) return changed_error("it no longer exists");
    if (r->status == 416) return changed_error("416: it is shorter now");
    if (r->status != 200 && r->status != 206) return status_error(target_, *r);
    if (!etag_.empty() && !r->etag.empty() && r->etag != etag_) {
      return changed_error("ETag " + r->etag + ", opened as " + etag_);
    }
    const std::string asked = std::to_string(offset) + "-" + std::to_string(last);
    if (r->status == 200) {
      if (offset != 0 || out.size() != size_) {
        return make_error(ErrorCode::unsupported,
                          name() + ": the server ignored the Range header (200 for " + asked + ")");
      }
    } else {
      const auto range = detail::parse_content_range(r->content_range);
      if (!range || !range->total || !range->first) {
        return make_error(
            ErrorCode::corrupt,
            name() + ": 206 for " + asked + " with Content-Range \"" + r->content_range + "\"");
      }
      if (*range->total != size_) {
        return changed_error("its size is " + std::to_string(*range->total) + ", opened as " +
                             std::to_string(size_));
      }
      if (*range->first != offset || *range->last != last) {
        return make_error(ErrorCode::corrupt, name() + ": asked for bytes " + asked +
                                                  ", answered with " + r->content_range);
      }
    }
    if (r->overflow || r->received != out.size()) {
      return make_error(ErrorCode::corrupt, name() + ": " + std::to_string(r->received) +
                                                (r->overflow ? "+" : "") + " bytes for the " +
                                                std::to_string(out.size()) + " of " + asked);
    }
    return {};
  }

  const Target target_;
  const StoreOptions options_;
  const std::uint64_t size_;
  const std::string etag_, last_modified_;
  const std::vector<std::uint8_t> first_block_;
  mutable std::atomic<bool> changed_{false};  // sticky, like archive's FileBytes
  mutable std::mutex flights_mutex_;
  mutable std::condition_variable flights_done_;
  mutable std::map<Range, std::shared_ptr<Flight>> flights_;
};

// The object's size from the answer to open_object()'s first GET.
Result<std::uint64_t> size_from_first_answer(const Target& t, const HttpResponse& r,
                                             std::size_t asked) {
  if (r.status == 206) {
    const auto range = detail::parse_content_range(r.content_range);
    if (!range || !range->total || !range->first || *range->first != 0 ||
        *range->last >= *range->total || *range->last - *range->first + 1 != r.received ||
        (r.received != asked && *range->total != r.received)) {
      return make_error(ErrorCode::corrupt, t.location.url + ": 206 with Content-Range \"" +
                                                r.content_range + "\" and " +
                                                std::to_string(r.received) + " bytes");
    }
    return *range->total;
  }
  if (r.status == 200) {
    if (r.overflow) {
      return make_error(ErrorCode::unsupported,
                        t.location.url + ": the server ignores Range requests (" + t.request_url +
                            " answered 200 with the whole object)");
    }
    return r.received;
  }
  if (r.status == 416) {  // an empty object: there is no byte 0 to send
    const auto range = detail::parse_content_range(r.content_range);
    if (range && range->total && *range->total == 0) return std::uint64_t{0};
  }
  return status_error(t, r);
}

}  // namespace

Result<std::unique_ptr<archive::ByteSource>> open_object(const std::string& location,
                                                         const StoreOptions& options) {
  Result<Target> t = resolve(location, options);
  if (!t) return std::move(t).error();
  if (t->location.scheme == Scheme::s3 && t->location.key.empty()) {
    return make_error(ErrorCode::invalid_argument, location + ": no object key");
  }
  const std::size_t block = std::max<std::size_t>(options.first_block, 1);
  HttpRequest req = request_for(*t);
  req.headers.push_back("Range: bytes=0-" + std::to_string(block - 1));
  req.max_body = block;
  Result<HttpResponse> r = detail::perform(req, options, location);
  if (!r) return std::move(r).error();
  Result<std::uint64_t> size = size_from_first_answer(*t, *r, block);
  if (!size) return std::move(size).error();
  std::vector<std::uint8_t> first(r->body.begin(), r->body.end());
  return std::unique_ptr<archive::ByteSource>(
      std::make_unique<RemoteObject>(std::move(*t), options, *size, std::move(r->etag),
                                     std::move(r->last_modified), std::move(first)));
}

Result<std::string> get_object(const std::string& location, const StoreOptions& options,
                               std::size_t max_bytes) {
  Result<Target> t = resolve(location, options);
  if (!t) return std::move(t).error();
  HttpRequest req = request_for(*t);
  req.max_body = max_bytes;
  Result<HttpResponse> r = detail::perform(req, options, location);
  if (!r) return std::move(r).error();
  if (r->status != 200) return status_error(*t, *r);
  if (r->overflow) {
    return make_error(ErrorCode::too_large,
                      location + " has more than " + std::to_string(max_bytes) + " bytes");
  }
  return std::move(r->body);
}

Result<std::string> object_etag(const std::string& location, const StoreOptions& options) {
  Result<Target> t = resolve(location, options);
  if (!t) return std::move(t).error();
  HttpRequest req = request_for(*t);
  req.head = true;
  Result<HttpResponse> r = detail::perform(req, options, location);
  if (!r) return std::move(r).error();
  if (r->status != 200) return status_error(*t, *r);
  if (!r->etag.empty()) return std::move(r->etag);
  if (!r->last_modified.empty()) return "last-modified: " + r->last_modified;
  return make_error(ErrorCode::unsupported,
                    location + ": the server sends neither ETag nor Last-Modified");
}

Result<std::vector<ObjectInfo>> list_objects(const std::string& prefix_location,
                                             const StoreOptions& options) {
  Result<Listing> l = list_folder(prefix_location, options);
  if (!l) return std::move(l).error();
  return std::move(l->objects);
}

Result<Listing> list_folder(const std::string& prefix_location, const StoreOptions& options) {
  Result<Target> t = resolve(prefix_location, options);
  if (!t) return std::move(t).error();
  if (t->location.scheme != Scheme::s3) {
    return make_error(ErrorCode::unsupported,
                      prefix_location +
                          ": only s3:// prefixes can be listed (HTTP has no "
                          "listing; name the archives one by one)");
  }
  std::string prefix = t->location.key;
  if (!prefix.empty() && prefix.back() != '/') prefix += '/';
  Location bucket = t->location;
  bucket.key.clear();
  const std::string bucket_url = s3_request_url(bucket, options);
  Listing listing;
  std::vector<ObjectInfo>& objects = listing.objects;
  std::set<std::string> tokens_seen;
  std::string token;
  for (;;) {
    // Parameters sorted by name and URI-encoded: SigV4's canonical query, which curl 7.88 signs
    // as it finds it.
    std::string query = "?";
    if (!token.empty()) query += "continuation-token=" + uri_encode(token, false) + "&";
    query += "delimiter=%2F&list-type=2&prefix=" + uri_encode(prefix, false);
    HttpRequest req = request_for(*t);
    req.url = bucket_url + query;
    req.max_body = std::size_t{16} << 20;
    Result<HttpResponse> r = detail::perform(req, options, prefix_location);
    if (!r) return std::move(r).error();
    if (r->status != 200) return status_error(*t, *r);
    if (r->overflow) {
      return make_error(ErrorCode::too_large, prefix_location + ": a listing page over 16 MiB");
    }
    Result<detail::XmlNode> doc = detail::parse_xml(r->body);
    if (!doc || doc->name != "ListBucketResult") {
      return make_error(ErrorCode::corrupt,
                        prefix_location + ": the listing is not a ListBucketResult" +
                            (doc ? std::string{} : " (" + doc.error().message + ")"));
    }
    for (const detail::XmlNode& c : doc->children) {
      if (c.name == "CommonPrefixes") {
        const std::string sub = c.child_text("Prefix");
        if (sub.size() > prefix.size() && sub.starts_with(prefix))
          listing.folders.push_back("s3://" + t->location.bucket + "/" + sub);
        continue;
      }
      if (c.name != "Contents") continue;
      ObjectInfo info;
      info.key = c.child_text("Key");
      if (info.key == prefix) continue;  // a "folder" marker object, not an archive
      const std::string size = c.child_text("Size");
      const auto [end, ec] = std::from_chars(size.data(), size.data() + size.size(), info.size);
      if (ec != std::errc{} || end != size.data() + size.size() || size.empty()) {
        return make_error(ErrorCode::corrupt,
                          prefix_location + ": key \"" + info.key + "\" has size \"" + size + "\"");
      }
      info.etag = c.child_text("ETag");
      info.url = "s3://" + t->location.bucket + "/" + info.key;
      objects.push_back(std::move(info));
    }
    if (doc->child_text("IsTruncated") != "true") break;
    token = doc->child_text("NextContinuationToken");
    if (token.empty() || !tokens_seen.insert(token).second) {
      return make_error(ErrorCode::corrupt, prefix_location +
                                                ": a truncated listing page without a new "
                                                "continuation token");
    }
  }
  std::sort(objects.begin(), objects.end(),
            [](const ObjectInfo& a, const ObjectInfo& b) { return a.key < b.key; });
  std::sort(listing.folders.begin(), listing.folders.end());
  return listing;
}

}  // namespace vts::store
