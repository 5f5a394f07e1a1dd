#!/usr/bin/env bash
# Sharded build benchmark (issue 20): what cutting one `vts build` into N shards costs on this
# machine. Runs the single `vts build` of the input, then for each N: `vts plan --shards N`, every
# shard (`vts build --plan P --shard I --out-dir parts/ --json`) JOBS at a time, the apex
# (`--apex`) and `vts merge`, each under /usr/bin/time -v; checks that the merged archive is the
# single build's byte for byte (sha256) and fails loudly (exit 1) when it is not.
#
#   bash bench/shard_bench.sh [--small] [--input IMAGE] [--shards "1 4 16"] [--jobs 2]
#                             [--codec C] [--vts PATH] [--out FILE] [--json] [--keep]
#
#   --small     the 16384x8192 uncompressed TIFF of build_bench.sh instead (a quick check)
#   --input     another image (default: the 100000x50000 tiled JPEG BigTIFF of memory_bench.sh,
#               bench/.cache/earth_100000x50000.tif, made once by vips)
#   --shards    the N to plan for (`vts plan --shards N`: at least N shards, so the plan may have
#               more: the smallest split level L giving N; apex level min(L + 2, finest))
#   --jobs      shards run at once (default 2, the issue's setting on this 2-core machine; each
#               shard uses the machine's default thread count, like the single build)
#   --codec     passed to `vts build` and `vts plan` (default: vts build's, lossless)
#   --json      print one JSON object on stdout; the table goes to stderr (and --out)
#   --keep      keep the archives and parts in bench/.cache/shard_out/ (default: only the logs)
#
# Figures: single build wall, CPU (user+sys) and peak RSS; per N the shards' summed CPU, their
# wall time as a batch, the largest shard's peak RSS, the apex's CPU, the ratio
# (sum of shard CPU + apex CPU) / single-build CPU (issue 20's bar: <= 1.10), the same ratio net
# of one process start each (the CPU of `vts --help`: loading the shared libraries), the shards' halo
# overhead (`texels_read / core_texels` of each shard's --json: mean and max), and the merge's
# wall, CPU, peak RSS and tiles/s (tiles = addressed tiles, the merge's --json "tiles"). Logs in
# bench/.cache/shard_out/.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

OUT_FILE=""
VTS_ARG=""
INPUT=""
SMALL=0
SHARDS="1 4 16"
JOBS=2
CODEC=""
JSON=0
KEEP=0
while (($#)); do
  case "$1" in
    --small) SMALL=1; shift ;;
    --shards) (($# >= 2)) || die "--shards needs a value"; SHARDS=$2; shift 2 ;;
    --jobs) (($# >= 2)) || die "--jobs needs a value"; JOBS=$2; shift 2 ;;
    --codec) (($# >= 2)) || die "--codec needs a value"; CODEC=$2; shift 2 ;;
    --json) JSON=1; shift ;;
    --keep) KEEP=1; shift ;;
    *) bench_option "$@"; shift "$OPT_SHIFT" ;;
  esac
done
[[ $JOBS =~ ^[1-9][0-9]*$ ]] || die "--jobs must be a positive integer, not '$JOBS'"
read -r -a SHARD_LIST <<<"$SHARDS"
((${#SHARD_LIST[@]})) || die "--shards needs at least one N"
for n in "${SHARD_LIST[@]}"; do
  [[ $n =~ ^[1-9][0-9]*$ ]] || die "--shards takes positive integers, not '$n'"
done

need node sha256sum
[[ -x $TIME_BIN ]] || die "missing $TIME_BIN (Debian package 'time')"
VTS=$(find_vts "$VTS_ARG")
BUILD_ARGS=()
[[ -z $CODEC ]] || BUILD_ARGS+=(--codec "$CODEC")

if [[ -z $INPUT ]]; then
  if ((SMALL)); then
    need oiiotool
    INPUT=$(earth_16k_tif)
  else
    INPUT=$(earth_100k_tif)
  fi
fi
[[ -r $INPUT ]] || die "cannot read input $INPUT"
cat "$INPUT" >/dev/null # into the page cache, for the single build and the shards alike

WORK="$CACHE/shard_out"
rm -rf "$WORK"
mkdir -p "$WORK/single"
cleanup_out() { ((KEEP)) || rm -rf "$@"; }

jget() { # FILE KEY: a top-level value of a JSON file
  node -e 'const v = JSON.parse(require("fs").readFileSync(process.argv[1]))[process.argv[2]];
    console.log(v === undefined ? "" : v)' "$1" "$2"
}
sha() { sha256sum "$1" | cut -d' ' -f1; }
now() { date +%s.%N; }
elapsed() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.2f", b - a }'; }
# step NAME JSON LOG CMD...: measure_split; dies naming the log when CMD fails.
step() {
  local name=$1 json=$2 log=$3
  shift 3
  echo "[bench] $name ..." >&2
  measure_split "$json" "$log" "$@"
  ((M_RC == 0)) || die "$name failed (exit $M_RC): $(tail -n 3 "$log"; tail -n 3 "$json")"
}

# The fixed cost of one vts process (loading its shared libraries): the least CPU of 3
# `vts --help`. Every shard, the apex and the merge pay it once; the "net" ratio takes it out.
START_CPU=""
for _ in 1 2 3; do
  measure "$WORK/start.log" "$VTS" --help
  if [[ -z $START_CPU ]] || awk -v a="$M_CPU2" -v b="$START_CPU" 'BEGIN { exit !(a < b) }'; then
    START_CPU=$M_CPU2
  fi
done

# The single build: the reference archive, its CPU the denominator of every ratio. Both archives
# are named earth.pmtiles (the name in the metadata is the output's stem).
step "single vts build" "$WORK/single.json" "$WORK/single.log" \
  "$VTS" build "$INPUT" -o "$WORK/single/earth.pmtiles" "${BUILD_ARGS[@]}" --json
S_WALL=$M_WALL S_CPU=$M_CPU2 S_RSS=$M_RSS_MB
S_TILES=$(jget "$WORK/single.json" tiles)
S_SHA=$(sha "$WORK/single/earth.pmtiles")
S_BYTES=$(bytes_of "$WORK/single/earth.pmtiles")
IN_W=$(jget "$WORK/single.json" width)
IN_H=$(jget "$WORK/single.json" height)

# run_shard DIR I: one shard under /usr/bin/time; "rc wall cpu rss" to DIR/logs/shard-I.time.
run_shard() {
  local dir=$1 i=$2 base
  base=$(printf '%s/logs/shard-%06d' "$1" "$2")
  measure_split "$base.json" "$base.log" "$VTS" build --plan "$dir/plan.json" --shard "$i" \
    --out-dir "$dir/parts" --json
  echo "$M_RC $M_WALL $M_CPU2 $M_RSS_MB" >"$base.time"
}

# halo DIR: "mean max" of the shards' halo_overhead (--json), 0 0 when none read texels.
halo() {
  node -e 'const fs = require("fs"), d = process.argv[1];
    const v = fs.readdirSync(d).filter(f => /^shard-\d+\.json$/.test(f))
      .map(f => JSON.parse(fs.readFileSync(d + "/" + f)).halo_overhead).filter(x => x > 0);
    const mean = v.length ? v.reduce((a, b) => a + b, 0) / v.length : 0;
    console.log(mean.toFixed(4), (v.length ? Math.max(...v) : 0).toFixed(4))' "$1/logs"
}

ROWS=() BARS=() JSON_RUNS=() MISMATCH=()
run_n() { # N
  local n=$1 dir="$WORK/n$1" count level apex_level i t0 t1 rc cpu rss failed=0
  mkdir -p "$dir/parts" "$dir/logs"
  step "plan --shards $n" "$dir/plan.out.json" "$dir/logs/plan.log" \
    "$VTS" plan "$INPUT" -o "$dir/plan.json" --shards "$n" "${BUILD_ARGS[@]}" --json
  local plan_cpu=$M_CPU2 plan_wall=$M_WALL
  count=$(jget "$dir/plan.out.json" shards)
  level=$(jget "$dir/plan.out.json" split_level)
  apex_level=$(jget "$dir/plan.out.json" apex_level)

  echo "[bench] $count shards (split level $level, apex level $apex_level), $JOBS at a time ..." >&2
  t0=$(now)
  for ((i = 0; i < count; i++)); do
    while (($(jobs -rp | wc -l) >= JOBS)); do wait -n || true; done
    run_shard "$dir" "$i" &
  done
  wait
  t1=$(now)
  local sh_wall sh_cpu=0 sh_rss=0
  sh_wall=$(elapsed "$t0" "$t1")
  for ((i = 0; i < count; i++)); do
    read -r rc _ cpu rss <"$(printf '%s/logs/shard-%06d.time' "$dir" "$i")"
    if ((rc != 0)); then
      echo "[bench] shard $i FAILED (exit $rc): $(printf '%s/logs/shard-%06d.log' "$dir" "$i")" >&2
      failed=1
    fi
    sh_cpu=$(awk -v a="$sh_cpu" -v b="$cpu" 'BEGIN { printf "%.2f", a + b }')
    ((rss > sh_rss)) && sh_rss=$rss
  done
  ((failed == 0)) || die "shards failed for N = $n (logs in $dir/logs)"

  local apex_cpu=0 apex_wall=0
  if ((apex_level > 0)); then
    step "apex" "$dir/logs/apex.json" "$dir/logs/apex.log" \
      "$VTS" build --plan "$dir/plan.json" --apex --out-dir "$dir/parts" --json
    apex_cpu=$M_CPU2 apex_wall=$M_WALL
  fi
  step "merge" "$dir/merge.json" "$dir/logs/merge.log" \
    "$VTS" merge --plan "$dir/plan.json" "$dir/parts" -o "$dir/earth.pmtiles" --json
  local m_wall=$M_WALL m_cpu=$M_CPU2 m_rss=$M_RSS_MB m_tiles m_rate same=yes got
  m_tiles=$(jget "$dir/merge.json" tiles)
  m_rate=$(awk -v t="$m_tiles" -v w="$m_wall" 'BEGIN { if (w > 0) printf "%.0f", t / w; else print "-" }')
  got=$(sha "$dir/earth.pmtiles")
  if [[ $got != "$S_SHA" ]]; then
    same=NO
    MISMATCH+=("$n")
    KEEP=1 # keep the evidence
    echo "[bench] N = $n: MERGED ARCHIVE DIFFERS from the single build (sha256 $got, single $S_SHA)" >&2
  fi
  cleanup_out "$dir/parts" "$dir/earth.pmtiles"

  local build_cpu ratio net_ratio all_ratio halo_mean halo_max total_wall
  build_cpu=$(awk -v a="$sh_cpu" -v b="$apex_cpu" 'BEGIN { printf "%.2f", a + b }')
  ratio=$(ratio "$build_cpu" "$S_CPU")
  net_ratio=$(awk -v b="$build_cpu" -v s="$S_CPU" -v p="$((count + (level > 0)))" -v c="$START_CPU" \
    'BEGIN { printf "%.2f", (b - p * c) / (s - c) }')
  all_ratio=$(awk -v a="$build_cpu" -v p="$plan_cpu" -v m="$m_cpu" -v s="$S_CPU" \
    'BEGIN { printf "%.2f", (a + p + m) / s }')
  read -r halo_mean halo_max < <(halo "$dir")
  total_wall=$(awk -v a="$plan_wall" -v b="$sh_wall" -v c="$apex_wall" -v d="$m_wall" \
    'BEGIN { printf "%.2f", a + b + c + d }')
  ROWS+=("| $n | $count (L $level) | $sh_wall | $sh_cpu | $sh_rss | $apex_cpu | $ratio | $net_ratio | $halo_mean ($halo_max) | $m_wall | $m_cpu | $m_rss | $m_rate | $total_wall | $all_ratio | $same |")
  if awk -v r="$ratio" 'BEGIN { exit !(r <= 1.10) }'; then
    BARS+=("- N = $n ($count shards): (shard + apex CPU) / single-build CPU = $ratio: bar (<= 1.10) met.")
  else
    BARS+=("- N = $n ($count shards): (shard + apex CPU) / single-build CPU = $ratio: bar (<= 1.10) NOT met.")
  fi
  JSON_RUNS+=("$(printf '{"shards_asked":%s,"shards":%s,"split_level":%s,"plan_wall_s":%s,"plan_cpu_s":%s,"shards_wall_s":%s,"shards_cpu_s":%s,"shard_max_rss_mib":%s,"apex_wall_s":%s,"apex_cpu_s":%s,"cpu_ratio":%s,"cpu_ratio_net_of_start":%s,"cpu_ratio_with_plan_and_merge":%s,"halo_overhead_mean":%s,"halo_overhead_max":%s,"merge_wall_s":%s,"merge_cpu_s":%s,"merge_peak_rss_mib":%s,"merge_tiles":%s,"merge_tiles_per_s":%s,"total_wall_s":%s,"identical":%s}' \
    "$n" "$count" "$level" "$plan_wall" "$plan_cpu" "$sh_wall" "$sh_cpu" "$sh_rss" "$apex_wall" \
    "$apex_cpu" "$ratio" "$net_ratio" "$all_ratio" "$halo_mean" "$halo_max" "$m_wall" "$m_cpu" "$m_rss" \
    "$m_tiles" "${m_rate/-/0}" "$total_wall" "$([[ $same == yes ]] && echo true || echo false)")")
}

for n in "${SHARD_LIST[@]}"; do
  run_n "$n"
done

report() {
  echo "## Sharded builds: ${IN_W}x${IN_H}, N = ${SHARD_LIST[*]}, $JOBS shards at a time"
  echo
  machine_info
  echo "- input: $(basename "$INPUT") ($(mb "$(bytes_of "$INPUT")") MiB, read from the page cache)"
  echo "- options: ${BUILD_ARGS[*]:-defaults (lossless)}; each run uses the default thread count"
  echo "- one vts process's start (\`vts --help\`, least of 3): $START_CPU s CPU; the net ratio takes it out once per shard, apex and single build"
  echo "- single \`vts build\`: wall $S_WALL s, CPU $S_CPU s, peak RSS $S_RSS MiB, $S_TILES tiles, $(mb "$S_BYTES") MiB"
  echo
  echo "| N | shards | shards wall s | shards CPU s | shard peak RSS MiB | apex CPU s | (shards + apex) / single CPU | the same net of process start | halo overhead mean (max) | merge wall s | merge CPU s | merge peak RSS MiB | merge tiles/s | plan to archive wall s | all CPU / single | sha256 = single |"
  echo "| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |"
  printf '%s\n' "${ROWS[@]}"
  echo
  printf '%s\n' "${BARS[@]}"
  if ((${#MISMATCH[@]})); then
    echo "- MERGED ARCHIVE DIFFERS from the single build for N = ${MISMATCH[*]} (both kept in $WORK)"
  else
    echo "- every merged archive is the single build's, byte for byte (sha256 $S_SHA)."
  fi
}
json() {
  local runs
  runs=$(IFS=,; echo "${JSON_RUNS[*]}")
  printf '{"input":"%s","width":%s,"height":%s,"codec":"%s","jobs":%s,"cores":%s,"process_start_cpu_s":%s,"single":{"wall_s":%s,"cpu_s":%s,"peak_rss_mib":%s,"tiles":%s,"bytes":%s,"sha256":"%s"},"runs":[%s]}\n' \
    "$(basename "$INPUT")" "$IN_W" "$IN_H" "${CODEC:-default}" "$JOBS" "$(nproc)" "$START_CPU" "$S_WALL" \
    "$S_CPU" "$S_RSS" "$S_TILES" "$S_BYTES" "$S_SHA" "$runs"
}

emit_report
((${#MISMATCH[@]} == 0)) || die "merged archive differs from the single build for N = ${MISMATCH[*]}"
cleanup_out "$WORK/single"
