#!/usr/bin/env bash
# Where `vts build` places georeferenced inputs, measured in fractions of a texel against gdalwarp,
# with real GDAL on real files made here from the Earth image by gdal_translate/gdalwarp/
# gdalbuildvrt: the EPSG:4326 halves, a piece in EPSG:3857 (onto WebMercatorQuad), pieces in two
# UTM zones (EPSG:32631, EPSG:32632) in one build, a COG, a VRT of 16 pieces, an input with nodata,
# 12-bit data in UInt16 (--range 0,4095), Int16 with negative values and Float32 (--range).
#
# Placement: for each case, the finest level `vts extract` writes is compared with what gdalwarp
# makes from the same inputs onto the same grid with the same resampling (Float32, mapped to codes
# as --range does). georef_placement.py estimates the sub-texel shift between the two by iterated
# least squares on the reference's gradients (ours(x,y) ~ ref(x+dx, y+dy) over texels opaque in
# both and textured) and the test asserts |(dx, dy)| <= 0.25 texel, printing the measured shift.
# The bound: the issue asks for 0.5 texel; half a texel is exactly what a pixel-corner/pixel-centre
# confusion costs, so a bound of 0.5 would pass that mistake on its boundary. 0.25 rejects it with
# margin while staying far above what the measurement can resolve (its error on known shifts is
# below 0.05 texel: checked here on a reference moved by (+0.5, +0.25) texel and on our level
# moved by one whole texel). Colours: mean |diff| <= 1 code, p99 <= 4; transparency agreeing on
# >= 99.8% of texels.
#
# Bounds: `vts info`, the PMTiles header (read by the npm `pmtiles` library), TileJSON and the
# tile matrix set's limits (from `vts serve` on loopback) equal the union of the inputs' extents
# to 1e-7 degrees; each extent is computed here by gdaltransform on 2001 points along every edge
# of the raster (so a UTM piece's northernmost point, in the middle of its north edge, counts).
# Tile counts are the footprint's (FORMAT.md §6, computed in Python), not the planet's.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
# shellcheck source=serve_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/serve_lib.sh"
: "${PMTILES_JS:?PMTILES_JS must name tests/integration/pmtiles_js}"
HERE=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
for t in python3 gdal_translate gdalwarp gdalinfo gdalbuildvrt gdaltransform "$NODE"; do
  require_tool "$t"
done
[[ -f $PMTILES_JS/node_modules/pmtiles/package.json ]] ||
  fail "npm package pmtiles is not installed in $PMTILES_JS (run scripts/setup.sh)"
# numpy: Debian's python3-numpy, which a python3 earlier on PATH (pyenv, a venv) may not see.
PY=""
for p in ${PYTHON3:-} python3 /usr/bin/python3; do
  if command -v "$p" >/dev/null && "$p" -c 'import numpy' 2>/dev/null; then
    PY=$p
    break
  fi
done
[[ -n $PY ]] || fail "no python3 that imports numpy (Debian package python3-numpy; scripts/setup.sh)"
M=20037508.342789244

cd "$WORK"
mkdir -p archives
T() { gdal_translate -q "$@" || fail "gdal_translate $*"; }
W() { gdalwarp -q "$@" || fail "gdalwarp $*"; }
T -a_srs EPSG:4326 -a_ullr -180 90 180 -90 "$EARTH" world.tif
T -srcwin 0 0 1024 1024 world.tif west.tif
T -srcwin 1024 0 1024 1024 world.tif east.tif
W -t_srs EPSG:3857 -te_srs EPSG:4326 -te -20 -35 50 40 -r bilinear world.tif merc.tif
# Zone 31 (central meridian 3 E) across its central meridian, Europe and West Africa; zone 32
# (9 E) from the equator up, North and Central Africa; they overlap between about 4.5 and 12 E.
# The zone 31 piece is centred on its meridian, where its north edge peaks in latitude and where
# the builder's 21-point densified extent has a point: georef_bounds_edge_extreme.sh has a piece
# off-centre, whose bounds the builder gets wrong today.
W -t_srs EPSG:32631 -te -100000 1000000 1100000 5800000 -tr 8000 8000 -r bilinear world.tif utm31.tif
W -t_srs EPSG:32632 -te 0 0 1000000 4500000 -tr 8000 8000 -r bilinear world.tif utm32.tif
T -of COG -co COMPRESS=DEFLATE -co OVERVIEWS=AUTO -projwin -130 60 -30 -60 world.tif cog.tif
gdalinfo cog.tif | grep -q "LAYOUT=COG" || fail "cog.tif is not a COG"
gdalinfo cog.tif | grep -q "Overviews:" || fail "cog.tif has no overviews"
for i in $(seq 0 15); do # 4 x 4 pieces of 512 x 256
  # shellcheck disable=SC2017  # integer division intended: the row of piece i
  T -srcwin $((i % 4 * 512)) $((i / 4 * 256)) 512 256 world.tif "piece$i.tif"
done
gdalbuildvrt -q pieces.vrt piece*.tif || fail "gdalbuildvrt"
# Longitudes -60..0 of it have no data (0, declared as nodata): transparent.
W -te -60 -60 60 60 -dstnodata 0 east.tif nodata.tif
T -ot UInt16 -scale 0 255 0 4095 -projwin 60 60 150 0 world.tif u12.tif
T -ot Int16 -scale 0 255 -12800 12700 -projwin -100 20 -30 -60 world.tif i16.tif
T -ot Float32 -scale 0 255 -1 1 -projwin 100 -5 180 -50 world.tif f32.tif
"$PY" - <<'PY' || fail "the typed inputs do not hold the values they should"
import subprocess, json
def stats(f):
    j = json.loads(subprocess.check_output(["gdalinfo", "-json", "-mm", f]))
    return j["bands"][0]["type"], j["bands"][0]["computedMin"], j["bands"][0]["computedMax"]
t, lo, hi = stats("u12.tif"); assert t == "UInt16" and 0 <= lo and 3000 < hi <= 4095, (t, lo, hi)
t, lo, hi = stats("i16.tif"); assert t == "Int16" and lo < -10000 and hi > 0, (t, lo, hi)
t, lo, hi = stats("f32.tif"); assert t == "Float32" and lo < -0.5 and 0.5 < hi <= 1, (t, lo, hi)
PY

# extent FILE: W,S,E,N of FILE in degrees from gdaltransform of 2001 points along each edge.
extent() {
  local size
  size=$("$PY" -c 'import json,sys; print(*json.load(sys.stdin)["size"])' < <(gdalinfo -json "$1"))
  # shellcheck disable=SC2086
  "$PY" - $size <<'PY' | gdaltransform -t_srs EPSG:4326 "$1" >"$1.edges" || fail "gdaltransform $1"
import sys
w, h = map(int, sys.argv[1:])
for i in range(2001):
    f = i / 2000
    for x, y in ((f * w, 0), (f * w, h), (0, f * h), (w, f * h)):
        print(repr(x), repr(y))
PY
  "$PY" - "$1.edges" <<'PY'
import sys
pts = [tuple(map(float, l.split()[:2])) for l in open(sys.argv[1]) if l.strip()]
assert len(pts) == 8004, len(pts)
lon, lat = [p[0] for p in pts], [p[1] for p in pts]
print(",".join(repr(v) for v in (min(lon), min(lat), max(lon), max(lat))))
PY
}

# check NAME SCHEME MAXZ RESAMPLING BANDS INPUT...: build INPUTs (with --range $RANGE when set),
# check bounds and tile count, and measure the finest level against gdalwarp's.
check() {
  local name=$1 scheme=$2 maxz=$3 r=$4 bands=$5 w h srs te bbox lo=0 hi=255
  shift 5
  note "$name: $* onto $scheme level $maxz ($r${RANGE:+, --range $RANGE})"
  expect_ok "$VTS" build "$@" --tiling "$scheme" --max-level "$maxz" --resampling "$r" \
    ${RANGE:+--range=$RANGE} -o "archives/$name.pmtiles" --threads 2 -q
  bbox=$(for f in "$@"; do extent "$f"; done | "$PY" -c '
import sys
b = [list(map(float, l.split(","))) for l in sys.stdin]
lim = 85.05112877980659 if sys.argv[1] == "WebMercatorQuad" else 90
print(",".join(repr(v) for v in (max(min(x[0] for x in b), -180), max(min(x[1] for x in b), -lim),
                                 min(max(x[2] for x in b), 180), min(max(x[3] for x in b), lim))))
' "$scheme")
  echo "$bbox" >"$name.bbox"
  echo "$scheme $maxz" >"$name.scheme"
  expect_ok "$VTS" info "archives/$name.pmtiles" --json
  cp "$OUT" "$name.info.json"
  "$PY" - "$name.info.json" "$bbox" "$(python3 count.py "$maxz" 256 "$bbox" "$scheme")" \
    "$maxz" "$scheme" <<'PY' || fail "$name: bounds, tile count or level differ (want $bbox)"
import json, sys
i = json.load(open(sys.argv[1]))
want = [float(v) for v in sys.argv[2].split(",")]
g = i["georeference"]
print(f"  bounds {g['bounds']}, want {want}; tiles {i['tiles']} of the full grid's {g['tiles_full_grid']}")
assert g["tiling"] == sys.argv[5], g
assert all(abs(a - b) <= 1e-7 for a, b in zip(g["bounds"], want)), (g["bounds"], want)
assert i["tiles"] == g["tiles_present"] == int(sys.argv[3]), (i["tiles"], g, sys.argv[3])
assert i["max_zoom"] == int(sys.argv[4]) and i["sparse"] is True, i
if want[2] - want[0] < 180:  # a regional archive: fewer tiles than the planet's
    assert i["tiles"] < g["tiles_full_grid"], (i["tiles"], g["tiles_full_grid"])
PY
  w=$((256 << maxz))
  if [[ $scheme == WorldCRS84Quad ]]; then
    h=$((w / 2)) srs=EPSG:4326 te=(-180 -90 180 90)
  else
    h=$w srs=EPSG:3857 te=("-$M" "-$M" "$M" "$M")
  fi
  [[ -n ${RANGE:-} ]] && IFS=, read -r lo hi <<<"$RANGE"
  expect_ok "$VTS" extract "archives/$name.pmtiles" --level "$maxz" -o "$name.level.tif"
  T -of ENVI -co INTERLEAVE=BIP "$name.level.tif" "$name.ours.bil"
  W -t_srs "$srs" -te "${te[@]}" -ts "$w" "$h" -r "$r" -et 0 -ot Float32 -dstalpha \
    -wo DST_ALPHA_MAX=255 -of ENVI -co INTERLEAVE=BIP "$@" "$name.ref.bil"
  "$PY" "$HERE/georef_placement.py" compare "$name.ours.bil" "$name.ref.bil" "$w" "$h" "$bands" \
    "$lo" "$hi" "$name" ${NODATA_COLS:+"$NODATA_COLS"} >"$name.cmp" || {
    cat "$name.cmp"
    fail "$name: not where gdalwarp puts it, or not what it puts there"
  }
  tee -a shifts.txt <"$name.cmp"
}

# count.py MAXZ T W,S,E,N SCHEME: the footprint's tile count (FORMAT.md §6).
cp "$HERE/footprint_count.py" count.py

: >shifts.txt
check halves WorldCRS84Quad 3 cubic 3 west.tif east.tif
check east WorldCRS84Quad 3 bilinear 3 east.tif
check merc WebMercatorQuad 3 bilinear 3 merc.tif
check utm WorldCRS84Quad 4 bilinear 3 utm31.tif utm32.tif
check cog WorldCRS84Quad 2 cubic 3 cog.tif
check vrt16 WorldCRS84Quad 3 cubic 3 pieces.vrt
# Level 3: 2048 texels around the globe; the nodata spans longitudes -60..0: columns 683..1024.
NODATA_COLS=683,1024 check nodata WorldCRS84Quad 3 cubic 3 nodata.tif
RANGE=0,4095 check u12 WorldCRS84Quad 4 bilinear 3 u12.tif
RANGE=-12800,12700 check i16 WorldCRS84Quad 3 lanczos 3 i16.tif
RANGE=-1,1 check f32 WorldCRS84Quad 3 cubic 3 f32.tif

note "the measurement measures: gdalwarp's reference moved by (+0.5, +0.25) texel, ours by one"
# vrt16 at level 3 (2048 x 1024, 0.17578125 degrees a texel): the grid moved half a texel east
# and a quarter south, so ref'(x, y) = ref(x + 0.5, y + 0.25) and ours ~ ref'(x - 0.5, y - 0.25).
C=0.17578125
read -r XW XE YS YN < <(awk -v c=$C 'BEGIN { printf "%.12f %.12f %.12f %.12f\n", -180 + c / 2, 180 + c / 2, -90 - c / 4, 90 - c / 4 }')
W -t_srs EPSG:4326 -te "$XW" "$YS" "$XE" "$YN" -ts 2048 1024 -r cubic -et 0 -ot Float32 -dstalpha \
  -wo DST_ALPHA_MAX=255 -of ENVI -co INTERLEAVE=BIP pieces.vrt moved.ref.bil
"$PY" "$HERE/georef_placement.py" calibrate vrt16.ours.bil moved.ref.bil 2048 1024 3 -0.5 -0.25 ||
  fail "the shift measurement does not measure a known shift"
if "$PY" "$HERE/georef_placement.py" compare vrt16.ours.bil moved.ref.bil 2048 1024 3 0 255 \
  vrt16-against-the-moved-grid >moved.cmp; then
  fail "a level half a texel from gdalwarp's passes the placement check: $(cat moved.cmp)"
fi
grep -q "placed 0.5[0-9]* texels from gdalwarp's" moved.cmp || fail "moved: $(cat moved.cmp)"

note "header, TileJSON and tile matrix set limits carry the footprint (vts serve on loopback)"
start_server archives
for f in archives/*.pmtiles; do
  name=$(basename "$f" .pmtiles)
  read -r scheme maxz <"$name.scheme"
  "$NODE" "$PMTILES_JS/dump.mjs" header "$f" >"$name.header" || fail "dump.mjs header $name"
  curl -sf "$BASE/$name.json" -o "$name.tilejson" || fail "GET /$name.json"
  curl -sf "$BASE/$name/tilematrixset.json" -o "$name.tms" || fail "GET /$name/tilematrixset.json"
  "$PY" - "$name" "$(cat "$name.bbox")" "$scheme" "$maxz" <<'PY' || fail "$name: served bounds"
import json, math, sys
name, scheme, maxz = sys.argv[1], sys.argv[3], int(sys.argv[4])
bbox = [float(v) for v in sys.argv[2].split(",")]
h = dict(l.strip().split("=", 1) for l in open(name + ".header") if "=" in l)
got = [int(h[k]) / 1e7 for k in ("min_lon_e7", "min_lat_e7", "max_lon_e7", "max_lat_e7")]
assert all(abs(a - b) <= 1e-7 + 1e-12 for a, b in zip(got, bbox)), ("header", got, bbox)
tj = json.load(open(name + ".tilejson"))
assert all(abs(a - b) <= 1e-7 for a, b in zip(tj["bounds"], bbox)), ("TileJSON", tj["bounds"], bbox)
assert tj["maxzoom"] == maxz, tj
# The limits: the footprint's tile ranges per level; TMS level k is our k+1 on WorldCRS84Quad.
crs84 = scheme == "WorldCRS84Quad"
N = 256 * 2 ** maxz
def ty(lat):
    if crs84:
        return (90 - lat) / 360 * N
    return (1 - math.log(math.tan(math.pi / 4 + math.radians(lat) / 2)) / math.pi) / 2 * N
def snap(v, f):
    r = round(v)
    return r if abs(v - r) <= 1e-6 else f(v)
x0, y0 = snap((bbox[0] + 180) / 360 * N, math.floor), snap(ty(bbox[3]), math.floor)
x1, y1 = min(snap((bbox[2] + 180) / 360 * N, math.ceil), N), min(snap(ty(bbox[1]), math.ceil), N // 2 if crs84 else N)
t = json.load(open(name + ".tms"))
assert t["id"] == scheme, t["id"]
ls = t["tileMatrixSetLimits"]
assert len(ls) == (maxz if crs84 else maxz + 1), ls
for l in ls:
    z = int(l["tileMatrix"]) + (1 if crs84 else 0)
    d = maxz - z
    want = {"tileMatrix": l["tileMatrix"], "minTileCol": (x0 >> d) // 256, "minTileRow": (y0 >> d) // 256,
            "maxTileCol": -(-(-(-x1 // 2 ** d)) // 256) - 1, "maxTileRow": -(-(-(-y1 // 2 ** d)) // 256) - 1}
    assert l == want, ("limits", l, want)
print(f"  {name}: header {got}, TileJSON {tj['bounds']}, {len(ls)} tile matrix limits")
PY
done
stop_server

note "measured shifts (texels; ours(x, y) ~ gdalwarp(x + dx, y + dy))"
grep -o '^[a-z0-9]*: shift [^(]*' shifts.txt
note "ok"
