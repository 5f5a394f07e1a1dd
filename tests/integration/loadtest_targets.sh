#!/usr/bin/env bash
# vts loadtest and vts warm against third-party tile servers on loopback: nginx over a folder of
# PNG tiles made by the real gdal2tiles.py (an XYZ template, the same folder as TMS with {-y}, a
# third-party TileJSON pointing at it) and a stock raster PMTiles archive (vts export: no
# "vtstream" metadata, tile type png; and the same rewritten with uncompressed directories in
# leaves by pmtiles_uncompressed.py) served by nginx with Range; vts view shows the templates.
# Each run has requests and no errors; warm fetches exactly the tiles of zooms 0-3 that exist; --decode counts a corrupted PNG as
# "undecodable" (and without --decode it is not an error); a template that 404s counts http_404
# errors and never a checksum error; a template without --zoom is refused naming --zoom.
source "$(dirname "$0")/lib.sh"
source "$(dirname "$0")/serve_lib.sh"
source "$(dirname "$0")/deploy_lib.sh"
require_tool gdal2tiles.py
require_tool gdal_translate
require_tool sqlite3

note "PNG tiles of zooms 0-3 by gdal2tiles.py (XYZ and TMS folders) and a stock PMTiles archive"
WWW="$WORK/www"
mkdir -p "$WWW"
expect_ok gdal_translate -q -of GTiff -outsize 1024 512 -a_srs EPSG:4326 \
  -a_ullr -180 85 180 -85 "$EARTH" "$WORK/earth.tif"
expect_ok gdal2tiles.py -q -z 0-3 -w none --processes=1 --xyz "$WORK/earth.tif" "$WWW/xyz"
expect_ok gdal2tiles.py -q -z 0-3 -w none --processes=1 "$WORK/earth.tif" "$WWW/tms"
n=$(find "$WWW/xyz" -name '*.png' | wc -l)
[[ $n == 85 ]] || fail "gdal2tiles wrote $n PNG tiles, expected 85 (zooms 0-3 of the world)"
# The root tile, which every view asks for, replaced by bytes that are no PNG.
cp -r "$WWW/xyz" "$WWW/bad"
printf 'this is not a PNG' >"$WWW/bad/0/0/0.png"
build_earth "$WORK/earth.pmtiles" --quiet
expect_ok "$VTS" export "$WORK/earth.pmtiles" -o "$WWW/stock.pmtiles" --format png --quiet
# The same archive as another writer may lay it out: directories and metadata uncompressed
# (internal compression none), the tile entries in leaf directories of 8. Stock npm pmtiles reads
# the same 43 tiles from both.
expect_ok python3 "$(dirname "$0")/pmtiles_uncompressed.py" "$WWW/stock.pmtiles" \
  "$WWW/stock-raw.pmtiles" 8
for a in stock stock-raw; do
  expect_ok "$NODE" "$PMTILES_JS/read_export.mjs" "$WWW/$a.pmtiles" "$WORK/js-$a"
  cp "$OUT" "$WORK/js-$a.json"
done
json_check "$WORK/js-stock.json" 'j.internalCompression === 2 && j.tiles_read === 43' "gzip directories"
json_check "$WORK/js-stock-raw.json" 'j.internalCompression === 1 && j.tiles_read === 43' \
  "uncompressed directories"
diff -r "$WORK/js-stock" "$WORK/js-stock-raw" >/dev/null || fail "npm pmtiles reads other tiles"

nginx_prepare "$WORK/nginx"
cat >"$N/conf.d/tiles.conf" <<CONF
server {
  listen 127.0.0.1:$HTTP_PORT;
  root $WWW;
  access_log $N/logs/access.log;
  location /xyz/ { add_header Cache-Control "max-age=3600"; }
}
log_format protocol '\$server_protocol \$request_uri';
server {
  listen 127.0.0.1:$HTTPS_PORT ssl http2;
  ssl_certificate $N/tls/cert.pem;
  ssl_certificate_key $N/tls/key.pem;
  root $WWW;
  access_log $N/logs/tls.log protocol;
}
CONF
if ((EUID == 0)); then chmod -R a+rX "$WWW"; fi
start_nginx "$N"
S="http://127.0.0.1:$HTTP_PORT"
wait_http "$S/xyz/0/0/0.png"
cat >"$WWW/tilejson.json" <<JSON
{"tilejson": "2.2.0", "name": "earth", "scheme": "xyz", "minzoom": 0, "maxzoom": 3,
 "bounds": [-180, -85, 180, 85], "tiles": ["$S/xyz/{z}/{x}/{y}.png"]}
JSON
cat >"$WWW/tms.json" <<JSON
{"tilejson": "3.0.0", "scheme": "tms", "maxzoom": 3, "tiles": ["tms/{z}/{x}/{y}.png"]}
JSON
cat >"$WWW/vector.json" <<JSON
{"tilejson": "3.0.0", "tiles": ["$S/v/{z}/{x}/{y}.pbf"], "vector_layers": [{"id": "roads"}]}
JSON
if ((EUID == 0)); then chmod a+r "$WWW/tilejson.json" "$WWW/tms.json" "$WWW/vector.json"; fi
# Range requests work on this nginx (a PMTiles reader needs them).
[[ $(curl -s -o /dev/null -w '%{http_code}' -r 0-126 "$S/stock.pmtiles") == 206 ]] ||
  fail "nginx does not answer Range requests for $S/stock.pmtiles"

# loadtest_json NAME URL ARGS...: a 2 s load test, its JSON in $WORK/NAME.json.
loadtest_json() {
  local name=$1 url=$2
  shift 2
  # Errors are counted by kind below, not gated.
  expect_ok "$VTS" loadtest "$url" --viewers 2 --duration 2 --fps 10 --json --quiet \
    --max-error-rate 100% "$@"
  cp "$OUT" "$WORK/$name.json"
}

# NAME|URL|ARGS|TILES: the gdal2tiles folder has all 85 tiles of zooms 0-3; the exported plain
# 2048x1024 image covers the top half of the Web Mercator square: 1 + 2 + 8 + 32 = 43 tiles.
for target in "xyz|$S/xyz/{z}/{x}/{y}.png|--zoom 0-3|85" \
  "tms|$S/tms/{z}/{x}/{-y}.png|--zoom 0-3|85" "tilejson|$S/tilejson.json||85" \
  "tmsjson|$S/tms.json||85" \
  "pmtiles|$S/stock.pmtiles||43" "pmtiles-raw|$S/stock-raw.pmtiles||43"; do
  IFS='|' read -r name url extra tiles <<<"$target"
  note "loadtest $name: requests, bytes, no errors"
  # shellcheck disable=SC2086  # extra is a list of arguments
  loadtest_json "$name" "$url" $extra
  json_check "$WORK/$name.json" 'j.totals.requests > 0 && j.totals.errors === 0 && j.totals.bytes > 0' \
    "$name: requests > 0, bytes, 0 errors"
  json_check "$WORK/$name.json" 'j.latency_ns.first_visible.count > 0 &&
    j.latency_ns.full_resolution.count > 0 && j.latency_ns.total.count === j.totals.requests' \
    "$name: moves timed to first visible tile and full resolution"
  note "warm $name: exactly its $tiles tiles of zooms 0-3 from the network, the rest absent"
  # shellcheck disable=SC2086
  expect_ok "$VTS" warm "$url" --cache-dir "$WORK/cache-$name" --json --quiet $extra
  cp "$OUT" "$WORK/warm-$name.json"
  json_check "$WORK/warm-$name.json" \
    "j.tiles_total === 85 && j.from_network === $tiles && j.absent === 85 - $tiles &&
     j.failed === 0 && j.complete === true" "$name: warm fetched the $tiles tiles"
done
# Every cache holds the server's PNGs byte for byte at the same z/x/y: TMS rows ({-y}, a
# TileJSON with "scheme": "tms" and a relative template) were flipped right.
tiles_of() {
  sqlite3 "$WORK/cache-$1/cache.db" "SELECT z, x, y, hex(payload) FROM tiles ORDER BY z, x, y"
}
[[ $(tiles_of xyz | wc -l) == 85 && $(tiles_of xyz | cut -d'|' -f4 | cut -c1-8 | sort -u) == 89504E47 ]] ||
  fail "the warmed tiles are not the server's 85 PNGs"
for name in tms tilejson tmsjson; do
  [[ $(tiles_of xyz | md5sum) == $(tiles_of "$name" | md5sum) ]] ||
    fail "the $name cache holds other tiles than the xyz cache"
done
# Each tile keeps the lifetime its answer's Cache-Control gave: max-age=3600 under /xyz/, none
# under /tms/ (-1: the cache's own revalidation rule).
fresh_of() { sqlite3 "$WORK/cache-$1/cache.db" "SELECT DISTINCT fresh_for FROM tiles"; }
[[ $(fresh_of xyz) == 3600 && $(fresh_of tms) == -1 ]] ||
  fail "fresh_for: xyz $(fresh_of xyz), tms $(fresh_of tms); expected 3600 and -1"
[[ $(tiles_of pmtiles | wc -l) == 43 && $(tiles_of pmtiles | md5sum) == $(tiles_of pmtiles-raw | md5sum) ]] ||
  fail "the archive with uncompressed directories warms other tiles than the gzip one"

note "hosts: {s}, {a-c} and a TileJSON's three templates spread requests by (x + y) % 3"
mkdir -p "$WWW/sub"
for h in a b c; do ln -s ../xyz "$WWW/sub/$h"; done
cat >"$WWW/mirrors.json" <<JSON
{"tilejson": "3.0.0", "maxzoom": 3,
 "tiles": ["sub/a/{z}/{x}/{y}.png", "sub/b/{z}/{x}/{y}.png", "$S/sub/c/{z}/{x}/{y}.png"]}
JSON
if ((EUID == 0)); then chmod a+r "$WWW/mirrors.json"; fi
for target in "s|$S/sub/{s}/{z}/{x}/{y}.png|--zoom 0-3" \
  "range|$S/sub/{a-c}/{z}/{x}/{y}.png|--zoom 0-3" "mirrors|$S/mirrors.json|"; do
  IFS='|' read -r name url extra <<<"$target"
  : >"$N/logs/access.log"
  # shellcheck disable=SC2086
  expect_ok "$VTS" warm "$url" --cache-dir "$WORK/cache-$name" --json --quiet $extra
  [[ $(tiles_of xyz | md5sum) == $(tiles_of "$name" | md5sum) ]] ||
    fail "the $name cache holds other tiles than the xyz cache"
  python3 - "$N/logs/access.log" "$name" <<'EOF_PY' || fail "$name: requests not spread as web maps do"
import re, sys
hosts = {}
for line in open(sys.argv[1]):
    m = re.search(r'"GET /sub/([abc])/(\d+)/(\d+)/(\d+)\.png HTTP', line)
    if not m:
        continue
    h, z, x, y = m.group(1), *map(int, m.groups()[1:])
    if h != "abc"[(x + y) % 3]:
        sys.exit(f"{sys.argv[2]}: tile {z}/{x}/{y} asked of host {h}")
    hosts[h] = hosts.get(h, 0) + 1
if sum(hosts.values()) != 85 or len(hosts) != 3:
    sys.exit(f"{sys.argv[2]}: requests per host {hosts}, expected 85 over a, b and c")
print(f"{sys.argv[2]}: {hosts}")
EOF_PY
done

note "a template's query (credentials) is sent but not saved in the cache"
expect_ok "$VTS" warm "$S/xyz/{z}/{x}/{y}.png?token=s3cret" --zoom 0-3 --cache-dir "$WORK/cache-query" \
  --json --quiet
[[ $(tiles_of xyz | md5sum) == $(tiles_of query | md5sum) ]] || fail "the query cache differs"
grep -q 'token=s3cret' "$N/logs/access.log" || fail "the query was not sent"
! grep -rqa 's3cret' "$WORK/cache-query" || fail "the query's credentials were saved in the cache"

note "https with HTTP/2: --cacert trusts the server's private certificate; without it, kind tls"
TLS="https://127.0.0.1:$HTTPS_PORT/xyz/{z}/{x}/{y}.png"
: >"$N/logs/tls.log"
loadtest_json https "$TLS" --zoom 0-3 --cacert "$N/tls/cert.pem"
json_check "$WORK/https.json" 'j.totals.requests > 0 && j.totals.errors === 0' "https load test"
expect_ok "$VTS" warm "$TLS" --zoom 0-3 --cacert "$N/tls/cert.pem" --cache-dir "$WORK/cache-https" \
  --json --quiet
[[ $(tiles_of xyz | md5sum) == $(tiles_of https | md5sum) ]] ||
  fail "the https cache holds other tiles than the xyz cache"
[[ $(grep -c . "$N/logs/tls.log") -gt 85 && -z $(grep -v '^HTTP/2.0 ' "$N/logs/tls.log") ]] ||
  fail "not every request came over HTTP/2: $(sort "$N/logs/tls.log" | cut -d' ' -f1 | uniq -c)"
loadtest_json untrusted "$TLS" --zoom 0-3
json_check "$WORK/untrusted.json" 'j.totals.errors > 0 && j.errors_by_kind.tls === j.totals.errors' \
  "an untrusted certificate: every error is of kind tls"
run "$VTS" loadtest "$TLS" --zoom 0-3 --cacert "$WORK/no-such.pem" --duration 1
((RC == 2)) && grep -q 'no-such.pem' "$ERR" || { show_output; fail "a missing --cacert is not named"; }

note "the viewers' disk caches take image tiles"
loadtest_json disk "$S/xyz/{z}/{x}/{y}.png" --zoom 0-3 --cache disk --cache-dir "$WORK/lt-caches"
json_check "$WORK/disk.json" 'j.totals.requests > 0 && j.totals.errors === 0' "--cache disk"

note "--decode: the corrupted root PNG is an undecodable error; without --decode it is not"
loadtest_json nodecode "$S/bad/{z}/{x}/{y}.png" --zoom 0-3
json_check "$WORK/nodecode.json" 'j.totals.errors === 0' "no decode, no error"
loadtest_json decode "$S/bad/{z}/{x}/{y}.png" --zoom 0-3 --decode
json_check "$WORK/decode.json" \
  'j.errors_by_kind.undecodable > 0 && j.totals.errors === j.errors_by_kind.undecodable' \
  "--decode counts the corrupted PNG as undecodable, and only it"
loadtest_json decode_ok "$S/xyz/{z}/{x}/{y}.png" --zoom 0-3 --decode
json_check "$WORK/decode_ok.json" 'j.totals.requests > 0 && j.totals.errors === 0' "valid PNGs decode"

note "a template that 404s: http_404 errors, no checksum errors"
loadtest_json missing "$S/nope/{z}/{x}/{y}.png" --zoom 0-3
json_check "$WORK/missing.json" \
  'j.totals.errors > 0 && j.errors_by_kind.http_404 === j.totals.errors && !("checksum" in j.errors_by_kind)' \
  "every error is http_404"

note "nothing listening: every error is of kind connect"
dead=$(free_port)
loadtest_json dead "http://127.0.0.1:$dead/{z}/{x}/{y}.png" --zoom 0-3
json_check "$WORK/dead.json" 'j.totals.errors > 0 && j.errors_by_kind.connect === j.totals.errors' \
  "connection refused counts as connect"

note "bodies shorter than their Content-Length: every error is of kind truncated"
timeout 120 python3 - "$WORK/short.port" >"$LOGS/short.out" 2>&1 <<'EOF_PY' &
import http.server, sys
class H(http.server.BaseHTTPRequestHandler):
    def do_GET(self):
        self.send_response(200)
        self.send_header("Content-Length", "1000")
        self.send_header("Connection", "close")
        self.end_headers()
        self.wfile.write(b"\x89PNG short")
        self.close_connection = True
    def log_message(self, *a):
        pass
s = http.server.ThreadingHTTPServer(("127.0.0.1", 0), H)
open(sys.argv[1] + ".tmp", "w").write(str(s.server_address[1]))
__import__("os").rename(sys.argv[1] + ".tmp", sys.argv[1])
s.serve_forever()
EOF_PY
SHORT_PID=$!
for ((i = 0; i < 100; i++)); do [[ -s $WORK/short.port ]] && break; sleep 0.05; done
[[ -s $WORK/short.port ]] || fail "the short-body server did not start: $(cat "$LOGS/short.out")"
loadtest_json short "http://127.0.0.1:$(cat "$WORK/short.port")/{z}/{x}/{y}.png" --zoom 0-3
kill "$SHORT_PID" 2>/dev/null || true
json_check "$WORK/short.json" \
  'j.totals.errors > 0 && j.errors_by_kind.truncated === j.totals.errors' "short bodies: truncated"

note "--bounds limits requests to the tiles over the box"
expect_ok "$VTS" warm "$S/xyz/{z}/{x}/{y}.png" --zoom 0-3 --bounds 0,0,90,60 \
  --cache-dir "$WORK/cache-bounds" --json --quiet
cp "$OUT" "$WORK/warm-bounds.json"
# z0: 1, z1: 1 (x 1, y 0), z2: 1 (x 2, y 1), z3: x 4-5, y 2-3 = 4 tiles.
json_check "$WORK/warm-bounds.json" \
  'j.from_network === 7 && j.absent === j.tiles_total - 7 && j.failed === 0' "7 tiles over the box"

note "a template without --zoom, a bad --zoom or --bounds: refused, naming the option"
expect_clean_failure "$VTS" loadtest "$S/xyz/{z}/{x}/{y}.png" --duration 1
grep -q -- '--zoom' "$ERR" || fail "the refusal does not name --zoom: $(cat "$ERR")"
for bad in "--zoom 3-1" "--zoom x" "--zoom 0-25" "--zoom 0-3 --bounds 1,2,3" \
  "--zoom 0-3 --bounds 10,0,5,10"; do
  # shellcheck disable=SC2086  # bad is flags and their values
  expect_clean_failure "$VTS" warm "$S/xyz/{z}/{x}/{y}.png" $bad --cache-dir "$WORK/c-bad"
  [[ $bad == *bounds* ]] && word=bounds || word=zoom
  grep -q -- "$word" "$ERR" || fail "'$bad' refused without naming $word: $(cat "$ERR")"
  [[ ! -e $WORK/c-bad ]] || fail "'$bad' was refused but made a cache folder"
done
note "vts view --headless of the XYZ and the TMS template: complete, no errors, the same picture"
XVFB=(xvfb-run -a -s "-screen 0 1280x1024x24")
require_tool xvfb-run
for name in xyz tms; do
  url="$S/$name/{z}/{x}/{y}.png"
  [[ $name == tms ]] && url="$S/tms/{z}/{x}/{-y}.png"
  expect_ok "${XVFB[@]}" "$VTS" view "$url" --zoom 0-3 --headless --frames 200 --until-complete \
    --screenshot "$WORK/view-$name.png" --json --width 320 --height 200
  cp "$OUT" "$WORK/view-$name.json"
  json_check "$WORK/view-$name.json" 'j.complete_at !== null && j.frames.at(-1).errors === 0 &&
    j.frames.at(-1).resident > 0' "$name: the view completes with resident tiles, no errors"
done
cmp -s "$WORK/view-xyz.png" "$WORK/view-tms.png" || fail "the XYZ and TMS views differ"
# Not one flat colour: the decoded Earth shows (its channels' min and max differ).
python3 - "$WORK/view-xyz.png" <<'EOF_PY' || fail "the view of the XYZ template is one flat colour"
import sys, zlib, struct
data = open(sys.argv[1], "rb").read()
idat = b"".join(data[i + 8:i + 8 + struct.unpack(">I", data[i:i + 4])[0]]
                for i in range(8, len(data)) if data[i + 4:i + 8] == b"IDAT")
sys.exit(0 if len(set(zlib.decompress(idat))) > 16 else 1)
EOF_PY
note "a TileJSON of vector tiles is refused, saying so"
expect_clean_failure "$VTS" loadtest "$S/vector.json" --duration 1
grep -q "vector tiles" "$ERR" || fail "the refusal does not say why: $(cat "$ERR")"

note "vts cache serve refuses a server of image tiles, saying so"
expect_clean_failure "$VTS" cache serve --upstream "$S/tilejson.json" --cache-dir "$WORK/daemon" \
  --listen 127.0.0.1:0
grep -q "standard image tiles" "$ERR" || fail "the refusal does not say why: $(cat "$ERR")"

note "nginx gone: vts warm of the TileJSON checks its cache offline, every tile still there"
kill -QUIT "$NGINX_PID"
wait "$NGINX_PID" 2>/dev/null || true
expect_ok "$VTS" warm "$S/tilejson.json" --cache-dir "$WORK/cache-tilejson" --json --quiet
cp "$OUT" "$WORK/warm-offline.json"
json_check "$WORK/warm-offline.json" \
  'j.already_cached === 85 && j.from_network === 0 && j.complete === true' "offline: 85 cached"
note "ok"
