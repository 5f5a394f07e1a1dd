#!/usr/bin/env bash
# Installs everything vtstream needs to build, test and benchmark on Debian 12 (bookworm):
# Debian packages with apt, then the npm packages the integration tests use (from the committed
# package-lock.json). Safe to run again: each step is skipped when already done.
#
#   bash scripts/setup.sh            # as root, or as a user with sudo
#   VTS_SETUP_FORCE=1 bash scripts/setup.sh   # run apt-get and npm ci even if all looks installed
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
FORCE=${VTS_SETUP_FORCE:-0}

log() { printf '[setup] %s\n' "$*"; }

SUDO=()
if [[ $(id -u) -ne 0 ]]; then
  if command -v sudo >/dev/null 2>&1; then
    SUDO=(sudo)
  else
    echo "setup.sh: installing packages needs root; run as root or install sudo" >&2
    exit 1
  fi
fi

PACKAGES=(
  # toolchain and build
  build-essential cmake ninja-build pkg-config git clang libclang-rt-14-dev clang-format ccache
  # libraries
  libopenimageio-dev libzstd-dev libxxhash-dev zlib1g-dev nlohmann-json3-dev libcli11-dev
  libspdlog-dev libfmt-dev libboost1.81-dev libssl-dev libcurl4-openssl-dev libsqlite3-dev
  # store/: S3's XML answers (ListObjectsV2, errors) read with Expat
  libexpat1-dev
  # the bc1 tile codec's encoders: libsquish, and stb_dxt from libstb-dev (below)
  libsquish-dev
  # standard web images of tiles (PNG, WebP, JPEG) for web maps and `vts export`; libdeflate is
  # the PNG writer's deflate (several times zlib's speed at the same bytes)
  libpng-dev libwebp-dev libturbojpeg0-dev libdeflate-dev
  # GeoTIFF and other georeferenced inputs of vts build (builder/src/gdal_source.cpp); gdal-bin's
  # gdal_translate/gdalwarp make the test inputs and references; python3-gdal is gdal2tiles.py's
  # (bench/georef_bench.sh's peer; gdal-bin depends on it on bookworm, named here all the same)
  libgdal-dev gdal-bin python3-gdal
  # tests/integration/georef_placement.py measures sub-texel shifts with numpy (Debian's, for
  # /usr/bin/python3)
  python3-numpy
  # the OpenGL viewer (renderer/): GLFW 3.3, libepoxy (GL loader), GLM; its tests render under
  # Xvfb with Mesa's llvmpipe (GL 4.5 core, no GPU needed)
  libglfw3-dev libepoxy-dev libglm-dev xvfb xauth libgl1-mesa-dri
  # the viewer's headless path with no display (EGL: a GPU's device platform, or Mesa's
  # surfaceless platform in the tests)
  libegl-dev libegl-mesa0
  # the viewer's HUD text (stb_easy_font) and real input events in its
  # interactive test (xdotool)
  libstb-dev xdotool
  # tests and benchmarks
  libgtest-dev libgmock-dev libbenchmark-dev
  # real peers, sample data and measuring tools for tests and benchmarks
  openimageio-tools libvips-tools xplanet-images curl ca-certificates time python3 nginx wrk
  sqlite3
  # the load-test report is checked by rendering it in a real headless browser
  chromium
  # deploy/ tests: nginx templates filled by envsubst, a TLS front with a throwaway certificate,
  # compose and Kubernetes YAML checked with python3
  gettext-base openssl python3-yaml
  # store/'s SigV4 signatures recomputed independently by AWS's botocore (store_s3.sh)
  python3-botocore
  # GIS clients of the WMTS and OGC API - Tiles routes (tests/integration/gis_*.sh): OWSLib
  # reads the capabilities as QGIS and other Python GIS tools do (GDAL's drivers are the others)
  python3-owslib
  # deploy/batch/slurm on a real Slurm cluster: tests/integration/slurm_cluster.sh and
  # bench/batch_bench.sh start slurmctld, slurmd and munged of their own on loopback (as root,
  # no systemd: the packages' own services are not used)
  slurm-wlm munge
)
# Node.js may come from elsewhere (e.g. NodeSource) with its own npm: only ask Debian for what is
# missing, so the two never fight over /usr/bin/node or /usr/bin/npm.
command -v node >/dev/null 2>&1 || PACKAGES+=(nodejs)
command -v npm >/dev/null 2>&1 || PACKAGES+=(npm)

missing=()
for pkg in "${PACKAGES[@]}"; do
  status=$(dpkg-query -W -f='${db:Status-Status}' "$pkg" 2>/dev/null || true)
  [[ $status == installed ]] || missing+=("$pkg")
done

if ((${#missing[@]} > 0)) || [[ $FORCE == 1 ]]; then
  if ((${#missing[@]} > 0)); then
    log "installing Debian packages: ${missing[*]}"
  else
    log "VTS_SETUP_FORCE=1: reinstalling Debian packages"
  fi
  apt_opts=(-o DPkg::Lock::Timeout=600 -o Dpkg::Use-Pty=0)
  # libgdal-dev needs libkml-dev, which depends on libboost-dev: Boost 1.74 on bookworm, which
  # conflicts with the libboost1.81-dev we build with. A tiny local package that provides
  # libboost-dev by depending on libboost1.81-dev resolves it (built here with dpkg-deb).
  shim_deb=""
  if [[ $(dpkg-query -W -f='${db:Status-Status}' vts-libboost-dev-shim 2>/dev/null || true) != installed ]]; then
    shim_dir=$(mktemp -d)
    mkdir -p "$shim_dir/pkg/DEBIAN"
    cat >"$shim_dir/pkg/DEBIAN/control" <<'CONTROL'
Package: vts-libboost-dev-shim
Version: 1.81.0
Architecture: all
Maintainer: vtstream <noreply@localhost>
Depends: libboost1.81-dev
Provides: libboost-dev (= 1.81.0)
Section: libdevel
Priority: optional
Description: lets packages that need libboost-dev use Boost 1.81
 libkml-dev (needed by libgdal-dev) depends on libboost-dev, Boost 1.74 on bookworm, which
 conflicts with libboost1.81-dev.
CONTROL
    dpkg-deb --build "$shim_dir/pkg" "$shim_dir/vts-libboost-dev-shim.deb" >/dev/null
    chmod -R a+rX "$shim_dir"
    shim_deb="$shim_dir/vts-libboost-dev-shim.deb"
  fi
  "${SUDO[@]}" env DEBIAN_FRONTEND=noninteractive apt-get "${apt_opts[@]}" update -q
  "${SUDO[@]}" env DEBIAN_FRONTEND=noninteractive apt-get "${apt_opts[@]}" install -y -q \
    --no-install-recommends ${shim_deb:+"$shim_deb"} "${PACKAGES[@]}"
else
  log "all ${#PACKAGES[@]} Debian packages already installed"
fi

for tool in node npm cmake ninja oiiotool idiff vips gdal_translate gdalwarp; do
  command -v "$tool" >/dev/null 2>&1 || {
    echo "setup.sh: '$tool' is still missing after installing packages" >&2
    exit 1
  }
done

# npm packages for the build (server/web) and the integration tests: exactly what package-lock.json pins. A stamp holding the
# lock file's hash makes re-runs instant; a changed lock file (or VTS_SETUP_FORCE=1) reinstalls.
npm_ci() { # DIR
  local dir=$1 stamp want
  stamp="$dir/node_modules/.vts-setup-stamp"
  want="$(sha256sum "$dir/package-lock.json" | cut -d' ' -f1) node-$(node --version)"
  if [[ $FORCE != 1 && -f $stamp && $(cat "$stamp") == "$want" ]]; then
    log "npm packages in ${dir#"$ROOT"/} up to date"
    return
  fi
  log "npm ci in ${dir#"$ROOT"/}"
  (cd "$dir" && npm ci --no-audit --no-fund --loglevel=error </dev/null)
  printf '%s\n' "$want" >"$stamp"
}
export npm_config_update_notifier=false
# server/web: OpenLayers for the browser viewer, which the build embeds in vts (CMake stops with
# a message naming this script when it is missing); tests/integration/browser_js: puppeteer-core,
# which drives Debian's chromium against that viewer.
npm_ci "$ROOT/server/web"
npm_ci "$ROOT/tests/integration/pmtiles_js"
npm_ci "$ROOT/tests/integration/deploy_js"
npm_ci "$ROOT/tests/integration/browser_js"
# s3rver: a real S3-protocol server on loopback for the store's test (tests/integration/store_s3.sh).
npm_ci "$ROOT/tests/integration/s3_js"

log "done"
