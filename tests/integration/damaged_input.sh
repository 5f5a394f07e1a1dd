#!/usr/bin/env bash
# `vts build` on a truncated or corrupt input (PNG, JPEG, strip and tiled TIFF, a piece of a
# mosaic) exits 5 with a message naming the file and what failed, and writes nothing: no output
# file, no temporary file, an archive already under the output name left as it was. Was: the
# decoders' complaints (libjpeg's "Premature end of JPEG file", libtiff's short strips) were
# ignored and the build exited 0 with an archive of grey or black tiles that `vts verify` passed.
# Inputs with harmless oddities (bytes after the end of the image, an unknown JFIF revision, a bad
# CRC on a PNG text chunk) still build; a file that is no image at all is exit 2.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
require_tool "$OIIOTOOL"
require_tool python3

HERE=$(dirname "${BASH_SOURCE[0]}")
D="$WORK/out"
I="$WORK/in"
mkdir -p "$D" "$I"

# cut FILE BYTES OUT: the first BYTES bytes of FILE.
cut_to() { head -c "$2" "$1" >"$3"; }
size_of() { stat -c %s "$1"; }
# flip FILE OFFSET OUT: FILE with the byte at OFFSET inverted.
flip() {
  python3 -c 'import sys; d = bytearray(open(sys.argv[1], "rb").read()); o = int(sys.argv[2])
d[o] ^= 0xFF; open(sys.argv[3], "wb").write(d)' "$1" "$2" "$3"
}

# expect_damaged KIND TEXT NAMED ARGS...: `vts build ARGS -o $D/out.pmtiles` exits 5 saying
# "'NAMED' is KIND" and TEXT, and leaves $D as it was.
expect_damaged() {
  local kind=$1 text=$2 named=$3 before after
  shift 3
  before=$(dir_listing "$D")
  run "$VTS" build "$@" -o "$D/out.pmtiles"
  if ((RC != 5)) || ! grep -qF "'$named' is $kind" "$ERR" || ! grep -qF "$text" "$ERR"; then
    show_output
    fail "vts build $* exited $RC, expected 5 with \"'$named' is $kind\" and \"$text\""
  fi
  after=$(dir_listing "$D")
  [[ $after == "$before" ]] || fail "vts build $* left files behind: $(echo "$after" | tr '\n' ' ')"
}

# expect_builds FILE: a clean build of FILE that verifies.
expect_builds() {
  expect_ok "$VTS" build "$1" -o "$D/ok.pmtiles"
  expect_ok "$VTS" verify "$D/ok.pmtiles"
  rm -f "$D/ok.pmtiles"
}

note "inputs: the Earth JPEG as PNG, as OpenImageIO's TIFF and as directory-first strip/tiled TIFFs"
cp "$EARTH" "$I/earth.jpg"
"$OIIOTOOL" "$EARTH" -o "$I/earth.png"
"$OIIOTOOL" "$EARTH" -o "$I/earth-oiio.tif"
"$OIIOTOOL" "$EARTH" -o "$WORK/earth.ppm"
for layout in strip tiled; do
  python3 "$HERE/tiff_directory_first.py" "$WORK/earth.ppm" "$I/$layout.tif" $layout
  python3 "$HERE/tiff_directory_first.py" "$WORK/earth.ppm" "$I/$layout-deflate.tif" $layout deflate
done
for f in "$I"/*; do
  expect_builds "$f"
done

note "truncated at 50% and 90%: pixel data cut short"
for f in earth.jpg earth.png strip.tif tiled.tif strip-deflate.tif tiled-deflate.tif; do
  n=$(size_of "$I/$f")
  for pct in 50 90; do
    cut_to "$I/$f" $((n * pct / 100)) "$I/cut$pct-$f"
    expect_damaged truncated "reading rows" "$I/cut$pct-$f" "$I/cut$pct-$f"
  done
done

note "truncated in the header: the file no longer opens"
cut_to "$I/earth.jpg" 300 "$I/head-earth.jpg"
expect_damaged truncated "opening it as jpeg failed: JPEG error: Premature end of JPEG file" \
  "$I/head-earth.jpg" "$I/head-earth.jpg"
cut_to "$I/earth.png" 100 "$I/head-earth.png"
expect_damaged truncated "opening it as png failed" "$I/head-earth.png" "$I/head-earth.png"
cut_to "$I/strip.tif" 100 "$I/head-strip.tif"
expect_damaged corrupt "opening it as tiff failed" "$I/head-strip.tif" "$I/head-strip.tif"
# OpenImageIO writes the TIFF directory last, so any cut loses it.
cut_to "$I/earth-oiio.tif" $(($(size_of "$I/earth-oiio.tif") * 90 / 100)) "$I/cut90-earth-oiio.tif"
expect_damaged corrupt "opening it as tiff failed: Could not open file" \
  "$I/cut90-earth-oiio.tif" "$I/cut90-earth-oiio.tif"
# Headers only, no pixel data at all: the JPEG's scan has just begun.
cut_to "$I/earth.jpg" 2000 "$I/scan-earth.jpg"
expect_damaged truncated "reading rows 0..64 failed: JPEG error: Premature end of JPEG file" \
  "$I/scan-earth.jpg" "$I/scan-earth.jpg"
: >"$I/empty.png"
expect_damaged truncated "empty" "$I/empty.png" "$I/empty.png"

note "corrupt bytes in the middle"
flip "$I/earth.png" $(($(size_of "$I/earth.png") / 2)) "$I/flip-data.png"
expect_damaged corrupt "IDAT: CRC error" "$I/flip-data.png" "$I/flip-data.png"
# The stored CRC of the first IDAT chunk itself.
idat_crc=$(python3 -c 'import struct, sys
d = open(sys.argv[1], "rb").read(); p = 8
while d[p + 4:p + 8] != b"IDAT": p += 12 + struct.unpack(">I", d[p:p + 4])[0]
print(p + 8 + struct.unpack(">I", d[p:p + 4])[0])' "$I/earth.png")
flip "$I/earth.png" "$idat_crc" "$I/flip-crc.png"
expect_damaged corrupt "IDAT: CRC error" "$I/flip-crc.png" "$I/flip-crc.png"
# JPEG has no checksum: a flipped byte is seen only where it breaks the entropy coding. This one
# (in the Earth JPEG's restart interval structure) makes libjpeg warn and resynchronise.
flip "$I/earth.jpg" 200000 "$I/flip.jpg"
expect_damaged corrupt "Corrupt JPEG data" "$I/flip.jpg" "$I/flip.jpg"

note "a 2x1 mosaic whose second piece is truncated: the error names that piece"
expect_damaged truncated "reading rows" "$I/cut90-earth.jpg" --grid 2x1 "$I/earth.jpg" "$I/cut90-earth.jpg"
expect_damaged truncated "reading rows" "$I/cut50-strip.tif" --grid 2x1 "$I/strip.tif" "$I/cut50-strip.tif"

note "a failed build leaves an archive already under the output name untouched"
expect_ok "$VTS" build "$I/earth.jpg" -o "$D/out.pmtiles"
cp "$D/out.pmtiles" "$WORK/out.orig"
expect_damaged truncated "reading rows" "$I/cut50-earth.png" "$I/cut50-earth.png"
cmp -s "$D/out.pmtiles" "$WORK/out.orig" || fail "a failed build changed the existing archive"
rm "$D/out.pmtiles"

note "a file that is no image at all: a bad argument (exit 2), not a damaged image"
printf 'this is not an image\n' >"$I/text.png"
run "$VTS" build "$I/text.png" -o "$D/x.pmtiles"
((RC == 2)) || { show_output; fail "vts build on a text file exited $RC, expected 2"; }
[[ ! -e $D/x.pmtiles ]] || fail "vts build on a text file wrote $D/x.pmtiles"

note "harmless oddities still build"
{ cat "$I/earth.jpg"; printf 'trailing bytes after EOI\n'; } >"$I/trailing.jpg"
{ cat "$I/earth.png"; printf 'trailing bytes after IEND\n'; } >"$I/trailing.png"
expect_builds "$I/trailing.jpg"
expect_builds "$I/trailing.png"
# JFIF version byte (offset 11) 3: libjpeg warns "unknown JFIF revision number", pixels intact.
python3 -c 'import sys; d = bytearray(open(sys.argv[1], "rb").read()); assert d[6:11] == b"JFIF\0"
d[11] = 3; open(sys.argv[2], "wb").write(d)' "$I/earth.jpg" "$I/jfif3.jpg"
expect_builds "$I/jfif3.jpg"
# A bad CRC on an ancillary chunk (the first tEXt): libpng drops the chunk, the pixels are intact.
text_crc=$(python3 -c 'import struct, sys
d = open(sys.argv[1], "rb").read(); p = 8
while d[p + 4:p + 8] != b"tEXt": p += 12 + struct.unpack(">I", d[p:p + 4])[0]
print(p + 8 + struct.unpack(">I", d[p:p + 4])[0])' "$I/earth.png")
flip "$I/earth.png" "$text_crc" "$I/text-crc.png"
expect_builds "$I/text-crc.png"

note "PASS"
