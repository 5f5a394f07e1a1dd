#!/usr/bin/env bash
# Georeferenced builds at planet scale keep only their footprint: a 2048 x 1024-pixel piece of
# Paris at 1.19 m (EPSG:3857) lands on level 17 of WebMercatorQuad (its 1.1943 m texels are within 1 % of the pixels), a grid
# 2^25 texels wide, as a
# sparse archive of exactly the footprint's tiles (counted independently by footprint_count.py),
# read in one pass over a window of the footprint's width; an input 80000 pixels wide (a footprint
# of 131072 texels at level 9 of WorldCRS84Quad) is built in column stripes no wider than the
# 32768-texel window limit plus a pass over their scratch level, still with the footprint's tile
# count, and its finest level equals gdalwarp's onto the same grid where both are opaque. (That
# stripes give byte-identical tiles to one pass is checked by GdalBuild.StripesGiveTheSameTiles
# AsOnePass; that windows equal a whole-grid reduction by test_cascade.cpp.)
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
HERE=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
require_tool python3
require_tool gdal_translate
require_tool gdalinfo

cd "$WORK"
# extent FILE: W,S,E,N in degrees of an EPSG:3857 or EPSG:4326 raster, from gdalinfo -json.
extent() {
  gdalinfo -json "$1" >"$1.json" || fail "gdalinfo $1"
  python3 - "$1.json" <<'PY'
import json, math, sys
j = json.load(open(sys.argv[1]))
c = j["cornerCoordinates"]
x0, y1 = c["upperLeft"]; x1, y0 = c["lowerRight"]
if "Pseudo-Mercator" in j["coordinateSystem"]["wkt"]:
    R = 6378137.0
    lon = lambda x: math.degrees(x / R)
    lat = lambda y: math.degrees(math.atan(math.sinh(y / R)))
    x0, x1, y0, y1 = lon(x0), lon(x1), lat(y0), lat(y1)
print(",".join(repr(v) for v in (x0, y0, x1, y1)))
PY
}

note "a 1.19 m piece of Paris on WebMercatorQuad: level 17 of a 2^25-texel grid, sparse"
gdal_translate -q -a_srs EPSG:3857 -a_ullr 261000 6250000 263437.1 6248781.4 "$EARTH" paris.tif ||
  fail "gdal_translate paris"
expect_ok "$VTS" build paris.tif --tiling WebMercatorQuad -o paris.pmtiles --threads 2 --json
cp "$OUT" paris.json
want=$(python3 "$HERE/footprint_count.py" 17 256 "$(extent paris.tif)" WebMercatorQuad)
python3 - paris.json "$want" <<'PY' || fail "the Paris build is not the footprint's sparse archive"
import json, sys
j = json.load(open(sys.argv[1]))
assert j["max_zoom"] == 17 and j["width"] == 2 ** 25, (j["max_zoom"], j["width"])
assert j["tiles"] == int(sys.argv[2]), (j["tiles"], sys.argv[2])
assert j["passes"] == 1 and 2040 <= j["window_width"] <= 2060, (j["passes"], j["window_width"])
assert j["georeference"]["tiling"] == "WebMercatorQuad", j["georeference"]
PY
expect_ok "$VTS" verify paris.pmtiles

note "an input 80000 pixels wide: column stripes within the window limit, then their scratch level"
gdal_translate -q -a_srs EPSG:4326 -a_ullr -180 0.9 180 0 -outsize 80000 200 "$EARTH" strip.tif ||
  fail "gdal_translate strip"
expect_ok "$VTS" build strip.tif --resampling bilinear -o strip.pmtiles --threads 2 --json
cp "$OUT" strip.json
want=$(python3 "$HERE/footprint_count.py" 9 256 "$(extent strip.tif)")
python3 - strip.json "$want" <<'PY' || fail "the wide build was not striped or lost tiles"
import json, sys
j = json.load(open(sys.argv[1]))
assert j["max_zoom"] == 9 and j["width"] == 131072, (j["max_zoom"], j["width"])
assert j["tiles"] == int(sys.argv[2]), (j["tiles"], sys.argv[2])
assert j["passes"] > 2 and j["window_width"] <= 32768, (j["passes"], j["window_width"])
PY
expect_ok "$VTS" verify strip.pmtiles
ls -A | grep -q "scratch" && fail "a scratch file was left behind"
note "ok"
