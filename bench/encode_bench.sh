#!/usr/bin/env bash
# Cold web-tile encoding per core: what `vts serve` pays for each /{z}/{x}/{y}.png|.webp it has not
# cached, and what `vts export` pays per tile, against `vips pngsave` / `vips webpsave` (libvips)
# on the same 256x256 tile contents in the same run. Prints a markdown table: per setting, bytes
# per tile, quality (PNG: exact round trip; WebP: PSNR of RGB against the source), CPU time per
# tile (= per core) and tiles/s per core, and the ratios to vips and to the baseline.
#
#   bash bench/encode_bench.sh [--vts PATH] [--driver PATH] [--baseline DRIVER] [--tiles N]
#                              [--passes N] [--out FILE] [SETTING...]
#
# Tiles: --tiles (default 256) existing tiles of bench/.cache/earth_16384x8192.pmtiles (the 16384 x
# 8192 Earth, built once by --vts), every k-th in tile-id order so every level is in, those whose
# content is opaque (all but the root here), cropped as the server crops them.
# vts: bench/vts_encode_bench (--driver; default next to --vts: BUILD/bench/vts_encode_bench)
# encodes each tile with each SETTING (default: the table of docs/ACCURACY.md, "Web tile
# encoding") through imaging::encode_web_image on one thread; time = that thread's CPU time, best
# of --passes (default 3) passes. --baseline DRIVER: the same driver built from an older tree
# (e.g. libpng's writer), run on the same tiles with png:level=6 and webp:method=4 (the old
# defaults): its rows are the "today" the ratios refer to.
# vips: the same tiles as raw RGB strips of 32 tiles stacked vertically (256 x 8192 texels:
# the same 256-texel rows as a tile, one process per strip so start-up is amortised), each
# loaded once into a .v file, then `vips pngsave --compression 6` (libpng, zlib 6, vips's default
# filter) and `vips webpsave --Q 90 --effort 4` (libwebp method 4, as before) of every strip,
# VIPS_CONCURRENCY=1; time = the loop's user + system CPU time minus that of `vips copy` of the
# same strips (start-up, load and write), best of --passes. Bytes: the strips' files / tiles.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

VTS_ARG="" OUT_FILE="" DRIVER="" BASELINE="" TILES=256 PASSES=3
SETTINGS=()
while (($#)); do
  case $1 in
    --driver) DRIVER=$2; shift 2 ;;
    --baseline) BASELINE=$2; shift 2 ;;
    --tiles) TILES=$2; shift 2 ;;
    --passes) PASSES=$2; shift 2 ;;
    png* | webp*) SETTINGS+=("$1"); shift ;;
    *) bench_option "$@"; shift "$OPT_SHIFT" ;;
  esac
done
need vips jq oiiotool
[[ -x $TIME_BIN ]] || die "missing $TIME_BIN (Debian package 'time')"
VTS=$(find_vts "$VTS_ARG")
[[ -n $DRIVER ]] || DRIVER=$(dirname "$VTS")/../bench/vts_encode_bench
[[ -x $DRIVER ]] || die "no driver at $DRIVER (build the target vts_encode_bench)"
if ((${#SETTINGS[@]} == 0)); then
  # PNG: filters at the default level, then levels with the default filter (3 = average); WebP:
  # methods at quality 90.
  SETTINGS=('png:level=4,filter=0' 'png:level=4,filter=1' 'png:level=4,filter=2' 'png:level=4,filter=4'
    'png:level=4,filter=5' 'png:level=0,filter=3' 'png:level=1,filter=3' 'png:level=2,filter=3'
    'png:level=3,filter=3' 'png:level=4,filter=3' 'png:level=5,filter=3' 'png:level=6,filter=3'
    'png:level=9,filter=3' webp:method=0 webp:method=1 webp:method=2 webp:method=3 webp:method=4
    webp:method=6)
fi

INPUT=$(earth_16k_tif)
ARCHIVE=$CACHE/earth_16384x8192.pmtiles
build_once "$INPUT" "$ARCHIVE" -q

T=$(mktemp -d "${TMPDIR:-/tmp}/vts-encode-bench.XXXXXX")
trap 'rm -rf "$T"' EXIT

echo "[bench] vts: ${#SETTINGS[@]} settings on $TILES tiles" >&2
"$DRIVER" "$ARCHIVE" --tiles "$TILES" --passes "$PASSES" --raw-dir "$T/raw" "${SETTINGS[@]}" \
  >"$T/vts.jsonl" || die "$DRIVER failed"
NT=$(jq -s '.[0].tiles' "$T/vts.jsonl")
if [[ -n $BASELINE ]]; then
  echo "[bench] baseline: $BASELINE" >&2
  "$BASELINE" "$ARCHIVE" --tiles "$TILES" --passes "$PASSES" png:level=6 webp:method=4 \
    >"$T/base.jsonl" || die "$BASELINE failed"
fi

# The peer: every strip loaded once, then timed loops of one vips process per strip.
mapfile -t STRIPS < <(awk '{ print $1 }' "$T/raw/strips.txt")
while read -r file w h; do
  vips rawload "$T/raw/$file" "$T/raw/${file%.raw}.v" "$w" "$h" 3 || die "vips rawload failed"
done <"$T/raw/strips.txt"
export VIPS_CONCURRENCY=1
declare -A VCPU
vips_best() { # KEY OP SUFFIX [ARGS...]: VCPU[KEY] = the best CPU seconds of `vips OP` of every strip
  local key=$1 op=$2 suffix=$3 s i args
  shift 3
  args=""
  (($#)) && args=$(printf ' %q' "$@")
  for s in "${STRIPS[@]}"; do
    printf 'vips %s %q %q%s\n' "$op" "$T/raw/${s%.raw}.v" "$T/out_${s%.raw}.$suffix" "$args"
  done >"$T/loop_$key.sh"
  for ((i = 0; i < PASSES; i++)); do
    measure "$T/$key.log" bash -e "$T/loop_$key.sh"
    ((M_RC == 0)) || die "vips $key failed: $(tail -n 3 "$T/$key.log")"
    if [[ -z ${VCPU[$key]:-} ]] || awk -v a="$M_CPU2" -v b="${VCPU[$key]}" 'BEGIN { exit !(a < b) }'; then
      VCPU[$key]=$M_CPU2
    fi
  done
}
echo "[bench] vips: ${#STRIPS[@]} strips" >&2
vips_best copy copy v
vips_best png pngsave png --compression 6
PNG_BYTES=$(bytes_of "$T"/out_*.png)
vips_best webp webpsave webp --Q 90 --effort 4
WEBP_BYTES=$(bytes_of "$T"/out_*.webp)
vips_ms() { awk -v c="${VCPU[$1]}" -v z="${VCPU[copy]}" -v n="$NT" 'BEGIN { printf "%.3f", (c - z) * 1000 / n }'; }
VIPS_PNG_MS=$(vips_ms png)
VIPS_WEBP_MS=$(vips_ms webp)

# row NAME BYTES QUALITY MS BASE_MS BASE_BYTES VIPS_MS: one table row.
row() {
  awk -v name="$1" -v b="$2" -v q="$3" -v ms="$4" -v bms="$5" -v bb="$6" -v vms="$7" 'BEGIN {
    rate = ms > 0 ? 1000 / ms : 0
    vs_vips = ms > 0 ? sprintf("%.2fx", vms / ms) : "-"
    vs_base = bms > 0 && ms > 0 ? sprintf("%.2fx", bms / ms) : "-"
    bytes_base = bb > 0 ? sprintf("%.2fx", b / bb) : "-"
    printf "| %s | %d | %s | %.2f | %.0f | %s | %s | %s |\n", name, b, q, ms, rate, vs_vips, vs_base, bytes_base
  }'
}
field() { jq -r --arg s "$2" "select(.setting == \$s) | .$3" "$1"; }
report() {
  echo "## Cold web-tile encoding per core: $NT tiles of ${ARCHIVE##*/}"
  echo
  machine_info
  echo "- peer: $(vips --version), VIPS_CONCURRENCY=1, strips of 32 tiles (see the script)"
  echo "- vts: $DRIVER, one thread, best of $PASSES passes; baseline: ${BASELINE:-none}"
  echo
  echo "| setting | bytes/tile | quality | ms/tile/core | tiles/s/core | speed vs vips | speed vs today | bytes vs today |"
  echo "|---|---:|---|---:|---:|---:|---:|---:|"
  local fmt s b q ms bms="" bb="" vms
  for fmt in png webp; do
    if [[ -n $BASELINE ]]; then
      local base_setting=png:level=6
      [[ $fmt == webp ]] && base_setting=webp:method=4
      bms=$(field "$T/base.jsonl" "$base_setting" ms_per_tile)
      bb=$(field "$T/base.jsonl" "$base_setting" bytes_per_tile)
      q=$(field "$T/base.jsonl" "$base_setting" psnr_db)
      [[ $fmt == png ]] && q=exact
      row "today: $base_setting (baseline driver)" "$bb" "$q" "$bms" "$bms" "$bb" "$([[ $fmt == png ]] && echo "$VIPS_PNG_MS" || echo "$VIPS_WEBP_MS")"
    fi
    vms=$VIPS_PNG_MS
    [[ $fmt == webp ]] && vms=$VIPS_WEBP_MS
    for s in "${SETTINGS[@]}"; do
      [[ $s == "$fmt"* ]] || continue
      b=$(field "$T/vts.jsonl" "$s" bytes_per_tile)
      ms=$(field "$T/vts.jsonl" "$s" ms_per_tile)
      if [[ $fmt == png ]]; then
        q=$([[ $(field "$T/vts.jsonl" "$s" exact) == true ]] && echo exact || echo NOT-EXACT)
      else
        q="$(field "$T/vts.jsonl" "$s" psnr_db) dB"
      fi
      row "vts $s" "$b" "$q" "$ms" "$bms" "$bb" "$vms"
    done
    if [[ $fmt == png ]]; then
      row "vips pngsave --compression 6" $((PNG_BYTES / NT)) exact "$VIPS_PNG_MS" "$bms" "$bb" "$VIPS_PNG_MS"
    else
      row "vips webpsave --Q 90 --effort 4" $((WEBP_BYTES / NT)) "-" "$VIPS_WEBP_MS" "$bms" "$bb" "$VIPS_WEBP_MS"
    fi
  done
}
if [[ -n $OUT_FILE ]]; then report | tee "$OUT_FILE"; else report; fi
