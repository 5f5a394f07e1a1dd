// What our archive metadata says about a tileset: geometry, codec and format version. Stored in
// the PMTiles JSON metadata under the key "vtstream" (docs/FORMAT.md lists every key), next to
// the generic keys other PMTiles tools read ("name", "description", "type", "format").
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "vts/base/result.hpp"
#include "vts/protocol/codec.hpp"
#include "vts/protocol/geometry.hpp"
#include "vts/protocol/tiling.hpp"

namespace vts {
inline namespace protocol {

// Where a georeferenced tileset sits on the Earth (docs/FORMAT.md "Georeference"). Stored in the
// metadata as the object "vtstream.georeference"; absent for plain images.
struct Georeference {
  Tiling tiling = Tiling::world_crs84_quad;  // never none
  LonLatBounds bounds;                       // the data's footprint, degrees (not snapped to tiles)
  LonLatLevel center;                        // initial view: lon, lat (degrees) and our level
  std::string crs() const { return std::string(tiling_crs(tiling)); }
  bool operator==(const Georeference&) const = default;
};

// Checks a georeference against the pyramid it describes: a tiling other than none whose grid the
// geometry is (check_tiling_geometry); finite bounds with west < east and south < north (a
// footprint crossing the antimeridian is refused: split it in two tilesets) inside the scheme's
// extent (latitudes within +-85.0511 for WebMercatorQuad); a center inside the bounds at a level
// within 0..max_zoom. The error (invalid_argument) names the field.
Status check_georeference(const Georeference& geo, const Geometry& g);

struct TilesetInfo {
  static constexpr int kFormatVersion = 1;

  int format_version = kFormatVersion;
  Geometry geometry = Geometry::create(1, 1).value();
  CodecId codec = CodecId::lossless;
  std::string name;
  std::string description;
  std::string color_space = "srgb";       // texel encoding of decoded rgba8
  std::string downsample = "box-linear";  // how level z-1 was made from level z
  bool sparse = false;                    // some tiles inside the image may be absent
  std::string generator = "vtstream";     // tool and version that wrote the archive
  // 16 hex digits summarising every tile's id and payload checksum (order-independent), so two
  // archives with different tile bytes never share metadata — and the server's archive version,
  // which hashes the metadata, always changes with the tiles. Optional; empty when unknown.
  std::string content_hash;
  // Set for a tileset on an OGC tile matrix set; nullopt for a plain image.
  std::optional<Georeference> georeference;

  // What every tile of this tileset is: stored_size() x stored_size() texels of `codec`.
  TileSpec tile_spec() const { return {geometry.stored_size(), geometry.stored_size(), codec}; }

  std::string to_json() const;
  // Validates every field (unknown codec, unsupported format_version, bad geometry, a
  // georeference check_georeference() refuses → error).
  static Result<TilesetInfo> from_json(const std::string& metadata_json);
};

// Tileset names travel in URLs and are looked up in tables, so they keep to an unreserved-only
// alphabet that never needs escaping and can never mean a path: [A-Za-z0-9._-]+, no leading dot,
// at most 128 characters. Returns empty for a valid name, else why it is not ("is empty",
// "starts with a dot", ...), to be quoted in an error.
std::string tileset_name_problem(std::string_view name);
inline constexpr std::string_view kTilesetNameRule =
    "names are [A-Za-z0-9._-], at most 128 characters, no leading dot";

}  // namespace protocol
}  // namespace vts
