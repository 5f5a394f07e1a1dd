// Fuzz target: the JSON documents the protocol library reads from places it does not control. The
// input is read as a TileJSON document (read_tilejson: what `vts warm`, `loadtest`, `view` and the
// cache daemon do with a server's answer) and as archive metadata (TilesetInfo::from_json: what
// `vts serve` and `vts info` do when they open an archive). Metadata that reads is written as the
// server's TileJSON, which must read back to the same tileset. Any crash, sanitizer report or hang
// is a bug; errors are the expected outcome for most inputs.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <span>
#include <string>

#include "vts/protocol/tilejson.hpp"
#include "vts/protocol/tileset.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string url = "http://fuzz.example/t/t.json";
  (void)vts::read_tilejson(std::span<const std::uint8_t>(data, size), url);

  auto info = vts::TilesetInfo::from_json(std::string(reinterpret_cast<const char*>(data), size));
  if (!info) return 0;
  const std::string doc = vts::write_tilejson({.tileset = "t",
                                               .info = &*info,
                                               .version = "0123456789abcdef",
                                               .tiles_url = "/t@0123456789abcdef/{z}/{x}/{y}",
                                               .archive_url = "/t.pmtiles"});
  auto back = vts::read_tilejson(
      std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(doc.data()), doc.size()),
      url);
  if (!back) std::abort();
  vts::TilesetInfo expected = *info;
  // TileJSON's name falls back to the tileset's.
  if (expected.name.empty()) expected.name.push_back('t');
  if (back->info.to_json() != expected.to_json() || back->version != "0123456789abcdef")
    std::abort();
  return 0;
}
