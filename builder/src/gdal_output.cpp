#include "gdal_output.hpp"

#include <cpl_conv.h>
#include <ogr_spatialref.h>

#include <cstdlib>
#include <memory>
#include <mutex>

namespace vts {
inline namespace builder {
namespace detail {

void register_gdal() {
  static std::once_flag once;
  std::call_once(once, [] {
    GDALAllRegister();
    // Strips aligned to the warped blocks read each block once, so 64 MiB (the source tiles a
    // block's warp reads) costs no time (an 80000-pixel-wide build: 2.2 s, 414 MiB peak, vs
    // 2.0 s, 578 MiB with 256 MiB). GDAL_CACHEMAX in the environment still rules.
    if (!std::getenv("GDAL_CACHEMAX")) GDALSetCacheMax64(GIntBig{64} << 20);
    // A VRT's raw band (VRTRawRasterBand) reads any local file as pixels: an input handed to a
    // build could put /etc/passwd into the tiles. Off unless the environment turns it on
    // (GDAL_VRT_ENABLE_RAWRASTERBAND=YES); gdal_source.cpp's check_vrt_sources refuses it too
    // (GDAL < 3.7).
    if (!std::getenv("GDAL_VRT_ENABLE_RAWRASTERBAND"))
      CPLSetConfigOption("GDAL_VRT_ENABLE_RAWRASTERBAND", "NO");
  });
}

GdalErrors::GdalErrors() {
  CPLPushErrorHandlerEx(&GdalErrors::handle, this);
  CPLErrorReset();
}
GdalErrors::~GdalErrors() {
  CPLPopErrorHandler();
}

std::string GdalErrors::text() const {
  return messages_.empty() ? "GDAL reported no reason" : messages_;
}

Error GdalErrors::error(const std::string& what) const {
  return make_error(ErrorCode::io, what + ": " + text());
}

void CPL_STDCALL GdalErrors::handle(CPLErr level, CPLErrorNum, const char* msg) {
  auto* self = static_cast<GdalErrors*>(CPLGetErrorHandlerUserData());
  if (level < CE_Failure || !self || self->messages_.size() > 400) return;
  if (!self->messages_.empty()) self->messages_ += "; ";
  self->messages_ += msg ? msg : "?";
}

Status set_georeference(GDALDataset& ds, const GeoTiffRegion& region) {
  OGRSpatialReference srs;
  srs.importFromEPSG(region.tiling == Tiling::web_mercator_quad ? 3857 : 4326);
  srs.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
  double gt[6];
  std::copy(std::begin(region.geotransform), std::end(region.geotransform), gt);
  GdalErrors errors;
  if (ds.SetSpatialRef(&srs) != CE_None || ds.SetGeoTransform(gt) != CE_None)
    return errors.error("cannot set the georeference of '" + std::string(ds.GetDescription()) +
                        "'");
  return {};
}

Status add_georeference(const std::filesystem::path& path, const GeoTiffRegion& region,
                        std::filesystem::path* side_file) {
  register_gdal();
  GdalErrors errors;
  // A TIFF takes the tags in update mode; other formats are opened read-only and GDAL keeps the
  // georeference in its PAM side file.
  GdalDatasetPtr ds(GDALDataset::Open(path.c_str(), GDAL_OF_RASTER | GDAL_OF_UPDATE, nullptr));
  bool tiff = ds && ds->GetDriver() && EQUAL(ds->GetDriver()->GetDescription(), "GTiff");
  if (!tiff) {
    ds.reset();
    CPLErrorReset();
    ds.reset(GDALDataset::Open(path.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY, nullptr));
  }
  if (!ds) return errors.error("cannot georeference '" + path.string() + "'");
  if (Status st = set_georeference(*ds, region); !st) return st;
  ds.reset();  // writes the tags or the side file
  if (side_file)
    *side_file = tiff ? std::filesystem::path() : std::filesystem::path(path.string() + ".aux.xml");
  return {};
}

}  // namespace detail
}  // namespace builder
}  // namespace vts
