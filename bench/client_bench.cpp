// The client stack's benchmark (driven by bench/client_bench.sh):
//   cold   every tile of a tileset through the full client — fetch, checksum, disk cache write,
//          decode — into an empty cache; wall time until the last tile is decoded and written
//   disk   a get() of each tile from a new cache over the same folder (RAM off): latency of a
//          disk hit (SQLite read + checksum), per get, p50/p99
//   ram    the same gets again from a RAM cache holding every tile: latency of a RAM hit
//   fetch  (breakdown) every tile fetched through the source alone: no checksum, cache or decode
//   decode (breakdown) every payload decoded from memory by --decode-threads threads: the floor
//          the decode step puts under `cold` on this machine
// Besides wall time, each of fetch, decode and cold reports the CPU seconds it took: this
// process's (user + sys), the server's when --server-pid names it (read from /proc), and for cold
// the split by thread name (vts-decode, vts-disk, vts-fetch, ...), so that a reader sees how much
// CPU the work needs on this machine, not only how long it took.
// Prints one JSON object.
//
//   vts_client_bench URL --cache-dir DIR [--in-flight N] [--decode-threads N] [--server-pid PID]
//                    [--phases fetch,decode,cold,disk,ram]
// --phases runs only the named phases (e.g. `--phases cold` under a profiler); decode needs fetch,
// disk and ram need cold.
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <set>
#include <sstream>
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

double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// ---- CPU accounting -----------------------------------------------------------------------------

// user + sys seconds of a /proc/.../stat line (fields 14 and 15, after the "(comm)" field); the
// comm goes to `name` when asked for.
double stat_cpu(const std::string& path, std::string* name = nullptr) {
  std::ifstream in(path);
  std::string line;
  if (!std::getline(in, line)) return 0;
  const auto open = line.find('('), close = line.rfind(')');
  if (open == std::string::npos || close == std::string::npos) return 0;
  if (name) *name = line.substr(open + 1, close - open - 1);
  std::istringstream rest(line.substr(close + 2));
  std::string field;
  unsigned long long utime = 0, stime = 0;
  for (int i = 3; i <= 15 && rest >> field; ++i) {
    if (i == 14) utime = std::stoull(field);
    if (i == 15) stime = std::stoull(field);
  }
  return double(utime + stime) / double(sysconf(_SC_CLK_TCK));
}

double process_cpu() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  auto s = [](const timeval& t) { return double(t.tv_sec) + double(t.tv_usec) * 1e-6; };
  return s(u.ru_utime) + s(u.ru_stime);
}

// Every thread of this process now: tid -> (name, CPU seconds so far).
std::map<std::string, std::pair<std::string, double>> thread_cpu() {
  std::map<std::string, std::pair<std::string, double>> out;
  for (const auto& e : std::filesystem::directory_iterator("/proc/self/task")) {
    std::string name;
    const double cpu = stat_cpu(e.path().string() + "/stat", &name);
    out[e.path().filename().string()] = {name, cpu};
  }
  return out;
}

// CPU of one phase: this process, the server, and this process's threads by name.
struct CpuMeter {
  int server_pid = 0;
  double proc0 = 0, server0 = 0;
  std::map<std::string, std::pair<std::string, double>> threads0;

  double server_cpu() const {
    return server_pid ? stat_cpu("/proc/" + std::to_string(server_pid) + "/stat") : 0;
  }
  void start() {
    proc0 = process_cpu();
    server0 = server_cpu();
    threads0 = thread_cpu();
  }
  // Call before the phase's threads end (a thread gone is not counted).
  std::map<std::string, double> by_thread() const {
    std::map<std::string, double> out;
    for (const auto& [tid, t] : thread_cpu()) {
      auto it = threads0.find(tid);
      out[t.first] += t.second - (it == threads0.end() ? 0 : it->second.second);
    }
    return out;
  }
  double proc() const { return process_cpu() - proc0; }
  double server() const { return server_cpu() - server0; }
};

struct Phase {
  double wall_s = 0, cpu_s = 0, server_cpu_s = 0;
  double first_s = 0, events_s = 0;       // cold: first and last tile event (before the flush)
  std::map<std::string, double> threads;  // cold only
};

std::string json_phase(const char* name, const Phase& p) {
  char buf[256];
  std::snprintf(buf, sizeof buf, "\"%s_s\": %.3f, \"%s_cpu_s\": %.3f, \"%s_server_cpu_s\": %.3f",
                name, p.wall_s, name, p.cpu_s, name, p.server_cpu_s);
  return buf;
}

// ---- phases -------------------------------------------------------------------------------------

struct Setup {
  std::string url, dir;
  std::size_t in_flight = 32;
  int decode_threads = 2;
  int server_pid = 0;
  std::set<std::string> phases{"fetch", "decode", "cold", "disk", "ram"};
  bool runs(const char* p) const { return phases.count(p) > 0; }
};

// Breakdown, fetch alone: every tile through the source (the fetcher), nothing else.
vts::Status fetch_only(TileSource& source, const std::vector<vts::TileId>& ids, CpuMeter& meter,
                       Phase& phase, std::vector<std::vector<std::uint8_t>>& payloads) {
  payloads.assign(ids.size(), {});
  std::mutex m;
  std::condition_variable cv;
  std::size_t done = 0, failed = 0;
  meter.start();
  const auto t0 = Clock::now();
  for (std::size_t i = 0; i < ids.size(); ++i)
    source.fetch(SourceRequest{ids[i], {}, ids[i].z, 0}, [&, i](SourceTile&& t) {
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
    return vts::make_error(vts::ErrorCode::io, "fetch-only phase timed out");
  phase.wall_s = seconds_since(t0);
  phase.cpu_s = meter.proc();
  phase.server_cpu_s = meter.server();
  if (failed)
    return vts::make_error(vts::ErrorCode::io,
                           std::to_string(failed) + " tiles failed in the fetch-only phase");
  return {};
}

// Breakdown, decode alone: the payloads, from memory, on `threads` threads.
vts::Status decode_only(const std::vector<std::vector<std::uint8_t>>& payloads, int threads,
                        CpuMeter& meter, Phase& phase) {
  std::atomic<std::size_t> next{0}, bad{0};
  meter.start();
  const auto t0 = Clock::now();
  std::vector<std::thread> pool;
  for (int t = 0; t < threads; ++t)
    pool.emplace_back([&] {
      for (std::size_t i; (i = next.fetch_add(1)) < payloads.size();)
        if (!vts::decode_tile(payloads[i])) ++bad;
    });
  for (auto& t : pool) t.join();
  phase.wall_s = seconds_since(t0);
  phase.cpu_s = meter.proc();
  phase.server_cpu_s = meter.server();
  if (bad)
    return vts::make_error(vts::ErrorCode::corrupt,
                           std::to_string(bad.load()) + " tiles did not decode");
  return {};
}

// Cold: every tile through fetch + verify + disk write + decode. Sets `bytes` (on disk).
vts::Status cold(const Setup& s, std::shared_ptr<TileSource> source,
                 const std::vector<vts::TileId>& ids, CpuMeter& meter, Phase& phase,
                 std::uint64_t& bytes) {
  TileClientOptions o;
  o.cache.disk = DiskCacheOptions{};
  o.cache.disk->dir = s.dir;
  o.cache.disk->max_bytes = 64ull << 30;
  o.decode_threads = s.decode_threads;
  o.decoded_bytes = 256u << 20;
  auto client = TileClient::create(std::move(source), o);
  if (!client) return client.error();
  meter.start();
  const auto t0 = Clock::now();
  for (const auto id : ids) (*client)->request(id, 0);
  std::size_t done = 0, decoded = 0;
  while (done < ids.size()) {
    auto e = (*client)->wait(std::chrono::seconds(30));
    if (!e)
      return vts::make_error(vts::ErrorCode::io,
                             "timed out after " + std::to_string(done) + " tiles");
    if (done++ == 0) phase.first_s = seconds_since(t0);
    if (e->kind == TileEvent::Kind::decoded) ++decoded;
  }
  phase.events_s = seconds_since(t0);
  if (auto st = (*client)->cache().flush(); !st) return st;
  phase.wall_s = seconds_since(t0);
  phase.cpu_s = meter.proc();
  phase.server_cpu_s = meter.server();
  phase.threads = meter.by_thread();
  if (decoded != ids.size())
    return vts::make_error(vts::ErrorCode::corrupt,
                           std::to_string(ids.size() - decoded) + " tiles not decoded");
  bytes = (*client)->cache().disk()->stats().bytes;
  return {};
}

// Disk hits: one get at a time, RAM off.
vts::Status disk_hits(const Setup& s, std::shared_ptr<TileSource> source,
                      const std::vector<vts::TileId>& ids, std::vector<double>& us) {
  TileCacheOptions o;
  o.ram_bytes = 0;
  o.disk = DiskCacheOptions{};
  o.disk->dir = s.dir;
  o.disk->max_bytes = 64ull << 30;
  o.revalidate_after = std::chrono::hours(24);
  auto cache = TileCache::create(std::move(source), o);
  if (!cache) return cache.error();
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
    us.push_back(std::chrono::duration<double, std::micro>(Clock::now() - t0).count());
    if (!from_disk)
      return vts::make_error(vts::ErrorCode::internal,
                             "tile " + id.to_string() + " was not a disk hit");
  }
  return {};
}

// RAM hits: a cache that has every tile in RAM.
vts::Status ram_hits(const Setup& s, std::shared_ptr<TileSource> source,
                     const std::vector<vts::TileId>& ids, std::uint64_t bytes,
                     std::vector<double>& us) {
  TileCacheOptions o;
  o.ram_bytes = std::size_t(bytes * 2 + (64u << 20));
  o.revalidate_after = std::chrono::hours(24);
  o.disk = DiskCacheOptions{};
  o.disk->dir = s.dir;
  o.disk->max_bytes = 64ull << 30;
  auto cache = TileCache::create(std::move(source), o);
  if (!cache) return cache.error();
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
      us.push_back(std::chrono::duration<double, std::micro>(Clock::now() - t0).count());
      if (!hit)
        return vts::make_error(vts::ErrorCode::internal,
                               "tile " + id.to_string() + " was not a RAM hit");
    }
  return {};
}

bool parse_args(int argc, char** argv, Setup& s, std::string& error) {
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const bool has_value = i + 1 < argc;
    if (a == "--cache-dir" && has_value) {
      s.dir = argv[++i];
    } else if (a == "--in-flight" && has_value) {
      s.in_flight = std::stoul(argv[++i]);
    } else if (a == "--decode-threads" && has_value) {
      s.decode_threads = std::stoi(argv[++i]);
    } else if (a == "--server-pid" && has_value) {
      s.server_pid = std::stoi(argv[++i]);
    } else if (a == "--phases" && has_value) {
      s.phases.clear();
      std::istringstream list(argv[++i]);
      for (std::string p; std::getline(list, p, ',');) s.phases.insert(p);
    } else if (s.url.empty()) {
      s.url = a;
    } else {
      error = "unexpected argument '" + a + "'";
      return false;
    }
  }
  if (s.url.empty() || s.dir.empty()) {
    error = "usage: vts_client_bench URL --cache-dir DIR";
    return false;
  }
  if ((s.runs("decode") && !s.runs("fetch")) ||
      ((s.runs("disk") || s.runs("ram")) && !s.runs("cold"))) {
    error = "--phases: decode needs fetch; disk and ram need cold";
    return false;
  }
  return true;
}

// {"vts-decode": 1.23, ...}: the cold phase's CPU by thread name.
std::string json_threads(const std::map<std::string, double>& threads) {
  std::string out = "{";
  for (const auto& [name, cpu] : threads) {
    if (out.size() > 1) out += ", ";
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.3f", cpu);
    out += "\"" + name + "\": " + buf;
  }
  return out + "}";
}

}  // namespace

int main(int argc, char** argv) {
  Setup s;
  if (std::string error; !parse_args(argc, argv, s, error)) return fail(error);
  std::filesystem::remove_all(s.dir);

  SourceOptions so;
  so.fetcher.max_in_flight = s.in_flight;
  auto opened = open_source(s.url, so);
  if (!opened) return fail(opened.error().to_string());
  std::shared_ptr<TileSource> source = std::move(*opened);
  const auto& g = source->info().info.geometry;
  std::vector<vts::TileId> ids;
  for (int z = 0; z <= g.max_zoom(); ++z)
    for (std::uint32_t y = 0; y < g.tiles_y(std::uint8_t(z)); ++y)
      for (std::uint32_t x = 0; x < g.tiles_x(std::uint8_t(z)); ++x)
        ids.push_back(vts::TileId{std::uint8_t(z), x, y});

  CpuMeter meter;
  meter.server_pid = s.server_pid;
  Phase fetch, decode, cold_phase;
  std::uint64_t bytes = 0;
  std::vector<double> disk_us, ram_us;
  if (s.runs("fetch")) {
    std::vector<std::vector<std::uint8_t>> payloads;
    if (auto st = fetch_only(*source, ids, meter, fetch, payloads); !st)
      return fail(st.error().to_string());
    if (s.runs("decode"))
      if (auto st = decode_only(payloads, s.decode_threads, meter, decode); !st)
        return fail(st.error().to_string());
  }
  if (s.runs("cold"))
    if (auto st = cold(s, source, ids, meter, cold_phase, bytes); !st)
      return fail(st.error().to_string());
  if (s.runs("disk"))
    if (auto st = disk_hits(s, source, ids, disk_us); !st) return fail(st.error().to_string());
  if (s.runs("ram"))
    if (auto st = ram_hits(s, source, ids, bytes, ram_us); !st) return fail(st.error().to_string());

  std::printf(
      "{\"tiles\": %zu, \"bytes\": %llu, \"decode_threads\": %d, %s, %s, %s, "
      "\"cold_first_event_s\": %.3f, \"cold_last_event_s\": %.3f, "
      "\"cold_threads_cpu_s\": %s, \"disk_hit_p50_us\": %.1f, \"disk_hit_p99_us\": %.1f, "
      "\"ram_hit_p50_us\": %.2f, \"ram_hit_p99_us\": %.2f}\n",
      ids.size(), (unsigned long long)bytes, s.decode_threads,
      json_phase("cold", cold_phase).c_str(), json_phase("fetch_only", fetch).c_str(),
      json_phase("decode_only", decode).c_str(), cold_phase.first_s, cold_phase.events_s,
      json_threads(cold_phase.threads).c_str(), percentile(disk_us, 0.5), percentile(disk_us, 0.99),
      percentile(ram_us, 0.5), percentile(ram_us, 0.99));
  return 0;
}
