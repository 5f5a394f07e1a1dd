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
// This library decodes every codec, encodes `lossless` (the exact inverse of its decoder) and
// frames texels an encoder has already made into a payload (pack_tile()). The bc1 block encoders
// (stb_dxt, libsquish) live with their only user, the builder (vts/builder/tile_encoder.hpp), so
// nothing that merely reads tiles links them. Every function here is thread-safe.
#pragma once

#include <cstddef>
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

const char* codec_name(CodecId id) noexcept;
Result<CodecId> parse_codec_name(std::string_view name);
const char* filter_name(Filter f) noexcept;

// BC1 packs 4x4 texels into a block of kBc1BlockBytes; a side of `texels` takes bc1_blocks(texels)
// blocks (the last one partial when `texels` is not a multiple of 4).
inline constexpr std::size_t kBc1BlockBytes = 8;
constexpr std::size_t bc1_blocks(std::uint32_t texels) noexcept {
  return (std::size_t(texels) + 3) / 4;
}

// Decoded texels. rgba8: width*height*4 bytes, rows top to bottom, no padding, sRGB-encoded colour
// with straight (not premultiplied) alpha. bc1: ceil(w/4)*ceil(h/4) blocks of 8 bytes.
struct TileImage {
  std::uint32_t width = 0;
  std::uint32_t height = 0;
  PixelFormat format = PixelFormat::rgba8;
  std::vector<std::uint8_t> pixels;
};

// The lossless encoder's settings.
struct LosslessOptions {
  int zstd_level = 3;  // 1..19 (negative fast levels also accepted by zstd)
  FilterChoice filter = FilterChoice::automatic;  // automatic keeps the smaller of none / gradient
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

// A codec as a reader sees it: stateless singletons (find_codec()).
class Codec {
 public:
  virtual ~Codec() = default;
  virtual CodecId id() const = 0;
  virtual PixelFormat decoded_format() const = 0;
  // Verifies the header and checksum, then decodes into the codec's decoded_format().
  virtual Result<TileImage> decode(std::span<const std::uint8_t> payload) const = 0;
};

// invalid_argument naming what is wrong (and `codec`) unless `image` is rgba8 of
// 1..TileHeader::kMaxDimension texels a side holding exactly width * height * 4 bytes: what every
// encoder takes, checked before it reads a texel.
Status check_encode_input(const TileImage& image, CodecId codec);

// Encodes an rgba8 image (check_encode_input()) as a lossless payload: the filter `options` asks
// for (automatic: whichever of none and gradient compresses smaller, a tie going to none), then
// zstd at options.zstd_level. invalid_argument on a bad image or zstd level. The returned
// vector's capacity is its size.
Result<std::vector<std::uint8_t>> encode_lossless(const TileImage& image,
                                                  const LosslessOptions& options = {});

// Frames a body an encoder has already made into a complete payload: the header frame (codec,
// its pixel format — lossless: rgba8, bc1: bc1 —, filter none, width x height, the checksum)
// followed by `body` compressed at `zstd_level`. The inverse of Codec::decode() for a body
// without a filter: bc1 blocks (ceil(w/4) * ceil(h/4) * 8 bytes, row-major) or unfiltered rgba8.
// invalid_argument when the codec is unknown, a side is outside 1..kMaxDimension, body's size is
// not the codec's for that size, or zstd_level is not a zstd level. The returned vector's capacity
// is its size.
Result<std::vector<std::uint8_t>> pack_tile(CodecId codec, std::uint32_t width,
                                            std::uint32_t height,
                                            std::span<const std::uint8_t> body, int zstd_level);

// The rgba8 image a bc1 image decodes to (width x height texels, the partial blocks of a size
// that is not a multiple of 4 cropped): what a GPU sampling GL_COMPRESSED_SRGB_ALPHA_S3TC_DXT1
// reads, before the sRGB decode. A block's two 5:6:5 endpoints are widened to 8 bits by bit
// replication; c0 > c1 selects four colours (c0, c1, (2 c0 + c1) / 3, (c0 + 2 c1) / 3), else three
// and transparent black. The interpolants round as libsquish's decoder does (integer division,
// bit for bit; tests/unit/builder checks it against libsquish); GPUs may differ by one code (the
// S3TC specification leaves the rounding open). invalid_argument when `image` is not bc1 or its
// byte count does not match its size.
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
