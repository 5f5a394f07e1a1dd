#!/usr/bin/env bash
# `vts view` in its interactive window, driven by real X input events: an Xvfb server of this
# test's own (Xvfb -displayfd picks a free display number), a real archive built by `vts build`,
# and xdotool sending a mouse drag (pan), wheel clicks (zoom), keys (debug view, HUD) and Escape
# (quit). `--print-camera` prints the final camera as a one-key camera path; python3 checks that
# each input moved it the way the controls promise, and a headless run replays that path.
# `--record` writes the whole session: it must start at the default camera and end at the
# printed one.
# Every wait has a time limit; on failure the viewer's and the X server's output are shown.
# Environment (besides lib.sh's): XVFB, the Xvfb server; XDOTOOL, xdotool; VTS_TEST_DISPLAY, a
# display number to use instead of the first free one.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

XVFB=${XVFB:-Xvfb}
XDOTOOL=${XDOTOOL:-xdotool}
require_tool "$XVFB"
require_tool "$XDOTOOL"
require_tool python3

# The window: 320 x 200 frames of the 2048 x 1024 Earth. The default camera shows the whole image:
# texels_per_pixel = max(2048 / 320, 1024 / 200) * 1.05 = 6.72, centred on (1024, 512).
W=320
H=200
TPP0=6.72
U0=1024
V0=512

XVFB_PID=
VIEW_PID=
stop_pid() {  # stop_pid PID: TERM, then KILL after 5 s; only our own children
  local pid=$1 i
  [[ -n $pid ]] && kill -0 "$pid" 2>/dev/null || return 0
  kill -TERM "$pid" 2>/dev/null || true
  for ((i = 0; i < 50; ++i)); do
    kill -0 "$pid" 2>/dev/null || return 0
    sleep 0.1
  done
  kill -KILL "$pid" 2>/dev/null || true
}
finish() {
  local rc=$?
  stop_pid "$VIEW_PID"
  stop_pid "$XVFB_PID"
  if ((rc != 0)); then
    for f in view.out view.err xvfb.err; do
      [[ -s $LOGS/$f ]] && { echo "---- $f (last 30 lines):" >&2; tail -n 30 "$LOGS/$f" >&2; }
    done
  fi
  set +e
  (exit "$rc")
  cleanup  # lib.sh's: reads the status just set
}
trap finish EXIT

# wait_for SECONDS WHAT CMD...: polls CMD every 0.1 s until it succeeds; fails after SECONDS.
wait_for() {
  local limit=$1 what=$2 i
  shift 2
  for ((i = 0; i < limit * 10; ++i)); do
    "$@" && return 0
    sleep 0.1
  done
  fail "timed out after ${limit}s waiting for $what"
}
# xdo ARGS...: one xdotool command under a time limit.
xdo() {
  timeout -k 2 10 "$XDOTOOL" "$@" || fail "xdotool $* failed"
}

ARCHIVE="$WORK/earth.pmtiles"
note "vts build earth.jpg --tile 64"
build_earth "$ARCHIVE" --tile 64

# A free display number unless VTS_TEST_DISPLAY pins one (Xvfb writes the number it took).
note "Xvfb on its own display"
if [[ -n ${VTS_TEST_DISPLAY:-} ]]; then
  echo "$VTS_TEST_DISPLAY" >"$LOGS/display.pinned"
  "$XVFB" ":$VTS_TEST_DISPLAY" -screen 0 640x480x24 -nolisten tcp >"$LOGS/xvfb.out" \
    2>"$LOGS/xvfb.err" &
  XVFB_PID=$!
  # The number is known; the server is up once a client can connect.
  display_up() {
    kill -0 "$XVFB_PID" 2>/dev/null || fail "Xvfb :$VTS_TEST_DISPLAY did not start"
    DISPLAY=":$VTS_TEST_DISPLAY" timeout -k 2 5 "$XDOTOOL" getmouselocation >/dev/null 2>&1
  }
  wait_for 20 "Xvfb :$VTS_TEST_DISPLAY" display_up
  mv "$LOGS/display.pinned" "$LOGS/display"
else
  exec 3>"$LOGS/display"
  "$XVFB" -displayfd 3 -screen 0 640x480x24 -nolisten tcp >"$LOGS/xvfb.out" 2>"$LOGS/xvfb.err" &
  XVFB_PID=$!
  exec 3>&-
fi
display_ready() { grep -qE '^[0-9]+$' "$LOGS/display"; }
wait_for 20 "Xvfb to report its display number" display_ready
DISPLAY=":$(cat "$LOGS/display")"
export DISPLAY
note "DISPLAY=$DISPLAY"

note "vts view ARCHIVE (interactive) --print-camera --record FILE"
timeout -k 5 120 "$VTS" view "$ARCHIVE" --width "$W" --height "$H" --print-camera \
  --record "$WORK/session.json" >"$LOGS/view.out" 2>"$LOGS/view.err" </dev/null &
VIEW_PID=$!

# The window exists, and its title carries the HUD numbers: the frame loop (and with it the input
# callbacks) is running.
WID=
find_window() {
  kill -0 "$VIEW_PID" 2>/dev/null || fail "vts view exited before its window appeared"
  WID=$(timeout -k 2 5 "$XDOTOOL" search --name '^vts view' 2>/dev/null | head -n 1) || true
  [[ -n $WID ]]
}
wait_for 60 "the vts view window" find_window
looping() {
  kill -0 "$VIEW_PID" 2>/dev/null || fail "vts view exited early"
  [[ $(timeout -k 2 5 "$XDOTOOL" getwindowname "$WID" 2>/dev/null) == *resident* ]]
}
wait_for 60 "the vts view frame loop (HUD numbers in the title)" looping
xdo getwindowgeometry "$WID" >"$LOGS/geometry"
grep -q "Geometry: ${W}x${H}" "$LOGS/geometry" || { cat "$LOGS/geometry" >&2; fail "window size"; }
# No window manager here: focus follows the pointer, which stays in the window from now on.
xdo mousemove --window "$WID" 100 100
sleep 0.3
xdo windowfocus "$WID"

note "left-drag 60 pixels to the right: the image follows the cursor (center_u decreases)"
xdo mousedown 1
sleep 0.2
for x in 110 120 130 140 150 160; do
  xdo mousemove --window "$WID" "$x" 100
  sleep 0.1
done
sleep 0.2
xdo mouseup 1
sleep 0.3

note "three wheel clicks up (closer), one down, at the window's centre"
xdo mousemove --window "$WID" $((W / 2)) $((H / 2))
sleep 0.3
for b in 4 4 4 5; do
  xdo click "$b"
  sleep 0.2
done

note "key 2: the levels debug view; H twice: HUD off and on again"
xdo key 2
sleep 0.3
xdo key h
sleep 0.2
xdo key h
sleep 0.3
kill -0 "$VIEW_PID" 2>/dev/null || fail "vts view exited before Escape"

note "Escape: vts view exits 0 within 20 s and prints the camera"
xdo key Escape
exited() { ! kill -0 "$VIEW_PID" 2>/dev/null; }
wait_for 20 "vts view to exit after Escape" exited
set +e
wait "$VIEW_PID"
rc=$?
set -e
VIEW_PID=
((rc == 0)) || fail "vts view exited $rc after Escape, expected 0"
if grep -qE 'warning|error' "$LOGS/view.err"; then
  fail "vts view complained on stderr"
fi
tail -n 1 "$LOGS/view.out" >"$WORK/recorded.json"

python3 - "$WORK/recorded.json" "$TPP0" "$U0" "$V0" <<'EOF' || fail "the camera did not move as the input asked"
import json, math, sys
path, tpp0, u0, v0 = sys.argv[1], float(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4])
j = json.load(open(path))
def need(cond, what):
    if not cond:
        print("FAIL:", what, file=sys.stderr)
        print(json.dumps(j), file=sys.stderr)
        sys.exit(1)
need(j.get("scene") == "plane", "scene %r" % j.get("scene"))
need(j.get("debug") == "levels", "key 2 did not switch the debug view to levels: %r" % j.get("debug"))
keys = j.get("keys")
need(isinstance(keys, list) and len(keys) == 1, "not a one-key camera path")
k = keys[0]
need(k.get("frame") == 0, "frame %r" % k.get("frame"))
u, v = k["center"]
tpp = k["texels_per_pixel"]
# Wheel: 1.25x closer per click up, 1.25x farther per click down; 3 up + 1 down = 1.25^-2.
want_tpp = tpp0 * 1.25 ** -2
need(abs(tpp - want_tpp) < 1e-6 * want_tpp,
     "texels_per_pixel %r after 3 wheel clicks up and 1 down, expected %r" % (tpp, want_tpp))
# Drag: 60 pixels right at 6.72 texels per pixel drags the image 403.2 texels right. The zoom at
# the window's centre keeps the centre where it is (to well under a pixel's worth of texels).
want_u = u0 - 60 * tpp0
need(abs(u - want_u) < 2 * tpp0, "center_u %r after the drag, expected about %r" % (u, want_u))
need(abs(v - v0) < 2 * tpp0, "center_v %r moved on a horizontal drag (was %r)" % (v, v0))
need(k.get("heading") == 0 and k.get("tilt") == 0, "heading/tilt changed: %r" % k)
EOF

note "--record wrote the session: the default camera first, the printed camera last"
[[ -s $WORK/session.json ]] || fail "--record wrote no session file"
cp "$WORK/session.json" "$LOGS/session.json"
python3 - "$WORK/session.json" "$WORK/recorded.json" "$TPP0" "$U0" "$V0" <<'EOF' || fail "the recorded session is wrong (kept in logs)"
import json, sys
s, printed = json.load(open(sys.argv[1])), json.load(open(sys.argv[2]))
tpp0, u0, v0 = float(sys.argv[3]), float(sys.argv[4]), float(sys.argv[5])
def need(cond, what):
    if not cond:
        print("FAIL:", what, file=sys.stderr)
        sys.exit(1)
keys = s["keys"]
frames = [k["frame"] for k in keys]
need(frames == sorted(set(frames)) and frames[0] == 0, "frames %r" % frames[:20])
# The drag and the wheel clicks each changed the camera: a key at least before and after each.
need(len(keys) >= 4, "only %d keys" % len(keys))
first, last = keys[0], keys[-1]
need(first.get("move") is True, "the first key is not a move")
need(first["center"] == [u0, v0] and abs(first["texels_per_pixel"] - tpp0) < 1e-9,
     "the first key is not the default camera: %r" % first)
want = printed["keys"][0]
for f in ("center", "texels_per_pixel", "heading", "tilt", "fov_y"):
    need(last[f] == want[f], "the last key's %s is %r, --print-camera said %r" % (f, last[f], want[f]))
need(not any("lon" in k for k in keys), "a plane session carries globe fields")
EOF

note "the recorded camera replays: --camera-path FILE renders exactly that camera"
expect_ok timeout -k 5 120 "$VTS" view "$ARCHIVE" --headless --frames 3 --width "$W" \
  --height "$H" --camera-path "$WORK/recorded.json" --print-camera
python3 - "$WORK/recorded.json" "$OUT" <<'EOF' || fail "the replayed camera differs from the recorded one"
import json, sys
a, b = json.load(open(sys.argv[1])), json.loads(open(sys.argv[2]).read().strip().splitlines()[-1])
ka, kb = a["keys"][0], b["keys"][0]
for f in ("center", "texels_per_pixel", "heading", "tilt", "fov_y"):
    if ka[f] != kb[f]:
        print("FAIL: %s recorded %r, replayed %r" % (f, ka[f], kb[f]), file=sys.stderr)
        sys.exit(1)
EOF

note "bad options fail cleanly"
expect_clean_failure "$VTS" view "$ARCHIVE" --headless --frames 1 --anisotropy 0
expect_clean_failure "$VTS" view "$ARCHIVE" --headless --frames 1 --anisotropy 17
expect_clean_failure "$VTS" view "$ARCHIVE" --headless --frames 1 --hud
expect_clean_failure "$VTS" view "$ARCHIVE" --headless --frames 1 --json --print-camera

note "ok"
