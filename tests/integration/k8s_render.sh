#!/usr/bin/env bash
# deploy/batch/k8s/render.sh: the Kubernetes manifests of a sharded build, rendered from the plan.
#   - real plans of 1 and 8 shards (earth.jpg, `--shards 4` makes 8), the 32 768-shard plate-carrée
#     planet (split level 8) and the 131 072-shard one (level 9, above the API server's 100 000
#     soft limit for an Indexed Job's completions), rendered; every object valid against the
#     Kubernetes 1.33 OpenAPI schemas (validate_k8s.js, kubernetes-models 4.5.1, pinned in
#     deploy_js/package-lock.json) and the Job rules the API server adds (job_rules.js); the
#     figures from the plan: completions, parallelism, maxFailedIndexes, the image everywhere, the
#     storage class, the claim's size (recomputed here from docs/PLANET.md's tile count); the
#     archive estimate render.sh sizes it from equals `vts plan --json`'s, dense, sparse, each codec;
#   - every rule of job_rules.js broken in turn in a copy of a rendered manifest that the schema
#     still accepts, and refused with the rule's id; the shards Job of before render.sh (completions
#     1 < maxFailedIndexes 16) refused; each rule in docs/DEPLOY.md's table;
#   - the plan Job's `vts plan --update` run on the volume's layout (a directory here): the same
#     build, the inputs at their /inputs paths; its shards, apex and merge make vts build's bytes;
#   - a plan of a set of archives (`vts plan --archive-level K`): render.sh --estimate's archive
#     count and largest archive equal `vts plan --json`'s (plain, sparse, georeferenced, K above
#     and below the split level); the merge Job Indexed over the archives, then a manifest Job,
#     valid; each merge pod's command run here for its index, then the manifest's: joined
#     (`vts merge --join`), the set is vts build's archive byte for byte;
#   - bad arguments and plans: exit 2, a message naming the problem, nothing written.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
PY=${PYTHON3:-python3}
require_tool "$PY"
require_tool "$NODE"
"$PY" -c 'import yaml' 2>/dev/null || fail "python3 cannot import yaml (Debian package python3-yaml)"
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
RENDER="$ROOT/deploy/batch/k8s/render.sh"
DEPLOY_JS=${DEPLOY_JS:-$ROOT/tests/integration/deploy_js}
for pkg in kubernetes-models yaml; do
  [[ -f $DEPLOY_JS/node_modules/$pkg/package.json ]] ||
    fail "npm package $pkg is not installed in $DEPLOY_JS (run scripts/setup.sh)"
done
[[ $("$NODE" -p 'require(process.argv[1]).version' "$DEPLOY_JS/node_modules/kubernetes-models/package.json") == 4.5.1 ]] ||
  fail "kubernetes-models is not 4.5.1 (the Kubernetes 1.33 schemas the docs name): npm ci in $DEPLOY_JS"
t_start=$(date +%s%N)
IMAGE=registry.example.org/vtstream/vts-build:0.1
P="$WORK/plans"
mkdir -p "$P"

# ---- plans ------------------------------------------------------------------------------------
note "plans: earth.jpg with 1 and 8 shards, the planet at split levels 8 and 9 (synthetic)"
expect_ok "$VTS" plan "$EARTH" --name earth -o "$P/one.json" --shards 1 -q
expect_ok "$VTS" plan "$EARTH" --name earth -o "$P/eight.json" --shards 4 -q
expect_ok "$VTS" plan --synthetic 33554432x16777216 -o "$P/planet.json" --split-level 8 -q
expect_ok "$VTS" plan --synthetic 33554432x16777216 -o "$P/planet9.json" --split-level 9 --codec bc1 -q
shards() { "$PY" -c 'import json,sys; print(len(json.load(open(sys.argv[1]))["shards"]))' "$1"; }
for want in one:1 eight:8 planet:32768 planet9:131072; do
  [[ $(shards "$P/${want%%:*}.json") == "${want#*:}" ]] || fail "${want%%:*}.json: $(shards "$P/${want%%:*}.json") shards, expected ${want#*:}"
done

# The claim's archive estimate is vts's (`vts plan --json`'s "estimated_bytes"): render.sh keeps its
# own copy of the rule (it runs where vts need not be), so the two are compared, lossless with and
# without the filter and bc1, for 1 and 8 shards and the planets.
note "render.sh --estimate agrees with vts plan --json's estimated_bytes"
expect_ok "$VTS" plan "$EARTH" --name earth -o "$P/eight-nf.json" --shards 4 --filter none -q
expect_ok "$VTS" plan "$EARTH" --name earth -o "$P/eight-bc1.json" --shards 4 --codec bc1 -q
# sparse: a planet whose tiles below level 3 lie in one corner (the apex counts ancestors only)
expect_ok "$VTS" plan --synthetic 33554432x16777216 --region 0,0,3000000,2000000 --region-level 3 \
  -o "$P/sparse.json" --split-level 8 -q
for name in one eight eight-nf eight-bc1 planet planet9 sparse; do
  # The same plan again, printed (vts prints the estimate of the plan it writes).
  expect_ok "$VTS" plan --update "$P/$name.json" -o "$WORK/again.json" --json
  vts_est=$(json_get "$OUT" '[j.estimated_bytes.archive, j.estimated_bytes.tile_bytes].join(" ")')
  expect_ok bash "$RENDER" --estimate "$P/$name.json"
  render_est=$(json_get "$OUT" '[j.archive, j.tile_bytes].join(" ")')
  [[ $vts_est == "$render_est" && ${vts_est%% *} -gt 0 ]] ||
    fail "$name.json: vts estimates '$vts_est' (archive, per tile), render.sh '$render_est'"
done

# A set's archive count and largest archive: render.sh keeps vts's rule (deploy/batch/plan_set.py).
note "render.sh --estimate agrees with vts plan --json on a set's archives and largest archive"
# name K SPLIT-ARGS BUILD-ARGS...: K below and above the split level, dense, sparse, georeferenced.
set_plans=(
  "set:2:--shards 4:$EARTH --name earth"
  "set-fine:3:--split-level 1:$EARTH --name earth"
  "set-sparse:5:--split-level 4:--synthetic 33554432x33554432 --region 1048000,1048000,1049200,1048800 --region-level 3 --codec bc1"
  "set-crs84:4:--split-level 2:--synthetic 16384x8192 --tiling WorldCRS84Quad --bbox=-10,-5,30,40"
  "set-merc:5:--split-level 1:--synthetic 16384x16384 --tiling WebMercatorQuad --bbox=100,-60,179,70 --filter none"
)
for s in "${set_plans[@]}"; do
  IFS=: read -r name k split build <<<"$s"
  # shellcheck disable=SC2086 # the words of the plan's arguments
  expect_ok "$VTS" plan $build -o "$P/$name.json" $split --archive-level "$k" --json
  cp "$OUT" "$P/$name.out"
  vts_set=$(json_get "$OUT" '[j.archive_level, j.archives, j.estimated_bytes.archive_max, j.estimated_bytes.archive].join(" ")')
  expect_ok bash "$RENDER" --estimate "$P/$name.json"
  render_set=$(json_get "$OUT" '[j.archive_level, j.archives, j.archive_max, j.archive].join(" ")')
  [[ $vts_set == "$render_set" ]] ||
    fail "$name.json: vts says '$vts_set' (level, archives, largest, all), render.sh '$render_set'"
done

# ---- render, schema, rules, figures -------------------------------------------------------------
schema() { "$NODE" "$DEPLOY_JS/validate_k8s.js" "$@"; }
rules() { "$NODE" "$DEPLOY_JS/job_rules.js" "$@"; }
# render_ok PLAN OUT ARGS...: render.sh succeeds; the manifests pass the schema and the rules.
render_ok() {
  local plan=$1 out=$2
  shift 2
  expect_ok bash "$RENDER" "$plan" "$out" --image "$IMAGE" "$@"
  schema "$out"/*.yaml >"$LOGS/schema.log" 2>&1 || { cat "$LOGS/schema.log" >&2; fail "$out: schema (above)"; }
  rules "$out"/*.yaml >"$LOGS/rules.log" 2>&1 || { cat "$LOGS/rules.log" >&2; fail "$out: Job rules (above)"; }
  note "$(basename "$plan"): $(head -n 1 "$OUT") | $(cat "$LOGS/schema.log") | $(cat "$LOGS/rules.log")"
}
R="$WORK/rendered"
render_ok "$P/one.json" "$R/one" --storage-class nfs-rwx
render_ok "$P/eight.json" "$R/eight" --storage-class nfs-rwx
render_ok "$P/planet.json" "$R/planet" --storage-class filestore-rwx
render_ok "$P/planet9.json" "$R/planet9" --parallelism 20000 --max-failed-indexes 50000 --name planet9
render_ok "$P/eight.json" "$R/eight-sized" --claim-size 3Ti --parallelism 3 --max-failed-indexes 0
render_ok "$P/set.json" "$R/set" --merge-parallelism 4
render_ok "$P/set-fine.json" "$R/set-fine"

note "the figures come from the plan"
"$PY" - "$R" "$IMAGE" "$EARTH" "$(json_get "$P/set.out" j.archives)" "$(json_get "$P/set-fine.out" j.archives)" <<'PYTHON' ||
  fail "rendered figures (above)"
import math, os, sys, yaml
R, image, earth = sys.argv[1], sys.argv[2], sys.argv[3]
errors = []
def check(cond, what):
    if not cond:
        errors.append(what)
def load(d):
    objs = {}
    for f in sorted(os.listdir(d)):
        if f.endswith(".yaml"):
            for o in yaml.safe_load_all(open(os.path.join(d, f))):
                objs[(o["kind"], o["metadata"]["name"])] = o
    return objs
GiB = 2**30
# The planet's claim from docs/PLANET.md: 1 + (4^18 - 4) / 6 tiles (plate carrée, maxz 17, dense),
# 34 478 B (lossless, filtered) or 264²/2 B (bc1) each, twice (parts and archive), + 5%.
tiles = 1 + (4**18 - 4) // 6
planet_lossless = math.ceil(tiles * 34478 * 2 * 1.05 / GiB)
planet_bc1 = math.ceil(tiles * (264 * 264 // 2) * 2 * 1.05 / GiB)
cases = [  # dir, prefix, N, parallelism, maxFailedIndexes, storage class, claim
    ("one", "vts-build", 1, 1, 1, "nfs-rwx", "1Gi"),
    ("eight", "vts-build", 8, 8, 8, "nfs-rwx", "1Gi"),
    ("planet", "vts-build", 32768, 256, 16, "filestore-rwx", f"{planet_lossless}Gi"),
    ("planet9", "planet9", 131072, 10000, 10000, None, f"{planet_bc1}Gi"),
    ("eight-sized", "vts-build", 8, 3, 0, None, "3Ti"),
]
for d, prefix, n, par, mfi, sc, claim in cases:
    o = load(os.path.join(R, d))
    want = {("PersistentVolumeClaim", prefix), ("Pod", f"{prefix}-load")} | \
        {("Job", f"{prefix}-{c}") for c in ("plan", "shards", "apex", "merge")}
    check(set(o) == want, f"{d}: objects {sorted(o)}")
    if set(o) != want:
        continue
    s = o[("Job", f"{prefix}-shards")]["spec"]
    got = (s["completionMode"], s["completions"], s["parallelism"], s["maxFailedIndexes"], s["backoffLimitPerIndex"])
    check(got == ("Indexed", n, par, mfi, 3), f"{d}: shards (mode, completions, parallelism, maxFailedIndexes, backoffLimitPerIndex) {got}")
    pvc = o[("PersistentVolumeClaim", prefix)]["spec"]
    check(pvc.get("storageClassName") == sc, f"{d}: storageClassName {pvc.get('storageClassName')}, expected {sc}")
    check(pvc["resources"]["requests"]["storage"] == claim, f"{d}: claim {pvc['resources']['requests']['storage']}, expected {claim}")
    check(pvc["accessModes"] == ["ReadWriteMany"], f"{d}: accessModes")
    for (kind, name), obj in o.items():
        if kind == "PersistentVolumeClaim":
            continue
        pod = obj["spec"] if kind == "Pod" else obj["spec"]["template"]["spec"]
        check([c["image"] for c in pod["containers"]] == [image], f"{d}: {name}: image")
        check(pod["volumes"][0]["persistentVolumeClaim"]["claimName"] == prefix, f"{d}: {name}: claim")
        if kind == "Job":
            check(obj["spec"]["suspend"] is True, f"{d}: {name} is not created suspended")
    plan_cmd = o[("Job", f"{prefix}-plan")]["spec"]["template"]["spec"]["containers"][0]["command"]
    inputs = open(os.path.join(R, d, "plan", "inputs.txt")).read()
    update = "vts plan --update /plan/plan.local.json " + ("" if d.startswith("planet") else "--input-list /plan/inputs.txt ")
    check(plan_cmd[:2] == ["sh", "-c"] and len(plan_cmd) == 3 and plan_cmd[2].startswith(update + "-o /tmp/plan.json "),
          f"{d}: plan command {plan_cmd}")
    if d.startswith("planet"):
        check(inputs == "", f"{d}: a synthetic plan lists inputs {inputs!r}")
    else:
        check(inputs == f"/inputs/{os.path.basename(earth)}\n", f"{d}: inputs.txt {inputs!r}")
    check(open(os.path.join(R, d, "plan", "plan.local.json"), "rb").read() ==
          open(os.path.join(os.path.dirname(R), "plans", {"one": "one", "planet9": "planet9", "planet": "planet"}.get(d, "eight") + ".json"), "rb").read(),
          f"{d}: plan/plan.local.json is not the plan")
# A set: the merge Job Indexed over its archives (vts plan --json's count), then the manifest Job.
for d, n_archives, par in (("set", int(sys.argv[4]), 4), ("set-fine", int(sys.argv[5]), 16)):
    o = load(os.path.join(R, d))
    want = {("PersistentVolumeClaim", "vts-build"), ("Pod", "vts-build-load")} | \
        {("Job", f"vts-build-{c}") for c in ("plan", "shards", "apex", "merge", "manifest")}
    check(set(o) == want, f"{d}: objects {sorted(o)}")
    if set(o) != want:
        continue
    s = o[("Job", "vts-build-merge")]["spec"]
    got = (s.get("completionMode"), s.get("completions"), s.get("parallelism"), s.get("maxFailedIndexes"))
    check(got == ("Indexed", n_archives, min(par, n_archives), min(16, n_archives)),
          f"{d}: merge (mode, completions, parallelism, maxFailedIndexes) {got}, {n_archives} archives")
    cmd = s["template"]["spec"]["containers"][0]["command"]
    check(cmd == ["vts", "merge", "--plan", "/plan/plan.json", "/parts", "-o", "/out/set/", "--archive",
                  "$(JOB_COMPLETION_INDEX)"], f"{d}: merge command {cmd}")
    cmd = o[("Job", "vts-build-manifest")]["spec"]["template"]["spec"]["containers"][0]["command"]
    check(cmd == ["vts", "merge", "--plan", "/plan/plan.json", "/parts", "-o", "/out/set/", "--manifest"],
          f"{d}: manifest command {cmd}")
for e in errors:
    print("k8s_render: " + e, file=sys.stderr)
sys.exit(1 if errors else 0)
PYTHON

# ---- each rule broken ---------------------------------------------------------------------------------
note "job_rules.js: each rule broken in a copy the schema accepts, refused with the rule's id"
B="$WORK/broken"
mkdir -p "$B"
"$PY" - "$R" "$B" <<'PYTHON' || fail "making the broken copies"
import copy, os, sys, yaml
R, B = sys.argv[1], sys.argv[2]
def obj(d, f):
    return yaml.safe_load(open(os.path.join(R, d, f)))
def shards(o): return o["spec"]
def pod(o): return o["spec"]["template"]["spec"]
# rule id, a short name, the rendered file, the mutation
cases = [
    ("name-dns-subdomain", "pod-name", "eight", "load-pod.yaml", lambda o: o["metadata"].update(name="Vts_Load")),
    ("job-name-label", "apex-name-64", "eight", "apex-job.yaml", lambda o: o["metadata"].update(name="a" * 64)),
    ("indexed-pod-hostname", "shards-name-62", "eight", "shards-job.yaml", lambda o: o["metadata"].update(name="s" * 62)),
    ("nonnegative", "backoffLimit--1", "eight", "apex-job.yaml", lambda o: o["spec"].update(backoffLimit=-1)),
    ("restart-policy", "restart-always", "eight", "merge-job.yaml",
     lambda o: (o["spec"].pop("podFailurePolicy"), pod(o).update(restartPolicy="Always"))),
    ("podFailurePolicy-restartPolicy-never", "restart-onfailure", "eight", "shards-job.yaml",
     lambda o: pod(o).update(restartPolicy="OnFailure")),
    ("FailIndex-needs-backoffLimitPerIndex", "no-backoffLimitPerIndex", "eight", "shards-job.yaml",
     lambda o: (o["spec"].pop("backoffLimitPerIndex"), o["spec"].pop("maxFailedIndexes"))),
    ("per-index-needs-Indexed", "nonindexed", "eight", "shards-job.yaml", lambda o: o["spec"].update(completionMode="NonIndexed")),
    ("maxFailedIndexes-needs-backoffLimitPerIndex", "maxFailed-alone", "eight", "shards-job.yaml",
     lambda o: (o["spec"].pop("backoffLimitPerIndex"), o["spec"]["podFailurePolicy"]["rules"][0].update(action="FailJob"))),
    ("Indexed-needs-completions", "no-completions", "eight", "shards-job.yaml", lambda o: o["spec"].pop("completions")),
    ("maxFailedIndexes<=completions", "maxFailed-9-of-8", "eight", "shards-job.yaml", lambda o: o["spec"].update(maxFailedIndexes=9)),
    ("Indexed-parallelism<=100000", "parallelism-100001", "planet", "shards-job.yaml", lambda o: o["spec"].update(parallelism=100001)),
    ("maxFailedIndexes<=100000", "maxFailed-100001", "planet9", "shards-job.yaml",
     lambda o: o["spec"].update(maxFailedIndexes=100001)),
    ("completions>100000-limits", "high-parallelism", "planet9", "shards-job.yaml", lambda o: o["spec"].update(parallelism=10001)),
    ("completions>100000-limits", "high-maxFailed", "planet9", "shards-job.yaml", lambda o: o["spec"].update(maxFailedIndexes=10001)),
    ("completions>100000-limits", "high-no-maxFailed", "planet9", "shards-job.yaml", lambda o: o["spec"].pop("maxFailedIndexes")),
    ("podFailurePolicy-rules", "exit-codes-unordered", "eight", "shards-job.yaml",
     lambda o: o["spec"]["podFailurePolicy"]["rules"][0]["onExitCodes"].update(values=[3, 2, 5, 6])),
    ("podFailurePolicy-rules", "exit-code-0", "eight", "apex-job.yaml",
     lambda o: o["spec"]["podFailurePolicy"]["rules"][0]["onExitCodes"].update(values=[0, 2])),
    ("podFailurePolicy-rules", "container-unknown", "eight", "merge-job.yaml",
     lambda o: o["spec"]["podFailurePolicy"]["rules"][0]["onExitCodes"].update(containerName="other")),
    ("podReplacementPolicy-with-podFailurePolicy", "replacement", "eight", "shards-job.yaml",
     lambda o: o["spec"].update(podReplacementPolicy="TerminatingOrFailed")),
    ("container-names", "container-upper", "eight", "load-pod.yaml", lambda o: o["spec"]["containers"][0].update(name="Vts")),
]
with open(os.path.join(B, "cases.txt"), "w") as out:
    for rule, short, d, f, mutate in cases:
        o = obj(d, f)
        before = copy.deepcopy(o)
        mutate(o)
        assert o != before, short
        path = os.path.join(B, f"{short}.yaml")
        yaml.safe_dump(o, open(path, "w"), sort_keys=False)
        out.write(f"{rule}\t{path}\n")
PYTHON
declare -A covered
while IFS=$'\t' read -r rule file; do
  if rules "$file" >"$LOGS/broken.log" 2>&1; then
    cat "$LOGS/broken.log" >&2
    fail "job_rules.js accepted $(basename "$file") (breaks $rule)"
  fi
  grep -qF "rule $rule:" "$LOGS/broken.log" || { cat "$LOGS/broken.log" >&2; fail "$(basename "$file"): not refused by rule $rule"; }
  # The schema does not see these: each breach passes it (a rule the schema caught would not need checking here).
  schema "$file" >"$LOGS/broken-schema.log" 2>&1 || { cat "$LOGS/broken-schema.log" >&2; fail "the schema refuses $(basename "$file"): not a rule beyond the schema"; }
  covered[$rule]=1
  note "refused: $(basename "$file" .yaml) — $(grep -m1 -o "rule $rule: .*" "$LOGS/broken.log")"
done <"$B/cases.txt"
while IFS=$'\t' read -r rule source; do
  [[ -n ${covered[$rule]:-} ]] || fail "rule $rule ($source) is broken by no case here"
  grep -qF -- "\`$rule\`" "$ROOT/docs/DEPLOY.md" || fail "docs/DEPLOY.md's rules table lacks \`$rule\`"
done < <(rules --list)
note "every rule of job_rules.js broken once at least and listed in docs/DEPLOY.md"

note "the shards Job of before render.sh (completions 1, maxFailedIndexes 16) is refused"
FIXTURE="$DEPLOY_JS/fixtures/shards-job-before-render.yaml"
! rules "$FIXTURE" >"$LOGS/fixture.log" 2>&1 || fail "job_rules.js accepted $FIXTURE"
grep -q 'rule maxFailedIndexes<=completions: spec.maxFailedIndexes 16 > spec.completions 1' "$LOGS/fixture.log" ||
  { cat "$LOGS/fixture.log" >&2; fail "$FIXTURE refused for another reason"; }
schema "$FIXTURE" >/dev/null 2>&1 || fail "the schema refuses $FIXTURE (it accepted it: the API server's rule caught it)"

# ---- the plan Job's command on the volume's layout, then the shards, apex and merge ----------------
note "the plan Job, shards, apex and merge of the 8-shard rendering, on a directory laid out as the volume"
V="$WORK/volume"
mkdir -p "$V/inputs" "$V/plan" "$V/parts" "$V/out"
common=$(dirname "$EARTH")
tar -C "$common" -cf - -T "$R/eight/plan/upload.txt" | tar -xf - -C "$V/inputs"
cp "$R/eight/plan/plan.local.json" "$V/plan/"
# inputs.txt names /inputs/...: the pods' paths; here they lie under $V/inputs.
sed "s|^/inputs/|$V/inputs/|" "$R/eight/plan/inputs.txt" >"$V/plan/inputs.txt"
for j in shards apex merge; do mapfile -t "cmd_$j" < <(k8s_job_command "$R/eight/$j-job.yaml" "$V"); done
# The plan Job's shell script, its /plan/ and /tmp/ in $V, `vts` the one under test.
plan_script=$("$PY" -c 'import sys, yaml; print(yaml.safe_load(open(sys.argv[1]))["spec"]["template"]["spec"]["containers"][0]["command"][2])' \
  "$R/eight/plan-job.yaml")
plan_script=${plan_script//\/tmp\//$V/tmp/} # first: $V is itself under /tmp
plan_script=${plan_script//\/plan\//$V/plan/}
mkdir -p "$V/tmp" "$WORK/bin"
ln -s "$VTS" "$WORK/bin/vts"
earth_copy="$V/inputs/$(basename "$EARTH")"
cp "$earth_copy" "$WORK/earth.good"
printf '\125' | dd of="$earth_copy" bs=1 seek=200000 conv=notrunc 2>/dev/null
cmp -s "$earth_copy" "$WORK/earth.good" && fail "the copy was not changed"
PATH="$WORK/bin:$PATH" expect_clean_failure sh -c "$plan_script"
if ((RC != 5)) || ! grep -qF 'an input copy differs from the one planned' "$ERR" || ! grep -qF "$earth_copy" "$OUT"; then
  show_output
  fail "the plan Job over a changed copy: expected exit 5 naming it, got $RC"
fi
[[ ! -e $V/plan/plan.json ]] || fail "the plan Job wrote plan.json over a changed copy"
cp "$WORK/earth.good" "$earth_copy"
PATH="$WORK/bin:$PATH" expect_ok sh -c "$plan_script"
"$PY" - "$V/plan/plan.local.json" "$V/plan/plan.json" "$V/inputs" <<'PYTHON' || fail "the plan Job's plan (above)"
import json, os, sys
a, b = (json.load(open(p)) for p in sys.argv[1:3])
assert a["build_hash"] == b["build_hash"] and a["shards"] == b["shards"], "another build"
assert [i["path"] for i in b["inputs"]] == [os.path.join(sys.argv[3], os.path.basename(i["path"])) for i in a["inputs"]], b["inputs"]
assert [i["fingerprint"] for i in b["inputs"]] == [i["fingerprint"] for i in a["inputs"]]
PYTHON
for ((i = 0; i < 8; i++)); do
  # shellcheck disable=SC2154
  JOB_COMPLETION_INDEX=$i expect_ok "$VTS" "${cmd_shards[@]:1}"
done
# The apex and merge pods do not mount inputs/: they must not need them.
mv "$V/inputs" "$V/inputs.unmounted"
# shellcheck disable=SC2154
expect_ok "$VTS" "${cmd_apex[@]:1}"
# shellcheck disable=SC2154
expect_ok "$VTS" "${cmd_merge[@]:1}"
mv "$V/inputs.unmounted" "$V/inputs"
expect_ok "$VTS" build "$EARTH" --name earth -o "$WORK/single.pmtiles"
[[ $(sha256sum <"$V/out/planet.pmtiles") == $(sha256sum <"$WORK/single.pmtiles") ]] ||
  fail "the rendered Jobs' archive differs from vts build's"

note "the set's merge pods, one per index, then the manifest Job, on the same parts: joined, vts build's bytes"
# The set plan is the 8-shard build cut at level 2 (the archive level is not in the build hash:
# the parts above are its parts).
cp "$P/set.json" "$V/plan/plan.json"
n_archives=$(json_get "$P/set.out" j.archives)
((n_archives > 1)) || fail "set.json: $n_archives archives"
mapfile -t cmd_set < <(k8s_job_command "$R/set/merge-job.yaml" "$V")
mapfile -t cmd_manifest < <(k8s_job_command "$R/set/manifest-job.yaml" "$V")
for ((i = n_archives - 1; i >= 0; i--)); do
  # The pod's command as the kubelet runs it: $(JOB_COMPLETION_INDEX) expanded to the index.
  args=("${cmd_set[@]:1}")
  expect_ok "$VTS" "${args[@]/"\$(JOB_COMPLETION_INDEX)"/$i}" -q
  [[ ! -e $V/out/set/tileset.json ]] || fail "a merge pod wrote the manifest"
done
expect_ok "$VTS" "${cmd_manifest[@]:1}"
expect_ok "$VTS" merge --join "$V/out/set" -o "$WORK/joined.pmtiles" -q
[[ $(sha256sum <"$WORK/joined.pmtiles") == $(sha256sum <"$WORK/single.pmtiles") ]] ||
  fail "the rendered set Jobs' archives, joined, differ from vts build's"

# ---- refused --------------------------------------------------------------------------------------------
note "render.sh refuses bad arguments and plans: exit 2, the problem named, nothing written"
printf 'not json' >"$P/garbage.json"
echo '{"version": 3, "splits": []}' >"$P/noshards.json"
"$PY" -c 'import json,sys; p=json.load(open(sys.argv[1])); p["shards"]=[]; json.dump(p, open(sys.argv[2], "w"))' "$P/eight.json" "$P/empty.json"
"$PY" -c 'import json,sys; p=json.load(open(sys.argv[1])); p["version"]=2; json.dump(p, open(sys.argv[2], "w"))' "$P/eight.json" "$P/v2.json"
n_refused=0
# refused MESSAGE PLAN ARGS...: render.sh PLAN OUT ARGS exits 2 saying MESSAGE (fixed string); OUT not made.
refused() {
  local msg=$1 plan=$2 out="$WORK/refused-$n_refused"
  n_refused=$((n_refused + 1))
  shift 2
  expect_clean_failure bash "$RENDER" "$plan" "$out" "$@"
  if ((RC != 2)) || ! grep -qF -- "$msg" "$ERR"; then
    show_output
    fail "render.sh $plan $*: expected exit 2 and '$msg', got exit $RC"
  fi
  [[ ! -e $out ]] || fail "render.sh $plan $* made $out"
}
refused 'cannot read the plan' "$P/missing.json" --image "$IMAGE"
refused 'is not JSON' "$P/garbage.json" --image "$IMAGE"
refused 'is not a vts plan (no "shards" array)' "$P/noshards.json" --image "$IMAGE"
refused 'the plan has no shards' "$P/empty.json" --image "$IMAGE"
refused 'plan version 2' "$P/v2.json" --image "$IMAGE"
refused '--image REF is required' "$P/eight.json"
refused "is too long for 32768 shards: the shards' last pod hostname" "$P/planet.json" --image "$IMAGE" --name "$(printf 'p%.0s' {1..51})"
refused 'is not a DNS-1123 label' "$P/eight.json" --image "$IMAGE" --name Build
refused 'is not a valid StorageClass name' "$P/eight.json" --image "$IMAGE" --storage-class 'NFS RWX'
refused '--parallelism must be a positive integer' "$P/eight.json" --image "$IMAGE" --parallelism 0
refused '--claim-size' "$P/eight.json" --image "$IMAGE" --claim-size 2TB
refused 'unknown option --completions' "$P/eight.json" --image "$IMAGE" --completions 8
refused 'expected PLAN.json and OUT_DIR' "$P/eight.json" --image "$IMAGE" extra
mkdir -p "$WORK/occupied"
echo 'kind: ConfigMap' >"$WORK/occupied/mine.yaml"
expect_clean_failure bash "$RENDER" "$P/eight.json" "$WORK/occupied" --image "$IMAGE"
if ((RC != 2)) || ! grep -qF 'holds other files (mine.yaml)' "$ERR"; then
  show_output
  fail "render.sh into a directory of other files: expected exit 2, got $RC"
fi
[[ $(ls "$WORK/occupied") == mine.yaml ]] || fail "render.sh wrote beside another file"
# Rendering again into its own directory replaces its files.
render_ok "$P/one.json" "$R/eight"
grep -q '^  completions: 1$' "$R/eight/shards-job.yaml" || fail "a second rendering did not replace shards-job.yaml"
# A plan of one archive rendered where a set's were: no manifest Job is left to apply.
render_ok "$P/one.json" "$R/set"
[[ ! -e $R/set/manifest-job.yaml ]] || fail "a rendering of one archive left the set's manifest-job.yaml"
refused '--merge-parallelism is for a plan of a set' "$P/eight.json" --image "$IMAGE" --merge-parallelism 4
# The longest name that fits: 50 + "-shards-32767" = 63 characters.
render_ok "$P/planet.json" "$R/longest" --name "$(printf 'p%.0s' {1..50})"

if command -v shellcheck >/dev/null 2>&1; then
  shellcheck "$RENDER" || fail "shellcheck render.sh (above)"
else
  note "SKIP shellcheck: not installed"
fi
note "PASS in $((($(date +%s%N) - t_start) / 1000000)) ms"
