// The one answer pipeline (docs/ARCHITECTURE.md "One answer pipeline"): route() answers what it can
// at once and plans the rest (PendingAnswer); finish_pending() carries a plan out, in the same
// order for every kind of answer:
//   0. a tile of an archive in an object store, read on the store-read pool;
//   1. the provider's tile (vts cache serve), mapped to its answer by the router
//      (answer_provided), which may be a web image to make;
//   2. the web image: the cache (a hit, or the flight another request leads), else this request
//      leads the flight and its encode is queued on the cache's encode pool (fair between
//      connections, shed over its caps, dropped when nobody waits any more);
//   3. one finish: the final response with the marker's CORS headers, HEAD flag and tileset.
// No step blocks a thread: each hands the next to the callback of the one before.
#include <cassert>
#include <chrono>
#include <exception>
#include <future>

#include "router_internal.hpp"
#include "vts/base/worker_pool.hpp"
#include "vts/protocol/codec.hpp"
#include "web_tile_cache.hpp"

namespace vts {
inline namespace server {
namespace {

using namespace router_detail;
using http_detail::EncodeQueue;
using http_detail::Flight;
using http_detail::WebTile;
using http_detail::WebTileCache;
using http_detail::WebTilePtr;
using Done = std::function<void(HttpResponse)>;

// Step 3: `r` as the request's answer (route()'s finishing touches, kept on `marker`).
HttpResponse finished(const HttpResponse& marker, HttpResponse r) {
  r.route = Route::tile;
  if (!r.hold) r.hold = marker.hold;
  for (const auto& h : marker.headers) r.headers.push_back(h);  // CORS, from route()
  r.head_only = marker.head_only;
  // 204 and 304 carry no body by definition (RFC 9110 §15.3.5, §15.4.5).
  if (r.status == 204 || r.status == 304) {
    r.owned.clear();
    r.view = {};
    r.keep.reset();
    r.content_length = 0;
  }
  return r;
}

// Runs the job's encode, counts it and (with a cache) stores the image and ends the flight `lead`,
// which answers the requests waiting for it. Null with `why` set when encoding failed.
WebTilePtr encode_now(WebTileCache* cache, const WebImageJob& job,
                      const std::shared_ptr<Flight>& lead, std::string& why) {
  const auto start = std::chrono::steady_clock::now();
  WebTilePtr tile;
  try {
    if (auto bytes = job.encode()) {
      tile =
          std::make_shared<const WebTile>(WebTile{std::move(*bytes), job.etag, job.content_type});
    } else {
      why = bytes.error().to_string();
    }
  } catch (const std::exception& e) {  // bad_alloc: the waiters must still be answered
    why = e.what();
  }
  if (cache != nullptr) {
    const auto us = std::chrono::duration_cast<std::chrono::microseconds>(
                        std::chrono::steady_clock::now() - start)
                        .count();
    cache->encodes.fetch_add(1, std::memory_order_relaxed);
    cache->encode_us_sum.fetch_add(std::uint64_t(us), std::memory_order_relaxed);
    if (!tile) cache->encode_failures.fetch_add(1, std::memory_order_relaxed);
    cache->finish(job.key, lead, tile, tile ? 200 : 500, why);
  }
  return tile;
}

// The answer a flight's result gives: the image (200 / 304); 503 with Retry-After when the server
// shed or dropped the encode (`why` says which); 500 when encoding failed.
HttpResponse web_answer(const WebTilePtr& tile, int status, const std::string& why,
                        std::string_view if_none_match, const std::string& cc) {
  if (tile) return web_image_response(tile, if_none_match, cc);
  if (status == 503) {
    HttpResponse r = tile_error(503, why);
    add(r, "Retry-After", "1");
    return r;
  }
  return tile_error(500, "cannot encode the web image: " + why);
}

std::string shed_reason(EncodeQueue::Admit why, const WebTileCache& cache) {
  const http_detail::EncodeLimits l = cache.limits();
  return why == EncodeQueue::Admit::owner_full
             ? "this connection already has " + std::to_string(l.max_queued_per_owner) +
                   " web images waiting to be encoded; retry after those"
             : "the server has " + std::to_string(l.max_queued) +
                   " web images waiting to be encoded; retry shortly";
}

// Step 2 (then 3) for the plan `p` with its image job.
void make_image(HttpResponse marker, const std::shared_ptr<const PendingAnswer>& p,
                std::stop_token interest, Done done) {
  const WebImageJob& job = *p->image;
  WebTileCache* cache = p->cache.get();
  if (cache == nullptr) {  // no cache: encoded here, kept nowhere
    std::string why;
    WebTilePtr tile = encode_now(nullptr, job, nullptr, why);
    return done(finished(
        marker, web_answer(tile, tile ? 200 : 500, why, p->if_none_match, p->cache_control)));
  }
  WebTileCache::Lookup found = cache->acquire(job.key);
  if (found.hit) {
    return done(
        finished(marker, web_image_response(found.hit, p->if_none_match, p->cache_control)));
  }
  std::shared_ptr<Flight> flight = found.wait;
  if (found.lead) {
    flight = found.lead;
    if (cache->has_workers()) {
      // The job, not the plan: a queued encode must not keep the cache (and its pool) alive.
      const auto admit =
          cache->queue(job.key, found.lead, p->connection, [cache, lead = found.lead, job] {
            std::string why;
            encode_now(cache, job, lead, why);
          });
      // Refused: the flight ends now, so this request and any that joined it meanwhile get 503.
      if (admit != EncodeQueue::Admit::queued)
        cache->finish(job.key, found.lead, nullptr, 503, shed_reason(admit, *cache));
    } else {
      std::string why;
      encode_now(cache, job, found.lead, why);
    }
  }
  flight->on_done(
      [marker = std::move(marker), inm = p->if_none_match, cc = p->cache_control, done](
          const WebTilePtr& tile, int status, const std::string& why) {
        done(finished(marker, web_answer(tile, status, why, inm, cc)));
      },
      std::move(interest));
}

// The threads that read tiles from object stores: each read waits on the network (a ranged GET of
// a few milliseconds), so many more threads than cores, and never the I/O threads. Bounded: a
// flood over it is shed with 503. Started on first use, for the process's life.
constexpr unsigned kStoreReadThreads = 32;
constexpr std::size_t kStoreReadQueue = 4096;

base::WorkerPool* store_reads() {
  static const std::unique_ptr<base::WorkerPool> pool = [] {
    auto started = base::WorkerPool::start(
        {.threads = kStoreReadThreads, .capacity = kStoreReadQueue, .name = "vts-store-read"});
    return started ? std::move(*started) : nullptr;
  }();
  return pool.get();
}

// Step 0 (then 2 for a web image, then 3): the tile from its archive in a store, on the
// store-read pool.
void read_stored(HttpResponse marker, const std::shared_ptr<const PendingAnswer>& p,
                 std::stop_token interest, Done done) {
  auto job = [marker, p, interest, done]() mutable {
    if (interest.stop_requested()) {  // nobody waits for it any more: no request to the store
      return done(finished(marker, tile_error(503, "the request was abandoned")));
    }
    auto payload = p->stored->reader->get(p->id);
    // A store's bytes are checked whole before they are sent: an object replaced while it is read
    // (a store whose writes are not atomic, a file copied over behind a web server) can answer the
    // old ETag with new bytes. Hashing a tile is microseconds against the request's milliseconds.
    // Directories read mid-replacement fail the same way: both are answered 503 and the tileset
    // reloaded (a store object that is damaged for good stays 503 until it is replaced).
    Status whole;
    if (!payload) {
      whole = payload.error();
    } else if (auto checked = verify_tile(*payload); !checked) {
      whole = checked.error();
    }
    if (!whole &&
        (whole.error().code == ErrorCode::corrupt || whole.error().code == ErrorCode::truncated ||
         whole.error().code == ErrorCode::checksum)) {
      HttpResponse r = archive_changed(
          p->stored, make_error(ErrorCode::changed, "tile " + p->id.to_string() +
                                                        " read from the store is not whole (" +
                                                        whole.error().message + ")"));
      return done(finished(marker, std::move(r)));
    }
    HttpResponse r = p->answer_stored ? p->answer_stored(std::move(payload))
                                      : stored_tile_answer(p->stored, p->id, std::move(payload),
                                                           p->if_none_match, p->cache_control);
    if (r.pending) return make_image(std::move(marker), r.pending, interest, std::move(done));
    done(finished(marker, std::move(r)));
  };
  base::WorkerPool* pool = store_reads();
  if (pool == nullptr) return job();  // no thread could start: read here rather than fail
  if (!pool->try_submit(job)) {
    HttpResponse r = tile_error(503, "the server has " + std::to_string(kStoreReadQueue) +
                                         " tile reads from object stores waiting; retry shortly");
    add(r, "Retry-After", "1");
    done(finished(marker, std::move(r)));
  }
}

}  // namespace

void finish_pending(HttpResponse marker, AsyncTileProvider* provider, std::stop_token interest,
                    Done done) {
  std::shared_ptr<const PendingAnswer> p = std::move(marker.pending);
  assert(p);
  if (p->stored) return read_stored(std::move(marker), p, std::move(interest), std::move(done));
  if (!p->provided) return make_image(std::move(marker), p, std::move(interest), std::move(done));
  if (provider == nullptr) {  // route() plans a fetch only from the provider it was given
    return done(finished(marker, tile_error(500, "no tile provider to fetch " + p->id.to_string() +
                                                     " of " + p->provided->name + " from")));
  }
  provider->tile(
      p->provided, p->id,
      [marker = std::move(marker), p, interest, done](ProvidedTile tile) mutable {
        HttpResponse r = answer_provided(*p, std::move(tile));
        if (!r.pending) return done(finished(marker, std::move(r)));
        make_image(std::move(marker), r.pending, std::move(interest), std::move(done));
      },
      interest);
}

HttpResponse finish_pending_now(HttpResponse marker, AsyncTileProvider* provider) {
  if (!marker.pending) return marker;
  auto answer = std::make_shared<std::promise<HttpResponse>>();
  std::future<HttpResponse> future = answer->get_future();
  finish_pending(std::move(marker), provider, {},
                 [answer](HttpResponse r) { answer->set_value(std::move(r)); });
  return future.get();
}

}  // namespace server
}  // namespace vts
