#!/usr/bin/env bash
# deploy/batch: the sharded build's files for Kubernetes, Slurm and one machine.
#   - the manifests k8s/render.sh writes for a small synthetic plan (k8s_render.sh checks them
#     against the schemas and the API server's Job rules for plans of every size): each document
#     against its apiVersion/kind schema (deploy_js/validate_k8s.js), plus python3-yaml checks of
#     what the schema cannot see: completions = the plan's shard count, the volumes mounted where
#     the commands read and write, one image and user everywhere, and the per-index command line —
#     the container's command must be the one build.sbatch and local/run-shards.sh run. Broken
#     copies must fail the schema and these checks.
#   - the builder image's runtime packages against the DT_NEEDED entries of the vts under test;
#   - bash -n and shellcheck on the scripts; the runner's usage errors;
#   - the runner, the sbatch scripts (with SLURM_ARRAY_TASK_ID set by hand) and the Jobs'
#     command vectors run for real on a small synthetic plan, each merged
#     archive byte-identical (sha256) to a single-machine `vts build`; a deleted part is the only
#     shard rebuilt on the next run; a runner killed (SIGKILL) mid-way resumes to the same bytes;
#   - a plan of a set of archives (vts plan --archive-level 2): the runner's parallel archive
#     merges and manifest, and apex.sbatch + merge.sbatch per array task (VTS_ARCHIVE_OFFSET) +
#     merge.sbatch --manifest, each set joined (vts merge --join) byte-identical to `vts build`'s;
#     an OUT that is not what the plan makes (a file for a set, a folder for one archive) refused.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
PY=${PYTHON3:-python3}
require_tool "$PY"
"$PY" -c 'import yaml' 2>/dev/null ||
  fail "python3 cannot import yaml (Debian package python3-yaml; run scripts/setup.sh)"
DEPLOY=${VTS_DEPLOY_DIR:-$(cd "$(dirname "${BASH_SOURCE[0]}")/../../deploy" && pwd)}
DEPLOY_JS=${DEPLOY_JS:-$(cd "$(dirname "${BASH_SOURCE[0]}")/deploy_js" && pwd)}
t_start=$(date +%s%N)

# ---- the plan and the rendered manifests ----------------------------------------------------------
# $BATCH: a copy of deploy/batch whose k8s/ holds what render.sh writes for the synthetic plan below.
R="$WORK/run"
mkdir -p "$R"
SIZE=3000x1700
# One name for all: the name defaults to the output file's stem, which differs below.
expect_ok "$VTS" plan --synthetic "$SIZE" --name planet -o "$R/plan.json" --shards 4
n=$("$PY" -c 'import json,sys; print(len(json.load(open(sys.argv[1]))["shards"]))' "$R/plan.json")
((n >= 2)) || fail "the plan has $n shards, expected several"
mkdir -p "$WORK/batch"
cp -r "$DEPLOY/batch"/. "$WORK/batch/"
BATCH="$WORK/batch"
rm -r "${BATCH:?}/k8s" # render.sh writes only into a directory of its own
expect_ok bash "$DEPLOY/batch/k8s/render.sh" "$R/plan.json" "$BATCH/k8s" --image registry.example.org/vts-build:test

# ---- consistency (python3-yaml) -----------------------------------------------------------------
# consistency BATCH_DIR: the checks below on a deploy/batch tree (the real one or a broken copy).
consistency() {
  "$PY" - "$1" "$DEPLOY" "$n" <<'PYTHON'
import os, re, shlex, sys, yaml

batch, deploy, n_shards = sys.argv[1], sys.argv[2], int(sys.argv[3])
k8s = os.path.join(batch, "k8s")
errors = []
def check(cond, what):
    if not cond:
        errors.append(what)

docs = []
for f in sorted(f for f in os.listdir(k8s) if f.endswith(".yaml")):
    docs += [d for d in yaml.safe_load_all(open(os.path.join(k8s, f))) if d]
by = {}
for d in docs:
    by.setdefault(d["kind"], {})[d["metadata"]["name"]] = d
jobs = by.get("Job", {})
check(set(jobs) == {"vts-build-plan", "vts-build-shards", "vts-build-apex", "vts-build-merge"}, f"Jobs: {sorted(jobs)}")
pvcs = by.get("PersistentVolumeClaim", {})
check("ReadWriteMany" in pvcs.get("vts-build", {}).get("spec", {}).get("accessModes", []),
      "PVC vts-build is ReadWriteMany (every pod writes its part to it)")

def pod(job):
    return jobs[job]["spec"]["template"]["spec"]
def ctr(job):
    return pod(job)["containers"][0]
def mounts(job):  # mountPath -> (volume, subPath, readOnly)
    return {m["mountPath"]: (m["name"], m.get("subPath", ""), bool(m.get("readOnly")))
            for m in ctr(job).get("volumeMounts", [])}

for name, job in jobs.items():
    spec = job["spec"]
    ps = pod(name)
    # The API server's own rules: job_rules.js (k8s_render.sh); here, that the four are suspended.
    check(spec.get("suspend") is True, f"{name}: created suspended (resumed in order)")
    vols = {v["name"]: v for v in ps.get("volumes", [])}
    for path, (vol, sub, ro) in mounts(name).items():
        check(vol in vols, f"{name}: mount {path} names no volume {vol}")
        claim = vols.get(vol, {}).get("persistentVolumeClaim", {}).get("claimName")
        check(claim is None or claim in pvcs, f"{name}: volume {vol} claims unknown PVC {claim}")
    sc = ps.get("securityContext", {})
    check(sc.get("runAsNonRoot") is True and sc.get("runAsUser") == 10001,
          f"{name}: runs as non-root uid 10001 (deploy/k8s's and the image's user)")
    csc = ctr(name).get("securityContext", {})
    check(csc.get("readOnlyRootFilesystem") is True and csc.get("allowPrivilegeEscalation") is False,
          f"{name}: read-only root, no privilege escalation")
    check(ctr(name)["image"] == ctr("vts-build-shards")["image"], f"{name}: the shards' image")
    check(not any(e.get("name") == "JOB_COMPLETION_INDEX" for e in ctr(name).get("env", [])),
          f"{name}: sets JOB_COMPLETION_INDEX itself (Kubernetes sets it in Indexed mode)")

shards = jobs["vts-build-shards"]["spec"]
check(shards.get("completionMode") == "Indexed", "shards: completionMode: Indexed")
check(shards.get("completions") == n_shards, f"shards: completions {shards.get('completions')}, the plan has {n_shards} shards")
check(isinstance(shards.get("parallelism"), int) and shards["parallelism"] >= 1, "shards: parallelism")
check(isinstance(shards.get("backoffLimitPerIndex"), int), "shards: backoffLimitPerIndex")
check(isinstance(shards.get("maxFailedIndexes"), int), "shards: maxFailedIndexes")
rules = shards.get("podFailurePolicy", {}).get("rules", [])
check(any(r["action"] == "FailIndex" and 2 in r.get("onExitCodes", {}).get("values", [])
          and r["onExitCodes"].get("operator") == "In" for r in rules),
      "shards: exit code 2 (bad arguments) fails the index at once (FailIndex)")
check(not any(4 in r.get("onExitCodes", {}).get("values", []) for r in rules),
      "shards: exit code 4 (I/O error) is retried, not failed at once")
req = ctr("vts-build-shards").get("resources", {}).get("requests", {})
check(str(req.get("cpu")) == "2" and req.get("memory"), "shards: requests 2 CPU and memory")

# The per-index command: the container's, build.sbatch's and the runner's, with the plan and the
# parts directory as PLAN and PARTS.
cmd = ctr("vts-build-shards")["command"]
check(cmd[:2] == ["vts", "build"] and "--shard" not in cmd,
      f"shards: command is `vts build` without --shard (the index comes from the environment): {cmd}")
def arg(c, flag):
    return c[c.index(flag) + 1] if flag in c and c.index(flag) + 1 < len(c) else None
plan, parts = arg(cmd, "--plan"), arg(cmd, "--out-dir")
canon = lambda c, p, d: ["PLAN" if a == p else "PARTS" if a == d else a for a in c]
k8s_line = canon(cmd[1:], plan, parts)
check(k8s_line == ["build", "--plan", "PLAN", "--out-dir", "PARTS"], f"shards: command {cmd}")
m = mounts("vts-build-shards")
check(m.get(os.path.dirname(plan or "/x/y"), ("", "", False))[1] == "plan",
      f"shards: {plan}'s directory is the volume's plan/ mount")
check(m.get(parts, ("", "", True))[1] == "parts" and not m[parts][2], f"shards: {parts} is parts/, writable")
check(m.get("/inputs", ("", "", False))[2], "shards: inputs mounted read-only at /inputs")
apex = ctr("vts-build-apex")["command"]
check(canon(apex[1:], plan, parts) == ["build", "--plan", "PLAN", "--apex", "--out-dir", "PARTS"],
      f"apex: command {apex}")
merge = ctr("vts-build-merge")["command"]
out = arg(merge, "-o")
check(canon(merge[1:], plan, parts) == ["merge", "--plan", "PLAN", "PARTS", "-o", out], f"merge: command {merge}")
for name in ("vts-build-apex", "vts-build-merge"):
    mm = mounts(name)
    check(mm.get(os.path.dirname(plan or "/x/y"), ("", "", False))[1] == "plan", f"{name}: plan/ mounted")
    check(mm.get(parts, ("", "", False))[1] == "parts", f"{name}: parts/ mounted at {parts}")
check(mounts("vts-build-apex")[parts][2] is False, "apex: parts/ writable (it writes apex.part)")
check(mounts("vts-build-merge").get(os.path.dirname(out or "/x/y"), ("", "", True))[1] == "out"
      and not mounts("vts-build-merge")[os.path.dirname(out)][2], "merge: out/ mounted writable")

def shell_line(path, pattern, plan_var, parts_var):
    """The vts arguments of the one uncommented line of PATH matching PATTERN, with the plan and
    parts variables as PLAN and PARTS (redirections and what follows them dropped)."""
    hits = [l for l in open(path).read().splitlines()
            if re.search(pattern, l) and not l.lstrip().startswith("#")]
    check(len(hits) == 1, f"{os.path.basename(path)}: one line matching {pattern!r} (got {len(hits)})")
    if not hits:
        return []
    words = shlex.split(hits[0].rstrip().rstrip("\\"))
    while words and (words[0] == "exec" or re.match(r"^[A-Z_]+=", words[0])):
        words = words[1:]
    words = words[1:]  # the vts executable
    stop = next((i for i, w in enumerate(words) if w[:1] in "<>|&" or w[:2] == "2>"), len(words))
    return ["PLAN" if w == plan_var else "PARTS" if w == parts_var else w for w in words[:stop]]
sb = shell_line(os.path.join(batch, "slurm", "build.sbatch"), r'"\$VTS" build ', "$PLAN", "$PARTS")
check(sb == k8s_line, f"build.sbatch runs {sb}, the Job runs {k8s_line}")
fin = shell_line(os.path.join(batch, "slurm", "finish.sbatch"), r'"\$VTS" build .*--apex', "$PLAN", "$PARTS")
check(fin == canon(apex[1:], plan, parts), f"finish.sbatch's apex {fin}")
rs = shell_line(os.path.join(batch, "local", "run-shards.sh"), r'JOB_COMPLETION_INDEX=.*"\$RUNNER_VTS" build ',
                "$RUNNER_PLAN", "$RUNNER_PARTS")
check(rs == k8s_line, f"run-shards.sh runs {rs}, the Job runs {k8s_line}")
sbatch = open(os.path.join(batch, "slurm", "build.sbatch")).read()
check(re.search(r"^#SBATCH --cpus-per-task=2$", sbatch, re.M), "build.sbatch: 2 CPUs per task, as the Job")
check("SLURM_ARRAY_TASK_ID" in sbatch and "--array=0-$((N-1))" in sbatch, "build.sbatch: array usage")
check("--dependency=afterok:" in open(os.path.join(batch, "slurm", "finish.sbatch")).read(),
      "finish.sbatch: afterok dependency documented")

# The builder image: its tag is the Jobs' image, its user the Jobs' uid.
df = open(os.path.join(batch, "Dockerfile")).read()
check(re.search(r"docker build -f deploy/batch/Dockerfile -t (\S+) \.", df) and "render.sh" in df
      and "--image" in df, "Dockerfile: documents its build and render.sh --image")
check(re.search(r"^USER 10001:10001$", df, re.M), "Dockerfile: USER 10001")
check("-DVTS_BUILD_BUILDER=OFF" not in df, "Dockerfile: the builder image keeps the builder")

for e in errors:
    print("deploy_batch: " + e, file=sys.stderr)
sys.exit(1 if errors else 0)
PYTHON
}
note "k8s/*.yaml, build.sbatch, finish.sbatch, run-shards.sh: consistent (one per-index command)"
consistency "$BATCH" >"$LOGS/consistency.log" 2>&1 ||
  { cat "$LOGS/consistency.log" >&2; fail "deploy/batch is inconsistent (above)"; }

note "the builder image's runtime packages: the libraries of the vts and vts-build under test"
VTS_BUILD_EXE=$(dirname "$VTS")/vts-build
[[ -x $VTS_BUILD_EXE ]] || fail "no vts-build beside $VTS (vts hands the build commands to it)"
needed=()
while read -r lib; do
  path=$(ldconfig -p | awk -v l="$lib" '$1 == l && !p { print $NF; p = 1 }')
  [[ -n $path ]] || fail "cannot find $lib"
  real=$(readlink -f "$path")
  pkg=$(dpkg -S "$real" 2>/dev/null || dpkg -S "/usr$real" 2>/dev/null || dpkg -S "${real#/usr}" 2>/dev/null || true)
  pkg=${pkg%%:*}
  [[ -n $pkg ]] || fail "no Debian package owns $real ($lib)"
  case $pkg in libc6 | libgcc-s1 | libglfw3 | libepoxy0) continue ;; esac # base image / viewer only
  [[ " ${needed[*]} " == *" $pkg "* ]] || needed+=("$pkg")
done < <(readelf -d "$VTS" "$VTS_BUILD_EXE" | sed -nE 's/.*\(NEEDED\).*\[(.*)\]/\1/p' | sort -u)
# missing_pkgs DOCKERFILE: prints the packages of $needed its runtime stage does not install.
missing_pkgs() {
  local runtime pkg
  runtime=$(sed -n '/^FROM debian:12-slim/,$p' "$1" | sed -n '/apt-get install/,/rm -rf/p')
  for pkg in "${needed[@]}"; do
    tr -s ' \\\t' '\n' <<<"$runtime" | grep -qxF -- "$pkg" || echo "$pkg"
  done
}
miss=$(missing_pkgs "$BATCH/Dockerfile")
[[ -z $miss ]] || fail "deploy/batch/Dockerfile's runtime stage lacks ${miss//$'\n'/ } (vts or vts-build needs them: readelf -d)"
note "${needed[*]}"

# ---- docs/PLANET.md's arithmetic -------------------------------------------------------------------
note "docs/PLANET.md: the tile counts, shard table and hours recomputed"
"$PY" - "$DEPLOY/../docs/PLANET.md" <<'PYTHON' || fail "docs/PLANET.md's figures do not follow from its formulas (above)"
import re, sys
doc = re.sub(r"(?<=\d) (?=\d{3}\b)", "", open(sys.argv[1]).read())  # "11 453 246 123" -> digits
errors = []
def has(text, what):
    if text not in doc:
        errors.append(f"{what}: expected {text!r}")
maxz, T = 17, 256
assert T * 2**maxz == 2**25
crs84 = lambda z: 1 if z == 0 else 4**z // 2
merc = lambda z: 4**z
tot = {n: sum(f(z) for z in range(maxz + 1)) for n, f in (("crs84", crs84), ("merc", merc))}
has(f"**{tot['crs84']}**", "WorldCRS84Quad tiles")
has(f"**{tot['merc']}**", "WebMercatorQuad tiles")
for L in (7, 8, 9):
    per = (4**(maxz + 1 - L) - 1) // 3
    for n, f in (("crs84", crs84), ("merc", merc)):
        assert f(L) * per + sum(f(z) for z in range(L)) == tot[n]
    row = re.search(rf"^\| \**{L}\** \| \**{crs84(L)} / {merc(L)}\** \| {per} \| {T * 2**(maxz - L)} \|", doc, re.M)
    if not row:
        errors.append(f"shard table row L={L}: {crs84(L)} / {merc(L)} shards, {per} tiles, {T * 2**(maxz - L)} wide")
has(f"32768 × 349525 + {sum(crs84(z) for z in range(8))} = {tot['crs84']}", "the L = 8 check")
rate = 5e9 / 63.54
has("7.87·10^7 texels/s", "throughput")
bc1, sharding = 100.77 / 82.42, 1.10  # measured: bc1 / lossless single-build CPU; shards / single
has(f"**{bc1:.2f}×**", "bc1 factor")
has(f"**{sharding:.2f}×**", "sharding factor")
for texels, lossless, bc1_cell in ((2**49, "8.5 h", "**10.4 h**"), (2**50, "17.1 h", "20.9 h")):
    h = texels / (256 * rate) / 3600
    has(lossless, "sharded lossless hours")
    has(bc1_cell, "sharded bc1 hours")
    if lossless != f"{h * sharding:.1f} h" or bc1_cell.strip("*") != f"{h * sharding * bc1:.1f} h":
        errors.append(f"sharded hours {lossless} / {bc1_cell} are not {h * sharding:.1f} h / {h * sharding * bc1:.1f} h")
for texels, cell in ((2**25 * 2**24, "**7.8 h**"), (2**50, "15.5 h")):
    has(cell, f"lossless hours {texels / (256 * rate) / 3600:.1f}")
    if cell.strip("*") != f"{texels / (256 * rate) / 3600:.1f} h":
        errors.append(f"{cell} is not {texels / (256 * rate) / 3600:.1f} h")
has(f"{tot['crs84'] * 12302 / 2**40:.0f} TiB", "bc1 bytes")
for e in errors:
    print("PLANET.md: " + e, file=sys.stderr)
sys.exit(1 if errors else 0)
PYTHON

# ---- schema validation ------------------------------------------------------------------------------
require_tool "$NODE"
for pkg in kubernetes-models yaml; do
  [[ -f $DEPLOY_JS/node_modules/$pkg/package.json ]] ||
    fail "npm package $pkg is not installed in $DEPLOY_JS (run scripts/setup.sh)"
done
validate_k8s() { "$NODE" "$DEPLOY_JS/validate_k8s.js" "$@"; }
job_rules() { "$NODE" "$DEPLOY_JS/job_rules.js" "$@"; }
note "render.sh's manifests: each document against its apiVersion/kind schema (kubernetes-models)"
validate_k8s "$BATCH"/k8s/*.yaml >"$LOGS/validate_k8s.log" 2>&1 ||
  { cat "$LOGS/validate_k8s.log" >&2; fail "render.sh's manifests failed schema validation (above)"; }
note "$(cat "$LOGS/validate_k8s.log")"

note "broken copies are rejected"
BROKEN="$WORK/broken"
n_broken=0
# broken_copy FILE SED_EXPR: a copy of deploy/batch (in $BROKEN/bN) with FILE edited by SED_EXPR,
# which must change it. Sets COPY.
broken_copy() {
  n_broken=$((n_broken + 1))
  COPY="$BROKEN/b$n_broken"
  mkdir -p "$COPY"
  cp -r "$BATCH"/. "$COPY/"
  sed "$2" "$BATCH/$1" >"$COPY/$1"
  ! cmp -s "$BATCH/$1" "$COPY/$1" || fail "broken_copy: '$2' does not change $1 (update the test)"
}
# expect_rejected WHAT PATTERN CMD...: CMD must fail and print PATTERN (an ERE).
expect_rejected() {
  local what=$1 pattern=$2 log="$LOGS/broken-$n_broken.log"
  shift 2
  if "$@" >"$log" 2>&1; then
    cat "$log" >&2
    fail "accepted: $what"
  fi
  grep -qE "$pattern" "$log" || { cat "$log" >&2; fail "rejected $what without /$pattern/"; }
  note "rejected: $what"
}
broken_copy k8s/shards-job.yaml 's/^  backoffLimitPerIndex: \([0-9]*\)$/  backoffLimitPerIndex: "\1"/'
expect_rejected "backoffLimitPerIndex: a string" 'Job/vts-build-shards.*spec/backoffLimitPerIndex must be integer' \
  validate_k8s "$COPY"/k8s/*.yaml
broken_copy k8s/shards-job.yaml 's/^      - action: FailIndex$/      - action: FailIdx/'
expect_rejected "a podFailurePolicy action FailIdx" 'Job/vts-build-shards.*podFailurePolicy/rules/0/action must be equal to one of the allowed values' \
  validate_k8s "$COPY"/k8s/*.yaml
broken_copy k8s/shards-job.yaml 's/^  maxFailedIndexes:/  maxFailedIndices:/'
expect_rejected "an unknown field maxFailedIndices" 'Job/vts-build-shards.*unknown field /spec/maxFailedIndices' \
  validate_k8s "$COPY"/k8s/*.yaml
broken_copy k8s/shards-job.yaml 's/^  completionMode: Indexed$/  completionMode: NonIndexed/'
expect_rejected "per-index limits on a NonIndexed Job" 'shards: completionMode: Indexed' consistency "$COPY"
expect_rejected "per-index limits on a NonIndexed Job" 'rule per-index-needs-Indexed' job_rules "$COPY"/k8s/*.yaml
broken_copy k8s/shards-job.yaml 's/^      restartPolicy: Never$/      restartPolicy: OnFailure/'
expect_rejected "podFailurePolicy with restartPolicy OnFailure" 'rule podFailurePolicy-restartPolicy-never' \
  job_rules "$COPY"/k8s/*.yaml
broken_copy k8s/shards-job.yaml 's|"--out-dir", /parts\]|"--shard", "0", "--out-dir", /parts]|'
# shellcheck disable=SC2016  # literal backquotes and $VARS in these patterns and sed expressions
expect_rejected "a Job command with --shard" 'shards: command is `vts build` without --shard' consistency "$COPY"
# shellcheck disable=SC2016
broken_copy slurm/build.sbatch 's|--out-dir "\$PARTS"$|--out-dir "$PARTS" --threads 1|'
expect_rejected "build.sbatch running another command than the Job" 'build.sbatch runs .*--threads' \
  consistency "$COPY"
# shellcheck disable=SC2016
broken_copy local/run-shards.sh 's|"\$RUNNER_VTS" build --plan "\$RUNNER_PLAN"|"$RUNNER_VTS" build --codec bc1 --plan "$RUNNER_PLAN"|'
expect_rejected "run-shards.sh running another command than the Job" 'run-shards.sh runs .*bc1' \
  consistency "$COPY"
broken_copy k8s/shards-job.yaml 's|mountPath: /parts$|mountPath: /part|'
expect_rejected "the parts volume mounted off the command's --out-dir" 'shards: /parts is parts/, writable' \
  consistency "$COPY"
broken_copy k8s/shards-job.yaml "s|^  completions: $n\$|  completions: $((n + 1))|"
expect_rejected "completions other than the plan's shard count" "shards: completions $((n + 1)), the plan has $n shards" \
  consistency "$COPY"
dropped=""
for pkg in "${needed[@]}"; do if [[ $pkg =~ ^[a-z0-9.-]+$ ]]; then dropped=$pkg; fi; done
[[ -n $dropped ]] || fail "no package to drop from a copy of the Dockerfile"
broken_copy Dockerfile "s/ ${dropped//./\\.}\\b//"
[[ $(missing_pkgs "$COPY/Dockerfile") == "$dropped" ]] || fail "the package check misses a removed $dropped"
note "rejected: a builder image without $dropped"

# ---- scripts -----------------------------------------------------------------------------------------
SCRIPTS=("$BATCH/local/run-shards.sh" "$BATCH/slurm/submit.sh" "$BATCH/slurm/build.sbatch"
  "$BATCH/slurm/finish.sbatch" "$BATCH/slurm/apex.sbatch" "$BATCH/slurm/merge.sbatch")
for s in "${SCRIPTS[@]}"; do
  bash -n "$s" || fail "bash -n $s"
  [[ -x $s ]] || fail "$s is not executable"
done
bash -n "$BATCH/lib.sh" || fail "bash -n $BATCH/lib.sh"
if command -v shellcheck >/dev/null 2>&1; then
  note "shellcheck $(shellcheck --version | sed -n 's/^version: //p')"
  # -x: follow what they source (deploy/batch/lib.sh), found next to each script.
  shellcheck -x "${SCRIPTS[@]}" || fail "shellcheck found problems (above)"
else
  note "SKIP shellcheck: not installed (Debian package shellcheck)"
fi

RUNNER="$BATCH/local/run-shards.sh"
note "run-shards.sh: usage errors exit 2 naming the problem"
echo '{"splits": []}' >"$WORK/noshards.json"
# usage_error MESSAGE ARGS...: the runner with ARGS exits 2 and says MESSAGE (fixed string).
usage_error() {
  local msg=$1
  shift
  expect_clean_failure bash "$RUNNER" --vts "$VTS" "$@"
  if ((RC != 2)) || ! grep -qF -- "$msg" "$ERR"; then
    show_output
    fail "run-shards.sh $*: expected exit 2 and '$msg', got exit $RC"
  fi
}
usage_error 'is not a plan with a "shards" array' --out "$WORK/x.pmtiles" "$WORK/noshards.json"
usage_error '--jobs must be a positive integer' --jobs 0 --out "$WORK/x.pmtiles" "$WORK/noshards.json"
usage_error '--out OUT.pmtiles is required' "$WORK/noshards.json"
usage_error 'cannot read the plan' --out "$WORK/x.pmtiles" "$WORK/missing.json"

# ---- for real: a synthetic plan through the runner, the sbatch scripts and the Job's commands -------
expect_ok "$VTS" build --synthetic "$SIZE" --name planet -o "$R/single.pmtiles"
want=$(sha256sum <"$R/single.pmtiles")

note "run-shards.sh: $n shards, 2 at a time, then apex and merge"
expect_ok bash "$RUNNER" --vts "$VTS" --jobs 2 --out "$R/merged.pmtiles" "$R/plan.json"
[[ $(sha256sum <"$R/merged.pmtiles") == "$want" ]] || fail "run-shards.sh's archive differs from vts build's"
[[ $(wc -l <"$R/logs/joblog") == "$n" ]] || fail "joblog: expected $n lines"

note "a deleted part: only that shard is rebuilt, the archive is the same"
victim=$((n - 2))
victim_part=$(printf '%s/parts/shard-%06d.part' "$R" "$victim")
declare -A mtime
for p in "$R"/parts/shard-*.part; do mtime[$p]=$(stat -c %Y.%y "$p"); done
rm "$victim_part"
rm "$R/merged.pmtiles"
expect_ok bash "$RUNNER" --vts "$VTS" --jobs 2 --out "$R/merged.pmtiles" "$R/plan.json"
grep -q "^run-shards: $n shards, $((n - 1)) with a part already, 1 to build" "$OUT" || { show_output; fail "resume summary"; }
if [[ $(grep -c '^run-shards: shard [0-9]* built$' "$OUT") != 1 ]] ||
  ! grep -q "^run-shards: shard $victim built$" "$OUT"; then
  show_output
  fail "the rerun built other shards than $victim"
fi
[[ $(tail -n 1 "$R/logs/joblog" | cut -d' ' -f1-2) == "$victim 0" && $(wc -l <"$R/logs/joblog") == $((n + 1)) ]] ||
  fail "joblog: expected one new line for shard $victim"
for p in "${!mtime[@]}"; do
  [[ $p == "$victim_part" || $(stat -c %Y.%y "$p") == "${mtime[$p]}" ]] || fail "$p was rewritten"
done
[[ $(sha256sum <"$R/merged.pmtiles") == "$want" ]] || fail "the resumed archive differs"

note "the runner killed (SIGKILL, its whole process group) once a part exists, then run again"
rm -rf "$R/kparts" "$R/klogs"
setsid bash "$RUNNER" --vts "$VTS" --jobs 1 --parts "$R/kparts" --logs "$R/klogs" --out "$R/killed.pmtiles" \
  "$R/plan.json" >"$LOGS/killed.out" 2>&1 </dev/null &
killed_pid=$!
for ((i = 0; i < 600; i++)); do
  compgen -G "$R/kparts/shard-*.part" >/dev/null && break
  kill -0 "$killed_pid" 2>/dev/null || break
  sleep 0.05
done
kill -KILL -- "-$killed_pid" 2>/dev/null || true
wait "$killed_pid" 2>/dev/null || true
have=$(compgen -G "$R/kparts/shard-*.part" | wc -l)
((have >= 1)) || { cat "$LOGS/killed.out" >&2; fail "no part appeared before the runner ended"; }
if ((have == n)); then note "(every shard was done before the kill: the resume below only merges)"; fi
expect_ok bash "$RUNNER" --vts "$VTS" --jobs 2 --parts "$R/kparts" --logs "$R/klogs" --out "$R/killed.pmtiles" "$R/plan.json"
grep -q "^run-shards: $n shards, $have with a part already" "$OUT" || { show_output; fail "resume after the kill"; }
[[ $(sha256sum <"$R/killed.pmtiles") == "$want" ]] || fail "the archive after a killed run differs"

note "build.sbatch per array task (SLURM_ARRAY_TASK_ID), then finish.sbatch"
mkdir -p "$R/sparts"
for ((i = 0; i < n; i++)); do
  SLURM_ARRAY_TASK_ID=$i VTS=$VTS expect_ok bash "$BATCH/slurm/build.sbatch" "$R/plan.json" "$R/sparts"
done
VTS=$VTS expect_ok bash "$BATCH/slurm/finish.sbatch" "$R/plan.json" "$R/sparts" "$R/slurm.pmtiles"
[[ $(sha256sum <"$R/slurm.pmtiles") == "$want" ]] || fail "the sbatch scripts' archive differs"

note "the Jobs' command vectors, verbatim but for the mount paths (JOB_COMPLETION_INDEX per shard)"
mkdir -p "$R/k/plan" "$R/k/parts" "$R/k/out"
cp "$R/plan.json" "$R/k/plan/plan.json"
job_cmd() { k8s_job_command "$BATCH/k8s/$1-job.yaml" "$R/k"; } # JOB: its command, run in $R/k
mapfile -t shard_cmd < <(job_cmd shards)
mapfile -t apex_cmd < <(job_cmd apex)
mapfile -t merge_cmd < <(job_cmd merge)
[[ ${shard_cmd[0]} == vts && ${apex_cmd[0]} == vts && ${merge_cmd[0]} == vts ]] || fail "commands start with vts"
for ((i = 0; i < n; i++)); do
  JOB_COMPLETION_INDEX=$i expect_ok "$VTS" "${shard_cmd[@]:1}"
done
expect_ok "$VTS" "${apex_cmd[@]:1}"
expect_ok "$VTS" "${merge_cmd[@]:1}"
[[ $(sha256sum <"$R/k/out/planet.pmtiles") == "$want" ]] || fail "the Jobs' commands' archive differs"

# ---- a set of archives ----------------------------------------------------------------------------
# The same build cut at level 2: its parts are the plan's above (the archive level is not in the
# build hash), so the runner goes straight to the archives' merges.
expect_ok "$VTS" plan --synthetic "$SIZE" --name planet -o "$R/set.plan.json" --shards 4 --archive-level 2 --json
archives=$(json_get "$OUT" j.archives)
((archives > 3)) || fail "the set plan has $archives archives, expected several"
note "run-shards.sh with a set plan: $archives archive merges, 2 at a time, then the manifest"
usage_error '--out is a folder' --out "$R/set.pmtiles" "$R/set.plan.json"
usage_error 'the plan makes one archive' --out "$R/one/" "$R/plan.json"
expect_ok bash "$RUNNER" --vts "$VTS" --jobs 2 --out "$R/set" "$R/set.plan.json"
grep -q "^run-shards: $archives archives (level 2) into $R/set/, 2 at a time" "$OUT" || { show_output; fail "set summary"; }
[[ $(grep -c '^run-shards: archive [0-9]* merged$' "$OUT") == "$archives" ]] || { show_output; fail "not every archive merged"; }
[[ -s $R/set/tileset.json && $(wc -l <"$R/logs/merge-joblog") == "$archives" ]] || fail "no manifest, or merge-joblog"
expect_ok "$VTS" merge --join "$R/set" -o "$R/set-joined.pmtiles" -q
[[ $(sha256sum <"$R/set-joined.pmtiles") == "$want" ]] || fail "run-shards.sh's set, joined, differs from vts build's"

note "apex.sbatch, merge.sbatch per array task (two arrays: VTS_ARCHIVE_OFFSET 0 and 3), --manifest"
VTS=$VTS expect_ok bash "$BATCH/slurm/apex.sbatch" "$R/set.plan.json" "$R/sparts"
for ((i = 0; i < archives; i++)); do
  off=$((i < 3 ? 0 : 3))
  SLURM_ARRAY_TASK_ID=$((i - off)) VTS_ARCHIVE_OFFSET=$off VTS=$VTS \
    expect_ok bash "$BATCH/slurm/merge.sbatch" "$R/set.plan.json" "$R/sparts" "$R/sset"
done
[[ ! -e $R/sset/tileset.json ]] || fail "an archive's merge task wrote the manifest"
VTS=$VTS expect_ok bash "$BATCH/slurm/merge.sbatch" "$R/set.plan.json" "$R/sparts" "$R/sset/" --manifest
expect_ok "$VTS" merge --join "$R/sset" -o "$R/sset-joined.pmtiles" -q
[[ $(sha256sum <"$R/sset-joined.pmtiles") == "$want" ]] || fail "the sbatch scripts' set, joined, differs from vts build's"

note "PASS in $((($(date +%s%N) - t_start) / 1000000)) ms"
