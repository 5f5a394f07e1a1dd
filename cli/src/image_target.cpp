#include "image_target.hpp"

#include "commands.hpp"
#include "progress.hpp"

namespace vts::cli {

void add_image_target_options(CLI::App* c, ImageTargetArgs& a) {
  c->add_option("--bounds", a.bounds,
                "Image tiles: W,S,E,N (degrees) with tiles (a {z}/{x}/{y} template's default: the "
                "world)");
  c->add_option("--zoom", a.zoom,
                "Image tiles: zoom levels A-B the server has (a {z}/{x}/{y} template needs it)");
  c->add_option("--tile-size", a.tile_size,
                "Image tiles: a {z}/{x}/{y} template's tile size in pixels, a power of two "
                "64-1024 [default: 256]");
  add_max_download_option(c, a.max_download);
  c->add_option("--cacert", a.ca_file,
                "Verify https:// servers with the CA certificates in this PEM file instead of the "
                "system's")
      ->check(CLI::ExistingFile);
}

Status apply_image_target(const ImageTargetArgs& a, client::SourceOptions& o) {
  o.max_download = a.max_download;
  if (!a.ca_file.empty()) o.fetcher.ca_file = a.ca_file;
  if (a.tile_size != 0) o.tile_size = a.tile_size;  // checked where the layout is made
  if (!a.bounds.empty()) {
    auto b = parse_numbers(a.bounds, 4, "--bounds", "W,S,E,N");
    if (!b) return b.error();
    o.bounds = LonLatBounds{(*b)[0], (*b)[1], (*b)[2], (*b)[3]};
  }
  if (!a.zoom.empty()) {
    auto z = parse_level_range(a.zoom, "--zoom");
    if (!z) return z.error();
    o.min_zoom = z->first;
    o.max_zoom = z->second;
  }
  return {};
}

Result<std::unique_ptr<client::TileSource>> open_with_layout(const std::string& location,
                                                             const ImageTargetArgs& a,
                                                             client::SourceOptions options) {
  if (auto st = apply_image_target(a, options); !st) return st.error();
  return client::open_source(location, std::move(options));
}

}  // namespace vts::cli
