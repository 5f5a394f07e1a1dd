// vts extract: one tile, or a whole level, of an archive written as an image file. A tile written
// as PNG is done here, by whichever executable runs the command (the runtime `vts` links neither
// GDAL nor OpenImageIO); a whole level, or a tile in another format, is the `rest` each
// executable gives: vts-build writes it through OpenImageIO (cmd_extract_build.cpp), `vts` hands
// the command over to vts-build (handover.cpp).
#include <algorithm>
#include <cctype>
#include <filesystem>
#include <memory>
#include <string>

#include "commands.hpp"
#include "vts/archive/inspect.hpp"
#include "vts/base/file_io.hpp"
#include "vts/imaging/web_image.hpp"

namespace vts::cli {

namespace {

bool is_png_path(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext == ".png";
}

// Tile `a.tile` of `a.archive` as a PNG file: the content clipped to the image (or the stored
// tile with its border), straight alpha, tagged sRGB, written atomically.
int extract_tile_png(const ExtractArgs& a) {
  auto id = parse_tile_id(a.tile);
  if (!id) return report_error(id.error());
  auto reader = open_archive(a.archive);
  if (!reader) return report_error(reader.error());
  auto info = archive::archive_tileset((*reader)->header(), (*reader)->metadata_json());
  if (!info) return report_error(info.error());
  if (!info->geometry.exists(*id))
    return report_error(
        make_error(ErrorCode::not_found, "tile " + id->to_string() + " is outside the pyramid"));
  auto stored = archive::read_tile_rgba8(**reader, *info, *id);
  if (!stored) return report_error(stored.error());
  const TileImage img = archive::extracted_texels(*stored, info->geometry, *id, a.with_border);
  if (Status s = imaging::write_png(a.output, static_cast<int>(img.width),
                                    static_cast<int>(img.height), img.pixels, 6, a.channels);
      !s)
    return report_error(s.error());
  return 0;
}

int run_extract(const ExtractArgs& a, const std::function<int(const ExtractArgs&)>& rest) {
  if (a.tile.empty() == (a.level < 0))
    return report_error(
        make_error(ErrorCode::invalid_argument, "give exactly one of Z/X/Y or --level Z"));
  if (a.with_border && a.level >= 0)
    return report_error(
        make_error(ErrorCode::invalid_argument, "--with-border applies to a single tile"));
  const std::filesystem::path archive = a.archive;
  if (Status s = check_output_is_not_an_input(a.output, {&archive, 1}); !s)
    return report_error(s.error());
  if (!a.tile.empty() && is_png_path(a.output)) return extract_tile_png(a);
  return rest(a);
}

}  // namespace

Runner add_extract_command(CLI::App& app, std::function<int(const ExtractArgs&)> rest) {
  auto a = std::make_shared<ExtractArgs>();
  CLI::App* c = app.add_subcommand(
      "extract", "Write one tile, or a whole level stitched together, as an image file");
  c->add_option("archive", a->archive, "Archive (.pmtiles)")->required();
  c->add_option("tile", a->tile, "Tile as Z/X/Y");
  c->add_option("--level", a->level, "Extract the whole level Z");
  c->add_option("-o,--output", a->output,
                "Output image; format from the extension. From a georeferenced archive a .tif "
                "gets GeoTIFF tags, other formats (a level, or a tile not as PNG) an .aux.xml")
      ->required();
  c->add_flag("--with-border", a->with_border, "Include the tile's border texels");
  c->add_option("--channels", a->channels, "4 = RGBA, 3 = RGB")
      ->check(CLI::IsMember({3, 4}))
      ->capture_default_str();
  return [a, rest = std::move(rest)] { return run_extract(*a, rest); };
}

}  // namespace vts::cli
