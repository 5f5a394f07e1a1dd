// pmtiles_dump: prints what our own PMTiles reader (vts::archive::Reader) sees in an archive, in a
// line format that tests/integration/pmtiles_js/dump.mjs reproduces with the npm `pmtiles`
// library. The integration tests compare the two outputs byte for byte.
//
//   pmtiles_dump tiles   ARCHIVE   one line per addressed tile id, in tile-id order (run lengths
//                                  expanded): "tile_id z x y length fnv1a64-hex"
//   pmtiles_dump header  ARCHIVE   "key=value" lines of header fields both readers expose, then
//                                  "metadata_keys=" the sorted top-level keys of the JSON metadata
//   pmtiles_dump offsets ARCHIVE   "tile_id z x y absolute_offset length" per addressed tile id
//                                  (lets the shell tests corrupt one chosen tile in place)
//
// Exit status: 0 on success, 1 on a reader error (message on stderr), 2 on bad usage.
#include <cinttypes>
#include <cstdint>
#include <cstdio>
#include <set>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "vts/archive/pmtiles.hpp"

namespace {

// FNV-1a, 64 bit: trivial to reimplement exactly in JavaScript (see dump.mjs).
std::uint64_t fnv1a64(std::span<const std::uint8_t> bytes) {
  std::uint64_t h = 0xcbf29ce484222325ULL;
  for (std::uint8_t b : bytes) {
    h ^= b;
    h *= 0x100000001b3ULL;
  }
  return h;
}

int fail(const vts::Error& e, const char* what) {
  std::fprintf(stderr, "pmtiles_dump: %s: %s\n", what, e.to_string().c_str());
  return 1;
}

int usage() {
  std::fprintf(stderr, "usage: pmtiles_dump (tiles|header|offsets) ARCHIVE\n");
  return 2;
}

int dump_header(const vts::archive::Reader& reader) {
  const auto& h = reader.header();
  std::printf("spec_version=3\n");
  std::printf("min_zoom=%u\n", unsigned(h.min_zoom));
  std::printf("max_zoom=%u\n", unsigned(h.max_zoom));
  std::printf("tile_compression=%u\n", unsigned(h.tile_compression));
  std::printf("internal_compression=%u\n", unsigned(h.internal_compression));
  std::printf("tile_type=%u\n", unsigned(h.tile_type));
  std::printf("clustered=%s\n", h.clustered ? "true" : "false");
  std::printf("addressed_tiles=%" PRIu64 "\n", h.addressed_tiles);
  std::printf("tile_entries=%" PRIu64 "\n", h.tile_entries);
  std::printf("tile_contents=%" PRIu64 "\n", h.tile_contents);
  std::printf("root_dir_offset=%" PRIu64 "\n", h.root_dir_offset);
  std::printf("root_dir_length=%" PRIu64 "\n", h.root_dir_length);
  std::printf("metadata_offset=%" PRIu64 "\n", h.metadata_offset);
  std::printf("metadata_length=%" PRIu64 "\n", h.metadata_length);
  std::printf("leaf_dirs_offset=%" PRIu64 "\n", h.leaf_dirs_offset);
  std::printf("leaf_dirs_length=%" PRIu64 "\n", h.leaf_dirs_length);
  std::printf("tile_data_offset=%" PRIu64 "\n", h.tile_data_offset);
  std::printf("tile_data_length=%" PRIu64 "\n", h.tile_data_length);
  std::printf("min_lon_e7=%" PRId32 "\n", h.min_lon_e7);
  std::printf("min_lat_e7=%" PRId32 "\n", h.min_lat_e7);
  std::printf("max_lon_e7=%" PRId32 "\n", h.max_lon_e7);
  std::printf("max_lat_e7=%" PRId32 "\n", h.max_lat_e7);
  std::printf("center_zoom=%u\n", unsigned(h.center_zoom));
  std::printf("center_lon_e7=%" PRId32 "\n", h.center_lon_e7);
  std::printf("center_lat_e7=%" PRId32 "\n", h.center_lat_e7);

  std::string keys;
  auto meta = nlohmann::json::parse(reader.metadata_json(), nullptr, /*allow_exceptions=*/false);
  if (meta.is_discarded() || !meta.is_object()) {
    keys = "<not a JSON object>";
  } else {
    std::set<std::string> sorted;
    for (const auto& item : meta.items()) sorted.insert(item.key());
    for (const auto& k : sorted) keys += (keys.empty() ? "" : ",") + k;
  }
  std::printf("metadata_keys=%s\n", keys.c_str());
  return 0;
}

int dump_tiles(const vts::archive::Reader& reader, bool offsets) {
  std::vector<vts::archive::Entry> entries;
  if (auto st = reader.for_each_entry([&](const vts::archive::Entry& e) {
        entries.push_back(e);
        return true;
      });
      !st) {
    return fail(st.error(), "walking directories");
  }
  for (const auto& e : entries) {
    for (std::uint64_t i = 0; i < e.run_length; ++i) {
      const std::uint64_t id = e.tile_id + i;
      auto zxy = vts::archive::tile_id_to_zxy(id);
      if (!zxy) return fail(zxy.error(), "tile id");
      auto payload = reader.get_by_tile_id(id);
      if (!payload) return fail(payload.error(), ("tile " + zxy->to_string()).c_str());
      const auto& t = *zxy;
      if (offsets) {
        const auto abs = reader.header().tile_data_offset + e.offset;
        std::printf("%" PRIu64 " %u %u %u %" PRIu64 " %zu\n", id, unsigned(t.z), t.x, t.y, abs,
                    payload->size());
      } else {
        std::printf("%" PRIu64 " %u %u %u %zu %016" PRIx64 "\n", id, unsigned(t.z), t.x, t.y,
                    payload->size(), fnv1a64(*payload));
      }
    }
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 3) return usage();
  const std::string_view mode = argv[1];
  if (mode != "tiles" && mode != "header" && mode != "offsets") return usage();

  auto reader = vts::archive::Reader::open(argv[2]);
  if (!reader) return fail(reader.error(), argv[2]);

  const int rc = mode == "header" ? dump_header(**reader) : dump_tiles(**reader, mode == "offsets");
  if (std::fflush(stdout) != 0) {
    std::perror("pmtiles_dump: stdout");
    return 1;
  }
  return rc;
}
