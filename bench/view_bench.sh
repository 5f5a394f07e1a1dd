#!/usr/bin/env bash
# Renderer benchmark, on Mesa llvmpipe here (all this machine has), in one run:
#   - CPU time per frame in the virtual-texturing system (feedback reduction, requests, uploads,
#     page table) at 1920x1080 with 1/8 feedback;
#   - render time of the same tilted view through the virtual texture vs an ordinary mipmapped
#     texture of the whole image (the peer: what a texture that fits costs), as a ratio;
#   - the same two frame times with anisotropic filtering (8 taps; the peer: hardware anisotropy 8);
#   - time to full resolution after a jump: cold from `vts serve` over loopback, warm RAM (the
#     client's RAM cache holds the tiles), warm disk (a new client over a filled disk cache).
# The image is the Earth at 8192x4096 (it must fit one texture for the mipmapped peer, which is
# the archive's finest level assembled).
# The context: on a display, GLFW's window; with none (a GPU server), EGL with no display
# (docs/RENDERER.md); --gl NAME forces one (glfw with no display runs under xvfb-run).
# bench/gpu_device.sh runs the same driver on an NVIDIA GPU with no display.
#
#   bash bench/view_bench.sh [--vts PATH] [--driver PATH] [--frames N] [--gl NAME] [--out FILE]
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

VTS_ARG="" DRIVER="" OUT_FILE="" FRAMES=60 GL=${VTS_GL:-auto}
while (($#)); do
  case $1 in
    --vts) VTS_ARG=$2; shift 2 ;;
    --driver) DRIVER=$2; shift 2 ;;
    --frames) FRAMES=$2; shift 2 ;;
    --gl) GL=$2; shift 2 ;;
    --out) OUT_FILE=$2; shift 2 ;;
    *) die "unknown argument '$1'" ;;
  esac
done
# GLFW with no display runs under Xvfb; anything else runs as it is (EGL needs no display).
WRAP=()
if [[ $GL == glfw && -z ${DISPLAY:-}${WAYLAND_DISPLAY:-} ]]; then
  need xvfb-run
  WRAP=(xvfb-run -a -s "-screen 0 1920x1080x24")
fi
VTS=$(find_vts "$VTS_ARG")
DRIVER=${DRIVER:-$(dirname "$VTS")/../bench/vts_view_bench}
[[ -x $DRIVER ]] || die "no vts_view_bench at $DRIVER (build with VTS_BUILD_BENCH=ON and the renderer)"

ARCHIVE=$(earth_archive view_earth_8192x4096 8192x4096)
NAME=$(basename "${ARCHIVE%.pmtiles}")

T=$(mktemp -d "${TMPDIR:-/tmp}/vts-view-bench.XXXXXX")
VTS_PID=""
finish() {
  [[ -n $VTS_PID ]] && kill -TERM "$VTS_PID" 2>/dev/null && wait "$VTS_PID" 2>/dev/null
  rm -rf "$T"
}
trap finish EXIT
start_vts_serve "$ARCHIVE" "$T" 1

"${WRAP[@]}" "$DRIVER" "http://127.0.0.1:$PORT/$NAME" --gl "$GL" \
  --frames "$FRAMES" --cache-dir "$T/cache" >"$T/view.json" || die "driver failed"
# The same view with 8-tap anisotropic filtering against the peer's hardware anisotropy 8.
"${WRAP[@]}" "$DRIVER" "http://127.0.0.1:$PORT/$NAME" --gl "$GL" \
  --frames "$FRAMES" --anisotropy 8 >"$T/view-aniso.json" || die "driver failed (anisotropy 8)"
J=$(cat "$T/view.json")
JA=$(cat "$T/view-aniso.json")
field() { python3 -c "import json,sys; print(json.loads(sys.argv[1])[sys.argv[2]])" "$J" "$1"; }
afield() { python3 -c "import json,sys; print(json.loads(sys.argv[1])[sys.argv[2]])" "$JA" "$1"; }
{
  echo "### Renderer: virtual texture vs mipmapped texture, $(field gl_renderer) ($(date -u '+%Y-%m-%d'))"
  echo
  machine_info
  echo "- GL: $(field gl_renderer) through $(field gl_backend); view: 1920x1080, tilt 0.9 rad, ~1.2 texels/pixel at the centre"
  echo "- command: \`bash bench/view_bench.sh --frames $FRAMES\` (image: Earth 8192x4096, 256-texel tiles)"
  echo
  echo "| measure | result |"
  echo "|---|---|"
  echo "| VT system CPU per frame (median; feedback 1/8) | $(field vt_cpu_ms) ms |"
  echo "| frame through the virtual texture (GPU-finished, median) | $(field vt_frame_ms) ms |"
  echo "| frame through one mipmapped texture (median) | $(field mip_frame_ms) ms |"
  echo "| ratio VT / mipmapped | $(field vt_over_mip)x |"
  echo "| anisotropic 8: frame through the virtual texture (8 taps) | $(afield vt_frame_ms) ms |"
  echo "| anisotropic 8: frame through the mipmapped texture (hardware, max 8) | $(afield mip_frame_ms) ms |"
  echo "| anisotropic 8: ratio VT / mipmapped | $(afield vt_over_mip)x |"
  echo "| full resolution, cold over loopback | $(field first_full_ms) ms |"
  echo "| full resolution after a jump, warm RAM | $(field jump_warm_ram_ms) ms |"
  echo "| full resolution, new client over a warm disk cache | $(field jump_warm_disk_ms) ms |"
  echo "| page table / physical texture GPU memory | $(field page_table_bytes) B / $(field physical_bytes) B |"
} | tee "${OUT_FILE:-/dev/null}"
