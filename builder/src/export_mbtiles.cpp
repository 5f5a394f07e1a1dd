// The MBTiles 1.3 sink of `vts export --format mbtiles` (export_pipeline.hpp): SQLite through its
// C API, as the client's disk cache uses it.
#include <sqlite3.h>

#include <cstdio>
#include <mutex>

#include "export_pipeline.hpp"

namespace vts {
inline namespace builder {
namespace detail {

namespace {

std::string number(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.9g", v);
  return buf;
}

class MbtilesSink final : public TileSink {
 public:
  static Result<std::unique_ptr<TileSink>> open(const std::filesystem::path& path,
                                                const MbtilesMetadata& m) {
    auto s = std::unique_ptr<MbtilesSink>(new MbtilesSink(path));
    if (sqlite3_open_v2(path.c_str(), &s->db_, SQLITE_OPEN_READWRITE | SQLITE_OPEN_NOMUTEX,
                        nullptr) != SQLITE_OK)
      return s->error("open");
    // One writer, a fresh file renamed into place only once complete: no journal is needed, and
    // a crash leaves only the temporary.
    if (Status st = s->exec("PRAGMA journal_mode=OFF; PRAGMA synchronous=OFF;"
                            "PRAGMA page_size=4096; BEGIN;"
                            "CREATE TABLE metadata (name TEXT, value TEXT);"
                            "CREATE TABLE tiles (zoom_level INTEGER, tile_column INTEGER,"
                            " tile_row INTEGER, tile_data BLOB);"
                            "CREATE UNIQUE INDEX tile_index ON tiles"
                            " (zoom_level, tile_column, tile_row);");
        !st)
      return st.error();
    if (Status st = s->write_metadata(m); !st) return st.error();
    if (sqlite3_prepare_v2(s->db_, "INSERT INTO tiles VALUES (?, ?, ?, ?)", -1, &s->insert_,
                           nullptr) != SQLITE_OK)
      return s->error("prepare an insert in");
    return std::unique_ptr<TileSink>(std::move(s));
  }
  ~MbtilesSink() override {
    if (insert_) sqlite3_finalize(insert_);
    if (db_) sqlite3_close(db_);
  }

  Status put(TileId id, std::span<const std::uint8_t> bytes) override {
    std::lock_guard lock(mutex_);
    const std::int64_t tms_row = (std::int64_t{1} << id.z) - 1 - std::int64_t{id.y};
    sqlite3_reset(insert_);
    sqlite3_bind_int(insert_, 1, id.z);
    sqlite3_bind_int64(insert_, 2, id.x);
    sqlite3_bind_int64(insert_, 3, tms_row);
    sqlite3_bind_blob64(insert_, 4, bytes.data(), bytes.size(), SQLITE_STATIC);
    const int rc = sqlite3_step(insert_);
    sqlite3_bind_null(insert_, 4);  // the bytes are the caller's
    if (rc != SQLITE_DONE) return error("write a tile " + id.to_string() + " to");
    ++stats_.addressed_tiles;
    ++stats_.tile_contents;
    stats_.tile_bytes += bytes.size();
    return {};
  }

  Result<archive::WriterStats> finish(const std::string&) override {
    std::lock_guard lock(mutex_);
    sqlite3_finalize(insert_);
    insert_ = nullptr;
    if (Status st = exec("COMMIT;"); !st) return st.error();
    if (sqlite3_close(db_) != SQLITE_OK) return error("close");
    db_ = nullptr;
    return stats_;
  }

 private:
  explicit MbtilesSink(std::filesystem::path p) : path_(std::move(p)) {}

  Error error(const std::string& what) const {
    return make_error(ErrorCode::io, "cannot " + what + " MBTiles '" + path_.string() +
                                         "': " + (db_ ? sqlite3_errmsg(db_) : "out of memory"));
  }
  Status exec(const char* sql) {
    char* msg = nullptr;
    if (sqlite3_exec(db_, sql, nullptr, nullptr, &msg) == SQLITE_OK) return {};
    std::string text = msg ? msg : "?";
    sqlite3_free(msg);
    return make_error(ErrorCode::io, "cannot write MBTiles '" + path_.string() + "': " + text);
  }
  Status write_metadata(const MbtilesMetadata& m) {
    const LonLatBounds& b = m.bounds;
    const std::pair<const char*, std::string> rows[] = {
        {"name", m.name},
        {"description", m.description},
        {"attribution", m.attribution},
        {"format", m.format},
        {"type", "baselayer"},
        {"version", "1"},  // the tileset's revision (the spec is 1.3)
        {"bounds",
         number(b.west) + "," + number(b.south) + "," + number(b.east) + "," + number(b.north)},
        {"center",
         number(m.center_lon) + "," + number(m.center_lat) + "," + std::to_string(m.center_zoom)},
        {"minzoom", std::to_string(m.min_zoom)},
        {"maxzoom", std::to_string(m.max_zoom)},
    };
    sqlite3_stmt* st = nullptr;
    if (sqlite3_prepare_v2(db_, "INSERT INTO metadata VALUES (?, ?)", -1, &st, nullptr) !=
        SQLITE_OK)
      return error("prepare the metadata of");
    for (const auto& [name, value] : rows) {
      if (value.empty()) continue;  // no description or attribution: no row
      sqlite3_reset(st);
      sqlite3_bind_text(st, 1, name, -1, SQLITE_STATIC);
      sqlite3_bind_text(st, 2, value.data(), static_cast<int>(value.size()), SQLITE_STATIC);
      if (sqlite3_step(st) != SQLITE_DONE) {
        sqlite3_finalize(st);
        return error("write the metadata of");
      }
    }
    sqlite3_finalize(st);
    return {};
  }

  std::filesystem::path path_;
  sqlite3* db_ = nullptr;
  sqlite3_stmt* insert_ = nullptr;
  std::mutex mutex_;
  archive::WriterStats stats_;
};

}  // namespace

Result<std::unique_ptr<TileSink>> open_mbtiles_sink(const std::filesystem::path& path,
                                                    const MbtilesMetadata& metadata) {
  return MbtilesSink::open(path, metadata);
}

}  // namespace detail
}  // namespace builder
}  // namespace vts
