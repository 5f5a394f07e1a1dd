#!/usr/bin/env bash
# Pyramid build benchmark: `vts build` (lossless, default options) against
# `vips dzsave` with PNG tiles, `vips dzsave` with JPEG Q90 tiles and OpenImageIO's `maketx`, all on
# the same 16384x8192 RGB input, one after another on this machine. Measures wall time, CPU time,
# peak RSS (/usr/bin/time -v) and output bytes, and prints a markdown table with ratios against
# dzsave-PNG.
#
#   bash bench/build_bench.sh [--out FILE] [--vts PATH] [--input IMAGE]
#                             [--tools vts,dzsave-png,dzsave-jpeg,maketx] [--keep]
#
# Input: bench/.cache/earth_16384x8192.tif, made once by upscaling xplanet's 2048x1024 Earth JPEG
# 8x with a Lanczos-3 filter (oiiotool), stored as an uncompressed 8-bit RGB TIFF (scanline
# strips), so that decoding the input costs every tool next to nothing and the comparison is about
# building the pyramid. It is read once before the runs, so every tool reads it from the page cache.
#
# Peer settings (chosen to match the published peer figures, whose PNG run made 2,739 tiles):
#   vips dzsave IN DIR --tile-size 256 --overlap 0 --suffix .png        (PNG, libvips' default zlib level)
#   vips dzsave IN DIR --tile-size 256 --overlap 0 --suffix '.jpg[Q=90]'
#   maketx IN -o OUT.tx --tile 256 256                                  (tiled, mip-mapped TIFF, zip)
# dzsave's default depth (down to a 1x1 level) adds 8 tiny levels; ours stops at a single 256-px
# tile. Our tiles also carry a 4-texel border on every side (264x264 stored), which dzsave with
# --overlap 0 does not: both differences favour the peers slightly.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

OUT_FILE=""
VTS_ARG=""
INPUT=""
TOOLS="vts,dzsave-png,dzsave-jpeg,maketx"
KEEP=0
while (($#)); do
  case "$1" in
    --tools) TOOLS=$2; shift 2 ;;
    --keep) KEEP=1; shift ;;
    *) bench_option "$@"; shift "$OPT_SHIFT" ;;
  esac
done

need oiiotool vips maketx node
[[ -x $TIME_BIN ]] || die "missing $TIME_BIN (Debian package 'time')"
VTS=""
[[ ,$TOOLS, == *,vts,* ]] && VTS=$(find_vts "$VTS_ARG")
mkdir -p "$CACHE"

[[ -n $INPUT ]] || INPUT=$(earth_16k_tif)
[[ -r $INPUT ]] || die "cannot read input $INPUT"
read -r IN_W IN_H IN_C < <(oiiotool --info "$INPUT" |
  sed -nE 's/.*: *([0-9]+) x *([0-9]+), ([0-9]+) channel.*/\1 \2 \3/p')
cat "$INPUT" >/dev/null # into the page cache, for every tool alike

OUTDIR="$CACHE/build_out"
rm -rf "$OUTDIR"
mkdir -p "$OUTDIR"

ROWS=()
declare -A WALL BYTES
add_row() { # NAME SETTINGS TILES OUTPUT_PATH...
  local name=$1 settings=$2 tiles=$3
  shift 3
  if ((M_RC != 0)); then
    ROWS+=("| $name | $settings | FAILED (exit $M_RC, log bench/.cache/build_out/$name.log) | | | | | | |")
    return
  fi
  local bytes
  bytes=$(bytes_of "$@")
  WALL[$name]=$M_WALL
  BYTES[$name]=$bytes
  ROWS+=("| $name | $settings | $M_WALL | $M_CPU | $M_RSS_MB | $(mb "$bytes") | $tiles |")
}
cleanup_out() { ((KEEP)) || rm -rf "$@"; }

IFS=, read -r -a tool_list <<<"$TOOLS"
for tool in "${tool_list[@]}"; do
  echo "[bench] $tool ..." >&2
  case "$tool" in
    vts)
      out="$OUTDIR/vts.pmtiles"
      measure "$OUTDIR/vts.log" "$VTS" build "$INPUT" -o "$out"
      tiles="?"
      if ((M_RC == 0)) && "$VTS" info "$out" --json >"$OUTDIR/vts_info.json" 2>/dev/null; then
        tiles=$(node -e 'console.log(JSON.parse(require("fs").readFileSync(process.argv[1])).tiles)' \
          "$OUTDIR/vts_info.json" 2>/dev/null || echo "?")
      fi
      add_row vts "lossless RGBA8 + zstd, 256 px + 4 px border, default options" "$tiles" "$out"
      cleanup_out "$out"
      ;;
    dzsave-png)
      out="$OUTDIR/dz_png"
      measure "$OUTDIR/$tool.log" vips dzsave "$INPUT" "$out" --tile-size 256 --overlap 0 --suffix .png
      add_row "$tool" "256 px, overlap 0, PNG" "$(find "$out"_files -name '*.png' 2>/dev/null | wc -l)" \
        "$out"_files "$out.dzi"
      cleanup_out "$out"_files "$out.dzi"
      ;;
    dzsave-jpeg)
      out="$OUTDIR/dz_jpeg"
      measure "$OUTDIR/$tool.log" vips dzsave "$INPUT" "$out" --tile-size 256 --overlap 0 \
        --suffix '.jpg[Q=90]'
      add_row "$tool" "256 px, overlap 0, JPEG Q90 (lossy)" \
        "$(find "$out"_files -name '*.jpg' 2>/dev/null | wc -l)" "$out"_files "$out.dzi"
      cleanup_out "$out"_files "$out.dzi"
      ;;
    maketx)
      out="$OUTDIR/maketx.tx"
      measure "$OUTDIR/$tool.log" maketx "$INPUT" -o "$out" --tile 256 256
      add_row "$tool" "tiled 256x256 mip-mapped TIFF (zip)" "1 file" "$out"
      cleanup_out "$out"
      ;;
    *) die "unknown tool '$tool' (known: vts, dzsave-png, dzsave-jpeg, maketx)" ;;
  esac
done

# Ratios against dzsave-PNG, filled in once every run is known.
BASE_WALL=${WALL[dzsave-png]:-}
BASE_BYTES=${BYTES[dzsave-png]:-}
report() {
  echo "## Pyramid build: ${IN_W}x${IN_H} ${IN_C}-channel input, 256-px tiles"
  echo
  machine_info
  echo "- input: $(basename "$INPUT") ($(mb "$(bytes_of "$INPUT")") MiB, read from the page cache)"
  echo "- peers: $(vips --version), OpenImageIO $(oiiotool --version 2>/dev/null | head -n1)"
  echo
  echo "| tool | settings | wall s | CPU s | peak RSS MiB | output MiB | tiles | wall / dzsave-PNG | bytes / dzsave-PNG |"
  echo "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"
  local row name
  for row in "${ROWS[@]}"; do
    name=$(awk -F' [|] ' '{ print $1 }' <<<"${row#| }")
    if [[ -n ${WALL[$name]:-} && -n $BASE_WALL ]]; then
      echo "$row $(ratio "${WALL[$name]}" "$BASE_WALL") | $(ratio "${BYTES[$name]}" "$BASE_BYTES") |"
    elif [[ -n ${WALL[$name]:-} ]]; then
      echo "$row - | - |"
    else
      echo "$row"
    fi
  done
  if [[ -n ${WALL[vts]:-} && -n $BASE_WALL ]]; then
    local r
    r=$(ratio "${WALL[vts]}" "$BASE_WALL")
    echo
    if awk -v r="$r" 'BEGIN { exit !(r < 0.5) }'; then
      echo "Bar (lossless build in under half of dzsave-PNG's time): met, ratio $r."
    else
      echo "Bar (lossless build in under half of dzsave-PNG's time): NOT met, ratio $r."
    fi
  fi
}

if [[ -n $OUT_FILE ]]; then
  report | tee "$OUT_FILE"
else
  report
fi
