#!/usr/bin/env bash
# `vts build` on bad input fails cleanly and writes nothing: no output file, no temporary files,
# and an archive already under the output name is left exactly as it was.
# Every command that reads an input file (build, info, verify, extract, serve, warm, cache serve,
# loadtest) refuses a device or a FIFO at once with exit 2.
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

# Truncated and corrupt images (exit 5, nothing written): damaged_input.sh.

note "a directory as input"
expect_clean_failure "$VTS" build "$WORK" -o "$D/x.pmtiles"
expect_nothing_written

note "a device or a FIFO as input: refused at once, naming the file (was: /dev/zero read forever, a FIFO blocked in open)"
mkfifo "$WORK/fifo.png" "$WORK/fifo.pmtiles" "$WORK/fifo.json"
# expect_refused_at_once TEXT CMD...: CMD must exit 2 (a clean error, not a crash) within 10 s
# (a hang fails the test rather than stalling it) with TEXT in its message.
expect_refused_at_once() {
  local text=$1
  shift
  run timeout -k 2 10 "$@"
  if ((RC != 2)) || ! grep -qF "$text" "$ERR"; then
    show_output
    fail "'$*' exited $RC (124: still running after 10 s), expected 2 and '$text'"
  fi
}
# expect_not_regular KIND FILE CMD...: the message says FILE is not a regular file of kind KIND.
expect_not_regular() {
  local kind=$1 file=$2
  shift 2
  expect_refused_at_once "not a regular file: $file ($kind)" "$@"
}
for input in /dev/zero "$WORK/fifo.png"; do
  kind="character device"
  [[ $input == /dev/zero ]] || kind=FIFO
  expect_not_regular "$kind" "$input" "$VTS" build "$input" -o "$D/x.pmtiles"
  expect_nothing_written
  expect_not_regular "$kind" "$input" "$VTS" build --grid 2x1 "$EARTH" "$input" -o "$D/x.pmtiles"
  expect_nothing_written
done
for input in /dev/zero "$WORK/fifo.pmtiles"; do
  kind="character device"
  [[ $input == /dev/zero ]] || kind=FIFO
  expect_not_regular "$kind" "$input" "$VTS" info "$input"
  expect_not_regular "$kind" "$input" "$VTS" verify "$input"
  expect_not_regular "$kind" "$input" "$VTS" extract "$input" --level 0 -o "$D/x.png"
  expect_nothing_written
  expect_not_regular "$kind" "$input" "$VTS" serve "$input" --listen 127.0.0.1:0
  expect_not_regular "$kind" "$input" "$VTS" warm "$input" --cache-dir "$WORK/warm-cache"
  expect_not_regular "$kind" "$input" "$VTS" cache serve --upstream "$input" \
    --cache-dir "$WORK/daemon-cache" --listen 127.0.0.1:0 --no-admin
  expect_not_regular "$kind" "$input" "$VTS" loadtest "$input" --duration 1
done
# Small files read whole (configs, keys) were already refused by their own checks; still at once.
expect_refused_at_once "fifo.json" "$VTS" serve "$WORK/s.pmtiles" --listen 127.0.0.1:0 \
  --config "$WORK/fifo.json"
expect_refused_at_once "fifo.json" "$VTS" sign /s/0/0/0 --key-file "$WORK/fifo.json"

note "plan and merge refuse an output that is one of their inputs (was: the image became a plan, a part or the plan the archive)"
cp "$WORK/in.jpg" "$WORK/in.orig"
expect_clean_failure "$VTS" plan "$WORK/in.jpg" --shards 2 -o "$WORK/in.jpg"
((RC == 2)) && grep -q 'is the input' "$ERR" || { show_output; fail "vts plan -o INPUT exited $RC"; }
cmp -s "$WORK/in.jpg" "$WORK/in.orig" || fail "vts plan -o INPUT changed its input"
printf '%s\n' "$WORK/in.jpg" >"$WORK/list.txt"
cp "$WORK/list.txt" "$WORK/list.orig"
for cmd in plan build; do
  extra=()
  [[ $cmd == plan ]] && extra=(--shards 2)
  expect_clean_failure "$VTS" "$cmd" --input-list "$WORK/list.txt" "${extra[@]}" -o "$WORK/list.txt"
  ((RC == 2)) && grep -q 'is the input' "$ERR" || { show_output; fail "vts $cmd -o ITS-LIST exited $RC"; }
  cmp -s "$WORK/list.txt" "$WORK/list.orig" || fail "vts $cmd -o ITS-LIST changed the list"
done
expect_ok "$VTS" plan --synthetic 1024x1024 --shards 4 -o "$WORK/p.json"
for s in 0 1 2 3; do expect_ok "$VTS" build --plan "$WORK/p.json" --shard $s --out-dir "$WORK/parts" -q; done
expect_ok "$VTS" build --plan "$WORK/p.json" --apex --out-dir "$WORK/parts" -q
cp -r "$WORK/parts" "$WORK/parts.orig"
cp "$WORK/p.json" "$WORK/p.orig"
expect_clean_failure "$VTS" plan --update "$WORK/p.json" -o "$WORK/p.json"
((RC == 2)) && grep -q 'is the input' "$ERR" || { show_output; fail "vts plan --update P -o P exited $RC"; }
for out in "$WORK/parts/shard-000001.part" "$WORK/parts/apex.part" "$WORK/p.json"; do
  expect_clean_failure "$VTS" merge --plan "$WORK/p.json" "$WORK/parts" -o "$out"
  ((RC == 2)) && grep -q 'is the input' "$ERR" || { show_output; fail "vts merge -o $out exited $RC"; }
done
cmp -s "$WORK/p.json" "$WORK/p.orig" || fail "vts merge -o PLAN changed the plan"
diff -r "$WORK/parts" "$WORK/parts.orig" >/dev/null || fail "vts merge -o PART changed the parts"
expect_ok "$VTS" merge --plan "$WORK/p.json" "$WORK/parts" -o "$WORK/merged.pmtiles" -q

note "reports and recordings refuse an output that is an input: loadtest --report, loadtest merge --report, view --record/--screenshot"
mkdir -p "$WORK/report"
ln -f "$WORK/s.pmtiles" "$WORK/report/index.html"
expect_clean_failure "$VTS" loadtest "$WORK/s.pmtiles" --duration 1 --report "$WORK/report"
((RC == 2)) && grep -q 'is the input' "$ERR" || { show_output; fail "loadtest --report over its target exited $RC"; }
expect_clean_failure "$VTS" loadtest merge "$WORK/report/index.html" --report "$WORK/report"
((RC == 2)) && grep -q 'is the input' "$ERR" || { show_output; fail "loadtest merge --report over a run exited $RC"; }
if "$VTS" view --help >/dev/null 2>&1; then
  for opt in --record --screenshot; do
    expect_clean_failure "$VTS" view "$WORK/s.pmtiles" --headless --frames 1 "$opt" "$WORK/s.pmtiles"
    ((RC == 2)) && grep -q 'is the input' "$ERR" || { show_output; fail "view $opt over its source exited $RC"; }
  done
fi
cmp -s "$WORK/s.pmtiles" "$WORK/s.copy" || fail "a report or recording changed the archive"
if "$VTS" bench --help >/dev/null 2>&1; then
  mkdir -p "$WORK/bench"
  cp "$EARTH" "$WORK/bench/report.md"
  expect_clean_failure "$VTS" bench accuracy --input "$WORK/bench/report.md" --report "$WORK/bench" --quick -q
  ((RC == 2)) && grep -q 'is the input' "$ERR" || { show_output; fail "bench --report over its input exited $RC"; }
  cmp -s "$EARTH" "$WORK/bench/report.md" || fail "bench --report changed its input"
fi

note "a FIFO named like a part, an --input-list that is a FIFO or a device: refused at once"
mv "$WORK/parts/shard-000002.part" "$WORK/shard-000002.part"
mkfifo "$WORK/parts/shard-000002.part"
expect_not_regular FIFO "$WORK/parts/shard-000002.part" \
  "$VTS" merge --plan "$WORK/p.json" "$WORK/parts" -o "$D/x.pmtiles"
expect_nothing_written
mkfifo "$WORK/list.fifo"
for list in /dev/zero "$WORK/list.fifo"; do
  kind="character device"
  [[ $list == /dev/zero ]] || kind=FIFO
  expect_not_regular "$kind" "$list" "$VTS" build --input-list "$list" -o "$D/x.pmtiles"
  expect_not_regular "$kind" "$list" "$VTS" plan --input-list "$list" --shards 2 -o "$D/x.json"
  expect_nothing_written
done

note "a VRT whose source is a FIFO or a device: refused at once, naming it (was: blocked in GDAL)"
# vrt FILE SOURCE [BAND-ATTRIBUTES] [GEOTRANSFORM] [BAND-CONTENT]: a one-band georeferenced VRT.
vrt() {
  local content=${5:-"<SimpleSource><SourceFilename>$2</SourceFilename><SourceBand>1</SourceBand></SimpleSource>"}
  cat >"$1" <<EOF
<VRTDataset rasterXSize="64" rasterYSize="32">
  <SRS>EPSG:4326</SRS>
  <GeoTransform>${4:--180,5.625,0,90,0,-5.625}</GeoTransform>
  <VRTRasterBand dataType="Byte" band="1" ${3:-}>
    $content
  </VRTRasterBand>
</VRTDataset>
EOF
}
mkfifo "$WORK/source.fifo"
vrt "$WORK/fifo.vrt" "$WORK/source.fifo"
vrt "$WORK/zero.vrt" /dev/zero
vrt "$WORK/nested.vrt" "$WORK/fifo.vrt"
expect_not_regular FIFO "$WORK/source.fifo" "$VTS" build "$WORK/fifo.vrt" -o "$D/x.pmtiles"
expect_not_regular FIFO "$WORK/source.fifo" "$VTS" build "$WORK/nested.vrt" -o "$D/x.pmtiles"
expect_not_regular "character device" /dev/zero "$VTS" build "$WORK/zero.vrt" -o "$D/x.pmtiles"
expect_nothing_written
vrt "$WORK/good.vrt" "$EARTH"
expect_ok "$VTS" build "$WORK/good.vrt" -o "$WORK/good.pmtiles"

note "a VRT raw band is refused unless GDAL_VRT_ENABLE_RAWRASTERBAND=YES (was: any file's bytes in the tiles)"
head -c 2048 /dev/urandom >"$WORK/secret.bin"
vrt "$WORK/raw.vrt" "" 'subClass="VRTRawRasterBand"' "" \
  "<SourceFilename>$WORK/secret.bin</SourceFilename><ImageOffset>0</ImageOffset><PixelOffset>1</PixelOffset><LineOffset>64</LineOffset>"
vrt "$WORK/raw-nested.vrt" "$WORK/raw.vrt"
for input in raw.vrt raw-nested.vrt; do
  expect_clean_failure "$VTS" build "$WORK/$input" -o "$D/x.pmtiles"
  ((RC == 2)) && grep -q 'raw band (VRTRawRasterBand).*GDAL_VRT_ENABLE_RAWRASTERBAND=YES' "$ERR" ||
    { show_output; fail "a VRT raw band in $input was not refused (exit $RC)"; }
  expect_nothing_written
done
expect_ok env GDAL_VRT_ENABLE_RAWRASTERBAND=YES "$VTS" build "$WORK/raw.vrt" -o "$WORK/raw.pmtiles"

note "a geotransform that is not finite is named as such (was: 'crosses the antimeridian (inf .. -inf)')"
vrt "$WORK/nan.vrt" "$EARTH" "" "nan,5.625,0,90,0,-5.625"
expect_clean_failure "$VTS" build "$WORK/nan.vrt" -o "$D/x.pmtiles"
((RC == 2)) && grep -q 'its geotransform is not finite' "$ERR" ||
  { show_output; fail "a NaN geotransform (exit $RC) was not named"; }
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
