// Test archives built in process with the real builder (vts::build_synthetic_pyramid: synthetic
// options only, so a test links no image library), no subprocess.
// Failures throw std::runtime_error: a test that cannot make its input cannot run.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <vector>

#include "vts/archive/pmtiles.hpp"
#include "vts/builder/builder.hpp"

namespace vts::test {

// Options for a synthetic build of width x height texels written to `output` (two encoder
// threads). Adjust the rest before passing it to build_archive().
BuildOptions synthetic_options(const std::filesystem::path& output, std::uint64_t width,
                               std::uint64_t height, std::optional<TexelRect> region = std::nullopt,
                               int region_level = 6);

// Builds the synthetic archive `options` describe (creating its folder); returns the build report.
BuildReport build_archive(const BuildOptions& options);

// An archive opened for reading, with every stored tile listed in directory order.
struct OpenedArchive {
  std::filesystem::path path;
  std::shared_ptr<archive::Reader> reader;
  std::vector<TileId> tiles;
};
OpenedArchive open_archive(const std::filesystem::path& path);

// Every byte of the archive `reader` opened (test archives are small); throws on a read error.
std::vector<std::uint8_t> read_all(const archive::Reader& reader);

// build_archive() then open_archive().
OpenedArchive build_and_open(const BuildOptions& options);

}  // namespace vts::test
