#!/usr/bin/env bash
# `vts view` of borderless third-party image tiles shows no seams at tile edges. A smooth image
# (ramps plus a diagonal sine) is built into our archive (tiles with borders), served by a real
# `vts serve` as PNG tiles on {z}/{x}/{y}.png (no borders), and both are viewed magnified
# (2 px per texel) with `vts view --headless` under Xvfb + Mesa llvmpipe, on the same camera, with
# a vertical and a horizontal tile edge in the frame. The XYZ frame must match our archive's
# within half the image's largest texel-to-texel step (the renderer keeps a borderless tile's
# bilinear footprint inside its content, docs/RENDERER.md "Borderless tiles"), and no pixel may
# differ from its neighbour by more than that step: a texel of an unrelated slot blended in at a
# tile edge (what the viewer did before) differs by tens of codes.
# Environment (besides lib.sh's): XVFB_RUN, the xvfb-run script.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
# shellcheck source=serve_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/serve_lib.sh"

XVFB_RUN=${XVFB_RUN:-xvfb-run}
PY=/usr/bin/python3
require_tool "$XVFB_RUN"
XVFB=("$XVFB_RUN" -a -s "-screen 0 1280x1024x24")

note "a smooth 1024x1024 GeoTIFF over the whole Web Mercator square, built with borders"
"$PY" - "$WORK/smooth.tif" <<'PYTHON' || fail "cannot write the test GeoTIFF"
import sys
import numpy as np
from osgeo import gdal, osr
n = 1024
X, Y = np.meshgrid(np.arange(n, dtype=np.float64), np.arange(n, dtype=np.float64))
bands = (np.round(255 * X / (n - 1)), np.round(255 * Y / (n - 1)),
         np.round(128 + 100 * np.sin(2 * np.pi * (X + Y) / 128)))
ds = gdal.GetDriverByName("GTiff").Create(sys.argv[1], n, n, 3, gdal.GDT_Byte)
e = 20037508.342789244
ds.SetGeoTransform([-e, 2 * e / n, 0, e, 0, -2 * e / n])
srs = osr.SpatialReference()
srs.ImportFromEPSG(3857)
ds.SetProjection(srs.ExportToWkt())
for i, b in enumerate(bands):
    ds.GetRasterBand(i + 1).WriteArray(b.astype(np.uint8))
PYTHON
expect_ok "$VTS" build "$WORK/smooth.tif" -o "$WORK/smooth.pmtiles" --tiling WebMercatorQuad -q
# 256 px tiles with a border of 4, levels 0..2: finest tile edges at texels 256, 512 and 768.
echo '{"scene": "plane", "camera": {"center": [512, 512], "texels_per_pixel": 0.5}}' \
  >"$WORK/scene.json"

# view NAME SOURCE [ARGS...]: a converged 640x480 frame of SOURCE as $WORK/NAME.png.
view() {
  local name=$1 source=$2
  shift 2
  expect_ok "${XVFB[@]}" "$VTS" view "$source" "$@" --headless --frames 300 --until-complete \
    --width 640 --height 480 --scene "$WORK/scene.json" --screenshot "$WORK/$name.png"
  grep -q 'complete at frame' "$OUT" || { show_output; fail "$name: the view never completed"; }
}

# check_seams NAME: $WORK/NAME.png (a borderless view) against $WORK/ours.png.
check_seams() {
  "$PY" - "$WORK/smooth.tif" "$WORK/ours.png" "$WORK/$1.png" "$LOGS/seams-$1.png" <<'PYTHON' ||
import sys
import numpy as np
from osgeo import gdal
src = gdal.Open(sys.argv[1]).ReadAsArray().astype(int)
ours = gdal.Open(sys.argv[2]).ReadAsArray().astype(int)[:3]
xyz = gdal.Open(sys.argv[3]).ReadAsArray().astype(int)[:3]
# The image's own largest texel-to-texel step, on either axis (5 codes here).
step = max(np.abs(np.diff(src, axis=1)).max(), np.abs(np.diff(src, axis=2)).max())
diff = np.abs(xyz - ours).max(axis=0)
dx = np.abs(np.diff(xyz, axis=2)).max(axis=(0, 1))
dy = np.abs(np.diff(xyz, axis=1)).max(axis=(0, 2))
print("texel step %d; vs our archive max %d; adjacent columns max %d (col %d), rows max %d (row %d)"
      % (step, diff.max(), dx.max(), dx.argmax(), dy.max(), dy.argmax()))
ok = diff.max() <= (step + 1) // 2 + 1 and dx.max() <= step + 1 and dy.max() <= step + 1
if not ok:
    img = np.clip(diff * 8, 0, 255).astype(np.uint8)
    d = gdal.GetDriverByName("MEM").Create("", img.shape[1], img.shape[0], 1, gdal.GDT_Byte)
    d.GetRasterBand(1).WriteArray(img)
    gdal.GetDriverByName("PNG").CreateCopy(sys.argv[4], d)
    print("seams: |xyz - ours| x8 written to", sys.argv[4], file=sys.stderr)
sys.exit(0 if ok else 1)
PYTHON
    fail "seams at tile edges in the $1 view (VTS_KEEP_TMP=1 keeps $LOGS/seams-$1.png)"
}

# The same image in 512 px tiles (levels 0..1), for a template whose tiles are not 256 px.
mkdir -p "$WORK/ts"
expect_ok "$VTS" build "$WORK/smooth.tif" -o "$WORK/ts/smooth512.pmtiles" --tiling WebMercatorQuad \
  --tile 512 -q
cp "$WORK/smooth.pmtiles" "$WORK/ts/"

start_server "$WORK/ts"
note "vts view of our archive (borders) and of its PNG tiles as an XYZ template (no borders)"
view ours "$WORK/smooth.pmtiles"
view xyz "$BASE/smooth/{z}/{x}/{y}.png" --zoom 0-2
note "and of the 512 px tiles, the template's tile size given with --tile-size"
view xyz512 "$BASE/smooth512/{z}/{x}/{y}.png" --zoom 0-1 --tile-size 512
note "without --tile-size the 512 px tiles cannot be shown, and the view says why"
expect_ok "${XVFB[@]}" "$VTS" view "$BASE/smooth512/{z}/{x}/{y}.png" --zoom 0-1 --headless \
  --frames 2000 --width 64 --height 64
grep -q 'tile errors, the last: tile 0/0/0: image tile of 512x512 pixels in a tileset of 256 px' \
  "$OUT" || { show_output; fail "the view does not say why the 512 px tiles are not shown"; }
stop_server

for name in xyz xyz512; do
  note "the $name frame has no seams: within half a texel step of ours, no step over one texel's"
  check_seams "$name"
done
note "ok"

