// Table 1: codec x quality. Every stored tile of the lossless archive (the source texels, border
// included) is encoded with each setting, decoded, compared with the source and, where a GL
// context is current, uploaded into a texture the way the renderer's physical texture is fed.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "vts/accuracy/accuracy.hpp"
#include "vts/archive/pmtiles.hpp"
#include "vts/builder/tile_encoder.hpp"
#include "vts/protocol/codec.hpp"
#include "vts/protocol/tileset.hpp"

#ifdef VTS_ACCURACY_HAVE_GL
#include <epoxy/gl.h>

#include "vts/renderer/gl_context.hpp"
#include "vts/renderer/gl_handle.hpp"
#endif

namespace vts::accuracy {
namespace {

using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point t) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

struct Setting {
  std::string family;  // plot series: "lossless none", "lossless gradient", "bc1"
  std::string label;
  CodecId codec = CodecId::lossless;
  EncodeOptions encode;
};

std::vector<Setting> settings(bool quick) {
  std::vector<Setting> out;
  const int levels_full[] = {1, 3, 9, 19};
  const int levels_quick[] = {1, 19};
  for (FilterChoice f : {FilterChoice::none, FilterChoice::gradient}) {
    const char* fname = f == FilterChoice::none ? "none" : "gradient";
    auto add = [&](int level) {
      Setting s;
      s.family = std::string("lossless ") + fname;
      s.label = "lossless " + std::string(fname) + " zstd " + std::to_string(level);
      s.encode.zstd_level = level;
      s.encode.filter = f;
      out.push_back(s);
    };
    if (quick) {
      for (int l : levels_quick) add(l);
    } else {
      for (int l : levels_full) add(l);
    }
  }
  for (Bc1Quality q : {Bc1Quality::fast, Bc1Quality::high, Bc1Quality::best}) {
    Setting s;
    s.family = "bc1";
    s.label = std::string("bc1 ") + bc1_quality_name(q) + " zstd 3";
    s.codec = CodecId::bc1;
    s.encode.bc1 = q;
    out.push_back(s);
  }
  return out;
}

// The stored tiles of the archive, decoded: the reference texels of this table. At most `limit`,
// taken evenly over the archive's tile order (every level contributes its share).
Result<std::vector<TileImage>> source_tiles(const std::filesystem::path& archive,
                                            std::size_t limit) {
  auto reader = archive::Reader::open(archive);
  if (!reader) return reader.error();
  std::vector<std::uint64_t> ids;
  Status visit = (*reader)->for_each_entry([&](const archive::Entry& e) {
    ids.push_back(e.tile_id);
    return true;
  });
  if (!visit) return visit.error();
  const std::size_t stride = std::max<std::size_t>(1, (ids.size() + limit - 1) / limit);
  std::vector<TileImage> tiles;
  for (std::size_t i = 0; i < ids.size(); i += stride) {
    auto payload = (*reader)->get_by_tile_id(ids[i]);
    if (!payload) return payload.error();
    auto img = decode_tile(*payload);
    if (!img) return img.error();
    tiles.push_back(std::move(*img));
  }
  if (tiles.empty()) return Error{ErrorCode::corrupt, archive.string() + " has no tiles"};
  return tiles;
}

#ifdef VTS_ACCURACY_HAVE_GL
// Mean time to upload one tile into a slot of an atlas of the renderer's kind (one level, sRGB),
// through a mapped pixel-unpack buffer as the renderer does, until the GPU has it (glFinish).
double upload_ms_per_tile(const std::vector<TileImage>& decoded, PixelFormat format,
                          std::uint32_t size, int rounds) {
  // Measured only where a GL context is current (run_accuracy makes one when it can).
  if (!renderer::GlContext::any_current() || decoded.empty()) return NAN;
  const bool bc1 = format == PixelFormat::bc1;
  if (bc1 && !(epoxy_has_gl_extension("GL_EXT_texture_compression_s3tc") &&
               epoxy_has_gl_extension("GL_EXT_texture_sRGB")))
    return NAN;
  const int slots_per_row = 4;
  renderer::GlTexture tex;
  renderer::GlBuffer pbo;
  glCreateTextures(GL_TEXTURE_2D, 1, tex.out());
  glTextureStorage2D(tex.get(), 1, bc1 ? GL_COMPRESSED_SRGB_ALPHA_S3TC_DXT1_EXT : GL_SRGB8_ALPHA8,
                     GLsizei(size * slots_per_row), GLsizei(size * slots_per_row));
  const std::size_t bytes = decoded.front().pixels.size();
  glCreateBuffers(1, pbo.out());
  glNamedBufferStorage(pbo.get(), GLsizeiptr(bytes), nullptr, GL_MAP_WRITE_BIT);
  glBindBuffer(GL_PIXEL_UNPACK_BUFFER, pbo.get());
  glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
  glPixelStorei(GL_UNPACK_ROW_LENGTH, 0);
  glFinish();
  const auto t0 = Clock::now();
  std::size_t n = 0;
  for (int r = 0; r < rounds; ++r) {
    for (const TileImage& t : decoded) {
      if (t.pixels.size() != bytes) continue;
      void* dst = glMapNamedBufferRange(pbo.get(), 0, GLsizeiptr(bytes),
                                        GL_MAP_WRITE_BIT | GL_MAP_INVALIDATE_BUFFER_BIT);
      if (dst == nullptr) break;
      std::memcpy(dst, t.pixels.data(), bytes);
      glUnmapNamedBuffer(pbo.get());
      const GLint x = GLint((n % slots_per_row) * size), y = GLint((n / slots_per_row % 4) * size);
      if (bc1) {
        glCompressedTextureSubImage2D(tex.get(), 0, x, y, GLsizei(size), GLsizei(size),
                                      GL_COMPRESSED_SRGB_ALPHA_S3TC_DXT1_EXT, GLsizei(bytes),
                                      nullptr);
      } else {
        glTextureSubImage2D(tex.get(), 0, x, y, GLsizei(size), GLsizei(size), GL_RGBA,
                            GL_UNSIGNED_BYTE, nullptr);
      }
      ++n;
    }
  }
  glFinish();
  const double ms = ms_since(t0);
  glBindBuffer(GL_PIXEL_UNPACK_BUFFER, 0);
  const bool ok = glGetError() == GL_NO_ERROR;
  return ok && n > 0 ? ms / double(n) : NAN;
}
#else
double upload_ms_per_tile(const std::vector<TileImage>&, PixelFormat, std::uint32_t, int) {
  return NAN;
}
#endif

}  // namespace

Result<AccuracyTable> codec_table(const AccuracyContext& ctx) {
  auto src = source_tiles(ctx.archive, ctx.quick ? 24 : 400);
  if (!src) return src.error();
  const std::vector<TileImage>& tiles = *src;
  const std::uint32_t size = tiles.front().width;
  const double texels = double(size) * size;

  AccuracyTable t;
  t.id = "codec";
  t.title = "Codec x quality";
  t.columns = {{"setting", "setting", 0},           {"psnr_db", "PSNR dB", 2},
               {"max_error", "max error", 0},       {"bytes_per_tile", "bytes/tile", 0},
               {"bits_per_texel", "bits/texel", 3}, {"encode_ms", "encode ms/tile", 3},
               {"decode_ms", "decode ms/tile", 3},  {"upload_ms", "upload ms/tile", 3},
               {"gpu_bytes", "GPU bytes/tile", 0}};
  TablePlot size_plot{"codec-bytes-vs-encode",
                      "Bytes per tile against encode time",
                      "encode ms per tile",
                      "bytes per tile",
                      true,
                      false,
                      {}};
  TablePlot quality_plot{"codec-psnr-vs-bytes",
                         "Lossy settings: PSNR against bytes per tile",
                         "bytes per tile",
                         "PSNR (dB)",
                         false,
                         false,
                         {}};
  const int rounds = ctx.quick ? 1 : 3;
  double upload_rgba = NAN, upload_bc1 = NAN;
  for (const Setting& s : settings(ctx.quick)) {
    ctx.say("codec table: " + s.label);
    double encode_ms = 0, decode_ms = 0, se = 0;
    std::uint64_t bytes = 0, values = 0;
    int max_err = 0;
    std::vector<TileImage> decoded;
    decoded.reserve(tiles.size());
    for (const TileImage& tile : tiles) {
      const auto te = Clock::now();
      auto payload = encode_tile(tile, s.codec, s.encode);
      encode_ms += ms_since(te);
      if (!payload) return payload.error();
      bytes += payload->size();
      const auto td = Clock::now();
      auto d = decode_tile(*payload);
      decode_ms += ms_since(td);
      if (!d) return d.error();
      Result<TileImage> rgba = d->format == PixelFormat::bc1 ? bc1_to_rgba8(*d) : *d;
      if (!rgba) return rgba.error();
      for (std::size_t i = 0; i < tile.pixels.size(); ++i) {
        if (i % 4 == 3) continue;
        const int e = std::abs(int(rgba->pixels[i]) - int(tile.pixels[i]));
        se += double(e) * e;
        max_err = std::max(max_err, e);
        ++values;
      }
      decoded.push_back(std::move(*d));
    }
    const double n = double(tiles.size());
    const double psnr = se == 0 ? INFINITY : 10 * std::log10(255.0 * 255.0 * double(values) / se);
    const bool bc1 = s.codec == CodecId::bc1;
    double& upload = bc1 ? upload_bc1 : upload_rgba;
    if (std::isnan(upload))
      upload = upload_ms_per_tile(decoded, decoded.front().format, size, rounds);
    const double gpu_bytes = bc1 ? std::ceil(size / 4.0) * std::ceil(size / 4.0) * 8 : texels * 4;
    t.rows.push_back({s.label, psnr, double(max_err), double(bytes) / n,
                      double(bytes) * 8 / (n * texels), encode_ms / n, decode_ms / n, upload,
                      gpu_bytes});
    auto series = std::find_if(size_plot.series.begin(), size_plot.series.end(),
                               [&](const PlotSeries& p) { return p.label == s.family; });
    if (series == size_plot.series.end())
      series = size_plot.series.insert(size_plot.series.end(), PlotSeries{s.family, {}, {}});
    series->points.emplace_back(encode_ms / n, double(bytes) / n);
    series->labels.push_back(bc1 ? bc1_quality_name(s.encode.bc1)
                                 : "z" + std::to_string(s.encode.zstd_level));
    if (bc1) {
      if (quality_plot.series.empty())
        quality_plot.series.push_back({"bc1 fast, high, best", {}, {}});
      quality_plot.series.front().points.emplace_back(double(bytes) / n, psnr);
      quality_plot.series.front().labels.push_back(bc1_quality_name(s.encode.bc1));
    }
  }
  t.notes = {
      std::to_string(tiles.size()) + " stored tiles of " + std::to_string(size) + " x " +
          std::to_string(size) +
          " texels (content + border) from every level of the lossless "
          "archive of the input (at most " +
          std::to_string(ctx.quick ? 24 : 400) +
          ", evenly over the archive's tile order); each encoded, decoded and compared with "
          "the source tile.",
      "PSNR and max error over R, G and B of the sRGB-encoded texels the GPU is given "
      "(bc1: decoded on the CPU by bc1_to_rgba8, libsquish's decoder to the bit); inf = exact.",
      "encode: encode_tile (filter + zstd, or BC1 block search + zstd); decode: decode_tile "
      "(checksum + zstd + unfilter; bc1 stops at the blocks the GPU takes). One thread.",
      "upload: memcpy into a mapped pixel-unpack buffer + glTextureSubImage2D "
      "(bc1: glCompressedTextureSubImage2D) into an sRGB atlas, until glFinish; measured once per "
      "texture format; n/a without GL.",
      "GPU bytes: the tile's slot in the physical texture (RGBA8: 4 bytes per texel, BC1: 0.5).",
  };
  t.plots = {size_plot, quality_plot};
  return t;
}

}  // namespace vts::accuracy
