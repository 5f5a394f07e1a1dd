#!/usr/bin/env bash
# Files GIS tools read (docs/GIS.md "Files for GIS tools"), checked with GDAL's own tools:
# `vts export --format gtiff` of a level and of a --bbox is a COG (gdalinfo: LAYOUT=COG, the
# tileset's CRS, the level's cell size and origin, the overviews' count and sizes, an alpha band)
# whose full resolution equals `vts extract` of the level and whose every overview equals `vts
# extract` of the coarser level, texel for texel (no second resampling); gdal_translate -projwin of
# a region equals the same region extracted. `--format mbtiles`: gdalinfo reads the bounds and
# zooms, sqlite3 shows the metadata rows, and every zoom GDAL reads equals the WebMercatorQuad PNG
# export's tiles. `vts extract` keeps the georeference. A WorldCRS84Quad archive exported as png
# is WebMercatorQuad by default, its own grid with --tiling WorldCRS84Quad or native.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
require_tool gdalinfo
require_tool gdal_translate
require_tool sqlite3
: "${PMTILES_JS:?PMTILES_JS must name tests/integration/pmtiles_js}"
PY=/usr/bin/python3
COMPARE="$(dirname "${BASH_SOURCE[0]}")/export_gis_compare.py"

note "a WorldCRS84Quad archive of the Earth (levels 0..3) and a WebMercatorQuad one"
expect_ok gdal_translate -q -a_srs EPSG:4326 -a_ullr -180 90 180 -90 "$EARTH" "$WORK/in.tif"
G="$WORK/geo.pmtiles" M="$WORK/merc.pmtiles"
expect_ok "$VTS" build "$WORK/in.tif" -o "$G" -q
expect_ok "$VTS" build "$WORK/in.tif" --tiling WebMercatorQuad -o "$M" -q
for z in 0 1 2 3; do
  expect_ok "$VTS" extract "$G" --level "$z" -o "$WORK/geo_l$z.png"
  expect_ok "$VTS" extract "$M" --level "$z" -o "$WORK/merc_l$z.png"
done

# check_cog FILE CRS CELL ORIGIN_X ORIGIN_Y W H OVERVIEWS: gdalinfo -json of a COG.
check_cog() {
  local f=$1 epsg=$2 cell=$3 ox=$4 oy=$5 w=$6 h=$7 ovr=$8 info
  info="$LOGS/$(basename "$1").json"
  expect_ok gdalinfo -json "$f"
  cp "$OUT" "$info"
  json_check "$info" "j.metadata.IMAGE_STRUCTURE.LAYOUT === 'COG' &&
      j.metadata.IMAGE_STRUCTURE.COMPRESSION === 'DEFLATE'" "$f: COG layout, DEFLATE"
  json_check "$info" "j.stac['proj:epsg'] === $epsg" "$f: EPSG:$epsg"
  json_check "$info" "j.size[0] === $w && j.size[1] === $h" "$f: ${w}x$h"
  # Within a millionth of a texel.
  json_check "$info" "Math.abs(j.geoTransform[0] - ($ox)) < 1e-6 * $cell &&
      Math.abs(j.geoTransform[3] - ($oy)) < 1e-6 * $cell &&
      Math.abs(j.geoTransform[1] - $cell) < 1e-9 * $cell &&
      Math.abs(j.geoTransform[5] + $cell) < 1e-9 * $cell && j.geoTransform[2] === 0" \
    "$f: origin ($ox, $oy), cell $cell"
  json_check "$info" "j.bands.length === 4 && j.bands[3].colorInterpretation === 'Alpha' &&
      (j.bands[0].overviews || []).length === $ovr" "$f: RGBA, $ovr overviews"
  local k
  for ((k = 0; k < ovr; k++)); do
    json_check "$info" "j.bands[0].overviews[$k].size[0] === Math.ceil($w / 2 ** ($k + 1)) &&
        j.bands[0].overviews[$k].size[1] === Math.ceil($h / 2 ** ($k + 1))" \
      "$f: overview $((k + 1)) is half the previous"
  done
}

note "gtiff of the finest level: a COG whose overviews are our levels 2 and 1"
expect_ok "$VTS" export "$G" --format gtiff -o "$WORK/geo.tif" --json
cp "$OUT" "$LOGS/geo_gtiff.json"
json_check "$LOGS/geo_gtiff.json" "j.level === 3 && j.overviews === 2 && j.crs === 'EPSG:4326'"
check_cog "$WORK/geo.tif" 4326 0.17578125 -180 90 2048 1024 2
expect_ok "$PY" "$COMPARE" level "$WORK/geo.tif" 0 0 "$WORK/geo_l3.png" "$WORK/geo_l2.png" \
  "$WORK/geo_l1.png"

note "gtiff of a level of the WebMercatorQuad archive (EPSG:3857)"
expect_ok "$VTS" export "$M" --format gtiff --level 2 -o "$WORK/merc.tif"
check_cog "$WORK/merc.tif" 3857 39135.75848201024 -20037508.342789244 20037508.342789244 \
  1024 1024 1
expect_ok "$PY" "$COMPARE" level "$WORK/merc.tif" 0 0 "$WORK/merc_l2.png" "$WORK/merc_l1.png"

note "gtiff of a --bbox: snapped outward to texels of the coarsest overview's level"
expect_ok "$VTS" export "$G" --format gtiff --level 3 --bbox=-100.3,-40.2,60.7,55.1 \
  -o "$WORK/box.tif" --json
cp "$OUT" "$LOGS/box.json"
# Level 3 texels are 0.17578125 degrees; the box is 916x542 texels, so one overview (level 2):
# x0 = floor((180 - 100.3) / 0.17578125 / 2) * 2 = 452, y0 = floor((90 - 55.1) / c / 2) * 2 = 198.
json_check "$LOGS/box.json" "j.overviews === 1 && j.texel_rect[0] === 452 &&
    j.texel_rect[1] === 198 && j.texel_rect[0] % 2 === 0 && j.texel_rect[2] % 2 === 0 &&
    j.texel_rect[1] % 2 === 0 && j.texel_rect[3] % 2 === 0" "the box's texels, snapped to 2"
x0=$(json_get "$LOGS/box.json" "j.texel_rect[0]") y0=$(json_get "$LOGS/box.json" "j.texel_rect[1]")
w=$(json_get "$LOGS/box.json" j.width) h=$(json_get "$LOGS/box.json" j.height)
check_cog "$WORK/box.tif" 4326 0.17578125 "-180 + $x0 * 0.17578125" "90 - $y0 * 0.17578125" \
  "$w" "$h" 1
json_check "$LOGS/box.json" "j.bounds[0] <= -100.3 && j.bounds[1] <= -40.2 &&
    j.bounds[2] >= 60.7 && j.bounds[3] >= 55.1" "the box is inside the snapped bounds"
expect_ok "$PY" "$COMPARE" level "$WORK/box.tif" "$x0" "$y0" "$WORK/geo_l3.png" "$WORK/geo_l2.png"

note "gdal_translate -projwin of the COG equals the same region extracted"
expect_ok gdal_translate -q -projwin -45 30 45 -15.1 "$WORK/geo.tif" "$WORK/win.tif"
# -45..45 degrees, 30..-15.1 (rounded to texels: 30 / c = 170.67 -> GDAL rounds 341.33 -> 341)
expect_ok gdalinfo -json "$WORK/win.tif"
cp "$OUT" "$LOGS/win.json"
wx=$(json_get "$LOGS/win.json" "Math.round((j.geoTransform[0] + 180) / 0.17578125)")
wy=$(json_get "$LOGS/win.json" "Math.round((90 - j.geoTransform[3]) / 0.17578125)")
expect_ok "$PY" "$COMPARE" level "$WORK/win.tif" "$wx" "$wy" "$WORK/geo_l3.png"

note "vts extract keeps the georeference: a level as GeoTIFF, a tile, a PNG's .aux.xml"
expect_ok "$VTS" extract "$G" --level 3 -o "$WORK/x3.tif"
check_geo() { # FILE ORIGIN_X ORIGIN_Y CELL EPSG
  expect_ok gdalinfo -json "$1"
  cp "$OUT" "$LOGS/x.json"
  json_check "$LOGS/x.json" "j.stac['proj:epsg'] === $5 &&
      Math.abs(j.geoTransform[0] - ($2)) < 1e-6 * $4 && Math.abs(j.geoTransform[3] - ($3)) < 1e-6 * $4 &&
      Math.abs(j.geoTransform[1] - $4) < 1e-9 && Math.abs(j.geoTransform[5] + $4) < 1e-9" \
    "$1: EPSG:$5, origin ($2, $3), cell $4"
}
gt=$(json_get "$LOGS/geo.tif.json" "j.geoTransform.join(' ')")
read -r gx _ _ gy _ _ <<<"$gt"
check_geo "$WORK/x3.tif" "$gx" "$gy" 0.17578125 4326
expect_ok "$PY" "$COMPARE" level "$WORK/x3.tif" 0 0 "$WORK/geo_l3.png"
expect_ok "$VTS" extract "$G" 3/5/2 -o "$WORK/t.tif"
check_geo "$WORK/t.tif" "-180 + 5 * 45" "90 - 2 * 45" 0.17578125 4326
expect_ok "$VTS" extract "$G" 3/5/2 --with-border -o "$WORK/tb.tif"
check_geo "$WORK/tb.tif" "-180 + 5 * 45 - 4 * 0.17578125" "90 - 2 * 45 + 4 * 0.17578125" \
  0.17578125 4326
expect_ok "$VTS" extract "$M" --level 2 -o "$WORK/x2.jpg" --channels 3
[[ -s $WORK/x2.jpg.aux.xml ]] || fail "no .aux.xml beside a georeferenced JPEG extract"
check_geo "$WORK/x2.jpg" -20037508.342789244 20037508.342789244 39135.75848201024 3857

note "mbtiles: GDAL reads it, the metadata rows are there, every zoom equals the PNG export"
expect_ok "$VTS" export "$G" --format mbtiles -o "$WORK/geo.mbtiles" --json
cp "$OUT" "$LOGS/mbtiles.json"
json_check "$LOGS/mbtiles.json" "j.tiling === 'WebMercatorQuad' && j.min_zoom === 0 &&
    j.max_zoom === 3 && j.tiles === 85" "85 WebMercatorQuad tiles, zooms 0..3"
sqlite3 "$WORK/geo.mbtiles" "SELECT name || '=' || value FROM metadata ORDER BY name" \
  >"$LOGS/meta.txt" || fail "sqlite3 cannot read the MBTiles"
for row in "format=png" "type=baselayer" "minzoom=0" "maxzoom=3" "name=geo" "version=1" \
  "bounds=-180,-85.0511288,180,85.0511288" "center=0,0,0"; do
  grep -qxF "$row" "$LOGS/meta.txt" || fail "MBTiles metadata lacks '$row': $(cat "$LOGS/meta.txt")"
done
rows=$(sqlite3 "$WORK/geo.mbtiles" "SELECT count(*) FROM tiles WHERE zoom_level = 3 AND
  tile_column = 5 AND tile_row = 7 - 2")
[[ $rows == 1 ]] || fail "XYZ tile 3/5/2 is not at TMS row 5"
expect_ok gdalinfo -json "$WORK/geo.mbtiles"
cp "$OUT" "$LOGS/mb_info.json"
json_check "$LOGS/mb_info.json" "j.driverShortName === 'MBTiles' && j.size[0] === 2048 &&
    j.metadata[''].minzoom === '0' && j.metadata[''].maxzoom === '3' &&
    j.bands[0].overviews.length === 3 && Math.abs(j.geoTransform[0] + 20037508.342789244) < 1e-3 &&
    Math.abs(j.geoTransform[1] - 19567.87924100512) < 1e-6" \
  "gdalinfo: MBTiles, 2048 texels at zoom 3, zooms 0..3"
expect_ok "$VTS" export "$G" --format png --layout xyz -o "$WORK/xyz"
expect_ok "$PY" "$COMPARE" mbtiles "$WORK/geo.mbtiles" "$WORK/xyz" 3
note "mbtiles: $(cat "$OUT")"
# gdal_translate of a zoom level and of a region (-outsize of zoom 1 selects its overview).
expect_ok gdal_translate -q -of PNG -outsize 512 512 "$WORK/geo.mbtiles" "$WORK/mb_z1.png"
expect_ok gdal_translate -q -of PNG -srcwin 768 512 512 256 "$WORK/geo.mbtiles" "$WORK/mb_win.png"
expect_ok "$PY" "$COMPARE" xyzregion "$WORK/mb_z1.png" "$WORK/xyz" 1 0 0
expect_ok "$PY" "$COMPARE" xyzregion "$WORK/mb_win.png" "$WORK/xyz" 3 768 512

note "the default grid of a WorldCRS84Quad archive's web export is WebMercatorQuad"
: "${PMTILES_DUMP:?PMTILES_DUMP must name the pmtiles_dump tool}"
expect_ok "$NODE" -e 1
expect_ok "$VTS" export "$G" --format png -o "$WORK/def.pmtiles" --json
cp "$OUT" "$LOGS/def.json"
grep -q "grid WebMercatorQuad, reprojected from the archive's WorldCRS84Quad" "$ERR" ||
  fail "no note of the grid chosen: $(cat "$ERR")"
expect_ok "$NODE" "$PMTILES_JS/read_export.mjs" "$WORK/def.pmtiles" "$WORK/js_def"
cp "$OUT" "$LOGS/def_read.json"
json_check "$LOGS/def_read.json" "j.metadata.tiling === 'WebMercatorQuad' && j.tiles_read === 85 &&
    Math.abs(j.maxLat - 85.0511288) < 1e-6" "default: WebMercatorQuad (header and metadata)"
for t in WorldCRS84Quad native; do
  expect_ok "$VTS" export "$G" --format png --tiling "$t" -o "$WORK/native_$t.pmtiles"
  grep -q "grid WorldCRS84Quad (the archive's own)" "$ERR" || fail "no note: $(cat "$ERR")"
  expect_ok "$NODE" "$PMTILES_JS/read_export.mjs" "$WORK/native_$t.pmtiles" "$WORK/js_$t"
  cp "$OUT" "$LOGS/native.json"
  json_check "$LOGS/native.json" "j.metadata.tiling === 'WorldCRS84Quad' && j.tiles_read === 43 &&
      Math.abs(j.maxLat - 90) < 1e-6" "--tiling $t: the native CRS84 grid, said in the metadata"
done

note "bad inputs fail cleanly, naming what was wrong, and leave nothing"
P="$WORK/plain.pmtiles"
expect_ok "$VTS" build --synthetic 600x300 -o "$P" -q
mkdir -p "$WORK/bad"
expect_bad() { # EXIT_CODE MESSAGE_REGEX ARGS...
  local code=$1 re=$2
  shift 2
  expect_clean_failure "$VTS" export "$@"
  ((RC == code)) || fail "'vts export $*' exited $RC, expected $code: $(cat "$ERR")"
  grep -qE -- "$re" "$ERR" || fail "'vts export $*': message '$(cat "$ERR")' lacks /$re/"
  [[ -z $(ls -A "$WORK/bad") ]] || fail "'vts export $*' left $(ls -A "$WORK/bad")"
}
expect_bad 2 "plain image" "$P" --format gtiff -o "$WORK/bad/x.tif"
expect_bad 2 "plain image" "$P" --format mbtiles -o "$WORK/bad/x.mbtiles"
expect_bad 2 "--level 9 is outside 0..3" "$G" --format gtiff --level 9 -o "$WORK/bad/x.tif"
expect_bad 2 "--bbox" "$G" --format gtiff --bbox=10,20,5,30 -o "$WORK/bad/x.tif"
expect_bad 2 "--bbox" "$G" --format gtiff --bbox=10,20,30 -o "$WORK/bad/x.tif"
expect_bad 2 "--bbox lies outside" "$M" --format gtiff --bbox=0,86,10,89 -o "$WORK/bad/x.tif"
expect_bad 2 "--bbox applies to --format gtiff" "$G" --format png --bbox=0,0,1,1 \
  -o "$WORK/bad/x.pmtiles"
expect_bad 2 "MBTiles holds WebMercatorQuad" "$G" --format mbtiles --tiling native \
  -o "$WORK/bad/x.mbtiles"
expect_bad 2 "not an export grid" "$M" --format png --tiling WorldCRS84Quad -o "$WORK/bad/x.pmtiles"
expect_bad 2 "--tile-format" "$G" --format mbtiles --tile-format gif -o "$WORK/bad/x.mbtiles"
expect_bad 4 "nowhere" "$G" --format gtiff -o "$WORK/nowhere/x.tif"
expect_bad 4 "nowhere" "$G" --format mbtiles -o "$WORK/nowhere/x.mbtiles"
note "ok"
