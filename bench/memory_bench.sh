#!/usr/bin/env bash
# Memory-bound check (DESIGN.md §6: "memory bounded independent of image size"): peak RSS of
# `vts build` as the image grows, from 5*10^7 to 5*10^9 texels. Slow (the largest synthetic build
# encodes ~102k tiles); not part of ctest.
#
#   bash bench/memory_bench.sh [--out FILE] [--vts PATH] [--no-real] [--threads N]
#
# Runs, each writing to a temporary directory that is removed afterwards:
#   synthetic  10000x5000, 30000x15000, 100000x50000   (`vts build --synthetic WxH`)
#   real       16384x8192 and 32768x16384 uncompressed RGB TIFFs made (once, cached in
#              bench/.cache/) by upscaling the Earth JPEG with oiiotool: the same path through the
#              image decoder (OpenImageIO) that real inputs take. Skipped with --no-real.
# Prints a markdown table and a verdict: the bound holds when the largest run's peak RSS is within
# 1.5x of the smallest's, in each group.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

OUT_FILE=""
VTS_ARG=""
REAL=1
THREADS=()
while (($#)); do
  case "$1" in
    --out) OUT_FILE=$2; shift 2 ;;
    --vts) VTS_ARG=$2; shift 2 ;;
    --no-real) REAL=0; shift ;;
    --threads) THREADS=(--threads "$2"); shift 2 ;;
    -h | --help) sed -n '2,/^# shellcheck/p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
    *) die "unknown argument '$1' (see --help)" ;;
  esac
done

VTS=$(find_vts "$VTS_ARG")
[[ -x $TIME_BIN ]] || die "missing $TIME_BIN (Debian package 'time')"
mkdir -p "$CACHE"
TMP=$(mktemp -d "${TMPDIR:-/tmp}/vts-membench.XXXXXX")
trap 'rm -rf "$TMP"' EXIT

ROWS=()
declare -A RSS
run_case() { # GROUP LABEL TEXELS VTS-BUILD-ARGS...
  local group=$1 label=$2 texels=$3
  shift 3
  echo "[bench] $group $label ..." >&2
  measure "$TMP/log" "$VTS" build "$@" -o "$TMP/x.pmtiles" "${THREADS[@]}"
  if ((M_RC != 0)); then
    cp "$TMP/log" "$CACHE/memory_bench_${group}_${label}.log" 2>/dev/null || true
    ROWS+=("| $group | $label | $texels | FAILED (exit $M_RC) | | | |")
    rm -f "$TMP/x.pmtiles"
    return
  fi
  local bytes
  bytes=$(bytes_of "$TMP/x.pmtiles")
  rm -f "$TMP/x.pmtiles"
  RSS[$group:$label]=$M_RSS_MB
  ROWS+=("| $group | $label | $texels | $M_WALL | $M_CPU | $M_RSS_MB | $(mb "$bytes") |")
}

run_case synthetic 10000x5000 5.0e7 --synthetic 10000x5000
run_case synthetic 30000x15000 4.5e8 --synthetic 30000x15000
run_case synthetic 100000x50000 5.0e9 --synthetic 100000x50000

if ((REAL)); then
  need oiiotool
  for size in 16384x8192 32768x16384; do
    f="$CACHE/earth_$size.tif"
    if [[ ! -s $f ]]; then
      echo "[bench] making $f (once)" >&2
      oiiotool "$EARTH" --resize:filter=lanczos3 "$size" -d uint8 --compression none -o "$f.tmp.tif"
      mv "$f.tmp.tif" "$f"
    fi
  done
  run_case real 16384x8192 1.3e8 "$CACHE/earth_16384x8192.tif"
  run_case real 32768x16384 5.4e8 "$CACHE/earth_32768x16384.tif"
fi

verdict() { # GROUP SMALL LARGE
  local a=${RSS[$1:$2]:-} b=${RSS[$1:$3]:-} r
  [[ -n $a && -n $b ]] || { echo "- $1: not measured (a run failed)"; return; }
  r=$(ratio "$b" "$a")
  if awk -v r="$r" 'BEGIN { exit !(r <= 1.5) }'; then
    echo "- $1: peak RSS $a MiB at $2, $b MiB at $3: ratio $r, bounded."
  else
    echo "- $1: peak RSS $a MiB at $2, $b MiB at $3: ratio $r, GROWS with image size."
  fi
}

report() {
  echo "## vts build peak memory vs image size"
  echo
  machine_info
  echo "- vts build options: defaults${THREADS[*]:+, ${THREADS[*]}}"
  echo
  echo "| input | size | texels | wall s | CPU s | peak RSS MiB | output MiB |"
  echo "| --- | --- | ---: | ---: | ---: | ---: | ---: |"
  printf '%s\n' "${ROWS[@]}"
  echo
  verdict synthetic 10000x5000 100000x50000
  ((REAL)) && verdict real 16384x8192 32768x16384
  return 0
}

if [[ -n $OUT_FILE ]]; then
  report | tee "$OUT_FILE"
else
  report
fi
