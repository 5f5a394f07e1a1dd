#!/usr/bin/env bash
# vts build of georeferenced rasters (GDAL) onto WorldCRS84Quad, end to end with real GeoTIFFs made
# from the Earth image by gdal_translate/gdalwarp: the whole world, its west half, a piece in
# EPSG:3857, an input with nodata, two overlapping inputs, a 16-bit input. For each, `vts info`
# shows the input's extent as bounds (1e-7 degrees; expected values computed here from gdalinfo's
# corner coordinates), the tile count is the footprint's (FORMAT.md §6, computed in Python), and
# the finest level `vts extract` writes matches what gdalwarp makes onto the same grid with the same
# resampling (over texels opaque in both: mean absolute difference <= 1 code, 99th percentile <= 4
# codes, and one texel of shift at least doubles the mean; transparency agreeing on >= 99.8% of
# texels). Not exact: GDAL's warper widens its kernel when it downsamples by a scale it measures
# per chunk, and our windows are not gdalwarp's chunks (0.25 mean, 3 at p99 for the Mercator piece). The identity case (the world at its own resolution, nearest) is
# checked exactly against the input's pixels. A truncated GeoTIFF exits 5 and leaves nothing.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
HERE=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
require_tool python3
require_tool gdal_translate
require_tool gdalwarp
require_tool gdalinfo

cd "$WORK"
T() { gdal_translate -q "$@" || fail "gdal_translate $*"; }
T -a_srs EPSG:4326 -a_ullr -180 90 180 -90 "$EARTH" world.tif
T -srcwin 0 0 1024 1024 world.tif west.tif
T -a_ullr 0 90 180 -90 west.tif moved.tif # the west half's pixels labelled as the east half
T -outsize 2100 1050 world.tif fine.tif
T -ot UInt16 -scale 0 255 0 65535 world.tif u16.tif
gdalwarp -q -t_srs EPSG:3857 -te_srs EPSG:4326 -te 0 20 40 60 -r bilinear world.tif merc.tif ||
  fail "gdalwarp merc"
gdalwarp -q -te -180 -90 90 90 -dstnodata 0 west.tif padded.tif || fail "gdalwarp padded"
T -b 1 world.tif grey.tif
T -b 1 -b 2 -b 3 -b mask -a_nodata none -co ALPHA=YES padded.tif rgba.tif # nodata as alpha

# raw FILE OUT: pixel-interleaved bytes of a raster (gdal_translate to ENVI, BIP).
raw() { T -of ENVI -co INTERLEAVE=BIP "$1" "$2"; }

# extent.py FILE.json: the raster's extent in degrees from gdalinfo -json's corner coordinates
# (EPSG:3857 inverted here with the spherical Mercator formula).
cat >extent.py <<'PY'
import json, math, sys
j = json.load(open(sys.argv[1]))
c = j["cornerCoordinates"]
x0, y1 = c["upperLeft"]; x1, y0 = c["lowerRight"]
if "3857" in json.dumps(j["coordinateSystem"]["wkt"])[-40:] or "Pseudo-Mercator" in j["coordinateSystem"]["wkt"]:
    R = 6378137.0
    lon = lambda x: math.degrees(x / R)
    lat = lambda y: math.degrees(math.atan(math.sinh(y / R)))
    x0, x1, y0, y1 = lon(x0), lon(x1), lat(y0), lat(y1)
print(",".join(repr(v) for v in (x0, y0, x1, y1)))
PY
# count.py MAXZ T W,S,E,N [SCHEME]: the footprint's tile count (footprint_count.py).
cp "$HERE/footprint_count.py" count.py
# compare.py OURS.bil REF.bil W H: ours is RGBA; the reference grey+alpha or RGB+alpha. Over the
# texels opaque in both: the mean and 99th percentile of the absolute colour difference, and the
# placement: shifting ours by one texel in any direction must make the mean at least twice worse.
cat >compare.py <<'PY'
import sys
a, b = open(sys.argv[1], "rb").read(), open(sys.argv[2], "rb").read()
w, h = int(sys.argv[3]), int(sys.argv[4])
n = w * h
assert len(a) == 4 * n, (len(a), n)
rc = len(b) // n
assert rc in (2, 4), rc
alpha_bad = sum(1 for i in range(n) if (a[4 * i + 3] > 0) != (b[rc * i + rc - 1] > 0))
both = [i for i in range(n) if a[4 * i + 3] == 255 and b[rc * i + rc - 1] == 255]
assert len(both) >= 10000, ("too few opaque texels to compare", len(both))
def diffs(dx, dy, step):
    hist = [0] * 256
    for i in both[::step]:
        x, y = i % w + dx, i // w + dy
        if not (0 <= x < w and 0 <= y < h) or a[4 * (y * w + x) + 3] != 255:
            continue
        j = y * w + x
        for k in range(3):
            hist[abs(a[4 * j + k] - b[rc * i + (k if rc == 4 else 0)])] += 1
    total = sum(hist)
    return hist, sum(d * c for d, c in enumerate(hist)) / total, total
hist, mean, total = diffs(0, 0, 1)
acc, p99 = 0, 0
for d, c in enumerate(hist):
    acc += c
    if acc >= 0.99 * total:
        p99 = d
        break
shifted = min(diffs(dx, dy, 3)[1] for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)))
print(f"opaque {len(both)} texels: mean |diff| {mean:.3f}, p99 {p99}, "
      f"max {max(d for d, c in enumerate(hist) if c)}; shifted by one texel: mean {shifted:.3f}; "
      f"alpha disagrees on {alpha_bad}")
assert mean <= 1.0 and p99 <= 4, "pixels differ from gdalwarp's"
assert mean * 2 <= shifted, "placement is off by about a texel"
assert alpha_bad <= 0.002 * n, "transparency differs from gdalwarp's"
PY

# check NAME INPUT MAXZ RESAMPLING [vts build options...]: build, check bounds, tile count, and the
# finest level against gdalwarp's onto the same grid (of $REF_INPUT when set: an 8-bit equivalent).
check() {
  local name=$1 input=$2 maxz=$3 r=$4 w h bbox
  shift 4
  note "$name: $input at level $maxz ($r)"
  expect_ok "$VTS" build "$input" --tiling WorldCRS84Quad --max-level "$maxz" --resampling "$r" \
    -o "$name.pmtiles" --threads 2 --json "$@"
  cp "$OUT" "$name.build.json"
  gdalinfo -json "$input" >"$name.gdalinfo.json" || fail "gdalinfo $input"
  bbox=$(python3 extent.py "$name.gdalinfo.json")
  expect_ok "$VTS" info "$name.pmtiles" --json
  cp "$OUT" "$name.info.json"
  python3 - "$name.info.json" "$bbox" "$(python3 count.py "$maxz" 256 "$bbox")" "$maxz" <<'PY' ||
import json, sys
i = json.load(open(sys.argv[1]))
want = [float(v) for v in sys.argv[2].split(",")]
g = i["georeference"]
assert g["tiling"] == "WorldCRS84Quad" and g["crs"] == "OGC:CRS84", g
assert all(abs(a - b) <= 1e-7 for a, b in zip(g["bounds"], want)), (g["bounds"], want)
assert i["tiles"] == g["tiles_present"] == int(sys.argv[3]), (i["tiles"], g, sys.argv[3])
assert i["max_zoom"] == int(sys.argv[4]) and i["sparse"] is True, i
PY
    fail "$name: bounds, tile count or level differ (want bounds $bbox)"
  w=$((256 << maxz))
  h=$((w / 2))
  expect_ok "$VTS" extract "$name.pmtiles" --level "$maxz" -o "$name.level.tif"
  raw "$name.level.tif" "$name.ours.bil"
  gdalwarp -q -t_srs EPSG:4326 -te -180 -90 180 90 -ts "$w" "$h" -r "$r" -et 0 -dstalpha -of ENVI \
    -co INTERLEAVE=BIP "${REF_INPUT:-$input}" "$name.ref.bil" || fail "gdalwarp reference for $name"
  python3 compare.py "$name.ours.bil" "$name.ref.bil" "$w" "$h" || fail "$name: pixels"
}

check world world.tif 2 cubic
check west west.tif 3 cubic
check merc merc.tif 3 bilinear
check padded padded.tif 3 cubic
python3 - padded.ours.bil <<'PY' || fail "padded: its nodata part is not transparent"
import sys
a = open(sys.argv[1], "rb").read()
# Level 3 is 2048 x 1024; the input's nodata covers longitudes 0..90: columns 1024..1536.
bad = [(x, y) for y in range(0, 1024, 3) for x in range(1026, 1534, 3) if a[4 * (y * 2048 + x) + 3] != 0]
assert not bad, bad[:5]
assert all(a[4 * (y * 2048 + 500) + 3] == 255 for y in range(1024)), "the data part is not opaque"
PY
check grey grey.tif 2 near
check rgba rgba.tif 3 cubic
# u16.tif is world.tif * 257: with --range 0,65535 it maps back to the 8-bit values.
REF_INPUT=world.tif check u16 u16.tif 2 lanczos --range 0,65535

note "WebMercatorQuad: the west half, clipped to +-85.0511 degrees, against gdalwarp in EPSG:3857"
expect_ok "$VTS" build west.tif --tiling WebMercatorQuad --max-level 3 --resampling bilinear \
  -o wm.pmtiles --threads 2
expect_ok "$VTS" info wm.pmtiles --json
cp "$OUT" wm.info.json
WM_BBOX="-180,-85.05112877980659,0,85.05112877980659"
python3 - wm.info.json "$WM_BBOX" "$(python3 count.py 3 256 "$WM_BBOX" WebMercatorQuad)" <<'PY' ||
import json, sys
i = json.load(open(sys.argv[1]))
g = i["georeference"]
want = [float(v) for v in sys.argv[2].split(",")]
assert g["tiling"] == "WebMercatorQuad" and g["crs"] == "EPSG:3857", g
assert all(abs(a - b) <= 1e-7 for a, b in zip(g["bounds"], want)), (g["bounds"], want)
assert i["tiles"] == int(sys.argv[3]) and i["width"] == i["height"] == 2048, (i["tiles"], sys.argv[3])
PY
  fail "WebMercatorQuad: bounds, tile count or size"
expect_ok "$VTS" extract wm.pmtiles --level 3 -o wm.tif
raw wm.tif wm.bil
M=20037508.342789244
gdalwarp -q -t_srs EPSG:3857 -te -$M -$M $M $M -ts 2048 2048 -r bilinear -et 0 -dstalpha \
  -of ENVI -co INTERLEAVE=BIP west.tif wm.ref.bil || fail "gdalwarp WebMercatorQuad reference"
python3 compare.py wm.bil wm.ref.bil 2048 2048 || fail "WebMercatorQuad: pixels"

note "the identity: the world at its own resolution (level chosen from it), nearest, is the input"
expect_ok "$VTS" build world.tif --resampling near -o same.pmtiles --threads 2 --json
json_check "$OUT" 'j.max_zoom === 3 && j.width === 2048 && j.height === 1024' "level 3 chosen"
expect_ok "$VTS" extract same.pmtiles --level 3 -o same.tif
raw same.tif same.bil
raw world.tif world.bil
python3 - same.bil world.bil <<'PY' || fail "the identity build moved or changed pixels"
import sys
a, b = open(sys.argv[1], "rb").read(), open(sys.argv[2], "rb").read()
assert len(a) == 2048 * 1024 * 4 and len(b) == 2048 * 1024 * 3
assert all(a[4 * i + 3] == 255 for i in range(0, 2048 * 1024, 997)), "not opaque"
bad = sum(1 for i in range(2048 * 1024) if a[4 * i:4 * i + 3] != b[3 * i:3 * i + 3])
assert bad == 0, f"{bad} texels differ"
PY

expect_ok "$VTS" info same.pmtiles --json
json_check "$OUT" 'j.georeference.tiling === "WorldCRS84Quad"' "WorldCRS84Quad by default"

note "inputs in different CRSs (EPSG:4326, EPSG:3857) together, as gdalwarp composites them"
expect_ok "$VTS" build world.tif merc.tif --max-level 3 --resampling bilinear -o mixed.pmtiles
expect_ok "$VTS" extract mixed.pmtiles --level 3 -o mixed.tif
raw mixed.tif mixed.bil
gdalwarp -q -t_srs EPSG:4326 -te -180 -90 180 90 -ts 2048 1024 -r bilinear -et 0 -dstalpha \
  -of ENVI -co INTERLEAVE=BIP world.tif merc.tif mixed.ref.bil || fail "gdalwarp mixed"
python3 compare.py mixed.bil mixed.ref.bil 2048 1024 || fail "mixed CRSs: pixels"

note "several inputs: the footprint is the union of their extents"
expect_ok "$VTS" build west.tif merc.tif --max-level 2 -o union.pmtiles
expect_ok "$VTS" info union.pmtiles --json
cp "$OUT" union.info.json
gdalinfo -json merc.tif >merc.gdalinfo.json || fail "gdalinfo merc.tif"
python3 - union.info.json "$(python3 extent.py merc.gdalinfo.json)" <<'PY' || fail "union bounds"
import json, sys
b = json.load(open(sys.argv[1]))["georeference"]["bounds"]
m = [float(v) for v in sys.argv[2].split(",")]
want = [-180, -90, max(0, m[2]), 90]
assert all(abs(x - y) <= 1e-7 for x, y in zip(b, want)), (b, want)
PY

note "the level rule: the first level whose texel is no larger than the input's pixel"
expect_ok "$VTS" build fine.tif -o fine.pmtiles --threads 2 --json
json_check "$OUT" 'j.max_zoom === 4' "2100 px around the globe -> level 4 (4096 texels)"

note "later inputs win where they have data"
expect_ok "$VTS" build world.tif moved.tif --resampling near --max-level 3 -o two.pmtiles --json
expect_ok "$VTS" extract two.pmtiles --level 3 -o two.tif
raw two.tif two.bil
python3 - two.bil world.bil <<'PY' || fail "the second input does not cover the first"
import sys
a, b = open(sys.argv[1], "rb").read(), open(sys.argv[2], "rb").read()
for y in range(0, 1024, 7):
    for x in range(0, 2048, 5):
        src = x if x < 1024 else x - 1024  # the east half shows the west half's pixels
        got, want = a[4 * (y * 2048 + x):4 * (y * 2048 + x) + 3], b[3 * (y * 2048 + src):3 * (y * 2048 + src) + 3]
        assert got == want, (x, y, got, want)
PY

note "refusals"
expect_clean_failure "$VTS" build u16.tif -o x.pmtiles
((RC == 2)) || fail "16-bit without --range exited $RC, expected 2"
grep -q "u16.tif" "$ERR" && grep -q -- "--range" "$ERR" && grep -q "65535" "$ERR" ||
  fail "16-bit without --range: $(cat "$ERR")"
expect_clean_failure "$VTS" build "$EARTH" --tiling WorldCRS84Quad -o x.pmtiles
grep -q "no georeference" "$ERR" || fail "a plain image with --tiling: $(cat "$ERR")"
expect_clean_failure "$VTS" build world.tif --max-level 23 -o x.pmtiles
((RC == 6)) || fail "a grid beyond the width limit exited $RC, expected 6"
grep -q "1073741824" "$ERR" || fail "the width limit is not named: $(cat "$ERR")"
expect_clean_failure "$VTS" build world.tif --range 5,1 -o x.pmtiles
grep -q -- "--range" "$ERR" || fail "a bad --range: $(cat "$ERR")"

mkfifo fifo.tif
expect_clean_failure "$VTS" build fifo.tif --tiling WorldCRS84Quad -o x.pmtiles
grep -q "fifo.tif" "$ERR" || fail "a FIFO input with --tiling: $(cat "$ERR")"
[[ ! -e x.pmtiles ]] || fail "a refused build left an output file"

# (An input crossing the antimeridian is built, not refused: georef_world.sh.)

note "a truncated GeoTIFF exits 5, names the file and leaves nothing"
head -c 3000000 world.tif >trunc.tif
expect_clean_failure "$VTS" build trunc.tif -o trunc.pmtiles
((RC == 5)) || fail "a truncated GeoTIFF exited $RC, expected 5"
grep -q "trunc.tif" "$ERR" || fail "the error does not name the file: $(cat "$ERR")"
[[ ! -e trunc.pmtiles ]] || fail "a failed build left its output"
ls -A | grep -q "trunc.pmtiles" && fail "a failed build left a temporary file"
note "ok"
