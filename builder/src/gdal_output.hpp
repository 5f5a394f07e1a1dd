// What the builder's GDAL code shares (gdal_source.cpp, export_gtiff.cpp, extract.cpp): GDAL's
// drivers registered once with a bounded block cache, GDAL's error messages captured as our errors,
// and a georeference (GeoTiffRegion: CRS + geotransform) set on a dataset or added to a written
// file.
#pragma once

#include <gdal_priv.h>

#include <filesystem>
#include <memory>
#include <string>

#include "vts/base/result.hpp"
#include "vts/builder/export.hpp"

namespace vts {
inline namespace builder {
namespace detail {

// A dataset closed (and flushed) by GDALClose.
struct GdalClose {
  void operator()(GDALDataset* ds) const { GDALClose(ds); }
};
using GdalDatasetPtr = std::unique_ptr<GDALDataset, GdalClose>;

// GDALAllRegister() once, for the builder's readers (gdal_source.cpp) and writers alike: GDAL's
// block cache capped at 64 MiB unless GDAL_CACHEMAX is set (its default, 5 % of RAM, would be most
// of a build's or export's memory, and both touch each block about once), and VRT raw bands off.
void register_gdal();

// Collects GDAL's error messages on this thread instead of letting GDAL print them.
class GdalErrors {
 public:
  GdalErrors();
  ~GdalErrors();
  GdalErrors(const GdalErrors&) = delete;
  GdalErrors& operator=(const GdalErrors&) = delete;
  // Whether GDAL reported a failure since construction.
  bool failed() const { return CPLGetLastErrorType() >= CE_Failure; }
  // GDAL's messages, "; "-separated, or "GDAL reported no reason".
  std::string text() const;
  // io: "WHAT: GDAL's messages".
  Error error(const std::string& what) const;

 private:
  static void CPL_STDCALL handle(CPLErr level, CPLErrorNum, const char* msg);
  std::string messages_;
};

// The CRS of a tiling (EPSG:4326 in longitude, latitude order for WorldCRS84Quad, EPSG:3857 for
// WebMercatorQuad) and the region's geotransform, set on `ds`.
Status set_georeference(GDALDataset& ds, const GeoTiffRegion& region);

// Adds the georeference to an image file already written (by OpenImageIO): inside it for a TIFF
// (GeoTIFF tags, GDAL in update mode); for any other format GDAL reads, in a PAM side file
// `path`.aux.xml, which GDAL and QGIS read (returned in *side_file; empty for a TIFF).
Status add_georeference(const std::filesystem::path& path, const GeoTiffRegion& region,
                        std::filesystem::path* side_file);

}  // namespace detail
}  // namespace builder
}  // namespace vts
