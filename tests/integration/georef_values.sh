#!/usr/bin/env bash
# vts build of georeferenced rasters whose values are not plain 8-bit RGB, and of many inputs, end
# to end with real files made from the Earth image by gdal_translate/gdalbuildvrt:
#   --bands: a 6-band file with R, G, B as bands 4, 3, 2 builds the same texels as the RGB file;
#     --bands 1,2,3 of a file with nodata, an alpha band or a mask builds the same archive as
#     without (nodata stays transparent);
#     without --bands it is refused (exit 2, naming --bands), a band beyond its count too;
#   --range auto on 12-bit data: the printed range (also in --json) is the 2 %..98 % percentiles per
#     band computed here from the pixels (within 1 % of 4095: the sample is approximate),
#     every texel is the 8-bit original mapped by that range (mean |diff| <= 0.6, max <= 2 codes),
#     and building again with the printed --range gives the same archive (content hash);
#   --range on int16 and float32 data (all bands, and per band) maps back to the original (<= 1);
#   uint16 data within 0..255 builds as it is (the same archive as the 8-bit file); int16 data
#     beyond it is refused (exit 2, naming the input, its values, --range and --range auto);
#   a warning on stderr and in --json's "warnings" for an input using under 1/16 of 0..255;
#   a VRT of 16 pieces (gdalbuildvrt) builds the same archive as the whole file;
#   300 pieces by --input-list and by a quoted glob build the same archive, also under
#     `ulimit -n 64` (inputs are opened a few at a time), and the same as the file they were cut
#     from, and so do that file given before the list; a glob matching nothing (exit 3), a missing
#     list (exit 3), malformed --bands / --range and --bands with a plain image (exit 2) are
#     refused naming what is wrong; no .aux.xml is left beside the inputs.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
require_tool python3
require_tool gdal_translate
require_tool gdalbuildvrt
require_tool gdalwarp

cd "$WORK"
T() { gdal_translate -q "$@" || fail "gdal_translate $*"; }
T -a_srs EPSG:4326 -a_ullr -180 90 180 -90 "$EARTH" world.tif
raw() { T -of ENVI -co INTERLEAVE=BIP "$1" "$2"; }

# build NAME ARGS...: vts build at level 2 (1024 x 512), nearest, --json into NAME.json; the
# archive's content hash into $HASH and its finest level's pixels into NAME.bil.
build() {
  local name=$1
  shift
  expect_ok "$VTS" build "$@" --max-level 2 --resampling near -o "$name.pmtiles" --threads 2 --json
  cp "$OUT" "$name.json"
  cp "$ERR" "$name.err"
  archive_facts "$name"
}
archive_facts() {
  expect_ok "$VTS" info "$1.pmtiles" --json
  HASH=$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["content_hash"])' "$OUT")
  expect_ok "$VTS" extract "$1.pmtiles" --level 2 -o "$1.level.tif"
  raw "$1.level.tif" "$1.bil"
}
# same A B [TOLERANCE]: the RGBA pixels of A.bil and B.bil differ by at most TOLERANCE (0).
same() {
  python3 - "$1.bil" "$2.bil" "${3:-0}" <<'PY' || fail "$1 and $2 differ"
import sys
a, b, tol = open(sys.argv[1], "rb").read(), open(sys.argv[2], "rb").read(), int(sys.argv[3])
assert len(a) == len(b) == 1024 * 512 * 4, (len(a), len(b))
worst = max(abs(x - y) for x, y in zip(a, b)) if a != b else 0
assert worst <= tol, f"max |diff| {worst} > {tol}"
PY
}

build world world.tif
WORLD_HASH=$HASH

note "--bands 4,3,2 of a 6-band file is the RGB file"
T -b 1 -b 3 -b 2 -b 1 -b 2 -b 3 world.tif six.tif # band 4 R, 3 G, 2 B
build six six.tif --bands 4,3,2
[[ $HASH == "$WORLD_HASH" ]] || fail "--bands 4,3,2 built another archive than the RGB file"
expect_clean_failure "$VTS" build six.tif -o x.pmtiles
((RC == 2)) && grep -q "six.tif: 6 bands" "$ERR" && grep -q -- "--bands" "$ERR" ||
  fail "6 bands without --bands (exit $RC): $(cat "$ERR")"
expect_clean_failure "$VTS" build six.tif --bands 1,7,2 -o x.pmtiles
((RC == 2)) && grep -q "six.tif: has 6 bands; --bands asks for band 7" "$ERR" ||
  fail "a band beyond the count (exit $RC): $(cat "$ERR")"

note "--bands keeps nodata, an alpha band and a mask"
T -srcwin 0 0 1024 1024 world.tif west.tif
gdalwarp -q -te -180 -90 90 90 -dstnodata 0 west.tif nodata.tif || fail "gdalwarp" # 0..90 E: nodata
T -b 1 -b 2 -b 3 -b mask -a_nodata none -co ALPHA=YES nodata.tif alpha.tif
T -b 1 -b 2 -b 3 -a_nodata none -mask 1 nodata.tif masked.tif
hash_of() {
  expect_ok "$VTS" info "$1" --json
  python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["content_hash"])' "$OUT"
}
for f in nodata alpha masked; do
  expect_ok "$VTS" build "$f.tif" --max-level 2 -o "$f.pmtiles" --threads 2
  expect_ok "$VTS" build "$f.tif" --bands 1,2,3 --max-level 2 -o "$f.b.pmtiles" --threads 2
  [[ $(hash_of "$f.pmtiles") == $(hash_of "$f.b.pmtiles") ]] ||
    fail "$f: --bands 1,2,3 built another archive"
done
expect_ok "$VTS" extract nodata.b.pmtiles --level 2 -o nodata.level.tif
raw nodata.level.tif nodata.bil
python3 - nodata.bil <<'PY' || fail "nodata is not transparent with --bands"
import sys
a = open(sys.argv[1], "rb").read()
# Level 2 is 1024 x 512; the nodata covers longitudes 0..90: columns 512..768.
bad = [(x, y) for y in range(0, 512, 3) for x in range(514, 766, 3) if a[4 * (y * 1024 + x) + 3] != 0]
assert not bad, ("nodata texels not transparent", bad[:5])
assert all(a[4 * (y * 1024 + 300) + 3] == 255 for y in range(512)), "the data part is not opaque"
PY

note "--range auto on 12-bit data: the 2%..98% percentiles, printed, reusable"
T -ot UInt16 -scale 0 255 1000 3000 world.tif u12.tif # 12-bit values, not all of 0..4095
build u12 u12.tif --range auto
RANGE=$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["range"])' u12.json)
note "chosen: --range $RANGE"
raw u12.tif u12.raw
raw world.tif world.raw
python3 - u12.raw "$RANGE" u12.bil world.bil <<'PY' || fail "--range auto"
import array, sys
v = array.array("H", open(sys.argv[1], "rb").read())
r = [float(x) for x in sys.argv[2].split(",")]
assert len(r) == 6, r
for k in range(3):
    hist = [0] * 4096
    for x in v[k::3]:
        hist[x] += 1
    total, acc, lo, hi = sum(hist), 0, None, None
    for value, c in enumerate(hist):
        acc += c
        if lo is None and acc >= 0.02 * total:
            lo = value
        if hi is None and acc >= 0.98 * total:
            hi = value
    got = r[2 * k:2 * k + 2]
    print(f"band {k + 1}: exact percentiles {lo}..{hi}, chosen {got[0]:g}..{got[1]:g}")
    assert abs(got[0] - lo) <= 41 and abs(got[1] - hi) <= 41, (k, lo, hi, got)
ours, orig = open(sys.argv[3], "rb").read(), open(sys.argv[4], "rb").read()
worst, total, n = 0, 0, 0
for i in range(0, 1024 * 512 * 4, 4):
    for k in range(3):
        lo, hi = r[2 * k], r[2 * k + 1]
        u12 = round(1000 + orig[i + k] * 2000 / 255)
        want = min(255, max(0, round((u12 - lo) * 255 / (hi - lo))))
        d = abs(ours[i + k] - want)
        worst, total, n = max(worst, d), total + d, n + 1
print(f"against the 8-bit original mapped by the range: mean {total / n:.3f}, max {worst}")
assert total / n <= 0.6 and worst <= 2
PY
AUTO_HASH=$HASH
grep -q "value range: --range" u12.err && fail "the range went to stderr"
expect_ok "$VTS" build u12.tif --range auto --max-level 2 --resampling near -o u12b.pmtiles
grep -q "^value range: --range $RANGE\$" "$OUT" || fail "the range is not printed: $(cat "$OUT")"
build u12again u12.tif --range "$RANGE"
[[ $HASH == "$AUTO_HASH" ]] || fail "the printed range does not build the same archive"

note "int16 and float32 with --range, uint16 within 0..255 as it is"
T -ot Int16 -scale 0 255 -1000 1000 world.tif i16.tif
build i16 i16.tif --range=-1000,1000
same i16 world 1
T -ot Float32 -scale 0 255 0 1 world.tif f32.tif
build f32 f32.tif --range 0,1
same f32 world 1
build f32band f32.tif --range 0,1,0,2,0,1 # green halved
python3 - f32band.bil world.bil <<'PY' || fail "a per-band range"
import sys
a, b = open(sys.argv[1], "rb").read(), open(sys.argv[2], "rb").read()
worst = max(abs(a[i + k] - (b[i + k] / 2 if k == 1 else b[i + k])) for i in range(0, len(a), 4) for k in range(3))
assert worst <= 1, worst
PY
T -ot UInt16 world.tif u8in16.tif
build u8in16 u8in16.tif
[[ $HASH == "$WORLD_HASH" ]] || fail "uint16 data within 0..255 did not build as it is"
expect_clean_failure "$VTS" build i16.tif -o x.pmtiles
((RC == 2)) && grep -q "i16.tif: Int16 data (values about -1000 .. 1000) would clip" "$ERR" &&
  grep -q -- "--range auto" "$ERR" || fail "int16 without --range (exit $RC): $(cat "$ERR")"

note "a warning for values using under 1/16 of 0..255"
T -scale 0 255 0 9 world.tif dark.tif
build dark dark.tif
grep -q "^warning: dark.tif: values 0 .. 9 use under 1/16 of 0..255" dark.err ||
  fail "no warning on stderr: $(cat dark.err)"
json_check dark.json 'j.warnings.length === 1 && j.warnings[0].startsWith("dark.tif: values 0 .. 9")' \
  "the warning in --json"
json_check world.json 'Array.isArray(j.warnings) && j.warnings.length === 0 && !("range" in j)' \
  "no warnings, no range for the 8-bit file"

note "a VRT of 16 pieces is the whole file"
mkdir vrt
for r in 0 1 2 3; do
  for c in 0 1 2 3; do T -srcwin $((c * 512)) $((r * 256)) 512 256 world.tif "vrt/p$r$c.tif"; done
done
gdalbuildvrt -q mosaic.vrt vrt/*.tif || fail "gdalbuildvrt"
build vrt mosaic.vrt
[[ $HASH == "$WORLD_HASH" ]] || fail "the VRT built another archive than the whole file"

note "300 pieces: --input-list, a glob, and ulimit -n 64"
T -outsize 600 300 world.tif small.tif # 0.6 degree pixels: level 2 (1024 texels around)
raw small.tif small.raw
# Its 20 x 15 pieces of 30 x 20 pixels as GeoTIFFs (EPSG:4326, uncompressed RGB) written here:
# 300 gdal_translate runs would take half a minute.
mkdir pieces
python3 - small.raw <<'PY' || fail "writing the pieces"
import struct, sys
src = open(sys.argv[1], "rb").read()
W, w, h = 600, 30, 20
for r in range(15):
    for c in range(20):
        data = b"".join(src[3 * ((r * h + y) * W + c * w):3 * ((r * h + y) * W + c * w + w)]
                        for y in range(h))
        extra = (struct.pack("<3H", 8, 8, 8) + struct.pack("<3d", 0.6, 0.6, 0)
                 + struct.pack("<6d", 0, 0, 0, -180 + c * w * 0.6, 90 - r * h * 0.6, 0)
                 + struct.pack("<16H", 1, 1, 0, 3, 1024, 0, 1, 2, 1025, 0, 1, 1, 2048, 0, 1, 4326))
        tags = [(256, 3, 1, w), (257, 3, 1, h), (258, 3, 3, "bps"), (259, 3, 1, 1),
                (262, 3, 1, 2), (273, 4, 1, "data"), (277, 3, 1, 3), (278, 3, 1, h),
                (279, 4, 1, len(data)), (284, 3, 1, 1), (33550, 12, 3, "scale"),
                (33922, 12, 6, "tie"), (34735, 3, 16, "keys")]
        base = 8 + 2 + 12 * len(tags) + 4
        at = {"bps": base, "scale": base + 6, "tie": base + 30, "keys": base + 78,
              "data": base + len(extra)}
        ifd = struct.pack("<H", len(tags))
        for tag, typ, count, value in tags:
            v = at[value] if isinstance(value, str) else value
            ifd += struct.pack("<HHI", tag, typ, count)
            ifd += struct.pack("<HH", v, 0) if typ == 3 and count == 1 else struct.pack("<I", v)
        ifd += struct.pack("<I", 0)
        with open(f"pieces/p{r:02d}_{c:02d}.tif", "wb") as f:
            f.write(b"II*\0" + struct.pack("<I", 8) + ifd + extra + data)
PY
{
  echo "# the pieces of small.tif"
  echo
  ls pieces/*.tif
} >list.txt
many() { # many NAME ARGS...: a level 2 build of ARGS; its content hash into $HASH
  local name=$1
  shift
  expect_ok "$@" --resampling near -o "$name.pmtiles" --threads 2 --json
  json_check "$OUT" 'j.max_zoom === 2' "$name: level 2"
  expect_ok "$VTS" info "$name.pmtiles" --json
  HASH=$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["content_hash"])' "$OUT")
}
many small "$VTS" build small.tif
SMALL_HASH=$HASH
many list "$VTS" build --input-list list.txt
[[ $HASH == "$SMALL_HASH" ]] || fail "the 300 pieces built another archive than the whole file"
many limited bash -c 'ulimit -n 64 && exec "$@"' sh "$VTS" build --input-list list.txt
[[ $HASH == "$SMALL_HASH" ]] || fail "under ulimit -n 64 the 300 pieces built another archive"
many both "$VTS" build small.tif --input-list list.txt # given inputs first, then the list's
[[ $HASH == "$SMALL_HASH" ]] || fail "an input and a list together"
many glob bash -c 'ulimit -n 64 && exec "$@"' sh "$VTS" build 'pieces/p*.tif'
[[ $HASH == "$SMALL_HASH" ]] || fail "the glob built another archive"
expect_clean_failure "$VTS" build 'pieces/q*.tif' -o x.pmtiles
((RC == 3)) && grep -q "input pattern 'pieces/q\*.tif' matches no file" "$ERR" ||
  fail "an empty glob (exit $RC): $(cat "$ERR")"
expect_clean_failure "$VTS" build --input-list missing.txt -o x.pmtiles
((RC == 3)) && grep -q "input-list 'missing.txt' cannot be read" "$ERR" ||
  fail "a missing list (exit $RC): $(cat "$ERR")"
for bad in 0 1,2 1,2,3,4 x; do
  expect_clean_failure "$VTS" build world.tif --bands "$bad" -o x.pmtiles
  ((RC == 2)) && grep -q -- "--bands '$bad' is not B (grey) or R,G,B" "$ERR" ||
    fail "--bands $bad (exit $RC): $(cat "$ERR")"
done
for bad in 1 1,2,3 5,1 1,2,3,4 auto,1; do
  expect_clean_failure "$VTS" build u12.tif --range "$bad" -o x.pmtiles
  ((RC == 2)) && grep -q -- "--range '$bad' is not" "$ERR" || fail "--range $bad (exit $RC): $(cat "$ERR")"
done
expect_clean_failure "$VTS" build "$EARTH" --bands 1 -o x.pmtiles
((RC == 2)) && grep -q "bands and a value range apply to georeferenced inputs only" "$ERR" ||
  fail "--bands with a plain image (exit $RC): $(cat "$ERR")"
[[ -z $(find . -name '*.tif.aux.xml' -o -name '*.vrt.aux.xml') ]] ||
  fail "statistics were written beside the inputs: $(find . -name '*.aux.xml')"
note "ok"
