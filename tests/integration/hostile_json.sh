#!/usr/bin/env bash
# JSON from places we do not control, nested 100,000 levels deep (200 KB, far inside every size
# limit) or with counts and rows no run makes, written by hostile_json.py:
#   - archives whose metadata nests that deep under an unknown key of "vtstream" and of
#     "vtstream.georeference": `vts serve` of a folder holding them skips each with the reason
#     and serves the good archive, GET /{ts}.json of each is 404, the server stays up; `vts serve`
#     of such an archive alone and `vts info` fail cleanly (they were read, then one GET of the
#     TileJSON overflowed the I/O thread's stack: SIGSEGV, every tileset down);
#   - TileJSON documents nested that deep, served by `python3 -m http.server`: `vts warm` and
#     `vts loadtest` fail cleanly naming the depth (they crashed with SIGSEGV, rc 139);
#   - load-test reports: `vts loadtest merge` refuses one of 2,000,000 per-second rows naming the
#     field and the file, and counts that sum past 2^64 naming the field.
# A clean failure: a non-zero exit that is not a signal (lib.sh's expect_clean_failure).
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
# shellcheck source=serve_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/serve_lib.sh"
require_tool python3
HOSTILE="$(dirname "${BASH_SOURCE[0]}")/hostile_json.py"
DEPTH_ERROR='nests objects or arrays deeper than 64 levels'

HTTP_PID=""
hostile_cleanup() {
  if [[ -n $HTTP_PID ]]; then kill "$HTTP_PID" 2>/dev/null || true; fi
  serve_cleanup
}
trap hostile_cleanup EXIT

note "a georeferenced archive, and copies whose metadata nests 100,000 levels deep"
D="$WORK/serve"
mkdir -p "$D"
expect_ok "$VTS" build --synthetic 2048x1024 --tiling WorldCRS84Quad --bbox=-10,35,30,60 \
  -o "$D/good.pmtiles" --threads 2
for where in vtstream georeference; do
  expect_ok python3 "$HOSTILE" archive "$D/good.pmtiles" "$D/deep-$where.pmtiles" "$where"
  size=$(stat -c %s "$D/deep-$where.pmtiles")
  ((size < 100000)) || fail "deep-$where.pmtiles is $size bytes; its metadata should be gzip"
  expect_ok python3 "$HOSTILE" metadata "$D/good.pmtiles" "$WORK/meta-$where.json" "$where"
  size=$(stat -c %s "$WORK/meta-$where.json")
  ((size > 200000 && size < 16 * 1024 * 1024)) ||
    fail "the metadata of deep-$where is $size bytes, expected 200 KB .. 16 MiB"
done

note "vts info refuses each, naming the depth"
for where in vtstream georeference; do
  expect_clean_failure "$VTS" info "$D/deep-$where.pmtiles"
  grep -q "$DEPTH_ERROR" "$ERR" || fail "vts info deep-$where: $(cat "$ERR")"
  grep -q "future_key" "$ERR" || fail "vts info deep-$where does not say where: $(cat "$ERR")"
done
expect_ok "$VTS" info "$D/good.pmtiles"

note "vts serve of a deep archive alone fails cleanly"
expect_clean_failure "$VTS" serve "$D/deep-vtstream.pmtiles" --listen 127.0.0.1:0 --no-admin
grep -q "$DEPTH_ERROR" "$ERR" || fail "vts serve deep-vtstream.pmtiles: $(cat "$ERR")"

note "vts serve of the folder skips the deep archives, serves the good one and stays up"
start_server "$D"
grep -q ', 1 tilesets' "$LOGS/serve.out" || fail "not 1 tileset: $(cat "$LOGS/serve.out")"
for where in vtstream georeference; do
  grep -F "skipped $D/deep-$where.pmtiles: " "$LOGS/serve.err" | grep -q "$DEPTH_ERROR" ||
    fail "deep-$where.pmtiles is not skipped with the reason: $(cat "$LOGS/serve.err")"
  for i in 1 2; do
    expect_status 404 "$BASE/deep-$where.json"
  done
done
curl -sf -o "$WORK/good.json" "$BASE/good.json" || fail "GET /good.json failed"
kill -0 "$SERVER_PID" 2>/dev/null || fail "vts serve died"
expect_status 200 "$BASE/good/0/0/0"
# The TileJSON's "vtstream" object has the keys this build knows, not the archive's own extras.
grep -q future_key "$WORK/good.json" && fail "good.json has a future_key"

note "deeply nested TileJSON from python3 -m http.server: vts warm and loadtest fail cleanly"
WWW="$WORK/www"
mkdir -p "$WWW"
for where in vtstream georeference top; do
  expect_ok python3 "$HOSTILE" tilejson "$WORK/good.json" "$WWW/deep-$where.json" "$where"
done
: >"$LOGS/http.out"
python3 -u -m http.server 0 --bind 127.0.0.1 --directory "$WWW" >"$LOGS/http.out" 2>&1 &
HTTP_PID=$!
for ((i = 0; i < 100; i++)); do
  grep -q 'port [0-9]' "$LOGS/http.out" && break
  sleep 0.05
done
HTTP_PORT=$(sed -nE 's/.* port ([0-9]+) .*/\1/p' "$LOGS/http.out" | head -1)
[[ -n $HTTP_PORT ]] || fail "python3 -m http.server printed no port: $(cat "$LOGS/http.out")"
S="http://127.0.0.1:$HTTP_PORT"
for where in vtstream georeference top; do
  expect_clean_failure "$VTS" warm "$S/deep-$where.json" --cache-dir "$WORK/cache-$where" --quiet
  grep -q "$DEPTH_ERROR" "$ERR" || fail "vts warm deep-$where.json: $(cat "$ERR")"
  grep -qF "$S/deep-$where.json" "$ERR" || fail "vts warm does not name the URL: $(cat "$ERR")"
  expect_clean_failure "$VTS" loadtest "$S/deep-$where.json" --duration 1 --quiet
  grep -q "$DEPTH_ERROR" "$ERR" || fail "vts loadtest deep-$where.json: $(cat "$ERR")"
done
kill "$HTTP_PID"
wait "$HTTP_PID" 2>/dev/null || true
HTTP_PID=""

note "load-test reports: millions of rows and counts past 2^64 are refused by name"
expect_ok "$VTS" loadtest "$BASE/good" --viewers 2 --duration 1 --json --quiet
cp "$OUT" "$WORK/run.json"
expect_ok "$VTS" loadtest merge "$WORK/run.json" "$WORK/run.json" --json
expect_ok python3 "$HOSTILE" report-rows "$WORK/run.json" "$WORK/rows.json" 2000000
expect_clean_failure "$VTS" loadtest merge "$WORK/run.json" "$WORK/rows.json"
grep -qF "$WORK/rows.json: seconds holds more than" "$ERR" ||
  fail "2,000,000 rows are not refused naming the field and the file: $(cat "$ERR")"
expect_ok python3 "$HOSTILE" report-overflow "$WORK/run.json" "$WORK/half.json" requests
expect_ok "$VTS" loadtest merge "$WORK/half.json" "$WORK/run.json"
expect_clean_failure "$VTS" loadtest merge "$WORK/half.json" "$WORK/half.json"
grep -q 'totals.requests: the counts sum past 2^64 - 1' "$ERR" ||
  fail "counts summing past 2^64 are not refused by name: $(cat "$ERR")"
expect_ok python3 "$HOSTILE" report-overflow "$WORK/run.json" "$WORK/wrap.json" buckets
hist=$(cat "$OUT")
expect_clean_failure "$VTS" loadtest merge "$WORK/run.json" "$WORK/wrap.json"
grep -qF "$WORK/wrap.json: $hist" "$ERR" || fail "wrapped bucket counts: $(cat "$ERR")"
grep -q 'sum past 2^64 - 1' "$ERR" || fail "wrapped bucket counts: $(cat "$ERR")"

note "the server is still up and serving"
expect_status 200 "$BASE/good.json"
stop_server
