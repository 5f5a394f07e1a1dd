#!/usr/bin/env bash
# A truncated, empty or missing archive makes `vts verify` and `vts info` fail cleanly: non-zero
# exit, a message on stderr, no crash and no hang.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

A="$WORK/earth.pmtiles"
build_earth "$A"
size=$(stat -c %s "$A")
((size > 16384)) || fail "archive unexpectedly small ($size bytes)"

# Cut inside the magic, inside the header, right after the header, inside the root directory,
# at 16 KiB, in the middle of the tile data, and one byte short of the end.
for n in 0 3 100 126 127 200 16384 $((size / 2)) $((size - 1)); do
  T="$WORK/truncated_$n.pmtiles"
  head -c "$n" "$A" >"$T"
  note "truncated to $n of $size bytes"
  expect_clean_failure "$VTS" verify "$T"
  expect_clean_failure "$VTS" info "$T"
  expect_clean_failure "$VTS" info "$T" --json
done

note "missing archive"
expect_clean_failure "$VTS" verify "$WORK/does-not-exist.pmtiles"
expect_clean_failure "$VTS" info "$WORK/does-not-exist.pmtiles"

note "a directory instead of an archive"
mkdir -p "$WORK/a-directory.pmtiles"
expect_clean_failure "$VTS" verify "$WORK/a-directory.pmtiles"

note "a file that is not an archive (the source JPEG)"
expect_clean_failure "$VTS" verify "$EARTH"
expect_clean_failure "$VTS" info "$EARTH"

note "PASS"
