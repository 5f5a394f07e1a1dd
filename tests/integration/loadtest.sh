#!/usr/bin/env bash
# vts loadtest against the real `vts serve`, directly and through fault_proxy (errors and delays
# on a known schedule): the report counts exactly what the proxy injected (every request the
# proxy numbered is one request of the report, every injected 503 an http_503 error, every
# injected delay a request of >= 1 s) and writes the HTML report with its four plots; clean
# closed-loop runs on the flyover and pan presets reach full resolution without errors; an open
# loop holds its rate; bad input fails with a message naming the problem; SIGINT ends a run
# promptly with exit 130 and still prints the summary.
source "$(dirname "$0")/lib.sh"
source "$(dirname "$0")/serve_lib.sh"
: "${FAULT_PROXY:?FAULT_PROXY must name the fault_proxy executable}"
require_tool "$FAULT_PROXY"

LT_PID=""
loadtest_cleanup() {
  if [[ -n $LT_PID ]]; then kill -KILL "$LT_PID" 2>/dev/null || true; fi
  fault_proxy_cleanup
  serve_cleanup
}
trap loadtest_cleanup EXIT

# no_sanitizer_report FILE: FILE (a captured stderr) holds no sanitizer report.
no_sanitizer_report() {
  if grep -qE 'AddressSanitizer|runtime error:|LeakSanitizer|ThreadSanitizer' "$1"; then
    cat "$1" >&2
    fail "sanitizer report in $1"
  fi
}

note "Earth archives (256- and 64-texel tiles) and vts serve"
build_earth "$WORK/earth.pmtiles" --quiet
build_earth "$WORK/earth64.pmtiles" --tile 64 --border 2 --quiet
start_server "$WORK/earth.pmtiles" "$WORK/earth64.pmtiles"
curl -sSf "$BASE/earth.json" -o "$WORK/earth.json" || fail "no TileJSON at $BASE/earth.json"

# ---- 1. through the fault proxy: the report counts exactly what was injected -------------------
note "jumps through fault_proxy --error-every 10 --delay-every 7 --delay-ms 1000"
# 1 s: far above anything a loaded 2-core machine adds to an undelayed request on loopback (a
# stall of the whole machine lengthens every request in flight: at 100 ms concurrent tests once
# pushed 22 undelayed requests over the line, at 300 ms 6 of 109 under a full CI run).
start_fault_proxy --prefix /earth@ --error-every 10 --error-status 503 --delay-every 7 --delay-ms 1000
# --max-error-rate 100%: 10% errors would fail the default 1% gate (loadtest_gates.sh tests that).
expect_ok "$VTS" loadtest "$PROXY/earth" --viewers 4 --duration 4 --path jumps --json --quiet \
  --report "$WORK/report" --title "through the fault proxy" --max-error-rate 100%
cp "$OUT" "$WORK/faults.json"
no_sanitizer_report "$ERR"
curl -sSf "$PROXY/_proxy/stats" -o "$WORK/proxy.json" || fail "no /_proxy/stats"
json_check "$WORK/proxy.json" 'j.resets == 0 && j.upstream_errors == 0 && j.delay_ms == 1000' \
  "proxy stats $(cat "$WORK/proxy.json")"
requests=$(json_get "$WORK/faults.json" 'j.totals.requests')
errors=$(json_get "$WORK/faults.json" 'j.totals.errors')
e503=$(json_get "$WORK/faults.json" 'j.errors_by_kind.http_503 || 0')
slow=$(json_get "$WORK/faults.json" \
  'j.latency_ns.total.buckets.filter(b => b.high > 1e9).reduce((s, b) => s + b.count, 0)')
cancelled=$(json_get "$WORK/faults.json" 'j.wasted.cancelled')
abandoned=$(json_get "$WORK/faults.json" 'j.simulation.abandoned')
matched=$(json_get "$WORK/proxy.json" 'j.matched')
p_errors=$(json_get "$WORK/proxy.json" 'j.errors')
p_delays=$(json_get "$WORK/proxy.json" 'j.delays')
note "report: $requests requests, $e503 http_503, $slow >= 1 s, $cancelled cancelled," \
  "$abandoned abandoned; proxy: $matched matched, $p_errors errors, $p_delays delays"
((matched >= 40 && p_errors >= 4 && p_delays >= 5)) ||
  fail "too little traffic to check the schedule: $(cat "$WORK/proxy.json")"
((abandoned == 0)) || fail "$abandoned requests abandoned at the end (the drain should wait)"
((requests == matched)) ||
  fail "the report counts $requests requests ($cancelled cancelled), the proxy numbered $matched"
((e503 == p_errors)) || fail "the report counts $e503 http_503 errors, the proxy injected $p_errors"
((errors == e503)) || fail "$errors errors, of which only $e503 are the injected 503s"
((slow == p_delays)) || fail "$slow requests took >= 1 s, the proxy delayed $p_delays"
json_check "$WORK/faults.json" 'j.format == "vts-loadtest-report" && j.scenario.viewers == 4 &&
  j.scenario.path == "jumps" && j.scenario.mode == "closed" && j.title == "through the fault proxy"' \
  "scenario of the report"
json_check "$WORK/faults.json" 'j.by_status["503"] == j.errors_by_kind.http_503 &&
  j.by_status["200"] + j.by_status["503"] == j.totals.requests' "statuses add up"
json_check "$WORK/faults.json" 'j.totals.camera_moves >= 4' "a move per viewer at least"
[[ -s $WORK/report/index.html ]] || fail "--report wrote no $WORK/report/index.html"
json_check "$WORK/faults.json" "j.report == \"$WORK/report/index.html\"" "report path in the JSON"
for id in plot-latency plot-full-resolution plot-throughput plot-errors; do
  grep -q "id=\"$id\"" "$WORK/report/index.html" || fail "the HTML report has no $id"
done
stop_fault_proxy

# ---- 2. clean closed-loop runs on the presets, straight against vts serve ----------------------
for path in flyover pan; do
  note "--path $path against vts serve"
  expect_ok "$VTS" loadtest "$BASE/earth" --viewers 3 --duration 3 --path "$path" --json --quiet
  cp "$OUT" "$WORK/$path.json"
  no_sanitizer_report "$ERR"
  json_check "$WORK/$path.json" 'j.totals.errors == 0 && Object.keys(j.errors_by_kind).length == 0' \
    "no errors on $path: $(json_get "$WORK/$path.json" 'j.errors_by_kind')"
  json_check "$WORK/$path.json" 'j.totals.requests > 0 && j.totals.camera_moves >= 3' \
    "requests and a move per viewer on $path"
  json_check "$WORK/$path.json" 'j.latency_ns.full_resolution.count > 0' \
    "a view at full resolution on $path"
  json_check "$WORK/$path.json" "j.scenario.path == \"$path\" && j.scenario.mode == \"closed\"" \
    "scenario of $path"
done

# ---- 3. open loop: the rate is held ------------------------------------------------------------
# On the 64-texel archive, so that 4 viewers want more than 200 tiles in 2 s.
note "open loop --rate 100 --duration 2"
start=$(date +%s%N)
expect_ok "$VTS" loadtest "$BASE/earth64" --viewers 4 --duration 2 --rate 100 --path jumps --json \
  --quiet
wall_ms=$((($(date +%s%N) - start) / 1000000))
cp "$OUT" "$WORK/open.json"
json_check "$WORK/open.json" 'j.scenario.mode == "open" && j.scenario.rate == 100' "open-loop scenario"
json_check "$WORK/open.json" 'j.totals.requests >= 170 && j.totals.requests <= 230' \
  "200 +- 15% requests at 100/s for 2 s: $(json_get "$WORK/open.json" 'j.totals.requests')"
json_check "$WORK/open.json" 'j.totals.errors == 0' "no errors in the open loop"
json_check "$WORK/open.json" 'j.simulation.idle_slots + j.simulation.startup_slots <= 20' \
  "the demand filled the rate: $(json_get "$WORK/open.json" 'j.simulation.idle_slots') idle slots, $(json_get "$WORK/open.json" 'j.simulation.startup_slots') at start-up"
# Requests still waiting for a slot at the end were never sent: the run does not wait for them.
((wall_ms < 5000)) || fail "a 2 s open-loop run took $wall_ms ms"

# ---- 4. bad input --------------------------------------------------------------------------------
note "bad input fails with a message naming the problem"
expect_clean_failure "$VTS" loadtest "$BASE/earth" --duration 1 --path nosuchpreset --quiet
grep -q "'nosuchpreset' is neither a preset (flyover, zoom, jumps, pan)" "$ERR" ||
  { show_output; fail "an unknown path name is not named with the presets"; }
expect_clean_failure "$VTS" loadtest "$BASE/earth" --duration 1 --path "$WORK/missing.json" --quiet
grep -q 'missing.json' "$ERR" || { show_output; fail "a missing camera-path file is not named"; }
expect_clean_failure "$VTS" loadtest "$BASE/earth" --duration 1 --cache sometimes --quiet
grep -q 'sometimes' "$ERR" || { show_output; fail "a bad --cache value is not named"; }
expect_clean_failure "$VTS" loadtest "$BASE/earth" --duration 1 --cache disk --quiet
grep -q -- '--cache-dir' "$ERR" || { show_output; fail "--cache disk without --cache-dir: no hint"; }
# A port nothing listens on: the proxy's, now closed.
expect_clean_failure "$VTS" loadtest "$PROXY/earth" --duration 1 --quiet
grep -q "${PROXY#http://}" "$ERR" || { show_output; fail "an unreachable URL is not named"; }
[[ ! -e $WORK/missing.json ]] || fail "a failed run created $WORK/missing.json"

# ---- 5. SIGINT ---------------------------------------------------------------------------------
note "SIGINT during a 60 s run: exit 130 promptly, with the summary"
# Not under timeout(1): it passes a SIGINT on to its child and to its process group, and a second
# SIGINT is meant to kill vts outright. The wait below has its own limit.
"$VTS" loadtest "$BASE/earth" --viewers 2 --duration 60 --path jumps --quiet \
  >"$OUT" 2>"$ERR" </dev/null &
LT_PID=$!
# Send the SIGINT once the run is under way: vts holds its SIGINT handler (a background job of a
# non-interactive shell starts with SIGINT ignored, so a signal sent before the handler would be
# lost) and the server has answered tile requests beyond those it had answered before.
tiles_served() {
  curl -s "$ADMIN_BASE/metrics" |
    awk '/^vts_http_requests_total\{route="tile"/ { n += $2 } END { print n + 0 }'
}
before=$(tiles_served)
started=0
for ((i = 0; i < 600; i++)); do
  kill -0 "$LT_PID" 2>/dev/null || break
  cgt=$(awk '/^SigCgt:/ { print $2 }' "/proc/$LT_PID/status" 2>/dev/null)
  if [[ -n $cgt ]] && (((16#$cgt >> 1) & 1)) && (($(tiles_served) > before + 20)); then
    started=1
    break
  fi
  sleep 0.05
done
kill -0 "$LT_PID" 2>/dev/null || { show_output; fail "vts loadtest ended before the SIGINT"; }
((started)) || { show_output; fail "vts loadtest did not start its run within 30 s"; }
sent=$(date +%s%N)
kill -INT "$LT_PID"
for ((i = 0; i < 200; i++)); do
  kill -0 "$LT_PID" 2>/dev/null || break
  sleep 0.05
done
kill -0 "$LT_PID" 2>/dev/null && { show_output; fail "vts loadtest still running 10 s after SIGINT"; }
waited_ms=$((($(date +%s%N) - sent) / 1000000))
rc=0
wait "$LT_PID" || rc=$?
LT_PID=""
((rc == 130)) || { show_output; fail "vts loadtest exited $rc after SIGINT, expected 130"; }
((waited_ms < 2000)) || fail "vts loadtest took $waited_ms ms to stop after SIGINT"
if ! grep -q 'requests' "$OUT" || ! grep -q '^simulation: ' "$OUT"; then
  show_output
  fail "no summary after SIGINT"
fi
no_sanitizer_report "$ERR"
note "stopped $waited_ms ms after SIGINT"

stop_server
note "ok"
