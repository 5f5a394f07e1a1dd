#!/usr/bin/env bash
# submit.sh: a planned build (`vts plan`) on a Slurm cluster, submitted from the login node: the
# shards as job arrays of build.sbatch, then finish.sbatch (the apex, then the merge into OUT),
# held until every array task has succeeded (--dependency=afterok on every array).
#
#   submit.sh [--throttle P] [--chunk C] [--json] PLAN PARTS_DIR OUT.pmtiles [-- SBATCH_OPTION...]
#   submit.sh --resubmit I[,J...] [--chunk C] [--json] PLAN PARTS_DIR [OUT.pmtiles] [-- SBATCH_OPTION...]
#
# A Slurm array's indexes stop below the cluster's MaxArraySize (1001 by default), far fewer than
# a planet's shards. So the shards go in arrays of at most C tasks (default: MaxArraySize, read
# with `scontrol show config`), each `--array=0-(n-1)` with VTS_SHARD_OFFSET set to its first
# shard: `vts build --plan` builds shard VTS_SHARD_OFFSET + SLURM_ARRAY_TASK_ID.
#   --throttle P  at most P tasks of each array at once (Slurm's --array=...%P). The arrays are
#                 submitted together: the cluster's own limits (partition, QOS MaxJobsPerUser)
#                 bound the total
#   --chunk C     tasks per array (at most MaxArraySize)
#   --json        print the job ids as JSON instead of text
#   --resubmit I  submit shard I again alone (a comma-separated list: those shards; "missing":
#                 every shard without a part in PARTS_DIR), in an array of the same chunk and
#                 offset as at first; with OUT, a finish job after it
#   -- ...        options for every sbatch (--partition, --account, --time, ...)
# The shard count is read from PLAN (python3). PLAN, PARTS_DIR and OUT must be on a file system
# every node sees; PARTS_DIR and OUT's folder are created here and must take a file. The jobs run
# `vts` from PATH, or $VTS (sbatch passes the environment on). Their logs, vts-shard-%A_%a.out
# and vts-merge-%j.out, go to the folder sbatch is run from.
#
# A failed shard: afterok is then never satisfied, so the finish job stays pending for ever
# (Reason=DependencyNeverSatisfied). Cancel it and resubmit the failed shards with a new finish
# job; the other parts are kept:
#   scancel FINISH_JOB; submit.sh --resubmit I PLAN PARTS_DIR OUT.pmtiles
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
BATCH_PROG=submit
die() {
  printf 'submit: %s\n' "$*" >&2
  exit 2
}
# shellcheck source-path=SCRIPTDIR source=../lib.sh
source "$here/../lib.sh"

throttle="" chunk="" json=0 resubmit=""
args=() extra=()
while (($#)); do
  case $1 in
    --throttle) throttle=${2:?--throttle needs a number}; shift 2 ;;
    --chunk) chunk=${2:?--chunk needs a number}; shift 2 ;;
    --json) json=1; shift ;;
    --resubmit) resubmit=${2:?--resubmit needs a shard index}; shift 2 ;;
    -h | --help) sed -n '2,/^set -euo/{/^set -euo/d;s/^# \{0,1\}//;p}' "$0"; exit 0 ;;
    --) shift; extra=("$@"); break ;;
    -*) die "unknown option $1 (see --help)" ;;
    *) args+=("$1"); shift ;;
  esac
done
if [[ -n $resubmit ]]; then
  ((${#args[@]} == 2 || ${#args[@]} == 3)) || die "usage: submit.sh --resubmit I PLAN PARTS_DIR [OUT.pmtiles]"
  [[ $resubmit == missing || $resubmit =~ ^[0-9]+(,[0-9]+)*$ ]] ||
    die "--resubmit takes shard indexes (I or I,J,...) or 'missing', not '$resubmit'"
else
  ((${#args[@]} == 3)) || die "usage: submit.sh [--throttle P] [--chunk C] [--json] PLAN PARTS_DIR OUT.pmtiles (see --help)"
fi
[[ -z $throttle || $throttle =~ ^[1-9][0-9]*$ ]] || die "--throttle must be a positive integer, not '$throttle'"
[[ -z $chunk || $chunk =~ ^[1-9][0-9]*$ ]] || die "--chunk must be a positive integer, not '$chunk'"
command -v sbatch >/dev/null 2>&1 || die "no sbatch on PATH (run this on a Slurm login node)"

# Absolute paths: the jobs may start in another folder than this one.
plan=$(realpath -m -- "${args[0]}")
parts=$(realpath -m -- "${args[1]}")
out=""
((${#args[@]} < 3)) || out=$(realpath -m -- "${args[2]}")
[[ -r $plan ]] || die "cannot read the plan $plan"

n=$(plan_shard_count "$plan") || exit 2

max=$(scontrol show config 2>/dev/null | awk '$1 == "MaxArraySize" { print $3 }') || true
[[ $max =~ ^[0-9]+$ ]] || die "cannot read MaxArraySize from \`scontrol show config\` (is this a Slurm login node?)"
chunk=${chunk:-$max}
((chunk <= max)) || die "--chunk $chunk: the cluster's MaxArraySize is $max (array indexes 0..$((max - 1)))"

writable_folder "$parts" "PARTS_DIR"
[[ -z $out ]] || writable_folder "$(dirname -- "$out")" "the folder of OUT"

# submit ARGS...: sbatch --parsable; prints the job id (without a ";cluster" suffix).
submit() {
  local id
  id=$(sbatch --parsable "${extra[@]}" "$@") || die "sbatch $* failed"
  printf '%s\n' "${id%%;*}"
}

# array OFFSET SPEC: an array of build.sbatch building shards OFFSET + each index of SPEC.
array() {
  submit --array="$2${throttle:+%$throttle}" --export="ALL,VTS_SHARD_OFFSET=$1" \
    "$here/build.sbatch" "$plan" "$parts"
}

jobs=() arrays_json=()
if [[ -z $resubmit ]]; then
  for ((first = 0; first < n; first += chunk)); do
    count=$((n - first < chunk ? n - first : chunk))
    id=$(array "$first" "0-$((count - 1))") || exit 2
    jobs+=("$id")
    arrays_json+=("{\"job\": \"${jobs[-1]}\", \"first_shard\": $first, \"shards\": $count}")
    ((json)) || printf 'submit: shards %d-%d: job %s\n' "$first" "$((first + count - 1))" "${jobs[-1]}"
  done
else
  # The shards of one chunk go in one array, with the offset and task indexes of the first
  # submission (the same SLURM_ARRAY_TASK_ID as the task that failed).
  declare -A tasks=()
  wanted=()
  if [[ $resubmit == missing ]]; then
    for ((i = 0; i < n; i++)); do
      [[ -e $(printf '%s/shard-%06d.part' "$parts" "$i") ]] || wanted+=("$i")
    done
    ((${#wanted[@]})) || die "--resubmit missing: every shard has a part in $parts"
  else
    IFS=, read -ra wanted <<<"$resubmit"
  fi
  for i in "${wanted[@]}"; do
    i=$((10#$i))
    ((i < n)) || die "--resubmit $i: the plan has $n shards (0..$((n - 1)))"
    first=$((i / chunk * chunk))
    tasks[$first]+="${tasks[$first]:+,}$((i - first))"
  done
  for first in "${!tasks[@]}"; do
    id=$(array "$first" "${tasks[$first]}") || exit 2
    jobs+=("$id")
    arrays_json+=("{\"job\": \"${jobs[-1]}\", \"first_shard\": $first, \"tasks\": \"${tasks[$first]}\"}")
    ((json)) || printf 'submit: shards %s of the array at offset %d: job %s\n' \
      "${tasks[$first]}" "$first" "${jobs[-1]}"
  done
fi

finish=""
if [[ -n $out ]]; then
  dep=$(IFS=:; printf '%s' "${jobs[*]}")
  finish=$(submit --dependency="afterok:$dep" "$here/finish.sbatch" "$plan" "$parts" "$out") || exit 2
fi
if ((json)); then
  printf '{"shards": %d, "max_array_size": %d, "chunk": %d, "arrays": [%s], "finish": "%s"}\n' \
    "$n" "$max" "$chunk" "$(IFS=,; printf '%s' "${arrays_json[*]}")" "$finish"
elif [[ -n $finish ]]; then
  printf 'submit: apex and merge into %s: job %s, after %s\n' "$out" "$finish" "${jobs[*]}"
  printf 'submit: if shard I fails, job %s never starts: scancel %s; %s --resubmit I %s %s %s\n' \
    "$finish" "$finish" "$0" "$plan" "$parts" "$out"
fi
