#!/usr/bin/env bash
# Object-store serving benchmark (issue 32): `vts serve s3://bucket/prefix/` over s3rver (npm, a
# real S3-protocol server on loopback, tests/integration/s3_js) against `vts serve DIR` over the
# same files on local disk, and s3rver itself answering a plain ranged GET of the same object.
# The issue's bar: warm tiles from the object store cost one ranged GET per tile once the
# directories are cached, and vts serve over s3rver reaches at least 0.5x the req/s of vts serve
# over the local files (s3rver is slow itself: its own req/s for a plain ranged GET is reported
# beside ours).
#
#   bash bench/store_bench.sh [--duration 10s] [--threads 1] [--connections 64] [--runs 1]
#                             [--input IMAGE] [--vts PATH] [--out FILE]
#
#   --threads      vts serve --threads (default 1, as serve_bench.sh: wrk needs about a core)
#   --connections  wrk's connections (default 64; wrk -t2)
#   --runs         wrk runs per target (default 1); the table shows the median by req/s
#
# Inputs: serve_bench.sh's archive of serve_input's image (bench/.cache/serve_<image>.pmtiles),
# and the same build as a set (`vts plan --archive-level 2 --shards 4`, shards, apex, merge into
# bench/.cache/store_set_<image>/), both made once. The local folder holds earth.pmtiles and the set
# earth_set/; the bucket `tiles` holds the same under maps/ (uploaded with `curl --aws-sigv4`,
# the set's manifest last). Both servers run with reload_interval_ms 0 (no periodic checks, so
# s3rver's log holds only tile reads). Before the timed runs every tile is read once from each
# server (the directories cached), then once more through the store: the GETs s3rver logs for that
# pass over the tile count are the GETs per warm tile. wrk -t2 -cC --latency with
# bench/random_tiles.lua over random existing tiles (GET /earth/z/x/y, /earth_set/z/x/y); s3rver
# direct: GET /tiles/maps/earth.pmtiles with the Range of a random tile and a static SigV4
# Authorization header naming key id S3RVER (s3rver checks the key id, not the signature; the
# wrk script is written to the work folder). Server CPU per request from /proc (vts serve's
# process; s3rver's node process).
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

VTS_ARG=""
DURATION=10s
THREADS=1
CONNS=64
RUNS=1
INPUT=""
OUT_FILE=""
while (($#)); do
  case $1 in
    --duration) (($# >= 2)) || die "--duration needs a value"; DURATION=$2; shift 2 ;;
    --threads) (($# >= 2)) || die "--threads needs a value"; THREADS=$2; shift 2 ;;
    --connections) (($# >= 2)) || die "--connections needs a value"; CONNS=$2; shift 2 ;;
    --runs) (($# >= 2)) || die "--runs needs a value"; RUNS=$2; shift 2 ;;
    *) bench_option "$@"; shift "$OPT_SHIFT" ;;
  esac
done
[[ $THREADS =~ ^[1-9][0-9]*$ ]] || die "--threads must be a positive integer, not '$THREADS'"
[[ $CONNS =~ ^[1-9][0-9]*$ ]] || die "--connections must be a positive integer, not '$CONNS'"
[[ $RUNS =~ ^[1-9][0-9]*$ ]] || die "--runs must be a positive integer, not '$RUNS'"
need wrk curl node sha256sum xargs
VTS=$(find_vts "$VTS_ARG")
DUMP=${PMTILES_DUMP:-$(dirname "$VTS")/../tests/integration/pmtiles_dump}
[[ -x $DUMP ]] || DUMP=$(dirname "$VTS")/pmtiles_dump
[[ -x $DUMP ]] || die "no pmtiles_dump beside $VTS (build the tests, or set PMTILES_DUMP)"
S3_JS=${S3_JS:-$ROOT/tests/integration/s3_js}
[[ -f $S3_JS/node_modules/s3rver/package.json ]] ||
  die "npm package s3rver is not installed in $S3_JS (run scripts/setup.sh)"

[[ -n $INPUT ]] || INPUT=$(serve_input)
STEM=$(basename "${INPUT%.*}")
ARCHIVE=$CACHE/serve_$STEM.pmtiles
build_once "$INPUT" "$ARCHIVE"
SET=$CACHE/store_set_$STEM
if [[ ! -s $SET/tileset.json || $INPUT -nt $SET/tileset.json ]]; then
  echo "[bench] making the set $SET (once, not timed)" >&2
  rm -rf "$SET" "$SET.work"
  mkdir -p "$SET.work"
  "$VTS" plan "$INPUT" -o "$SET.work/plan.json" --shards 4 --archive-level 2 -q || die "vts plan failed"
  n=$(node -e 'console.log(JSON.parse(require("fs").readFileSync(process.argv[1])).shards.length)' \
    "$SET.work/plan.json")
  seq 0 $((n - 1)) | xargs -P 2 -I{} "$VTS" build --plan "$SET.work/plan.json" --shard {} \
    --out-dir "$SET.work/parts" -q || die "a shard failed"
  "$VTS" build --plan "$SET.work/plan.json" --apex --out-dir "$SET.work/parts" -q || die "apex failed"
  "$VTS" merge --plan "$SET.work/plan.json" "$SET.work/parts" -o "$SET/" -q || die "merge failed"
  rm -rf "$SET.work"
fi

T=$(mktemp -d "${TMPDIR:-/tmp}/vts-store-bench.XXXXXX")
S3_PID="" LOCAL_PID="" REMOTE_PID=""
finish() {
  local p
  for p in "$LOCAL_PID" "$REMOTE_PID" "$S3_PID"; do
    [[ -n $p ]] && kill -TERM "$p" 2>/dev/null && wait "$p" 2>/dev/null
  done
  rm -rf "$T"
}
trap finish EXIT

mkdir -p "$T/local" "$T/s3"
cp "$ARCHIVE" "$T/local/earth.pmtiles"
cp -r "$SET" "$T/local/earth_set"
SET_ARCHIVES=$(find "$T/local/earth_set" -name '*.pmtiles' | wc -l)

# s3rver, and the uploads.
node "$S3_JS/serve.js" "$T/s3" tiles >"$T/s3rver.log" 2>&1 </dev/null &
S3_PID=$!
for ((i = 0; i < 200; i++)); do
  grep -qE '^port [0-9]+$' "$T/s3rver.log" && break
  kill -0 "$S3_PID" 2>/dev/null || die "s3rver exited: $(cat "$T/s3rver.log")"
  sleep 0.05
done
S3_PORT=$(sed -nE 's/^port ([0-9]+)$/\1/p' "$T/s3rver.log")
[[ -n $S3_PORT ]] || die "s3rver did not start: $(cat "$T/s3rver.log")"
S3="http://127.0.0.1:$S3_PORT"
put_object() { # FILE KEY
  local code
  code=$(curl -s -o "$T/put.out" -w '%{http_code}' -X PUT -T "$1" \
    --aws-sigv4 aws:amz:us-east-1:s3 --user S3RVER:S3RVER \
    -H "x-amz-content-sha256: $(sha256sum "$1" | cut -d' ' -f1)" "$S3/tiles/$2")
  [[ $code == 200 ]] || die "PUT $2 answered $code: $(cat "$T/put.out")"
}
echo "[bench] uploading to s3rver" >&2
put_object "$T/local/earth.pmtiles" maps/earth.pmtiles
for a in "$T/local/earth_set"/*.pmtiles; do put_object "$a" "maps/earth_set/$(basename "$a")"; done
put_object "$T/local/earth_set/tileset.json" maps/earth_set/tileset.json

# The two servers: the same config, no periodic reload.
echo '{"reload_interval_ms": 0}' >"$T/serve.json"
export AWS_ACCESS_KEY_ID=S3RVER AWS_SECRET_ACCESS_KEY=S3RVER AWS_REGION=us-east-1
unset AWS_PROFILE AWS_DEFAULT_PROFILE AWS_SESSION_TOKEN AWS_ENDPOINT_URL AWS_ENDPOINT_URL_S3
start_serve() { # NAME WHAT...: sets SERVE_PID and SERVE_PORT
  local name=$1 i
  shift
  "$VTS" serve "$@" --listen 127.0.0.1:0 --no-admin --threads "$THREADS" --config "$T/serve.json" \
    >"$T/$name.out" 2>"$T/$name.err" &
  SERVE_PID=$!
  for ((i = 0; i < 200; i++)); do
    grep -q 'listening on' "$T/$name.out" 2>/dev/null && break
    kill -0 "$SERVE_PID" 2>/dev/null || die "vts serve ($name) exited: $(cat "$T/$name.err")"
    sleep 0.05
  done
  SERVE_PORT=$(sed -nE 's|.*listening on http://[^ ]*:([0-9]+)[ ,].*|\1|p' "$T/$name.out")
  [[ -n $SERVE_PORT ]] || die "vts serve ($name) did not start: $(cat "$T/$name.err")"
}
start_serve local "$T/local"
LOCAL_PID=$SERVE_PID LOCAL_PORT=$SERVE_PORT
start_serve remote s3://tiles/maps/ --s3-endpoint "$S3"
REMOTE_PID=$SERVE_PID REMOTE_PORT=$SERVE_PORT

# The tiles: every stored tile of the archive (the set holds the same tiles).
"$DUMP" offsets "$T/local/earth.pmtiles" >"$T/offsets" || die "pmtiles_dump offsets failed"
NTILES=$(wc -l <"$T/offsets")
TILE_BYTES=$(awk '{ s += $6 } END { print s }' "$T/offsets")
awk '{ print "/earth/" $2 "/" $3 "/" $4 }' "$T/offsets" >"$T/earth.tiles"
awk '{ print "/earth_set/" $2 "/" $3 "/" $4 }' "$T/offsets" >"$T/earth_set.tiles"
awk '{ print "/tiles/maps/earth.pmtiles", $5, $5 + $6 - 1 }' "$T/offsets" >"$T/direct.ranges"

# pass PORT LIST: GET every tile of LIST once (curl, one connection), failing on any non-2xx.
pass() {
  sed "s|^|url = \"http://127.0.0.1:$1|; s|\$|\"\noutput = \"/dev/null\"|" "$2" >"$T/pass.cfg"
  curl -sf -K "$T/pass.cfg" -w '%{http_code}\n' >"$T/pass.codes" || die "a tile of $2 failed on port $1"
  [[ $(grep -c '^200$' "$T/pass.codes") == "$NTILES" ]] || die "not every tile of $2 answered 200"
}
# gets PATTERN: the requests s3rver has logged for keys matching PATTERN ("info: /KEY STATUS").
gets() { grep -cE "info.*: /$1 " "$T/s3rver.log" || true; }
echo "[bench] warming both servers (every tile once), then one pass through the store counted" >&2
for l in earth earth_set; do
  pass "$LOCAL_PORT" "$T/$l.tiles"
  pass "$REMOTE_PORT" "$T/$l.tiles"
done
b=$(gets 'maps/earth\.pmtiles')
pass "$REMOTE_PORT" "$T/earth.tiles"
WARM_ONE=$(($(gets 'maps/earth\.pmtiles') - b))
b=$(gets 'maps/earth_set/[^ ]*\.pmtiles')
pass "$REMOTE_PORT" "$T/earth_set.tiles"
WARM_SET=$(($(gets 'maps/earth_set/[^ ]*\.pmtiles') - b))
# Same bytes: a sample of tiles from both servers and from s3rver directly.
while read -r p; do
  cmp -s <(curl -sf "http://127.0.0.1:$LOCAL_PORT$p") <(curl -sf "http://127.0.0.1:$REMOTE_PORT$p") ||
    die "local and store differ on $p"
done < <(shuf -n 20 "$T/earth.tiles"; shuf -n 20 "$T/earth_set.tiles")

# The wrk script for s3rver: random_tiles.lua's range mode plus a static SigV4 header set.
AMZ_DATE=$(date -u +%Y%m%dT%H%M%SZ)
cat >"$T/s3_range.lua" <<LUA
-- Random tile-sized ranges of one object (lines "PATH START END"), with static SigV4 headers.
local entries, unexpected = {}, 0
local headers = {
  ["Authorization"] = "AWS4-HMAC-SHA256 Credential=S3RVER/${AMZ_DATE:0:8}/us-east-1/s3/aws4_request, SignedHeaders=host;x-amz-date, Signature=$(printf '0%.0s' {1..64})",
  ["x-amz-date"] = "$AMZ_DATE",
  ["x-amz-content-sha256"] = "UNSIGNED-PAYLOAD",
}
function init(args)
  for line in io.lines(args[1]) do
    local p, a, b = line:match("^(%S+)%s+(%S+)%s+(%S+)")
    if p then entries[#entries + 1] = { p, a, b } end
  end
  math.randomseed(math.floor(os.clock() * 1e6) + #tostring({}))
end
function request()
  local e = entries[math.random(#entries)]
  local h = {}
  for k, v in pairs(headers) do h[k] = v end
  h["Range"] = "bytes=" .. e[2] .. "-" .. e[3]
  return wrk.format("GET", e[1], h)
end
LUA
# Check that the header set works before measuring with it.
read -r _ so sl < <(head -n 1 "$T/direct.ranges")
code=$(curl -s -o "$T/direct.one" -w '%{http_code}' -r "$so-$sl" \
  -H "Authorization: $(sed -nE 's/.*\["Authorization"\] = "(.*)",$/\1/p' "$T/s3_range.lua")" \
  -H "x-amz-date: $AMZ_DATE" -H "x-amz-content-sha256: UNSIGNED-PAYLOAD" "$S3/tiles/maps/earth.pmtiles")
[[ $code == 206 ]] || die "s3rver answered $code to a ranged GET with the static header: $(head -c 300 "$T/direct.one")"

to_ms() { # wrk latency like 1.23ms / 456.00us / 1.20s
  awk -v v="$1" 'BEGIN { n = v + 0; if (v ~ /us$/) n /= 1000; else if (v ~ /ms$/) ; else if (v ~ /s$/) n *= 1000; printf "%.2f", n }'
}
ticks() { # PID...: CPU clock ticks used so far
  local p
  for p in "$@"; do awk '{ print $14 + $15 }' "/proc/$p/stat"; done | awk '{ s += $1 } END { print s + 0 }'
}
CLK_TCK=$(getconf CLK_TCK)
# run_wrk NAME URL SCRIPT LIST MODE CPU-PIDS: one wrk run; appends "NAME RPS P50 P99 ERRORS CPU_US(...)".
RES=$T/results.txt
: >"$RES"
run_wrk() {
  local name=$1 url=$2 script=$3 list=$4 mode=$5 log="$T/wrk_$1.txt" n errs cpus="" p t0=() t1
  shift 5
  for p in "$@"; do t0+=("$(ticks "$p")"); done
  wrk -t"$((CONNS < 2 ? CONNS : 2))" -c"$CONNS" -d"$DURATION" --latency -s "$script" "$url" -- "$list" "$mode" >"$log" 2>&1 ||
    die "wrk failed: $(cat "$log")"
  n=$(awk '/requests in/ { print $1 }' "$log")
  local i=0
  for p in "$@"; do
    t1=$(ticks "$p")
    cpus+="$(awk -v a="${t0[$i]}" -v b="$t1" -v n="$n" -v hz="$CLK_TCK" 'BEGIN { printf "%.0f", (b - a) / hz * 1e6 / n }') "
    i=$((i + 1))
  done
  errs=$(awk '/Non-2xx or 3xx/ { print $NF }' "$log")
  local sock
  sock=$(awk '/Socket errors/ { gsub(/,/, ""); print $4 + $6 + $8 + $10 }' "$log" | head -n 1)
  errs=$((${errs:-0} + ${sock:-0}))
  echo "$name $(awk '/^Requests\/sec:/ { printf "%.0f", $2 }' "$log") $(to_ms "$(awk '$1 == "50%" { print $2 }' "$log")") $(to_ms "$(awk '$1 == "99%" { print $2 }' "$log")") $errs $cpus" >>"$RES"
  echo "[bench] $name: $(tail -n 1 "$RES")" >&2
}
LUA=$BENCH_DIR/random_tiles.lua
for ((r = 1; r <= RUNS; r++)); do
  run_wrk local-one "http://127.0.0.1:$LOCAL_PORT" "$LUA" "$T/earth.tiles" tiles "$LOCAL_PID"
  run_wrk store-one "http://127.0.0.1:$REMOTE_PORT" "$LUA" "$T/earth.tiles" tiles "$REMOTE_PID" "$S3_PID"
  run_wrk local-set "http://127.0.0.1:$LOCAL_PORT" "$LUA" "$T/earth_set.tiles" tiles "$LOCAL_PID"
  run_wrk store-set "http://127.0.0.1:$REMOTE_PORT" "$LUA" "$T/earth_set.tiles" tiles "$REMOTE_PID" "$S3_PID"
  run_wrk s3rver "$S3" "$T/s3_range.lua" "$T/direct.ranges" range "$S3_PID"
  CONNS_SAVED=$CONNS CONNS=1
  run_wrk s3rver-1 "$S3" "$T/s3_range.lua" "$T/direct.ranges" range "$S3_PID"
  CONNS=$CONNS_SAVED
done
# The connections vts serve holds to s3rver while loaded (ss, in the middle of a short run).
wrk -t2 -c"$CONNS" -d4s -s "$LUA" "http://127.0.0.1:$REMOTE_PORT" -- "$T/earth.tiles" tiles >/dev/null 2>&1 &
WRK_PID=$!
sleep 2
STORE_CONNS=$(ss -tnH state established "( sport = :$S3_PORT )" | wc -l)
wait "$WRK_PID" || true

median() { # NAME: the result line with the median req/s
  awk -v n="$1" '$1 == n' "$RES" | sort -k2,2g | awk '{ l[NR] = $0 } END { print l[int((NR + 1) / 2)] }'
}
report() {
  local lo so ls ss dr d1
  lo=$(median local-one) so=$(median store-one) ls=$(median local-set) ss=$(median store-set)
  dr=$(median s3rver) d1=$(median s3rver-1)
  local r_d1 p_d1 e_d1 c_d1 r_lo p_lo e_lo c_lo r_so p_so e_so c_so c_so_s3 r_ls p_ls e_ls c_ls r_ss p_ss e_ss c_ss c_ss_s3 r_dr p_dr e_dr c_dr
  read -r _ r_lo _ p_lo e_lo c_lo <<<"$lo"
  read -r _ r_so _ p_so e_so c_so c_so_s3 <<<"$so"
  read -r _ r_ls _ p_ls e_ls c_ls <<<"$ls"
  read -r _ r_ss _ p_ss e_ss c_ss c_ss_s3 <<<"$ss"
  read -r _ r_dr _ p_dr e_dr c_dr <<<"$dr"
  read -r _ r_d1 _ p_d1 e_d1 c_d1 <<<"$d1"
  echo "## Serving from an object store ($(date -u '+%Y-%m-%d'))"
  echo
  machine_info
  echo "- input: $(basename "$ARCHIVE") ($(mb "$(bytes_of "$T/local/earth.pmtiles")") MiB, $NTILES tiles, average $((TILE_BYTES / NTILES)) B) and the same build as a set of $SET_ARCHIVES archives (\`--archive-level 2\`), in a local folder and in s3rver $(node -e 'console.log(require(process.argv[1]).version)' "$S3_JS/node_modules/s3rver/package.json") (bucket on its own disk folder, loopback)"
  echo "- vts serve --threads $THREADS, reload_interval_ms 0; wrk -t2 -c$CONNS -d$DURATION --latency, random existing tiles; s3rver direct: random tile ranges of earth.pmtiles with a static SigV4 header; median of $RUNS run(s) by req/s"
  echo "- warm GETs: after one pass over every tile, one more pass through the store cost **$WARM_ONE GETs for $NTILES tiles** of the archive ($(ratio "$WARM_ONE" "$NTILES") per tile) and **$WARM_SET for $NTILES tiles** of the set ($(ratio "$WARM_SET" "$NTILES") per tile), in s3rver's log"
  echo
  echo "| target | req/s | p99 ms | errors | CPU µs/req (vts serve; s3rver) | req/s vs local | req/s vs s3rver direct |"
  echo "| --- | ---: | ---: | ---: | ---: | ---: | ---: |"
  echo "| vts serve DIR, archive | $r_lo | $p_lo | $e_lo | $c_lo | 1.00 | $(ratio "$r_lo" "$r_dr") |"
  echo "| vts serve s3://, archive | $r_so | $p_so | $e_so | $c_so; $c_so_s3 | **$(ratio "$r_so" "$r_lo")** | **$(ratio "$r_so" "$r_dr")** |"
  echo "| vts serve DIR, set | $r_ls | $p_ls | $e_ls | $c_ls | 1.00 | $(ratio "$r_ls" "$r_dr") |"
  echo "| vts serve s3://, set | $r_ss | $p_ss | $e_ss | $c_ss; $c_ss_s3 | **$(ratio "$r_ss" "$r_ls")** | **$(ratio "$r_ss" "$r_dr")** |"
  echo "| s3rver direct, ranged GET | $r_dr | $p_dr | $e_dr | -; $c_dr | $(ratio "$r_dr" "$r_lo") | 1.00 |"
  echo "| s3rver direct, one connection (wrk -c1) | $r_d1 | $p_d1 | $e_d1 | -; $c_d1 | $(ratio "$r_d1" "$r_lo") | $(ratio "$r_d1" "$r_dr") |"
  echo
  echo "vts serve held $STORE_CONNS connection(s) to s3rver under wrk -c$CONNS (ss, mid-run)."
}
if [[ -n $OUT_FILE ]]; then report | tee "$OUT_FILE"; else report; fi
