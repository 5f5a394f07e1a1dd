// cache_torture: drives the client's DiskCache from the shell for the crash, full-disk and
// multi-process tests (cache_*.sh).
//
//   cache_torture fill DIR --first K --count N [--cap BYTES] [--pin] [--tileset NAME]
//       Puts tiles K .. K+N-1 of NAME (default "torture") into the cache in DIR, skipping those
//       already present with a valid checksum (so a killed fill resumes). Each tile's size
//       (1 .. 64 KiB) and bytes are derived from its key alone. Prints a progress line every 50
//       tiles and a summary at the end; on an error prints it and exits with vts::exit_code().
//
//   cache_torture check DIR [--expect-tiles N]
//       Opens the cache (which must exist), runs PRAGMA integrity_check, reads every row directly
//       and checks its payload is the deterministic content for its key and its checksum
//       matches, reads every tile through DiskCache as well, and checks that the totals row
//       equals SUM(size) / COUNT(*) of the rows (all in one read snapshot). Exits 0 with a
//       one-line summary, or 1 naming the first problem.
#include <sqlite3.h>
#include <xxhash.h>

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "vts/base/result.hpp"
#include "vts/client/disk_cache.hpp"

namespace {

using vts::TileId;
using vts::client::CachedTile;
using vts::client::DiskCache;
using vts::client::DiskCacheOptions;

constexpr std::uint8_t kZoom = 20;

std::uint64_t splitmix(std::uint64_t& s) {
  std::uint64_t z = (s += 0x9e3779b97f4a7c15ULL);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

TileId tile_of_index(std::uint64_t i) {
  return TileId{kZoom, static_cast<std::uint32_t>(i & 0xffff), static_cast<std::uint32_t>(i >> 16)};
}

// The one payload a key may ever hold: 1 .. 65536 bytes, all derived from the key.
std::vector<std::uint8_t> content_for(std::string_view tileset, TileId id) {
  std::uint64_t seed = XXH3_64bits(tileset.data(), tileset.size());
  seed ^= (std::uint64_t(id.z) << 58) ^ (std::uint64_t(id.x) << 29) ^ id.y;
  std::uint64_t s = seed;
  std::vector<std::uint8_t> out(1 + splitmix(s) % 65536);
  std::size_t i = 0;
  for (; i + 8 <= out.size(); i += 8) {
    const std::uint64_t v = splitmix(s);
    for (int b = 0; b < 8; ++b) out[i + b] = static_cast<std::uint8_t>(v >> (8 * b));
  }
  for (const std::uint64_t v = splitmix(s); i < out.size(); ++i)
    out[i] = static_cast<std::uint8_t>(v >> (8 * (i % 8)));
  return out;
}

std::string etag_for(TileId id) {
  return "\"" + id.to_string() + "\"";
}

[[noreturn]] void usage(const char* why) {
  std::fprintf(stderr,
               "cache_torture: %s\n"
               "usage: cache_torture fill DIR --first K --count N [--cap BYTES] [--pin] "
               "[--tileset NAME]\n"
               "       cache_torture check DIR [--expect-tiles N]\n",
               why);
  std::exit(2);
}

int fail(const vts::Error& e, const char* what) {
  std::fprintf(stderr, "cache_torture: %s: %s\n", what, e.to_string().c_str());
  return vts::exit_code(e.code);
}

std::uint64_t parse_u64(const char* flag, const char* text) {
  char* end = nullptr;
  errno = 0;
  const unsigned long long v = std::strtoull(text, &end, 10);
  if (errno || end == text || *end || text[0] == '-')
    usage((std::string("bad number for ") + flag + ": '" + text + "'").c_str());
  return v;
}

double mib(std::uint64_t bytes) {
  return double(bytes) / (1 << 20);
}

int fill(int argc, char** argv) {
  if (argc < 3) usage("fill needs DIR");
  DiskCacheOptions options;
  options.dir = argv[2];
  std::uint64_t first = 0, count = 0;
  bool have_first = false, have_count = false, pin = false;
  std::string tileset = "torture";
  for (int i = 3; i < argc; ++i) {
    const std::string_view arg = argv[i];
    auto value = [&]() -> const char* {
      if (i + 1 >= argc) usage((std::string(arg) + " needs a value").c_str());
      return argv[++i];
    };
    if (arg == "--first") {
      first = parse_u64("--first", value());
      have_first = true;
    } else if (arg == "--count") {
      count = parse_u64("--count", value());
      have_count = true;
    } else if (arg == "--cap") {
      options.max_bytes = parse_u64("--cap", value());
    } else if (arg == "--pin") {
      pin = true;
    } else if (arg == "--tileset") {
      tileset = value();
    } else {
      usage(("unknown option '" + std::string(arg) + "'").c_str());
    }
  }
  if (!have_first || !have_count) usage("fill needs --first and --count");

  auto opened = DiskCache::open(options);
  if (!opened) return fail(opened.error(), "fill");
  DiskCache& cache = **opened;
  std::uint64_t stored = 0, skipped = 0, bytes = 0;
  for (std::uint64_t i = first; i < first + count; ++i) {
    const TileId id = tile_of_index(i);
    auto present = cache.contains(tileset, id);
    if (!present) return fail(present.error(), "fill");
    if (*present) {
      ++skipped;
    } else {
      CachedTile tile;
      tile.payload = content_for(tileset, id);
      tile.etag = etag_for(id);
      tile.validated_unix = 1700000000 + static_cast<std::int64_t>(i);
      if (vts::Status s = cache.put(tileset, id, tile, pin); !s.ok()) {
        std::printf("fill: stopped at tile %llu after %llu stored\n",
                    static_cast<unsigned long long>(i), static_cast<unsigned long long>(stored));
        std::fflush(stdout);
        return fail(s.error(), "fill");
      }
      ++stored;
      bytes += tile.payload.size();
    }
    const std::uint64_t done = i - first + 1;
    if (done % 50 == 0) {
      std::printf("fill: %llu/%llu tiles (%llu already present, %.1f MiB written)\n",
                  static_cast<unsigned long long>(done), static_cast<unsigned long long>(count),
                  static_cast<unsigned long long>(skipped), mib(bytes));
      std::fflush(stdout);
    }
  }
  if (vts::Status s = cache.flush(); !s.ok()) return fail(s.error(), "fill");
  const auto st = cache.stats();
  std::printf(
      "fill: done: %llu stored, %llu already present, %.1f MiB written; cache holds %llu tiles, "
      "%llu bytes (cap %llu), %llu evicted\n",
      static_cast<unsigned long long>(stored), static_cast<unsigned long long>(skipped), mib(bytes),
      static_cast<unsigned long long>(st.tiles), static_cast<unsigned long long>(st.bytes),
      static_cast<unsigned long long>(st.max_bytes), static_cast<unsigned long long>(st.evicted));
  return 0;
}

// A read-only look at the database with SQLite itself, independent of DiskCache's code.
class Raw {
 public:
  ~Raw() { sqlite3_close(db_); }
  std::string open(const std::filesystem::path& file) {
    if (sqlite3_open_v2(file.c_str(), &db_, SQLITE_OPEN_READWRITE, nullptr) != SQLITE_OK)
      return "cannot open " + file.string() + ": " + sqlite3_errmsg(db_);
    sqlite3_busy_timeout(db_, 10000);
    return {};
  }
  sqlite3* db() const { return db_; }
  std::string error(const char* doing) const {
    return std::string(doing) + ": " + sqlite3_errmsg(db_);
  }

 private:
  sqlite3* db_ = nullptr;
};

struct Stmt {
  sqlite3_stmt* s = nullptr;
  ~Stmt() { sqlite3_finalize(s); }
};

int check_failed(const std::string& why) {
  std::fprintf(stderr, "cache_torture: check: %s\n", why.c_str());
  return 1;
}

int check(int argc, char** argv) {
  if (argc < 3) usage("check needs DIR");
  const std::filesystem::path dir = argv[2];
  std::int64_t expect_tiles = -1;
  for (int i = 3; i < argc; ++i) {
    const std::string_view arg = argv[i];
    if (arg == "--expect-tiles" && i + 1 < argc) {
      expect_tiles = static_cast<std::int64_t>(parse_u64("--expect-tiles", argv[++i]));
    } else {
      usage(("unknown option '" + std::string(arg) + "'").c_str());
    }
  }
  const std::filesystem::path file = dir / DiskCache::kFileName;
  if (!std::filesystem::exists(file)) return check_failed("no cache at " + file.string());

  // Through the cache's own open(): schema version, WAL; a cap far above anything held, so that
  // opening never evicts.
  DiskCacheOptions options;
  options.dir = dir;
  options.max_bytes = std::uint64_t(1) << 60;
  auto opened = DiskCache::open(options);
  if (!opened) return fail(opened.error(), "check");
  DiskCache& cache = **opened;

  Raw raw;
  if (std::string e = raw.open(file); !e.empty()) return check_failed(e);
  std::string integrity;
  {
    Stmt st;
    if (sqlite3_prepare_v2(raw.db(), "PRAGMA integrity_check", -1, &st.s, nullptr) != SQLITE_OK)
      return check_failed(raw.error("integrity_check"));
    int rc;
    while ((rc = sqlite3_step(st.s)) == SQLITE_ROW) {
      if (!integrity.empty()) integrity += "; ";
      integrity += reinterpret_cast<const char*>(sqlite3_column_text(st.s, 0));
    }
    if (rc != SQLITE_DONE) return check_failed(raw.error("integrity_check"));
  }
  if (integrity != "ok") return check_failed("PRAGMA integrity_check: " + integrity);

  // One read snapshot for the rows and the totals.
  if (sqlite3_exec(raw.db(), "BEGIN", nullptr, nullptr, nullptr) != SQLITE_OK)
    return check_failed(raw.error("BEGIN"));
  std::uint64_t rows = 0, bytes = 0, pinned_rows = 0, pinned_bytes = 0;
  std::vector<std::pair<std::string, TileId>> keys;
  {
    Stmt st;
    if (sqlite3_prepare_v2(raw.db(),
                           "SELECT s.key, t.z, t.x, t.y, t.size, t.checksum, t.pinned, t.etag, "
                           "t.payload FROM tiles t JOIN tilesets s ON s.id = t.tileset_id",
                           -1, &st.s, nullptr) != SQLITE_OK)
      return check_failed(raw.error("reading rows"));
    int rc;
    while ((rc = sqlite3_step(st.s)) == SQLITE_ROW) {
      const std::string tileset = reinterpret_cast<const char*>(sqlite3_column_text(st.s, 0));
      const TileId id{static_cast<std::uint8_t>(sqlite3_column_int(st.s, 1)),
                      static_cast<std::uint32_t>(sqlite3_column_int64(st.s, 2)),
                      static_cast<std::uint32_t>(sqlite3_column_int64(st.s, 3))};
      const auto size = static_cast<std::uint64_t>(sqlite3_column_int64(st.s, 4));
      const auto checksum = static_cast<std::uint64_t>(sqlite3_column_int64(st.s, 5));
      const bool pinned = sqlite3_column_int(st.s, 6) != 0;
      const auto* etag = reinterpret_cast<const char*>(sqlite3_column_text(st.s, 7));
      const auto* blob = static_cast<const std::uint8_t*>(sqlite3_column_blob(st.s, 8));
      const auto n = static_cast<std::size_t>(sqlite3_column_bytes(st.s, 8));
      const std::string name = tileset + "/" + id.to_string();
      if (n != size)
        return check_failed(name + ": payload is " + std::to_string(n) + " bytes, size column " +
                            std::to_string(size));
      if (XXH3_64bits(blob, n) != checksum) return check_failed(name + ": checksum mismatch");
      const std::vector<std::uint8_t> want = content_for(tileset, id);
      if (want.size() != n || !std::equal(want.begin(), want.end(), blob))
        return check_failed(name + ": payload is not the content written for this key");
      if (!etag || etag_for(id) != etag) return check_failed(name + ": wrong etag");
      ++rows;
      bytes += size;
      if (pinned) {
        ++pinned_rows;
        pinned_bytes += size;
      }
      keys.emplace_back(tileset, id);
    }
    if (rc != SQLITE_DONE) return check_failed(raw.error("reading rows"));
  }
  {
    Stmt st;
    if (sqlite3_prepare_v2(
            raw.db(), "SELECT bytes, tiles, pinned_bytes, pinned_tiles FROM totals WHERE id = 0",
            -1, &st.s, nullptr) != SQLITE_OK ||
        sqlite3_step(st.s) != SQLITE_ROW)
      return check_failed(raw.error("reading totals"));
    const auto t_bytes = static_cast<std::uint64_t>(sqlite3_column_int64(st.s, 0));
    const auto t_tiles = static_cast<std::uint64_t>(sqlite3_column_int64(st.s, 1));
    const auto t_pbytes = static_cast<std::uint64_t>(sqlite3_column_int64(st.s, 2));
    const auto t_ptiles = static_cast<std::uint64_t>(sqlite3_column_int64(st.s, 3));
    if (t_bytes != bytes || t_tiles != rows || t_pbytes != pinned_bytes || t_ptiles != pinned_rows)
      return check_failed("totals row says " + std::to_string(t_tiles) + " tiles / " +
                          std::to_string(t_bytes) + " bytes (" + std::to_string(t_ptiles) +
                          " pinned / " + std::to_string(t_pbytes) + " bytes), rows hold " +
                          std::to_string(rows) + " / " + std::to_string(bytes) + " (" +
                          std::to_string(pinned_rows) + " / " + std::to_string(pinned_bytes) + ")");
  }
  sqlite3_exec(raw.db(), "COMMIT", nullptr, nullptr, nullptr);
  if (expect_tiles >= 0 && rows != static_cast<std::uint64_t>(expect_tiles))
    return check_failed("expected " + std::to_string(expect_tiles) + " tiles, found " +
                        std::to_string(rows));

  // And every tile through the cache's own read path, which verifies checksums (contains(), not
  // get(), so that checking records no access times: it writes nothing).
  for (const auto& [tileset, id] : keys) {
    auto present = cache.contains(tileset, id);
    if (!present) return fail(present.error(), "check");
    if (!*present)
      return check_failed(tileset + "/" + id.to_string() + ": DiskCache does not find it");
  }
  const auto st = cache.stats();
  if (st.corrupt_dropped != 0) return check_failed("DiskCache dropped corrupt rows");
  std::printf(
      "check: ok: integrity ok, %llu tiles (%llu pinned), %.1f MiB, every payload and checksum "
      "verified, totals exact\n",
      static_cast<unsigned long long>(rows), static_cast<unsigned long long>(pinned_rows),
      mib(bytes));
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) usage("no command");
  const std::string_view command = argv[1];
  if (command == "fill") return fill(argc, argv);
  if (command == "check") return check(argc, argv);
  usage(("unknown command '" + std::string(command) + "'").c_str());
}
