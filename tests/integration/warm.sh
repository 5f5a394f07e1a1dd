#!/usr/bin/env bash
# `vts warm` against the real `vts serve` on 127.0.0.1 (port 0), its cache checked with the sqlite3
# CLI. One part per ctest (the first argument):
#   fill      every tile fetched and pinned; the cache survives the server going away; a second
#             warm serves everything from the cache; remote .pmtiles and local archives work too;
#             a cache too small for the pinned set fails and says so
#   subset    --levels and --region select exactly the tiles the geometry says
#   crash     kill -9 at random moments and SIGINT leave a valid cache; warm then resumes to the end
#   bad_input unreachable URL, bad --levels/--region/--cache-size: clean errors, no cache folder
#   bbox      --bbox (degrees) on sparse georeferenced archives warms exactly the tiles of the box
#             clipped to the footprint, as docs/FORMAT.md §6 defines them (computed here in
#             Python); a box outside the footprint warms nothing (exit 0); no georeference: exit 2
# Environment (besides lib.sh's): SQLITE3, the sqlite3 CLI.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
# shellcheck source=serve_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/serve_lib.sh"

SQLITE3=${SQLITE3:-sqlite3}
require_tool "$SQLITE3"
PART=${1:?usage: warm.sh fill|subset|crash|bad_input|bbox}

# sql DIR QUERY: the sqlite3 CLI's answer for the cache in DIR.
sql() { "$SQLITE3" "$1/cache.db" "$2"; }

# expect_valid_cache DIR: PRAGMA integrity_check by the sqlite3 CLI prints exactly "ok".
expect_valid_cache() {
  local got
  got=$(sql "$1" 'PRAGMA integrity_check' 2>&1) || fail "sqlite3 cannot read $1/cache.db: $got"
  [[ $got == ok ]] || fail "PRAGMA integrity_check on $1/cache.db: $got"
}

# expect_cached DIR N: the cache holds exactly N tiles, every one pinned.
expect_cached() {
  local got
  got=$(sql "$1" 'SELECT count(*) || "/" || coalesce(sum(pinned), 0) FROM tiles')
  [[ $got == "$2/$2" ]] || fail "$1 holds $got tiles/pinned, expected $2/$2"
}

# warm_json ARGS...: `vts warm ARGS --json` must succeed; its JSON is kept in $LOGS/warm.json.
warm_json() {
  expect_ok "$VTS" warm "$@" --json
  cp "$OUT" "$LOGS/warm.json"
}

# tile_list W H T Z0 Z1 X0 Y0 X1 Y1: "z x y" of every tile of levels Z0..Z1 over the finest-level
# texel rectangle [X0,X1) x [Y0,Y1), by the pyramid geometry rules restated here.
tile_list() {
  local w=$1 h=$2 t=$3 z0=$4 z1=$5 x0=$6 y0=$7 x1=$8 y1=$9 maxz=0 z s lw lh rx0 ry0 rx1 ry1 x y
  while (((t << maxz) < (w > h ? w : h))); do maxz=$((maxz + 1)); done
  for ((z = z0; z <= z1; z++)); do
    s=$((maxz - z))
    lw=$(((w + (1 << s) - 1) >> s))
    lh=$(((h + (1 << s) - 1) >> s))
    rx0=$((x0 >> s)) ry0=$((y0 >> s))
    rx1=$(((x1 + (1 << s) - 1) >> s)) ry1=$(((y1 + (1 << s) - 1) >> s))
    ((rx1 > lw)) && rx1=$lw
    ((ry1 > lh)) && ry1=$lh
    for ((y = ry0 / t; y < (ry1 + t - 1) / t; y++)); do
      for ((x = rx0 / t; x < (rx1 + t - 1) / t; x++)); do echo "$z $x $y"; done
    done
  done
}

# expect_tiles DIR LIST_FILE: the cache holds exactly the tiles listed ("z x y" lines).
expect_tiles() {
  sql "$1" "SELECT z || ' ' || x || ' ' || y FROM tiles ORDER BY z, y, x" >"$LOGS/got.txt"
  if ! diff -q "$2" "$LOGS/got.txt" >/dev/null; then
    diff "$2" "$LOGS/got.txt" | head -20 >&2
    fail "$1 does not hold exactly the expected tiles"
  fi
}

# start_server_on LISTEN ARCHIVES...: like start_server, on a given address (to come back on the
# same port: the port is part of the tileset's cache key).
start_server_on() {
  local listen=$1 i
  shift
  : >"$LOGS/serve.out" # not the redirection's job: a previous server's line would pass the poll
  "$VTS" serve "$@" --listen "$listen" --admin 127.0.0.1:0 \
    >"$LOGS/serve.out" 2>"$LOGS/serve.err" </dev/null &
  SERVER_PID=$!
  for ((i = 0; i < 100; i++)); do
    grep -q 'listening on' "$LOGS/serve.out" && return 0
    kill -0 "$SERVER_PID" 2>/dev/null || { cat "$LOGS/serve.err" >&2; fail "vts serve exited"; }
    sleep 0.05
  done
  fail "vts serve did not start on $listen"
}

SYN_TILES=43 # 2048x1024, T = 256: levels 0-3 hold 1 + 2 + 8 + 32 tiles

part_fill() {
  expect_ok "$VTS" build --synthetic 2048x1024 -o "$WORK/syn.pmtiles"
  start_server "$WORK/syn.pmtiles"
  local url="$BASE/syn" dir="$WORK/cache"

  note "warm fetches every tile and pins it"
  warm_json "$url" --cache-dir "$dir"
  json_check "$LOGS/warm.json" "j.tiles_total == $SYN_TILES && j.from_network == $SYN_TILES &&
    j.already_cached == 0 && j.absent == 0 && j.failed == 0 && j.complete === true &&
    j.bytes_fetched > 0 && j.cache.pinned_tiles == $SYN_TILES" "all $SYN_TILES tiles fetched"
  local fetched
  fetched=$(json_get "$LOGS/warm.json" j.bytes_fetched)

  stop_server
  note "with the server gone the cache is complete and valid"
  expect_cached "$dir" "$SYN_TILES"
  expect_valid_cache "$dir"
  tile_list 2048 1024 256 0 3 0 0 2048 1024 >"$LOGS/want.txt"
  expect_tiles "$dir" "$LOGS/want.txt"
  [[ $(sql "$dir" 'SELECT key FROM tilesets') == "$url" ]] || fail "tileset key is not $url"
  [[ $(sql "$dir" 'SELECT sum(size) FROM tiles') == "$fetched" ]] ||
    fail "cached bytes differ from the $fetched bytes reported fetched"
  note "with the server gone, warm verifies the cache offline (the tileset was remembered)"
  [[ -n $(ls "$dir/sources/"*.json 2>/dev/null) ]] || fail "no saved source description"
  warm_json "$url" --cache-dir "$dir"
  json_check "$LOGS/warm.json" "j.from_network == 0 && j.already_cached == $SYN_TILES &&
    j.complete" "offline: everything from the cache"
  note "the cache daemon starts offline from a cache that only warm filled"
  : >"$LOGS/daemon.out" # exists before the poll reads it (the job opens it when it starts)
  "$VTS" cache serve --upstream "$url" --cache-dir "$dir" --listen 127.0.0.1:0 --no-admin \
    >"$LOGS/daemon.out" 2>"$LOGS/daemon.err" </dev/null &
  local daemon_pid=$! dport="" i
  for ((i = 0; i < 200; i++)); do
    dport=$(sed -nE 's|.*listening on http://[^ ]*:([0-9]+)[ ,].*|\1|p' "$LOGS/daemon.out")
    [[ -n $dport ]] && break
    kill -0 "$daemon_pid" 2>/dev/null || break
    sleep 0.05
  done
  [[ -n $dport ]] || { cat "$LOGS/daemon.err" >&2; fail "vts cache serve did not start offline"; }
  local name=${url##*/}
  curl -sf -o "$LOGS/daemon_tile" "http://127.0.0.1:$dport/$name/0/0/0" ||
    { kill -TERM "$daemon_pid"; fail "the offline daemon did not serve a warmed tile"; }
  [[ -s $LOGS/daemon_tile ]] || fail "empty tile from the offline daemon"
  kill -TERM "$daemon_pid"
  wait "$daemon_pid" || fail "vts cache serve did not exit 0 on SIGTERM"
  # A cache that never saw this URL has nothing to fall back on: a clean failure.
  expect_clean_failure "$VTS" warm "$url" --cache-dir "$WORK/empty-cache"
  expect_cached "$dir" "$SYN_TILES"
  expect_valid_cache "$dir"

  note "warm again, server back on the same port: everything already cached"
  # shellcheck disable=SC2153  # PORT is set by start_server (serve_lib.sh)
  start_server_on "127.0.0.1:$PORT" "$WORK/syn.pmtiles"
  warm_json "$url" --cache-dir "$dir"
  json_check "$LOGS/warm.json" "j.tiles_total == $SYN_TILES && j.from_network == 0 &&
    j.already_cached == $SYN_TILES && j.bytes_fetched == 0 && j.complete" "all from the cache"
  expect_ok "$VTS" warm "$url" --cache-dir "$dir"
  grep -qE "already cached +$SYN_TILES" "$OUT" || { show_output; fail "text summary"; }
  grep -qE "from network +0 " "$OUT" || { show_output; fail "text summary"; }

  note "a remote .pmtiles URL and a local archive work too"
  warm_json "$BASE/syn.pmtiles" --cache-dir "$WORK/remote" --concurrency 4
  json_check "$LOGS/warm.json" "j.from_network == $SYN_TILES && j.complete" "remote archive"
  expect_cached "$WORK/remote" "$SYN_TILES"
  expect_tiles "$WORK/remote" "$LOGS/want.txt"
  warm_json "$WORK/syn.pmtiles" --cache-dir "$WORK/local"
  json_check "$LOGS/warm.json" "j.tiles_total == $SYN_TILES && j.already_cached == 0 &&
    j.from_network + j.absent == $SYN_TILES && j.failed == 0 && j.complete" "local archive"
  expect_valid_cache "$WORK/local"

  note "a cache too small for the pinned set fails and says so"
  expect_clean_failure "$VTS" warm "$url" --cache-dir "$WORK/small" --cache-size 2K --json
  ((RC == 6 || RC == 4)) || { show_output; fail "too small a cache exited $RC, expected 6 or 4"; }
  grep -q 'vts: error: .*cache' "$ERR" || { show_output; fail "no error naming the cache"; }
  json_check "$OUT" 'j.complete === false && j.disk_error' "JSON names the disk error"
  expect_valid_cache "$WORK/small"
  stop_server
}

part_subset() {
  expect_ok "$VTS" build --synthetic 2048x1024 -o "$WORK/syn.pmtiles"
  start_server "$WORK/syn.pmtiles"
  local url="$BASE/syn" n
  # levels region expected-count (the counts are also worked out by hand: level 3 holds 8x4
  # tiles; the region covers tiles x 1-3, y 0-2 at level 3, 2x2 at level 2, 1 at levels 1 and 0).
  while read -r levels region count; do
    local dir="$WORK/c_${levels}_${region//,/_}" z0 z1 args=()
    z0=${levels%-*} z1=${levels#*-}
    [[ $levels == all ]] && z0=0 z1=3
    [[ $levels != all ]] && args+=(--levels "$levels")
    local r=(0 0 2048 1024)
    if [[ $region != all ]]; then
      args+=(--region "$region")
      IFS=, read -r -a r <<<"$region"
    fi
    note "--levels $levels --region $region: $count tiles"
    warm_json "$url" --cache-dir "$dir" "${args[@]}"
    json_check "$LOGS/warm.json" "j.tiles_total == $count && j.from_network == $count &&
      j.complete" "$count tiles"
    tile_list 2048 1024 256 "$z0" "$z1" "${r[@]}" >"$LOGS/want.txt"
    n=$(wc -l <"$LOGS/want.txt")
    ((n == count)) || fail "the geometry gives $n tiles for $levels/$region, the table says $count"
    expect_tiles "$dir" "$LOGS/want.txt"
    expect_cached "$dir" "$count"
  done <<'EOF'
2-3 all 40
1-1 all 2
3 all 32
all 300,200,900,700 15
2-3 300,200,900,700 13
3 2047,1023,2048,1024 1
all 0,0,1,1 4
EOF
  stop_server
}

part_crash() {
  # 8192x8192 in 64-texel tiles: 21845 tiles, enough for a warm to take a few seconds.
  expect_ok "$VTS" build --synthetic 8192x8192 --tile 64 -o "$WORK/t64.pmtiles"
  local total=21845
  start_server "$WORK/t64.pmtiles"
  local url="$BASE/t64" dir="$WORK/cache" killed=0 round ms rc before=0 now pid i

  note "SIGINT stops cleanly: exit 130, every tile reported fetched is in a valid cache"
  # SIGINT only once warm is fetching (it has the cache open), not while the process starts: a
  # signal before its handler is installed would kill it without a word.
  "$VTS" warm "$url" --cache-dir "$WORK/int" --json --concurrency 1 >"$OUT" 2>"$ERR" </dev/null &
  pid=$!
  for ((i = 0; i < 1000; i++)); do
    readlink "/proc/$pid/fd/"* 2>/dev/null | grep -q 'cache\.db$' && break
    kill -0 "$pid" 2>/dev/null || break
    sleep 0.01
  done
  sleep 0.3
  kill -INT "$pid" 2>/dev/null || true
  RC=0
  { wait "$pid"; } 2>/dev/null || RC=$?
  ((RC != 0)) || fail "warm finished before SIGINT, so nothing was interrupted (raise the size)"
  ((RC == 130)) || { show_output; fail "warm after SIGINT exited $RC, expected 130"; }
  json_check "$OUT" "j.interrupted === true && j.complete === false && j.from_network > 0 &&
    j.from_network < $total" "JSON reports the interruption"
  grep -q 'interrupted' "$ERR" || { show_output; fail "no message about the interruption"; }
  expect_valid_cache "$WORK/int"
  expect_cached "$WORK/int" "$(json_get "$OUT" j.from_network)"

  # Each round waits until warm has the cache open (the process takes a while to start), then
  # kills it 50-500 ms later: mid-fetch, mid-write or mid-commit.
  note "kill -9 at random moments"
  for round in $(seq 1 12); do
    ms=$((50 + RANDOM % 451))
    "$VTS" warm "$url" --cache-dir "$dir" --concurrency 1 -q >"$OUT" 2>"$ERR" </dev/null &
    pid=$!
    for ((i = 0; i < 1000; i++)); do
      readlink "/proc/$pid/fd/"* 2>/dev/null | grep -q 'cache\.db$' && break
      kill -0 "$pid" 2>/dev/null || break
      sleep 0.01
    done
    sleep "$(printf '0.%03d' "$ms")"
    kill -9 "$pid" 2>/dev/null || true
    rc=0
    { wait "$pid"; } 2>/dev/null || rc=$?
    if ((rc == 137)); then
      killed=$((killed + 1))
    elif ((rc != 0)); then
      show_output
      fail "warm exited $rc before it was killed"
    fi
    expect_valid_cache "$dir"
    now=$(sql "$dir" 'SELECT count(*) FROM tiles WHERE pinned = 1')
    note "round $round: killed $ms ms after opening the cache (exit $rc), $now tiles cached"
    ((now >= before)) || fail "the cache lost tiles: $before before, $now now"
    before=$now
  done
  ((killed >= 8)) || fail "only $killed of 12 warms were killed mid-way"
  ((before < total)) || fail "the killed warms completed the cache; the resume tests nothing"

  note "warm resumes to completion"
  warm_json "$url" --cache-dir "$dir"
  json_check "$LOGS/warm.json" "j.tiles_total == $total && j.complete &&
    j.from_network + j.already_cached == $total && j.already_cached == $before" \
    "resumed: $before from the cache, the rest from the network"
  expect_cached "$dir" "$total"
  expect_valid_cache "$dir"
  stop_server
}

part_bad_input() {
  expect_ok "$VTS" build --synthetic 2048x1024 -o "$WORK/syn.pmtiles"
  start_server "$WORK/syn.pmtiles"
  local dir="$WORK/never"
  # expect_rejected WANT_PATTERN ARGS...: warm fails cleanly, says WANT_PATTERN, creates nothing.
  expect_rejected() {
    local want=$1
    shift
    expect_clean_failure "$VTS" warm "$@" --cache-dir "$dir"
    grep -qiE -e "$want" "$ERR" || { show_output; fail "'warm $*': no message matching '$want'"; }
    [[ ! -e $dir ]] || fail "'warm $*' created $dir"
  }
  expect_rejected 'refused|connect' http://127.0.0.1:1/syn
  expect_rejected 'no tileset|404' "$BASE/nosuch"
  expect_rejected 'not|no such' "$WORK/missing.pmtiles"
  expect_rejected '--levels' "$BASE/syn" --levels 3-1
  expect_rejected '--levels' "$BASE/syn" --levels x
  expect_rejected '--levels.*levels 0-3' "$BASE/syn" --levels 0-9
  expect_rejected '--region' "$BASE/syn" --region 1,2,3
  expect_rejected '--region' "$BASE/syn" --region 5,5,5,9
  expect_rejected '--region.*beyond' "$BASE/syn" --region 0,0,4096,10
  expect_rejected '--cache-size' "$BASE/syn" --cache-size 10X
  expect_rejected '--cache-size' "$BASE/syn" --cache-size 0
  expect_rejected 'concurrency' "$BASE/syn" --concurrency 0
  stop_server
}

# bbox_tiles SCHEME MAXZ T BOUNDS BBOX: "z x y" of every tile over BBOX clipped to BOUNDS (both
# W,S,E,N degrees), by docs/FORMAT.md §6's footprint rule restated in Python; nothing if disjoint.
bbox_tiles() {
  python3 - "$@" <<'PY'
import math, sys
scheme, maxz, T = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
bw, bs, be, bn = map(float, sys.argv[4].split(","))
w, s, e, n = map(float, sys.argv[5].split(","))
w, s, e, n = max(w, bw), max(s, bs), min(e, be), min(n, bn)
if w >= e or s >= n:
    sys.exit(0)
N = T * 2 ** maxz
def tx(lon): return (lon + 180) / 360 * N
def ty(lat):
    if scheme == "WorldCRS84Quad": return (90 - lat) / 360 * N
    return (1 - math.log(math.tan(math.pi / 4 + math.radians(lat) / 2)) / math.pi) / 2 * N
def snap(v): return round(v) if abs(v - round(v)) < 1e-6 else v
W, H = N, (N // 2 if scheme == "WorldCRS84Quad" else N)
x0, y0 = max(math.floor(snap(tx(w))), 0), max(math.floor(snap(ty(n))), 0)
x1, y1 = min(math.ceil(snap(tx(e))), W), min(math.ceil(snap(ty(s))), H)
for z in range(maxz + 1):
    d = maxz - z
    lx0, ly0, lx1, ly1 = x0 >> d, y0 >> d, -(-x1 // 2 ** d), -(-y1 // 2 ** d)
    for y in range(ly0 // T, -(-ly1 // T)):
        for x in range(lx0 // T, -(-lx1 // T)):
            print(z, x, y)
PY
}

part_bbox() {
  # WorldCRS84Quad TMS levels 0-5 = our levels 0-6 (16384 x 8192); WebMercatorQuad levels 0-6.
  local geo_bounds="-10.5,35.25,30.125,60.1" web_bounds="2.2,48.8,2.5,48.95"
  expect_ok "$VTS" build --synthetic 16384x8192 --tiling WorldCRS84Quad --bbox="$geo_bounds" \
    -o "$WORK/geo.pmtiles" --threads 2
  expect_ok "$VTS" build --synthetic 16384x16384 --tiling WebMercatorQuad --bbox="$web_bounds" \
    -o "$WORK/web.pmtiles" --threads 2
  expect_ok "$VTS" build --synthetic 2048x1024 -o "$WORK/syn.pmtiles"
  start_server "$WORK/geo.pmtiles" "$WORK/web.pmtiles" "$WORK/syn.pmtiles"
  local name scheme bounds bbox count i=0 dir
  # archive bbox: inside the footprint, straddling its edges, the whole world, a sliver thinner
  # than a texel; around Paris on Web Mercator (inside, and a box holding the whole footprint).
  while read -r name bbox; do
    i=$((i + 1))
    dir="$WORK/b$i"
    if [[ $name == geo ]]; then scheme=WorldCRS84Quad bounds=$geo_bounds; else
      scheme=WebMercatorQuad bounds=$web_bounds
    fi
    bbox_tiles "$scheme" 6 256 "$bounds" "$bbox" >"$LOGS/want.txt"
    count=$(wc -l <"$LOGS/want.txt")
    note "$name --bbox $bbox: $count tiles (Python, FORMAT.md §6)"
    ((count > 0)) || fail "the table's box $bbox misses the footprint"
    warm_json "$BASE/$name" --cache-dir "$dir" --bbox="$bbox"
    json_check "$LOGS/warm.json" "j.tiles_total == $count && j.from_network == $count &&
      j.absent == 0 && j.failed == 0 && j.complete && j.bbox.join() == [$bbox].join()" \
      "$count tiles, none absent"
    expect_tiles "$dir" "$LOGS/want.txt"
    expect_cached "$dir" "$count"
  done <<'EOF'
geo 0,40,10,50
geo -20,30,0,45
geo -180,-90,180,90
geo 12.0001,44.5,12.0002,44.50001
web 2.3,48.85,2.35,48.9
web 2,48,3,49
EOF
  note "a box outside the footprint warms nothing and says so (exit 0)"
  warm_json "$BASE/geo" --cache-dir "$WORK/outside" --bbox=100,0,110,10
  json_check "$LOGS/warm.json" "j.tiles_total == 0 && j.from_network == 0 && j.absent == 0 &&
    j.complete" "nothing to warm"
  grep -q "does not overlap" "$ERR" || { show_output; fail "no note that the box misses"; }
  note "refusals (exit 2): no georeference, malformed or inverted boxes, --bbox with --region"
  local bad args
  for bad in "syn --bbox=0,0,1,1:georeference" "geo --bbox=0,0,1:W,S,E,N" \
    "geo --bbox=10,0,5,1:west < east" "geo --bbox=0,0,nan,1:W,S,E,N" \
    "geo --bbox=0,0,1,1 --region 0,0,1,1:excludes"; do
    read -r -a args <<<"${bad%%:*}"
    expect_clean_failure "$VTS" warm "$BASE/${args[0]}" "${args[@]:1}" --cache-dir "$WORK/never"
    ((RC == 2)) || { show_output; fail "warm ${bad%%:*} exited $RC, expected 2"; }
    grep -q -- "${bad#*:}" "$ERR" || { show_output; fail "warm ${bad%%:*}: no '${bad#*:}'"; }
    [[ ! -e $WORK/never ]] || fail "warm ${bad%%:*} created a cache folder"
  done
  stop_server
}

case $PART in
  fill) part_fill ;;
  subset) part_subset ;;
  crash) part_crash ;;
  bad_input) part_bad_input ;;
  bbox) part_bbox ;;
  *) fail "unknown part '$PART'" ;;
esac
note "PASS"
