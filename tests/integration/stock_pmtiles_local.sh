#!/usr/bin/env bash
# A local stock raster PMTiles (PNG tiles, no vtstream metadata: `vts export`'s) opens in
# `vts info`, `vts verify` and `vts view` as `vts view` opens image tiles over HTTP: info
# describes it, verify decodes every tile as its declared type and size (and names a damaged
# one), and the view from the file equals the view of the same tiles served as an XYZ template
# by a real `vts serve`, pixel for pixel.
# Environment (besides lib.sh's): XVFB_RUN, the xvfb-run script.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
# shellcheck source=serve_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/serve_lib.sh"

XVFB_RUN=${XVFB_RUN:-xvfb-run}
PY=/usr/bin/python3
require_tool "$XVFB_RUN"
XVFB=("$XVFB_RUN" -a -s "-screen 0 1280x1024x24")

note "a 512x512 GeoTIFF over the Web Mercator square, built, exported as PNG tiles"
"$PY" - "$WORK/img.tif" <<'PYTHON' || fail "cannot write the test GeoTIFF"
import sys
import numpy as np
from osgeo import gdal, osr
n = 512
X, Y = np.meshgrid(np.arange(n, dtype=np.float64), np.arange(n, dtype=np.float64))
bands = (255 * X / (n - 1), 255 * Y / (n - 1), 128 + 100 * np.sin(2 * np.pi * (X - Y) / 64))
ds = gdal.GetDriverByName("GTiff").Create(sys.argv[1], n, n, 3, gdal.GDT_Byte)
e = 20037508.342789244
ds.SetGeoTransform([-e, 2 * e / n, 0, e, 0, -2 * e / n])
srs = osr.SpatialReference()
srs.ImportFromEPSG(3857)
ds.SetProjection(srs.ExportToWkt())
for i, b in enumerate(bands):
    ds.GetRasterBand(i + 1).WriteArray(np.round(b).astype(np.uint8))
PYTHON
expect_ok "$VTS" build "$WORK/img.tif" -o "$WORK/img.pmtiles" --tiling WebMercatorQuad -q
STOCK="$WORK/stock.pmtiles"
expect_ok "$VTS" export "$WORK/img.pmtiles" --format png --tiling WebMercatorQuad -o "$STOCK" -q

note "vts info describes the stock archive"
expect_ok "$VTS" info "$STOCK"
grep -q 'stock raster PMTiles of png tiles' "$OUT" || { show_output; fail "info: no kind line"; }
grep -qE 'tiles +256 px, zoom 0\.\.1, WebMercatorQuad' "$OUT" || { show_output; fail "info: tiles"; }
expect_ok "$VTS" info --json "$STOCK"
cp "$OUT" "$WORK/info.json"
json_check "$WORK/info.json" 'j.kind === "stock-raster" && j.tile_type === "png" &&
  j.tile_size === 256 && j.min_zoom === 0 && j.max_zoom === 1 && j.tiles === 5 &&
  j.tiling === "WebMercatorQuad" && j.bounds[0] === -180 && j.bounds[2] === 180 &&
  j.levels.length === 2 && j.levels[1].tiles === 4 && j.levels[1].tiles_possible === 4'

note "vts verify decodes every tile"
expect_ok "$VTS" verify "$STOCK"
grep -q 'ok, 5 tiles (5 distinct payloads) decode as 256 px png images' "$OUT" ||
  { show_output; fail "verify: summary line"; }
expect_ok "$VTS" verify --json "$STOCK"
cp "$OUT" "$WORK/verify.json"
json_check "$WORK/verify.json" 'j.ok === true && j.kind === "stock-raster" &&
  j.tiles_checked === 5 && j.payloads_checked === 5 && j.bad_tiles === 0'

note "vts verify names a tile that is not a PNG"
cp "$STOCK" "$WORK/damaged.pmtiles"
"$PY" - "$WORK/damaged.pmtiles" <<'PYTHON' || fail "cannot damage the archive"
import struct, sys
with open(sys.argv[1], "r+b") as f:
    head = f.read(127)
    tile_data = struct.unpack_from("<Q", head, 56)[0]  # PMTiles v3 header: tile data offset
    f.seek(tile_data)
    f.write(b"GIF89a not a png")  # the first stored tile's signature
PYTHON
expect_clean_failure "$VTS" verify "$WORK/damaged.pmtiles"
grep -q 'tiles are bad; first bad tile .*png tileset.s tile is not an image' "$ERR" ||
  { show_output; fail "verify: the damaged tile is not named as it should be"; }

note "vts view of the file equals the view of the same tiles over HTTP"
echo '{"scene": "plane", "camera": {"center": [256, 256], "texels_per_pixel": 0.75}}' \
  >"$WORK/scene.json"
view() {
  local name=$1 source=$2
  shift 2
  expect_ok "${XVFB[@]}" "$VTS" view "$source" "$@" --headless --frames 300 --until-complete \
    --width 320 --height 240 --scene "$WORK/scene.json" --screenshot "$WORK/$name.png"
  grep -q 'complete at frame' "$OUT" || { show_output; fail "$name: the view never completed"; }
}
view local "$STOCK"
start_server "$WORK/img.pmtiles"
view xyz "$BASE/img/{z}/{x}/{y}.png" --zoom 0-1
stop_server
expect_same_pixels "$WORK/local.png" "$WORK/xyz.png"
note "ok"
