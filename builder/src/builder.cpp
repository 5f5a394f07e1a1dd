#include "vts/builder/builder.hpp"

#include <algorithm>
#include <cassert>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <thread>

#include <xxhash.h>

#include "build_core.hpp"
#include "build_plan.hpp"
#include "cascade.hpp"
#include "gdal_source.hpp"
#include "image_source.hpp"
#include "input_drivers.hpp"
#include "vts/base/file_io.hpp"
#include "vts/builder/downsample.hpp"
#include "vts/builder/synthetic.hpp"
#include "work_queue.hpp"

namespace vts {
inline namespace builder {

namespace {

using Clock = std::chrono::steady_clock;
using detail::GdalSource;
using detail::ImageSource;

double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// State shared by the building thread and the encoder workers.
struct Shared {
  CodecId codec = CodecId::lossless;
  EncodeOptions encode;
  archive::TileSink* sink = nullptr;
  // A shard's level-A tiles, kept lossless for the apex (shard.hpp).
  std::optional<detail::BuildRun::Keep> keep;
  std::mutex kept_mutex;
  std::map<std::pair<std::uint32_t, std::uint32_t>, std::vector<std::uint8_t>> kept;
  const std::atomic<bool>* cancel = nullptr;
  std::atomic<std::uint64_t> tiles_done{0};
  std::atomic<std::uint64_t> bytes{0};
  // Sum over tiles of XXH3(tile id, payload checksum): order-independent, so encoder threads can
  // add in any order. Becomes TilesetInfo::content_hash.
  std::atomic<std::uint64_t> content_sum{0};
  std::atomic<bool> failed{false};
  std::mutex error_mutex;
  std::optional<Error> error;

  void fail(Error e) {
    std::lock_guard lock(error_mutex);
    if (!error) error = std::move(e);
    failed = true;
  }
  // True when the build must stop (an error, or the caller cancelled).
  bool stopping() {
    if (!failed && cancel && cancel->load())
      fail(make_error(ErrorCode::cancelled, "build cancelled"));
    return failed;
  }
  void store(TileId id, const TileImage& img) {
    if (failed) return;
    auto payload = encode_tile(img, codec, encode);
    if (!payload) return fail(std::move(payload).error());
    if (auto st = sink->add_tile(id, *payload); !st) return fail(st.error());
    if (keep && id.z == keep->z && id.x >= keep->rect.x0 && id.x < keep->rect.x1 &&
        id.y >= keep->rect.y0 && id.y < keep->rect.y1) {
      auto exact = encode_lossless(img);
      if (!exact) return fail(std::move(exact).error());
      std::lock_guard lock(kept_mutex);
      kept[{id.y, id.x}] = std::move(exact).value();
    }
    if (auto header = parse_tile_header(*payload)) {
      const std::uint64_t key[2] = {archive::zxy_to_tile_id(id.z, id.x, id.y), header->checksum};
      content_sum += XXH3_64bits(key, sizeof key);
    }
    bytes += payload->size();
    ++tiles_done;
  }
};

// Strips of scanlines handed from the reader threads to the cascade in order, with a fixed number
// of buffers: reader k of n reads strips k, k + n, ...; strip i may take a buffer only while
// i < next + buffers - 1 (next: the strip the cascade waits for), so the strip it waits for
// always finds one and the readers never run ahead by more than the buffers.
class StripChannel {
 public:
  struct Strip {
    std::uint64_t index = 0, y = 0;
    std::uint32_t rows = 0;
    std::vector<std::uint8_t> pixels;
  };

  StripChannel(std::size_t buffers, std::size_t bytes, unsigned readers)
      : buffers_(buffers), readers_(readers) {
    for (std::size_t i = 0; i < buffers; ++i) free_.emplace_back().pixels.resize(bytes);
  }
  // Reader side: a buffer for strip `index`, once its turn comes; nullopt when closed.
  std::optional<Strip> take_free(std::uint64_t index) {
    std::unique_lock lock(m_);
    cv_.wait(lock, [&] { return closed_ || (!free_.empty() && index + 1 < next_ + buffers_); });
    if (closed_) return std::nullopt;
    Strip s = std::move(free_.front());
    free_.pop_front();
    s.index = index;
    return s;
  }
  void put_full(Strip s) {
    std::lock_guard lock(m_);
    const std::uint64_t i = s.index;
    full_.emplace(i, std::move(s));
    cv_.notify_all();
  }
  // A reader is done (after its last strip, or on an error: the first one is kept).
  void finish_reading(std::optional<Error> error) {
    std::lock_guard lock(m_);
    --readers_;
    if (error && !error_) error_ = std::move(error);
    cv_.notify_all();
  }
  // Consumer side: the next strip in order; nullopt at the end or after an error (check error()).
  std::optional<Strip> take_full() {
    std::unique_lock lock(m_);
    cv_.wait(lock, [&] { return error_ || readers_ == 0 || full_.count(next_); });
    auto it = full_.find(next_);
    if (error_ || it == full_.end()) return std::nullopt;
    Strip s = std::move(it->second);
    full_.erase(it);
    ++next_;
    cv_.notify_all();
    return s;
  }
  void give_back(Strip s) {
    std::lock_guard lock(m_);
    free_.push_back(std::move(s));
    cv_.notify_all();
  }
  void close() {
    std::lock_guard lock(m_);
    closed_ = true;
    cv_.notify_all();
  }
  std::optional<Error> error() {
    std::lock_guard lock(m_);
    return error_;
  }

 private:
  std::mutex m_;
  std::condition_variable cv_;
  std::deque<Strip> free_;
  std::map<std::uint64_t, Strip> full_;
  std::size_t buffers_;
  unsigned readers_;
  std::uint64_t next_ = 0;
  bool closed_ = false;
  std::optional<Error> error_;
};

class ProgressTicker {
 public:
  ProgressTicker(const BuildOptions& o, Shared& s, std::uint64_t tiles_total,
                 std::uint64_t rows_total)
      : o_(o), s_(s), t0_(Clock::now()) {
    p_.tiles_total = tiles_total;
    p_.rows_total = rows_total;
  }
  void tick(std::uint64_t rows_read, bool force = false) {
    if (!o_.on_progress) return;
    const auto now = Clock::now();
    if (!force && now - last_ < std::chrono::milliseconds(100)) return;
    last_ = now;
    p_.rows_read = rows_read;
    p_.tiles_done = s_.tiles_done;
    p_.bytes_written = s_.bytes;
    p_.seconds = seconds_since(t0_);
    o_.on_progress(p_);
  }

 private:
  const BuildOptions& o_;
  Shared& s_;
  Clock::time_point t0_, last_{};
  BuildProgress p_;
};

// Strips start at multiples of this row (GdalSource's warped VRTs are made of blocks this high).
constexpr std::uint32_t kStripAlign = detail::kWarpBlockRows;

using detail::WindowReader;

// Everything the passes of one build share.
struct PassContext {
  const BuildOptions& o;
  const Geometry& g;
  Shared& shared;
  WorkerPool& queue;  // the encoders (detail::start_encoders)
  ProgressTicker& ticker;
  std::uint64_t rows = 0;  // read so far, all passes
};

// One pass (build_plan.hpp): a reader thread reads strips of the window's rows, this thread pushes
// them through the cascade, whose tiles go to the encoder pool and whose coarsest rows, for a
// stripe, to its scratch raster.
void run_pass(PassContext& c, const detail::Pass& pass, const std::vector<WindowReader>& readers,
              detail::ScratchRaster* scratch) {
  const std::vector<TexelRect> windows = detail::pass_windows(c.g, c.o.downsample, pass);
  const TexelRect& coarse = windows[static_cast<std::size_t>(pass.coarsest)];
  Shared& shared = c.shared;
  WorkerPool& queue = c.queue;
  detail::Cascade::RowSink to_scratch;
  if (scratch)
    to_scratch = [&](std::uint64_t y, const std::uint8_t* row) {
      if (shared.failed) return;
      const std::uint8_t* from = row + (pass.core_x0 - coarse.x0) * 4;
      if (Status st = scratch->write(y, pass.core_x0, pass.core_x1, from); !st)
        shared.fail(st.error());
    };
  detail::Cascade cascade(
      c.g, pass.finest, pass.coarsest, windows, c.o.downsample, pass.emit,
      [&](TileId id, TileImage&& img) {
        Shared* s = &shared;
        queue.submit([s, id, img = std::move(img)] { s->store(id, img); });
      },
      to_scratch);
  const TexelRect& w = pass.window;
  const std::uint64_t row_bytes = w.width() * 4;
  // About 4 MiB per strip. Several readers (the warp): a multiple of kStripAlign rows (the warped
  // VRTs' block height) starting at multiples of it, so that strips of different readers never
  // share a block of the warp, which each would otherwise compute again (at most 16 MiB: 128 rows
  // of 32768). One reader: 1 to 64 rows.
  const std::uint64_t fit = (4u << 20) / row_bytes;
  const auto strip_rows = static_cast<std::uint32_t>(
      readers.size() > 1 ? std::max<std::uint64_t>(fit / kStripAlign, 1) * kStripAlign
                         : std::clamp<std::uint64_t>(fit, 1, 64));
  const std::uint64_t first = w.y0 / strip_rows * strip_rows;  // strip i: [first + i * rows, ...)
  const auto nreaders = static_cast<unsigned>(readers.size());
  StripChannel channel(nreaders + 2, strip_rows * row_bytes, nreaders);
  detail::ThreadGroup threads;
  for (unsigned k = 0; k < nreaders; ++k) {
    Status started = threads.start(
        [&, k] {
          std::optional<Error> error;
          for (std::uint64_t i = k;; i += nreaders) {
            const std::uint64_t y = std::max(w.y0, first + i * strip_rows);
            if (y >= w.y1) break;
            auto strip = channel.take_free(i);
            if (!strip || shared.failed) break;
            strip->y = y;
            strip->rows = static_cast<std::uint32_t>(
                std::min<std::uint64_t>(first + (i + 1) * strip_rows, w.y1) - y);
            if (auto st = readers[k](w.x0, w.x1, y, strip->rows, strip->pixels.data()); !st) {
              error = st.error();
              break;
            }
            channel.put_full(std::move(*strip));
          }
          channel.finish_reading(std::move(error));
        },
        "reader");
    if (!started) {
      // The readers started so far stop at their next strip; the missing ones never finish.
      shared.fail(started.error());
      channel.close();
      return;
    }
  }
  std::uint64_t rows = 0;
  while (auto strip = channel.take_full()) {
    for (std::uint32_t r = 0; r < strip->rows && !shared.stopping(); ++r)
      cascade.push_row(strip->pixels.data() + r * row_bytes);
    rows += strip->rows;
    channel.give_back(std::move(*strip));
    c.ticker.tick(c.rows + rows);
    if (shared.stopping()) break;
  }
  channel.close();
  threads.join();
  c.rows += rows;
  if (auto e = channel.error(); e && !shared.failed) shared.fail(*e);
  if (!shared.failed && rows != w.height())
    shared.fail(make_error(ErrorCode::internal, "input ended early"));
}

// Runs the plan's passes in order: stripes fill their scratch rasters, which later passes read.
void build_from_source(const BuildOptions& o, const std::filesystem::path& scratch_dir,
                       const std::vector<WindowReader>& read_input, const detail::BuildPlan& plan,
                       const Geometry& g, Shared& shared, unsigned threads) {
  std::vector<detail::ScratchRaster> scratch;
  for (const detail::ScratchPlan& sp : plan.scratch) {
    auto r = detail::ScratchRaster::create(scratch_dir, sp.window);
    if (!r) return shared.fail(std::move(r).error());
    scratch.push_back(std::move(r).value());
  }
  auto queue = detail::start_encoders(threads);
  if (!queue) return shared.fail(std::move(queue).error());
  ProgressTicker ticker(o, shared, plan.tiles, plan.rows);
  PassContext c{o, g, shared, **queue, ticker};
  for (const detail::Pass& pass : plan.passes) {
    if (shared.stopping()) break;
    std::vector<WindowReader> from_scratch;
    if (pass.source >= 0)
      from_scratch.push_back([&, i = static_cast<std::size_t>(pass.source)](
                                 std::uint64_t x0, std::uint64_t x1, std::uint64_t y,
                                 std::uint32_t n,
                                 std::uint8_t* out) { return scratch[i].read(x0, x1, y, n, out); });
    run_pass(c, pass, pass.source >= 0 ? from_scratch : read_input,
             pass.scratch >= 0 ? &scratch[static_cast<std::size_t>(pass.scratch)] : nullptr);
  }
  (*queue)->join();
  ticker.tick(c.rows, true);
}

void build_synthetic(const BuildOptions& o, const std::vector<TileRect>& levels, const Geometry& g,
                     Shared& shared, unsigned threads) {
  std::uint64_t total = 0;
  for (const TileRect& r : levels) total += r.count();
  ProgressTicker ticker(o, shared, total, 0);
  auto started = detail::start_encoders(threads);
  if (!started) return shared.fail(std::move(started).error());
  WorkerPool& queue = **started;
  for (int z = 0; z < static_cast<int>(levels.size()) && !shared.stopping(); ++z) {
    const TileRect r = levels[static_cast<std::size_t>(z)];
    for (std::uint32_t y = r.y0; y < r.y1 && !shared.stopping(); ++y) {
      // A row can be millions of tiles long (--synthetic 4294967296x1): stop checks per tile.
      for (std::uint32_t x = r.x0; x < r.x1 && !shared.stopping(); ++x) {
        const TileId id{static_cast<std::uint8_t>(z), x, y};
        Shared* s = &shared;
        const Geometry* gp = &g;
        queue.submit([s, gp, id] {
          if (!s->failed) s->store(id, synthetic_tile(*gp, id));
        });
        ticker.tick(0);
      }
    }
  }
  queue.join();
  ticker.tick(0, true);
}

// The georeference BuildOptions asks for (nullopt for a plain image), checked against the
// geometry. A synthetic build without a region of its own gets the footprint as its region, at
// every level.
// `tiling` and `data_bounds` are the scheme and footprint of georeferenced inputs, if any.
Result<std::optional<Georeference>> make_georeference(
    const BuildOptions& o, Tiling tiling, const std::optional<LonLatBounds>& data_bounds,
    const Geometry& g, std::optional<SyntheticSpec>& synthetic) {
  if (tiling == Tiling::none) {
    if (o.bounds) return make_error(ErrorCode::invalid_argument, "bounds need a tiling scheme");
    return std::optional<Georeference>();
  }
  Georeference geo;
  geo.tiling = tiling;
  geo.bounds = o.bounds.value_or(data_bounds.value_or(scheme_extent(tiling)));
  if (Status s = check_tiling_geometry(tiling, g); !s) return s.error();
  // The center is checked with the bounds; compute it only from bounds that can be valid.
  geo.center = {geo.bounds.west, geo.bounds.south, 0};
  if (Status s = check_georeference(geo, g); !s) return s.error();
  geo.center = default_center(tiling, g, geo.bounds);
  if (synthetic && !synthetic->region) {
    synthetic->region = footprint_texels(tiling, g, geo.bounds);
    synthetic->region_level = 0;
  }
  return std::optional<Georeference>(geo);
}

// Georeferenced inputs through GDAL; a C x R grid does not apply (they place themselves).
Result<std::unique_ptr<GdalSource>> open_gdal(const BuildOptions& o) {
  if (o.grid_columns != 1 || o.grid_rows != 1)
    return make_error(ErrorCode::invalid_argument,
                      "a mosaic grid does not apply to georeferenced inputs (each is placed by its "
                      "georeference)");
  detail::GdalSourceOptions go = detail::gdal_source_options(o);
  if (o.on_progress)
    go.on_probe = [&o, last = Clock::time_point{}](std::size_t done, std::size_t total) mutable {
      const auto now = Clock::now();
      if (done < total && now - last < std::chrono::milliseconds(100)) return;
      last = now;
      BuildProgress p;
      p.inputs_checked = done;
      p.inputs_total = total;
      o.on_progress(p);
    };
  auto drivers = detail::input_drivers();
  if (!drivers) return std::move(drivers).error();
  auto s = (*drivers)->open_georeferenced(o.inputs, go);
  if (s && o.on_warning)
    for (const std::string& w : (*s)->warnings()) o.on_warning(w);
  return s;
}

}  // namespace

namespace detail {

GdalSourceOptions gdal_source_options(const BuildOptions& o) {
  GdalSourceOptions go;
  go.tiling = o.tiling == Tiling::none ? Tiling::world_crs84_quad : o.tiling;
  go.tile_size = o.tile_size;
  go.border = o.border;
  go.max_level = o.max_level;
  go.resampling = o.resampling;
  go.warp_error = o.warp_error;
  go.bands = o.bands;
  go.value_ranges = o.band_ranges;
  if (o.value_range) go.value_ranges = {*o.value_range};
  go.auto_range = o.auto_range;
  return go;
}

unsigned worker_count(unsigned requested) {
  if (requested) return requested;
  return std::max(1u, std::thread::hardware_concurrency());
}

TileRect synthetic_tiles(const Geometry& g, const SyntheticSpec& spec, int z) {
  TileRect r{0, 0, g.tiles_x(z), g.tiles_y(z)};
  if (!spec.region || z < spec.region_level) return r;
  const TexelRect level = g.map_rect(g.max_zoom(), *spec.region, z);
  const std::uint32_t T = g.tile_size();
  r.x0 = static_cast<std::uint32_t>(level.x0 / T);
  r.y0 = static_cast<std::uint32_t>(level.y0 / T);
  r.x1 = std::max(r.x0, static_cast<std::uint32_t>((level.x1 + T - 1) / T));
  r.y1 = std::max(r.y0, static_cast<std::uint32_t>((level.y1 + T - 1) / T));
  return r;
}

std::vector<TileRect> build_emit_rects(const PreparedBuild& p) {
  const Geometry& g = *p.geometry;
  std::vector<TileRect> rects;
  for (int z = 0; z <= g.max_zoom(); ++z) {
    if (p.synthetic)
      rects.push_back(synthetic_tiles(g, *p.synthetic, z));
    else if (p.gdal_inputs)
      rects.push_back(footprint_tiles(p.tiling, g, z, p.georeference->bounds));
    else
      rects.push_back(TileRect{0, 0, g.tiles_x(z), g.tiles_y(z)});
  }
  return rects;
}

std::string content_hash_text(std::uint64_t content_sum) {
  char hash[17];
  std::snprintf(hash, sizeof hash, "%016llx", static_cast<unsigned long long>(content_sum));
  return hash;
}

TilesetInfo build_tileset_info(const BuildOptions& o, const PreparedBuild& p,
                               const std::filesystem::path& output, std::uint64_t content_sum) {
  TilesetInfo info;
  info.geometry = *p.geometry;
  info.codec = o.codec;
  info.name = o.name.empty() ? output.stem().string() : o.name;
  info.description = o.description.empty() ? p.input_description : o.description;
  info.downsample = o.synthetic ? "synthetic-per-level" : downsample_method(o.downsample);
  info.sparse = (p.synthetic && p.synthetic->region.has_value()) || p.gdal_inputs;
  info.georeference = p.georeference;
  info.content_hash = content_hash_text(content_sum);
  return info;
}

archive::WriterOptions build_writer_options(const PreparedBuild& p,
                                            const std::filesystem::path& output) {
  archive::WriterOptions wo;
  if (p.georeference)
    wo.bounds = archive::georeferenced_bounds(p.georeference->bounds, p.georeference->center);
  wo.path = output;
  wo.min_zoom = 0;
  wo.max_zoom = static_cast<std::uint8_t>(p.geometry->max_zoom());
  return wo;
}

std::vector<WindowReader> source_readers(PreparedBuild& p, unsigned threads) {
  std::vector<WindowReader> readers;
  if (p.gdal) {
    // The warp is most of the work: one reader per thread, each with its own GDAL datasets.
    for (GdalSource* r : p.gdal->split(threads))
      readers.push_back([r](std::uint64_t x0, std::uint64_t x1, std::uint64_t y, std::uint32_t n,
                            std::uint8_t* out) { return r->read_window(x0, x1, y, n, out); });
    return readers;
  }
  // A narrower window than the image (a shard) reads only its columns.
  ImageSource* src = p.source.get();
  readers.push_back([src](std::uint64_t x0, std::uint64_t x1, std::uint64_t y, std::uint32_t n,
                          std::uint8_t* out) { return src->read_window(x0, x1, y, n, out); });
  return readers;
}

Result<BuildRunResult> run_build(const BuildRun& run) {
  Shared shared;
  shared.codec = run.codec;
  shared.encode = run.options->encode;
  shared.sink = run.sink;
  shared.cancel = run.options->cancel;
  shared.keep = run.keep;
  const unsigned threads = worker_count(run.threads);
  if (run.plan)
    build_from_source(*run.options, run.scratch_dir, run.readers, *run.plan, *run.geometry, shared,
                      threads);
  else
    build_synthetic(*run.options, run.synthetic, *run.geometry, shared, threads);
  if (shared.failed) return *shared.error;
  if (run.options->cancel && run.options->cancel->load())
    return make_error(ErrorCode::cancelled, "build cancelled");
  BuildRunResult r;
  r.tiles = shared.tiles_done;
  r.bytes = shared.bytes;
  r.content_sum = shared.content_sum;
  r.kept = std::move(shared.kept);
  return r;
}

namespace {

Status check_synthetic_region(const SyntheticSpec& s, std::uint64_t width, std::uint64_t height) {
  if (!s.region) return {};
  const TexelRect& r = *s.region;
  if (r.empty() || r.x1 > width || r.y1 > height)
    return make_error(ErrorCode::invalid_argument,
                      "region " + std::to_string(r.x0) + "," + std::to_string(r.y0) + "," +
                          std::to_string(r.x1) + "," + std::to_string(r.y1) +
                          " is empty or outside the " + std::to_string(width) + "x" +
                          std::to_string(height) + " image");
  if (s.region_level < 0)
    return make_error(ErrorCode::invalid_argument, "region level must be >= 0");
  return {};
}

// Opens the source of a build's inputs (not synthetic).
Status open_source(const BuildOptions& o, PreparedBuild& p) {
  auto drivers = detail::input_drivers();
  if (!drivers) return std::move(drivers).error();
  if (o.tiling != Tiling::none || (*drivers)->is_georeferenced(o.inputs.front())) {
    auto src = open_gdal(o);
    if (!src) return std::move(src).error();
    p.gdal = std::move(src).value();
    p.gdal_inputs = true;
    p.input_description = p.gdal->description();
    if (p.tiling == Tiling::none) p.tiling = Tiling::world_crs84_quad;
    return {};
  }
  if (o.max_level || o.value_range || !o.band_ranges.empty() || o.auto_range || !o.bands.empty())
    return make_error(ErrorCode::invalid_argument,
                      "a maximum level, bands and a value range apply to georeferenced inputs "
                      "only "
                      "(" +
                          o.inputs.front().string() + " has no georeference)");
  auto src = (*drivers)->open_image(o.inputs, o.grid_columns, o.grid_rows);
  if (!src) return std::move(src).error();
  p.source = std::move(src).value();
  p.input_description = p.source->description();
  return {};
}

}  // namespace

Result<PreparedBuild> prepare_build(const BuildOptions& o) {
  PreparedBuild p;
  if (find_codec(o.codec) == nullptr)
    return make_error(ErrorCode::unsupported,
                      std::string("codec '") + codec_name(o.codec) + "' is not available yet");
  p.codec = o.codec;
  if (o.synthetic && !o.inputs.empty())
    return make_error(ErrorCode::invalid_argument, "give either input images or --synthetic");
  if (!o.synthetic && o.inputs.empty())
    return make_error(ErrorCode::invalid_argument, "no input image given");
  p.tiling = o.tiling;
  std::uint64_t width = 0, height = 0;
  if (o.synthetic) {
    width = o.synthetic->width;
    height = o.synthetic->height;
    p.input_description = "synthetic " + std::to_string(width) + "x" + std::to_string(height);
  } else {
    if (Status st = open_source(o, p); !st) return st.error();
    width = p.gdal ? p.gdal->width() : p.source->width();
    height = p.gdal ? p.gdal->height() : p.source->height();
  }
  auto geometry = Geometry::create(width, height, o.tile_size, o.border);
  if (!geometry) return std::move(geometry).error();
  const Geometry& g = *geometry;
  p.geometry = g;
  // A bc1 tile is whole 4x4 blocks, and the renderer places tiles in its compressed atlas at
  // block-aligned slots: the stored size T + 2B must be a multiple of 4 (T is a power of two >= 4,
  // so B must be even).
  if (o.codec == CodecId::bc1 && g.stored_size() % 4 != 0)
    return make_error(ErrorCode::invalid_argument,
                      "codec bc1 needs tile + 2 x border to be a multiple of 4, whole 4x4 blocks "
                      "(tile " +
                          std::to_string(g.tile_size()) + " + 2 x border " +
                          std::to_string(g.border()) + " = " + std::to_string(g.stored_size()) +
                          "): use an even border");
  if (o.synthetic)
    if (Status st = check_synthetic_region(*o.synthetic, width, height); !st) return st.error();
  p.synthetic = o.synthetic;
  std::optional<LonLatBounds> data_bounds;
  if (p.gdal) data_bounds = p.gdal->bounds();
  auto georeference = make_georeference(o, p.tiling, data_bounds, g, p.synthetic);
  if (!georeference) return std::move(georeference).error();
  p.georeference = *georeference;
  return p;
}

Result<BuildReport> build(const BuildOptions& o) {
  const auto t0 = Clock::now();
  if (o.output.empty()) return make_error(ErrorCode::invalid_argument, "no output file given");
  if (Status s = check_output_is_not_an_input(o.output, o.inputs); !s) return s.error();
  auto prepared = detail::prepare_build(o);
  if (!prepared) return std::move(prepared).error();
  detail::PreparedBuild& p = *prepared;
  const Geometry& g = *p.geometry;
  const std::vector<TileRect> emit = detail::build_emit_rects(p);

  // Plain images are read whole rows at a time, once: one pass. Georeferenced ones are read in
  // windows of their footprint, in stripes when it is wider than the window limit.
  std::optional<detail::BuildPlan> plan;
  if (!p.synthetic) {
    const TexelRect window = p.gdal ? footprint_texels(p.tiling, g, p.georeference->bounds)
                                    : TexelRect{0, 0, g.width(), g.height()};
    const std::uint64_t max_width =
        !p.gdal ? UINT64_MAX : (o.max_window_width ? o.max_window_width : kDefaultWindowWidth);
    auto bp = detail::make_build_plan(g, o.downsample, window, emit, max_width);
    if (!bp) return std::move(bp).error();
    plan = std::move(bp).value();
  }

  auto writer = archive::Writer::create(detail::build_writer_options(p, o.output));
  if (!writer) return std::move(writer).error();
  detail::BuildRun run;
  run.options = &o;
  run.scratch_dir = o.output.parent_path();
  run.geometry = &g;
  run.codec = p.codec;
  run.sink = writer->get();
  run.threads = o.threads;
  if (plan) {
    run.plan = &*plan;
    run.readers = detail::source_readers(p, detail::worker_count(o.threads));
  } else {
    run.synthetic = emit;
  }
  auto result = detail::run_build(run);
  if (!result) {
    (*writer)->abort();
    return std::move(result).error();
  }

  BuildReport report;
  report.input_description = p.input_description;
  if (plan) {
    report.passes = plan->passes.size();
    report.window_width = plan->widest;
  }
  if (p.gdal) {
    report.warnings = p.gdal->warnings();
    report.value_ranges = p.gdal->value_ranges();
  }
  report.info = detail::build_tileset_info(o, p, o.output, result->content_sum);
  for (int z = 0; z <= g.max_zoom(); ++z)
    report.levels.push_back(
        {z, g.level_width(z), g.level_height(z),
         p.synthetic || p.gdal ? emit[static_cast<std::size_t>(z)].count() : g.tile_count(z)});
  if (o.on_progress) {
    BuildProgress bp;
    bp.tiles_done = bp.tiles_total = result->tiles;
    bp.bytes_written = result->bytes;
    bp.seconds = seconds_since(t0);
    bp.finishing = true;
    o.on_progress(bp);
  }
  auto stats = (*writer)->finish(report.info.to_json());
  if (!stats) return std::move(stats).error();
  report.stats = *stats;
  report.seconds = seconds_since(t0);
  return report;
}

}  // namespace detail

Result<BuildReport> build_synthetic_pyramid(const BuildOptions& o) {
  if (!o.synthetic)
    return make_error(ErrorCode::invalid_argument,
                      "build_synthetic_pyramid builds synthetic options only");
  return detail::build(o);
}

}  // namespace builder
}  // namespace vts
