// The client's Fetcher against FaultServer on loopback: byte-exact tiles and ranges, priority
// order, merging, cancellation, retries and their limits, load, shutdown and bad input. The archive
// comes from the real builder, in process, and every body is compared
// with what archive::Reader returns. Faults are chosen by URL (see fault_server.hpp).
#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdlib>
#include <filesystem>
#include <future>
#include <map>
#include <mutex>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "fault_server.hpp"
#include "vts/archive/pmtiles.hpp"
#include "vts/client/fetcher.hpp"
#include "vts/test/archive.hpp"
#include "vts/test/temp_dir.hpp"

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using vts::client::FetchCallback;
using vts::client::Fetcher;
using vts::client::FetcherOptions;
using vts::client::FetchRequest;
using vts::client::FetchResult;
using vts::test::FaultServer;
using Clock = std::chrono::steady_clock;

namespace {

// One synthetic archive for the whole process (built once, in process): "a", served as
// /a/{z}/{x}/{y}.
const vts::test::TempDir& archive_dir() {
  static const vts::test::TempDir d("vts-fetch-test");
  return d;
}

const vts::test::OpenedArchive& archive() {
  static const vts::test::OpenedArchive a = vts::test::build_and_open(
      vts::test::synthetic_options(archive_dir() / "a.pmtiles", 1024, 512));
  return a;
}

std::vector<std::uint8_t> tile_bytes(vts::TileId id) {
  auto t = archive().reader->get(id);
  if (!t) throw std::runtime_error(t.error().to_string());
  return {t->begin(), t->end()};
}

std::vector<std::uint8_t> archive_bytes(std::uint64_t first, std::uint64_t last) {
  const auto all = vts::test::read_all(*archive().reader);
  return {all.begin() + std::ptrdiff_t(first), all.begin() + std::ptrdiff_t(last + 1)};
}

std::string tile_path(vts::TileId id) {
  return "/a/" + id.to_string();
}

// Options that keep retries quick; tests override what they measure.
FetcherOptions quick_options() {
  FetcherOptions o;
  o.backoff_base = 10ms;
  o.backoff_max = 50ms;
  o.connect_timeout = 2000ms;
  o.request_timeout = 10000ms;
  return o;
}

std::unique_ptr<Fetcher> make_fetcher(FetcherOptions o = quick_options()) {
  auto f = Fetcher::create(std::move(o));
  if (!f) throw std::runtime_error(f.error().to_string());
  return std::move(*f);
}

std::unique_ptr<FaultServer> start_server() {
  auto s = FaultServer::start(archive().path, "a");
  if (!s) throw std::runtime_error(s.error().to_string());
  return std::move(*s);
}

FetchRequest get(std::string url, int level = 0, double urgency = 0) {
  FetchRequest r;
  r.url = std::move(url);
  r.level = level;
  r.urgency = urgency;
  return r;
}

// Submits and waits for the callback (at most `limit`).
FetchResult fetch(Fetcher& f, FetchRequest req, std::chrono::seconds limit = 30s) {
  auto promise = std::make_shared<std::promise<FetchResult>>();
  auto future = promise->get_future();
  f.submit(std::move(req), [promise](FetchResult&& r) { promise->set_value(std::move(r)); });
  if (future.wait_for(limit) != std::future_status::ready) {
    ADD_FAILURE() << "no callback within " << limit.count() << " s";
    return {};
  }
  return future.get();
}

template <typename Pred>
bool wait_until(Pred pred, std::chrono::milliseconds limit = 5000ms) {
  const auto deadline = Clock::now() + limit;
  while (!pred()) {
    if (Clock::now() > deadline) return false;
    std::this_thread::sleep_for(2ms);
  }
  return true;
}

// Results of many requests, by tag, in completion order; callbacks count how often each ran.
class Collector {
 public:
  FetchCallback callback(std::string tag) {
    return [this, tag = std::move(tag)](FetchResult&& r) {
      std::lock_guard lock(mutex_);
      ++calls_[tag];
      order_.push_back(tag);
      results_[tag] = std::move(r);
      cv_.notify_all();
    };
  }
  bool wait_for(std::size_t n, std::chrono::milliseconds limit = 30000ms) {
    std::unique_lock lock(mutex_);
    return cv_.wait_for(lock, limit, [&] { return order_.size() >= n; });
  }
  std::vector<std::string> order() const {
    std::lock_guard lock(mutex_);
    return order_;
  }
  FetchResult result(const std::string& tag) const {
    std::lock_guard lock(mutex_);
    auto it = results_.find(tag);
    return it == results_.end() ? FetchResult{} : it->second;
  }
  int calls(const std::string& tag) const {
    std::lock_guard lock(mutex_);
    auto it = calls_.find(tag);
    return it == calls_.end() ? 0 : it->second;
  }

 private:
  mutable std::mutex mutex_;
  std::condition_variable cv_;
  std::vector<std::string> order_;
  std::map<std::string, FetchResult> results_;
  std::map<std::string, int> calls_;
};

std::string error_text(const FetchResult& r) {
  return r.error ? r.error->to_string() : "(none)";
}

// Occupies the only in-flight slot of a max_in_flight = 1 fetcher with a stalled request, so
// what is submitted next stays queued until release().
class Blocker {
 public:
  Blocker(Fetcher& f, FaultServer& s, Collector& c) : fetcher_(f) {
    const std::string target = "/fault/stall/a/0/0/0?blocker";
    handle_ = f.submit(get(s.base_url() + target, -100), c.callback("blocker"));
    if (!wait_until([&] { return s.attempts(target) == 1; })) {
      ADD_FAILURE() << "the blocker never reached the server";
    }
  }
  void release() { fetcher_.cancel(handle_); }

 private:
  Fetcher& fetcher_;
  Fetcher::Handle handle_ = 0;
};

TEST(Fetcher, ReturnsEveryTileByteExactWithItsETag) {
  auto server = start_server();
  auto fetcher = make_fetcher();
  Collector c;
  for (const vts::TileId& id : archive().tiles) {
    fetcher->submit(get(server->base_url() + tile_path(id), id.z), c.callback(id.to_string()));
  }
  ASSERT_TRUE(c.wait_for(archive().tiles.size()));
  ASSERT_GE(archive().tiles.size(), 11u);
  for (const vts::TileId& id : archive().tiles) {
    const FetchResult r = c.result(id.to_string());
    ASSERT_FALSE(r.error) << error_text(r);
    EXPECT_EQ(r.status, 200);
    EXPECT_EQ(r.body, tile_bytes(id)) << id.to_string();
    EXPECT_EQ(r.attempts, 1);
    EXPECT_EQ(r.etag.size(), 18u) << r.etag;
  }

  // The validator comes back as a 304 with no body (a normal result, not an error).
  const vts::TileId id = archive().tiles.front();
  FetchRequest again = get(server->base_url() + tile_path(id));
  again.if_none_match = c.result(id.to_string()).etag;
  const FetchResult r = fetch(*fetcher, again);
  EXPECT_FALSE(r.error) << error_text(r);
  EXPECT_EQ(r.status, 304);
  EXPECT_TRUE(r.body.empty());
  EXPECT_EQ(r.etag, again.if_none_match);
}

TEST(Fetcher, ReturnsArchiveRangesByteExact) {
  auto server = start_server();
  auto fetcher = make_fetcher();
  const std::uint64_t size = archive().reader->size();
  ASSERT_GT(size, 1000u);
  const std::vector<std::pair<std::uint64_t, std::uint64_t>> ranges = {
      {0, 126}, {127, size / 2}, {size / 2, size / 2 + 99}, {size - 1, size - 1}, {0, size - 1}};
  const std::string url = server->base_url() + "/a.pmtiles";
  for (const auto& range : ranges) {
    FetchRequest req = get(url);
    req.range = range;
    const FetchResult r = fetch(*fetcher, req);
    ASSERT_FALSE(r.error) << error_text(r);
    EXPECT_EQ(r.status, 206);
    EXPECT_EQ(r.body, archive_bytes(range.first, range.second))
        << range.first << "-" << range.second;
  }

  // A range running past the end is answered up to the last byte.
  FetchRequest tail = get(url);
  tail.range = {size - 10, size + 100};
  FetchResult r = fetch(*fetcher, tail);
  ASSERT_FALSE(r.error) << error_text(r);
  EXPECT_EQ(r.body, archive_bytes(size - 10, size - 1));

  // A truncated 206 is retried.
  FetchRequest truncated = get(server->base_url() + "/fault/truncate*1/a.pmtiles");
  truncated.range = {100, size - 100};
  r = fetch(*fetcher, truncated);
  ASSERT_FALSE(r.error) << error_text(r);
  EXPECT_EQ(r.attempts, 2);
  EXPECT_EQ(r.body, archive_bytes(100, size - 100));

  // Tile URLs ignore Range and answer 200 with the whole tile: the fetcher keeps the slice.
  const vts::TileId id = archive().tiles.back();
  const std::vector<std::uint8_t> whole = tile_bytes(id);
  ASSERT_GT(whole.size(), 100u);
  FetchRequest slice = get(server->base_url() + tile_path(id));
  slice.range = {10, 99};
  r = fetch(*fetcher, slice);
  ASSERT_FALSE(r.error) << error_text(r);
  EXPECT_EQ(r.status, 200);
  EXPECT_EQ(r.body, std::vector<std::uint8_t>(whole.begin() + 10, whole.begin() + 100));

  // ...and a range that starts past such a body is an error.
  slice.range = {whole.size(), whole.size() + 10};
  r = fetch(*fetcher, slice);
  ASSERT_TRUE(r.error);
  EXPECT_EQ(r.error->code, vts::ErrorCode::invalid_argument);
}

TEST(Fetcher, StartsCoarserLevelsFirstThenMoreUrgentThenInOrder) {
  auto server = start_server();
  FetcherOptions o = quick_options();
  o.max_in_flight = 1;
  auto fetcher = make_fetcher(o);
  Collector c;
  Blocker blocker(*fetcher, *server, c);

  const std::string tile = server->base_url() + "/a/0/0/0?t=";  // distinct URLs: no merging
  fetcher->submit(get(tile + "1", 2, 0), c.callback("L2 first"));
  fetcher->submit(get(tile + "2", 2, 0), c.callback("L2 second"));
  fetcher->submit(get(tile + "3", 1, 1), c.callback("L1 u1"));
  fetcher->submit(get(tile + "4", 1, 5), c.callback("L1 u5"));
  fetcher->submit(get(tile + "5", 0, 0), c.callback("L0"));
  fetcher->submit(get(tile + "6", 1, 3), c.callback("L1 u3"));
  const auto late = fetcher->submit(get(tile + "7", 3, 0), c.callback("L3 raised to L0 u9"));
  fetcher->reprioritize(late, 0, 9);
  blocker.release();

  ASSERT_TRUE(c.wait_for(8));
  const std::vector<std::string> expected = {
      "blocker", "L3 raised to L0 u9", "L0", "L1 u5", "L1 u3", "L1 u1", "L2 first", "L2 second"};
  EXPECT_EQ(c.order(), expected);
  EXPECT_TRUE(c.result("blocker").cancelled);
  EXPECT_EQ(c.result("L2 second").status, 200);
}

TEST(Fetcher, MergesEqualRequestsIntoOneTransfer) {
  auto server = start_server();
  FetcherOptions o = quick_options();
  o.max_in_flight = 1;
  auto fetcher = make_fetcher(o);
  Collector c;
  Blocker blocker(*fetcher, *server, c);
  const vts::TileId id = archive().tiles.at(3);
  for (int i = 0; i < 8; ++i) {
    fetcher->submit(get(server->base_url() + tile_path(id), 2, i), c.callback(std::to_string(i)));
  }
  blocker.release();
  ASSERT_TRUE(c.wait_for(9));
  EXPECT_EQ(server->attempts(tile_path(id)), 1);
  for (int i = 0; i < 8; ++i) {
    const FetchResult r = c.result(std::to_string(i));
    ASSERT_FALSE(r.error) << error_text(r);
    EXPECT_EQ(r.body, tile_bytes(id));
    EXPECT_EQ(c.calls(std::to_string(i)), 1);
  }
  EXPECT_EQ(fetcher->stats().merged, 7u);

  // A request also joins a transfer that waits for its retry.
  const std::string target = "/fault/503ra1*1/a/0/0/0";
  Collector d;
  fetcher->submit(get(server->base_url() + target), d.callback("first"));
  ASSERT_TRUE(wait_until([&] { return server->attempts(target) == 1; }));
  fetcher->submit(get(server->base_url() + target), d.callback("second"));
  ASSERT_TRUE(d.wait_for(2));
  EXPECT_EQ(server->attempts(target), 2);
  for (const char* tag : {"first", "second"}) {
    EXPECT_EQ(d.result(tag).status, 200) << error_text(d.result(tag));
    EXPECT_EQ(d.result(tag).attempts, 2);
    EXPECT_EQ(d.result(tag).body, tile_bytes({0, 0, 0}));
  }
}

TEST(Fetcher, CancellingAQueuedRequestNeverContactsTheServer) {
  auto server = start_server();
  FetcherOptions o = quick_options();
  o.max_in_flight = 1;
  auto fetcher = make_fetcher(o);
  Collector c;
  Blocker blocker(*fetcher, *server, c);
  const std::string target = "/a/1/0/0?queued";
  const auto h = fetcher->submit(get(server->base_url() + target), c.callback("queued"));
  fetcher->cancel(h);
  ASSERT_TRUE(c.wait_for(1, 2000ms));
  EXPECT_EQ(c.order().front(), "queued");
  const FetchResult r = c.result("queued");
  EXPECT_TRUE(r.cancelled);
  ASSERT_TRUE(r.error);
  EXPECT_EQ(r.error->code, vts::ErrorCode::cancelled);
  EXPECT_EQ(r.attempts, 0);
  fetcher->cancel(h);  // a second cancel is ignored

  blocker.release();
  ASSERT_TRUE(c.wait_for(2, 2000ms));
  // The slot is free again; a later request goes through while the cancelled one never went out.
  EXPECT_EQ(fetch(*fetcher, get(server->base_url() + "/a/0/0/0")).status, 200);
  EXPECT_EQ(server->attempts(target), 0);
  EXPECT_EQ(c.calls("queued"), 1);
  const Fetcher::Stats s = fetcher->stats();
  EXPECT_EQ(s.cancelled, 2u);
  EXPECT_EQ(s.in_flight, 0u);
  EXPECT_EQ(s.queued, 0u);
}

TEST(Fetcher, CancellingAStalledTransferAbortsItPromptly) {
  auto server = start_server();
  FetcherOptions o = quick_options();
  o.request_timeout = 30000ms;
  auto fetcher = make_fetcher(o);
  const std::string target = "/fault/stall/a/0/0/0";
  auto promise = std::make_shared<std::promise<FetchResult>>();
  auto future = promise->get_future();
  const auto h = fetcher->submit(get(server->base_url() + target),
                                 [promise](FetchResult&& r) { promise->set_value(std::move(r)); });
  ASSERT_TRUE(wait_until([&] { return server->attempts(target) == 1; }));
  const auto start = Clock::now();
  fetcher->cancel(h);
  ASSERT_EQ(future.wait_for(2s), std::future_status::ready);
  EXPECT_LT(Clock::now() - start, 1s);
  const FetchResult r = future.get();
  EXPECT_TRUE(r.cancelled);
  EXPECT_EQ(r.attempts, 1);
  EXPECT_EQ(fetcher->stats().in_flight, 0u);
  EXPECT_EQ(server->attempts(target), 1);
}

TEST(Fetcher, CancellingARequestWaitingToRetryDropsTheRetry) {
  auto server = start_server();
  auto fetcher = make_fetcher();
  // 503 with Retry-After: 1 keeps the transfer waiting a second before its next attempt.
  const std::string target = "/fault/503ra1/a/0/0/0";
  auto promise = std::make_shared<std::promise<FetchResult>>();
  auto future = promise->get_future();
  const auto h = fetcher->submit(get(server->base_url() + target),
                                 [promise](FetchResult&& r) { promise->set_value(std::move(r)); });
  ASSERT_TRUE(wait_until([&] { return server->attempts(target) == 1; }));
  ASSERT_TRUE(wait_until([&] { return fetcher->stats().in_flight == 0; }));  // in its backoff
  fetcher->cancel(h);
  ASSERT_EQ(future.wait_for(500ms), std::future_status::ready);
  EXPECT_TRUE(future.get().cancelled);
  EXPECT_EQ(fetcher->stats().queued, 0u);
  // The retry would have gone out after 1 s: it never does.
  EXPECT_FALSE(wait_until([&] { return server->attempts(target) > 1; }, 1500ms));
}

TEST(Fetcher, DeadlineFailsAStalledTransferAndRemovesIt) {
  auto server = start_server();
  FetcherOptions o = quick_options();
  o.request_timeout = 30000ms;
  o.deadline = 500ms;
  auto fetcher = make_fetcher(o);
  const std::string url = server->base_url() + "/fault/stall/a/0/0/0";
  const auto start = Clock::now();
  const FetchResult r = fetch(*fetcher, get(url));
  const auto took = Clock::now() - start;
  EXPECT_GE(took, 450ms);
  EXPECT_LT(took, 2s);
  ASSERT_TRUE(r.error);
  EXPECT_FALSE(r.cancelled);
  EXPECT_EQ(r.error->code, vts::ErrorCode::io);
  EXPECT_NE(r.error->message.find(url + ": no answer within the deadline of 500 ms"),
            std::string::npos)
      << r.error->message;
  const Fetcher::Stats s = fetcher->stats();
  EXPECT_EQ(s.expired, 1u);
  EXPECT_EQ(s.failed, 1u);
  EXPECT_EQ(s.in_flight, 0u);
  EXPECT_EQ(s.queued, 0u);
  EXPECT_EQ(server->attempts("/fault/stall/a/0/0/0"), 1);
  // The fetcher goes on: the next request is served.
  EXPECT_EQ(fetch(*fetcher, get(server->base_url() + "/a/0/0/0")).status, 200);
}

TEST(Fetcher, DeadlineCoversRetriesAndTheirBackoff) {
  auto server = start_server();
  FetcherOptions o = quick_options();
  o.max_attempts = 1000;
  o.deadline = 400ms;
  auto fetcher = make_fetcher(o);
  const auto start = Clock::now();
  const FetchResult r = fetch(*fetcher, get(server->base_url() + "/fault/500/a/0/0/0"));
  EXPECT_LT(Clock::now() - start, 2s);
  ASSERT_TRUE(r.error);
  EXPECT_GT(r.attempts, 1);
  EXPECT_NE(r.error->message.find("deadline of 400 ms"), std::string::npos) << r.error->message;
  EXPECT_EQ(fetcher->stats().expired, 1u);
}

TEST(Fetcher, AGroupAtItsCapWaitsWhileOtherGroupsStart) {
  auto server = start_server();
  FetcherOptions o = quick_options();
  o.request_timeout = 30000ms;
  o.max_in_flight = 8;
  o.max_in_flight_per_group = 2;
  Collector c;  // outlives the fetcher, whose destruction cancels the rest into it
  auto fetcher = make_fetcher(o);
  std::vector<Fetcher::Handle> slow;
  const auto stall = [](int i) { return "/fault/stall/a/0/0/0?g=" + std::to_string(i); };
  for (int i = 0; i < 6; ++i) {
    FetchRequest r = get(server->base_url() + stall(i), /*level=*/-1);  // before anything else
    r.group = "slow";
    slow.push_back(fetcher->submit(std::move(r), c.callback("slow " + std::to_string(i))));
  }
  ASSERT_TRUE(wait_until([&] { return fetcher->stats().in_flight == 2; }));
  // A request of another group starts at once and is served while the slow group waits.
  FetchRequest other = get(server->base_url() + "/a/1/0/0");
  other.group = "other";
  const FetchResult r = fetch(*fetcher, other, 5s);
  EXPECT_EQ(r.status, 200) << error_text(r);
  const Fetcher::Stats s = fetcher->stats();
  EXPECT_EQ(s.in_flight, 2u);
  EXPECT_EQ(s.queued, 4u);
  int started = 0;
  for (int i = 0; i < 6; ++i) started += server->attempts(stall(i));
  EXPECT_EQ(started, 2);
  // Cancelling one of the group's transfers in flight lets its next one start.
  fetcher->cancel(slow[0]);
  fetcher->cancel(slow[1]);
  EXPECT_TRUE(
      wait_until([&] { return server->attempts(stall(2)) + server->attempts(stall(3)) == 2; }));
  EXPECT_EQ(server->attempts(stall(4)) + server->attempts(stall(5)), 0);
}

TEST(Fetcher, RetriesTransientFailuresUntilTheyPass) {
  auto server = start_server();
  auto fetcher = make_fetcher();
  struct Case {
    std::string spec;
    int attempts;
  };
  const std::vector<Case> cases = {{"drop*2", 3}, {"reset*2", 3},  {"truncate*2", 3}, {"500*2", 3},
                                   {"503*1", 2},  {"429ra1*1", 2}, {"503ra1*1", 2}};
  const vts::TileId id = archive().tiles.back();
  Collector c;
  const auto start = Clock::now();
  std::map<std::string, Clock::duration> elapsed;
  std::mutex elapsed_mutex;
  for (const Case& k : cases) {
    FetchCallback done = c.callback(k.spec);
    fetcher->submit(get(server->base_url() + "/fault/" + k.spec + tile_path(id)),
                    [&, done, spec = k.spec](FetchResult&& r) {
                      {
                        std::lock_guard lock(elapsed_mutex);
                        elapsed[spec] = Clock::now() - start;
                      }
                      done(std::move(r));
                    });
  }
  ASSERT_TRUE(c.wait_for(cases.size()));
  std::uint64_t retries = 0;
  for (const Case& k : cases) {
    const FetchResult r = c.result(k.spec);
    ASSERT_FALSE(r.error) << k.spec << ": " << error_text(r);
    EXPECT_EQ(r.status, 200) << k.spec;
    EXPECT_EQ(r.body, tile_bytes(id)) << k.spec;
    EXPECT_EQ(server->attempts("/fault/" + k.spec + tile_path(id)), k.attempts) << k.spec;
    // libcurl itself resends once, on a fresh connection, a request whose reused keep-alive
    // connection dies before any response byte (drop, reset); that resend is not our attempt.
    const bool no_byte_back = k.spec.starts_with("drop") || k.spec.starts_with("reset");
    EXPECT_LE(r.attempts, k.attempts) << k.spec;
    EXPECT_GE(r.attempts, no_byte_back ? 2 : k.attempts) << k.spec;
    retries += std::uint64_t(r.attempts - 1);
  }
  // Retry-After: 1 is the minimum delay before the retry.
  std::lock_guard lock(elapsed_mutex);
  EXPECT_GE(elapsed["503ra1*1"], 1s);
  EXPECT_GE(elapsed["429ra1*1"], 1s);
  const Fetcher::Stats s = fetcher->stats();
  EXPECT_EQ(s.retried, retries);
  EXPECT_EQ(s.started, cases.size() + retries);
  EXPECT_EQ(s.succeeded, cases.size());
}

TEST(Fetcher, ReturnsClientErrorsWithoutRetrying) {
  auto server = start_server();
  auto fetcher = make_fetcher();
  FetchResult r = fetch(*fetcher, get(server->base_url() + "/fault/404/a/0/0/0"));
  EXPECT_FALSE(r.error) << error_text(r);
  EXPECT_EQ(r.status, 404);
  EXPECT_EQ(r.attempts, 1);
  EXPECT_EQ(server->attempts("/fault/404/a/0/0/0"), 1);

  r = fetch(*fetcher, get(server->base_url() + "/a/9/0/0"));  // outside the pyramid
  EXPECT_FALSE(r.error) << error_text(r);
  EXPECT_EQ(r.status, 404);
  EXPECT_EQ(server->attempts("/a/9/0/0"), 1);

  FetchRequest unsatisfiable = get(server->base_url() + "/a.pmtiles");
  unsatisfiable.range = {1u << 30, (1u << 30) + 10};
  r = fetch(*fetcher, unsatisfiable);
  EXPECT_FALSE(r.error) << error_text(r);
  EXPECT_EQ(r.status, 416);
  EXPECT_EQ(r.attempts, 1);
}

TEST(Fetcher, GivesUpAfterMaxAttemptsNamingTheUrl) {
  auto server = start_server();
  FetcherOptions o = quick_options();
  o.max_attempts = 3;
  auto fetcher = make_fetcher(o);
  const std::string url = server->base_url() + "/fault/500/a/0/0/0";
  const FetchResult r = fetch(*fetcher, get(url));
  ASSERT_TRUE(r.error);
  EXPECT_EQ(r.status, 500);
  EXPECT_EQ(r.attempts, 3);
  EXPECT_EQ(server->attempts("/fault/500/a/0/0/0"), 3);
  EXPECT_NE(r.error->message.find(url), std::string::npos) << r.error->message;
  EXPECT_NE(r.error->message.find("HTTP 500 after 3 attempts"), std::string::npos)
      << r.error->message;
  EXPECT_EQ(fetcher->stats().failed, 1u);
}

TEST(Fetcher, TimesOutAttemptsThatGetNoAnswer) {
  auto server = start_server();
  FetcherOptions o = quick_options();
  o.request_timeout = 300ms;
  o.max_attempts = 2;
  auto fetcher = make_fetcher(o);
  const auto start = Clock::now();
  const FetchResult r = fetch(*fetcher, get(server->base_url() + "/fault/stall/a/0/0/0"));
  EXPECT_LT(Clock::now() - start, 5s);
  ASSERT_TRUE(r.error);
  EXPECT_EQ(r.status, 0);
  EXPECT_EQ(r.attempts, 2);
  EXPECT_NE(r.error->message.find("timed out after 2 attempts"), std::string::npos)
      << r.error->message;
  EXPECT_TRUE(wait_until([&] { return server->attempts("/fault/stall/a/0/0/0") == 2; }));
}

TEST(Fetcher, AbortsTransfersSlowerThanTheLowSpeedLimit) {
  auto server = start_server();
  FetcherOptions o = quick_options();
  o.low_speed_bytes = 1024;
  o.low_speed_time = 1s;
  o.max_attempts = 1;
  auto fetcher = make_fetcher(o);
  const auto start = Clock::now();
  const FetchResult r = fetch(*fetcher, get(server->base_url() + "/fault/slow/a/0/0/0"));
  EXPECT_LT(Clock::now() - start, 5s);
  ASSERT_TRUE(r.error);
  EXPECT_NE(r.error->message.find("timed out"), std::string::npos) << r.error->message;
}

// The fetcher moves bytes; checking them is the caller's job (the tile header's XXH3 checksum,
// verified by the cache and the decoder). So a corrupt body arrives as a normal 200.
TEST(Fetcher, DeliversCorruptBodiesAsReceived) {
  auto server = start_server();
  auto fetcher = make_fetcher();
  const vts::TileId id = archive().tiles.back();
  const FetchResult r = fetch(*fetcher, get(server->base_url() + "/fault/corrupt" + tile_path(id)));
  ASSERT_FALSE(r.error) << error_text(r);
  EXPECT_EQ(r.status, 200);
  const std::vector<std::uint8_t> good = tile_bytes(id);
  ASSERT_EQ(r.body.size(), good.size());
  EXPECT_NE(r.body, good);
}

TEST(Fetcher, FailsAtOnceWhenRetryAfterExceedsTheLimit) {
  auto server = start_server();
  FetcherOptions o = quick_options();
  o.max_retry_after = 60s;
  auto fetcher = make_fetcher(o);
  const auto start = Clock::now();
  const FetchResult r = fetch(*fetcher, get(server->base_url() + "/fault/503ra120/a/0/0/0"));
  EXPECT_LT(Clock::now() - start, 1s);
  ASSERT_TRUE(r.error);
  EXPECT_EQ(r.status, 503);
  EXPECT_EQ(r.attempts, 1);
  EXPECT_NE(r.error->message.find("Retry-After 120 s"), std::string::npos) << r.error->message;
  EXPECT_EQ(server->attempts("/fault/503ra120/a/0/0/0"), 1);
}

TEST(Fetcher, RefusesBodiesOverTheSizeLimit) {
  auto server = start_server();
  FetcherOptions o = quick_options();
  o.max_body_bytes = 1000;
  auto fetcher = make_fetcher(o);
  const FetchResult r = fetch(*fetcher, get(server->base_url() + "/a.pmtiles"));
  ASSERT_TRUE(r.error);
  EXPECT_EQ(r.error->code, vts::ErrorCode::too_large);
  EXPECT_EQ(r.attempts, 1);
  EXPECT_TRUE(r.body.empty());
  EXPECT_EQ(server->attempts("/a.pmtiles"), 1);
}

TEST(Fetcher, ServesAThousandRandomRequestsByteExactWithConsistentStats) {
  auto server = start_server();
  FetcherOptions o = quick_options();
  o.max_in_flight = 32;
  auto fetcher = make_fetcher(o);
  std::mt19937 rng(42);
  const auto& tiles = archive().tiles;
  std::uniform_int_distribution<std::size_t> pick(0, tiles.size() - 1);
  std::uniform_real_distribution<double> urgency(0, 1);
  constexpr int kRequests = 1000;
  std::vector<vts::TileId> asked(kRequests);
  std::vector<FetchResult> results(kRequests);
  std::atomic<int> done{0};
  std::uint64_t expected_bytes = 0;
  for (int i = 0; i < kRequests; ++i) {
    asked[i] = tiles[pick(rng)];
    expected_bytes += tile_bytes(asked[i]).size();
    // A unique query per request so that every one is its own transfer.
    fetcher->submit(get(server->base_url() + tile_path(asked[i]) + "?n=" + std::to_string(i),
                        asked[i].z, urgency(rng)),
                    [&, i](FetchResult&& r) {
                      results[i] = std::move(r);
                      done.fetch_add(1);
                    });
  }
  ASSERT_TRUE(wait_until([&] { return done.load() == kRequests; }, 30000ms));
  for (int i = 0; i < kRequests; ++i) {
    ASSERT_FALSE(results[i].error) << i << ": " << error_text(results[i]);
    ASSERT_EQ(results[i].status, 200) << i;
    ASSERT_EQ(results[i].body, tile_bytes(asked[i])) << i;
  }
  const Fetcher::Stats s = fetcher->stats();
  EXPECT_EQ(s.submitted, std::uint64_t(kRequests));
  EXPECT_EQ(s.merged, 0u);
  EXPECT_EQ(s.started, std::uint64_t(kRequests));
  EXPECT_EQ(s.retried, 0u);
  EXPECT_EQ(s.succeeded, std::uint64_t(kRequests));
  EXPECT_EQ(s.failed, 0u);
  EXPECT_EQ(s.cancelled, 0u);
  EXPECT_EQ(s.in_flight, 0u);
  EXPECT_EQ(s.queued, 0u);
  EXPECT_EQ(s.bytes, expected_bytes);
}

TEST(Fetcher, DestructionCallsEveryPendingCallbackOnceAsCancelled) {
  auto server = start_server();
  FetcherOptions o = quick_options();
  o.max_in_flight = 2;
  o.request_timeout = 30000ms;
  auto fetcher = make_fetcher(o);
  Collector c;
  for (int i = 0; i < 2; ++i) {
    fetcher->submit(get(server->base_url() + "/fault/stall/a/0/0/0?s=" + std::to_string(i), -1),
                    c.callback("stall " + std::to_string(i)));
  }
  ASSERT_TRUE(wait_until([&] {
    return server->attempts("/fault/stall/a/0/0/0?s=0") == 1 &&
           server->attempts("/fault/stall/a/0/0/0?s=1") == 1;
  }));
  constexpr int kQueued = 30;
  for (int i = 0; i < kQueued; ++i) {
    // Every third one merges with its predecessor's URL.
    const int n = i - (i % 3 == 2 ? 1 : 0);
    fetcher->submit(get(server->base_url() + "/a/0/0/0?q=" + std::to_string(n)),
                    c.callback("queued " + std::to_string(i)));
  }
  // A callback that submits from its cancellation: the new request is cancelled too.
  Fetcher* raw = fetcher.get();
  FetchCallback inner_done = c.callback("submitted during shutdown");
  FetchCallback outer_done = c.callback("reentrant");
  const std::string inner_url = server->base_url() + "/a/0/0/0?r2";
  fetcher->submit(get(server->base_url() + "/a/0/0/0?r"),
                  [raw, inner_url, inner_done, outer_done](FetchResult&& r) {
                    raw->submit(get(inner_url), inner_done);
                    outer_done(std::move(r));
                  });

  const auto start = Clock::now();
  fetcher.reset();
  EXPECT_LT(Clock::now() - start, 2s);
  ASSERT_TRUE(c.wait_for(2 + kQueued + 2, 0ms));
  for (const std::string& tag : c.order()) {
    EXPECT_EQ(c.calls(tag), 1) << tag;
    EXPECT_TRUE(c.result(tag).cancelled) << tag;
  }
  EXPECT_EQ(c.order().size(), std::size_t(2 + kQueued + 2));
}

TEST(Fetcher, CallbacksMaySubmitAndCancelRequests) {
  auto server = start_server();
  auto fetcher = make_fetcher();
  constexpr int kChain = 20;
  std::promise<int> finished;
  std::atomic<int> ok{0};
  std::function<void(int)> next = [&](int i) {
    fetcher->submit(
        get(server->base_url() + "/a/1/1/0?chain=" + std::to_string(i)), [&, i](FetchResult&& r) {
          if (!r.error && r.body == tile_bytes({1, 1, 0})) ok.fetch_add(1);
          // Submit-and-cancel from inside a callback as well.
          fetcher->cancel(fetcher->submit(get(server->base_url() + "/a/0/0/0?x"), [](auto&&) {}));
          if (i + 1 < kChain) {
            next(i + 1);
          } else {
            finished.set_value(i);
          }
        });
  };
  next(0);
  auto future = finished.get_future();
  ASSERT_EQ(future.wait_for(20s), std::future_status::ready);
  EXPECT_EQ(future.get(), kChain - 1);
  EXPECT_EQ(ok.load(), kChain);
}

TEST(Fetcher, BadUrlsFailCleanly) {
  FetcherOptions o = quick_options();
  o.max_attempts = 2;
  auto fetcher = make_fetcher(o);

  FetchResult r = fetch(*fetcher, get("http://127.0.0.1:1/x"));
  ASSERT_TRUE(r.error);
  EXPECT_EQ(r.status, 0);
  EXPECT_EQ(r.attempts, 2);
  EXPECT_NE(r.error->message.find("GET http://127.0.0.1:1/x: connection refused after 2 attempts"),
            std::string::npos)
      << r.error->message;

  for (const char* url : {"not a url", "", "ftp://127.0.0.1/x", "file:///etc/passwd",
                          "http://[::1/x", "http://example.invalid\r\n/x"}) {
    r = fetch(*fetcher, get(url));
    ASSERT_TRUE(r.error) << url;
    EXPECT_EQ(r.status, 0) << url;
    EXPECT_NE(r.error->message.find(url), std::string::npos) << r.error->message;
  }

  FetchRequest backwards = get("http://127.0.0.1:1/x");
  backwards.range = {10, 5};
  r = fetch(*fetcher, backwards);
  ASSERT_TRUE(r.error);
  EXPECT_EQ(r.error->code, vts::ErrorCode::invalid_argument);
  EXPECT_EQ(r.attempts, 0);

  const Fetcher::Stats s = fetcher->stats();
  EXPECT_EQ(s.submitted, s.failed);
}

TEST(FaultServer, CountsAttemptsPerTargetAndResets) {
  auto server = start_server();
  auto fetcher = make_fetcher();
  EXPECT_EQ(fetch(*fetcher, get(server->base_url() + "/a/0/0/0?k=1")).status, 200);
  EXPECT_EQ(fetch(*fetcher, get(server->base_url() + "/fault/bogus/a/0/0/0")).status, 400);
  EXPECT_EQ(server->attempts("/a/0/0/0?k=1"), 1);
  FetchResult stats = fetch(*fetcher, get(server->base_url() + "/_stats"));
  const std::string json(stats.body.begin(), stats.body.end());
  EXPECT_NE(json.find("\"/a/0/0/0?k=1\":1"), std::string::npos) << json;
  EXPECT_EQ(fetch(*fetcher, get(server->base_url() + "/_reset")).status, 200);
  EXPECT_EQ(server->attempts("/a/0/0/0?k=1"), 0);
}

}  // namespace
