#!/usr/bin/env bash
# Which ETag `vts cache serve` revalidates with, and which it serves, against an origin that is
# not `vts serve`: a small Python static server holding the tileset's TileJSON and tile files.
#   etag  the origin tags each file with its own ETag ("py-<sha1>") and answers 304 to it: the
#         daemon's revalidation sends exactly that tag and gets the 304; clients get the tag
#         derived from the payload's header frame (the one `vts serve` gives the same bytes).
#   none  the origin sends no ETag: the daemon revalidates without If-None-Match (it used to send
#         a tag it made from the payload, one the origin never issued); clients still get the
#         derived tag.
# The daemon runs with --revalidate-after 0, so every hit is revalidated in the background (the
# origin sends no Cache-Control, so that is the tiles' lifetime). Then it follows the origin's
# Cache-Control (the daemon at its default --revalidate-after, an hour):
#   maxage1    "max-age=1": hits a second later revalidate (If-None-Match with the origin's tag,
#              304)
#   immutable  "public, max-age=31536000, immutable": hits never revalidate
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
# shellcheck source=serve_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/serve_lib.sh"
PYTHON=${PYTHON:-python3}
require_tool "$PYTHON"

PY_PID="" DAEMON_PID=""
stop_all_then_cleanup() {
  local rc=$?
  set +e
  for p in $PY_PID $DAEMON_PID; do kill -KILL "$p" 2>/dev/null && wait "$p" 2>/dev/null; done
  (exit "$rc")
  serve_cleanup
}
trap stop_all_then_cleanup EXIT

cat >"$WORK/origin.py" <<'PY'
# A static origin: GET /PATH serves ROOT/PATH; logs "GET <path> inm=<If-None-Match or -> <status>"
# to stdout. With "etag", every file has ETag "py-<sha1 prefix>" and a matching If-None-Match
# is 304; with "none", no ETag is sent and If-None-Match is ignored.
import hashlib, http.server, os, sys
root, mode = sys.argv[1], sys.argv[2]
cache_control = sys.argv[3] if len(sys.argv) > 3 else ""
class Handler(http.server.BaseHTTPRequestHandler):
    protocol_version = "HTTP/1.1"
    def do_GET(self):
        inm = self.headers.get("If-None-Match", "-")
        path = os.path.join(root, self.path.lstrip("/"))
        try:
            data = open(path, "rb").read()
        except OSError:
            data = None
        tag = '"py-%s"' % hashlib.sha1(data).hexdigest()[:16] if data is not None else ""
        status = 404 if data is None else 304 if mode == "etag" and inm == tag else 200
        print("GET %s inm=%s %d" % (self.path, inm, status), flush=True)
        self.send_response(status)
        if mode == "etag" and data is not None:
            self.send_header("ETag", tag)
        if cache_control and data is not None:
            self.send_header("Cache-Control", cache_control)
        body = data if status == 200 else b""
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)
    def log_message(self, *args):
        pass
server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
print("port %d" % server.server_address[1], flush=True)
server.serve_forever()
PY

note "the tileset: built, served once by vts serve to take its TileJSON and two tiles"
expect_ok "$VTS" build --synthetic 1024x1024 -o "$WORK/syn.pmtiles"
start_server "$WORK/syn.pmtiles"
mkdir -p "$WORK/origin/syn/0/0" "$WORK/origin/syn/1/1"
curl -sf "$BASE/syn.json" -o "$WORK/tilejson" || fail "no TileJSON from vts serve"
for t in 0/0/0 1/1/0; do
  curl -sf -D "$WORK/headers_${t//\//_}" "$BASE/syn/$t" -o "$WORK/origin/syn/$t" || fail "tile $t"
done
vts_tag=$(sed -nE 's/^ETag: (.*)\r$/\1/Ip' "$WORK/headers_0_0_0")
[[ $vts_tag =~ ^\"[0-9a-f]{16}\"$ ]] || fail "vts serve's ETag: '$vts_tag'"
stop_server

for mode in etag none; do
  note "origin mode '$mode'"
  "$PYTHON" "$WORK/origin.py" "$WORK/origin" "$mode" >"$LOGS/origin_$mode.log" 2>&1 &
  PY_PID=$!
  for ((i = 0; i < 200; i++)); do
    grep -q "^port " "$LOGS/origin_$mode.log" 2>/dev/null && break
    sleep 0.05
  done
  py_port=$(sed -nE 's/^port ([0-9]+)$/\1/p' "$LOGS/origin_$mode.log")
  [[ -n $py_port ]] || { cat "$LOGS/origin_$mode.log" >&2; fail "the Python origin did not start"; }
  ORIGIN="http://127.0.0.1:$py_port"
  "$PYTHON" -c 'import json, sys
j = json.load(open(sys.argv[1])); j["tiles"] = [sys.argv[2] + "/syn/{z}/{x}/{y}"]
json.dump(j, open(sys.argv[3], "w"))' "$WORK/tilejson" "$ORIGIN" "$WORK/origin/syn.json"

  start_daemon cache "$VTS" cache serve --upstream "$ORIGIN/syn.json" --cache-dir "$WORK/cache_$mode" \
    --revalidate-after 0 --listen 127.0.0.1:0 --no-admin

  for n in 1 2; do
    curl -sf -D "$WORK/d_$n" "$D/syn/0/0/0" -o "$WORK/d_body" || fail "daemon GET $n failed"
    cmp -s "$WORK/d_body" "$WORK/origin/syn/0/0/0" || fail "daemon GET $n: other bytes"
    got=$(sed -nE 's/^ETag: (.*)\r$/\1/Ip' "$WORK/d_$n")
    [[ $got == "$vts_tag" ]] || fail "daemon serves ETag '$got', want the derived '$vts_tag'"
  done
  # The second GET was a stale hit: its revalidation reaches the origin in the background.
  for ((i = 0; i < 200; i++)); do
    (($(grep -c '^GET /syn/0/0/0 ' "$LOGS/origin_$mode.log") >= 2)) && break
    sleep 0.05
  done
  reval=$(grep '^GET /syn/0/0/0 ' "$LOGS/origin_$mode.log" | sed -n 2p)
  note "origin saw: $(grep '^GET /syn/0/0/0 ' "$LOGS/origin_$mode.log" | tr '\n' ';')"
  [[ -n $reval ]] || fail "no revalidation reached the origin"
  if [[ $mode == etag ]]; then
    origin_tag=$("$PYTHON" -c 'import hashlib,sys; print("\"py-%s\"" % hashlib.sha1(open(sys.argv[1],"rb").read()).hexdigest()[:16])' \
        "$WORK/origin/syn/0/0/0")
    [[ $reval == "GET /syn/0/0/0 inm=$origin_tag 304" ]] ||
      fail "revalidation was '$reval', want If-None-Match $origin_tag answered 304"
  else
    [[ $reval == "GET /syn/0/0/0 inm=- 200" ]] ||
      fail "revalidation was '$reval', want no If-None-Match (the origin issued no tag)"
  fi
  curl -sf -D "$WORK/d_3" "$D/syn/0/0/0" -o /dev/null || fail "daemon GET after revalidation"
  [[ $(sed -nE 's/^ETag: (.*)\r$/\1/Ip' "$WORK/d_3") == "$vts_tag" ]] ||
    fail "after revalidation the daemon serves another tag"
  kill -TERM "$DAEMON_PID"
  wait "$DAEMON_PID" || fail "vts cache serve exited $? after SIGTERM"
  DAEMON_PID=""
  kill "$PY_PID"
  wait "$PY_PID" 2>/dev/null || true
  PY_PID=""
done

# origin_gets MODE: the origin's log lines for tile 0/0/0.
origin_gets() { grep '^GET /syn/0/0/0 ' "$LOGS/origin_$1.log" || true; }

for cc in maxage1 immutable; do
  case $cc in
    maxage1) header="max-age=1" ;;
    immutable) header="public, max-age=31536000, immutable" ;;
  esac
  note "origin sends Cache-Control: $header"
  "$PYTHON" "$WORK/origin.py" "$WORK/origin" etag "$header" >"$LOGS/origin_$cc.log" 2>&1 &
  PY_PID=$!
  for ((i = 0; i < 200; i++)); do
    grep -q "^port " "$LOGS/origin_$cc.log" 2>/dev/null && break
    sleep 0.05
  done
  py_port=$(sed -nE 's/^port ([0-9]+)$/\1/p' "$LOGS/origin_$cc.log")
  [[ -n $py_port ]] || { cat "$LOGS/origin_$cc.log" >&2; fail "the Python origin did not start"; }
  ORIGIN="http://127.0.0.1:$py_port"
  "$PYTHON" -c 'import json, sys
j = json.load(open(sys.argv[1])); j["tiles"] = [sys.argv[2] + "/syn/{z}/{x}/{y}"]
json.dump(j, open(sys.argv[3], "w"))' "$WORK/tilejson" "$ORIGIN" "$WORK/origin/syn.json"
  start_daemon cache "$VTS" cache serve --upstream "$ORIGIN/syn.json" --cache-dir "$WORK/cache_$cc" \
    --listen 127.0.0.1:0 --no-admin
  origin_tag=$("$PYTHON" -c 'import hashlib,sys; print("\"py-%s\"" % hashlib.sha1(open(sys.argv[1],"rb").read()).hexdigest()[:16])' \
      "$WORK/origin/syn/0/0/0")
  # Hits for 3 s: with max-age=1 the tile goes stale within the first 2 and a hit after that
  # revalidates it; an immutable tile never does. (Waiting is the point here: ages are in seconds.)
  end=$(($(date +%s%N) + 3000000000))
  while (($(date +%s%N) < end)); do
    curl -sf "$D/syn/0/0/0" -o "$WORK/d_body" || fail "daemon GET failed"
    cmp -s "$WORK/d_body" "$WORK/origin/syn/0/0/0" || fail "daemon GET: other bytes"
    [[ $cc == maxage1 ]] && (($(origin_gets "$cc" | wc -l) >= 2)) && break
    sleep 0.1 # paces the hits; not a synchronisation
  done
  if [[ $cc == maxage1 ]]; then
    # The revalidation runs in the background: poll for it.
    for ((i = 0; i < 100; i++)); do
      (($(origin_gets "$cc" | wc -l) >= 2)) && break
      sleep 0.05
    done
    reval=$(origin_gets "$cc" | sed -n 2p)
    [[ $reval == "GET /syn/0/0/0 inm=$origin_tag 304" ]] ||
      fail "max-age=1: revalidation was '$reval', want If-None-Match $origin_tag answered 304 (origin saw: $(origin_gets "$cc" | tr '\n' ';'))"
  else
    [[ $(origin_gets "$cc" | wc -l) == 1 ]] ||
      fail "immutable: the origin saw $(origin_gets "$cc" | tr '\n' ';'), want one GET and no revalidation"
  fi
  kill -TERM "$DAEMON_PID"
  wait "$DAEMON_PID" || fail "vts cache serve exited $? after SIGTERM"
  DAEMON_PID=""
  if [[ $cc == immutable ]]; then
    note "after a restart the tile's lifetime comes from the disk cache: still no revalidation"
    start_daemon cache "$VTS" cache serve --upstream "$ORIGIN/syn.json" \
      --cache-dir "$WORK/cache_$cc" --listen 127.0.0.1:0 --no-admin --revalidate-after 0
    curl -sf "$D/syn/0/0/0" -o /dev/null || fail "daemon GET after restart"
    curl -sf "$D/syn/0/0/0" -o /dev/null || fail "daemon GET after restart"
    kill -TERM "$DAEMON_PID"
    wait "$DAEMON_PID" || fail "vts cache serve exited $? after SIGTERM"
    DAEMON_PID=""
    [[ $(origin_gets "$cc" | wc -l) == 1 ]] ||
      fail "immutable after restart: the origin saw $(origin_gets "$cc" | tr '\n' ';')"
  fi
  kill "$PY_PID"
  wait "$PY_PID" 2>/dev/null || true
  PY_PID=""
done
note "PASS"
