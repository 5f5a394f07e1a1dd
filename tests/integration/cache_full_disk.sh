#!/usr/bin/env bash
# A full disk (a 2 MiB tmpfs) makes a fill fail cleanly with "disk full" in its message and the
# I/O exit code, and leaves a cache that opens, passes integrity_check (ours and the sqlite3
# CLI's) and reads back every tile it holds. Needs to mount a tmpfs: where that is not allowed
# (not root), exits 77, which ctest reports as skipped.
# Environment: CACHE_TORTURE (tests/integration/cache_torture), SQLITE3 (the sqlite3 CLI).
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

: "${CACHE_TORTURE:?CACHE_TORTURE must name the cache_torture executable}"
SQLITE3=${SQLITE3:-sqlite3}
require_tool "$CACHE_TORTURE"
require_tool "$SQLITE3"

MNT="$WORK/tmpfs"
mkdir -p "$MNT"
if ! mount -t tmpfs -o size=2m vts-cache-full-disk "$MNT" 2>"$LOGS/mount.err"; then
  echo "SKIP: cannot mount a tmpfs to fill up (needs root): $(cat "$LOGS/mount.err")"
  exit 77
fi
unmount_then_cleanup() {
  local rc=$?
  set +e # or the (exit) below would end the trap before cleanup on a failure
  umount "$MNT" 2>/dev/null || umount -l "$MNT" 2>/dev/null
  (exit "$rc") # lib.sh's cleanup reads the test's exit status from $?
  cleanup
}
trap unmount_then_cleanup EXIT

DIR="$MNT/cache"
note "fill until the 2 MiB disk is full"
expect_clean_failure "$CACHE_TORTURE" fill "$DIR" --first 0 --count 1000
grep -q 'disk full writing cache' "$ERR" || { show_output; fail "no 'disk full' in the message"; }
((RC == 4)) || fail "exit code $RC, expected 4 (I/O error)"
note "$(head -c 300 "$ERR")"
grep -q 'fill: stopped at tile' "$OUT" || fail "the fill did not get far enough to store tiles"

note "the cache is valid and reads back"
expect_ok "$CACHE_TORTURE" check "$DIR"
note "$(cat "$OUT")"
got=$("$SQLITE3" "$DIR/cache.db" 'PRAGMA integrity_check' 2>&1) || fail "sqlite3 failed: $got"
[[ $got == ok ]] || fail "sqlite3 PRAGMA integrity_check: $got"
stored=$("$SQLITE3" "$DIR/cache.db" 'SELECT COUNT(*) FROM tiles')
((stored > 0)) || fail "no tiles were stored before the disk filled up"

note "still full: the next fill fails the same clean way, the cache stays valid"
expect_clean_failure "$CACHE_TORTURE" fill "$DIR" --first 5000 --count 100
grep -q 'disk full writing cache' "$ERR" || { show_output; fail "no 'disk full' the second time"; }
expect_ok "$CACHE_TORTURE" check "$DIR" --expect-tiles "$stored"

# (The WAL needs room to grow and the checkpoint room to copy it into cache.db, so freeing a few
# hundred KiB is not enough to write again; growing the file system stands in for freeing space.)
note "space given back (the tmpfs grown to 8 MiB): a fill resumes, evicts under its cap, completes"
mount -o remount,size=8m "$MNT" || fail "cannot grow the tmpfs"
expect_ok "$CACHE_TORTURE" fill "$DIR" --first 0 --count 150 --cap $((3 << 20))
grep -q "fill: done: [0-9]* stored, $stored already present" "$OUT" ||
  fail "the fill did not resume from the $stored tiles present: $(tail -n 1 "$OUT")"
note "$(tail -n 1 "$OUT")"
expect_ok "$CACHE_TORTURE" check "$DIR"
note "PASS"
