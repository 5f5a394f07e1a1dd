#!/usr/bin/env bash
# run-shards.sh: a planned build (`vts plan`) on one machine — every shard, then the apex, then
# the merge (for a plan of a set of archives, `vts plan --archive-level K`: each archive's merge,
# JOBS at a time, then the set's manifest) — with the per-index command of the Kubernetes Job and
# the Slurm array:
#
#   JOB_COMPLETION_INDEX=I vts build --plan PLAN --out-dir PARTS
#
# for each shard index I whose part (PARTS/shard-IIIIII.part) does not exist yet, JOBS at a time
# (xargs -P). A part only exists complete (vts writes it to a temporary name, fsyncs and renames
# it), so the runner is resumable: run it again after a failure, a kill or a reboot and it builds
# only the shards without a part, then the apex and the merge again.
#
# usage: run-shards.sh [--jobs J] [--parts DIR] [--logs DIR] [--vts PATH] [--no-space-check]
#                      --out OUT PLAN
#   --jobs J      shards (and a set's archive merges) at once (default: the number of CPUs / 2, at
#                 least 1; each uses ~2)
#   --parts DIR   the parts (default: PLAN's directory/parts)
#   --logs DIR    one log per shard, shard-IIIIII.log, and the joblog: a line per shard run,
#                 "index exit_status seconds" (default: PLAN's directory/logs); a set's merges:
#                 merge-IIIIII.log each and merge-joblog, a line per archive merged
#   --out OUT     the merged archive OUT.pmtiles (its folder is created if missing); for a plan of
#                 a set, the set's folder (created if missing): each archive
#                 (vts merge --archive I) and tileset.json (vts merge --manifest)
#   --vts PATH    the vts executable (default: vts on PATH, or $VTS)
#   --no-space-check  passed to every vts build --plan and vts merge: run even where a folder
#                 has less free space than the plan's estimate of what it writes there
# Before any shard runs, the folders of the parts, the logs and the archive are created if
# missing and must take a new file (exit 2 naming the folder otherwise). Each shard, the apex and
# the merge refuse at once a folder with less free space than the plan's estimate of their output
# (exit 4; `vts plan --json`'s "estimated_bytes"); the script adds no check of the total, as no
# vts command prints the estimate of an existing plan.
# Exit status: 0 when the archive (the set) is written; 1 when shards failed (named, with their
# logs; the apex and merge are not run) or a set's archive merges failed (named, with their logs;
# no manifest is written; run again to retry); 2 on bad usage; otherwise the failing apex's,
# merge's or manifest's status.
set -euo pipefail
# Each shard's index is JOB_COMPLETION_INDEX itself: an offset meant for an engine's arrays
# (deploy/batch/slurm/submit.sh) left in the environment would shift every shard.
unset VTS_SHARD_OFFSET

BATCH_PROG=run-shards
die() {
  printf 'run-shards: %s\n' "$*" >&2
  exit 2
}
# shellcheck source-path=SCRIPTDIR source=../lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/../lib.sh"

# Internal: one shard, run by xargs as `run-shards.sh --run-one I` with the settings in the
# environment. Appends "I status seconds" to the joblog; a failed shard leaves no part.
if [[ ${1:-} == --run-one ]]; then
  i=$2
  log=$(printf '%s/shard-%06d.log' "$RUNNER_LOGS" "$i")
  t0=$(date +%s)
  rc=0
  JOB_COMPLETION_INDEX=$i "$RUNNER_VTS" build --plan "$RUNNER_PLAN" --out-dir "$RUNNER_PARTS" \
    ${RUNNER_SPACE:+"$RUNNER_SPACE"} >"$log" 2>&1 </dev/null || rc=$?
  printf '%s %s %s\n' "$i" "$rc" "$(($(date +%s) - t0))" >>"$RUNNER_LOGS/joblog"
  if ((rc == 0)); then
    printf 'run-shards: shard %s built\n' "$i"
  else
    printf 'run-shards: shard %s failed (exit %s): %s\n' "$i" "$rc" "$log" >&2
  fi
  exit 0 # failures are counted from the parts, so xargs goes on with the other shards
fi
# Internal: archive I of a set, run by xargs as `run-shards.sh --run-merge I`; appends
# "I status seconds" to the merge joblog.
if [[ ${1:-} == --run-merge ]]; then
  i=$2
  log=$(printf '%s/merge-%06d.log' "$RUNNER_LOGS" "$i")
  t0=$(date +%s)
  rc=0
  "$RUNNER_VTS" merge --plan "$RUNNER_PLAN" "$RUNNER_PARTS" -o "$RUNNER_OUT" --archive "$i" \
    ${RUNNER_SPACE:+"$RUNNER_SPACE"} >"$log" 2>&1 </dev/null || rc=$?
  printf '%s %s %s\n' "$i" "$rc" "$(($(date +%s) - t0))" >>"$RUNNER_LOGS/merge-joblog"
  if ((rc == 0)); then
    printf 'run-shards: archive %s merged\n' "$i"
  else
    printf 'run-shards: archive %s failed (exit %s): %s\n' "$i" "$rc" "$log" >&2
  fi
  exit 0 # failures are counted from the joblog, so xargs goes on with the other archives
fi

ncpu=$(nproc 2>/dev/null || echo 2)
jobs=$((ncpu / 2 > 0 ? ncpu / 2 : 1))
parts="" logs="" out="" plan="" space=""
vts=${VTS:-vts}
while (($#)); do
  case $1 in
    --jobs) jobs=${2:?--jobs needs a number}; shift 2 ;;
    --parts) parts=${2:?--parts needs a directory}; shift 2 ;;
    --logs) logs=${2:?--logs needs a directory}; shift 2 ;;
    --out) out=${2:?--out needs a file}; shift 2 ;;
    --vts) vts=${2:?--vts needs a path}; shift 2 ;;
    --no-space-check) space=--no-space-check; shift ;;
    -h | --help) sed -n '2,/^set -euo/{/^set -euo/d;s/^# \{0,1\}//;p}' "$0"; exit 0 ;;
    -*) die "unknown option $1 (see --help)" ;;
    *) [[ -z $plan ]] || die "one plan only (got $plan and $1)"; plan=$1; shift ;;
  esac
done
[[ -n $plan ]] || die "no plan given (see --help)"
[[ -n $out ]] || die "--out OUT.pmtiles is required (a plan of a set: --out OUT_DIR/)"
[[ $jobs =~ ^[1-9][0-9]*$ ]] || die "--jobs must be a positive integer, not '$jobs'"
[[ -r $plan ]] || die "cannot read the plan $plan"
command -v "$vts" >/dev/null 2>&1 || die "no vts executable '$vts' (--vts PATH)"
dir=$(dirname "$plan")
parts=${parts:-$dir/parts}
logs=${logs:-$dir/logs}
n=$(plan_shard_count "$plan") || exit 2
set_info=$(plan_set_info "$plan") || exit 2
read -r _ archive_level archives <<<"$set_info"
if ((archives)); then
  [[ $out != *.pmtiles ]] ||
    die "the plan makes a set of $archives archives (archive level $archive_level): --out is a folder (OUT_DIR/), not $out"
  out=${out%/}/
else
  [[ $out != */ ]] ||
    die "the plan makes one archive: --out is OUT.pmtiles, not a folder $out (for a set: vts plan --archive-level K or --max-archive-size)"
fi
writable_folder "$parts" "--parts"
writable_folder "$logs" "--logs"
if ((archives)); then
  writable_folder "$out" "--out, the set's folder"
else
  writable_folder "$(dirname -- "$out")" "the folder of --out"
fi

todo=()
for ((i = 0; i < n; i++)); do
  [[ -e $(printf '%s/shard-%06d.part' "$parts" "$i") ]] || todo+=("$i")
done
printf 'run-shards: %d shards, %d with a part already, %d to build, %d at a time\n' \
  "$n" "$((n - ${#todo[@]}))" "${#todo[@]}" "$jobs"
if ((${#todo[@]})); then
  export RUNNER_VTS=$vts RUNNER_PLAN=$plan RUNNER_PARTS=$parts RUNNER_LOGS=$logs RUNNER_SPACE=$space
  printf '%s\n' "${todo[@]}" | xargs -P "$jobs" -n 1 "$BASH" "$0" --run-one
fi

failed=()
for ((i = 0; i < n; i++)); do
  [[ -e $(printf '%s/shard-%06d.part' "$parts" "$i") ]] || failed+=("$i")
done
if ((${#failed[@]})); then
  printf 'run-shards: %d shard(s) failed: %s (logs in %s; run again to retry them)\n' \
    "${#failed[@]}" "${failed[*]}" "$logs" >&2
  exit 1
fi

# The apex depends on every shard's part: rebuilt whenever a shard was, or when it is missing.
if ((${#todo[@]})) || [[ ! -e $parts/apex.part ]]; then
  printf 'run-shards: apex\n'
  "$vts" build --plan "$plan" --apex --out-dir "$parts" ${space:+"$space"}
fi
if ((archives == 0)); then
  printf 'run-shards: merge into %s\n' "$out"
  "$vts" merge --plan "$plan" "$parts" -o "$out" ${space:+"$space"}
  printf 'run-shards: done: %s\n' "$out"
  exit 0
fi

# A set: every archive's merge (each rewrites its archive: the apex may be new), then the manifest.
printf 'run-shards: %d archives (level %d) into %s, %d at a time\n' "$archives" "$archive_level" "$out" "$jobs"
: >"$logs/merge-joblog"
export RUNNER_VTS=$vts RUNNER_PLAN=$plan RUNNER_PARTS=$parts RUNNER_LOGS=$logs RUNNER_SPACE=$space \
  RUNNER_OUT=$out
seq 0 $((archives - 1)) | xargs -P "$jobs" -n 1 "$BASH" "$0" --run-merge
declare -A merged=()
while read -r i rc _; do ((rc != 0)) || merged[$i]=1; done <"$logs/merge-joblog"
failed=()
for ((i = 0; i < archives; i++)); do [[ -n ${merged[$i]:-} ]] || failed+=("$i"); done
if ((${#failed[@]})); then
  printf 'run-shards: %d archive merge(s) failed: %s (logs merge-IIIIII.log in %s; run again to retry)\n' \
    "${#failed[@]}" "${failed[*]}" "$logs" >&2
  exit 1
fi
printf 'run-shards: manifest %stileset.json\n' "$out"
"$vts" merge --plan "$plan" "$parts" -o "$out" --manifest
printf 'run-shards: done: %s\n' "$out"
