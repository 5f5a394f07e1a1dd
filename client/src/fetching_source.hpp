// What the two network sources (TileJSON, remote archive) share: the table of requests in flight,
// each finished exactly once, cancellation down to the fetcher's transfer, and closing.
//
// `Pending` is the source's own per-request state; it has at least
//   SourceRequest request; SourceCallback callback;
//   Fetcher::Handle fetch;  // the transfer in progress, 0 when none
//   bool cancelled;
// Every field of it, pending_, closing_ and fetcher_ are guarded by mutex_, which the source may
// use for its own state too.
//
// A source calls close() first thing in its destructor: the fetcher's callbacks still reach the
// source's own members while the transfers are cancelled.
#pragma once

#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <unordered_map>
#include <utility>
#include <vector>

#include "vts/client/fetcher.hpp"
#include "vts/client/source.hpp"

namespace vts::client {

// The first line of a (text) error body, at most 200 bytes, for messages.
inline std::string first_line(const std::vector<std::uint8_t>& body) {
  std::string s;
  for (std::uint8_t b : body) {
    if (b == '\n' || b == '\r' || s.size() >= 200) break;
    s.push_back(b >= 0x20 && b < 0x7f ? static_cast<char>(b) : '?');
  }
  return s;
}

// "WHAT URL: HTTP NNN (the body's first line)".
inline std::string http_failure(std::string_view what, const std::string& url,
                                const FetchResult& r) {
  std::string m = std::string(what) + " " + url + ": HTTP " + std::to_string(r.status);
  const std::string line = first_line(r.body);
  if (!line.empty()) m += " (" + line + ")";
  return m;
}

// Replaces every `from` in s (a URL template's {z}, {x}, ...).
inline void replace_all(std::string& s, std::string_view from, const std::string& to) {
  for (std::size_t pos = s.find(from); pos != std::string::npos; pos = s.find(from, pos)) {
    s.replace(pos, from.size(), to);
    pos += to.size();
  }
}

inline SourceTransfer transfer_of(const FetchResult& r) {
  return {r.status,        r.body.size(),       r.attempts,
          r.timing.queued, r.timing.first_byte, r.timing.total};
}

// The fetcher group of a tile's transfers (FetchRequest::group): its level and its 8x8-tile
// block, the unit of "one slow region of the origin". A viewer's screen spans a few blocks of a
// level, so the per-group cap rarely binds it; a region the origin is slow to serve holds at
// most the cap of the fetcher's slots.
inline std::string region_group(const TileId& id) {
  return std::to_string(id.z) + '/' + std::to_string(id.x >> 3) + '/' + std::to_string(id.y >> 3);
}

template <class Pending>
class FetchingSource : public TileSource {
 public:
  // fh == 0: no transfer yet (the answer is on its way by another path, which reports the
  // cancellation). Otherwise the fetcher's callback for fh finishes the request with
  // Kind::cancelled; if it is already running, it sees `cancelled` before starting another step.
  void cancel(Handle h) override {
    Fetcher* fetcher = nullptr;
    Fetcher::Handle fh = 0;
    {
      std::lock_guard lock(mutex_);
      auto it = pending_.find(h);
      if (it == pending_.end() || fetcher_ == nullptr) return;  // done, or closing
      it->second->cancelled = true;
      fetcher = fetcher_.get();
      fh = it->second->fetch;
    }
    if (fh != 0) fetcher->cancel(fh);
  }

 protected:
  explicit FetchingSource(std::unique_ptr<Fetcher> fetcher) : fetcher_(std::move(fetcher)) {}

  // Cancels every transfer: their callbacks run now, each finishing its request.
  void close() {
    std::unique_ptr<Fetcher> fetcher;
    {
      std::lock_guard lock(mutex_);
      closing_ = true;
      fetcher = std::move(fetcher_);
    }
    fetcher.reset();
  }

  // A new request in the table; the caller holds mutex_.
  std::pair<Handle, std::shared_ptr<Pending>> add_locked(const SourceRequest& request,
                                                         SourceCallback callback) {
    auto p = std::make_shared<Pending>();
    p->request = request;
    p->callback = std::move(callback);
    const Handle h = ++next_handle_;
    pending_.emplace(h, p);
    return {h, std::move(p)};
  }

  // Removes the request and runs its callback (outside the lock), on the calling thread. A
  // cancel() that came in before this point wins over whatever the transfer brought.
  void finish(Handle h, SourceTile&& tile) {
    std::shared_ptr<Pending> p;
    {
      std::lock_guard lock(mutex_);
      auto it = pending_.find(h);
      if (it == pending_.end()) return;
      p = std::move(it->second);
      pending_.erase(it);
    }
    if (p->cancelled && tile.kind != SourceTile::Kind::cancelled) {
      tile = SourceTile{};
      tile.kind = SourceTile::Kind::cancelled;
    }
    p->callback(std::move(tile));
  }

  void finish_kind(Handle h, SourceTile::Kind kind,
                   std::optional<SourceTransfer> transfer = std::nullopt) {
    SourceTile t;
    t.kind = kind;
    t.transfer = transfer;
    finish(h, std::move(t));
  }

  void finish_error(Handle h, Error e, std::optional<SourceTransfer> transfer = std::nullopt) {
    SourceTile t;
    t.kind = SourceTile::Kind::error;
    t.error = std::move(e);
    t.transfer = transfer;
    finish(h, std::move(t));
  }

  // The answers to a tile's GET every network source takes alike: cancelled, a transfer error,
  // 200 (the payload, the server's own ETag, the lifetime its Cache-Control gives), 304 (with
  // the ETag asked with when the answer names none) and 204 (no tile here). True when `r` was one
  // of them and the request is finished; false leaves the status (404, others) to the source.
  bool finish_fetched(Handle h, FetchResult& r) {
    if (r.cancelled) {
      finish_kind(h, SourceTile::Kind::cancelled);
      return true;
    }
    const SourceTransfer transfer = transfer_of(r);
    if (r.error) {
      finish_error(h, std::move(*r.error), transfer);
      return true;
    }
    SourceTile t;
    t.transfer = transfer;
    switch (r.status) {
      case 200:
        t.kind = SourceTile::Kind::ok;
        // A tag made here from the payload would be one the server never issued: empty when it
        // sends none (a revalidation then asks unconditionally).
        t.etag = std::move(r.etag);
        t.payload = std::move(r.body);
        t.fresh_for = cache_control_lifetime(r.cache_control);
        break;
      case 304:
        t.kind = SourceTile::Kind::not_modified;
        t.etag = std::move(r.etag);
        t.fresh_for = cache_control_lifetime(r.cache_control);
        if (t.etag.empty()) {
          std::lock_guard lock(mutex_);
          if (auto it = pending_.find(h); it != pending_.end())
            t.etag = it->second->request.if_none_match;
        }
        break;
      case 204:
        t.kind = SourceTile::Kind::absent;
        break;
      default:
        return false;
    }
    finish(h, std::move(t));
    return true;
  }

  // The request to continue after a step, under mutex_: nullptr when it is done, cancelled or the
  // source is closing (the caller then finishes it with Kind::cancelled).
  Pending* resume(Handle h) {
    auto it = pending_.find(h);
    if (it == pending_.end() || it->second->cancelled || closing_) return nullptr;
    return it->second.get();
  }

  std::mutex mutex_;
  std::unique_ptr<Fetcher> fetcher_;  // null once closing
  std::unordered_map<Handle, std::shared_ptr<Pending>> pending_;
  Handle next_handle_ = 0;
  bool closing_ = false;
};

}  // namespace vts::client
