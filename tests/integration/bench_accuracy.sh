#!/usr/bin/env bash
# `vts bench accuracy --quick` end to end under Xvfb with Mesa llvmpipe, on a small copy of the
# Earth: every one of the six tables is produced (none skipped, none failed) with its rows, the
# report directory holds report.md, report.json and every plot as well-formed SVG, the JSON on
# stdout agrees with the report, and the figures that must hold do (lossless is exact, bc1 is
# lossy within bounds and 1/8 of the GPU bytes, 1/1 feedback finds every needed tile, the warp's
# resampling methods rank as interpolation theory says against the analytic reference, and no
# method scores below the 8-bit rounding floor, which only a reference made by the warper itself
# could). Bad options fail cleanly.
#
# Environment (besides lib.sh's): XVFB_RUN, the xvfb-run script.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
require_tool "$OIIOTOOL"
require_tool "$NODE"
XVFB_RUN=${XVFB_RUN:-xvfb-run}
require_tool "$XVFB_RUN"
XVFB=("$XVFB_RUN" -a -s "-screen 0 1280x1024x24")

SMALL="$WORK/earth512.png"
"$OIIOTOOL" "$EARTH" --resize 512x256 -o "$SMALL" || fail "cannot make the small input"
R="$WORK/report"

note "vts bench accuracy --quick (all six tables)"
expect_ok "${XVFB[@]}" "$VTS" bench accuracy --quick --input "$SMALL" --report "$R" --json
J="$WORK/accuracy.json"
cp "$OUT" "$J"
cat "$ERR" >&2

json_check "$J" "JSON.stringify(j.tables.map(t => t.id)) === \
JSON.stringify(['codec', 'feedback', 'filtering', 'addressing', 'downsample', 'resampling'])" \
  "the six tables, in order"
json_check "$J" "j.skipped.length === 0" "no table skipped or failed"
json_check "$J" "j.tables.every(t => t.rows.length > 0 && t.columns.length > 1 && t.notes.length > 0 \
&& t.plots.length > 0 && t.rows.every(r => Object.keys(r).length === t.columns.length))" \
  "every table has rows with every column, notes and a plot"
json_check "$J" "j.gl.includes('llvmpipe') || j.gl.includes('Mesa')" "GL context named"
json_check "$J" "j.quick === true && j.input.includes('512x256')" "input and mode recorded"

note "table 1: lossless is exact, bc1 lossy within bounds at 1/8 of the GPU bytes"
codec="j.tables[0].rows"
json_check "$J" "$codec.filter(r => r.setting.startsWith('lossless')).length >= 4" "lossless rows"
json_check "$J" "$codec.filter(r => r.setting.startsWith('bc1')).length === 3" "3 bc1 rows"
json_check "$J" "$codec.filter(r => r.setting.startsWith('lossless')).every(r => \
r.psnr_db === 'inf' && r.max_error === 0)" "lossless rows are exact"
json_check "$J" "$codec.filter(r => r.setting.startsWith('bc1')).every(r => \
r.psnr_db > 30 && r.psnr_db < 60 && r.max_error > 0)" "bc1 rows are lossy, PSNR in 30..60 dB"
json_check "$J" "(() => { const l = $codec.find(r => r.setting.startsWith('lossless')), \
b = $codec.find(r => r.setting.startsWith('bc1')); return l.gpu_bytes === 8 * b.gpu_bytes; })()" \
  "bc1 GPU bytes are 1/8 of rgba8"
json_check "$J" "$codec.every(r => r.encode_ms > 0 && r.decode_ms > 0 && r.upload_ms > 0 \
&& r.bytes_per_tile > 0)" "every codec row was timed (upload included: GL is there)"

note "table 2: 1/1 feedback finds every needed tile"
json_check "$J" "j.tables[1].rows.length === 5" "five feedback divisors"
json_check "$J" "Object.values(j.tables[1].rows[0]).includes(1)" "1/1 row present"

note "table 6: warp resampling against the analytic pattern"
res="j.tables[5].rows"
rms="(p, m) => $res.find(r => r.pattern === p && r.resampling === m).rms_error"
json_check "$J" "JSON.stringify($res.map(r => r.pattern + ' ' + r.resampling + ' ' + r.warp_error)) === \
JSON.stringify(['smooth near 0.01', 'smooth bilinear 0.01', 'smooth cubic 0.01', \
'smooth lanczos 0.01', 'fine near 0.01', 'fine bilinear 0.01', 'fine cubic 0.01', \
'fine lanczos 0.01', 'smooth cubic 0', 'smooth cubic 0.125', 'fine cubic 0', 'fine cubic 0.125'])" \
  "two patterns x four methods, then cubic with the exact transformer and with -et 0.125"
json_check "$J" "(() => { const e = (p, x) => $res.find(r => r.pattern === p && r.resampling === \
'cubic' && r.warp_error === x).rms_error; return e('smooth', 0.01) < 1.05 * e('smooth', 0) \
&& e('smooth', 0.125) > 1.5 * e('smooth', 0.01); })()" \
  "smooth: -et 0.01 as exact as the exact transformer, gdalwarp's 0.125 clearly worse"
json_check "$J" "(() => { const e = $rms; return e('smooth', 'cubic') < e('smooth', 'bilinear') \
&& e('smooth', 'lanczos') < e('smooth', 'bilinear') && e('smooth', 'bilinear') < e('smooth', 'near'); \
})()" "smooth pattern: cubic and lanczos beat bilinear, which beats near"
json_check "$J" "(() => { const e = $rms; return e('fine', 'lanczos') < e('fine', 'cubic') \
&& e('fine', 'cubic') < e('fine', 'bilinear') && e('fine', 'bilinear') < e('fine', 'near'); })()" \
  "fine pattern: the longer the kernel, the smaller the error"
json_check "$J" "(() => { const e = $rms; return e('smooth', 'cubic') < 0.4 \
&& e('smooth', 'cubic') < e('smooth', 'lanczos') && e('smooth', 'lanczos') < 0.5; })()" \
  "smooth: cubic at the 8-bit rounding floor (0.289 RMS), lanczos just above it"
json_check "$J" "(() => { const e = $rms; return 2 * e('fine', 'lanczos') < e('fine', 'cubic') \
&& 2 * e('fine', 'cubic') < e('fine', 'near'); })()" \
  "fine: lanczos halves cubic's error, cubic halves near's"
json_check "$J" "$res.every(r => r.rms_error >= 0.25 && r.max_error > 0.4 && r.texels > 1000 \
&& r.build_s > 0)" "no row beats the 8-bit rounding floor; every row compared texels and was timed"

note "the report directory: report.md, report.json, every plot"
[[ -s $R/report.md && -s $R/report.json ]] || fail "report.md or report.json missing"
for n in 1 2 3 4 5 6; do
  grep -q "^### $n\. " "$R/report.md" || fail "report.md has no section $n"
done
json_check "$R/report.json" "j.tables.length === 6" "report.json holds the six tables"
plots=$(json_get "$J" "j.tables.flatMap(t => t.plots.map(p => p.id)).join(' ')")
for p in $plots; do
  [[ -s $R/$p.svg ]] || fail "plot $p.svg missing from the report"
  grep -q "($p.svg)" "$R/report.md" || fail "report.md does not link $p.svg"
  python3 -c 'import sys, xml.dom.minidom; xml.dom.minidom.parse(sys.argv[1])' "$R/$p.svg" ||
    fail "$p.svg is not well-formed XML"
  grep -q 'class="series"' "$R/$p.svg" || fail "$p.svg draws no data series"
done

note "bad options fail cleanly"
expect_clean_failure "$VTS" bench accuracy --quick --input "$WORK/missing.png"
expect_clean_failure "$VTS" bench accuracy --quick --tables codec,colour
expect_clean_failure "$VTS" bench accuracy --quick --size 0x9
note "ok"
