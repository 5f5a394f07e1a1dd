#!/usr/bin/env bash
# A raster PMTiles archive written by `vts export --format png`, served by nginx as a static file
# (deploy/nginx/vts-static.conf.template, as in deploy_static.sh: no tile server at all), shown by
# stock MapLibre GL JS with the stock npm pmtiles protocol (both pinned in browser_js/) in Debian's
# chromium: the screenshot at one screen pixel per texel of a level equals, pixel for pixel
# (within 1/255), that window of the level as `vts extract` writes it, and the page meets no
# error. Exit 77 (skipped) while this vts has no `export` command.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
# shellcheck source=serve_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/serve_lib.sh"
# shellcheck source=deploy_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/deploy_lib.sh"
BROWSER_JS=${BROWSER_JS:-$(dirname "${BASH_SOURCE[0]}")/browser_js}
export CHROMIUM=${CHROMIUM:-$(command -v chromium || true)}
[[ -x $CHROMIUM ]] || fail "missing chromium (Debian package; run scripts/setup.sh)"
for pkg in puppeteer-core maplibre-gl pmtiles; do
  [[ -f $BROWSER_JS/node_modules/$pkg/package.json ]] ||
    fail "npm package $pkg is not installed in $BROWSER_JS (run scripts/setup.sh)"
done
require_tool gdal_translate
if ! "$VTS" --help | grep -qE '^ +export '; then
  echo "this vts has no export command: skipped"
  exit 77
fi
export HOME="$WORK/home"
mkdir -p "$HOME"

note "the Earth in WebMercatorQuad (level 3), exported as a PNG PMTiles archive"
gdal_translate -q -of GTiff -a_srs EPSG:4326 -a_ullr -180 90 180 -90 "$EARTH" "$WORK/earth.tif" ||
  fail "gdal_translate could not georeference the Earth image"
expect_ok "$VTS" build "$WORK/earth.tif" --tiling WebMercatorQuad --max-level 3 \
  -o "$WORK/merc.pmtiles" --threads 2
mkdir -p "$WORK/srv"
expect_ok "$VTS" export "$WORK/merc.pmtiles" -o "$WORK/srv/merc_png.pmtiles" --format png
expect_ok "$VTS" extract "$WORK/merc.pmtiles" --level 3 --channels 3 -o "$WORK/level3.png"

note "nginx serves it statically"
start_static_nginx "$WORK/srv"
wait_http "$S/merc_png.pmtiles"

note "MapLibre GL JS + pmtiles protocol: level 3, pixels (700, 600) at the top-left"
expect_ok "$NODE" "$BROWSER_JS/maplibre.mjs" "$S" "pmtiles://$S/merc_png.pmtiles" 3 700 600 \
  "$WORK/shot.png"
tail -n 1 "$OUT" >"$WORK/shot.json"
json_check "$WORK/shot.json" 'j.problems.length === 0 && j.loaded > 0' "MapLibre met no error"
crop_ref "$WORK/level3.png" 384 256 764 664 "$WORK/want.png"
"$OIIOTOOL" "$WORK/shot.png" --ch R,G,B --cut 384x256+64+64 --origin +0+0 --fullpixels \
  -o "$WORK/got.png"
if ! "$IDIFF" -fail 0.004 -warn 0.004 "$WORK/got.png" "$WORK/want.png" >"$LOGS/idiff.txt" 2>&1; then
  cat "$LOGS/idiff.txt" >&2
  fail "MapLibre shows other pixels than level 3 of the archive"
fi
echo "MapLibre on a static exported archive OK"
