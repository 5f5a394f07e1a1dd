// Tile payload framing (skippable header frame + one zstd frame, pack_tile()) and the lossless
// codec.
// Byte layout of the header frame, all little-endian:
//
//   offset size  field
//        0    4  magic 0x184D2A5A (a zstd skippable frame)
//        4    4  frame content size = 32
//        8    1  version (1)
//        9    1  codec (0 lossless, 1 bc1)
//       10    1  filter (0 none, 1 gradient)
//       11    1  pixel format (0 rgba8, 1 bc1)
//       12    4  width   (1..kMaxDimension)
//       16    4  height  (1..kMaxDimension)
//       20    4  body_size: decompressed size of the body frame
//       24    8  checksum: XXH3_64bits (seed 0) of payload[40 .. end)
//       32    8  reserved, must be zero
//
// followed by exactly one zstd frame that declares its content size (== body_size) and ends
// exactly at the end of the payload.
#define ZSTD_STATIC_LINKING_ONLY  // ZSTD_getFrameHeader(): frame header fields for the size checks
#include <zstd.h>
#include <zstd_errors.h>

#include <xxhash.h>

#include <cassert>
#include <cstdio>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "codec_internal.hpp"
#include "vts/protocol/codec.hpp"

namespace vts {
inline namespace protocol {
namespace {

constexpr std::size_t kFrameBytes = TileHeader::kFrameBytes;

// ---- little-endian helpers --------------------------------------------------------------------

std::uint32_t load_u32(const std::uint8_t* p) {
  return std::uint32_t(p[0]) | std::uint32_t(p[1]) << 8 | std::uint32_t(p[2]) << 16 |
         std::uint32_t(p[3]) << 24;
}
std::uint64_t load_u64(const std::uint8_t* p) {
  return std::uint64_t(load_u32(p)) | std::uint64_t(load_u32(p + 4)) << 32;
}
void store_u32(std::uint8_t* p, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}
void store_u64(std::uint8_t* p, std::uint64_t v) {
  for (int i = 0; i < 8; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}

std::string hex64(std::uint64_t v) {
  char buf[19];
  std::snprintf(buf, sizeof buf, "0x%016llx", static_cast<unsigned long long>(v));
  return buf;
}

// Expected body size for a codec, pixel format and size; 0 when the combination is invalid.
std::uint64_t expected_body_size(CodecId codec, PixelFormat format, std::uint32_t w,
                                 std::uint32_t h) {
  if (codec == CodecId::lossless && format == PixelFormat::rgba8) return std::uint64_t(w) * h * 4;
  if (codec == CodecId::bc1 && format == PixelFormat::bc1)
    return std::uint64_t(bc1_blocks(w)) * bc1_blocks(h) * kBc1BlockBytes;
  return 0;
}

// Validates what parse_tile_header() promises about a header, wherever it came from.
Status check_header(const TileHeader& h) {
  if (h.version != TileHeader::kVersion)
    return make_error(ErrorCode::unsupported, "tile header version " + std::to_string(h.version) +
                                                  " (this build reads " +
                                                  std::to_string(TileHeader::kVersion) + ")");
  if (static_cast<std::uint8_t>(h.codec) > static_cast<std::uint8_t>(CodecId::bc1))
    return make_error(ErrorCode::unsupported,
                      "unknown tile codec " + std::to_string(static_cast<int>(h.codec)));
  if (static_cast<std::uint8_t>(h.filter) > static_cast<std::uint8_t>(Filter::gradient))
    return make_error(ErrorCode::unsupported,
                      "unknown tile filter " + std::to_string(static_cast<int>(h.filter)));
  if (static_cast<std::uint8_t>(h.format) > static_cast<std::uint8_t>(PixelFormat::bc1))
    return make_error(ErrorCode::unsupported,
                      "unknown pixel format " + std::to_string(static_cast<int>(h.format)));
  if (h.width == 0 || h.height == 0)
    return make_error(ErrorCode::corrupt, "tile header declares an empty tile (" +
                                              std::to_string(h.width) + "x" +
                                              std::to_string(h.height) + ")");
  if (h.width > TileHeader::kMaxDimension || h.height > TileHeader::kMaxDimension)
    return make_error(ErrorCode::too_large, "tile header declares " + std::to_string(h.width) +
                                                "x" + std::to_string(h.height) + " texels (limit " +
                                                std::to_string(TileHeader::kMaxDimension) +
                                                " per side)");
  const std::uint64_t expected = expected_body_size(h.codec, h.format, h.width, h.height);
  if (expected == 0)
    return make_error(ErrorCode::corrupt, std::string("tile header pairs codec ") +
                                              codec_name(h.codec) + " with pixel format " +
                                              std::to_string(static_cast<int>(h.format)));
  if (h.codec == CodecId::bc1 && h.filter != Filter::none)
    return make_error(ErrorCode::corrupt, "bc1 tiles take no filter");
  if (h.body_size != expected)
    return make_error(ErrorCode::corrupt, "tile header body_size " + std::to_string(h.body_size) +
                                              " != " + std::to_string(expected) + " for " +
                                              std::to_string(h.width) + "x" +
                                              std::to_string(h.height) + " " + codec_name(h.codec));
  return {};
}

void write_header(const TileHeader& h, std::uint8_t* out) {
  store_u32(out, TileHeader::kSkippableMagic);
  store_u32(out + 4, TileHeader::kHeaderBytes);
  out[8] = h.version;
  out[9] = static_cast<std::uint8_t>(h.codec);
  out[10] = static_cast<std::uint8_t>(h.filter);
  out[11] = static_cast<std::uint8_t>(h.format);
  store_u32(out + 12, h.width);
  store_u32(out + 16, h.height);
  store_u32(out + 20, h.body_size);
  store_u64(out + 24, h.checksum);
  std::memset(out + 32, 0, 8);
}

// zstd contexts are expensive to create (hundreds of KB of tables) and cheap to reuse, so each
// thread keeps one of each for its lifetime.
struct CCtxDeleter {
  void operator()(ZSTD_CCtx* c) const { ZSTD_freeCCtx(c); }
};
struct DCtxDeleter {
  void operator()(ZSTD_DCtx* d) const { ZSTD_freeDCtx(d); }
};
ZSTD_CCtx* thread_cctx() {
  thread_local std::unique_ptr<ZSTD_CCtx, CCtxDeleter> ctx(ZSTD_createCCtx());
  return ctx.get();
}
ZSTD_DCtx* thread_dctx() {
  thread_local std::unique_ptr<ZSTD_DCtx, DCtxDeleter> ctx(ZSTD_createDCtx());
  return ctx.get();
}

// Per-thread scratch buffers, so that encoding millions of tiles does not allocate per tile
// except for the returned payload. Each keeps the capacity of the largest recent tile, unless
// that exceeds kKeepScratchBytes: a rare huge tile must not pin its size per thread for ever.
constexpr std::size_t kKeepScratchBytes = std::size_t(16) << 20;
std::vector<std::uint8_t>* scratch_buffers() {
  thread_local std::vector<std::uint8_t> buffers[3];
  return buffers;
}
std::vector<std::uint8_t>& scratch(int slot) {
  return scratch_buffers()[slot];
}
struct TrimScratchOnExit {
  ~TrimScratchOnExit() {
    for (int i = 0; i < 3; ++i)
      if (scratch(i).capacity() > kKeepScratchBytes) std::vector<std::uint8_t>().swap(scratch(i));
  }
};

// Upper bound of what one zstd frame may decompress to, from its block headers alone (raw and RLE
// blocks state their size, a compressed block yields at most blockSizeMax). Lets a decoder reject
// a header that declares far more texels than the body could ever produce before allocating.
// Returns 0 on a malformed block list (check_body_frame() rejects those first).
std::uint64_t frame_content_bound(std::span<const std::uint8_t> frame, const ZSTD_frameHeader& fh) {
  std::size_t pos = fh.headerSize;
  std::uint64_t bound = 0;
  for (;;) {
    if (frame.size() - pos < 3) return 0;
    const std::uint32_t bh = std::uint32_t(frame[pos]) | std::uint32_t(frame[pos + 1]) << 8 |
                             std::uint32_t(frame[pos + 2]) << 16;
    pos += 3;
    const std::uint32_t type = (bh >> 1) & 3, size = bh >> 3;
    if (type == 3) return 0;  // reserved block type
    // Raw and RLE blocks state their decoded size; a compressed one yields at most blockSizeMax.
    bound += type == 2 ? fh.blockSizeMax : size;
    // An RLE block stores its one repeated byte; raw and compressed blocks store `size` bytes.
    pos += type == 1 ? 1 : size;
    if (pos > frame.size()) return 0;
    if (bh & 1) return bound;  // last block
  }
}

// The zstd frame following the header must be complete, alone, and declare body_size.
Status check_body_frame(const TileHeader& h, std::span<const std::uint8_t> body) {
  if (body.empty()) return make_error(ErrorCode::truncated, "tile payload has no body frame");
  ZSTD_frameHeader fh{};
  const std::size_t r = ZSTD_getFrameHeader(&fh, body.data(), body.size());
  if (ZSTD_isError(r))
    return make_error(ErrorCode::corrupt,
                      std::string("tile body is not a zstd frame: ") + ZSTD_getErrorName(r));
  if (r > 0) return make_error(ErrorCode::truncated, "tile body ends inside its zstd frame header");
  if (fh.frameType != ZSTD_frame)
    return make_error(ErrorCode::corrupt, "tile body is a skippable frame, not a zstd frame");
  if (fh.frameContentSize == ZSTD_CONTENTSIZE_UNKNOWN)
    return make_error(ErrorCode::corrupt, "tile body frame does not declare its content size");
  if (fh.frameContentSize != h.body_size)
    return make_error(ErrorCode::corrupt, "tile body frame declares " +
                                              std::to_string(fh.frameContentSize) +
                                              " bytes, header says " + std::to_string(h.body_size));
  const std::size_t frame_size = ZSTD_findFrameCompressedSize(body.data(), body.size());
  if (ZSTD_isError(frame_size)) {
    if (ZSTD_getErrorCode(frame_size) == ZSTD_error_srcSize_wrong)
      return make_error(ErrorCode::truncated, "tile body ends inside its zstd frame");
    return make_error(ErrorCode::corrupt, std::string("tile body frame is malformed: ") +
                                              ZSTD_getErrorName(frame_size));
  }
  if (frame_size != body.size())
    return make_error(ErrorCode::corrupt, std::to_string(body.size() - frame_size) +
                                              " trailing bytes after the tile body frame");
  return {};
}

Result<TileHeader> verify_impl(std::span<const std::uint8_t> payload) {
  auto header = parse_tile_header(payload);
  if (!header) return header;
  const auto body = payload.subspan(kFrameBytes);
  if (body.empty()) return make_error(ErrorCode::truncated, "tile payload has no body frame");
  const std::uint64_t actual = XXH3_64bits(body.data(), body.size());
  if (actual != header->checksum) {
    // A truncated body fails here too; say so when the frame structure suggests it, but keep the
    // code `checksum`: a flipped block-header byte looks exactly like a truncation.
    const std::size_t fs = ZSTD_findFrameCompressedSize(body.data(), body.size());
    const bool short_frame = ZSTD_isError(fs) && ZSTD_getErrorCode(fs) == ZSTD_error_srcSize_wrong;
    return make_error(ErrorCode::checksum,
                      "tile checksum mismatch: header says " + hex64(header->checksum) +
                          ", body hashes to " + hex64(actual) +
                          (short_frame ? " (body frame incomplete: payload truncated?)" : ""));
  }
  if (Status s = check_body_frame(*header, body); !s) return s.error();
  return header;
}

class LosslessCodec final : public Codec {
 public:
  CodecId id() const override { return CodecId::lossless; }
  PixelFormat decoded_format() const override { return PixelFormat::rgba8; }
  Result<TileImage> decode(std::span<const std::uint8_t> payload) const override;
};

// Tiles with at most this many distinct RGBA values count as "paletted" for
// FilterChoice::automatic.
constexpr std::size_t kPaletteColours = 256;

// True when the texels hold at most `limit` distinct RGBA values. Stops at the (limit+1)-th
// colour, which continuous-tone tiles reach within a few hundred texels; runs of equal texels
// (flat fills) cost one comparison each.
bool has_at_most_colours(const std::uint8_t* rgba, std::size_t texels, std::size_t limit) {
  constexpr std::size_t kSlots = 1024;  // power of two, > 2 * limit keeps probe chains short
  assert(limit * 2 < kSlots);
  std::uint32_t table[kSlots];
  bool used[kSlots] = {};
  std::size_t distinct = 0;
  std::uint32_t prev = 0;
  for (std::size_t i = 0; i < texels; ++i) {
    std::uint32_t v;
    std::memcpy(&v, rgba + 4 * i, 4);
    if (i > 0 && v == prev) continue;
    prev = v;
    std::size_t slot = (v * 0x9E3779B1u) >> 22;  // Fibonacci hashing to 10 bits
    while (used[slot] && table[slot] != v) slot = (slot + 1) & (kSlots - 1);
    if (used[slot]) continue;
    if (++distinct > limit) return false;
    used[slot] = true;
    table[slot] = v;
  }
  return true;
}

}  // namespace

// Compresses `body` into `out` (resized to header frame + compressed body) and fills the header.
Status detail::compress_payload(const std::uint8_t* body, std::size_t body_size, int level,
                                TileHeader header, std::vector<std::uint8_t>& out) {
  ZSTD_CCtx* cctx = thread_cctx();
  if (cctx == nullptr) return make_error(ErrorCode::internal, "ZSTD_createCCtx failed");
  ZSTD_CCtx_reset(cctx, ZSTD_reset_session_and_parameters);
  // The content size in the frame header is part of the format (decoders check it against
  // body_size before allocating); the zstd frame checksum is redundant with ours.
  size_t r = ZSTD_CCtx_setParameter(cctx, ZSTD_c_compressionLevel, level);
  if (!ZSTD_isError(r)) r = ZSTD_CCtx_setParameter(cctx, ZSTD_c_contentSizeFlag, 1);
  if (!ZSTD_isError(r)) r = ZSTD_CCtx_setParameter(cctx, ZSTD_c_checksumFlag, 0);
  if (ZSTD_isError(r))
    return make_error(ErrorCode::internal, std::string("zstd parameters: ") + ZSTD_getErrorName(r));
  out.resize(kFrameBytes + ZSTD_compressBound(body_size));
  const std::size_t n =
      ZSTD_compress2(cctx, out.data() + kFrameBytes, out.size() - kFrameBytes, body, body_size);
  if (ZSTD_isError(n))
    return make_error(ErrorCode::internal,
                      std::string("zstd compression: ") + ZSTD_getErrorName(n));
  out.resize(kFrameBytes + n);
  header.body_size = static_cast<std::uint32_t>(body_size);
  header.checksum = XXH3_64bits(out.data() + kFrameBytes, n);
  write_header(header, out.data());
  return {};
}

Result<std::vector<std::uint8_t>> encode_lossless(const TileImage& image,
                                                  const LosslessOptions& options) {
  if (Status s = check_encode_input(image, CodecId::lossless); !s) return s.error();
  const std::size_t body_size = std::size_t(image.width) * image.height * 4;
  if (Status s = detail::check_zstd_level(options.zstd_level); !s) return s.error();

  TileHeader header;
  header.codec = CodecId::lossless;
  header.format = PixelFormat::rgba8;
  header.width = image.width;
  header.height = image.height;

  const TrimScratchOnExit trim;
  std::vector<std::uint8_t>& plain = scratch(0);
  std::vector<std::uint8_t>& filtered = scratch(1);
  // automatic: continuous-tone tiles (photographs, rendered terrain) always compress better with
  // the gradient filter — on the Earth test tiles best-of-both was within 0.04% of gradient-only
  // at every zstd level — so only tiles with few colours (maps, diagrams, flat fills), where
  // zstd's matches on raw texels can win, pay for encoding both ways.
  const bool automatic = options.filter == FilterChoice::automatic;
  const bool few_colours =
      automatic && has_at_most_colours(image.pixels.data(), body_size / 4, kPaletteColours);
  const bool try_none = options.filter == FilterChoice::none || few_colours;
  const bool try_gradient = options.filter != FilterChoice::none;
  if (try_none) {
    header.filter = Filter::none;
    if (Status s = detail::compress_payload(image.pixels.data(), body_size, options.zstd_level,
                                            header, plain);
        !s)
      return s.error();
  }
  if (try_gradient) {
    std::vector<std::uint8_t>& planes = scratch(2);
    planes.resize(body_size);
    detail::gradient_filter(image.pixels.data(), image.width, image.height, planes.data());
    header.filter = Filter::gradient;
    if (Status s = detail::compress_payload(planes.data(), body_size, options.zstd_level, header,
                                            filtered);
        !s)
      return s.error();
  }
  // When both were encoded the smaller payload wins; a tie goes to `none`, which decodes faster.
  const std::vector<std::uint8_t>& best =
      !try_gradient || (try_none && plain.size() <= filtered.size()) ? plain : filtered;
  // Copy out of the scratch buffer so the payload's capacity is its size (payloads are queued by
  // the thousands in builders and caches).
  return std::vector<std::uint8_t>(best.begin(), best.end());
}

Result<std::vector<std::uint8_t>> pack_tile(CodecId codec, std::uint32_t width,
                                            std::uint32_t height,
                                            std::span<const std::uint8_t> body, int zstd_level) {
  if (codec != CodecId::lossless && codec != CodecId::bc1)
    return make_error(ErrorCode::invalid_argument,
                      "pack_tile: unknown codec " + std::to_string(static_cast<int>(codec)));
  if (width == 0 || height == 0 || width > TileHeader::kMaxDimension ||
      height > TileHeader::kMaxDimension)
    return make_error(ErrorCode::invalid_argument, "tile size " + std::to_string(width) + "x" +
                                                       std::to_string(height) + " outside 1.." +
                                                       std::to_string(TileHeader::kMaxDimension));
  TileHeader header;
  header.codec = codec;
  header.format = codec == CodecId::bc1 ? PixelFormat::bc1 : PixelFormat::rgba8;
  header.filter = Filter::none;
  header.width = width;
  header.height = height;
  const std::uint64_t expected = expected_body_size(codec, header.format, width, height);
  if (body.size() != expected)
    return make_error(ErrorCode::invalid_argument,
                      std::string(codec_name(codec)) + " body of " + std::to_string(width) + "x" +
                          std::to_string(height) + " texels needs " + std::to_string(expected) +
                          " bytes, has " + std::to_string(body.size()));
  if (Status s = detail::check_zstd_level(zstd_level); !s) return s.error();
  const TrimScratchOnExit trim;
  std::vector<std::uint8_t>& packed = scratch(0);
  if (Status s = detail::compress_payload(body.data(), body.size(), zstd_level, header, packed); !s)
    return s.error();
  return std::vector<std::uint8_t>(packed.begin(), packed.end());  // capacity == size, as above
}

namespace {

Result<TileImage> LosslessCodec::decode(std::span<const std::uint8_t> payload) const {
  auto header = verify_impl(payload);
  if (!header) return std::move(header).error();
  if (header->codec != CodecId::lossless)
    return make_error(
        ErrorCode::invalid_argument,
        std::string("lossless codec asked to decode a ") + codec_name(header->codec) + " tile");
  return detail::decode_lossless_body(*header, payload.subspan(kFrameBytes));
}

const LosslessCodec kLossless;

}  // namespace

const char* codec_name(CodecId id) noexcept {
  switch (id) {
    case CodecId::lossless:
      return "lossless";
    case CodecId::bc1:
      return "bc1";
  }
  return "unknown";
}

Result<CodecId> parse_codec_name(std::string_view name) {
  if (name == "lossless") return CodecId::lossless;
  if (name == "bc1") return CodecId::bc1;
  return make_error(ErrorCode::unsupported,
                    "unknown codec \"" + std::string(name) + "\" (known: lossless, bc1)");
}

const char* filter_name(Filter f) noexcept {
  switch (f) {
    case Filter::none:
      return "none";
    case Filter::gradient:
      return "gradient";
  }
  return "unknown";
}

Result<TileHeader> parse_tile_header(std::span<const std::uint8_t> payload) {
  // Check what is present before complaining about what is missing, so that a short non-tile is
  // reported as corrupt rather than truncated.
  if (payload.size() >= 4 && load_u32(payload.data()) != TileHeader::kSkippableMagic)
    return make_error(ErrorCode::corrupt, "not a vtstream tile (bad header frame magic " +
                                              hex64(load_u32(payload.data())) + ")");
  if (payload.size() >= 8 && load_u32(payload.data() + 4) != TileHeader::kHeaderBytes)
    return make_error(ErrorCode::corrupt, "tile header frame size " +
                                              std::to_string(load_u32(payload.data() + 4)) +
                                              " != " + std::to_string(TileHeader::kHeaderBytes));
  if (payload.size() < kFrameBytes)
    return make_error(ErrorCode::truncated, "tile payload of " + std::to_string(payload.size()) +
                                                " bytes ends inside its " +
                                                std::to_string(kFrameBytes) + "-byte header");
  const std::uint8_t* p = payload.data();
  TileHeader h;
  h.version = p[8];
  h.codec = static_cast<CodecId>(p[9]);
  h.filter = static_cast<Filter>(p[10]);
  h.format = static_cast<PixelFormat>(p[11]);
  h.width = load_u32(p + 12);
  h.height = load_u32(p + 16);
  h.body_size = load_u32(p + 20);
  h.checksum = load_u64(p + 24);
  // The version decides how the rest is read, so it is checked before the reserved bytes.
  if (h.version != TileHeader::kVersion) return check_header(h).error();
  if (load_u64(p + 32) != 0)
    return make_error(ErrorCode::corrupt, "tile header reserved bytes are not zero");
  if (Status s = check_header(h); !s) return s.error();
  return h;
}

Result<TileHeader> verify_tile(std::span<const std::uint8_t> payload) {
  return verify_impl(payload);
}

Status check_tile_against(const TileHeader& header, const TileSpec& spec) {
  if (header.codec != spec.codec)
    return make_error(ErrorCode::corrupt, std::string("tile uses codec ") +
                                              codec_name(header.codec) + ", the tileset " +
                                              codec_name(spec.codec));
  const PixelFormat format = spec.codec == CodecId::bc1 ? PixelFormat::bc1 : PixelFormat::rgba8;
  if (header.format != format)
    return make_error(ErrorCode::corrupt, "tile declares pixel format " +
                                              std::to_string(static_cast<int>(header.format)) +
                                              ", the tileset's " + codec_name(spec.codec) +
                                              " tiles are " +
                                              std::to_string(static_cast<int>(format)));
  if (header.width != spec.width || header.height != spec.height)
    return make_error(ErrorCode::corrupt,
                      "tile declares " + std::to_string(header.width) + "x" +
                          std::to_string(header.height) + " texels, the tileset's tiles are " +
                          std::to_string(spec.width) + "x" + std::to_string(spec.height));
  return {};
}

Result<TileHeader> verify_tile(std::span<const std::uint8_t> payload, const TileSpec& spec) {
  // The header alone first: a tile of the wrong shape is refused without hashing its body.
  auto header = parse_tile_header(payload);
  if (!header) return header;
  if (Status s = check_tile_against(*header, spec); !s) return s.error();
  return verify_impl(payload);
}

const Codec* find_codec(CodecId id) noexcept {
  switch (id) {
    case CodecId::lossless:
      return &kLossless;
    case CodecId::bc1:
      return &detail::bc1_codec();
  }
  return nullptr;
}

Result<TileImage> decode_tile(std::span<const std::uint8_t> payload) {
  auto header = parse_tile_header(payload);
  if (!header) return std::move(header).error();
  const Codec* codec = find_codec(header->codec);
  if (codec == nullptr)
    return make_error(ErrorCode::unsupported, std::string("tile codec ") +
                                                  codec_name(header->codec) +
                                                  " is not implemented in this build");
  return codec->decode(payload);
}

Result<TileImage> decode_tile(std::span<const std::uint8_t> payload, const TileSpec& spec) {
  auto header = parse_tile_header(payload);
  if (!header) return std::move(header).error();
  if (Status s = check_tile_against(*header, spec); !s) return s.error();
  return decode_tile(payload);
}

namespace detail {

Status check_zstd_level(int level) {
  if (level < ZSTD_minCLevel() || level > ZSTD_maxCLevel())
    return make_error(ErrorCode::invalid_argument, "zstd level " + std::to_string(level) +
                                                       " outside " +
                                                       std::to_string(ZSTD_minCLevel()) + ".." +
                                                       std::to_string(ZSTD_maxCLevel()));
  return {};
}

}  // namespace detail

Status check_encode_input(const TileImage& image, CodecId codec) {
  if (image.format != PixelFormat::rgba8)
    return make_error(ErrorCode::invalid_argument,
                      std::string(codec_name(codec)) + " codec encodes rgba8 images only");
  if (image.width == 0 || image.height == 0 || image.width > TileHeader::kMaxDimension ||
      image.height > TileHeader::kMaxDimension)
    return make_error(ErrorCode::invalid_argument, "tile size " + std::to_string(image.width) +
                                                       "x" + std::to_string(image.height) +
                                                       " outside 1.." +
                                                       std::to_string(TileHeader::kMaxDimension));
  const std::size_t bytes = std::size_t(image.width) * image.height * 4;
  if (image.pixels.size() != bytes)
    return make_error(ErrorCode::invalid_argument,
                      "image has " + std::to_string(image.pixels.size()) + " bytes, " +
                          std::to_string(image.width) + "x" + std::to_string(image.height) +
                          " rgba8 needs " + std::to_string(bytes));
  return {};
}

namespace detail {

Result<TileHeader> verify_payload(std::span<const std::uint8_t> payload) {
  return verify_impl(payload);
}

Status decompress_body(const TileHeader& header, std::span<const std::uint8_t> body,
                       std::vector<std::uint8_t>& dst) {
  if (Status s = check_header(header); !s) return s.error();
  if (Status s = check_body_frame(header, body); !s) return s.error();
  // check_body_frame() has parsed this header already; it cannot fail here.
  ZSTD_frameHeader fh{};
  ZSTD_getFrameHeader(&fh, body.data(), body.size());
  if (frame_content_bound(body, fh) < header.body_size)
    return make_error(ErrorCode::corrupt, "tile body frame's blocks cannot hold the declared " +
                                              std::to_string(header.body_size) + " bytes");
  ZSTD_DCtx* dctx = thread_dctx();
  if (dctx == nullptr) return make_error(ErrorCode::internal, "ZSTD_createDCtx failed");
  dst.resize(header.body_size);  // only now: the frame can produce this many bytes
  const std::size_t n =
      ZSTD_decompressDCtx(dctx, dst.data(), header.body_size, body.data(), body.size());
  if (ZSTD_isError(n))
    return make_error(ErrorCode::corrupt,
                      std::string("tile body does not decompress: ") + ZSTD_getErrorName(n));
  if (n != header.body_size)
    return make_error(ErrorCode::corrupt, "tile body decompressed to " + std::to_string(n) +
                                              " bytes, header says " +
                                              std::to_string(header.body_size));
  return {};
}

Result<TileImage> decode_lossless_body(const TileHeader& header,
                                       std::span<const std::uint8_t> body) {
  if (Status s = check_header(header); !s) return s.error();
  if (header.codec != CodecId::lossless)
    return make_error(ErrorCode::invalid_argument, "not a lossless tile header");
  TileImage image;
  image.width = header.width;
  image.height = header.height;
  image.format = PixelFormat::rgba8;
  // Filter none decompresses straight into the image; gradient goes through a scratch buffer.
  const TrimScratchOnExit trim;
  if (header.filter != Filter::gradient) {
    if (Status s = decompress_body(header, body, image.pixels); !s) return s.error();
    return image;
  }
  std::vector<std::uint8_t>& planes = scratch(2);
  if (Status s = decompress_body(header, body, planes); !s) return s.error();
  image.pixels.resize(header.body_size);
  gradient_unfilter(planes.data(), header.width, header.height, image.pixels.data());
  return image;
}

}  // namespace detail
}  // namespace protocol
}  // namespace vts
