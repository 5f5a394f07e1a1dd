#!/usr/bin/env bash
# Georeferenced build benchmark: a mosaic of 16 GeoTIFFs in two UTM zones tiled to
# WebMercatorQuad by `vts build --tiling WebMercatorQuad` against the pipelines a GIS user would
# pick with GDAL, one after another on this machine, in one run:
#   vts        vts build IN... --tiling WebMercatorQuad --max-level Z            (default: cubic)
#   vts-R      the same with --resampling R                                      (R: the peers' -r)
#   vts-z9     the default build with --zstd-level 9 (smaller tiles for a little CPU)
#   gdalwarp   gdalwarp -t_srs EPSG:3857 -r R -dstalpha -multi -wo NUM_THREADS=ALL_CPUS
#              -co TILED=YES IN... mosaic.tif   (one GeoTIFF; shared by the two pipelines below)
#   gdal2tiles gdal2tiles.py --processes 2 --xyz -z 0-Z -r R -w none mosaic.tif DIR  (PNG tiles)
#   cog        gdal_translate -of COG -co RESAMPLING=R mosaic.tif out.tif  (LZW, overviews)
# Measures each step's wall time, CPU time, peak RSS (/usr/bin/time -v) and output bytes (the
# archive; the tile folder's files; the COG), and prints a markdown table with ratios against the
# gdal2tiles pipeline (gdalwarp + gdal2tiles), tile counts per zoom level of vts and gdal2tiles
# (the same area and zoom range), and verdicts for the bars: vts <= 0.3x the gdal2tiles pipeline's
# wall time, output no larger, peak RSS within the stated bound (docs/ARCHITECTURE.md).
#
#   bash bench/georef_bench.sh [--quick] [--out FILE] [--json FILE] [--vts PATH] [--resampling R]
#                              [--keep]
#
# Inputs, made once and cached in bench/.cache/georef_<N>/: xplanet's 2048x1024 Earth JPEG
# (georeferenced as EPSG:4326, -180..180, -90..90) warped (gdalwarp -r cubic) into 16 tiled,
# uncompressed RGB GeoTIFFs of NxN pixels: a 2x4 block in UTM zone 31N (EPSG:32631) and a 2x4 block
# in zone 32N (EPSG:32632), each block two pieces either side of its zone's central meridian,
# northings 4,400,000 .. 5,383,040 m: about 0..12.3 E, 39.7..48.6 N (south of France, the Alps,
# northern Italy, Corsica, Sardinia). N = 2048 at 120 m per pixel (default: WebMercatorQuad level
# Z = 10), or with --quick N = 512 at 480 m (Z = 8). The JPEG is
# upscaled ~160x, so the data is far smoother than real imagery: every tool's output is smaller and
# faster to encode than on real data. The inputs are read once before the runs (page cache).
#
# Peak RSS is /usr/bin/time's maximum resident set size: of the largest single process of the
# tree, so gdal2tiles' figure is one of its 3 processes (main + 2 workers), not their sum.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"

OUT_FILE=""
JSON_FILE=""
VTS_ARG=""
QUICK=0
RES=bilinear
KEEP=0
while (($#)); do
  case "$1" in
    --quick) QUICK=1; shift ;;
    --out) OUT_FILE=$2; shift 2 ;;
    --json) JSON_FILE=$2; shift 2 ;;
    --vts) VTS_ARG=$2; shift 2 ;;
    --resampling) RES=$2; shift 2 ;;
    --keep) KEEP=1; shift ;;
    -h | --help) sed -n '2,/^# shellcheck/p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
    *) die "unknown argument '$1' (see --help)" ;;
  esac
done
case "$RES" in
  near | bilinear | cubic | lanczos) ;;
  *) die "--resampling '$RES' is not near, bilinear, cubic or lanczos (the values both sides take)" ;;
esac

need gdal_translate gdalwarp gdalinfo gdal2tiles.py node
[[ -x $TIME_BIN ]] || die "missing $TIME_BIN (Debian package 'time')"
[[ -r $EARTH ]] || die "missing $EARTH (Debian package 'xplanet-images')"
VTS=$(find_vts "$VTS_ARG")

if ((QUICK)); then
  N=512 PIX=480 Z=8
else
  N=2048 PIX=120 Z=10
fi
SPAN=$((N * PIX)) # metres per piece, the same in both modes
IN_DIR="$CACHE/georef_$N"
mkdir -p "$IN_DIR"

# The 16 pieces: zone 31 and 32, two columns either side of the central meridian (easting
# 500,000), four rows from northing 4,400,000 m.
INPUTS=()
make_inputs() {
  local earth=$IN_DIR/earth_4326.vrt zone c r x0 y0 f
  [[ -s $earth ]] || gdal_translate -q -of VRT -a_srs EPSG:4326 -a_ullr -180 90 180 -90 "$EARTH" \
    "$earth"
  for zone in 31 32; do
    for r in 0 1 2 3; do
      for c in 0 1; do
        x0=$((500000 + (c - 1) * SPAN)) y0=$((4400000 + r * SPAN))
        f=$IN_DIR/utm${zone}_r${r}_c${c}.tif
        if [[ ! -s $f ]]; then
          echo "[bench] making $f (once)" >&2
          gdalwarp -q -overwrite -t_srs "EPSG:326$zone" -te "$x0" "$y0" $((x0 + SPAN)) $((y0 + SPAN)) \
            -ts "$N" "$N" -r cubic -co TILED=YES "$earth" "$f.tmp.tif" || die "gdalwarp made no $f"
          mv "$f.tmp.tif" "$f"
        fi
        INPUTS+=("$f")
      done
    done
  done
}
make_inputs
IN_BYTES=$(bytes_of "${INPUTS[@]}")
cat "${INPUTS[@]}" >/dev/null # into the page cache, for every tool alike

OUTDIR="$CACHE/georef_out"
rm -rf "$OUTDIR"
mkdir -p "$OUTDIR"
cleanup_out() { ((KEEP)) || rm -rf "$@"; }

declare -A WALL CPU RSS BYTES TILES
run_step() { # NAME LOG CMD...: measures CMD, records its figures under NAME
  local name=$1 log=$2
  shift 2
  echo "[bench] $name ..." >&2
  measure "$log" "$@"
  if ((M_RC != 0)); then
    echo "[bench] $name FAILED (exit $M_RC): $(tail -n 3 "$log")" >&2
    return 1
  fi
  WALL[$name]=$M_WALL CPU[$name]=$M_CPU RSS[$name]=$M_RSS_MB
}

# vts tiles per level (JSON of `vts info`): "z:count" words.
vts_levels() {
  node -e 'const j = JSON.parse(require("fs").readFileSync(process.argv[1]));
    console.log(j.levels.filter(l => l.tiles > 0).map(l => l.z + ":" + l.tiles).join(" "))' "$1"
}
vts_total() {
  node -e 'console.log(JSON.parse(require("fs").readFileSync(process.argv[1])).tiles)' "$1"
}
dir_levels() { # DIR of z/x/y.png: "z:count" words
  local z
  for z in $(find "$1" -mindepth 1 -maxdepth 1 -type d -printf '%f\n' | sort -n); do
    printf '%s:%s ' "$z" "$(find "$1/$z" -name '*.png' | wc -l)"
  done | sed 's/ $//'
}

FAILED=()
vts_run() { # NAME RESAMPLING-ARGS...
  local name=$1 out=$OUTDIR/$1.pmtiles
  shift
  if run_step "$name" "$OUTDIR/$name.log" "$VTS" build "${INPUTS[@]}" -o "$out" \
    --tiling WebMercatorQuad --max-level "$Z" -q "$@"; then
    BYTES[$name]=$(bytes_of "$out")
    "$VTS" info "$out" --json >"$OUTDIR/$name.info.json"
    TILES[$name]=$(vts_total "$OUTDIR/$name.info.json")
    LEVELS[$name]=$(vts_levels "$OUTDIR/$name.info.json")
    cleanup_out "$out"
  else
    FAILED+=("$name")
  fi
}
declare -A LEVELS
vts_run vts
vts_run "vts-$RES" --resampling "$RES"
vts_run vts-z9 --zstd-level 9

MOSAIC=$OUTDIR/mosaic_3857.tif
if run_step gdalwarp "$OUTDIR/gdalwarp.log" gdalwarp -q -overwrite -t_srs EPSG:3857 -r "$RES" \
  -dstalpha -multi -wo NUM_THREADS=ALL_CPUS -co TILED=YES -co BIGTIFF=IF_SAFER "${INPUTS[@]}" \
  "$MOSAIC"; then
  BYTES[gdalwarp]=$(bytes_of "$MOSAIC")
  MOSAIC_SIZE=$(gdalinfo "$MOSAIC" | sed -nE 's/^Size is ([0-9]+), ([0-9]+)/\1x\2/p')
  T2=$OUTDIR/gdal2tiles
  if run_step gdal2tiles "$OUTDIR/gdal2tiles.log" gdal2tiles.py --processes 2 --xyz -z "0-$Z" \
    -r "$RES" -w none "$MOSAIC" "$T2"; then
    # The tiles only (gdal2tiles also writes tilemapresource.xml, a few hundred bytes).
    BYTES[gdal2tiles]=$(find "$T2" -name '*.png' -printf '%s\n' | awk '{ s += $1 } END { print s + 0 }')
    TILES[gdal2tiles]=$(find "$T2" -name '*.png' | wc -l)
    LEVELS[gdal2tiles]=$(dir_levels "$T2")
    DISK_T2=$(du -sk "$T2" | awk '{ print $1 * 1024 }') # allocated blocks, for the record
    cleanup_out "$T2"
  else
    FAILED+=(gdal2tiles)
  fi
  COG=$OUTDIR/mosaic_cog.tif
  if run_step cog "$OUTDIR/cog.log" gdal_translate -q -of COG -co RESAMPLING="$RES" "$MOSAIC" "$COG"; then
    BYTES[cog]=$(bytes_of "$COG")
    OVR=$(gdalinfo "$COG" | sed -nE '0,/^  Overviews: /s/^  Overviews: //p')
    TILES[cog]="1 file, $(awk -F', ' '{ print NF }' <<<"$OVR") overviews"
    cleanup_out "$COG"
  else
    FAILED+=(cog)
  fi
  cleanup_out "$MOSAIC"
else
  FAILED+=(gdalwarp)
fi

sum() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.2f", a + b }'; }
maxi() { awk -v a="$1" -v b="$2" 'BEGIN { print (a > b ? a : b) }'; }
have() { local k; for k in "$@"; do [[ -n ${WALL[$k]:-} ]] || return 1; done; }
if have gdalwarp gdal2tiles; then
  WALL[g2t-total]=$(sum "${WALL[gdalwarp]}" "${WALL[gdal2tiles]}")
  CPU[g2t-total]=$(sum "${CPU[gdalwarp]}" "${CPU[gdal2tiles]}")
  RSS[g2t-total]=$(maxi "${RSS[gdalwarp]}" "${RSS[gdal2tiles]}")
  BYTES[g2t-total]=${BYTES[gdal2tiles]}
  TILES[g2t-total]=${TILES[gdal2tiles]}
fi
if have gdalwarp cog; then
  WALL[cog-total]=$(sum "${WALL[gdalwarp]}" "${WALL[cog]}")
  CPU[cog-total]=$(sum "${CPU[gdalwarp]}" "${CPU[cog]}")
  RSS[cog-total]=$(maxi "${RSS[gdalwarp]}" "${RSS[cog]}")
  BYTES[cog-total]=${BYTES[cog]}
  TILES[cog-total]=${TILES[cog]}
fi

# The stated memory bound of a georeferenced build (docs/ARCHITECTURE.md, "Memory bound"): for
# the widest pass window Ww (the footprint's width at level Z, at most 32768), level rings
# 8 (S + 2) Ww bytes, S = 264; threads + 2 strips of 4 x 128 Ww bytes; per reader (one per thread)
# a Float32 strip of 16 x 128 Ww bytes and GDAL's 64 MiB warp buffer; GDAL's block cache (64 MiB);
# 4 x threads tiles of 4 S^2 bytes; the fixed ~130 MiB. 15% allowance for allocator slack, as
# bench/memory_bench.sh.
THREADS=$(nproc)
WW=$(node -e "const j = JSON.parse(require('fs').readFileSync('$OUTDIR/vts.info.json')); \
  const [w, , e] = j.georeference.bounds; \
  const x = (lon) => (lon + 180) / 360 * (256 << $Z); \
  console.log(Math.min(32768, Math.ceil(x(e)) - Math.floor(x(w))))" 2>/dev/null || echo 32768)
BOUND_MB=$((((8 * 266 * WW + (THREADS + 2) * 512 * WW + THREADS * 2048 * WW + \
  4 * THREADS * 4 * 264 * 264) / 1048576 + THREADS * 64 + 64 + 130) * 115 / 100))

step_label() {
  case "$1" in
    vts) echo "vts build --tiling WebMercatorQuad --max-level $Z (cubic, the default)" ;;
    vts-z9) echo "vts build --tiling WebMercatorQuad --max-level $Z --zstd-level 9 (cubic)" ;;
    vts-*) echo "vts build --tiling WebMercatorQuad --max-level $Z --resampling $RES" ;;
    gdalwarp) echo "gdalwarp -t_srs EPSG:3857 -r $RES -dstalpha -multi (to one GeoTIFF${MOSAIC_SIZE:+, $MOSAIC_SIZE})" ;;
    gdal2tiles) echo "gdal2tiles.py --processes 2 --xyz -z 0-$Z -r $RES (PNG)" ;;
    g2t-total) echo "**gdalwarp + gdal2tiles**" ;;
    cog) echo "gdal_translate -of COG -co RESAMPLING=$RES (LZW, overviews${OVR:+: $OVR})" ;;
    cog-total) echo "**gdalwarp + COG**" ;;
  esac
}
STEPS=(vts "vts-$RES" vts-z9 gdalwarp gdal2tiles g2t-total cog cog-total)
BASE_WALL=${WALL[g2t-total]:-}
BASE_BYTES=${BYTES[g2t-total]:-}

report() {
  echo "## Georeferenced build: 16 GeoTIFFs in two UTM zones to WebMercatorQuad z0-$Z"
  echo
  machine_info
  echo "- input: 16 tiled uncompressed RGB GeoTIFFs of ${N}x${N} px at $PIX m, 8 in EPSG:32631 and 8 in EPSG:32632 ($(mb "$IN_BYTES") MiB, page cache), ~0..12.3 E, 39.7..48.6 N; command: \`bash bench/georef_bench.sh$( ((QUICK)) && echo ' --quick')\`"
  echo "- peers: $(gdalinfo --version | cut -d, -f1), gdal2tiles.py, $(nproc) cores (vts --threads 0 = all)"
  echo
  echo "| step | wall s | CPU s | peak RSS MiB | output MiB | tiles | wall / gdal2tiles pipeline | bytes / gdal2tiles pipeline |"
  echo "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"
  local s w b
  for s in "${STEPS[@]}"; do
    if [[ -z ${WALL[$s]:-} ]]; then
      echo "| $(step_label "$s") | FAILED or not run | | | | | | |"
      continue
    fi
    w=- b=-
    if [[ -n $BASE_WALL && $s != gdalwarp && $s != gdal2tiles && $s != cog ]]; then
      w=$(ratio "${WALL[$s]}" "$BASE_WALL")
      b=$(ratio "${BYTES[$s]}" "$BASE_BYTES")
    fi
    echo "| $(step_label "$s") | ${WALL[$s]} | ${CPU[$s]} | ${RSS[$s]} | $(mb "${BYTES[$s]:-0}") | ${TILES[$s]:--} | $w | $b |"
  done
  echo
  echo "The gdalwarp step runs once and counts in both pipelines' totals; a total's peak RSS is the larger of its steps'."
  echo "Tiles per zoom level (same area, same zoom range):"
  echo
  local k
  for k in vts "vts-$RES" vts-z9 gdal2tiles; do
    [[ -n ${LEVELS[$k]:-} ]] && echo "- $k: ${LEVELS[$k]} (total ${TILES[$k]})"
  done
  [[ -n ${DISK_T2:-} ]] && echo "- gdal2tiles' folder takes $(mb "$DISK_T2") MiB on disk (4 KiB blocks); the table counts the PNG files' bytes"
  echo
  if [[ -n $BASE_WALL ]]; then
    for k in vts "vts-$RES" vts-z9; do
      [[ -n ${WALL[$k]:-} ]] || continue
      local r rb verdict
      r=$(ratio "${WALL[$k]}" "$BASE_WALL")
      rb=$(ratio "${BYTES[$k]}" "$BASE_BYTES")
      verdict="NOT met"
      awk -v r="$r" 'BEGIN { exit !(r <= 0.3) }' && verdict=met
      echo "- $k: wall $r x the gdal2tiles pipeline (bar <= 0.3x: $verdict); output $rb x ($(awk -v r="$rb" 'BEGIN { print (r <= 1 ? "no larger: met" : "larger: NOT met") }')); peak RSS ${RSS[$k]} MiB vs the stated bound $BOUND_MB MiB ($( ((RSS[$k] <= BOUND_MB)) && echo within || echo OVER))"
    done
  fi
  ((${#FAILED[@]} == 0)) || echo "- failed: ${FAILED[*]} (logs in bench/.cache/georef_out/)"
  return 0
}

json() {
  local s first=1
  printf '{"quick":%s,"max_level":%s,"resampling":"%s","input_bytes":%s,"rss_bound_mib":%s,"steps":{' \
    "$( ((QUICK)) && echo true || echo false)" "$Z" "$RES" "$IN_BYTES" "$BOUND_MB"
  for s in "${STEPS[@]}"; do
    [[ -n ${WALL[$s]:-} ]] || continue
    ((first)) || printf ','
    first=0
    printf '"%s":{"wall_s":%s,"cpu_s":%s,"peak_rss_mib":%s,"bytes":%s}' "$s" "${WALL[$s]}" \
      "${CPU[$s]}" "${RSS[$s]}" "${BYTES[$s]:-0}"
  done
  printf '}}\n'
}

if [[ -n $OUT_FILE ]]; then
  report | tee "$OUT_FILE"
else
  report
fi
[[ -z $JSON_FILE ]] || json >"$JSON_FILE"
((${#FAILED[@]} == 0))
