#!/usr/bin/env bash
# Web images of tiles from the real `vts serve` over loopback with curl (docs/PROTOCOL.md §13):
# PNG identical to `vts extract` for a lossless and a bc1 archive, WebP and JPEG within stated PSNR
# bounds, ETag / 304, transparency beyond the image's edge, 400 for a bad extension or format, the
# web TileJSON, one encoding for a burst of concurrent requests (single flight), and the RAM cache
# within its byte cap under parallel load (read back from /metrics).
source "$(dirname "$0")/lib.sh"
source "$(dirname "$0")/serve_lib.sh"
require_tool "$OIIOTOOL"
require_tool "$IDIFF"

# psnr IMAGE REFERENCE: the PSNR (dB) oiiotool reports between the RGB channels of two images.
psnr() {
  { "$OIIOTOOL" "$1" --ch R,G,B "$2" --ch R,G,B --diff 2>&1 || true; } |
    sed -nE 's/.*Peak SNR *[=:] *([0-9.inf]+).*/\1/p' | head -n1
}
# metric NAME: the value of an unlabelled counter or gauge on /metrics.
metric() { curl -sf "$ADMIN_BASE/metrics" | sed -nE "s/^$1 ([0-9.e+]+)\$/\1/p"; }
# header_of NAME URL [CURL ARGS...]: a response header's value.
header_of() {
  local name=$1 url=$2
  shift 2
  curl -s -D - -o /dev/null "$@" "$url" | tr -d '\r' | sed -nE "s/^$name: (.*)/\1/Ip"
}

build_earth "$WORK/earth.pmtiles"
build_earth "$WORK/bc1.pmtiles" --codec bc1

note "single flight: 24 concurrent requests for one image, one encoding, the others wait for it"
# 1024-texel tiles in lossless WebP at method 6 take most of a second to encode: the requests
# overlap it, on four I/O threads.
build_earth "$WORK/big.pmtiles" --tile 1024
echo '{"web": {"webp_lossless": true, "webp_method": 6}}' >"$WORK/slow.json"
start_server "$WORK/big.pmtiles" --config "$WORK/slow.json" --threads 4
: >"$WORK/burst.cfg"
for ((i = 0; i < 24; i++)); do
  printf 'url = "%s/big/1/0/0.webp"\noutput = "%s/burst_%d.webp"\n' "$BASE" "$WORK" "$i" \
    >>"$WORK/burst.cfg"
done
curl -sf --parallel --parallel-immediate --parallel-max 24 -K "$WORK/burst.cfg" 2>"$LOGS/curl.err" ||
  fail "a concurrent request for one web image failed"
[[ $(metric vts_web_encodes_total) == 1 ]] ||
  fail "24 concurrent requests encoded $(metric vts_web_encodes_total) times, expected once"
(($(metric vts_web_cache_waits_total) > 0)) || fail "no request waited for the encoding under way"
for ((i = 1; i < 24; i++)); do
  cmp -s "$WORK/burst_0.webp" "$WORK/burst_$i.webp" || fail "concurrent answers differ ($i)"
done
stop_server

echo '{"web": {"cache_mib": 1}}' >"$WORK/config.json"
start_server "$WORK/earth.pmtiles" "$WORK/bc1.pmtiles" --config "$WORK/config.json" \
  --access-log "$WORK/access.log"

for A in earth bc1; do
  note "$A: PNG == vts extract; WebP and JPEG within PSNR bounds"
  for t in 3/1/0 3/7/3 3/5/2 2/3/1; do
    IFS=/ read -r z x y <<<"$t"
    f="$WORK/${A}_${z}_${x}_${y}"
    expect_ok "$VTS" extract "$WORK/$A.pmtiles" "$t" -o "$f.ref.png"
    for ext in png webp jpg; do
      curl -sf "$BASE/$A/$t.$ext" -o "$f.$ext" || fail "GET /$A/$t.$ext failed"
    done
    expect_same_pixels "$f.ref.png" "$f.png"  # the PNG of an opaque tile may be RGB
    p=$(psnr "$f.webp" "$f.ref.png")
    awk -v p="$p" 'BEGIN { exit !(p == "inf" || p >= 32) }' || fail "$A $t WebP PSNR $p dB < 32"
    p=$(psnr "$f.jpg" "$f.ref.png")
    awk -v p="$p" 'BEGIN { exit !(p == "inf" || p >= 30) }' || fail "$A $t JPEG PSNR $p dB < 30"
  done
done

note "content types, ETag and Cache-Control; 304 on If-None-Match"
for ext in png:image/png webp:image/webp jpg:image/jpeg; do
  IFS=: read -r e type <<<"$ext"
  [[ $(header_of Content-Type "$BASE/earth/3/1/0.$e") == "$type" ]] || fail ".$e is not $type"
  etag=$(header_of ETag "$BASE/earth/3/1/0.$e")
  [[ $etag =~ ^\"[0-9a-f]{16}-[a-z0-9]+\"$ ]] || fail "ETag of .$e is '$etag'"
  expect_status 304 -H "If-None-Match: $etag" "$BASE/earth/3/1/0.$e"
done
[[ $(header_of ETag "$BASE/earth/3/1/0.png") != "$(header_of ETag "$BASE/earth/3/1/0.webp")" ]] ||
  fail "PNG and WebP share an ETag"
[[ $(header_of ETag "$BASE/earth/3/1/0.png") != "$(header_of ETag "$BASE/bc1/3/1/0.png")" ]] ||
  fail "the lossless and bc1 tiles share an ETag"
version=$(curl -sf "$BASE/earth.json" | sed -nE 's/.*"version": "([^"]+)".*/\1/p' | head -n1)
[[ $(header_of Cache-Control "$BASE/earth@$version/3/1/0.png") == *immutable* ]] ||
  fail "a versioned web tile is not immutable"
[[ $(header_of Cache-Control "$BASE/earth/3/1/0.png") != *immutable* ]] ||
  fail "an unversioned web tile is immutable"
expect_status 404 "$BASE/earth@0000000000000000/3/1/0.png"
[[ $(curl -s -I "$BASE/earth/3/1/0.png" -o /dev/null -w '%{http_code} %{size_download}') == "200 0" ]] ||
  fail "HEAD of a web tile"

note "beyond the image's edge: transparent texels; beyond the XYZ grid or the pyramid: 404"
# Level 0 is 256x128 in a 256x256 tile: the lower half is transparent.
curl -sf "$BASE/earth/0/0/0.png" -o "$WORK/edge.png"
[[ $(image_dims "$WORK/edge.png") == "256 256 4" ]] || fail "edge tile is $(image_dims "$WORK/edge.png")"
expect_ok "$VTS" extract "$WORK/earth.pmtiles" 0/0/0 -o "$WORK/edge.ref.png"
"$OIIOTOOL" "$WORK/edge.png" --cut 256x128+0+0 --origin +0+0 --fullpixels -o "$WORK/edge_top.png"
"$OIIOTOOL" "$WORK/edge.png" --cut 256x128+0+128 --origin +0+0 --fullpixels -o "$WORK/edge_low.png"
"$OIIOTOOL" --pattern constant:color=0,0,0,0 256x128 4 -d uint8 -o "$WORK/clear.png"
expect_same_pixels "$WORK/edge_top.png" "$WORK/edge.ref.png"
expect_same_pixels "$WORK/edge_low.png" "$WORK/clear.png"
# Level 3 is 8x4 tiles, its XYZ grid 8x8: rows 4..7 are wholly outside the image.
for ext in png webp; do
  curl -sf "$BASE/earth/3/2/6.$ext" -o "$WORK/outside.$ext" || fail "3/2/6.$ext is not a 200"
  "$OIIOTOOL" "$WORK/outside.$ext" --ch R,G,B,A -d uint8 -o "$WORK/outside_$ext.png"
  "$OIIOTOOL" --pattern constant:color=0,0,0,0 256x256 4 -d uint8 -o "$WORK/clear256.png"
  expect_same_pixels "$WORK/outside_$ext.png" "$WORK/clear256.png"
done
[[ $(header_of Content-Type "$BASE/earth/3/2/6.jpg") == image/png ]] ||
  fail "the empty tile of .jpg is not a (transparent) PNG"
expect_status 404 "$BASE/earth/3/8/0.png"
expect_status 404 "$BASE/earth/4/0/0.png"

note "bad extension or format: 400 naming the allowed ones"
curl -s "$BASE/earth/3/1/0.gif" -o "$WORK/bad.txt" -w '%{http_code}' >"$WORK/bad.status"
[[ $(cat "$WORK/bad.status") == 400 ]] && grep -q '.png, .webp or .jpg' "$WORK/bad.txt" ||
  fail "a .gif tile is not a 400 naming the extensions: $(cat "$WORK/bad.txt")"
curl -s "$BASE/earth.json?format=gif" -o "$WORK/bad.txt" -w '%{http_code}' >"$WORK/bad.status"
[[ $(cat "$WORK/bad.status") == 400 ]] && grep -q 'png, webp, jpg' "$WORK/bad.txt" ||
  fail "format=gif is not a 400 naming the formats: $(cat "$WORK/bad.txt")"
expect_status 400 "$BASE/earth.json?format=png&format=webp"
expect_status 400 "$BASE/earth.json?format=png&tiling=WebMercatorQuad"  # a plain image
expect_status 400 "$BASE/earth.json?format=png&tiling=Mars"

note "web TileJSON: the versioned template with the extension, tileSize, zooms, bounds, center"
curl -sf "$BASE/earth.json?format=webp" -o "$WORK/web.json"
json_check "$WORK/web.json" "j.tilejson === '3.0.0' && j.scheme === 'xyz' && j.tileSize === 256"
json_check "$WORK/web.json" "j.tiles[0] === '$BASE/earth@$version/{z}/{x}/{y}.webp'"
json_check "$WORK/web.json" "j.minzoom === 0 && j.maxzoom === 3 && j.center.length === 3"
json_check "$WORK/web.json" "j.bounds[0] === -180 && j.bounds[1] === 0 && j.bounds[2] === 180"
json_check "$WORK/web.json" "j.vtstream === undefined" "no vtstream object (the tiles are images)"

note "the cache stays within its 1 MiB cap under parallel load"
: >"$WORK/load.cfg"
for A in earth bc1; do
  for ((x = 0; x < 8; x++)); do
    for ((y = 0; y < 4; y++)); do
      for ext in png webp jpg; do
        printf 'url = "%s/%s/3/%d/%d.%s"\noutput = "/dev/null"\n' "$BASE" "$A" "$x" "$y" "$ext" \
          >>"$WORK/load.cfg"
      done
    done
  done
done
for round in 1 2; do
  curl -sf --parallel --parallel-max 16 -K "$WORK/load.cfg" 2>"$LOGS/curl.err" || fail "parallel load round $round"
done
bytes=$(metric vts_web_cache_bytes)
((bytes > 0 && bytes <= 1048576)) || fail "the web cache holds $bytes bytes (cap 1048576)"
(($(metric vts_web_cache_evictions_total) > 0)) || fail "no evictions under a 1 MiB cap"
curl -sf "$ADMIN_BASE/metrics" -o "$WORK/metrics.txt" || fail "no /metrics"
grep -q '^vts_web_tile_requests_total{format="jpg"} [1-9]' "$WORK/metrics.txt" ||
  fail "no jpg requests counted"
grep -q '/earth/3/1/0.png' "$WORK/access.log" || fail "web tiles are not in the access log"

stop_server

note "WebMercatorQuad from a WorldCRS84Quad archive: TileJSON and resampled tiles"
expect_ok "$VTS" build --synthetic 4096x2048 --tiling WorldCRS84Quad --bbox=-10.5,35.25,30.125,60.1 \
  -o "$WORK/geo.pmtiles" --threads 2
start_server "$WORK/geo.pmtiles" "$WORK/earth.pmtiles"
gv=$(curl -sf "$BASE/geo.json" | sed -nE 's/.*"version": "([^"]+)".*/\1/p' | head -n1)
curl -sf "$BASE/geo.json?format=png&tiling=WebMercatorQuad" -o "$WORK/wmq.json"
json_check "$WORK/wmq.json" "j.tiles[0] === '$BASE/geo@$gv/WebMercatorQuad/{z}/{x}/{y}.png'"
json_check "$WORK/wmq.json" "j.minzoom === 0 && j.tileSize === 256 && j.scheme === 'xyz'"
json_check "$WORK/wmq.json" "j.bounds[0] === -10.5 && j.bounds[3] === 60.1"
mz=$(json_get "$WORK/wmq.json" j.maxzoom)
# Paris lies inside the footprint: tile of (2.35 E, 48.85 N) at zoom mz.
read -r px py < <(awk -v z="$mz" 'BEGIN { pi = atan2(0, -1); n = 2 ^ z; lat = 48.85 * pi / 180;
  printf "%d %d\n", (2.35 + 180) / 360 * n, (1 - log(sin(lat) / cos(lat) + 1 / cos(lat)) / pi) / 2 * n }')
curl -sf "$BASE/geo@$gv/WebMercatorQuad/$mz/$px/$py.png" -o "$WORK/wmq.png" ||
  fail "no WebMercatorQuad tile $mz/$px/$py"
[[ $(image_dims "$WORK/wmq.png") == "256 256 "* ]] || fail "WebMercatorQuad tile is $(image_dims "$WORK/wmq.png")"
[[ $(header_of Cache-Control "$BASE/geo@$gv/WebMercatorQuad/$mz/$px/$py.png") == *immutable* ]] ||
  fail "a versioned WebMercatorQuad tile is not immutable"
etag=$(header_of ETag "$BASE/geo/WebMercatorQuad/$mz/$px/$py.webp")
expect_status 304 -H "If-None-Match: $etag" "$BASE/geo/WebMercatorQuad/$mz/$px/$py.webp"
# Zoom 1 tile 0/1 (south-west quarter) is outside the footprint: transparent.
curl -sf "$BASE/geo/WebMercatorQuad/1/0/1.png" -o "$WORK/wmq_out.png"
"$OIIOTOOL" "$WORK/wmq_out.png" --ch R,G,B,A -d uint8 -o "$WORK/wmq_out4.png"
expect_same_pixels "$WORK/wmq_out4.png" "$WORK/clear256.png"
expect_status 404 "$BASE/geo/WebMercatorQuad/$((mz + 1))/0/0.png"
expect_status 404 "$BASE/earth/WebMercatorQuad/0/0/0.png"  # a plain image
expect_status 400 "$BASE/geo/WebMercatorQuad/0/0/0"          # an image extension is required

note "vts cache serve: the same web images from its provider (the origin: vts serve)"
start_daemon cache "$VTS" cache serve --upstream "$BASE/earth.json" --cache-dir "$WORK/cache" \
  --listen 127.0.0.1:0 --no-admin
curl -sf "$BASE/earth/3/5/2.png" -o "$WORK/origin.png" || fail "origin PNG"
for n in 1 2; do  # a miss (fetched from the origin), then a hit
  curl -sf "$D/earth/3/5/2.png" -o "$WORK/daemon.png" || fail "daemon PNG ($n)"
  cmp -s "$WORK/origin.png" "$WORK/daemon.png" || fail "the daemon's PNG differs from vts serve's ($n)"
done
etag=$(header_of ETag "$D/earth/3/5/2.webp")
[[ $etag == "$(header_of ETag "$BASE/earth/3/5/2.webp")" ]] || fail "daemon ETag $etag differs"
expect_status 304 -H "If-None-Match: $etag" "$D/earth/3/5/2.webp"
[[ $(header_of Content-Type "$D/earth/3/5/2.jpg") == image/jpeg ]] || fail "daemon .jpg"
curl -sf "$D/earth/3/2/6.png" -o "$WORK/d_outside.png" || fail "daemon filler"
"$OIIOTOOL" "$WORK/d_outside.png" --ch R,G,B,A -d uint8 -o "$WORK/d_outside4.png"
expect_same_pixels "$WORK/d_outside4.png" "$WORK/clear256.png"
expect_status 400 "$D/earth/3/1/0.gif"
expect_status 404 "$D/earth/3/8/0.png"  # beyond the XYZ grid, as on vts serve
expect_status 404 "$D/earth/3/0/8.png"
expect_status 404 "$D/earth/4/0/0.png"
curl -sf "$D/earth.json?format=png" -o "$WORK/d_web.json" || fail "daemon web TileJSON"
json_check "$WORK/d_web.json" "j.tiles[0] === '$D/earth/{z}/{x}/{y}.png' && j.tileSize === 256"
kill -TERM "$DAEMON_PID"
wait "$DAEMON_PID" || true
stop_server

note "bad web config values are refused, naming the key"
for bad in '{"web": {"png_level": 10}}' '{"web": {"cache_mib": -1}}' '{"web": {"jpeg_quality": 0}}' \
  '{"web": {"webp_lossless": 1}}' '{"web": {"colour": 1}}'; do
  echo "$bad" >"$WORK/bad.json"
  expect_clean_failure "$VTS" serve "$WORK/earth.pmtiles" --config "$WORK/bad.json" \
    --listen 127.0.0.1:0 --no-admin
  grep -q 'web\.' "$ERR" || fail "the error for $bad does not name the key: $(cat "$ERR")"
done
