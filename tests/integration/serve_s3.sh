#!/usr/bin/env bash
# `vts serve` and the clients reading archives and sets from an object store (s3rver, npm, a real
# S3-protocol server on loopback; docs/PROTOCOL.md §14): `vts serve s3://bucket/prefix/` serves
# every archive and set under the prefix as `vts serve DIR` serves a folder, tile for tile the
# bytes of the local files; a warm tile costs exactly one ranged GET in s3rver's own log; a set
# replaced in the bucket (archives, then the manifest) is reloaded whole, never served as a mix;
# a stopped store gives 503 with Retry-After within the store's timeout, never a hang; wrong
# credentials and missing keys are clear errors at start-up naming the URL; `vts info`,
# `vts verify` and the client sources take s3:// locations.
# A && B || fail: fail unless both hold.
# shellcheck disable=SC2015
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
# shellcheck source=serve_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/serve_lib.sh"
# shellcheck source=deploy_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/deploy_lib.sh"
# shellcheck source=s3_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/s3_lib.sh"
: "${PMTILES_DUMP:?PMTILES_DUMP must name the pmtiles_dump tool}"

s3_cleanup() {
  serve_cleanup
  store_cleanup
}
trap s3_cleanup EXIT

export HOME="$WORK/home"
mkdir -p "$HOME"
unset AWS_PROFILE AWS_DEFAULT_PROFILE AWS_SESSION_TOKEN AWS_CONFIG_FILE AWS_SHARED_CREDENTIALS_FILE \
  AWS_ENDPOINT_URL AWS_ENDPOINT_URL_S3 AWS_DEFAULT_REGION
export AWS_ACCESS_KEY_ID=S3RVER AWS_SECRET_ACCESS_KEY=S3RVER AWS_REGION=us-east-1

# set_of NAME PLAN-ARGS...: a set cut at level 2 in $WORK/NAME/ (plan, shards, apex, merge).
set_of() {
  local name=$1
  shift
  expect_ok "$VTS" plan "$@" -o "$WORK/$name.plan.json" --shards 4 --archive-level 2 -q
  local n i
  n=$(json_get "$WORK/$name.plan.json" "j.shards.length")
  for ((i = 0; i < n; i++)); do
    expect_ok "$VTS" build --plan "$WORK/$name.plan.json" --shard "$i" --out-dir "$WORK/$name.parts" -q
  done
  expect_ok "$VTS" build --plan "$WORK/$name.plan.json" --apex --out-dir "$WORK/$name.parts" -q
  expect_ok "$VTS" merge --plan "$WORK/$name.plan.json" "$WORK/$name.parts" -o "$WORK/$name/" -q
}

# upload_set DIR KEY-PREFIX: the archives first, the manifest last (how a set is replaced).
upload_set() {
  local a
  for a in "$1"/*.pmtiles; do put_object "$a" "$2/$(basename "$a")"; done
  put_object "$1/tileset.json" "$2/tileset.json"
}

# requests [PATTERN]: the requests s3rver has logged so far for keys matching PATTERN: "info:
# /KEY STATUS ..." for a GET, "info: s/KEY STATUS ..." for a HEAD (s3rver 3.7.1's log lines).
requests() { grep -cE "info.*: s?/${1:-}" "$LOGS/s3rver.log" || true; }
# answered: every request s3rver has answered (a log line with a status), whatever its key.
answered() { grep -cE 'info.*: [^ ]* [0-9]{3} ' "$LOGS/s3rver.log" || true; }

note "a set and an archive, local and in the bucket"
# The Earth: tiles of tens of KiB, so that a tile lies beyond the first 16 KiB of its archive
# (read when the archive is opened) and each warm tile costs its own GET.
SYN=("$EARTH" --name t)
set_of lossless "${SYN[@]}"
mkdir -p "$WORK/local"
expect_ok "$VTS" build "${SYN[@]}" -o "$WORK/local/ref.pmtiles" -q
expect_ok "$VTS" build "${SYN[@]}" --codec bc1 -o "$WORK/local/bc1ref.pmtiles" -q
start_s3rver
put_object "$WORK/local/ref.pmtiles" maps/one.pmtiles
upload_set "$WORK/lossless" maps/planet
"$PMTILES_DUMP" tiles "$WORK/local/ref.pmtiles" >"$WORK/ref.tiles"
ntiles=$(wc -l <"$WORK/ref.tiles")

note "vts info, vts verify over s3://"
export AWS_ENDPOINT_URL_S3="http://127.0.0.1:$S3_PORT"
expect_ok "$VTS" info "s3://tiles/maps/planet/tileset.json" --json
json_check "$OUT" "j.max_zoom === 3"
expect_ok "$VTS" verify "s3://tiles/maps/planet/tileset.json"
grep -q "$ntiles tiles" "$OUT" || { show_output; fail "verify over s3 did not check every tile"; }
expect_ok "$VTS" verify "s3://tiles/maps/one.pmtiles"

note "errors at start-up name the URL"
expect_clean_failure "$VTS" serve "s3://tiles/maps/nope.pmtiles" --listen 127.0.0.1:0 --no-admin
((RC == 3)) && grep -q "s3://tiles/maps/nope.pmtiles" "$ERR" || { show_output; fail "missing key"; }
AWS_ACCESS_KEY_ID=WRONG expect_clean_failure "$VTS" serve "s3://tiles/maps/" --listen 127.0.0.1:0 \
  --no-admin
grep -q "credentials refused" "$ERR" && grep -q "s3://tiles/maps" "$ERR" ||
  { show_output; fail "wrong credentials: no clear error"; }
expect_clean_failure "$VTS" serve "s3://nobucket/maps/" --listen 127.0.0.1:0 --no-admin
grep -q 'bucket "nobucket" does not exist' "$ERR" || { show_output; fail "missing bucket"; }

note "vts serve s3://tiles/maps/ beside a local folder: every tile as the local file's"
cat >"$WORK/serve.json" <<JSON
{"reload_interval_ms": 200, "store_timeout_ms": 1000, "store_retries": 1, "threads": 1}
JSON
start_server "s3://tiles/maps/" "$WORK/local" --config "$WORK/serve.json"
curl -sf "$BASE/" >"$WORK/index.json"
json_check "$WORK/index.json" "j.map(t => t.name).join() === 'bc1ref,one,planet,ref'"
set_version=$(json_get "$WORK/lossless/tileset.json" "j.version")
curl -sf "$BASE/planet.json" >"$WORK/planet.json"
json_check "$WORK/planet.json" "j.version === '$set_version'"
tiles_equal() { # NAME REF: every tile of ref.tiles
  local z x y
  while read -r _ z x y _; do
    [[ $(curl -sf "$BASE/$1/$z/$x/$y" | sha256sum) == $(curl -sf "$BASE/$2/$z/$x/$y" | sha256sum) ]] ||
      fail "tile $z/$x/$y of $1 differs from $2's"
  done <"$WORK/ref.tiles"
}
before=$(requests)
tiles_equal planet ref
tiles_equal one ref
cold=$(($(requests) - before))
# The set's archives only: the reload loop's HEADs go to its tileset.json and to one.pmtiles.
store_requests() { curl -sf "$ADMIN_BASE/metrics" | sed -nE 's/^vts_store_requests_total ([0-9]+)$/\1/p'; }
ours_before=$(store_requests)
all_before=$(answered)
before=$(requests 'maps/planet/[^ ]*\.pmtiles ')
while read -r _ z x y _; do curl -sf -o /dev/null "$BASE/planet/$z/$x/$y"; done <"$WORK/ref.tiles"
warm=$(($(requests 'maps/planet/[^ ]*\.pmtiles ') - before))
ours=$(($(store_requests) - ours_before))
all=$(($(answered) - all_before))
note "   $ntiles tiles: $cold GETs cold (set and archive), $warm warm for the set"
# Web images of the set's tiles (read on the store-read pool, then encoded): the local ones.
while read -r _ z x y _; do
  [[ $(curl -sf "$BASE/planet/$z/$x/$y.png" | sha256sum) == $(curl -sf "$BASE/ref/$z/$x/$y.png" | sha256sum) ]] ||
    fail "the PNG of tile $z/$x/$y of the set differs from the local archive's"
done < <(head -8 "$WORK/ref.tiles")
((warm == ntiles)) || fail "$warm GETs for $ntiles warm tiles of the set (one each expected)"
# The server counts what the store answered over the warm pass: the tiles' GETs, and the reload
# loop's HEADs and listings (a few of which may be in flight at either end, seen by one side only).
((ours >= warm && ours <= all + 3 && all <= ours + 3)) ||
  fail "vts_store_requests_total grew by $ours over a pass in which s3rver answered $all requests"

note "a set replaced in the bucket is reloaded whole: never a mix, then the new set"
set_of bc1 "${SYN[@]}" --codec bc1
new_version=$(json_get "$WORK/bc1/tileset.json" "j.version")
(while :; do
  while read -r _ z x y _; do
    code=$(curl -s -o "$WORK/body.bin" -w '%{http_code}' "$BASE/planet/$z/$x/$y")
    echo "$code"
    [[ $code == 200 || $code == 503 ]] || cat "$WORK/body.bin" >>"$WORK/errors.txt"
  done <"$WORK/ref.tiles"
done >"$WORK/codes.txt") &
LOAD_PID=$!
upload_set "$WORK/bc1" maps/planet
for ((i = 0; i < 100; i++)); do
  curl -sf "$BASE/planet.json" >"$WORK/planet.json"
  [[ $(json_get "$WORK/planet.json" "j.version") == "$new_version" ]] && break
  sleep 0.1
done
kill "$LOAD_PID"
wait "$LOAD_PID" 2>/dev/null || true
[[ $(json_get "$WORK/planet.json" "j.version") == "$new_version" ]] || fail "the new set was not loaded"
if grep -vE '^(200|503)$' "$WORK/codes.txt" | sort | uniq -c >&2; then
  cat "$WORK/errors.txt" >&2
  fail "requests during the replacement got other answers than 200 or 503"
fi
note "   $(grep -c . "$WORK/codes.txt") requests during the replacement: $(grep -c '^503$' "$WORK/codes.txt" || true) answered 503"
tiles_equal planet bc1ref

note "a stopped store: 503 with Retry-After, no hang; local tiles meanwhile answered at once"
kill -STOP "$S3_PID"
start=$(date +%s%N)
curl -s -o /dev/null -D "$WORK/h.txt" -w '%{http_code}' -m 30 "$BASE/one/0/0/0" >"$WORK/code.txt" &
STALLED=$!
# Once the server holds that request's connection (the metrics request is the other one), a local
# tile must still come at once: with one
# I/O thread, the store's reads wait on their own pool, not on it.
for ((i = 0; i < 100; i++)); do
  grep -qx 'vts_http_open_connections 2' <(curl -sf "$ADMIN_BASE/metrics") && break
  sleep 0.05
done
grep -qx 'vts_http_open_connections 2' <(curl -sf "$ADMIN_BASE/metrics") ||
  fail "the stalled request's connection is not open"
local_ms=$(curl -s -o /dev/null -w '%{time_total}' -m 5 "$BASE/ref/0/0/0" | awk '{print int($1 * 1000)}')
wait "$STALLED" || true
code=$(cat "$WORK/code.txt")
ms=$((($(date +%s%N) - start) / 1000000))
kill -CONT "$S3_PID"
((local_ms < 1000)) || fail "a local tile took $local_ms ms while a store read was stalled"
[[ $code == 503 ]] || fail "a stopped store answered $code"
grep -qi '^retry-after: 1' "$WORK/h.txt" || fail "no Retry-After"
((ms < 10000)) || fail "the 503 took $ms ms"
note "   503 after $ms ms; a local tile meanwhile in $local_ms ms"
expect_status 200 "$BASE/one/0/0/0"
stop_server

note "a prefix holding a tileset.json is that set; the clients read s3:// sets (vts warm)"
start_server "s3://tiles/maps/planet/" --config "$WORK/serve.json"
curl -sf "$BASE/" >"$WORK/index.json"
json_check "$WORK/index.json" "j.length === 1 && j[0].name === 'planet' && j[0].version === '$new_version'"
stop_server
expect_ok "$VTS" warm "s3://tiles/maps/planet/tileset.json" --cache-dir "$WORK/cache" --json
json_check "$OUT" "j.complete && j.failed === 0 && j.from_network === $ntiles && \
  j.cache.pinned_tiles === $ntiles" "warm fetched every tile of the set"

note "a set on a web server (nginx with Range, deploy/nginx/vts-static.conf.template)"
mkdir -p "$WORK/www"
cp -r "$WORK/lossless" "$WORK/www/planet"
start_static_nginx "$WORK/www"
wait_http "$S/planet/tileset.json"
expect_status 404 "$S/planet/"
start_server "$S/planet/tileset.json" "$WORK/local" --config "$WORK/serve.json"
tiles_equal planet ref
stop_server
echo ok
