#!/usr/bin/env bash
# The browser viewer of `vts serve` in a real browser: Debian's chromium, driven by the pinned npm
# puppeteer-core (browser_js/view.mjs), opens GET /{tileset}/ for the Earth as a plain image, a
# WorldCRS84Quad and a WebMercatorQuad archive, sets a view of one screen pixel per texel of a
# level, waits for its tiles, and the screenshot must show, pixel for pixel (within 1/255), the
# window of that level that `vts extract --level` writes; the page must log no error and fail no
# request, and the cursor readout must name the texel (plain image) or the lon/lat
# (georeferenced) under a known pixel. Also over curl: the HTML index for a browser while the
# JSON index stays as it was, the page's 404 for an unknown tileset, and the embedded assets'
# content types, immutable caching, content hash in the URL, ETag and 304. Last, stock MapLibre
# GL JS (pinned npm maplibre-gl) on the web TileJSON of the WebMercatorQuad archive (the same pixels
# as vts extract) and on the WorldCRS84Quad archive resampled to WebMercatorQuad (the same pixels
# as the tiles that TileJSON names).
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
# shellcheck source=serve_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/serve_lib.sh"
BROWSER_JS=${BROWSER_JS:-$(dirname "${BASH_SOURCE[0]}")/browser_js}
export CHROMIUM=${CHROMIUM:-$(command -v chromium || true)}
[[ -x $CHROMIUM ]] || fail "missing chromium (Debian package; run scripts/setup.sh)"
[[ -f $BROWSER_JS/node_modules/puppeteer-core/package.json ]] ||
  fail "npm package puppeteer-core is not installed in $BROWSER_JS (run scripts/setup.sh)"
require_tool python3
require_tool gdal_translate
require_tool vips
export HOME="$WORK/home" # chromium's profile and crash files stay in the test's directory
mkdir -p "$HOME"

TS="$WORK/tilesets"
mkdir -p "$TS"
# The Earth (real content: a misplaced tile shows), as a plain image and, placed on the whole
# world by a GeoTIFF, in both grids.
build_earth "$TS/plain.pmtiles" --threads 2
gdal_translate -q -of GTiff -a_srs EPSG:4326 -a_ullr -180 90 180 -90 "$EARTH" "$WORK/earth.tif" ||
  fail "gdal_translate could not georeference the Earth image"
expect_ok "$VTS" build "$WORK/earth.tif" --tiling WorldCRS84Quad -o "$TS/crs84.pmtiles" --threads 2
expect_ok "$VTS" build "$WORK/earth.tif" --tiling WebMercatorQuad --max-level 3 -o "$TS/merc.pmtiles" \
  --threads 2
start_server "$TS"

note "GET / for a browser is an HTML list of viewers; without text/html the JSON"
curl -sf -H 'Accept: text/html,application/xhtml+xml,*/*;q=0.8' -D "$WORK/index.h" "$BASE/" \
  >"$WORK/index.html" || fail "GET / (Accept: text/html) failed"
grep -qi '^content-type: text/html; charset=utf-8' "$WORK/index.h" || fail "the HTML index's type"
grep -qi '^vary: accept' "$WORK/index.h" || fail "the HTML index has no Vary: Accept"
grep -qF '<a href="plain/">plain</a>' "$WORK/index.html" || fail "no link to plain/: $(cat "$WORK/index.html")"
grep -qF '<a href="crs84/">crs84</a> (georeferenced)' "$WORK/index.html" || fail "no crs84 link"
curl -sf -D "$WORK/json.h" "$BASE/" >"$WORK/index.json" || fail "GET / failed"
grep -qi '^content-type: application/json' "$WORK/json.h" || fail "GET / without text/html is not JSON"
json_check "$WORK/index.json" 'j.length === 3 && j[0].name === "crs84" && j[0].tilejson.endsWith("/crs84.json")'

note "GET /{ts}/ is the viewer page; its assets are embedded, immutable, with ETag and 304"
curl -sf -D "$WORK/page.h" "$BASE/plain/" >"$WORK/page.html" || fail "GET /plain/ failed"
grep -qi '^content-type: text/html; charset=utf-8' "$WORK/page.h" || fail "the page's type"
grep -qF 'data-tileset="plain" data-tilejson="../plain.json"' "$WORK/page.html" ||
  fail "the page does not name its tileset escaped: $(cat "$WORK/page.html")"
expect_status 404 "$BASE/nosuch/"
for asset in $(grep -oE '_viewer/[a-z]+\.[0-9a-f]{16}\.(js|css)' "$WORK/page.html"); do
  curl -sf -D "$WORK/asset.h" -o "$WORK/asset.body" "$BASE/$asset" || fail "GET /$asset failed"
  case $asset in
    *.js) want='text/javascript; charset=utf-8' ;;
    *) want='text/css; charset=utf-8' ;;
  esac
  grep -qi "^content-type: $want" "$WORK/asset.h" || fail "/$asset is not $want"
  grep -qi '^cache-control: public, max-age=31536000, immutable' "$WORK/asset.h" ||
    fail "/$asset is not cached as immutable"
  hash=$(sha256sum "$WORK/asset.body" | cut -c1-16)
  [[ $asset == *".$hash."* ]] || fail "/$asset does not name its content's hash ($hash)"
  grep -qi "^etag: \"$hash\"" "$WORK/asset.h" || fail "/$asset's ETag is not \"$hash\""
  expect_status 304 -H "If-None-Match: \"$hash\"" "$BASE/$asset"
done
[[ $(grep -c '_viewer/' "$WORK/page.html") == 4 ]] || fail "the page links 4 assets"
expect_status 404 "$BASE/_viewer/ol.0000000000000000.js"

note "vts cache serve answers the same pages for the tilesets it provides"
start_daemon cache "$VTS" cache serve --upstream "$BASE/plain" --cache-dir "$WORK/cache" \
  --listen 127.0.0.1:0 --admin 127.0.0.1:0
curl -sf -H 'Accept: text/html' "$D/" >"$WORK/daemon_index.html" || fail "daemon: GET / (HTML)"
grep -qF '<a href="plain/">plain</a>' "$WORK/daemon_index.html" ||
  fail "the daemon's HTML index does not link plain/: $(cat "$WORK/daemon_index.html")"
curl -sf "$D/plain/" >"$WORK/daemon_page.html" || fail "daemon: GET /plain/"
cmp -s "$WORK/daemon_page.html" "$WORK/page.html" || fail "the daemon's page of plain differs"
asset=$(grep -oE '_viewer/ol\.[0-9a-f]{16}\.js' "$WORK/page.html")
expect_status 200 "$D/$asset"
kill -TERM "$DAEMON_PID"
wait "$DAEMON_PID" || true

# view NAME Z PX PY MX MY: the page of NAME in chromium; one screen pixel per image pixel of level
# Z, image pixel (PX, PY) at the top-left corner; the mouse at (MX, MY). Leaves $WORK/NAME.png
# (the screenshot) and $WORK/NAME.json (readout, tile counts, problems); fails on any problem.
view() {
  local name=$1
  expect_ok "$NODE" "$BROWSER_JS/view.mjs" "$BASE/$name/" "$2" "$3" "$4" "$WORK/$name.png" "$5" "$6"
  tail -n 1 "$OUT" >"$WORK/$name.json"
  json_check "$WORK/$name.json" 'j.problems.length === 0' "$name: the page met no error"
  json_check "$WORK/$name.json" 'j.tiles.loaded > 0 && j.tiles.failed === 0' "$name: tiles loaded"
}

# same_window NAME Z PX PY [SHOT]: the 384x256 window at (64, 64) of the screenshot SHOT (default
# $WORK/NAME.png; away from the controls) equals that window of level Z of archive NAME as
# `vts extract` writes it.
same_window() {
  local name=$1 z=$2 px=$3 py=$4 shot=${5:-$WORK/$1.png}
  local tag
  tag=$(basename "$shot" .png)
  expect_ok "$VTS" extract "$TS/$name.pmtiles" --level "$z" --channels 3 -o "$WORK/$name.level.png"
  crop_ref "$WORK/$name.level.png" 384 256 $((px + 64)) $((py + 64)) "$WORK/$tag.want.png"
  "$OIIOTOOL" "$shot" --ch R,G,B --cut 384x256+64+64 --origin +0+0 --fullpixels \
    -o "$WORK/$tag.got.png"
  if ! "$IDIFF" -fail 0.004 -warn 0.004 "$WORK/$tag.got.png" "$WORK/$tag.want.png" \
    >"$LOGS/idiff.$tag.txt" 2>&1; then
    cat "$LOGS/idiff.$tag.txt" >&2
    fail "$tag: the browser shows other pixels than level $z of $name"
  fi
}

note "a plain image in pixel space: level 3 (2048x1024) texels (700, 300) at the top-left"
view plain 3 700 300 100 50
same_window plain 3 700 300
# Level 3 of 3 is full resolution: the texel under screen pixel (100, 50) is (800, 350).
json_check "$WORK/plain.json" 'j.kind === "pixels" && j.readout === "x 800, y 350"' "plain readout"

note "WorldCRS84Quad on EPSG:4326: our level 3 (TMS 2, 2048x1024), pixels (1000, 300) at the top-left"
view crs84 3 1000 300 100 50
same_window crs84 3 1000 300
readout=$(json_get "$WORK/crs84.json" j.readout)
python3 - "$readout" <<'PY' || fail "crs84: the cursor readout '$readout' is not where the mouse is"
import sys
lon, lat = (float(p.split()[1]) for p in sys.argv[1].split(", "))
res = 360 / 2048  # degrees per texel of our level 3
want_lon, want_lat = -180 + (1000 + 100) * res, 90 - (300 + 50) * res
assert abs(lon - want_lon) < 1e-5 and abs(lat - want_lat) < 1e-5, (lon, lat, want_lon, want_lat)
PY

note "WebMercatorQuad on EPSG:3857: level 3, pixels (700, 600) at the top-left"
view merc 3 700 600 100 50
same_window merc 3 700 600
readout=$(json_get "$WORK/merc.json" j.readout)
python3 - "$readout" <<'PY' || fail "merc: the cursor readout '$readout' is not where the mouse is"
import math, sys
lon, lat = (float(p.split()[1]) for p in sys.argv[1].split(", "))
n = 2048  # texels per side of level 3
x, y = (700 + 100) / n, (600 + 50) / n
want_lon = x * 360 - 180
want_lat = math.degrees(math.atan(math.sinh(math.pi * (1 - 2 * y))))
assert abs(lon - want_lon) < 1e-5 and abs(lat - want_lat) < 1e-5, (lon, lat, want_lon, want_lat)
PY

note "stock MapLibre GL JS on the web TileJSON (?format=png) of the WebMercatorQuad archive"
expect_ok "$NODE" "$BROWSER_JS/maplibre.mjs" "$BASE" "$BASE/merc.json?format=png" 3 700 600 \
  "$WORK/maplibre.png"
tail -n 1 "$OUT" >"$WORK/maplibre.json"
json_check "$WORK/maplibre.json" 'j.problems.length === 0 && j.loaded > 0' "MapLibre met no error"
same_window merc 3 700 600 "$WORK/maplibre.png"

note "stock MapLibre GL JS on the WorldCRS84Quad archive resampled to WebMercatorQuad"
curl -sf "$BASE/crs84.json?format=png&tiling=WebMercatorQuad" >"$WORK/crs84_wmq.json" ||
  fail "GET /crs84.json?format=png&tiling=WebMercatorQuad failed"
template=$(json_get "$WORK/crs84_wmq.json" 'j.tiles[0]')
expect_ok "$NODE" "$BROWSER_JS/maplibre.mjs" "$BASE" "$BASE/crs84.json?format=png&tiling=WebMercatorQuad" \
  3 700 600 "$WORK/maplibre_wmq.png"
tail -n 1 "$OUT" >"$WORK/maplibre_wmq.json"
json_check "$WORK/maplibre_wmq.json" 'j.problems.length === 0 && j.loaded > 0' \
  "MapLibre on the resampled tiles met no error"
# The reference: the tiles the TileJSON names, x 2..4 and y 2..3 of zoom 3, joined; the window
# (764, 664) of zoom 3's world is at (252, 152) in them.
tiles=()
for y in 2 3; do
  for x in 2 3 4; do
    url=${template//\{z\}/3}
    url=${url//\{x\}/$x}
    url=${url//\{y\}/$y}
    curl -sf -o "$WORK/wmq_${x}_$y.png" "$url" || fail "GET $url failed"
    tiles+=("$WORK/wmq_${x}_$y.png")
  done
done
vips arrayjoin "${tiles[*]}" "$WORK/wmq_mosaic.png" --across 3 || fail "vips arrayjoin failed"
"$OIIOTOOL" "$WORK/wmq_mosaic.png" --ch R,G,B --cut 384x256+252+152 --origin +0+0 --fullpixels \
  -o "$WORK/wmq.want.png"
"$OIIOTOOL" "$WORK/maplibre_wmq.png" --ch R,G,B --cut 384x256+64+64 --origin +0+0 --fullpixels \
  -o "$WORK/wmq.got.png"
if ! "$IDIFF" -fail 0.004 -warn 0.004 "$WORK/wmq.got.png" "$WORK/wmq.want.png" \
  >"$LOGS/idiff.wmq.txt" 2>&1; then
  cat "$LOGS/idiff.wmq.txt" >&2
  fail "MapLibre shows other pixels than the resampled tiles its TileJSON names"
fi

stop_server
echo "browser viewer OK"
