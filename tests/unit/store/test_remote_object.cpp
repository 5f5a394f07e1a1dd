// The remote byte source and whole-object reads over plain HTTP against a real server on
// loopback: the fault-injecting one of the client's tests (tests/integration/fault_server.hpp),
// which serves one archive by Range and fails exactly as its URL says.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <chrono>
#include <thread>

#include "fault_server.hpp"
#include "vts/archive/pmtiles.hpp"
#include "vts/store/store.hpp"
#include "vts/test/archive.hpp"
#include "vts/test/temp_dir.hpp"

namespace vts::store {
namespace {

using namespace std::chrono_literals;

// One synthetic archive for every test here (built once: the build is the slow part).
const vts::test::OpenedArchive& local_archive() {
  static vts::test::TempDir dir("vts-store-remote");
  static const vts::test::OpenedArchive a = [] {
    return vts::test::build_and_open(vts::test::synthetic_options(dir / "a.pmtiles", 4000, 3000));
  }();
  return a;
}

std::unique_ptr<vts::test::FaultServer> start_fault_server() {
  auto s = vts::test::FaultServer::start(local_archive().path, "a");
  if (!s) throw std::runtime_error(s.error().to_string());
  return std::move(*s);
}

// Options with quick retries; each test sets what it measures.
StoreOptions quick() {
  StoreOptions o;
  o.retry_backoff = 10ms;
  o.connect_timeout = 2000ms;
  o.timeout = 10000ms;
  return o;
}

std::uint64_t requests(const StoreOptions& o) {
  return o.counters->requests.load();
}

class RemoteObject : public ::testing::Test {
 protected:
  std::unique_ptr<vts::test::FaultServer> server_ = start_fault_server();
  std::string url(const std::string& path) const { return server_->base_url() + path; }
};

TEST_F(RemoteObject, OpeningAnArchiveCostsOneRequestAndEveryTileReadsAsTheLocalFile) {
  const StoreOptions o = quick();
  auto source = open_object(url("/a.pmtiles"), o);
  ASSERT_TRUE(source) << source.error().to_string();
  EXPECT_EQ((*source)->size(), local_archive().reader->size());
  ASSERT_GT((*source)->size(), 2 * o.first_block) << "tiles must lie beyond the first block";
  EXPECT_EQ((*source)->name(), url("/a.pmtiles"));
  auto reader = archive::Reader::open_source(std::move(*source));
  ASSERT_TRUE(reader) << reader.error().to_string();
  EXPECT_EQ(requests(o), 1u) << "the header, root directory and metadata lie in the first block";
  EXPECT_EQ((*reader)->version(), local_archive().reader->version());
  const auto& tiles = local_archive().tiles;
  ASSERT_GT(tiles.size(), 10u);
  for (const TileId& id : tiles) {
    auto remote = (*reader)->get(id);
    ASSERT_TRUE(remote) << id.to_string() << ": " << remote.error().to_string();
    EXPECT_EQ(*remote, *local_archive().reader->get(id)) << id.to_string();
  }
  // Directories are cached: a tile read again is exactly one more GET, unless it lies within
  // the first block (no request at all).
  const archive::Header& h = (*reader)->header();
  int beyond = 0;
  for (const TileId& id : tiles) {
    auto e = (*reader)->find_entry(archive::zxy_to_tile_id(id.z, id.x, id.y));
    ASSERT_TRUE(e);
    const bool in_first_block = h.tile_data_offset + e->offset + e->length <= o.first_block;
    const std::uint64_t before = requests(o);
    ASSERT_TRUE((*reader)->get(id));
    EXPECT_EQ(requests(o), before + (in_first_block ? 0 : 1)) << id.to_string();
    beyond += in_first_block ? 0 : 1;
  }
  EXPECT_GE(beyond, 3);
  EXPECT_EQ(o.counters->retries.load(), 0u);
}

TEST_F(RemoteObject, ThreadsReadingDifferentTilesAtOnceAllGetTheirBytes) {
  const StoreOptions o = quick();
  auto source = open_object(url("/a.pmtiles"), o);
  ASSERT_TRUE(source);
  auto reader = archive::Reader::open_source(std::move(*source));
  ASSERT_TRUE(reader);
  const auto& tiles = local_archive().tiles;
  std::atomic<int> mismatches{0};
  std::vector<std::thread> threads;
  for (std::size_t t = 0; t < 6; ++t) {
    threads.emplace_back([&, t] {
      for (std::size_t i = t; i < tiles.size(); i += 3) {  // every tile read by two threads
        auto r = (*reader)->get(tiles[i]);
        if (!r || *r != *local_archive().reader->get(tiles[i])) ++mismatches;
      }
    });
  }
  for (auto& t : threads) t.join();
  EXPECT_EQ(mismatches.load(), 0);
}

TEST_F(RemoteObject, EqualConcurrentReadsShareOneGet) {
  StoreOptions o = quick();
  o.first_block = 1;  // the "slow" fault sends a byte per 200 ms: keep the open short
  auto source = open_object(url("/fault/slow/a.pmtiles"), o);
  ASSERT_TRUE(source) << source.error().to_string();
  ASSERT_EQ(requests(o), 1u);
  // 6 bytes take ~1.2 s to arrive: the other readers join the first one's GET meanwhile.
  constexpr int kReaders = 8;
  std::vector<std::vector<std::uint8_t>> got(kReaders, std::vector<std::uint8_t>(6));
  std::vector<std::thread> threads;
  std::atomic<int> failures{0};
  for (int i = 0; i < kReaders; ++i) {
    threads.emplace_back([&, i] {
      if (!(*source)->read(1000, got[static_cast<std::size_t>(i)])) ++failures;
    });
  }
  for (auto& t : threads) t.join();
  EXPECT_EQ(failures.load(), 0);
  EXPECT_EQ(requests(o), 2u) << "one GET for all " << kReaders << " readers";
  EXPECT_EQ(o.counters->coalesced.load(), static_cast<std::uint64_t>(kReaders - 1));
  const auto all = vts::test::read_all(*local_archive().reader);
  const std::vector<std::uint8_t> want(all.begin() + 1000, all.begin() + 1006);
  for (const auto& g : got) EXPECT_EQ(g, want);
}

TEST_F(RemoteObject, FiveHundredsAreRetriedThenTheObjectOpens) {
  const StoreOptions o = quick();  // 2 retries
  auto source = open_object(url("/fault/503*2/a.pmtiles"), o);
  ASSERT_TRUE(source) << source.error().to_string();
  EXPECT_EQ(server_->attempts("/fault/503*2/a.pmtiles"), 3);
  EXPECT_EQ(requests(o), 3u);
  EXPECT_EQ(o.counters->retries.load(), 2u);
}

TEST_F(RemoteObject, DroppedAndTruncatedAnswersAreRetried) {
  for (const char* fault : {"drop*1", "reset*1", "truncate*1"}) {
    const StoreOptions o = quick();
    const std::string path = std::string("/fault/") + fault + "/a.pmtiles";
    auto source = open_object(url(path), o);
    ASSERT_TRUE(source) << fault << ": " << source.error().to_string();
    EXPECT_EQ(server_->attempts(path), 2) << fault;
    auto reader = archive::Reader::open_source(std::move(*source));
    ASSERT_TRUE(reader) << fault << ": " << reader.error().to_string();
    EXPECT_EQ((*reader)->version(), local_archive().reader->version());
  }
}

TEST_F(RemoteObject, AStoreThatKeepsFailingIsUnavailableNamingTheUrl) {
  StoreOptions o = quick();
  o.retries = 3;
  auto source = open_object(url("/fault/503/a.pmtiles"), o);
  ASSERT_FALSE(source);
  EXPECT_EQ(source.error().code, ErrorCode::unavailable);
  EXPECT_NE(source.error().message.find(url("/fault/503/a.pmtiles")), std::string::npos)
      << source.error().message;
  EXPECT_NE(source.error().message.find("HTTP 503"), std::string::npos);
  EXPECT_EQ(server_->attempts("/fault/503/a.pmtiles"), 4);
}

TEST_F(RemoteObject, AServerThatNeverAnswersIsUnavailableWithinTheTimeouts) {
  StoreOptions o = quick();
  o.timeout = 300ms;
  o.retries = 1;
  const auto start = std::chrono::steady_clock::now();
  auto source = open_object(url("/fault/stall/a.pmtiles"), o);
  const auto took = std::chrono::steady_clock::now() - start;
  ASSERT_FALSE(source);
  EXPECT_EQ(source.error().code, ErrorCode::unavailable) << source.error().to_string();
  EXPECT_EQ(server_->attempts("/fault/stall/a.pmtiles"), 2);
  EXPECT_GE(took, 600ms);
  EXPECT_LT(took, 5s) << "two 300 ms attempts and a 10 ms backoff";
}

TEST_F(RemoteObject, ARefusedConnectionIsUnavailable) {
  // A port that was just free: bound, then closed, so nothing listens there.
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  ASSERT_GE(fd, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ASSERT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr), 0);
  socklen_t len = sizeof addr;
  ASSERT_EQ(::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len), 0);
  ::close(fd);
  const std::string closed = "http://127.0.0.1:" + std::to_string(ntohs(addr.sin_port)) + "/a";
  const StoreOptions o = quick();
  for (auto r :
       {open_object(closed, o).ok(), object_etag(closed, o).ok(), get_object(closed, o, 10).ok()}) {
    EXPECT_FALSE(r);
  }
  auto source = open_object(closed, o);
  ASSERT_FALSE(source);
  EXPECT_EQ(source.error().code, ErrorCode::unavailable);
  EXPECT_NE(source.error().message.find(closed), std::string::npos);
}

TEST_F(RemoteObject, MissingObjectsAreNotFoundNamingTheUrl) {
  const StoreOptions o = quick();
  for (const std::string& path :
       {std::string("/nothing.pmtiles"), std::string("/fault/404/a.pmtiles")}) {
    auto source = open_object(url(path), o);
    ASSERT_FALSE(source) << path;
    EXPECT_EQ(source.error().code, ErrorCode::not_found) << source.error().to_string();
    EXPECT_NE(source.error().message.find(url(path)), std::string::npos);
  }
  auto etag = object_etag(url("/nothing.pmtiles"), o);
  ASSERT_FALSE(etag);
  EXPECT_EQ(etag.error().code, ErrorCode::not_found);
}

TEST_F(RemoteObject, WholeObjectsAreReadUpToTheirLimit) {
  const StoreOptions o = quick();
  const auto all = vts::test::read_all(*local_archive().reader);
  auto whole = get_object(url("/a.pmtiles"), o, all.size());
  ASSERT_TRUE(whole) << whole.error().to_string();
  EXPECT_EQ(std::vector<std::uint8_t>(whole->begin(), whole->end()), all);
  auto over = get_object(url("/a.pmtiles"), o, all.size() - 1);
  ASSERT_FALSE(over);
  EXPECT_EQ(over.error().code, ErrorCode::too_large);
  EXPECT_NE(over.error().message.find(url("/a.pmtiles")), std::string::npos);
}

TEST_F(RemoteObject, HttpPrefixesCannotBeListed) {
  auto list = list_objects(url("/"), quick());
  ASSERT_FALSE(list);
  EXPECT_EQ(list.error().code, ErrorCode::unsupported);
  EXPECT_NE(list.error().message.find("s3://"), std::string::npos);
}

TEST_F(RemoteObject, ReadsOutsideTheObjectAreRefusedWithoutARequest) {
  const StoreOptions o = quick();
  auto source = open_object(url("/a.pmtiles"), o);
  ASSERT_TRUE(source);
  std::vector<std::uint8_t> buf(10);
  Status s = (*source)->read((*source)->size() - 5, buf);
  ASSERT_FALSE(s);
  EXPECT_EQ(s.error().code, ErrorCode::invalid_argument);
  EXPECT_TRUE((*source)->read(0, std::span<std::uint8_t>{}));
  EXPECT_EQ(requests(o), 1u);
}

}  // namespace
}  // namespace vts::store
