#!/usr/bin/env bash
# `vts serve` end to end over real sockets with the curl CLI: every route and status, tile bytes
# identical to the archive's stored bytes, keep-alive reuse, pipelining, conditional GET, Range,
# CORS, parse errors, /metrics and /health, the access log, and a clean exit on SIGTERM.
source "$(dirname "$0")/lib.sh"
source "$(dirname "$0")/serve_lib.sh"
: "${PMTILES_DUMP:?}"

expect_ok "$VTS" build --synthetic 3000x1700 -o "$WORK/syn.pmtiles"
build_earth "$WORK/earth.pmtiles"
start_server "$WORK/syn.pmtiles" "$WORK/earth.pmtiles" --access-log "$WORK/access.log"
grep -q ', 2 tilesets' "$LOGS/serve.out" || fail "startup line does not count 2 tilesets"

note "index and TileJSON"
curl -sf "$BASE/" -o "$WORK/index.json"
json_check "$WORK/index.json" 'Array.isArray(j) ? j.length == 2 : Object.keys(j).length > 0' \
  "index lists the tilesets"
if ! grep -q '"syn"' "$WORK/index.json" || ! grep -q '"earth"' "$WORK/index.json"; then
  fail "index does not name both tilesets"
fi
curl -sf "$BASE/earth.json" -o "$WORK/earth.json"
json_check "$WORK/earth.json" 'j.tilejson && j.tiles && j.tiles[0].includes("{z}/{x}/{y}")' \
  "TileJSON with a tiles template"

note "every tile byte-exact (one keep-alive connection)"
for a in syn earth; do
  "$PMTILES_DUMP" offsets "$WORK/$a.pmtiles" >"$WORK/$a.offsets"
  args=()
  while read -r _ z x y _ _; do
    args+=("$BASE/$a/$z/$x/$y" -o "$WORK/t_${a}_${z}_${x}_$y")
  done <"$WORK/$a.offsets"
  curl -sf -v "${args[@]}" 2>"$LOGS/curl_$a.txt" || fail "fetching $a tiles failed"
  n=0
  while read -r _ z x y off len; do
    cmp -s <(archive_bytes "$WORK/$a.pmtiles" "$off" "$len") "$WORK/t_${a}_${z}_${x}_$y" ||
      fail "$a/$z/$x/$y differs from the archive's bytes"
    n=$((n + 1))
  done <"$WORK/$a.offsets"
  ((n > 10)) || fail "only $n tiles in $a"
  conns=$(grep -c 'Connected to' "$LOGS/curl_$a.txt" || true)
  grep -q 'Re-using existing connection' "$LOGS/curl_$a.txt" || fail "curl did not reuse the connection"
  ((conns == 1)) || fail "$n tiles took $conns connections, expected 1"
  note "$a: $n tiles identical, 1 connection"
done

note "HEAD sends headers only"
read -r _ z x y off len < <(head -1 "$WORK/earth.offsets")
curl -sf -I "$BASE/earth/$z/$x/$y" -o "$WORK/head.txt"
grep -qi "^content-length: $len" "$WORK/head.txt" || fail "HEAD content-length"
grep -qi '^server: vtstream' "$WORK/head.txt" || fail "no Server header"
grep -qi '^date: ' "$WORK/head.txt" || fail "no Date header"

note "conditional GET"
etag=$(curl -sf -D - -o /dev/null "$BASE/earth/$z/$x/$y" | sed -nE 's/^[Ee][Tt][Aa][Gg]: (.*)\r$/\1/p')
[[ -n $etag ]] || fail "no ETag"
expect_status 304 -H "If-None-Match: $etag" "$BASE/earth/$z/$x/$y"
expect_status 200 -H 'If-None-Match: "0000000000000000"' "$BASE/earth/$z/$x/$y"

note "Range on the archive"
curl -sf -r 0-126 "$BASE/earth.pmtiles" -o "$WORK/range.bin" -w '%{http_code}' >"$WORK/code"
[[ $(cat "$WORK/code") == 206 ]] || fail "range answered $(cat "$WORK/code")"
cmp -s "$WORK/range.bin" <(head -c 127 "$WORK/earth.pmtiles") || fail "range bytes differ"
size=$(stat -c %s "$WORK/earth.pmtiles")
curl -sf -r $((size - 100))- "$BASE/earth.pmtiles" -o "$WORK/tail.bin"
cmp -s "$WORK/tail.bin" <(tail -c 100 "$WORK/earth.pmtiles") || fail "suffix range bytes differ"
expect_status 416 -r "$((size + 10))-$((size + 20))" "$BASE/earth.pmtiles"
curl -sf "$BASE/earth.pmtiles" -o "$WORK/whole.pmtiles"
cmp -s "$WORK/whole.pmtiles" "$WORK/earth.pmtiles" || fail "whole archive differs"

note "CORS preflight"
curl -s -X OPTIONS -D "$WORK/pre.txt" -o /dev/null -H 'Origin: https://viewer.example' \
  -H 'Access-Control-Request-Method: GET' "$BASE/earth/$z/$x/$y"
head -1 "$WORK/pre.txt" | grep -qE ' 20[04] ' || fail "preflight: $(head -1 "$WORK/pre.txt")"
grep -qi '^access-control-allow-origin: \*' "$WORK/pre.txt" || fail "preflight: no allow-origin"
grep -qi '^access-control-allow-methods: .*GET' "$WORK/pre.txt" || fail "preflight: no methods"

note "errors"
expect_status 404 "$BASE/nosuch/0/0/0"
expect_status 404 "$BASE/earth/30/0/0"
expect_status 400 "$BASE/earth/a/b/c"
expect_status 405 -X DELETE "$BASE/earth/0/0/0"
expect_status 414 "$BASE/earth/$(head -c 3000 /dev/zero | tr '\0' a)"
expect_status 431 -H "X-Big: $(head -c 10000 /dev/zero | tr '\0' a)" "$BASE/earth/0/0/0"
expect_status 413 -X GET --data-binary 'xxxx' "$BASE/earth/0/0/0"
exec 3<>"/dev/tcp/127.0.0.1/$PORT"
printf 'NOT HTTP AT ALL\r\n\r\n' >&3
timeout 5 cat <&3 >"$WORK/garbage.txt" || true
exec 3<&-
head -1 "$WORK/garbage.txt" | grep -q '^HTTP/1.1 400' || fail "garbage answered: $(head -1 "$WORK/garbage.txt")"

note "pipelining: three requests in one write, three responses in order"
mapfile -t three < <(head -3 "$WORK/earth.offsets")
exec 3<>"/dev/tcp/127.0.0.1/$PORT"
req=""
i=0
for line in "${three[@]}"; do
  read -r _ z x y _ _ <<<"$line"
  i=$((i + 1))
  conn=keep-alive
  ((i == 3)) && conn=close
  req+="GET /earth/$z/$x/$y HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: $conn\r\n\r\n"
done
printf '%b' "$req" >&3
timeout 5 cat <&3 >"$WORK/pipe.txt" || true
exec 3<&-
[[ $(grep -ao 'HTTP/1.1 200 OK' "$WORK/pipe.txt" | wc -l) == 3 ]] || fail "pipelined: not 3 responses"
want=$(for line in "${three[@]}"; do read -r _ _ _ _ _ len <<<"$line"; echo "$len"; done)
got=$(tr -d '\r' <"$WORK/pipe.txt" | sed -nE 's/^[Cc]ontent-[Ll]ength: ([0-9]+)$/\1/p')
[[ $want == "$got" ]] || fail "pipelined responses out of order: $got vs $want"

note "admin: /health and /metrics"
[[ $(curl -s "$ADMIN_BASE/health") == ok ]] || fail "/health is not ok"
curl -sf "$ADMIN_BASE/metrics" -o "$WORK/metrics.txt"
for m in 'vts_http_requests_total{route="tile",status="200"}' \
  'vts_http_requests_total{route="tile",status="304"}' \
  'vts_http_requests_total{route="archive",status="206"}' \
  'vts_http_request_duration_seconds_bucket{le="+Inf"}' vts_http_response_bytes_total \
  vts_http_open_connections 'vts_tilesets_loaded 2' 'vts_reloads_total{result="refused"} 0'; do
  grep -qF "$m" "$WORK/metrics.txt" || fail "/metrics lacks $m"
done
expect_status 404 "$ADMIN_BASE/earth/0/0/0"
expect_status 404 "$BASE/metrics"
expect_status 405 -X POST "$ADMIN_BASE/metrics"
curl -sf "$ADMIN_BASE/metrics" -o "$WORK/metrics2.txt"
grep -qE '^vts_http_requests_total\{route="admin",status="404"\} 1$' "$WORK/metrics2.txt" ||
  fail "admin answers are not counted under route=\"admin\""

note "a stale version is a 404 with Vts-Error: version-not-current; other 404s have no Vts-Error"
curl -s -D "$WORK/stale.txt" -o "$WORK/stale.body" "$BASE/earth@0123456789abcdef/0/0/0"
head -1 "$WORK/stale.txt" | grep -q '^HTTP/1.1 404' || fail "stale version: $(head -1 "$WORK/stale.txt")"
grep -qi '^vts-error: version-not-current' "$WORK/stale.txt" || fail "stale version lacks Vts-Error"
grep -q 'is not current' "$WORK/stale.body" || fail "stale version lacks its message"
curl -s -D "$WORK/missing.txt" -o /dev/null "$BASE/nosuch/0/0/0"
! grep -qi '^vts-error:' "$WORK/missing.txt" || fail "an unknown tileset's 404 carries Vts-Error"

note "access log"
grep -q '"target":"/earth.json"' "$WORK/access.log" || fail "access log lacks /earth.json"
json_check <(tail -1 "$WORK/access.log") 'j.status && j.method && j.route && j.duration_us >= 0' \
  "access log lines are JSON"

stop_server
note "ok"
