#!/usr/bin/env bash
# deploy/nginx/vts-front.conf.template, as checked in, as the cache front of two `vts serve`
# replicas on loopback (plain HTTP and TLS + HTTP/2 listeners, a self-signed certificate):
#   1. tiles, TileJSON and archive ranges are byte-exact through the front; ETag and
#      Cache-Control pass through; HTTP/2 over TLS works;
#   2. a repeated tile is a cache HIT (X-Cache-Status), web images (.png) too; "version not
#      current" 404s are not cached; the index varies by Accept (HTML or JSON) through the cache;
#   3. a rebuilt archive is rolled out (renamed into place on both replicas, which hot-reload):
#      the new TileJSON's versioned URLs give the new bytes; an old versioned URL gives the old
#      bytes where a cache holds them and 404 "not current" elsewhere; no response ever carries a
#      tile of one version under a URL of another, even while the replicas disagree;
#   4. one replica SIGKILLed in the middle of a few thousand parallel cold-cache requests: every
#      request succeeds, byte-exact.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
# shellcheck source=serve_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/serve_lib.sh"
# shellcheck source=deploy_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/deploy_lib.sh"
require_tool "$NODE"
require_tool "$OIIOTOOL"
t_start=$(date +%s%N)

note "archives: earth v1, earth v2 (the image flipped: same pyramid, other pixels), a larger synthetic one"
build_earth "$WORK/earth_v1.pmtiles"
"$OIIOTOOL" "$EARTH" --flip -o "$WORK/earth_flipped.png" || fail "oiiotool --flip failed"
expect_ok "$VTS" build "$WORK/earth_flipped.png" -o "$WORK/earth_v2.pmtiles"
expect_ok "$VTS" build --synthetic 16384x8192 -o "$WORK/synth.pmtiles"
for r in 1 2; do
  mkdir -p "$WORK/replica$r"
  cp "$WORK/earth_v1.pmtiles" "$WORK/replica$r/earth.pmtiles"
  cp "$WORK/synth.pmtiles" "$WORK/replica$r/synth.pmtiles"
done
# Each replica has its own copy (as on separate hosts) and notices a replaced file within 200 ms.
echo '{"reload_interval_ms": 200, "threads": 1}' >"$WORK/serve.json"
start_replica 1 "$WORK/replica1" --config "$WORK/serve.json"
start_replica 2 "$WORK/replica2" --config "$WORK/serve.json"
R1="http://127.0.0.1:${REPLICA_PORTS[1]}"
R2="http://127.0.0.1:${REPLICA_PORTS[2]}"

note "nginx front from deploy/nginx (replicas :${REPLICA_PORTS[1]} and :${REPLICA_PORTS[2]})"
nginx_prepare "$WORK/nginx"
export VTS_CACHE_DIR="$N/cache" VTS_CACHE_SIZE=1g VTS_SERVER_NAME=localhost \
  VTS_FRONT_HTTP_LISTEN="127.0.0.1:$HTTP_PORT" VTS_FRONT_HTTPS_LISTEN="127.0.0.1:$HTTPS_PORT" \
  VTS_TLS_CERT="$N/tls/cert.pem" VTS_TLS_KEY="$N/tls/key.pem"
render "$DEPLOY/nginx/vts-front.conf.template" "$N/conf.d/vts-front.conf" VTS_CACHE_DIR \
  VTS_CACHE_SIZE VTS_SERVER_NAME VTS_FRONT_HTTP_LISTEN VTS_FRONT_HTTPS_LISTEN VTS_TLS_CERT VTS_TLS_KEY
: >"$N/conf.d/vts-replicas.inc"
for r in 1 2; do
  VTS_REPLICA="127.0.0.1:${REPLICA_PORTS[r]}" render "$DEPLOY/nginx/vts-replicas.inc.template" \
    "$N/replica$r.inc" VTS_REPLICA
  cat "$N/replica$r.inc" >>"$N/conf.d/vts-replicas.inc"
done
start_nginx "$N"
F="http://127.0.0.1:$HTTP_PORT"
wait_http "$F/.front-health"

# ---- 1. byte-exact through the front ------------------------------------------------------------
note "every earth tile through the front equals the replica's, headers pass through"
"$PMTILES_DUMP" offsets "$WORK/earth_v1.pmtiles" >"$WORK/earth.offsets" || fail "pmtiles_dump offsets"
mapfile -t EARTH_TILES < <(awk '{ print $2 "/" $3 "/" $4 }' "$WORK/earth.offsets")
((${#EARTH_TILES[@]} == 43)) || fail "expected 43 earth tiles, found ${#EARTH_TILES[@]}"
mkdir -p "$WORK/direct" "$WORK/front"
fetch_all() { # BASE PREFIX DIR: every earth tile, BASE/PREFIX/z/x/y into DIR/z_x_y
  local t cfg="$LOGS/fetch.cfg"
  : >"$cfg"
  for t in "${EARTH_TILES[@]}"; do
    printf 'url = "%s/%s/%s"\noutput = "%s/%s"\n' "$1" "$2" "$t" "$3" "${t//\//_}" >>"$cfg"
  done
  curl -s --parallel --parallel-max 8 -K "$cfg" -w '%{http_code}\n' >"$LOGS/fetch.codes" 2>"$LOGS/fetch.err" ||
    fail "curl failed fetching $1/$2"
  grep -vc '^200$' "$LOGS/fetch.codes" >/dev/null &&
    fail "$1/$2: $(grep -vc '^200$' "$LOGS/fetch.codes") non-200 answers: $(sort "$LOGS/fetch.codes" | uniq -c | tr '\n' ' ')"
  return 0
}
fetch_all "$R1" earth "$WORK/direct"
fetch_all "$F" earth "$WORK/front"
diff -rq "$WORK/direct" "$WORK/front" || fail "tiles through the front differ from the replica's"
cmp -s <(curl -sf "$R1/earth.json" | sed "s|127.0.0.1:${REPLICA_PORTS[1]}|FRONT|g") \
  <(curl -sf "$F/earth.json" | sed "s|127.0.0.1:$HTTP_PORT|FRONT|g") ||
  fail "TileJSON through the front differs from the replica's (other than the host)"
[[ $(header_of ETag "$F/earth/2/1/1") == "$(header_of ETag "$R2/earth/2/1/1")" ]] ||
  fail "ETag differs through the front"
[[ $(header_of Cache-Control "$F/earth/2/1/1") == "public, max-age=3600" ]] ||
  fail "Cache-Control through the front: $(header_of Cache-Control "$F/earth/2/1/1")"
# The archive for range readers: passed through, not cached.
cmp -s <(curl -sf -r 0-126 "$F/earth.pmtiles") <(archive_bytes "$WORK/earth_v1.pmtiles" 0 127) ||
  fail "archive range through the front differs"
expect_status 206 -r 1000-1999 "$F/earth.pmtiles"
[[ -z $(header_of X-Cache-Status -r 0-9 "$F/earth.pmtiles") ]] || fail "the archive went through the cache"
expect_status 304 -H "If-None-Match: $(header_of ETag "$R1/earth/1/0/0")" "$F/earth/1/0/0"

note "TLS + HTTP/2 listener"
h2=$(curl -s --cacert "$N/tls/cert.pem" --http2 -o "$WORK/h2.bin" -w '%{http_code} %{http_version}' \
  "https://127.0.0.1:$HTTPS_PORT/earth/3/5/2")
[[ $h2 == "200 2" ]] || fail "https with HTTP/2 answered '$h2', expected '200 2'"
cmp -s "$WORK/h2.bin" "$WORK/direct/3_5_2" || fail "tile over HTTP/2 differs"

# ---- 2. cache HITs -------------------------------------------------------------------------------
note "repeat requests are cache HITs; 'not current' 404s are never cached"
[[ $(header_of X-Cache-Status "$F/earth/3/5/2") == HIT ]] || fail "repeated tile is not a HIT"
V1=$(tilejson_version "$F/earth.json")
[[ -n $V1 ]] || fail "no version in the front's TileJSON"
template=$(curl -sf "$F/earth.json" | json_get /dev/stdin 'j.tiles[0]')
[[ $template == "$F/earth@$V1/{z}/{x}/{y}" ]] || fail "TileJSON tiles through the front: $template"
url_of() { # TEMPLATE z/x/y
  local z x y
  IFS=/ read -r z x y <<<"$2"
  local u=${1/\{z\}/$z}
  u=${u/\{x\}/$x}
  echo "${u/\{y\}/$y}"
}
u=$(url_of "$template" 2/1/1)
[[ $(header_of X-Cache-Status "$u") == MISS ]] || fail "first versioned request is not a MISS"
[[ $(header_of X-Cache-Status "$u") == HIT ]] || fail "second versioned request is not a HIT"
[[ $(header_of Cache-Control "$u") == "public, max-age=31536000, immutable" ]] ||
  fail "versioned tile is not immutable through the front"
# Web images and the web TileJSON go through the same cache: a versioned PNG is immutable and a
# HIT the second time; the index answers HTML to a browser and JSON otherwise, through one cache.
web=$(curl -sf "$F/earth.json?format=png" | json_get /dev/stdin 'j.tiles[0]')
[[ $web == "$F/earth@$V1/{z}/{x}/{y}.png" ]] || fail "web TileJSON tiles through the front: $web"
u=$(url_of "$web" 2/1/1)
[[ $(header_of X-Cache-Status "$u") == MISS ]] || fail "first web image request is not a MISS"
[[ $(header_of X-Cache-Status "$u") == HIT ]] || fail "second web image request is not a HIT"
[[ $(header_of Content-Type "$u") == image/png ]] || fail "web image through the front is not a PNG"
[[ $(header_of Cache-Control "$u") == "public, max-age=31536000, immutable" ]] ||
  fail "versioned web image is not immutable through the front"
for i in 1 2; do
  [[ $(header_of Content-Type -H 'Accept: text/html' "$F/") == text/html* ]] ||
    fail "a browser got no HTML index through the front (try $i)"
  [[ $(header_of Content-Type "$F/") == application/json* ]] ||
    fail "a client got no JSON index through the front (try $i)"
done
bogus="$F/earth@0123456789abcdef/0/0/0"
for i in 1 2; do
  expect_status 404 "$bogus"
  [[ $(header_of X-Cache-Status "$bogus") == MISS ]] || fail "'not current' 404 was cached (try $i)"
done

# ---- 3. rollout of a rebuilt archive -------------------------------------------------------------
note "rollout: earth v2 renamed into place on both replicas, with a prober racing it"
# Old versioned URLs of levels 0-2 are put in the front's cache before the rollout; those of
# level 3 are not.
mkdir -p "$WORK/v1"
for t in "${EARTH_TILES[@]}"; do
  u=$(url_of "$template" "$t")
  [[ $t == 3/* ]] && u="$R1/earth@$V1/$t" # the reference bytes, not through the front
  curl -sf -o "$WORK/v1/${t//\//_}" "$u" || fail "v1 $t"
done
for t in "${EARTH_TILES[@]}"; do
  [[ $t == 3/* ]] && continue
  [[ $(header_of X-Cache-Status "$(url_of "$template" "$t")") == HIT ]] || fail "v1 $t not cached"
done
# The prober: TileJSON through the front, then two of the tiles it names, as fast as it can,
# keeping every answer (version, tile, status, body) for the check below.
mkdir -p "$WORK/probe"
: >"$WORK/probe/done"
rm -f "$WORK/probe/done"
(
  for ((k = 0; k < 400; k++)); do
    [[ -e $WORK/probe/done ]] && break
    tj=$(curl -s --max-time 5 "$F/earth.json") || continue
    v=$(sed -nE 's/.*"version" *: *"([0-9a-f]+)".*/\1/p' <<<"$tj")
    [[ -n $v ]] || continue
    for t in 2/1/1 3/6/3; do
      z=${t%%/*}
      rest=${t#*/}
      code=$(curl -s --max-time 5 -o "$WORK/probe/$k.$v.${t//\//_}" -w '%{http_code}' \
        "$F/earth@$v/$z/$rest") || code=000
      echo "$k $v ${t//\//_} $code" >>"$WORK/probe/log"
    done
  done
) &
prober=$!
# probes_of VERSION: how many answers the prober has logged for VERSION.
probes_of() { grep -c " $1 " "$WORK/probe/log" 2>/dev/null || true; }
# The prober is under way (two rounds of the old version) before the rollout starts ...
for ((i = 0; i < 400; i++)); do
  (($(probes_of "$V1") >= 4)) && break
  kill -0 "$prober" 2>/dev/null || break
  sleep 0.05
done
(($(probes_of "$V1") >= 4)) || fail "the prober logged no answers before the rollout"
for r in 1 2; do
  cp "$WORK/earth_v2.pmtiles" "$WORK/replica$r/.earth.pmtiles.tmp"
  mv "$WORK/replica$r/.earth.pmtiles.tmp" "$WORK/replica$r/earth.pmtiles"
  [[ $r == 2 ]] || sleep 0.3 # the replicas disagree for a moment, as in a rolling update
done
rolled=$(date +%s%N)
for ((i = 0; i < 100; i++)); do
  a=$(tilejson_version "$R1/earth.json")
  b=$(tilejson_version "$R2/earth.json")
  [[ -n $a && $a != "$V1" && $a == "$b" ]] && break
  sleep 0.1
done
V2=$a
[[ -n $V2 && $V2 != "$V1" && $V2 == "$b" ]] || fail "replicas did not both reload (versions '$a' '$b')"
for ((i = 0; i < 100; i++)); do
  [[ $(tilejson_version "$F/earth.json") == "$V2" ]] && break
  sleep 0.1
done
[[ $(tilejson_version "$F/earth.json") == "$V2" ]] || fail "the front still hands out version $V1"
rollout_ms=$((($(date +%s%N) - rolled) / 1000000))
# ... and runs until it has seen two rounds of the new one.
for ((i = 0; i < 400; i++)); do
  (($(probes_of "$V2") >= 4)) && break
  kill -0 "$prober" 2>/dev/null || break
  sleep 0.05
done
touch "$WORK/probe/done"
timeout 20 tail --pid="$prober" -f /dev/null || fail "the prober did not stop"
wait "$prober" || true
note "version $V1 -> $V2: the front's TileJSON names it $rollout_ms ms after the last rename"

note "the new TileJSON's versioned URLs give the new bytes, through the front"
template2=$(curl -sf "$F/earth.json" | json_get /dev/stdin 'j.tiles[0]')
[[ $template2 == "$F/earth@$V2/{z}/{x}/{y}" ]] || fail "new TileJSON tiles: $template2"
mkdir -p "$WORK/v2direct" "$WORK/v2front"
fetch_all "$R2" "earth@$V2" "$WORK/v2direct"
fetch_all "$F" "earth@$V2" "$WORK/v2front"
diff -rq "$WORK/v2direct" "$WORK/v2front" || fail "v2 tiles through the front differ from the replica's"
changed=0
for t in "${EARTH_TILES[@]}"; do
  cmp -s "$WORK/v1/${t//\//_}" "$WORK/v2front/${t//\//_}" || changed=$((changed + 1))
done
((changed >= 40)) || fail "only $changed of 43 tiles changed between v1 and v2"

note "old versioned URLs: the old bytes where cached, else 404 not current; never new bytes"
old_hits=0 old_404=0
for t in "${EARTH_TILES[@]}"; do
  u=$(url_of "$template" "$t")
  code=$(curl -s -o "$WORK/old.bin" -w '%{http_code}' "$u")
  case $code in
    200)
      cmp -s "$WORK/old.bin" "$WORK/v1/${t//\//_}" || fail "$u: 200 with other bytes than v1's"
      # 3/6/3 is the prober's: it may have cached it under the old version before the rollout.
      [[ $t != 3/* || $t == 3/6/3 ]] ||
        fail "$u: an uncached old version was served (the origin says not current)"
      old_hits=$((old_hits + 1))
      ;;
    404)
      [[ $t == 3/* ]] || fail "$u: a cached immutable tile was dropped"
      [[ $(header_of Cache-Control "$u") == no-store ]] || fail "$u: 404 not no-store"
      old_404=$((old_404 + 1))
      ;;
    *) fail "$u answered $code" ;;
  esac
done
curl -s "$(url_of "$template" 3/0/0)" | grep -q 'not current' || fail "no 'not current' message"
note "old URLs: $old_hits cached (v1 bytes), $old_404 404 not current"

note "the prober saw no tile of one version under another's URL"
probes=0 probe_200=0
while read -r k v t code; do
  probes=$((probes + 1))
  f="$WORK/probe/$k.$v.$t"
  case $code in
    200)
      if [[ $v == "$V1" ]]; then ref="$WORK/v1/$t"; elif [[ $v == "$V2" ]]; then ref="$WORK/v2direct/$t"; else fail "probe: unknown version $v"; fi
      cmp -s "$f" "$ref" || fail "probe $k: $t under version $v has other bytes"
      probe_200=$((probe_200 + 1))
      ;;
    404) ;; # a replica not yet reloaded (or already reloaded) says "not current"
    *) fail "probe $k: $t under $v answered $code" ;;
  esac
done <"$WORK/probe/log"
((probes > 10)) || fail "the prober made only $probes requests"
note "$probes probes during the rollout, $probe_200 x 200 (right bytes), $((probes - probe_200)) x 404"

note "unversioned URLs stay as cached until max-age: why clients use the versioned ones"
[[ $(header_of X-Cache-Status "$F/earth/3/5/2") == HIT ]] || fail "unversioned tile not a HIT"
cmp -s <(curl -s "$F/earth/3/5/2") "$WORK/v1/3_5_2" || fail "expected the cached v1 bytes"

# ---- 4. a replica killed under load ------------------------------------------------------------
note "one replica SIGKILLed during a few thousand parallel cold-cache requests"
"$PMTILES_DUMP" offsets "$WORK/synth.pmtiles" >"$WORK/synth.offsets" || fail "pmtiles_dump offsets"
mapfile -t SYNTH < <(awk '{ print $2 "/" $3 "/" $4 }' "$WORK/synth.offsets")
nsynth=${#SYNTH[@]}
((nsynth > 2000)) || fail "synthetic archive has only $nsynth tiles"
mkdir -p "$WORK/synth_direct" "$WORK/synth_front"
: >"$LOGS/direct.cfg"
: >"$LOGS/front.cfg"
for t in "${SYNTH[@]}"; do
  printf 'url = "%s/synth/%s"\noutput = "%s/%s"\n' "$R1" "$t" "$WORK/synth_direct" "${t//\//_}" >>"$LOGS/direct.cfg"
  printf 'url = "%s/synth/%s"\noutput = "%s/%s"\n' "$F" "$t" "$WORK/synth_front" "${t//\//_}" >>"$LOGS/front.cfg"
done
curl -s --parallel --parallel-max 16 -K "$LOGS/direct.cfg" -w '%{http_code}\n' >"$LOGS/direct.codes" 2>"$LOGS/direct.err" ||
  fail "direct fetch failed"
[[ $(grep -c '^200$' "$LOGS/direct.codes") == "$nsynth" ]] || fail "direct fetch: not all 200"
load_start=$(date +%s%N)
: >"$LOGS/front.codes" # exists before the poll below reads it
timeout 120 curl -s --parallel --parallel-max 32 -K "$LOGS/front.cfg" \
  -w '%{http_code} %{exitcode} %{size_download}\n' >>"$LOGS/front.codes" 2>"$LOGS/front.err" &
load=$!
# Kill once the load is well under way (a third of the requests answered).
for ((i = 0; i < 400; i++)); do
  (($(wc -l <"$LOGS/front.codes") >= nsynth / 3)) && break
  kill -0 "$load" 2>/dev/null || break
  sleep 0.01
done
answered_at_kill=$(wc -l <"$LOGS/front.codes")
kill_replica 2
rc=0
wait "$load" || rc=$?
load_ms=$((($(date +%s%N) - load_start) / 1000000))
((rc == 0)) || fail "the load client exited $rc"
((answered_at_kill > 0 && answered_at_kill < nsynth)) ||
  fail "the replica was not killed mid-load ($answered_at_kill of $nsynth answered)"
total=$(wc -l <"$LOGS/front.codes")
bad=$(grep -vc '^200 0 ' "$LOGS/front.codes" || true)
((total == nsynth)) || fail "only $total of $nsynth requests answered"
((bad == 0)) || fail "$bad of $total requests failed: $(awk '{ print $1, $2 }' "$LOGS/front.codes" | sort | uniq -c | tr '\n' ' ')"
diff -rq "$WORK/synth_direct" "$WORK/synth_front" >"$LOGS/synth.diff" ||
  { head "$LOGS/synth.diff" >&2; fail "tiles through the front differ after the kill"; }
retried=$(grep -cE 'upstream prematurely closed|Connection refused|Connection reset|no live upstreams' \
  "$N/logs/error.log" || true)
((retried > 0)) || fail "nginx logged no upstream failure: was the replica serving?"
note "$total requests in $load_ms ms, replica 2 killed after $answered_at_kill: 0 failed, all byte-exact ($retried upstream errors retried by nginx)"
[[ $(header_of X-Cache-Status "$F/synth/${SYNTH[7]}") == HIT ]] || fail "no HIT after the kill"

note "PASS in $(elapsed_ms) ms"
