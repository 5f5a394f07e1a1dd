#!/usr/bin/env bash
# GeoTIFF export benchmark (issue 33): `vts export --format gtiff` (a Cloud Optimized GeoTIFF of
# the finest level, its overviews copied from our own coarser levels) against GDAL's own COG driver
# writing the same texels (`gdal_translate -of COG`, which computes the overviews by resampling),
# one after another on this machine. Wall time best of N runs (default 3), CPU time and peak RSS of
# that run, output bytes, overview count, and the ratio vts / GDAL as a markdown table.
#
#   bash bench/gtiff_bench.sh [--out FILE] [--vts PATH] [--runs N] [--threads N]
#
# Input: bench/.cache/earth_16384x8192.tif (bench/build_bench.sh's upscaled Earth) placed on the
# whole world (EPSG:4326, -180 90 180 -90) and built once as a WorldCRS84Quad archive (level 6 is
# 16384 x 8192); for GDAL, that level as `vts extract --level 6` writes it (an uncompressed
# georeferenced RGBA TIFF: the same texels). Neither preparation is timed; both inputs are read
# once before the runs (page cache).
#   vts export ARCHIVE --format gtiff -o OUT.tif
#   gdal_translate -of COG -co COMPRESS=DEFLATE -co PREDICTOR=2 -co BLOCKSIZE=512
#     -co OVERVIEW_RESAMPLING=AVERAGE -co NUM_THREADS=N LEVEL6.tif OUT.tif
# Both write DEFLATE with the horizontal predictor in 512-texel blocks, RGBA.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

OUT_FILE="" VTS_ARG="" RUNS=3 THREADS=0
while (($#)); do
  case "$1" in
    --runs) RUNS=$2; shift 2 ;;
    --threads) THREADS=$2; shift 2 ;;
    *) bench_option "$@"; shift "$OPT_SHIFT" ;;
  esac
done
[[ $RUNS =~ ^[1-9][0-9]*$ ]] || die "--runs must be a positive integer, not '$RUNS'"
need oiiotool gdal_translate gdalinfo node
[[ -x $TIME_BIN ]] || die "missing $TIME_BIN (Debian package 'time')"
VTS=$(find_vts "$VTS_ARG")
mkdir -p "$CACHE"
INPUT=$(earth_16k_tif)
GEO="$CACHE/earth_16384x8192_crs84.tif"
if [[ ! -s $GEO || $INPUT -nt $GEO ]]; then
  gdal_translate -q -a_srs EPSG:4326 -a_ullr -180 90 180 -90 "$INPUT" "$GEO.tmp.tif" ||
    die "gdal_translate could not georeference $INPUT"
  mv "$GEO.tmp.tif" "$GEO"
fi
ARCHIVE="$CACHE/earth_16384x8192_crs84.pmtiles"
build_once "$GEO" "$ARCHIVE" -q
LEVEL="$CACHE/earth_16384x8192_crs84_level6.tif"
if [[ ! -s $LEVEL || $ARCHIVE -nt $LEVEL ]]; then
  "$VTS" extract "$ARCHIVE" --level 6 -o "$LEVEL" >/dev/null || die "vts extract failed"
fi
cat "$ARCHIVE" "$LEVEL" >/dev/null # into the page cache
GDAL_THREADS=$THREADS
((GDAL_THREADS > 0)) || GDAL_THREADS=ALL_CPUS

OUTDIR="$CACHE/gtiff_out"
rm -rf "$OUTDIR"
mkdir -p "$OUTDIR"
before_run() { rm -f "$OUTDIR/$1.tif"; }

best_of gdal gdal_translate -q -of COG -co COMPRESS=DEFLATE -co PREDICTOR=2 -co BLOCKSIZE=512 \
  -co OVERVIEW_RESAMPLING=AVERAGE -co NUM_THREADS="$GDAL_THREADS" "$LEVEL" "$OUTDIR/gdal.tif"
best_of vts "$VTS" export "$ARCHIVE" --format gtiff -o "$OUTDIR/vts.tif" --threads "$THREADS" -q

# overviews FILE: how many overviews GDAL sees, and the layout it reports.
overviews() {
  gdalinfo -json "$1" | node -e '
    const j = JSON.parse(require("fs").readFileSync(0, "utf8"));
    const ovr = (j.bands[0].overviews || []).length;
    const layout = ((j.metadata || {})["IMAGE_STRUCTURE"] || {}).LAYOUT || "?";
    console.log(ovr + " " + layout);'
}
read -r VTS_OVR VTS_LAYOUT < <(overviews "$OUTDIR/vts.tif")
read -r GDAL_OVR GDAL_LAYOUT < <(overviews "$OUTDIR/gdal.tif")

report() {
  echo "## GeoTIFF export: level 6 of the Earth (16384 x 8192, WorldCRS84Quad) as a COG"
  echo
  machine_info
  echo "- peer: $(gdalinfo --version); best of $RUNS runs each"
  echo "- vts: \`vts export earth_crs84.pmtiles --format gtiff -o OUT.tif\` (overviews: our levels 5..0)"
  echo "- GDAL: \`gdal_translate -of COG -co COMPRESS=DEFLATE -co PREDICTOR=2 -co BLOCKSIZE=512 -co OVERVIEW_RESAMPLING=AVERAGE -co NUM_THREADS=$GDAL_THREADS level6.tif OUT.tif\`"
  echo
  echo "| tool | wall s (best) | CPU s | peak RSS MiB | output MiB | overviews | layout | wall / GDAL |"
  echo "| --- | ---: | ---: | ---: | ---: | ---: | --- | ---: |"
  echo "| vts export --format gtiff | ${BEST[vts]} | ${CPU[vts]} | ${RSS[vts]} | $(mb "$(bytes_of "$OUTDIR/vts.tif")") | $VTS_OVR | $VTS_LAYOUT | $(ratio "${BEST[vts]}" "${BEST[gdal]}") |"
  echo "| gdal_translate -of COG | ${BEST[gdal]} | ${CPU[gdal]} | ${RSS[gdal]} | $(mb "$(bytes_of "$OUTDIR/gdal.tif")") | $GDAL_OVR | $GDAL_LAYOUT | 1.00 |"
}
if [[ -n $OUT_FILE ]]; then report | tee "$OUT_FILE"; else report; fi
rm -rf "$OUTDIR"
