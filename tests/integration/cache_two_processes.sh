#!/usr/bin/env bash
# Two processes fill one cache folder at once (disjoint key ranges, starting from an empty folder
# so that both race to create the database): both succeed, every tile of both is there with its
# content, and the totals row is exact.
# Environment: CACHE_TORTURE (tests/integration/cache_torture), SQLITE3 (the sqlite3 CLI).
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

: "${CACHE_TORTURE:?CACHE_TORTURE must name the cache_torture executable}"
SQLITE3=${SQLITE3:-sqlite3}
require_tool "$CACHE_TORTURE"
require_tool "$SQLITE3"

DIR="$WORK/cache"
N=600
"$CACHE_TORTURE" fill "$DIR" --first 0 --count $N >"$LOGS/a.out" 2>"$LOGS/a.err" </dev/null &
a=$!
"$CACHE_TORTURE" fill "$DIR" --first $N --count $N >"$LOGS/b.out" 2>"$LOGS/b.err" </dev/null &
b=$!
ra=0
rb=0
wait "$a" || ra=$?
wait "$b" || rb=$?
for p in a b; do
  note "fill $p: $(tail -n 1 "$LOGS/$p.out")"
done
((ra == 0)) || { cat "$LOGS/a.err" >&2; fail "first fill exited $ra"; }
((rb == 0)) || { cat "$LOGS/b.err" >&2; fail "second fill exited $rb"; }

expect_ok "$CACHE_TORTURE" check "$DIR" --expect-tiles $((2 * N))
note "$(cat "$OUT")"
count=$("$SQLITE3" "$DIR/cache.db" 'SELECT COUNT(*) FROM tiles')
totals=$("$SQLITE3" "$DIR/cache.db" 'SELECT tiles FROM totals')
((count == 2 * N)) || fail "sqlite3 counts $count tiles, expected $((2 * N))"
((totals == 2 * N)) || fail "the totals row says $totals tiles, expected $((2 * N))"
[[ $("$SQLITE3" "$DIR/cache.db" 'PRAGMA integrity_check') == ok ]] || fail "integrity_check failed"

note "both again at once: every tile is already there, nothing is stored twice"
"$CACHE_TORTURE" fill "$DIR" --first 0 --count $((2 * N)) >"$LOGS/a.out" 2>"$LOGS/a.err" &
a=$!
"$CACHE_TORTURE" fill "$DIR" --first 0 --count $((2 * N)) >"$LOGS/b.out" 2>"$LOGS/b.err" &
b=$!
ra=0
rb=0
wait "$a" || ra=$?
wait "$b" || rb=$?
((ra == 0 && rb == 0)) || { cat "$LOGS/a.err" "$LOGS/b.err" >&2; fail "refills exited $ra / $rb"; }
grep -q "fill: done: 0 stored, $((2 * N)) already present" "$LOGS/a.out" ||
  fail "refill stored tiles again: $(tail -n 1 "$LOGS/a.out")"
expect_ok "$CACHE_TORTURE" check "$DIR" --expect-tiles $((2 * N))
note "PASS"
