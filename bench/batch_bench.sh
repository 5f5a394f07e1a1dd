#!/usr/bin/env bash
# Batch engines benchmark: one input built three ways in one run, wall time of each from the
# command to the finished archive — one `vts build`; the planned build on this machine
# (deploy/batch/local/run-shards.sh); the same plan on a real one-node Slurm cluster started here
# (tests/integration/slurm_lib.sh: slurm-wlm and munge on loopback, as root), submitted with
# deploy/batch/slurm/submit.sh (arrays under MaxArraySize, then the apex and merge held by
# afterok). Fails (exit 1) unless the three archives are byte-identical (sha256).
#
#   sudo bash bench/batch_bench.sh [--input IMAGE] [--shards N] [--max-array M] [--vts PATH]
#                                  [--out FILE] [--json]
#
#   --input      the image (default: bench/.cache/earth_16384x8192.tif, the Earth upscaled 8x as
#                an uncompressed TIFF, made once with oiiotool)
#   --shards     `vts plan --shards N` (default 16: the plan may have more, see docs/PLANET.md)
#   --max-array  the cluster's MaxArraySize (default 1001, Slurm's default; a smaller one makes
#                submit.sh cut the shards into several arrays)
#
# Both engines get the same machine: run-shards.sh runs nproc/2 shards at once (its default) and
# the Slurm node has nproc CPUs for build.sbatch's 2-CPU tasks, so nproc/2 tasks at once; every
# shard uses vts's default thread count, as the single build does. The Slurm figure is from
# submit.sh to the finish job's end: scheduling, the tasks' starts and the dependency included,
# not the cluster's own start. Logs and archives in bench/.cache/batch_out/.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
# shellcheck source=../tests/integration/slurm_lib.sh
source "$ROOT/tests/integration/slurm_lib.sh"
fail() { die "$@"; }

OUT_FILE=""
VTS_ARG=""
INPUT=""
SHARDS=16
MAX_ARRAY=1001
JSON=0
while (($#)); do
  case "$1" in
    --shards) (($# >= 2)) || die "--shards needs a value"; SHARDS=$2; shift 2 ;;
    --max-array) (($# >= 2)) || die "--max-array needs a value"; MAX_ARRAY=$2; shift 2 ;;
    --json) JSON=1; shift ;;
    *) bench_option "$@"; shift "$OPT_SHIFT" ;;
  esac
done
[[ $SHARDS =~ ^[1-9][0-9]*$ ]] || die "--shards must be a positive integer, not '$SHARDS'"
[[ $MAX_ARRAY =~ ^[1-9][0-9]*$ ]] || die "--max-array must be a positive integer, not '$MAX_ARRAY'"
need python3 sha256sum ss
VTS=$(find_vts "$VTS_ARG")
VTS=$(realpath "$VTS")
export VTS
INPUT_ARG=$INPUT # for the report
[[ -n $INPUT ]] || INPUT=$(earth_16k_tif)
[[ -r $INPUT ]] || die "cannot read input $INPUT"
INPUT=$(realpath "$INPUT")
cat "$INPUT" >/dev/null # into the page cache, for every run alike

WORK=$CACHE/batch_out
rm -rf "$WORK"
mkdir -p "$WORK"/{single,local,slurm,joblogs}
trap slurm_stop EXIT

# now: seconds since the epoch, to the millisecond.
now() { date +%s.%3N; }
secs() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.2f", b - a }'; }

echo "[bench] one vts build" >&2
t0=$(now)
"$VTS" build "$INPUT" -o "$WORK/single/earth.pmtiles" -q || die "vts build failed"
SINGLE=$(secs "$t0" "$(now)")

"$VTS" plan "$INPUT" -o "$WORK/plan.json" --shards "$SHARDS" --json >"$WORK/plan.out" ||
  die "vts plan failed: $(cat "$WORK/plan.out")"
N=$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["shards"])' "$WORK/plan.out")

echo "[bench] run-shards.sh: $N shards" >&2
t0=$(now)
bash "$ROOT/deploy/batch/local/run-shards.sh" --vts "$VTS" --parts "$WORK/local/parts" \
  --logs "$WORK/local/logs" --out "$WORK/local/earth.pmtiles" "$WORK/plan.json" \
  >"$WORK/local/run.log" 2>&1 || die "run-shards.sh failed: $(tail -5 "$WORK/local/run.log")"
LOCAL=$(secs "$t0" "$(now)")
LOCAL_JOBS=$(($(nproc) / 2 > 0 ? $(nproc) / 2 : 1))

echo "[bench] Slurm: starting a one-node cluster (not timed)" >&2
slurm_start "$WORK/cluster" "$MAX_ARRAY" "$(nproc)"
echo "[bench] Slurm: submit.sh, $N shards" >&2
cd "$WORK/joblogs" || die "no $WORK/joblogs"
t0=$(now)
bash "$ROOT/deploy/batch/slurm/submit.sh" --json "$WORK/plan.json" "$WORK/slurm/parts" \
  "$WORK/slurm/earth.pmtiles" >"$WORK/submit.json" || die "submit.sh failed"
mapfile -t JOBS < <(python3 -c '
import json, sys
j = json.load(open(sys.argv[1]))
print("\n".join([a["job"] for a in j["arrays"]] + [j["finish"]]))' "$WORK/submit.json")
ARRAYS=$((${#JOBS[@]} - 1))
slurm_wait_jobs 3600 "${JOBS[@]}"
SLURM=$(secs "$t0" "$(now)")
for j in "${JOBS[@]}"; do
  if slurm_job_states "$j" | grep -qv ' COMPLETED$'; then
    die "Slurm job $j did not complete: $(slurm_job_states "$j" | tr '\n' ' ') (logs: $WORK/joblogs)"
  fi
done
slurm_stop

SHA=$(sha256sum <"$WORK/single/earth.pmtiles")
SAME=yes
for f in local slurm; do
  [[ $(sha256sum <"$WORK/$f/earth.pmtiles") == "$SHA" ]] || SAME=no
done
[[ $SAME == yes ]] || die "the archives differ (bench/.cache/batch_out/{single,local,slurm})"
read -r W H < <(python3 -c 'import json,sys; j=json.load(open(sys.argv[1])); print(j["width"], j["height"])' "$WORK/plan.out")

report() {
  echo "- command: \`sudo bash bench/batch_bench.sh${INPUT_ARG:+ --input $INPUT_ARG} --shards $SHARDS --max-array $MAX_ARRAY\`"
  machine_info
  echo "- input: $(basename "$INPUT") (${W}x${H}, $(mb "$(bytes_of "$INPUT")") MiB, page cache); vts build's defaults (lossless)"
  echo
  echo "| input | shards | vts build wall s | run-shards.sh wall s ($LOCAL_JOBS at once) | Slurm wall s ($ARRAYS array(s), MaxArraySize $MAX_ARRAY, submit to archive) | sha256 equal |"
  echo "| --- | ---: | ---: | ---: | ---: | --- |"
  echo "| ${W}x${H} | $N | $SINGLE | $LOCAL | $SLURM | $SAME |"
}
json() {
  printf '{"input": "%s", "width": %s, "height": %s, "shards": %s, "single_s": %s, "local_s": %s, "local_jobs": %s, "slurm_s": %s, "slurm_arrays": %s, "max_array_size": %s, "identical": true}\n' \
    "$(basename "$INPUT")" "$W" "$H" "$N" "$SINGLE" "$LOCAL" "$LOCAL_JOBS" "$SLURM" "$ARRAYS" "$MAX_ARRAY"
}
emit_report
