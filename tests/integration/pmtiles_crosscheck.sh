#!/usr/bin/env bash
# Our archives read the same through the npm `pmtiles` library as through our own reader: every
# addressed tile (id, z/x/y, length, FNV-1a 64 of the payload) and the header fields match exactly.
#
#   pmtiles_crosscheck.sh synthetic|earth
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
: "${PMTILES_DUMP:?PMTILES_DUMP must name the pmtiles_dump tool}"
: "${PMTILES_JS:?PMTILES_JS must name tests/integration/pmtiles_js}"
require_tool "$NODE"
[[ -f $PMTILES_JS/node_modules/pmtiles/package.json ]] ||
  fail "npm package pmtiles is not installed in $PMTILES_JS (run scripts/setup.sh)"

case "${1:-}" in
  synthetic)
    input=(--synthetic 3000x1700)
    max_zoom=4 tiles=117 # levels: 1, 2x1, 3x2, 6x4, 12x7
    ;;
  earth)
    input=("$EARTH")
    max_zoom=3 tiles=43 # levels: 1, 2x1, 4x2, 8x4
    ;;
  *) fail "usage: pmtiles_crosscheck.sh synthetic|earth" ;;
esac

A="$WORK/archive.pmtiles"
note "vts build ${input[*]}"
expect_ok "$VTS" build "${input[@]}" -o "$A"

dump_both() { # MODE
  "$PMTILES_DUMP" "$1" "$A" >"$WORK/cpp_$1.txt" || fail "pmtiles_dump $1 failed"
  "$NODE" "$PMTILES_JS/dump.mjs" "$1" "$A" >"$WORK/js_$1.txt" || fail "node dump.mjs $1 failed"
  if ! cmp -s "$WORK/cpp_$1.txt" "$WORK/js_$1.txt"; then
    diff -u --label "ours ($1)" --label "npm pmtiles ($1)" \
      "$WORK/cpp_$1.txt" "$WORK/js_$1.txt" | head -n 60 >&2 || true
    fail "our reader and the npm pmtiles library disagree ($1)"
  fi
}

note "header: ours vs npm pmtiles"
dump_both header
cat "$WORK/js_header.txt"
H="$WORK/js_header.txt"
field() { sed -n "s/^$1=//p" "$H"; }
[[ $(field spec_version) == 3 ]] || fail "spec version $(field spec_version), expected 3"
[[ $(field min_zoom) == 0 ]] || fail "min zoom $(field min_zoom), expected 0"
[[ $(field max_zoom) == "$max_zoom" ]] || fail "max zoom $(field max_zoom), expected $max_zoom"
[[ $(field tile_compression) == 4 ]] || fail "tile compression $(field tile_compression), expected 4 (zstd)"
[[ $(field addressed_tiles) == "$tiles" ]] ||
  fail "numAddressedTiles $(field addressed_tiles), expected $tiles"
[[ ,$(field metadata_keys), == *,vtstream,* ]] ||
  fail "the JSON metadata has no \"vtstream\" key (keys: $(field metadata_keys))"

note "tiles: ours vs npm pmtiles"
dump_both tiles
n=$(wc -l <"$WORK/js_tiles.txt")
((n == tiles)) || fail "npm pmtiles found $n tiles, expected $tiles"
distinct=$(awk '{print $6}' "$WORK/js_tiles.txt" | sort -u | wc -l)
[[ $distinct == "$(field tile_contents)" ]] ||
  fail "$distinct distinct payloads, but the header says tile_contents=$(field tile_contents)"
note "$n tiles ($distinct distinct payloads) read identically by both"

note "header vs vts info --json"
expect_ok "$VTS" info "$A" --json
cp "$OUT" "$WORK/info.json"
json_check "$WORK/info.json" "j.tiles === $tiles && j.max_zoom === $max_zoom" \
  "vts info: tiles $tiles, max_zoom $max_zoom"
json_check "$WORK/info.json" "j.unique_tiles === $(field tile_contents)" \
  "vts info unique_tiles equals the header's tile_contents ($(field tile_contents))"

note "PASS"
