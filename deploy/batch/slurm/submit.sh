#!/usr/bin/env bash
# submit.sh: a planned build (`vts plan`) on a Slurm cluster, submitted from the login node: the
# shards as job arrays of build.sbatch, then finish.sbatch (the apex, then the merge into OUT),
# held until every array task has succeeded (--dependency=afterok on every array). For a plan of
# a set of archives (vts plan --archive-level K or --max-archive-size: `vts plan --json` says
# "archives": N), OUT is the set's folder and the merges run in parallel: apex.sbatch after the
# shards, then merge.sbatch as arrays of N tasks in all (task I merges archive I) after the apex,
# then merge.sbatch --manifest (OUT/tileset.json) after every merge task.
#
#   submit.sh [--throttle P] [--chunk C] [--json] PLAN PARTS_DIR OUT [-- SBATCH_OPTION...]
#   submit.sh --resubmit I[,J...] [--chunk C] [--json] PLAN PARTS_DIR [OUT] [-- SBATCH_OPTION...]
#   submit.sh --resubmit-merge I[,J...] [--chunk C] [--json] PLAN PARTS_DIR OUT_DIR [-- ...]
#
# OUT: OUT.pmtiles for a plan of one archive; a folder (OUT_DIR/) for a plan of a set.
# A Slurm array's indexes stop below the cluster's MaxArraySize (1001 by default), far fewer than
# a planet's shards. So the shards go in arrays of at most C tasks (default: MaxArraySize, read
# with `scontrol show config`), each `--array=0-(n-1)` with VTS_SHARD_OFFSET set to its first
# shard: `vts build --plan` builds shard VTS_SHARD_OFFSET + SLURM_ARRAY_TASK_ID. A set's merges
# are cut the same way, with VTS_ARCHIVE_OFFSET.
#   --throttle P  at most P tasks of each array at once (Slurm's --array=...%P), the shards' and
#                 the merges'. The arrays are submitted together: the cluster's own limits
#                 (partition, QOS MaxJobsPerUser) bound the total
#   --chunk C     tasks per array (at most MaxArraySize)
#   --json        print the job ids as JSON instead of text
#   --resubmit I  submit shard I again alone (a comma-separated list: those shards; "missing":
#                 every shard without a part in PARTS_DIR), in an array of the same chunk and
#                 offset as at first; with OUT, the jobs after the shards again (finish, or for a
#                 set the apex, the merges and the manifest)
#   --resubmit-merge I  a set's archive I merged again alone (a comma-separated list: those),
#                 in an array of the same chunk and offset as at first, then a manifest job
#   -- ...        options for every sbatch (--partition, --account, --time, ...)
# The shard and archive counts are read from PLAN (python3, ../plan_set.py). PLAN, PARTS_DIR and
# OUT must be on a file system every node sees; PARTS_DIR and OUT's folder (a set: OUT itself)
# are created here and must take a file. The jobs run `vts` from PATH, or $VTS (sbatch passes the
# environment on). Their logs, vts-shard-%A_%a.out, vts-merge-%j.out (a set: vts-apex-%j.out,
# vts-merge-%A_%a.out, vts-manifest-%j.out) go to the folder sbatch is run from.
#
# A failed shard: afterok is then never satisfied, so the finish job stays pending for ever
# (Reason=DependencyNeverSatisfied). Cancel it and resubmit the failed shards with a new finish
# job; the other parts are kept:
#   scancel FINISH_JOB; submit.sh --resubmit I PLAN PARTS_DIR OUT.pmtiles
# For a set, cancel the apex, merge and manifest jobs instead (`scancel --name=vts-apex,...`, or
# their ids). A failed archive merge of a set: the manifest job stays pending the same way;
#   scancel MANIFEST_JOB; submit.sh --resubmit-merge I PLAN PARTS_DIR OUT_DIR/
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
BATCH_PROG=submit
die() {
  printf 'submit: %s\n' "$*" >&2
  exit 2
}
# shellcheck source-path=SCRIPTDIR source=../lib.sh
source "$here/../lib.sh"

throttle="" chunk="" json=0 resubmit="" remerge=""
args=() extra=()
while (($#)); do
  case $1 in
    --throttle) throttle=${2:?--throttle needs a number}; shift 2 ;;
    --chunk) chunk=${2:?--chunk needs a number}; shift 2 ;;
    --json) json=1; shift ;;
    --resubmit) resubmit=${2:?--resubmit needs a shard index}; shift 2 ;;
    --resubmit-merge) remerge=${2:?--resubmit-merge needs an archive index}; shift 2 ;;
    -h | --help) sed -n '2,/^set -euo/{/^set -euo/d;s/^# \{0,1\}//;p}' "$0"; exit 0 ;;
    --) shift; extra=("$@"); break ;;
    -*) die "unknown option $1 (see --help)" ;;
    *) args+=("$1"); shift ;;
  esac
done
if [[ -n $resubmit ]]; then
  [[ -z $remerge ]] || die "give one of --resubmit and --resubmit-merge, not both"
  ((${#args[@]} == 2 || ${#args[@]} == 3)) || die "usage: submit.sh --resubmit I PLAN PARTS_DIR [OUT]"
  [[ $resubmit == missing || $resubmit =~ ^[0-9]+(,[0-9]+)*$ ]] ||
    die "--resubmit takes shard indexes (I or I,J,...) or 'missing', not '$resubmit'"
elif [[ -n $remerge ]]; then
  ((${#args[@]} == 3)) || die "usage: submit.sh --resubmit-merge I PLAN PARTS_DIR OUT_DIR/"
  [[ $remerge =~ ^[0-9]+(,[0-9]+)*$ ]] ||
    die "--resubmit-merge takes archive indexes (I or I,J,...), not '$remerge'"
else
  ((${#args[@]} == 3)) || die "usage: submit.sh [--throttle P] [--chunk C] [--json] PLAN PARTS_DIR OUT (see --help)"
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
set_info=$(plan_set_info "$plan") || exit 2
read -r _ archive_level archives <<<"$set_info"
if ((archives)); then
  [[ -z $out || ${args[2]} != *.pmtiles ]] ||
    die "the plan makes a set of $archives archives (archive level $archive_level): OUT is a folder (OUT_DIR/), not ${args[2]}"
else
  [[ -z $remerge ]] || die "--resubmit-merge: the plan makes one archive, not a set"
  [[ -z $out || ${args[2]} != */ ]] ||
    die "the plan makes one archive: OUT is OUT.pmtiles, not a folder ${args[2]} (for a set: vts plan --archive-level K or --max-archive-size)"
fi

max=$(scontrol show config 2>/dev/null | awk '$1 == "MaxArraySize" { print $3 }') || true
[[ $max =~ ^[0-9]+$ ]] || die "cannot read MaxArraySize from \`scontrol show config\` (is this a Slurm login node?)"
chunk=${chunk:-$max}
((chunk <= max)) || die "--chunk $chunk: the cluster's MaxArraySize is $max (array indexes 0..$((max - 1)))"

writable_folder "$parts" "PARTS_DIR"
if [[ -n $out ]] && ((archives)); then
  writable_folder "$out" "OUT_DIR, the set's folder"
elif [[ -n $out ]]; then
  writable_folder "$(dirname -- "$out")" "the folder of OUT"
fi

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

# merge_array OFFSET SPEC [SBATCH_OPTION...]: an array of merge.sbatch merging the set's archives
# OFFSET + each index of SPEC.
merge_array() {
  local first=$1 spec=$2
  shift 2
  submit "$@" --array="$spec${throttle:+%$throttle}" --export="ALL,VTS_ARCHIVE_OFFSET=$first" \
    "$here/merge.sbatch" "$plan" "$parts" "$out/"
}

# chunked OPTION COUNT WHAT LIST: the indexes of LIST (comma-separated, each < COUNT, else dies
# naming OPTION and COUNT WHAT) grouped by the chunk they lie in, as "FIRST TASK,TASK..." lines
# (tasks relative to FIRST: the offset and SLURM_ARRAY_TASK_ID of the first submission).
chunked() {
  local option=$1 count=$2 what=$3 i
  local -A tasks=()
  local wanted=()
  IFS=, read -ra wanted <<<"$4"
  for i in "${wanted[@]}"; do
    i=$((10#$i))
    ((i < count)) || die "$option $i: the plan has $count $what (0..$((count - 1)))"
    tasks[$((i / chunk * chunk))]+="${tasks[$((i / chunk * chunk))]:+,}$((i - i / chunk * chunk))"
  done
  for i in "${!tasks[@]}"; do printf '%s %s\n' "$i" "${tasks[$i]}"; done | sort -n
}

jobs=() arrays_json=()
if [[ -n $remerge ]]; then
  : # the shards and the apex are done
elif [[ -z $resubmit ]]; then
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
  if [[ $resubmit == missing ]]; then
    wanted=()
    for ((i = 0; i < n; i++)); do
      [[ -e $(printf '%s/shard-%06d.part' "$parts" "$i") ]] || wanted+=("$i")
    done
    ((${#wanted[@]})) || die "--resubmit missing: every shard has a part in $parts"
    resubmit=$(IFS=,; printf '%s' "${wanted[*]}")
  fi
  groups=$(chunked --resubmit "$n" shards "$resubmit") || exit 2
  while read -r first tasks; do
    id=$(array "$first" "$tasks") || exit 2
    jobs+=("$id")
    arrays_json+=("{\"job\": \"${jobs[-1]}\", \"first_shard\": $first, \"tasks\": \"$tasks\"}")
    ((json)) || printf 'submit: shards %s of the array at offset %d: job %s\n' "$tasks" "$first" "${jobs[-1]}"
  done <<<"$groups"
fi

finish="" apex="" merges=() merges_json=()
if [[ -n $out ]] && ((archives)); then
  # A set: the apex after the shards, the merges after the apex, the manifest after the merges.
  merge_dep=()
  if [[ -z $remerge ]]; then
    apex=$(submit --dependency="afterok:$(IFS=:; printf '%s' "${jobs[*]}")" \
      "$here/apex.sbatch" "$plan" "$parts") || exit 2
    ((json)) || printf 'submit: apex: job %s, after %s\n' "$apex" "${jobs[*]}"
    merge_dep=(--dependency="afterok:$apex")
    for ((first = 0; first < archives; first += chunk)); do
      count=$((archives - first < chunk ? archives - first : chunk))
      id=$(merge_array "$first" "0-$((count - 1))" "${merge_dep[@]}") || exit 2
      merges+=("$id")
      merges_json+=("{\"job\": \"$id\", \"first_archive\": $first, \"archives\": $count}")
      ((json)) || printf 'submit: merges of archives %d-%d into %s/: job %s\n' "$first" "$((first + count - 1))" "$out" "$id"
    done
  else
    groups=$(chunked --resubmit-merge "$archives" archives "$remerge") || exit 2
    while read -r first tasks; do
      id=$(merge_array "$first" "$tasks") || exit 2
      merges+=("$id")
      merges_json+=("{\"job\": \"$id\", \"first_archive\": $first, \"tasks\": \"$tasks\"}")
      ((json)) || printf 'submit: merges %s of the array at offset %d: job %s\n' "$tasks" "$first" "$id"
    done <<<"$groups"
  fi
  finish=$(submit --dependency="afterok:$(IFS=:; printf '%s' "${merges[*]}")" --job-name=vts-manifest \
    --output=vts-manifest-%j.out "$here/merge.sbatch" "$plan" "$parts" "$out/" --manifest) || exit 2
elif [[ -n $out ]]; then
  dep=$(IFS=:; printf '%s' "${jobs[*]}")
  finish=$(submit --dependency="afterok:$dep" "$here/finish.sbatch" "$plan" "$parts" "$out") || exit 2
fi
if ((json)); then
  set_json=""
  ((archives == 0)) || set_json=$(printf ', "archive_level": %d, "archives": %d, "apex": "%s", "merges": [%s], "manifest": "%s"' \
    "$archive_level" "$archives" "$apex" "$(IFS=,; printf '%s' "${merges_json[*]}")" "$finish")
  printf '{"shards": %d, "max_array_size": %d, "chunk": %d, "arrays": [%s], "finish": "%s"%s}\n' \
    "$n" "$max" "$chunk" "$(IFS=,; printf '%s' "${arrays_json[*]}")" "$finish" "$set_json"
elif [[ -n $finish ]] && ((archives)); then
  printf 'submit: the manifest %s/tileset.json: job %s, after %s\n' "$out" "$finish" "${merges[*]}"
  printf 'submit: if archive I'"'"'s merge fails, job %s never starts: scancel %s; %s --resubmit-merge I %s %s %s/\n' \
    "$finish" "$finish" "$0" "$plan" "$parts" "$out"
elif [[ -n $finish ]]; then
  printf 'submit: apex and merge into %s: job %s, after %s\n' "$out" "$finish" "${jobs[*]}"
  printf 'submit: if shard I fails, job %s never starts: scancel %s; %s --resubmit I %s %s %s\n' \
    "$finish" "$finish" "$0" "$plan" "$parts" "$out"
fi
