#!/usr/bin/env bash
# `vts serve` lifecycle over real sockets: hot reload of a replaced archive under load with zero
# failed requests, a broken replacement refused (old archive kept), SIGHUP, a token-protected
# tileset from the config file, and SIGTERM during a slow download: the download completes
# byte-exact and the server exits 0.
source "$(dirname "$0")/lib.sh"
source "$(dirname "$0")/serve_lib.sh"

mkdir -p "$WORK/serve"
expect_ok "$VTS" build --synthetic 2048x1024 -o "$WORK/v1.pmtiles"
expect_ok "$VTS" build --synthetic 2048x1536 -o "$WORK/v2.pmtiles"
build_earth "$WORK/serve/earth.pmtiles"
cp "$WORK/v1.pmtiles" "$WORK/serve/tiles.pmtiles"
cp "$WORK/v1.pmtiles" "$WORK/serve/signed.pmtiles"
cat >"$WORK/config.json" <<JSON
{"reload_interval_ms": 200, "threads": 2, "limits": {"drain_timeout_ms": 10000},
 "access": {"earth": {"tokens": ["s3cret"]}, "signed": {"hmac_keys": ["k3y-one", "k3y-two"]}}}
JSON
note "a config key that is not known stops vts serve with an error naming the key and the file"
echo '{"reload_interval_ms": 200, "limits": {"idle_timeout": 5000}}' >"$WORK/typo.json"
expect_clean_failure "$VTS" serve "$WORK/serve" --listen 127.0.0.1:0 --admin 127.0.0.1:0 \
  --config "$WORK/typo.json"
((RC == 2)) || fail "an unknown config key exited $RC, expected 2"
grep -qF 'unknown key "limits.idle_timeout"' "$ERR" || fail "the error does not name the key: $(cat "$ERR")"
grep -qF "$WORK/typo.json" "$ERR" || fail "the error does not name the file: $(cat "$ERR")"
note "an access entry for a tileset that is not served stops vts serve (it would stay public)"
echo '{"access": {"eartj": {"tokens": ["s3cret"]}}}' >"$WORK/misspelt.json"
expect_clean_failure "$VTS" serve "$WORK/serve" --listen 127.0.0.1:0 --admin 127.0.0.1:0 \
  --config "$WORK/misspelt.json"
((RC == 2)) || fail "an access entry for no tileset exited $RC, expected 2"
grep -qF '"eartj"' "$ERR" || fail "the error does not name the tileset: $(cat "$ERR")"

start_server "$WORK/serve" --config "$WORK/config.json"

version() { curl -sf "$BASE/tiles.json" | sed -nE 's/.*"version" *: *"([0-9a-f]+)".*/\1/p'; }
v1=$(version)
[[ -n $v1 ]] || fail "no version in TileJSON: $(curl -s "$BASE/tiles.json" | head -c 300)"

note "hot reload under load: replace the archive (write + rename) while clients fetch"
urls=()
for ((i = 0; i < 3000; i++)); do urls+=("$BASE/tiles/$((i % 3))/0/0"); done
printf 'url = "%s"\noutput = "/dev/null"\n' "${urls[@]}" >"$WORK/urls.cfg"
curl -s --parallel --parallel-max 8 -K "$WORK/urls.cfg" -w '%{http_code}\n' >"$WORK/codes.txt" &
load=$!
sleep 0.3
cp "$WORK/v2.pmtiles" "$WORK/serve/.tiles.tmp"
mv "$WORK/serve/.tiles.tmp" "$WORK/serve/tiles.pmtiles"
wait "$load" || fail "load client failed"
bad=$(grep -vc '^200$' "$WORK/codes.txt" || true)
total=$(wc -l <"$WORK/codes.txt")
((total == 3000)) || fail "only $total of 3000 requests answered"
((bad == 0)) || fail "$bad of $total requests failed during reload: $(sort "$WORK/codes.txt" | uniq -c)"
for ((i = 0; i < 50; i++)); do
  v=$(version)
  [[ $v != "$v1" ]] && break
  sleep 0.1
done
[[ $v != "$v1" ]] || fail "the replaced archive was not picked up"
grep -q 'reloaded 1 tileset' "$LOGS/serve.err" || fail "no reload logged"
note "version $v1 -> $v, $total requests, 0 failed"

note "a broken replacement is refused and the old archive kept"
head -c 5000 /dev/urandom >"$WORK/serve/.tiles.tmp"
mv "$WORK/serve/.tiles.tmp" "$WORK/serve/tiles.pmtiles"
for ((i = 0; i < 50; i++)); do
  grep -q 'reload refused' "$LOGS/serve.err" && break
  sleep 0.1
done
grep -q 'reload refused' "$LOGS/serve.err" || fail "broken archive not refused"
[[ $(version) == "$v" ]] || fail "version changed after a broken replacement"
expect_status 200 "$BASE/tiles/1/1/0"
grep -qE '^vts_reloads_total\{result="refused"\} [1-9]' <<<"$(curl -sf "$ADMIN_BASE/metrics")" ||
  fail "refusal not counted in /metrics"

note "SIGHUP reloads (a fixed archive comes back)"
cp "$WORK/v1.pmtiles" "$WORK/serve/.tiles.tmp"
mv "$WORK/serve/.tiles.tmp" "$WORK/serve/tiles.pmtiles"
kill -HUP "$SERVER_PID"
for ((i = 0; i < 50; i++)); do
  [[ $(version) == "$v1" ]] && break
  sleep 0.1
done
[[ $(version) == "$v1" ]] || fail "SIGHUP did not bring back version $v1"

note "a tileset protected by a bearer token from the config file"
expect_status 401 "$BASE/earth/0/0/0"
expect_status 403 -H 'Authorization: Bearer wrong' "$BASE/earth/0/0/0"
expect_status 401 "$BASE/earth.pmtiles"
expect_status 200 -H 'Authorization: Bearer s3cret' "$BASE/earth/0/0/0"
expect_status 200 "$BASE/tiles/0/0/0"

note "a tileset protected by expiring HMAC-signed URLs (made with vts sign)"
expect_status 401 "$BASE/signed/0/0/0"
good=$("$VTS" sign /signed/0/0/0 --key k3y-two --ttl 300)
expect_status 200 "$BASE$good"
expect_status 200 "$BASE$("$VTS" sign /signed.json --key k3y-one)"
expect_status 403 "$BASE$("$VTS" sign /signed/0/0/0 --key wrong-key)"
# An expired signature, made with openssl (vts sign refuses to make one).
past=$(($(date +%s) - 5))
sig=$(printf '%s' "/signed/0/0/0?expires=$past" | openssl dgst -sha256 -hmac k3y-one -hex | sed 's/.* //')
expect_status 200 "$BASE$("$VTS" sign /signed/0/0/0 --key k3y-one --expires $((past + 3600)))"
expect_status 403 "$BASE/signed/0/0/0?expires=$past&sig=$sig"
# A signature is bound to its path: reusing it for another tile is refused.
expect_status 403 "$BASE/signed/1/0/0?${good#*\?}"
tampered=$(sed -E 's/sig=(.)/sig=\1\1/' <<<"$good")
expect_status 403 "$BASE$tampered"

note "SIGTERM during a slow download: it completes, then the server exits 0"
curl -sf --limit-rate 1M -H 'Authorization: Bearer s3cret' "$BASE/earth.pmtiles" -o "$WORK/slow.pmtiles" &
dl=$!
sleep 0.7
start=$(date +%s%N)
kill -TERM "$SERVER_PID"
sleep 0.2
status_of --max-time 2 "$BASE/" >"$WORK/after_code" || true
[[ $(cat "$WORK/after_code") == 000 ]] || fail "new connections accepted after SIGTERM"
wait "$dl" || fail "the in-flight download failed after SIGTERM"
cmp -s "$WORK/slow.pmtiles" "$WORK/serve/earth.pmtiles" || fail "drained download differs"
rc=0
wait "$SERVER_PID" || rc=$?
SERVER_PID=""
((rc == 0)) || { cat "$LOGS/serve.err" >&2; fail "vts serve exited $rc after SIGTERM"; }
note "drained in $((($(date +%s%N) - start) / 1000000)) ms, exit 0"
if grep -qE 'AddressSanitizer|runtime error:' "$LOGS/serve.err"; then
  cat "$LOGS/serve.err" >&2
  fail "sanitizer report from vts serve"
fi
