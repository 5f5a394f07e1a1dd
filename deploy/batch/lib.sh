# shellcheck shell=bash
# What deploy/batch/local/run-shards.sh and deploy/batch/slurm/submit.sh both do before they start
# anything (sourced; plan_set.py beside it). The caller sets BATCH_PROG (its name, for messages) and defines
# die MESSAGE (prints "$BATCH_PROG: MESSAGE", exits 2).

# plan_shard_count PLAN: prints the number of shards of the plan (the length of its "shards"
# array); exits 2 naming the plan when it is not one.
plan_shard_count() {
  python3 -c '
import json, sys
prog, plan = sys.argv[1], sys.argv[2]
try:
    shards = json.load(open(plan))["shards"]
except (OSError, ValueError, KeyError, TypeError) as e:
    sys.exit(f"{prog}: {plan} is not a plan with a \"shards\" array ({e!r})")
if not isinstance(shards, list) or not shards:
    sys.exit(f"{prog}: {plan}: \"shards\" is not a non-empty array")
print(len(shards))' "$BATCH_PROG" "$1" || exit 2
}

# plan_set_info PLAN: prints "SHARDS ARCHIVE_LEVEL ARCHIVES" (plan_set.py): the plan's shard count
# and, for a plan of a set of archives (vts plan --archive-level K), K and the archive count N
# (vts merge --archive 0..N-1); "0 0" for a plan of one archive. Exits 2 naming the plan when it is
# not one.
plan_set_info() {
  python3 "$(dirname "${BASH_SOURCE[0]}")/plan_set.py" "$BATCH_PROG" "$1" || exit 2
}

# writable_folder DIR WHAT: DIR exists (created with its parents, as mkdir -p) and takes a new
# file; else dies naming DIR and WHAT it is for. Before any work, so that a run does not fail at
# its end on a folder it could have refused at once.
writable_folder() {
  mkdir -p -- "$1" 2>/dev/null || die "cannot create the folder $1 ($2)"
  local probe
  probe=$(mktemp "$1/.$BATCH_PROG-check.XXXXXX" 2>/dev/null) || die "cannot write in the folder $1 ($2)"
  rm -f -- "$probe"
}
