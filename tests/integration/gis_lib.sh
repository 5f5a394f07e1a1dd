# shellcheck shell=bash disable=SC2034  # MERC_HALF is used by the scripts that source this
# Shared by the GIS client tests (gis_wmts.sh, gis_ogcapi.sh; sourced after lib.sh and
# serve_lib.sh): the Earth as georeferenced archives, `vts serve` of them with one protected, and
# the level images to compare clients' rasters with.
require_tool gdal_translate
require_tool gdalinfo
PY=/usr/bin/python3 # Debian's: GDAL's bindings, numpy, OWSLib
require_tool "$PY"
HERE=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
# GDAL's WMS cache (under the WMTS and OGCAPI drivers) in the test's folder, not the caller's.
export GDAL_DEFAULT_WMS_CACHE_PATH="$WORK/gdalwmscache"
# Half the side of Web Mercator's level-2 tile: the corners of its four middle tiles, in metres.
MERC_HALF=10018754.171394622

# gis_setup: earth (WorldCRS84Quad, TMS levels 0..2), merc (WebMercatorQuad 0..3), secret (a
# copy of earth behind a bearer token) and the plain images wmts and ogcapi, served; earth3.png and merc2.png are what `vts extract`
# writes of earth's level 3 (TMS 2) and merc's level 2.
gis_setup() {
  gdal_translate -q -a_srs EPSG:4326 -a_ullr -180 90 180 -90 "$EARTH" "$WORK/world.tif" ||
    fail "gdal_translate world.tif"
  expect_ok "$VTS" build "$WORK/world.tif" -o "$WORK/earth.pmtiles" --threads 2 -q
  expect_ok "$VTS" build "$WORK/world.tif" --tiling WebMercatorQuad --max-level 3 \
    -o "$WORK/merc.pmtiles" --threads 2 -q
  cp "$WORK/earth.pmtiles" "$WORK/secret.pmtiles"
  echo '{"access": {"secret": {"tokens": ["s3cret"]}}}' >"$WORK/serve.json"
  expect_ok "$VTS" extract "$WORK/earth.pmtiles" --level 3 -o "$WORK/earth3.png"
  expect_ok "$VTS" extract "$WORK/merc.pmtiles" --level 2 -o "$WORK/merc2.png"
  # Plain images named as the OGC routes' first segments: their tile paths still answer.
  build_earth "$WORK/wmts.pmtiles" --threads 2 -q
  cp "$WORK/wmts.pmtiles" "$WORK/ogcapi.pmtiles"
  start_server "$WORK/earth.pmtiles" "$WORK/merc.pmtiles" "$WORK/secret.pmtiles" \
    "$WORK/wmts.pmtiles" "$WORK/ogcapi.pmtiles" --config "$WORK/serve.json"
}

# same_texels OUT REF X Y MODE...: gis_compare.py (exact, or a PSNR floor for lossy codecs).
same_texels() { "$PY" "$HERE/gis_compare.py" "$@" || fail "$1 is not $2's texels at $3,$4"; }

# body_has URL TEXT [CURL ARGS...]: the response body of URL contains TEXT.
body_has() {
  local url=$1 text=$2
  shift 2
  # Read whole before searching: grep -q stops at the first match, and curl writing the rest of a
  # large body into the closed pipe would fail the pipeline (pipefail).
  local body
  body=$(curl -s "$@" "$url")
  grep -qF -- "$text" <<<"$body" || fail "$url: no '$text' in the body"
}
