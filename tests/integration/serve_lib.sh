# shellcheck shell=bash disable=SC2034  # BASE, ADMIN_BASE, ... are used by the scripts that source this
# Helpers for the `vts serve` integration tests (sourced after lib.sh): start the real server on
# 127.0.0.1 port 0, learn its ports from its first stdout line, stop it with SIGTERM.
require_tool curl

SERVER_PID=""
PORT=""
ADMIN=""
serve_cleanup() {
  if [[ -n $SERVER_PID ]] && kill -0 "$SERVER_PID" 2>/dev/null; then
    kill -KILL "$SERVER_PID" 2>/dev/null || true
  fi
  cleanup
}
trap serve_cleanup EXIT

# start_server ARGS...: starts `vts serve ARGS --listen 127.0.0.1:0 --admin 127.0.0.1:0` in the
# background; sets SERVER_PID, PORT, ADMIN, BASE and ADMIN_BASE.
start_server() {
  : >"$LOGS/serve.out"
  "$VTS" serve "$@" --listen 127.0.0.1:0 --admin 127.0.0.1:0 \
    >"$LOGS/serve.out" 2>"$LOGS/serve.err" </dev/null &
  SERVER_PID=$!
  local i
  for ((i = 0; i < 100; i++)); do
    if grep -q 'listening on' "$LOGS/serve.out"; then break; fi
    kill -0 "$SERVER_PID" 2>/dev/null || { cat "$LOGS/serve.err" >&2; fail "vts serve exited"; }
    sleep 0.05
  done
  PORT=$(sed -nE 's|.*listening on http://[^ ]*:([0-9]+) .*|\1|p' "$LOGS/serve.out")
  ADMIN=$(sed -nE 's|.*admin http://[^ ]*:([0-9]+)\).*|\1|p' "$LOGS/serve.out")
  [[ -n $PORT && -n $ADMIN ]] || { cat "$LOGS/serve.out" "$LOGS/serve.err" >&2; fail "no ports"; }
  BASE="http://127.0.0.1:$PORT"
  ADMIN_BASE="http://127.0.0.1:$ADMIN"
}

# start_daemon NAME COMMAND...: starts COMMAND (vts cache serve, or another server that prints
# "listening on http://HOST:PORT" and perhaps "(admin http://HOST:PORT)") in the background with
# its output in $LOGS/NAME.out and .err, and waits for that line; sets DAEMON_PID, D (its base
# URL) and DADMIN (its admin URL, empty when it has none).
start_daemon() {
  local name=$1 i
  shift
  : >"$LOGS/$name.out"
  "$@" >"$LOGS/$name.out" 2>"$LOGS/$name.err" </dev/null &
  DAEMON_PID=$!
  for ((i = 0; i < 200; i++)); do
    grep -q 'listening on' "$LOGS/$name.out" && break
    kill -0 "$DAEMON_PID" 2>/dev/null || { cat "$LOGS/$name.err" >&2; fail "$name exited"; }
    sleep 0.05
  done
  D=$(sed -nE 's|.*listening on (http://[^ ,]*).*|\1|p' "$LOGS/$name.out")
  DADMIN=$(sed -nE 's|.*\(admin (http://[^ )]*)\).*|\1|p' "$LOGS/$name.out")
  [[ -n $D ]] || { cat "$LOGS/$name.out" "$LOGS/$name.err" >&2; fail "$name: no port"; }
}

# stop_server: SIGTERM; the server must exit 0 within 15 s.
stop_server() {
  kill -TERM "$SERVER_PID"
  local rc=0 i
  for ((i = 0; i < 150; i++)); do
    kill -0 "$SERVER_PID" 2>/dev/null || break
    sleep 0.1
  done
  kill -0 "$SERVER_PID" 2>/dev/null && fail "vts serve still running 15 s after SIGTERM"
  wait "$SERVER_PID" || rc=$?
  SERVER_PID=""
  ((rc == 0)) || { cat "$LOGS/serve.err" >&2; fail "vts serve exited $rc after SIGTERM"; }
  if grep -qE 'AddressSanitizer|runtime error:' "$LOGS/serve.err"; then
    cat "$LOGS/serve.err" >&2
    fail "sanitizer report from vts serve"
  fi
}

# status_of ARGS...: prints the HTTP status curl got for ARGS.
status_of() { curl -s -o /dev/null -w '%{http_code}' "$@"; }

# expect_status WANT ARGS...
expect_status() {
  local want=$1 got
  shift
  got=$(status_of "$@")
  local args="$*"
  [[ $got == "$want" ]] || fail "curl ${args:0:200} answered $got, expected $want"
}

# archive_bytes ARCHIVE OFFSET LENGTH: the raw bytes at OFFSET (independent of any reader).
archive_bytes() { tail -c +$(($2 + 1)) "$1" | head -c "$3"; }

# fault_proxy (tests/integration/fault_proxy.hpp) in front of the server started above, for the
# load test scripts. FAULT_PROXY names the executable.
PROXY_PID=""
# start_fault_proxy ARGS...: `fault_proxy --upstream $BASE ARGS` in the background; sets
# PROXY_PID (timeout(1)'s: SIGTERM reaches fault_proxy through it) and PROXY (its base URL).
start_fault_proxy() {
  local i port
  : >"$LOGS/proxy.out"
  timeout -k 5 "$CMD_TIMEOUT" "$FAULT_PROXY" --upstream "$BASE" "$@" \
    >"$LOGS/proxy.out" 2>"$LOGS/proxy.err" </dev/null &
  PROXY_PID=$!
  for ((i = 0; i < 100; i++)); do
    grep -q '^listening on [0-9]' "$LOGS/proxy.out" && break
    kill -0 "$PROXY_PID" 2>/dev/null || { cat "$LOGS/proxy.err" >&2; fail "fault_proxy exited"; }
    sleep 0.05
  done
  port=$(sed -nE 's/^listening on ([0-9]+)$/\1/p' "$LOGS/proxy.out")
  [[ -n $port ]] || { cat "$LOGS/proxy.err" >&2; fail "fault_proxy printed no port"; }
  PROXY="http://127.0.0.1:$port"
}
# stop_fault_proxy: SIGTERM; fault_proxy must exit 0 (writing its --stats file, if any).
stop_fault_proxy() {
  kill -TERM "$PROXY_PID"
  wait "$PROXY_PID" || fail "fault_proxy exited non-zero after SIGTERM"
  PROXY_PID=""
}
# fault_proxy_cleanup: for an EXIT trap; SIGTERM first (SIGKILL of timeout(1) would orphan it).
fault_proxy_cleanup() {
  local i
  if [[ -n $PROXY_PID ]] && kill -TERM "$PROXY_PID" 2>/dev/null; then
    for ((i = 0; i < 40; i++)); do
      kill -0 "$PROXY_PID" 2>/dev/null || break
      sleep 0.05
    done
    kill -KILL "$PROXY_PID" 2>/dev/null || true
  fi
}
