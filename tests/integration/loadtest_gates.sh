#!/usr/bin/env bash
# vts loadtest as a CI gate, against the real `vts serve` on loopback and fault_proxy in front of
# it answering every 5th tile request with 503 (20% errors):
#   - no gate given: the default --max-error-rate 1% fails the run (exit 1, one line on stderr);
#     --max-error-rate 50% and 0.5 hold (exit 0); the JSON's "gates" says which held and the
#     measured value, equal to totals.error_ratio;
#   - --slo on a clean run: 'p99<1ns' fails (exit 1, naming the gate and the measured p99),
#     'p99<60s' and 'full_res_p95<60s' hold; a malformed --slo is a usage error (exit 2) naming
#     the text and listing the metric names;
#   - compare: the faulty run against the clean one marks error_rate as a regression (table and
#     --json), --fail-on-regression exits 1, a run against itself has no regression; --baseline
#     overlays the baseline in the HTML report;
#   - merge: two runs with different --seed (as --generators 2 --generator-index 0/1) merged:
#     every count is the sum of the two, every latency count the sum, gates apply to the merge.
source "$(dirname "$0")/lib.sh"
source "$(dirname "$0")/serve_lib.sh"
: "${FAULT_PROXY:?FAULT_PROXY must name the fault_proxy executable}"
require_tool "$FAULT_PROXY"
require_tool "$NODE"

gates_cleanup() {
  fault_proxy_cleanup
  serve_cleanup
}
trap gates_cleanup EXIT

# expect_rc N WHAT CMD...: CMD exits N.
expect_rc() {
  local want=$1 what=$2
  shift 2
  run "$@"
  ((RC == want)) || { show_output; fail "$what: exited $RC, expected $want"; }
}

# start_proxy ARGS...: fault_proxy in front of vts serve's tiles, its counts in proxy.stats.json.
start_proxy() {
  start_fault_proxy --prefix /earth@ "$@" --stats "$WORK/proxy.stats.json"
}

note "Earth archive and vts serve; fault_proxy answering every 5th tile with 503"
build_earth "$WORK/earth.pmtiles" --quiet
start_server "$WORK/earth.pmtiles"
start_proxy --error-every 5 --error-status 503
LT=(--viewers 3 --duration 2 --path jumps --quiet)

# ---- the error rate gate ---------------------------------------------------------------------
note "through the proxy, no gate: the default 1% error rate gate fails the run"
expect_rc 1 "20% errors, no gate" "$VTS" loadtest "$PROXY/earth" "${LT[@]}" --json
cp "$OUT" "$WORK/faulty.json"
[[ $(wc -l <"$ERR") -eq 1 ]] || { show_output; fail "the reason is not one line"; }
grep -qE '^vts: gate failed: error_rate<=1% \(error_rate = [0-9.]+%\)$' "$ERR" ||
  { show_output; fail "the reason does not name the error rate gate"; }
json_check "$WORK/faulty.json" 'j.totals.errors > 0 && j.errors_by_kind.http_503 == j.totals.errors' \
  "the errors are the injected 503s"
json_check "$WORK/faulty.json" 'j.gates.passed === false && j.gates.results.length == 1 &&
  j.gates.results[0].gate == "error_rate<=1%" && j.gates.results[0].held === false &&
  j.gates.results[0].measured == j.totals.error_ratio && j.gates.results[0].threshold == 0.01' \
  "gates section of a failed run"
ratio=$(json_get "$WORK/faulty.json" 'j.totals.error_ratio')
note "error ratio $ratio"
json_check "$WORK/faulty.json" 'j.totals.error_ratio > 0.1 && j.totals.error_ratio < 0.3' \
  "about one error in five: $ratio"

for limit in 50% 0.5; do
  note "--max-error-rate $limit holds"
  expect_rc 0 "--max-error-rate $limit" "$VTS" loadtest "$PROXY/earth" "${LT[@]}" --json \
    --max-error-rate "$limit"
  json_check "$OUT" 'j.gates.passed === true && j.gates.results[0].held === true &&
    j.gates.results[0].threshold == 0.5 && j.totals.errors > 0' "gates with --max-error-rate $limit"
done
note "--max-error-rate 5% is violated: exit 1 also without --json, after the tables"
expect_rc 1 "--max-error-rate 5%" "$VTS" loadtest "$PROXY/earth" "${LT[@]}" --max-error-rate 5%
grep -q '^vts: gate failed: error_rate<=5% ' "$ERR" || { show_output; fail "no reason for 5%"; }
grep -q 'http_503' "$OUT" || { show_output; fail "the tables are missing"; }
stop_fault_proxy

note "fault_proxy breaking off every 4th tile half way: the gate fires on truncated bodies"
start_proxy --truncate-every 4
expect_rc 1 "25% truncated, no gate" "$VTS" loadtest "$PROXY/earth" "${LT[@]}" --json
cp "$OUT" "$WORK/truncated.json"
grep -qE '^vts: gate failed: error_rate<=1% \(error_rate = [0-9.]+%\)$' "$ERR" ||
  { show_output; fail "the reason does not name the error rate gate"; }
expect_rc 0 "--max-error-rate 50% with truncations" "$VTS" loadtest "$PROXY/earth" "${LT[@]}" \
  --json --max-error-rate 50%
stop_fault_proxy
truncations=$(json_get "$WORK/proxy.stats.json" 'j.truncations')
# Every error is a truncated body, never a checksum error; a request the view dropped while its
# body was on the way is cancelled, not an error, so errors <= truncations of the first run.
json_check "$WORK/truncated.json" "j.totals.errors > 0 && j.errors_by_kind.truncated == j.totals.errors &&
  j.totals.error_ratio > 0.1 && j.totals.error_ratio < 0.4" "the errors are the truncated bodies"
errors=$(json_get "$WORK/truncated.json" 'j.totals.errors')
((errors + $(json_get "$OUT" 'j.totals.errors') <= truncations)) ||
  fail "$errors + $(json_get "$OUT" 'j.totals.errors') truncated errors counted, the proxy cut $truncations"
note "$errors truncated bodies counted (proxy: $truncations cut over both runs)"

note "fault_proxy holding every 4th tile for 3 s, --timeout 0.5: errors of kind timeout"
start_proxy --delay-every 4 --delay-ms 3000
expect_rc 1 "--timeout 0.5 with 3 s delays" "$VTS" loadtest "$PROXY/earth" "${LT[@]}" --json \
  --timeout 0.5
stop_fault_proxy
json_check "$OUT" "j.totals.errors > 0 && j.errors_by_kind.timeout == j.totals.errors &&
  j.totals.errors <= $(json_get "$WORK/proxy.stats.json" 'j.delays')" "the errors are the delayed tiles"

note "fault_proxy holding every tile for 3 s: the progress lines of seconds without a response"
note "show no latency (never 'p99 0')"
start_proxy --delay-every 1 --delay-ms 3000
expect_rc 0 "every tile 3 s late" "$VTS" loadtest "$PROXY/earth" --viewers 3 \
  --duration 2 --path jumps
stop_fault_proxy
grep -qE '^\[ +[0-9]+s/2s\] .*, no responses this second, ' "$ERR" ||
  { show_output; fail "no progress line says that no response came"; }
grep -qE '^\[.*p99 0 ' "$ERR" && { show_output; fail "a progress line shows p99 0"; }

# ---- --slo on a clean run ----------------------------------------------------------------------
note "straight against vts serve: --slo 'p99<60s' --slo 'full_res_p95<60s' hold"
expect_rc 0 "holding SLOs" "$VTS" loadtest "$BASE/earth" "${LT[@]}" --json --slo 'p99<60s' \
  --slo 'full_res_p95 < 60s' --report "$WORK/clean-report"
cp "$OUT" "$WORK/clean.json"
json_check "$WORK/clean.json" 'j.totals.errors == 0 && j.gates.passed === true &&
  j.gates.results.map(r => r.gate).join(",") == "p99<60s,full_res_p95 < 60s,error_rate<=1%" &&
  j.gates.results.every(r => r.held) && j.gates.results[0].measured == j.latency_ns.total.p99 &&
  j.gates.results[1].measured > 0 && j.latency_ns.full_resolution.count > 0' "gates of a clean run"
note "--slo 'p99<1ns' fails naming the gate and the measured p99"
expect_rc 1 "p99<1ns" "$VTS" loadtest "$BASE/earth" "${LT[@]}" --slo 'p99<1ns'
[[ $(wc -l <"$ERR") -eq 1 ]] || { show_output; fail "the reason is not one line"; }
grep -qE '^vts: gate failed: p99<1ns \(p99 = [0-9.]+ (us|ms|s)\)$' "$ERR" ||
  { show_output; fail "the reason does not name p99<1ns"; }
note "--slo 'requests_per_s>=1e9' fails"
expect_rc 1 "requests_per_s>=1e9" "$VTS" loadtest "$BASE/earth" "${LT[@]}" --slo 'requests_per_s>=1e9'
grep -q 'gate failed: requests_per_s>=1e9 (requests_per_s = ' "$ERR" || { show_output; fail "rps"; }

note "malformed --slo and --max-error-rate: exit 2 before any request"
for bad in 'p99<200' 'p99' 'latency<1s' 'p99<=fast' 'requests<5ms'; do
  expect_rc 2 "--slo '$bad'" "$VTS" loadtest "$BASE/earth" "${LT[@]}" --slo "$bad"
  grep -qF -- "--slo '$bad'" "$ERR" || { show_output; fail "the error does not name '$bad'"; }
  grep -qF 'full_res_' "$ERR" || { show_output; fail "the error does not list the metrics"; }
done
for bad in 2 -1% 1%% x; do
  expect_rc 2 "--max-error-rate $bad" "$VTS" loadtest "$BASE/earth" "${LT[@]}" --max-error-rate "$bad"
  grep -qF -- "--max-error-rate '$bad'" "$ERR" || { show_output; fail "no '$bad' in the error"; }
done

# ---- compare and --baseline --------------------------------------------------------------------
note "compare clean faulty: error_rate is a regression"
expect_rc 0 "compare" "$VTS" loadtest compare "$WORK/clean.json" "$WORK/faulty.json"
grep -qE '^error_rate +0% +[0-9.]+% +\+[0-9.]+% +- +REGRESSION$' "$OUT" ||
  { show_output; fail "the table does not mark error_rate"; }
for m in p99 full_res_p99 requests_per_s; do
  grep -qE "^$m " "$OUT" || { show_output; fail "compare shows no $m"; }
done
expect_rc 0 "compare --json" "$VTS" loadtest compare "$WORK/clean.json" "$WORK/faulty.json" --json
json_check "$OUT" 'j.metrics.find(m => m.name == "error_rate").regression === true &&
  j.metrics.find(m => m.name == "error_rate").relative === null && j.regressions >= 1 &&
  j.metrics.find(m => m.name == "requests").absolute ==
    j.metrics.find(m => m.name == "requests").b - j.metrics.find(m => m.name == "requests").a' \
  "compare --json"
reqs_a=$(json_get "$WORK/clean.json" 'j.totals.requests')
json_check "$OUT" "j.metrics.find(m => m.name == 'requests').a == $reqs_a" "A's requests"
expect_rc 1 "--fail-on-regression" "$VTS" loadtest compare "$WORK/clean.json" "$WORK/faulty.json" \
  --fail-on-regression
expect_rc 0 "a run against itself" "$VTS" loadtest compare "$WORK/clean.json" "$WORK/clean.json" \
  --fail-on-regression --json
json_check "$OUT" 'j.regressions == 0 && j.metrics.every(m => m.absolute == 0)' "no change"
expect_rc 3 "compare a missing file" "$VTS" loadtest compare "$WORK/clean.json" "$WORK/missing.json"
grep -qF "$WORK/missing.json" "$ERR" || { show_output; fail "the error does not name the file"; }
echo '{"format": "something"}' >"$WORK/other.json"
expect_rc 2 "compare a non-report" "$VTS" loadtest compare "$WORK/clean.json" "$WORK/other.json"
grep -qF "other.json: not a vts loadtest report" "$ERR" || { show_output; fail "non-report"; }

note "--baseline: the report overlays the baseline run"
expect_rc 1 "faulty run with --baseline" "$VTS" loadtest "$BASE/earth" "${LT[@]}" --slo 'p99<1ns' \
  --baseline "$WORK/faulty.json" --report "$WORK/overlay"
for want in 'id="plot-latency-cdf"' 'data-series="baseline_total"' \
  'data-series="baseline_full_resolution"' 'class="compare"'; do
  grep -qF "$want" "$WORK/overlay/index.html" || fail "the overlay report has no $want"
done
grep -qF 'plot-latency-cdf' "$WORK/clean-report/index.html" && fail "a report without baseline overlays"

note "the HTML report opens with the gates: red naming the failed one, else passed"
# gate_rows REPORT: the gate section's rows as "gate|measured|result" lines.
gate_rows() {
  sed -n '/<section class="gates/,/<\/section>/p' "$1" |
    sed -nE 's|<tr><td>([^<]*)</td><td class="num">([^<]*)</td><td class="[a-z]*">([^<]*)</td></tr>|\1\|\2\|\3|p'
}
head -c 2000 "$WORK/overlay/index.html" | grep -qF '<section class="gates failed" id="gates">' ||
  fail "the failed run's report does not open with a failed gate section"
gate_rows "$WORK/overlay/index.html" >"$WORK/overlay.gates"
if ! grep -qE '^p99&lt;1ns\|p99 = [0-9.]+ (ns|us|ms|s)\|FAIL$' "$WORK/overlay.gates" ||
  ! grep -qE '^error_rate&lt;=1%\|error_rate = [0-9.]+%\|pass$' "$WORK/overlay.gates"; then
  cat "$WORK/overlay.gates" >&2
  fail "the failed run's gate rows"
fi
head -c 2000 "$WORK/clean-report/index.html" | grep -qF '<section class="gates" id="gates">' ||
  fail "the clean run's report does not open with a passed gate section"
[[ $(gate_rows "$WORK/clean-report/index.html" | grep -c '|pass$') == 3 ]] ||
  fail "the clean run's report does not show its 3 gates passed"

# ---- merge ---------------------------------------------------------------------------------------
note "two generators (--generators 2, index 0 and 1: seeds 7 and 8) merged: counts are sums"
for i in 0 1; do
  expect_rc 0 "generator $i" "$VTS" loadtest "$BASE/earth" --viewers 4 --duration 2 --path jumps \
    --quiet --json --seed 7 --generators 2 --generator-index "$i"
  cp "$OUT" "$WORK/gen$i.json"
  json_check "$WORK/gen$i.json" "j.generator.index == $i && j.generator.generators == 2 &&
    j.generator.viewers == 2 && j.generator.first_viewer == 2 * $i && j.generator.seed == 7 + $i &&
    j.scenario.viewers == 2 && j.totals.requests > 0" "generator $i's share"
done
expect_rc 0 "merge" "$VTS" loadtest merge "$WORK/gen0.json" "$WORK/gen1.json" --json \
  --report "$WORK/merged-report"
cp "$OUT" "$WORK/merged.json"
node_sum() {
  # shellcheck disable=SC2016  # JavaScript, not shell
  "$NODE" -e '
    const fs = require("fs");
    const [m, a, b] = process.argv.slice(1).map(f => JSON.parse(fs.readFileSync(f, "utf8")));
    const bad = [];
    const eq = (what, x, y) => { if (x !== y) bad.push(`${what}: ${x} != ${y}`); };
    for (const k of ["requests", "bytes", "errors", "camera_moves"])
      eq(k, m.totals[k], a.totals[k] + b.totals[k]);
    eq("viewers", m.scenario.viewers, a.scenario.viewers + b.scenario.viewers);
    for (const h of Object.keys(a.latency_ns)) {
      eq(h + ".count", m.latency_ns[h].count, a.latency_ns[h].count + b.latency_ns[h].count);
      const n = m.latency_ns[h].buckets.reduce((s, x) => s + x.count, 0);
      eq(h + " bucket counts", n, m.latency_ns[h].count);
      if (a.latency_ns[h].count && b.latency_ns[h].count)
        eq(h + ".max", m.latency_ns[h].max, Math.max(a.latency_ns[h].max, b.latency_ns[h].max));
    }
    for (const s of Object.keys(a.by_status))
      eq("status " + s, m.by_status[s], a.by_status[s] + (b.by_status[s] || 0));
    eq("merged files", m.merged.length, 2);
    eq("gates", m.gates.passed, true);
    if (bad.length) { console.error(bad.join("\n")); process.exit(1); }' "$@"
}
node_sum "$WORK/merged.json" "$WORK/gen0.json" "$WORK/gen1.json" || fail "merged counts are not the sums"
[[ -s $WORK/merged-report/index.html ]] || fail "merge --report wrote no index.html"
grep -qF '<section class="gates" id="gates">' "$WORK/merged-report/index.html" ||
  fail "the merged report has no gate section"
note "merged: $(json_get "$WORK/merged.json" 'j.totals.requests') requests"
expect_rc 1 "merge with a failing --slo" "$VTS" loadtest merge "$WORK/gen0.json" "$WORK/gen1.json" \
  --slo 'p50<1ns'
grep -q '^vts: gate failed: p50<1ns' "$ERR" || { show_output; fail "merge gate"; }
expect_rc 1 "merge of a faulty run: the default error gate" "$VTS" loadtest merge \
  "$WORK/gen0.json" "$WORK/faulty.json"
note "the generator index from \$SLURM_ARRAY_TASK_ID and \$AWS_BATCH_JOB_ARRAY_INDEX"
for var in SLURM_ARRAY_TASK_ID AWS_BATCH_JOB_ARRAY_INDEX; do
  expect_rc 0 "$var=1" env "$var=1" "$VTS" loadtest "$BASE/earth" --viewers 3 --duration 0.5 \
    --quiet --json --generators 2
  json_check "$OUT" 'j.generator.index == 1 && j.generator.first_viewer == 1 &&
    j.generator.viewers == 2 && j.scenario.viewers == 2' "generator 1 of 2 from \$$var"
done
expect_rc 2 "--generators without an index" env -u JOB_COMPLETION_INDEX -u SLURM_ARRAY_TASK_ID \
  -u AWS_BATCH_JOB_ARRAY_INDEX "$VTS" loadtest "$BASE/earth" "${LT[@]}" --generators 2
grep -qF -- '--generators without --generator-index' "$ERR" || { show_output; fail "no index"; }
expect_rc 2 "fewer viewers than generators" "$VTS" loadtest "$BASE/earth" --viewers 1 \
  --generators 2 --generator-index 0 --duration 1
grep -qF -- '--viewers 1 is fewer than --generators 2' "$ERR" || { show_output; fail "viewers"; }
expect_rc 2 "--generator-index 2 of 2" "$VTS" loadtest "$BASE/earth" "${LT[@]}" --generators 2 \
  --generator-index 2
grep -qF 'generator index 2 is not below --generators 2' "$ERR" || { show_output; fail "index"; }
note "PASS"
