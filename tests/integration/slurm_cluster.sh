#!/usr/bin/env bash
# deploy/batch/slurm/ on a real Slurm cluster (slurm-wlm and munge, one node on loopback, started
# and stopped here: slurm_lib.sh), submitted as docs/PLANET.md tells a user: submit.sh cuts a plan
# of more shards than the cluster's MaxArraySize (5 here, as Slurm's default 1001 is for a planet's
# 32,768 shards) into arrays with VTS_SHARD_OFFSET, and holds finish.sbatch (apex, then merge) by
# --dependency=afterok on every array. The merged archive must be byte-identical to `vts build`'s.
# Then one shard's task is cancelled while it runs: the finish job is then never satisfied
# (DependencyNeverSatisfied), and the user's recovery — scancel it, `submit.sh --resubmit K` with
# the archive — rebuilds that shard alone and merges the same bytes again.
# Last, a plan of a set of archives (vts plan --archive-level 2: 9 archives, more than
# MaxArraySize): apex.sbatch after the shard arrays, merge.sbatch as arrays of 5 (with
# VTS_ARCHIVE_OFFSET) after the apex, merge.sbatch --manifest after every merge array; the set
# joined (`vts merge --join`) is vts build's archive byte for byte; an archive removed and merged
# again alone (`submit.sh --resubmit-merge I`) with a new manifest gives the same set.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
# shellcheck source=slurm_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/slurm_lib.sh"
require_tool ss
require_tool python3
SLURM_BATCH=$(cd "$(dirname "${BASH_SOURCE[0]}")/../../deploy/batch/slurm" && pwd)
SUBMIT=$SLURM_BATCH/submit.sh
JOB_TIMEOUT=240

slurm_cleanup() {
  local rc=$?
  slurm_stop
  # cleanup reads the exit status from $?.
  if ((rc == 0)); then cleanup; else (exit "$rc") || cleanup; fi
}
trap slurm_cleanup EXIT

# show_job_logs: the jobs' own logs (they go to the folder sbatch ran in: $WORK/joblogs).
show_job_logs() { tail_logs "$WORK"/joblogs/*.out; }

# 4 CPUs: two 2-CPU shard tasks at once (the node's resources are configured, not detected).
slurm_start "$WORK/slurm" 5 4
note "a one-node Slurm cluster is up: MaxArraySize $(scontrol show config | awk '$1 == "MaxArraySize" { print $3 }')"

expect_ok "$VTS" plan "$EARTH" -o "$WORK/plan.json" --shards 8 --json
n=$(json_get "$OUT" "j.shards")
((n > 5)) || fail "the plan has $n shards, not more than MaxArraySize 5"
mkdir -p "$WORK/ref"
build_earth "$WORK/ref/earth.pmtiles" -q
want=$(sha "$WORK/ref/earth.pmtiles")

note "one array of all $n shards is refused by this cluster; submit.sh --chunk above it too"
mkdir -p "$WORK/joblogs"
cd "$WORK/joblogs" || fail "no $WORK/joblogs"
run sbatch --array=0-$((n - 1)) "$SLURM_BATCH/build.sbatch" "$WORK/plan.json" "$WORK/parts0"
if ((RC == 0)) || ! grep -q 'Invalid job array specification' "$ERR"; then
  show_output
  fail "sbatch --array=0-$((n - 1)) was not refused with MaxArraySize 5"
fi
run bash "$SUBMIT" --chunk 6 "$WORK/plan.json" "$WORK/parts0" "$WORK/out0/earth.pmtiles"
if ((RC != 2)) || ! grep -q 'MaxArraySize is 5' "$ERR"; then
  show_output
  fail "submit.sh --chunk 6 with MaxArraySize 5: expected exit 2 naming MaxArraySize"
fi

# The jobs run vts through VTS (sbatch passes the environment on). VTS_GATE names a shard whose
# task waits, before it runs vts, until $WORK/gate exists: a task that is surely running when
# the test cancels it.
cat >"$WORK/vts-gated" <<EOF
#!/usr/bin/env bash
shard=\$((\${VTS_SHARD_OFFSET:-0} + \${SLURM_ARRAY_TASK_ID:-0}))
if [[ -n \${SLURM_ARRAY_TASK_ID:-} && \$shard == "\${VTS_GATE:-}" ]]; then
  touch "$WORK/gated-\$shard-running"
  until [[ -e "$WORK/gate" ]]; do sleep 0.1; done
fi
exec "$VTS" "\$@"
EOF
chmod +x "$WORK/vts-gated"
export VTS=$WORK/vts-gated

note "submit.sh: $n shards in arrays of 5, then apex and merge after afterok on every array"
t0=$SECONDS
expect_ok bash "$SUBMIT" --json --throttle 2 "$WORK/plan.json" "$WORK/parts" "$WORK/out/earth.pmtiles"
cp "$OUT" "$WORK/submit.json"
json_check "$WORK/submit.json" "j.shards === $n && j.max_array_size === 5 && j.chunk === 5 &&
  j.arrays.length === $(((n + 4) / 5)) && j.arrays.every((a, i) => a.first_shard === 5 * i) &&
  j.arrays.reduce((s, a) => s + a.shards, 0) === $n && /^[0-9]+$/.test(j.finish)"
mapfile -t arrays < <(json_get "$WORK/submit.json" "j.arrays.map(a => a.job).join('\n')")
finish=$(json_get "$WORK/submit.json" "j.finish")
dep=$(scontrol -o show job "$finish" | grep -o 'Dependency=[^ ]*')
for j in "${arrays[@]}"; do
  grep -q "afterok:${j}_\*" <<<"$dep" || fail "the finish job's $dep does not wait for array $j"
done
slurm_wait_jobs "$JOB_TIMEOUT" "${arrays[@]}" "$finish"
for j in "${arrays[@]}" "$finish"; do
  bad=$(slurm_job_states "$j" | grep -v ' COMPLETED$') && { show_job_logs; fail "job $j: $bad"; }
done
[[ -s $WORK/out/earth.pmtiles ]] || { show_job_logs; fail "no archive after the finish job"; }
[[ $(sha "$WORK/out/earth.pmtiles") == "$want" ]] || fail "the Slurm build's archive differs from vts build's"
note "the $n shards, apex and merge through Slurm: byte-identical to vts build ($((SECONDS - t0)) s)"
for ((i = 0; i < n; i++)); do
  [[ -e $(printf '%s/parts/shard-%06d.part' "$WORK" "$i") ]] || fail "no part for shard $i"
done

note "a shard's task cancelled while it runs: the finish job is never satisfied"
victim=6 # the second array's task 1: VTS_SHARD_OFFSET=5 + SLURM_ARRAY_TASK_ID=1
export VTS_GATE=$victim
expect_ok bash "$SUBMIT" --json "$WORK/plan.json" "$WORK/parts2" "$WORK/out2/earth.pmtiles"
cp "$OUT" "$WORK/submit2.json"
mapfile -t arrays < <(json_get "$WORK/submit2.json" "j.arrays.map(a => a.job).join('\n')")
finish=$(json_get "$WORK/submit2.json" "j.finish")
victim_running() { [[ -e $WORK/gated-$victim-running ]]; }
slurm_poll "$JOB_TIMEOUT" "shard $victim's task running" victim_running
[[ $(slurm_job_states "${arrays[1]}" | awk '$1 == 1 { print $2 }') == RUNNING ]] ||
  fail "shard $victim's task (${arrays[1]}_1) is not RUNNING: $(slurm_job_states "${arrays[1]}")"
expect_ok scancel "${arrays[1]}_1"
slurm_wait_jobs "$JOB_TIMEOUT" "${arrays[@]}"
states=$(slurm_job_states "${arrays[0]}"; slurm_job_states "${arrays[1]}")
[[ $(grep -c ' COMPLETED$' <<<"$states") == $((n - 1)) && $(grep -c ' CANCELLED' <<<"$states") == 1 ]] ||
  { show_job_logs; fail "expected $((n - 1)) tasks COMPLETED and one CANCELLED: $states"; }
[[ ! -e $(printf '%s/parts2/shard-%06d.part' "$WORK" "$victim") ]] || fail "the cancelled shard left a part"
never() { scontrol -o show job "$finish" | grep -q 'JobState=PENDING .*Reason=DependencyNeverSatisfied'; }
slurm_poll 30 "the finish job $finish pending with DependencyNeverSatisfied" never
[[ ! -e $WORK/out2/earth.pmtiles ]] || fail "an archive was written although a shard failed"

note "the recovery: scancel the finish job, submit.sh --resubmit $victim with the archive"
# The other shards' parts stay the files they are (inode and change time: not rewritten).
parts_stat() { find "$WORK/parts2" -name 'shard-*.part' -printf '%f %i %C@\n' | LC_ALL=C sort; }
before=$(parts_stat)
expect_ok scancel "$finish"
touch "$WORK/gate"
run bash "$SUBMIT" --resubmit "$n" "$WORK/plan.json" "$WORK/parts2" "$WORK/out2/earth.pmtiles"
if ((RC != 2)) || ! grep -q "the plan has $n shards" "$ERR"; then
  show_output
  fail "submit.sh --resubmit $n (past the plan's shards): expected exit 2 naming the shard count"
fi
# "missing": the shards without a part, here the victim alone.
expect_ok bash "$SUBMIT" --json --resubmit missing "$WORK/plan.json" "$WORK/parts2" "$WORK/out2/earth.pmtiles"
cp "$OUT" "$WORK/resubmit.json"
json_check "$WORK/resubmit.json" "j.arrays.length === 1 && j.arrays[0].first_shard === 5 &&
  j.arrays[0].tasks === '1' && /^[0-9]+$/.test(j.finish)"
again=$(json_get "$WORK/resubmit.json" "j.arrays[0].job")
finish=$(json_get "$WORK/resubmit.json" "j.finish")
slurm_wait_jobs "$JOB_TIMEOUT" "$again" "$finish"
for j in "$again" "$finish"; do
  bad=$(slurm_job_states "$j" | grep -v ' COMPLETED$') && { show_job_logs; fail "job $j: $bad"; }
done
[[ $(slurm_job_states "$again") == "1 COMPLETED" ]] || fail "the resubmission ran $(slurm_job_states "$again")"
[[ $(sha "$WORK/out2/earth.pmtiles") == "$want" ]] || fail "the recovered build's archive differs from vts build's"
[[ $(parts_stat | grep -v "shard-00000$victim.part") == "$before" ]] ||
  fail "a part other than shard $victim's changed: $(diff <(echo "$before") <(parts_stat))"

note "a plan of a set: the shards, the apex, the merges as arrays of 5, the manifest after them"
expect_ok "$VTS" plan "$EARTH" --name earth -o "$WORK/set.plan.json" --shards 8 --archive-level 2 --json
archives=$(json_get "$OUT" j.archives)
((archives > 5)) || fail "the set plan has $archives archives, not more than MaxArraySize 5"
t0=$SECONDS
expect_ok bash "$SUBMIT" --json --throttle 2 "$WORK/set.plan.json" "$WORK/sparts" "$WORK/set/"
cp "$OUT" "$WORK/submit-set.json"
json_check "$WORK/submit-set.json" "j.archive_level === 2 && j.archives === $archives &&
  j.merges.length === $(((archives + 4) / 5)) && j.merges.every((m, i) => m.first_archive === 5 * i) &&
  j.merges.reduce((s, m) => s + m.archives, 0) === $archives && /^[0-9]+$/.test(j.apex) &&
  /^[0-9]+$/.test(j.manifest) && j.finish === j.manifest"
mapfile -t arrays < <(json_get "$WORK/submit-set.json" "j.arrays.map(a => a.job).join('\n')")
mapfile -t merges < <(json_get "$WORK/submit-set.json" "j.merges.map(m => m.job).join('\n')")
apex=$(json_get "$WORK/submit-set.json" "j.apex")
manifest=$(json_get "$WORK/submit-set.json" "j.manifest")
dep=$(scontrol -o show job "$apex" | grep -o 'Dependency=[^ ]*')
for j in "${arrays[@]}"; do
  grep -q "afterok:${j}_\*" <<<"$dep" || fail "the apex job's $dep does not wait for shard array $j"
done
for j in "${merges[@]}"; do
  dep=$(scontrol -o show job "$j" | grep -o 'Dependency=[^ ]*' | head -n 1)
  grep -q "afterok:${apex}[(]" <<<"$dep" || fail "merge array $j's $dep does not wait for the apex $apex"
done
dep=$(scontrol -o show job "$manifest" | grep -o 'Dependency=[^ ]*')
for j in "${merges[@]}"; do
  grep -q "afterok:${j}_\*" <<<"$dep" || fail "the manifest job's $dep does not wait for merge array $j"
done
slurm_wait_jobs "$JOB_TIMEOUT" "${arrays[@]}" "$apex" "${merges[@]}" "$manifest"
for j in "${arrays[@]}" "$apex" "${merges[@]}" "$manifest"; do
  bad=$(slurm_job_states "$j" | grep -v ' COMPLETED$') && { show_job_logs; fail "job $j: $bad"; }
done
[[ $(slurm_job_states "${merges[0]}" | wc -l) == 5 ]] || fail "the first merge array ran $(slurm_job_states "${merges[0]}")"
[[ -s $WORK/set/tileset.json ]] || { show_job_logs; fail "no tileset.json after the manifest job"; }
expect_ok "$VTS" merge --join "$WORK/set" -o "$WORK/set-joined.pmtiles" -q
[[ $(sha "$WORK/set-joined.pmtiles") == "$want" ]] || fail "the Slurm build's set, joined, differs from vts build's"
note "the set's $archives archives merged as Slurm arrays: joined, byte-identical to vts build ($((SECONDS - t0)) s)"

note "an archive merged again alone: submit.sh --resubmit-merge, then a new manifest"
redo=6 # the second merge array's task 1
name=$(json_get "$WORK/set/tileset.json" "j.archives[$redo].name")
rm "$WORK/set/$name" "$WORK/set/tileset.json"
run bash "$SUBMIT" --resubmit-merge "$archives" "$WORK/set.plan.json" "$WORK/sparts" "$WORK/set/"
if ((RC != 2)) || ! grep -q "the plan has $archives archives" "$ERR"; then
  show_output
  fail "submit.sh --resubmit-merge $archives (past the set's archives): expected exit 2 naming the count"
fi
expect_ok bash "$SUBMIT" --json --resubmit-merge "$redo" "$WORK/set.plan.json" "$WORK/sparts" "$WORK/set/"
cp "$OUT" "$WORK/remerge.json"
json_check "$WORK/remerge.json" "j.arrays.length === 0 && j.merges.length === 1 &&
  j.merges[0].first_archive === 5 && j.merges[0].tasks === '1' && /^[0-9]+$/.test(j.manifest)"
again=$(json_get "$WORK/remerge.json" "j.merges[0].job")
manifest=$(json_get "$WORK/remerge.json" "j.manifest")
slurm_wait_jobs "$JOB_TIMEOUT" "$again" "$manifest"
for j in "$again" "$manifest"; do
  bad=$(slurm_job_states "$j" | grep -v ' COMPLETED$') && { show_job_logs; fail "job $j: $bad"; }
done
[[ -s $WORK/set/$name && -s $WORK/set/tileset.json ]] || fail "the archive merged again or the manifest is missing"
expect_ok "$VTS" merge --join "$WORK/set" -o "$WORK/set-joined2.pmtiles" -q
[[ $(sha "$WORK/set-joined2.pmtiles") == "$want" ]] || fail "the set after --resubmit-merge differs from vts build's"
note "PASS: chunked arrays, afterok, a cancelled shard resubmitted alone, a set's merges as arrays: the same archive"
