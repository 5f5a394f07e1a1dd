#!/usr/bin/env bash
# The RAM cache of native tiles (tile_cache_mib): a hot tile is answered from it (counted in
# /metrics) with the archive's bytes, and once the server has noticed that the archive was
# rewritten in place, the tile it cached is never answered again: 503 until the reload opens the
# new archive, then the new archive's tile.
source "$(dirname "$0")/lib.sh"
source "$(dirname "$0")/serve_lib.sh"
require_tool sha256sum

mkdir -p "$WORK/serve" "$WORK/ref"
build_earth "$WORK/ref/a.pmtiles"
build_earth "$WORK/ref/b.pmtiles" --codec bc1
cp "$WORK/ref/a.pmtiles" "$WORK/serve/served.pmtiles"
# No periodic reload: the change is found by the requests alone.
echo '{"tile_cache_mib": 8, "reload_interval_ms": 0}' >"$WORK/config.json"
start_server "$WORK/serve/served.pmtiles" "$WORK/ref" --config "$WORK/config.json"

hash_of() { curl -s "$1" | sha256sum | cut -d' ' -f1; }
metric() { curl -sf "$ADMIN_BASE/metrics" | awk -v m="$1" '$1 == m { print $2 }'; }

old=$(hash_of "$BASE/served/1/1/0")
[[ $old == $(hash_of "$BASE/a/1/1/0") ]] || fail "served/1/1/0 is not a's tile"
new=$(hash_of "$BASE/b/1/1/0")
[[ $new != "$old" ]] || fail "tile 1/1/0 is the same in a and b"
hits=$(metric vts_tile_cache_hits_total)
[[ $(hash_of "$BASE/served/1/1/0") == "$old" ]] || fail "the hot tile changed"
(($(metric vts_tile_cache_hits_total) > hits)) || fail "the hot tile was not answered from the cache"
(($(metric vts_tile_cache_bytes) > 0)) || fail "the cache holds no bytes"

note "rewrite the served archive in place with b's bytes"
size_b=$(stat -c %s "$WORK/ref/b.pmtiles")
dd if="$WORK/ref/b.pmtiles" of="$WORK/serve/served.pmtiles" bs=64k conv=notrunc status=none
truncate -s "$size_b" "$WORK/serve/served.pmtiles"
# Tile 1/0/0 was never read: reading it finds the change.
expect_status 503 "$BASE/served/1/0/0"
got=$(hash_of "$BASE/served/1/1/0")
[[ $got != "$old" ]] || fail "the cache answered a's tile after the change was found"
expect_status 503 "$BASE/served/1/1/0"

note "until the reload opens b: never a's tile; then b's"
for ((i = 0; i < 200; i++)); do
  got=$(hash_of "$BASE/served/1/1/0")
  [[ $got != "$old" ]] || fail "the cache answered a's tile after the change was found"
  [[ $got == "$new" ]] && break
  kill -0 "$SERVER_PID" 2>/dev/null || fail "vts serve died: $(tail -5 "$LOGS/serve.err")"
  sleep 0.1
done
[[ $got == "$new" ]] || fail "served/1/1/0 is not b's tile 20 s after the rewrite"
[[ $(hash_of "$BASE/served/1/1/0") == "$new" ]] || fail "b's tile, read again, differs"
(($(metric vts_tile_cache_invalidations_total) > 0)) || fail "a's tiles were not dropped"
stop_server
