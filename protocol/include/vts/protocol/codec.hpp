// Tile codecs. A stored tile ("payload") is a valid zstd stream made of two frames:
//
//   1. a zstd *skippable* frame (magic 0x184D2A5A) carrying our 32-byte tile header — codec,
//   filter,
//      dimensions, decoded size and an XXH3-64 checksum of the bytes that follow;
//   2. one ordinary zstd frame holding the codec's body (for `lossless`: the possibly filtered
//      RGBA8 texels, see docs/FORMAT.md).
//
// So the archive can declare tile_compression = zstd truthfully (generic tools skip our header
// frame), and any holder of the payload — server, cache, CDN checker — can verify the checksum
// without decoding. Every decode verifies the checksum and checks every declared size against
// hard limits before allocating; hostile bytes yield an Error, never a crash.
//
// Codecs are stateless singletons; encode() and decode() are thread-safe.
#pragma once

#include <cstdint>
#include <span>
#include <string_view>
#include <vector>

#include "vts/base/result.hpp"

namespace vts {
inline namespace protocol {

enum class CodecId : std::uint8_t { lossless = 0, bc1 = 1 };
enum class PixelFormat : std::uint8_t { rgba8 = 0, bc1 = 1 };
// Prediction filter applied before zstd by the lossless codec.
enum class Filter : std::uint8_t {
  none = 0,  // interleaved RGBA8 as is
  gradient =
      1,  // planar R,G,B,A, each byte predicted by clamp(left + up - upleft), residual mod 256
};
enum class FilterChoice : std::uint8_t { none, gradient, automatic };
// How hard the bc1 codec searches for each 4x4 block's two endpoint colours. Every mode writes the
// same format; they differ in encode time and error (docs/ACCURACY.md, table 1):
//   fast: stb_dxt (stb_compress_dxt_block, STB_DXT_HIGHQUAL): the principal axis by power
//         iteration, endpoints refined twice by least squares;
//   high: libsquish cluster fit: searches the orderings of the 16 texels along the
//         principal axis;
//   best: libsquish iterative cluster fit: repeats the cluster fit with the refined axis.
enum class Bc1Quality : std::uint8_t { fast, high, best };

const char* codec_name(CodecId id) noexcept;
Result<CodecId> parse_codec_name(std::string_view name);
const char* filter_name(Filter f) noexcept;
const char* bc1_quality_name(Bc1Quality q) noexcept;
Result<Bc1Quality> parse_bc1_quality(std::string_view name);

// Decoded texels. rgba8: width*height*4 bytes, rows top to bottom, no padding, sRGB-encoded colour
// with straight (not premultiplied) alpha. bc1: ceil(w/4)*ceil(h/4) blocks of 8 bytes.
struct TileImage {
  std::uint32_t width = 0;
  std::uint32_t height = 0;
  PixelFormat format = PixelFormat::rgba8;
  std::vector<std::uint8_t> pixels;
};

struct EncodeOptions {
  int zstd_level = 3;  // 1..19 (negative fast levels also accepted by zstd)
  FilterChoice filter = FilterChoice::automatic;  // lossless: automatic keeps the smaller of
                                                  // none / gradient; bc1 takes no filter
  Bc1Quality bc1 = Bc1Quality::fast;              // bc1 only (docs/ACCURACY.md: fast is 40x quicker
                                                  // than high for 0.3 dB less on the Earth)
};

// What the skippable header frame says. parse_tile_header() reads it without decompressing.
struct TileHeader {
  static constexpr std::uint32_t kSkippableMagic = 0x184D2A5A;
  static constexpr std::uint32_t kHeaderBytes = 32;  // content of the skippable frame
  static constexpr std::uint32_t kFrameBytes = 8 + kHeaderBytes;
  static constexpr std::uint8_t kVersion = 1;
  static constexpr std::uint32_t kMaxDimension = 8192;

  std::uint8_t version = kVersion;
  CodecId codec = CodecId::lossless;
  Filter filter = Filter::none;
  PixelFormat format = PixelFormat::rgba8;
  std::uint32_t width = 0;
  std::uint32_t height = 0;
  std::uint32_t body_size = 0;  // decompressed size of the zstd body frame
  std::uint64_t checksum = 0;   // XXH3-64 (seed 0) of every payload byte after the header frame
};

// Parses and validates the header frame (magic, version, known codec/filter, dimensions within
// kMaxDimension, body_size consistent with codec and dimensions). Does not touch the body.
Result<TileHeader> parse_tile_header(std::span<const std::uint8_t> payload);
// parse_tile_header() plus the checksum of the body. Cheap: hashing only, no decompression.
Result<TileHeader> verify_tile(std::span<const std::uint8_t> payload);

// What a tileset says every one of its tiles is: width x height texels (its geometry's
// stored_size() on both sides, edge tiles included) encoded with `codec`, whose pixel format
// follows (lossless: rgba8, bc1: bc1). TilesetInfo::tile_spec() gives a tileset's.
struct TileSpec {
  std::uint32_t width = 0;
  std::uint32_t height = 0;
  CodecId codec = CodecId::lossless;
};
// The one check of a tile against its tileset, made by every cache before it stores or hands
// out a tile and by every decoder given a tileset: corrupt, naming the field, when the header's
// size, codec or pixel format is not the tileset's. Reads the header only.
Status check_tile_against(const TileHeader& header, const TileSpec& spec);
// verify_tile() + check_tile_against().
Result<TileHeader> verify_tile(std::span<const std::uint8_t> payload, const TileSpec& spec);

class Codec {
 public:
  virtual ~Codec() = default;
  virtual CodecId id() const = 0;
  virtual PixelFormat decoded_format() const = 0;
  // `image` must be rgba8 of the tileset's stored size. Returns the complete payload.
  virtual Result<std::vector<std::uint8_t>> encode(const TileImage& image,
                                                   const EncodeOptions& options) const = 0;
  // Verifies the header and checksum, then decodes into the codec's decoded_format().
  virtual Result<TileImage> decode(std::span<const std::uint8_t> payload) const = 0;
};

// The rgba8 image a bc1 image decodes to (width x height texels, the partial blocks of a size
// that is not a multiple of 4 cropped): what a GPU sampling GL_COMPRESSED_SRGB_ALPHA_S3TC_DXT1
// reads, before the sRGB decode. A block's two 5:6:5 endpoints are widened to 8 bits by bit
// replication; c0 > c1 selects four colours (c0, c1, (2 c0 + c1) / 3, (c0 + 2 c1) / 3), else three
// and transparent black. The interpolants follow libsquish's integer rounding; GPUs may differ
// by one code (the S3TC specification leaves the rounding open). invalid_argument when `image`
// is not bc1 or its byte count does not match its size.
Result<TileImage> bc1_to_rgba8(const TileImage& image);

// The codec singleton for an id; nullptr when not implemented in this build.
const Codec* find_codec(CodecId id) noexcept;
// Decodes any payload with the codec its header names. Without a tileset the declared size is
// bounded only by TileHeader::kMaxDimension per side (256 MiB of rgba8): give the tileset's
// TileSpec whenever there is one.
Result<TileImage> decode_tile(std::span<const std::uint8_t> payload);
// Refuses (corrupt) a tile whose header contradicts `spec` before allocating anything for its
// texels, then decodes it as above.
Result<TileImage> decode_tile(std::span<const std::uint8_t> payload, const TileSpec& spec);

}  // namespace protocol
}  // namespace vts
