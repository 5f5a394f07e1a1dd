// `vts export --format gtiff`: one level (or a box of it) as a Cloud Optimized GeoTIFF whose
// overviews are our coarser levels (vts/builder/export.hpp).
#include <gdal_priv.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <map>
#include <mutex>
#include <vector>

#include "export_pipeline.hpp"
#include "gdal_output.hpp"
#include "vts/archive/inspect.hpp"
#include "vts/base/file_io.hpp"
#include "vts/builder/export.hpp"

namespace vts {
inline namespace builder {

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

// GeoTIFF blocks (and the COG's), texels a side: GDAL's COG default.
constexpr std::uint32_t kBlock = 512;

// A coordinate within 1e-6 texel of an integer counts as that integer (as footprint_texels).
double snap_down(double v) {
  return std::floor(v + 1e-6);
}
double snap_up(double v) {
  return std::ceil(v - 1e-6);
}

// The region of level z the box covers, rounded outwards to multiples of `step` texels and
// clipped to the level. Empty when the box misses the level.
TexelRect box_texels(const TilesetInfo& info, int z, const LonLatBounds& b, std::uint64_t step) {
  const Tiling t = info.georeference->tiling;
  const std::uint32_t T = info.geometry.tile_size();
  const TexelPoint a = lonlat_to_texel(t, T, z, {b.west, b.north});
  const TexelPoint c = lonlat_to_texel(t, T, z, {b.east, b.south});
  const double w = double(info.geometry.level_width(z)), h = double(info.geometry.level_height(z));
  const double s = double(step);
  const auto x0 = std::clamp(std::floor(snap_down(a.x) / s) * s, 0.0, w);
  const auto y0 = std::clamp(std::floor(snap_down(a.y) / s) * s, 0.0, h);
  const auto x1 = std::clamp(std::ceil(snap_up(c.x) / s) * s, 0.0, w);
  const auto y1 = std::clamp(std::ceil(snap_up(c.y) / s) * s, 0.0, h);
  return {std::uint64_t(x0), std::uint64_t(y0), std::uint64_t(x1), std::uint64_t(y1)};
}

// Overviews until the coarsest fits one block, and no coarser than our level 0.
int overview_count(const TexelRect& r, int z) {
  int k = 0;
  while (k < z &&
         std::max((r.width() + (1ull << k) - 1) >> k, (r.height() + (1ull << k) - 1) >> k) > kBlock)
    ++k;
  return k;
}

// Writes rectangle `rect` of level z, assembled from our tiles, into `ds` (rect.width() x
// rect.height(), 4 bands) one row of blocks per job. GDAL is called under `gdal` (one dataset,
// one writer at a time); the tiles of a row's previous block are kept for the next (they share a
// column when the rectangle is not tile-aligned), nothing older.
class LevelWriter {
 public:
  using Cache = std::map<std::uint64_t, std::optional<TileImage>>;

  LevelWriter(const archive::Reader& r, const TilesetInfo& info, GDALDataset& ds, std::mutex& gdal,
              detail::Counters& c, const std::atomic<bool>* cancel)
      : reader_(r), info_(info), ds_(ds), gdal_(gdal), counters_(c), cancel_(cancel) {}

  Status row(int z, const TexelRect& rect, std::uint64_t y0) const {
    Cache previous, current;
    std::vector<std::uint8_t> block;
    const std::uint64_t y1 = std::min(rect.y1, y0 + kBlock);
    for (std::uint64_t x0 = rect.x0; x0 < rect.x1; x0 += kBlock) {
      if (cancel_ && cancel_->load()) return make_error(ErrorCode::cancelled, "export cancelled");
      const TexelRect b{x0, y0, std::min(rect.x1, x0 + kBlock), y1};
      block.assign(b.width() * b.height() * 4, 0);
      if (Status s = assemble(z, b, block, previous, current); !s) return s;
      if (Status s = write(rect, b, block); !s) return s;
      previous = std::move(current);
      current.clear();
      counters_.done.fetch_add(1);
    }
    return {};
  }

 private:
  Result<const std::optional<TileImage>*> tile(TileId id, Cache& previous, Cache& current) const {
    const std::uint64_t key = tile_key(id);
    if (auto it = current.find(key); it != current.end()) return &it->second;
    if (auto it = previous.find(key); it != previous.end())
      return &current.emplace(key, std::move(it->second)).first->second;
    auto img = archive::read_tile_rgba8(reader_, info_, id);
    std::optional<TileImage> held;
    if (img)
      held = std::move(img).value();
    else if (!(img.error().code == ErrorCode::not_found && info_.sparse))
      return std::move(img).error();  // a sparse archive's absent tile is transparent
    return &current.emplace(key, std::move(held)).first->second;
  }

  // Copies the content texels of every tile meeting `b` (level z texels) into `out`.
  Status assemble(int z, const TexelRect& b, std::vector<std::uint8_t>& out, Cache& previous,
                  Cache& current) const {
    const Geometry& g = info_.geometry;
    const std::uint32_t T = g.tile_size(), B = g.border(), S = g.stored_size();
    for (std::uint64_t ty = b.y0 / T; ty * T < b.y1; ++ty)
      for (std::uint64_t tx = b.x0 / T; tx * T < b.x1; ++tx) {
        const TileId id{static_cast<std::uint8_t>(z), std::uint32_t(tx), std::uint32_t(ty)};
        if (!g.exists(id)) continue;
        auto img = tile(id, previous, current);
        if (!img) return img.error();
        if (!**img) continue;
        const TileImage& t = ***img;
        const TexelRect c = g.content_rect(id);
        const std::uint64_t x0 = std::max(b.x0, c.x0), x1 = std::min(b.x1, c.x1);
        for (std::uint64_t y = std::max(b.y0, c.y0); y < std::min(b.y1, c.y1); ++y)
          std::memcpy(&out[((y - b.y0) * b.width() + (x0 - b.x0)) * 4],
                      &t.pixels[((B + y - c.y0) * S + B + (x0 - c.x0)) * 4], (x1 - x0) * 4);
      }
    return {};
  }

  Status write(const TexelRect& rect, const TexelRect& b, std::vector<std::uint8_t>& block) const {
    std::lock_guard lock(gdal_);
    detail::GdalErrors errors;
    const int w = int(b.width()), h = int(b.height());
    if (ds_.RasterIO(GF_Write, int(b.x0 - rect.x0), int(b.y0 - rect.y0), w, h, block.data(), w, h,
                     GDT_Byte, 4, nullptr, 4, GSpacing{w} * 4, 1, nullptr) != CE_None)
      return errors.error("cannot write the temporary GeoTIFF");
    return {};
  }

  const archive::Reader& reader_;
  const TilesetInfo& info_;
  GDALDataset& ds_;
  std::mutex& gdal_;
  detail::Counters& counters_;
  const std::atomic<bool>* cancel_;
};

std::uint64_t block_count(const TexelRect& r) {
  return ((r.width() + kBlock - 1) / kBlock) * ((r.height() + kBlock - 1) / kBlock);
}

TexelRect overview_rect(const TexelRect& r, int k) {
  return {r.x0 >> k, r.y0 >> k, r.x1 >> k, r.y1 >> k};  // exact: r is snapped to 2^overviews
}

// The temporary tiled GTiff: full resolution, then the overview IFDs created empty and filled
// from our coarser levels.
class Staging {
 public:
  Staging(const archive::Reader& r, const TilesetInfo& info, const GeoTiffRegion& region,
          const GeoTiffOptions& o)
      : reader_(r), info_(info), region_(region), options_(o) {}

  Status write(const fs::path& path, unsigned threads, detail::Counters& counters,
               std::uint64_t total) {
    GDALDriver* gtiff = GetGDALDriverManager()->GetDriverByName("GTiff");
    detail::GdalErrors errors;
    if (!gtiff) return errors.error("GDAL has no GTiff driver");
    const std::string nthreads = std::to_string(threads);
    // Fast lossless compression: the temporary is read once, by the COG driver.
    const char* opts[] = {"TILED=YES",        "BLOCKXSIZE=512",  "BLOCKYSIZE=512",
                          "COMPRESS=ZSTD",    "ZSTD_LEVEL=1",    "PREDICTOR=2",
                          "INTERLEAVE=PIXEL", "PHOTOMETRIC=RGB", "ALPHA=UNASSOCIATED",
                          "BIGTIFF=YES",      nullptr,           nullptr};
    const std::string threads_opt = "NUM_THREADS=" + nthreads;
    opts[10] = threads_opt.c_str();
    const TexelRect& r = region_.texels;
    ds_.reset(gtiff->Create(path.c_str(), int(r.width()), int(r.height()), 4, GDT_Byte,
                            const_cast<char**>(opts)));
    if (!ds_) return errors.error("cannot create '" + path.string() + "'");
    if (Status s = detail::set_georeference(*ds_, region_); !s) return s;
    // Straight alpha, so that GDAL and QGIS draw texels beyond the data as transparent.
    ds_->GetRasterBand(4)->SetColorInterpretation(GCI_AlphaBand);
    if (Status s = create_overviews(); !s) return s;
    std::mutex gdal;
    const detail::FeederOptions fo{threads, options_.cancel, options_.on_progress};
    detail::Feeder feeder(fo, counters, total);
    bool stopped = false;  // the feeder holds the reason
    for (int k = 0; k <= region_.overviews && !stopped; ++k) {
      GDALDataset* target = k == 0 ? ds_.get() : overview(k);
      if (!target) return errors.error("GDAL made no overview " + std::to_string(k));
      auto writer =
          std::make_shared<LevelWriter>(reader_, info_, *target, gdal, counters, options_.cancel);
      const int z = region_.level - k;
      const TexelRect lr = overview_rect(r, k);
      for (std::uint64_t y = lr.y0; y < lr.y1 && !stopped; y += kBlock)
        stopped = !feeder.submit([writer, z, lr, y] { return writer->row(z, lr, y); });
    }
    if (Status s = feeder.finish({}); !s) return s;
    CPLErrorReset();
    ds_->FlushCache(false);
    if (CPLGetLastErrorType() >= CE_Failure)
      return errors.error("cannot write '" + path.string() + "'");
    return {};
  }

  GDALDataset& dataset() { return *ds_; }
  void close() { ds_.reset(); }

 private:
  Status create_overviews() {
    if (region_.overviews == 0) return {};
    std::vector<int> factors;
    for (int k = 1; k <= region_.overviews; ++k) factors.push_back(1 << k);
    // The overviews' blocks as the full resolution's, compressed the same way.
    CPLSetThreadLocalConfigOption("GDAL_TIFF_OVR_BLOCKSIZE", "512");
    CPLSetThreadLocalConfigOption("COMPRESS_OVERVIEW", "ZSTD");
    CPLSetThreadLocalConfigOption("PREDICTOR_OVERVIEW", "2");
    detail::GdalErrors errors;
    // "NONE": the IFDs only; we fill them from our own levels.
    const CPLErr e = ds_->BuildOverviews("NONE", int(factors.size()), factors.data(), 0, nullptr,
                                         nullptr, nullptr, nullptr);
    CPLSetThreadLocalConfigOption("GDAL_TIFF_OVR_BLOCKSIZE", nullptr);
    CPLSetThreadLocalConfigOption("COMPRESS_OVERVIEW", nullptr);
    CPLSetThreadLocalConfigOption("PREDICTOR_OVERVIEW", nullptr);
    if (e != CE_None) return errors.error("cannot create the overviews");
    return {};
  }
  GDALDataset* overview(int k) {
    GDALRasterBand* band = ds_->GetRasterBand(1)->GetOverview(k - 1);
    return band ? band->GetDataset() : nullptr;
  }

  const archive::Reader& reader_;
  const TilesetInfo& info_;
  const GeoTiffRegion& region_;
  const GeoTiffOptions& options_;
  detail::GdalDatasetPtr ds_;
};

struct CogProgress {
  const GeoTiffOptions* options;
  std::uint64_t base, span;
  Clock::time_point last = Clock::now();
  static int CPL_STDCALL report(double fraction, const char*, void* self) {
    auto* p = static_cast<CogProgress*>(self);
    if (p->options->cancel && p->options->cancel->load()) return FALSE;
    if (p->options->on_progress && Clock::now() - p->last > std::chrono::milliseconds(100)) {
      p->last = Clock::now();
      p->options->on_progress(p->base + std::uint64_t(fraction * double(p->span)),
                              p->base + p->span);
    }
    return TRUE;
  }
};

// The COG of the staged GTiff, into `path`.
Status write_cog(GDALDataset& staged, const fs::path& path, unsigned threads,
                 const GeoTiffOptions& o, std::uint64_t blocks) {
  GDALDriver* cog = GetGDALDriverManager()->GetDriverByName("COG");
  detail::GdalErrors errors;
  if (!cog) return errors.error("GDAL has no COG driver (GDAL 3.1 or later is needed)");
  const std::string threads_opt = "NUM_THREADS=" + std::to_string(threads);
  const char* opts[] = {"COMPRESS=DEFLATE",
                        "PREDICTOR=YES",
                        "LEVEL=6",
                        "BLOCKSIZE=512",
                        "OVERVIEWS=FORCE_USE_EXISTING",
                        "BIGTIFF=IF_SAFER",
                        threads_opt.c_str(),
                        nullptr};
  CogProgress progress{&o, blocks, blocks};
  detail::GdalDatasetPtr out(cog->CreateCopy(path.c_str(), &staged, FALSE, const_cast<char**>(opts),
                                             &CogProgress::report, &progress));
  if (o.cancel && o.cancel->load()) return make_error(ErrorCode::cancelled, "export cancelled");
  if (!out) return errors.error("cannot write the COG '" + path.string() + "'");
  out.reset();
  return {};
}

// Removes a file (and GDAL's side file) when it goes out of scope.
struct RemoveOnExit {
  fs::path path;
  ~RemoveOnExit() {
    std::error_code ec;
    fs::remove(path, ec);
    fs::remove(path.string() + ".aux.xml", ec);
  }
};

}  // namespace

GeoTiffRegion level_rect_georeference(const TilesetInfo& info, int level, const TexelRect& rect) {
  GeoTiffRegion r;
  r.level = level;
  r.texels = rect;
  r.tiling = info.georeference->tiling;
  const std::uint32_t T = info.geometry.tile_size();
  const CrsBounds origin = tile_bounds_crs(r.tiling, T, {static_cast<std::uint8_t>(level), 0, 0});
  const double cell = level_cell_size(r.tiling, T, level);
  const double gt[6] = {origin.min_x + double(rect.x0) * cell, cell, 0,
                        origin.max_y - double(rect.y0) * cell, 0,    -cell};
  std::copy(std::begin(gt), std::end(gt), r.geotransform);
  return r;
}

Result<GeoTiffRegion> geotiff_region(const TilesetInfo& info, std::optional<int> level,
                                     const std::optional<LonLatBounds>& bbox) {
  if (!info.georeference)
    return make_error(ErrorCode::invalid_argument,
                      "a GeoTIFF needs a georeferenced archive; this one is a plain image (vts "
                      "extract --level Z -o OUT.tif writes a level without a georeference)");
  const Geometry& g = info.geometry;
  const int z = level.value_or(g.max_zoom());
  if (!g.valid_level(z))
    return make_error(
        ErrorCode::invalid_argument,
        "--level " + std::to_string(z) + " is outside 0.." + std::to_string(g.max_zoom()));
  const LonLatBounds b = bbox.value_or(info.georeference->bounds);
  if (!(std::isfinite(b.west) && std::isfinite(b.south) && std::isfinite(b.east) &&
        std::isfinite(b.north) && b.west < b.east && b.south < b.north))
    return make_error(ErrorCode::invalid_argument,
                      "--bbox must be finite W,S,E,N degrees with W < E and S < N");
  TexelRect r = box_texels(info, z, b, 1);
  if (r.empty())
    return make_error(ErrorCode::invalid_argument,
                      "--bbox lies outside level " + std::to_string(z) + "'s extent");
  if (r.width() > INT32_MAX || r.height() > INT32_MAX)
    return make_error(ErrorCode::too_large, "the region is wider than a GeoTIFF can hold");
  const int k = overview_count(r, z);
  r = box_texels(info, z, b, std::uint64_t{1} << k);
  GeoTiffRegion region = level_rect_georeference(info, z, r);
  region.overviews = k;
  return region;
}

Result<GeoTiffReport> export_geotiff(const archive::Reader& reader, const TilesetInfo& info,
                                     const GeoTiffOptions& o) {
  const auto t0 = Clock::now();
  if (o.output.empty()) return make_error(ErrorCode::invalid_argument, "no output given");
  auto region = geotiff_region(info, o.level, o.bbox);
  if (!region) return region.error();
  detail::register_gdal();
  const unsigned threads =
      o.threads ? o.threads : std::max(1u, std::thread::hardware_concurrency());
  GeoTiffReport report;
  report.region = *region;
  std::uint64_t blocks = 0;
  for (int k = 0; k <= region->overviews; ++k) {
    const TexelRect lr = overview_rect(region->texels, k);
    blocks += block_count(lr);
    report.texels += lr.width() * lr.height();
  }
  detail::Counters counters;
  // The COG goes into write_file_atomically's temporary (GDAL rewrites it in place, by name),
  // the staged GTiff beside it.
  Status written = write_file_atomically(o.output, [&](int, const fs::path& tmp) -> Status {
    RemoveOnExit staged_file{tmp.string() + ".staging.tif"};
    Staging staging(reader, info, *region, o);
    if (Status s = staging.write(staged_file.path, threads, counters, blocks * 2); !s) return s;
    Status s = write_cog(staging.dataset(), tmp, threads, o, blocks);
    staging.close();
    return s;
  });
  if (!written) return written.error();
  if (o.on_progress) o.on_progress(blocks * 2, blocks * 2);
  const TexelRect& r = region->texels;
  const LonLat nw = texel_to_lonlat(region->tiling, info.geometry.tile_size(), region->level,
                                    {double(r.x0), double(r.y0)});
  const LonLat se = texel_to_lonlat(region->tiling, info.geometry.tile_size(), region->level,
                                    {double(r.x1), double(r.y1)});
  report.bounds = {nw.lon, se.lat, se.lon, nw.lat};
  std::error_code ec;
  report.file_bytes = fs::file_size(o.output, ec);
  report.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  return report;
}

}  // namespace builder
}  // namespace vts
