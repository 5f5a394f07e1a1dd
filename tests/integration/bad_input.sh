#!/usr/bin/env bash
# `vts build` on bad input fails cleanly and writes nothing: no output file, no temporary files,
# and an archive already under the output name is left exactly as it was.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

D="$WORK/out"
mkdir -p "$D"

# expect_nothing_written: the output directory holds exactly what it held before ($before).
expect_nothing_written() {
  local after
  after=$(dir_listing "$D")
  if [[ $after != "$before" ]]; then
    printf 'before:\n%s\nafter:\n%s\n' "$before" "$after" >&2
    fail "a failed build left files behind in $D"
  fi
}

before=$(dir_listing "$D")

note "an output that is one of the inputs (by its own name or through a link)"
cp "$EARTH" "$WORK/in.jpg"
ln -s "$WORK/in.jpg" "$WORK/in-link.pmtiles"
for out in "$WORK/in.jpg" "$WORK/in-link.pmtiles"; do
  expect_clean_failure "$VTS" build "$WORK/in.jpg" -o "$out"
  ((RC == 2)) || fail "vts build with its input as output exited $RC, expected 2"
  grep -q 'is the input' "$ERR" || { show_output; fail "the error does not say the output is the input"; }
  cmp -s "$EARTH" "$WORK/in.jpg" || fail "vts build -o $out changed its input"
done
"$VTS" build --synthetic 512x512 -o "$WORK/s.pmtiles" >/dev/null 2>&1 || fail "cannot build s.pmtiles"
cp "$WORK/s.pmtiles" "$WORK/s.copy"
expect_clean_failure "$VTS" extract "$WORK/s.pmtiles" --level 0 -o "$WORK/s.pmtiles"
((RC == 2)) || fail "vts extract with its archive as output exited $RC, expected 2"
cmp -s "$WORK/s.pmtiles" "$WORK/s.copy" || fail "vts extract -o ARCHIVE changed the archive"

note "missing input file"
expect_clean_failure "$VTS" build "$WORK/no-such-image.jpg" -o "$D/x.pmtiles"
grep -q 'no-such-image' "$ERR" || { show_output; fail "the error does not name the missing file"; }
expect_nothing_written

note "a file that is not an image"
printf 'this is not an image\n' >"$WORK/not-an-image.jpg"
expect_clean_failure "$VTS" build "$WORK/not-an-image.jpg" -o "$D/x.pmtiles"
expect_nothing_written

note "an empty file"
: >"$WORK/empty.png"
expect_clean_failure "$VTS" build "$WORK/empty.png" -o "$D/x.pmtiles"
expect_nothing_written

note "a truncated JPEG"
head -c 3000 "$EARTH" >"$WORK/truncated.jpg"
run "$VTS" build "$WORK/truncated.jpg" -o "$D/x.pmtiles"
# libjpeg may accept a truncated stream (grey fill with a warning); either way no crash and, on
# failure, no file.
((RC < 124)) || { show_output; fail "vts build on a truncated JPEG exited $RC (crash or hang)"; }
if ((RC != 0)); then
  grep -q '[^[:space:]]' "$ERR" || fail "failed on a truncated JPEG without a message"
  expect_nothing_written
else
  rm -f "$D/x.pmtiles"
fi

note "a directory as input"
expect_clean_failure "$VTS" build "$WORK" -o "$D/x.pmtiles"
expect_nothing_written

note "an output directory that does not exist"
expect_clean_failure "$VTS" build "$EARTH" -o "$WORK/no-such-dir/x.pmtiles"
[[ ! -e $WORK/no-such-dir ]] || fail "vts build created $WORK/no-such-dir"

note "invalid options"
expect_clean_failure "$VTS" build "$EARTH"  # no -o
expect_clean_failure "$VTS" build "$EARTH" -o "$D/x.pmtiles" --tile 300
expect_nothing_written
expect_clean_failure "$VTS" build "$EARTH" -o "$D/x.pmtiles" --codec no-such-codec
expect_nothing_written
expect_clean_failure "$VTS" build --synthetic 0x100 -o "$D/x.pmtiles"
expect_nothing_written
expect_clean_failure "$VTS" build --synthetic banana -o "$D/x.pmtiles"
expect_nothing_written
expect_clean_failure "$VTS" no-such-subcommand

note "a failed build leaves an existing archive untouched"
build_earth "$D/keep.pmtiles"
cp "$D/keep.pmtiles" "$WORK/keep.orig"
before=$(dir_listing "$D")
expect_clean_failure "$VTS" build "$WORK/no-such-image.jpg" -o "$D/keep.pmtiles"
expect_clean_failure "$VTS" build "$WORK/not-an-image.jpg" -o "$D/keep.pmtiles"
cmp -s "$D/keep.pmtiles" "$WORK/keep.orig" || fail "a failed build modified the existing archive"
expect_nothing_written

note "PASS"
