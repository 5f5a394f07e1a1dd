#!/usr/bin/env bash
# deploy/loadtest: N load generators as a Kubernetes Indexed Job and the merge of their results.
#   - every document against its apiVersion/kind schema (deploy_js/validate_k8s.js,
#     kubernetes-models), plus python3-yaml checks of what the schema cannot see: the Jobs and the
#     PVC the kustomization lists, completions = parallelism = GENERATORS, Indexed, the results
#     volume mounted at RESULTS, the merge created suspended, the generators' command reading the
#     index from the environment (no --generator-index) and writing RESULTS/generator-INDEX.json
#     that the merge reads. A broken copy must fail.
#   - for real: the generators' container command, word for word, run by sh as two local
#     processes at once (JOB_COMPLETION_INDEX 0 and 1, GENERATORS=2) against `vts serve` on
#     loopback, then the merge Job's command: the merged counts are the sums of the two results.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
source "$(dirname "${BASH_SOURCE[0]}")/serve_lib.sh"
PY=${PYTHON3:-python3}
require_tool "$PY"
require_tool "$NODE"
"$PY" -c 'import yaml' 2>/dev/null || fail "python3 cannot import yaml (Debian package python3-yaml)"
DEPLOY=${VTS_DEPLOY_DIR:-$(cd "$(dirname "${BASH_SOURCE[0]}")/../../deploy" && pwd)}
DEPLOY_JS=${DEPLOY_JS:-$(cd "$(dirname "${BASH_SOURCE[0]}")/deploy_js" && pwd)}
LT="$DEPLOY/loadtest"

# consistency DIR: the checks on a deploy/loadtest tree; with OUT_DIR set, writes the generators'
# and the merge's shell commands to OUT_DIR/generators.sh and OUT_DIR/merge.sh.
consistency() {
  "$PY" - "$1" "${OUT_DIR:-}" <<'PYTHON'
import os, sys, yaml
d, out = sys.argv[1], sys.argv[2]
errors = []
def check(cond, what):
    if not cond:
        errors.append(what)
files = sorted(f for f in os.listdir(d) if f.endswith(".yaml") and f != "kustomization.yaml")
kust = yaml.safe_load(open(os.path.join(d, "kustomization.yaml")))
check(sorted(kust.get("resources", [])) == files, "kustomization lists every manifest")
docs = [x for f in files for x in yaml.safe_load_all(open(os.path.join(d, f))) if x]
jobs = {x["metadata"]["name"]: x for x in docs if x["kind"] == "Job"}
pvcs = {x["metadata"]["name"]: x for x in docs if x["kind"] == "PersistentVolumeClaim"}
check(set(jobs) == {"vts-loadtest-generators", "vts-loadtest-merge"}, f"Jobs: {sorted(jobs)}")
check("ReadWriteMany" in pvcs.get("vts-loadtest-results", {}).get("spec", {}).get("accessModes", []),
      "PVC vts-loadtest-results is ReadWriteMany (every generator writes to it)")
def ctr(name):
    return jobs[name]["spec"]["template"]["spec"]["containers"][0]
def env(name):
    return {e["name"]: e.get("value") for e in ctr(name).get("env", [])}
gen = jobs["vts-loadtest-generators"]["spec"]
n = env("vts-loadtest-generators").get("GENERATORS")
check(gen.get("completionMode") == "Indexed", "generators: completionMode: Indexed")
check(str(gen.get("completions")) == n and str(gen.get("parallelism")) == n,
      f"generators: completions {gen.get('completions')} and parallelism {gen.get('parallelism')} "
      f"equal GENERATORS {n}")
check(jobs["vts-loadtest-merge"]["spec"].get("suspend") is True, "merge: created suspended")
cmds = {}
for name in jobs:
    c = ctr(name)["command"]
    check(c[:2] == ["sh", "-c"] and len(c) == 3, f"{name}: command is sh -c SCRIPT")
    cmds[name] = c[-1]
    results = env(name).get("RESULTS")
    mounts = {m["mountPath"]: m["name"] for m in ctr(name).get("volumeMounts", [])}
    vols = {v["name"]: v for v in jobs[name]["spec"]["template"]["spec"].get("volumes", [])}
    claim = vols.get(mounts.get(results), {}).get("persistentVolumeClaim", {}).get("claimName")
    check(claim == "vts-loadtest-results", f"{name}: RESULTS={results} is the results volume")
    check(ctr(name)["image"] == ctr("vts-loadtest-generators")["image"], f"{name}: one image")
    sc = jobs[name]["spec"]["template"]["spec"].get("securityContext", {})
    check(sc.get("runAsNonRoot") is True and sc.get("runAsUser") == 10001, f"{name}: uid 10001")
g = cmds.get("vts-loadtest-generators", "")
check(g.startswith("exec vts loadtest \"$TARGET\" --generators \"$GENERATORS\""), f"generators: {g}")
check("--generator-index" not in g, "generators: the index comes from JOB_COMPLETION_INDEX")
check(g.endswith('> "$RESULTS/generator-$JOB_COMPLETION_INDEX.json"'), "generators write their file")
m = cmds.get("vts-loadtest-merge", "")
check(m.startswith('exec vts loadtest merge "$RESULTS"/generator-*.json'), f"merge: {m}")
if out:
    open(os.path.join(out, "generators.sh"), "w").write(g + "\n")
    open(os.path.join(out, "merge.sh"), "w").write(m + "\n")
for e in errors:
    print("deploy_loadtest: " + e, file=sys.stderr)
sys.exit(1 if errors else 0)
PYTHON
}

note "deploy/loadtest: consistent"
OUT_DIR="$WORK" consistency "$LT" >"$LOGS/consistency.log" 2>&1 ||
  { cat "$LOGS/consistency.log" >&2; fail "deploy/loadtest is inconsistent (above)"; }
note "a broken copy (completions 3, GENERATORS 4) is rejected"
mkdir -p "$WORK/broken"
cp "$LT"/*.yaml "$WORK/broken/"
sed -i 's/^  completions: 4$/  completions: 3/' "$WORK/broken/generators-job.yaml"
! cmp -s "$LT/generators-job.yaml" "$WORK/broken/generators-job.yaml" || fail "the sed changed nothing"
if consistency "$WORK/broken" >"$LOGS/broken.log" 2>&1; then fail "accepted completions != GENERATORS"; fi
grep -q 'equal GENERATORS 4' "$LOGS/broken.log" || { cat "$LOGS/broken.log" >&2; fail "wrong reason"; }

for pkg in kubernetes-models yaml; do
  [[ -f $DEPLOY_JS/node_modules/$pkg/package.json ]] ||
    fail "npm package $pkg is not installed in $DEPLOY_JS (run scripts/setup.sh)"
done
note "every document against its schema (kubernetes-models)"
"$NODE" "$DEPLOY_JS/validate_k8s.js" "$LT"/*.yaml >"$LOGS/validate.log" 2>&1 ||
  { cat "$LOGS/validate.log" >&2; fail "deploy/loadtest/*.yaml failed schema validation"; }
sed 's/^  completionMode: Indexed$/  completionMode: Indexd/' "$LT/generators-job.yaml" >"$WORK/bad.yaml"
if "$NODE" "$DEPLOY_JS/validate_k8s.js" "$WORK/bad.yaml" >"$LOGS/bad.log" 2>&1; then
  fail "the schema accepted completionMode: Indexd"
fi

# ---- for real -------------------------------------------------------------------------------------
note "the generators' command as two processes (JOB_COMPLETION_INDEX 0 and 1) against vts serve"
build_earth "$WORK/earth.pmtiles" --quiet
start_server "$WORK/earth.pmtiles"
mkdir -p "$WORK/bin" "$WORK/results"
ln -s "$VTS" "$WORK/bin/vts"
pids=()
for i in 0 1; do
  env PATH="$WORK/bin:$PATH" JOB_COMPLETION_INDEX=$i TARGET="$BASE/earth" GENERATORS=2 VIEWERS=4 \
    DURATION=2 SEED=1 RESULTS="$WORK/results" \
    timeout -k 10 "$CMD_TIMEOUT" sh -c "$(cat "$WORK/generators.sh")" 2>"$LOGS/gen$i.err" </dev/null &
  pids+=($!)
done
for i in 0 1; do
  wait "${pids[$i]}" || { cat "$LOGS/gen$i.err" >&2; fail "generator $i failed"; }
  json_check "$WORK/results/generator-$i.json" "j.generator.index == $i && j.generator.viewers == 2 &&
    j.generator.seed == 1 + $i && j.totals.requests > 0" "generator $i"
done
note "the merge Job's command"
run env PATH="$WORK/bin:$PATH" RESULTS="$WORK/results" sh -c "$(cat "$WORK/merge.sh")"
((RC == 0)) || { show_output; fail "the merge exited $RC"; }
[[ -s $WORK/results/report/index.html ]] || fail "no merged HTML report"
# shellcheck disable=SC2016  # JavaScript, not shell
"$NODE" -e '
  const fs = require("fs");
  const [m, a, b] = process.argv.slice(1).map(f => JSON.parse(fs.readFileSync(f, "utf8")));
  const bad = [];
  for (const k of ["requests", "bytes", "errors", "camera_moves"])
    if (m.totals[k] !== a.totals[k] + b.totals[k]) bad.push(`${k}: ${m.totals[k]} != ${a.totals[k]} + ${b.totals[k]}`);
  for (const h of Object.keys(a.latency_ns))
    if (m.latency_ns[h].count !== a.latency_ns[h].count + b.latency_ns[h].count) bad.push(h);
  if (m.scenario.viewers !== 4) bad.push("viewers " + m.scenario.viewers);
  if (!m.gates.passed || m.gates.results.length !== 3) bad.push("gates");
  if (bad.length) { console.error(bad.join("\n")); process.exit(1); }
  console.log(`-- merged ${m.totals.requests} = ${a.totals.requests} + ${b.totals.requests} requests`);' \
  "$WORK/results/merged.json" "$WORK/results/generator-0.json" "$WORK/results/generator-1.json" ||
  fail "the merged counts are not the sums (above)"
note "PASS"
