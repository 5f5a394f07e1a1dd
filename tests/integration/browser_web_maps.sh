#!/usr/bin/env bash
# A GeoTIFF built as it comes (WorldCRS84Quad, the default of a georeferenced build) and shown by
# the three stock web maps (pinned npm maplibre-gl, leaflet and ol in Debian's chromium) given only
# the plain web TileJSON URL `/{ts}.json?format=webp` that README and the index name: each draws
# the whole world at web zoom 1 where gdalwarp puts it in EPSG:3857 (mean difference a few levels
# of 255, the sea/land outline the same within 4 % of the pixels), with no error. The native grid,
# drawn by the same maps as if it were Web Mercator, squeezes the world into the northern half and
# fails both bars (checked too, so the bars can fail). Over curl: the index names each client's
# URLs; a native tile asked for as an image (a browser's Accept) is 406 naming the image routes,
# while our clients' Accept still gets the tile.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
# shellcheck source=serve_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/serve_lib.sh"
BROWSER_JS=${BROWSER_JS:-$(dirname "${BASH_SOURCE[0]}")/browser_js}
export CHROMIUM=${CHROMIUM:-$(command -v chromium || true)}
[[ -x $CHROMIUM ]] || fail "missing chromium (Debian package; run scripts/setup.sh)"
for pkg in puppeteer-core maplibre-gl leaflet ol; do
  [[ -f $BROWSER_JS/node_modules/$pkg/package.json ]] ||
    fail "npm package $pkg is not installed in $BROWSER_JS (run scripts/setup.sh)"
done
require_tool gdal_translate
require_tool gdalwarp
/usr/bin/python3 -c 'import numpy; from osgeo import gdal' 2>/dev/null ||
  fail "Debian's python3-numpy and python3-gdal are needed (run scripts/setup.sh)"
export HOME="$WORK/home" # chromium's profile and crash files stay in the test's directory
mkdir -p "$HOME"

note "the Earth as a whole-world GeoTIFF, built with no tiling option (WorldCRS84Quad)"
gdal_translate -q -of GTiff -a_srs EPSG:4326 -a_ullr -180 90 180 -90 "$EARTH" "$WORK/earth.tif" ||
  fail "gdal_translate could not georeference the Earth image"
mkdir -p "$WORK/ts"
expect_ok "$VTS" build "$WORK/earth.tif" -o "$WORK/ts/earth.pmtiles" --threads 2
expect_ok "$VTS" info "$WORK/ts/earth.pmtiles" --json
json_check "$OUT" 'j.georeference.tiling === "WorldCRS84Quad"' "the build is WorldCRS84Quad"
gdalwarp -q -t_srs EPSG:3857 -te -20037508.342789244 -20037508.342789244 20037508.342789244 \
  20037508.342789244 -ts 512 512 -r bilinear "$WORK/earth.tif" "$WORK/want.tif" ||
  fail "gdalwarp could not make the reference"

start_server "$WORK/ts"

note "the index names each client's URLs"
curl -sf "$BASE/" >"$WORK/index.json" || fail "GET / failed"
json_check "$WORK/index.json" "j[0].tilejson === '$BASE/earth.json' &&
  j[0].web_map.tilejson === '$BASE/earth.json?format=webp' &&
  j[0].web_map.tiling === 'WebMercatorQuad' && j[0].tiling === 'WorldCRS84Quad' &&
  j[0].gis.xyz === '$BASE/earth/WebMercatorQuad/{z}/{x}/{y}.png' &&
  j[0].gis.wmts === '$BASE/wmts/1.0.0/WMTSCapabilities.xml' &&
  j[0].gis.ogcapi === '$BASE/ogcapi/collections/earth'" "the index entry"

note "a browser's index links the same: the web map TileJSON, WMTS, OGC API"
curl -sf -H 'Accept: text/html' "$BASE/" >"$WORK/index.html" || fail "GET / as a browser failed"
for want in '<a class="web-map" href="earth.json?format=webp">' \
  '<a class="wmts" href="wmts/1.0.0/WMTSCapabilities.xml">' \
  '<a class="ogcapi" href="ogcapi/collections/earth">'; do
  grep -qF "$want" "$WORK/index.html" || { cat "$WORK/index.html" >&2; fail "no $want"; }
done

note "the plain web TileJSON is Web Mercator; the native grid only when asked by name"
curl -sf "$BASE/earth.json?format=webp" >"$WORK/web.json" || fail "web TileJSON failed"
json_check "$WORK/web.json" "j.tileMatrixSet === 'WebMercatorQuad' && j.crs === 'EPSG:3857' &&
  /\/WebMercatorQuad\/\{z\}\/\{x\}\/\{y\}\.webp$/.test(j.tiles[0]) && j.maxzoom === 3 &&
  Math.abs(j.bounds[3] - 85.0511287798) < 1e-6" "the web TileJSON"
curl -sf "$BASE/earth.json?format=webp&tiling=WorldCRS84Quad" >"$WORK/native.json" ||
  fail "the native-grid web TileJSON failed"
json_check "$WORK/native.json" "j.tileMatrixSet === 'WorldCRS84Quad' && j.crs === 'OGC:CRS84' &&
  /\/earth@[0-9a-f]+\/\{z\}\/\{x\}\/\{y\}\.webp$/.test(j.tiles[0])" "the native-grid TileJSON"
expect_status 400 "$BASE/earth.json?format=webp&tiling=EuropeanETRS89_LAEAQuad"

note "a native tile asked for as an image is 406 naming the image routes"
code=$(curl -s -o "$WORK/406.txt" -w '%{http_code}' -H 'Accept: image/avif,image/webp,*/*' \
  "$BASE/earth/1/0/0")
[[ $code == 406 ]] || fail "a browser's Accept on a native tile got $code, not 406"
if ! grep -q 'earth.json?format=webp' "$WORK/406.txt" || ! grep -q '/earth/1/0/0.png' "$WORK/406.txt"; then
  fail "the 406 does not name the image routes: $(cat "$WORK/406.txt")"
fi
for accept in '*/*' 'application/vnd.vtstream.tile' 'image/png, application/vnd.vtstream.tile'; do
  code=$(curl -s -o /dev/null -w '%{http_code}' -H "Accept: $accept" "$BASE/earth/1/0/0")
  [[ $code == 200 ]] || fail "Accept: $accept on a native tile got $code, not 200"
done

# compare SHOT: prints the mean absolute difference from the gdalwarp reference (RGB, of 255)
# and the share of pixels whose sea/land class (blue well above red and green) differs.
compare() {
  /usr/bin/python3 - "$1" "$WORK/want.tif" <<'EOF'
import sys
import numpy as np
from osgeo import gdal
got = gdal.Open(sys.argv[1]).ReadAsArray()[:3].astype(int)
want = gdal.Open(sys.argv[2]).ReadAsArray()[:3].astype(int)
def sea(a):
    return (a[2] > a[0] + 30) & (a[2] > a[1] + 10)
print(f"{np.abs(got - want).mean():.2f} {(sea(got) != sea(want)).mean():.4f}")
EOF
}

for lib in maplibre leaflet openlayers; do
  note "$lib on $BASE/earth.json?format=webp"
  expect_ok "$NODE" "$BROWSER_JS/webmaps.mjs" "$lib" "$BASE" "$BASE/earth.json?format=webp" \
    "$WORK/$lib.png"
  tail -n 1 "$OUT" >"$WORK/$lib.json"
  json_check "$WORK/$lib.json" 'j.problems.length === 0 && j.loaded >= 4' "$lib met no error"
  read -r mean outline < <(compare "$WORK/$lib.png")
  echo "$lib: mean difference $mean / 255, sea/land outline differs on $outline of the pixels"
  awk -v m="$mean" -v o="$outline" 'BEGIN { exit !(m < 8 && o < 0.04) }' ||
    fail "$lib does not show the world where gdalwarp puts it (mean $mean, outline $outline)"
done

note "the native grid in a web map misplaces the world (the bars above can fail)"
expect_ok "$NODE" "$BROWSER_JS/webmaps.mjs" leaflet "$BASE" \
  "$BASE/earth.json?format=webp&tiling=WorldCRS84Quad" "$WORK/native.png"
read -r mean outline < <(compare "$WORK/native.png")
echo "native grid: mean difference $mean / 255, outline $outline"
awk -v m="$mean" -v o="$outline" 'BEGIN { exit !(m >= 8 && o >= 0.04) }' ||
  fail "the native grid passed the bars meant to catch it (mean $mean, outline $outline)"
stop_server
echo "web maps on a WorldCRS84Quad GeoTIFF build OK"
