// How to open a target, shared by loadtest, warm and view: --bounds and --zoom, the layout of an
// XYZ/TMS template target (which says nothing of itself) or an override of what a third-party
// TileJSON or archive says; --max-download, for a host that ignores HTTP Range; --cacert, for an
// https:// server whose certificate a private CA signed.
#pragma once

#include <memory>
#include <string>

#include <CLI/CLI.hpp>

#include "vts/base/result.hpp"
#include "vts/client/source.hpp"

namespace vts::cli {

struct ImageTargetArgs {
  std::string bounds, zoom;
  std::uint64_t max_download = client::kDefaultMaxDownload;
  std::string ca_file;          // --cacert
  std::uint32_t tile_size = 0;  // --tile-size; 0: the source's own (a template's: 256)
};

void add_image_target_options(CLI::App* c, ImageTargetArgs& a);
// Sets options.bounds, the zoom range, the tile size and max_download; invalid_argument naming
// the flag.
Status apply_image_target(const ImageTargetArgs& a, client::SourceOptions& options);

// apply_image_target() then client::open_source().
Result<std::unique_ptr<client::TileSource>> open_with_layout(const std::string& location,
                                                             const ImageTargetArgs& a,
                                                             client::SourceOptions options = {});

}  // namespace vts::cli
