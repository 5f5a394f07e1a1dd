#include "vts/builder/export.hpp"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <thread>

#include "export_pipeline.hpp"
#include "vts/archive/inspect.hpp"
#include "vts/base/file_io.hpp"
#include "vts/imaging/web_mercator.hpp"
#include "vts/protocol/json_input.hpp"

namespace vts {
inline namespace builder {

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

using detail::Counters;
using detail::Feeder;
using detail::TileSink;

class ArchiveSink final : public TileSink {
 public:
  explicit ArchiveSink(std::unique_ptr<archive::Writer> w) : writer_(std::move(w)) {}
  ~ArchiveSink() override {
    if (writer_) writer_->abort();
  }
  Status put(TileId id, std::span<const std::uint8_t> bytes) override {
    return writer_->add_tile(id, bytes);
  }
  Result<archive::WriterStats> finish(const std::string& metadata_json) override {
    auto stats = writer_->finish(metadata_json);
    if (stats) writer_.reset();
    return stats;
  }

 private:
  std::unique_ptr<archive::Writer> writer_;
};

Status io_error(const std::string& what, const fs::path& p, int err) {
  return make_error(ErrorCode::io,
                    "cannot " + what + " '" + p.string() + "': " + std::strerror(err));
}

Status write_file(const fs::path& p, std::span<const std::uint8_t> bytes) {
  const int fd = ::open(p.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return io_error("create", p, errno);
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const int err = n < 0 ? errno : EIO;
      ::close(fd);
      return io_error("write", p, err);
    }
    done += static_cast<std::size_t>(n);
  }
  if (::close(fd) != 0) return io_error("write", p, errno);
  return {};
}

// {z}/{x}/{y}.ext under a temporary folder beside the output, renamed to it by finish().
class FolderSink final : public TileSink {
 public:
  static Result<std::unique_ptr<FolderSink>> create(const fs::path& out, imaging::WebFormat f) {
    std::error_code ec;
    if (fs::exists(out, ec) && !(fs::is_directory(out, ec) && fs::is_empty(out, ec)))
      return make_error(ErrorCode::invalid_argument,
                        "output '" + out.string() + "' exists and is not an empty folder");
    const fs::path dest = out.has_filename() ? out : out.parent_path();
    fs::path parent = dest.parent_path();
    if (parent.empty()) parent = ".";
    // Like `mkdir -p`: a site's tile folder often goes a few levels down a fresh tree.
    fs::create_directories(parent, ec);
    if (ec)
      return make_error(ErrorCode::io, "cannot create '" + parent.string() + "': " + ec.message());
    const std::string prefix = "." + dest.filename().string() + ".partial-";
    remove_stale_partials(parent, prefix);
    std::string tmpl = (parent / (prefix + "XXXXXX")).string();
    if (::mkdtemp(tmpl.data()) == nullptr)
      return io_error("create a folder in", parent, errno).error();
    auto s = std::unique_ptr<FolderSink>(new FolderSink);
    s->tmp_ = tmpl;  // removed by the destructor from here on
    // Held until the export ends: the next export to this output sees that it is not stale.
    s->lock_fd_ = ::open(tmpl.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (s->lock_fd_ < 0 || ::flock(s->lock_fd_, LOCK_EX | LOCK_NB) != 0)
      return io_error("lock", tmpl, errno).error();
    // mkdtemp makes it 0700; a folder for static hosting is readable by the web server.
    std::error_code perm_ec;
    fs::permissions(tmpl, fs::perms(0755), perm_ec);
    s->dest_ = dest;
    s->ext_ = imaging::web_format_extension(f);
    return s;
  }
  ~FolderSink() override {
    if (!tmp_.empty()) {
      std::error_code ec;
      fs::remove_all(tmp_, ec);
    }
    if (lock_fd_ >= 0) ::close(lock_fd_);
  }
  Status put(TileId id, std::span<const std::uint8_t> bytes) override {
    const fs::path dir = tmp_ / std::to_string(id.z) / std::to_string(id.x);
    std::error_code ec;
    fs::create_directories(dir, ec);
    if (ec)
      return make_error(ErrorCode::io, "cannot create '" + dir.string() + "': " + ec.message());
    if (Status s = write_file(dir / (std::to_string(id.y) + "." + std::string(ext_)), bytes); !s)
      return s;
    std::lock_guard lock(mutex_);
    ++stats_.addressed_tiles;
    ++stats_.tile_contents;
    stats_.tile_bytes += bytes.size();
    return {};
  }
  Result<archive::WriterStats> finish(const std::string& metadata_json) override {
    const std::string& m = metadata_json;
    if (Status s = write_file(tmp_ / "metadata.json",
                              {reinterpret_cast<const std::uint8_t*>(m.data()), m.size()});
        !s)
      return s.error();
    std::error_code ec;
    if (fs::is_directory(dest_, ec)) fs::remove(dest_, ec);  // empty (checked at create)
    fs::rename(tmp_, dest_, ec);
    if (ec)
      return make_error(ErrorCode::io,
                        "cannot rename to '" + dest_.string() + "': " + ec.message());
    tmp_.clear();
    return stats_;
  }

 private:
  FolderSink() = default;

  // The partial folders of exports to the same output that were killed (SIGKILL, a second
  // signal): those no running export holds locked. Best effort: what cannot be removed stays.
  static void remove_stale_partials(const fs::path& parent, const std::string& prefix) {
    std::error_code ec;
    for (fs::directory_iterator it(parent, ec), end; !ec && it != end; it.increment(ec)) {
      const std::string name = it->path().filename().string();
      if (name.size() != prefix.size() + 6 || name.compare(0, prefix.size(), prefix) != 0) continue;
      const int fd = ::open(it->path().c_str(), O_RDONLY | O_DIRECTORY | O_NOFOLLOW | O_CLOEXEC);
      if (fd < 0) continue;
      if (::flock(fd, LOCK_EX | LOCK_NB) == 0) {
        std::error_code rm_ec;
        fs::remove_all(it->path(), rm_ec);
      }
      ::close(fd);
    }
  }

  int lock_fd_ = -1;
  fs::path dest_, tmp_;
  std::string_view ext_;
  std::mutex mutex_;
  archive::WriterStats stats_;
};

bool wholly_transparent(const TileImage& img) {
  for (std::size_t i = 3; i < img.pixels.size(); i += 4)
    if (img.pixels[i] != 0) return false;
  return true;
}

archive::TileType tile_type(imaging::WebFormat f) {
  switch (f) {
    case imaging::WebFormat::png:
      return archive::TileType::png;
    case imaging::WebFormat::jpeg:
      return archive::TileType::jpeg;
    case imaging::WebFormat::webp:
      return archive::TileType::webp;
  }
  return archive::TileType::unknown;
}

LonLatLevel export_center(const TilesetInfo& info, const LonLatBounds& b) {
  if (info.georeference) {  // inside b (a reprojection clips the latitudes)
    LonLatLevel c = info.georeference->center;
    c.lat = std::clamp(c.lat, b.south, b.north);
    return c;
  }
  const Geometry& g = info.geometry;
  int z = 0;
  while (z < g.max_zoom() &&
         std::max(g.level_width(z), g.level_height(z)) < std::uint64_t{g.tile_size()})
    ++z;
  return {(b.west + b.east) / 2, (b.south + b.north) / 2, z};
}

// One directory entry: its payload decoded once, then one output tile per tile id of its run
// (tiles of one run with the same clipped content size give the same output: encoded once).
class EntryJob {
 public:
  EntryJob(const archive::Reader& r, const TilesetInfo& info, const ExportOptions& o, TileSink& s,
           Counters& c)
      : reader_(r), info_(info), options_(o), sink_(s), counters_(c) {}

  Status run(const archive::Entry& e) const {
    auto stored = load(e);
    if (!stored) return stored.error();
    std::optional<std::pair<std::uint64_t, std::uint64_t>> last_size;
    std::optional<std::vector<std::uint8_t>> last_bytes;  // nullopt: transparent
    for (std::uint32_t i = 0; i < e.run_length; ++i) {
      auto id = archive::tile_id_to_zxy(e.tile_id + i);
      if (!id) return id.error();
      const TexelRect r = info_.geometry.content_rect(*id);
      const std::pair size{r.width(), r.height()};
      if (last_size != size) {
        auto content = imaging::tile_content(*stored, info_.geometry, *id);
        if (!content) return with_tile(content.error(), *id);
        last_size = size;
        last_bytes.reset();
        if (!wholly_transparent(*content)) {
          auto bytes = imaging::encode_web_image(*content, options_.format, options_.encode);
          if (!bytes) return with_tile(bytes.error(), *id);
          last_bytes = std::move(bytes).value();
        }
      }
      if (last_bytes) {
        if (Status s = sink_.put(*id, *last_bytes); !s) return s;
        counters_.written.fetch_add(1);
      } else {
        counters_.skipped.fetch_add(1);
      }
      counters_.done.fetch_add(1);
    }
    return {};
  }

 private:
  static Error with_tile(Error e, TileId id) {
    e.message = "tile " + id.to_string() + ": " + e.message;
    return e;
  }
  Result<TileImage> load(const archive::Entry& e) const {
    std::vector<std::uint8_t> bytes(e.length);
    if (Status s = reader_.read(reader_.header().tile_data_offset + e.offset, bytes); !s)
      return s.error();
    auto first = archive::tile_id_to_zxy(e.tile_id);
    if (!first) return first.error();
    auto img = decode_tile(bytes, info_.tile_spec());
    if (img && img->format == PixelFormat::bc1) img = bc1_to_rgba8(*img);
    if (!img) return with_tile(img.error(), *first);
    return img;
  }

  const archive::Reader& reader_;
  const TilesetInfo& info_;
  const ExportOptions& options_;
  TileSink& sink_;
  Counters& counters_;
};

// Decoded stored texels of a source tile as rgba8; nullopt when the archive lacks it.
Result<std::optional<TileImage>> load_stored(const archive::Reader& reader, const TilesetInfo& info,
                                             TileId id) {
  auto img = archive::read_tile_rgba8(reader, info, id);
  if (!img && img.error().code == ErrorCode::not_found) return std::optional<TileImage>{};
  if (!img) return std::move(img).error();
  return std::optional<TileImage>(std::move(img).value());
}

// One column (z, x) of WebMercatorQuad tiles, rows [y0, y1), reprojected from a WorldCRS84Quad
// source (web_mercator.hpp). Going down the column, the source tiles of the previous output tile
// are kept for the next one (neighbours share source rows), nothing older: at most the source
// tiles of two output tiles are held.
class ColumnJob {
 public:
  ColumnJob(const archive::Reader& r, const TilesetInfo& info, const ExportOptions& o, TileSink& s,
            Counters& c)
      : reader_(r), info_(info), options_(o), sink_(s), counters_(c) {}

  Status run(int z, std::uint32_t x, std::uint32_t y0, std::uint32_t y1) const {
    using Cache = std::map<std::uint64_t, std::optional<TileImage>>;
    Cache previous, current;
    const imaging::FetchStoredTile fetch = [&](TileId id) -> Result<std::optional<TileImage>> {
      const std::uint64_t key = tile_key(id);
      if (auto it = current.find(key); it != current.end()) return it->second;
      if (auto it = previous.find(key); it != previous.end())
        return current.emplace(key, std::move(it->second)).first->second;
      auto img = load_stored(reader_, info_, id);
      if (!img) return img.error();
      return current.emplace(key, std::move(img).value()).first->second;
    };
    for (std::uint32_t y = y0; y < y1; ++y) {
      // A column can be long (2^z rows): cancellation is checked per tile, not per job.
      if (options_.cancel && options_.cancel->load())
        return make_error(ErrorCode::cancelled, "export cancelled");
      if (Status s = render(z, x, y, fetch); !s) return s;
      previous = std::move(current);
      current.clear();
      counters_.done.fetch_add(1);
    }
    return {};
  }

 private:
  Status render(int z, std::uint32_t x, std::uint32_t y,
                const imaging::FetchStoredTile& fetch) const {
    const TileId id{static_cast<std::uint8_t>(z), x, y};
    auto tile = imaging::render_web_mercator_tile(info_, z, x, y, fetch);
    if (!tile) {
      Error e = std::move(tile).error();
      e.message = "WebMercatorQuad tile " + id.to_string() + ": " + e.message;
      return e;
    }
    if (!*tile || wholly_transparent(**tile)) {
      counters_.skipped.fetch_add(1);
      return {};
    }
    auto bytes = imaging::encode_web_image(**tile, options_.format, options_.encode);
    if (!bytes) return bytes.error();
    if (Status s = sink_.put(id, *bytes); !s) return s;
    counters_.written.fetch_add(1);
    return {};
  }

  const archive::Reader& reader_;
  const TilesetInfo& info_;
  const ExportOptions& options_;
  TileSink& sink_;
  Counters& counters_;
};

// What the export writes: the zoom range and bounds of its grid, and whether tiles are
// reprojected (WorldCRS84Quad source, WebMercatorQuad output).
struct Plan {
  int min_zoom = 0, max_zoom = 0;
  LonLatBounds bounds;
  bool reproject = false;
  Tiling grid = Tiling::none;
};

Result<Plan> make_plan(const TilesetInfo& info, Tiling grid) {
  Plan p;
  p.max_zoom = info.geometry.max_zoom();
  p.bounds = export_bounds(info);
  p.grid = grid;
  if (grid == Tiling::web_mercator_quad && info.georeference->tiling == Tiling::world_crs84_quad) {
    auto range = imaging::web_mercator_range(info);
    if (!range) return range.error();
    p = {range->min_zoom, range->max_zoom, range->bounds, true, grid};
  }
  return p;
}

Result<std::unique_ptr<TileSink>> open_mbtiles(const TilesetInfo& info, const ExportOptions& o,
                                               const Plan& plan, const fs::path& temporary) {
  detail::MbtilesMetadata m;
  m.name = info.name;
  m.description = info.description;
  m.format = std::string(imaging::web_format_extension(o.format));
  m.bounds = plan.bounds;
  const LonLatLevel c = export_center(info, plan.bounds);
  m.center_lon = c.lon;
  m.center_lat = c.lat;
  m.center_zoom = std::clamp(c.level, plan.min_zoom, plan.max_zoom);
  m.min_zoom = plan.min_zoom;
  m.max_zoom = plan.max_zoom;
  return detail::open_mbtiles_sink(temporary, m);
}

Result<std::unique_ptr<TileSink>> open_sink(const TilesetInfo& info, const ExportOptions& o,
                                            const Plan& plan) {
  if (o.layout == ExportLayout::xyz) {
    auto s = FolderSink::create(o.output, o.format);
    if (!s) return s.error();
    return std::unique_ptr<TileSink>(std::move(s).value());
  }
  archive::WriterOptions w;
  w.path = o.output;
  w.internal_compression = archive::Compression::gzip;
  w.tile_compression = archive::Compression::none;
  w.tile_type = tile_type(o.format);
  w.min_zoom = static_cast<std::uint8_t>(plan.min_zoom);
  w.max_zoom = static_cast<std::uint8_t>(plan.max_zoom);
  w.bounds = archive::georeferenced_bounds(plan.bounds, export_center(info, plan.bounds));
  auto writer = archive::Writer::create(std::move(w));
  if (!writer) {
    Error e = std::move(writer).error();
    e.message = "'" + o.output.string() + "': " + e.message;
    return e;
  }
  return std::unique_ptr<TileSink>(std::make_unique<ArchiveSink>(std::move(writer).value()));
}

// The archive's own grid: walks the source directory, one job per entry.
Status walk_entries(const archive::Reader& reader, const TilesetInfo& info, const ExportOptions& o,
                    TileSink& sink, Counters& counters) {
  EntryJob job(reader, info, o, sink, counters);
  const detail::FeederOptions fo{o.threads, o.cancel, o.on_progress};
  Feeder feeder(fo, counters, reader.header().addressed_tiles);
  Status walked = reader.for_each_entry(
      [&](const archive::Entry& e) { return feeder.submit([&job, e] { return job.run(e); }); });
  return feeder.finish(walked);
}

// WebMercatorQuad from WorldCRS84Quad: every zoom's tiles over the bounds, one job per column.
Status walk_reprojected(const archive::Reader& reader, const TilesetInfo& info,
                        const ExportOptions& o, const Plan& plan, TileSink& sink,
                        Counters& counters) {
  auto web =
      tiling_geometry(Tiling::web_mercator_quad, plan.max_zoom, info.geometry.tile_size(), 0);
  if (!web) return web.error();
  std::uint64_t total = 0;
  for (int z = plan.min_zoom; z <= plan.max_zoom; ++z)
    total += footprint_tiles(Tiling::web_mercator_quad, *web, z, plan.bounds).count();
  ColumnJob job(reader, info, o, sink, counters);
  const detail::FeederOptions fo{o.threads, o.cancel, o.on_progress};
  Feeder feeder(fo, counters, total);
  for (int z = plan.min_zoom; z <= plan.max_zoom; ++z) {
    const TileRect r = footprint_tiles(Tiling::web_mercator_quad, *web, z, plan.bounds);
    for (std::uint32_t x = r.x0; x < r.x1; ++x)
      if (!feeder.submit([&job, z, x, r] { return job.run(z, x, r.y0, r.y1); }))
        return feeder.finish({});
  }
  return feeder.finish({});
}

}  // namespace

Result<Tiling> export_grid(const TilesetInfo& info, ExportLayout layout,
                           std::optional<Tiling> wanted) {
  const Tiling own = info.georeference ? info.georeference->tiling : Tiling::none;
  if (layout == ExportLayout::mbtiles && own == Tiling::none)
    return make_error(ErrorCode::invalid_argument,
                      "MBTiles needs a georeferenced archive (its tiles are Web Mercator); this "
                      "one is a plain image: export it as pmtiles or xyz");
  if (!wanted)  // web maps draw every tile as Web Mercator
    return own == Tiling::none ? Tiling::none : Tiling::web_mercator_quad;
  if (*wanted == Tiling::none) wanted = own;  // "native"
  if (layout == ExportLayout::mbtiles && *wanted != Tiling::web_mercator_quad)
    return make_error(ErrorCode::invalid_argument,
                      "MBTiles holds WebMercatorQuad tiles only; leave out --tiling");
  if (own == Tiling::none && *wanted != Tiling::none)
    return make_error(ErrorCode::invalid_argument,
                      "--tiling " + std::string(tiling_name(*wanted)) +
                          " needs a georeferenced archive; this one is a plain image (export it on "
                          "its own grid: leave out --tiling)");
  if (*wanted != own && *wanted != Tiling::web_mercator_quad)
    return make_error(ErrorCode::invalid_argument,
                      "--tiling " + std::string(tiling_name(*wanted)) +
                          " is not an export grid of this " + std::string(tiling_name(own)) +
                          " archive; the choices are its own grid (native) and WebMercatorQuad");
  return *wanted;
}

LonLatBounds export_bounds(const TilesetInfo& info) {
  if (info.georeference) return info.georeference->bounds;
  const Geometry& g = info.geometry;
  const int z = g.max_zoom();
  const LonLat a = texel_to_lonlat(Tiling::web_mercator_quad, g.tile_size(), z, {0, 0});
  const LonLat b = texel_to_lonlat(Tiling::web_mercator_quad, g.tile_size(), z,
                                   {double(g.width()), double(g.height())});
  return {a.lon, b.lat, b.lon, a.lat};
}

std::string export_metadata_json(const TilesetInfo& info, const std::string& source_metadata,
                                 const std::string& source_name, const std::string& source_version,
                                 imaging::WebFormat format, const LonLatBounds& b, int min_zoom,
                                 int max_zoom, Tiling grid) {
  const LonLatLevel c = export_center(info, b);
  nlohmann::json j;
  j["name"] = info.name;
  j["description"] = info.description;
  // The source's metadata is untrusted: only its attribution string is copied, and unreadable
  // metadata has none.
  if (auto src = parse_json(source_metadata, "the source's metadata")) {
    const auto it = src->is_object() ? src->find("attribution") : src->end();
    if (it != src->end() && it->is_string()) j["attribution"] = it->get<std::string>();
  }
  j["type"] = "baselayer";
  j["format"] = std::string(imaging::web_format_extension(format));
  j["bounds"] = {b.west, b.south, b.east, b.north};
  j["center"] = {c.lon, c.lat, c.level};
  j["minzoom"] = min_zoom;
  j["maxzoom"] = max_zoom;
  j["tileSize"] = info.geometry.tile_size();
  j["tiling"] = std::string(tiling_name(grid));
  nlohmann::json s;
  s["archive"] = source_name;
  s["version"] = source_version;
  s["content_hash"] = info.content_hash;
  s["codec"] = codec_name(info.codec);
  s["width"] = info.geometry.width();
  s["height"] = info.geometry.height();
  s["border"] = info.geometry.border();
  s["tiling"] = info.georeference ? std::string(tiling_name(info.georeference->tiling)) : "none";
  j["vtstream_source"] = s;
  return j.dump();
}

Result<ExportReport> export_web_tiles(const archive::Reader& reader, const TilesetInfo& info,
                                      const ExportOptions& o) {
  const auto t0 = Clock::now();
  if (Status s = validate(o.encode); !s) return s.error();
  auto grid = export_grid(info, o.layout, o.tiling);
  if (!grid) return grid.error();
  if (o.output.empty()) return make_error(ErrorCode::invalid_argument, "no output given");
  auto plan = make_plan(info, *grid);
  if (!plan) return plan.error();
  ExportReport r;
  r.bounds = plan->bounds;
  r.min_zoom = plan->min_zoom;
  r.max_zoom = plan->max_zoom;
  r.grid = *grid;
  Counters counters;
  // Walks the tiles into a sink and finishes it.
  const auto write = [&](TileSink& sink) -> Result<archive::WriterStats> {
    Status walked = plan->reproject ? walk_reprojected(reader, info, o, *plan, sink, counters)
                                    : walk_entries(reader, info, o, sink, counters);
    if (!walked) return walked.error();
    return sink.finish(export_metadata_json(info, reader.metadata_json(), o.source_name,
                                            reader.version(), o.format, r.bounds, r.min_zoom,
                                            r.max_zoom, r.grid));
  };
  std::optional<Result<archive::WriterStats>> stats;
  if (o.layout == ExportLayout::mbtiles) {
    // SQLite writes by name: into the temporary that replaces the output once complete.
    Status st = write_file_atomically(o.output, [&](int, const fs::path& tmp) -> Status {
      auto sink = open_mbtiles(info, o, *plan, tmp);
      if (!sink) return sink.error();
      stats = write(**sink);
      return *stats ? Status{} : Status{stats->error()};
    });
    if (!st) return st.error();
    std::error_code ec;
    (*stats)->file_bytes = fs::file_size(o.output, ec);
  } else {
    auto sink = open_sink(info, o, *plan);
    if (!sink) return sink.error();
    stats = write(**sink);
    if (!*stats) return stats->error();
  }
  const archive::WriterStats& written = **stats;
  r.source_tiles = counters.done.load();
  r.tiles_written = counters.written.load();
  r.tiles_skipped = counters.skipped.load();
  r.unique_tiles = written.tile_contents;
  r.tile_bytes = written.tile_bytes;
  r.file_bytes = written.file_bytes;
  r.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  return r;
}

}  // namespace builder
}  // namespace vts
