#!/usr/bin/env bash
# One flipped byte inside one tile's payload: `vts verify` exits 5 and names that tile (z/x/y) on
# stderr, and `vts extract` refuses to hand out the tile.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
: "${PMTILES_DUMP:?PMTILES_DUMP must name the pmtiles_dump tool}"

A="$WORK/earth.pmtiles"
build_earth "$A"
"$PMTILES_DUMP" offsets "$A" >"$WORK/offsets.txt" || fail "pmtiles_dump offsets failed"

# Pick a finest-level tile whose payload is stored once (not shared through dedup), so that the
# corruption belongs to exactly one tile: lines are "tile_id z x y absolute_offset length".
read -r _ z x y off len < <(awk '
  { count[$5]++; line[NR] = $0; offs[NR] = $5; zs[NR] = $2 }
  END { for (i = NR; i >= 1; i--) if (count[offs[i]] == 1 && zs[i] == 3) { print line[i]; exit } }
' "$WORK/offsets.txt")
[[ -n ${len:-} ]] || fail "no unshared tile at level 3 in $A"
(( len > 64 )) || fail "tile $z/$x/$y has only $len bytes"

# Flip every bit of one byte in the middle of the tile's zstd body (past our 40-byte header frame).
pos=$((off + 40 + (len - 40) / 2))
old=$(od -An -tu1 -j "$pos" -N1 "$A" | tr -d ' ')
new=$((old ^ 0xFF))
B="$WORK/bitflip.pmtiles"
cp "$A" "$B"
printf '%b' "\\0$(printf '%03o' "$new")" | dd of="$B" bs=1 seek="$pos" conv=notrunc status=none
cmp -s "$A" "$B" && fail "byte flip did not change the file"
note "flipped byte $pos ($old -> $new) inside tile $z/$x/$y"

expect_clean_failure "$VTS" verify "$B"
((RC == 5)) || { show_output; fail "vts verify exited $RC on a corrupt tile, expected 5"; }
grep -qE "(^|[^0-9/])$z/$x/$y([^0-9/]|$)" "$ERR" || {
  show_output
  fail "vts verify did not name the corrupt tile $z/$x/$y on stderr"
}

note "vts verify --json on the corrupt archive"
expect_clean_failure "$VTS" verify "$B" --json
((RC == 5)) || fail "vts verify --json exited $RC on a corrupt tile, expected 5"

note "vts extract of the corrupt tile fails and writes nothing"
expect_clean_failure "$VTS" extract "$B" "$z/$x/$y" -o "$WORK/bad_tile.png"
[[ ! -e $WORK/bad_tile.png ]] || fail "vts extract wrote $WORK/bad_tile.png from a corrupt tile"

note "the untouched archive still verifies"
expect_ok "$VTS" verify "$A"

note "PASS"
