#!/usr/bin/env bash
# Memory-bound check ("memory bounded independent of image size"): peak RSS of
# `vts build` as the image grows, from 5*10^7 to 5*10^9 texels. Slow (the largest synthetic build
# encodes ~102k tiles); not part of ctest.
#
#   bash bench/memory_bench.sh [--out FILE] [--vts PATH] [--no-real] [--threads N]
#
# Runs, each writing to a temporary directory that is removed afterwards:
#   synthetic  10000x5000, 30000x15000, 100000x50000   (`vts build --synthetic WxH`)
#   real       16384x8192 uncompressed RGB TIFF (oiiotool, Lanczos-3) and 100000x50000 tiled
#              JPEG-compressed BigTIFF (vips, bilinear), both the Earth JPEG upscaled and cached in
#              bench/.cache/: the same path through OpenImageIO that real inputs take. Skipped
#              with --no-real.
# Prints a markdown table and verdicts: synthetic peak RSS must stay flat (largest within 1.5x of
# the smallest); real inputs must stay within the stated width-proportional bound and under 1 GiB.
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
  need oiiotool vips
  f=$(earth_16k_tif)
  # The issue's size: 100000x50000 RGB, a tiled JPEG-compressed BigTIFF (lib.sh: earth_100k_tif).
  big=$(earth_100k_tif)
  run_case real 16384x8192 1.3e8 "$f"
  run_case real 100000x50000 5.0e9 "$big"
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
  if ((REAL)); then
    # Real inputs: the stated bound grows with the width only (docs/ARCHITECTURE.md): level rings
    # 8*(T+2B+2)*W bytes, plus one band of input tiles (256 rows * W * 3), plus a fixed ~130 MiB
    # (the synthetic runs above: code, of which ~85 MiB is shared libraries, and fixed buffers);
    # 15% allowance for allocator slack. The bar: 100000x50000 well under 1 GiB.
    local b=${RSS[real:100000x50000]:-}
    if [[ -n $b ]]; then
      local bound=$((((8 * 266 * 100000 + 256 * 100000 * 3) / 1048576 + 130) * 115 / 100))
      if ((b < bound && b < 1024)); then
        echo "- real: 100000x50000 peaked at $b MiB: within the stated bound ($bound MiB) and under 1 GiB."
      else
        echo "- real: 100000x50000 peaked at $b MiB: OVER the stated bound ($bound MiB) or 1 GiB."
      fi
    else
      echo "- real: 100000x50000 not measured (a run failed)"
    fi
  fi
  return 0
}

if [[ -n $OUT_FILE ]]; then
  report | tee "$OUT_FILE"
else
  report
fi
