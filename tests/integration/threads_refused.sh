#!/usr/bin/env bash
# A thread the system refuses (a task limit, ulimit -v) is an error, never an abort: `vts serve`,
# `vts cache serve` and `vts warm` run with their first n thread starts allowed and the next one
# refused (refuse_threads.cpp, LD_PRELOAD), for n = 0, 1, 2, ... until the command works. Each
# refusal must end the command with exit 4 (io) and "cannot start ... thread" on stderr, the threads
# already started joined (no "terminate called", no signal).
# Environment (besides lib.sh's): REFUSE_THREADS, the shim (a shared library).
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
: "${REFUSE_THREADS:?REFUSE_THREADS must name the refuse_threads shared library}"
[[ -f $REFUSE_THREADS ]] || fail "no shim at $REFUSE_THREADS"
require_tool curl

expect_ok "$VTS" build --synthetic 1024x512 -o "$WORK/syn.pmtiles"

# check_refused WHAT N: the run that just ended ($RC, $ERR) failed cleanly.
check_refused() {
  if ((RC != 4)) || ! grep -q 'cannot start .*thread' "$ERR" || grep -q 'terminate called' "$ERR"; then
    show_output
    fail "$1 with $2 thread(s) allowed exited $RC, expected 4 and 'cannot start ... thread'"
  fi
}

# "${with_threads[@]}" VTS_THREADS_ALLOWED=N CMD...: CMD with its first N thread starts allowed.
with_threads=(env "LD_PRELOAD=$REFUSE_THREADS" ASAN_OPTIONS=verify_asan_link_order=0)

# server_refused NAME N CMD...: starts the server CMD (it prints "listening on http://HOST:PORT"),
# and waits until it exits (returns 0, $RC set) or serves GET /syn/0/0/0 (stops it; returns 1).
server_refused() {
  local name=$1 n=$2 pid i port=""
  shift 2
  : >"$OUT"
  "${with_threads[@]}" "VTS_THREADS_ALLOWED=$n" "$@" >"$OUT" 2>"$ERR" </dev/null &
  pid=$!
  for ((i = 0; i < 400; i++)); do
    if ! kill -0 "$pid" 2>/dev/null; then
      RC=0
      wait "$pid" || RC=$?
      return 0
    fi
    port=$(sed -nE 's|.*listening on http://[^ ]*:([0-9]+)[ ,].*|\1|p' "$OUT")
    if [[ -n $port ]] && curl -sf -o /dev/null "http://127.0.0.1:$port/syn/0/0/0"; then
      kill -TERM "$pid"
      wait "$pid" || fail "$name with $n threads allowed served, then exited $? on SIGTERM"
      return 1
    fi
    sleep 0.05
  done
  kill -KILL "$pid"
  fail "$name with $n thread(s) allowed neither exited nor served within 20 s"
}

# Libraries start threads of their own while the program loads, before main() (log4cplus, pulled
# in by GDAL): those cannot be refused cleanly by us. The count starts after them: the fewest
# threads with which `vts --help` runs.
for ((first = 0; ; first++)); do
  ((first < 64)) || fail "vts --help does not run with 64 threads allowed"
  run "${with_threads[@]}" "VTS_THREADS_ALLOWED=$first" "$VTS" --help
  ((RC == 0)) && break
done
note "$first thread(s) started before main()"

for what in serve cache_serve; do
  for ((n = first; ; n++)); do
    ((n < 64)) || fail "$what still refused with 64 threads allowed"
    if [[ $what == serve ]]; then
      server_refused "$what" "$n" "$VTS" serve "$WORK/syn.pmtiles" --listen 127.0.0.1:0 \
        --admin 127.0.0.1:0 --threads 3 || break
    else
      rm -rf "$WORK/cache"
      server_refused "$what" "$n" "$VTS" cache serve --upstream "$WORK/syn.pmtiles" \
        --cache-dir "$WORK/cache" --listen 127.0.0.1:0 --admin 127.0.0.1:0 --threads 3 || break
    fi
    check_refused "$what" "$n"
  done
  note "$what: a clean error for each of its first $((n - first)) thread starts refused"
done

for ((n = first; ; n++)); do
  ((n < 64)) || fail "warm still refused with 64 threads allowed"
  rm -rf "$WORK/cache"
  run "${with_threads[@]}" "VTS_THREADS_ALLOWED=$n" "$VTS" warm "$WORK/syn.pmtiles" \
    --cache-dir "$WORK/cache"
  ((RC == 0)) && break
  check_refused warm "$n"
done
note "warm: a clean error for each of its first $((n - first)) thread starts refused"
note "PASS"
