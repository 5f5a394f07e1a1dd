#!/usr/bin/env bash
# kill -9 at any moment leaves a disk cache that opens, passes PRAGMA integrity_check (ours and
# the sqlite3 CLI's), holds only rows whose content and checksum verify and whose totals row is
# exact; and a later fill resumes from it and completes.
# Environment: CACHE_TORTURE (tests/integration/cache_torture), SQLITE3 (the sqlite3 CLI).
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

: "${CACHE_TORTURE:?CACHE_TORTURE must name the cache_torture executable}"
SQLITE3=${SQLITE3:-sqlite3}
require_tool "$CACHE_TORTURE"
require_tool "$SQLITE3"
ROUNDS=${CACHE_CRASH_ROUNDS:-30}
CAP=$((8 << 20)) # ~250 tiles of 1..64 KiB: rounds soon evict and vacuum

# sqlite_integrity DIR: the sqlite3 CLI's own integrity_check must print exactly "ok".
sqlite_integrity() {
  local got
  got=$("$SQLITE3" "$1/cache.db" 'PRAGMA integrity_check' 2>&1) ||
    fail "sqlite3 could not read $1/cache.db: $got"
  [[ $got == ok ]] || fail "sqlite3 PRAGMA integrity_check on $1/cache.db: $got"
}

# killed_fill DIR DELAY_MS FILL_ARGS...: starts a fill and kills it with SIGKILL after DELAY_MS.
KILLED=0
killed_fill() {
  local dir=$1 delay_ms=$2 pid rc=0
  shift 2
  "$CACHE_TORTURE" fill "$dir" "$@" >"$LOGS/fill.out" 2>"$LOGS/fill.err" </dev/null &
  pid=$!
  sleep "$(printf '%d.%03d' $((delay_ms / 1000)) $((delay_ms % 1000)))"
  kill -9 "$pid" 2>/dev/null || true
  { wait "$pid"; } 2>/dev/null || rc=$?
  if ((rc == 137)); then
    KILLED=$((KILLED + 1))
  elif ((rc != 0)); then
    cat "$LOGS/fill.err" >&2
    fail "fill $* exited $rc before it was killed"
  fi
}

note "kills while the cache is being created"
for round in 1 2 3 4 5 6; do
  dir="$WORK/fresh$round"
  killed_fill "$dir" $((round * 4)) --first 0 --count 100000 --cap "$CAP"
  if [[ -e $dir/cache.db ]]; then
    expect_ok "$CACHE_TORTURE" check "$dir"
    sqlite_integrity "$dir"
    note "killed after $((round * 4)) ms: $(cat "$OUT")"
  else
    note "killed after $((round * 4)) ms: before cache.db was created"
  fi
done

DIR="$WORK/cache"
note "a first fill to completion"
expect_ok "$CACHE_TORTURE" fill "$DIR" --first 0 --count 150 --cap "$CAP"
expect_ok "$CACHE_TORTURE" check "$DIR"

for round in $(seq 1 "$ROUNDS"); do
  delay_ms=$((10 + RANDOM % 291))
  if ((round % 5 == 0)); then
    # A few pinned tiles too (a distinct range, well under the cap in total).
    args=(--first $((1000000 + round * 10)) --count 10 --pin)
  else
    # Overlapping ranges: part resumes (tiles present), part new, with evictions.
    args=(--first $((round * 60)) --count 100000)
  fi
  killed_fill "$DIR" "$delay_ms" "${args[@]}" --cap "$CAP"
  expect_ok "$CACHE_TORTURE" check "$DIR"
  summary=$(cat "$OUT")
  sqlite_integrity "$DIR"
  note "round $round: killed after ${delay_ms} ms ($(tail -n 1 "$LOGS/fill.out" 2>/dev/null)); $summary"
done
((KILLED >= ROUNDS / 2)) || fail "only $KILLED fills were killed mid-way; the test did not test much"

# Around the most recently stored unpinned tile, which is surely present and evicted last.
latest=$("$SQLITE3" "$DIR/cache.db" \
  'SELECT x + y * 65536 FROM tiles WHERE pinned = 0 ORDER BY atime DESC LIMIT 1')
[[ $latest =~ ^[0-9]+$ ]] || fail "no unpinned tile left to resume from ('$latest')"
first=$((latest > 100 ? latest - 100 : 0))
note "a final fill of tiles $first.. (tile $latest is present) resumes and completes"
expect_ok "$CACHE_TORTURE" fill "$DIR" --first "$first" --count 300 --cap "$CAP"
grep -q '^fill: done: [0-9]* stored, [1-9][0-9]* already present' "$OUT" ||
  fail "the final fill did not resume from tiles already present: $(tail -n 1 "$OUT")"
note "$(tail -n 1 "$OUT")"
expect_ok "$CACHE_TORTURE" check "$DIR"
sqlite_integrity "$DIR"
note "PASS ($KILLED fills killed)"
