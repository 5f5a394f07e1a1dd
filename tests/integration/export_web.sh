#!/usr/bin/env bash
# `vts export` writes standard web tiles that a stock reader displays: the npm `pmtiles` library,
# with its default decompressor (no zstd), reads the header (tile type, compression none, zooms,
# bounds) and every tile of a PNG, WebP and JPEG export of a lossless and a bc1 archive. PNG tiles
# decode to exactly what `vts extract` gives for the same tile (padded with transparent texels
# beyond the image's edge); WebP and JPEG tiles stay above PSNR bounds. --layout xyz writes the same
# tile set, byte for byte; wholly transparent tiles are not written; a WorldCRS84Quad archive
# exported with --tiling WebMercatorQuad holds exactly web_mercator_tile's tiles; bad inputs fail
# cleanly with no output left.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
: "${PMTILES_JS:?PMTILES_JS must name tests/integration/pmtiles_js}"
require_tool "$NODE"
require_tool /usr/bin/time
require_tool "$OIIOTOOL"
: "${PMTILES_DUMP:?PMTILES_DUMP must name the pmtiles_dump tool}"
: "${WEB_TILE_COMPARE:?WEB_TILE_COMPARE must name tests/integration/web_tile_compare}"
[[ -f $PMTILES_JS/node_modules/pmtiles/package.json ]] ||
  fail "npm package pmtiles is not installed in $PMTILES_JS (run scripts/setup.sh)"
T=256
# Lower bounds of the PSNR (dB, all channels of the tile's content) at --quality 90, measured at
# lowest at 34.5 dB (WebP) and 32.2 dB (JPEG) on these inputs (the Earth's level 0).
WEBP_MIN_PSNR=${WEBP_MIN_PSNR:-32}
JPEG_MIN_PSNR=${JPEG_MIN_PSNR:-30}

# extract_refs ARCHIVE REFDIR: every tile's content as `vts extract` writes it (RGBA).
extract_refs() {
  local a=$1 dir=$2 z x y
  mkdir -p "$dir"
  expect_ok "$VTS" info --json "$a"
  cp "$OUT" "$dir/info.json"
  while read -r z x y; do
    expect_ok "$VTS" extract "$a" "$z/$x/$y" -o "$dir/${z}_${x}_${y}.png"
  done < <("$PMTILES_DUMP" tiles "$a" | awk '{print $2, $3, $4}')
}

# check_export ARCHIVE REFDIR FORMAT TILES: export, read back with npm pmtiles, compare every tile.
check_export() {
  local a=$1 refs=$2 fmt=$3 tiles=$4 name
  name=$(basename "$a" .pmtiles)_$fmt
  local e="$WORK/$name.pmtiles" js="$WORK/js_$name"
  note "export $(basename "$a") to $fmt"
  expect_ok "$VTS" export "$a" -o "$e" --format "$fmt" --json
  json_check "$OUT" "j.tiles === $tiles" "$name: $tiles tiles written"
  expect_ok "$NODE" "$PMTILES_JS/read_export.mjs" "$e" "$js"
  local h="$LOGS/header_$name.json" type
  cp "$OUT" "$h"
  case $fmt in png) type=2 ;; jpg) type=3 ;; webp) type=4 ;; esac
  local maxz
  maxz=$(json_get "$refs/info.json" j.max_zoom)
  json_check "$h" "j.tileType === $type && j.tileCompression === 1 && j.internalCompression === 2" \
    "$name: tile type $type, tile compression none, gzip directories"
  json_check "$h" "j.minZoom === 0 && j.maxZoom === $maxz && j.tiles_read === $tiles" \
    "$name: zooms 0..$maxz, $tiles tiles read"
  json_check "$h" "j.metadata.format === '$fmt' && j.metadata.tileSize === $T &&
      j.metadata.vtstream_source.archive === '$(basename "$a")' &&
      [0,1,2,3].every(i => Math.abs(j.metadata.bounds[i] - [j.minLon, j.minLat, j.maxLon, j.maxLat][i]) < 1e-6)" \
    "$name: metadata format, tile size, source and bounds (= the header's)"
  local f z x y list="$LOGS/list_$name.txt"
  : >"$list"
  for f in "$js"/*/*/*."$fmt"; do
    IFS=/ read -r z x y <<<"${f#"$js"/}"
    y=${y%."$fmt"}
    [[ -f $refs/${z}_${x}_${y}.png ]] || fail "$name: tile $z/$x/$y is not in the source archive"
    echo "$f $refs/${z}_${x}_${y}.png" >>"$list"
  done
  case $fmt in
    png) expect_ok "$WEB_TILE_COMPARE" exact "$list" ;;
    webp) expect_ok "$WEB_TILE_COMPARE" rgba "$list" "$WEBP_MIN_PSNR" ;;
    jpg) expect_ok "$WEB_TILE_COMPARE" rgb "$list" "$JPEG_MIN_PSNR" ;;
  esac
  note "$name: $(cat "$OUT")"
}

L="$WORK/lossless.pmtiles" C="$WORK/bc1.pmtiles"
build_earth "$L"
expect_ok "$VTS" build --synthetic 1000x600 --codec bc1 -o "$C"
extract_refs "$L" "$WORK/ref_lossless"
extract_refs "$C" "$WORK/ref_bc1"
for fmt in png webp jpg; do
  check_export "$L" "$WORK/ref_lossless" "$fmt" 43
  check_export "$C" "$WORK/ref_bc1" "$fmt" 17
done

note "--quality is applied: Q50 is smaller than the default Q90"
for fmt in webp jpg; do
  expect_ok "$VTS" export "$L" -o "$WORK/q50_$fmt.pmtiles" --format "$fmt" --quality 50
  q50=$(stat -c %s "$WORK/q50_$fmt.pmtiles") q90=$(stat -c %s "$WORK/lossless_$fmt.pmtiles")
  ((q50 < q90 * 3 / 4)) || fail "$fmt: --quality 50 gave $q50 bytes, Q90 $q90"
done

note "--layout xyz: the same tiles, byte for byte"
expect_ok "$VTS" export "$L" --layout xyz -o "$WORK/xyz" --format png
(cd "$WORK/xyz" && find . -name '*.png' | LC_ALL=C sort) >"$LOGS/xyz_list.txt"
(cd "$WORK/js_lossless_png" && find . -name '*.png' | LC_ALL=C sort) >"$LOGS/js_list.txt"
cmp -s "$LOGS/xyz_list.txt" "$LOGS/js_list.txt" || fail "the folder and the archive hold other tiles"
while read -r f; do
  cmp -s "$WORK/xyz/$f" "$WORK/js_lossless_png/$f" || fail "xyz $f differs from the archive's"
done <"$LOGS/xyz_list.txt"
json_check "$WORK/xyz/metadata.json" "j.format === 'png' && j.maxzoom === 3" "xyz metadata.json"

note "wholly transparent tiles are not written"
"$OIIOTOOL" "$EARTH" --resize 1024x512 --ch R,G,B,A=1.0 -o "$WORK/opaque.png"
"$OIIOTOOL" --create 512x512 4 -o "$WORK/clear.png"
"$OIIOTOOL" "$WORK/clear.png" "$WORK/opaque.png" --paste +512+0 -o "$WORK/half.png"
expect_ok "$VTS" build "$WORK/half.png" -o "$WORK/half.pmtiles"
extract_refs "$WORK/half.pmtiles" "$WORK/ref_half"
# z2: 4x2 tiles, the right 2x2 clear; z1: 2x1, the right one clear; z0: half clear.
check_export "$WORK/half.pmtiles" "$WORK/ref_half" png 6
[[ ! -e $WORK/js_half_png/2/2/0.png && ! -e $WORK/js_half_png/1/1/0.png ]] ||
  fail "a wholly transparent tile was written"

note "georeferenced: header bounds are the footprint; WebMercatorQuad is the native grid"
W="$WORK/web.pmtiles"
expect_ok "$VTS" build --synthetic 2048x2048 --tiling WebMercatorQuad --bbox=-20,-10,30,40 -o "$W"
expect_ok "$VTS" export "$W" -o "$WORK/web_png.pmtiles" --format png --tiling WebMercatorQuad
expect_ok "$NODE" "$PMTILES_JS/read_export.mjs" "$WORK/web_png.pmtiles" "$WORK/js_web"
cp "$OUT" "$LOGS/web.json"
json_check "$LOGS/web.json" "Math.abs(j.minLon + 20) < 1e-6 && Math.abs(j.minLat + 10) < 1e-6 &&
    Math.abs(j.maxLon - 30) < 1e-6 && Math.abs(j.maxLat - 40) < 1e-6" "header bounds = --bbox"
expect_ok "$VTS" info --json "$W"
json_check "$LOGS/web.json" "j.tiles_read === $(json_get "$OUT" j.tiles)" "every footprint tile"

note "WorldCRS84Quad reprojected to WebMercatorQuad: every tile is web_mercator_tile's"
: "${WEB_MERCATOR_TILE:?WEB_MERCATOR_TILE must name tests/integration/web_mercator_tile}"
G="$WORK/geo.pmtiles"
expect_ok "$VTS" build --synthetic 2048x1024 --tiling WorldCRS84Quad --bbox=-40,-30,50,88 -o "$G"
expect_ok "$VTS" export "$G" -o "$WORK/geo_web.pmtiles" --format png --tiling WebMercatorQuad --json
cp "$OUT" "$LOGS/geo_export.json"
expect_ok "$NODE" "$PMTILES_JS/read_export.mjs" "$WORK/geo_web.pmtiles" "$WORK/js_geo"
cp "$OUT" "$LOGS/geo.json"
json_check "$LOGS/geo.json" "j.tileType === 2 && j.minZoom === 0 && j.maxZoom === 3 &&
    j.metadata.tiling === 'WebMercatorQuad' && Math.abs(j.minLon + 40) < 1e-6 &&
    Math.abs(j.maxLat - 85.0511288) < 1e-6 && Math.abs(j.minLat + 30) < 1e-6" \
  "reprojected: PNG, zooms 0..3 (our levels), bounds clipped to 85.0511"
json_check "$LOGS/geo.json" "j.tiles_read === $(json_get "$LOGS/geo_export.json" j.tiles) &&
    j.tiles_read > 10" "every reprojected tile read"
: >"$LOGS/list_geo.txt"
for f in "$WORK"/js_geo/*/*/*.png; do
  IFS=/ read -r z x y <<<"${f#"$WORK"/js_geo/}"
  y=${y%.png}
  expect_ok "$WEB_MERCATOR_TILE" "$G" "$z" "$x" "$y" "$WORK/wm_${z}_${x}_$y.rgba"
  echo "$f $WORK/wm_${z}_${x}_$y.rgba" >>"$LOGS/list_geo.txt"
done
expect_ok "$WEB_TILE_COMPARE" exact "$LOGS/list_geo.txt"
note "reprojected: $(cat "$OUT")"

note "memory does not grow with the tile count: 117 tiles vs 10,923 tiles"
peak_rss_kib() { # ARCHIVE OUT: peak RSS (KiB) of a JPEG export
  /usr/bin/time -f %M -o "$LOGS/rss.txt" "$VTS" export "$1" -o "$2" --format jpg -q ||
    fail "vts export $1 failed"
  cat "$LOGS/rss.txt"
}
expect_ok "$VTS" build --synthetic 3000x1700 -o "$WORK/small.pmtiles"
expect_ok "$VTS" build --synthetic 32768x16384 -o "$WORK/large.pmtiles"
small=$(peak_rss_kib "$WORK/small.pmtiles" "$WORK/small.jpg.pmtiles")
large=$(peak_rss_kib "$WORK/large.pmtiles" "$WORK/large.jpg.pmtiles")
note "peak RSS: $small KiB (117 tiles), $large KiB (10,923 tiles)"
((large < small + 16384)) || fail "peak RSS grew from $small KiB to $large KiB with the tile count"

note "SIGINT during an export: exit 130, nothing left (polled: interrupted once tiles are written)"
mkdir -p "$WORK/int"
"$VTS" export "$WORK/large.pmtiles" --layout xyz -o "$WORK/int/site" --format webp --threads 1 \
  -q >"$OUT" 2>"$ERR" </dev/null &
pid=$!
deadline=$((SECONDS + 60))
until [[ -n $(find "$WORK/int" -name '*.webp' -print -quit) ]]; do
  kill -0 "$pid" 2>/dev/null || fail "the export ended before any tile was seen"
  ((SECONDS < deadline)) || fail "no tile written within 60 s"
  sleep 0.05 # poll interval
done
kill -INT "$pid"
set +e
wait "$pid"
RC=$?
set -e
((RC == 130)) || { show_output; fail "interrupted export exited $RC, expected 130"; }
[[ -z $(ls -A "$WORK/int") ]] || fail "an interrupted export left $(ls -A "$WORK/int")"

note "bad inputs fail cleanly and leave nothing"
mkdir -p "$WORK/bad" "$WORK/full"
touch "$WORK/full/keep"
expect_bad() { # EXIT_CODE MESSAGE_REGEX ARGS...
  local code=$1 re=$2
  shift 2
  expect_clean_failure "$VTS" export "$@"
  ((RC == code)) || fail "'vts export $*' exited $RC, expected $code: $(cat "$ERR")"
  grep -qE -- "$re" "$ERR" || fail "'vts export $*': message '$(cat "$ERR")' lacks /$re/"
  [[ -z $(ls -A "$WORK/bad") ]] || fail "'vts export $*' left $(ls -A "$WORK/bad")"
}
expect_bad 3 "missing.pmtiles" "$WORK/missing.pmtiles" -o "$WORK/bad/x.pmtiles" --format png
expect_bad 2 "gif" "$L" -o "$WORK/bad/x.pmtiles" --format gif
expect_bad 2 "--quality 101" "$L" -o "$WORK/bad/x.pmtiles" --format webp --quality 101
expect_bad 2 "--quality 0" "$L" -o "$WORK/bad/x.pmtiles" --format jpg --quality 0
expect_bad 2 "--quality -5" "$L" -o "$WORK/bad/x.pmtiles" --format webp --quality -5
expect_bad 2 "--quality" "$L" -o "$WORK/bad/x.pmtiles" --format webp --quality 99999999999
expect_bad 2 "--threads" "$L" -o "$WORK/bad/x.pmtiles" --format webp --threads 100000
expect_bad 2 "--layout" "$L" -o "$WORK/bad/x.pmtiles" --format webp --layout zxy
expect_bad 2 "--tiling" "$L" -o "$WORK/bad/x.pmtiles" --format webp --tiling Mercator
expect_bad 2 "png is lossless" "$L" -o "$WORK/bad/x.pmtiles" --format png --quality 50
expect_bad 4 "nowhere" "$L" -o "$WORK/nowhere/x.pmtiles" --format png
expect_bad 2 "plain image" "$L" -o "$WORK/bad/x.pmtiles" --format png --tiling WebMercatorQuad
expect_bad 2 "not an export grid" "$W" -o "$WORK/bad/x.pmtiles" --format png --tiling WorldCRS84Quad
expect_bad 2 "not an empty folder" "$L" --layout xyz -o "$WORK/full" --format png
[[ $(ls -A "$WORK/full") == keep ]] || fail "a refused export touched the non-empty folder"
expect_bad 2 "is an input|same file" "$L" -o "$L" --format png
note "ok"
