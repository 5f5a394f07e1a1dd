#!/usr/bin/env bash
# `vts warm` and `vts view`'s source against a host that ignores HTTP Range: the real
# `python3 -m http.server` on 127.0.0.1 (it answers every GET with 200 and the whole file). The
# archive must be downloaded exactly once (the server's own log counts the GETs), the cache must
# hold every tile; with --max-download below the archive's size warm must fail at once, naming the
# host's behaviour, and write nothing.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

PYTHON=${PYTHON:-python3}
SQLITE3=${SQLITE3:-sqlite3}
require_tool "$PYTHON"
require_tool "$SQLITE3"

HTTP_PID=""
http_cleanup() {
  if [[ -n $HTTP_PID ]] && kill -0 "$HTTP_PID" 2>/dev/null; then kill -KILL "$HTTP_PID" || true; fi
  cleanup
}
trap http_cleanup EXIT

mkdir -p "$WORK/www"
expect_ok "$VTS" build --synthetic 4096x4096 -o "$WORK/www/syn.pmtiles"
SIZE=$(stat -c %s "$WORK/www/syn.pmtiles")
TILES=341 # 4096x4096, T = 256: levels 0-4 hold 1 + 4 + 16 + 64 + 256 tiles
((SIZE > 16384)) || fail "the archive ($SIZE bytes) must be larger than the opening read"

note "python3 -m http.server on 127.0.0.1 (port 0), polled until it listens"
: >"$LOGS/http.out" # exists before the poll reads it (the job opens it when it starts)
(cd "$WORK/www" && exec "$PYTHON" -u -m http.server 0 --bind 127.0.0.1) \
  >"$LOGS/http.out" 2>"$LOGS/http.log" </dev/null &
HTTP_PID=$!
PORT=""
for ((i = 0; i < 200; i++)); do
  PORT=$(sed -nE 's/^Serving HTTP on .* port ([0-9]+) .*/\1/p' "$LOGS/http.out")
  [[ -n $PORT ]] && break
  kill -0 "$HTTP_PID" 2>/dev/null || { cat "$LOGS/http.log" >&2; fail "http.server exited"; }
  sleep 0.05
done
[[ -n $PORT ]] || fail "http.server did not start"
URL="http://127.0.0.1:$PORT/syn.pmtiles"
# The premise: this host ignores Range.
[[ $(curl -s -o /dev/null -w '%{http_code} %{size_download}' -r 0-99 "$URL") == "200 $SIZE" ]] ||
  fail "http.server honoured Range; the test needs a host that ignores it"
: >"$LOGS/http.log"

# gets: the GETs of the archive in the server's log so far.
gets() { grep -c '"GET /syn.pmtiles ' "$LOGS/http.log" || true; }

note "warm downloads the archive once and caches every tile"
expect_ok "$VTS" warm "$URL" --cache-dir "$WORK/cache" --json
json_check "$OUT" "j.tiles_total == $TILES && j.from_network == $TILES && j.failed == 0 &&
  j.complete === true" "every tile warmed"
[[ $("$SQLITE3" "$WORK/cache/cache.db" 'SELECT count(*) FROM tiles') == "$TILES" ]] ||
  fail "the cache does not hold $TILES tiles"
[[ $(gets) == 1 ]] || { cat "$LOGS/http.log" >&2; fail "$(gets) GETs of the archive, expected 1"; }

note "--max-download below the archive's size: a clean failure naming the behaviour, quickly"
: >"$LOGS/http.log"
start=$(date +%s%N)
expect_clean_failure "$VTS" warm "$URL" --cache-dir "$WORK/cache2" --max-download 20K
elapsed_ms=$((($(date +%s%N) - start) / 1000000))
grep -qF "host http://127.0.0.1:$PORT ignores HTTP Range requests (answered 200 with the whole $SIZE-byte file" "$ERR" ||
  { show_output; fail "the error does not name the host's behaviour and the file's size"; }
grep -qF -- "--max-download" "$ERR" || fail "the error does not name --max-download"
((elapsed_ms < 5000)) || fail "the failure took $elapsed_ms ms"
[[ $(gets) -le 1 ]] || fail "$(gets) GETs of the archive for a refused download"
[[ ! -e $WORK/cache2/cache.db ]] || fail "a refused download wrote a cache"

note "--max-download 0: never download the whole file"
expect_clean_failure "$VTS" warm "$URL" --cache-dir "$WORK/cache3" --max-download 0
grep -qF "ignores HTTP Range requests" "$ERR" || { show_output; fail "no message for 0"; }

note "a bad --max-download is a usage error"
expect_clean_failure "$VTS" warm "$URL" --cache-dir "$WORK/cache4" --max-download lots
grep -q -- "--max-download" "$ERR" || { show_output; fail "the error does not name the option"; }
note "ok"
