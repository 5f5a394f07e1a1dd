#!/usr/bin/env bash
# Web export benchmark: `vts export ARCHIVE --format webp` (our archive of the 16384x8192 Earth to a
# raster PMTiles of WebP tiles) against `vips dzsave` writing WebP tiles of the same image (same
# quality, tile size 256, overlap 0, google layout), one after another on this machine. Wall time
# best of N runs (default 3), CPU time and peak RSS of that run, output bytes and tile counts, and
# the ratio vts / vips as a markdown table.
#
#   bash bench/export_bench.sh [--out FILE] [--vts PATH] [--quality Q] [--runs N] [--threads N]
#
# Input: bench/.cache/earth_16384x8192.tif (made as bench/build_bench.sh makes it: xplanet's Earth
# upscaled 8x, Lanczos-3, uncompressed 8-bit RGB TIFF) for vips, and its lossless archive
# bench/.cache/earth_16384x8192.pmtiles (vts build, default options) for vts export; both read
# once before the runs, so each tool reads its input from the page cache. The archive's build is
# not timed: the journey is "serve the archive you have to stock web maps".
#   vts export ARCHIVE -o OUT.pmtiles --format webp --quality Q
#   vips dzsave IN DIR --layout google --tile-size 256 --overlap 0 --suffix '.webp[Q=Q]'
# Both use libwebp's default effort (method 4) and lossy WebP. dzsave in google layout stops at the
# level where the image fits one tile and skips blank tiles, as vts export does.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

OUT_FILE="" VTS_ARG="" QUALITY=90 RUNS=3 THREADS=0
while (($#)); do
  case "$1" in
    --quality) QUALITY=$2; shift 2 ;;
    --runs) RUNS=$2; shift 2 ;;
    --threads) THREADS=$2; shift 2 ;;
    *) bench_option "$@"; shift "$OPT_SHIFT" ;;
  esac
done
need oiiotool vips node
[[ -x $TIME_BIN ]] || die "missing $TIME_BIN (Debian package 'time')"
VTS=$(find_vts "$VTS_ARG")
mkdir -p "$CACHE"
INPUT=$(earth_16k_tif)
ARCHIVE="$CACHE/earth_16384x8192.pmtiles"
build_once "$INPUT" "$ARCHIVE" -q
cat "$INPUT" "$ARCHIVE" >/dev/null # into the page cache

OUTDIR="$CACHE/export_out"
rm -rf "$OUTDIR"
mkdir -p "$OUTDIR"
before_run() { rm -rf "$OUTDIR/vts.pmtiles" "$OUTDIR/dz" "$OUTDIR/dz.dzi" "$OUTDIR"/dz_files; }

best_of vips vips dzsave "$INPUT" "$OUTDIR/dz" --layout google --tile-size 256 --overlap 0 \
  --suffix ".webp[Q=$QUALITY]"
DZ_TILES=$(find "$OUTDIR/dz" -name '*.webp' | wc -l)
DZ_BYTES=$(bytes_of "$OUTDIR/dz")
best_of vts "$VTS" export "$ARCHIVE" -o "$OUTDIR/vts.pmtiles" --format webp --quality "$QUALITY" \
  --threads "$THREADS" --json
VTS_TILES=$(node -e 'console.log(JSON.parse(require("fs").readFileSync(process.argv[1])).tiles)' \
  "$OUTDIR/vts.log" 2>/dev/null || echo "?")
VTS_BYTES=$(bytes_of "$OUTDIR/vts.pmtiles")

report() {
  echo "## Web export: ${INPUT##*/} to WebP Q$QUALITY, 256-px tiles"
  echo
  machine_info
  echo "- peer: $(vips --version); best of $RUNS runs each"
  echo "- vts: \`vts export earth_16384x8192.pmtiles -o OUT.pmtiles --format webp --quality $QUALITY\`"
  echo "- vips: \`vips dzsave earth_16384x8192.tif DIR --layout google --tile-size 256 --overlap 0 --suffix '.webp[Q=$QUALITY]'\`"
  echo
  echo "| tool | wall s (best) | CPU s | peak RSS MiB | output MiB | tiles | wall / vips |"
  echo "| --- | ---: | ---: | ---: | ---: | ---: | ---: |"
  echo "| vts export | ${BEST[vts]} | ${CPU[vts]} | ${RSS[vts]} | $(mb "$VTS_BYTES") | $VTS_TILES | $(ratio "${BEST[vts]}" "${BEST[vips]}") |"
  echo "| vips dzsave | ${BEST[vips]} | ${CPU[vips]} | ${RSS[vips]} | $(mb "$DZ_BYTES") | $DZ_TILES | 1.00 |"
}
if [[ -n $OUT_FILE ]]; then report | tee "$OUT_FILE"; else report; fi
rm -rf "$OUTDIR"
