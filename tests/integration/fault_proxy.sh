#!/usr/bin/env bash
# fault_proxy (tests/integration/fault_proxy.hpp) in front of the real `vts serve`, driven by the
# curl CLI: it injects exactly the errors, resets, truncations and delays its schedule names, in
# arrival order, only on requests under --prefix, with precedence error > reset > delay (a
# truncation sends half the body under the full Content-Length); forwarded answers are
# byte-identical to direct ones and reuse one upstream connection per client connection; delays
# do not hold up other connections (64 in parallel); /_proxy/stats and the --stats file count
# exactly what was injected; SIGTERM ends it promptly (a delay in progress included) with exit 0;
# an unreachable upstream is a 502 it counts; bad arguments exit 2.
source "$(dirname "$0")/lib.sh"
source "$(dirname "$0")/serve_lib.sh"
: "${FAULT_PROXY:?FAULT_PROXY must name the fault_proxy executable}"
: "${PMTILES_DUMP:?}"
require_tool "$FAULT_PROXY"

PROXY_PIDS=()
proxy_cleanup() {
  local pid
  for pid in "${PROXY_PIDS[@]}"; do kill -KILL "$pid" 2>/dev/null || true; done
  serve_cleanup
}
trap proxy_cleanup EXIT

# start_proxy NAME ARGS...: starts `fault_proxy --upstream $BASE ARGS --stats $WORK/NAME.stats.json`
# in the background; sets PROXY_PID and PROXY (its base URL).
start_proxy() {
  local name=$1 i
  shift
  : >"$LOGS/$name.out"
  timeout -k 5 "$CMD_TIMEOUT" "$FAULT_PROXY" --upstream "$BASE" "$@" \
    --stats "$WORK/$name.stats.json" >"$LOGS/$name.out" 2>"$LOGS/$name.err" </dev/null &
  PROXY_PID=$!
  PROXY_PIDS+=("$PROXY_PID")
  for ((i = 0; i < 100; i++)); do
    grep -q '^listening on [0-9]' "$LOGS/$name.out" && break
    kill -0 "$PROXY_PID" 2>/dev/null || { cat "$LOGS/$name.err" >&2; fail "fault_proxy exited"; }
    sleep 0.05
  done
  local port
  port=$(sed -nE 's/^listening on ([0-9]+)$/\1/p' "$LOGS/$name.out")
  [[ -n $port ]] || { cat "$LOGS/$name.err" >&2; fail "fault_proxy printed no port"; }
  PROXY="http://127.0.0.1:$port"
}

# stop_proxy PID NAME [MAX_SECONDS]: SIGTERM; it must exit 0 within MAX_SECONDS (default 5) and
# leave its --stats file.
stop_proxy() {
  local pid=$1 name=$2 max=${3:-5} rc=0 i
  kill -TERM "$pid"
  for ((i = 0; i < max * 20; i++)); do
    kill -0 "$pid" 2>/dev/null || break
    sleep 0.05
  done
  kill -0 "$pid" 2>/dev/null && fail "fault_proxy ($name) still running ${max} s after SIGTERM"
  wait "$pid" || rc=$?
  ((rc == 0)) || { cat "$LOGS/$name.err" >&2; fail "fault_proxy ($name) exited $rc after SIGTERM"; }
  [[ -s $WORK/$name.stats.json ]] || fail "fault_proxy ($name) left no --stats file"
  if grep -qE 'AddressSanitizer|runtime error:|LeakSanitizer|ThreadSanitizer' "$LOGS/$name.err"; then
    cat "$LOGS/$name.err" >&2
    fail "sanitizer report from fault_proxy ($name)"
  fi
}

# fault_of N E R D: the fault the schedule gives matching request N with --error-every E,
# --reset-every R, --delay-every D (0: off): error, reset, delay or none.
fault_of() {
  local n=$1 e=$2 r=$3 d=$4
  if ((e > 0 && n % e == 0)); then
    echo error
  elif ((r > 0 && n % r == 0)); then
    echo reset
  elif ((d > 0 && n % d == 0)); then
    echo delay
  else
    echo none
  fi
}

# expect_stats FILE JS_EXPR...: each JS expression (j = the stats) must hold, and so must
# requests = forwarded + errors + resets + upstream_errors.
expect_stats() {
  local file=$1
  shift
  json_check "$file" 'j.requests == j.forwarded + j.errors + j.resets + j.upstream_errors' \
    "requests = forwarded + errors + resets + upstream_errors in $(cat "$file")"
  local e
  for e in "$@"; do json_check "$file" "$e" "$e in $(cat "$file")"; done
}

# at_least_ms SECONDS MS: SECONDS (as curl's %{time_total} prints them, "0.100634") >= MS.
at_least_ms() {
  local whole=${1%%.*} frac=${1#*.}000000
  [[ $1 == *.* ]] || frac=000000
  ((10#$whole * 1000000 + 10#${frac:0:6} >= $2 * 1000))
}

note "bad arguments exit 2, an unwritable --stats file 1"
expect_ok "$VTS" build --synthetic 3000x1700 -o "$WORK/syn.pmtiles"
for args in "" "--upstream" "--upstream nope" "--upstream 0" "--upstream 1234 --frobnicate 1" \
  "--upstream 1234 --error-every 0" "--upstream 1234 --error-every 3 --error-status 200" \
  "--upstream 1234 --error-status 503" "--upstream 1234 --delay-every 2" \
  "--upstream 1234 --delay-ms 10" "--upstream 1234 --delay-every 2 --delay-ms -1" \
  "--upstream 1234 --reset-every x" "--upstream 1234 --threads 0" "--upstream 1234 --port 70000" \
  "--upstream http://example.org:80"; do
  # shellcheck disable=SC2086  # word splitting of $args is the point
  run "$FAULT_PROXY" $args
  ((RC == 2)) || { show_output; fail "fault_proxy $args exited $RC, expected 2"; }
  grep -q '^fault_proxy: ' "$ERR" || { show_output; fail "fault_proxy $args: no message saying why"; }
done
run "$FAULT_PROXY" --upstream 1234 --stats "$WORK/no/such/dir/stats.json"
((RC == 1)) || { show_output; fail "unwritable --stats exited $RC, expected 1"; }

start_server "$WORK/syn.pmtiles" --access-log "$WORK/access.log"
"$PMTILES_DUMP" offsets "$WORK/syn.pmtiles" >"$WORK/syn.offsets"
mapfile -t TILES < <(awk '{ print $2 "/" $3 "/" $4 }' "$WORK/syn.offsets")
((${#TILES[@]} >= 100)) || fail "only ${#TILES[@]} tiles in the synthetic archive"
note "direct fetches of ${#TILES[@]} tiles"
mkdir -p "$WORK/direct"
args=()
for t in "${TILES[@]}"; do args+=("$BASE/syn/$t" -o "$WORK/direct/${t//\//_}"); done
timeout "$CMD_TIMEOUT" curl -sSf "${args[@]}" || fail "direct fetches failed"

# ---- 1. one keep-alive connection, 100 tiles and 10 TileJSON requests in order -----------------
note "sequential: --error-every 10 --delay-every 7 --delay-ms 100 on /syn/ only"
E=10 R=0 D=7
start_proxy seq --prefix /syn/ --error-every $E --error-status 503 --delay-every $D --delay-ms 100
SEQ_PID=$PROXY_PID
mkdir -p "$WORK/seq"
args=()
for ((n = 1; n <= 100; n++)); do
  t=${TILES[n - 1]}
  args+=("$PROXY/syn/$t" -o "$WORK/seq/$n")
  if ((n % 10 == 0)); then args+=("$PROXY/syn.json" -o "$WORK/seq/json_$n"); fi
done
lines_before=$(wc -l <"$WORK/access.log")
timeout "$CMD_TIMEOUT" curl -sS -v "${args[@]}" \
  -w '%{http_code} %{time_total} %{num_connects} %{url_effective}\n' \
  >"$WORK/seq.txt" 2>"$LOGS/curl_seq.txt" || fail "curl through the proxy failed"
(($(wc -l <"$WORK/seq.txt") == 110)) || fail "curl reported $(wc -l <"$WORK/seq.txt") transfers, not 110"
conns=$(awk '{ s += $3 } END { print s }' "$WORK/seq.txt")
((conns == 1)) || fail "110 requests took $conns client connections, expected 1 (keep-alive)"

errors=0 delays=0 forwarded=0 n=0
while read -r code time _ url; do
  if [[ $url == */syn.json ]]; then
    [[ $code == 200 ]] || fail "$url (not under the prefix) answered $code, expected 200"
    forwarded=$((forwarded + 1))
    continue
  fi
  n=$((n + 1))
  t=${TILES[n - 1]}
  case $(fault_of $n $E $R $D) in
    error)
      [[ $code == 503 ]] || fail "request $n ($url) answered $code, expected the injected 503"
      [[ $(cat "$WORK/seq/$n") == "injected 503" ]] || fail "request $n: body '$(cat "$WORK/seq/$n")'"
      errors=$((errors + 1))
      ;;
    delay | none)
      [[ $code == 200 ]] || fail "request $n ($url) answered $code, expected 200"
      cmp -s "$WORK/seq/$n" "$WORK/direct/${t//\//_}" || fail "request $n ($url): bytes differ"
      forwarded=$((forwarded + 1))
      if [[ $(fault_of $n $E $R $D) == delay ]]; then
        at_least_ms "$time" 100 || fail "request $n was to be delayed 100 ms but took ${time} s"
        delays=$((delays + 1))
      fi
      ;;
  esac
done <"$WORK/seq.txt"
((n == 100 && errors == 10 && delays == 13 && forwarded == 100)) ||
  fail "schedule: $n tiles, $errors errors, $delays delays, $forwarded forwarded"
note "10 errors (503), 13 delays >= 100 ms, 90 tiles byte-identical, 10 TileJSON untouched"
curl -sSf "$PROXY/_proxy/stats" -o "$WORK/seq.live.json"
expect_stats "$WORK/seq.live.json" 'j.requests == 110' 'j.matched == 100' 'j.forwarded == 100' \
  'j.errors == 10' 'j.delays == 13' 'j.resets == 0' 'j.upstream_errors == 0' 'j.delay_ms == 100'

# Upstream saw exactly the forwarded requests, all over one kept-alive connection.
for ((i = 0; i < 40; i++)); do
  (($(wc -l <"$WORK/access.log") - lines_before >= 100)) && break
  sleep 0.05
done
tail -n +$((lines_before + 1)) "$WORK/access.log" >"$WORK/seq.access"
(($(wc -l <"$WORK/seq.access") == 100)) ||
  fail "vts serve logged $(wc -l <"$WORK/seq.access") requests from the proxy, expected 100"
upstream_conns=$(sed -nE 's/.*"remote":"([^"]*)".*/\1/p' "$WORK/seq.access" | sort -u | wc -l)
((upstream_conns == 1)) || fail "the proxy used $upstream_conns upstream connections, expected 1"

note "headers pass through: HEAD, ETag and If-None-Match, HTTP/1.0"
t=${TILES[0]}
curl -sSf -I "$PROXY/syn/$t" -o "$WORK/head_proxy.txt"
curl -sSf -I "$BASE/syn/$t" -o "$WORK/head_direct.txt"
for h in content-length etag content-type cache-control; do
  a=$(grep -i "^$h:" "$WORK/head_proxy.txt" || true)
  b=$(grep -i "^$h:" "$WORK/head_direct.txt" || true)
  [[ -n $a && $a == "$b" ]] || fail "HEAD via the proxy: '$a', directly: '$b'"
done
etag=$(sed -nE 's/^[Ee][Tt][Aa][Gg]: (.*)\r$/\1/p' "$WORK/head_direct.txt")
expect_status 304 -H "If-None-Match: $etag" "$PROXY/syn/$t"
curl -sSf -0 -D "$WORK/http10.txt" "$PROXY/syn/$t" -o "$WORK/http10.bin"
head -1 "$WORK/http10.txt" | grep -q '^HTTP/1.0 200' || fail "HTTP/1.0: $(head -1 "$WORK/http10.txt")"
cmp -s "$WORK/http10.bin" "$WORK/direct/${t//\//_}" || fail "HTTP/1.0 body differs"
curl -sSf "$PROXY/_proxy/stats" -o "$WORK/seq.live.json"
expect_stats "$WORK/seq.live.json" 'j.requests == 113' 'j.matched == 103' 'j.forwarded == 103'
stop_proxy "$SEQ_PID" seq
cmp -s "$WORK/seq.stats.json" "$WORK/seq.live.json" ||
  fail "--stats file $(cat "$WORK/seq.stats.json") differs from /_proxy/stats $(cat "$WORK/seq.live.json")"

# ---- 2. 64 connections at once ----------------------------------------------------------------
note "parallel: 640 tile requests over 64 connections"
start_proxy par --prefix /syn/ --error-every 10 --error-status 500 --delay-every 7 --delay-ms 100 \
  --threads 2
PAR_PID=$PROXY_PID
mkdir -p "$WORK/par"
: >"$WORK/par.cfg"
for ((i = 0; i < 640; i++)); do
  t=${TILES[i % ${#TILES[@]}]}
  printf 'url = "%s/syn/%s?i=%d"\noutput = "%s/par/%d.%s"\n' "$PROXY" "$t" "$i" "$WORK" "$i" \
    "${t//\//_}" >>"$WORK/par.cfg"
done
start=$(date +%s%N)
timeout "$CMD_TIMEOUT" curl -sS --parallel --parallel-max 64 -K "$WORK/par.cfg" \
  -w '%{http_code} %{time_total} %{num_connects} %{filename_effective}\n' \
  >"$WORK/par.txt" 2>"$LOGS/curl_par.txt" || fail "parallel curl failed: $(tail -3 "$LOGS/curl_par.txt")"
wall_ms=$((($(date +%s%N) - start) / 1000000))
ok=0 err=0 slow=0
while read -r code time _ file; do
  case $code in
    200)
      ok=$((ok + 1))
      base=${file##*/}
      cmp -s "$file" "$WORK/direct/${base#*.}" || fail "$file differs from the direct fetch"
      ;;
    500) err=$((err + 1)) ;;
    *) fail "$file: status $code" ;;
  esac
  if at_least_ms "$time" 100; then slow=$((slow + 1)); fi
done <"$WORK/par.txt"
conns=$(awk '{ s += $3 } END { print s }' "$WORK/par.txt")
curl -sSf "$PROXY/_proxy/stats" -o "$WORK/par.live.json"
expect_stats "$WORK/par.live.json" 'j.requests == 640' 'j.matched == 640' 'j.errors == 64' \
  'j.forwarded == 576' 'j.delays == 82' 'j.resets == 0' 'j.upstream_errors == 0'
((ok == 576 && err == 64)) || fail "curl saw $ok answers and $err injected 500s, expected 576 and 64"
((slow >= 82)) || fail "only $slow transfers took >= 100 ms; 82 were delayed"
((conns >= 32)) || fail "curl opened only $conns connections"
# 82 delays of 100 ms one after another would take 8.2 s; waited on timers, they overlap.
((wall_ms < 4000)) || fail "640 requests with 82 delays took $wall_ms ms: delays block each other?"
note "64 errors, 82 delays ($slow transfers >= 100 ms), 576 identical tiles; $conns connections, $wall_ms ms"
stop_proxy "$PAR_PID" par
expect_stats "$WORK/par.stats.json" 'j.requests == 640' 'j.errors == 64' 'j.delays == 82'

# ---- 3. resets and precedence, one fresh connection per request --------------------------------
# (A client reusing a connection would not show a reset: libcurl silently retries a request whose
# reused connection dies before any answer, and the retry is another request to the schedule.)
note "resets and precedence: --reset-every 4 --error-every 6 --delay-every 3 --delay-ms 50"
E=6 R=4 D=3
start_proxy rst --prefix /syn/ --error-every $E --error-status 500 --reset-every $R \
  --delay-every $D --delay-ms 50
RST_PID=$PROXY_PID
RST=$PROXY
declare -A want=([error]=0 [reset]=0 [delay]=0 [none]=0)
for ((n = 1; n <= 24; n++)); do
  t=${TILES[n - 1]}
  set +e
  out=$(timeout 30 curl -sS -o "$WORK/rst_$n" -w '%{http_code} %{time_total}' "$PROXY/syn/$t" \
    2>"$LOGS/curl_rst_$n.txt")
  rc=$?
  set -e
  read -r code time <<<"$out"
  f=$(fault_of $n $E $R $D)
  want[$f]=$((want[$f] + 1))
  case $f in
    error) [[ $rc == 0 && $code == 500 ]] || fail "request $n: rc $rc status $code, expected 500" ;;
    reset)
      [[ $rc == 56 && $code == 000 ]] ||
        fail "request $n: rc $rc status $code, expected a reset (curl 56): $(cat "$LOGS/curl_rst_$n.txt")"
      grep -qi 'reset by peer' "$LOGS/curl_rst_$n.txt" || fail "request $n: $(cat "$LOGS/curl_rst_$n.txt")"
      ;;
    delay | none)
      [[ $rc == 0 && $code == 200 ]] || fail "request $n: rc $rc status $code, expected 200"
      cmp -s "$WORK/rst_$n" "$WORK/direct/${t//\//_}" || fail "request $n: bytes differ"
      if [[ $f == delay ]]; then at_least_ms "$time" 50 || fail "request $n not delayed: $time s"; fi
      ;;
  esac
done
((want[error] == 4 && want[reset] == 4 && want[delay] == 4)) || fail "precedence table: ${want[*]}"
curl -sSf "$RST/_proxy/stats" -o "$WORK/rst.live.json"
expect_stats "$WORK/rst.live.json" 'j.requests == 24' 'j.errors == 4' 'j.resets == 4' \
  'j.delays == 4' 'j.forwarded == 16' 'j.upstream_errors == 0'
note "4 errors over 4 resets over 4 delays, as the precedence says"

note "truncations: --truncate-every 3 (the header's full Content-Length, half the body, then close)"
start_proxy trunc --prefix /syn/ --truncate-every 3
TRUNC_PID=$PROXY_PID
for ((n = 1; n <= 9; n++)); do
  t=${TILES[n - 1]}
  direct=$WORK/direct/${t//\//_}
  set +e
  code=$(timeout 30 curl -sS -o "$WORK/trunc_$n" -w '%{http_code}' "$PROXY/syn/$t" \
    2>"$LOGS/curl_trunc_$n.txt")
  rc=$?
  set -e
  if ((n % 3 == 0)); then
    # curl 18: "transfer closed with N bytes remaining to read"
    [[ $rc == 18 && $code == 200 ]] ||
      fail "request $n: rc $rc status $code, expected a partial file (curl 18): $(cat "$LOGS/curl_trunc_$n.txt")"
    half=$(($(stat -c %s "$direct") / 2))
    [[ $(stat -c %s "$WORK/trunc_$n") == "$half" ]] ||
      fail "request $n: $(stat -c %s "$WORK/trunc_$n") bytes arrived, expected half ($half)"
    cmp -s "$WORK/trunc_$n" <(head -c "$half" "$direct") || fail "request $n: the half that came differs"
  else
    [[ $rc == 0 && $code == 200 ]] || fail "request $n: rc $rc status $code, expected 200"
    cmp -s "$WORK/trunc_$n" "$direct" || fail "request $n: bytes differ"
  fi
done
curl -sSf "$PROXY/_proxy/stats" -o "$WORK/trunc.live.json"
expect_stats "$WORK/trunc.live.json" 'j.requests == 9' 'j.truncations == 3' 'j.forwarded == 9' \
  'j.errors == 0' 'j.resets == 0'
stop_proxy "$TRUNC_PID" trunc
note "3 of 9 answers broken off at half their body, curl says so (18); the rest whole"

note "SIGTERM during a delay ends the proxy promptly"
start_proxy slow --delay-every 1 --delay-ms 60000
SLOW_PID=$PROXY_PID
timeout 30 curl -s -o /dev/null "$PROXY/syn/${TILES[0]}" &
CURL_PID=$!
for ((i = 0; i < 100; i++)); do
  curl -sSf "$PROXY/_proxy/stats" -o "$WORK/slow.live.json"
  grep -q '"delays":1' "$WORK/slow.live.json" && break
  sleep 0.05
done
grep -q '"delays":1' "$WORK/slow.live.json" || fail "the delay did not start: $(cat "$WORK/slow.live.json")"
stop_proxy "$SLOW_PID" slow 3
rc=0
wait "$CURL_PID" || rc=$?
((rc != 0 && rc != 124)) || fail "the client of the delayed request ended with $rc"
json_check "$WORK/slow.stats.json" 'j.requests == 1 && j.delays == 1 && j.forwarded == 0' \
  "stats of the interrupted delay: $(cat "$WORK/slow.stats.json")"

note "an unreachable upstream is a 502, counted"
stop_server
code=$(timeout 30 curl -s -o "$WORK/502.txt" -w '%{http_code}' "$RST/syn/${TILES[0]}")
[[ $code == 502 ]] || fail "with vts serve stopped the proxy answered $code, expected 502"
curl -sSf "$RST/_proxy/stats" -o "$WORK/rst.live.json"
expect_stats "$WORK/rst.live.json" 'j.requests == 25' 'j.upstream_errors == 1'
stop_proxy "$RST_PID" rst
cmp -s "$WORK/rst.stats.json" "$WORK/rst.live.json" || fail "--stats file differs from /_proxy/stats"
note "ok"
