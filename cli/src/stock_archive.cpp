// vts info / verify of a stock raster PMTiles (stock_archive.hpp).
#include "stock_archive.hpp"

#include <cstdio>
#include <nlohmann/json.hpp>

#include "progress.hpp"

namespace vts::cli {

namespace {

void print_stock_json(const std::string& path, const client::SourceInfo& stock,
                      const archive::ArchiveSummary& s) {
  const LonLatBounds& b = s.info.georeference->bounds;
  nlohmann::json j{{"path", path},
                   {"kind", "stock-raster"},
                   {"tile_type", stock.image_format},
                   {"tile_size", stock.image_tile_size},
                   {"min_zoom", stock.min_zoom},
                   {"max_zoom", s.info.geometry.max_zoom()},
                   {"tiling", std::string(tiling_name(s.info.georeference->tiling))},
                   {"bounds", {b.west, b.south, b.east, b.north}},
                   {"tiles", s.addressed_tiles},
                   {"unique_tiles", s.unique_tiles},
                   {"entries", s.entries},
                   {"leaf_directories", s.leaf_directories},
                   {"bytes", s.file_bytes},
                   {"tile_bytes", s.stored_bytes},
                   {"addressed_bytes", s.addressed_bytes}};
  j["levels"] = nlohmann::json::array();
  for (const auto& l : s.levels)
    j["levels"].push_back({{"z", l.z},
                           {"tiles", l.tiles_present},
                           {"tiles_possible", l.tiles_possible},
                           {"bytes", l.bytes}});
  std::printf("%s\n", j.dump(2).c_str());
}

void print_stock_text(const std::string& path, const client::SourceInfo& stock,
                      const archive::ArchiveSummary& s) {
  const LonLatBounds& b = s.info.georeference->bounds;
  std::printf("%s\n", path.c_str());
  std::printf("  kind         %s\n", stock_kind(stock).c_str());
  std::printf("  tiles        %u px, zoom %d..%d, %s\n", stock.image_tile_size, stock.min_zoom,
              s.info.geometry.max_zoom(),
              std::string(tiling_name(s.info.georeference->tiling)).c_str());
  std::printf("  bounds       %.9g,%.9g,%.9g,%.9g\n", b.west, b.south, b.east, b.north);
  std::printf("  archive      %s, %llu tiles, %llu unique, %llu entries, %llu leaf directories\n",
              human_bytes(s.file_bytes).c_str(), (unsigned long long)s.addressed_tiles,
              (unsigned long long)s.unique_tiles, (unsigned long long)s.entries,
              (unsigned long long)s.leaf_directories);
  std::printf("  %5s %10s %12s\n", "level", "tiles", "bytes");
  for (const auto& l : s.levels)
    std::printf("  %5d %10llu %12s\n", l.z, (unsigned long long)l.tiles_present,
                human_bytes(l.bytes).c_str());
}

}  // namespace

std::string stock_kind(const client::SourceInfo& s) {
  return "stock raster PMTiles of " + s.image_format +
         " tiles (not a vtstream archive: no vtstream codec, borders or checksums)";
}

// The stock raster archive `reader` holds, as the client opens it; nullopt for an archive that is
// not one (ours, or neither: summarize/verify then say why).
std::optional<Result<client::SourceInfo>> stock_archive(const archive::Reader& reader,
                                                        const std::string& path) {
  if (!client::is_stock_image_archive(reader.header())) return std::nullopt;
  auto ours = archive::archive_tileset(reader.header(), reader.metadata_json());
  if (ours || ours.error().code != ErrorCode::unsupported) return std::nullopt;
  auto info = client::stock_archive_info(reader.header(), reader.metadata_json(), path);
  if (!info) {
    Error e = info.error();
    e.message = "'" + path + "': stock raster archive: " + e.message;
    return e;
  }
  return info;
}

void print_stock_info(const std::string& path, const client::SourceInfo& stock,
                      const archive::ArchiveSummary& summary, bool json) {
  if (json)
    print_stock_json(path, stock, summary);
  else
    print_stock_text(path, stock, summary);
}

}  // namespace vts::cli
