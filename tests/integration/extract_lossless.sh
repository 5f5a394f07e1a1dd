#!/usr/bin/env bash
# Lossless end to end: the finest level extracted from an archive built from the Earth JPEG equals
# the source pixels exactly (OpenImageIO's idiff with zero tolerance), and so do single tiles, with
# and without their borders. Coarser levels have the expected sizes.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
require_tool "$OIIOTOOL"
require_tool "$IDIFF"

A="$WORK/earth.pmtiles"
build_earth "$A"

note "vts extract --level 3 (the finest level) == source"
expect_ok "$VTS" extract "$A" --level 3 -o "$WORK/level3.png"
expect_same_pixels "$WORK/level3.png" "$EARTH"

note "coarser levels have the downsampled sizes"
for lv in 2:1024:512 1:512:256 0:256:128; do
  IFS=: read -r z w h <<<"$lv"
  expect_ok "$VTS" extract "$A" --level "$z" -o "$WORK/level$z.png"
  read -r gw gh _ <<<"$(image_dims "$WORK/level$z.png")"
  [[ "$gw x $gh" == "$w x $h" ]] || fail "level $z extracted as ${gw}x${gh}, expected ${w}x${h}"
done

note "single tiles == the matching window of the source"
# 3/1/0: top edge; 3/7/3: bottom-right corner tile.
for t in 3/1/0 3/7/3 3/5/2; do
  IFS=/ read -r z x y <<<"$t"
  expect_ok "$VTS" extract "$A" "$t" -o "$WORK/tile_${x}_${y}.png"
  crop_ref "$EARTH" 256 256 $((x * 256)) $((y * 256)) "$WORK/ref_${x}_${y}.png"
  expect_same_pixels "$WORK/tile_${x}_${y}.png" "$WORK/ref_${x}_${y}.png"
done

note "an interior tile with its border == the source window grown by 4 texels"
expect_ok "$VTS" extract "$A" 3/3/1 --with-border -o "$WORK/tile_3_1_b.png"
crop_ref "$EARTH" 264 264 $((3 * 256 - 4)) $((1 * 256 - 4)) "$WORK/ref_3_1_b.png"
expect_same_pixels "$WORK/tile_3_1_b.png" "$WORK/ref_3_1_b.png"

note "extracting a tile that does not exist fails cleanly"
for t in 3/0/4 3/8/0 4/0/0; do  # below the image; outside level 3; below the finest level
  expect_clean_failure "$VTS" extract "$A" "$t" -o "$WORK/none.png"
  [[ ! -e $WORK/none.png ]] || fail "vts extract wrote a file for the missing tile $t"
done
expect_clean_failure "$VTS" extract "$A" --level 9 -o "$WORK/none.png"
[[ ! -e $WORK/none.png ]] || fail "vts extract wrote a file for a missing level"

note "translucent RGBA PNG: straight alpha in, the same texels out (never premultiplied)"
# Every alpha from 0.1 to 1 and saturated colours: a reader or writer that premultiplied (or
# divided) by alpha on the way changes colour codes where alpha < 1.
"$OIIOTOOL" --pattern fill:topleft=1,0.2,0,0.1:topright=0,1,0.4,0.5:bottomleft=0.3,0,1,1:bottomright=1,1,0.7,0.25 \
  300x200 4 -d uint8 -o "$WORK/alpha.png" || fail "cannot make the RGBA input"
expect_ok "$VTS" build "$WORK/alpha.png" -o "$WORK/alpha.pmtiles" --tile 64
expect_ok "$VTS" extract "$WORK/alpha.pmtiles" --level 3 -o "$WORK/alpha_out.png"
for f in alpha alpha_out; do
  "$OIIOTOOL" --iconfig oiio:UnassociatedAlpha 1 --dumpdata "$WORK/$f.png" >"$WORK/$f.txt" 2>&1 ||
    fail "cannot dump $f.png"
done
if ! cmp -s <(grep Pixel "$WORK/alpha.txt") <(grep Pixel "$WORK/alpha_out.txt"); then
  diff <(grep Pixel "$WORK/alpha.txt") <(grep Pixel "$WORK/alpha_out.txt") | head -n 6 >&2
  fail "the RGBA texels changed between the PNG and the archive (alpha handling)"
fi
grep -q "Pixel" "$WORK/alpha.txt" || fail "no texels dumped from alpha.png"

note "PASS"
