#!/usr/bin/env bash
# `cmake --install` of the build under test, as a release is made: bin/vts and bin/vts-build are
# stripped (no .debug_* sections, no symbol table) and each has its debug information apart in
# bin/.debug/NAME.debug, named by a .gnu_debuglink section (where gdb looks); the installed vts
# loads neither GDAL nor OpenImageIO nor their heavy dependencies, lists the build commands and
# hands them over to the installed vts-build beside it; without a vts-build beside it or on PATH,
# `vts build` fails with exit 6 saying vts-build is missing, and the runtime commands still work,
# `vts extract` of a tile as PNG among them (the pixels vts-build's OpenImageIO writer gives).
source "$(dirname "$0")/lib.sh"
: "${VTS_BUILD_DIR:?VTS_BUILD_DIR must name the build folder to install}"
require_tool readelf

P=$WORK/prefix
note "cmake --install $VTS_BUILD_DIR --prefix $P"
expect_ok cmake --install "$VTS_BUILD_DIR" --prefix "$P"
for exe in vts vts-build; do
  bin=$P/bin/$exe dbg=$P/bin/.debug/$exe.debug
  [[ -x $bin ]] || fail "no $bin after the install"
  [[ -s $dbg ]] || fail "no $dbg after the install"
  # (readelf's whole output first: `readelf | grep -q` under pipefail fails when grep stops early.)
  readelf -S --wide "$bin" >"$WORK/$exe.sections" 2>&1 || fail "readelf -S $bin failed"
  # (its exit status is not used: for a .debug file readelf may complain of the missing
  # program interpreter; what matters is the section list it printed)
  readelf -S --wide "$dbg" >"$WORK/$exe.debug.sections" 2>&1 || true
  if grep -E '\.debug_|\.symtab' "$WORK/$exe.sections"; then
    fail "$bin is not stripped (sections above)"
  fi
  grep -q '\.debug_line' "$WORK/$exe.debug.sections" || fail "$dbg holds no .debug_line"
  link=$(readelf --string-dump=.gnu_debuglink "$bin" | sed -nE 's/^ *\[ *0\] +//p')
  [[ $link == "$exe.debug" ]] || fail "$bin's .gnu_debuglink names '$link', expected $exe.debug"
  note "$exe: $(stat -c %s "$bin") bytes stripped, debug information $(stat -c %s "$dbg") bytes"
done

note "the installed runtime vts: no GDAL, OpenImageIO, OpenVDB, poppler, HDF5"
ldd "$P/bin/vts" >"$WORK/ldd.txt" || fail "ldd $P/bin/vts failed"
if grep -iE 'gdal|openimageio|openvdb|poppler|hdf5' "$WORK/ldd.txt"; then
  fail "the runtime vts loads the libraries above"
fi
note "$(wc -l <"$WORK/ldd.txt") shared libraries"
expect_ok "$P/bin/vts" --help
for c in build plan merge extract export serve loadtest; do
  grep -qE "^ +$c " "$OUT" || fail "vts --help does not list $c"
done

note "the installed vts hands vts build to the installed vts-build"
expect_ok "$P/bin/vts" build --synthetic 600x400 -o "$WORK/a.pmtiles"
expect_ok "$P/bin/vts" verify "$WORK/a.pmtiles"
expect_ok "$P/bin/vts" build --help
grep -q '^Usage: vts build' "$OUT" || fail "vts build --help: $(head -1 "$OUT")"

note "vts without vts-build: build fails saying so (exit 6), serve's help still works"
mkdir -p "$WORK/alone"
cp "$P/bin/vts" "$WORK/alone/vts"
PATH=/usr/bin:/bin run "$WORK/alone/vts" build --synthetic 600x400 -o "$WORK/b.pmtiles"
((RC == 6)) || { show_output; fail "vts build without vts-build exited $RC, expected 6"; }
grep -q "vts-build, which is not installed" "$ERR" || { show_output; fail "no message naming vts-build"; }
[[ ! -e $WORK/b.pmtiles ]] || fail "vts build without vts-build wrote $WORK/b.pmtiles"
PATH=/usr/bin:/bin expect_ok "$WORK/alone/vts" info "$WORK/a.pmtiles"

note "vts without vts-build extracts a tile as PNG itself, the pixels OpenImageIO's TIFF has"
# (600 x 400 texels, 256-texel tiles: 2/2/1 is an edge tile, clipped to 88 x 144 texels.)
for t in 2/0/0 2/2/1; do
  f=${t//\//_}
  PATH=/usr/bin:/bin expect_ok "$WORK/alone/vts" extract "$WORK/a.pmtiles" "$t" -o "$WORK/$f.png"
  expect_ok "$P/bin/vts" extract "$WORK/a.pmtiles" "$t" -o "$WORK/$f.tif"  # vts-build's writer
  expect_same_pixels "$WORK/$f.png" "$WORK/$f.tif"
done
read -r w h c <<<"$(image_dims "$WORK/2_2_1.png")"
[[ "$w $h $c" == "88 144 4" ]] || fail "the edge tile's PNG is ${w}x${h}, $c channels; expected 88x144, 4"
PATH=/usr/bin:/bin expect_ok "$WORK/alone/vts" extract "$WORK/a.pmtiles" 2/1/0 --with-border \
  --channels 3 -o "$WORK/border.png"
read -r w h c <<<"$(image_dims "$WORK/border.png")"
[[ "$w $h $c" == "264 264 3" ]] || fail "--with-border --channels 3 gave ${w}x${h}, $c channels"
expect_ok "$P/bin/vts" extract "$WORK/a.pmtiles" 2/1/0 --with-border --channels 3 -o "$WORK/border.tif"
expect_same_pixels "$WORK/border.png" "$WORK/border.tif"
note "... and hands a whole level, or another format, to vts-build: exit 6 without it"
for args in "--level 1 -o $WORK/level.png" "2/0/0 -o $WORK/tile.tif"; do
  # shellcheck disable=SC2086  # the words of $args are the arguments
  PATH=/usr/bin:/bin run "$WORK/alone/vts" extract "$WORK/a.pmtiles" $args
  ((RC == 6)) || { show_output; fail "vts extract $args without vts-build exited $RC, expected 6"; }
  grep -q "vts-build, which is not installed" "$ERR" || { show_output; fail "no message naming vts-build"; }
done
[[ ! -e $WORK/level.png && ! -e $WORK/tile.tif ]] || fail "an extract handed to no vts-build wrote a file"
note "ok"
