#!/usr/bin/env bash
# Process start-up benchmark: what starting `vts` costs before it does any work, beside two peers'
# start-up, on this machine in one run, so the figures compare as ratios on a busy shared machine:
#   vts --help
#   vts info ARCHIVE     ARCHIVE: `vts build --synthetic 3000x1700` (117 tiles), made once per run
#                        in a temporary directory, not timed
#   vts serve --help
#   gdalinfo --version   peer: a GDAL tool's start
#   nginx -v             peer: a lean C program's start (its output, on stderr, is discarded)
#   true                 the floor: starting an empty process the same way (a reference row)
# Each command runs once untimed (page cache), then N times, interleaved (run i of every command,
# then run i + 1, the starting command rotating), each under `/usr/bin/time -f %M` for its peak
# resident set; the wall time of each run is bash's $EPOCHREALTIME (microseconds) around it, so
# every row includes the same spawn of /usr/bin/time (the `true` row shows that floor).
#
#   bash bench/startup_bench.sh [--runs N] [--vts PATH] [--out FILE] [--json]
#
#   --runs N   timed runs of each command (default 20)
#   --vts      the vts executable (default build/cli/vts)
#   --out      also write the markdown to FILE
#   --json     print one JSON object on stdout; the markdown goes to stderr (and --out)
#
# Prints a markdown table: per command the median and p90 (nearest rank) wall ms, the largest peak
# RSS of its runs (MiB) and its median / gdalinfo --version's median; then the bars (`vts --help`
# at most 0.5x gdalinfo --version; each vts command's peak RSS at most 20 MiB), PASS or FAIL each;
# then the shared libraries the executable loads (`ldd | wc -l`) and any of them that name gdal,
# OpenImageIO, openvdb, poppler or hdf5. Exits 0 whatever the figures (it reports, it does not
# gate); 1 when a command fails to run.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

RUNS=20
VTS_ARG=""
OUT_FILE=""
JSON=0
while (($#)); do
  case $1 in
    --runs) (($# >= 2)) || die "--runs needs a value"; RUNS=$2; shift 2 ;;
    --json) JSON=1; shift ;;
    *) bench_option "$@"; shift "$OPT_SHIFT" ;;
  esac
done
[[ $RUNS =~ ^[1-9][0-9]*$ ]] || die "--runs must be a positive integer, not '$RUNS'"
need gdalinfo nginx ldd awk sort
[[ -x $TIME_BIN ]] || die "missing $TIME_BIN (Debian package 'time')"
[[ -n ${EPOCHREALTIME:-} ]] || die "needs bash 5 (\$EPOCHREALTIME)"
VTS=$(find_vts "$VTS_ARG")

WORK=$(mktemp -d "${TMPDIR:-/tmp}/vts-startup-bench.XXXXXX")
trap 'rm -rf "$WORK"' EXIT
"$VTS" build --synthetic 3000x1700 -o "$WORK/x.pmtiles" >"$WORK/build.log" 2>&1 ||
  die "vts build --synthetic 3000x1700 failed: $(tail -n 3 "$WORK/build.log")"

# The commands, by key, in table order; LABEL is what the table shows.
KEYS=(help info serve_help gdalinfo nginx floor)
declare -A LABEL=([help]="vts --help" [info]="vts info x.pmtiles" [serve_help]="vts serve --help"
  [gdalinfo]="gdalinfo --version" [nginx]="nginx -v" [floor]="true (floor)")
VTS_KEYS=(help info serve_help)
cmd_of() { # KEY: sets CMD to the command's words
  case $1 in
    help) CMD=("$VTS" --help) ;;
    info) CMD=("$VTS" info "$WORK/x.pmtiles") ;;
    serve_help) CMD=("$VTS" serve --help) ;;
    gdalinfo) CMD=(gdalinfo --version) ;;
    nginx) CMD=(nginx -v) ;;
    floor) CMD=(true) ;; # /usr/bin/time execs the external true
  esac
}

# run_once KEY [RECORD]: one run of KEY's command under /usr/bin/time (output discarded: stdout to
# /dev/null, stderr kept for a failure's message); with RECORD, appends its wall time (µs) to
# WORK/KEY.us and its peak RSS (KiB) to WORK/KEY.kib. Dies when the command fails.
run_once() {
  local key=$1 t0 t1 rc=0
  cmd_of "$key"
  t0=${EPOCHREALTIME//[!0-9]/}
  "$TIME_BIN" -f '%M' -o "$WORK/time.txt" "${CMD[@]}" >/dev/null 2>"$WORK/err.txt" </dev/null || rc=$?
  t1=${EPOCHREALTIME//[!0-9]/}
  ((rc == 0)) || die "'${CMD[*]}' failed (exit $rc): $(tail -n 3 "$WORK/err.txt")"
  if (($# > 1)); then
    echo $((t1 - t0)) >>"$WORK/$key.us"
    tail -n 1 "$WORK/time.txt" >>"$WORK/$key.kib"
  fi
}

for key in "${KEYS[@]}"; do
  run_once "$key" # warm-up, not recorded
done
echo "[bench] $RUNS runs of ${#KEYS[@]} commands, interleaved ..." >&2
for ((i = 0; i < RUNS; i++)); do
  for ((j = 0; j < ${#KEYS[@]}; j++)); do
    run_once "${KEYS[(i + j) % ${#KEYS[@]}]}" record
  done
done

# Figures per key: MEDIAN and P90 (ms, 2 decimals), RSS (MiB, 1 decimal).
declare -A MEDIAN P90 RSS RATIO
for key in "${KEYS[@]}"; do
  read -r "MEDIAN[$key]" "P90[$key]" < <(sort -n "$WORK/$key.us" | awk '{ v[NR] = $1 } END {
      m = NR % 2 ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2
      r = int(0.9 * NR); if (r < 0.9 * NR) r++
      printf "%.2f %.2f\n", m / 1000, v[r] / 1000 }')
  RSS[$key]=$(sort -n "$WORK/$key.kib" | awk 'END { printf "%.1f", $1 / 1024 }')
done
for key in "${KEYS[@]}"; do
  RATIO[$key]=$(ratio "${MEDIAN[$key]}" "${MEDIAN[gdalinfo]}")
done
le() { awk -v a="$1" -v b="$2" 'BEGIN { exit !(a != "-" && a + 0 <= b + 0) }'; } # A <= B
mark() { if le "$1" "$2"; then echo PASS; else echo FAIL; fi; }
HELP_MARK=$(mark "${RATIO[help]}" 0.5)
declare -A RSS_MARK
for key in "${VTS_KEYS[@]}"; do RSS_MARK[$key]=$(mark "${RSS[$key]}" 20); done

# The shared libraries the executable loads (ldd's lines), and the heavy ones among them.
LDD_OUT=$(ldd "$VTS" 2>&1 || true)
if grep -q 'not a dynamic executable' <<<"$LDD_OUT"; then LIBS=0; else LIBS=$(wc -l <<<"$LDD_OUT"); fi
HEAVY_RE='gdal|openimageio|openvdb|poppler|hdf5'
mapfile -t HEAVY < <(grep -iE "$HEAVY_RE" <<<"$LDD_OUT" | awk '{ print $1 }' || true)
if ((${#HEAVY[@]})); then HEAVY_MARK=FAIL; else HEAVY_MARK=PASS; fi

report() {
  echo "## Process start-up: vts vs gdalinfo and nginx ($(date -u '+%Y-%m-%d'))"
  echo
  machine_info
  echo "- vts: $VTS"
  echo "- load average at start: $(cut -d' ' -f1-3 /proc/loadavg) (a shared machine: figures vary run to run)"
  echo "- $RUNS runs of each, interleaved, after one untimed run each; wall: \$EPOCHREALTIME around \`/usr/bin/time -f %M\` (its spawn included in every row); peak RSS: the largest of the runs"
  echo "- $(gdalinfo --version 2>&1 | head -n 1); $(nginx -v 2>&1 | sed 's|.*: ||')"
  echo
  echo "| command | median ms | p90 ms | max RSS MiB | median vs gdalinfo --version |"
  echo "| --- | ---: | ---: | ---: | ---: |"
  for key in "${KEYS[@]}"; do
    echo "| \`${LABEL[$key]}\` | ${MEDIAN[$key]} | ${P90[$key]} | ${RSS[$key]} | ${RATIO[$key]}x |"
  done
  echo
  echo "- vts --help: ${RATIO[help]}x gdalinfo --version (bar <= 0.5x): $HELP_MARK"
  for key in "${VTS_KEYS[@]}"; do
    echo "- ${LABEL[$key]} RSS: ${RSS[$key]} MiB (bar <= 20 MiB): ${RSS_MARK[$key]}"
  done
  echo "- shared libraries: $LIBS (\`ldd $(basename "$VTS") | wc -l\`)"
  if ((${#HEAVY[@]})); then
    echo "- heavy libraries loaded (gdal, OpenImageIO, openvdb, poppler, hdf5): ${HEAVY[*]}: $HEAVY_MARK"
  else
    echo "- heavy libraries loaded (gdal, OpenImageIO, openvdb, poppler, hdf5): none: $HEAVY_MARK"
  fi
}

jstr() { # S: S as a JSON string
  local s=${1//\\/\\\\}
  s=${s//\"/\\\"}
  printf '"%s"' "$s"
}
jnum() { if [[ $1 == - ]]; then echo null; else echo "$1"; fi; }
jbool() { if [[ $1 == PASS ]]; then echo true; else echo false; fi; }
json() {
  local key rows=() heavy=() h
  for key in "${KEYS[@]}"; do
    rows+=("$(printf '{"command":%s,"median_ms":%s,"p90_ms":%s,"max_rss_mib":%s,"ratio_vs_gdalinfo":%s}' \
      "$(jstr "${LABEL[$key]}")" "${MEDIAN[$key]}" "${P90[$key]}" "${RSS[$key]}" "$(jnum "${RATIO[$key]}")")")
  done
  for h in "${HEAVY[@]}"; do heavy+=("$(jstr "$h")"); done
  local rss_pass=()
  for key in "${VTS_KEYS[@]}"; do
    rss_pass+=("$(printf '%s:%s' "$(jstr "${LABEL[$key]}")" "$(jbool "${RSS_MARK[$key]}")")")
  done
  printf '{"vts":%s,"revision":%s,"cores":%s,"load_average":%s,"runs":%s,"commands":[%s],' \
    "$(jstr "$VTS")" "$(jstr "$(git -C "$ROOT" describe --always --dirty 2>/dev/null || echo unknown)")" \
    "$(nproc)" "$(jstr "$(cut -d' ' -f1-3 /proc/loadavg)")" "$RUNS" "$(IFS=,; echo "${rows[*]}")"
  printf '"help_ratio_vs_gdalinfo":%s,"help_ratio_bar":0.5,"help_ratio_pass":%s,' \
    "$(jnum "${RATIO[help]}")" "$(jbool "$HELP_MARK")"
  printf '"rss_bar_mib":20,"rss_pass":{%s},' "$(IFS=,; echo "${rss_pass[*]}")"
  printf '"shared_libraries":%s,"heavy_libraries":[%s],"heavy_libraries_pass":%s}\n' \
    "$LIBS" "$(IFS=,; echo "${heavy[*]}")" "$(jbool "$HEAVY_MARK")"
}

emit_report
