// The client stack's benchmark (driven by bench/client_bench.sh):
//   cold   every tile of a tileset through the full client — fetch, checksum, disk cache write,
//          decode — into an empty cache; wall time until the last tile is decoded and written
//   disk   a get() of each tile from a new cache over the same folder (RAM off): latency of a
//          disk hit (SQLite read + checksum), per get, p50/p99
//   ram    the same gets again from a RAM cache holding every tile: latency of a RAM hit
//   fetch  (breakdown) every tile fetched through the source alone: no checksum, cache or decode
//   decode (breakdown) every payload decoded from memory by --decode-threads threads: the floor
//          the decode step puts under `cold` on this machine
// Prints one JSON object.
//
//   vts_client_bench URL --cache-dir DIR [--in-flight N] [--decode-threads N]
#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "vts/client/tile_client.hpp"
#include "vts/protocol/codec.hpp"

using namespace vts::client;
using Clock = std::chrono::steady_clock;

namespace {

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, std::size_t(p * double(v.size())))];
}

int fail(const std::string& message) {
  std::fprintf(stderr, "vts_client_bench: %s\n", message.c_str());
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  std::string url, dir;
  std::size_t in_flight = 32;
  int decode_threads = 2;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--cache-dir" && i + 1 < argc) {
      dir = argv[++i];
    } else if (a == "--in-flight" && i + 1 < argc) {
      in_flight = std::stoul(argv[++i]);
    } else if (a == "--decode-threads" && i + 1 < argc) {
      decode_threads = std::stoi(argv[++i]);
    } else if (url.empty()) {
      url = a;
    } else {
      return fail("unexpected argument '" + a + "'");
    }
  }
  if (url.empty() || dir.empty()) return fail("usage: vts_client_bench URL --cache-dir DIR");
  std::filesystem::remove_all(dir);

  SourceOptions so;
  so.fetcher.max_in_flight = in_flight;
  auto opened = open_source(url, so);
  if (!opened) return fail(opened.error().to_string());
  std::shared_ptr<TileSource> source = std::move(*opened);
  const auto& g = source->info().info.geometry;
  std::vector<vts::TileId> ids;
  for (int z = 0; z <= g.max_zoom(); ++z)
    for (std::uint32_t y = 0; y < g.tiles_y(std::uint8_t(z)); ++y)
      for (std::uint32_t x = 0; x < g.tiles_x(std::uint8_t(z)); ++x)
        ids.push_back(vts::TileId{std::uint8_t(z), x, y});

  // Breakdown, fetch alone: every tile through the source (the fetcher), nothing else.
  double fetch_s = 0;
  std::vector<std::vector<std::uint8_t>> payloads(ids.size());
  {
    std::mutex m;
    std::condition_variable cv;
    std::size_t done = 0, failed = 0;
    const auto t0 = Clock::now();
    for (std::size_t i = 0; i < ids.size(); ++i)
      source->fetch(SourceRequest{ids[i], {}, ids[i].z, 0}, [&, i](SourceTile&& t) {
        std::lock_guard lock(m);
        if (t.kind == SourceTile::Kind::ok)
          payloads[i] = std::move(t.payload);
        else
          ++failed;
        ++done;
        cv.notify_one();
      });
    std::unique_lock lock(m);
    if (!cv.wait_for(lock, std::chrono::seconds(120), [&] { return done == ids.size(); }))
      return fail("fetch-only phase timed out");
    fetch_s = std::chrono::duration<double>(Clock::now() - t0).count();
    if (failed) return fail(std::to_string(failed) + " tiles failed in the fetch-only phase");
  }
  // Breakdown, decode alone: the payloads above, from memory, on decode_threads threads.
  double decode_s = 0;
  {
    std::atomic<std::size_t> next{0}, bad{0};
    const auto t0 = Clock::now();
    std::vector<std::thread> pool;
    for (int t = 0; t < decode_threads; ++t)
      pool.emplace_back([&] {
        for (std::size_t i; (i = next.fetch_add(1)) < payloads.size();)
          if (!vts::decode_tile(payloads[i])) ++bad;
      });
    for (auto& t : pool) t.join();
    decode_s = std::chrono::duration<double>(Clock::now() - t0).count();
    if (bad) return fail(std::to_string(bad.load()) + " tiles did not decode");
  }
  payloads.clear();

  // Cold: every tile through fetch + verify + disk write + decode.
  double cold_s = 0;
  std::uint64_t bytes = 0;
  {
    TileClientOptions o;
    o.cache.disk = DiskCacheOptions{};
    o.cache.disk->dir = dir;
    o.cache.disk->max_bytes = 64ull << 30;
    o.decode_threads = decode_threads;
    o.decoded_bytes = 256u << 20;
    auto client = TileClient::create(source, o);
    if (!client) return fail(client.error().to_string());
    const auto t0 = Clock::now();
    for (const auto id : ids) (*client)->request(id, 0);
    std::size_t done = 0, decoded = 0;
    std::vector<TileEvent> events;
    while (done < ids.size()) {
      auto e = (*client)->wait(std::chrono::seconds(30));
      if (!e) return fail("timed out after " + std::to_string(done) + " tiles");
      ++done;
      if (e->kind == TileEvent::Kind::decoded) ++decoded;
    }
    if (auto st = (*client)->cache().flush(); !st) return fail(st.error().to_string());
    cold_s = std::chrono::duration<double>(Clock::now() - t0).count();
    if (decoded != ids.size())
      return fail(std::to_string(ids.size() - decoded) + " tiles not decoded");
    bytes = (*client)->cache().disk()->stats().bytes;
  }

  // Disk hits: one get at a time, RAM off.
  std::vector<double> disk_us, ram_us;
  {
    TileCacheOptions o;
    o.ram_bytes = 0;
    o.disk = DiskCacheOptions{};
    o.disk->dir = dir;
    o.disk->max_bytes = 64ull << 30;
    o.revalidate_after = std::chrono::hours(24);
    auto cache = TileCache::create(source, o);
    if (!cache) return fail(cache.error().to_string());
    std::mutex m;
    std::condition_variable cv;
    for (const auto id : ids) {
      bool got = false;
      bool from_disk = false;
      const auto t0 = Clock::now();
      (*cache)->get(id, {}, [&](PayloadResult&& r) {
        std::lock_guard lock(m);
        got = true;
        from_disk = r.kind == PayloadResult::Kind::ok && r.from == PayloadResult::From::disk;
        cv.notify_one();
      });
      std::unique_lock lock(m);
      cv.wait(lock, [&] { return got; });
      disk_us.push_back(std::chrono::duration<double, std::micro>(Clock::now() - t0).count());
      if (!from_disk) return fail("tile " + id.to_string() + " was not a disk hit");
    }
  }
  // RAM hits: a cache that has every tile in RAM.
  {
    TileCacheOptions o;
    o.ram_bytes = std::size_t(bytes * 2 + (64u << 20));
    o.revalidate_after = std::chrono::hours(24);
    o.disk = DiskCacheOptions{};
    o.disk->dir = dir;
    o.disk->max_bytes = 64ull << 30;
    auto cache = TileCache::create(source, o);
    if (!cache) return fail(cache.error().to_string());
    std::mutex m;
    std::condition_variable cv;
    std::size_t loaded = 0;
    for (const auto id : ids)
      (*cache)->get(id, {}, [&](PayloadResult&&) {
        std::lock_guard lock(m);
        ++loaded;
        cv.notify_one();
      });
    {
      std::unique_lock lock(m);
      cv.wait(lock, [&] { return loaded == ids.size(); });
    }
    for (int round = 0; round < 5; ++round)
      for (const auto id : ids) {
        bool hit = false;
        const auto t0 = Clock::now();
        (*cache)->get(id, {}, [&](PayloadResult&& r) { hit = r.from == PayloadResult::From::ram; });
        ram_us.push_back(std::chrono::duration<double, std::micro>(Clock::now() - t0).count());
        if (!hit) return fail("tile " + id.to_string() + " was not a RAM hit");
      }
  }
  std::printf(
      "{\"tiles\": %zu, \"bytes\": %llu, \"cold_s\": %.3f, \"fetch_only_s\": %.3f, "
      "\"decode_only_s\": %.3f, \"disk_hit_p50_us\": %.1f, "
      "\"disk_hit_p99_us\": %.1f, \"ram_hit_p50_us\": %.2f, \"ram_hit_p99_us\": %.2f}\n",
      ids.size(), (unsigned long long)bytes, cold_s, fetch_s, decode_s, percentile(disk_us, 0.5),
      percentile(disk_us, 0.99), percentile(ram_us, 0.5), percentile(ram_us, 0.99));
  return 0;
}
