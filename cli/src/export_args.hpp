// The arguments of `vts export` (cmd_export.cpp) and the lines it prints (export_report.cpp).
#pragma once

#include <optional>
#include <string>

#include "vts/builder/export.hpp"
#include "vts/protocol/tileset.hpp"

namespace vts::cli {

struct ExportArgs {
  std::string archive, output, format, layout, tiling, tile_format, bbox;
  std::optional<int> quality;  // unset: the format's default
  std::optional<int> level;    // gtiff
  unsigned threads = 0;
  bool json = false, quiet = false;
};

inline bool is_gtiff(const ExportArgs& a) {
  return a.format == "gtiff";
}
inline bool is_mbtiles(const ExportArgs& a) {
  return a.format == "mbtiles";
}

// The result, as JSON (--json) or one line (unless --quiet).
void print_report(const ExportArgs& a, const ExportReport& r);
void print_geotiff_report(const ExportArgs& a, const GeoTiffReport& r);
// The one-line note on stderr of the grid a web export writes.
void note_grid(const ExportArgs& a, const TilesetInfo& info, const ExportOptions& o);

}  // namespace vts::cli
