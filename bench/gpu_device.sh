#!/usr/bin/env bash
# The renderer on a GPU with no display (an NVIDIA GPU server, e.g. the device machine), on an EGL
# device-platform context (VTS_GL=egl-device: the first hardware device of eglQueryDevicesEXT;
# docs/RENDERER.md, "Contexts: GLFW or EGL"), in one run:
#   - the view benchmark's driver (vts_view_bench, as bench/view_bench.sh runs it): the virtual
#     texture against one mipmapped texture of the whole image in the same run, trilinear and
#     anisotropic 8, at each size (default 1920x1080 and 3840x2160), over `vts serve` on loopback;
#   - the GL accuracy tables of `vts bench accuracy` (feedback, filtering, addressing;
#     docs/ACCURACY.md) at the same sizes.
# It builds nothing. `pack` gathers, on the build machine, what the run needs into a bundle
# folder: the executables (stripped), their shared libraries but glibc's and the C++ runtime's
# (the device's are newer), glvnd's EGL and OpenGL loaders (libepoxy loads them at run time), the
# Earth archive of the view benchmark (8192x4096) and the accuracy tables' input (the 2048x1024
# Earth). vts-build, which runs the accuracy tables, links GDAL and OpenImageIO: its libraries go
# in xz parts of at most --part-mib MiB each, so that each device call carries under its limit.
# `stash` (there) keeps the parts a call carried in /tmp/vts-gpu-stash for a later call on the
# same warm machine; `run` (there) runs everything from the bundle (and the stash) and writes
# report.md, view.jsonl, accuracy_WxH.json, env.txt and log.txt under $OUT (or --out DIR).
#
#   bash bench/gpu_device.sh pack [--build DIR] [--bundle DIR] [--part-mib N] [--xz-level N]
#                                 [--no-accuracy]
#   bash bench/gpu_device.sh stash [--bundle DIR]
#   bash bench/gpu_device.sh run [--bundle DIR] [--out DIR] [--sizes WxH,...] [--frames N]
#                                [--tables LIST] [--quick] [--no-accuracy] [--allow-any-device]
# --allow-any-device runs on whatever EGL device there is (Mesa's software device here: the dry
# run); without it the run stops unless nvidia-smi is there and the GL renderer is NVIDIA's.
# Defaults: --build build, --bundle BUILD/gpu-bundle (inside the ignored build folder).
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

MODE=${1:-}
(($#)) && shift
BUILD=$ROOT/build BUNDLE="" PART_MIB=45 XZ_LEVEL=6 ACCURACY=1 OUT_DIR=${OUT:-}
SIZES=1920x1080,3840x2160 FRAMES=60 TABLES=feedback,filtering,addressing QUICK=0 ANY_DEVICE=0
while (($#)); do
  case $1 in
    --build) BUILD=$(cd "$2" && pwd); shift 2 ;;
    --bundle) BUNDLE=$2; shift 2 ;;
    --part-mib) PART_MIB=$2; shift 2 ;;
    --xz-level) XZ_LEVEL=$2; shift 2 ;;
    --no-accuracy) ACCURACY=0; shift ;;
    --out) OUT_DIR=$2; shift 2 ;;
    --sizes) SIZES=$2; shift 2 ;;
    --frames) FRAMES=$2; shift 2 ;;
    --tables) TABLES=$2; shift 2 ;;
    --quick) QUICK=1; shift ;;
    --allow-any-device) ANY_DEVICE=1; shift ;;
    -h | --help) sed -n '2,/^# shellcheck/p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
    *) die "unknown argument '$1' (see --help)" ;;
  esac
done
BUNDLE=${BUNDLE:-$BUILD/gpu-bundle}
STASH=/tmp/vts-gpu-stash

# ---- pack (the build machine) -------------------------------------------------------------------

# libs_of BIN...: the shared libraries BIN... load, as resolved here, but glibc's and the C++
# runtime's.
libs_of() {
  ldd "$@" | awk '$2 == "=>" && $3 ~ /^\// { print $3 }' | sort -u |
    grep -vE '/(libc|libm|libdl|librt|libpthread|libresolv|libutil|libstdc\+\+|libgcc_s)\.so|/ld-linux'
}

# copy_libs DIR LIB...: LIB... into DIR under their sonames (the files the links point to).
copy_libs() {
  local dir=$1 lib
  shift
  mkdir -p "$dir"
  for lib in "$@"; do cp -L "$lib" "$dir/$(basename "$lib")"; done
}

pack() {
  need strip xz ldd
  local vts=$BUILD/cli/vts driver=$BUILD/bench/vts_view_bench vts_build=$BUILD/cli/vts-build
  [[ -x $vts && -x $driver ]] || die "no $vts or $driver: build vts and vts_view_bench first"
  rm -rf "$BUNDLE"
  mkdir -p "$BUNDLE/stage/bin"
  local T=$BUNDLE/stage
  cp "$vts" "$driver" "$T/bin/"
  strip "$T/bin/vts" "$T/bin/vts_view_bench"
  mapfile -t libs < <(libs_of "$vts" "$driver")
  # glvnd's loaders: libepoxy opens libEGL.so.1 and libOpenGL.so.0 (libGL.so.1) itself. The
  # vendor library (NVIDIA's libEGL_nvidia, Mesa's libEGL_mesa) is the device's own.
  local loader
  for loader in libEGL.so.1 libGLdispatch.so.0 libOpenGL.so.0 libGL.so.1 libGLX.so.0; do
    # (awk reads to the end: an early exit would kill ldconfig with SIGPIPE, a failure here)
    libs+=("$(ldconfig -p | awk -v n="$loader" '$1 == n && /x86-64/ && !f { print $NF; f = 1 }')")
  done
  copy_libs "$T/lib" "${libs[@]}"
  (cd "$T" && tar cf - bin lib) | xz -T2 "-$XZ_LEVEL" >"$BUNDLE/view.tar.xz"
  VTS=$vts
  cp "$(earth_archive view_earth_8192x4096 8192x4096)" "$BUNDLE/earth.pmtiles"
  cp "$EARTH" "$BUNDLE/earth.jpg"
  if ((ACCURACY)); then
    [[ -x $vts_build ]] || die "no $vts_build (build vts-build, or pack --no-accuracy)"
    rm -rf "${T:?}/bin" "${T:?}/lib" && mkdir -p "$T/bin"
    cp "$vts_build" "$T/bin/" && strip "$T/bin/vts-build"
    mapfile -t libs < <(libs_of "$vts_build")
    copy_libs "$T/lib" "${libs[@]}"
    (cd "$T" && tar cf - bin lib) | xz -T2 "-$XZ_LEVEL" |
      split -b "${PART_MIB}M" -d -a 1 - "$BUNDLE/accuracy.tar.xz.part"
  fi
  rm -rf "$T"
  pack_plan
}

# pack_plan: the bundle's parts and the device calls that carry them, each under a call's 64 MiB
# with the working tree (about 9 MiB): one call per vts-build part, which `stash` keeps on the warm
# machine, then the call that runs.
pack_plan() {
  local rel=${BUNDLE#"$ROOT"/} f p
  echo "bundle $BUNDLE:"
  for f in "$BUNDLE"/*; do printf '  %-40s %6s MiB\n' "$(basename "$f")" "$(mb "$(bytes_of "$f")")"; done
  echo "device calls, one after another while the machine is warm (carry: command):"
  for p in "$BUNDLE"/accuracy.tar.xz.part*; do
    [[ -e $p ]] || continue
    echo "  [\"$rel/$(basename "$p")\"]: bash bench/gpu_device.sh stash --bundle $rel"
  done
  echo "  [\"$rel/view.tar.xz\", \"$rel/earth.pmtiles\", \"$rel/earth.jpg\"]:" \
    "bash bench/gpu_device.sh run --bundle $rel"
}

# ---- stash and run (the device) ------------------------------------------------------------------

stash() {
  mkdir -p "$STASH"
  local p
  for p in "$BUNDLE"/accuracy.tar.xz.part*; do
    [[ -e $p ]] && cp "$p" "$STASH/" && echo "stashed $(basename "$p")"
  done
  ls -l "$STASH"
}

# untar_xz FILE DIR: python3's tarfile, which every such machine has (xz may not be there).
untar_xz() {
  python3 - "$1" "$2" <<'EOF'
import sys, tarfile
with tarfile.open(sys.argv[1], "r:xz") as t:
    if hasattr(tarfile, "tar_filter"):
        t.extractall(sys.argv[2], filter="tar")
    else:
        t.extractall(sys.argv[2])
EOF
}

# gl_env: OUR_LD, the library path of our executables (the bundle's libraries first, then the
# NVIDIA driver's folder where it is mounted; python3 and the system's tools keep theirs), and
# glvnd pointed at NVIDIA's EGL vendor file when the usual folders hold none.
gl_env() {
  local d
  OUR_LD=$RUN/lib
  for d in /usr/local/nvidia/lib64 /usr/local/nvidia/lib; do [[ -d $d ]] && OUR_LD+=:$d; done
  OUR_LD+=${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
  local nv=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
  if [[ -r $nv ]] && ! ls /usr/share/glvnd/egl_vendor.d/*nvidia* /etc/glvnd/egl_vendor.d/*nvidia* >/dev/null 2>&1; then
    export __EGL_VENDOR_LIBRARY_FILENAMES=$nv
  fi
  export VTS_GL=egl-device
  unset DISPLAY WAYLAND_DISPLAY
}

# wrap NAME...: $RUN/wrap/NAME runs $RUN/bin/NAME on OUR_LD.
wrap() {
  local name
  mkdir -p "$RUN/wrap"
  for name in "$@"; do
    printf '#!/bin/sh\nLD_LIBRARY_PATH=%q exec %q "$@"\n' "$OUR_LD" "$RUN/bin/$name" >"$RUN/wrap/$name"
    chmod +x "$RUN/wrap/$name"
  done
}

# check_loads BIN...: every library BIN... needs is found (else the names of those that are not).
check_loads() {
  local missing
  missing=$(LD_LIBRARY_PATH=$OUR_LD ldd "$@" | awk '/not found/ { print $1 }' | sort -u | tr '\n' ' ')
  [[ -z $missing ]] || die "libraries not found for $*: $missing(pack again on the build machine)"
}

# unpack_accuracy: vts-build from the parts in the bundle and the stash; 0 when it is there.
unpack_accuracy() {
  local parts=() p
  for p in "$STASH"/accuracy.tar.xz.part* "$BUNDLE"/accuracy.tar.xz.part*; do
    [[ -e $p ]] && parts+=("$p")
  done
  ((${#parts[@]})) || { echo "accuracy: no vts-build parts (pack without --no-accuracy)" >&2; return 1; }
  mapfile -t parts < <(for p in "${parts[@]}"; do echo "$(basename "$p") $p"; done | sort -u -k1,1 | cut -d' ' -f2)
  cat "${parts[@]}" >"$RUN/accuracy.tar.xz"
  if ! untar_xz "$RUN/accuracy.tar.xz" "$RUN" 2>"$RUN/untar.err"; then
    echo "accuracy: the vts-build parts do not make a whole archive (${#parts[@]} found: a" \
      "stash call missing, or the machine was not warm): $(tail -n 1 "$RUN/untar.err")" >&2
    return 1
  fi
  rm -f "$RUN/accuracy.tar.xz"
}

environment() {
  echo "date: $(date -u '+%Y-%m-%d %H:%M UTC')"
  echo "machine: $(nproc) cores, $(uname -sr)"
  if command -v nvidia-smi >/dev/null; then
    nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader
  else
    echo "nvidia-smi: not here"
  fi
  echo "library path of the executables: $OUR_LD"
  echo "__EGL_VENDOR_LIBRARY_FILENAMES=${__EGL_VENDOR_LIBRARY_FILENAMES:-}"
}

# view_runs: the driver at each size, trilinear and anisotropic 8, one JSON line each.
view_runs() {
  local name size w h aniso
  name=$(basename "${ARCHIVE%.pmtiles}")
  start_vts_serve "$ARCHIVE" "$RUN" 2
  for size in ${SIZES//,/ }; do
    w=${size%x*} h=${size#*x}
    for aniso in 1 8; do
      echo "[gpu] view bench ${w}x${h}, anisotropy $aniso" >&2
      rm -rf "$RUN/cache"
      "$RUN/wrap/vts_view_bench" "http://127.0.0.1:$PORT/$name" --gl egl-device --width "$w" \
        --height "$h" --frames "$FRAMES" --anisotropy "$aniso" --cache-dir "$RUN/cache" \
        >>"$OUT_DIR/view.jsonl" || die "vts_view_bench ${w}x${h} anisotropy $aniso failed"
      if ((!ANY_DEVICE)) && ! tail -n 1 "$OUT_DIR/view.jsonl" | grep -q '"gl_renderer": "NVIDIA'; then
        die "the EGL device is not an NVIDIA GPU: $(tail -n 1 "$OUT_DIR/view.jsonl" | cut -c1-200) (--allow-any-device to go on)"
      fi
    done
  done
  kill -TERM "$VTS_PID" 2>/dev/null && wait "$VTS_PID" 2>/dev/null
  VTS_PID=""
}

accuracy_runs() {
  local size args
  for size in ${SIZES//,/ }; do
    echo "[gpu] accuracy tables $TABLES at $size" >&2
    args=(bench accuracy --input "$BUNDLE/earth.jpg" --tables "$TABLES" --size "$size" --json -q)
    ((QUICK)) && args+=(--quick)
    "$RUN/wrap/vts-build" "${args[@]}" >"$OUT_DIR/accuracy_$size.json" ||
      die "vts bench accuracy at $size failed"
  done
}

# view_table: the view runs as a Markdown table.
view_table() {
  python3 - "$OUT_DIR/view.jsonl" <<'EOF'
import json, sys
rows = [json.loads(l) for l in open(sys.argv[1]) if l.strip()]
if rows:
    print("GL: %s (%s, %s)\n" % (rows[0]["gl_renderer"], rows[0]["gl_backend"], rows[0]["gl_device"]))
print("| size | anisotropy | VT CPU/frame ms | VT frame ms | mipmapped frame ms | VT / mipmapped |"
      " full res. cold ms | warm RAM ms | warm disk ms |")
print("|---|---|---|---|---|---|---|---|---|")
for r in rows:
    print("| %dx%d | %d | %.3f | %.2f | %.2f | %.2fx | %.1f | %.1f | %.1f |" % (
        r["width"], r["height"], r["anisotropy"], r["vt_cpu_ms"], r["vt_frame_ms"],
        r["mip_frame_ms"], r["vt_over_mip"], r["first_full_ms"], r["jump_warm_ram_ms"],
        r["jump_warm_disk_ms"]))
EOF
}

# accuracy_tables FILE: one accuracy report (JSON) as Markdown tables.
accuracy_tables() {
  python3 - "$1" <<'EOF'
import json, sys
j = json.load(open(sys.argv[1]))
print("GL: %s; %.1f s" % (j.get("gl"), j.get("seconds", 0)))
for t in j.get("tables", []):
    print("\n#### %s\n" % t["title"])
    keys = [c["key"] for c in t["columns"]]
    print("| " + " | ".join(c["title"] for c in t["columns"]) + " |")
    print("|" + "---|" * len(keys))
    for row in t["rows"]:
        cells = [row.get(k, "") for k in keys]
        print("| " + " | ".join("%.4g" % c if isinstance(c, float) else str(c) for c in cells) + " |")
EOF
}

run_device() {
  [[ -n $OUT_DIR ]] || die "no \$OUT and no --out DIR: where do the results go?"
  mkdir -p "$OUT_DIR"
  [[ -r $BUNDLE/view.tar.xz && -r $BUNDLE/earth.pmtiles ]] || die "no bundle at $BUNDLE (pack it)"
  if ((!ANY_DEVICE)); then
    command -v nvidia-smi >/dev/null || die "no nvidia-smi: not an NVIDIA machine (--allow-any-device to go on)"
  fi
  RUN=$(mktemp -d "${TMPDIR:-/tmp}/vts-gpu.XXXXXX")
  untar_xz "$BUNDLE/view.tar.xz" "$RUN"
  gl_env
  check_loads "$RUN/bin/vts" "$RUN/bin/vts_view_bench"
  wrap vts vts_view_bench
  VTS=$RUN/wrap/vts
  environment | tee "$OUT_DIR/env.txt" >&2
  ARCHIVE=$BUNDLE/earth.pmtiles
  : >"$OUT_DIR/view.jsonl"
  view_runs
  local have_accuracy=0
  if ((ACCURACY)) && unpack_accuracy; then
    check_loads "$RUN/bin/vts-build"
    wrap vts-build
    accuracy_runs
    have_accuracy=1
  fi
  {
    echo "### Renderer on $(head -n 3 "$OUT_DIR/env.txt" | tail -n 1), EGL device platform"
    echo
    sed 's/^/- /' "$OUT_DIR/env.txt"
    echo "- command: \`bash bench/gpu_device.sh run --sizes $SIZES --frames $FRAMES\`"
    echo
    view_table
    if ((have_accuracy)); then
      local size
      for size in ${SIZES//,/ }; do
        echo
        echo "### Accuracy tables at $size (\`vts bench accuracy --tables $TABLES --size $size\`)"
        echo
        accuracy_tables "$OUT_DIR/accuracy_$size.json"
      done
    fi
  } >"$OUT_DIR/report.md"
  cat "$OUT_DIR/report.md"
}

VTS_PID=""
RUN=""
OUR_LD=""
finish() {
  [[ -n $VTS_PID ]] && kill -TERM "$VTS_PID" 2>/dev/null && wait "$VTS_PID" 2>/dev/null
  [[ -n $RUN ]] && rm -rf "$RUN"
  return 0
}
trap finish EXIT

case $MODE in
  pack) pack ;;
  stash) stash ;;
  run)
    [[ -n $OUT_DIR ]] && mkdir -p "$OUT_DIR"
    run_device 2> >(tee "${OUT_DIR:-/tmp}/log.txt" >&2)
    ;;
  *) die "usage: gpu_device.sh pack|stash|run [options] (see --help)" ;;
esac
