#!/usr/bin/env bash
# The viewer with no display: `vts view --headless` and the view benchmark's driver
# (vts_view_bench) on EGL contexts (Mesa's surfaceless platform, and the device platform on Mesa's
# software device, both llvmpipe) with DISPLAY and WAYLAND_DISPLAY unset, against the same runs
# under Xvfb through GLFW: the converged frame is the same (one driver, one rasteriser: at most
# 0.1% of the pixels may differ, by one 8-bit step at most, the run-to-run spread of a converged
# globe frame on llvmpipe, seen on either path; mostly the frames are identical); the reports
# name the context they ran on; a context that cannot be had is a clean error that says what to
# do.
# Environment (besides ../integration/lib.sh's): XVFB_RUN, the xvfb-run script; VIEW_BENCH, the
# vts_view_bench executable (its part is skipped when unset: a build without VTS_BUILD_BENCH).
# shellcheck source=../integration/lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/../integration/lib.sh"

XVFB_RUN=${XVFB_RUN:-xvfb-run}
VIEW_BENCH=${VIEW_BENCH:-}
require_tool "$XVFB_RUN"
require_tool python3
require_tool "$IDIFF"

XVFB=("$XVFB_RUN" -a -s "-screen 0 1280x1024x24")
# No display, and nothing in the environment that picks a context: the automatic choice.
NO_DISPLAY=(env -u DISPLAY -u WAYLAND_DISPLAY -u VTS_GL -u VTS_EGL_DEVICE -u EGL_PLATFORM)

# expect_same_frame IMAGE REFERENCE: IMAGE is REFERENCE within the tolerance above (idiff).
expect_same_frame() {
  if ! "$IDIFF" -fail 0 -failpercent 0.1 -hardfail 0.0040 -warn 1 "$1" "$2" >"$LOGS/idiff.txt" 2>&1; then
    cat "$LOGS/idiff.txt" >&2
    fail "$1 differs from $2 by more than one 8-bit step or on more than 0.1% of its pixels"
  fi
}

# json_field FILE KEY: prints the report's top-level KEY.
json_field() {
  python3 -c 'import json, sys; print(json.load(open(sys.argv[1])).get(sys.argv[2]))' "$1" "$2"
}

# expect_backend FILE BACKEND: the report in FILE ran on BACKEND (gl_backend).
expect_backend() {
  local got
  got=$(json_field "$1" gl_backend)
  [[ $got == "$2" ]] || { show_output; fail "$1: gl_backend is '$got', expected '$2'"; }
}

ARCHIVE=$WORK/earth.pmtiles
note "building the Earth archive"
build_earth "$ARCHIVE"

# view NAME SCENE [ENV...] -- [ARGS...]: `vts view --headless` of ARCHIVE, 320x200, until the first
# complete frame, its JSON report in $WORK/NAME.json and its screenshot in $WORK/NAME.png.
view() {
  local name=$1 scene=$2
  shift 2
  local pre=()
  while (($#)) && [[ $1 != -- ]]; do pre+=("$1"); shift; done
  shift
  expect_ok "${pre[@]}" "$VTS" view "$ARCHIVE" --scene "$scene" --headless --frames 400 \
    --until-complete --width 320 --height 200 --json --screenshot "$WORK/$name.png" "$@"
  cp "$OUT" "$WORK/$name.json"
  [[ $(json_field "$WORK/$name.json" complete_at) != None ]] || fail "$name never converged"
}

for scene in plane globe; do
  note "$scene: Xvfb + GLFW"
  view "glfw-$scene" "$scene" "${XVFB[@]}" --
  expect_backend "$WORK/glfw-$scene.json" glfw

  note "$scene: no display, the automatic choice (EGL: Mesa's surfaceless platform here)"
  view "auto-$scene" "$scene" "${NO_DISPLAY[@]}" --
  expect_backend "$WORK/auto-$scene.json" egl-surfaceless
  expect_same_frame "$WORK/auto-$scene.png" "$WORK/glfw-$scene.png"

  note "$scene: no display, the EGL device platform (VTS_GL=egl-device)"
  view "device-$scene" "$scene" "${NO_DISPLAY[@]}" VTS_GL=egl-device --
  expect_backend "$WORK/device-$scene.json" egl-device
  device=$(json_field "$WORK/device-$scene.json" gl_device)
  [[ $device == "device 0 of "* ]] || fail "gl_device is '$device', expected 'device 0 of N: ...'"
  expect_same_frame "$WORK/device-$scene.png" "$WORK/glfw-$scene.png"
done

note "VTS_GL=egl with Mesa's EGL_PLATFORM=surfaceless"
view surfaceless plane "${NO_DISPLAY[@]}" VTS_GL=egl EGL_PLATFORM=surfaceless --
expect_backend "$WORK/surfaceless.json" egl-surfaceless

note "clean errors: GLFW with no display, a window on EGL, a bad VTS_GL, a device EGL lacks"
expect_clean_failure "${NO_DISPLAY[@]}" VTS_GL=glfw "$VTS" view "$ARCHIVE" --headless --frames 2
if ! grep -q 'xvfb-run' "$ERR" || ! grep -q 'VTS_GL=egl' "$ERR"; then
  show_output
  fail "the no-display GLFW error does not say what to do"
fi
expect_clean_failure "${NO_DISPLAY[@]}" VTS_GL=egl "$VTS" view "$ARCHIVE"
grep -q 'GLFW' "$ERR" || { show_output; fail "a window asked of EGL: the error does not say why"; }
expect_clean_failure "${NO_DISPLAY[@]}" VTS_GL=vulkan "$VTS" view "$ARCHIVE" --headless --frames 2
grep -q 'VTS_GL=vulkan' "$ERR" || { show_output; fail "a bad VTS_GL is not named"; }
expect_clean_failure "${NO_DISPLAY[@]}" VTS_GL=egl-device VTS_EGL_DEVICE=64 "$VTS" view "$ARCHIVE" \
  --headless --frames 2
grep -q 'EGL lists' "$ERR" || { show_output; fail "a device EGL lacks: the error does not say so"; }

if [[ -z $VIEW_BENCH ]]; then
  note "no VIEW_BENCH: the benchmark driver's part is skipped"
  exit 0
fi
require_tool "$VIEW_BENCH"
# bench NAME [ENV...]: the driver on ARCHIVE at 320x200, its JSON in $WORK/NAME.json and the
# converged virtual-texture frame in $WORK/NAME.png.
bench() {
  local name=$1
  shift
  expect_ok "$@" "$VIEW_BENCH" "$ARCHIVE" --width 320 --height 200 --frames 3 \
    --screenshot "$WORK/$name.png"
  cp "$OUT" "$WORK/$name.json"
  python3 - "$WORK/$name.json" <<'EOF' || { show_output; fail "bad vts_view_bench report"; }
import json, sys
j = json.load(open(sys.argv[1]))
for k in ("vt_frame_ms", "mip_frame_ms", "vt_over_mip", "first_full_ms", "jump_warm_ram_ms"):
    assert j[k] > 0, (k, j[k])
assert j["width"] == 320 and j["height"] == 200, j
EOF
}
note "view bench driver: Xvfb + GLFW, then no display (automatic, and the device platform)"
bench bench-glfw "${XVFB[@]}"
expect_backend "$WORK/bench-glfw.json" glfw
bench bench-auto "${NO_DISPLAY[@]}"
expect_backend "$WORK/bench-auto.json" egl-surfaceless
expect_same_frame "$WORK/bench-auto.png" "$WORK/bench-glfw.png"
bench bench-device "${NO_DISPLAY[@]}" VTS_GL=egl-device
expect_backend "$WORK/bench-device.json" egl-device
expect_same_frame "$WORK/bench-device.png" "$WORK/bench-glfw.png"
note "ok"
