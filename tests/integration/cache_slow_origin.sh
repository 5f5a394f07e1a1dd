#!/usr/bin/env bash
# A slow region of the origin cannot stall the cache daemon's other misses. The origin is a real
# `vts serve` behind slow_origin.py, which holds the tiles of level 5 with x >= 16 for 8 s.
#  1. 32 clients ask the daemon for 32 of those tiles and give up after 1 s (curl --max-time 1);
#     then an uncached tile elsewhere must be answered within 2 s (it took ~14 s when the
#     abandoned fetches held the fetcher), /metrics must count the abandoned gets, and the origin
#     must have seen the daemon close every held request (the transfers left libcurl).
#  2. 16 clients keep waiting on tiles of one 8x8 region: it holds at most --upstream-region-cap
#     (8) transfers, so a tile elsewhere is still answered within 2 s.
#  3. With --upstream-deadline 2, a held tile answers 503 after ~2 s and the origin sees the
#     request closed; a second client of that tile leaving after 1 s did not end the shared fetch
#     early (the first client's answer still took the whole deadline).
#  4. A client that pipelines 16 PNGs of the slow region and closes at once: the daemon notices
#     (its pipeline full, it reads on), cancels all 16 gets (the origin sees them closed) and
#     encodes nothing (it made one upstream fetch per abandoned request before).
# Extra arguments go to every `vts cache serve` (e.g. --upstream-region-cap 0 shows 2 failing).
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
# shellcheck source=serve_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/serve_lib.sh"
require_tool python3
require_tool curl

PROXY_PID="" DAEMON_PID=""
slow_cleanup() {
  for pid in "$DAEMON_PID" "$PROXY_PID"; do
    if [[ -n $pid ]]; then kill -KILL "$pid" 2>/dev/null || true; fi
  done
  serve_cleanup
}
trap slow_cleanup EXIT

# wait_line FILE PATTERN PID WHAT: polls (10 s) until FILE has a line matching PATTERN.
wait_line() {
  local i
  for ((i = 0; i < 200; i++)); do
    grep -qs "$2" "$1" && return 0
    kill -0 "$3" 2>/dev/null || { cat "$1" "$LOGS"/*.err >&2; fail "$4 exited"; }
    sleep 0.05
  done
  fail "$4 did not start"
}

"$VTS" build --synthetic 8192x8192 -o "$WORK/s.pmtiles" >/dev/null 2>&1 || fail "cannot build s.pmtiles"
start_server "$WORK/s.pmtiles"

python3 "$(dirname "${BASH_SOURCE[0]}")/slow_origin.py" --upstream "127.0.0.1:$PORT" \
  --slow-z 5 --slow-x-min 16 --delay 8 >"$LOGS/proxy.out" 2>"$LOGS/proxy.err" </dev/null &
PROXY_PID=$!
wait_line "$LOGS/proxy.out" 'listening on' "$PROXY_PID" "slow_origin.py"
PROXY="http://127.0.0.1:$(sed -nE 's/^listening on ([0-9]+)/\1/p' "$LOGS/proxy.out")"

# start_daemon ARGS...: a fresh `vts cache serve` on the slow origin; sets DAEMON_PID, D, DA.
start_daemon() {
  # Emptied here, not by the redirection below: that runs in the background child, so the
  # previous daemon's "listening on" line could satisfy wait_line before it is truncated.
  : >"$LOGS/daemon.out"
  "$VTS" cache serve --upstream "$PROXY/s" --cache-dir "$WORK/cache$#" --listen 127.0.0.1:0 \
    --admin 127.0.0.1:0 "$@" >"$LOGS/daemon.out" 2>"$LOGS/daemon.err" </dev/null &
  DAEMON_PID=$!
  wait_line "$LOGS/daemon.out" 'listening on' "$DAEMON_PID" "vts cache serve"
  D=$(sed -nE 's|.*listening on (http://[^ ,]*).*|\1|p' "$LOGS/daemon.out")
  DA=$(sed -nE 's|.*admin (http://[^ )]*)\).*|\1|p' "$LOGS/daemon.out")
}
stop_daemon() {
  kill -TERM "$DAEMON_PID"
  wait "$DAEMON_PID" || fail "vts cache serve exited $? after SIGTERM"
  DAEMON_PID=""
}
# origin_count KEY: the slow origin's counter KEY (slow, aborted, done).
origin_count() { curl -s "$PROXY/__stats" | sed -nE "s/.*\"$1\": ([0-9]+).*/\1/p"; }
# timed_get URL: prints "STATUS SECONDS".
timed_get() { curl -s -o /dev/null -w '%{http_code} %{time_total}' --max-time 30 "$1"; }
# expect_fast WHAT URL: URL must answer 200 within 2 s.
expect_fast() {
  local t code secs
  t=$(timed_get "$2")
  code=${t%% *} secs=${t#* }
  note "$1: HTTP $code in $secs s"
  [[ $code == 200 ]] || fail "$1 answered $code"
  awk -v s="$secs" 'BEGIN { exit !(s < 2.0) }' || fail "$1 took $secs s (bound 2 s)"
}

start_daemon "$@"
note "the fast path: an uncached tile outside the slow region"
t=$(curl -s -o /dev/null -w '%{http_code} %{time_total}' --max-time 30 "$D/s/5/0/0")
[[ $t == 200\ * ]] || fail "tile 5/0/0 answered '$t'"
note "5/0/0: $t s"

note "32 clients ask for tiles of the slow region (level 5, x >= 16) and give up after 1 s"
pids=()
for ((i = 0; i < 32; i++)); do
  curl -s -o /dev/null --max-time 1 "$D/s/5/$((16 + i % 16))/$((i / 16))" &
  pids+=($!)
done
for pid in "${pids[@]}"; do wait "$pid" || true; done

note "an uncached tile outside the region while those fetches would still be held"
expect_fast "5/1/1 after 32 clients abandoned slow tiles" "$D/s/5/1/1"

note "the daemon counted the abandoned gets, and closed every held upstream request"
cancelled=$(curl -s "$DA/metrics" | sed -nE 's/^vts_cache_cancelled_total ([0-9]+)$/\1/p')
[[ -n $cancelled ]] || fail "/metrics has no vts_cache_cancelled_total"
((cancelled >= 32)) || fail "vts_cache_cancelled_total is $cancelled, expected >= 32"
for ((i = 0; i < 100; i++)); do
  slow=$(origin_count slow) aborted=$(origin_count aborted)
  ((aborted == slow)) && break
  sleep 0.05
done
note "origin: $slow slow requests held, $aborted closed by the daemon"
((slow >= 1)) || fail "the origin saw no request for the slow region: the test tested nothing"
((aborted == slow)) || fail "the origin held $slow slow requests but only $aborted were closed by the daemon"

note "16 clients that keep waiting for one slow region (5/16..23/2..3) hold at most its cap"
slow0=$(origin_count slow)
waiting=()
for ((i = 0; i < 16; i++)); do
  curl -s -o /dev/null --max-time 30 "$D/s/5/$((16 + i % 8))/$((2 + i / 8))" &
  waiting+=($!)
done
for ((i = 0; i < 200; i++)); do
  (($(origin_count slow) - slow0 >= 8)) && break
  sleep 0.05
done
(($(origin_count slow) - slow0 >= 8)) || fail "the origin never held 8 requests of the slow region"
expect_fast "5/2/2 while 16 clients wait on the slow region" "$D/s/5/2/2"
held=$(($(origin_count slow) - slow0))
note "the origin holds $held of the region's 16 requests"
[[ ${*:-} == *region-cap* ]] || ((held == 8)) || fail "the slow region holds $held transfers, cap 8"
kill "${waiting[@]}" 2>/dev/null || true
wait "${waiting[@]}" 2>/dev/null || true
stop_daemon

note "a fetch the origin holds past --upstream-deadline 2: 503 after ~2 s, the request closed;"
note "a second client of the same tile that leaves after 1 s does not cancel the shared fetch"
start_daemon --upstream-deadline 2 "$@"
aborted0=$(origin_count aborted)
curl -s -o /dev/null --max-time 1 "$D/s/5/30/5" &
leaver=$!
t=$(timed_get "$D/s/5/30/5")
wait "$leaver" || true
cancelled=$(curl -s "$DA/metrics" | sed -nE 's/^vts_cache_cancelled_total ([0-9]+)$/\1/p')
[[ $cancelled == 1 ]] || fail "vts_cache_cancelled_total is '$cancelled', expected 1 (the client that left)"
code=${t%% *} secs=${t#* }
note "5/30/5: HTTP $code in $secs s"
[[ $code == 503 ]] || fail "a fetch past its deadline answered $code, expected 503"
awk -v s="$secs" 'BEGIN { exit !(s >= 1.9 && s < 4.0) }' ||
  fail "a fetch with a 2 s deadline answered after $secs s"
for ((i = 0; i < 100; i++)); do
  (($(origin_count aborted) > aborted0)) && break
  sleep 0.05
done
(($(origin_count aborted) > aborted0)) || fail "the origin's held request was not closed at the deadline"
expect_fast "5/3/3 after the deadline" "$D/s/5/3/3"
stop_daemon

note "a client pipelines 16 PNGs of the slow region (a full pipeline) and closes at once: the"
note "daemon notices although it reads no further request, cancels every fetch, encodes nothing"
start_daemon "$@"
slow0=$(origin_count slow) aborted0=$(origin_count aborted)
python3 - "${D##*:}" <<'PY' || fail "cannot send the pipelined requests"
import socket, sys
s = socket.create_connection(("127.0.0.1", int(sys.argv[1])))
s.sendall(b"".join(b"GET /s/5/%d/6.png HTTP/1.1\r\nHost: d\r\n\r\n" % x for x in range(16, 32)))
s.close()
PY
# daemon_metric NAME: the daemon's unlabelled counter NAME.
daemon_metric() { curl -s "$DA/metrics" | sed -nE "s/^$1 ([0-9]+)\$/\1/p"; }
for ((i = 0; i < 200; i++)); do
  [[ $(daemon_metric vts_cache_cancelled_total) == 16 ]] && break
  sleep 0.05
done
[[ $(daemon_metric vts_http_abandoned_connections_total) == 1 ]] ||
  fail "the daemon did not count the connection as abandoned ($(daemon_metric vts_http_abandoned_connections_total))"
cancelled=$(daemon_metric vts_cache_cancelled_total)
[[ $cancelled == 16 ]] || fail "vts_cache_cancelled_total is '$cancelled' after the client left, expected 16"
for ((i = 0; i < 100; i++)); do
  slow=$(($(origin_count slow) - slow0)) aborted=$(($(origin_count aborted) - aborted0))
  ((aborted == slow)) && break
  sleep 0.05
done
note "origin: $slow requests of the pipelined tiles held, $aborted closed by the daemon"
((aborted == slow)) || fail "the origin held $slow requests but the daemon closed only $aborted"
encodes=$(daemon_metric vts_web_encodes_total)
[[ $encodes == 0 ]] || fail "the daemon encoded $encodes images nobody waited for"
stop_daemon
kill -TERM "$PROXY_PID"
wait "$PROXY_PID" 2>/dev/null || true
PROXY_PID=""
note "PASS"
