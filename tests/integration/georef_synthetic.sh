#!/usr/bin/env bash
# A sparse georeferenced synthetic planet end to end: `vts build --synthetic --tiling --bbox`
# writes only the footprint's tiles; `vts info` reports the georeference and coverage; `vts serve`
# answers TileJSON whose bounds are the footprint, and the OGC 2D Tile Matrix Set with the numbers
# the OGC registry publishes; the PMTiles header, read by the npm `pmtiles` library, carries the
# footprint to 1e-7 degrees. Expected tile counts and limits are computed here in Python from the
# definitions in docs/FORMAT.md §6, independently of the C++.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
# shellcheck source=serve_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/serve_lib.sh"
: "${PMTILES_JS:?PMTILES_JS must name tests/integration/pmtiles_js}"
require_tool python3
require_tool "$NODE"
[[ -f $PMTILES_JS/node_modules/pmtiles/package.json ]] ||
  fail "npm package pmtiles is not installed in $PMTILES_JS (run scripts/setup.sh)"

D="$WORK/tilesets"
mkdir -p "$D"
# WorldCRS84Quad TMS levels 0..5 = our levels 0..6 (16384 x 8192 texels); Europe-ish footprint.
GEO_BBOX="-10.5,35.25,30.125,60.1"
# WebMercatorQuad levels 0..6 (16384 x 16384); around Paris.
WEB_BBOX="2.2,48.8,2.5,48.95"

note "build a sparse WorldCRS84Quad and a WebMercatorQuad synthetic planet"
expect_ok "$VTS" build --synthetic 16384x8192 --tiling WorldCRS84Quad --bbox="$GEO_BBOX" \
  -o "$D/geo.pmtiles" --threads 2 --json
cp "$OUT" "$WORK/build_geo.json"
expect_ok "$VTS" build --synthetic 16384x16384 --tiling webmercatorquad --bbox="$WEB_BBOX" \
  -o "$D/web.pmtiles" --threads 2 --json
expect_ok "$VTS" build --synthetic 600x300 -o "$D/plain.pmtiles" --threads 2

note "refusals name what is wrong"
expect_clean_failure "$VTS" build "$EARTH" --tiling WorldCRS84Quad -o "$WORK/x.pmtiles"
grep -q "no georeference" "$ERR" || fail "a plain image with --tiling: $(cat "$ERR")"
expect_clean_failure "$VTS" build --synthetic 16000x8000 --tiling WorldCRS84Quad -o "$WORK/x.pmtiles"
grep -q "16384x8192" "$ERR" || fail "a wrong image size does not name the right one: $(cat "$ERR")"
expect_clean_failure "$VTS" build --synthetic 4096x2048 --tiling WorldCRS84Quad --bbox=170,0,-170,10 \
  -o "$WORK/x.pmtiles"
grep -q "antimeridian" "$ERR" || fail "an antimeridian bbox is not refused by name: $(cat "$ERR")"
expect_clean_failure "$VTS" build --synthetic 4096x4096 --tiling WebMercatorQuad --bbox=0,80,10,89 \
  -o "$WORK/x.pmtiles"
grep -q "extent" "$ERR" || fail "a bbox beyond 85.05 degrees is not refused: $(cat "$ERR")"
expect_clean_failure "$VTS" build --synthetic 4096x2048 --bbox=0,0,1,1 -o "$WORK/x.pmtiles"
grep -q -- "--bbox needs --tiling" "$ERR" || fail "--bbox without --tiling: $(cat "$ERR")"
expect_clean_failure "$VTS" build --synthetic 4096x2048 --tiling Mercator -o "$WORK/x.pmtiles"
grep -q "WorldCRS84Quad" "$ERR" || fail "an unknown scheme does not list the known ones"
expect_clean_failure "$VTS" build --synthetic 4096x2048 --tiling WorldCRS84Quad --bbox=1,2,3 \
  -o "$WORK/x.pmtiles"
[[ ! -e $WORK/x.pmtiles ]] || fail "a refused build left an output file"

# expected.py SCHEME MAXZ T BBOX: the footprint's tiles per level, as FORMAT.md §6 defines them.
cat >"$WORK/expected.py" <<'PY'
import json, math, sys
scheme, maxz, T, bbox = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
w, s, e, n = map(float, bbox.split(","))
N = T * 2 ** maxz
def tx(lon): return (lon + 180) / 360 * N
def ty(lat):
    if scheme == "WorldCRS84Quad": return (90 - lat) / 360 * N
    return (1 - math.log(math.tan(math.pi / 4 + math.radians(lat) / 2)) / math.pi) / 2 * N
W, H = N, (N // 2 if scheme == "WorldCRS84Quad" else N)
x0, y0 = math.floor(tx(w)), math.floor(ty(n))
x1, y1 = min(math.ceil(tx(e)), W), min(math.ceil(ty(s)), H)
levels = []
for z in range(maxz + 1):
    d = maxz - z
    lx0, ly0 = x0 >> d, y0 >> d
    lx1, ly1 = -(-x1 // 2 ** d), -(-y1 // 2 ** d)
    levels.append([lx0 // T, ly0 // T, -(-lx1 // T) - 1, -(-ly1 // T) - 1])
full = sum(-(-(W >> (maxz - z)) // T) * -(-(H >> (maxz - z)) // T) for z in range(maxz + 1))
count = sum((c1 - c0 + 1) * (r1 - r0 + 1) for c0, r0, c1, r1 in levels)
print(json.dumps({"levels": levels, "count": count, "full": full}))
PY
python3 "$WORK/expected.py" WorldCRS84Quad 6 256 "$GEO_BBOX" >"$WORK/expected_geo.json"
python3 "$WORK/expected.py" WebMercatorQuad 6 256 "$WEB_BBOX" >"$WORK/expected_web.json"

note "tile counts equal the footprint's"
python3 - "$WORK/build_geo.json" "$WORK/expected_geo.json" <<'PY' || fail "build tile count"
import json, sys
b, x = (json.load(open(p)) for p in sys.argv[1:])
assert b["tiles"] == x["count"], (b["tiles"], x["count"])
assert x["count"] < x["full"] / 10, x  # sparse indeed
PY

note "vts info shows tiling, CRS, bounds and coverage"
for t in geo web; do
  expect_ok "$VTS" info "$D/$t.pmtiles" --json
  cp "$OUT" "$WORK/info_$t.json"
done
python3 - "$WORK/info_geo.json" "$WORK/expected_geo.json" "$GEO_BBOX" <<'PY' || fail "info --json"
import json, sys
i, x = json.load(open(sys.argv[1])), json.load(open(sys.argv[2]))
bbox = [float(v) for v in sys.argv[3].split(",")]
g = i["georeference"]
assert g["tiling"] == "WorldCRS84Quad" and g["crs"] == "OGC:CRS84", g
assert g["bounds"] == bbox, (g["bounds"], bbox)
assert g["tiles_present"] == x["count"] == i["tiles"], (g, x)
assert g["tiles_full_grid"] == x["full"], (g, x)
assert i["sparse"] is True
PY
python3 - "$WORK/info_web.json" "$WORK/expected_web.json" <<'PY' || fail "info --json (web)"
import json, sys
i, x = json.load(open(sys.argv[1])), json.load(open(sys.argv[2]))
g = i["georeference"]
assert g["tiling"] == "WebMercatorQuad" and g["crs"] == "EPSG:3857", g
assert g["tiles_present"] == x["count"] and g["tiles_full_grid"] == x["full"], (g, x)
PY
expect_ok "$VTS" info "$D/geo.pmtiles"
grep -q "georef       WorldCRS84Quad (OGC:CRS84), bounds -10.5,35.25,30.125,60.1" "$OUT" ||
  fail "vts info does not show the georeference: $(cat "$OUT")"
grep -qE "coverage     $(json_get "$WORK/expected_geo.json" j.count) of the full grid's $(json_get "$WORK/expected_geo.json" j.full) tiles" "$OUT" ||
  fail "vts info does not show the coverage: $(cat "$OUT")"
expect_ok "$VTS" info "$D/plain.pmtiles" --json
python3 -c 'import json,sys; assert "georeference" not in json.load(open(sys.argv[1]))' "$OUT" ||
  fail "a plain image reports a georeference"

note "PMTiles header through the npm pmtiles library"
for t in geo web; do
  "$NODE" "$PMTILES_JS/dump.mjs" header "$D/$t.pmtiles" >"$WORK/header_$t.txt" ||
    fail "node dump.mjs header $t failed"
done
python3 - "$WORK/header_geo.txt" "$GEO_BBOX" 6 <<'PY' || fail "geo header fields"
import sys
h = dict(l.strip().split("=", 1) for l in open(sys.argv[1]) if "=" in l)
bbox = [float(v) for v in sys.argv[2].split(",")]
got = [int(h[k]) / 1e7 for k in ("min_lon_e7", "min_lat_e7", "max_lon_e7", "max_lat_e7")]
for g, b in zip(got, bbox):
    assert abs(g - b) <= 1e-7 + 1e-12, (got, bbox)
assert got[0] <= bbox[0] and got[1] <= bbox[1] and got[2] >= bbox[2] and got[3] >= bbox[3], got
assert int(h["min_zoom"]) == 0 and int(h["max_zoom"]) == int(sys.argv[3]), h
clon, clat = int(h["center_lon_e7"]) / 1e7, int(h["center_lat_e7"]) / 1e7
assert abs(clon - (bbox[0] + bbox[2]) / 2) <= 1e-7 and abs(clat - (bbox[1] + bbox[3]) / 2) <= 1e-7, h
assert 0 <= int(h["center_zoom"]) <= int(sys.argv[3]), h
PY
python3 - "$WORK/header_web.txt" "$WEB_BBOX" <<'PY' || fail "web header fields"
import sys
h = dict(l.strip().split("=", 1) for l in open(sys.argv[1]) if "=" in l)
bbox = [float(v) for v in sys.argv[2].split(",")]
got = [int(h[k]) / 1e7 for k in ("min_lon_e7", "min_lat_e7", "max_lon_e7", "max_lat_e7")]
assert all(abs(g - b) <= 1e-7 + 1e-12 for g, b in zip(got, bbox)), (got, bbox)
PY

note "vts serve: TileJSON bounds and center, the tile matrix set, a 404 for a plain image"
start_server "$D"
curl -sf -D "$WORK/tj.h" "$BASE/geo.json" -o "$WORK/geo.tilejson" || fail "GET /geo.json"
curl -sf -D "$WORK/tms.h" "$BASE/geo/tilematrixset.json" -o "$WORK/geo.tms" ||
  fail "GET /geo/tilematrixset.json"
curl -sf "$BASE/web/tilematrixset.json" -o "$WORK/web.tms" || fail "GET /web/tilematrixset.json"
curl -sf "$BASE/web.json" -o "$WORK/web.tilejson" || fail "GET /web.json"
expect_status 404 "$BASE/plain/tilematrixset.json"
curl -s "$BASE/plain/tilematrixset.json" | grep -q "not georeferenced" ||
  fail "the 404 does not say why"
for h in "$WORK/tj.h" "$WORK/tms.h"; do
  grep -qi '^cache-control: public, max-age=60' "$h" || fail "$h: Cache-Control"
  grep -qi '^access-control-allow-origin: \*' "$h" || fail "$h: CORS"
  grep -qi '^content-type: application/json' "$h" || fail "$h: Content-Type"
done
python3 - "$WORK/geo.tilejson" "$GEO_BBOX" <<'PY' || fail "TileJSON"
import json, sys
j = json.load(open(sys.argv[1]))
bbox = [float(v) for v in sys.argv[2].split(",")]
assert len(j["bounds"]) == 4 and all(abs(a - b) <= 1e-7 for a, b in zip(j["bounds"], bbox)), j["bounds"]
assert j["minzoom"] == 0 and j["maxzoom"] == 6, j
lon, lat, z = j["center"]
assert abs(lon - (bbox[0] + bbox[2]) / 2) < 1e-9 and abs(lat - (bbox[1] + bbox[3]) / 2) < 1e-9, j["center"]
assert isinstance(z, int) and 0 <= z <= 6, j["center"]
assert j["vtstream"]["georeference"]["tiling"] == "WorldCRS84Quad"
PY
check_tms() { # FILE SCHEME EXPECTED_JSON
  python3 - "$@" <<'PY'
import json, sys
t, scheme, x = json.load(open(sys.argv[1])), sys.argv[2], json.load(open(sys.argv[3]))
crs84 = scheme == "WorldCRS84Quad"
for k in ("id", "crs", "orderedAxes", "tileMatrices", "tileMatrixSetLimits"):
    assert k in t, "missing " + k
assert t["id"] == scheme
assert t["uri"] == "http://www.opengis.net/def/tilematrixset/OGC/1.0/" + scheme
assert t["crs"] == ("http://www.opengis.net/def/crs/OGC/1.3/CRS84" if crs84
                    else "http://www.opengis.net/def/crs/EPSG/0/3857")
assert t["orderedAxes"] == (["Lon", "Lat"] if crs84 else ["X", "Y"])
ms, ls = t["tileMatrices"], t["tileMatrixSetLimits"]
assert len(ms) == (6 if crs84 else 7) == len(ls), (len(ms), len(ls))
sd0 = 279541132.0143589 if crs84 else 559082264.0287178
cs0 = 0.703125 if crs84 else 156543.03392804097
for k, m in enumerate(ms):
    for f in ("id", "scaleDenominator", "cellSize", "cornerOfOrigin", "pointOfOrigin",
              "tileWidth", "tileHeight", "matrixWidth", "matrixHeight"):
        assert f in m, "tileMatrix %d lacks %s" % (k, f)
    assert m["id"] == str(k)
    assert abs(m["scaleDenominator"] - sd0 / 2 ** k) <= 1e-9 * sd0, m
    assert abs(m["cellSize"] - cs0 / 2 ** k) <= 1e-12 * cs0, m
    assert m["cornerOfOrigin"] == "topLeft"
    o = m["pointOfOrigin"]
    assert (o == [-180, 90]) if crs84 else (abs(o[0] + 20037508.3427892) < 1e-6 and abs(o[1] - 20037508.3427892) < 1e-6), o
    assert m["tileWidth"] == m["tileHeight"] == 256
    assert m["matrixWidth"] == 2 ** (k + 1 if crs84 else k), m
    assert m["matrixHeight"] == 2 ** k, m
# Limits: TMS level k is our level k+1 (WorldCRS84Quad) or k.
for k, l in enumerate(ls):
    c0, r0, c1, r1 = x["levels"][k + 1 if crs84 else k]
    assert l == {"tileMatrix": str(k), "minTileRow": r0, "maxTileRow": r1,
                 "minTileCol": c0, "maxTileCol": c1}, (l, x["levels"])
PY
}
check_tms "$WORK/geo.tms" WorldCRS84Quad "$WORK/expected_geo.json" || fail "WorldCRS84Quad TMS"
check_tms "$WORK/web.tms" WebMercatorQuad "$WORK/expected_web.json" || fail "WebMercatorQuad TMS"

note "the tiles inside the limits exist, one outside is known-empty"
read -r c0 r0 c1 r1 <<<"$(json_get "$WORK/expected_geo.json" 'j.levels[6].join(" ")')"
expect_status 200 "$BASE/geo/6/$c0/$r0"
expect_status 200 "$BASE/geo/6/$c1/$r1"
expect_status 204 "$BASE/geo/6/$((c1 + 1))/$r1"
stop_server
