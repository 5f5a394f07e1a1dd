#!/usr/bin/env bash
# Whole-world and antimeridian georeferenced inputs, built by `vts build` with real GDAL files
# made here from the Earth image (2048 x 1024 plate carree) and compared with real gdalwarp.
#
# Level: with no --max-level, the level follows the input's resolution at its middle (the
# equator when it spans it), not GDAL's suggested warp of the whole raster, which is degenerate at
# the poles on Web Mercator (a +-90 degree input got level 0, one 256-texel tile): the whole world
# at 360/2048 degrees a pixel is level 3 (2048 texels around) on both schemes, and on
# WebMercatorQuad its footprint is clipped to +-85.0511 degrees, with no warning.
#
# Antimeridian: the region 150E..150W as EPSG:4326 with longitudes 150..210, the whole world as a
# 0..360 grid, the region in EPSG:3832 (PDC Mercator, centred on 150 E, made by gdalwarp) all
# build; the footprint recorded is every longitude (west < east, as TileJSON needs) and their
# latitudes; the tiles are the footprint's; and the finest level is where gdalwarp puts the same
# input on the same grid (georef_placement.py: shift <= 0.25 texel, colours, transparency), with
# each side of 180 degrees opaque where gdalwarp's is (counted per half). An EPSG:3857 raster
# whose x runs past 20037508 m is placed as gdalwarp places it (up to 180 degrees) and the part
# past it is named in a warning. The old refusal ("split it in two") is gone.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
HERE=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
for t in gdal_translate gdalwarp gdalinfo; do
  require_tool "$t"
done
PY=/usr/bin/python3 # Debian's: numpy and GDAL's bindings
"$PY" -c 'import numpy' 2>/dev/null || fail "no numpy for /usr/bin/python3 (python3-numpy)"
M=20037508.342789244
LAT=85.05112877980659

cd "$WORK"
T() { gdal_translate -q "$@" || fail "gdal_translate $*"; }
W() { gdalwarp -q "$@" || fail "gdalwarp $*"; }
T -a_srs EPSG:4326 -a_ullr -180 90 180 -90 "$EARTH" world.tif
# The same pixels as a 0..360 grid (climate and DEM data often come so): a pixel copy, halves
# swapped, checked below.
W -te 0 -90 360 90 -ts 2048 1024 -r near world.tif g360.tif
T -projwin 150 60 210 -60 g360.tif am4326.tif
W -t_srs EPSG:3832 -te_srs EPSG:4326 -te 150 -60 210 60 -r bilinear world.tif am3832.tif
T -a_srs EPSG:3857 -a_ullr 18924313.43 1118889.97 21150591.25 0 -outsize 64 32 world.tif am3857.tif
"$PY" - <<'PY' || fail "the inputs are not what they should be"
from osgeo import gdal
import numpy as np
w, g = gdal.Open("world.tif").ReadAsArray(), gdal.Open("g360.tif").ReadAsArray()
assert (g[:, :, :1024] == w[:, :, 1024:]).all() and (g[:, :, 1024:] == w[:, :, :1024]).all()
gt = gdal.Open("am4326.tif").GetGeoTransform()
x1 = gt[0] + gt[1] * gdal.Open("am4326.tif").RasterXSize
assert gt[0] < 180 < x1 <= 211, (gt, x1)
PY

# extent FILE: W,S,E,N in degrees of a 4326 file (gdalinfo's corners), latitudes clipped to LIM.
extent() {
  "$PY" - "$1" "$2" <<'PY'
import sys
from osgeo import gdal
d = gdal.Open(sys.argv[1])
gt, lim = d.GetGeoTransform(), float(sys.argv[2])
n, s = gt[3], gt[3] + gt[5] * d.RasterYSize
print(",".join(repr(v) for v in (-180.0, max(s, -lim), 180.0, min(n, lim))))
PY
}

# check NAME SCHEME LEVEL BBOX INPUT [vts build options]: build INPUT (cubic; no --max-level unless given),
# check the level, the bounds (1e-7 degrees), the tile count and that no warning is printed, then
# compare the finest level with gdalwarp's of INPUT onto the same grid, and each half of it.
check() {
  local name=$1 scheme=$2 level=$3 bbox=$4 input=$5 w h srs te
  shift 5
  note "$name: $input onto $scheme, level $level from its resolution"
  expect_ok "$VTS" build "$input" --tiling "$scheme" -o "$name.pmtiles" --threads 2 --json "$@"
  cp "$OUT" "$name.build.json"
  cp "$ERR" "$name.build.err"
  if [[ -z ${WARNS:-} ]] && grep -qi "warn" "$ERR"; then fail "$name: warned: $(cat "$ERR")"; fi
  grep -q "split it in two" "$ERR" && fail "$name: the old refusal is still there"
  expect_ok "$VTS" info "$name.pmtiles" --json
  "$PY" - "$OUT" "$bbox" "$(python3 "$HERE/footprint_count.py" "$level" 256 "$bbox" "$scheme")" \
    "$level" "$scheme" "$name.build.json" <<'PY' || fail "$name: level, bounds or tiles differ"
import json, sys
i, b = json.load(open(sys.argv[1])), json.load(open(sys.argv[6]))
want = [float(v) for v in sys.argv[2].split(",")]
g = i["georeference"]
print(f"  level {i['max_zoom']}, bounds {g['bounds']}, {i['tiles']} tiles, warnings {b['warnings']}")
assert g["tiling"] == sys.argv[5], g
assert i["max_zoom"] == int(sys.argv[4]), ("level", i["max_zoom"], sys.argv[4])
assert all(abs(x - y) <= 1e-7 for x, y in zip(g["bounds"], want)), (g["bounds"], want)
assert g["bounds"][0] < g["bounds"][2], "west < east"
assert i["tiles"] == g["tiles_present"] == int(sys.argv[3]), (i["tiles"], sys.argv[3])
PY
  w=$((256 << level))
  if [[ $scheme == WorldCRS84Quad ]]; then
    h=$((w / 2)) srs=EPSG:4326 te=(-180 -90 180 90)
  else
    h=$w srs=EPSG:3857 te=("-$M" "-$M" "$M" "$M")
  fi
  expect_ok "$VTS" extract "$name.pmtiles" --level "$level" -o "$name.level.tif"
  T -of ENVI -co INTERLEAVE=BIP "$name.level.tif" "$name.ours.bil"
  W -t_srs "$srs" -te "${te[@]}" -ts "$w" "$h" -r cubic -et 0 -ot Float32 -dstalpha \
    -wo DST_ALPHA_MAX=255 -of ENVI -co INTERLEAVE=BIP "$input" "$name.ref.bil"
  "$PY" "$HERE/georef_placement.py" compare "$name.ours.bil" "$name.ref.bil" "$w" "$h" 3 0 255 \
    "$name" >"$name.cmp" || {
    cat "$name.cmp"
    fail "$name: not where gdalwarp puts it, or not what it puts there"
  }
  cat "$name.cmp"
  "$PY" - "$name.ours.bil" "$name.ref.bil" "$w" "$h" "${HALVES:-both}" <<'PY' ||
import sys
import numpy as np
w, h = int(sys.argv[3]), int(sys.argv[4])
ours = np.fromfile(sys.argv[1], dtype=np.uint8).reshape(h, w, 4)[:, :, 3] > 0
ref = np.fromfile(sys.argv[2], dtype="<f4").reshape(h, w, 4)[:, :, 3] >= 0.5
for side, cols in (("west of 0", slice(0, w // 2)), ("east of 0", slice(w // 2, w))):
    o, r = int(ours[:, cols].sum()), int(ref[:, cols].sum())
    print(f"  {side}: {o} texels opaque, gdalwarp {r}")
    assert abs(o - r) <= 0.002 * max(r, 1), (side, o, r)
    assert sys.argv[5] != "both" or o > 0, (side, "empty")
PY
    fail "$name: a side of the level is not as gdalwarp fills it"
}

WORLD_WM="-180,-$LAT,180,$LAT"
check world-wm WebMercatorQuad 3 "$WORLD_WM" world.tif
check world-crs84 WorldCRS84Quad 3 "-180,-90,180,90" world.tif
check g360-wm WebMercatorQuad 3 "$WORLD_WM" g360.tif
check g360-crs84 WorldCRS84Quad 3 "-180,-90,180,90" g360.tif
check am4326-crs84 WorldCRS84Quad 3 "$(extent am4326.tif 90)" am4326.tif
check am4326-wm WebMercatorQuad 3 "$(extent am4326.tif $LAT)" am4326.tif
# EPSG:3832's latitudes: gdalwarp's -te 150 -60 210 60, to about 1e-12.
check am3832-crs84 WorldCRS84Quad 3 "-180,-60,180,60" am3832.tif
check am3832-wm WebMercatorQuad 3 "-180,-60,180,60" am3832.tif

note "the whole world's level is the same whatever the tile size: 512-texel tiles, level 2"
expect_ok "$VTS" build world.tif --tiling WebMercatorQuad --tile 512 -o t512.pmtiles --json
json_check "$OUT" 'j.max_zoom === 2 && j.width === 2048' "level 2 of 512-texel tiles"

note "EPSG:3857 past x = 20037508 m: placed as gdalwarp places it, the rest named in a warning"
WARNS=1 HALVES=one check am3857 WorldCRS84Quad 4 "-180,0,180,10" am3857.tif --max-level 4
grep -q "am3857.tif: its part at longitudes -180 .. -170" am3857.build.err ||
  fail "no warning names the part left out: $(cat am3857.build.err)"
note "ok"
