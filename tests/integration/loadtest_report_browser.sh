#!/usr/bin/env bash
# The `vts loadtest --report` page in a real browser: load_report_sample writes reports from
# synthetic data (a full run, an empty run, a run with a hostile title), and headless Chromium
# renders them. Checked:
#   - the page as Chromium parsed it (--dump-dom): every plot is an <svg class="plot"> with its
#     axes, tick labels, legend and one <path> per series inside it; no script element anywhere;
#     the hostile title is text, not markup; the empty run's plots each say "no data";
#   - what Chromium drew (--screenshot): the page is not blank, every series colour is on it, and
#     each plot rendered on its own shows its lines;
#   - the --json document and the terminal summary written alongside.
# Environment (besides lib.sh's): LOAD_REPORT_SAMPLE (tests/integration/load_report_sample),
# CHROMIUM (Debian's chromium).
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

LOAD_REPORT_SAMPLE=${LOAD_REPORT_SAMPLE:?LOAD_REPORT_SAMPLE must name tests/integration/load_report_sample}
CHROMIUM=${CHROMIUM:-chromium}
require_tool "$LOAD_REPORT_SAMPLE"
require_tool "$CHROMIUM"
require_tool python3
require_tool "$OIIOTOOL"
# A browser that hangs must fail the test quickly, not at ctest's limit.
CMD_TIMEOUT=${VTS_TEST_CMD_TIMEOUT:-90}

PLOTS=(plot-latency plot-full-resolution plot-throughput plot-errors)

# browser ARGS... URL: headless Chromium with a throw-away profile, under the time limit.
browser() {
  expect_ok "$CHROMIUM" --headless --no-sandbox --disable-gpu --no-first-run \
    --disable-extensions --disable-dev-shm-usage --hide-scrollbars --force-device-scale-factor=1 \
    --user-data-dir="$WORK/.chromium-profile" "$@"
}

# dump_dom HTML OUT: the DOM Chromium built from HTML, serialised, into OUT.
dump_dom() {
  browser --dump-dom "file://$1"
  cp "$OUT" "$2"
  [[ -s $2 ]] || fail "chromium --dump-dom printed nothing for $1"
}

# screenshot HTML PNG WIDTH HEIGHT: what Chromium draws for HTML in a WIDTH x HEIGHT window.
screenshot() {
  rm -f "$2"
  browser --screenshot="$2" --window-size="$3,$4" "file://$1"
  [[ -s $2 ]] || fail "chromium --screenshot wrote no $2"
}

# check_dom DOM MODE: python3 walks the parsed DOM. MODE full: every plot has axes, ticks, legend
# and its series paths; empty: every plot says "no data" and has no series.
check_dom() {
  python3 - "$1" "$2" "${PLOTS[@]}" <<'EOF' || fail "DOM check of $1 failed (see above)"
import sys
from html.parser import HTMLParser

dom_file, mode, plot_ids = sys.argv[1], sys.argv[2], sys.argv[3:]
# Series each plot draws in the full sample (data-series attributes).
SERIES = {
    "plot-latency": ["p50", "p90", "p99"],
    "plot-full-resolution": ["full_resolution", "first_visible"],
    "plot-throughput": ["requests_per_s", "megabytes_per_s"],
    "plot-errors": ["errors_per_s"],
}
VOID = {"meta", "link", "br", "img", "input", "hr", "col", "area", "base", "wbr", "source"}


class Node:
    def __init__(self, tag, attrs, parent):
        self.tag, self.attrs, self.parent = tag, dict(attrs), parent
        self.children, self.text = [], ""

    def walk(self):
        yield self
        for c in self.children:
            yield from c.walk()

    def all_text(self):
        return self.text + "".join(c.all_text() for c in self.children)


class Tree(HTMLParser):
    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.root = Node("#root", [], None)
        self.cur = self.root

    def handle_starttag(self, tag, attrs):
        node = Node(tag, attrs, self.cur)
        self.cur.children.append(node)
        if tag not in VOID:
            self.cur = node

    def handle_startendtag(self, tag, attrs):
        self.cur.children.append(Node(tag, attrs, self.cur))

    def handle_endtag(self, tag):
        n = self.cur
        while n is not None and n.tag != tag:
            n = n.parent
        if n is not None and n.parent is not None:
            self.cur = n.parent

    def handle_data(self, data):
        self.cur.text += data


tree = Tree()
tree.feed(open(dom_file, encoding="utf-8").read())
nodes = list(tree.root.walk())
errors = []
if any(n.tag == "script" for n in nodes):
    errors.append("the page has a <script> element")
for pid in plot_ids:
    svgs = [n for n in nodes if n.tag == "svg" and n.attrs.get("id") == pid]
    if len(svgs) != 1:
        errors.append(f"{pid}: {len(svgs)} <svg> elements with that id, expected 1")
        continue
    svg = svgs[0]
    if "plot" not in svg.attrs.get("class", "").split():
        errors.append(f"{pid}: the <svg> lacks class=plot")
    inside = list(svg.walk())
    groups = {n.attrs.get("class", ""): n for n in inside if n.tag == "g"}
    texts = [n.all_text().strip() for n in inside if n.tag == "text"]
    if mode == "empty":
        if "no data" not in texts:
            errors.append(f"{pid}: the empty run's plot does not say 'no data' ({texts})")
        if any(n.attrs.get("class") == "series" for n in inside):
            errors.append(f"{pid}: the empty run's plot draws a series")
        continue
    for axis in ("axis x-axis", "axis y-axis", "legend"):
        g = groups.get(axis)
        if g is None:
            errors.append(f"{pid}: no <g class='{axis}'>")
            continue
        labels = [n.all_text().strip() for n in g.walk() if n.tag == "text"]
        if len([t for t in labels if t]) < 2 and axis != "legend":
            errors.append(f"{pid}: {axis} has {len(labels)} tick labels")
        if axis == "legend" and len(labels) != len(SERIES[pid]):
            errors.append(f"{pid}: legend has {labels}, expected {len(SERIES[pid])} entries")
    series = {n.attrs.get("data-series"): n for n in inside
              if n.tag == "g" and n.attrs.get("class") == "series"}
    if sorted(series) != sorted(SERIES[pid]):
        errors.append(f"{pid}: series {sorted(series)}, expected {sorted(SERIES[pid])}")
    for name, g in series.items():
        paths = [n for n in g.walk() if n.tag == "path"]
        if len(paths) != 1 or paths[0].attrs.get("d", "").count("L") < 10:
            errors.append(f"{pid}: series {name} has no line of at least 10 segments")
    if "no data" in texts:
        errors.append(f"{pid}: the full run's plot says 'no data'")
for e in errors:
    print("DOM:", e, file=sys.stderr)
print(f"-- {dom_file}: {len(plot_ids)} plots checked ({mode})")
sys.exit(1 if errors else 0)
EOF
}

# check_pixels PNG MIN_INK COLOURS...: PNG (via oiiotool as binary PPM) has at least MIN_INK
# (a fraction) pixels that are not the background, and at least 300 pixels of each #rrggbb colour
# (within a small tolerance, since lines are anti-aliased): more than a legend swatch (22x3)
# alone, so each colour's line must be drawn.
check_pixels() {
  local png=$1 min_ink=$2
  shift 2
  "$OIIOTOOL" "$png" --ch R,G,B -d uint8 -o "$png.ppm" || fail "oiiotool cannot convert $png"
  python3 - "$png.ppm" "$min_ink" "$@" <<'EOF' || fail "$png does not look like the report"
import sys

path, min_ink, colours = sys.argv[1], float(sys.argv[2]), sys.argv[3:]
data = open(path, "rb").read()
# Binary PPM: "P6" width height maxval, each followed by one whitespace byte, then RGB bytes.
fields, pos = [], 0
while len(fields) < 4:
    while data[pos:pos + 1].isspace():
        pos += 1
    start = pos
    while not data[pos:pos + 1].isspace():
        pos += 1
    fields.append(data[start:pos])
pos += 1
assert fields[0] == b"P6" and fields[3] == b"255", fields
w, h = int(fields[1]), int(fields[2])
pixels = data[pos:pos + 3 * w * h]
assert len(pixels) == 3 * w * h, "truncated PPM"
counts = {}
for i in range(0, len(pixels), 3):
    rgb = pixels[i:i + 3]
    counts[rgb] = counts.get(rgb, 0) + 1
background, bg_count = max(counts.items(), key=lambda kv: kv[1])
ink = 1 - bg_count / (w * h)
ok = True
print(f"-- {path}: {w}x{h}, {len(counts)} colours, {ink:.1%} not background")
if ink < min_ink:
    print(f"PIXELS: only {ink:.2%} of {path} differs from the background {background.hex()}",
          file=sys.stderr)
    ok = False
for c in colours:
    want = bytes.fromhex(c.lstrip("#"))
    n = sum(k for rgb, k in counts.items() if max(abs(a - b) for a, b in zip(rgb, want)) <= 12)
    print(f"--   {c}: {n} pixels")
    if n < 300:
        print(f"PIXELS: colour {c} drawn on {n} pixels of {path}, expected at least 300",
              file=sys.stderr)
        ok = False
sys.exit(0 if ok else 1)
EOF
}

# --- A full run: the report, its JSON and its summary.
note "writing a report from synthetic data"
expect_ok "$LOAD_REPORT_SAMPLE" "$WORK/full" --json "$WORK/full.json" --summary "$WORK/summary.txt"
[[ -s $WORK/full/index.html ]] || fail "no $WORK/full/index.html"
[[ $(dir_listing "$WORK/full") == ./index.html ]] || fail "the report folder holds more than index.html"
python3 - "$WORK/full.json" <<'EOF' || fail "the --json document is wrong"
import json, sys
j = json.load(open(sys.argv[1]))
assert j["format"] == "vts-loadtest-report" and j["version"] == 1
assert j["totals"]["requests"] == sum(s["requests"] for s in j["seconds"]) > 0
for key in ("queue_time", "ttfb", "total", "first_visible", "full_resolution"):
    m = j["latency_ns"][key]
    assert m["count"] == sum(b["count"] for b in m["buckets"]) > 0, key
    assert m["min"] <= m["p50"] <= m["p90"] <= m["p99"] <= m["p99_9"] <= m["max"], key
assert len(j["seconds"]) == 90
EOF
grep -q 'full resolution' "$WORK/summary.txt" || fail "the summary lacks the full-resolution row"

note "rendering it in headless Chromium"
dump_dom "$WORK/full/index.html" "$WORK/full.dom.html"
check_dom "$WORK/full.dom.html" full
screenshot "$WORK/full/index.html" "$WORK/full.png" 1000 3400
# p50 blue, p90 orange, p99/errors red, MB/s green, first-visible purple.
check_pixels "$WORK/full.png" 0.03 '#1f77b4' '#ff7f0e' '#d62728' '#2ca02c' '#9467bd'

# Each plot on its own page, as Chromium serialised it: it must draw its own lines.
note "rendering each plot alone"
for id in "${PLOTS[@]}"; do
  python3 - "$WORK/full.dom.html" "$id" "$WORK/$id.html" <<'EOF' || fail "cannot cut $id out of the DOM"
import sys
dom, pid, out = open(sys.argv[1], encoding="utf-8").read(), sys.argv[2], sys.argv[3]
start = dom.index(f'<svg class="plot" id="{pid}"')
end = dom.index("</svg>", start) + len("</svg>")
open(out, "w", encoding="utf-8").write(
    '<!DOCTYPE html><html><head><meta charset="utf-8"><style>body{margin:0;background:#fff}'
    "</style></head><body>" + dom[start:end] + "</body></html>")
EOF
  screenshot "$WORK/$id.html" "$WORK/$id.png" 800 340
  case $id in
    plot-latency) colours=('#1f77b4' '#ff7f0e' '#d62728') ;;
    plot-full-resolution) colours=('#1f77b4' '#9467bd') ;;
    plot-throughput) colours=('#1f77b4' '#2ca02c') ;;
    plot-errors) colours=('#d62728') ;;
  esac
  check_pixels "$WORK/$id.png" 0.02 "${colours[@]}"
done

# --- A run in which nothing completed.
note "an empty run"
expect_ok "$LOAD_REPORT_SAMPLE" "$WORK/empty" --empty --json "$WORK/empty.json"
python3 -c 'import json,sys; j=json.load(open(sys.argv[1])); assert j["totals"]["requests"]==0' \
  "$WORK/empty.json" || fail "the empty run's JSON is wrong"
dump_dom "$WORK/empty/index.html" "$WORK/empty.dom.html"
check_dom "$WORK/empty.dom.html" empty
screenshot "$WORK/empty/index.html" "$WORK/empty.png" 1000 2400
check_pixels "$WORK/empty.png" 0.01

# --- A hostile title: text on the page, never markup.
note "a hostile title"
hostile='</title><script>document.title="pwned"</script><svg onload=alert(1)><img src=x>&amp;'
expect_ok "$LOAD_REPORT_SAMPLE" "$WORK/hostile" --title "$hostile"
dump_dom "$WORK/hostile/index.html" "$WORK/hostile.dom.html"
check_dom "$WORK/hostile.dom.html" full
python3 - "$WORK/hostile.dom.html" "$hostile" <<'EOF' || fail "the hostile title was not escaped"
import sys
from html.parser import HTMLParser
dom, hostile = open(sys.argv[1], encoding="utf-8").read(), sys.argv[2]

class P(HTMLParser):
    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.tags, self.where, self.title, self.h1 = [], None, "", ""
    def handle_starttag(self, tag, attrs):
        self.tags.append(tag)
        self.where = tag if tag in ("title", "h1") else None
    def handle_endtag(self, tag):
        self.where = None
    def handle_data(self, data):
        if self.where == "title" and not self.title:
            self.title = data
        elif self.where == "h1":
            self.h1 += data

p = P()
p.feed(dom)
assert "script" not in p.tags and "img" not in p.tags, p.tags
assert p.title == hostile, repr(p.title)
assert p.h1 == hostile, repr(p.h1)
EOF

note "ok"
