#!/usr/bin/env bash
# A build from a real JPEG verifies clean and `vts info --json` describes its geometry.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
require_tool "$NODE"

A="$WORK/earth.pmtiles"
note "vts build $EARTH"
build_earth "$A"

note "vts verify"
expect_ok "$VTS" verify "$A"

note "vts verify --json"
expect_ok "$VTS" verify "$A" --json
cp "$OUT" "$WORK/verify.json"
json_check "$WORK/verify.json" 'typeof j === "object" && j !== null' "verify --json prints a JSON object"

note "vts info (human)"
expect_ok "$VTS" info "$A"
grep -q '[^[:space:]]' "$OUT" || fail "vts info printed nothing"

note "vts info --json"
expect_ok "$VTS" info "$A" --json
cp "$OUT" "$WORK/info.json"
I="$WORK/info.json"
# 2048x1024 in 256-px tiles: max zoom 3; levels have 1x1, 2x1, 4x2, 8x4 tiles = 43 tiles.
json_check "$I" 'j.width === 2048 && j.height === 1024' "width 2048, height 1024"
json_check "$I" 'j.tile_size === 256 && j.border === 4' "tile_size 256, border 4 (defaults)"
json_check "$I" 'j.max_zoom === 3' "max_zoom 3"
json_check "$I" 'j.codec === "lossless"' "codec lossless (default)"
json_check "$I" 'Array.isArray(j.levels) && j.levels.length === 4' "4 levels"
json_check "$I" 'j.levels.map(l => l.z).join() === "0,1,2,3"' "levels z = 0..3 in order"
json_check "$I" 'j.levels.map(l => l.tiles).join() === "1,2,8,32"' "tiles per level 1,2,8,32"
json_check "$I" 'j.tiles === 43' "43 tiles in all"
json_check "$I" 'Number.isInteger(j.unique_tiles) && j.unique_tiles >= 1 && j.unique_tiles <= j.tiles' \
  "1 <= unique_tiles <= tiles"
json_check "$I" 'Number.isInteger(j.bytes) && j.bytes > 0' "bytes > 0"
json_check "$I" 'typeof j.dedup_ratio === "number" && j.dedup_ratio > 0' "dedup_ratio is a positive number"

note "rebuilding over an existing archive replaces it"
build_earth "$A"
expect_ok "$VTS" verify "$A"

note "vts build --synthetic 3000x1700 --json prints JSON on stdout"
expect_ok "$VTS" build --synthetic 3000x1700 -o "$WORK/synth.pmtiles" --json
cp "$OUT" "$WORK/build.json"
json_check "$WORK/build.json" 'typeof j === "object" && j !== null' "build --json prints a JSON object"
expect_ok "$VTS" info "$WORK/synth.pmtiles" --json
cp "$OUT" "$WORK/synth_info.json"
# 3000x1700: max zoom 4; levels 1, 2x1, 3x2, 6x4, 12x7 tiles = 117.
json_check "$WORK/synth_info.json" 'j.width === 3000 && j.height === 1700 && j.max_zoom === 4' \
  "synthetic 3000x1700, max_zoom 4"
json_check "$WORK/synth_info.json" 'j.levels.map(l => l.tiles).join() === "1,2,6,24,84" && j.tiles === 117' \
  "synthetic tiles per level 1,2,6,24,84 (117)"
expect_ok "$VTS" verify "$WORK/synth.pmtiles"

note "PASS"
