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
