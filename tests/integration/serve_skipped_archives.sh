#!/usr/bin/env bash
# One bad file in a served folder does not keep the others offline: `vts serve DIR` with a good
# archive, a truncated copy and a file named é.pmtiles starts, serves the good one, names each bad
# file with its reason on stderr, in /health and as a /metrics gauge, and serves a bad file once
# it is fixed. An archive named on the command line must still open, and a folder whose every
# archive is refused still fails (nothing to serve), with the code of what was wrong.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
# shellcheck source=serve_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/serve_lib.sh"

build_earth "$WORK/earth.pmtiles"
size=$(stat -c %s "$WORK/earth.pmtiles")
mkdir -p "$WORK/serve"
cp "$WORK/earth.pmtiles" "$WORK/serve/good.pmtiles"
head -c $((size / 2)) "$WORK/earth.pmtiles" >"$WORK/serve/half.pmtiles"
cp "$WORK/earth.pmtiles" "$WORK/serve/é.pmtiles"
echo '{"reload_interval_ms": 100}' >"$WORK/config.json"

note "a file named by itself must still open (exit 5 truncated, 2 bad name)"
run "$VTS" serve "$WORK/serve/half.pmtiles" --listen 127.0.0.1:0 --no-admin
((RC == 5)) || { show_output; fail "serving a truncated file exited $RC, expected 5"; }
run "$VTS" serve "$WORK/serve/é.pmtiles" --listen 127.0.0.1:0 --no-admin
((RC == 2)) || { show_output; fail "serving é.pmtiles exited $RC, expected 2"; }

note "a folder with nothing servable fails: no archive at all (exit 3), or every one refused"
mkdir -p "$WORK/empty"
run "$VTS" serve "$WORK/empty" --listen 127.0.0.1:0 --no-admin
((RC == 3)) || { show_output; fail "an empty folder exited $RC, expected 3"; }
mkdir -p "$WORK/allbad"
head -c $((size / 2)) "$WORK/earth.pmtiles" >"$WORK/allbad/half.pmtiles"
run "$VTS" serve "$WORK/allbad" --listen 127.0.0.1:0 --no-admin
((RC == 5)) || { show_output; fail "a folder of broken archives exited $RC, expected 5"; }
grep -q 'no archive can be served' "$ERR" || fail "no reason given: $(cat "$ERR")"
grep -qF "$WORK/allbad/half.pmtiles: " "$ERR" || fail "the file is not named: $(cat "$ERR")"

note "a folder with one good archive among bad ones starts and serves it"
start_server "$WORK/serve" --config "$WORK/config.json"
grep -q ', 1 tilesets' "$LOGS/serve.out" || fail "not 1 tileset: $(cat "$LOGS/serve.out")"
expect_status 200 "$BASE/good/0/0/0"
expect_status 200 "$BASE/good.json"
expect_status 404 "$BASE/half/0/0/0"
for f in half.pmtiles é.pmtiles; do
  [[ $(grep -cF "vts serve: skipped $WORK/serve/$f: " "$LOGS/serve.err") == 1 ]] ||
    fail "stderr has not one line for $f: $(cat "$LOGS/serve.err")"
done
grep -F "skipped $WORK/serve/é.pmtiles: " "$LOGS/serve.err" | grep -q 'tileset name' ||
  fail "no reason for é.pmtiles: $(cat "$LOGS/serve.err")"

curl -s -o "$WORK/health.txt" -w '%{http_code}' "$ADMIN_BASE/health" >"$WORK/health.code"
[[ $(cat "$WORK/health.code") == 200 ]] || fail "/health answered $(cat "$WORK/health.code")"
[[ $(head -1 "$WORK/health.txt") == ok ]] || fail "/health first line: $(head -1 "$WORK/health.txt")"
[[ $(grep -c '^skipped ' "$WORK/health.txt") == 2 ]] || fail "/health: $(cat "$WORK/health.txt")"
grep -qF "skipped $WORK/serve/half.pmtiles: " "$WORK/health.txt" || fail "/health lacks half"
grep -F "skipped $WORK/serve/é.pmtiles: " "$WORK/health.txt" | grep -q 'tileset name' ||
  fail "/health lacks é.pmtiles and its reason: $(cat "$WORK/health.txt")"
grep -qx 'vts_archives_skipped 2' <<<"$(curl -sf "$ADMIN_BASE/metrics")" ||
  fail "metrics: $(curl -s "$ADMIN_BASE/metrics" | grep vts_archives_skipped)"
grep -qx 'vts_tilesets_loaded 1' <<<"$(curl -sf "$ADMIN_BASE/metrics")" || fail "not 1 tileset loaded"

note "the truncated copy, completed (written elsewhere and renamed), is served after a reload"
cp "$WORK/earth.pmtiles" "$WORK/serve/.half.tmp"
mv "$WORK/serve/.half.tmp" "$WORK/serve/half.pmtiles"
for ((i = 0; i < 100; i++)); do
  [[ $(status_of "$BASE/half/0/0/0") == 200 ]] && break
  sleep 0.1
done
expect_status 200 "$BASE/half/0/0/0"
grep -qx 'vts_archives_skipped 1' <<<"$(curl -sf "$ADMIN_BASE/metrics")" ||
  fail "metrics after the fix: $(curl -s "$ADMIN_BASE/metrics" | grep vts_archives_skipped)"
curl -s "$ADMIN_BASE/health" >"$WORK/health.txt"
[[ $(grep -c '^skipped ' "$WORK/health.txt") == 1 ]] || fail "/health: $(cat "$WORK/health.txt")"

note "the badly named file, renamed, is served; nothing is listed any more"
mv "$WORK/serve/é.pmtiles" "$WORK/serve/e.pmtiles"
for ((i = 0; i < 100; i++)); do
  [[ $(status_of "$BASE/e/0/0/0") == 200 ]] && break
  sleep 0.1
done
expect_status 200 "$BASE/e/0/0/0"
[[ $(curl -s "$ADMIN_BASE/health") == ok ]] || fail "/health: $(curl -s "$ADMIN_BASE/health")"
grep -qx 'vts_archives_skipped 0' <<<"$(curl -sf "$ADMIN_BASE/metrics")" || fail "skipped not back to 0"

stop_server
note "PASS"
