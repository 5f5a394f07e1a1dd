#!/usr/bin/env bash
# `vts view --headless` end to end under Xvfb (xvfb-run -a) with Mesa llvmpipe: a real archive
# built by `vts build`, viewed from the file and through a real `vts serve` on 127.0.0.1; the
# JSON report checked with python3, the screenshot with python3 (PNG header) and oiiotool; a
# camera path flown with --record and the recording replayed to the same camera; bad sources and
# a missing display must fail cleanly with a message that says why.
# Environment (besides lib.sh's): XVFB_RUN, the xvfb-run script.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
# shellcheck source=serve_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/serve_lib.sh"

XVFB_RUN=${XVFB_RUN:-xvfb-run}
require_tool "$XVFB_RUN"
require_tool python3
require_tool "$OIIOTOOL"

W=320
H=200
XVFB=("$XVFB_RUN" -a -s "-screen 0 1280x1024x24")

# check_view_json FILE PNG: the report of a run that must have converged, and its screenshot.
check_view_json() {
  local json=$1 png=$2
  python3 - "$json" "$png" "$W" "$H" <<'EOF' || fail "bad vts view --json report in $1 (kept in logs)"
import json, struct, sys
path, png, w, h = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
j = json.load(open(path))
def need(cond, what):
    if not cond:
        print("FAIL:", what, file=sys.stderr)
        print(json.dumps({k: v for k, v in j.items() if k != "frames"}, indent=1), file=sys.stderr)
        sys.exit(1)
for k in ("source", "scene", "width", "height", "frames", "complete_at", "screenshot",
          "page_table_bytes", "physical_bytes", "gl_renderer"):
    need(k in j, "no %r in the report" % k)
need(j["scene"] == "plane", "scene is %r" % j["scene"])
need(j["width"] == w and j["height"] == h, "size %rx%r" % (j["width"], j["height"]))
need(isinstance(j["complete_at"], int) and not isinstance(j["complete_at"], bool),
     "complete_at is %r, expected a frame number" % j["complete_at"])
frames = j["frames"]
need(isinstance(frames, list) and 0 < len(frames) <= 200, "%d frames" % len(frames))
last = frames[-1]
need(last["complete"] is True, "the last frame is not complete (--until-complete)")
need(last["frame"] == j["complete_at"], "stopped at frame %r, complete_at %r" %
     (last["frame"], j["complete_at"]))
need(not any(f["complete"] for f in frames[:-1]), "an earlier frame was complete already")
need(last["pending"] == 0 and last["resident"] > 0 and last["errors"] == 0,
     "last frame: %r" % last)
for f in ("vt_cpu_ms", "frame_ms", "wanted", "wanted_missing", "uploads", "upload_bytes",
          "feedback_frames", "mip_bias", "hit_ratio", "evictions", "refusals", "absent"):
    need(f in last, "frame stats lack %r" % f)
need(sum(f["uploads"] for f in frames) >= last["resident"] - 1, "fewer uploads than resident tiles")
need(j["page_table_bytes"] > 0 and j["physical_bytes"] > 0, "GPU byte counts")
need(j["screenshot"] == png, "screenshot %r" % j["screenshot"])
with open(png, "rb") as f:
    head = f.read(24)
need(head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR", "%s is not a PNG" % png)
pw, ph = struct.unpack(">II", head[16:24])
need((pw, ph) == (w, h), "the PNG header says %dx%d" % (pw, ph))
EOF
  local dims
  dims=$(image_dims "$png")
  [[ $dims == "$W $H 4" ]] || fail "oiiotool reads $png as '$dims', expected '$W $H 4'"
  # Not uniform: the Earth has oceans and continents; every colour channel must vary.
  "$OIIOTOOL" --stats "$png" >"$LOGS/stats.txt" 2>&1 || fail "oiiotool --stats $png failed"
  grep -q 'Constant: No' "$LOGS/stats.txt" || { cat "$LOGS/stats.txt" >&2; fail "$png is uniform"; }
  python3 - "$LOGS/stats.txt" <<'EOF' || { cat "$LOGS/stats.txt" >&2; fail "$png is nearly uniform"; }
import re, sys
sd = [float(x) for x in re.search(r"StdDev: ([0-9. ]+)", open(sys.argv[1]).read()).group(1).split()]
sys.exit(0 if min(sd[:3]) > 10 else 1)
EOF
}

ARCHIVE="$WORK/earth.pmtiles"
note "vts build earth.jpg --tile 64"
build_earth "$ARCHIVE" --tile 64

note "vts view ARCHIVE --headless --until-complete"
expect_ok "${XVFB[@]}" "$VTS" view "$ARCHIVE" --headless --frames 200 --until-complete \
  --screenshot "$WORK/local.png" --json --width "$W" --height "$H"
cp "$OUT" "$LOGS/local.json"
check_view_json "$LOGS/local.json" "$WORK/local.png"

note "vts view BC1-ARCHIVE --headless --until-complete: compressed slots, the same picture but lossy"
BC1_ARCHIVE="$WORK/earth-bc1.pmtiles"
build_earth "$BC1_ARCHIVE" --tile 64 --codec bc1
expect_ok "${XVFB[@]}" "$VTS" view "$BC1_ARCHIVE" --headless --frames 200 --until-complete \
  --screenshot "$WORK/bc1.png" --json --width "$W" --height "$H"
cp "$OUT" "$LOGS/bc1.json"
check_view_json "$LOGS/bc1.json" "$WORK/bc1.png"
python3 - "$LOGS/local.json" "$LOGS/bc1.json" <<'EOF' || fail "bad bc1 view report (kept in logs)"
import json, sys
rgba, bc1 = json.load(open(sys.argv[1])), json.load(open(sys.argv[2]))
if rgba.get("tile_format") != "rgba8" or bc1.get("tile_format") != "bc1":
    sys.exit("tile formats %r and %r" % (rgba.get("tile_format"), bc1.get("tile_format")))
# The same slots in S3TC DXT1: half a byte per texel instead of four.
if bc1["physical_bytes"] * 8 != rgba["physical_bytes"]:
    sys.exit("physical bytes %d (bc1) vs %d (rgba8)" % (bc1["physical_bytes"], rgba["physical_bytes"]))
EOF
# Lossy, so not identical to the lossless view, but close (docs/RENDERER.md, "BC1 tilesets").
"$IDIFF" -v -fail 1 -failpercent 100 "$WORK/local.png" "$WORK/bc1.png" >"$LOGS/idiff-bc1.txt" 2>&1 || true
python3 - "$LOGS/idiff-bc1.txt" <<'EOF' || { cat "$LOGS/idiff-bc1.txt" >&2; fail "the bc1 view is not close to the lossless one"; }
import re, sys
m = re.search(r"Peak SNR = ([0-9.]+)", open(sys.argv[1]).read())
sys.exit(0 if m and 30 <= float(m.group(1)) < 60 else 1)
EOF

note "vts view http://127.0.0.1:PORT/earth (vts serve) --headless --until-complete"
start_server "$ARCHIVE"
expect_ok "${XVFB[@]}" "$VTS" view "$BASE/earth" --headless --frames 200 --until-complete \
  --screenshot "$WORK/served.png" --json --width "$W" --height "$H"
cp "$OUT" "$LOGS/served.json"
check_view_json "$LOGS/served.json" "$WORK/served.png"
# The same tiles through the network draw the same picture.
"$IDIFF" -fail 0.01 -failpercent 0.1 "$WORK/local.png" "$WORK/served.png" >"$LOGS/idiff.txt" 2>&1 ||
  { cat "$LOGS/idiff.txt" >&2; fail "the served view differs from the local one"; }

# record_and_replay NAME SCENE PATH.json: a headless flight along PATH.json recorded with --record,
# the recording checked against the path (python3), then replayed: the same final camera.
record_and_replay() {
  local name=$1 scene=$2 path=$3 rec="$WORK/$1.rec.json"
  expect_ok "${XVFB[@]}" "$VTS" view "$ARCHIVE" --headless --frames 25 --width "$W" --height "$H" \
    --scene "$scene" --camera-path "$path" --record "$rec" --print-camera
  tail -n 1 "$OUT" >"$LOGS/$name.flown.json"
  [[ -s $rec ]] || fail "--record wrote no $rec"
  cp "$rec" "$LOGS/$name.rec.json"
  if compgen -G "$rec.tmp.*" >/dev/null; then fail "--record left a temporary file next to $rec"; fi
  python3 - "$path" "$rec" "$scene" <<'EOF' || fail "the $name recording does not follow its path (kept in logs)"
import json, sys
path, rec, scene = json.load(open(sys.argv[1])), json.load(open(sys.argv[2])), sys.argv[3]
def need(cond, what):
    if not cond:
        print("FAIL:", what, file=sys.stderr)
        sys.exit(1)
keys = rec["keys"]
frames = [k["frame"] for k in keys]
need(all(isinstance(f, int) for f in frames), "frames are not whole numbers: %r" % frames)
# The path moves between its keys (a key every frame), then holds (no key until the last frame).
need(frames == list(range(21)) + [24], "recorded frames %r, expected 0 .. 20 and 24" % frames)
need(keys[0].get("move") is True, "the first key is not a move")
fields = ("lon", "lat", "altitude_m") if scene == "globe" else ("center", "texels_per_pixel")
other = ("center", "texels_per_pixel") if scene == "globe" else ("lon", "lat", "altitude_m")
by_frame = {k["frame"]: k for k in keys}
for k in path["keys"]:
    r = by_frame[k["frame"]]
    for f in fields + ("heading", "tilt"):
        if f in k:
            need(r[f] == k[f], "frame %d: %s recorded %r, the path says %r" % (k["frame"], f, r[f], k[f]))
    need(r.get("move", False) == (k.get("move", False) or k["frame"] == 0),
         "frame %d: move %r" % (k["frame"], r.get("move")))
need(not any(f in k for k in keys for f in other), "a %s recording carries the other scene's fields" % scene)
EOF
  expect_ok "${XVFB[@]}" "$VTS" view "$ARCHIVE" --headless --frames 25 --width "$W" --height "$H" \
    --scene "$scene" --camera-path "$rec" --print-camera
  tail -n 1 "$OUT" >"$LOGS/$name.replayed.json"
  python3 -c 'import json, sys; sys.exit(json.load(open(sys.argv[1])) != json.load(open(sys.argv[2])))' \
    "$LOGS/$name.flown.json" "$LOGS/$name.replayed.json" ||
    { diff "$LOGS/$name.flown.json" "$LOGS/$name.replayed.json" >&2; fail "the $name replay ends elsewhere"; }
}

note "--record: 3-key plane and globe flights recorded headless, then replayed to the same camera"
cat >"$WORK/plane3.json" <<'EOF'
{"keys": [{"frame": 0, "center": [300, 200], "texels_per_pixel": 4, "heading": 0, "tilt": 0},
          {"frame": 10, "center": [900, 500], "texels_per_pixel": 1.5, "heading": 0.3, "tilt": 0.4},
          {"frame": 20, "center": [1700, 800], "texels_per_pixel": 2.25, "move": true}]}
EOF
record_and_replay plane plane "$WORK/plane3.json"
cat >"$WORK/globe3.json" <<'EOF'
{"keys": [{"frame": 0, "lon": -40, "lat": 10, "altitude_m": 2e7},
          {"frame": 10, "lon": 20, "lat": 35, "altitude_m": 3e6, "heading": 0.5, "tilt": 0.3},
          {"frame": 20, "lon": 25.5, "lat": 40.25, "altitude_m": 8e5}]}
EOF
record_and_replay globe globe "$WORK/globe3.json"

note "--record into a folder that does not exist fails before anything opens"
expect_clean_failure "${XVFB[@]}" "$VTS" view "$ARCHIVE" --headless --frames 2 \
  --record "$WORK/no/such/dir/rec.json"
grep -q -- '--record' "$ERR" || { show_output; fail "the error does not name --record"; }

note "a missing tileset (served) and a missing archive fail naming the source"
expect_clean_failure "${XVFB[@]}" "$VTS" view "$BASE/nosuch" --headless --frames 5
grep -q "nosuch" "$ERR" || { show_output; fail "the error does not name $BASE/nosuch"; }
stop_server
expect_clean_failure "${XVFB[@]}" "$VTS" view "$WORK/missing.pmtiles" --headless --frames 5
grep -q "missing.pmtiles" "$ERR" || { show_output; fail "the error does not name the archive"; }
[[ ! -e $WORK/missing.pmtiles ]] || fail "vts view created $WORK/missing.pmtiles"

note "a bad option fails cleanly"
expect_clean_failure "${XVFB[@]}" "$VTS" view "$ARCHIVE" --headless --frames 5 --feedback 3
expect_clean_failure "${XVFB[@]}" "$VTS" view "$ARCHIVE" --headless --frames 5 --debug sideways
echo '{"keys":[{"frame":0},{"frame":"later"}]}' >"$WORK/path.json"
expect_clean_failure "${XVFB[@]}" "$VTS" view "$ARCHIVE" --headless --frames 5 --camera-path "$WORK/path.json"
grep -q 'key 1' "$ERR" || { show_output; fail "the camera path error does not name key 1"; }

note "no display with GLFW asked for (VTS_GL=glfw): the error says to use xvfb-run"
expect_clean_failure env -u DISPLAY -u WAYLAND_DISPLAY VTS_GL=glfw "$VTS" view "$ARCHIVE" --headless --frames 5
grep -q 'xvfb-run' "$ERR" || { show_output; fail "the no-display error does not mention xvfb-run"; }
[[ ! -s $OUT ]] || { show_output; fail "vts view printed a report without a display"; }

note "georeferenced: --center/--level start plane and globe over the place; refusals"
expect_ok "$VTS" build --synthetic 4096x2048 --tiling WorldCRS84Quad \
  --bbox=-10.5,35.25,30.125,60.1 -o "$WORK/geo.pmtiles" --threads 2
expect_ok "$VTS" build --synthetic 4096x4096 --tiling WebMercatorQuad --bbox=2,48,3,49 \
  -o "$WORK/web.pmtiles" --threads 2
for scene in plane globe; do
  expect_ok "${XVFB[@]}" "$VTS" view "$WORK/geo.pmtiles" --headless --frames 2 --width "$W" \
    --height "$H" --scene "$scene" --center 5,45 --level 3 --json
  # 4096 texels over 360 degrees from (-180, 90); level 3 of 4: 2 finest texels per pixel.
  python3 - "$OUT" "$scene" <<'EOF' || fail "--center 5,45 --level 3 ($scene): wrong camera"
import json, sys
k = json.load(open(sys.argv[1]))["camera"]["keys"][0]
if sys.argv[2] == "plane":
    u, v = k["center"]
    assert abs(u - 185 / 360 * 4096) < 1e-6 and abs(v - 512) < 1e-6, k
    assert k["texels_per_pixel"] == 2, k
else:
    assert k["lon"] == 5 and k["lat"] == 45 and k["tilt"] == 0, k
EOF
done
expect_clean_failure "${XVFB[@]}" "$VTS" view "$ARCHIVE" --headless --frames 1 --center 5,45
if ((RC != 2)) || ! grep -q 'not georeferenced' "$ERR"; then show_output; fail "--center, plain image"; fi
expect_clean_failure "${XVFB[@]}" "$VTS" view "$WORK/geo.pmtiles" --headless --frames 1 --center 5
if ((RC != 2)) || ! grep -q 'LON,LAT' "$ERR"; then show_output; fail "--center 5"; fi
expect_clean_failure "${XVFB[@]}" "$VTS" view "$WORK/web.pmtiles" --headless --frames 1 \
  --scene globe
if ((RC != 6)) || ! grep -q 'WebMercatorQuad' "$ERR"; then show_output; fail "Web Mercator globe"; fi

note "ok"
