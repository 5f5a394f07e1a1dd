#include "vts/renderer/reference.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <utility>

#include "vts/archive/inspect.hpp"
#include "vts/protocol/codec.hpp"
#include "vts/protocol/tileset.hpp"
#include "vts/renderer/footprint.hpp"
#include "vts/renderer/pyramid.hpp"

namespace vts::renderer {

namespace {

std::string quoted(const std::filesystem::path& p) {
  return "'" + p.string() + "'";
}

// srgb_to_linear of every 8-bit code, computed with the exact formula.
const std::array<double, 256>& decode_table() {
  static const std::array<double, 256> table = [] {
    std::array<double, 256> t{};
    for (int i = 0; i < 256; ++i) t[i] = srgb_to_linear(i / 255.0);
    return t;
  }();
  return table;
}

}  // namespace

// ---- PyramidSampler --------------------------------------------------------------------------

PyramidSampler::PyramidSampler(std::filesystem::path path, std::shared_ptr<archive::Reader> reader,
                               Geometry geometry, PixelFormat format, TileSpec spec,
                               std::size_t cache_tiles)
    : path_(std::move(path)),
      reader_(std::move(reader)),
      geometry_(geometry),
      format_(format),
      spec_(spec),
      cache_tiles_(std::max<std::size_t>(cache_tiles, 1)) {}

Result<std::unique_ptr<PyramidSampler>> PyramidSampler::open(const std::filesystem::path& archive,
                                                             std::size_t cache_tiles) {
  auto reader = archive::Reader::open(archive);
  if (!reader) {
    Error e = std::move(reader).error();
    if (e.message.find(archive.string()) == std::string::npos)
      e.message = quoted(archive) + ": " + e.message;
    return e;
  }
  auto info = archive::archive_tileset((*reader)->header(), (*reader)->metadata_json());
  if (!info) {
    Error e = std::move(info).error();
    e.message = quoted(archive) + ": metadata: " + e.message;
    return e;
  }
  const Codec* codec = find_codec(info->codec);
  if (!codec)
    return make_error(ErrorCode::unsupported, quoted(archive) + ": codec '" +
                                                  codec_name(info->codec) +
                                                  "' is not implemented in this build");
  const PixelFormat format = codec->decoded_format();
  if (format != PixelFormat::rgba8 && format != PixelFormat::bc1)
    return make_error(ErrorCode::unsupported, quoted(archive) + ": codec '" +
                                                  codec_name(info->codec) +
                                                  "' decodes to neither rgba8 nor bc1 texels");
  if (format == PixelFormat::bc1 && info->geometry.stored_size() % 4 != 0)
    return make_error(ErrorCode::unsupported, quoted(archive) + ": bc1 tiles of " +
                                                  std::to_string(info->geometry.stored_size()) +
                                                  " texels a side are not whole 4 x 4 blocks");
  return std::unique_ptr<PyramidSampler>(new PyramidSampler(
      archive, std::move(*reader), info->geometry, format, info->tile_spec(), cache_tiles));
}

Result<const std::vector<std::uint8_t>*> PyramidSampler::tile(TileId id) {
  const std::uint64_t key = tile_key(id);
  if (auto it = cache_.find(key); it != cache_.end()) {
    if (lru_.begin() != it->second.lru) lru_.splice(lru_.begin(), lru_, it->second.lru);
    return it->second.pixels.get();
  }
  std::shared_ptr<const std::vector<std::uint8_t>> pixels;
  auto bytes = reader_->get(id);
  if (bytes) {
    auto img = decode_tile(*bytes, spec_);  // a contradicting header is refused before allocating
    if (!img)
      return make_error(img.error().code,
                        quoted(path_) + ": tile " + id.to_string() + ": " + img.error().message);
    const std::uint32_t s = geometry_.stored_size();
    const char* expected = format_ == PixelFormat::bc1 ? "bc1" : "rgba8";
    if (img->format != format_ || img->width != s || img->height != s)
      return make_error(ErrorCode::corrupt,
                        quoted(path_) + ": tile " + id.to_string() + " decodes to " +
                            std::to_string(img->width) + "x" + std::to_string(img->height) +
                            (img->format == PixelFormat::bc1 ? " bc1" : " rgba8") + ", expected " +
                            std::to_string(s) + "x" + std::to_string(s) + " " + expected);
    if (img->format == PixelFormat::bc1) {  // what the GPU's S3TC decoder reads
      auto rgba = bc1_to_rgba8(*img);
      if (!rgba)
        return make_error(ErrorCode::corrupt,
                          quoted(path_) + ": tile " + id.to_string() + ": " + rgba.error().message);
      *img = std::move(*rgba);
    }
    ++stats_.tiles_decoded;
    pixels = std::make_shared<const std::vector<std::uint8_t>>(std::move(img->pixels));
  } else if (bytes.error().code != ErrorCode::not_found) {
    return make_error(bytes.error().code,
                      quoted(path_) + ": tile " + id.to_string() + ": " + bytes.error().message);
  }
  if (cache_.size() >= cache_tiles_) {
    cache_.erase(lru_.back());
    lru_.pop_back();
  }
  lru_.push_front(key);
  const std::vector<std::uint8_t>* result = pixels.get();
  cache_.emplace(key, Entry{std::move(pixels), lru_.begin()});
  return result;
}

Result<Rgba8> PyramidSampler::texel(int z, std::int64_t x, std::int64_t y) {
  if (!geometry_.valid_level(z))
    return make_error(ErrorCode::invalid_argument, quoted(path_) + ": level " + std::to_string(z) +
                                                       " is outside [0, " +
                                                       std::to_string(max_level()) + "]");
  auto clamp_to = [](std::int64_t v, std::uint64_t extent) {
    return static_cast<std::uint64_t>(std::clamp<std::int64_t>(v, 0, std::int64_t(extent) - 1));
  };
  std::uint64_t px = clamp_to(x, geometry_.level_width(z));
  std::uint64_t py = clamp_to(y, geometry_.level_height(z));
  for (int level = z; level >= 0; --level) {
    const TileId id = geometry_.tile_of_texel(level, px, py);
    auto pixels = tile(id);
    if (!pixels) return std::move(pixels).error();
    if (*pixels) {
      if (level != z) ++stats_.fallback_texels;
      const std::uint64_t T = geometry_.tile_size(), B = geometry_.border();
      const std::uint64_t sx = px - std::uint64_t{id.x} * T + B;
      const std::uint64_t sy = py - std::uint64_t{id.y} * T + B;
      const std::uint8_t* p = (*pixels)->data() + (sy * geometry_.stored_size() + sx) * 4;
      return Rgba8{p[0], p[1], p[2], p[3]};
    }
    px >>= 1;
    py >>= 1;
  }
  return make_error(ErrorCode::not_found, quoted(path_) + ": no tile holds level " +
                                              std::to_string(z) + " texel " + std::to_string(x) +
                                              "," + std::to_string(y) + " nor any ancestor");
}

Result<LinearRgba> PyramidSampler::bilinear(int z, double tx, double ty) {
  if (!geometry_.valid_level(z))
    return make_error(ErrorCode::invalid_argument, quoted(path_) + ": level " + std::to_string(z) +
                                                       " is outside [0, " +
                                                       std::to_string(max_level()) + "]");
  if (!std::isfinite(tx) || !std::isfinite(ty))
    return make_error(ErrorCode::invalid_argument, "bilinear sample at a non-finite coordinate");
  // Beyond one texel past the edge every tap clamps to the edge texel: clamping the coordinate
  // there first keeps the integer conversion in range without changing the result.
  const double sx = std::clamp(tx - 0.5, -1.0, static_cast<double>(geometry_.level_width(z)));
  const double sy = std::clamp(ty - 0.5, -1.0, static_cast<double>(geometry_.level_height(z)));
  const double fx0 = std::floor(sx), fy0 = std::floor(sy);
  const double fx = sx - fx0, fy = sy - fy0;
  const auto x0 = static_cast<std::int64_t>(fx0), y0 = static_cast<std::int64_t>(fy0);
  const double wx[2] = {1 - fx, fx}, wy[2] = {1 - fy, fy};
  const auto& lin = decode_table();
  LinearRgba out{0, 0, 0, 0};
  for (int j = 0; j < 2; ++j) {
    for (int i = 0; i < 2; ++i) {
      const double w = wx[i] * wy[j];
      if (w == 0) continue;
      auto t = texel(z, x0 + i, y0 + j);
      if (!t) return std::move(t).error();
      for (int c = 0; c < 3; ++c) out[c] += w * lin[(*t)[c]];
      out[3] += w * ((*t)[3] / 255.0);
    }
  }
  return out;
}

// ---- render_reference ------------------------------------------------------------------------

namespace {

// d(u, v)/d(sx) (axis 0) or d(u, v)/d(sy) (axis 1) of camera.hit at screen point (sx, sy), which
// must hit the plane: p = eye + t d with t = -eye.z / d.z, so dp = t (dd - d dd.z / d.z).
std::pair<double, double> analytic_derivative(const PlaneCamera& cam, double sx, double sy,
                                              int axis) {
  const Vec3d d = cam.ray(sx, sy);
  const Vec3d dd = axis == 0 ? cam.right * (2.0 / cam.width * cam.tan_half_fov * cam.aspect)
                             : cam.up * (-2.0 / cam.height * cam.tan_half_fov);
  const double t = -cam.eye.z / d.z;
  const Vec3d dp = (dd - d * (dd.z / d.z)) * t;
  return {dp.x, dp.y};
}

// The shared body: `hit_at(sx, sy)` gives the absolute (u, v) at a screen point; `fallback(sx,
// sy, axis)` the derivative where the quad partner misses.
template <typename HitFn, typename FallbackFn>
Result<Image> render_with(PyramidSampler& sampler, int w, int h, double bias, int anisotropy,
                          double period, HitFn&& hit_at, FallbackFn&& fallback) {
  constexpr int kMaxSide = 1 << 14;
  if (w <= 0 || h <= 0 || w > kMaxSide || h > kMaxSide)
    return make_error(ErrorCode::invalid_argument,
                      "reference viewport " + std::to_string(w) + "x" + std::to_string(h) +
                          " is empty or larger than " + std::to_string(kMaxSide) + " a side");
  const Geometry& g = sampler.geometry();
  const int max_level = g.max_zoom();
  const double W = static_cast<double>(g.width()), H = static_cast<double>(g.height());
  Image img = Image::blank(w, h);
  std::optional<Error> failure;

  const auto shade = [&](const PixelFootprint& p) {
    const double lx = std::hypot(p.dudx, p.dvdx), ly = std::hypot(p.dudy, p.dvdy);
    const FootprintLevel fl = footprint_level(lx, ly, max_level, -bias, anisotropy);
    const int taps = fl.taps;
    const int l0 = static_cast<int>(std::floor(fl.c));
    const double f = fl.c - l0;
    const double ax = lx >= ly ? p.dudx : p.dudy, ay = lx >= ly ? p.dvdx : p.dvdy;
    LinearRgba colour{0, 0, 0, 0};
    for (int i = 0; i < taps; ++i) {
      double tu = p.u, tv = p.v;
      if (taps > 1) {
        const double t = (i + 0.5) / taps - 0.5;
        tu = p.u + ax * t;
        tv = p.v + ay * t;
        if (period > 0) {
          tu -= period * std::floor(tu / period);
        } else if (!(tu >= 0 && tu < W)) {
          tu = tu < 0 ? 0.5 : W - 0.5;
        }
        if (!(tv >= 0 && tv < H)) tv = tv < 0 ? 0.5 : H - 0.5;
      }
      for (int k = 0; k < 2; ++k) {
        const int level = l0 + k;
        const double weight = (k == 0 ? 1 - f : f) / taps;
        if (level > max_level || weight == 0) continue;
        auto s = sampler.bilinear(level, std::ldexp(tu, level - max_level),
                                  std::ldexp(tv, level - max_level));
        if (!s) {
          failure = std::move(s).error();
          return false;
        }
        for (int ch = 0; ch < 4; ++ch) colour[ch] += weight * (*s)[ch];
      }
    }
    std::uint8_t* out = img.at(p.x, p.y);
    // Over the black background, as the shader composites: straight colour times alpha.
    const double alpha = std::clamp(colour[3], 0.0, 1.0);
    for (int ch = 0; ch < 3; ++ch) out[ch] = encode_srgb8_exact(colour[ch] * alpha);
    out[3] = 255;
    return true;
  };
  const auto background = [&](int x, int y) {
    std::copy(kBackground, kBackground + 4, img.at(x, y));
    return true;
  };
  if (!for_each_footprint(w, h, W, H, period, hit_at, fallback, shade, background))
    return std::move(*failure);
  return img;
}

}  // namespace

Result<Image> render_reference(PyramidSampler& sampler, const PlaneCamera& camera, double bias,
                               int anisotropy) {
  return render_with(
      sampler, camera.width, camera.height, bias, anisotropy, 0,
      [&](double sx, double sy) {
        const SurfaceHit h = camera.hit(sx, sy);
        return GridPoint{h, h};
      },
      [&](double sx, double sy, int axis) { return analytic_derivative(camera, sx, sy, axis); });
}

Result<Image> render_reference(PyramidSampler& sampler, const Scene& scene, int width, int height,
                               double bias, int anisotropy) {
  return render_with(
      sampler, width, height, bias, anisotropy, scene.u_period(),
      [&](double sx, double sy) { return scene_point(scene, sx, sy, width, height); },
      [&](double sx, double sy, int axis) {
        return scene_derivative(scene, sx, sy, width, height, axis);
      });
}

namespace {

// A scene seen through a viewport `factor` times finer: sample (sx, sy) of the fine viewport is
// point (sx, sy) / factor of the original. Only hit() and u_period() are used by the reference.
class SubpixelScene final : public Scene {
 public:
  SubpixelScene(const Scene& inner, int factor) : inner_(inner), factor_(factor) {}
  std::string_view name() const override { return inner_.name(); }
  std::string glsl() const override { return inner_.glsl(); }
  void set_uniforms(UniformSink& sink, int width, int height) const override {
    inner_.set_uniforms(sink, width / factor_, height / factor_);
  }
  std::array<std::int64_t, 2> anchor() const override { return inner_.anchor(); }
  std::pair<double, double> focus() const override { return inner_.focus(); }
  double texels_per_pixel() const override { return inner_.texels_per_pixel() / factor_; }
  UvHit hit(double sx, double sy, int width, int height) const override {
    return inner_.hit(sx / factor_, sy / factor_, width / factor_, height / factor_);
  }
  double u_period() const override { return inner_.u_period(); }

 private:
  const Scene& inner_;
  int factor_;
};

}  // namespace

Result<Image> render_supersampled(PyramidSampler& sampler, const Scene& scene, int width,
                                  int height, int factor) {
  if (factor < 1 || factor > 16)
    return make_error(ErrorCode::invalid_argument,
                      "supersampling factor " + std::to_string(factor) + " is outside 1 to 16");
  if (width <= 0 || height <= 0 || std::int64_t(width) * factor > (1 << 14) ||
      std::int64_t(height) * factor > (1 << 14))
    return make_error(ErrorCode::invalid_argument,
                      "supersampled viewport " + std::to_string(width) + "x" +
                          std::to_string(height) + " x" + std::to_string(factor) +
                          " is empty or larger than 16384 a side");
  const SubpixelScene fine_scene(scene, factor);
  auto fine = render_reference(sampler, fine_scene, width * factor, height * factor);
  if (!fine) return std::move(fine).error();
  const auto& lin = decode_table();
  Image out = Image::blank(width, height);
  const double n = double(factor) * factor;
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      double sum[3] = {0, 0, 0};
      for (int j = 0; j < factor; ++j) {
        for (int i = 0; i < factor; ++i) {
          const std::uint8_t* p = fine->at(x * factor + i, y * factor + j);
          for (int c = 0; c < 3; ++c) sum[c] += lin[p[c]];
        }
      }
      std::uint8_t* o = out.at(x, y);
      for (int c = 0; c < 3; ++c) o[c] = encode_srgb8_exact(sum[c] / n);
      o[3] = 255;
    }
  }
  return out;
}

// ---- metrics ---------------------------------------------------------------------------------

Result<ImageDiff> compare_images(const Image& a, const Image& b, int threshold) {
  if (a.width != b.width || a.height != b.height)
    return make_error(ErrorCode::invalid_argument, "cannot compare a " + std::to_string(a.width) +
                                                       "x" + std::to_string(a.height) +
                                                       " image with a " + std::to_string(b.width) +
                                                       "x" + std::to_string(b.height) + " one");
  if (a.width < 0 || a.height < 0)
    return make_error(ErrorCode::invalid_argument, "negative image size");
  const std::size_t n = std::size_t(a.width) * std::size_t(a.height);
  if (a.rgba.size() != n * 4 || b.rgba.size() != n * 4)
    return make_error(ErrorCode::invalid_argument,
                      "image buffers of " + std::to_string(a.rgba.size()) + " and " +
                          std::to_string(b.rgba.size()) + " bytes for " + std::to_string(n) +
                          " pixels");
  ImageDiff d;
  d.threshold = threshold;
  d.pixels = n;
  std::uint64_t sum_abs = 0, sum_sq = 0;
  for (std::size_t i = 0; i < n; ++i) {
    int pixel_max = 0;
    for (int c = 0; c < 3; ++c) {
      const int diff = std::abs(int(a.rgba[i * 4 + c]) - int(b.rgba[i * 4 + c]));
      pixel_max = std::max(pixel_max, diff);
      sum_abs += std::uint64_t(diff);
      sum_sq += std::uint64_t(diff) * std::uint64_t(diff);
    }
    d.max_abs = std::max(d.max_abs, pixel_max);
    if (pixel_max > threshold) ++d.pixels_over;
  }
  const double values = 3.0 * double(n);
  d.mean_abs = n ? double(sum_abs) / values : 0.0;
  d.psnr_db = sum_sq == 0 ? std::numeric_limits<double>::infinity()
                          : 10.0 * std::log10(255.0 * 255.0 * values / double(sum_sq));
  return d;
}

}  // namespace vts::renderer
