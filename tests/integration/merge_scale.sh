#!/usr/bin/env bash
# The merge of parts at scale, and nested leaves read by a stock reader:
#   - 10^7 tiny tiles in 17 parts (the apex and 16 sub-pyramids): merge_parts() peaks under
#     256 MiB RSS (the bound docs/PLANET.md states) and writes the pmtiles::Writer's archive of the
#     same tiles byte for byte (the small-payload table fills its 2^20 slots on the way);
#   - an archive with two levels of leaves (leaves of 16 entries) reads the same
#     through the npm `pmtiles` library as through our reader, merged or written whole.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
: "${PART_FIXTURE:?PART_FIXTURE must name the part_fixture tool}"
: "${PMTILES_DUMP:?PMTILES_DUMP must name the pmtiles_dump tool}"
require_tool "$NODE"
[[ -f $PMTILES_JS/node_modules/pmtiles/package.json ]] ||
  fail "npm package pmtiles is not installed in $PMTILES_JS (run scripts/setup.sh)"

N=10000000
note "writing $N tiny tiles as 17 parts, and as one archive through the Writer"
"$PART_FIXTURE" parts "$WORK/parts" "$N" 2 || fail "part_fixture parts failed"
"$PART_FIXTURE" single "$WORK/single.pmtiles" "$N" || fail "part_fixture single failed"
note "merging"
"$PART_FIXTURE" merge "$WORK/parts" "$WORK/merged.pmtiles" >"$WORK/merge.json" ||
  fail "the merge failed"
cat "$WORK/merge.json"
json_check "$WORK/merge.json" "j.tiles === $N" "the merged archive addresses $N tiles"
json_check "$WORK/merge.json" "j.max_rss_kib <= 256 * 1024" "the merge peaked under 256 MiB RSS"
json_check "$WORK/merge.json" "j.leaves >= 1800" "the entries went to leaves of 4096"
cmp -s "$WORK/single.pmtiles" "$WORK/merged.pmtiles" ||
  fail "the merged archive differs from the Writer's archive of the same tiles"
note "merged == written whole ($(stat -c %s "$WORK/merged.pmtiles") bytes)"

note "nested leaves: 3000 tiles in leaves of 16 entries"
"$PART_FIXTURE" parts "$WORK/small" 3000 1 || fail "part_fixture parts failed"
"$PART_FIXTURE" single "$WORK/nested.pmtiles" 3000 16 || fail "part_fixture single failed"
"$PART_FIXTURE" merge "$WORK/small" "$WORK/nested_merged.pmtiles" 16 >"$WORK/nested.json" ||
  fail "the merge failed"
# 2240 entries (runs merge the rest): 140 leaves of 16, under 9 leaves of pointers, under the root.
json_check "$WORK/nested.json" "j.leaves === 140 + 9" "140 leaves under 9 leaves of pointers"
cmp -s "$WORK/nested.pmtiles" "$WORK/nested_merged.pmtiles" ||
  fail "the merged nested archive differs from the Writer's"
"$PMTILES_DUMP" tiles "$WORK/nested.pmtiles" >"$WORK/cpp.txt" || fail "pmtiles_dump failed"
"$NODE" "$PMTILES_JS/dump.mjs" tiles "$WORK/nested.pmtiles" >"$WORK/js.txt" ||
  fail "npm pmtiles could not read the nested archive"
cmp -s "$WORK/cpp.txt" "$WORK/js.txt" || {
  diff -u "$WORK/cpp.txt" "$WORK/js.txt" | head -20 >&2
  fail "our reader and npm pmtiles disagree on the nested archive"
}
n=$(wc -l <"$WORK/js.txt")
((n == 3000)) || fail "npm pmtiles found $n tiles, expected 3000"
note "PASS"
