#!/usr/bin/env bash
# The store (vts::store, through tests/integration/store_probe) against real servers on loopback:
#   - s3rver (npm, tests/integration/s3_js): an archive uploaded with curl --aws-sigv4 reads tile
#     for tile as the local file; opening costs one GET and a warm tile exactly one (our counters
#     and s3rver's own request log agree); listing a prefix; ETags; a replaced object is
#     `changed`; a stopped (SIGSTOP) or killed server is `unavailable` within the timeouts; a
#     wrong key id, a missing key and a missing bucket are clear errors naming the URL;
#   - SigV4 checked independently of s3rver (which does not verify signatures): every request
#     passes through s3_sigv4_proxy.py, where botocore recomputes its signature — with and
#     without a session token, for a key that needs encoding; a wrong secret is caught there;
#   - nginx serving the same file (http:// standing in for https://): the same tile bytes, and a
#     file replaced under the reader answers If-Match with 412: `changed`.
# A && B || fail: fail unless both hold.
# shellcheck disable=SC2015
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
# shellcheck source=serve_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/serve_lib.sh"
# shellcheck source=deploy_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/deploy_lib.sh"
: "${STORE_PROBE:?STORE_PROBE must name tests/integration/store_probe}"
# shellcheck source=s3_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/s3_lib.sh"
PYTHON3=${PYTHON3:-python3}
require_tool "$PYTHON3"
"$PYTHON3" -c 'import botocore.auth' 2>/dev/null ||
  fail "$PYTHON3 has no botocore (Debian package python3-botocore; run scripts/setup.sh)"

# probe ARGS...: store_probe under the time limit; output in $OUT, exit code in RC.
probe() { run "$STORE_PROBE" "$@"; }
expect_line() { # PATTERN WHAT
  grep -qE "$1" "$OUT" || { show_output; fail "$2: no line /$1/"; }
}

# A home of our own: no ~/.aws of the machine's takes part.
export HOME="$WORK/home"
mkdir -p "$HOME"
unset AWS_PROFILE AWS_DEFAULT_PROFILE AWS_SESSION_TOKEN AWS_CONFIG_FILE AWS_SHARED_CREDENTIALS_FILE \
  AWS_ENDPOINT_URL AWS_DEFAULT_REGION
export AWS_ACCESS_KEY_ID=S3RVER AWS_SECRET_ACCESS_KEY=S3RVER AWS_REGION=us-east-1

note "archives"
build_earth "$WORK/a.pmtiles"
"$VTS" build --synthetic 3000x2000 -o "$WORK/b.pmtiles" >"$LOGS/build.log" 2>&1 ||
  { cat "$LOGS/build.log" >&2; fail "cannot build b.pmtiles"; }
(($(stat -c %s "$WORK/a.pmtiles") > 3 * 16384)) || fail "a.pmtiles is too small to need GETs"

note "s3rver: upload, then every tile through the store"
start_s3rver
export AWS_ENDPOINT_URL_S3="http://127.0.0.1:$S3_PORT"
put_object "$WORK/a.pmtiles" a.pmtiles
put_object "$WORK/b.pmtiles" sets/b.pmtiles
put_object "$WORK/a.pmtiles" "sets/a%20b%2Bc.pmtiles"
put_object "$WORK/b.pmtiles" sets/deeper/z.pmtiles
logged_before=$(grep -c '/a\.pmtiles ' "$LOGS/s3rver.log" || true)
probe compare "$WORK/a.pmtiles" s3://tiles/a.pmtiles
((RC == 0)) || { show_output; fail "compare over s3 exited $RC"; }
expect_line '^open_requests 1$' "opening costs one GET"
expect_line '^warm_tile_requests 1$' "a warm tile costs one GET"
total=$(sed -nE 's/^requests_total ([0-9]+)$/\1/p' "$OUT")
logged=$(($(grep -c '/a\.pmtiles ' "$LOGS/s3rver.log") - logged_before))
((logged == total)) || fail "s3rver logged $logged requests for a.pmtiles, our counters $total"
note "   $(sed -nE 's/^tiles //p' "$OUT") tiles equal, $total GETs (s3rver counted $logged)"

note "listing and ETags"
probe list s3://tiles/sets
((RC == 0)) || { show_output; fail "list exited $RC"; }
want_etag_b="\"$(md5sum "$WORK/b.pmtiles" | cut -d' ' -f1)\""
want_etag_a="\"$(md5sum "$WORK/a.pmtiles" | cut -d' ' -f1)\""
cat >"$LOGS/list.want" <<LIST
s3://tiles/sets/a b+c.pmtiles $(stat -c %s "$WORK/a.pmtiles") $want_etag_a
s3://tiles/sets/b.pmtiles $(stat -c %s "$WORK/b.pmtiles") $want_etag_b
LIST
diff "$LOGS/list.want" "$OUT" >&2 || fail "listing of s3://tiles/sets/ differs"
probe etag s3://tiles/sets/b.pmtiles
[[ $(cat "$OUT") == "$want_etag_b" ]] || { show_output; fail "object_etag is not the MD5 ETag"; }
probe get s3://tiles/sets/b.pmtiles 100
[[ $RC == 6 ]] && grep -q '^error too_large: s3://tiles/sets/b.pmtiles' "$OUT" ||
  { show_output; fail "get_object over its limit: expected too_large"; }

note "errors name the URL"
probe etag s3://tiles/nope.pmtiles
[[ $RC == 3 ]] && grep -q '^error not_found: s3://tiles/nope.pmtiles' "$OUT" ||
  { show_output; fail "a missing key is not not_found"; }
probe compare "$WORK/a.pmtiles" s3://tiles/nope.pmtiles
grep -qE '^error not_found: s3://tiles/nope.pmtiles: not found \(HTTP 404, NoSuchKey' "$OUT" ||
  { show_output; fail "a missing key's message"; }
probe compare "$WORK/a.pmtiles" s3://nobucket/a.pmtiles
grep -qE '^error not_found: s3://nobucket/a.pmtiles: bucket "nobucket" does not exist' "$OUT" ||
  { show_output; fail "a missing bucket's message"; }
AWS_ACCESS_KEY_ID=WRONG probe compare "$WORK/a.pmtiles" s3://tiles/a.pmtiles
grep -qE "^error io: s3://tiles/a.pmtiles: credentials refused by http://127.0.0.1:$S3_PORT/tiles/a.pmtiles \(HTTP 403, InvalidAccessKeyId" "$OUT" ||
  { show_output; fail "a wrong key id's message"; }

note "a replaced object is changed"
mkfifo "$WORK/go"
hold() { # URL: store_probe hold URL in the background, fed by fd 3; waits for "opened"
  "$STORE_PROBE" hold "$1" <"$WORK/go" >"$LOGS/hold.out" 2>&1 &
  HOLD_PID=$!
  exec 3>"$WORK/go"
  wait_line "$LOGS/hold.out" '^opened$' "$HOLD_PID"
}
release() { # -> RC, $LOGS/hold.out
  echo go >&3
  exec 3>&-
  set +e
  timeout 120 tail --pid="$HOLD_PID" -f /dev/null
  wait "$HOLD_PID"
  RC=$?
  set -e
}
hold s3://tiles/a.pmtiles
put_object "$WORK/b.pmtiles" a.pmtiles
release
((RC == 75)) && grep -qE '^error changed: s3://tiles/a.pmtiles changed after it was opened' \
  "$LOGS/hold.out" || { cat "$LOGS/hold.out" >&2; fail "a replaced object: expected changed"; }
put_object "$WORK/a.pmtiles" a.pmtiles

note "a stopped s3rver is unavailable within the timeouts, not a hang"
export STORE_TIMEOUT_MS=1000 STORE_RETRIES=1
hold s3://tiles/a.pmtiles
kill -STOP "$S3_PID"
release
kill -CONT "$S3_PID"
((RC == 75)) && grep -qE "^error unavailable: s3://tiles/a.pmtiles \(http://127.0.0.1:$S3_PORT/tiles/a.pmtiles\) did not answer after 2 attempts" \
  "$LOGS/hold.out" || { cat "$LOGS/hold.out" >&2; fail "a stopped store: expected unavailable"; }
ms=$(sed -nE 's/^elapsed_ms ([0-9]+)$/\1/p' "$LOGS/hold.out")
((ms >= 2000 && ms < 8000)) || fail "two 1 s attempts took ${ms} ms"
note "   unavailable after ${ms} ms"

note "SigV4 recomputed by botocore"
"$PYTHON3" "$HERE/s3_sigv4_proxy.py" "$S3_PORT" S3RVER S3RVER "$LOGS/sigv4.log" \
  >"$LOGS/proxy.out" 2>&1 </dev/null &
PROXY_PID=$!
wait_line "$LOGS/proxy.out" '^port [0-9]+$' "$PROXY_PID"
PROXY_PORT=$(sed -nE 's/^port ([0-9]+)$/\1/p' "$LOGS/proxy.out")
unset STORE_TIMEOUT_MS STORE_RETRIES
for token in "" "FwoGZXIvYXdzE/session+token=="; do
  : >"$LOGS/sigv4.log"
  AWS_SESSION_TOKEN=$token AWS_ENDPOINT_URL_S3="http://127.0.0.1:$PROXY_PORT" \
    probe compare "$WORK/a.pmtiles" "s3://tiles/sets/a b+c.pmtiles"
  ((RC == 0)) || { show_output; fail "compare through the checking proxy exited $RC"; }
  AWS_SESSION_TOKEN=$token AWS_ENDPOINT_URL_S3="http://127.0.0.1:$PROXY_PORT" probe list s3://tiles/sets/
  ((RC == 0)) || { show_output; fail "list through the checking proxy exited $RC"; }
  AWS_SESSION_TOKEN=$token AWS_ENDPOINT_URL_S3="http://127.0.0.1:$PROXY_PORT" \
    probe etag s3://tiles/sets/b.pmtiles
  ((RC == 0)) || { show_output; fail "etag through the checking proxy exited $RC"; }
  n=$(wc -l <"$LOGS/sigv4.log")
  ((n > 3)) || fail "the proxy saw $n requests"
  if grep -v '^ok ' "$LOGS/sigv4.log" >&2; then fail "botocore computes other signatures"; fi
  grep -q '^ok GET /tiles/sets/a%20b%2Bc.pmtiles signed=host;if-match;range;x-amz-content-sha256;x-amz-date' \
    "$LOGS/sigv4.log" || { cat "$LOGS/sigv4.log" >&2; fail "a tile GET's signed headers"; }
  grep -q '^ok GET /tiles?delimiter=%2F&list-type=2&prefix=sets%2F signed=' "$LOGS/sigv4.log" ||
    { cat "$LOGS/sigv4.log" >&2; fail "the listing's canonical query"; }
  grep -q '^ok HEAD /tiles/sets/b.pmtiles ' "$LOGS/sigv4.log" || fail "no signed HEAD"
  if [[ -n $token ]]; then
    if grep -v 'x-amz-security-token' "$LOGS/sigv4.log" >&2; then fail "the session token is not signed"; fi
  fi
  note "   $n requests, every signature equal to botocore's${token:+ (session token)}"
done
# The check can fail: curl signing with the wrong secret is caught.
curl -s -o /dev/null --aws-sigv4 aws:amz:us-east-1:s3 --user S3RVER:not-the-secret \
  -H "x-amz-content-sha256: e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855" \
  "http://127.0.0.1:$PROXY_PORT/tiles/a.pmtiles"
tail -n 1 "$LOGS/sigv4.log" | grep -q '^mismatch GET /tiles/a.pmtiles' ||
  { cat "$LOGS/sigv4.log" >&2; fail "a wrong secret's signature was not caught"; }

note "a killed s3rver is unavailable"
STORE_TIMEOUT_MS=1000 STORE_RETRIES=2 hold s3://tiles/a.pmtiles
{ kill -KILL "$S3_PID" && wait "$S3_PID"; } 2>/dev/null || true
S3_PID=""
release
((RC == 75)) && grep -qE '^error unavailable: s3://tiles/a.pmtiles .* did not answer after 3 attempts' \
  "$LOGS/hold.out" || { cat "$LOGS/hold.out" >&2; fail "a killed store: expected unavailable"; }

note "nginx with Range (http:// for https://)"
mkdir -p "$WORK/www"
cp "$WORK/a.pmtiles" "$WORK/www/a.pmtiles"
start_static_nginx "$WORK/www"
wait_http "$S/a.pmtiles"
probe compare "$WORK/a.pmtiles" "$S/a.pmtiles"
((RC == 0)) || { show_output; fail "compare over nginx exited $RC"; }
expect_line '^open_requests 1$' "opening over nginx costs one GET"
expect_line '^warm_tile_requests 1$' "a warm tile over nginx costs one GET"
hold "$S/a.pmtiles"
cp "$WORK/b.pmtiles" "$WORK/www/b.tmp" && mv "$WORK/www/b.tmp" "$WORK/www/a.pmtiles"
release
((RC == 75)) && grep -qE "^error changed: $S/a.pmtiles changed after it was opened \(412" \
  "$LOGS/hold.out" || { cat "$LOGS/hold.out" >&2; fail "a replaced file behind nginx: expected changed"; }
note "ok"
