#!/usr/bin/env bash
# WebMercatorQuad tiles made on the fly from a WorldCRS84Quad archive (render_web_mercator_tile,
# through tests/integration/web_mercator_tile.cpp reading and decoding the archive's real tiles)
# against gdalwarp: the Earth as a GDAL-made GeoTIFF is built onto WorldCRS84Quad (levels 0..3),
# the source level the tile reads (min(z, 3)) is extracted with `vts extract`, georeferenced by
# gdal_translate and warped by gdalwarp onto the Web Mercator tile's exact extent (bilinear,
# -et 0). gdalwarp blends the values it is given, so each of our two blends is checked against
# gdalwarp given the matching values: our sRGB-code blend against gdalwarp on the codes, our
# linear-light blend (the default) against gdalwarp on the level decoded to linear light (Float32)
# and encoded back to sRGB here. Over every texel of each tile and channel: max difference <= 1
# code, mean <= 0.05, PSNR >= 60 dB; and the comparison can tell a misplacement: gdalwarp's tile
# shifted by half a texel on both axes scores at least 10 dB worse. The last column shows what the
# linear-light blend differs from gdalwarp on codes (not asserted: that is the choice of blend).
# Tiles: several zooms, high latitudes (to 85.05 degrees), the antimeridian column, and zooms
# 4 and 5 beyond the finest level (magnified). A tile outside a partial archive's footprint
# draws nothing (exit 3). The table in docs/ACCURACY.md §7 is this script's output.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
: "${WEB_MERCATOR_TILE:?WEB_MERCATOR_TILE must name tests/integration/web_mercator_tile}"
PY=/usr/bin/python3
require_tool gdal_translate
require_tool gdalwarp
"$PY" -c 'import numpy, osgeo' 2>/dev/null || fail "$PY lacks numpy or osgeo (GDAL's Python)"

cd "$WORK"
T() { gdal_translate -q "$@" || fail "gdal_translate $*"; }
T -a_srs EPSG:4326 -a_ullr -180 90 180 -90 "$EARTH" world.tif
MAXZ=3
expect_ok "$VTS" build world.tif --tiling WorldCRS84Quad --max-level "$MAXZ" \
  --resampling bilinear -o world.pmtiles --threads 2

# Each source level as a georeferenced image (RGB: the archive is opaque), and the same decoded to
# linear light (Float32), so gdalwarp's bilinear blends what ours blends in each mode.
cat >to_linear.py <<'PY'
import sys
import numpy as np
from osgeo import gdal
src = gdal.Open(sys.argv[1])
a = src.ReadAsArray().astype(np.float64) / 255.0
lin = np.where(a <= 0.04045, a / 12.92, ((a + 0.055) / 1.055) ** 2.4)
dst = gdal.GetDriverByName("GTiff").Create(sys.argv[2], src.RasterXSize, src.RasterYSize, 3,
                                            gdal.GDT_Float32)
dst.SetGeoTransform(src.GetGeoTransform())
dst.SetProjection(src.GetProjection())
for b in range(3):
    dst.GetRasterBand(b + 1).WriteArray(lin[b].astype(np.float32))
dst = None
PY
for L in $(seq 0 "$MAXZ"); do
  expect_ok "$VTS" extract world.pmtiles --level "$L" --channels 3 -o "level$L.tif"
  T -a_srs EPSG:4326 -a_ullr -180 90 180 -90 "level$L.tif" "level$L.codes.tif"
  "$PY" to_linear.py "level$L.codes.tif" "level$L.linear.tif" || fail "level $L to linear light"
done

# extent Z X Y SHIFT: the tile's EPSG:3857 extent, moved by SHIFT texels east and south.
extent() {
  "$PY" - "$@" <<'PY'
import sys
z, x, y, s = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4])
M = 20037508.342789244
span = 2 * M / 2 ** z
d = s * span / 256
print(-M + x * span + d, M - (y + 1) * span - d, -M + (x + 1) * span + d, M - y * span - d)
PY
}

# compare.py MODE OURS REF REF_SHIFTED OTHER TILE LATS: REF is gdalwarp's tile in MODE (codes:
# uint8; linear: float32 linear light, encoded to sRGB codes here), REF_SHIFTED the same half a
# texel off, OTHER gdalwarp's codes tile (what ours in linear light gives up against it).
cat >compare.py <<'PY'
import math, sys
import numpy as np
mode, ours_path, ref_path, shifted_path, other_path, tile, lats = sys.argv[1:8]
def load_ref(path, kind):
    if kind == "codes":
        return np.fromfile(path, np.uint8).reshape(256, 256, 3).astype(np.int32)
    v = np.clip(np.fromfile(path, np.float32).reshape(256, 256, 3).astype(np.float64), 0, 1)
    e = np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1 / 2.4) - 0.055)
    return np.rint(e * 255).astype(np.int32)
ours = np.fromfile(ours_path, np.uint8).reshape(256, 256, 4)
assert (ours[:, :, 3] == 255).all(), "ours has transparent texels"
a = ours[:, :, :3].astype(np.int32)
ref, shifted = load_ref(ref_path, mode), load_ref(shifted_path, mode)
other = load_ref(other_path, "codes")
def psnr(x, y):
    mse = ((x - y) ** 2).mean()
    return 99.0 if mse == 0 else min(99.0, 10 * math.log10(255 ** 2 / mse))  # 99: identical
d = np.abs(a - ref)
mean = d.reshape(-1, 3).mean(axis=0)
p99 = np.percentile(d.reshape(-1, 3), 99, axis=0)
p, ps = psnr(a, ref), psnr(a, shifted)
print("| %s | %s | %s | %.1f | %.3f | %d | %d | %.1f | %.1f |" % (mode, tile, lats, p, mean.max(),
      p99.max(), d.max(), ps, psnr(a, other)))
assert mean.max() <= 0.05, ("mean abs difference per channel", mean)
assert d.max() <= 1, ("max difference", d.max())
assert p >= 60, ("PSNR", p)
assert p >= ps + 10, ("half a texel of shift is not clearly worse", p, ps)
PY

echo "| blend | tile z/x/y | latitudes | PSNR dB | mean abs (worst channel) | p99 | max | PSNR, gdalwarp half a texel off | PSNR vs gdalwarp on codes |"
for tile in 0/0/0 1/1/0 2/0/0 2/2/1 3/4/3 3/5/1 3/6/0 4/9/5 4/3/1 5/17/11; do
  IFS=/ read -r z x y <<<"$tile"
  L=$((z < MAXZ ? z : MAXZ))
  lat=$("$PY" -c "import math; f = lambda v: math.degrees(math.atan(math.sinh(math.pi * (1 - 2 * v / 2 ** $z)))); print('%.1f..%.1f' % (f($y + 1), f($y)))")
  for s in 0 0.5; do
    for mode in codes linear; do
      # shellcheck disable=SC2046
      gdalwarp -q -overwrite -t_srs EPSG:3857 -te $(extent "$z" "$x" "$y" "$s") -ts 256 256 \
        -r bilinear -et 0 -of ENVI -co INTERLEAVE=BIP "level$L.$mode.tif" "ref.$mode.$s.$z.$x.$y.bil" ||
        fail "gdalwarp $tile"
    done
  done
  for mode in codes linear; do
    expect_ok "$WEB_MERCATOR_TILE" world.pmtiles "$z" "$x" "$y" "ours.$mode.$z.$x.$y.rgba" \
      $([[ $mode == codes ]] && echo codes)
    grep -q "^level $L " "$OUT" || fail "$tile: not read from level $L: $(cat "$OUT")"
    "$PY" compare.py "$mode" "ours.$mode.$z.$x.$y.rgba" "ref.$mode.0.$z.$x.$y.bil" \
      "ref.$mode.0.5.$z.$x.$y.bil" "ref.codes.0.$z.$x.$y.bil" "$tile" "$lat" ||
      fail "$tile ($mode): does not agree with gdalwarp"
  done
done

note "a partial archive: a tile outside its footprint draws nothing, one inside draws its data"
T -srcwin 0 0 1024 1024 world.tif west.tif
expect_ok "$VTS" build west.tif --tiling WorldCRS84Quad --max-level 2 -o west.pmtiles --threads 2
run "$WEB_MERCATOR_TILE" west.pmtiles 1 1 0 east.rgba
((RC == 3)) || fail "a tile east of the footprint: exit $RC, want 3 (nothing to draw)"
[[ ! -e east.rgba ]] || fail "a tile outside the footprint wrote an image"
expect_ok "$WEB_MERCATOR_TILE" west.pmtiles 1 0 0 west.rgba
"$PY" -c "import numpy as np; a = np.fromfile('west.rgba', np.uint8).reshape(256, 256, 4); assert (a[:, 8:248, 3] == 255).all(), 'inside the footprint is not opaque'" ||
  fail "a tile inside the footprint"
run "$WEB_MERCATOR_TILE" west.pmtiles 1 2 0 bad.rgba
((RC == 1)) && grep -q "outside level 1" "$ERR" || fail "x = 2 at z 1: exit $RC, $(cat "$ERR")"
note "ok"
