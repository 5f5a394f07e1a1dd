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

#include "build_plan.hpp"
#include "cascade.hpp"
#include "gdal_source.hpp"
#include "image_source.hpp"
#include "vts/builder/downsample.hpp"
#include "vts/builder/synthetic.hpp"
#include "vts/protocol/file_io.hpp"
#include "work_queue.hpp"

namespace vts {

namespace {

using Clock = std::chrono::steady_clock;
using detail::GdalSource;
using detail::ImageSource;
using detail::WorkQueue;

double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// State shared by the building thread and the encoder workers.
struct Shared {
  const Codec* codec = nullptr;
  EncodeOptions encode;
  pmtiles::Writer* writer = nullptr;
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
    auto payload = codec->encode(img, encode);
    if (!payload) return fail(std::move(payload).error());
    if (auto st = writer->add_tile(id, *payload); !st) return fail(st.error());
    if (auto header = parse_tile_header(*payload)) {
      const std::uint64_t key[2] = {pmtiles::zxy_to_tile_id(id.z, id.x, id.y), header->checksum};
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

unsigned worker_count(unsigned requested) {
  if (requested) return requested;
  return std::max(1u, std::thread::hardware_concurrency());
}

// Tiles of level z that a synthetic build writes: all of them, or only those over the region.
struct TileRange {
  std::uint32_t x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  std::uint64_t count() const { return std::uint64_t(x1 - x0) * (y1 - y0); }
};

TileRange synthetic_range(const Geometry& g, const SyntheticSpec& spec, int z) {
  TileRange r{0, 0, g.tiles_x(z), g.tiles_y(z)};
  if (!spec.region || z < spec.region_level) return r;
  const TexelRect level = g.map_rect(g.max_zoom(), *spec.region, z);
  const std::uint32_t T = g.tile_size();
  r.x0 = static_cast<std::uint32_t>(level.x0 / T);
  r.y0 = static_cast<std::uint32_t>(level.y0 / T);
  r.x1 = std::max(r.x0, static_cast<std::uint32_t>((level.x1 + T - 1) / T));
  r.y1 = std::max(r.y0, static_cast<std::uint32_t>((level.y1 + T - 1) / T));
  return r;
}

// Strips start at multiples of this row (GdalSource's warped VRTs are made of blocks this high).
constexpr std::uint32_t kStripAlign = detail::kWarpBlockRows;

// Reads columns [x0, x1) of rows [y, y + count) of a pass's finest level as RGBA8; each pass
// reads its rows in increasing order.
using WindowReader = std::function<Status(std::uint64_t x0, std::uint64_t x1, std::uint64_t y,
                                          std::uint32_t count, std::uint8_t* out)>;

// The tiles of every level a build writes: the footprint's (a sparse georeferenced build) or all.
std::vector<TileRect> emit_rects(const std::optional<Georeference>& geo, const Geometry& g) {
  std::vector<TileRect> rects;
  for (int z = 0; z <= g.max_zoom(); ++z)
    rects.push_back(geo ? footprint_tiles(geo->tiling, g, z, geo->bounds)
                        : TileRect{0, 0, g.tiles_x(z), g.tiles_y(z)});
  return rects;
}

// Everything the passes of one build share.
struct PassContext {
  const BuildOptions& o;
  const Geometry& g;
  Shared& shared;
  WorkQueue& queue;
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
  WorkQueue& queue = c.queue;
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
  std::vector<std::thread> threads;
  for (unsigned k = 0; k < nreaders; ++k)
    threads.emplace_back([&, k] {
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
    });
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
  for (auto& t : threads) t.join();
  c.rows += rows;
  if (auto e = channel.error(); e && !shared.failed) shared.fail(*e);
  if (!shared.failed && rows != w.height())
    shared.fail(make_error(ErrorCode::internal, "input ended early"));
}

// Runs the plan's passes in order: stripes fill their scratch rasters, which later passes read.
void build_from_source(const BuildOptions& o, const std::vector<WindowReader>& read_input,
                       const detail::BuildPlan& plan, const Geometry& g, Shared& shared,
                       unsigned threads) {
  std::vector<detail::ScratchRaster> scratch;
  for (const detail::ScratchPlan& sp : plan.scratch) {
    auto r = detail::ScratchRaster::create(o.output.parent_path(), sp.window);
    if (!r) return shared.fail(std::move(r).error());
    scratch.push_back(std::move(r).value());
  }
  WorkQueue queue(threads, std::size_t{threads} * 4);
  ProgressTicker ticker(o, shared, plan.tiles, plan.rows);
  PassContext c{o, g, shared, queue, ticker};
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
  queue.close_and_join();
  ticker.tick(c.rows, true);
}

void build_synthetic(const BuildOptions& o, const SyntheticSpec& spec, const Geometry& g,
                     Shared& shared, unsigned threads) {
  std::uint64_t total = 0;
  for (int z = 0; z <= g.max_zoom(); ++z) total += synthetic_range(g, spec, z).count();
  ProgressTicker ticker(o, shared, total, 0);
  WorkQueue queue(threads, std::size_t{threads} * 4);
  for (int z = 0; z <= g.max_zoom() && !shared.stopping(); ++z) {
    const TileRange r = synthetic_range(g, spec, z);
    for (std::uint32_t y = r.y0; y < r.y1 && !shared.stopping(); ++y) {
      for (std::uint32_t x = r.x0; x < r.x1; ++x) {
        const TileId id{static_cast<std::uint8_t>(z), x, y};
        Shared* s = &shared;
        const Geometry* gp = &g;
        queue.submit([s, gp, id] {
          if (!s->failed) s->store(id, synthetic_tile(*gp, id));
        });
      }
      ticker.tick(0);
    }
  }
  queue.close_and_join();
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
  detail::GdalSourceOptions go;
  go.tiling = o.tiling == Tiling::none ? Tiling::world_crs84_quad : o.tiling;
  go.tile_size = o.tile_size;
  go.border = o.border;
  go.max_level = o.max_level;
  go.resampling = o.resampling;
  go.warp_error = o.warp_error;
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
  go.bands = o.bands;
  go.value_ranges = o.band_ranges;
  if (o.value_range) go.value_ranges = {*o.value_range};
  go.auto_range = o.auto_range;
  auto s = GdalSource::open(o.inputs, go);
  if (s && o.on_warning)
    for (const std::string& w : (*s)->warnings()) o.on_warning(w);
  return s;
}

}  // namespace

Result<BuildReport> build_pyramid(const BuildOptions& o) {
  const auto t0 = Clock::now();
  if (o.output.empty()) return make_error(ErrorCode::invalid_argument, "no output file given");
  const Codec* codec = find_codec(o.codec);
  if (!codec)
    return make_error(ErrorCode::unsupported,
                      std::string("codec '") + codec_name(o.codec) + "' is not available yet");
  if (o.synthetic && !o.inputs.empty())
    return make_error(ErrorCode::invalid_argument, "give either input images or --synthetic");
  if (!o.synthetic && o.inputs.empty())
    return make_error(ErrorCode::invalid_argument, "no input image given");
  if (Status s = check_output_is_not_an_input(o.output, o.inputs); !s) return s.error();

  std::unique_ptr<ImageSource> source;
  std::unique_ptr<GdalSource> gdal;
  Tiling tiling = o.tiling;
  std::optional<LonLatBounds> data_bounds;
  std::uint64_t width = 0, height = 0;
  std::string input_desc;
  if (o.synthetic) {
    width = o.synthetic->width;
    height = o.synthetic->height;
    input_desc = "synthetic " + std::to_string(width) + "x" + std::to_string(height);
  } else if (o.tiling != Tiling::none || detail::gdal_is_georeferenced(o.inputs.front())) {
    auto src = open_gdal(o);
    if (!src) return std::move(src).error();
    gdal = std::move(src).value();
    width = gdal->width();
    height = gdal->height();
    input_desc = gdal->description();
    if (tiling == Tiling::none) tiling = Tiling::world_crs84_quad;
    data_bounds = gdal->bounds();
  } else {
    if (o.max_level || o.value_range || !o.band_ranges.empty() || o.auto_range || !o.bands.empty())
      return make_error(ErrorCode::invalid_argument,
                        "a maximum level, bands and a value range apply to georeferenced inputs "
                        "only "
                        "(" +
                            o.inputs.front().string() + " has no georeference)");
    auto src = ImageSource::open(o.inputs, o.grid_columns, o.grid_rows);
    if (!src) return std::move(src).error();
    source = std::move(src).value();
    width = source->width();
    height = source->height();
    input_desc = source->description();
  }
  auto geometry = Geometry::create(width, height, o.tile_size, o.border);
  if (!geometry) return std::move(geometry).error();
  const Geometry& g = *geometry;
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
  if (o.synthetic && o.synthetic->region) {
    const TexelRect& r = *o.synthetic->region;
    if (r.empty() || r.x1 > width || r.y1 > height)
      return make_error(ErrorCode::invalid_argument,
                        "region " + std::to_string(r.x0) + "," + std::to_string(r.y0) + "," +
                            std::to_string(r.x1) + "," + std::to_string(r.y1) +
                            " is empty or outside the " + std::to_string(width) + "x" +
                            std::to_string(height) + " image");
    if (o.synthetic->region_level < 0)
      return make_error(ErrorCode::invalid_argument, "region level must be >= 0");
  }

  std::optional<SyntheticSpec> synthetic = o.synthetic;
  auto georeference = make_georeference(o, tiling, data_bounds, g, synthetic);
  if (!georeference) return std::move(georeference).error();

  // Plain images are read whole rows at a time, once: one pass. Georeferenced ones are read in
  // windows of their footprint, in stripes when it is wider than the window limit.
  std::optional<detail::BuildPlan> plan;
  if (!synthetic) {
    const TexelRect window = gdal ? footprint_texels(tiling, g, (*georeference)->bounds)
                                  : TexelRect{0, 0, width, height};
    const std::uint64_t max_width =
        !gdal ? UINT64_MAX : (o.max_window_width ? o.max_window_width : kDefaultWindowWidth);
    auto p =
        detail::make_build_plan(g, o.downsample, window, emit_rects(*georeference, g), max_width);
    if (!p) return std::move(p).error();
    plan = std::move(p).value();
  }

  pmtiles::WriterOptions wo;
  if (*georeference)
    wo.bounds = pmtiles::georeferenced_bounds((*georeference)->bounds, (*georeference)->center);
  wo.path = o.output;
  wo.min_zoom = 0;
  wo.max_zoom = static_cast<std::uint8_t>(g.max_zoom());
  auto writer = pmtiles::Writer::create(wo);
  if (!writer) return std::move(writer).error();

  Shared shared;
  shared.codec = codec;
  shared.encode = o.encode;
  shared.writer = writer->get();
  shared.cancel = o.cancel;
  const unsigned threads = worker_count(o.threads);
  if (synthetic)
    build_synthetic(o, *synthetic, g, shared, threads);
  else if (gdal) {
    // The warp is most of the work: one reader per thread, each with its own GDAL datasets.
    std::vector<WindowReader> readers;
    for (GdalSource* r : gdal->split(threads))
      readers.push_back([r](std::uint64_t x0, std::uint64_t x1, std::uint64_t y, std::uint32_t n,
                            std::uint8_t* out) { return r->read_window(x0, x1, y, n, out); });
    build_from_source(o, readers, *plan, g, shared, threads);
  } else {
    build_from_source(o,
                      {[&](std::uint64_t, std::uint64_t, std::uint64_t y, std::uint32_t n,
                           std::uint8_t* out) { return source->read_rows(y, n, out); }},
                      *plan, g, shared, threads);
  }
  if (shared.failed) {
    (*writer)->abort();
    return *shared.error;
  }

  BuildReport report;
  report.input_description = input_desc;
  if (plan) {
    report.passes = plan->passes.size();
    report.window_width = plan->widest;
  }
  if (gdal) {
    report.warnings = gdal->warnings();
    report.value_ranges = gdal->value_ranges();
  }
  TilesetInfo& info = report.info;
  info.geometry = g;
  info.codec = o.codec;
  info.name = o.name.empty() ? o.output.stem().string() : o.name;
  info.description = o.description.empty() ? input_desc : o.description;
  info.downsample = o.synthetic ? "synthetic-per-level" : downsample_method(o.downsample);
  info.sparse = (synthetic && synthetic->region.has_value()) || gdal != nullptr;
  info.georeference = *georeference;
  char hash[17];
  std::snprintf(hash, sizeof hash, "%016llx",
                static_cast<unsigned long long>(shared.content_sum.load()));
  info.content_hash = hash;
  for (int z = 0; z <= g.max_zoom(); ++z) {
    std::uint64_t n = g.tile_count(z);
    if (synthetic)
      n = synthetic_range(g, *synthetic, z).count();
    else if (gdal)
      n = footprint_tiles(tiling, g, z, (*georeference)->bounds).count();
    report.levels.push_back({z, g.level_width(z), g.level_height(z), n});
  }
  if (o.cancel && o.cancel->load()) {
    (*writer)->abort();
    return make_error(ErrorCode::cancelled, "build cancelled");
  }
  if (o.on_progress) {
    BuildProgress p;
    p.tiles_done = p.tiles_total = shared.tiles_done;
    p.bytes_written = shared.bytes;
    p.seconds = seconds_since(t0);
    p.finishing = true;
    o.on_progress(p);
  }
  auto stats = (*writer)->finish(info.to_json());
  if (!stats) return std::move(stats).error();
  report.stats = *stats;
  report.seconds = seconds_since(t0);
  return report;
}

}  // namespace vts
