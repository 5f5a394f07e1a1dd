// vts-build's extract: what cmd_extract.cpp does not do itself (a whole level, or a tile in an
// image format other than PNG), written through OpenImageIO (builder/extract.hpp).
#include <filesystem>
#include <memory>
#include <string>

#include "commands.hpp"
#include "vts/archive/inspect.hpp"
#include "vts/builder/extract.hpp"

namespace vts::cli {

namespace {

int extract_through_builder(const ExtractArgs& a) {
  auto reader = open_archive(a.archive);
  if (!reader) return report_error(reader.error());
  auto info = archive::archive_tileset((*reader)->header(), (*reader)->metadata_json());
  if (!info) return report_error(info.error());
  ExtractOptions o;
  o.output = a.output;
  o.with_border = a.with_border;
  o.channels = a.channels;
  // SIGINT/SIGTERM stop a level's extraction cleanly (its temporary file removed); a second kills.
  o.cancel = &install_stop_signals();
  Status st;
  if (!a.tile.empty()) {
    auto id = parse_tile_id(a.tile);
    if (!id) return report_error(id.error());
    st = extract_tile(**reader, *info, *id, o);
  } else {
    st = extract_level(**reader, *info, a.level, o);
  }
  if (!st) return report_error(st.error());
  return 0;
}

}  // namespace

Runner add_extract(CLI::App& app) {
  return add_extract_command(app, &extract_through_builder);
}

}  // namespace vts::cli
