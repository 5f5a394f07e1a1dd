#!/usr/bin/env bash
# What `vts serve` writes to its logs cannot be forged or flooded from outside:
# - a file in a served folder named with a newline and ESC (a forged "vts serve:" line, a terminal
#   escape) is named on one line, its control bytes as \xHH, when it is skipped at start, when a
#   reload refuses it, and in /health; the access log's JSON escapes a request target's controls;
# - out of file descriptors (prlimit on the running server, clients holding connections), the
#   accept loop backs off and says so once, then at most every 5 s with the count of failed
#   accepts, and once it accepts again; connections waiting meanwhile are then served. The
#   reloads that cannot list the folder meanwhile say so once, not at every reload.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
# shellcheck source=serve_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/serve_lib.sh"
require_tool python3
require_tool prlimit

# wait_for PATTERN FILE: waits (20 s at most) until FILE has a line matching the fixed string.
wait_for() {
  local i
  for ((i = 0; i < 400; i++)); do
    grep -qF -- "$1" "$2" && return 0
    sleep 0.05
  done
  fail "no line with '$1' in $2: $(cat "$2")"
}

build_earth "$WORK/earth.pmtiles"
mkdir -p "$WORK/serve"
cp "$WORK/earth.pmtiles" "$WORK/serve/good.pmtiles"
crafted=$'x\nvts serve: forged line \e[31m.pmtiles'
echo 'not an archive' >"$WORK/serve/$crafted"
echo '{"reload_interval_ms": 100}' >"$WORK/config.json"

note "a crafted file name is skipped at start on one line, escaped"
start_server "$WORK/serve" --config "$WORK/config.json" --access-log "$WORK/access.log" --threads 2
grep -qF "vts serve: skipped $WORK/serve/x\\x0avts serve: forged line \\x1b[31m.pmtiles: " \
  "$LOGS/serve.err" || fail "no escaped skipped line: $(cat -A "$LOGS/serve.err")"
grep -q '^vts serve: forged' "$LOGS/serve.err" && fail "a forged line: $(cat -A "$LOGS/serve.err")"
grep -q $'\e' "$LOGS/serve.err" && fail "an ESC reached stderr: $(cat -A "$LOGS/serve.err")"

note "a crafted file that appears later is refused by a reload on one line, escaped"
crafted2=$'y\nvts serve: forged again \e[2J.pmtiles'
echo 'not an archive either' >"$WORK/serve/.incoming"
mv "$WORK/serve/.incoming" "$WORK/serve/$crafted2"
wait_for 'vts serve: reload refused: ' "$LOGS/serve.err"
grep -F 'vts serve: reload refused: ' "$LOGS/serve.err" |
  grep -qF "$WORK/serve/y\\x0avts serve: forged again \\x1b[2J.pmtiles" ||
  fail "the reload line does not name the file escaped: $(cat -A "$LOGS/serve.err")"
grep -q '^vts serve: forged' "$LOGS/serve.err" && fail "a forged line: $(cat -A "$LOGS/serve.err")"
grep -q $'\e' "$LOGS/serve.err" && fail "an ESC reached stderr: $(cat -A "$LOGS/serve.err")"
curl -s "$ADMIN_BASE/health" >"$WORK/health.txt"
[[ $(grep -c '^skipped ' "$WORK/health.txt") == 2 ]] || fail "/health: $(cat -A "$WORK/health.txt")"
grep -q $'\e' "$WORK/health.txt" && fail "an ESC in /health: $(cat -A "$WORK/health.txt")"

note "a request target with control bytes is one JSON line of the access log"
python3 - "$PORT" <<'PY'
import socket, sys
s = socket.create_connection(("127.0.0.1", int(sys.argv[1])))
s.sendall(b"GET /good/0/0/0?\x1b[2J\nvts HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n")
while s.recv(65536):
    pass
PY
expect_status 200 "$BASE/good/0/0/0"  # a line after it: the raw request's line is written by now
grep -q $'\e' "$WORK/access.log" && fail "an ESC in the access log: $(cat -A "$WORK/access.log")"
python3 - "$WORK/access.log" <<'PY' || fail "access log: $(cat -A "$WORK/access.log")"
import json, sys
lines = open(sys.argv[1], "rb").read().split(b"\n")[:-1]
for line in lines:
    json.loads(line)  # every line is one whole JSON object
PY

note "out of descriptors: one line, then one per 5 s with a count, and one when accepting again"
prlimit --pid "$SERVER_PID" --nofile=48:48
python3 - "$PORT" "$WORK/held" "$WORK/release" <<'PY' &
import os, socket, sys, time
port, held, release = int(sys.argv[1]), sys.argv[2], sys.argv[3]
conns = [socket.create_connection(("127.0.0.1", port)) for _ in range(80)]
open(held, "w").close()
while not os.path.exists(release):
    time.sleep(0.05)
for c in conns:
    c.close()
PY
holder=$!
wait_for 'vts serve: cannot accept connections: ' "$LOGS/serve.err"
grep -F 'vts serve: cannot accept connections: ' "$LOGS/serve.err" | grep -qi 'too many open files' ||
  fail "the first line does not say why: $(cat "$LOGS/serve.err")"
wait_for 'vts serve: still cannot accept connections: ' "$LOGS/serve.err"
[[ $(grep -c 'cannot accept connections' "$LOGS/serve.err") == 2 ]] ||
  fail "not one line, then one after 5 s: $(grep -c 'cannot accept' "$LOGS/serve.err") lines"
grep -E 'still cannot accept connections: .*; [0-9]+ failed accepts since the last report' \
  "$LOGS/serve.err" >/dev/null || fail "no count of failed accepts: $(cat "$LOGS/serve.err")"
# Meanwhile every reload (10 a second here) failed to list the folder: logged once, not 50 times.
[[ $(grep -c 'reload refused: .*Too many open files' "$LOGS/serve.err") == 1 ]] ||
  fail "a reload failure repeated: $(grep -c 'reload refused' "$LOGS/serve.err") lines"
touch "$WORK/release"
wait "$holder" || fail "the client holding connections failed"
wait_for 'vts serve: accepting connections again, after ' "$LOGS/serve.err"
expect_status 200 "$BASE/good/0/0/0"
expect_status 200 "$ADMIN_BASE/health"
stop_server
note "PASS"
