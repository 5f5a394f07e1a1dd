#!/usr/bin/env bash
# A projected input's footprint includes the extreme of an edge that lies between its corners. A
# UTM zone 31 piece at 62..68 N spanning 1.5 zones west and east of the central meridian (3 E): its
# north edge (constant northing) is highest in latitude at the central meridian, mid-edge.
# OCTTransformBounds(..., 21) alone (21 points per edge, none at 3 E here: the meridian falls
# midway between two of them) gave 67.6072 instead of 67.6155 degrees and cut the texel rows
# between from the footprint (gdalwarp makes them opaque); gdal_source.cpp's
# widen_to_edge_extremes() refines every edge's extremes.
# Checked: `vts info` bounds equal the extent gdaltransform gives for 20001 points along each edge
# (1e-7 degrees), and in the level-8 tile over the central meridian's top every texel gdalwarp
# makes opaque (same grid, same resampling) is not transparent in ours.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
for t in python3 gdal_translate gdalwarp gdaltransform; do
  require_tool "$t"
done
cd "$WORK"
gdal_translate -q -a_srs EPSG:4326 -a_ullr -180 90 180 -90 "$EARTH" world.tif ||
  fail "gdal_translate"
# 3080 km wide in 22 densification segments of 140 km; the central meridian (x = 500 km) at the
# middle of the 11th: 70 km from the nearest densified point.
gdalwarp -q -t_srs EPSG:32631 -te -970000 7300000 2110000 7500000 -tr 4000 4000 -r bilinear \
  world.tif top.tif || fail "gdalwarp top.tif"

python3 -c '
for i in range(20001):
    f = i / 20000
    for x, y in ((f * 770, 0), (f * 770, 50), (0, f * 50), (770, f * 50)):
        print(x, y)' | gdaltransform -t_srs EPSG:4326 top.tif >edges.txt || fail "gdaltransform"
BBOX=$(python3 -c '
import sys
p = [tuple(map(float, l.split()[:2])) for l in open("edges.txt") if l.strip()]
assert len(p) == 80004, len(p)
print(",".join(repr(f(v[k] for v in p)) for f, k in ((min, 0), (min, 1), (max, 0), (max, 1))))')

note "bounds: the extent along the whole edges, $BBOX"
expect_ok "$VTS" build top.tif --max-level 8 --resampling bilinear -o top.pmtiles --threads 2 -q
expect_ok "$VTS" info top.pmtiles --json
cp "$OUT" info.json
bounds_ok=1
python3 - info.json "$BBOX" <<'PY' || bounds_ok=0
import json, sys
b = json.load(open(sys.argv[1]))["georeference"]["bounds"]
want = [float(v) for v in sys.argv[2].split(",")]
print(f"  vts info bounds {b}\n  want            {want}")
bad = [(k, g, w) for k, g, w in zip(("west", "south", "east", "north"), b, want) if abs(g - w) > 1e-7]
for k, g, w in bad:
    print(f"  {k}: {g!r} is {abs(g - w):.3g} degrees from {w!r}")
sys.exit(1 if bad else 0)
PY

note "texels: tile 8/130/15 (lon 2.8125..4.21875, lat 67.5..68.90625) against gdalwarp's"
expect_ok "$VTS" extract top.pmtiles 8/130/15 -o tile.tif
gdal_translate -q -of ENVI -co INTERLEAVE=BIP tile.tif tile.bil || fail "gdal_translate tile"
gdalwarp -q -t_srs EPSG:4326 -te 2.8125 67.5 4.21875 68.90625 -ts 256 256 -r bilinear -et 0 \
  -dstalpha -of ENVI -co INTERLEAVE=BIP top.tif ref.bil || fail "gdalwarp reference tile"
texels_ok=1
python3 - tile.bil ref.bil <<'PY' || texels_ok=0
import sys
a, b = open(sys.argv[1], "rb").read(), open(sys.argv[2], "rb").read()
assert len(a) == 256 * 256 * 4 and len(b) == 256 * 256 * 4, (len(a), len(b))
lost = [(i % 256, i // 256) for i in range(256 * 256) if b[4 * i + 3] >= 128 and a[4 * i + 3] == 0]
rows = sorted({y for _, y in lost})
print(f"  {len(lost)} texels opaque in gdalwarp's tile are transparent in ours (rows {rows})")
sys.exit(1 if lost else 0)
PY
((bounds_ok && texels_ok)) ||
  fail "the footprint misses the north edge's extreme at the central meridian"
note "ok"
