// The CPU reference renderer: what the GPU renderer's screenshots are judged against. It renders
// any scene by the sampling rules of camera.hpp in double precision, reading texels straight from
// a PMTiles archive, and compares images. The rules in full (derivatives, anisotropy, sparse
// archives, bc1) are in docs/RENDERER.md, "The CPU reference renderer".
//
// Errors name the archive. Thread safety: a PyramidSampler is not thread-safe (its tile cache
// mutates on every read); use one per thread. compare_images() is pure.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <list>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

#include "vts/archive/pmtiles.hpp"
#include "vts/base/result.hpp"
#include "vts/base/srgb.hpp"
#include "vts/protocol/codec.hpp"
#include "vts/protocol/geometry.hpp"
#include "vts/renderer/camera.hpp"
#include "vts/renderer/footprint.hpp"
#include "vts/renderer/scene.hpp"

namespace vts::renderer {

// An 8-bit RGBA image: rows top to bottom, 4 bytes per pixel, sRGB-encoded colour, straight alpha.
struct Image {
  int width = 0, height = 0;
  std::vector<std::uint8_t> rgba;

  static Image blank(int width, int height) {
    return Image{width, height, std::vector<std::uint8_t>(std::size_t(width) * height * 4, 0)};
  }
  std::uint8_t* at(int x, int y) { return rgba.data() + (std::size_t(y) * width + x) * 4; }
  const std::uint8_t* at(int x, int y) const {
    return rgba.data() + (std::size_t(y) * width + x) * 4;
  }
};

using Rgba8 = std::array<std::uint8_t, 4>;
using LinearRgba = std::array<double, 4>;  // linear-light colour, straight alpha, all in [0, 1]

// The exact IEC 61966-2-1 transfer functions (no lookup-table approximation in the encoder).

class PyramidSampler {
 public:
  struct Stats {
    std::uint64_t tiles_decoded = 0;    // decode_tile() calls (cache misses on present tiles)
    std::uint64_t fallback_texels = 0;  // texel reads answered by an ancestor of an absent tile
  };

  // Opens the archive and reads the geometry from its metadata. `cache_tiles` decoded tiles are
  // kept (at least 1).
  static Result<std::unique_ptr<PyramidSampler>> open(const std::filesystem::path& archive,
                                                      std::size_t cache_tiles = 64);

  const Geometry& geometry() const { return geometry_; }
  int max_level() const { return geometry_.max_zoom(); }
  const Stats& stats() const { return stats_; }
  const std::filesystem::path& path() const { return path_; }

  // The stored sRGB texel of level z at (x, y), clamped to the level's image
  // ([0, level_width - 1] x [0, level_height - 1]). invalid_argument for a level outside
  // [0, max_level]; absent tiles fall back on their ancestors (see the top of this file).
  Result<Rgba8> texel(int z, std::int64_t x, std::int64_t y);

  // Bilinear sample of level z at (tx, ty) in level-z texel units, texel centres at +0.5 (so the
  // four texels around (tx - 0.5, ty - 0.5)), clamp to the level's edge, colour decoded from sRGB
  // before weighting. invalid_argument for a bad level or non-finite coordinates.
  Result<LinearRgba> bilinear(int z, double tx, double ty);

 private:
  struct Entry {
    std::shared_ptr<const std::vector<std::uint8_t>> pixels;  // null: absent from the archive
    std::list<std::uint64_t>::iterator lru;
  };

  PyramidSampler(std::filesystem::path path, std::shared_ptr<archive::Reader> reader,
                 Geometry geometry, PixelFormat format, TileSpec spec, std::size_t cache_tiles);
  // The decoded stored tile, or null when the archive does not have it.
  Result<const std::vector<std::uint8_t>*> tile(TileId id);

  std::filesystem::path path_;
  std::shared_ptr<archive::Reader> reader_;
  Geometry geometry_;
  PixelFormat format_;  // what the archive's tiles decode to (bc1 is then widened to rgba8)
  TileSpec spec_;       // what every tile's header must say (refused before decoding otherwise)
  std::size_t cache_tiles_;
  std::list<std::uint64_t> lru_;  // most recently used first
  std::unordered_map<std::uint64_t, Entry> cache_;
  Stats stats_;
};

// Renders the plane view `camera` (camera.width x camera.height pixels) by the rules at the top of
// this file. `bias` is added to the level like the GPU's mip bias (positive = coarser). Fails with
// invalid_argument for a viewport that is empty or larger than 16384 a side, or with the sampler's
// error.
Result<Image> render_reference(PyramidSampler& sampler, const PlaneCamera& camera, double bias = 0,
                               int anisotropy = 1);
// The same for any scene (Scene::hit in double), width x height pixels. Where a quad partner
// misses the surface its (u, v) is Scene::miss_uv (what the GPU computes there) or, when the scene
// has none, the derivative is a central difference of 1/1000 pixel; u differences are unwrapped
// by Scene::u_period() (footprint.hpp).
Result<Image> render_reference(PyramidSampler& sampler, const Scene& scene, int width, int height,
                               double bias = 0, int anisotropy = 1);

// The ground truth filters are judged against: `scene` rendered by the reference at `factor` times
// the resolution (each sample at its own, finer, level), every pixel the mean in linear light of
// its factor x factor samples. factor in [1, 16]; invalid_argument beyond, or when the fine
// viewport exceeds 16384 a side.
Result<Image> render_supersampled(PyramidSampler& sampler, const Scene& scene, int width,
                                  int height, int factor);

// Differences between two images of equal size over the R, G and B channels (alpha ignored).
struct ImageDiff {
  // 10 log10(255^2 / MSE) over every R, G, B value; +infinity when the images are identical
  // (including empty images).
  double psnr_db = 0;
  int max_abs = 0;                // largest |a - b| of any channel
  double mean_abs = 0;            // mean |a - b| over every R, G, B value
  int threshold = 0;              // the threshold pixels_over was counted with
  std::uint64_t pixels_over = 0;  // pixels whose largest channel difference exceeds threshold
  std::uint64_t pixels = 0;       // pixels compared
};

// invalid_argument when the sizes differ or a buffer does not hold width * height * 4 bytes.
Result<ImageDiff> compare_images(const Image& a, const Image& b, int threshold = 8);

}  // namespace vts::renderer
