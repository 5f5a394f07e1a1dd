// What `vts export` prints (export_args.hpp).
#include <cstdio>
#include <nlohmann/json.hpp>

#include "export_args.hpp"
#include "progress.hpp"

namespace vts::cli {

void print_report(const ExportArgs& a, const ExportReport& r) {
  if (a.json) {
    nlohmann::json j{{"output", a.output},
                     {"layout", is_mbtiles(a)      ? "mbtiles"
                                : a.layout.empty() ? "pmtiles"
                                                   : a.layout},
                     {"format", a.format},
                     {"source_tiles", r.source_tiles},
                     {"tiles", r.tiles_written},
                     {"skipped_transparent", r.tiles_skipped},
                     {"unique_tiles", r.unique_tiles},
                     {"tile_bytes", r.tile_bytes},
                     {"file_bytes", r.file_bytes},
                     {"min_zoom", r.min_zoom},
                     {"max_zoom", r.max_zoom},
                     {"bounds", {r.bounds.west, r.bounds.south, r.bounds.east, r.bounds.north}},
                     {"tiling", std::string(tiling_name(r.grid))},
                     {"seconds", r.seconds}};
    std::printf("%s\n", j.dump(2).c_str());
  } else if (!a.quiet) {
    std::printf("exported %s: %llu tiles (%llu unique, %llu transparent skipped), %s in %s\n",
                a.output.c_str(), (unsigned long long)r.tiles_written,
                (unsigned long long)r.unique_tiles, (unsigned long long)r.tiles_skipped,
                human_bytes(r.file_bytes ? r.file_bytes : r.tile_bytes).c_str(),
                human_duration(r.seconds).c_str());
  }
}

void print_geotiff_report(const ExportArgs& a, const GeoTiffReport& r) {
  const GeoTiffRegion& g = r.region;
  if (a.json) {
    nlohmann::json j{{"output", a.output},
                     {"format", "gtiff"},
                     {"level", g.level},
                     {"texel_rect", {g.texels.x0, g.texels.y0, g.texels.x1, g.texels.y1}},
                     {"width", g.texels.width()},
                     {"height", g.texels.height()},
                     {"overviews", g.overviews},
                     {"tiling", std::string(tiling_name(g.tiling))},
                     {"crs", g.tiling == Tiling::web_mercator_quad ? "EPSG:3857" : "EPSG:4326"},
                     {"geotransform", g.geotransform},
                     {"bounds", {r.bounds.west, r.bounds.south, r.bounds.east, r.bounds.north}},
                     {"texels", r.texels},
                     {"file_bytes", r.file_bytes},
                     {"seconds", r.seconds}};
    std::printf("%s\n", j.dump(2).c_str());
  } else if (!a.quiet) {
    std::printf("exported %s: level %d, %llux%llu texels, %d overviews, %s in %s\n",
                a.output.c_str(), g.level, (unsigned long long)g.texels.width(),
                (unsigned long long)g.texels.height(), g.overviews,
                human_bytes(r.file_bytes).c_str(), human_duration(r.seconds).c_str());
  }
}

// The one-line note of the grid a web export writes: a WorldCRS84Quad archive's tiles go out as
// Web Mercator unless asked otherwise, which a user of the old default should hear about.
void note_grid(const ExportArgs& a, const TilesetInfo& info, const ExportOptions& o) {
  if (a.quiet || !info.georeference) return;
  auto grid = export_grid(info, o.layout, o.tiling);
  if (!grid) return;  // the export reports it
  const Tiling own = info.georeference->tiling;
  if (*grid != own)
    std::fprintf(stderr,
                 "export: grid %s, reprojected from the archive's %s (--tiling native "
                 "keeps the archive's grid)\n",
                 std::string(tiling_name(*grid)).c_str(), std::string(tiling_name(own)).c_str());
  else
    std::fprintf(stderr, "export: grid %s (the archive's own)\n",
                 std::string(tiling_name(*grid)).c_str());
}

}  // namespace vts::cli
