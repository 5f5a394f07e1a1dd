#!/usr/bin/env bash
# Set merge benchmark (issue 32): the merge of a build's parts into one archive against the
# merges of the same parts into a set of P archives (`vts plan --archive-level K`, one
# `vts merge --plan P PARTS -o DIR/ --archive I` per archive, one after another, then
# `--manifest`). The issue's bar: the P merges together within 1.10x of the one-file merge's CPU
# time and bytes written, each doing about 1/P of it (so P machines merge in about 1/P of the time).
#
#   bash bench/set_merge_bench.sh [--sets "4 16"] [--runs 3] [--modes "verify no-verify"]
#                                 [--synthetic WxH] [--tile T] [--input IMAGE] [--vts PATH]
#                                 [--out FILE] [--keep]
#
#   --sets       the P to aim at: for each, the archive level K whose set has N - 1 archives under
#                the top closest to P (N from `vts plan --archive-level K --json`'s "archives")
#   --runs       runs of each merge (default 3); the table shows each one's median run (by CPU)
#   --modes      verify (the default merge: every payload checked against its checksum) and/or
#                no-verify (`--no-verify`: payloads copied in the kernel, copy_file_range)
#   --synthetic  the built-in synthetic source of WxH texels (default 16384x16384), built with
#                --filter none --tile T (default 64): ~1.1 GB, 87,381 tiles of ~13 KB, about the
#                shape of shard_bench's 100000x50000 Earth (1 GB, 102,326 tiles) and quick to make
#   --input      an image instead of the synthetic source (plan defaults otherwise)
#   --keep       keep the outputs in bench/.cache/set_merge/ (default: only the parts and logs)
#
# The parts (`vts plan --shards 16`, every shard two at a time, the apex) are made once, not timed,
# and kept in bench/.cache/set_merge/parts while the plan's build hash is the same; the archive level
# is not in the build hash, so the one-file plan and every set's plan merge the same parts (each set
# plan is made with the one-file plan's split level and checked to have its build hash). Each merge
# runs under /usr/bin/time -v: CPU (user + sys), wall, peak RSS; bytes written are the sizes of
# the archives (and manifest) it wrote. Each set is joined once (`vts merge --join`, not timed) and
# must give the one-file archive byte for byte. The outputs are deleted after each run.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

OUT_FILE=""
VTS_ARG=""
INPUT=""
SETS="4 16"
RUNS=3
MODES="verify no-verify"
SYNTH=16384x16384
TILE=64
KEEP=0
while (($#)); do
  case "$1" in
    --sets) (($# >= 2)) || die "--sets needs a value"; SETS=$2; shift 2 ;;
    --runs) (($# >= 2)) || die "--runs needs a value"; RUNS=$2; shift 2 ;;
    --modes) (($# >= 2)) || die "--modes needs a value"; MODES=$2; shift 2 ;;
    --synthetic) (($# >= 2)) || die "--synthetic needs a value"; SYNTH=$2; shift 2 ;;
    --tile) (($# >= 2)) || die "--tile needs a value"; TILE=$2; shift 2 ;;
    --keep) KEEP=1; shift ;;
    *) bench_option "$@"; shift "$OPT_SHIFT" ;;
  esac
done
[[ $RUNS =~ ^[1-9][0-9]*$ ]] || die "--runs must be a positive integer, not '$RUNS'"
read -r -a SET_LIST <<<"$SETS"
read -r -a MODE_LIST <<<"$MODES"
((${#SET_LIST[@]})) || die "--sets needs at least one P"
for p in "${SET_LIST[@]}"; do
  [[ $p =~ ^[1-9][0-9]*$ ]] || die "--sets takes positive integers, not '$p'"
done
for m in "${MODE_LIST[@]}"; do
  [[ $m == verify || $m == no-verify ]] || die "--modes takes verify and no-verify, not '$m'"
done

need node sha256sum xargs
[[ -x $TIME_BIN ]] || die "missing $TIME_BIN (Debian package 'time')"
VTS=$(find_vts "$VTS_ARG")

if [[ -n $INPUT ]]; then
  [[ -r $INPUT ]] || die "cannot read input $INPUT"
  SRC=("$INPUT" --name syn)
  SRC_DESC="$(basename "$INPUT") (plan defaults)"
else
  SRC=(--synthetic "$SYNTH" --filter none --tile "$TILE" --name syn)
  SRC_DESC="\`--synthetic $SYNTH --filter none --tile $TILE\` (lossless)"
fi

W="$CACHE/set_merge"
mkdir -p "$W/logs"
rm -rf "$W/out"
mkdir -p "$W/out"
jget() { # FILE EXPR: a value of a JSON file (j is the parsed file)
  node -e 'const j = JSON.parse(require("fs").readFileSync(process.argv[1]));
    const v = eval(process.argv[2]); console.log(v === undefined || v === null ? "" : v)' "$1" "$2"
}
sha() { sha256sum "$1" | cut -d' ' -f1; }
add() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.2f", a + b }'; }
max() { awk -v a="$1" -v b="$2" 'BEGIN { print (a + 0 > b + 0) ? a : b }'; }
# step LOG CMD...: measure; dies naming the log when CMD fails. Also sets M_USER and M_SYS.
step() {
  local log=$1 tf
  shift
  tf=$(mktemp)
  measure "$log" "$TIME_BIN" -f '%U %S' -o "$tf" "$@"
  ((M_RC == 0)) || die "'$*' failed (exit $M_RC): $(tail -n 5 "$log")"
  read -r M_USER M_SYS <"$tf"
  rm -f "$tf"
}

# The one-file plan and its parts (made once per build hash).
echo "[bench] plan (one file) ..." >&2
"$VTS" plan "${SRC[@]}" -o "$W/one.plan.json" --shards 16 --json >"$W/one.plan.out.json" ||
  die "vts plan failed"
BUILD_HASH=$(jget "$W/one.plan.out.json" j.build_hash)
SPLIT=$(jget "$W/one.plan.out.json" j.split_level)
MAX_ZOOM=$(jget "$W/one.plan.out.json" j.max_zoom)
NSHARDS=$(jget "$W/one.plan.out.json" j.shards)
PARTS="$W/parts"
if [[ $(cat "$PARTS/.build_hash" 2>/dev/null) != "$BUILD_HASH" ]]; then
  echo "[bench] building the $NSHARDS shards and the apex (once, not timed) ..." >&2
  rm -rf "$PARTS"
  mkdir -p "$PARTS"
  seq 0 $((NSHARDS - 1)) | xargs -P 2 -I{} "$VTS" build --plan "$W/one.plan.json" --shard {} \
    --out-dir "$PARTS" -q --no-space-check || die "a shard failed"
  if [[ $(jget "$W/one.plan.out.json" j.apex) == true ]]; then
    "$VTS" build --plan "$W/one.plan.json" --apex --out-dir "$PARTS" -q || die "the apex failed"
  fi
  echo "$BUILD_HASH" >"$PARTS/.build_hash"
fi
PARTS_BYTES=$(bytes_of "$PARTS")
cat "$PARTS"/*.part >/dev/null # into the page cache for every merge alike

# The set plans: for each P, the archive level K with N - 1 closest to P.
declare -A K_OF N_OF
for p in "${SET_LIST[@]}"; do
  best_k="" best_d=""
  for ((k = 1; k <= MAX_ZOOM; k++)); do
    "$VTS" plan "${SRC[@]}" -o "$W/k$k.plan.json" --split-level "$SPLIT" --archive-level "$k" \
      --json >"$W/k$k.plan.out.json" || die "vts plan --archive-level $k failed"
    [[ $(jget "$W/k$k.plan.out.json" j.build_hash) == "$BUILD_HASH" ]] ||
      die "the plan with --archive-level $k has another build hash than the one-file plan's"
    n=$(jget "$W/k$k.plan.out.json" j.archives)
    d=$((n - 1 - p))
    ((d < 0)) && d=$((-d))
    if [[ -z $best_d ]] || ((d < best_d)); then best_k=$k best_d=$d; fi
    ((n - 1 > p)) && break
  done
  K_OF[$p]=$best_k
  N_OF[$p]=$(jget "$W/k$best_k.plan.out.json" j.archives)
  echo "[bench] P = $p: archive level ${K_OF[$p]}, ${N_OF[$p]} archives (the top and $((N_OF[$p] - 1)))" >&2
done

# The CPU of one `vts merge` process start (vts and vts-build loading): least of 3 `--help`.
START_CPU=""
for _ in 1 2 3; do
  step "$W/logs/start.log" "$VTS" merge --help
  if [[ -z $START_CPU ]] || awk -v a="$M_CPU2" -v b="$START_CPU" 'BEGIN { exit !(a < b) }'; then
    START_CPU=$M_CPU2
  fi
done

# Results, one line per run: MODE CONFIG RUN CPU WALL BYTES MAX_CPU MAX_WALL MAX_BYTES RSS MERGES
RES="$W/results.txt"
: >"$RES"
ONE_SHA=""
declare -A JOINED

# one_file MODE RUN: the one-file merge.
one_file() {
  local mode=$1 run=$2 args=() out="$W/out/one.pmtiles"
  [[ $mode == no-verify ]] && args=(--no-verify)
  echo "[bench] $mode run $run: one-file merge ..." >&2
  step "$W/logs/one-$mode-$run.log" "$VTS" merge --plan "$W/one.plan.json" "$PARTS" -o "$out" \
    "${args[@]}" --json
  local bytes
  bytes=$(bytes_of "$out")
  echo "$mode one $run $M_CPU2 $M_WALL $bytes $M_CPU2 $M_WALL $bytes $M_RSS_MB 1 $M_USER $M_SYS" >>"$RES"
  [[ -n ${ONE_SHA:-} ]] || ONE_SHA=$(sha "$out")
  rm -f "$out"
}

# a_set MODE RUN P: every archive of P's set, one after another, then the manifest.
a_set() {
  local mode=$1 run=$2 p=$3 args=() dir="$W/out/set$3/" k=${K_OF[$3]} n=${N_OF[$3]} i
  [[ $mode == no-verify ]] && args=(--no-verify)
  echo "[bench] $mode run $run: set of $n archives (K = $k) ..." >&2
  local cpu=0 wall=0 bytes=0 mcpu=0 mwall=0 mbytes=0 rss=0 user=0 sys=0 b name
  for ((i = 0; i < n; i++)); do
    step "$W/logs/set$p-$mode-$run-$i.log" "$VTS" merge --plan "$W/k$k.plan.json" "$PARTS" -o "$dir" \
      --archive "$i" "${args[@]}" --json
    name=$(sed -nE 's/^ *"name": "([^"]+)".*/\1/p' "$W/logs/set$p-$mode-$run-$i.log" | head -n 1)
    [[ -n $name && -s $dir/$name ]] || die "archive $i of the P = $p set: no archive named in its --json"
    b=$(bytes_of "$dir/$name")
    cpu=$(add "$cpu" "$M_CPU2") wall=$(add "$wall" "$M_WALL") bytes=$((bytes + b))
    user=$(add "$user" "$M_USER") sys=$(add "$sys" "$M_SYS")
    mcpu=$(max "$mcpu" "$M_CPU2") mwall=$(max "$mwall" "$M_WALL") rss=$(max "$rss" "$M_RSS_MB")
    ((b > mbytes)) && mbytes=$b
  done
  step "$W/logs/set$p-$mode-$run-manifest.log" "$VTS" merge --plan "$W/k$k.plan.json" "$PARTS" \
    -o "$dir" --manifest --json
  cpu=$(add "$cpu" "$M_CPU2") wall=$(add "$wall" "$M_WALL")
  user=$(add "$user" "$M_USER") sys=$(add "$sys" "$M_SYS")
  bytes=$((bytes + $(bytes_of "$dir/tileset.json")))
  echo "$mode set$p $run $cpu $wall $bytes $mcpu $mwall $mbytes $rss $((n + 1)) $user $sys" >>"$RES"
  if [[ -z ${JOINED[$p]:-} ]]; then
    echo "[bench] joining the P = $p set (not timed) ..." >&2
    "$VTS" merge --join "$dir" -o "$W/out/joined.pmtiles" -q || die "vts merge --join failed"
    JOINED[$p]=$(sha "$W/out/joined.pmtiles")
    rm -f "$W/out/joined.pmtiles"
  fi
  ((KEEP)) || rm -rf "$dir"
}

for mode in "${MODE_LIST[@]}"; do
  for ((run = 1; run <= RUNS; run++)); do
    one_file "$mode" "$run"
    for p in "${SET_LIST[@]}"; do a_set "$mode" "$run" "$p"; done
  done
done
MISMATCH=()
for p in "${SET_LIST[@]}"; do
  [[ ${JOINED[$p]} == "$ONE_SHA" ]] || MISMATCH+=("$p")
done

# median MODE CONFIG: the result line of the run with the median CPU.
median() {
  awk -v m="$1" -v c="$2" '$1 == m && $2 == c' "$RES" | sort -k4,4g |
    awk '{ l[NR] = $0 } END { print l[int((NR + 1) / 2)] }'
}
net() { # CPU PROCESSES ONE-FILE-CPU: (CPU - PROCESSES starts) / (ONE-FILE-CPU - one start)
  awk -v c="$1" -v n="$2" -v o="$3" -v s="$START_CPU" 'BEGIN { if (o - s <= 0) print "-"; else printf "%.2f", (c - n * s) / (o - s) }'
}
range_cpu() { # MODE CONFIG: "min-max" CPU of the runs
  awk -v m="$1" -v c="$2" '$1 == m && $2 == c { v = $4 + 0; if (n++ == 0 || v < lo) lo = v; if (v > hi) hi = v }
    END { printf "%.2f-%.2f", lo, hi }' "$RES"
}

report() {
  echo "## Sets: parallel merges ($(date -u '+%Y-%m-%d'))"
  echo
  machine_info
  echo "- source: $SRC_DESC, max zoom $MAX_ZOOM; parts: \`vts plan --shards 16\` ($NSHARDS shards, split level $SPLIT, and the apex), $(mb "$PARTS_BYTES") MiB, read from the page cache"
  for p in "${SET_LIST[@]}"; do
    echo "- P = $p: \`--archive-level ${K_OF[$p]}\`: ${N_OF[$p]} archives (the top and $((N_OF[$p] - 1))), merged one after another, then \`--manifest\`"
  done
  echo "- one \`vts merge\` process start (\`vts merge --help\`, least of 3): $START_CPU s CPU"
  echo "- median of $RUNS runs (by CPU) of each merge; CPU = user + sys (/usr/bin/time -v); bytes = the sizes of the files written"
  local mode one p line oc ow ob orss ou os c w b mc mw mb_ rss nproc u s
  for mode in "${MODE_LIST[@]}"; do
    echo
    echo "\`vts merge\`$([[ $mode == no-verify ]] && echo ' --no-verify') (CPU range over the runs in brackets):"
    echo
    echo "| merge | processes | CPU s | user s / sys s | wall s | MiB written | largest archive's CPU s / wall s / MiB | peak RSS MiB | CPU / one-file | the same net of process starts | user CPU / one-file | bytes / one-file | largest's CPU / one-file | largest's wall / one-file | largest's bytes / one-file | 1/P |"
    echo "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"
    one=$(median "$mode" one)
    read -r _ _ _ oc ow ob _ _ _ orss _ ou os <<<"$one"
    echo "| one file | 1 | $oc ($(range_cpu "$mode" one)) | $ou / $os | $ow | $(mb "$ob") | - | $orss | 1.00 | 1.00 | 1.00 | 1.00 | 1.00 | 1.00 | 1.00 | 1 |"
    for p in "${SET_LIST[@]}"; do
      line=$(median "$mode" "set$p")
      read -r _ _ _ c w b mc mw mb_ rss nproc u s <<<"$line"
      echo "| set, P = $((N_OF[$p] - 1)) + top | $nproc | **$c** ($(range_cpu "$mode" "set$p")) | $u / $s | $w | $(mb "$b") | $mc / $mw / $(mb "$mb_") | $rss | **$(ratio "$c" "$oc")** | $(net "$c" "$nproc" "$oc") | $(ratio "$u" "$ou") | **$(ratio "$b" "$ob")** | $(ratio "$mc" "$oc") | $(ratio "$mw" "$ow") | $(ratio "$mb_" "$ob") | $(awk -v n="$((N_OF[$p] - 1))" 'BEGIN { printf "%.3f", 1 / n }') |"
    done
    if ((${#SET_LIST[@]} >= 2)); then
      local p1=${SET_LIST[0]} p2=${SET_LIST[-1]} c1 c2 n1 n2
      read -r _ _ _ c1 _ <<<"$(median "$mode" "set$p1")"
      read -r _ _ _ c2 _ <<<"$(median "$mode" "set$p2")"
      n1=$((N_OF[$p1] + 1)) n2=$((N_OF[$p2] + 1))
      echo
      echo "Fixed cost per merge process ($mode), from the two sets' CPU: (CPU of $n2 processes - CPU of $n1) / $((n2 - n1)) = $(awk -v a="$c2" -v b="$c1" -v d="$((n2 - n1))" 'BEGIN { printf "%.3f", (a - b) / d }') s, of which $START_CPU s is the process start."
    fi
  done
  echo
  if ((${#MISMATCH[@]})); then
    echo "- THE SET DID NOT JOIN to the one-file archive for P = ${MISMATCH[*]}"
  else
    echo "- every set joined (\`vts merge --join\`) to the one-file archive byte for byte (sha256 ${ONE_SHA:0:12}…)."
  fi
}
if [[ -n $OUT_FILE ]]; then report | tee "$OUT_FILE"; else report; fi
cp "$RES" "$W/logs/results.txt"
((${#MISMATCH[@]} == 0)) || die "a set did not join to the one-file archive (P = ${MISMATCH[*]})"
