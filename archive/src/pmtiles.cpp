// PMTiles v3 format primitives: Hilbert tile ids, the 127-byte header, varint directories and the
// internal compressions. The Writer lives in pmtiles_writer.cpp, the Reader in pmtiles_reader.cpp;
// both are built only on the public functions defined here.
//
// Every parser here treats its input as hostile: sizes are checked before allocating, arithmetic
// on untrusted values is overflow-checked, and failures come back as Errors naming what was wrong.
#include <zlib.h>
#include <zstd.h>
#include <zstd_errors.h>

#include <algorithm>
#include <cassert>
#include <cstring>
#include <limits>
#include <memory>
#include <string>

#include "pmtiles_io.hpp"
#include "vts/archive/pmtiles.hpp"

namespace vts::archive {
namespace {

using detail::get_u32;
using detail::get_u64;
using detail::put_u32;
using detail::put_u64;

constexpr int kMaxZ = 31;  // ids of z = 32 would no longer fit the uint32 x / y of TileId

// Number of tiles on all levels coarser than z: sum_{i<z} 4^i = (4^z - 1) / 3. Exact for z <= 31.
constexpr std::uint64_t tiles_before_level(int z) {
  return ((std::uint64_t{1} << (2 * z)) - 1) / 3;
}

// ---- varints (unsigned LEB128, at most 10 bytes for 64 bits) ------------------------------------

void put_varint(std::vector<std::uint8_t>& out, std::uint64_t v) {
  while (v >= 0x80) {
    out.push_back(static_cast<std::uint8_t>(v | 0x80));
    v >>= 7;
  }
  out.push_back(static_cast<std::uint8_t>(v));
}

enum class VarintStatus : std::uint8_t { ok, truncated, overflow, too_long };

// Reads one varint at bytes[pos], advancing pos. This is the inner loop of directory parsing (a
// leaf of 4096 entries is 16384 varints), so it reports failures as a small enum and leaves the
// message to varint_error(). Fails on a varint cut by the end of the input, on one whose 10th
// byte carries bits beyond 64, and on one longer than 10 bytes.
inline VarintStatus read_varint(std::span<const std::uint8_t> bytes, std::size_t& pos,
                                std::uint64_t& value) {
  const std::uint8_t* p = bytes.data();
  const std::size_t size = bytes.size();
  if (pos < size && p[pos] < 0x80) {  // one-byte varints dominate directories
    value = p[pos++];
    return VarintStatus::ok;
  }
  std::uint64_t v = 0;
  for (int i = 0; i < 10; ++i) {
    if (pos >= size) return VarintStatus::truncated;
    const std::uint8_t b = p[pos++];
    if (i == 9 && b > 1) return VarintStatus::overflow;
    v |= std::uint64_t{b & 0x7fu} << (7 * i);
    if ((b & 0x80) == 0) {
      value = v;
      return VarintStatus::ok;
    }
  }
  return VarintStatus::too_long;
}

Error varint_error(VarintStatus status, std::size_t pos, const char* what) {
  const std::string field = std::string("varint (") + what + ")";
  switch (status) {
    case VarintStatus::truncated:
      return make_error(ErrorCode::truncated,
                        "directory ends inside a " + field + " at byte " + std::to_string(pos));
    case VarintStatus::overflow:
      return make_error(ErrorCode::corrupt,
                        field + " ending at byte " + std::to_string(pos) + " overflows 64 bits");
    case VarintStatus::too_long:
    case VarintStatus::ok:
      break;
  }
  return make_error(ErrorCode::corrupt,
                    field + " ending at byte " + std::to_string(pos) + " is longer than 10 bytes");
}

// ---- compression --------------------------------------------------------------------------------

namespace {

Error unsupported_compression(Compression c) {
  return make_error(ErrorCode::unsupported, "internal compression " +
                                                std::to_string(static_cast<int>(c)) +
                                                " is not supported (none, gzip or zstd)");
}

}  // namespace

// zlib counts each call's input and output in uInt (32 bits); larger buffers are fed in pieces.
constexpr std::size_t kZlibChunk = std::numeric_limits<uInt>::max();

Result<std::vector<std::uint8_t>> gzip_compress(std::span<const std::uint8_t> in) {
  z_stream zs{};
  // windowBits 15 + 16: write a gzip (RFC 1952) stream, which is what "gzip" means in PMTiles.
  if (deflateInit2(&zs, Z_BEST_COMPRESSION, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY) != Z_OK) {
    return make_error(ErrorCode::internal, "deflateInit2 failed");
  }
  std::unique_ptr<z_stream, int (*)(z_stream*)> guard(&zs, &deflateEnd);
  std::vector<std::uint8_t> out(std::max<std::size_t>(in.size() / 2, 64));
  std::size_t consumed = 0;
  for (;;) {
    if (zs.total_out == out.size()) out.resize(out.size() * 2);
    const std::size_t in_chunk = std::min(kZlibChunk, in.size() - consumed);
    zs.next_in = const_cast<Bytef*>(in.data() + consumed);  // zlib is not const-correct; it reads
    zs.avail_in = static_cast<uInt>(in_chunk);
    zs.next_out = out.data() + zs.total_out;
    zs.avail_out = static_cast<uInt>(std::min(kZlibChunk, out.size() - zs.total_out));
    const bool last = consumed + in_chunk == in.size();
    const int rc = deflate(&zs, last ? Z_FINISH : Z_NO_FLUSH);
    consumed += in_chunk - zs.avail_in;
    if (rc == Z_STREAM_END) break;
    if (rc != Z_OK && rc != Z_BUF_ERROR) return make_error(ErrorCode::internal, "deflate failed");
  }
  out.resize(zs.total_out);
  return out;
}

// Output buffers grow geometrically from a guess up to a cap of max_output + 1 bytes: producing
// that last byte is how we know the stream wants more than the caller allows.
std::size_t output_cap(std::size_t max_output) {
  return max_output == std::numeric_limits<std::size_t>::max() ? max_output : max_output + 1;
}
std::size_t initial_capacity(std::size_t input, std::size_t max_output) {
  const std::size_t guess = input > (std::numeric_limits<std::size_t>::max() / 4)
                                ? std::numeric_limits<std::size_t>::max()
                                : std::max<std::size_t>(input * 4, 4096);
  return std::min(guess, output_cap(max_output));
}
std::size_t grow_capacity(std::size_t current, std::size_t max_output) {
  const std::size_t doubled =
      current > std::numeric_limits<std::size_t>::max() / 2 ? current : current * 2;
  return std::min(doubled, output_cap(max_output));
}

Error too_large_error(std::size_t max_output) {
  return make_error(ErrorCode::too_large, "decompressed size exceeds the limit of " +
                                              std::to_string(max_output) + " bytes");
}

Result<std::vector<std::uint8_t>> gzip_decompress(std::span<const std::uint8_t> in,
                                                  std::size_t max_output) {
  z_stream zs{};
  // windowBits 15 + 32: accept gzip and, leniently, zlib headers.
  if (inflateInit2(&zs, 15 + 32) != Z_OK) {
    return make_error(ErrorCode::internal, "inflateInit2 failed");
  }
  std::unique_ptr<z_stream, int (*)(z_stream*)> guard(&zs, &inflateEnd);
  std::vector<std::uint8_t> out(initial_capacity(in.size(), max_output));
  std::size_t consumed = 0;
  for (;;) {
    if (zs.total_out == out.size()) {
      if (out.size() > max_output) return too_large_error(max_output);
      out.resize(grow_capacity(out.size(), max_output));
    }
    const std::size_t in_chunk = std::min(kZlibChunk, in.size() - consumed);
    zs.next_in = const_cast<Bytef*>(in.data() + consumed);
    zs.avail_in = static_cast<uInt>(in_chunk);
    zs.next_out = out.data() + zs.total_out;
    zs.avail_out = static_cast<uInt>(std::min(kZlibChunk, out.size() - zs.total_out));
    const int rc = inflate(&zs, Z_NO_FLUSH);
    consumed += in_chunk - zs.avail_in;
    if (zs.total_out > max_output) return too_large_error(max_output);
    if (rc == Z_STREAM_END) break;
    if (rc != Z_OK && rc != Z_BUF_ERROR) {
      return make_error(ErrorCode::corrupt, std::string("invalid gzip stream: ") +
                                                (zs.msg != nullptr ? zs.msg : "inflate error"));
    }
    // inflate returns without an error only when the output is full or the input is used up;
    // with room left and no input, the stream was cut before its end marker.
    if (zs.avail_out != 0 && consumed == in.size()) {
      return make_error(
          ErrorCode::truncated,
          "gzip stream ends after " + std::to_string(in.size()) + " bytes, before its end marker");
    }
  }
  if (consumed != in.size()) {
    return make_error(ErrorCode::corrupt, std::to_string(in.size() - consumed) +
                                              " trailing bytes after the gzip stream");
  }
  out.resize(zs.total_out);
  return out;
}

Result<std::vector<std::uint8_t>> zstd_compress(std::span<const std::uint8_t> in) {
  std::vector<std::uint8_t> out(ZSTD_compressBound(in.size()));
  // Level 19: directories and metadata are small and written once; every byte saved in the root
  // directory is room for more entries inside the first 16 KiB.
  const std::size_t n = ZSTD_compress(out.data(), out.size(), in.data(), in.size(), 19);
  if (ZSTD_isError(n)) {
    return make_error(ErrorCode::internal, std::string("zstd: ") + ZSTD_getErrorName(n));
  }
  out.resize(n);
  return out;
}

Result<std::vector<std::uint8_t>> zstd_decompress(std::span<const std::uint8_t> in,
                                                  std::size_t max_output) {
  if (in.empty()) return make_error(ErrorCode::truncated, "empty zstd stream");
  std::unique_ptr<ZSTD_DStream, decltype(&ZSTD_freeDStream)> ds(ZSTD_createDStream(),
                                                                &ZSTD_freeDStream);
  if (!ds) return make_error(ErrorCode::internal, "ZSTD_createDStream failed");
  // Refuse frames whose window would make zstd itself allocate more than 128 MiB.
  ZSTD_DCtx_setParameter(ds.get(), ZSTD_d_windowLogMax, 27);
  std::vector<std::uint8_t> out(initial_capacity(in.size(), max_output));
  ZSTD_inBuffer ib{in.data(), in.size(), 0};
  std::size_t produced = 0;
  for (;;) {
    if (produced == out.size()) {
      if (out.size() > max_output) return too_large_error(max_output);
      out.resize(grow_capacity(out.size(), max_output));
    }
    ZSTD_outBuffer ob{out.data(), out.size(), produced};
    const std::size_t rc = ZSTD_decompressStream(ds.get(), &ob, &ib);
    if (ZSTD_isError(rc)) {
      if (ZSTD_getErrorCode(rc) == ZSTD_error_frameParameter_windowTooLarge) {
        return make_error(ErrorCode::too_large, "zstd frame window exceeds the limit");
      }
      return make_error(ErrorCode::corrupt,
                        std::string("invalid zstd stream: ") + ZSTD_getErrorName(rc));
    }
    produced = ob.pos;
    if (produced > max_output) return too_large_error(max_output);
    // rc == 0: a frame is complete and flushed; further input would be another frame.
    if (rc == 0 && ib.pos == ib.size) break;
    // With room left in the output and the input used up, zstd has flushed all it can and
    // still needs more: the frame was cut.
    if (rc != 0 && ib.pos == ib.size && ob.pos < ob.size) {
      return make_error(ErrorCode::truncated, "zstd stream ends after " +
                                                  std::to_string(in.size()) +
                                                  " bytes, before its frame is complete");
    }
  }
  out.resize(produced);
  return out;
}

}  // namespace

// ---- tile ids -----------------------------------------------------------------------------------

std::uint64_t zxy_to_tile_id(std::uint8_t z, std::uint32_t x, std::uint32_t y) {
  assert(z <= kMaxZ);
  assert(std::uint64_t{x} < (std::uint64_t{1} << z) && std::uint64_t{y} < (std::uint64_t{1} << z));
  if (z > kMaxZ) return std::numeric_limits<std::uint64_t>::max();  // release builds: no UB shift
  // Hilbert curve index of (x, y) on a 2^z grid: at each scale s, pick the quadrant, add the
  // number of cells in the quadrants before it, and rotate/flip the remaining low bits so the
  // sub-square is walked in the canonical orientation.
  std::uint64_t tx = x, ty = y, d = 0;
  for (std::uint64_t s = (std::uint64_t{1} << z) >> 1; s > 0; s >>= 1) {
    const std::uint64_t rx = (tx & s) != 0 ? 1 : 0;
    const std::uint64_t ry = (ty & s) != 0 ? 1 : 0;
    d += s * s * ((3 * rx) ^ ry);
    tx &= s - 1;
    ty &= s - 1;
    if (ry == 0) {
      if (rx == 1) {
        tx = s - 1 - tx;
        ty = s - 1 - ty;
      }
      std::swap(tx, ty);
    }
  }
  return tiles_before_level(z) + d;
}

TileIdRange subtree_tile_ids(TileId root, std::uint8_t z) {
  assert(root.z <= z && z <= kMaxZ);
  const std::uint64_t h = zxy_to_tile_id(root.z, root.x, root.y) - tiles_before_level(root.z);
  const unsigned shift = 2u * static_cast<unsigned>(z - root.z);
  const std::uint64_t first = tiles_before_level(z) + (h << shift);
  return {first, first + (std::uint64_t{1} << shift) - 1};
}

Result<TileId> tile_id_to_zxy(std::uint64_t tile_id) {
  int z = 0;
  while (z < kMaxZ && tile_id >= tiles_before_level(z + 1)) ++z;
  // Ids at z = 31 run up to tiles_before_level(31) + 4^31 - 1; anything above needs z >= 32.
  const std::uint64_t level_size = std::uint64_t{1} << (2 * z);
  const std::uint64_t pos = tile_id - tiles_before_level(z);
  if (pos >= level_size) {
    return make_error(ErrorCode::invalid_argument,
                      "tile id " + std::to_string(tile_id) + " lies beyond zoom 31");
  }
  // Inverse of zxy_to_tile_id: consume two bits per scale, from the finest scale up.
  std::uint64_t tx = 0, ty = 0, t = pos;
  for (std::uint64_t s = 1; s < (std::uint64_t{1} << z); s <<= 1) {
    const std::uint64_t rx = 1 & (t >> 1);
    const std::uint64_t ry = 1 & (t ^ rx);
    if (ry == 0) {
      if (rx == 1) {
        tx = s - 1 - tx;
        ty = s - 1 - ty;
      }
      std::swap(tx, ty);
    }
    tx += s * rx;
    ty += s * ry;
    t >>= 2;
  }
  return TileId{static_cast<std::uint8_t>(z), static_cast<std::uint32_t>(tx),
                static_cast<std::uint32_t>(ty)};
}

// ---- header -------------------------------------------------------------------------------------

std::array<std::uint8_t, kHeaderSize> serialize_header(const Header& h) {
  std::array<std::uint8_t, kHeaderSize> b{};
  std::memcpy(b.data(), "PMTiles", 7);
  b[7] = 3;
  put_u64(&b[8], h.root_dir_offset);
  put_u64(&b[16], h.root_dir_length);
  put_u64(&b[24], h.metadata_offset);
  put_u64(&b[32], h.metadata_length);
  put_u64(&b[40], h.leaf_dirs_offset);
  put_u64(&b[48], h.leaf_dirs_length);
  put_u64(&b[56], h.tile_data_offset);
  put_u64(&b[64], h.tile_data_length);
  put_u64(&b[72], h.addressed_tiles);
  put_u64(&b[80], h.tile_entries);
  put_u64(&b[88], h.tile_contents);
  b[96] = h.clustered ? 1 : 0;
  b[97] = static_cast<std::uint8_t>(h.internal_compression);
  b[98] = static_cast<std::uint8_t>(h.tile_compression);
  b[99] = static_cast<std::uint8_t>(h.tile_type);
  b[100] = h.min_zoom;
  b[101] = h.max_zoom;
  put_u32(&b[102], static_cast<std::uint32_t>(h.min_lon_e7));
  put_u32(&b[106], static_cast<std::uint32_t>(h.min_lat_e7));
  put_u32(&b[110], static_cast<std::uint32_t>(h.max_lon_e7));
  put_u32(&b[114], static_cast<std::uint32_t>(h.max_lat_e7));
  b[118] = h.center_zoom;
  put_u32(&b[119], static_cast<std::uint32_t>(h.center_lon_e7));
  put_u32(&b[123], static_cast<std::uint32_t>(h.center_lat_e7));
  return b;
}

Result<Header> parse_header(std::span<const std::uint8_t> bytes) {
  if (bytes.size() < kHeaderSize) {
    return make_error(ErrorCode::truncated, "archive is " + std::to_string(bytes.size()) +
                                                " bytes, shorter than the 127-byte header");
  }
  const std::uint8_t* b = bytes.data();
  if (std::memcmp(b, "PMTiles", 7) != 0) {
    return make_error(ErrorCode::corrupt, "not a PMTiles archive (bad magic)");
  }
  if (b[7] != 3) {
    return make_error(ErrorCode::unsupported,
                      "PMTiles spec version " + std::to_string(b[7]) + " (only 3 is supported)");
  }
  Header h;
  h.root_dir_offset = get_u64(&b[8]);
  h.root_dir_length = get_u64(&b[16]);
  h.metadata_offset = get_u64(&b[24]);
  h.metadata_length = get_u64(&b[32]);
  h.leaf_dirs_offset = get_u64(&b[40]);
  h.leaf_dirs_length = get_u64(&b[48]);
  h.tile_data_offset = get_u64(&b[56]);
  h.tile_data_length = get_u64(&b[64]);
  h.addressed_tiles = get_u64(&b[72]);
  h.tile_entries = get_u64(&b[80]);
  h.tile_contents = get_u64(&b[88]);
  h.clustered = b[96] == 1;
  // Enum bytes are kept as stored, even when unknown: the Reader decides what it can decompress,
  // and tools that only list headers should still see what a newer writer declared.
  h.internal_compression = static_cast<Compression>(b[97]);
  h.tile_compression = static_cast<Compression>(b[98]);
  h.tile_type = static_cast<TileType>(b[99]);
  h.min_zoom = b[100];
  h.max_zoom = b[101];
  h.min_lon_e7 = static_cast<std::int32_t>(get_u32(&b[102]));
  h.min_lat_e7 = static_cast<std::int32_t>(get_u32(&b[106]));
  h.max_lon_e7 = static_cast<std::int32_t>(get_u32(&b[110]));
  h.max_lat_e7 = static_cast<std::int32_t>(get_u32(&b[114]));
  h.center_zoom = b[118];
  h.center_lon_e7 = static_cast<std::int32_t>(get_u32(&b[119]));
  h.center_lat_e7 = static_cast<std::int32_t>(get_u32(&b[123]));
  return h;
}

// ---- directories --------------------------------------------------------------------------------

std::vector<std::uint8_t> serialize_directory(std::span<const Entry> entries) {
  std::vector<std::uint8_t> out;
  out.reserve(1 + entries.size() * 6);
  put_varint(out, entries.size());
  std::uint64_t last_id = 0;
  for (const Entry& e : entries) {
    assert(e.tile_id >= last_id);
    put_varint(out, e.tile_id - last_id);
    last_id = e.tile_id;
  }
  for (const Entry& e : entries) put_varint(out, e.run_length);
  for (const Entry& e : entries) put_varint(out, e.length);
  for (std::size_t i = 0; i < entries.size(); ++i) {
    const Entry& e = entries[i];
    if (i > 0 && e.offset == entries[i - 1].offset + entries[i - 1].length) {
      put_varint(out, 0);  // contiguous with the previous entry
    } else {
      assert(e.offset != std::numeric_limits<std::uint64_t>::max());
      put_varint(out, e.offset + 1);
    }
  }
  return out;
}

Result<std::vector<Entry>> parse_directory(std::span<const std::uint8_t> bytes,
                                           std::size_t max_entries) {
  std::size_t pos = 0;
  std::uint64_t n = 0;
  if (VarintStatus vs = read_varint(bytes, pos, n); vs != VarintStatus::ok) {
    return varint_error(vs, pos, "entry count");
  }
  if (n > max_entries) {
    return make_error(ErrorCode::too_large, "directory declares " + std::to_string(n) +
                                                " entries, more than the limit of " +
                                                std::to_string(max_entries) +
                                                " entries per directory");
  }
  // Every entry takes at least four one-byte varints; check before allocating n entries.
  const std::size_t remaining = bytes.size() - pos;
  if (n > remaining / 4) {
    return make_error(ErrorCode::truncated, "directory declares " + std::to_string(n) +
                                                " entries but only " + std::to_string(remaining) +
                                                " bytes follow");
  }
  std::vector<Entry> entries(static_cast<std::size_t>(n));
  constexpr std::uint64_t kMaxU32 = std::numeric_limits<std::uint32_t>::max();

  std::uint64_t id = 0;
  for (std::size_t i = 0; i < entries.size(); ++i) {
    std::uint64_t delta = 0;
    if (VarintStatus vs = read_varint(bytes, pos, delta); vs != VarintStatus::ok) {
      return varint_error(vs, pos, "tile id");
    }
    if (i > 0 && delta == 0) {
      return make_error(ErrorCode::corrupt, "directory entry " + std::to_string(i) +
                                                " repeats the tile id of the entry before it");
    }
    if (delta > std::numeric_limits<std::uint64_t>::max() - id) {
      return make_error(ErrorCode::corrupt,
                        "directory entry " + std::to_string(i) + " tile id overflows 64 bits");
    }
    id += delta;
    entries[i].tile_id = id;
  }
  for (std::size_t i = 0; i < entries.size(); ++i) {
    std::uint64_t v = 0;
    if (VarintStatus vs = read_varint(bytes, pos, v); vs != VarintStatus::ok) {
      return varint_error(vs, pos, "run length");
    }
    if (v > kMaxU32) {
      return make_error(ErrorCode::corrupt, "directory entry " + std::to_string(i) +
                                                " run length " + std::to_string(v) +
                                                " exceeds 32 bits");
    }
    entries[i].run_length = static_cast<std::uint32_t>(v);
  }
  for (std::size_t i = 0; i < entries.size(); ++i) {
    std::uint64_t v = 0;
    if (VarintStatus vs = read_varint(bytes, pos, v); vs != VarintStatus::ok) {
      return varint_error(vs, pos, "length");
    }
    if (v > kMaxU32) {
      return make_error(ErrorCode::corrupt, "directory entry " + std::to_string(i) + " length " +
                                                std::to_string(v) + " exceeds 32 bits");
    }
    if (v == 0) {
      return make_error(ErrorCode::corrupt,
                        "directory entry " + std::to_string(i) + " has length 0");
    }
    entries[i].length = static_cast<std::uint32_t>(v);
  }
  for (std::size_t i = 0; i < entries.size(); ++i) {
    std::uint64_t v = 0;
    if (VarintStatus vs = read_varint(bytes, pos, v); vs != VarintStatus::ok) {
      return varint_error(vs, pos, "offset");
    }
    if (v == 0 && i > 0) {
      const Entry& prev = entries[i - 1];
      if (prev.offset > std::numeric_limits<std::uint64_t>::max() - prev.length) {
        return make_error(ErrorCode::corrupt,
                          "directory entry " + std::to_string(i) + " offset overflows 64 bits");
      }
      entries[i].offset = prev.offset + prev.length;
    } else {
      // A 0 on the first entry has no previous entry to follow; read it as offset 0.
      entries[i].offset = v == 0 ? 0 : v - 1;
    }
  }
  if (pos != bytes.size()) {
    return make_error(ErrorCode::corrupt, "directory has " + std::to_string(bytes.size() - pos) +
                                              " trailing bytes after its " + std::to_string(n) +
                                              " entries");
  }
  // Runs must not overlap the next entry: lookups would otherwise depend on which one the binary
  // search happens to land on.
  for (std::size_t i = 0; i + 1 < entries.size(); ++i) {
    const Entry& e = entries[i];
    if (e.run_length > entries[i + 1].tile_id - e.tile_id) {
      return make_error(ErrorCode::corrupt, "directory entry " + std::to_string(i) + " (tile id " +
                                                std::to_string(e.tile_id) + ", run length " +
                                                std::to_string(e.run_length) +
                                                ") overlaps the next entry");
    }
  }
  return entries;
}

Result<Directory> decode_directory(std::span<const std::uint8_t> stored, Compression c,
                                   std::size_t max_decoded_bytes) {
  Result<std::vector<std::uint8_t>> raw = decompress(stored, c, max_decoded_bytes);
  if (!raw) return std::move(raw).error();
  Result<std::vector<Entry>> entries = parse_directory(*raw);
  if (!entries) return std::move(entries).error();
  return std::make_shared<const std::vector<Entry>>(std::move(*entries));
}

// ---- compression --------------------------------------------------------------------------------

Result<std::vector<std::uint8_t>> compress(std::span<const std::uint8_t> bytes, Compression c) {
  switch (c) {
    case Compression::none:
      return std::vector<std::uint8_t>(bytes.begin(), bytes.end());
    case Compression::gzip:
      return gzip_compress(bytes);
    case Compression::zstd:
      return zstd_compress(bytes);
    case Compression::unknown:
    case Compression::brotli:
      break;
  }
  return unsupported_compression(c);
}

Result<std::vector<std::uint8_t>> decompress(std::span<const std::uint8_t> bytes, Compression c,
                                             std::size_t max_output) {
  switch (c) {
    case Compression::none:
      if (bytes.size() > max_output) return too_large_error(max_output);
      return std::vector<std::uint8_t>(bytes.begin(), bytes.end());
    case Compression::gzip:
      return gzip_decompress(bytes, max_output);
    case Compression::zstd:
      return zstd_decompress(bytes, max_output);
    case Compression::unknown:
    case Compression::brotli:
      break;
  }
  return unsupported_compression(c);
}

}  // namespace vts::archive
