#!/usr/bin/env bash
# render.sh PLAN.json OUT_DIR --image REF [--storage-class NAME] [--claim-size SIZE]
#           [--parallelism P] [--max-failed-indexes K] [--merge-parallelism M] [--name PREFIX]
# render.sh --estimate PLAN.json   prints the archive estimate the claim is sized from, as JSON
#                                  ({"archive": bytes, "tile_bytes": bytes}; for a plan of a set
#                                  also "archive_level", "archives" and "archive_max": `vts plan
#                                  --json` prints the same figures)
#
# Writes the Kubernetes manifests of a sharded build for one plan (docs/DEPLOY.md §9), ready for
# `kubectl apply -f OUT_DIR`: every figure the API server checks comes from the plan, so nothing is
# edited by hand. OUT_DIR gets
#   volume.yaml       the ReadWriteMany claim PREFIX: inputs/, plan/, parts/, out/; its size from
#                     the plan (its inputs' bytes + twice the archive estimate, see claim_bytes)
#   load-pod.yaml     PREFIX-load: makes the four directories, then waits; the inputs and the plan
#                     are copied into the volume through it (tar over kubectl exec)
#   plan-job.yaml     PREFIX-plan: `vts plan --update` in the cluster: the plan made where the
#                     inputs were, re-pointed at their copies under /inputs (each input's size and
#                     fingerprint read again: a copy that differs fails it, exit 5, before any
#                     shard runs)
#   shards-job.yaml   PREFIX-shards: Indexed, completions = the plan's shard count
#   apex-job.yaml, merge-job.yaml
#                     for a plan of a set of archives (vts plan --archive-level K: N archives),
#                     merge-job.yaml is Indexed, completions N, M at once (--merge-parallelism,
#                     default min(N, 16)): pod I runs vts merge --archive I into /out/set/; then
#   manifest-job.yaml PREFIX-manifest: vts merge --manifest, the set's /out/set/tileset.json
#   plan/             plan.local.json (the plan), inputs.txt (each input's path in the pods),
#                     upload.txt (each input's path relative to the directory copied); not
#                     manifests: `kubectl apply -f OUT_DIR` does not descend into it
# The Jobs are created suspended and resumed in order (the steps are printed at the end).
# An input path the plan holds relative is taken from the current directory (where vts plan ran).
# Exit 2 with a message naming the problem on a bad argument or a plan it cannot render.
set -euo pipefail
PY=${PYTHON3:-python3}
# plan_set.py (the archive count and estimate of a set, vts's rule) lies in the folder above.
VTS_BATCH_DIR=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
export VTS_BATCH_DIR
command -v "$PY" >/dev/null 2>&1 || {
  echo "render.sh: needs python3" >&2
  exit 2
}
exec "$PY" - "$@" <<'PYTHON'
import json, math, os, re, sys

sys.path.insert(0, os.environ["VTS_BATCH_DIR"])
import plan_set  # noqa: E402 (deploy/batch/plan_set.py)

USAGE = ("usage: render.sh PLAN.json OUT_DIR --image REF [--storage-class NAME] [--claim-size SIZE]\n"
         "                 [--parallelism P] [--max-failed-indexes K] [--merge-parallelism M]\n"
         "                 [--name PREFIX]\n"
         "       render.sh --estimate PLAN.json")
# The API server's limits these manifests are kept within (docs/DEPLOY.md §9, the rules table).
LABEL_MAX = 63                 # a Job's name is its pods' job-name label value
INDEXED_SOFT_LIMIT = 100_000   # completions above it: parallelism and maxFailedIndexes <= 10 000
HIGH_COMPLETIONS_CAP = 10_000
INT32_MAX = 2**31 - 1
DNS_LABEL = re.compile(r"^[a-z0-9]([-a-z0-9]*[a-z0-9])?$")
DNS_SUBDOMAIN = re.compile(r"^[a-z0-9]([-a-z0-9]*[a-z0-9])?(\.[a-z0-9]([-a-z0-9]*[a-z0-9])?)*$")
YAML_WORDS = {"true", "false", "null", "yes", "no", "on", "off", "y", "n"}  # quoted: not booleans
QUANTITY = re.compile(r"^[1-9][0-9]*(Ki|Mi|Gi|Ti|Pi|Ei)?$")
# Bytes per stored tile of S x S texels (docs/PLANET.md, "Bytes"; measured at S = 264): bc1 is at
# most S²/2; lossless as measured, scaled by S² (the measured image is smoother than real imagery:
# give --claim-size where a better figure is known). vts has the same rule (builder/src/
# shard_size.cpp, estimate_plan_size): tests/integration/k8s_render.sh checks the two agree.
LOSSLESS_FILTERED, LOSSLESS_UNFILTERED, MEASURED_S = 34_478, 66_475, 264
OUTPUTS = ("volume.yaml", "load-pod.yaml", "plan-job.yaml", "shards-job.yaml", "apex-job.yaml", "merge-job.yaml",
           "manifest-job.yaml")
MERGE_PARALLELISM = 16  # a set's archive merges at once, by default (at most N)
SET_DIR = "/out/set/"
EXIT_CODES_FINAL = [2, 3, 5, 6]  # vts: bad arguments, not found, corrupt input, unsupported


def die(msg):
    print(f"render.sh: {msg}", file=sys.stderr)
    sys.exit(2)


def parse_args(argv):
    opts = {"image": None, "storage-class": None, "claim-size": None, "parallelism": "256",
            "max-failed-indexes": "16", "merge-parallelism": None, "name": "vts-build"}
    pos, i = [], 0
    while i < len(argv):
        a = argv[i]
        if a in ("-h", "--help"):
            print(USAGE)
            sys.exit(0)
        if a.startswith("--"):
            key, sep, val = a[2:].partition("=")
            if key not in opts:
                die(f"unknown option {a}\n{USAGE}")
            if not sep:
                i += 1
                if i >= len(argv):
                    die(f"{a} needs a value")
                val = argv[i]
            opts[key] = val
        else:
            pos.append(a)
        i += 1
    if len(pos) != 2:
        die(f"expected PLAN.json and OUT_DIR\n{USAGE}")
    return pos[0], pos[1], opts


def positive(opts, key, zero_ok=False):
    v = opts[key]
    if not re.fullmatch(r"[0-9]+", v) or (int(v) == 0 and not zero_ok) or int(v) > INT32_MAX:
        die(f"--{key} must be a {'non-negative' if zero_ok else 'positive'} integer, got {v!r}")
    return int(v)


def load_plan(path):
    try:
        with open(path, encoding="utf-8") as f:
            plan = json.load(f)
    except OSError as e:
        die(f"cannot read the plan {path}: {e.strerror}")
    except ValueError as e:
        die(f"{path} is not JSON: {e}")
    if not isinstance(plan, dict) or not isinstance(plan.get("shards"), list):
        die(f'{path} is not a vts plan (no "shards" array)')
    if plan.get("version") != 3:
        die(f"{path}: plan version {plan.get('version')!r}; render.sh reads version 3 (vts plan of this tree)")
    g, o = plan.get("geometry"), plan.get("options")
    ints = lambda d, keys: isinstance(d, dict) and all(isinstance(d.get(k), int) and d[k] >= 0 for k in keys)
    if not ints(g, ("width", "height", "max_zoom")) or not ints(o, ("tile_size", "border")) \
            or not ints(plan, ("split_level", "apex_level")) or not isinstance(plan.get("inputs"), list):
        die(f"{path}: a plan without geometry, options, split and apex levels or inputs")
    if not plan["shards"]:
        die(f"{path}: the plan has no shards (nothing to build)")
    if not all(isinstance(t, list) and len(t) == 2 and all(isinstance(v, int) and v >= 0 for v in t)
               for t in plan["shards"]):
        die(f"{path}: a shard that is not [x, y]")
    if len(plan["shards"]) > INT32_MAX:
        die(f"{path}: {len(plan['shards'])} shards: a Job's completions is a 32-bit integer")
    k = plan.get("archive_level", 0)
    if not isinstance(k, int) or isinstance(k, bool) or not 0 <= k <= g["max_zoom"]:
        die(f"{path}: archive_level {k!r} is not a level of 0..{g['max_zoom']}")
    return plan


def archive_estimate(plan):
    """The merged archive's bytes and the bytes per stored tile, estimated from the plan."""
    g, o = plan["geometry"], plan["options"]
    T, S = o["tile_size"], o["tile_size"] + 2 * o["border"]
    if o.get("codec") == "bc1":
        per_tile = S * S // 2
    else:
        per_tile = LOSSLESS_UNFILTERED if o.get("filter") == "none" else LOSSLESS_FILTERED
        per_tile = math.ceil(per_tile * S * S / MEASURED_S**2)
    maxz, L, A = g["max_zoom"], plan["split_level"], plan["apex_level"]
    shards = [(t[0], t[1]) for t in plan["shards"]]  # level-L tiles [x, y]
    def own(z):  # the shards' tiles at level z >= L: each one's descendants within the image
        w, h = (-(-(-(-d // 2 ** (maxz - z))) // T) for d in (g["width"], g["height"]))
        span = 2 ** (z - L)
        clip = lambda start, size: max(0, min(span, size - start * span))
        return sum(clip(x, w) * clip(y, h) for x, y in shards)
    # the apex: the shards' distinct ancestors above L, their own tiles from L to A
    apex = sum(len({(x >> (L - z), y >> (L - z)) for x, y in shards}) for z in range(min(L, A)))
    apex += sum(own(z) for z in range(L, A))
    shard = sum(own(z) for z in range(A, maxz + 1))  # a sparse plan's shards: those with tiles
    return (apex + shard) * per_tile, per_tile


def claim_bytes(plan):
    """The volume's size: the inputs' bytes, the parts (about the archive) and the merged archive."""
    inputs = sum(i.get("size", 0) for i in plan["inputs"] if isinstance(i, dict))
    total = (inputs + 2 * archive_estimate(plan)[0]) * 105 // 100  # 5%: manifests, temporaries
    return max(1, -(-total // 2**30))  # GiB, at least 1


# ---- YAML: the few shapes these manifests use (block maps and lists; strings JSON-quoted) --------
def scalar(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    plain = re.fullmatch(r"[A-Za-z/][A-Za-z0-9./_-]*", v) and v.lower() not in YAML_WORDS
    return v if plain else json.dumps(v)


def emit(v, indent=0):
    pad, out = " " * indent, []
    if isinstance(v, dict):
        for k, x in v.items():
            if isinstance(x, (dict, list)) and x and not (isinstance(x, list) and all(not isinstance(e, (dict, list)) for e in x)):
                out.append(f"{pad}{k}:")
                out += emit(x, indent + 2)
            elif isinstance(x, list):
                out.append(f"{pad}{k}: [{', '.join(scalar(e) for e in x)}]")
            elif isinstance(x, dict):
                out.append(f"{pad}{k}: {{}}")
            else:
                out.append(f"{pad}{k}: {scalar(x)}")
    else:
        for x in v:
            sub = emit(x, indent + 2)
            out.append(f"{pad}- {sub[0].lstrip()}")
            out += sub[1:]
    return out


def write(out_dir, fname, comment, obj):
    text = "".join(f"# {l}\n" if l else "#\n" for l in comment.strip("\n").split("\n"))
    with open(os.path.join(out_dir, fname), "w", encoding="utf-8") as f:
        f.write(text + "\n".join(emit(obj)) + "\n")


# ---- the objects ------------------------------------------------------------------------------
def labels(prefix, component):
    return {"app.kubernetes.io/name": "vtstream", "app.kubernetes.io/instance": prefix,
            "app.kubernetes.io/component": component}


def pod_spec(prefix, image, command, mounts, memory=("1Gi", "2Gi"), cpu="2"):
    """The pod of every Job: uid 10001 (the image's user), read-only root, one container `vts`."""
    return {
        "restartPolicy": "Never",  # required by podFailurePolicy; a retry is a new pod
        "securityContext": {"runAsNonRoot": True, "runAsUser": 10001, "runAsGroup": 10001,
                            "fsGroup": 10001, "seccompProfile": {"type": "RuntimeDefault"}},
        "containers": [{
            "name": "vts", "image": image, "command": command,
            "resources": {"requests": {"cpu": cpu, "memory": memory[0]}, "limits": {"memory": memory[1]}},
            "securityContext": {"allowPrivilegeEscalation": False, "readOnlyRootFilesystem": True,
                                "capabilities": {"drop": ["ALL"]}},
            "volumeMounts": [dict({"name": "build", "mountPath": "/" + sub, "subPath": sub},
                                  **({"readOnly": True} if ro else {})) for sub, ro in mounts]
                            + [{"name": "tmp", "mountPath": "/tmp"}],
        }],
        "volumes": [{"name": "build", "persistentVolumeClaim": {"claimName": prefix}},
                    {"name": "tmp", "emptyDir": {"sizeLimit": "1Gi"}}],
    }


def failure_policy(final_action):
    return {"rules": [
        {"action": final_action,
         "onExitCodes": {"containerName": "vts", "operator": "In", "values": EXIT_CODES_FINAL}},
        {"action": "Ignore", "onPodConditions": [{"type": "DisruptionTarget", "status": "True"}]},
    ]}


def job(prefix, component, spec, pod):
    name = f"{prefix}-{component}"
    return {"apiVersion": "batch/v1", "kind": "Job",
            "metadata": {"name": name, "labels": labels(prefix, f"build-{component}")},
            "spec": dict(spec, suspend=True, ttlSecondsAfterFinished=604800,
                         template={"metadata": {"labels": labels(prefix, f"build-{component}")}, "spec": pod})}


def main():
    if sys.argv[1:2] == ["--estimate"]:
        if len(sys.argv) != 3:
            die(f"--estimate takes one PLAN.json\n{USAGE}")
        plan = load_plan(sys.argv[2])
        archive, per_tile = archive_estimate(plan)
        est = {"archive": archive, "tile_bytes": per_tile}
        if plan_set.archive_count(plan):
            est.update(archive_level=plan["archive_level"], archives=plan_set.archive_count(plan),
                       archive_max=plan_set.archive_max(plan))
        print(json.dumps(est))
        return
    plan_path, out_dir, opts = parse_args(sys.argv[1:])
    image, prefix, sc = opts["image"], opts["name"], opts["storage-class"]
    if not image:
        die("--image REF is required: the builder image, built from deploy/batch/Dockerfile and pushed "
            "to a registry the cluster pulls from (docs/DEPLOY.md §9); no image is published")
    if re.search(r"\s", image):
        die(f"--image {image!r} contains white space")
    if sc is not None and (len(sc) > 253 or not DNS_SUBDOMAIN.match(sc)):
        die(f"--storage-class {sc!r} is not a valid StorageClass name (DNS-1123 subdomain)")
    if opts["claim-size"] is not None and not QUANTITY.match(opts["claim-size"]):
        die(f"--claim-size {opts['claim-size']!r}: a whole number with an optional binary suffix (e.g. 800Ti)")
    parallelism = positive(opts, "parallelism")
    max_failed = positive(opts, "max-failed-indexes", zero_ok=True)
    plan = load_plan(plan_path)
    n = len(plan["shards"])
    archives = plan_set.archive_count(plan)  # 0: one archive
    if archives > INT32_MAX:
        die(f"{plan_path}: {archives} archives: a Job's completions is a 32-bit integer")
    if opts["merge-parallelism"] is not None and not archives:
        die("--merge-parallelism is for a plan of a set of archives (vts plan --archive-level K)")
    merge_parallelism = min(positive(opts, "merge-parallelism") if opts["merge-parallelism"] else MERGE_PARALLELISM,
                            max(archives, 1))
    if not DNS_LABEL.match(prefix):
        die(f"--name {prefix!r} is not a DNS-1123 label (lower-case letters, digits, '-')")
    # The longest names the API server checks: an Indexed Job's last pod hostname, NAME-(N-1).
    for component, count, what, whose in (("shards", n, "shards", "shards'"), ("merge", archives, "archives", "merges'")):
        longest = f"{prefix}-{component}-{count - 1}"
        if count and len(longest) > LABEL_MAX:
            die(f"--name {prefix!r} is too long for {count} {what}: the {whose} last pod hostname {longest} "
                f"has {len(longest)} characters, at most {LABEL_MAX}")
    parallelism, max_failed = min(parallelism, n), min(max_failed, n)
    if n > INDEXED_SOFT_LIMIT:
        parallelism = min(parallelism, HIGH_COMPLETIONS_CAP)
        max_failed = min(max_failed, HIGH_COMPLETIONS_CAP)
    claim = opts["claim-size"] or f"{claim_bytes(plan)}Gi"

    paths = [i.get("path") if isinstance(i, dict) else None for i in plan["inputs"]]
    if any(not isinstance(p, str) or not p or "\n" in p for p in paths):
        die(f"{plan_path}: an input without a path, or a path with a newline")
    absolute = [os.path.abspath(p) for p in paths]
    common = os.path.commonpath([os.path.dirname(p) for p in absolute]) if absolute else ""
    rel = [os.path.relpath(p, common) for p in absolute]
    missing = [p for p in absolute if not os.path.isfile(p)]
    if missing:  # the manifests do not need them, the upload step does
        print(f"render.sh: warning: {len(missing)} input(s) not found here, e.g. {missing[0]} (a relative "
              "path in the plan is taken from the current directory: run render.sh where vts plan ran)",
              file=sys.stderr)

    # `kubectl apply -f OUT_DIR` applies every manifest there: only this script's may be.
    others = sorted(set(os.listdir(out_dir)) - set(OUTPUTS) - {"plan"}) if os.path.isdir(out_dir) else []
    if others:
        die(f"{out_dir} holds other files ({', '.join(others[:3])}): render into a new or empty directory")
    try:
        os.makedirs(os.path.join(out_dir, "plan"), exist_ok=True)
    except OSError as e:
        die(f"cannot make {out_dir}/plan: {e.strerror}")
    with open(plan_path, "rb") as src, open(os.path.join(out_dir, "plan", "plan.local.json"), "wb") as dst:
        dst.write(src.read())
    with open(os.path.join(out_dir, "plan", "inputs.txt"), "w", encoding="utf-8") as f:
        f.writelines(f"/inputs/{r}\n" for r in rel)
    with open(os.path.join(out_dir, "plan", "upload.txt"), "w", encoding="utf-8") as f:
        f.writelines(f"{r}\n" for r in rel)

    meta = lambda name, component: {"name": name, "labels": labels(prefix, component)}
    write(out_dir, "volume.yaml", f"""
The build's working volume, shared by every pod: ReadWriteMany (NFS, CephFS, EFS, Filestore,
Azure Files, ...). inputs/ (read-only in the Jobs), plan/, parts/ (each part written under a
temporary name, fsynced and renamed: a part that exists is complete), out/ (the archive, or a
set's archives and manifest in out/set/).
Size: the inputs' bytes ({len(paths)} in the plan) + twice the archive estimated from the plan's
geometry and codec (parts and archive side by side), + 5% (render.sh --claim-size overrides it).""",
          {"apiVersion": "v1", "kind": "PersistentVolumeClaim", "metadata": meta(prefix, "build"),
           "spec": dict({"accessModes": ["ReadWriteMany"]}, **({"storageClassName": sc} if sc else {}),
                        resources={"requests": {"storage": claim}})})

    load = pod_spec(prefix, image, ["sh", "-c", "mkdir -p /build/inputs /build/plan /build/parts /build/out "
                                    "&& exec sleep infinity"], [], memory=("64Mi", "256Mi"), cpu="100m")
    load["containers"][0]["volumeMounts"] = [{"name": "build", "mountPath": "/build"}]
    load["volumes"] = load["volumes"][:1]
    write(out_dir, "load-pod.yaml", """
Makes the volume's directories (the Jobs mount them by subPath), then waits: the inputs and the
plan are copied into the volume through it (tar over `kubectl exec`, the steps render.sh printed).
Delete it once the plan Job is complete.""",
          {"apiVersion": "v1", "kind": "Pod", "metadata": meta(f"{prefix}-load", "build-load"), "spec": load})

    update = "vts plan --update /plan/plan.local.json" + (" --input-list /plan/inputs.txt" if paths else "")
    plan_script = (f"{update} -o /tmp/plan.json --json >/tmp/update.json && cat /tmp/update.json && "
                   "if grep -q '\"changed_inputs\": \\[\\]' /tmp/update.json; then "
                   "cp /tmp/plan.json /plan/.plan.json.tmp && mv /plan/.plan.json.tmp /plan/plan.json; "
                   "else echo 'an input copy differs from the one planned (changed_inputs above): copy it again' >&2; "
                   "exit 5; fi")
    write(out_dir, "plan-job.yaml", """
The plan, in the cluster: `vts plan --update` points the plan made where the inputs were at their
copies under /inputs (plan/inputs.txt) and reads each again: the same build (the shards below),
refused if the copies make another; a copy that differs from the input planned (its size or
fingerprint) fails the Job with exit 5, named in its log, and no plan.json is written. Resume it
once the inputs and the plan are copied.""",
          job(prefix, "plan", {"backoffLimit": 2, "podFailurePolicy": failure_policy("FailJob")},
              pod_spec(prefix, image, ["sh", "-c", plan_script], [("inputs", True), ("plan", False)])))

    write(out_dir, "shards-job.yaml", f"""
The {n} shards: one pod per index (JOB_COMPLETION_INDEX, which `vts build --plan` reads), the same
command in each; {parallelism} at once. A failed pod is retried for its own index only
(backoffLimitPerIndex); the Job stops once more than {max_failed} indexes have failed. vts's exit codes 2, 3, 5, 6
say the same run would fail again: the index fails at once (FailIndex); 4 (I/O) and a killed pod
are retried; a drained node or preemption (DisruptionTarget) does not count. A shard is
idempotent: a retry writes the same part.""",
          job(prefix, "shards", {"completionMode": "Indexed", "completions": n, "parallelism": parallelism,
                                 "backoffLimitPerIndex": 3, "maxFailedIndexes": max_failed,
                                 "podFailurePolicy": failure_policy("FailIndex")},
              pod_spec(prefix, image, ["vts", "build", "--plan", "/plan/plan.json", "--out-dir", "/parts"],
                       [("inputs", True), ("plan", True), ("parts", False)])))

    write(out_dir, "apex-job.yaml", "The apex: the levels above the shards', from their parts.",
          job(prefix, "apex", {"backoffLimit": 3, "podFailurePolicy": failure_policy("FailJob")},
              pod_spec(prefix, image, ["vts", "build", "--plan", "/plan/plan.json", "--apex", "--out-dir", "/parts"],
                       [("plan", True), ("parts", False)])))

    merge_mounts = [("plan", True), ("parts", True), ("out", False)]
    if not archives:
        write(out_dir, "merge-job.yaml", """
The merge: the parts and the apex into one archive, byte-identical to a single-machine
`vts build` of the plan; its memory does not grow with the shard count (docs/PLANET.md).""",
              job(prefix, "merge", {"backoffLimit": 2, "podFailurePolicy": failure_policy("FailJob")},
                  pod_spec(prefix, image, ["vts", "merge", "--plan", "/plan/plan.json", "/parts", "-o", "/out/planet.pmtiles"],
                           merge_mounts, memory=("512Mi", "1Gi"), cpu="1")))
        stale = ["manifest-job.yaml"]
    else:
        merge_failed = min(positive(opts, "max-failed-indexes", zero_ok=True), archives)
        if archives > INDEXED_SOFT_LIMIT:
            merge_parallelism = min(merge_parallelism, HIGH_COMPLETIONS_CAP)
            merge_failed = min(merge_failed, HIGH_COMPLETIONS_CAP)
        write(out_dir, "merge-job.yaml", f"""
The merges of the set of {archives} archives (archive level {plan['archive_level']}, docs/PLANET.md): one pod
per index I (JOB_COMPLETION_INDEX), `vts merge --archive I` into {SET_DIR}, the archive's tiles byte for
byte the one-file merge's; {merge_parallelism} at once. A failed pod is retried for its own index
(backoffLimitPerIndex); the Job stops once more than {merge_failed} indexes have failed; exit codes as
the shards'. An archive without tiles (a sparse plan) leaves a marker, NAME.pmtiles.empty.""",
              job(prefix, "merge", {"completionMode": "Indexed", "completions": archives,
                                    "parallelism": merge_parallelism, "backoffLimitPerIndex": 2,
                                    "maxFailedIndexes": merge_failed,
                                    "podFailurePolicy": failure_policy("FailIndex")},
                  # $(JOB_COMPLETION_INDEX): the kubelet expands it from the variable the Job
                  # controller sets in every container of an Indexed Job's pods.
                  pod_spec(prefix, image, ["vts", "merge", "--plan", "/plan/plan.json", "/parts", "-o", SET_DIR,
                                           "--archive", "$(JOB_COMPLETION_INDEX)"],
                           merge_mounts, memory=("512Mi", "1Gi"), cpu="1")))
        write(out_dir, "manifest-job.yaml", f"""
The set's manifest, {SET_DIR}tileset.json, once every archive is merged: it names each one (its
version is the set's). An archive not merged fails it (exit 3, naming the --archive index).""",
              job(prefix, "manifest", {"backoffLimit": 2, "podFailurePolicy": failure_policy("FailJob")},
                  pod_spec(prefix, image, ["vts", "merge", "--plan", "/plan/plan.json", "/parts", "-o", SET_DIR,
                                           "--manifest"],
                           merge_mounts, memory=("256Mi", "512Mi"), cpu="1")))
        stale = []
    for f in stale:  # a file of an earlier rendering into this directory: kubectl apply would take it
        try:
            os.remove(os.path.join(out_dir, f))
        except FileNotFoundError:
            pass

    q = lambda s: "'" + s.replace("'", "'\\''") + "'"
    steps = [f"kubectl apply -f {q(out_dir)}",
             f"kubectl wait --for=condition=Ready --timeout=30m pod/{prefix}-load"]
    if paths:
        steps.append(f"tar -C {q(common)} -cf - -T {q(out_dir + '/plan/upload.txt')} | "
                     f"kubectl exec -i {prefix}-load -- tar -xf - -C /build/inputs")
    steps.append(f"tar -C {q(out_dir + '/plan')} -cf - plan.local.json inputs.txt | "
                 f"kubectl exec -i {prefix}-load -- tar -xf - -C /build/plan")
    for component, hours in (("plan", 6), ("shards", 48), ("apex", 6), ("merge", 48)) + \
            ((("manifest", 1),) if archives else ()):
        steps.append(f"kubectl patch job {prefix}-{component} --type=merge -p '{{\"spec\":{{\"suspend\":false}}}}'")
        steps.append(f"kubectl wait --for=condition=complete --timeout={hours}h job/{prefix}-{component}")
        if component == "plan":
            steps.append(f"kubectl delete pod {prefix}-load")
    print(f"render.sh: {n} shard{'s' * (n != 1)}, {parallelism} at once, at most {max_failed} failed indexes; "
          + (f"a set of {archives} archives, {merge_parallelism} merges at once, into {SET_DIR}; " if archives else "")
          + f"claim {prefix} {claim}{' of class ' + sc if sc else ''}; image {image}; in {out_dir}")
    print("then, in order (a wait that times out means that Job failed: kubectl describe job NAME):")
    for s in steps:
        print("  " + s)


main()
PYTHON
