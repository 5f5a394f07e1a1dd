// Fuzz target: a PMTiles archive from untrusted bytes. Opens the input with Reader::open_bytes and
// does what a server or `vts info` would: looks up a handful of tile ids (fixed ones and ones the
// directories name), walks every entry, counts leaf directories, reads the metadata and writes
// the TileJSON the server would answer with. Also feeds the raw bytes to
// the header and directory parsers directly. Any crash, sanitizer report or hang is a bug, and so
// is a tile that is not the bytes its entry points at; errors are the expected outcome for most
// inputs.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "vts/archive/pmtiles.hpp"
#include "vts/protocol/tilejson.hpp"
#include "vts/protocol/tileset.hpp"

namespace {

using vts::archive::Entry;
using vts::archive::Reader;

// A returned tile must be a copy of the bytes its directory entry points at, inside the input.
void check_tile(const Reader& reader, std::span<const std::uint8_t> all, std::uint64_t id,
                const std::vector<std::uint8_t>& tile) {
  auto e = reader.find_entry(id);
  if (!e) __builtin_trap();
  const std::uint64_t at = reader.header().tile_data_offset + e->offset;
  if (e->length != tile.size() || at > all.size() || tile.size() > all.size() - at ||
      !std::equal(tile.begin(), tile.end(), all.begin() + std::ptrdiff_t(at))) {
    __builtin_trap();
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::span<const std::uint8_t> bytes(data, size);

  (void)vts::archive::parse_header(bytes);
  (void)vts::archive::parse_directory(bytes, 1u << 16);

  // Small limits keep each input fast; the limits themselves are exercised by the unit tests.
  vts::archive::ReaderOptions options;
  options.max_directory_bytes = 1u << 20;
  options.max_metadata_bytes = 1u << 20;
  options.leaf_cache_entries = 2;  // small, so eviction runs too
  auto opened = Reader::open_bytes(bytes, options);
  if (!opened) return 0;
  const Reader& reader = **opened;

  for (std::uint64_t id = 0; id < 8; ++id) {
    if (auto t = reader.get_by_tile_id(id)) check_tile(reader, bytes, id, *t);
  }
  for (const vts::TileId t :
       {vts::TileId{0, 0, 0}, vts::TileId{1, 1, 0}, vts::TileId{3, 7, 7},
        vts::TileId{31, 0x7fffffff, 0}, vts::TileId{2, 4, 0}, vts::TileId{40, 0, 0}}) {
    if (auto tile = reader.get(t)) {
      check_tile(reader, bytes, vts::archive::zxy_to_tile_id(t.z, t.x, t.y), *tile);
    }
  }

  // Ids the archive itself mentions: the first and last tile of the first few runs, and the ids
  // just outside them.
  std::vector<Entry> seen;
  (void)reader.for_each_entry([&](const Entry& e) {
    seen.push_back(e);
    return seen.size() < 16;
  });
  for (const Entry& e : seen) {
    for (std::uint64_t id :
         {e.tile_id - 1, e.tile_id, e.tile_id + e.run_length - 1, e.tile_id + e.run_length}) {
      if (auto t = reader.get_by_tile_id(id)) check_tile(reader, bytes, id, *t);
    }
  }

  // A full walk, bounded so that a huge but valid archive cannot stall the fuzzer.
  std::uint64_t visits = 0;
  (void)reader.for_each_entry([&](const Entry&) { return ++visits < 100000; });
  (void)reader.leaf_directory_count();

  // What `vts serve` and `vts info` do next: read the metadata; the server then answers
  // GET /{ts}.json with the TileJSON made from it.
  if (auto info = vts::TilesetInfo::from_json(reader.metadata_json())) {
    (void)vts::write_tilejson({.tileset = "t", .info = &*info, .tiles_url = "/t/{z}/{x}/{y}"});
  }
  return 0;
}
