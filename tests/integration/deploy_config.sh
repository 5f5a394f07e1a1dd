#!/usr/bin/env bash
# deploy/: the files that cannot run here for real (no init system, no container engine) are
# checked as far as this machine allows:
#   - systemd units: `systemd-analyze verify` (with ExecStart pointing at the vts under test),
#     `systemd-analyze security --offline` exposure, the hardening directives present, and each
#     unit's ExecStart command line run for real (paths and ports swapped for the test's) — it
#     serves, reloads on the unit's ExecReload signal and stops cleanly;
#   - Dockerfile, compose.yaml and k8s/*.yaml: parsed (python3-yaml) and checked for consistency
#     with each other, with the binary's shared libraries and with deploy/nginx (health path,
#     ports, image, user, volumes, template placeholders, the ConfigMap holding the templates
#     verbatim); `docker compose config` and `kubectl kustomize` too when those tools exist;
#   - schema validation with npm packages pinned in tests/integration/deploy_js (scripts/setup.sh
#     installs them): dclint checks compose.yaml against the Compose Specification schema and its
#     lint rules (deploy/.dclintrc.yaml), deploy_js/validate_k8s.js every document of k8s/*.yaml
#     against its apiVersion/kind schema (kubernetes-models, plus unknown fields) and the
#     kustomization's resources: list; broken copies (wrong field types, an unknown field, a
#     missing resource) must fail them, so the validators are known to reject errors.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
# shellcheck source=serve_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/serve_lib.sh"
# shellcheck source=deploy_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/deploy_lib.sh"
PY=${PYTHON3:-python3}
require_tool "$PY"
"$PY" -c 'import yaml' 2>/dev/null ||
  fail "python3 cannot import yaml (Debian package python3-yaml; run scripts/setup.sh)"
t_start=$(date +%s%N)

# ---- systemd -------------------------------------------------------------------------------------
U="$WORK/units"
mkdir -p "$U"
for unit in vts-serve vts-cache; do
  sed "s|/usr/local/bin/vts|$VTS|g" "$DEPLOY/systemd/$unit.service" >"$U/$unit.service"
done
if command -v systemd-analyze >/dev/null 2>&1; then
  note "systemd-analyze verify (ExecStart: $VTS)"
  (cd "$U" && systemd-analyze verify ./vts-serve.service ./vts-cache.service) >"$LOGS/verify.log" 2>&1 ||
    { cat "$LOGS/verify.log" >&2; fail "systemd-analyze verify failed"; }
  if grep -q . "$LOGS/verify.log"; then
    cat "$LOGS/verify.log" >&2
    fail "systemd-analyze verify printed warnings"
  fi
  for unit in vts-serve vts-cache; do
    (cd "$U" && systemd-analyze security --offline=true "./$unit.service") >"$LOGS/security.log" 2>&1 ||
      { cat "$LOGS/security.log" >&2; fail "systemd-analyze security $unit failed"; }
    level=$(sed -nE 's/.*Overall exposure level for .*: ([0-9.]+) .*/\1/p' "$LOGS/security.log")
    [[ -n $level ]] || { cat "$LOGS/security.log" >&2; fail "no exposure level for $unit"; }
    awk -v l="$level" 'BEGIN { exit !(l <= 2.0) }' || fail "$unit: exposure $level, above 2.0"
    note "$unit.service: exposure level $level (systemd-analyze security: 0 best, 10 worst)"
  done
else
  note "SKIP systemd-analyze checks: systemd-analyze not installed (Debian package systemd)"
fi
note "hardening directives present"
for d in DynamicUser=yes ProtectSystem=strict ProtectHome=yes PrivateTmp=yes NoNewPrivileges=yes \
  '^CapabilityBoundingSet=$' Restart=on-failure; do
  for unit in vts-serve vts-cache; do
    grep -qE "^${d#^}" "$DEPLOY/systemd/$unit.service" || fail "$unit.service lacks $d"
  done
done
grep -q '^ReadOnlyPaths=/srv/vts$' "$DEPLOY/systemd/vts-serve.service" || fail "no ReadOnlyPaths"
# shellcheck disable=SC2016  # literal $MAINPID
grep -q '^ExecReload=/bin/kill -HUP \$MAINPID$' "$DEPLOY/systemd/vts-serve.service" || fail "no ExecReload"
grep -q '^StateDirectory=vts-cache$' "$DEPLOY/systemd/vts-cache.service" || fail "no StateDirectory"

# exec_line UNIT: the ExecStart command line of UNIT with the test's paths and loopback ports.
# shellcheck disable=SC2016  # literal $VTS_..._ARGS
exec_line() {
  sed -n 's/^ExecStart=//p' "$U/$1.service" |
    sed -e "s|/srv/vts|$WORK/srv|g" -e "s|%S|$WORK/state|g" -e 's|0\.0\.0\.0:8080|127.0.0.1:0|' \
      -e 's|127\.0\.0\.1:[0-9]\{4\}|127.0.0.1:0|g' -e 's|\$VTS_[A-Z_]*ARGS||' \
      -e "s|\${VTS_UPSTREAM}|${2:-}|"
}
# run_unit_line NAME LINE...: starts LINE; sets DAEMON_PID, DAEMON_BASE, DAEMON_ADMIN.
run_unit_line() {
  local name=$1 i
  shift
  : >"$LOGS/$name.out"
  "$@" >"$LOGS/$name.out" 2>"$LOGS/$name.err" </dev/null &
  DAEMON_PID=$!
  REPLICA_PIDS+=("$DAEMON_PID")
  for ((i = 0; i < 200; i++)); do
    grep -q 'listening on' "$LOGS/$name.out" && break
    kill -0 "$DAEMON_PID" 2>/dev/null || { cat "$LOGS/$name.err" >&2; fail "$name: the unit's ExecStart exited"; }
    sleep 0.05
  done
  DAEMON_BASE=$(sed -nE 's|.*listening on (http://[^ ,]*).*|\1|p' "$LOGS/$name.out")
  DAEMON_ADMIN=$(sed -nE 's|.*\(admin (http://[^ )]*)\).*|\1|p' "$LOGS/$name.out")
  [[ -n $DAEMON_BASE && -n $DAEMON_ADMIN ]] || { cat "$LOGS/$name.out" >&2; fail "$name: no ports"; }
}
stop_unit_line() { # NAME: SIGTERM (the units' KillSignal) must end it with 0 within 15 s
  local rc=0
  kill -TERM "$DAEMON_PID"
  timeout 15 tail --pid="$DAEMON_PID" -f /dev/null || fail "$1 still running 15 s after SIGTERM"
  wait "$DAEMON_PID" || rc=$?
  ((rc == 0)) || { cat "$LOGS/$1.err" >&2; fail "$1 exited $rc after SIGTERM"; }
}

note "vts-serve.service's ExecStart, run for real: serves, reloads on SIGHUP, stops on SIGTERM"
mkdir -p "$WORK/srv" "$WORK/state/vts-cache"
build_earth "$WORK/srv/earth.pmtiles"
read -ra line <<<"$(exec_line vts-serve)"
run_unit_line serve "${line[@]}"
serve_pid=$DAEMON_PID
serve_base=$DAEMON_BASE
expect_status 200 "$DAEMON_ADMIN/health"
expect_status 200 "$serve_base/earth/0/0/0"
kill -HUP "$serve_pid" # ExecReload
for ((i = 0; i < 200; i++)); do
  grep -q 'SIGHUP: reloading' "$LOGS/serve.err" && break
  kill -0 "$serve_pid" 2>/dev/null || break
  sleep 0.05
done
grep -q 'SIGHUP: reloading' "$LOGS/serve.err" || fail "vts serve did not act on SIGHUP"
kill -0 "$serve_pid" 2>/dev/null || fail "SIGHUP ended vts serve"
expect_status 200 "$serve_base/earth/1/0/0"

note "vts-cache.service's ExecStart, run for real against it"
read -ra line <<<"$(exec_line vts-cache "$serve_base/earth")"
run_unit_line cache "${line[@]}"
expect_status 200 "$DAEMON_ADMIN/health"
cmp -s <(curl -sf "$DAEMON_BASE/earth/2/1/1") <(curl -sf "$serve_base/earth/2/1/1") ||
  fail "tile through the cache unit differs"
[[ -s $WORK/state/vts-cache/cache.db ]] || fail "the cache is not in the state directory"
stop_unit_line cache
DAEMON_PID=$serve_pid
stop_unit_line serve

# ---- Dockerfile, compose, Kubernetes ----------------------------------------------------------------
# The image's binary is the server-only build (-DVTS_BUILD_BUILDER=OFF): scripts/test.sh builds it
# and names it in VTS_SERVER_ONLY. It must not need OpenImageIO; its DT_NEEDED entries are the
# runtime packages. Without it, the test build's vts stands in (it has `vts build`, so
# OpenImageIO and GDAL are allowed there).
if [[ -n ${VTS_SERVER_ONLY:-} ]]; then
  [[ -x $VTS_SERVER_ONLY ]] || fail "VTS_SERVER_ONLY=$VTS_SERVER_ONLY is not an executable"
  IMAGE_VTS=$VTS_SERVER_ONLY
  note "server-only binary: $IMAGE_VTS"
  if readelf -d "$IMAGE_VTS" | grep -iE 'NEEDED.*(openimageio|gdal)'; then
    fail "the server-only vts needs OpenImageIO or GDAL (readelf -d above)"
  fi
  if ldd "$IMAGE_VTS" | grep -iE 'openimageio|gdal'; then
    fail "the server-only vts loads OpenImageIO or GDAL (ldd above)"
  fi
  "$IMAGE_VTS" --help >"$LOGS/server-only-help.txt" || fail "the server-only vts --help failed"
  grep -qE '^ +serve' "$LOGS/server-only-help.txt" || fail "the server-only vts has no serve"
  # (extract is the runtime's own for a tile as PNG; it hands the rest to a vts-build.)
  if grep -qE '^ +(build|plan|merge|export|bench)\b' "$LOGS/server-only-help.txt"; then
    fail "the server-only vts still lists build commands"
  fi
  SERVER_ONLY=1
else
  note "VTS_SERVER_ONLY unset: checking the test build's vts (scripts/test.sh sets it)"
  IMAGE_VTS=$VTS
  SERVER_ONLY=0
fi

note "the binary's shared libraries: packages for the runtime image"
needed_pkgs=()
while read -r lib; do
  path=$(ldconfig -p | awk -v l="$lib" '$1 == l && !p { print $NF; p = 1 }')
  [[ -n $path ]] || fail "cannot find $lib"
  real=$(readlink -f "$path")
  pkg=$(dpkg -S "$real" 2>/dev/null || dpkg -S "/usr$real" 2>/dev/null || dpkg -S "${real#/usr}" 2>/dev/null || true)
  pkg=${pkg%%:*}
  [[ -n $pkg ]] || fail "no Debian package owns $real ($lib)"
  needed_pkgs+=("$lib=$pkg")
done < <(readelf -d "$IMAGE_VTS" | sed -nE 's/.*\(NEEDED\).*\[(.*)\]/\1/p')
note "${needed_pkgs[*]}"

note "Dockerfile, compose.yaml, k8s/*.yaml: parsed and consistent"
VTS_NEEDED="${needed_pkgs[*]}" SERVER_ONLY=$SERVER_ONLY "$PY" - "$DEPLOY" <<'PYTHON' || fail "deploy/ files are inconsistent (above)"
import os, re, sys, yaml

deploy = sys.argv[1]
errors = []
def check(cond, what):
    if not cond:
        errors.append(what)

def placeholders(path):
    return set(re.findall(r"\$\{(VTS_[A-Z_]+)\}", open(path).read()))

# -- Dockerfile
df = open(os.path.join(deploy, "Dockerfile")).read()
joined = re.sub(r"\\\n", " ", df)
froms = re.findall(r"^FROM\s+(\S+)(?:\s+AS\s+(\S+))?", joined, re.M)
check(len(froms) == 2, f"Dockerfile: two stages, found {froms}")
check(froms and froms[0][0].startswith("debian:12") and froms[0][1] == "build",
      "Dockerfile: build stage FROM debian:12 AS build")
check(froms and froms[-1][0].startswith("debian:12"), "Dockerfile: runtime stage on Debian 12")
check("-DVTS_BUILD_RENDERER=OFF" in joined, "Dockerfile: cmake -DVTS_BUILD_RENDERER=OFF")
check("-DVTS_BUILD_BUILDER=OFF" in joined, "Dockerfile: cmake -DVTS_BUILD_BUILDER=OFF")
runtime = joined.split("FROM " + froms[-1][0], 1)[-1] if froms else ""
m = re.search(r"apt-get install[^&]*", runtime)
runtime_pkgs = set(m.group(0).split()) if m else set()
for entry in os.environ["VTS_NEEDED"].split():
    lib, pkg = entry.split("=")
    if pkg in ("libc6", "libgcc-s1"):   # in every Debian image
        continue
    # The image builds with -DVTS_BUILD_RENDERER=OFF (checked above); a test build with the viewer
    # links GLFW and libepoxy for `vts view`, which the image's binary does not have.
    if pkg in ("libglfw3", "libepoxy0"):
        continue
    # Likewise the test build's `vts build` links OpenImageIO and GDAL, which the server-only
    # image lacks.
    if os.environ["SERVER_ONLY"] != "1" and pkg.startswith(("libopenimageio", "libgdal")):
        continue
    check(pkg in runtime_pkgs, f"Dockerfile: runtime stage lacks {pkg} (for {lib})")
if os.environ["SERVER_ONLY"] == "1":
    # And no dead weight: every library package the image installs is one the binary needs.
    wanted = {entry.split("=", 1)[1] for entry in os.environ["VTS_NEEDED"].split()}
    for pkg in sorted(runtime_pkgs):
        if pkg.startswith("lib"):
            check(pkg in wanted, f"Dockerfile: runtime stage installs {pkg}, which vts does not need")
for gl in ("libgl1", "libglfw3", "libepoxy0", "libglx0", "libegl1"):
    check(gl not in runtime_pkgs, f"Dockerfile: GL package {gl} in the runtime image")
for pkg in runtime_pkgs:
    check(not pkg.startswith(("libopenimageio", "libgdal")),
          f"Dockerfile: {pkg} in the server-only image")
check(re.search(r"^COPY --from=build \S+/cli/vts /usr/local/bin/vts$", runtime, re.M),
      "Dockerfile: runtime copies only the vts binary from the build stage")
user = re.findall(r"^USER\s+(\S+)", runtime, re.M)
check(user and user[-1].split(":")[0] not in ("0", "root"), f"Dockerfile: non-root USER ({user})")
uid = int(user[-1].split(":")[0]) if user and user[-1].split(":")[0].isdigit() else None
hc = re.search(r"^HEALTHCHECK.*CMD (.*)$", joined, re.M)
check(hc and "/health" in hc.group(1), "Dockerfile: HEALTHCHECK against /health")
exposed = set(re.findall(r"\d+", (re.search(r"^EXPOSE (.*)$", joined, re.M) or [""])[0]))
cmd = re.search(r"^CMD (\[.*\])$", joined, re.M)
cmd = yaml.safe_load(cmd.group(1)) if cmd else []
def port_after(args, flag):
    return args[args.index(flag) + 1].rsplit(":", 1)[1] if flag in args else None
check(port_after(cmd, "--listen") in exposed and port_after(cmd, "--admin") in exposed,
      f"Dockerfile: CMD ports {cmd} not all in EXPOSE {exposed}")
admin_port = port_after(cmd, "--admin")
check(re.search(r"ENV VTS_ADMIN_PORT=" + str(admin_port), joined),
      "Dockerfile: the health check's VTS_ADMIN_PORT is the CMD's admin port")

# -- compose.yaml
front_tpl = os.path.join(deploy, "nginx", "vts-front.conf.template")
rep_tpl = os.path.join(deploy, "nginx", "vts-replicas.inc.template")
c = yaml.safe_load(open(os.path.join(deploy, "compose.yaml")))
s = c.get("services", {})
check(set(s) >= {"vts", "front", "cache"}, f"compose: services {list(s)}")
vts, front, cache = s.get("vts", {}), s.get("front", {}), s.get("cache", {})
check(vts.get("deploy", {}).get("replicas") == 3, "compose: vts has 3 replicas")
check(os.path.normpath(os.path.join(deploy, vts.get("build", {}).get("context", "?"),
                                    vts.get("build", {}).get("dockerfile", "?")))
      == os.path.join(deploy, "Dockerfile"), "compose: vts is built from deploy/Dockerfile")
vol = [v for v in vts.get("volumes", []) if isinstance(v, dict) and v.get("target") == "/data"]
check(vol and vol[0].get("read_only") is True, "compose: the archive volume is mounted read-only at /data")
check(cmd[:2] == vts.get("command", [])[:2] and "/data" in vts.get("command", []),
      "compose: vts serves /data like the image's CMD")
vts_listen = port_after(vts.get("command", []), "--listen")
vts_admin = port_after(vts.get("command", []), "--admin")
hc = " ".join(vts.get("healthcheck", {}).get("test", []))
check(f"127.0.0.1:{vts_admin}/health" in hc, f"compose: vts health check on its admin port /health ({hc})")
check(cache.get("image") == vts.get("image"), "compose: the cache daemon runs the vts image")
env = {k: str(v) for k, v in front.get("environment", {}).items()}
mounted = {}
for v in front.get("volumes", []):
    src, dst = v.split(":")[:2]
    mounted[dst] = os.path.normpath(os.path.join(deploy, src))
for tpl in (front_tpl, rep_tpl):
    dst = "/etc/nginx/templates/" + os.path.basename(tpl)
    check(mounted.get(dst) == tpl, f"compose: front mounts {os.path.basename(tpl)} at {dst}")
    missing = placeholders(tpl) - set(env)
    check(not missing, f"compose: front environment lacks {sorted(missing)} for {os.path.basename(tpl)}")
check(env.get("VTS_REPLICA") == f"vts:{vts_listen}", f"compose: VTS_REPLICA {env.get('VTS_REPLICA')} is vts:{vts_listen}")
check(os.path.dirname(env.get("VTS_TLS_CERT", "")) in mounted, "compose: the TLS folder is mounted")
check(env.get("VTS_CACHE_DIR") in mounted, "compose: the nginx cache folder is a volume")
check("http://front/" in " ".join(cache.get("command", [])), "compose: the cache daemon reads through the front")
check(" ".join(front.get("healthcheck", {}).get("test", [])).endswith("/.front-health"),
      "compose: front health check")

# -- k8s
docs = []
for f in sorted(os.listdir(os.path.join(deploy, "k8s"))):
    if f.endswith(".yaml") and f != "kustomization.yaml":
        docs += [d for d in yaml.safe_load_all(open(os.path.join(deploy, "k8s", f))) if d]
kust = yaml.safe_load(open(os.path.join(deploy, "k8s", "kustomization.yaml")))
check(sorted(kust["resources"]) == sorted(f for f in os.listdir(os.path.join(deploy, "k8s"))
                                          if f.endswith(".yaml") and f != "kustomization.yaml"),
      "k8s: kustomization lists every manifest")
by = {}
for d in docs:
    check({"apiVersion", "kind", "metadata"} <= set(d), f"k8s: a document lacks apiVersion/kind/metadata")
    by.setdefault(d["kind"], {})[d["metadata"]["name"]] = d
need = {"Deployment": {"vts-serve", "vts-front"}, "Service": {"vts-serve", "vts-front"},
        "HorizontalPodAutoscaler": {"vts-serve"}, "PersistentVolumeClaim": {"vts-archives"},
        "ConfigMap": {"vts-nginx-templates"}}
for kind, names in need.items():
    check(names <= set(by.get(kind, {})), f"k8s: {kind} {sorted(names)} (have {sorted(by.get(kind, {}))})")
dep = by["Deployment"]["vts-serve"]
pod = dep["spec"]["template"]["spec"]
ctr = pod["containers"][0]
check(ctr["image"] == vts.get("image"), "k8s: vts-serve runs the compose/Dockerfile image")
ports = {p["name"]: p["containerPort"] for p in ctr["ports"]}
check(str(ports.get("http")) == port_after(ctr["args"], "--listen"), "k8s: http port = --listen")
check(str(ports.get("admin")) == port_after(ctr["args"], "--admin"), "k8s: admin port = --admin")
for probe in ("readinessProbe", "livenessProbe"):
    p = ctr.get(probe, {}).get("httpGet", {})
    check(p.get("path") == "/health" and p.get("port") in ("admin", ports.get("admin")),
          f"k8s: {probe} is GET /health on the admin port")
res = ctr.get("resources", {})
check(res.get("requests", {}).get("cpu") and res.get("requests", {}).get("memory")
      and res.get("limits", {}).get("memory"), "k8s: vts-serve resources (requests cpu/memory, limit memory)")
check(pod.get("securityContext", {}).get("runAsNonRoot") is True, "k8s: runAsNonRoot")
check(uid is None or pod.get("securityContext", {}).get("runAsUser") == uid, "k8s: runAsUser is the image's USER")
mounts = {m["name"]: m for m in ctr["volumeMounts"]}
vols = {v["name"]: v for v in pod["volumes"]}
check(mounts.get("archives", {}).get("mountPath") == "/data" and mounts["archives"].get("readOnly"),
      "k8s: archives read-only at /data")
check(vols.get("archives", {}).get("persistentVolumeClaim", {}).get("claimName") in by["PersistentVolumeClaim"],
      "k8s: the archive volume is the PVC")
labels = dep["spec"]["template"]["metadata"]["labels"]
for name in ("vts-serve", "vts-front"):
    svc = by["Service"][name]
    d = by["Deployment"][name]
    sel = svc["spec"]["selector"]
    check(all(d["spec"]["template"]["metadata"]["labels"].get(k) == v for k, v in sel.items()),
          f"k8s: Service {name} selects its Deployment's pods")
    cports = {p["name"] for c_ in d["spec"]["template"]["spec"]["containers"] for p in c_["ports"]}
    for p in svc["spec"]["ports"]:
        check(p["targetPort"] in cports, f"k8s: Service {name} targetPort {p['targetPort']}")
    check(all(d["spec"]["selector"]["matchLabels"].get(k) == v for k, v in sel.items()), f"k8s: {name} selector")
hpa = by["HorizontalPodAutoscaler"]["vts-serve"]["spec"]
check(hpa["scaleTargetRef"]["kind"] == "Deployment" and hpa["scaleTargetRef"]["name"] == "vts-serve",
      "k8s: HPA scales vts-serve")
cm = by["ConfigMap"]["vts-nginx-templates"]["data"]
for tpl in (front_tpl, rep_tpl):
    check(cm.get(os.path.basename(tpl)) == open(tpl).read(),
          f"k8s: ConfigMap {os.path.basename(tpl)} differs from deploy/nginx's (copy it verbatim)")
fctr = by["Deployment"]["vts-front"]["spec"]["template"]["spec"]["containers"][0]
fenv = {e["name"]: e.get("value") for e in fctr.get("env", [])}
for tpl in (front_tpl, rep_tpl):
    missing = placeholders(tpl) - set(fenv)
    check(not missing, f"k8s: front env lacks {sorted(missing)}")
svc_port = by["Service"]["vts-serve"]["spec"]["ports"][0]["port"]
check(fenv.get("VTS_REPLICA") == f"vts-serve:{svc_port}", f"k8s: VTS_REPLICA names the vts-serve Service")
fm = {m["mountPath"] for m in fctr["volumeMounts"]}
check({"/etc/nginx/templates", os.path.dirname(fenv.get("VTS_TLS_CERT", "")), fenv.get("VTS_CACHE_DIR")} <= fm,
      "k8s: front mounts templates, TLS and cache")

for e in errors:
    print("deploy_config: " + e, file=sys.stderr)
sys.exit(1 if errors else 0)
PYTHON

# ---- schema validation: npm packages pinned in tests/integration/deploy_js --------------------------
DEPLOY_JS=${DEPLOY_JS:-$(cd "$(dirname "${BASH_SOURCE[0]}")/deploy_js" && pwd)}
require_tool "$NODE"
for pkg in dclint kubernetes-models yaml; do
  [[ -f $DEPLOY_JS/node_modules/$pkg/package.json ]] ||
    fail "npm package $pkg is not installed in $DEPLOY_JS (run scripts/setup.sh)"
done
dclint() { # COMPOSE_FILE: the Compose Specification schema, then the rules; any warning fails too
  NO_COLOR=1 "$NODE" "$DEPLOY_JS/node_modules/dclint/bin/dclint.cjs" -c "$DEPLOY/.dclintrc.yaml" \
    --max-warnings 0 "$1"
}
validate_k8s() { "$NODE" "$DEPLOY_JS/validate_k8s.js" "$@"; }

note "compose.yaml: dclint $(dclint --version 2>/dev/null) (Compose Specification schema + rules of deploy/.dclintrc.yaml)"
dclint "$DEPLOY/compose.yaml" >"$LOGS/dclint.log" 2>&1 ||
  { cat "$LOGS/dclint.log" >&2; fail "dclint rejected deploy/compose.yaml (above)"; }
note "k8s/*.yaml: each document against its apiVersion/kind schema (kubernetes-models)"
validate_k8s "$DEPLOY"/k8s/*.yaml >"$LOGS/validate_k8s.log" 2>&1 ||
  { cat "$LOGS/validate_k8s.log" >&2; fail "deploy/k8s/*.yaml failed schema validation (above)"; }
note "$(cat "$LOGS/validate_k8s.log")"

note "the validators reject broken copies"
BROKEN="$WORK/broken"
# broken_copy SRC DST SED_EXPR: DST is SRC edited by SED_EXPR, which must change it.
broken_copy() {
  mkdir -p "$(dirname "$2")"
  sed "$3" "$1" >"$2"
  ! cmp -s "$1" "$2" || fail "broken_copy: '$3' does not change $1 (update the test)"
}
# expect_rejected WHAT LOG PATTERN CMD...: CMD must fail and print PATTERN (an ERE).
expect_rejected() {
  local what=$1 log=$2 pattern=$3
  shift 3
  if "$@" >"$log" 2>&1; then
    cat "$log" >&2
    fail "the validator accepted $what"
  fi
  grep -qE "$pattern" "$log" || { cat "$log" >&2; fail "the validator rejected $what without /$pattern/"; }
  note "rejected: $what"
}
broken_copy "$DEPLOY/compose.yaml" "$BROKEN/c1/compose.yaml" '0,/cap_drop: \[ALL\]/s//cap_drop: ALL/'
expect_rejected "compose.yaml with cap_drop: ALL (a string, not a list)" "$LOGS/broken-c1.log" \
  '/services/vts/cap_drop.*must be array.*invalid-schema' dclint "$BROKEN/c1/compose.yaml"
broken_copy "$DEPLOY/compose.yaml" "$BROKEN/c2/compose.yaml" '0,/^    read_only: true$/s//    read_onyl: true/'
expect_rejected "compose.yaml with an unknown service key read_onyl" "$LOGS/broken-c2.log" \
  '/services/vts.*invalid-schema' dclint "$BROKEN/c2/compose.yaml"
for n in 1 2 3; do mkdir -p "$BROKEN/k$n" && cp "$DEPLOY"/k8s/*.yaml "$BROKEN/k$n/"; done
broken_copy "$DEPLOY/k8s/vts-serve.yaml" "$BROKEN/k1/vts-serve.yaml" 's/^  replicas: \([0-9]*\)$/  replicas: "\1"/'
expect_rejected "a Deployment with replicas: a string" "$LOGS/broken-k1.log" \
  'vts-serve\.yaml document 0 \(Deployment/vts-serve\).*spec/replicas must be integer' \
  validate_k8s "$BROKEN"/k1/*.yaml
broken_copy "$DEPLOY/k8s/vts-serve.yaml" "$BROKEN/k2/vts-serve.yaml" 's/^  replicas: /  replicaz: /'
expect_rejected "a Deployment with an unknown field replicaz" "$LOGS/broken-k2.log" \
  'Deployment/vts-serve.*unknown field /spec/replicaz' validate_k8s "$BROKEN"/k2/*.yaml
rm "$BROKEN/k3/archive-pvc.yaml"
expect_rejected "a kustomization naming a missing file" "$LOGS/broken-k3.log" \
  'kustomization\.yaml.*archive-pvc\.yaml' validate_k8s "$BROKEN"/k3/*.yaml

if docker compose version >/dev/null 2>&1; then
  note "docker compose config"
  docker compose -f "$DEPLOY/compose.yaml" config -q || fail "docker compose config refused compose.yaml"
else
  note "SKIP docker compose config: no docker CLI with the compose plugin (static checks above ran)"
fi
if command -v kubectl >/dev/null 2>&1; then
  note "kubectl kustomize deploy/k8s"
  kubectl kustomize "$DEPLOY/k8s" >"$WORK/k8s.yaml" 2>"$LOGS/kustomize.err" ||
    { cat "$LOGS/kustomize.err" >&2; fail "kubectl kustomize failed"; }
  [[ $(grep -c '^kind:' "$WORK/k8s.yaml") == 7 ]] || fail "kustomize: expected 7 objects"
else
  note "SKIP kubectl kustomize: kubectl not installed (static checks above ran)"
fi

note "PASS in $((($(date +%s%N) - t_start) / 1000000)) ms"
