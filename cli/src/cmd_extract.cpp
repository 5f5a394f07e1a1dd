// vts extract: one tile, or a whole level, of an archive written as an image file (OpenImageIO).
#include <filesystem>
#include <memory>
#include <string>

#include "commands.hpp"
#include "vts/archive/inspect.hpp"
#include "vts/base/file_io.hpp"
#include "vts/builder/extract.hpp"

namespace vts::cli {

namespace {

struct ExtractArgs {
  std::string archive, tile, output;
  int level = -1;
  bool with_border = false;
  int channels = 4;
};

int run_extract(const ExtractArgs& a) {
  if (a.tile.empty() == (a.level < 0))
    return report_error(
        make_error(ErrorCode::invalid_argument, "give exactly one of Z/X/Y or --level Z"));
  const std::filesystem::path archive = a.archive;
  if (Status s = check_output_is_not_an_input(a.output, {&archive, 1}); !s)
    return report_error(s.error());
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
    if (a.with_border)
      return report_error(
          make_error(ErrorCode::invalid_argument, "--with-border applies to a single tile"));
    st = extract_level(**reader, *info, a.level, o);
  }
  if (!st) return report_error(st.error());
  return 0;
}
}  // namespace

Runner add_extract(CLI::App& app) {
  auto a = std::make_shared<ExtractArgs>();
  CLI::App* c = app.add_subcommand(
      "extract", "Write one tile, or a whole level stitched together, as an image file");
  c->add_option("archive", a->archive, "Archive (.pmtiles)")->required();
  c->add_option("tile", a->tile, "Tile as Z/X/Y");
  c->add_option("--level", a->level, "Extract the whole level Z");
  c->add_option("-o,--output", a->output, "Output image; format from the extension")->required();
  c->add_flag("--with-border", a->with_border, "Include the tile's border texels");
  c->add_option("--channels", a->channels, "4 = RGBA, 3 = RGB")
      ->check(CLI::IsMember({3, 4}))
      ->capture_default_str();
  return [a] { return run_extract(*a); };
}

}  // namespace vts::cli
