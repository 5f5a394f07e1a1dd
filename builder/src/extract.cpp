#include "vts/builder/extract.hpp"

#include <OpenImageIO/imageio.h>

#include <cstring>

#include "gdal_output.hpp"
#include "vts/archive/inspect.hpp"

namespace vts {
inline namespace builder {

namespace OIIO = OIIO_NAMESPACE;

namespace {

class Output {
 public:
  static Result<Output> open(const ExtractOptions& o, std::uint64_t w, std::uint64_t h) {
    if (o.channels != 3 && o.channels != 4)
      return make_error(ErrorCode::invalid_argument, "channels must be 3 or 4");
    if (w > INT32_MAX || h > INT32_MAX)
      return make_error(ErrorCode::too_large, "image too large for an image file");
    Output out;
    out.path_ = o.output;
    out.tmp_ = o.output;
    out.tmp_ += ".tmp";
    out.out_ = OIIO::ImageOutput::create(o.output.string());
    if (!out.out_)
      return make_error(ErrorCode::invalid_argument,
                        "cannot write '" + o.output.string() + "': " + OIIO::geterror());
    OIIO::ImageSpec spec(static_cast<int>(w), static_cast<int>(h), o.channels,
                         OIIO::TypeDesc::UINT8);
    spec.attribute("oiio:ColorSpace", "sRGB");
    // The texels have straight alpha: written as they are, not divided by alpha again.
    spec.attribute("oiio:UnassociatedAlpha", 1);
    // Write under a temporary name with the right extension handled by the plugin chosen above.
    if (!out.out_->open(out.tmp_.string(), spec))
      return make_error(ErrorCode::io,
                        "cannot write '" + o.output.string() + "': " + out.out_->geterror());
    out.channels_ = o.channels;
    out.width_ = w;
    return out;
  }
  // rows: RGBA8, width_ texels each.
  Status write_rows(std::uint64_t y, std::uint32_t n, const std::uint8_t* rgba) {
    const std::uint8_t* data = rgba;
    if (channels_ == 3) {
      rgb_.resize(std::size_t{n} * width_ * 3);
      for (std::size_t i = 0; i < std::size_t{n} * width_; ++i)
        std::memcpy(&rgb_[3 * i], rgba + 4 * i, 3);
      data = rgb_.data();
    }
    if (!out_->write_scanlines(static_cast<int>(y), static_cast<int>(y + n), 0,
                               OIIO::TypeDesc::UINT8, data))
      return make_error(ErrorCode::io, "writing '" + path_.string() + "': " + out_->geterror());
    return {};
  }
  // Closes the file, adds the georeference (when there is one) and renames it into place.
  Status finish(const std::optional<GeoTiffRegion>& georef) {
    const bool ok = out_->close();
    out_.reset();
    std::error_code ec;
    if (!ok) {
      std::filesystem::remove(tmp_, ec);
      return make_error(ErrorCode::io, "writing '" + path_.string() + "' failed");
    }
    std::filesystem::path side;  // a PAM .aux.xml for formats without GeoTIFF tags
    if (georef) {
      if (Status st = detail::add_georeference(tmp_, *georef, &side); !st) {
        std::filesystem::remove(tmp_, ec);
        std::filesystem::remove(tmp_.string() + ".aux.xml", ec);
        return st;
      }
      if (!side.empty()) std::filesystem::rename(side, path_.string() + ".aux.xml", ec);
      if (ec)
        return make_error(ErrorCode::io,
                          "renaming to '" + path_.string() + ".aux.xml': " + ec.message());
    }
    std::filesystem::rename(tmp_, path_, ec);
    if (ec)
      return make_error(ErrorCode::io, "renaming to '" + path_.string() + "': " + ec.message());
    return {};
  }
  ~Output() {
    if (out_) {
      out_->close();
      std::error_code ec;
      std::filesystem::remove(tmp_, ec);
    }
  }
  Output() = default;
  Output(Output&&) = default;
  Output& operator=(Output&&) = default;

 private:
  std::unique_ptr<OIIO::ImageOutput> out_;
  std::filesystem::path path_, tmp_;
  int channels_ = 4;
  std::uint64_t width_ = 0;
  std::vector<std::uint8_t> rgb_;
};

}  // namespace

Status extract_tile(const archive::Reader& reader, const TilesetInfo& info, TileId id,
                    const ExtractOptions& o) {
  const Geometry& g = info.geometry;
  if (!g.exists(id))
    return make_error(ErrorCode::not_found, "tile " + id.to_string() + " is outside the pyramid");
  auto stored = archive::read_tile_rgba8(reader, info, id);
  if (!stored) return std::move(stored).error();
  const TileImage img = archive::extracted_texels(*stored, g, id, o.with_border);
  auto out = Output::open(o, img.width, img.height);
  if (!out) return std::move(out).error();
  if (auto st = out->write_rows(0, img.height, img.pixels.data()); !st) return st;
  std::optional<GeoTiffRegion> georef;
  if (info.georeference) {
    georef = level_rect_georeference(info, id.z, g.content_rect(id));
    if (o.with_border) {  // the border starts B texels up and left (it may lie beyond the level)
      const double shift = g.border() * georef->geotransform[1];
      georef->geotransform[0] -= shift;
      georef->geotransform[3] += shift;
    }
  }
  return out->finish(georef);
}

Status extract_level(const archive::Reader& reader, const TilesetInfo& info, int z,
                     const ExtractOptions& o) {
  const Geometry& g = info.geometry;
  if (!g.valid_level(z))
    return make_error(
        ErrorCode::invalid_argument,
        "level " + std::to_string(z) + " is outside 0.." + std::to_string(g.max_zoom()));
  const std::uint64_t w = g.level_width(z), h = g.level_height(z);
  // One row of tiles is held in memory; refuse levels whose row would not fit comfortably (and
  // whose image few formats or viewers could take anyway).
  constexpr std::uint64_t kMaxStripBytes = 1ull << 30;
  if (w * g.tile_size() * 4 > kMaxStripBytes || w * h > (1ull << 34))
    return make_error(ErrorCode::too_large,
                      "level " + std::to_string(z) + " is " + std::to_string(w) + "x" +
                          std::to_string(h) +
                          " texels, too large to write as one image; extract single tiles or a "
                          "coarser level");
  auto out = Output::open(o, w, h);
  if (!out) return std::move(out).error();
  const std::uint32_t T = g.tile_size(), B = g.border(), S = g.stored_size();
  std::vector<std::uint8_t> strip(w * T * 4);
  for (std::uint32_t ty = 0; ty < g.tiles_y(z); ++ty) {
    if (o.cancel && o.cancel->load()) return make_error(ErrorCode::cancelled, "extract cancelled");
    std::fill(strip.begin(), strip.end(), 0);
    const std::uint64_t y0 = std::uint64_t{ty} * T;
    const auto rows = static_cast<std::uint32_t>(std::min<std::uint64_t>(T, h - y0));
    for (std::uint32_t tx = 0; tx < g.tiles_x(z); ++tx) {
      const TileId id{static_cast<std::uint8_t>(z), tx, ty};
      auto img = archive::read_tile_rgba8(reader, info, id);
      if (!img) {
        if (img.error().code == ErrorCode::not_found && info.sparse) continue;
        return std::move(img).error();
      }
      const TexelRect r = g.content_rect(id);
      for (std::uint32_t y = 0; y < rows; ++y)
        std::memcpy(&strip[(std::size_t{y} * w + r.x0) * 4],
                    &img->pixels[(std::size_t{B + y} * S + B) * 4], r.width() * 4);
    }
    if (auto st = out->write_rows(y0, rows, strip.data()); !st) return st;
  }
  std::optional<GeoTiffRegion> georef;
  if (info.georeference) georef = level_rect_georeference(info, z, {0, 0, w, h});
  return out->finish(georef);
}

}  // namespace builder
}  // namespace vts
