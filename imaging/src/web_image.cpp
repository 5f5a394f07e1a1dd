// Standard web images of tiles: our PNG writer over libdeflate (png_writer.cpp) and libpng's
// simplified reading API, libwebp (advanced API), TurboJPEG.
#include "vts/imaging/web_image.hpp"

#include <png.h>
#include <turbojpeg.h>
#include <webp/decode.h>
#include <webp/encode.h>

#include <algorithm>
#include <cstring>
#include <string>

#include "png_writer.hpp"
#include "vts/base/file_io.hpp"

namespace vts::imaging {
namespace {

Error bad(std::string message) {
  return make_error(ErrorCode::invalid_argument, std::move(message));
}

// ---- PNG (written by png_writer.cpp; read by libpng's simplified API)

bool opaque(const TileImage& rgba) {
  for (std::size_t i = 3; i < rgba.pixels.size(); i += 4)
    if (rgba.pixels[i] != 255) return false;
  return true;
}

// The RGB bytes of rgba8 pixels (alpha dropped).
std::vector<std::uint8_t> rgb_of(std::span<const std::uint8_t> rgba) {
  std::vector<std::uint8_t> rgb(rgba.size() / 4 * 3);
  for (std::size_t i = 0, j = 0; i < rgba.size(); i += 4, j += 3) std::memcpy(&rgb[j], &rgba[i], 3);
  return rgb;
}

Result<std::vector<std::uint8_t>> encode_png(const TileImage& rgba, const WebEncodeOptions& o) {
  if (opaque(rgba)) {  // RGB: a quarter smaller to write, decodes to the same rgba8
    const std::vector<std::uint8_t> rgb = rgb_of(rgba.pixels);
    return detail::png_bytes(rgb.data(), rgba.width, rgba.height, 3, o.png_level, o.png_filter,
                             false);
  }
  return detail::png_bytes(rgba.pixels.data(), rgba.width, rgba.height, 4, o.png_level,
                           o.png_filter, false);
}

Result<TileImage> decode_png(std::span<const std::uint8_t> bytes) {
  png_image image{};
  image.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_memory(&image, bytes.data(), bytes.size())) {
    return make_error(ErrorCode::corrupt, std::string("not a readable PNG: ") + image.message);
  }
  if (image.width == 0 || image.height == 0 || image.width > TileHeader::kMaxDimension ||
      image.height > TileHeader::kMaxDimension) {
    png_image_free(&image);
    return make_error(ErrorCode::corrupt, "PNG of " + std::to_string(image.width) + "x" +
                                              std::to_string(image.height) + " texels");
  }
  image.format = PNG_FORMAT_RGBA;
  TileImage out{image.width, image.height, PixelFormat::rgba8, {}};
  out.pixels.resize(PNG_IMAGE_SIZE(image));
  if (!png_image_finish_read(&image, nullptr, out.pixels.data(), 0, nullptr)) {
    const std::string why = image.message;
    png_image_free(&image);
    return make_error(ErrorCode::corrupt, "not a readable PNG: " + why);
  }
  return out;
}

// ---- WebP

Result<std::vector<std::uint8_t>> encode_webp(const TileImage& rgba, const WebEncodeOptions& o) {
  WebPConfig config;
  if (!WebPConfigInit(&config)) return make_error(ErrorCode::io, "libwebp: version mismatch");
  config.quality = static_cast<float>(o.webp_quality);
  config.method = o.webp_method;
  config.lossless = o.webp_lossless ? 1 : 0;
  WebPPicture picture;
  if (!WebPPictureInit(&picture)) return make_error(ErrorCode::io, "libwebp: version mismatch");
  // Lossy: the import converts straight to YUV (with an alpha plane only when a texel is not
  // opaque); lossless encodes ARGB.
  picture.use_argb = o.webp_lossless ? 1 : 0;
  picture.width = static_cast<int>(rgba.width);
  picture.height = static_cast<int>(rgba.height);
  WebPMemoryWriter writer;
  WebPMemoryWriterInit(&writer);
  picture.writer = WebPMemoryWrite;
  picture.custom_ptr = &writer;
  const bool ok =
      WebPPictureImportRGBA(&picture, rgba.pixels.data(), static_cast<int>(rgba.width) * 4) &&
      WebPEncode(&config, &picture);
  const int code = picture.error_code;
  WebPPictureFree(&picture);
  if (!ok) {
    WebPMemoryWriterClear(&writer);
    return make_error(ErrorCode::io,
                      "WebP encoding failed (libwebp error " + std::to_string(code) + ")");
  }
  std::vector<std::uint8_t> out(writer.mem, writer.mem + writer.size);
  WebPMemoryWriterClear(&writer);
  return out;
}

Result<TileImage> decode_webp(std::span<const std::uint8_t> bytes) {
  int width = 0, height = 0;
  if (!WebPGetInfo(bytes.data(), bytes.size(), &width, &height) || width <= 0 || height <= 0 ||
      width > int(TileHeader::kMaxDimension) || height > int(TileHeader::kMaxDimension)) {
    return make_error(ErrorCode::corrupt, "not a readable WebP image");
  }
  TileImage out{std::uint32_t(width), std::uint32_t(height), PixelFormat::rgba8, {}};
  out.pixels.resize(std::size_t(width) * height * 4);
  if (WebPDecodeRGBAInto(bytes.data(), bytes.size(), out.pixels.data(), out.pixels.size(),
                         width * 4) == nullptr) {
    return make_error(ErrorCode::corrupt, "not a readable WebP image (its data does not decode)");
  }
  return out;
}

// ---- JPEG (TurboJPEG handles are per thread: creating one costs more than a tile's encode)

struct TjHandle {
  tjhandle handle;
  explicit TjHandle(tjhandle h) : handle(h) {}
  TjHandle(const TjHandle&) = delete;
  TjHandle& operator=(const TjHandle&) = delete;
  ~TjHandle() {
    if (handle != nullptr) tjDestroy(handle);
  }
};

Result<std::vector<std::uint8_t>> encode_jpeg(const TileImage& rgba, int quality) {
  thread_local TjHandle tj(tjInitCompress());
  if (tj.handle == nullptr) return make_error(ErrorCode::io, "TurboJPEG: cannot start");
  // No alpha in JPEG: composite over black.
  std::vector<std::uint8_t> rgb(std::size_t(rgba.width) * rgba.height * 3);
  for (std::size_t i = 0, j = 0; i < rgba.pixels.size(); i += 4, j += 3) {
    const unsigned a = rgba.pixels[i + 3];
    for (int c = 0; c < 3; ++c) rgb[j + c] = std::uint8_t((rgba.pixels[i + c] * a + 127) / 255);
  }
  unsigned char* jpeg = nullptr;
  unsigned long size = 0;
  if (tjCompress2(tj.handle, rgb.data(), int(rgba.width), 0, int(rgba.height), TJPF_RGB, &jpeg,
                  &size, TJSAMP_420, quality, 0) != 0) {
    tjFree(jpeg);
    return make_error(ErrorCode::io,
                      std::string("JPEG encoding failed: ") + tjGetErrorStr2(tj.handle));
  }
  std::vector<std::uint8_t> out(jpeg, jpeg + size);
  tjFree(jpeg);
  return out;
}

Result<TileImage> decode_jpeg(std::span<const std::uint8_t> bytes) {
  thread_local TjHandle tj(tjInitDecompress());
  if (tj.handle == nullptr) return make_error(ErrorCode::io, "TurboJPEG: cannot start");
  int width = 0, height = 0, subsampling = 0, colorspace = 0;
  // A warning (truncated data, a bad marker) is an error here: a partly grey tile is no tile.
  if (tjDecompressHeader3(tj.handle, bytes.data(), bytes.size(), &width, &height, &subsampling,
                          &colorspace) != 0 ||
      width <= 0 || height <= 0 || width > int(TileHeader::kMaxDimension) ||
      height > int(TileHeader::kMaxDimension)) {
    return make_error(ErrorCode::corrupt,
                      std::string("not a readable JPEG: ") + tjGetErrorStr2(tj.handle));
  }
  TileImage out{std::uint32_t(width), std::uint32_t(height), PixelFormat::rgba8, {}};
  out.pixels.resize(std::size_t(width) * height * 4);
  if (tjDecompress2(tj.handle, bytes.data(), bytes.size(), out.pixels.data(), width, 0, height,
                    TJPF_RGBA, 0) != 0) {
    return make_error(ErrorCode::corrupt,
                      std::string("not a readable JPEG: ") + tjGetErrorStr2(tj.handle));
  }
  return out;
}

}  // namespace

std::string_view web_format_extension(WebFormat f) noexcept {
  switch (f) {
    case WebFormat::png:
      return "png";
    case WebFormat::webp:
      return "webp";
    case WebFormat::jpeg:
      return "jpg";
  }
  return "png";
}

std::string_view web_format_content_type(WebFormat f) noexcept {
  switch (f) {
    case WebFormat::png:
      return "image/png";
    case WebFormat::webp:
      return "image/webp";
    case WebFormat::jpeg:
      return "image/jpeg";
  }
  return "image/png";
}

Result<WebFormat> parse_web_format(std::string_view text) {
  if (iequals(text, "png")) return WebFormat::png;
  if (iequals(text, "webp")) return WebFormat::webp;
  if (iequals(text, "jpg") || iequals(text, "jpeg")) return WebFormat::jpeg;
  return bad("unknown image format \"" + std::string(text) + "\" (known: png, webp, jpg)");
}

Status validate(const WebEncodeOptions& o) {
  if (o.png_level < 0 || o.png_level > 9)
    return bad("png_level is " + std::to_string(o.png_level) + "; it must be 0..9");
  if (o.webp_quality < 0 || o.webp_quality > 100)
    return bad("webp_quality is " + std::to_string(o.webp_quality) + "; it must be 0..100");
  if (o.webp_method < 0 || o.webp_method > 6)
    return bad("webp_method is " + std::to_string(o.webp_method) + "; it must be 0..6");
  if (o.jpeg_quality < 1 || o.jpeg_quality > 100)
    return bad("jpeg_quality is " + std::to_string(o.jpeg_quality) + "; it must be 1..100");
  return {};
}

Result<std::vector<std::uint8_t>> encode_web_image(const TileImage& rgba, WebFormat format,
                                                   const WebEncodeOptions& options) {
  if (Status s = validate(options); !s) return s.error();
  if (rgba.format != PixelFormat::rgba8 || rgba.width == 0 || rgba.height == 0 ||
      rgba.width > TileHeader::kMaxDimension || rgba.height > TileHeader::kMaxDimension ||
      rgba.pixels.size() != std::size_t(rgba.width) * rgba.height * 4) {
    return bad("a web image needs a non-empty rgba8 image whose bytes match its size");
  }
  switch (format) {
    case WebFormat::png:
      return encode_png(rgba, options);
    case WebFormat::webp:
      return encode_webp(rgba, options);
    case WebFormat::jpeg:
      return encode_jpeg(rgba, options.jpeg_quality);
  }
  return bad("unknown web format");
}

Result<TileImage> decode_web_image(std::span<const std::uint8_t> bytes) {
  static constexpr std::uint8_t kPng[] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (bytes.size() >= 8 && std::equal(kPng, kPng + 8, bytes.begin())) return decode_png(bytes);
  if (bytes.size() >= 12 && std::memcmp(bytes.data(), "RIFF", 4) == 0 &&
      std::memcmp(bytes.data() + 8, "WEBP", 4) == 0) {
    return decode_webp(bytes);
  }
  if (bytes.size() >= 3 && bytes[0] == 0xff && bytes[1] == 0xd8 && bytes[2] == 0xff)
    return decode_jpeg(bytes);
  return make_error(ErrorCode::corrupt,
                    "not a PNG, WebP or JPEG image (" + std::to_string(bytes.size()) + " bytes)");
}

Result<TileImage> tile_content(const TileImage& stored, const Geometry& geometry, TileId id) {
  const std::uint32_t s = geometry.stored_size(), t = geometry.tile_size(), b = geometry.border();
  if (!geometry.valid_level(id.z) || !geometry.exists(id)) {
    return bad("tile " + id.to_string() + " is not in the pyramid");
  }
  if (stored.width != s || stored.height != s) {
    return bad("tile " + id.to_string() + " has " + std::to_string(stored.width) + "x" +
               std::to_string(stored.height) + " texels; the tileset's are " + std::to_string(s) +
               "x" + std::to_string(s));
  }
  TileImage converted;
  const TileImage* rgba = &stored;
  if (stored.format == PixelFormat::bc1) {
    auto decoded = bc1_to_rgba8(stored);
    if (!decoded) return decoded.error();
    converted = std::move(*decoded);
    rgba = &converted;
  }
  if (rgba->pixels.size() != std::size_t(s) * s * 4) {
    return bad("tile " + id.to_string() + ": its bytes do not match its size");
  }
  const TexelRect r = geometry.content_rect(id);
  TileImage out{t, t, PixelFormat::rgba8, std::vector<std::uint8_t>(std::size_t(t) * t * 4, 0)};
  const std::size_t row = std::size_t(r.width()) * 4;
  for (std::uint64_t y = 0; y < r.height(); ++y) {
    std::memcpy(&out.pixels[std::size_t(y) * t * 4],
                &rgba->pixels[(std::size_t(y + b) * s + b) * 4], row);
  }
  return out;
}

Status write_png(const std::filesystem::path& path, int width, int height,
                 std::span<const std::uint8_t> rgba, int level, int channels) {
  const std::string where = "cannot write '" + path.string() + "': ";
  if (width <= 0 || height <= 0 || width > (1 << 20) || height > (1 << 20) ||
      rgba.size() != std::size_t(width) * std::size_t(height) * 4)
    return bad(where + "invalid " + std::to_string(width) + "x" + std::to_string(height) +
               " image of " + std::to_string(rgba.size()) + " bytes");
  if (level < 0 || level > 9) return bad(where + "PNG level " + std::to_string(level));
  if (channels != 3 && channels != 4) return bad(where + std::to_string(channels) + " channels");
  std::vector<std::uint8_t> rgb;
  if (channels == 3) rgb = rgb_of(rgba);  // alpha dropped
  auto bytes = detail::png_bytes(channels == 3 ? rgb.data() : rgba.data(), std::uint32_t(width),
                                 std::uint32_t(height), channels, level,
                                 WebEncodeOptions{}.png_filter, true);
  if (!bytes) return make_error(ErrorCode::io, where + bytes.error().message);
  Status written = write_file_atomically(
      path, std::string_view(reinterpret_cast<const char*>(bytes->data()), bytes->size()));
  if (written) return written;
  Error e = std::move(written).error();  // names the temporary file: name the target as well
  e.message = where + e.message;
  return e;
}

}  // namespace vts::imaging
